"""Parameter sweeps: many runs of one scene, one row each.

    sweep(scene, ["press.J1=1,2,4", "motor.J_flywheel=0:0.4:5"], out="results/s")

Grid: the full factorial of the values given per parameter (`COMP.PARAM=V1,V2,...`, or
`COMP.PARAM=START:STOP:N` for N linearly spaced values, ends included), in the order given (the
last parameter varies fastest). With `samples=N`, a Latin hypercube of N points over each
parameter's range (START:STOP, or the min and max of a value list), drawn with `seed` (default
0: the same points on every call, so a sweep resumes; `latin_hypercube`).

Each run executes through one executor (this process, a local process pool, or a Dask cluster:
crankfmu.studies.executor); where it runs, its figures are computed from the scene's
[analysis] table with crankfmu.studies.compare's metric code: strokes, cycle time, mean crank speed,
delta, energy per stroke, peak drive and load torque, and the [analysis].events variables at the
run's end (hybrid scenes). DIR/sweep.csv holds one row per run: `run`, one column per varied
parameter (named COMP.PARAM), the figures, `status` (completed; "figures missing" when the run
completed without all its figures, e.g. no whole revolution after from_time; "unreliable" when
its port energy says it lost the solution, crankfmu.cosim.trust; failed, refused, error, lost),
`reason` (why, for every status but completed) and `wall_time`; rows are appended as runs
finish and the file is rewritten in grid order at the end. At most MAX_RUNS points, counted
before the grid is made; values must be finite; the analysis window must start before the stop
time; the output folder and its names are checked, and the folder locked, before any run
(crankfmu.outputs). DIR/sweep.json names the study (scene, settings, grid, FMU digests) and
the unit of each column of sweep.csv ("units": a parameter's and an event variable's as its
FMU declares it, a figure's, "s" for wall_time, null for text): a second call with the same
study keeps the rows already there and runs only the missing ones (and the "lost" ones: a
worker died); another study in the same DIR is refused. With `plot`, DIR/sweep.png plots each
figure against each varied parameter.
"""
from __future__ import annotations

import copy
import csv
import dataclasses
import hashlib
import itertools
import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..cosim.results import check_record_size, normalize_unit, save_figure
from ..errors import MAX_STUDY_RUNS, CrankfmuError
from ..outputs import atomic_write, check_files, folder_lock, open_regular
from ..system.scene import Scene, SceneError, _number, apply_overrides, check_run_size
from .compare import UNITS as FIGURE_UNITS
from .compare import check_window
from .executor import make_executor
from .table import Table

FIGURES = ("strokes", "cycle_time", "mean_crank_speed", "delta", "energy_per_stroke",
           "peak_drive_torque", "peak_load_torque")
TAIL = ("status", "reason", "wall_time")
TAIL_UNITS = {"run": None, "status": None, "reason": None, "wall_time": "s"}
RERUN = ("lost",)  # statuses a resumed sweep runs again
MISSING = "figures missing"  # status of a run that completed without all its figures
MAX_RUNS = MAX_STUDY_RUNS  # points of one sweep, counted before the grid is made (`--vary
# F=0:1:100000000` once took 17.5 GB before any run started)
CLI_NAMES = {"vary": "--vary", "samples": "--samples", "stop_time": "--stop-time",
             "from_time": "--from-time", "out": "--out"}  # how errors name the options


class SweepError(CrankfmuError, ValueError):
    pass


@dataclass(frozen=True)
class Vary:
    """One varied parameter: explicit `values`, or a range `lo`..`hi` with `n` points."""

    ref: str                       # "comp.param"
    values: tuple | None = None
    lo: float | None = None
    hi: float | None = None
    n: int | None = None

    @property
    def grid(self) -> list[float]:
        """The values (a range's N points: count_points has checked there is an N)."""
        if self.values is not None:
            return list(self.values)
        assert self.lo is not None and self.hi is not None and self.n is not None
        return [float(v) for v in np.linspace(self.lo, self.hi, self.n)]

    @property
    def size(self) -> int | None:
        """Points on the grid (None: a range without N, for a Latin hypercube only)."""
        return len(self.values) if self.values is not None else self.n

    @property
    def bounds(self) -> tuple[float, float]:
        if self.values is not None:
            return min(self.values), max(self.values)
        assert self.lo is not None and self.hi is not None  # a range (parse_vary)
        return self.lo, self.hi

    def check(self, name: str = "--vary") -> "Vary":
        """Finite numbers, N from 1 to MAX_RUNS; raises SweepError naming `name`."""
        what = f"{name} {self.ref}"
        numbers = self.values if self.values is not None else (self.lo, self.hi)
        if not isinstance(self.ref, str) or "." not in self.ref:
            raise SweepError(f"{name} {self.ref!r}: the parameter is named COMP.PARAM")
        if not numbers or not all(isinstance(v, (int, float)) and not isinstance(v, bool)
                                  and math.isfinite(v) for v in numbers):
            raise SweepError(f"{what}: every value must be a finite number, got "
                             f"{', '.join(map(str, numbers)) or 'none'}")
        if self.n is not None and not (isinstance(self.n, int) and 1 <= self.n <= MAX_RUNS):
            raise SweepError(f"{what}: N = {self.n} points; allowed 1 to {MAX_RUNS} (the "
                             "limit of a sweep's runs)")
        return self


def parse_vary(text: str, name: str = "--vary") -> Vary:
    """COMP.PARAM=V1,V2,... or COMP.PARAM=START:STOP[:N], checked (Vary.check)."""
    if not isinstance(text, str):
        raise SweepError(f"{name}: each entry is a string COMP.PARAM=V1,V2,... or "
                         f"COMP.PARAM=START:STOP:N (or a Vary), got {type(text).__name__}")
    if "=" not in text or "." not in text.split("=", 1)[0]:
        raise SweepError(f"{name} {text}: must look like COMP.PARAM=V1,V2,... or "
                         "COMP.PARAM=START:STOP:N")
    ref, spec = (s.strip() for s in text.split("=", 1))
    try:
        if ":" in spec:
            parts = spec.split(":")
            if len(parts) not in (2, 3):
                raise ValueError
            vary = Vary(ref, lo=float(parts[0]), hi=float(parts[1]),
                        n=int(parts[2]) if len(parts) == 3 else None)
        else:
            vary = Vary(ref, values=tuple(float(v) for v in spec.split(",") if v.strip()))
    except ValueError:
        raise SweepError(f"{name} {text}: values must be numbers (V1,V2,... or "
                         "START:STOP:N)") from None
    if vary.values == ():
        raise SweepError(f"{name} {text}: no values")
    return vary.check(name)


def count_points(varies: list[Vary], samples: int | None = None, names=CLI_NAMES) -> int:
    """How many runs the sweep has, counted before any point is made; raises SweepError
    above MAX_RUNS."""
    if samples is not None:
        if isinstance(samples, bool) or not isinstance(samples, int) or \
                not 1 <= samples <= MAX_RUNS:
            raise SweepError(f"{names['samples']}: {samples!r} points; allowed 1 to "
                             f"{MAX_RUNS} (the limit of a sweep's runs)")
        return samples
    count = 1
    for v in varies:
        if v.size is None:
            raise SweepError(f"{names['vary']} {v.ref}={v.lo:g}:{v.hi:g}: give the number of "
                             f"points (START:STOP:N) or use {names['samples']}")
        count *= v.size
        if count > MAX_RUNS:
            sizes = " x ".join(str(w.size) for w in varies)
            raise SweepError(f"{names['vary']}: the grid has {sizes} points, more than the "
                             f"limit of {MAX_RUNS} runs of one sweep; use fewer points or "
                             f"{names['samples']} N (a Latin hypercube)")
    return count


def latin_hypercube(dimensions: int, samples: int, seed: int) -> np.ndarray:
    """`samples` points in [0, 1)^dimensions, one row each: in every dimension each of the
    `samples` equal strata holds one point, at a uniform random place in it, the strata in a
    random order. The very numbers of scipy.stats.qmc.LatinHypercube(d=dimensions,
    seed=seed).random(samples) (its plain design: scrambled, no optimization; numpy's
    default_rng(seed) drawn in the same order), without importing scipy.stats, which cost a
    sweep 0.4-0.5 s of CPU at start."""
    rng = np.random.default_rng(seed)
    within = rng.uniform(size=(samples, dimensions))
    strata = np.tile(np.arange(1, samples + 1), (dimensions, 1))
    for row in strata:
        rng.shuffle(row)
    return (strata.T - within) / samples


def expand(varies: list[Vary], samples: int | None = None, seed: int = 0,
           names=CLI_NAMES) -> list[dict]:
    """The sweep's points: dicts ref -> value, in run order (count_points checked first)."""
    refs = [v.ref for v in varies]
    if len(set(refs)) != len(refs):
        raise SweepError(f"{names['vary']}: a parameter is given twice: {refs}")
    count_points(varies, samples, names)
    if samples:
        lo = [v.bounds[0] for v in varies]
        hi = [v.bounds[1] for v in varies]
        unit = latin_hypercube(len(varies), samples, seed)
        points = [[float(lo[k] + u[k] * (hi[k] - lo[k])) for k in range(len(varies))]
                  for u in unit]
        return [dict(zip(refs, p)) for p in points]
    return [dict(zip(refs, p)) for p in itertools.product(*(v.grid for v in varies))]


# -- the figures, computed in the worker -------------------------------------------------------------
def sweep_figures(names, rows, status, roles) -> dict:
    """A run's figures from its recorded arrays (crankfmu.studies.compare's metrics):
    {"values": figure -> value, "missing": why some are not there ("" if none is missing)}."""
    from .compare import metrics, series_from_arrays
    if status != "completed" or rows is None:
        return {"values": {}, "missing": ""}
    if len(rows) < 2:
        return {"values": {}, "missing": f"the run recorded {len(rows)} point(s), fewer than 2"}
    m = metrics(series_from_arrays("run", names, rows, roles))
    values = {k: float(m[k]) for k in FIGURES if k in m}
    for var in roles.get("events", []):
        values[var] = float(rows[-1, 1 + names.index(var)])
    reasons: dict[str, list[str]] = {}
    for figure, why in m["missing"].items():
        reasons.setdefault(why, []).append(figure)
    return {"values": values,
            "missing": "; ".join(f"{', '.join(f)}: {why}" for why, f in reasons.items())}


def figure_names(roles: dict) -> list[str]:
    return [f for f in FIGURES if f != "peak_load_torque" or "load_torque" in roles] \
        + list(roles.get("events", []))


# -- the table ---------------------------------------------------------------------------------------
@dataclass
class SweepTable(Table):
    """The sweep's rows (dicts column -> value) in run order, the unit of each column, and where
    they were written (None: not written, e.g. the API without `out`); `to_pandas()`."""

    columns: list[str]
    rows: list[dict]
    parameters: list[str]
    figures: list[str]
    csv: Path | None
    png: Path | None = None
    executed: int = 0          # runs executed by this call (the others came from sweep.csv)
    units: dict = dataclasses.field(default_factory=dict)  # column -> unit (None: text)
    sidecar: Path | None = None                            # sweep.json


def _format(value) -> str:
    if isinstance(value, float):
        return repr(value)
    return str(value)


def _parse(column: str, text: str):
    if column in ("status", "reason"):
        return text
    if column == "run":
        return int(text)
    return float(text) if text != "" else math.nan


def read_table(path: Path) -> tuple[list[str], list[dict]]:
    with open(path, newline="") as f:
        reader = csv.reader(f)
        header = next(reader)
        rows = []
        for raw in reader:
            if len(raw) != len(header):  # a row cut off by an interruption
                continue
            rows.append({c: _parse(c, v) for c, v in zip(header, raw)})
    return header, rows


def _write_row(f, columns, row) -> None:
    csv.writer(f).writerow([_format(row.get(c, math.nan)) for c in columns])


def _study_key(scene, points: list[dict], fmus: dict) -> dict:
    return {
        "scene": str(scene.path), "name": scene.name,
        "start_time": scene.start_time, "stop_time": scene.stop_time,
        "components": {n: {"fmu": c.fmu, "parameters": c.parameters, "effects": c.effects}
                       for n, c in scene.components.items()},
        "fmu_sha256": fmus,
        "connections": [[c.source, c.target] for c in scene.connections],
        "inputs": {k: [s.times, s.values, s.interpolation] for k, s in scene.inputs.items()},
        "master": dataclasses.asdict(scene.master), "record": scene.record,
        "record_interval": scene.record_interval, "analysis": scene.raw.get("analysis"),
        "points": hashlib.sha256(json.dumps(points).encode()).hexdigest(), "runs": len(points),
    }


def _row_key(row: dict, parameters: list[str]) -> tuple:
    return tuple(float(row[p]) for p in parameters)


# -- the sweep -------------------------------------------------------------------------------------
def sweep(scene, vary, out, *, jobs: int | None = 1, scheduler: str | None = None,
          client=None, executor=None, stop_time: float | None = None,
          from_time: float | None = None, samples: int | None = None, seed: int = 0,
          overrides=(), fmu_dir=None, progress=None, plot: bool = False,
          names: dict = CLI_NAMES) -> SweepTable:
    """Run the sweep into folder `out` and return its table (see the module's docstring).

    scene      a Scene or a path to a scene file (it needs an [analysis] table)
    vary       list of "COMP.PARAM=..." strings or Vary objects
    jobs       1 (default): every run in this process; N > 1: N worker processes (a script
               needs `if __name__ == "__main__":`, cosim.companions.MAIN_GUARD); 0: one per
               core
    scheduler  "tcp://HOST:PORT" of a Dask scheduler (or `client`: a distributed.Client);
               `executor`: any crankfmu.studies.executor.Executor (not closed here)
    stop_time  end of every run [s]; from_time: start of the analysis window [s]
               ([analysis].from_time); overrides: "COMP.PARAM=V" fixed for every run
    names      how errors name the options (CLI_NAMES: the command line's flags)

    Everything is checked before any FMU is built or run: the grid's size (MAX_RUNS) and
    values, the analysis window against the stop time, the output folder and its file names
    (crankfmu.outputs). The folder is locked for the sweep: a second sweep into it is refused.
    """
    scene, roles = _study_scene(scene, stop_time, from_time, overrides, names)
    varies = [v.check(names["vary"]) if isinstance(v, Vary) else parse_vary(v, names["vary"])
              for v in vary]
    if not varies:
        raise SweepError(f"give at least one {names['vary']} COMP.PARAM=...")
    parameters = [v.ref for v in varies]
    for ref in parameters:
        comp = ref.split(".", 1)[0]
        if comp not in scene.components:
            raise SceneError(scene.path, f"{names['vary']} {ref}", f"unknown component "
                             f"{comp!r}; components: {', '.join(scene.components)}")
    points = expand(varies, samples, seed, names)
    out = Path(out)
    check_files(out, ["sweep.csv", "sweep.json"] + (["sweep.png"] if plot else []),
                names["out"])
    with folder_lock(out, names["out"], wait=False):
        table = _run_grid(scene, roles, parameters, points, out, samples, seed,
                          executor or make_executor(jobs, scheduler, client), executor is None,
                          fmu_dir, progress, names)
        if plot:
            table.png = plot_sweep(out / "sweep.png", table, scene.name)
    return table


def _study_scene(scene, stop_time, from_time, overrides, names):
    """(a copy of the scene with overrides, stop time and from_time applied, its [analysis]
    roles); refuses an analysis window that starts at or after the stop time."""
    from ..errors import MAX_TIME
    from ..system.load import load_scene
    from .compare import analysis_roles, record_analysis_variables

    if not isinstance(scene, Scene):
        scene = load_scene(scene)
    scene = copy.deepcopy(scene)
    apply_overrides(scene, list(overrides))
    if stop_time is not None:
        scene.stop_time = _number(scene.path, names["stop_time"], stop_time, minimum=-MAX_TIME,
                                  maximum=MAX_TIME)
        if scene.stop_time <= scene.start_time:
            raise SceneError(scene.path, names["stop_time"], f"must exceed start_time = "
                                                             f"{scene.start_time}")
    roles = analysis_roles(scene)
    key = "[analysis].from_time"
    if from_time is not None:
        key = names["from_time"]
        roles["from_time"] = _number(scene.path, key, from_time, minimum=-MAX_TIME,
                                     maximum=MAX_TIME)
        scene.raw = {**scene.raw, "analysis": {**scene.raw.get("analysis", {}),
                                               "from_time": roles["from_time"]}}
    check_window(scene, roles["from_time"], key, names["stop_time"])
    record_analysis_variables(scene, roles)
    check_run_size(scene)
    check_record_size(scene)
    return scene, roles


def _run_grid(scene, roles, parameters, points, out: Path, samples, seed, executor, own: bool,
              fmu_dir, progress, names: dict = CLI_NAMES) -> SweepTable:
    """Run the points not kept from an earlier call into out/sweep.csv (the folder checked and
    locked by the caller)."""
    from .executor import RunTask, prepare_tasks

    tasks = []
    for k, point in enumerate(points):
        trial = copy.deepcopy(scene)
        for ref, value in point.items():
            comp, param = ref.split(".", 1)
            trial.components[comp].parameters[param] = value
        tasks.append(RunTask(k, trial, post=sweep_figures, post_args={"roles": roles},
                             keep_series=False))
    try:
        files = prepare_tasks(tasks[:1], fmu_dir)  # builds the FMUs once, here
        declared = _check_parameters(scene, parameters, tasks[0].fmus, files, names["vary"])
        fmus = {n: d for n, (d, _) in tasks[0].fmus.items()}
        figures = figure_names(roles)
        columns = ["run"] + parameters + figures + list(TAIL)
        units = {c: declared[c] if c in declared else TAIL_UNITS[c] if c in TAIL_UNITS
                 else FIGURE_UNITS.get(c) or _variable_unit(c, tasks[0].fmus, files)
                 for c in columns}
        key = _study_key(scene, points, fmus)
        kept = _resume(out, key, columns, parameters, names["out"])
        table_csv = out / "sweep.csv"
        todo = [t for t, p in zip(tasks, points)
                if tuple(p[r] for r in parameters) not in kept]
        rows_by_run = {}
        for k, p in enumerate(points):
            row = kept.get(tuple(p[r] for r in parameters))
            if row is not None:
                rows_by_run[k] = {**row, "run": k}
        text = json.dumps({"study": key, "varied": parameters, "samples": samples, "seed": seed,
                           "figures": figures, "units": units}, indent=2, default=str) + "\n"
        atomic_write(out / "sweep.json", lambda f: f.write(text))
        with open_regular(table_csv) as f:  # kept rows first, then rows as they finish
            csv.writer(f).writerow(columns)
            for k in sorted(rows_by_run):
                _write_row(f, columns, rows_by_run[k])
            f.flush()

            def on_done(output) -> None:
                rows_by_run[output.key] = row = _row(output, points[output.key], figures)
                _write_row(f, columns, row)
                f.flush()
            executor.run(todo, fmu_dir, on_done=on_done, progress=progress,
                         label=f"{scene.name} sweep")
        rows = [rows_by_run[k] for k in range(len(points))]

        def write(f) -> None:
            csv.writer(f).writerow(columns)
            for row in rows:
                _write_row(f, columns, row)
        atomic_write(table_csv, write)
    finally:
        if own:
            executor.close()
    return SweepTable(columns, rows, parameters, figures, table_csv, executed=len(todo),
                      units=units, sidecar=out / "sweep.json")


def _row(output, point: dict, figures: list[str]) -> dict:
    """A run's row: its point, figures, and a status that says why figures are missing
    (MISSING) or not to be trusted ("unreliable": crankfmu.cosim.trust)."""
    found = output.figures.get("values", {})
    row = {"run": output.key, **point, "wall_time": float(output.wall_seconds)}
    for name in figures:
        row[name] = float(found.get(name, math.nan))
    status = output.status
    reason = " | ".join(x.strip() for x in output.reason.splitlines() if x.strip())
    absent = [name for name in figures if not math.isfinite(row[name])]
    if status == "completed" and absent:
        status = MISSING
        reason = output.figures.get("missing") or f"{', '.join(absent)}: not computed"
    elif status == "completed" and output.sidecar.get("outcome") == "unreliable":
        status, reason = "unreliable", "; ".join(output.sidecar.get("unreliable", []))
    return {**row, "status": status, "reason": reason}


def _check_parameters(scene, parameters, fmus: dict, files: dict, option: str = "--vary"
                      ) -> dict[str, str]:
    """Fail before running anything when a varied parameter does not exist; returns each
    parameter's unit as its FMU declares it."""
    units = {}
    for ref in parameters:
        comp, param = ref.split(".", 1)
        declared = {v.name: v for v in _model_variables(files[fmus[comp][0]])
                    if v.causality == "parameter"}
        if param not in declared:
            raise SceneError(scene.path, f"{option} {ref}", f"{comp} has no parameter "
                             f"{param!r}; parameters: {', '.join(declared)}")
        units[ref] = normalize_unit(_unit(declared[param]))
    return units


def _model_variables(path: Path) -> list:
    from fmpy import read_model_description
    return read_model_description(str(path)).modelVariables


def _unit(variable) -> str | None:
    """A model variable's unit as fmpy reads it (its own, else its declared type's)."""
    declared = getattr(variable, "declaredType", None)
    return variable.unit or getattr(declared, "unit", None)


def _variable_unit(ref: str, fmus: dict, files: dict) -> str | None:
    """The unit of a recorded "comp.var" (an [analysis].events column) as its FMU declares it;
    None when it is not found there."""
    comp, name = ref.split(".", 1)
    if comp not in fmus:
        return None
    found = [v for v in _model_variables(files[fmus[comp][0]]) if v.name == name]
    return normalize_unit(_unit(found[0])) if found else None


def _resume(out: Path, key: dict, columns: list[str], parameters: list[str],
            option: str = "--out") -> dict:
    """Rows of an earlier call of the same study: point -> row (rows to run again dropped)."""
    table_csv, meta = out / "sweep.csv", out / "sweep.json"
    if not table_csv.is_file():
        return {}
    if not meta.is_file():
        raise SweepError(f"{table_csv} exists without sweep.json: not a sweep's folder; give "
                         f"another {option}")
    try:
        old = json.loads(meta.read_text()).get("study")
        header, rows = read_table(table_csv)
    except (ValueError, KeyError, AttributeError, StopIteration, UnicodeDecodeError):
        raise SweepError(f"{out} holds a sweep.json or sweep.csv this version cannot read; "
                         f"give another {option} or delete them") from None
    if json.loads(json.dumps(key, default=str)) != old:
        raise SweepError(f"{out} holds another study (scene, settings, grid or FMUs differ); "
                         f"give another {option} or delete it")
    if header != columns:
        raise SweepError(f"{table_csv}: columns differ from this study's; give another "
                         f"{option}")
    return {_row_key(r, parameters): r for r in rows if r["status"] not in RERUN}


def plot_sweep(path: Path, table: SweepTable, title: str) -> Path:
    """Each figure (rows of panels) against each varied parameter (columns); unreliable runs
    as hollow markers, runs without figures as a red x on the lower edge of their panels."""
    from .compare import UNITS
    from ..cosim.results import PALETTE, axis_label, new_figure

    figs, params = table.figures, table.parameters
    fig = new_figure(figsize=(3.6 * len(params) + 1, 2.0 * len(figs) + 0.8))
    axes = fig.subplots(len(figs), len(params), squeeze=False, sharex="col")
    status = np.array([r["status"] for r in table.rows])
    ok, doubtful = status == "completed", status == "unreliable"
    failed = ~(ok | doubtful)
    for j, p in enumerate(params):
        x = table.column(p)
        for i, name in enumerate(figs):
            ax = axes[i, j]
            y = table.column(name)
            order = np.argsort(x[ok], kind="stable")
            ax.plot(x[ok][order], y[ok][order], "o-" if len(params) == 1 else "o",
                    ms=3.5, lw=0.8, color=PALETTE[0])
            if doubtful.any():
                ax.plot(x[doubtful], y[doubtful], "o", mfc="none", ms=5, color=PALETTE[1],
                        label="unreliable")
            if failed.any():
                good = y[~failed][np.isfinite(y[~failed])]
                ax.plot(x[failed], np.full(failed.sum(), good.min() if good.size else 0.0),
                        "x", color=PALETTE[3], ms=6, label="no figures")
            if j == 0:
                ax.set_ylabel(axis_label(name, UNITS[name]) if name in UNITS else name,
                              fontsize=8)
            ax.grid(alpha=0.3)
            ax.tick_params(labelsize=7)
        axes[-1, j].set_xlabel(p)
    fig.suptitle(f"{title}: {len(table.rows)} runs, {int(ok.sum())} completed"
                 + (f", {int(doubtful.sum())} unreliable" if doubtful.any() else ""),
                 fontsize=10)
    fig.tight_layout(rect=(0, 0, 1, 0.98))
    return save_figure(fig, path, dpi=100)
