"""Run a planned scene (or one FMU) in libcosim, the Open Simulation Platform's engine (libcosimpy).

What libcosim does (libcosim src/cosim/algorithm/fixed_step_algorithm.cpp, the release bundled
with libcosimpy 0.0.6), and why the result equals crankfmu's Jacobi master:
- start values (our parameters, effect switches, constant inputs) are set in the instantiated
  state, then fmi2SetupExperiment(start, stop) WITHOUT a tolerance: each FMU integrates with its
  DefaultExperiment tolerance (plan.py refuses a scene asking for another one);
- initialization mode: N rounds (N = number of FMUs) of "set inputs, get outputs, transfer",
  then exitInitializationMode, get, transfer. crankfmu propagates with N + 1 Gauss-Seidel sweeps;
  both reach the same values when the chain of direct feedthrough is shorter than N rounds (true
  for the servo press: the press's connected outputs are states);
- each step: every FMU sets the transferred inputs, doStep(t, h), gets its outputs; then all
  outputs are transferred. That is the Jacobi scheme: every input over [t, t+h] is the source's
  output at t. Steps run on a thread pool; Python FMUs serialise on the interpreter lock.
Time is integer nanoseconds in libcosim, so the step must be a whole number of nanoseconds.

Recording uses libcosim's buffered time-series observer (in C++), read once at the end.
"""
from __future__ import annotations

import time
from ctypes import POINTER, c_double, c_int, c_int64, c_size_t, c_uint32, c_void_p, cast

import numpy as np

from .plan import PeerResult, Plan

ENGINE = "libcosim"


def _nanoseconds(seconds: float, what: str) -> int:
    ns = round(seconds * 1e9)
    if ns <= 0 or abs(ns - seconds * 1e9) > 1e-6 * max(1.0, seconds * 1e9):
        raise ValueError(f"libcosim counts time in whole nanoseconds; {what} = {seconds!r} s is "
                         "not a positive whole number of nanoseconds")
    return ns


def _last_error() -> str:
    from libcosimpy._internal import get_last_error_message
    return get_last_error_message()


def _real_samples(observer, slave: int, vr: int, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Step numbers and values of one variable from a time-series observer. Calls the C
    function directly: libcosimpy's wrapper drops samples whose step number is 0."""
    from libcosimpy._internal import libcosimc
    fn = libcosimc().cosim_observer_slave_get_real_samples
    fn.argtypes = [c_void_p, c_int, c_uint32, c_int64, c_size_t, POINTER(c_double),
                   POINTER(c_int64), POINTER(c_int64)]
    fn.restype = c_int64
    values, steps, times = (c_double * n)(), (c_int64 * n)(), (c_int64 * n)()
    got = fn(cast(observer.ptr(), c_void_p), slave, vr, 0, n, values, steps, times)
    if got < 0:
        raise RuntimeError(f"libcosim: cannot read samples of slave {slave} vr {vr}: "
                           f"{_last_error()}")
    return np.array(steps[:got]), np.array(values[:got])


def run(plan: Plan, log_level: str = "ERROR") -> PeerResult:
    """Run `plan` in libcosim with its fixed-step (Jacobi) algorithm; return the recorded series
    at `plan.sample_steps()`. The wall time covers loading, initialization and the steps."""
    from libcosimpy.CosimEnums import CosimVariableType
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
    from libcosimpy.CosimObserver import CosimObserver

    if plan.start_time != 0.0:
        raise ValueError("the libcosim adapter starts at t = 0 (libcosimpy's from_step_size); "
                         f"{plan.name} starts at {plan.start_time} s")
    log_output_level(CosimLogLevel[log_level])
    wall = time.perf_counter()
    execution = CosimExecution.from_step_size(_nanoseconds(plan.step, "[master].step"))
    index, slaves = _add_slaves(execution, plan)
    _connect(execution, plan, index)
    observer = CosimObserver.create_time_series(buffer_size=plan.n_steps + 16)
    execution.add_observer(observer)
    refs = []
    for ref in plan.record:
        comp, var = ref.split(".", 1)
        vr = plan.components[comp].variables[var].valueReference
        observer.start_time_series(index[comp], vr, CosimVariableType.REAL)
        refs.append((index[comp], vr))
    if not execution.step(plan.n_steps):
        raise RuntimeError(f"libcosim stopped: {_last_error()}")
    wall = time.perf_counter() - wall
    result = _collect(plan, observer, refs, wall)
    del execution, observer, slaves  # libcosim frees its instances here
    return result


def _add_slaves(execution, plan: Plan):
    from libcosimpy.CosimSlave import CosimLocalSlave
    index, slaves = {}, []
    for name, comp in plan.components.items():
        slave = CosimLocalSlave(fmu_path=str(comp.path), instance_name=name)
        index[name] = execution.add_local_slave(slave)
        if index[name] < 0:
            raise RuntimeError(f"libcosim cannot load {comp.path}: {_last_error()}")
        slaves.append(slave)  # libcosimpy frees the slave when the Python object goes
        for var, value in comp.start_values.items():
            _set_initial(execution, index[name], comp, var, value)
    return index, slaves


def _connect(execution, plan: Plan, index: dict[str, int]) -> None:
    for src, src_var, dst, dst_var in plan.links:
        status = execution.connect_real_variables(
            index[src], plan.components[src].variables[src_var].valueReference,
            index[dst], plan.components[dst].variables[dst_var].valueReference)
        if status != 0:
            raise RuntimeError(f"libcosim cannot connect {src}.{src_var} -> {dst}.{dst_var}: "
                               f"{_last_error()}")


def _set_initial(execution, idx: int, comp, var: str, value) -> None:
    vr = comp.variables[var].valueReference
    if isinstance(value, bool):
        ok = execution.boolean_initial_value(idx, vr, value)
    else:
        ok = execution.real_initial_value(idx, vr, float(value))
    if not ok:
        raise RuntimeError(f"libcosim cannot set {comp.name}.{var} = {value!r}: {_last_error()}")


def _collect(plan: Plan, observer, refs, wall: float) -> PeerResult:
    wanted = plan.sample_steps()
    rows = np.empty((len(wanted), len(refs)))
    for k, (idx, vr) in enumerate(refs):
        steps, values = _real_samples(observer, idx, vr, plan.n_steps + 16)
        where = np.minimum(np.searchsorted(steps, wanted), max(len(steps) - 1, 0))
        if len(steps) == 0 or np.any(steps[where] != wanted):
            raise RuntimeError(f"libcosim recorded steps {steps[:3]}..{steps[-3:]} of "
                               f"{plan.record[k]}, expected {wanted[:3]}..{wanted[-3:]}")
        rows[:, k] = values[where]
    times = plan.start_time + wanted * plan.step
    return PeerResult(ENGINE, times, {r: rows[:, k] for k, r in enumerate(plan.record)}, wall,
                      plan.n_steps)
