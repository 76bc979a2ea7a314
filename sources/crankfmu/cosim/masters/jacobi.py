"""Jacobi: every component steps from t with the outputs all components had at t.

The components are independent within a step (they could run in parallel); the price is a
coupling delay of one step on every connection, where Gauss-Seidel has it on half of them.
"""
from __future__ import annotations

from .base import Master


class Jacobi(Master):
    name = "jacobi"

    def step(self, t: float, h: float) -> float:
        system = self.system
        inputs = {comp: system.gather_inputs(comp) for comp in system.order}
        for comp in system.order:
            self.advance_component(comp, t, h, inputs[comp])
        for comp in system.order:
            system.refresh_outputs(comp)
        return h
