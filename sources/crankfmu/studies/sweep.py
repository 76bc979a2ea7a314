"""Parameter sweeps: many runs of one scene, one row each.

    sweep(scene, ["press.J1=1,2,4", "motor.J_flywheel=0:0.4:5"], out="results/s")

Grid: the full factorial of the values given per parameter (`COMP.PARAM=V1,V2,...`, or
`COMP.PARAM=START:STOP:N` for N linearly spaced values, ends included), in the order given (the
last parameter varies fastest). With `samples=N`, a Latin hypercube of N points over each
parameter's range (START:STOP, or the min and max of a value list), scipy.stats.qmc with `seed`
(default 0: the same points on every call, so a sweep resumes).

Each run executes through one executor (local process pool, or a Dask cluster:
crankfmu.studies.executor); in the worker, its figures are computed from the scene's
[analysis] table with crankfmu.studies.compare's metric code: strokes, cycle time, mean crank speed,
delta, energy per stroke, peak drive and load torque, and the [analysis].events variables at the
run's end (hybrid scenes). DIR/sweep.csv holds one row per run: `run`, one column per varied
parameter (named COMP.PARAM), the figures, `status` (completed, failed, refused, error, lost),
`reason` and `wall_seconds`; rows are appended as runs finish and the file is rewritten in grid
order at the end. DIR/sweep.json names the study (scene, settings, grid, FMU digests): a
second call with the same study keeps the rows already there and runs only the missing ones
(and the "lost" ones: a worker died); another study in the same DIR is refused.
DIR/sweep.png plots each figure against each varied parameter.
"""
from __future__ import annotations

from ..errors import CrankfmuError

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

FIGURES = ("strokes", "cycle_time", "mean_crank_speed", "delta", "energy_per_stroke",
           "peak_drive_torque", "peak_load_torque")
TAIL = ("status", "reason", "wall_seconds")
RERUN = ("lost",)  # statuses a resumed sweep runs again


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
        if self.values is not None:
            return list(self.values)
        if self.n is None:
            raise SweepError(f"--vary {self.ref}={self.lo:g}:{self.hi:g}: give the number of "
                             "points (START:STOP:N) or use --samples")
        return [float(v) for v in np.linspace(self.lo, self.hi, self.n)]

    @property
    def bounds(self) -> tuple[float, float]:
        if self.values is not None:
            return min(self.values), max(self.values)
        return self.lo, self.hi


def parse_vary(text: str) -> Vary:
    """COMP.PARAM=V1,V2,... or COMP.PARAM=START:STOP[:N]."""
    if "=" not in text or "." not in text.split("=", 1)[0]:
        raise SweepError(f"--vary {text}: must look like COMP.PARAM=V1,V2,... or "
                         "COMP.PARAM=START:STOP:N")
    ref, spec = (s.strip() for s in text.split("=", 1))
    try:
        if ":" in spec:
            parts = spec.split(":")
            if len(parts) not in (2, 3):
                raise ValueError
            lo, hi = float(parts[0]), float(parts[1])
            n = int(parts[2]) if len(parts) == 3 else None
            if n is not None and n < 1:
                raise SweepError(f"--vary {text}: N must be >= 1")
            return Vary(ref, lo=lo, hi=hi, n=n)
        values = tuple(float(v) for v in spec.split(",") if v.strip())
    except ValueError:
        raise SweepError(f"--vary {text}: values must be numbers (V1,V2,... or "
                         "START:STOP:N)") from None
    if not values:
        raise SweepError(f"--vary {text}: no values")
    return Vary(ref, values=values)


def expand(varies: list[Vary], samples: int | None = None, seed: int = 0) -> list[dict]:
    """The sweep's points: dicts ref -> value, in run order."""
    refs = [v.ref for v in varies]
    if len(set(refs)) != len(refs):
        raise SweepError(f"--vary: a parameter is given twice: {refs}")
    if samples:
        from scipy.stats import qmc
        lo = [v.bounds[0] for v in varies]
        hi = [v.bounds[1] for v in varies]
        unit = qmc.LatinHypercube(d=len(varies), seed=seed).random(samples)
        points = [[float(lo[k] + u[k] * (hi[k] - lo[k])) for k in range(len(varies))]
                  for u in unit]
        return [dict(zip(refs, p)) for p in points]
    return [dict(zip(refs, p)) for p in itertools.product(*(v.grid for v in varies))]


# -- the figures, computed in the worker -------------------------------------------------------------
def sweep_figures(names, rows, status, roles) -> dict:
    """A run's figures from its recorded arrays (crankfmu.studies.compare's metrics)."""
    from .compare import metrics, series_from_arrays
    if status != "completed" or rows is None or len(rows) < 2:
        return {}
    m = metrics(series_from_arrays("run", names, rows, roles))
    out = {k: float(m[k]) for k in FIGURES if k in m}
    for var in roles.get("events", []):
        out[var] = float(rows[-1, 1 + names.index(var)])
    return out


def figure_names(roles: dict) -> list[str]:
    return [f for f in FIGURES if f != "peak_load_torque" or "load_torque" in roles] \
        + list(roles.get("events", []))


# -- the table ---------------------------------------------------------------------------------------
@dataclass
class SweepTable:
    """The sweep's rows (dicts column -> value) in run order, and where they were written."""

    columns: list[str]
    rows: list[dict]
    parameters: list[str]
    figures: list[str]
    csv: Path
    png: Path | None = None
    executed: int = 0          # runs executed by this call (the others came from sweep.csv)

    def column(self, name: str) -> np.ndarray:
        return np.array([r[name] for r in self.rows], dtype=float)

    def __len__(self) -> int:
        return len(self.rows)


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
def sweep(scene, vary, out, *, jobs: int | None = None, scheduler: str | None = None,
          client=None, executor=None, stop_time: float | None = None,
          from_time: float | None = None, samples: int | None = None, seed: int = 0,
          overrides=(), fmu_dir=None, progress=None, plot: bool = True) -> SweepTable:
    """Run the sweep into folder `out` and return its table (see the module's docstring).

    scene      a Scene or a path to a scene file (it needs an [analysis] table)
    vary       list of "COMP.PARAM=..." strings or Vary objects
    jobs       local worker processes (default: the number of cores; 1 = one worker)
    scheduler  "tcp://HOST:PORT" of a Dask scheduler (or `client`: a distributed.Client);
               `executor`: any crankfmu.studies.executor.Executor (not closed here)
    stop_time  end of every run [s]; from_time: start of the analysis window [s]
               ([analysis].from_time); overrides: "COMP.PARAM=V" fixed for every run
    """
    from .compare import analysis_roles, record_analysis_variables
    from ..system.load import load_scene
    from ..system.scene import Scene, SceneError, apply_overrides
    from .executor import RunTask, file_digest, make_executor

    if not isinstance(scene, Scene):
        scene = load_scene(scene)
    scene = copy.deepcopy(scene)
    apply_overrides(scene, list(overrides))
    if stop_time is not None:
        if stop_time <= scene.start_time:
            raise SceneError(scene.path, "--stop-time", f"must exceed start_time = {scene.start_time}")
        scene.stop_time = float(stop_time)
    varies = [v if isinstance(v, Vary) else parse_vary(v) for v in vary]
    if not varies:
        raise SweepError("give at least one --vary COMP.PARAM=...")
    if samples is not None and samples < 1:
        raise SweepError(f"--samples must be >= 1, got {samples}")
    roles = analysis_roles(scene)
    if from_time is not None:
        roles["from_time"] = float(from_time)
        scene.raw = {**scene.raw, "analysis": {**scene.raw.get("analysis", {}),
                                               "from_time": float(from_time)}}
    record_analysis_variables(scene, roles)
    parameters = [v.ref for v in varies]
    for ref in parameters:
        comp = ref.split(".", 1)[0]
        if comp not in scene.components:
            raise SceneError(scene.path, f"--vary {ref}", f"unknown component {comp!r}; "
                             f"components: {', '.join(scene.components)}")
    points = expand(varies, samples, seed)

    tasks = []
    for k, point in enumerate(points):
        trial = copy.deepcopy(scene)
        for ref, value in point.items():
            comp, param = ref.split(".", 1)
            trial.components[comp].parameters[param] = value
        tasks.append(RunTask(k, trial, post=sweep_figures, post_args={"roles": roles},
                             keep_series=False))

    own = executor is None
    executor = executor or make_executor(jobs, scheduler, client)
    try:
        from .executor import prepare_tasks
        files = prepare_tasks(tasks[:1], fmu_dir)  # builds the FMUs once, here
        _check_parameters(scene, parameters, tasks[0].fmus, files)
        fmus = {n: d for n, (d, _) in tasks[0].fmus.items()}
        out = Path(out)
        out.mkdir(parents=True, exist_ok=True)
        figures = figure_names(roles)
        columns = ["run"] + parameters + figures + list(TAIL)
        key = _study_key(scene, points, fmus)
        kept = _resume(out, key, columns, parameters)
        table_csv = out / "sweep.csv"
        todo = [t for t, p in zip(tasks, points)
                if tuple(p[r] for r in parameters) not in kept]
        rows_by_run = {}
        for k, p in enumerate(points):
            row = kept.get(tuple(p[r] for r in parameters))
            if row is not None:
                rows_by_run[k] = {**row, "run": k}
        (out / "sweep.json").write_text(json.dumps({"study": key, "varied": parameters,
                                                    "samples": samples, "seed": seed,
                                                    "figures": figures}, indent=2,
                                                   default=str) + "\n")
        with open(table_csv, "w", newline="") as f:  # kept rows first, then rows as they finish
            csv.writer(f).writerow(columns)
            for k in sorted(rows_by_run):
                _write_row(f, columns, rows_by_run[k])
            f.flush()

            def on_done(output) -> None:
                row = {"run": output.key, **points[output.key], "status": output.status,
                       "reason": " | ".join(x.strip() for x in output.reason.splitlines()
                                            if x.strip()), "wall_seconds": float(output.wall_seconds)}
                for name in figures:
                    row[name] = float(output.figures.get(name, math.nan))
                rows_by_run[output.key] = row
                _write_row(f, columns, row)
                f.flush()
            executor.run(todo, fmu_dir, on_done=on_done, progress=progress,
                         label=f"{scene.name} sweep")
        rows = [rows_by_run[k] for k in range(len(points))]
        with open(table_csv, "w", newline="") as f:
            csv.writer(f).writerow(columns)
            for row in rows:
                _write_row(f, columns, row)
    finally:
        if own:
            executor.close()
    table = SweepTable(columns, rows, parameters, figures, table_csv, executed=len(todo))
    if plot:
        table.png = plot_sweep(out / "sweep.png", table, scene.name)
    return table


def _check_parameters(scene, parameters, fmus: dict, files: dict) -> None:
    """Fail before running anything when a varied parameter does not exist."""
    from fmpy import read_model_description

    from ..system.scene import SceneError
    for ref in parameters:
        comp, param = ref.split(".", 1)
        md = read_model_description(str(files[fmus[comp][0]]))
        allowed = [v.name for v in md.modelVariables if v.causality == "parameter"]
        if param not in allowed:
            raise SceneError(scene.path, f"--vary {ref}", f"{comp} has no parameter {param!r}; "
                                                          f"parameters: {', '.join(allowed)}")


def _resume(out: Path, key: dict, columns: list[str], parameters: list[str]) -> dict:
    """Rows of an earlier call of the same study: point -> row (rows to run again dropped)."""
    table_csv, meta = out / "sweep.csv", out / "sweep.json"
    if not table_csv.is_file():
        return {}
    if not meta.is_file():
        raise SweepError(f"{table_csv} exists without sweep.json: not a sweep's folder; give "
                         "another --out")
    old = json.loads(meta.read_text()).get("study")
    if json.loads(json.dumps(key, default=str)) != old:
        raise SweepError(f"{out} holds another study (scene, settings, grid or FMUs differ); "
                         "give another --out or delete it")
    header, rows = read_table(table_csv)
    if header != columns:
        raise SweepError(f"{table_csv}: columns differ from this study's; give another --out")
    return {_row_key(r, parameters): r for r in rows if r["status"] not in RERUN}


def plot_sweep(path: Path, table: SweepTable, title: str) -> Path:
    """Each figure (rows of panels) against each varied parameter (columns); failed runs are
    marked with a red x on the lower edge of their panels."""
    from .compare import UNITS
    from ..cosim.results import PALETTE, axis_label, new_figure

    figs, params = table.figures, table.parameters
    fig = new_figure(figsize=(3.6 * len(params) + 1, 2.0 * len(figs) + 0.8))
    axes = fig.subplots(len(figs), len(params), squeeze=False, sharex="col")
    ok = np.array([r["status"] == "completed" for r in table.rows], dtype=bool)
    for j, p in enumerate(params):
        x = table.column(p)
        for i, name in enumerate(figs):
            ax = axes[i, j]
            y = table.column(name)
            order = np.argsort(x[ok], kind="stable")
            ax.plot(x[ok][order], y[ok][order], "o-" if len(params) == 1 else "o",
                    ms=3.5, lw=0.8, color=PALETTE[0])
            if (~ok).any():
                good = y[ok][np.isfinite(y[ok])]
                ax.plot(x[~ok], np.full((~ok).sum(), good.min() if good.size else 0.0),
                        "x", color=PALETTE[3], ms=6, label="failed")
            if j == 0:
                ax.set_ylabel(axis_label(name, UNITS[name]) if name in UNITS else name,
                              fontsize=8)
            ax.grid(alpha=0.3)
            ax.tick_params(labelsize=7)
        axes[-1, j].set_xlabel(p)
    fig.suptitle(f"{title}: {len(table.rows)} runs, {int(ok.sum())} completed", fontsize=10)
    fig.tight_layout(rect=(0, 0, 1, 0.98))
    fig.savefig(path, dpi=100)
    return path
