"""Compare two scenes (a component swap): run both, align in time, report what matters.

Which recorded variable plays which role comes from each scene's [analysis] table, never from
here (the same press may be driven through different components):

    [analysis]
    crank_angle  = "press.phi"          # rad, continuous: strokes are its full revolutions
    crank_speed  = "press.w_crank"      # rad/s
    drive_torque = "motor.flange_tau"   # N.m, the motor's torque
    drive_power  = "motor.P_shaft"      # W, the motor's shaft power: energy per stroke
    load_torque  = "press.M_C"          # N.m, optional: the press's resistance moment
    from_time    = 0.5                  # s, optional (default start_time): skip a run-up
    events       = ["drive.E_brake_b", "drive.n_events"]   # optional, hybrid scenes: recorded
                                        # variables reported at the run's end (a sweep's columns)

Strokes: the crank angle at from_time is phi0; stroke k ends when the crank angle first reaches
phi0 + 2 pi k. The metrics use the complete strokes only, the window [from_time, end of the last
complete stroke] (the whole run after from_time if there is none):

    strokes, cycle time (mean stroke duration, pauses included), mean crank speed (time average),
    delta = (w_max - w_min)/w_mean, peak |drive torque|, peak |load torque|, energy per stroke
    (integral of drive_power over the window / strokes).

The time series are also aligned on a common grid (A's recorded times within both runs) for the
largest crank-speed difference and the overlay plot.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..system.analysis import LISTS, NUMBERS, analysis_roles
from ..system.scene import SceneError
from .table import Table


@dataclass
class Series:
    label: str
    time: np.ndarray
    values: dict[str, np.ndarray]  # role -> samples
    from_time: float


def role_variables(roles: dict) -> dict:
    """role -> recorded variable, without from_time and events."""
    return {r: v for r, v in roles.items() if r not in NUMBERS + LISTS}


def record_analysis_variables(scene, roles: dict) -> None:
    """Add the analysis variables (roles and events) to what `scene` records."""
    scene.record = list(dict.fromkeys(scene.record + list(role_variables(roles).values())
                                      + list(roles.get("events", []))))


def series_from_arrays(label: str, names: list, rows: np.ndarray, roles: dict) -> Series:
    """The role series of a run from its recorded arrays (time + `names` columns)."""
    return Series(label, rows[:, 0].copy(),
                  {r: rows[:, 1 + names.index(v)].copy() for r, v in role_variables(roles).items()},
                  roles["from_time"])


def _run_both(executor, scenes, out_dir: Path, options) -> list[Series]:
    """Both runs through `executor`; this process writes their CSVs and sidecars to out_dir.
    A run that stops early raises RunError here, as run_scene does on the serial path."""
    from ..cosim.runner import RunError
    from .executor import RunTask, write_run_files

    tasks, roles = [], []
    for scene, label in scenes:
        r = analysis_roles(scene)
        record_analysis_variables(scene, r)
        roles.append(r)
        tasks.append(RunTask(label, scene))
    outputs = executor.run(tasks, options.fmu_dir, progress=options.progress, label="compare")
    paths = getattr(executor, "fmu_files", {})
    series = []
    for task, output, r in zip(tasks, outputs, roles):
        csv = out_dir / f"{task.key}.csv"
        if output.sidecar:
            write_run_files(output, csv, {c: paths.get(d) for c, (d, _) in task.fmus.items()})
        if output.status == "failed":
            raise RunError(output.reason, csv)
        if output.status != "completed":
            raise RunError(f"{task.key}: {output.status}: {output.reason}", None)
        series.append(series_from_arrays(task.key, output.names, output.rows, r))
    return series


def run_for_comparison(scene, label: str, out_dir: Path, options) -> Series:
    """Run `scene` (recording its analysis variables too) and return its role series."""
    from dataclasses import replace
    from ..cosim.runner import run_scene
    roles = analysis_roles(scene)
    record_analysis_variables(scene, roles)
    result = run_scene(scene, replace(options, out=out_dir / f"{label}.csv"))
    rec = result.recorder
    return series_from_arrays(label, rec.names, rec.rows, roles)


def stroke_ends(time: np.ndarray, angle: np.ndarray, t0: float) -> list[float]:
    """Times the crank angle first reaches angle(t0) + 2 pi k, k = 1, 2, ... (interpolated)."""
    phi0 = float(np.interp(t0, time, angle))
    ends, k = [], 1
    for i in range(1, len(time)):
        if time[i] <= t0:
            continue
        while angle[i] >= phi0 + 2 * math.pi * k and angle[i - 1] < phi0 + 2 * math.pi * k:
            target = phi0 + 2 * math.pi * k
            s = (target - angle[i - 1]) / (angle[i] - angle[i - 1])
            ends.append(float(time[i - 1] + s * (time[i] - time[i - 1])))
            k += 1
    return ends


def metrics(s: Series) -> dict:
    """The figures of the module's docstring; a figure that cannot be computed is nan, and
    "missing" maps it to why (the run ends before the analysis window, no whole stroke)."""
    t, v = s.time, s.values
    ends = stroke_ends(t, v["crank_angle"], s.from_time)
    t_end = ends[-1] if ends else float(t[-1])
    window = (t >= s.from_time) & (t <= t_end)
    w, tw = v["crank_speed"][window], t[window]
    out: dict[str, Any] = {"strokes": len(ends), "window_start": s.from_time,
                           "window_end": t_end, "missing": {}}
    if len(tw) < 2:
        why = (f"the analysis window from from_time = {s.from_time:g} s to the run's end at "
               f"{float(t[-1]):g} s holds {len(tw)} recorded point(s), fewer than 2")
        names = ["cycle_time", "mean_crank_speed", "delta", "peak_drive_torque",
                 "energy_per_stroke"] + (["peak_load_torque"] if "load_torque" in v else [])
        return {**out, **{k: math.nan for k in names}, "missing": dict.fromkeys(names, why)}
    w_mean = float(np.trapezoid(w, tw) / (tw[-1] - tw[0]))
    energy = float(np.trapezoid(v["drive_power"][window], tw))
    out.update({
        "cycle_time": float(np.mean(np.subtract(ends, [s.from_time] + ends[:-1]))) if ends
        else math.nan,
        "mean_crank_speed": w_mean,
        "delta": float((w.max() - w.min()) / w_mean) if w_mean else math.nan,
        "peak_drive_torque": float(np.max(np.abs(v["drive_torque"][window]))),
        "energy_per_stroke": energy / len(ends) if ends else math.nan})
    if "load_torque" in v:
        out["peak_load_torque"] = float(np.max(np.abs(v["load_torque"][window])))
    if not ends:
        out["missing"].update(dict.fromkeys(
            ("cycle_time", "energy_per_stroke"), f"no whole crank revolution between "
            f"from_time = {s.from_time:g} s and the run's end at {float(t[-1]):g} s"))
    if not w_mean:
        out["missing"]["delta"] = "the mean crank speed is 0"
    return out


UNITS = {"strokes": "1", "cycle_time": "s", "mean_crank_speed": "rad/s", "delta": "1",
         "peak_drive_torque": "N.m", "peak_load_torque": "N.m", "energy_per_stroke": "J",
         "window_start": "s", "window_end": "s", "max_crank_speed_difference": "rad/s"}


def aligned_difference(a: Series, b: Series, role: str = "crank_speed") -> float:
    """max |a - b| of a role on A's recorded times within both runs (B interpolated)."""
    lo, hi = max(a.time[0], b.time[0]), min(a.time[-1], b.time[-1])
    grid = a.time[(a.time >= lo) & (a.time <= hi)]
    return float(np.max(np.abs(np.interp(grid, a.time, a.values[role])
                               - np.interp(grid, b.time, b.values[role]))))


def compare_table(a: Series, b: Series) -> list[tuple]:
    """Rows (metric, unit, A, B, B - A, (B - A)/|A|)."""
    ma, mb = metrics(a), metrics(b)
    rows = []
    for key in UNITS:
        if key == "max_crank_speed_difference":
            d = aligned_difference(a, b)
            rows.append((key, UNITS[key], 0.0, d, d, math.nan))
        elif key in ma and key in mb:
            va, vb = float(ma[key]), float(mb[key])
            rel = (vb - va) / abs(va) if va and math.isfinite(va) else math.nan
            rows.append((key, UNITS[key], va, vb, vb - va, rel))
    return rows


def format_table(rows, la: str, lb: str) -> str:
    wa, wb = max(14, len(la) + 2), max(14, len(lb) + 2)
    head = f"{'metric':<28}{'unit':<7}{la:>{wa}}{lb:>{wb}}{'B - A':>14}{'(B-A)/|A|':>11}"
    lines = [head, "-" * len(head)]
    for key, unit, va, vb, d, rel in rows:
        lines.append(f"{key:<28}{unit:<7}{va:>{wa}.6g}{vb:>{wb}.6g}{d:>14.5g}"
                     + (f"{rel:>11.3%}" if math.isfinite(rel) else f"{'':>11}"))
    return "\n".join(lines)


def write_table(path: Path, rows, la: str, lb: str) -> None:
    """The table as compare.csv at `path` (crankfmu.outputs.write_table: written whole)."""
    from ..outputs import write_table as write_csv_table
    write_csv_table(path, ["metric", "unit", la, lb, "B_minus_A", "relative"],
                    ([row[0], row[1]] + [repr(float(x)) for x in row[2:]] for row in rows))


def overlay_figure(a: Series, b: Series, title: str):
    """Crank speed, motor torque (and the press moment) of both runs over time; a panel where
    the two runs' curves coincide says so in its legend."""
    from ..cosim.results import axis_label, mark_coinciding, new_figure, style_axes
    panels = [("crank_speed", axis_label("crank speed", "rad/s")),
              ("drive_torque", axis_label("motor torque", "N.m"))]
    if "load_torque" in a.values and "load_torque" in b.values:
        panels.append(("load_torque", axis_label("press moment M_C", "N.m")))
    fig = new_figure(figsize=(9, 2.6 * len(panels)))
    axes = fig.subplots(len(panels), 1, sharex=True, squeeze=False)[:, 0]
    for ax, (role, label) in zip(axes, panels):
        style_axes(ax)
        for s, style in ((a, "-"), (b, "--")):
            ax.plot(s.time, s.values[role], style, lw=1.0, label=s.label)
        ax.set_ylabel(label)
        mark_coinciding(ax)
        ax.legend(loc="best", fontsize=8)
    axes[0].set_title(title)
    axes[-1].set_xlabel(axis_label("time", "s"))
    fig.tight_layout()
    return fig


def compare_labels(scene_a, scene_b) -> tuple[str, str]:
    """The runs' labels (their CSVs' names in the output folder): the scene names, or "A_" and
    "B_" before them when they are equal or one is "compare" (the table's own name)."""
    la, lb = scene_a.name, scene_b.name
    if la == lb or "compare" in (la, lb):
        la, lb = f"A_{la}", f"B_{lb}"
    return la, lb


def check_window(scene, from_time: float, key: str, stop_name: str = "--stop-time") -> None:
    """The analysis window [from_time, stop_time] is not empty, so figures can be computed
    (raises SceneError naming `key` and the option that lengthens the runs)."""
    if not (math.isfinite(from_time) and from_time < scene.stop_time):
        raise SceneError(scene.path, key, f"{from_time:g} s is not before the stop time "
                         f"{scene.stop_time:g} s: the runs would end before the analysis "
                         f"window starts, so they would have no figures; lengthen the runs "
                         f"({stop_name}) or start the window earlier")


def check_compare_outputs(scene_a, scene_b, out_dir, option: str = "--out",
                          stop_option: str = "--stop-time") -> Path:
    """Before any run: the output folder and every name compare writes there
    (crankfmu.outputs); the analysis window of each scene ends before its stop time."""
    from ..cosim.results import check_run_set
    from ..outputs import check_files
    for scene in (scene_a, scene_b):
        check_window(scene, analysis_roles(scene)["from_time"], "[analysis].from_time",
                     stop_option)
    out_dir = Path(out_dir)
    check_files(out_dir, ["compare.csv", "compare.png"], option)
    for label in compare_labels(scene_a, scene_b):
        check_run_set(out_dir / f"{label}.csv", option)
    return out_dir


CSV_COLUMNS = ("metric", "unit", "A", "B", "B_minus_A", "relative")  # A, B: the runs' labels


@dataclass
class CompareResult(Table):
    """The comparison: one row per figure (metric, unit, A, B, B - A, relative), `text` the
    table as printed, `a` and `b` the runs' role series; as a table (`to_pandas()`, indexed by
    the figure, `units`: figure -> its unit) the rows of compare.csv. Paths are None where
    nothing was written (the API without `out`, `png` without `plot`)."""

    table: list[tuple]
    text: str
    a: Series
    b: Series
    csv: Path | None
    png: Path | None = None

    @property
    def columns(self) -> list[str]:
        return [CSV_COLUMNS[0], CSV_COLUMNS[1], self.a.label, self.b.label, *CSV_COLUMNS[4:]]

    @property
    def rows(self) -> list[dict]:
        return [dict(zip(self.columns, row)) for row in self.table]

    @property
    def units(self) -> dict:
        return {row[0]: row[1] for row in self.table}

    def to_pandas(self):
        """A pandas DataFrame indexed by the figure (needs pandas); units in the "unit" column
        and in `df.attrs["units"]`."""
        from .table import data_frame
        return data_frame(self.table, self.columns, self.units, index="metric")


def compare_scenes(scene_a, scene_b, out_dir: Path, options, executor=None,
                   option: str = "--out", stop_option: str = "--stop-time",
                   plot: bool = False) -> CompareResult:
    """Run both scenes into out_dir; write compare.csv (and with `plot` compare.png); return
    the results. With an `executor` (crankfmu.studies.executor) both runs go through it (in
    parallel on a pool or cluster); without one they run in this process one after the other.
    Same numbers. Everything is checked before the runs (check_compare_outputs)."""
    from ..cosim.results import save_figure
    out_dir = check_compare_outputs(scene_a, scene_b, out_dir, option, stop_option)
    la, lb = compare_labels(scene_a, scene_b)
    if executor is None:
        a = run_for_comparison(scene_a, la, out_dir, options)
        b = run_for_comparison(scene_b, lb, out_dir, options)
    else:
        a, b = _run_both(executor, [(scene_a, la), (scene_b, lb)], out_dir, options)
    rows = compare_table(a, b)
    write_table(out_dir / "compare.csv", rows, la, lb)
    png = save_figure(overlay_figure(a, b, f"{la} (A) vs {lb} (B)"), out_dir / "compare.png") \
        if plot else None
    text = format_table(rows, la, lb)
    notes = missing_notes({la: metrics(a), lb: metrics(b)})
    return CompareResult(rows, text + ("\n" + notes if notes else ""), a, b,
                         out_dir / "compare.csv", png)


def missing_notes(by_label: dict) -> str:
    """One line per run whose figures are missing, saying which and why."""
    lines = []
    for label, m in by_label.items():
        reasons: dict[str, list[str]] = {}
        for figure, why in m["missing"].items():
            reasons.setdefault(why, []).append(figure)
        lines += [f"{label}: no {', '.join(f)}: {why}" for why, f in reasons.items()]
    return "\n".join(lines)
