"""Gauss-Seidel: components step one after another, each using the newest outputs.

Component k steps from t with inputs from components before it already at t + h and from those
after it still at t. The order is [master].order (default: the order of [components]).
"""
from __future__ import annotations

from .base import Master


class GaussSeidel(Master):
    name = "gauss-seidel"

    def step(self, t: float, h: float) -> float:
        system = self.system
        for comp in system.order:
            self.advance_component(comp, t, h, system.gather_inputs(comp))
            system.refresh_outputs(comp)
        return h
