"""The accuracy sweep: master algorithm x extrapolation x communication step (x FMU tolerance),
each run compared with the monolithic reference (computed once, cached in the output folder).

Fixed-step masters are swept over the communication step; a variable-step master (the one named
`adaptive`, or any master class with `variable_step = True`) is swept over its tolerance instead,
with the scene's step as its initial step.
"""
from __future__ import annotations

import copy
import hashlib
import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ...cosim.results import versions
from ...reference import record_times, solve_reference, write_reference
from .metrics import Metric, MetricError, ReferenceSamples, observed_order

FLOOR_FACTOR = 10.0  # errors below 10 x the FMUs' tolerance are not coupling errors


@dataclass(frozen=True)
class Setting:
    algorithm: str
    extrapolation: int
    step: float           # s, communication step (initial step of a variable-step master)
    fmu_tolerance: float
    tolerance: float      # the iterative/adaptive masters' own tolerance

    @property
    def label(self) -> str:
        return (f"{self.algorithm}_x{self.extrapolation}_h{self.step:g}_ft{self.fmu_tolerance:g}"
                f"_tol{self.tolerance:g}")


@dataclass
class Outcome:
    setting: Setting
    knob: str                  # "step" or "tolerance": what the sweep varies for this master
    error: float = math.inf
    wall_seconds: float = math.nan
    do_steps: int = 0
    rollbacks: int = 0
    communication_steps: int = 0
    status: str = "completed"
    extra: dict = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        return self.status == "completed" and math.isfinite(self.error)

    @property
    def knob_value(self) -> float:
        return self.setting.step if self.knob == "step" else self.setting.tolerance


def is_variable_step(algorithm: str) -> bool:
    from ...cosim.masters import MASTERS
    cls = MASTERS.get(algorithm)
    return algorithm == "adaptive" or bool(getattr(cls, "variable_step", False))


def settings_for(scene, algorithms, extrapolations, steps, fmu_tolerances,
                 tolerances) -> list[Setting]:
    out = []
    for alg in algorithms:
        for ex in extrapolations:
            for ft in fmu_tolerances:
                if is_variable_step(alg):
                    out += [Setting(alg, ex, scene.master.step, ft, tol) for tol in tolerances]
                else:
                    out += [Setting(alg, ex, h, ft, scene.master.tolerance) for h in steps]
    return out


# -- reference ---------------------------------------------------------------------------------
def reference_grid(scene, settings: list[Setting]) -> np.ndarray:
    """The union of the runs' record grids, so runs are compared at reference grid points."""
    grids = []
    for h in sorted({s.step for s in settings}):
        trial = copy.deepcopy(scene)
        trial.master.step = h
        grids.append(record_times(trial))
    return np.unique(np.round(np.concatenate(grids), 12))


def _cache_key(scene, grid: np.ndarray, rtol: float) -> str:
    payload = {"components": {n: [c.fmu, sorted(c.parameters.items()), sorted(c.effects)]
                              for n, c in scene.components.items()},
               "connections": [[c.source, c.target] for c in scene.connections],
               "inputs": {k: [s.times, s.values, s.interpolation] for k, s in scene.inputs.items()},
               "record": scene.record, "order": scene.master.order,
               "t": [scene.start_time, scene.stop_time], "rtol": rtol,
               "grid": hashlib.sha256(np.ascontiguousarray(grid).tobytes()).hexdigest(),
               "crankfmu": versions().get("crankfmu")}
    return hashlib.sha256(json.dumps(payload, sort_keys=True, default=str).encode()).hexdigest()


def load_or_solve_reference(scene, grid: np.ndarray, out_dir: Path, rtol: float,
                            progress=None) -> tuple[ReferenceSamples, Path, bool]:
    """The reference on `grid`, read from out_dir/reference.csv when its sidecar's cache key
    matches (same physics, inputs, times, tolerance), else solved and written there.
    Returns (samples, csv path, True if it came from the cache)."""
    csv = out_dir / "reference.csv"
    key = _cache_key(scene, grid, rtol)
    side = csv.with_suffix(".json")
    if csv.is_file() and side.is_file() and json.loads(side.read_text()).get("cache_key") == key:
        return _read_reference(csv), csv, True
    result = solve_reference(scene, rtol=rtol, times=grid, progress=progress)
    write_reference(scene, csv, result)
    meta = json.loads(side.read_text())
    meta["cache_key"] = key
    side.write_text(json.dumps(meta, indent=2) + "\n")
    rec = result.recorder
    return ReferenceSamples(rec.rows[:, 0], {n: rec.column(n) for n in rec.names}), csv, False


def _read_reference(csv: Path) -> ReferenceSamples:
    names = [n.strip('"') for n in csv.read_text().split("\n", 1)[0].split(",")]
    data = np.loadtxt(csv, delimiter=",", skiprows=1, ndmin=2)
    return ReferenceSamples(data[:, 0], {n: data[:, k] for k, n in enumerate(names) if k})


# -- runs ----------------------------------------------------------------------------------------
def trial_scene(scene, setting: Setting):
    """`scene` with the master settings of `setting`."""
    trial = copy.deepcopy(scene)
    m = trial.master
    m.algorithm, m.extrapolation, m.step = setting.algorithm, setting.extrapolation, setting.step
    m.fmu_tolerance, m.tolerance = setting.fmu_tolerance, setting.tolerance
    return trial


def run_one(scene, setting: Setting, metric: Metric, ref: ReferenceSamples, fmu_dir,
            runs_dir: Path, executor=None) -> Outcome:
    """One setting, run on `executor` (default: a pool of one worker process)."""
    return run_settings(scene, [setting], metric, ref, fmu_dir, runs_dir, executor,
                        progress=False)[0]


def run_settings(scene, settings: list[Setting], metric: Metric, ref: ReferenceSamples, fmu_dir,
                 runs_dir: Path, executor=None, progress=False, label: str = "runs") \
        -> list[Outcome]:
    """Every setting as one run on `executor` (default: a pool of one worker process, runs one
    after another); this process writes the runs' CSVs and sidecars into runs_dir. The
    outcomes do not depend on the executor (only wall times do)."""
    from ..executor import LocalPoolExecutor, RunTask

    tasks = [RunTask(k, trial_scene(scene, s)) for k, s in enumerate(settings)]
    own = executor is None
    executor = executor or LocalPoolExecutor(1)
    try:
        outputs = executor.run(tasks, fmu_dir, progress=progress, label=label)
    finally:
        if own:
            executor.close()
    paths = getattr(executor, "fmu_files", {})
    return [_outcome(s, o, t, metric, ref, runs_dir, paths)
            for s, o, t in zip(settings, outputs, tasks)]


def _outcome(setting: Setting, output, task, metric: Metric, ref: ReferenceSamples,
             runs_dir: Path, paths: dict) -> Outcome:
    from ...cosim.runner import RunError
    from ..executor import write_run_files

    outcome = Outcome(setting, "tolerance" if is_variable_step(setting.algorithm) else "step")
    csv = runs_dir / f"{setting.label}.csv"
    fmu_paths = {c: paths.get(d) for c, (d, _) in task.fmus.items()}
    if output.sidecar:  # the run got as far as writing results (completed or stopped early)
        write_run_files(output, csv, fmu_paths)
    if output.status == "failed":
        outcome.status = f"failed: {RunError(output.reason, csv)}"
        return outcome
    if output.status == "refused":  # a master refusing the scene or setting
        outcome.status = f"unavailable: {output.reason}"
        return outcome
    if output.status != "completed":
        outcome.status = f"{output.status}: {output.reason}"
        return outcome
    outcome.wall_seconds = output.wall_seconds
    outcome.do_steps, outcome.rollbacks = _counts(output.statistics)
    outcome.communication_steps = int(output.sidecar.get("communication_steps", output.steps))
    try:
        outcome.error = metric.error(output.rows[:, 0],
                                     {n: output.column(n) for n in output.names}, ref)
    except MetricError as err:
        outcome.status = f"no error figure: {err}"
    return outcome


def _counts(statistics: dict) -> tuple[int, int]:
    calls = rollbacks = 0
    for value in statistics.values():
        if isinstance(value, dict) and "doStep_calls" in value:
            calls += int(value["doStep_calls"])
            rollbacks += int(value.get("rollbacks", 0))
    return calls, rollbacks


# -- summaries -----------------------------------------------------------------------------------
def orders(outcomes: list[Outcome], floor_factor: float = FLOOR_FACTOR) -> dict:
    """Observed order per (algorithm, extrapolation, fmu_tolerance): slope of log error over log
    step (log tolerance for a variable-step master) over the errors above floor_factor x the FMU
    tolerance. Values: (order, points used, knob)."""
    groups: dict[tuple, list[Outcome]] = {}
    for o in outcomes:
        s = o.setting
        groups.setdefault((s.algorithm, s.extrapolation, s.fmu_tolerance), []).append(o)
    result = {}
    for key, group in groups.items():
        ok = [o for o in group if o.ok]
        order, used = observed_order([o.knob_value for o in ok], [o.error for o in ok],
                                     floor_factor * key[2])
        result[key] = (order, used, group[0].knob)
    return result


def cheapest(outcomes: list[Outcome], target: float) -> Outcome | None:
    """The run with the least wall time among those whose error meets the target (ties: fewer
    doStep calls)."""
    meeting = [o for o in outcomes if o.ok and o.error <= target]
    return min(meeting, key=lambda o: (o.wall_seconds, o.do_steps)) if meeting else None


def fewest_steps(outcomes: list[Outcome], target: float) -> Outcome | None:
    """The run with the fewest doStep calls among those meeting the target (timing-free)."""
    meeting = [o for o in outcomes if o.ok and o.error <= target]
    return min(meeting, key=lambda o: (o.do_steps, o.wall_seconds)) if meeting else None
