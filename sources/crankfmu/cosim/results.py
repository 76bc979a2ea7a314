"""Recording and writing results: CSV (fmpy.util.read_csv layout), JSON sidecar, PNG plot."""
from __future__ import annotations

import array
import io
import json
import math
import os
import platform
from pathlib import Path

import numpy as np

from ..outputs import atomic_write, check_file, folder_lock, output_folder, remove_file


class Recorder:
    """Rows of `time` and the recorded variables. A row is appended to a flat array of C doubles
    (array.array: extending it by a list of Python floats costs about a tenth of writing the row
    into a preallocated numpy block, which was 3-5 us of the 30-40 us a two-FMU step costs);
    `rows` gives them as a numpy array, made once per row count."""

    def __init__(self, names: list[str], units: list[str | None]):
        self.names, self.units = names, units
        self._width = len(names) + 1
        self._flat = array.array("d")
        self._array = np.empty((0, self._width))
        self.count = 0

    def add(self, t: float, values) -> None:
        """Append the row (t, *values); values: floats in the order of `names`."""
        flat = self._flat
        flat.append(t)
        flat.extend(values)
        self.count += 1
        if len(flat) != self.count * self._width:  # a row of the wrong length: undo it
            del flat[(self.count - 1) * self._width:]
            self.count -= 1
            raise ValueError(f"a row of {len(values)} values for {len(self.names)} recorded "
                             "variables")

    @property
    def rows(self) -> np.ndarray:
        """The rows so far, (count, 1 + len(names)); a copy, not changed by later rows."""
        if len(self._array) != self.count:
            self._array = np.array(self._flat, dtype=float).reshape(self.count, self._width)
            self._array.flags.writeable = False  # shared by every caller until the next row
        return self._array

    def column(self, name: str) -> np.ndarray:
        return self.rows[:, 1 + self.names.index(name)]


def record_rows(scene) -> int:
    """The most rows a run of `scene` records: a row every [record].interval (rounded to whole
    steps for a fixed-step master, at least min_step apart for a variable-step one), the start
    and the stop."""
    from ..masters import traits
    m, span = scene.master, scene.stop_time - scene.start_time
    interval = scene.record_interval or 0.0
    if traits(m.algorithm).variable_step:
        return math.ceil(span / max(interval, m.min_step)) + 2
    steps = max(1, math.ceil(span / m.step - 1e-9))
    return steps // max(1, round((interval or m.step) / m.step)) + 2


def check_record_size(scene) -> None:
    """The run's recorded values fit MAX_RECORD_BYTES (crankfmu.errors); checked before
    anything is loaded or allocated. Raises SceneError saying how to record less."""
    from ..errors import MAX_RECORD_BYTES, SceneError
    rows, columns = record_rows(scene), len(scene.record) + 1
    size = rows * columns * 8
    if size > MAX_RECORD_BYTES:
        raise SceneError(scene.path, "[record]", f"up to {rows} rows x {columns} columns "
                         f"({size / 2**30:.3g} GiB of recorded values) from start_time "
                         f"{scene.start_time:g} to stop_time {scene.stop_time:g} s, more than "
                         f"the limit of {MAX_RECORD_BYTES / 2**30:g} GiB: record fewer "
                         "variables, a longer [record].interval or a shorter run")


def normalize_unit(unit: str | None) -> str:
    """A unit in FMI's spelling (the modelDescription's): "1" for a dimensionless value."""
    return unit or "1"


def column_units(recorder: Recorder) -> dict[str, str]:
    """Unit of every CSV column, "time" first (the sidecar's "units")."""
    return {"time": "s", **{n: normalize_unit(u) for n, u in zip(recorder.names,
                                                                 recorder.units)}}


def write_csv(path: Path, recorder: Recorder) -> str:
    """The CSV (atomic_write: a regular file, never half written); returns its sha256."""
    def write(f):
        f.write(",".join(["time"] + [f'"{n}"' for n in recorder.names]) + "\n")
        for row in recorder.rows.tolist():  # Python floats: repr gives the shortest digits
            f.write(",".join(map(repr, row)) + "\n")
    return atomic_write(path, write)


def versions() -> dict:
    """Python's version and those of the packages a run's numbers depend on."""
    return {"python": platform.python_version(),
            **{pkg: _version(pkg) for pkg in ("crankfmu", "fmpy", "pythonfmu", "numpy", "scipy")}}


def _version(package: str) -> str | None:
    """An imported package's __version__; else the version its installed .dist-info folder is
    named with, found without importing the package (a run that does not use scipy does not
    import it); else importlib.metadata's answer (its import cost a run 20-40 ms)."""
    import sys
    if package in sys.modules:
        return getattr(sys.modules[package], "__version__", None)
    import importlib.util
    spec = importlib.util.find_spec(package)
    if spec is None or spec.origin is None:
        return None
    site = Path(spec.origin).parents[1]
    infos = [n for n in os.listdir(site)
             if n.startswith(f"{package}-") and n.endswith(".dist-info")]
    if len(infos) == 1:
        return infos[0][len(package) + 1:-len(".dist-info")]
    from importlib import metadata
    return metadata.version(package)


def _finite(value):
    """The payload with NaN and infinities as null: strict JSON, and no non-finite number in a
    written result (a failed run's statistics may hold them)."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: _finite(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_finite(v) for v in value]
    if isinstance(value, np.generic):
        return _finite(value.item())
    if isinstance(value, np.ndarray):
        return _finite(value.tolist())
    return value


def write_sidecar(path: Path, payload: dict) -> None:
    text = json.dumps(_finite(payload), indent=2, default=float, allow_nan=False) + "\n"
    atomic_write(path, lambda f: f.write(text))


# Okabe & Ito's colour-blind-safe palette (black first is left out: it is the grid's colour)
PALETTE = ("#0072B2", "#E69F00", "#009E73", "#D55E00", "#CC79A7", "#56B4E9", "#F0E442",
           "#000000")


def new_figure(**kwargs):
    """A matplotlib Figure that is not registered with pyplot: making, saving or returning it
    never selects or changes the backend (inline plots in Jupyter keep working), and it is freed
    like any object."""
    from matplotlib.figure import Figure
    return Figure(**kwargs)


def style_axes(ax) -> None:
    ax.set_prop_cycle(color=PALETTE)
    ax.grid(alpha=0.3)


def coincide(x1, y1, x2, y2, rtol: float = 5e-3) -> bool:
    """Two curves that would be drawn on top of each other: same x range, and on a common grid
    |y1 - y2| within rtol of the larger curve's span (one line width on a panel)."""
    x1, y1, x2, y2 = (np.asarray(v, dtype=float) for v in (x1, y1, x2, y2))
    if len(x1) < 2 or len(x2) < 2 or not (np.isfinite(y1).all() and np.isfinite(y2).all()):
        return bool(len(x1) == len(x2) and np.array_equal(x1, x2) and np.array_equal(y1, y2))
    lo, hi = max(x1.min(), x2.min()), min(x1.max(), x2.max())
    span_x = max(x1.max() - x1.min(), x2.max() - x2.min(), 1e-300)
    if hi - lo < (1 - rtol) * span_x:
        return False
    grid = np.union1d(x1[(x1 >= lo) & (x1 <= hi)], x2[(x2 >= lo) & (x2 <= hi)])
    a = np.interp(grid, *_sorted(x1, y1))
    b = np.interp(grid, *_sorted(x2, y2))
    span = max(np.ptp(y1), np.ptp(y2), 1e-300)
    return bool(np.max(np.abs(a - b)) <= rtol * span)


def _sorted(x, y):
    k = np.argsort(x, kind="stable")
    return x[k], y[k]


def mark_coinciding(ax) -> list[tuple[str, str]]:
    """Curves of one panel that lie on top of each other get one legend entry naming all of
    them ("A = B (curves coincide)"), instead of entries for lines nobody can see; the others
    are hidden, so the curve shown has the entry's colour. Returns the (first, other) pairs."""
    lines = [ln for ln in ax.get_lines() if not ln.get_label().startswith("_")]
    pairs, merged = [], set()
    for i, a in enumerate(lines):
        if id(a) in merged:
            continue
        same = [b for b in lines[i + 1:] if id(b) not in merged and
                coincide(a.get_xdata(), a.get_ydata(), b.get_xdata(), b.get_ydata())]
        if same:
            pairs += [(a.get_label(), b.get_label()) for b in same]
            a.set_label(" = ".join([a.get_label()] + [b.get_label() for b in same])
                        + " (curves coincide)")
            for b in same:  # not drawn: the legend's colour is the one on the panel
                merged.add(id(b))
                b.set_label("_" + b.get_label())
                b.set_visible(False)
    return pairs


def axis_label(name: str, unit: str | None) -> str:
    """`name [unit]` in FMI's unit spelling; `[1]` for a dimensionless value."""
    return f"{name} [{unit or '1'}]"


def is_running_angle(unit: str | None, values: np.ndarray) -> bool:
    """An angle that keeps turning (a crank's): more than two revolutions recorded."""
    return unit == "rad" and len(values) > 1 and np.ptp(values) > 4 * np.pi


def figure(names, units, rows: np.ndarray, title: str):
    """One panel per recorded variable over time, each axis labelled with its unit; an angle
    that keeps turning is drawn modulo 2 pi (its position in the revolution), not as a ramp.
    Returns the Figure (new_figure: the backend is left alone)."""
    n = len(names)
    fig = new_figure(figsize=(9, 1.9 * n + 0.8))
    axes = fig.subplots(n, 1, sharex=True, squeeze=False)
    t = rows[:, 0]
    for ax, name, unit, k in zip(axes[:, 0], names, units, range(n)):
        style_axes(ax)
        y = rows[:, k + 1]
        if is_running_angle(unit, y):
            ax.plot(t, np.mod(y, 2 * np.pi), ".", ms=1.0)
            name = f"{name} mod 2 pi"
        else:
            ax.plot(t, y, lw=1.0)
        ax.set_ylabel(axis_label(name, unit).replace(" [", "\n["), fontsize=8)
    axes[-1, 0].set_xlabel(axis_label("time", "s"))
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    return fig


STEADY_ROLES = (("crank_speed", "crank speed"), ("drive_torque", "drive torque"),
                ("load_torque", "load torque"))


def steady_window(time: np.ndarray, angle: np.ndarray, cycles: int = 3,
                  from_time: float | None = None) -> tuple[float, float]:
    """The last `cycles` whole revolutions of the crank angle after `from_time` (the end of the
    run-up, [analysis].from_time), fewer if the run has fewer; all of the run after from_time
    if it holds no whole revolution."""
    end = float(time[-1])
    start = float(time[0]) if from_time is None else min(max(from_time, float(time[0])), end)
    order = np.maximum.accumulate(angle)  # a monotone copy for the interpolation
    turned = angle[-1] - float(np.interp(start, time, angle))
    turns = min(cycles, int(turned / (2 * np.pi)))
    if turns < 1:
        return start, end
    return max(start, float(np.interp(angle[-1] - 2 * np.pi * turns, order, time))), end


def no_steady_state(names, rows: np.ndarray, roles: dict) -> str | None:
    """Why a run has no steady state to draw (it ends before the analysis window
    [analysis].from_time starts, or turns the crank less than a revolution in it); None when it
    has one."""
    t = rows[:, 0]
    angle = rows[:, 1 + list(names).index(roles["crank_angle"])]
    from_time = roles.get("from_time")
    start = float(t[0]) if from_time is None else float(from_time)
    if len(t) < 2 or t[-1] <= start:
        return (f"the run ends at t = {float(t[-1]):g} s, before the analysis window "
                f"([analysis].from_time = {start:g} s)")
    turned = angle[-1] - float(np.interp(start, t, angle))
    if turned < 2 * np.pi:
        return (f"the crank turns {turned / (2 * np.pi):.2g} revolutions after "
                f"[analysis].from_time = {start:g} s, less than one")
    return None


def steady_figure(names, units, rows: np.ndarray, roles: dict, title: str, reference=None,
                  cycles: int = 3):
    """The periodic steady state: crank speed and drive torque (and the load torque when
    recorded) over the last `cycles` revolutions, against the crank angle in the revolution;
    `reference` (names, rows) of the monolithic reference is drawn over it, dashed, and a panel
    where run and reference coincide says so. `roles`: the scene's [analysis] table
    (crank_angle, crank_speed, drive_torque, optional load_torque)."""
    col = {n: rows[:, k + 1] for k, n in enumerate(names)}
    unit = dict(zip(names, units))
    t = rows[:, 0]
    angle = col[roles["crank_angle"]]
    t0, t1 = steady_window(t, angle, cycles, roles.get("from_time"))
    panels = [(r, label) for r, label in STEADY_ROLES if roles.get(r) in col]
    fig = new_figure(figsize=(9, 2.4 * len(panels) + 0.9))
    axes = fig.subplots(len(panels), 1, sharex=True, squeeze=False)[:, 0]
    series = [("co-simulation", t, col, "-")]
    if reference is not None:
        ref_names, ref_rows = reference
        series.append(("monolithic reference", ref_rows[:, 0],
                       {n: ref_rows[:, k + 1] for k, n in enumerate(ref_names)}, "--"))
    for ax, (role, label) in zip(axes, panels):
        style_axes(ax)
        var = roles[role]
        for name, tt, cc, style in series:
            if var not in cc or roles["crank_angle"] not in cc:
                continue
            window = (tt >= t0 - 1e-12) & (tt <= t1 + 1e-12)
            ax.plot(tt[window], cc[var][window], style, lw=1.0, label=name)
        ax.set_ylabel(axis_label(f"{label}\n{var}", unit.get(var)), fontsize=8)
        if len(series) > 1:
            mark_coinciding(ax)
            ax.legend(fontsize=7, loc="best")
    revs = (angle[-1] - float(np.interp(t0, t, angle))) / (2 * np.pi)
    axes[-1].set_xlabel(axis_label("time", "s"))
    fig.suptitle(f"{title}\nsteady state: the last {revs:.3g} revolutions "
                 f"(t = {t0:.3g} to {t1:.3g} s)", fontsize=10)
    fig.tight_layout()
    return fig


def read_result_csv(path: Path) -> tuple[list[str], np.ndarray]:
    """(names without "time", rows) of a CSV in the runner's layout."""
    with open(path) as f:
        header = f.readline().strip().split(",")
    rows = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
    return [h.strip('"') for h in header[1:]], rows


def run_figure(recorder: Recorder, title: str, roles: dict | None = None, reference=None):
    """The steady state (steady_figure) when `roles` name a recorded crank angle, speed and
    drive torque and the run reaches a steady state (no_steady_state), else one panel per
    recorded variable, with units, over time (with a note in the title saying why when the
    scene has a steady state to show)."""
    if roles and all(roles.get(r) in recorder.names
                     for r in ("crank_angle", "crank_speed", "drive_torque")):
        why = no_steady_state(recorder.names, recorder.rows, roles)
        if why is None:
            return steady_figure(recorder.names, recorder.units, recorder.rows, roles, title,
                                 reference)
        title = f"{title}\nno steady state to show: {why}"
    return figure(recorder.names, recorder.units, recorder.rows, title)


def plot(path: Path, recorder: Recorder, title: str, roles: dict | None = None,
         reference=None) -> None:
    """A PNG of run_figure, written as a regular file (save_figure)."""
    save_figure(run_figure(recorder, title, roles, reference), path)


def figure_png(fig, dpi: int = 110) -> bytes:
    """The figure rendered as PNG bytes (rendered before any file is touched), drawn once.
    tight_layout leaves a placeholder layout engine on the figure, and savefig draws a figure
    that has any layout engine twice: first to lay it out, which a placeholder does not do,
    then to render it (a run's plot: 0.75-0.82 of the CPU once, `python
    benchmarks/plot_save.py`). The placeholder goes first: the figure is laid out already and
    its pixels are the same (tests/test_outputs.py and the benchmark compare the bytes)."""
    import matplotlib
    from matplotlib.layout_engine import PlaceHolderLayoutEngine

    if isinstance(fig.get_layout_engine(), PlaceHolderLayoutEngine):
        # no layout engine at all: what set_layout_engine(None) sets when these rcParams,
        # which would choose one, are off
        with matplotlib.rc_context({"figure.autolayout": False,
                                    "figure.constrained_layout.use": False}):
            fig.set_layout_engine(None)
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=dpi)
    return buffer.getvalue()


def save_figure(fig, path: Path, dpi: int = 110) -> Path:
    """The figure as a PNG at `path` through atomic_write (a regular file, never half written,
    never replacing anything else)."""
    data = figure_png(fig, dpi)
    atomic_write(path, lambda f: f.write(data))
    return Path(path)


def run_set_paths(csv: Path) -> tuple[Path, Path, Path]:
    """(CSV, JSON sidecar, PNG) of the run whose CSV is `csv`: one name, three suffixes."""
    csv = Path(csv)
    if csv.suffix != ".csv":  # the names of a set must differ (r.json as CSV once met its sidecar)
        raise ValueError(f"a result CSV's name ends in .csv, got {csv.name}")
    return csv, csv.with_suffix(".json"), csv.with_suffix(".png")


def check_run_set(csv: Path, option: str = "--out") -> Path:
    """Before a run: its output folder found or created and writable, and no name the run may
    write (the set's three, and the failed run's `<name>.failed.csv` and `.json`) taken by
    anything but a regular file (crankfmu.outputs). Raises OutputError naming `option`."""
    csv, sidecar, png = run_set_paths(csv)
    output_folder(csv.parent, option)
    failed = failed_csv(csv)
    for path in (csv, sidecar, png, failed, failed.with_suffix(".json")):
        check_file(path, option)
    return csv


def failed_csv(csv: Path) -> Path:
    """`<name>.failed.csv` beside `<name>.csv`: where a failed rerun keeps its rows, so the
    good result of an earlier run is never replaced by a failed one."""
    return csv.with_name(f"{csv.stem}.failed.csv")


def write_run_set(csv: Path, recorder: Recorder, metadata: dict, png: bytes | None = None
                  ) -> tuple[Path, Path, Path | None]:
    """Write a run's CSV, its JSON sidecar (`metadata` plus "csv": file name, sha256 and row
    count of the CSV written) and, given its bytes, its PNG, as one set: under an exclusive lock
    on the folder, so another process writing the same names waits and the three files always
    come from one run; a PNG of an earlier run beside the CSV is removed when this run draws
    none (it would describe another CSV). The sidecar is written last. Returns the paths."""
    csv, sidecar, png_path = run_set_paths(csv)
    with folder_lock(csv.parent):
        metadata["csv"] = {"file": csv.name, "sha256": write_csv(csv, recorder),
                           "rows": recorder.count}
        if png is not None:
            atomic_write(png_path, lambda f: f.write(png))
        else:
            remove_file(png_path)
        metadata["plot"] = png_path.name if png is not None else None
        write_sidecar(sidecar, metadata)
    return csv, sidecar, png_path if png is not None else None


def structured(names, rows: np.ndarray) -> np.ndarray:
    """fmpy's layout: a structured array with the field "time", then one per name."""
    dtype = np.dtype([("time", np.float64)] + [(n, np.float64) for n in names])
    out = np.empty(len(rows), dtype=dtype)
    for k, name in enumerate(dtype.names or ()):
        out[name] = rows[:, k]
    return out
