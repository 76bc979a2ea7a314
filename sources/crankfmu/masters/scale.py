"""Error scale and divergence: what a master's tolerance is relative to, and the check that
stops a run leaving the finite, bounded range. A part the master base composes; testable
alone."""
from __future__ import annotations

from itertools import chain

import numpy as np

RUNAWAY_LIMIT = 1e12  # |value| beyond this in a connected output is taken as divergence


class DivergenceError(RuntimeError):
    """The run left the finite, bounded range; names time, component and variable."""

    def __init__(self, time: float, component: str, variable: str, value: float):
        self.time, self.component, self.variable, self.value = time, component, variable, value
        super().__init__(f"diverged at t = {time:.6g} s: {component}.{variable} = {value!r}")


class ErrorScale:
    """Each connected output's largest magnitude so far, at least its nominal (the FMU's
    `nominal` attribute, else 1 in its SI unit)."""

    def __init__(self, system):
        # Python floats: a few values per component, updated every step (numpy's per-call cost
        # was most of it); the same comparisons, so the same floats
        self.scale = {c: [0.0] * len(v) for c, v in system.outputs.items()}
        self.nominal = {c: [_nominal(system.fmus[c], n) for n in system.out_names[c]]
                        for c in system.fmus}

    def update(self, outputs: dict) -> None:
        """A NaN output makes the scale NaN, as numpy's maximum does."""
        scale = self.scale
        for c, v in outputs.items():
            scale[c] = [a if a >= abs(b) else abs(b) for a, b in zip(scale[c], v)]

    def of(self, comp: str, values: np.ndarray) -> np.ndarray:
        """The scale as an array (the iterative master's interface vectors)."""
        return np.maximum(np.maximum(self.scale[comp], np.abs(values)), self.nominal[comp])

    def of_floats(self, comp: str, values) -> list[float]:
        """`of` in Python floats (a NaN value gives NaN, as numpy's maximum does)."""
        out = []
        for s, y, n in zip(self.scale[comp], values, self.nominal[comp]):
            y = abs(y)
            m = s if s >= y or s != s else y
            out.append(m if m >= n else n if m == m else m)
        return out


def check_finite(t: float, outputs: dict, out_names: dict) -> None:
    """DivergenceError naming the first output that is not finite or beyond RUNAWAY_LIMIT."""
    # one sum for the usual case: a NaN makes it NaN, an infinity inf (both fail the test)
    if sum(map(abs, chain.from_iterable(outputs.values()))) < RUNAWAY_LIMIT:
        return
    for comp, values in outputs.items():
        for name, x in zip(out_names[comp], values):
            if not -RUNAWAY_LIMIT < x < RUNAWAY_LIMIT:
                raise DivergenceError(t, comp, name, float(x))


def _nominal(fmu, name: str) -> float:
    nominal = getattr(fmu.variables[name], "nominal", None)
    try:
        return abs(float(nominal)) if nominal else 1.0
    except (TypeError, ValueError):
        return 1.0
