"""Gauss-Seidel: components step one after another, each using the newest outputs.

Component k steps from t with inputs from components before it already at t + h and from those
after it still at t. The order is [master].order (default: the order of [components]). With
extrapolation order p, inputs from a source still at t follow the polynomial through its last
p + 1 points; from a source already at t + h, the polynomial through that newest point and the p
before it (interpolation: 0 holds the newest value). Global error order: p + 1.
"""
from __future__ import annotations

from .base import Master
from .options import EXTRAPOLATION, TAYLOR


class GaussSeidel(Master):
    options = (EXTRAPOLATION, TAYLOR)
    startup_corrector = True
    name = "gauss-seidel"

    def _step(self, t: float, h: float) -> float:
        self.sequential_sweep(t, h, self.extrapolation)
        return h
