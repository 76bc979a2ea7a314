"""An example master, kept small to show what adding one takes (docs/masters.md, "Adding a master").

Iterated Gauss-Seidel (waveform relaxation): a Gauss-Seidel sweep with held inputs, then
`sweeps - 1` more passes over the same step, each rolled back to t with every input interpolated
linearly between its source's value at t and that source's output at t + h from the pass before
(a Jacobi pass on the interpolated waveforms). One pass is plain Gauss-Seidel with extrapolation
0 (global order 1). As the passes converge the inputs approach the trapezoidal coupling of the
interface (global order 2 for a smooth system); each pass costs one doStep per FMU.

Adding it is this file and one registration: in crankfmu/masters/__init__.py the line
`IteratedGaussSeidel,` in MASTERS (the tests call `crankfmu.masters.register` instead, so
the shipped list stays as it is).
"""
from __future__ import annotations

from crankfmu.masters.base import Master
from crankfmu.masters.options import Option

SWEEPS = Option("sweeps", int, "1", 2, "passes over each communication step (1: Gauss-Seidel "
                "with held inputs)", minimum=1, maximum=50)


class IteratedGaussSeidel(Master):
    name = "gauss-seidel-iterated"
    options = (SWEEPS,)
    needs_rollback = True  # the base checks canGetAndSetFMUstate for every FMU

    def __init__(self, system, settings):
        super().__init__(system, settings)
        self.sweeps = self.option("sweeps")
        self.extra_statistics = {"passes": 0}

    def _step(self, t: float, h: float) -> float:
        states = self.save_states()
        self.sequential_sweep(t, h, 0)
        for _ in range(self.sweeps - 1):
            newest = {c: (t + h, v.copy()) for c, v in self.system.outputs.items()}
            self.restore_states(states)
            self.parallel_sweep_towards(t, h, newest)
        self.free_states(states)
        self.extra_statistics["passes"] += self.sweeps
        return h

    def parallel_sweep_towards(self, t: float, h: float, newest: dict) -> None:
        """Every component steps from t, its inputs the line from t to `newest` at t + h."""
        coefficients = self.source_coefficients(t, 1, newest)
        for comp in self.system.order:
            self.advance_component(comp, t, h, self.gather(comp, coefficients))
        for comp in self.system.order:
            self.system.refresh_outputs(comp)
