"""The seed's mobility tables (seed mill_stand_drive_structure, Figs. 1b-3b) and kinematic
schemes (Figs. 1a-3a), beside the rank method (`crankfmu analyze mill-stand`; docs/structure.md,
section 6).

The seed's own method for one closed loop, written out here as `axis_reading` (the figures are
lost from the text; the rules are in it):

* Write each joint's freedoms into a table, translations (tx, ty, tz) in the left columns,
  rotations (rx, ry, rz) in the right, and add the columns: f = sum of the six sums.
* Angular: the loop closes without preload only if each rotation sum is at least 1; one
  rotation about each axis closes the loop, a missing one is a redundant constraint
  ("rotation about" that axis).
* Linear: a translation sum of 0 can be replaced by a spare rotation about a perpendicular
  axis b (one not used for the closure), provided a link turned about b moves along the
  needed direction: some joint of the loop lies off the rotation axis in the third direction.
  A direction that can be closed neither way is a redundant constraint ("translation along").
* What remains of the sums after closure and substitution is the loop's mobility.

It counts axis by axis, so it needs one loop and freedoms along the file's axes; it sees the
directions but not special geometry (the coaxial drive's rod-length constraint, which only the
rank of the constraint Jacobian finds: docs/structure.md, section 4).
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ...outputs import write_table
from .analysis import StructureResult
from .description import Mechanism

COLUMNS = ("tx", "ty", "tz", "rx", "ry", "rz")
_UNIT = {"x": np.array([1.0, 0, 0]), "y": np.array([0, 1.0, 0]), "z": np.array([0, 0, 1.0])}
TYPE_NAMES = {"R": "R", "P": "P", "C": "C", "U": "U", "S": "S", "E": "E", "free": "free"}


def joint_row(joint) -> dict:
    """{column: count} of a joint's freedoms along the file's axes ("other": oblique ones)."""
    row = dict.fromkeys(COLUMNS, 0)
    row["other"] = 0
    for fr in joint.freedoms:
        d = np.array(fr.direction)
        axis = next((a for a, u in _UNIT.items() if abs(abs(float(d @ u)) - 1.0) < 1e-9), None)
        row[f"{fr.kind}{axis}" if axis else "other"] += 1
    return row


def mobility_table(mech: Mechanism, joints=None) -> dict:
    """{"rows": {joint: row}, "sum": row} for the named joints (default all)."""
    names = joints or [j.name for j in mech.joints]
    rows = {j.name: joint_row(j) for j in mech.joints if j.name in names}
    total = {c: sum(r[c] for r in rows.values()) for c in (*COLUMNS, "other")}
    return {"rows": rows, "sum": total}


@dataclass
class AxisReading:
    """The seed's reading of one loop's table: redundant directions (named as the rank method
    names them: "rotation about y", "translation along x"), how each linear direction closes
    ("ty: rotation about x" for a substitution), and the freedoms left (the loop's mobility)."""

    loop: list
    redundant: list
    closures: dict
    left: int


def axis_reading(mech: Mechanism, result: StructureResult) -> AxisReading:
    """The seed's method on the single loop of `mech` (module docstring). ValueError for
    several loops or oblique freedoms (the method counts along the axes of one loop)."""
    if result.k != 1:
        raise ValueError(f"{mech.source}: the axis reading needs one loop, not {result.k}")
    loop = [s.strip() for s in result.loops[0].split(" - ")]
    table = mobility_table(mech, loop)
    total = table["sum"]
    if total["other"]:
        raise ValueError(f"{mech.source}: freedoms off the file's axes; the axis reading "
                         f"counts along x, y, z")
    joints = [j for j in mech.joints if j.name in loop]
    spare, redundant, closures = {}, [], {}
    for a in "xyz":
        if total[f"r{a}"] == 0:
            redundant.append(f"rotation about {a}")
        spare[a] = max(total[f"r{a}"] - 1, 0)
    for a in "xyz":
        if total[f"t{a}"]:
            closures[f"t{a}"] = f"translation along {a}"
            continue
        b = _substitute(joints, a, spare)
        if b is None:
            redundant.append(f"translation along {a}")
        else:
            spare[b] -= 1
            closures[f"t{a}"] = f"rotation about {b}"
    left = sum(spare.values()) + sum(max(total[f"t{a}"] - 1, 0) for a in "xyz")
    return AxisReading(loop, redundant, closures, left)


def _substitute(joints, a: str, spare: dict) -> str | None:
    """The axis b (perpendicular to a, with a spare rotation) whose rotation moves some link
    along a: a joint rotating about b and another joint off it along c = a x b."""
    best = None
    for b in "xyz":
        if b == a or spare[b] < 1:
            continue
        c = np.cross(_UNIT[a], _UNIT[b])
        pivots = [j for j in joints if any(fr.kind == "r" and
                                           abs(abs(float(np.array(fr.direction) @ _UNIT[b]))
                                               - 1.0) < 1e-9 for fr in j.freedoms)]
        lever = any(abs(float((np.array(k.point) - np.array(j.point)) @ c)) > 1e-9
                    for j in pivots for k in joints)
        if lever and (best is None or spare[b] > spare[best]):
            best = b
    return best


def _pair(joint) -> str:
    return f"p{joint.f} ({TYPE_NAMES[joint.kind]})"


def format_mobility(mech: Mechanism, result: StructureResult) -> str:
    """The seed's table for one mechanism with the counts and both readings, as text."""
    table = mobility_table(mech)
    lines = [f"{mech.name}: {mech.description}",
             f"{'joint':>6} {'pair':>10} | " + " ".join(f"{c:>3}" for c in COLUMNS[:3]) + " | "
             + " ".join(f"{c:>3}" for c in COLUMNS[3:])]
    for j in mech.joints:
        row = table["rows"][j.name]
        lines.append(f"{j.name:>6} {_pair(j):>10} | " + " ".join(
            f"{row[c] or '':>3}" for c in COLUMNS[:3]) + " | " + " ".join(
            f"{row[c] or '':>3}" for c in COLUMNS[3:]))
    s = table["sum"]
    lines.append(f"{'sum':>6} {'':>10} | " + " ".join(f"{s[c]:>3}" for c in COLUMNS[:3])
                 + " | " + " ".join(f"{s[c]:>3}" for c in COLUMNS[3:]) + f"   f = {result.f}")
    lines += _count_lines(result)
    try:
        reading = axis_reading(mech, result)
        lines.append(f"seed's axis reading of the loop {' - '.join(reading.loop)}: redundant "
                     f"{len(reading.redundant)}: {', '.join(reading.redundant) or 'none'}; "
                     + ", ".join(f"{k} by {v}" for k, v in reading.closures.items())
                     + f"; {reading.left} freedom(s) left for the loop's mobility")
    except ValueError as err:
        lines.append(f"seed's axis reading: not applicable ({err})")
    lines.append(f"rank method: q = {result.redundant['count']}: "
                 + "; ".join(result.redundant["directions"] or ["none"]))
    if result.local_mobilities["count"]:
        lines.append(f"  local mobilities {result.local_mobilities['count']}: "
                     + "; ".join(result.local_mobilities["directions"]))
    return "\n".join(lines)


def _count_lines(r: StructureResult) -> list:
    p = ", ".join(f"p{j} = {c}" for j, c in sorted(r.p_by_freedom.items()))
    return [f"Malyshev: n = {r.n}, {p}, W = {r.mobility}: q = {r.q_malyshev};  "
            f"Ozol: k = {r.k}, f = {r.f}: q = W + 6k - f = {r.q_ozol};  "
            f"rank: 6k = {6 * r.k}, rank {r.rank}: q = {r.redundant['count']}, dof "
            f"{r.dof_total} = {r.mobility} main + {r.local_mobilities['count']} local"]


def write_csv(items, path: Path) -> Path:
    """One row per joint of each (mechanism, result): the table's columns, the pair class."""
    rows = []
    for mech, result in items:
        table = mobility_table(mech)
        for j in mech.joints:
            row = table["rows"][j.name]
            rows.append([mech.name, j.name, f"p{j.f}", *(row[c] for c in COLUMNS), row["other"]])
    return write_table(path, ["mechanism", "joint", "pair", *COLUMNS, "other"], rows)


def figure(mech: Mechanism, result: StructureResult):
    """Left: the kinematic scheme (links as lines between their joints, joints labelled with
    their pair class; frame joints black). Right: the seed's mobility table with the counts,
    the seed's axis reading and the rank method's directions."""
    import mpl_toolkits.mplot3d  # noqa: F401 - registers the 3d projection

    from ...cosim.results import PALETTE, new_figure

    fig = new_figure(figsize=(13, 5.6))
    ax = fig.add_axes((0.0, 0.02, 0.44, 0.9), projection="3d")
    _scheme(ax, mech, PALETTE)
    _table(fig, mech, result)
    fig.suptitle(f"Seed 002: {mech.name}, kinematic scheme and mobility table (seed's axis "
                 f"reading against the rank of the constraint Jacobian)", fontsize=10)
    return fig


def _scheme(ax, mech: Mechanism, palette) -> None:
    points = {j.name: np.array(j.point) for j in mech.joints}
    for colour, link in zip(palette[1:], mech.links):
        names = [j.name for j in mech.joints if link in j.between]
        pts = np.array([points[n] for n in names])
        if len(pts) > 1:
            loop = np.vstack([pts, pts[:1]]) if len(pts) > 2 else pts
            ax.plot(loop[:, 0], loop[:, 1], loop[:, 2], lw=2.2, color=colour, label=link)
    for j in mech.joints:
        x, y, z = points[j.name]
        grounded = "frame" in j.between
        ax.scatter([x], [y], [z], s=40, color="k" if grounded else "w", edgecolors="k",
                   depthshade=False)
        ax.text(x, y, z + 0.04, f"{j.name}: {_pair(j)}", fontsize=8)
    span = np.ptp(np.array(list(points.values())), axis=0)
    ax.set_box_aspect(np.maximum(span, 0.35 * span.max()))
    ax.set_xlabel("x [m] (pin axes)", fontsize=8)
    ax.set_ylabel("y [m] (stroke)", fontsize=8)
    ax.set_zlabel("z [m]", fontsize=8)
    ax.tick_params(labelsize=7)
    ax.view_init(elev=22, azim=-58)
    ax.legend(fontsize=7, loc="upper left", title="links (black: joint to the frame)",
              title_fontsize=7)


def _table(fig, mech: Mechanism, result: StructureResult) -> None:
    table = mobility_table(mech)
    cells = [[_pair(j)] + [str(table["rows"][j.name][c] or "") for c in COLUMNS]
             for j in mech.joints]
    cells.append(["sum"] + [str(table["sum"][c]) for c in COLUMNS])
    tax = fig.add_axes((0.47, 0.56, 0.51, 0.34))
    tax.axis("off")
    t = tax.table(cellText=cells, rowLabels=[j.name for j in mech.joints] + [""],
                  colLabels=["pair", "f_x lin.", "f_y lin.", "f_z lin.", "f_x ang.", "f_y ang.",
                             "f_z ang."], loc="upper center", cellLoc="center")
    t.auto_set_font_size(False)
    t.set_fontsize(8)
    t.scale(1.0, 1.3)
    try:
        reading = axis_reading(mech, result)
        seed = _wrap(f"seed's axis reading (loop {' - '.join(reading.loop)}): "
                     f"{len(reading.redundant)} redundant: "
                     f"{', '.join(reading.redundant) or 'none'}; linear closures: "
                     + ", ".join(f"{k} by {v}" for k, v in reading.closures.items()))
    except ValueError as err:
        seed = f"seed's axis reading: not applicable ({err})"
    rank = (f"rank method: q = {result.redundant['count']}"
            + "".join("\n" + _wrap(f"- {d}", "  ") for d in result.redundant["directions"]))
    if result.local_mobilities["count"]:
        rank += f"\nlocal mobilities {result.local_mobilities['count']}:" + "".join(
            "\n" + _wrap(f"- {d}", "  ") for d in result.local_mobilities["directions"])
    text = "\n".join(_count_lines(result)[0].split(";  ")) + "\n" + seed + "\n" + rank
    fig.text(0.47, 0.53, text, fontsize=7.5, va="top", family="monospace")


def _wrap(text: str, indent: str = "  ", width: int = 100) -> str:
    import textwrap
    return textwrap.fill(text, width, subsequent_indent=indent)
