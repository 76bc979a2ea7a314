"""Run a scene: load the FMUs it names, wire them, initialize, step a master, write results."""
from __future__ import annotations

import functools
import math
import signal
import sys
import threading
import time
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from fmpy.fmi1 import FMICallException

from ..errors import CrankfmuError, InterruptedRun
from ..system.scene import Scene, SceneError, check_run_size
from ..fmu.instance import FmuInstance, LogCollector, note_failed_call
from ..masters import DivergenceError, Master, OptionError, make_master, traits
from ..masters.inputs import split_at_edges, step_edges
from .results import (Recorder, check_record_size, check_run_set, column_units, failed_csv,
                      figure_png, normalize_unit, run_figure, versions, write_run_set)
from .trust import judge_result
from ..system.wiring import (System, check_components, check_links, check_loops, check_physics,
                             default_fmu_dir, resolve_fmu)


class RunError(CrankfmuError, RuntimeError):
    """A run that stopped early; the rows computed so far were written to `csv` (beside an
    earlier result of the same name, never over it: see `partial_paths`)."""

    def __init__(self, message: str, csv: Path | None):
        self.csv = csv
        super().__init__(message + (f" (results up to then: {csv})" if csv else ""))


class RunInterrupted(RunError, InterruptedRun):
    """Ctrl-C (SIGINT) stopped the run between two steps; partial results were written."""


class NonFiniteValue(DivergenceError):
    """A recorded value is NaN or infinite: the run stops before writing it."""

    def __init__(self, time: float, component: str, variable: str, value: float):
        super().__init__(time, component, variable, value)
        self.args = (f"not finite at t = {time:.6g} s: {component}.{variable} = {value!r} "
                     f"(recorded variable of component {component})",)

    def __str__(self) -> str:
        return self.args[0]


@dataclass
class RunResult:
    csv: Path | None       # None: nothing was written (RunOptions.out None)
    sidecar: Path | None
    png: Path | None
    recorder: Recorder
    statistics: dict
    wall_seconds: float
    steps: int
    master_statistics: dict = field(default_factory=dict)
    coupling_error: dict = field(default_factory=dict)
    metadata: dict = field(default_factory=dict)  # the sidecar's content (also when not written)
    cpu_seconds: float = 0.0  # this process's CPU from initialization to the FMUs' release
    estimate: Any = None  # cosim.estimate.Estimate when RunOptions.estimate


@dataclass
class RunOptions:
    out: Path | None = None       # the CSV to write (sidecar, PNG beside it); None: write nothing
    plot: bool = False
    fmu_dir: Path | None = None
    progress: bool | None = None  # None: a bar when stderr is a terminal
    verbose_log: bool = False
    extra_sidecar: dict = field(default_factory=dict)
    # estimate the run's global error from companion runs (cosim/estimate.py): the sidecar's
    # "error_estimate"; off for the runs of studies, which compare against a reference
    estimate: bool = False
    # processes for the run and its companions (cosim/companions.py): 1 runs the companions
    # here after the run; 2 runs them in a worker beside it (pays on long runs with a free core:
    # benchmarks/estimate_cost.py, benchmarks/jobs.py)
    jobs: int = 1
    label: str | None = None  # the progress bar's (default: the scene's name)


_UNREADABLE = (OSError, ValueError, KeyError, IndexError, TypeError, AttributeError,
               zipfile.BadZipFile)


def unreadable_fmu(err: Exception) -> bool:
    """Whether `err`, raised while loading an FMU, says it is not an FMU fmpy can read (lxml's
    errors too: lxml is imported where fmpy parses a modelDescription, and a run whose FMUs
    were checked by an earlier process does not import it)."""
    lxml = sys.modules.get("lxml.etree")
    return isinstance(err, _UNREADABLE) or (lxml is not None and isinstance(err, lxml.LxmlError))


def load_fmus(scene: Scene, fmu_dir: Path, log: LogCollector) -> dict[str, FmuInstance]:
    """Every component's FMU, loaded (FMI 2.0 or 3.0, as the file is) for the interface the
    scene's master steps it through (`interface` of its class: CoSimulation by default)."""
    from ..fmu.instance3 import MODEL_EXCHANGE, open_fmu
    interface = traits(scene.master.algorithm).interface
    fmus: dict[str, FmuInstance] = {}
    for name in scene.components:
        path = resolve_fmu(scene, name, fmu_dir, model_exchange=interface == MODEL_EXCHANGE)
        try:
            fmus[name] = open_fmu(name, path, log, interface)
        except Exception as err:  # noqa: BLE001 - re-raised below unless it is unreadable_fmu
            if not unreadable_fmu(err):
                raise
            close_fmus(fmus)
            raise SceneError(scene.path, f"[components.{name}].fmu",
                             f"cannot load {path}: {type(err).__name__}: {err}") from None
    return fmus


def close_fmus(fmus: dict[str, FmuInstance]) -> None:
    for fmu in fmus.values():
        try:
            fmu.terminate()
        except Exception:  # an FMU that failed may refuse to terminate; results still count
            pass


def _setup(scene: Scene, fmus: dict[str, FmuInstance], log: LogCollector) -> None:
    for name, comp in scene.components.items():
        fmu = fmus[name]
        fmu.instantiate(logging_on=True)
        fmu.setup(scene.start_time, scene.stop_time, scene.master.fmu_tolerance)
        effects = {v: v[len("effect_"):] in comp.effects for v in fmu.variables
                   if v.startswith("effect_")}
        fmu.set_start_values({**effects, **comp.parameters})
        fmu.slave.enterInitializationMode()


def _recorder(scene: Scene, fmus) -> tuple[Recorder, list]:
    names = scene.record
    units = [fmus[r.split(".", 1)[0]].variable(r.split(".", 1)[1]).unit for r in names]
    readers: list[tuple] = []
    for comp in dict.fromkeys(r.split(".", 1)[0] for r in names):
        vars_ = [r.split(".", 1)[1] for r in names if r.split(".", 1)[0] == comp]
        readers.append((fmus[comp].reader(vars_), [names.index(f"{comp}.{v}") for v in vars_]))
    if [k for _, where in readers for k in where] == list(range(len(names))):
        readers = [(read, None) for read, _ in readers]  # the usual case: the row in order
    return Recorder(names, [normalize_unit(u) for u in units]), readers


def _sample(recorder: Recorder, readers, t: float) -> None:
    if readers and readers[0][1] is None:  # each reader's values in turn make the row
        row = []
        for read, _ in readers:
            row += read()  # a list of Python floats
    else:
        row = [0.0] * len(recorder.names)
        for read, where in readers:
            for k, v in zip(where, read()):
                row[k] = v
    if not math.isfinite(sum(row)):  # NaN or inf somewhere (or an overflowing sum): find it
        for name, v in zip(recorder.names, row):
            if not math.isfinite(v):
                comp, var = name.split(".", 1)
                raise NonFiniteValue(t, comp, var, v)
    recorder.add(t, row)


def partial_paths(out: Path) -> tuple[Path, Path]:
    """Where a failed run writes: `out` if nothing is there yet, else `<stem>.failed.csv`
    beside it (and its sidecar), so a failed rerun never replaces a good result."""
    sidecar = out.with_suffix(".json")
    if not out.exists() and not sidecar.exists():
        return out, sidecar
    failed = failed_csv(out)
    return failed, failed.with_suffix(".json")


class _Interrupt:
    """SIGINT sets a flag that the stepping loop reads between macro steps: no
    KeyboardInterrupt is ever raised inside an FMU call (pythonfmu runs the FMU's Python in
    this interpreter, and a Python exception inside an FMU call damages it: the process
    crashed later, at exit, in 3 of 5 tries before)."""

    def __init__(self):
        self.requested = False
        self._previous = None

    def __enter__(self):
        if threading.current_thread() is threading.main_thread():
            self._previous = signal.signal(signal.SIGINT, self._handle)
        return self

    def _handle(self, signum, frame) -> None:
        self.requested = True

    def __exit__(self, *exc) -> None:
        if self._previous is not None:
            signal.signal(signal.SIGINT, self._previous)


def run_scene(scene: Scene, options: RunOptions | None = None) -> RunResult:
    """Run the scene; a run that fails or is interrupted writes its rows so far (partial_paths)
    and raises RunError (RunInterrupted for Ctrl-C)."""
    options = options or RunOptions()
    check_run_size(scene)
    check_record_size(scene)
    if options.estimate:
        from .estimate import with_metric_record
        scene = with_metric_record(scene)
    out = check_run_set(Path(options.out)) if options.out is not None else None
    log = LogCollector(echo=options.verbose_log)
    fmu_dir = options.fmu_dir or default_fmu_dir(scene)
    companions = _companions(options)  # workers start while the FMUs load
    try:
        result = _prepare_and_run(scene, options, out, log, fmu_dir, companions)
    except BaseException:
        if companions is not None:  # the run stopped: its companions are of no use
            companions.close(abandon=True)
        raise
    if companions is not None:
        companions.close()
    return result


def _companions(options: RunOptions):
    if not options.estimate:
        return None
    from .companions import Companions
    return Companions(options.jobs)


@dataclass
class LoadedRun:
    """A scene's FMUs loaded, checked and wired to its master: what stepping needs."""
    fmus: dict[str, FmuInstance]
    system: System
    master: Master
    recorder: Recorder
    readers: list             # (read, columns) per component: _sample
    log: LogCollector


@dataclass
class Stepped:
    """How stepping a run went: the steps taken, its wall and CPU time (initialization to the
    FMUs' release), and why it stopped early (`failure`, None for a run that completed) as
    the sidecar's "outcome": "completed", "failed" or "interrupted"."""
    steps: int
    wall_seconds: float
    cpu_seconds: float
    failure: str | None = None
    outcome: str = "completed"


def _prepare_and_run(scene, options, out, log, fmu_dir, companions) -> RunResult:
    """Load, step, and turn the stepping into the run's result and files (a run that stopped
    early writes its rows and raises RunError: _stop)."""
    loaded = _load(scene, fmu_dir, log)
    # the FMUs are built now: the companions can load them beside this run
    pending = submit_companions(scene, fmu_dir, companions, options.progress) \
        if companions is not None else None
    try:
        with _Interrupt() as interrupt:  # Ctrl-C counted, not raised, until the rows are out
            stepped = _step(scene, loaded, options, interrupt)
            result = _run_result(scene, loaded, stepped, options.extra_sidecar)
            if stepped.failure:
                _stop(out, result, stepped)
    except BaseException:
        for _, companion in pending or ():
            companion.cancel()
        raise
    try:
        if pending is not None:
            _add_estimate(scene, fmu_dir, result, pending)
    except BaseException as err:  # the run's own results are kept, without the estimate
        result.metadata["error_estimate"] = {"estimated_error": None, "reason": "not "
                                             f"finished: {type(err).__name__}"}
        _write_result(scene, options, out, result, plot=False)
        if isinstance(err, (KeyboardInterrupt, InterruptedRun)):
            raise RunInterrupted("interrupted (Ctrl-C) while the error estimate's companion "
                                 "runs ran; the run's results were written without an "
                                 "estimate", result.csv) from None
        raise
    judge_result(scene, result)
    _write_result(scene, options, out, result)
    return result


def _load(scene: Scene, fmu_dir, log: LogCollector) -> LoadedRun:
    """The scene's FMUs loaded and checked against it, wired into a System, its master made
    and the recorder ready; the FMUs are released if anything fails."""
    fmus = load_fmus(scene, fmu_dir, log)
    try:
        check_components(scene, fmus)
        links = check_links(scene, fmus)
        check_physics(scene, fmus)
        system = System(scene, fmus, links)
        try:
            master = make_master(scene.master.algorithm, system, scene.master)
        except OptionError as err:  # an option set in code, checked against its declaration
            key, _, message = str(err).partition(": ")
            raise SceneError(scene.path, key, message) from None
        except ValueError as err:  # e.g. an FMU that cannot roll back, for a master that must
            raise SceneError(scene.path, "[master]", str(err)) from None
        check_loops(scene, fmus, links, master)
        recorder, readers = _recorder(scene, fmus)
    except BaseException:
        close_fmus(fmus)
        raise
    return LoadedRun(fmus, system, master, recorder, readers, log)


def _add_estimate(scene: Scene, fmu_dir, result: RunResult, pending: list) -> None:
    """Collect the companions, put the estimate in the result's metadata."""
    from .estimate import recorder_series
    result.estimate = estimate_run(scene, recorder_series(result.recorder), fmu_dir, pending)
    result.metadata["error_estimate"] = result.estimate.to_json()


def _step(scene: Scene, run: LoadedRun, options: RunOptions, interrupt) -> Stepped:
    """Initialize the FMUs and step the master to the stop time, recording rows; a failure
    (divergence, an FMU call, a value that is not finite) or Ctrl-C ends the stepping with the
    rows so far and says why (Stepped.failure). The FMUs are released in any case."""
    master, t0 = run.master, scene.start_time
    wall, cpu = time.perf_counter(), time.process_time()
    failure = outcome = None
    step, t = 0, t0
    try:
        _setup(scene, run.fmus, run.log)
        master.initialize(t0)
        _sample(run.recorder, run.readers, t0)
        loop = _variable_steps if master.variable_step else _fixed_steps
        for step, t, t_new, record in loop(master, scene, options.progress, options.label):
            if interrupt.requested:
                break
            master.check_finite(t_new)
            if record:
                _sample(run.recorder, run.readers, t_new)
    except DivergenceError as err:
        failure, outcome = str(err), "failed"
    except FMICallException as err:
        note_failed_call()
        failure, outcome = _fmi_failure(err, run.fmus, run.log, master.time
                                        if master.time is not None else t), "failed"
    except (ArithmeticError, ValueError, RuntimeError, OSError) as err:  # say it, keep the rows
        note_failed_call()  # perhaps inside an FMU (the Model Exchange master's calls)
        failure, outcome = f"stopped near t = {master.time or t:.6g} s: " \
                           f"{type(err).__name__}: {err}", "failed"
    finally:
        wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
        close_fmus(run.fmus)
    if interrupt.requested and not failure:
        failure, outcome = f"interrupted (Ctrl-C) at t = {master.time or t0:.6g} s", "interrupted"
    return Stepped(step, wall, cpu, failure, outcome or "completed")


def _run_result(scene: Scene, run: LoadedRun, stepped: Stepped, extra_sidecar: dict
                ) -> RunResult:
    """The run's result with the sidecar's content (metadata), nothing written yet."""
    master, m = run.master, scene.master
    statistics = master.statistics()
    metadata = {
        "scene": str(scene.path), "name": scene.name, "status": stepped.failure or "completed",
        "outcome": stepped.outcome, "rows": run.recorder.count,
        "units": column_units(run.recorder),
        "start_time": scene.start_time, "stop_time": scene.stop_time,
        "master": {**m.resolved(), "step": m.step, "order": run.system.order},  # its options
        "components": {n: {"fmu": str(f.path), "parameters": scene.components[n].parameters,
                           "effects": scene.components[n].effects}
                       for n, f in run.fmus.items()},
        "versions": versions(), "wall_seconds": stepped.wall_seconds,
        "cpu_seconds": stepped.cpu_seconds, "communication_steps": stepped.steps,
        "statistics": statistics, "master_statistics": master.master_statistics(),
        "coupling_error": master.coupling_error(), **extra_sidecar}
    return RunResult(None, None, None, run.recorder, statistics, stepped.wall_seconds,
                     stepped.steps, master.master_statistics(), master.coupling_error(),
                     metadata, stepped.cpu_seconds)


def _stop(out: Path | None, result: RunResult, stepped: Stepped) -> None:
    """A run that stopped early: its rows so far written beside any earlier result
    (partial_paths), then RunError (RunInterrupted for Ctrl-C) saying why and where."""
    csv = None
    if out is not None:
        csv, result.sidecar, _ = write_run_set(partial_paths(out)[0], result.recorder,
                                               result.metadata)
    raise (RunInterrupted if stepped.outcome == "interrupted" else RunError)(
        stepped.failure or stepped.outcome, csv)


def _write_result(scene: Scene, options: RunOptions, out: Path | None, result: RunResult,
                  plot: bool | None = None) -> None:
    """The run's CSV, sidecar and (options.plot) PNG, written as one set (write_run_set)."""
    if out is None:
        return
    png = None
    if options.plot if plot is None else plot:
        m = result.metadata["master"]
        title = f"{scene.name}: {m['algorithm']}, step {m['step']:g} s"
        if result.metadata.get("outcome") == "unreliable":
            title += " (UNRELIABLE: see the sidecar)"
        png = figure_png(run_figure(result.recorder, title, plot_roles(scene),
                                    _reference_beside(out, result.recorder)))
    result.csv, result.sidecar, result.png = write_run_set(out, result.recorder, result.metadata,
                                                           png)


FLOOR_FACTOR = 10.0  # an estimate below this x fmu_tolerance is flagged (the studies' floor)


def run_companion(scene, fmu_dir, progress: bool | None = False, label: str | None = None):
    """One companion run, no files written: a CompanionRun (module level: a worker of
    cosim.companions calls it). `progress`, `label`: its bar (RunOptions)."""
    from .companions import CompanionRun
    from .estimate import recorder_series
    t0 = time.perf_counter()
    try:
        result = run_scene(scene, RunOptions(out=None, fmu_dir=fmu_dir, progress=progress,
                                             label=label))
    except InterruptedRun:  # Ctrl-C: the user's, not a companion that stopped on its own
        raise
    except CrankfmuError as err:  # RunError (it stopped) or a refused setting (too many steps)
        return CompanionRun(None, time.perf_counter() - t0, str(err))
    return CompanionRun(recorder_series(result.recorder), time.perf_counter() - t0,
                        result=result)


def submit_companions(scene, fmu_dir, companions, progress: bool | None = False) -> list:
    """Start the companion runs of `scene`'s estimate (its master at half the step, or at a
    tenth of a variable-step master's tolerance): [(knob value, Pending)]. `progress`: a bar
    for each companion that runs here (companions.jobs 1), after the run's own."""
    from .estimate import companion_knobs, companion_scene
    m = scene.master
    if traits(m.algorithm).monolithic:
        return []
    knob, _, values = companion_knobs(m.algorithm, m.step, m.tolerance)
    here = progress if companions.jobs == 1 else False
    return [(v, companions.submit(run_companion, companion_scene(scene, knob, v), fmu_dir, here,
                                  f"{scene.name}: error estimate, companion at {knob} {v:g}"))
            for v in values]


def estimate_run(scene, run_series: tuple, fmu_dir=None, pending: list | None = None):
    """The estimated error of the run of `scene` recorded in `run_series` (times, columns),
    from its companions (`pending` from submit_companions; run here, one after another,
    without it)."""
    from .companions import Companions
    from .estimate import Estimate, companion_knobs, order_rule, richardson, scene_metric
    from .metrics import MetricError
    m = scene.master
    if traits(m.algorithm).monolithic:
        return Estimate(reason=f"{m.algorithm} has no coupling error to estimate: the FMUs are "
                               f"integrated as one ODE, to its solver's tolerance (compare "
                               f"with `crankfmu reference`)")
    knob, ratio, _ = companion_knobs(m.algorithm, m.step, m.tolerance)
    try:
        metric = scene_metric(scene)
    except MetricError as err:
        return Estimate(ratio=ratio, knob=knob, reason=str(err))
    if pending is None:
        pending = submit_companions(scene, fmu_dir, Companions(1))
    series, seconds = [run_series], 0.0
    for value, companion in pending:
        run = companion.result()
        seconds += run.wall_seconds
        if run.series is None:
            return Estimate(ratio=ratio, knob=knob, companion_seconds=seconds,
                            reason=f"the companion run at {knob} {value:g} stopped: "
                                   f"{run.reason}")
        series.append(run.series)
    est = richardson(metric, series, ratio, knob,
                     *order_rule(m.algorithm, m.extrapolation, m.taylor))
    est.companion_seconds = seconds
    if est.ok and est.error < FLOOR_FACTOR * m.fmu_tolerance:  # say it: no number hides it
        est.reason = "; ".join(filter(None, [est.reason, (
            f"below {FLOOR_FACTOR:g} x fmu_tolerance: the FMUs' own solver error, which a "
            f"companion with the same fmu_tolerance does not see, may be larger")]))
    return est


def plot_roles(scene: Scene) -> dict | None:
    """The scene's [analysis] roles (crank angle, speed, torques) for the steady-state plot;
    None without a complete [analysis] table."""
    from ..system.analysis import analysis_roles
    try:
        return analysis_roles(scene) if "analysis" in scene.raw else None
    except SceneError:
        return None


def _reference_beside(out: Path, recorder: Recorder):
    """(names, rows) of `<stem>_reference.csv` beside the run's CSV (crankfmu reference writes
    it there by default) when it records the same variables; else None."""
    from .results import read_result_csv
    path = out.with_name(f"{out.stem}_reference.csv")
    if not path.is_file():
        return None
    try:
        names, rows = read_result_csv(path)
    except (OSError, ValueError):
        return None
    return (names, rows) if set(recorder.names) <= set(names) and len(rows) > 1 else None


def _fixed_steps(master, scene: Scene, progress, label: str | None = None):
    """Steps of [master].step on the grid t0 + k h (the last one shortened to end at
    stop_time); yields (step, t, t_new, record?) with rows every [record].interval. A grid step
    across an edge of a step-table input is taken in pieces that end at the edge
    (masters.inputs.split_at_edges): the input is written at a step's start and held, so the
    edge would otherwise act up to a step late (on the conventional press at 4 ms that cost
    more error than the coupling did)."""
    h, t0, stop = scene.master.step, scene.start_time, scene.stop_time
    n_steps = max(1, math.ceil((stop - t0) / h - 1e-9))
    every = max(1, round((scene.record_interval or h) / h))
    edges = step_edges(master.system)
    advance = master.step
    for step in _progress(range(1, n_steps + 1), progress, label or scene.name):
        t = t0 + (step - 1) * h
        if edges:
            start = t
            for piece in split_at_edges(t, min(h, stop - t), edges):
                advance(start, piece)
                start += piece
        else:  # no step table: the grid step whole (what split_at_edges gives)
            advance(t, min(h, stop - t))
        yield step, t, min(t0 + step * h, stop), step % every == 0 or step == n_steps


def _variable_steps(master, scene: Scene, progress, label: str | None = None):
    """Steps the master chooses (`next_step`); a row at every accepted point at least
    [record].interval after the last row (every accepted point without an interval), and at
    stop_time. A step that would leave less than min_step before stop_time is stretched to it."""
    t, stop = scene.start_time, scene.stop_time
    min_step = scene.master.min_step  # a variable-step master's declared option
    interval = scene.record_interval or 0.0
    last_row, step = t, 0
    bar = _progress(None, progress, label or scene.name, total=stop - t)
    while t < stop:
        h = master.next_step
        if t + h > stop - min_step:
            h = stop - t
        taken = master.step(t, h)
        t_new = stop if taken == h and t + h >= stop - min_step else t + taken
        step += 1
        if bar is not None:
            bar.update(t_new - t)
        record = t_new == stop or t_new - last_row >= interval * (1 - 1e-9)
        if record:
            last_row = t_new
        yield step, t, t_new, record
        t = t_new
    if bar is not None:
        bar.close()


def _fmi_failure(err, fmus, log: LogCollector, t: float) -> str:
    reasons = [f"{name}: {msg}" for name in fmus for msg in log.errors_of(name)]
    return f"FMU call failed near t = {t:.6g} s: {err}" + \
        (f"; the FMU said: {' | '.join(reasons)}" if reasons else "")


def _on_terminal() -> bool:
    try:
        return sys.stderr.isatty()
    except (AttributeError, ValueError):  # replaced or closed: as tqdm takes it, no terminal
        return False


def _progress(steps, enabled, label, total=None):
    """A tqdm bar over `steps`, or (steps None) a bar over `total` seconds of simulated time;
    on a terminal (or `enabled` True) only, and from half a second into the run on (tqdm's
    refresh interval): a shorter run neither draws a bar nor imports tqdm."""
    if enabled is False or (enabled is None and not _on_terminal()):
        return steps  # tqdm draws nothing there (disable=None): not even imported
    if steps is None:
        return _LateBar(dict(total=total, desc=label, unit="s",
                             bar_format="{l_bar}{bar}| {n:.3g}/{total:.3g} s"))
    return _LateBar(dict(total=len(steps), desc=label, unit="step")).over(steps)


def progress_bar(iterable=None, **options):
    """A tqdm bar (tqdm's keywords) without tqdm's monitor thread: that thread would keep this
    process multi-threaded for good, and a study's pool started later could then not fork its
    workers (crankfmu.cosim.workers.start_method). Every bar crankfmu draws is one."""
    return _bar_class()(iterable, **options)


@functools.lru_cache(maxsize=1)
def _bar_class():
    from tqdm import tqdm

    class Bar(tqdm):
        monitor_interval = 0  # no monitor thread (its miniters tuning matters to no bar here)
    return Bar


class _LateBar:
    """A tqdm bar made at the first update half a second after this object: update(n), close()."""

    def __init__(self, options: dict):
        self._options, self._start, self._done, self._bar = options, time.perf_counter(), 0, None

    def update(self, n) -> None:
        self._done += n
        if self._bar is not None:
            self._bar.update(n)
        elif time.perf_counter() - self._start >= 0.5:
            self._bar = progress_bar(initial=self._done, disable=False, mininterval=0.5,
                                     leave=False, **self._options)

    def close(self) -> None:
        if self._bar is not None:
            self._bar.close()

    def over(self, steps):
        try:
            for step in steps:
                yield step
                self.update(1)
        finally:
            self.close()
