"""The accuracy sweep: master algorithm x extrapolation x communication step (x FMU tolerance),
each run compared with the monolithic reference (computed once, cached in the output folder).

Fixed-step masters are swept over the communication step; a variable-step master
(crankfmu.masters.traits: knob "tolerance") is swept over its tolerance instead, with the scene's
step as its initial step; a monolithic master (knob None) runs once, at the scene's step.

Each run's outcome is computed (and `report`ed, e.g. printed) as the run finishes, and kept as
runs/<label>.outcome.json beside its CSV with a key of everything it depends on (physics,
inputs, times, reference, metric, setting, crankfmu version): a sweep started again over the
same folder takes the finished runs from there and runs only the rest.

A run whose error exceeds UNSTABLE_ERROR (the coupling error as large as the quantity itself) or
that stopped (the master or an FMU gave up: diverging states, a step limit) is reported as
unstable, with the figure in the status, not as an error number to compare. A run that counts
other events than the reference (a blow more or less by the stop time) has no per-event figure
to compare either: its status says "events differ" and how many each had.
"""
from __future__ import annotations

import copy
import hashlib
import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import cast

import numpy as np

from ...cosim.results import versions
from ...masters import traits
from ...outputs import atomic_write
from ...monolithic import record_times, solve_reference, write_reference
from ...cosim.metrics import Metric, MetricError, ReferenceSamples, observed_order

FLOOR_FACTOR = 10.0  # errors below 10 x the FMUs' tolerance are not coupling errors
UNSTABLE_ERROR = 1.0  # relative error above which a run has lost the solution (unstable)
EVENTS_DIFFER = "events differ"  # status of a run that counts other events than the reference


@dataclass(frozen=True)
class Setting:
    algorithm: str
    extrapolation: int
    step: float           # s, communication step (initial step of a variable-step master)
    fmu_tolerance: float
    tolerance: float      # the iterative/adaptive masters' own tolerance
    taylor: int = 0       # a Taylor coupling's order ([master].taylor; then extrapolation 0)

    @property
    def label(self) -> str:
        coupling = f"_t{self.taylor}" if self.taylor else f"_x{self.extrapolation}"
        return (f"{self.algorithm}{coupling}_h{self.step:g}_ft{self.fmu_tolerance:g}"
                f"_tol{self.tolerance:g}")

    @property
    def coupling(self) -> str:
        """How the inputs over a step are made: "extrapolation p" or "taylor q"."""
        return f"taylor {self.taylor}" if self.taylor else f"extrapolation {self.extrapolation}"


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
    def unstable(self) -> bool:
        return self.status.startswith("unstable")

    @property
    def events_differ(self) -> bool:
        return self.status.startswith(EVENTS_DIFFER)

    def to_json(self) -> dict:
        s = self.setting
        return {"setting": [s.algorithm, s.extrapolation, s.step, s.fmu_tolerance, s.tolerance,
                            s.taylor],
                "knob": self.knob, "error": self.error if math.isfinite(self.error) else None,
                "wall_seconds": self.wall_seconds, "do_steps": self.do_steps,
                "rollbacks": self.rollbacks, "communication_steps": self.communication_steps,
                "status": self.status, "extra": self.extra}

    @classmethod
    def from_json(cls, data: dict) -> "Outcome":
        error = data["error"]
        return cls(Setting(*data["setting"]), data["knob"],
                   math.inf if error is None else error, data["wall_seconds"],
                   data["do_steps"], data["rollbacks"], data["communication_steps"],
                   data["status"], data.get("extra", {}))

    @property
    def knob_value(self) -> float:
        return self.setting.step if self.knob == "step" else self.setting.tolerance


def settings_for(scene, algorithms, extrapolations, steps, fmu_tolerances,
                 tolerances, taylors=()) -> list[Setting]:
    """The grid: a monolithic master once, at the scene's step (its record grid: the row the
    co-simulation masters are set against); for every other master each coupling (each
    extrapolation, then each Taylor order if the master declares the option) x FMU tolerance x
    tolerance (a variable-step master) or step (a fixed-step one)."""
    out = []
    for alg in algorithms:
        kind = traits(alg)
        if kind.monolithic:
            out.append(Setting(alg, 0, scene.master.step, fmu_tolerances[0],
                               scene.master.tolerance))
            continue
        couplings = [(ex, 0) for ex in extrapolations] + \
            [(0, q) for q in taylors if "taylor" in kind.options]
        for ex, q in couplings:
            for ft in fmu_tolerances:
                if kind.variable_step:
                    out += [Setting(alg, ex, scene.master.step, ft, tol, q) for tol in tolerances]
                else:
                    out += [Setting(alg, ex, h, ft, scene.master.tolerance, q) for h in steps]
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
    text = json.dumps(meta, indent=2) + "\n"
    atomic_write(side, lambda f: f.write(text))
    rec = result.recorder
    return ReferenceSamples(rec.rows[:, 0], {n: rec.column(n) for n in rec.names}), csv, False


def _read_reference(csv: Path) -> ReferenceSamples:
    names = [n.strip('"') for n in csv.read_text().split("\n", 1)[0].split(",")]
    data = np.loadtxt(csv, delimiter=",", skiprows=1, ndmin=2)
    return ReferenceSamples(data[:, 0], {n: data[:, k] for k, n in enumerate(names) if k})


def read_reference_file(csv: Path, needed: list[str], start: float,
                        stop: float) -> ReferenceSamples:
    """A reference from elsewhere (another tool, a finer run) in the run's CSV layout: first
    column time [s], then one column per variable named "component.variable". Checked: it
    reads as numbers, time increases, it covers [start, stop] and has the `needed` columns."""
    from ...cosim.metrics import MetricError
    csv = Path(csv)
    if not csv.is_file():
        raise MetricError(f"--reference {csv}: no such file")
    try:
        ref = _read_reference(csv)
    except (ValueError, IndexError) as err:
        raise MetricError(f"--reference {csv}: not a CSV of numbers in the run layout (time, "
                          f"then one column per \"component.variable\"): {err}") from None
    missing = [n for n in needed if n not in ref.columns]
    if missing:
        raise MetricError(f"--reference {csv}: no column {', '.join(missing)} (the metric "
                          f"needs them); columns: {', '.join(ref.columns) or 'none'}")
    t = ref.times
    if len(t) < 2 or not np.all(np.diff(t) > 0):
        raise MetricError(f"--reference {csv}: the time column must increase strictly")
    if t[0] > start + 1e-12 or t[-1] < stop - 1e-9 * max(1.0, abs(stop)):
        raise MetricError(f"--reference {csv}: covers t = {t[0]:g} to {t[-1]:g} s; the runs "
                          f"need {start:g} to {stop:g} s")
    bad = [n for n in needed if not np.all(np.isfinite(ref.columns[n]))]
    if bad:
        raise MetricError(f"--reference {csv}: column {bad[0]} has values that are not finite")
    return ref


# -- runs ----------------------------------------------------------------------------------------
def trial_scene(scene, setting: Setting):
    """`scene` with the master settings of `setting`."""
    trial = copy.deepcopy(scene)
    m = trial.master
    m.algorithm, m.extrapolation, m.step = setting.algorithm, setting.extrapolation, setting.step
    m.fmu_tolerance, m.tolerance = setting.fmu_tolerance, setting.tolerance
    if setting.taylor:
        m.taylor = setting.taylor
    return trial


def run_settings(scene, settings: list[Setting], metric: Metric, ref: ReferenceSamples, fmu_dir,
                 runs_dir: Path, executor=None, progress=False, label: str = "runs",
                 report=None, resume_key: str | None = None) -> list[Outcome]:
    """Every setting as one run on `executor` (default: in this process, one after another);
    this process writes the runs' CSVs, sidecars and outcomes into runs_dir
    and calls report(outcome) as each run finishes. With `resume_key`, settings whose outcome
    file in runs_dir carries the same key are taken from there, not run again. The outcomes
    do not depend on the executor (only wall times do)."""
    from ..executor import RunTask, make_executor

    outcomes: list[Outcome | None] = [None] * len(settings)
    if resume_key is not None:
        for k, s in enumerate(settings):
            outcomes[k] = _kept_outcome(runs_dir, s, resume_key)
            if outcomes[k] is not None and report is not None:
                report(outcomes[k], kept=True)
    todo = [k for k, o in enumerate(outcomes) if o is None]
    tasks = {k: RunTask(k, trial_scene(scene, settings[k])) for k in todo}
    if not tasks:
        return cast(list[Outcome], outcomes)  # every one kept
    own = executor is None
    executor = executor or make_executor(1)

    def done(output) -> None:
        k = output.key
        paths = getattr(executor, "fmu_files", {})
        outcomes[k] = _outcome(settings[k], output, tasks[k], metric, ref, runs_dir, paths)
        if resume_key is not None:
            _keep_outcome(runs_dir, outcomes[k], resume_key)
        if report is not None:
            report(outcomes[k], kept=False)
    try:
        executor.run(list(tasks.values()), fmu_dir, on_done=done, progress=progress,
                     label=label)
    finally:
        if own:
            executor.close()
    return cast(list[Outcome], outcomes)  # each run reported done, lost runs too


def resume_key(reference_key: str, metric: Metric) -> str:
    """What kept outcomes depend on besides their setting: the reference (its cache key, or an
    external file's digest), the metric and the crankfmu version."""
    payload = [reference_key, metric.describe(), versions().get("crankfmu")]
    return hashlib.sha256(json.dumps(payload).encode()).hexdigest()


def _outcome_file(runs_dir: Path, setting: Setting) -> Path:
    return Path(runs_dir) / f"{setting.label}.outcome.json"


def check_run_files(runs_dir: Path, settings: list[Setting], option: str = "--out") -> None:
    """Before any run: runs_dir is (or can be made) a folder, and none of the names the
    settings' runs and outcomes take there is anything but a regular file (crankfmu.outputs)."""
    from ...cosim.results import check_run_set
    from ...outputs import check_file, output_folder
    output_folder(runs_dir, option)
    for s in settings:
        check_run_set(Path(runs_dir) / f"{s.label}.csv", option)
        check_file(_outcome_file(runs_dir, s), option)


def _kept_outcome(runs_dir: Path, setting: Setting, key: str) -> Outcome | None:
    path = _outcome_file(runs_dir, setting)
    try:
        data = json.loads(path.read_text())
    except (OSError, ValueError):
        return None
    if not isinstance(data, dict) or data.get("key") != key + setting.label:
        return None
    return Outcome.from_json(data["outcome"])


def _keep_outcome(runs_dir: Path, outcome: Outcome, key: str) -> None:
    runs_dir = Path(runs_dir)
    runs_dir.mkdir(parents=True, exist_ok=True)
    text = json.dumps({"key": key + outcome.setting.label, "outcome": outcome.to_json()},
                      indent=1, default=float) + "\n"
    # atomic: an interrupted sweep never leaves half an outcome
    atomic_write(_outcome_file(runs_dir, outcome.setting), lambda f: f.write(text))


def _outcome(setting: Setting, output, task, metric: Metric, ref: ReferenceSamples,
             runs_dir: Path, paths: dict) -> Outcome:
    from ...cosim.runner import RunError
    from ..executor import write_run_files

    outcome = Outcome(setting, traits(setting.algorithm).knob or "step")
    csv = runs_dir / f"{setting.label}.csv"
    fmu_paths = {c: paths.get(d) for c, (d, _) in task.fmus.items()}
    if output.sidecar:  # the run got as far as writing results (completed or stopped early)
        write_run_files(output, csv, fmu_paths)
    if output.status == "failed":  # the run stopped early (diverged, not finite, step limit)
        outcome.status = f"unstable (stopped): {RunError(output.reason, csv)}"
        return outcome
    if output.status == "refused":  # a master refusing the scene or setting
        outcome.status = f"unavailable: {output.reason}"
        return outcome
    if output.status != "completed":  # a crash or a lost worker: not the coupling's doing
        outcome.status = f"{output.status}: {output.reason}"
        return outcome
    outcome.wall_seconds = output.wall_seconds
    outcome.do_steps, outcome.rollbacks = _counts(output.statistics)
    outcome.communication_steps = int(output.sidecar.get("communication_steps", output.steps))
    t = output.rows[:, 0]
    run = {n: output.column(n) for n in output.names}
    try:
        if metric.name == "events":
            details = metric.event_details(t, run, ref)
            outcome.extra["events"] = {d.spec.label: d.error for d in details}
            reasons = list(dict.fromkeys(d.reason for d in details if d.reason))
            if reasons:  # a missed or extra event: no figure to compare (not instability)
                outcome.status = f"{EVENTS_DIFFER}: {'; '.join(reasons)}"
                return outcome
        outcome.error = metric.error(t, run, ref)
    except MetricError as err:
        outcome.status = f"no error figure: {err}"
        return outcome
    if not math.isfinite(outcome.error) or outcome.error > UNSTABLE_ERROR:
        outcome.status = f"unstable: error {outcome.error:.3g} > {UNSTABLE_ERROR:g}"
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
    """Observed order per (algorithm, coupling, fmu_tolerance) (coupling: Setting.coupling,
    "extrapolation p" or "taylor q"): slope of log error over log step (log tolerance for a
    variable-step master) over the errors above floor_factor x the FMU tolerance. Values:
    (order, points used, knob)."""
    groups: dict[tuple, list[Outcome]] = {}
    for o in outcomes:
        s = o.setting
        groups.setdefault((s.algorithm, s.coupling, s.fmu_tolerance), []).append(o)
    result = {}
    for key, group in groups.items():
        if traits(key[0]).monolithic:  # one run: no order to observe
            continue
        ok = [o for o in group if o.ok]
        order, used = observed_order([o.knob_value for o in ok], [o.error for o in ok],
                                     floor_factor * key[2])
        result[key] = (order, used, group[0].knob)
    return result


def cheapest(outcomes: list[Outcome], target: float) -> Outcome | None:
    """The run with the least wall time among those whose error meets the target (ties: fewer
    doStep calls)."""
    meeting = _co_simulations_meeting(outcomes, target)
    return min(meeting, key=lambda o: (o.wall_seconds, o.do_steps)) if meeting else None


def fewest_steps(outcomes: list[Outcome], target: float) -> Outcome | None:
    """The run with the fewest doStep calls among those meeting the target (timing-free)."""
    meeting = _co_simulations_meeting(outcomes, target)
    return min(meeting, key=lambda o: (o.do_steps, o.wall_seconds)) if meeting else None


def _co_simulations_meeting(outcomes: list[Outcome], target: float) -> list[Outcome]:
    """The co-simulation runs meeting the target (the monolithic row is what they are set
    against, not a setting to choose)."""
    return [o for o in outcomes if o.ok and o.error <= target
            and not traits(o.setting.algorithm).monolithic]
