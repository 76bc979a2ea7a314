"""The servo press's non-uniformity against the flywheel, from a sweep, with the paper's
analysis beside it (crankfmu.studies.press_analysis; nothing here re-derives it):

    delta_1(J_f)   first approximation of delta (eq. 18-20, with the armature lag eq. 32-35 when
                   the scene's motor has the effect electrical_lag)
    J_Mx           eq. (28) (theta = 0, harmonic l = 1): the flywheel that minimises the ratio
                   (26) of the moment through the gear to the disturbance; reduced to the crank
                   by the paper, divided by i^2 here to give the motor-shaft value J_f
    sqrt(26)(J_f)  that ratio, minimal at J_Mx

`crankfmu analyze flywheel DIR/sweep.csv --scene SCENE --plot PNG` prints the table and draws
delta from the sweep (points) and delta_1 (line) against J_f, (28) marked, sqrt(26) on the
right axis.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

PARAMETER = "motor.J_flywheel"


def analytic(scene, J_f: np.ndarray, motor: str = "motor", press: str = "press") -> dict:
    """delta_1, sqrt(26) on J_f [kg m^2, motor shaft], and J_Mx of (28) on the motor shaft."""
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
    base = drive(0.0)
    err = pa.dynamic_error(base)
    i2 = model.p.gear_ratio ** 2
    W, J_D, J_M0, s = err.omega0, base.J_D, err.J0 - base.J_D, err.s
    return {
        "delta_1": np.array([pa.dynamic_error(drive(j), lag=lag).delta for j in J_f]),
        "ratio_26": np.array([math.sqrt(pa.flywheel_ratio(j * i2, W, J_D, J_M0, s))
                              for j in J_f]),
        "J_Mx": pa.flywheel_inertia_theta0(W, J_D, J_M0, s) / i2,
        "J_Mx_crank": pa.flywheel_inertia_theta0(W, J_D, J_M0, s),
        "omega0": W, "lag": lag,
    }


def report(table_csv: Path, scene, plot: Path | None = None) -> str:
    from .sweep import read_table

    header, rows = read_table(table_csv)
    if PARAMETER not in header:
        raise ValueError(f"{table_csv}: no column {PARAMETER} (sweep --vary {PARAMETER}=...)")
    rows = sorted((r for r in rows if r["status"] == "completed"), key=lambda r: r[PARAMETER])
    J = np.array([r[PARAMETER] for r in rows])
    delta = np.array([r["delta"] for r in rows])
    a = analytic(scene, J)
    lines = [f"{'J_flywheel [kg m^2]':>20}{'delta (sweep)':>15}{'delta_1':>10}{'sqrt(26)':>10}"]
    for j, d, d1, r26 in zip(J, delta, a["delta_1"], a["ratio_26"]):
        lines.append(f"{j:>20.4g}{d:>15.4%}{d1:>10.4%}{r26:>10.4f}")
    lines.append(f"(28): J_Mx = {a['J_Mx_crank']:.4g} kg m^2 at the crank = {a['J_Mx']:.4g} "
                 f"kg m^2 on the motor shaft (l = 1, omega0 = {a['omega0']:.5g} rad/s)")
    if plot:
        fine = np.linspace(0.0, max(float(J.max()), 1.2 * a["J_Mx"]), 61)
        _plot(plot, J, delta, a, fine, analytic(scene, fine), scene.name)
    return "\n".join(lines)


def _plot(path: Path, J, delta, a: dict, fine, af: dict, name: str) -> None:
    from ..cosim.results import PALETTE, new_figure

    fig = new_figure(figsize=(8, 4.6))
    ax = fig.subplots()
    ax.plot(J, 100 * delta, "o", color=PALETTE[0], label="co-simulation (crankfmu sweep)")
    ax.plot(fine, 100 * af["delta_1"], "-", color=PALETTE[0], lw=1.0, alpha=0.6,
            label="first approximation" + (" with armature lag" if a["lag"] else ""))
    ax.axvline(a["J_Mx"], color=PALETTE[3], ls="--", lw=1.0)
    ax.annotate(f"(28): J_Mx = {a['J_Mx']:.3f} kg.m2", (a["J_Mx"], 0.97),
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
    fig.savefig(path, dpi=110)
