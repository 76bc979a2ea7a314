"""Seed 000, Fig. 4 and the "built-in counterweight" claim: the servo press's non-uniformity
against the mass of the base link (link 2), with gravity on and off, and against a real
counterweight on the crank (`crankfmu analyze press`; docs/stephenson_press_analysis.md,
section 11).

The paper: "the base link, with a suitable geometry and mass, can act as a built-in
counterweight, substantially reducing the non-uniformity". Link 2 translates with the crank pin
(the model card), so it is a point mass m2 AT the pin: inertia m2 r^2 at the crank (a flywheel
of r^2 per kilogram) and weight moment +m2 g r cos phi, which adds to the slider's weight
moment m5 g S' ~ m5 g r cos phi. A counterweight is a mass OPPOSITE the pin: the same inertia,
the opposite weight moment (`papers.CrankMass`). Three cases, each at every mass of a grid:

    base link, gravity on      m2 varied, the scene's effects
    base link, gravity off     m2 varied, effect gravity removed
    counterweight              a point mass on the crank at radius r opposite the pin, the
                               scene's m2 and effects (gravity on)

For each: delta of the periodic steady state of motor + press (`papers.press_steady_revolution`,
the FMUs' equations as one ODE: the "simulation"), delta of the first approximation
(`press_analysis.dynamic_error`, with the armature lag when the scene's motor has it), the first
harmonic L_1 of the disturbance moment and the constant inertia J0.
"""
from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from ..outputs import write_table

CASES = ("base link, gravity on", "base link, gravity off", "counterweight on the crank")
DEFAULT_MASSES = tuple(float(m) for m in range(0, 401, 20))   # kg: the shipped 20 and 200 on it



def scene_drive(scene):
    """(press, motor as the scene has it, u0 [V], lag) of a servo press scene."""
    from .papers import press_models

    press, static, lagging, u0 = press_models(scene)
    lag = "electrical_lag" in scene.components["motor"].effects
    return press, (lagging if lag else static), u0, lag


def _case_models(press, case: str, mass: float):
    """(press, crank mass or None) of one case at one mass [kg]."""
    from ..models.stephenson_press.stephenson_press import StephensonPress
    from .papers import CrankMass

    effects = sorted(press.enabled)
    if case == CASES[2]:
        return press, CrankMass(mass, press.p.r, press.p.g)
    if case == CASES[1]:
        effects = [e for e in effects if e != "gravity"]
    return StephensonPress({**vars(press.p), "m2": mass}, effects), None


def _first_approximation(press, motor, u0: float, lag: bool, crank_mass):
    """press_analysis.dynamic_error of the drive, a crank mass added to J and M_C."""
    from . import press_analysis as pa

    drive = pa.ReducedDrive.from_models(press, motor, u0)
    if crank_mass is not None:
        J, M_C = drive.J, drive.M_C
        drive = replace(drive, J=lambda phi: J(phi) + crank_mass.inertia,
                        M_C=lambda phi: M_C(phi) + crank_mass.moment(phi))
    return pa.dynamic_error(drive, lag=lag)


def mass_sweep(scene, masses=DEFAULT_MASSES, cases=CASES) -> dict:
    """{case: {"mass", "delta_sim", "delta_1", "L1", "J0"}} (arrays over `masses` [kg]; delta
    [1], L1 [N m], J0 [kg m^2]) plus "lag" and "m2_scene" [kg]. Progress on stderr."""
    from .papers import press_steady_revolution
    from .progress import progress, progress_over

    from .flywheel import eq28_conventions

    press, motor, u0, lag = scene_drive(scene)
    masses = np.unique(np.asarray(masses, dtype=float))
    out = {"lag": lag, "m2_scene": press.p.m2, "r": press.p.r,
           "J_Mx": eq28_conventions(press, motor, u0)["mean"]["J_Mx"]}
    for case in cases:
        progress(f"analyze press: {case}, {masses.size} masses")
        rows = []
        for m in progress_over(masses, f"analyze press: {case}", "mass"):
            p, cm = _case_models(press, case, float(m))
            err = _first_approximation(p, motor, u0, lag, cm)
            rev = press_steady_revolution(p, motor, u0, crank_mass=cm)
            rows.append((rev.delta, err.delta, err.L.amp[0], err.J0))
        table = np.array(rows)
        out[case] = {"mass": masses, "delta_sim": table[:, 0], "delta_1": table[:, 1],
                     "L1": table[:, 2], "J0": table[:, 3]}
    return out


def _at(d: dict, mass: float) -> int:
    """Index of a swept mass [kg] (the nearest one)."""
    return int(np.argmin(np.abs(d["mass"] - mass)))


def claim_verdict(sweep: dict, m_low: float | None = None, m_high: float | None = None) -> list:
    """What the sweep says about the claim, from the simulated delta: the change from m_low
    (default the scene's m2) to m_high (default 10 m_low if swept, else the largest mass) in
    each base-link case, the base link as a flywheel, the best counterweight."""
    on, off, cw = (sweep[c] for c in CASES)
    swept = on["mass"]
    if m_low is None:
        m_low = sweep["m2_scene"] if np.any(swept == sweep["m2_scene"]) else swept.min()
    if m_high is None:
        m_high = 10 * m_low if m_low > 0 and np.any(swept == 10 * m_low) else swept.max()
    if m_high <= m_low:
        return ["no verdict on the claim: the sweep needs two masses"]
    lines, change = [], {}
    for name, d in (("gravity on", on), ("gravity off", off)):
        a, b = d["delta_sim"][_at(d, m_low)], d["delta_sim"][_at(d, m_high)]
        change[name] = b / a - 1
        lines.append(f"base link {m_low:g} -> {m_high:g} kg, {name}: delta {100 * a:.2f} % -> "
                     f"{100 * b:.2f} % ({100 * change[name]:+.1f} % relative)")
    k = int(np.argmin(cw["delta_sim"]))
    best = cw["delta_sim"][k] / cw["delta_sim"][0] - 1
    lines.append(f"counterweight opposite the pin, gravity on: delta lowest at {cw['mass'][k]:g} kg, "
                 f"{100 * cw['delta_sim'][k]:.2f} % ({100 * best:+.1f} % relative to "
                 f"{cw['mass'][0]:g} kg)")
    r2 = sweep["r"] ** 2
    lines.append(f"link 2 translates with the crank pin: a kilogram of it is a flywheel of "
                 f"r^2 = {r2:.4g} kg.m2 at the crank; the (28) flywheel, {sweep['J_Mx']:.2f} "
                 f"kg.m2 at the crank, would take {sweep['J_Mx'] / r2:.0f} kg of base link")
    holds = change["gravity on"] < 0   # a press has weights: the claim is about this case
    lines.append("the claim that the base link is a built-in counterweight reducing the "
                 "non-uniformity: " + ("holds" if holds else "FAILS") +
                 f": its weight acts at the pin and adds to the first harmonic (delta "
                 f"{'falls' if change['gravity on'] < 0 else 'rises'} with gravity); without "
                 f"gravity it helps only as that small flywheel ({100 * change['gravity off']:+.1f} "
                 f"% from {m_low:g} to {m_high:g} kg)")
    return lines


def format_table(sweep: dict) -> str:
    cell = "delta sim [%]  delta_1 [%]  L_1 [N m]"
    head = f"{'mass [kg]':>10}" + "".join(f" | {c:^{len(cell)}}" for c in CASES)
    sub = f"{'':>10}" + f" | {cell}" * len(CASES)
    lines = [f"Seed 000, Fig. 4: non-uniformity against the mass (simulation: motor + press as "
             f"one ODE; delta_1: first approximation{', armature lag' if sweep['lag'] else ''})",
             head, sub]
    d0 = sweep[CASES[0]]
    for k, m in enumerate(d0["mass"]):
        cells = "".join(f" | {100 * sweep[c]['delta_sim'][k]:>13.4f}  "
                        f"{100 * sweep[c]['delta_1'][k]:>11.4f}  {sweep[c]['L1'][k]:>9.2f}"
                        for c in CASES)
        lines.append(f"{m:>10g}{cells}")
    return "\n".join(lines)


def write_csv(sweep: dict, path: Path) -> Path:
    return write_table(path, ["case", "mass [kg]", "delta_sim [1]", "delta_1 [1]", "L_1 [N.m]",
                              "J0 [kg.m2]"],
                       ([c, sweep[c]["mass"][k], sweep[c]["delta_sim"][k], sweep[c]["delta_1"][k],
                         sweep[c]["L1"][k], sweep[c]["J0"][k]]
                        for c in CASES for k in range(sweep[c]["mass"].size)))


def figure(sweep: dict):
    """Top: delta against the mass, simulation (markers) and first approximation (lines), the
    three cases; the scene's m2 marked. Bottom: the first harmonic L_1 of the disturbance, the
    reason."""
    from ..cosim.results import PALETTE, axis_label, new_figure, style_axes

    fig = new_figure(figsize=(9, 7.5))
    ax = fig.subplots(2, 1, sharex=True)
    for a in ax:
        style_axes(a)
    for colour, case in zip(PALETTE, CASES):
        d = sweep[case]
        ax[0].plot(d["mass"], 100 * d["delta_sim"], "o", ms=4, color=colour,
                   label=f"{case}: simulation")
        ax[0].plot(d["mass"], 100 * d["delta_1"], "-", lw=1.0, color=colour,
                   label=f"{case}: first approximation")
        ax[1].plot(d["mass"], d["L1"], "-", lw=1.4, color=colour, label=case)
    for a in ax:
        a.axvline(sweep["m2_scene"], color="0.4", lw=0.8, ls=":")
    ax[0].annotate(f"the scene's m2 = {sweep['m2_scene']:g} kg", (sweep["m2_scene"], 0.03),
                   xycoords=("data", "axes fraction"), xytext=(4, 0), textcoords="offset points",
                   fontsize=8, va="bottom", color="0.3")
    ax[0].set_ylabel(axis_label("non-uniformity delta", "%"))
    ax[1].set_ylabel(axis_label("first harmonic L_1 of the disturbance", "N.m"))
    ax[1].set_xlabel(axis_label("mass of the base link m2, or of the counterweight", "kg"))
    ax[0].legend(fontsize=7, loc="upper left")
    ax[1].legend(fontsize=7, loc="upper left")
    ax[0].set_title("Seed 000, Fig. 4: base-link mass with gravity on and off, against a "
                    "counterweight opposite the crank pin", fontsize=10)
    fig.tight_layout()
    return fig
