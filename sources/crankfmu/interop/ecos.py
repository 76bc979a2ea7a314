"""Run a planned scene (or one FMU) in ecos (ecospy), Lars Ivar Hatledal's co-simulation engine.

What ecos does (ecos src/ecos/simulation.cpp and algorithm/fixed_step_algorithm.cpp), and why
the result equals crankfmu's Jacobi master:
- fmi2SetupExperiment(start) without a tolerance: each FMU integrates with its DefaultExperiment
  tolerance (plan.py refuses a scene asking for another one); then enterInitializationMode, then
  our start values as an ecos parameter set ("instance::variable" = value);
- initialization mode: N rounds (N = number of FMUs) of "set, get" on every FMU followed by a
  transfer over every connection; then exitInitializationMode, get, transfer, set, get;
- each step: every FMU sets its pending inputs, doStep(t, h), gets its outputs (in parallel
  with TBB: Python FMUs serialise on the interpreter lock); then every connection is
  transferred and set. So every input over [t, t+h] is the source's output at t: Jacobi.
ecos accumulates time as t += h, which differs from crankfmu's t0 + k h in the last bits only.

Recording: ecos's CSV writer prints 6 decimals, too few to compare at 1e-9, so a Python
listener reads the recorded variables after each recorded step (one C call per variable).
"""
from __future__ import annotations

import time

import numpy as np

from .plan import Plan, PeerResult

ENGINE = "ecos"
PARAMETER_SET = "crankfmu"


def _error() -> str:
    from ecospy import EcosLib
    return EcosLib.get_last_error()


def _structure(plan: Plan):
    from ecospy import EcosSimulationStructure
    from ecospy.EcosParameterSet import EcosParameterSet

    structure = EcosSimulationStructure()
    params = EcosParameterSet()
    for name, comp in plan.components.items():
        structure.add_model(name, str(comp.path))
        for var, value in comp.start_values.items():
            key = f"{name}::{var}"
            if isinstance(value, bool):
                params.add_bool(key, value)
            else:
                params.add_real(key, float(value))
    if not structure.add_parameter_set(PARAMETER_SET, params):
        raise RuntimeError(f"ecos rejects the start values of {plan.name}: {_error()}")
    params.free()
    for src, src_var, dst, dst_var in plan.links:
        structure.make_real_connection(f"{src}::{src_var}", f"{dst}::{dst_var}")
    return structure


def run(plan: Plan, log_level: str = "err") -> PeerResult:
    """Run `plan` in ecos with its fixed-step algorithm; return the recorded series at
    `plan.sample_steps()`. The wall time covers loading, initialization and the steps."""
    from ecospy import EcosLib, EcosSimulation, SimulationListener

    EcosLib.set_log_level(log_level)
    wall = time.perf_counter()
    structure = _structure(plan)
    sim = EcosSimulation(structure=structure, step_size=plan.step)
    ids = [ref.replace(".", "::", 1) for ref in plan.record]
    wanted = plan.sample_steps()
    rows = np.empty((len(wanted), len(ids)))
    filled = [0]
    get = sim.get_real

    def sample() -> None:
        rows[filled[0]] = [get(i) for i in ids]
        filled[0] += 1

    class Recorder(SimulationListener):
        def post(self, info):
            if filled[0] < len(wanted) and info.iterations == wanted[filled[0]]:
                sample()

    try:
        if not sim.init(plan.start_time, PARAMETER_SET):
            raise RuntimeError(f"ecos cannot initialize {plan.name}: {_error()}")
        sample()
        sim.add_listener("crankfmu_recorder", Recorder())
        sim.step(plan.n_steps)
        wall = time.perf_counter() - wall
        if filled[0] != len(wanted):
            raise RuntimeError(f"ecos stopped after {filled[0]} of {len(wanted)} samples: "
                               f"{_error()}")
        sim.terminate()
    finally:
        sim.free()
        structure.free()
    times = plan.start_time + wanted * plan.step
    return PeerResult(ENGINE, times, {r: rows[:, k] for k, r in enumerate(plan.record)}, wall,
                      plan.n_steps)
