"""Solve a scene's composed ODE at tight tolerance and record it like `crankfmu run` does.

The record grid is the runner's (start time, then every [record].interval rounded to whole
communication steps, and the stop time), so a reference CSV and a run CSV line up row by row.
The integration restarts at the time points of [inputs] tables (their kinks and jumps), with
`ComposedModel.advance` locating the models' events in between; the record times are read
from DOP853's dense output (with Radau the integration restarts at each of them, see
solve_reference).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..cosim.results import Recorder, column_units, normalize_unit, versions, write_run_set
from ..system.scene import Scene, SceneError
from .composed import ComposedModel

DEFAULT_RTOL = 1e-10


@dataclass
class ReferenceResult:
    csv: Path | None
    sidecar: Path | None
    recorder: Recorder
    wall_seconds: float
    rhs_calls: int
    rtol: float
    method: str
    png: Path | None = None


def record_times(scene: Scene, interval: float | None = None) -> np.ndarray:
    """The instants `crankfmu run` records at for this scene (same rounding as the runner);
    `interval` overrides [record].interval."""
    h, t0 = scene.master.step, scene.start_time
    n_steps = max(1, math.ceil((scene.stop_time - t0) / h - 1e-9))
    every = max(1, round(((interval or scene.record_interval) or h) / h))
    steps = [s for s in range(1, n_steps + 1) if s % every == 0 or s == n_steps]
    return np.array([t0] + [min(t0 + s * h, scene.stop_time) for s in steps])


def input_breakpoints(scene: Scene) -> list[float]:
    """Times inside the run where an external input table has a kink or a jump."""
    return sorted({t for s in scene.inputs.values() if len(s.times) > 1 for t in s.times
                   if scene.start_time < t < scene.stop_time})


class RecordMap:
    """Reads the scene's [record] variables from the composed model's parts."""

    def __init__(self, model: ComposedModel):
        self.model = model
        self.getters, self.units = [], []
        for ref in model.scene.record:
            getter, unit = self._getter(ref)
            self.getters.append(getter)
            self.units.append(unit)

    def _getter(self, ref: str):
        comp, var = ref.split(".", 1)
        k = self.model.index[comp]
        m = self.model.parts[k].model
        for kind, table in (("output", m.outputs), ("input", m.inputs)):
            names = [v.name for v in table]
            if var in names:
                j = names.index(var)
                return (lambda us, ys, k=k, j=j, kind=kind:
                        (ys if kind == "output" else us)[k][j]), table[j].unit
        names = [v.name for v in m.parameters]
        if var in names:
            value = float(getattr(m.p, var))
            return (lambda us, ys, value=value: value), m.parameters[names.index(var)].unit
        if var.startswith("effect_") and var[len("effect_"):] in {e.name for e in m.effects}:
            value = float(m.on(var[len("effect_"):]))
            return (lambda us, ys, value=value: value), None
        known = [v.name for v in m.outputs + m.inputs + m.parameters]
        raise SceneError(self.model.scene.path, "[record].variables",
                         f"{ref}: {comp} ({m.model_name}) has no variable {var!r}; "
                         f"variables: {', '.join(known)}")

    def row(self, t: float, x: np.ndarray) -> list[float]:
        us, ys = self.model.outputs_at(t, x)
        return [float(g(us, ys)) for g in self.getters]


def solve_reference(scene: Scene, rtol: float = DEFAULT_RTOL, times=None,
                    method: str | None = None, progress: bool | None = False,
                    dense: bool = True) -> ReferenceResult:
    """Integrate the composed scene and record on `times` (default: the run's grid). dense:
    read the record times from DOP853's dense output (False: restart the integration at each,
    as always with Radau: benchmarks/reference.py compares the two)."""
    model = ComposedModel(scene)
    rec_map = RecordMap(model)
    times = record_times(scene) if times is None else np.asarray(times, dtype=float)
    recorder = Recorder(list(scene.record), [normalize_unit(u) for u in rec_map.units])
    atol = rtol * model.state_nominal()
    x = model.initial_state(t0=scene.start_time)
    model.solver = "scipy"  # the reference is scipy's solve_ivp, independent of the FMU runtime
    model.integrator = method or model.choose_integrator(scene.start_time, x)
    samples = _Samples(model, rec_map, recorder, times)
    # DOP853's dense output (7th order) holds the tolerance between its steps: the record times
    # are read from it, and the integration restarts only every SAMPLED_PER_RESTART record
    # times (for the progress bar) and where an input table has a kink or a jump. Restarting
    # at every record time cost 5 to 250 times the right-hand-side calls (the solver's steps
    # are longer than the record interval); Radau's dense output is of lower order than its
    # steps: with Radau it restarts at every record time.
    dense = dense and model.integrator == "DOP853"
    restarts = times[::SAMPLED_PER_RESTART] if dense else times
    stops = sorted(set(restarts.tolist()) | {float(times[-1])} | set(input_breakpoints(scene)))
    t = scene.start_time
    no_input: list = []
    wall = time.perf_counter()
    bar = _progress(len(times), progress, scene.name)
    for t_next in stops:
        if t_next > t:
            x = model.advance(t, x, t_next - t, lambda s: no_input, rtol, atol,
                              sample=samples if dense else None)
            t = t_next
        samples.at_restart(t, x)
        if bar is not None:
            bar.update(samples.next - bar.n)
    if bar is not None:
        bar.close()
    return ReferenceResult(None, None, recorder, time.perf_counter() - wall, model.n_rhs, rtol,
                           model.integrator)


SAMPLED_PER_RESTART = 100  # record times read from one integration's dense output


class _Samples:
    """The reference's rows: each record time once, in order, either at a restart (the state
    the integration stopped with) or inside an integration (its dense output, the components'
    discrete states of that stretch: ComposedModel.advance's `sample`). The state at a record
    time is observed first (ComposedModel.observe), as a restart there would."""

    def __init__(self, model: ComposedModel, rec_map: RecordMap, recorder: Recorder, times):
        self.model, self.rec_map, self.recorder = model, rec_map, recorder
        self.times, self.next = times.tolist(), 0

    def __call__(self, t_from: float, t_to: float, state_at) -> None:
        """Every record time in [t_from, t_to) from `state_at`."""
        while self.next < len(self.times) and self.times[self.next] < t_to:
            t = self.times[self.next]
            x = np.asarray(state_at(t), dtype=float)
            self.model.observe(t, x)
            self._add(t, x)

    def at_restart(self, t: float, x) -> None:
        """The record times up to the restart time t (at most t itself), from its state."""
        while self.next < len(self.times) and self.times[self.next] <= t:
            self._add(self.times[self.next], x)

    def _add(self, t: float, x) -> None:
        self.recorder.add(t, self.rec_map.row(t, x))
        self.next += 1


def write_reference(scene: Scene, out: Path, result: ReferenceResult,
                    png: bytes | None = None) -> ReferenceResult:
    """The CSV (run layout), its JSON sidecar and, given its bytes, the PNG: one set
    (cosim.results.write_run_set)."""
    result.csv, result.sidecar, result.png = write_run_set(out, result.recorder, {
        "scene": str(scene.path), "name": scene.name, "status": "completed",
        "kind": "monolithic reference", "start_time": scene.start_time,
        "stop_time": scene.stop_time, "units": column_units(result.recorder),
        "reference": {"rtol": result.rtol, "atol": "rtol * state_nominal()",
                      "method": result.method, "rhs_calls": result.rhs_calls,
                      "record_points": result.recorder.count},
        "components": {n: {"fmu": c.fmu, "parameters": c.parameters, "effects": c.effects}
                       for n, c in scene.components.items()},
        "versions": versions(), "wall_seconds": result.wall_seconds}, png)
    return result


def _progress(points: int, enabled, label):
    """A bar over the record points (None when `enabled` is False)."""
    if enabled is False:
        return None
    from ..cosim.runner import progress_bar
    return progress_bar(total=points, desc=f"{label} reference", unit="pt", mininterval=0.5,
                        leave=False, disable=None if enabled is None else False)
