"""Recording and writing results: CSV (fmpy.util.read_csv layout), JSON sidecar, PNG plot."""
from __future__ import annotations

import json
import math
import os
import platform
import tempfile
from importlib import metadata
from pathlib import Path

import numpy as np


class Recorder:
    """Rows of `time` and the recorded variables, grown in blocks."""

    def __init__(self, names: list[str], units: list[str | None]):
        self.names, self.units = names, units
        self._rows = np.empty((1024, len(names) + 1))
        self.count = 0

    def add(self, t: float, values) -> None:
        if self.count == len(self._rows):
            self._rows = np.concatenate([self._rows, np.empty_like(self._rows)])
        self._rows[self.count, 0] = t
        self._rows[self.count, 1:] = values
        self.count += 1

    @property
    def rows(self) -> np.ndarray:
        return self._rows[:self.count]

    def column(self, name: str) -> np.ndarray:
        return self.rows[:, 1 + self.names.index(name)]


def normalize_unit(unit: str | None) -> str:
    """A unit in FMI's spelling (the modelDescription's): "1" for a dimensionless value."""
    return unit or "1"


def column_units(recorder: Recorder) -> dict[str, str]:
    """Unit of every CSV column, "time" first (the sidecar's "units")."""
    return {"time": "s", **{n: normalize_unit(u) for n, u in zip(recorder.names,
                                                                 recorder.units)}}


def atomic_write(path: Path, write) -> None:
    """Write through a temporary file in the same folder, then rename it onto `path`: a reader
    (or a crash) sees the old file or the new one, never a half-written one."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "w") as f:
            write(f)
        os.chmod(tmp, 0o666 & ~_umask())
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def write_csv(path: Path, recorder: Recorder) -> None:
    def write(f):
        f.write(",".join(["time"] + [f'"{n}"' for n in recorder.names]) + "\n")
        for row in recorder.rows:
            f.write(",".join(repr(float(v)) for v in row) + "\n")
    atomic_write(path, write)


def versions() -> dict:
    out = {"python": platform.python_version()}
    for pkg in ("crankfmu", "fmpy", "pythonfmu", "numpy", "scipy"):
        try:
            out[pkg] = metadata.version(pkg)
        except metadata.PackageNotFoundError:
            out[pkg] = None
    return out


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


def coincide(x1, y1, x2, y2, rtol: float = 2e-3) -> bool:
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
    them ("A = B (curves coincide)"), instead of entries for lines nobody can see; returns the
    coinciding (first, other) label pairs."""
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
            for b in same:
                merged.add(id(b))
                b.set_label("_" + b.get_label())
    return pairs


def axis_label(name: str, unit: str | None) -> str:
    """`name [unit]` in FMI's unit spelling; `[1]` for a dimensionless value."""
    return f"{name} [{unit or '1'}]"


def figure(names, units, rows: np.ndarray, title: str):
    """One panel per recorded variable over time, each axis labelled with its unit; returns the
    Figure (crankfmu.cosim.results.new_figure: the backend is left alone)."""
    n = len(names)
    fig = new_figure(figsize=(9, 1.9 * n + 0.8))
    axes = fig.subplots(n, 1, sharex=True, squeeze=False)
    t = rows[:, 0]
    for ax, name, unit, k in zip(axes[:, 0], names, units, range(n)):
        style_axes(ax)
        ax.plot(t, rows[:, k + 1], lw=1.0)
        ax.set_ylabel(axis_label(name, unit).replace(" [", "\n["), fontsize=8)
    axes[-1, 0].set_xlabel(axis_label("time", "s"))
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    return fig


def plot(path: Path, recorder: Recorder, title: str) -> None:
    """One panel per recorded variable, with units, over time, written as a PNG."""
    figure(recorder.names, recorder.units, recorder.rows, title).savefig(path, dpi=110)
