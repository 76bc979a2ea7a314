"""crankfmu's Python API, in the manner of fmpy's `simulate_fmu`:

    import crankfmu
    result = crankfmu.simulate("scenarios/servo_press.toml", stop_time=0.4,
                               parameters={"press.F_max": 65e3})
    result.values["press.w_crank"]      # numpy structured array: "time", then "comp.var"
    result.units["press.w_crank"]       # "rad/s" (FMI's spelling, as in the modelDescription)
    fig = result.plot()                 # a matplotlib Figure; the backend is left alone
    df = result.to_pandas()             # with pandas installed

Nothing is written unless `out` is given: the output folder (a str or a path), where each
function writes its files under names it chooses, as the command line's --out DIR does
(simulate: <scene name>.csv, .json, .png; reference: <scene name>_reference.csv, ...), checked
before anything runs. `scene` is a path to a scene file (.toml, .ssp; a str or a path) or a
loaded scene (`load_scene`); a loaded scene is copied, never changed. `parameters` and
`inputs` map "comp.name" to values: a parameter, a constant or a table [[t, v], ...] for an
unconnected input; "master.step" and the other [master] keys go in `parameters` too (as with
--set). An argument of the wrong type raises crankfmu.errors.OptionError naming it and what it
takes. A run whose own figures say it is not to be trusted has `Result.status` "unreliable"
(crankfmu.cosim.trust) and warns (UnreliableResultWarning) with the cause and the remedy.

Each function returns an object with its values, their units and `to_pandas()`: simulate and
reference a Result, sweep a SweepTable, accuracy an AccuracyResult, compare a CompareResult.

`jobs` means what the command line's --jobs N means (docs/cli.md): 1 (the default) runs
everything in the calling process, so a plain script needs no `if __name__ == "__main__":`;
N > 1 starts worker processes, which import the calling script again: a script must then make
its calls under `if __name__ == "__main__":` (without one, crankfmu raises
crankfmu.cosim.companions.WorkerStartError saying so); 0 is one per core.
"""
from __future__ import annotations

import os
import tempfile
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .errors import OptionError

__all__ = ["Result", "accuracy", "compare", "load_scene", "reference", "simulate", "sweep"]
API_NAMES = {"vary": "vary", "samples": "samples", "stop_time": "stop_time",
             "from_time": "from_time", "out": "out"}  # how errors name the arguments


@dataclass
class Result:
    """A run's (or a reference's) recorded values with units and what the sidecar holds."""

    values: np.ndarray                 # structured: "time", then one field per "comp.var"
    units: dict[str, str]              # field -> unit in FMI's spelling ("1": dimensionless)
    statistics: dict = field(default_factory=dict)      # per component: doStep calls, ...
    coupling_error: dict = field(default_factory=dict)  # the energy-mismatch error estimate
    metadata: dict = field(default_factory=dict)        # the JSON sidecar's content
    files: dict = field(default_factory=dict)           # what was written: csv, sidecar, png
    title: str = ""
    analysis: dict = field(default_factory=dict)        # the scene's [analysis] roles, if any

    @property
    def estimated_error(self) -> float | None:
        """The run's estimated global error in the scene's accuracy metric
        (crankfmu.cosim.estimate; metadata["error_estimate"] says how and, if None, why not)."""
        return (self.metadata.get("error_estimate") or {}).get("estimated_error")

    @property
    def status(self) -> str:
        """"completed", or "unreliable" when the run's own estimate or port energy says it is
        not to be trusted (the causes in `unreliable`; crankfmu.cosim.trust)."""
        return self.metadata.get("outcome", "completed")

    @property
    def unreliable(self) -> list[str]:
        """Why the run is not to be trusted (empty for a run that is)."""
        return list(self.metadata.get("unreliable", []))

    @property
    def names(self) -> list[str]:
        """The recorded variables ("comp.var"), without "time"."""
        return list(self.values.dtype.names or ())[1:]

    def __getitem__(self, name: str) -> np.ndarray:
        return self.values[name]

    def plot(self, variables=None, *, steady: bool = False, reference: "Result | None" = None,
             cycles: int = 3):
        """A matplotlib Figure: one panel per recorded variable (or `variables`), each axis
        with its unit, a turning crank angle modulo 2 pi. `steady=True`: the periodic steady
        state instead, crank speed and drive torque over the last `cycles` revolutions (needs
        the scene's [analysis] roles recorded, and a run that turns the crank at least once
        after [analysis].from_time: ValueError saying why otherwise), with `reference`
        (crankfmu.reference's Result) drawn over it. Not registered with pyplot, so the backend
        stays as it is; in Jupyter the returned Figure shows inline."""
        from .cosim.results import figure, no_steady_state, steady_figure
        if steady:
            if not self.analysis or not all(self.analysis.get(r) in self.names for r in
                                            ("crank_angle", "crank_speed", "drive_torque")):
                raise ValueError("plot(steady=True) needs the scene's [analysis] crank_angle, "
                                 "crank_speed and drive_torque among the recorded variables")
            rows = self.values.view(np.float64).reshape(len(self.values), -1)
            why = no_steady_state(self.names, rows, self.analysis)
            if why is not None:
                raise ValueError(f"plot(steady=True): no steady state to show: {why}; plot() "
                                 "draws the recorded variables over time")
            ref = None
            if reference is not None:
                ref = (reference.names,
                       reference.values.view(np.float64).reshape(len(reference.values), -1))
            return steady_figure(self.names, [self.units[n] for n in self.names], rows,
                                 self.analysis, self.title, ref, cycles)
        names = list(variables) if variables is not None else self.names
        rows = np.column_stack([self.values["time"]] + [self.values[n] for n in names])
        return figure(names, [self.units[n] for n in names], rows, self.title)

    def to_pandas(self):
        """A pandas DataFrame indexed by time (needs pandas); units in `df.attrs["units"]`."""
        from .studies.table import data_frame
        return data_frame(self.values.tolist(), ["time", *self.names], self.units, index="time")


def _result(recorder, metadata: dict, files: dict, title: str, statistics=None,
            coupling_error=None, scene=None) -> Result:
    from .cosim.results import column_units, structured
    from .cosim.runner import plot_roles
    return Result(structured(recorder.names, recorder.rows), column_units(recorder),
                  statistics if statistics is not None else metadata.get("statistics", {}),
                  coupling_error if coupling_error is not None
                  else metadata.get("coupling_error", {}),
                  metadata, {k: v for k, v in files.items() if v is not None}, title,
                  (plot_roles(scene) or {}) if scene is not None else {})


def load_scene(scene):
    """A scene file (.toml or .ssp) loaded and checked (crankfmu.system.load.load_scene)."""
    from .system.load import load_scene as _load
    return _load(_path(scene, "scene", "a path to a scene file (.toml or .ssp)", required=True))


def _path(value, name: str, what: str, required: bool = False) -> Path | None:
    """`value` as a Path (None stays None unless `required`); OptionError naming `name` for
    another type."""
    if value is None and not required:
        return None
    if _is_path(value):
        return Path(value)
    raise OptionError(f"{name}: {what} (a str or a pathlib.Path), got {_show(value)}")


def _is_path(value) -> bool:
    return isinstance(value, (str, os.PathLike)) and not isinstance(value, bytes) and \
        bool(os.fspath(value))


def _show(value) -> str:
    if value is None:
        return "None"
    text = repr(value)
    return f"{type(value).__name__} {text if len(text) <= 60 else text[:57] + '...'}"


def _scene(scene, name: str = "scene"):
    """A Scene as given, or the path to its file; OptionError for anything else."""
    from .system.scene import Scene
    if isinstance(scene, Scene):
        return scene
    if _is_path(scene):
        return Path(scene)
    raise OptionError(f"{name}: a path to a scene file (.toml or .ssp; a str or a "
                      f"pathlib.Path) or a Scene from crankfmu.load_scene, got {_show(scene)}")


def _mapping(value, name: str, example: str):
    """`value` if None or a mapping with str keys; OptionError for anything else."""
    if value is None or (isinstance(value, Mapping) and all(isinstance(k, str) for k in value)):
        return value
    raise OptionError(f"{name}: a dict from \"component.name\" to its value (e.g. {example}), "
                      f"got {_show(value)}")


def _jobs(value, name: str = "jobs") -> int:
    """`jobs` checked: a whole number >= 0 (0: one per core), as processes to use."""
    from .cosim.companions import processes
    if isinstance(value, bool) or not isinstance(value, int) or value < 0:
        raise OptionError(f"{name}: a whole number of processes >= 0 (1: this process; "
                          f"0: one per core), got {_show(value)}")
    return processes(value)


def prepare(scene, *, stop_time=None, step=None, algorithm=None, parameters=None, inputs=None,
            **master_options):
    """A copy of `scene` (or the scene loaded from that path) with the settings applied and
    checked as a scene file's would be (crankfmu.system.load.prepare_scene). `master_options`:
    the masters' own options as keyword arguments (extrapolation=2, tolerance=1e-4, min_step=...,
    as each master declares them: crankfmu.masters.MASTERS[name].options)."""
    from .system.load import prepare_scene
    return prepare_scene(_scene(scene), stop_time=stop_time, step=step, algorithm=algorithm,
                         parameters=_mapping(parameters, "parameters", '{"press.F_max": 65e3}'),
                         inputs=_mapping(inputs, "inputs", '{"motor.u": [[0, 200], [1, 220]]}'),
                         **master_options)


def simulate(scene, *, stop_time=None, step=None, algorithm=None, parameters=None,
             inputs=None, out=None, progress=False, plot=False, fmu_dir=None, log=False,
             estimate=True, target=None, jobs=1, **master_options) -> Result:
    """Co-simulate the scene with its master (crankfmu.cosim.runner.run_scene) and return the
    recorded values. `out`: the output folder (<scene name>.csv, its JSON sidecar
    <scene name>.json and with `plot=True` <scene name>.png); nothing is written without it.
    `fmu_dir`: the built FMUs (default:
    fmus/ beside the scene's scenarios/ folder, else the package's build folder; stale or
    missing FMUs are built there, never into the working folder). `master_options`: the
    chosen master's own options (extrapolation=2, tolerance=1e-4, ...; see `prepare`).
    `estimate`: run the companions of the error estimate (Result.estimated_error; 1.2-1.9 x
    the run's cost). `target` (or the scene's [master].target): the global error wanted;
    master, extrapolation and step are chosen from the estimate (crankfmu.cosim.target);
    raises crankfmu.cosim.target.TargetNotMet saying why when no setting meets it. `jobs=2`:
    the companion runs execute in a worker process beside the run (crankfmu.cosim.companions:
    forked from this process on Linux while it runs one thread; else it imports the calling
    script again, which then needs `if __name__ == "__main__":`, crankfmu.cosim.workers).
    A run marked unreliable (Result.status) warns with UnreliableResultWarning."""
    from .cosim.results import check_run_set
    from .cosim.runner import RunOptions, run_scene
    scene = prepare(scene, stop_time=stop_time, step=step, algorithm=algorithm,
                    parameters=parameters, inputs=inputs, **master_options)
    fmu_dir = _path(fmu_dir, "fmu_dir", "the folder of built FMUs")
    jobs = _jobs(jobs)
    if target is not None:
        set_value(scene, "master.target", target, "target")
    folder = _path(out, "out", "the output folder")
    csv = check_run_set(folder / f"{scene.name}.csv", "out") if folder is not None else None
    if scene.master.target is not None:
        result = _simulate_target(scene, csv, plot, fmu_dir, jobs)
    else:
        run = run_scene(scene, RunOptions(out=csv, plot=plot, fmu_dir=fmu_dir,
                                          progress=progress, verbose_log=log,
                                          estimate=estimate, jobs=jobs))
        m = scene.master
        result = _result(run.recorder, run.metadata,
                         {"csv": run.csv, "sidecar": run.sidecar, "png": run.png},
                         f"{scene.name}: {m.algorithm}, step {m.step:g} s", run.statistics,
                         run.coupling_error, scene)
    _warn_if_unreliable(scene, result)
    return result


def _warn_if_unreliable(scene, result: Result) -> None:
    import warnings

    from .cosim.trust import UnreliableResultWarning, warning_line
    line = warning_line(scene.name, result.metadata)
    if line:
        warnings.warn(UnreliableResultWarning(line), stacklevel=3)


def set_value(scene, ref, value, key):
    from .system.scene import set_value as _set
    _set(scene, ref, value, key)


def _simulate_target(scene, csv, plot, fmu_dir, jobs) -> Result:
    from .cosim.target import search, write_chosen
    result, report = search(scene, scene.master.target, fmu_dir, jobs)
    write_chosen(scene, result, report, csv, plot)
    m = result.metadata["master"]
    return _result(result.recorder, result.metadata,
                   {"csv": result.csv, "sidecar": result.sidecar, "png": result.png},
                   f"{scene.name}: {m['algorithm']}, step {m['step']:g} s (target "
                   f"{report.target:g})", result.statistics, result.coupling_error, scene)


def reference(scene, *, stop_time=None, parameters=None, inputs=None, rtol=None, method=None,
              out=None, progress=False) -> Result:
    """The scene's monolithic reference (its physics models as one ODE, scipy), recorded on
    the run's grid. `out`: the output folder (<scene name>_reference.csv and its sidecar);
    nothing is written without it."""
    from .cosim.results import check_run_set
    from .monolithic import DEFAULT_RTOL, solve_reference, write_reference
    scene = prepare(scene, stop_time=stop_time, parameters=parameters, inputs=inputs)
    folder = _path(out, "out", "the output folder")
    csv = check_run_set(folder / f"{scene.name}_reference.csv", "out") if folder else None
    result = solve_reference(scene, rtol=DEFAULT_RTOL if rtol is None else rtol,
                             method=method, progress=progress)
    metadata = {"kind": "monolithic reference", "method": result.method, "rtol": result.rtol,
                "rhs_calls": result.rhs_calls, "wall_seconds": result.wall_seconds}
    if csv is not None:
        write_reference(scene, csv, result)
    return _result(result.recorder, metadata, {"csv": result.csv, "sidecar": result.sidecar},
                   f"{scene.name}: monolithic reference, {result.method} rtol {result.rtol:g}",
                   {}, {}, scene)


def accuracy(scene, *, out=None, stop_time=None, parameters=None, inputs=None, **options):
    """Error against the monolithic reference and wall time per master setting
    (crankfmu.studies.accuracy.run_accuracy): an AccuracyResult (its outcomes, the observed
    orders, `to_pandas()` with the columns' units). `options` are AccuracyOptions' fields:
    algorithms, extrapolations, steps, tolerances, fmu_tolerances, metric, variables, cycles,
    meet (an error to meet: the result's cheapest and fewest_steps), plot, reference_rtol,
    reference_csv (a reference from elsewhere, in the CSV layout of a run), report
    (report(outcome, kept) as each run finishes), resume, fmu_dir, progress, jobs (1, the
    default: in this process; more: worker processes, the module's docstring), scheduler,
    executor. `out`: the folder to write (accuracy.csv, accuracy.json, the runs, with `plot`
    the figures); without it they go to a temporary folder that is removed, and the result's
    paths are None."""
    import dataclasses

    from .studies.accuracy import AccuracyOptions, run_accuracy
    known = {f.name for f in dataclasses.fields(AccuracyOptions)} - {"out_dir", "out_option"}
    unknown = sorted(set(options) - known)
    if unknown:
        raise OptionError(f"accuracy: unknown argument {', '.join(unknown)}; arguments: out, "
                          f"stop_time, parameters, inputs, {', '.join(sorted(known))}")
    scene = prepare(scene, stop_time=stop_time, parameters=parameters, inputs=inputs)
    options.setdefault("progress", False)
    options["fmu_dir"] = _path(options.get("fmu_dir"), "fmu_dir", "the folder of built FMUs")
    if "jobs" in options:
        options["jobs"] = _jobs(options["jobs"])
    folder = _path(out, "out", "the output folder")
    if folder is not None:
        return run_accuracy(scene, AccuracyOptions(out_dir=folder, out_option="out", **options))
    with _temporary_folder("crankfmu-accuracy-") as tmp:
        result = run_accuracy(scene, AccuracyOptions(out_dir=Path(tmp), out_option="out",
                                                     **options))
    result.reference_csv = result.csv = result.sidecar = None
    result.figures = []
    return result


def compare(scene_a, scene_b, *, stop_time=None, out=None, fmu_dir=None, jobs=1,
            scheduler=None, progress=False, plot=False):
    """Run two scenes (e.g. a component swap) and compare cycle time, speeds, delta, peak
    torques and energy per stroke (crankfmu.studies.compare): a CompareResult (`table`: rows
    (metric, unit, A, B, B - A, relative), `text`: the table as printed, `a` and `b`: the role
    series, `to_pandas()`); with `out`, the folder written (compare.csv, both runs' CSVs, with
    `plot` compare.png) and `csv`, `png` in it. `jobs`: 1 runs both here, one after the other;
    2 side by side in worker processes (the module's docstring)."""
    import contextlib

    from .studies.compare import compare_scenes
    from .cosim.runner import RunOptions
    from .studies.executor import make_executor
    scenes = [prepare(_scene(s, name), stop_time=stop_time)
              for s, name in ((scene_a, "scene_a"), (scene_b, "scene_b"))]
    options = RunOptions(fmu_dir=_path(fmu_dir, "fmu_dir", "the folder of built FMUs"),
                         progress=progress)
    jobs = _jobs(jobs)
    folder = _path(out, "out", "the output folder")
    serial = jobs == 1 and scheduler is None  # one after the other in this process
    with contextlib.nullcontext() if serial else make_executor(jobs, scheduler) as executor:
        if folder is not None:
            return compare_scenes(scenes[0], scenes[1], folder, options, executor, "out",
                                  "stop_time", plot)
        with _temporary_folder("crankfmu-compare-") as tmp:
            result = compare_scenes(scenes[0], scenes[1], Path(tmp), options, executor, "out",
                                    "stop_time", plot)
    result.csv = result.png = None
    return result


def _temporary_folder(prefix: str) -> tempfile.TemporaryDirectory:
    """Where a study without `out` writes, removed after it. Not made in a worker process that
    is importing the calling script again (a script without a main guard: WorkerStartError,
    cosim.companions): stopped there before its exit handlers are set, the worker left it."""
    from .cosim.companions import refuse_in_importing_worker
    refuse_in_importing_worker()
    return tempfile.TemporaryDirectory(prefix=prefix)


def sweep(scene, vary, out=None, **options):
    """Parameter sweep of a scene: a SweepTable (one row per run, the units of its columns,
    `to_pandas()`; crankfmu.studies.sweep.sweep, whose keyword arguments `options` are: jobs
    (1, the default: in this process; more: worker processes, the module's docstring),
    scheduler, stop_time, from_time, samples, seed, overrides, fmu_dir, progress, plot).
    `vary`: one "COMP.PARAM=V1,V2,..." or "COMP.PARAM=START:STOP:N" string, or a list of them
    (or of crankfmu.studies.sweep.Vary). `out`: the output folder (sweep.csv, sweep.json, with
    `plot` sweep.png); without it the sweep runs in a temporary folder that is removed (the
    table's paths are None)."""
    from .studies.sweep import Vary, sweep as _sweep
    scene = _scene(scene)
    vary = [vary] if isinstance(vary, (str, Vary)) else vary
    if not isinstance(vary, (list, tuple)) or not all(isinstance(v, (str, Vary)) for v in vary):
        raise OptionError(f"vary: a \"COMP.PARAM=V1,V2,...\" string or a list of them, got "
                          f"{_show(vary)}")
    options["fmu_dir"] = _path(options.get("fmu_dir"), "fmu_dir", "the folder of built FMUs")
    if "jobs" in options:
        options["jobs"] = _jobs(options["jobs"])
    folder = _path(out, "out", "the output folder")
    if folder is not None:
        return _sweep(scene, vary, folder, names=API_NAMES, **options)
    with _temporary_folder("crankfmu-sweep-") as tmp:
        table = _sweep(scene, vary, Path(tmp), names=API_NAMES, **options)
    table.csv = table.png = table.sidecar = None
    return table
