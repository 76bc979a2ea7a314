"""The servo press's non-uniformity against the flywheel, from a sweep, with the paper's
analysis beside it (crankfmu.studies.press_analysis; nothing here re-derives it):

    delta_1(J_f)   first approximation of delta (eq. 18-20, with the armature lag eq. 32-35 when
                   the scene's motor has the effect electrical_lag)
    J_Mx           eq. (28) (theta = 0, harmonic l = 1): the flywheel that minimises the ratio
                   (26) of the moment through the gear to the disturbance; reduced to the crank
                   by the paper, divided by i^2 here to give the motor-shaft value J_f
    sqrt(26)(J_f)  that ratio, minimal at J_Mx

(28) needs J_M0, the constant inertia besides the drive, and the paper and the product read it
differently (`eq28_conventions`): the paper J1 + J_2O, the product the mean of J(phi) - J_D,
which adds m5 <S'^2>. Both are offered; `crankfmu analyze press` tabulates them.

`crankfmu analyze flywheel DIR/sweep.csv --scene SCENE --out DIR --plot` prints the table and
draws delta from the sweep (points) and delta_1 (line) against J_f, (28) marked, sqrt(26) on
the right axis.
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from ..outputs import write_table

PARAMETER = "motor.J_flywheel"


CONVENTIONS = {"paper": "J_M0 = J1 + J_2O (the paper's (26))",
               "mean": "J_M0 = mean of J(phi) - J_D = J1 + J_2O + m5 <S'^2> (the product)"}


def eq28_conventions(press, motor, u0: float) -> dict:
    """Eq. (28) (theta = 0, l = 1) with J_M0 in both conventions:

        paper  J_M0 = J1 + J_2O = J1 + m2 r^2 (press.J_constant(0): eq. 22's J0 without the
               drive), so that m5 S'^2 stays in the variable part J~;
        mean   J_M0 = <J> - J_D, the mean of the reduced inertia without the drive: the J0 of
               the first approximation (19), which needs J~ of zero mean (press_analysis).

    They differ by m5 <S'^2> (and the rods' mean, effect rod_inertia). Returns omega0 [rad/s],
    J_D [kg m^2], s [N m s/rad], and per convention J_M0 and J_Mx [kg m^2] at the crank and on
    the motor shaft (/ i^2); "relative" = J_Mx(mean)/J_Mx(paper) - 1."""
    from . import press_analysis as pa

    drive = pa.ReducedDrive.from_models(press, motor, u0)
    W, J_D, s = pa.mean_speed(drive), drive.J_D, drive.s
    i2 = press.p.gear_ratio ** 2
    out: dict[str, Any] = {"omega0": W, "J_D": J_D, "s": s}
    for name, J_M0 in (("paper", press.J_constant(0.0)),
                       ("mean", pa.mean_inertia(drive) - J_D)):
        J_Mx = pa.flywheel_inertia_theta0(W, J_D, J_M0, s)
        out[name] = {"J_M0": J_M0, "J_Mx": J_Mx, "J_Mx_motor": J_Mx / i2}
    out["relative"] = out["mean"]["J_Mx"] / out["paper"]["J_Mx"] - 1.0
    return out


def eq28_against(press, motor, u0: float, parameter: str = "m5", values=None) -> dict:
    """J_Mx on the motor shaft [kg m^2] in both conventions and their relative difference, over
    one press parameter (default the slider mass m5 [kg], 0 ... 1000: the conventions differ by
    m5 <S'^2>, so the difference grows with it). "scene" is the scene's value."""
    from ..models.stephenson_press.stephenson_press import StephensonPress

    values = np.linspace(0.0, 1000.0, 41) if values is None else np.asarray(values, dtype=float)
    rows = []
    for v in values:
        c = eq28_conventions(StephensonPress({**vars(press.p), parameter: float(v)},
                                             sorted(press.enabled)), motor, u0)
        rows.append((c["paper"]["J_Mx_motor"], c["mean"]["J_Mx_motor"], c["relative"]))
    table = np.array(rows)
    return {"parameter": parameter, "values": values, "J_Mx_paper": table[:, 0],
            "J_Mx_mean": table[:, 1], "relative": table[:, 2],
            "scene": getattr(press.p, parameter)}


def format_conventions(conv: dict, name: str) -> str:
    lines = [f"{name}: eq. (28), l = 1, theta = 0, omega0 = {conv['omega0']:.5g} rad/s, "
             f"J_D = {conv['J_D']:.5g} kg.m2, s = {conv['s']:.5g} N.m.s/rad",
             f"{'convention':>10} {'J_M0 [kg.m2]':>14} {'J_Mx crank [kg.m2]':>20} "
             f"{'J_Mx motor [kg.m2]':>20}"]
    for c in ("paper", "mean"):
        d = conv[c]
        lines.append(f"{c:>10} {d['J_M0']:>14.6f} {d['J_Mx']:>20.6f} {d['J_Mx_motor']:>20.7f}"
                     f"   {CONVENTIONS[c]}")
    lines.append(f"difference (mean - paper)/paper: {100 * conv['relative']:+.3f} % "
                 f"(J_M0 differs by {conv['mean']['J_M0'] - conv['paper']['J_M0']:.6f} kg.m2)")
    return "\n".join(lines)


def analytic(scene, J_f: np.ndarray, motor: str = "motor", press: str = "press") -> dict:
    """delta_1, sqrt(26) on J_f [kg m^2, motor shaft], and J_Mx of (28) on the motor shaft
    (the product's convention; "J_Mx_paper" the paper's)."""
    from . import press_analysis as pa
    from ..models.dc_motor.dc_motor import DcServoMotor
    from ..models.stephenson_press.stephenson_press import StephensonPress

    p, m = scene.components[press], scene.components[motor]
    u0 = scene.inputs[f"{motor}.u"].values[0]
    model = StephensonPress(p.parameters, p.effects)
    lag = "electrical_lag" in m.effects

    def drive(jf):
        return pa.ReducedDrive.from_models(
            model, DcServoMotor({**m.parameters, "J_flywheel": float(jf)}, m.effects), u0)
    conv = eq28_conventions(model, DcServoMotor({**m.parameters, "J_flywheel": 0.0}, m.effects),
                            u0)
    i2 = model.p.gear_ratio ** 2
    W, J_D, J_M0, s = conv["omega0"], conv["J_D"], conv["mean"]["J_M0"], conv["s"]
    from .progress import progress_over
    return {
        "delta_1": np.array([pa.dynamic_error(drive(j), lag=lag).delta for j in
                             progress_over(J_f, "analyze flywheel", "flywheel")]),
        "ratio_26": np.array([math.sqrt(pa.flywheel_ratio(j * i2, W, J_D, J_M0, s))
                              for j in J_f]),
        "J_Mx": conv["mean"]["J_Mx_motor"], "J_Mx_crank": conv["mean"]["J_Mx"],
        "J_Mx_paper": conv["paper"]["J_Mx_motor"], "omega0": W, "lag": lag,
    }


def report(table_csv: Path, scene, out_dir: Path | None = None, plot: bool = False):
    """(text, written paths): the sweep's delta beside delta_1 and sqrt(26), (28) in both
    conventions; flywheel.csv in out_dir (if given), flywheel.png there with `plot`."""
    from .sweep import read_table

    header, rows = read_table(table_csv)
    if PARAMETER not in header:
        raise ValueError(f"{table_csv}: no column {PARAMETER} (sweep --vary {PARAMETER}=...)")
    rows = sorted((r for r in rows if r["status"] == "completed"), key=lambda r: r[PARAMETER])
    J = np.array([r[PARAMETER] for r in rows])
    delta = np.array([r["delta"] for r in rows])
    a = analytic(scene, J)
    lines = [f"{'J_flywheel [kg.m2]':>20}{'delta (sweep)':>15}{'delta_1':>10}{'sqrt(26)':>10}"]
    for j, d, d1, r26 in zip(J, delta, a["delta_1"], a["ratio_26"]):
        lines.append(f"{j:>20.4g}{d:>15.4%}{d1:>10.4%}{r26:>10.4f}")
    lines.append(f"(28): J_Mx = {a['J_Mx_crank']:.4g} kg.m2 at the crank = {a['J_Mx']:.4g} "
                 f"kg.m2 on the motor shaft (l = 1, omega0 = {a['omega0']:.5g} rad/s)")
    lines.append(f"      in the paper's convention J_M0 = J1 + J_2O: J_Mx = {a['J_Mx_paper']:.4g} "
                 f"kg.m2 on the motor shaft ({100 * (a['J_Mx'] / a['J_Mx_paper'] - 1):+.2f} % "
                 f"from it: the product's J_M0 adds m5 <S'^2>)")
    written = []
    if out_dir is not None:
        written.append(_write_csv(Path(out_dir) / "flywheel.csv", J, delta, a))
        if plot:
            fine = np.linspace(0.0, max(float(J.max()), 1.2 * a["J_Mx"]), 61)
            written.append(Path(out_dir) / "flywheel.png")
            _plot(written[-1], J, delta, a, fine, analytic(scene, fine), scene.name)
    return "\n".join(lines), written


def _write_csv(path: Path, J, delta, a: dict) -> Path:
    return write_table(path, ["J_flywheel [kg.m2]", "delta sweep [1]", "delta_1 [1]",
                              "sqrt(26) [1]"], zip(J, delta, a["delta_1"], a["ratio_26"]))


def _plot(path: Path, J, delta, a: dict, fine, af: dict, name: str) -> None:
    from ..cosim.results import PALETTE, new_figure, save_figure

    fig = new_figure(figsize=(8, 4.6))
    ax = fig.subplots()
    ax.plot(J, 100 * delta, "o", color=PALETTE[0], label="co-simulation (crankfmu sweep)")
    ax.plot(fine, 100 * af["delta_1"], "-", color=PALETTE[0], lw=1.0, alpha=0.6,
            label="first approximation" + (" with armature lag" if a["lag"] else ""))
    ax.axvline(a["J_Mx"], color=PALETTE[3], ls="--", lw=1.0)
    ax.annotate(f"(28): J_Mx = {a['J_Mx']:.4f} kg.m2 (paper's J_M0: {a['J_Mx_paper']:.4f})",
                (a["J_Mx"], 0.97),
                xycoords=("data", "axes fraction"), xytext=(6, 0), textcoords="offset points",
                color=PALETTE[3], fontsize=9, va="top")
    ax.set_xlabel("flywheel on the motor shaft, motor.J_flywheel [kg.m2]")
    ax.set_ylabel("non-uniformity delta [%]")
    ax.set_ylim(bottom=0.0)
    ax.grid(alpha=0.3)
    ax2 = ax.twinx()
    ax2.plot(fine, af["ratio_26"], "-", color="0.45", lw=1.2,
             label="sqrt(26): gear moment / disturbance (right)")
    ax2.set_ylabel("sqrt(26) [1]", color="0.35")
    h1, l1 = ax.get_legend_handles_labels()
    h2, l2 = ax2.get_legend_handles_labels()
    ax.legend(h1 + h2, l1 + l2, loc="upper right", fontsize=8, bbox_to_anchor=(1.0, 0.88))
    ax.set_title(f"{name}: delta against the flywheel; (28) minimises the gear moment, not delta",
                 fontsize=10)
    fig.tight_layout()
    save_figure(fig, path, dpi=110)


def write_conventions(conv: dict, path: Path) -> Path:
    """`eq28_conventions` as CSV: one row per convention."""
    return write_table(path, ["convention", "J_M0 [kg.m2]", "J_Mx at the crank [kg.m2]",
                              "J_Mx on the motor shaft [kg.m2]", "relative to the paper's [1]"],
                       ([c, conv[c]["J_M0"], conv[c]["J_Mx"], conv[c]["J_Mx_motor"],
                         conv[c]["J_Mx"] / conv["paper"]["J_Mx"] - 1.0]
                        for c in ("paper", "mean")))
