"""Jacobi: every component steps from t with inputs extrapolated from the past communication
points of their sources (order [master].extrapolation: 0 holds the value at t, 1 and 2 follow the
line / parabola through the last 2 / 3 points; fewer while the run has too few points).

The components are independent within a step (they could run in parallel); the price is a
coupling delay on every connection. Global error order: extrapolation order + 1.
"""
from __future__ import annotations

from .base import Master
from .options import EXTRAPOLATION, TAYLOR


class Jacobi(Master):
    options = (EXTRAPOLATION, TAYLOR)
    startup_corrector = True
    name = "jacobi"

    def _step(self, t: float, h: float) -> float:
        self.parallel_sweep(t, h, self.extrapolation)
        return h
