"""The contract every master algorithm implements (after scipy's OdeSolver).

A master advances a wired `System` (FMUs, links, external inputs) over communication steps.
Implementers subclass `Master` and provide:

    name              the algorithm's name in scenes and on the command line.
    step(t, h)        advance every FMU from t by h; on return every FMU is at t + h and
                      `system.outputs` holds the connected outputs at t + h. Return the step taken.

The base class provides `initialize()` (propagate connected values through initialization mode),
`check_finite()` (divergence with time, component and variable), and statistics per FMU.
A master that rolls FMUs back sets `needs_rollback = True`; the base then checks
canGetAndSetFMUstate for every FMU and names the one that cannot.
"""
from __future__ import annotations

import math

import numpy as np

RUNAWAY_LIMIT = 1e12  # |value| beyond this in a connected output is taken as divergence


class DivergenceError(RuntimeError):
    """The run left the finite, bounded range; names time, component and variable."""

    def __init__(self, time: float, component: str, variable: str, value: float):
        self.time, self.component, self.variable, self.value = time, component, variable, value
        super().__init__(f"diverged at t = {time:.6g} s: {component}.{variable} = {value!r}")


class Master:
    name = "base"
    needs_rollback = False

    def __init__(self, system, settings):
        self.system = system
        self.settings = settings
        if self.needs_rollback:
            for name, fmu in system.fmus.items():
                if not fmu.can_rollback:
                    raise ValueError(f"master {self.name} rolls FMUs back, but {name} "
                                     f"({fmu.path.name}) has canGetAndSetFMUstate = false")

    # -- initialization -------------------------------------------------------------------
    def initialize(self, t0: float) -> None:
        """In initialization mode, pass connected values along until they settle (one sweep per
        component covers any loop-free chain of direct feedthrough)."""
        system = self.system
        for comp in system.order:
            system.set_external(comp, t0, initial=True)
        for _ in range(len(system.order) + 1):
            for comp in system.order:
                system.write_inputs[comp](system.gather_inputs(comp))
                system.refresh_outputs(comp)
        for fmu in system.fmus.values():
            fmu.slave.exitInitializationMode()
        for comp in system.order:
            system.write_inputs[comp](system.gather_inputs(comp))
            system.refresh_outputs(comp)
        self.check_finite(t0)

    # -- contract -------------------------------------------------------------------------
    def step(self, t: float, h: float) -> float:
        raise NotImplementedError

    # -- shared helpers -------------------------------------------------------------------
    def advance_component(self, comp: str, t: float, h: float, inputs) -> None:
        system = self.system
        system.set_external(comp, t)
        system.write_inputs[comp](inputs)
        system.fmus[comp].do_step(t, h)

    def check_finite(self, t: float) -> None:
        for comp, values in self.system.outputs.items():
            if values.size and not (np.all(np.isfinite(values))
                                    and np.max(np.abs(values)) < RUNAWAY_LIMIT):
                k = int(np.argmax(~np.isfinite(values) | (np.abs(values) >= RUNAWAY_LIMIT)))
                raise DivergenceError(t, comp, self.system.out_names[comp][k], float(values[k]))

    def statistics(self) -> dict:
        return {name: fmu.stats.as_dict() for name, fmu in self.system.fmus.items()}


def finite(x: float) -> bool:
    return math.isfinite(x) and abs(x) < RUNAWAY_LIMIT
