"""Solve a scene's composed ODE at tight tolerance and record it like `crankfmu run` does.

The record grid is the runner's (start time, then every [record].interval rounded to whole
communication steps, and the stop time), so a reference CSV and a run CSV line up row by row.
The integration restarts at every record time and at the time points of [inputs] tables
(their kinks and jumps), with `PhysicsModel.advance` locating the models' events in between.
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
                    method: str | None = None, progress: bool | None = False) -> ReferenceResult:
    """Integrate the composed scene and record on `times` (default: the run's grid)."""
    model = ComposedModel(scene)
    rec_map = RecordMap(model)
    times = record_times(scene) if times is None else np.asarray(times, dtype=float)
    recorder = Recorder(list(scene.record), [normalize_unit(u) for u in rec_map.units])
    atol = rtol * model.state_nominal()
    x = model.initial_state(t0=scene.start_time)
    model.solver = "scipy"  # the reference is scipy's solve_ivp, independent of the FMU runtime
    model.integrator = method or model.choose_integrator(scene.start_time, x)
    t = scene.start_time
    no_input = []
    stops = sorted(set(times.tolist()) | set(input_breakpoints(scene)))
    recorded = set(times.tolist())
    wall = time.perf_counter()
    for t_next in _progress(stops, progress, scene.name):
        if t_next > t:
            x = model.advance(t, x, t_next - t, lambda s: no_input, rtol, atol)
            t = t_next
        if t_next in recorded:
            recorder.add(t, rec_map.row(t, x))
    return ReferenceResult(None, None, recorder, time.perf_counter() - wall, model.n_rhs, rtol,
                           model.integrator)


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


def _progress(items, enabled, label):
    if enabled is False:
        return items
    from tqdm import tqdm
    return tqdm(items, desc=f"{label} reference", unit="pt", mininterval=0.5, leave=False,
                disable=None if enabled is None else False)
