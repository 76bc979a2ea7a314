"""Seed 001: "stopping at top dead centre is the design case" (`crankfmu analyze stopping`;
docs/papers.md, section 3).

The paper: the stop may begin in any position of the main shaft; "obviously" a stop at the top
dead centre (TDC, the end of the slider's idle return stroke) takes the most energy to
accelerate the ring and lasts longest, so the drive is to be designed for it, with the initial
speeds w_h = w_a0 i_ha^b = w_a0/(1 + p) (ring held) and w_a0 the sun's speed at the end of the
return stroke.

Checked on the conventional press scene (induction motor + planetary clutch drive + Stephenson
press rigidly on the carrier, scenarios/conventional_press.toml), where the press's reduced
inertia and its forging and weight moments act on the carrier through the stop: one stroke is
engaged from rest at the scene's first command edge, and the stop command is given when the
crank has turned a given angle past TDC (on the step grid: within one step of crank travel,
< 1 deg; the angle actually reached is reported). Per angle: the stop duration (command to the
carrier's lock), the energy each brake absorbs over it, the speeds and the drive's kinetic
energy at the command, the crank's travel until it stands. Each stop is a co-simulation of the
scene's FMUs with its master (tests/test_papers_claims.py compares two angles with the
monolithic rigid reference).
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ..errors import CrankfmuError
from ..outputs import write_table
from ..system.scene import SceneError

DEFAULT_ANGLES = tuple(float(a) for a in range(90, 361, 15))   # deg after TDC
TDC_ANGLE = 360.0      # deg: the stroke's end, one revolution after the TDC it starts from
STOP_WINDOW = 0.5      # s: the longest stop simulated after a command (the scene's: 0.23 s)
FREE_RUN = 1.0        # s: the stroke without a stop, from the engagement (the scene: 730 deg)
NEEDS = ("press.phi", "press.w_crank", "drive.w_a", "drive.w_h", "drive.E_kin",
         "drive.E_brake_b", "drive.E_brake_h", "drive.t_lock_b", "drive.n_lock_b",
         "drive.t_lock_h", "drive.n_lock_h")
TDC_BAND = 5.0         # deg: the sweep's angle nearest 360 deg counts as the TDC case within it



def _setup(scene_path):
    """(scene recording what the study needs, engagement time [s], crank angle of TDC [rad])."""
    from ..system.load import load_scene
    from .papers import _component

    scene = load_scene(scene_path)
    _component(scene, "drive", "PlanetaryClutchDrive")
    press = _component(scene, "press", "StephensonPress")
    if "driven_crank" not in press.effects:
        raise SceneError(scene.path, "components.press.effects",
                         "the study needs the press on the carrier (effect driven_crank)")
    command = scene.inputs.get("drive.command")
    edges = [t for t, a, b in zip(command.times[1:], command.values, command.values[1:])
             if a < 0.5 <= b] if command and len(command.times) > 1 else []
    if not edges:
        raise SceneError(scene.path, "inputs.drive.command",
                         "the study needs a command table with an engage edge (0 -> 1)")
    scene.record = list(dict.fromkeys(scene.record + list(NEEDS)))
    return scene, float(edges[0]), -0.5 * math.pi   # S = r sin phi + ...: least at -pi/2


def _run(scene, t_on: float, t_stop: float | None, stop_time: float) -> np.ndarray:
    from ..system.load import prepare_scene
    from ..system.scene import InputSignal
    from .papers import simulated

    times, values = [0.0, t_on], [0.0, 1.0]
    if t_stop is not None:
        times.append(t_stop)
        values.append(0.0)
    sc = prepare_scene(scene, stop_time=stop_time)
    sc.inputs["drive.command"] = InputSignal("drive.command", times, values, "step")
    return simulated(sc)


def stopping_sweep(scene_path, angles=DEFAULT_ANGLES) -> dict:
    """One stop per crank angle [deg after TDC] (see the module docstring). Returns arrays
    angle [deg, reached], t_command [s], w_crank, w_a [rad/s], E_kin [J] at the command;
    t_stop [s] (command to the carrier's lock), E_h, E_b [J] absorbed by the carrier and the
    ring brake over the stop, travel [deg] of the crank until it stands; and the scene's name."""
    from .papers import progress

    scene, t_on, phi_tdc = _setup(scene_path)
    step = scene.master.step
    angles = np.asarray(sorted(angles), dtype=float)
    progress(f"analyze stopping: the stroke without a stop, then {angles.size} stops")
    free = _run(scene, t_on, None, t_on + FREE_RUN)
    after_tdc = np.degrees(free["press.phi"] - phi_tdc)
    if free["drive.n_lock_b"][-1] < 1:
        raise CrankfmuError(f"{scene.path}: the ring does not lock within {FREE_RUN:g} s of the "
                         f"engagement: no working stroke to stop from")
    locked = float(np.interp(free["drive.t_lock_b"][-1], free["time"], after_tdc))
    if angles.max() > after_tdc[-1] or angles.min() <= locked:
        raise CrankfmuError(f"--angles {angles.min():g} ... {angles.max():g}: a stop starts from "
                            f"the working stroke, from the ring's lock at {locked:.1f} deg after "
                            f"TDC to {after_tdc[-1]:.1f} deg ({FREE_RUN:g} s after the "
                            f"engagement)")
    rows = []
    for n, angle in enumerate(angles, start=1):
        t_cmd = step * round(float(np.interp(angle, after_tdc, free["time"])) / step)
        v = _run(scene, t_on, t_cmd, t_cmd + STOP_WINDOW)
        k = int(np.argmin(np.abs(v["time"] - t_cmd)))
        if v["drive.n_lock_h"][-1] < 1 or v["drive.t_lock_h"][-1] <= t_cmd:
            raise CrankfmuError(f"{scene.path}: the carrier did not lock within {STOP_WINDOW} s of the stop "
                             f"command at {angle:g} deg")
        rows.append((np.degrees(v["press.phi"][k] - phi_tdc), t_cmd, v["press.w_crank"][k],
                     v["drive.w_a"][k], v["drive.E_kin"][k], v["drive.t_lock_h"][-1] - t_cmd,
                     v["drive.E_brake_h"][-1] - v["drive.E_brake_h"][k],
                     v["drive.E_brake_b"][-1] - v["drive.E_brake_b"][k],
                     np.degrees(v["press.phi"][-1] - v["press.phi"][k])))
        progress(f"  stop {n}/{angles.size} at {angle:g} deg: {rows[-1][5]:.4f} s")
    table = np.array(rows)
    keys = ("angle", "t_command", "w_crank", "w_a", "E_kin", "t_stop", "E_h", "E_b", "travel")
    out: dict = {k: table[:, j] for j, k in enumerate(keys)}
    out["scene"] = scene.name
    return out


def verdict(sweep: dict) -> list[str]:
    """The TDC case (the angle nearest 360 deg, within TDC_BAND) against the others."""
    k = int(np.argmin(np.abs(sweep["angle"] - TDC_ANGLE)))
    if abs(sweep["angle"][k] - TDC_ANGLE) > TDC_BAND or sweep["angle"].size < 2:
        return [f"no verdict on the paper's claim: it needs the TDC case (within {TDC_BAND:g} "
                f"deg of {TDC_ANGLE:g} deg) and other angles to compare with"]
    lines = []
    for key, name, unit, fmt in (("t_stop", "stop duration", "s", ".4f"),
                                 ("E_h", "carrier-brake energy", "J", ".0f"),
                                 ("E_kin", "drive's kinetic energy at the command", "J", ".0f")):
        x = sweep[key]
        j = int(np.argmax(x))
        lines.append(f"{name}: {x.min():{fmt}} ... {x.max():{fmt}} {unit}, largest at "
                     f"{sweep['angle'][j]:.1f} deg; at TDC ({sweep['angle'][k]:.1f} deg) "
                     f"{x[k]:{fmt}} {unit} ({100 * (x[k] / x.max() - 1):+.2f} % of the largest)")
    holds = (int(np.argmax(sweep["t_stop"])) == k and int(np.argmax(sweep["E_h"])) == k)
    lines.append("the paper's claim (a stop at TDC lasts longest and costs the most brake "
                 "energy, so it is the design case): " + ("holds" if holds else "FAILS")
                 + " over these angles")
    return lines


def format_table(sweep: dict) -> str:
    lines = [f"{sweep['scene']}: stop command at a crank angle after TDC, one engaged stroke",
             f"{'angle':>7} {'t_cmd':>7} {'w_crank':>8} {'w_a':>8} {'E_kin':>8} {'t_stop':>7} "
             f"{'E_brake_h':>9} {'E_brake_b':>9} {'travel':>7}",
             f"{'[deg]':>7} {'[s]':>7} {'[rad/s]':>8} {'[rad/s]':>8} {'[J]':>8} {'[s]':>7} "
             f"{'[J]':>9} {'[J]':>9} {'[deg]':>7}"]
    for j in range(sweep["angle"].size):
        lines.append(f"{sweep['angle'][j]:>7.1f} {sweep['t_command'][j]:>7.3f} "
                     f"{sweep['w_crank'][j]:>8.3f} {sweep['w_a'][j]:>8.3f} "
                     f"{sweep['E_kin'][j]:>8.0f} {sweep['t_stop'][j]:>7.4f} "
                     f"{sweep['E_h'][j]:>9.1f} {sweep['E_b'][j]:>9.2f} {sweep['travel'][j]:>7.1f}")
    return "\n".join(lines)


UNITS = {"angle": "deg", "t_command": "s", "w_crank": "rad/s", "w_a": "rad/s", "E_kin": "J",
         "t_stop": "s", "E_h": "J", "E_b": "J", "travel": "deg"}


def write_csv(sweep: dict, path: Path) -> Path:
    return write_table(path, [f"{k} [{u}]" for k, u in UNITS.items()],
                       ([sweep[k][j] for k in UNITS] for j in range(sweep["angle"].size)))


def figure(sweep: dict, forging: tuple[float, float] | None = (150.0, 180.0)):
    """Stop duration, brake energies and the state at the command against the command angle;
    TDC marked, the forging window (deg after TDC) shaded."""
    from ..cosim.results import PALETTE, axis_label, new_figure, style_axes

    fig = new_figure(figsize=(9, 8.5))
    ax = fig.subplots(3, 1, sharex=True)
    for x in ax:
        style_axes(x)
        if forging:
            x.axvspan(*forging, color="0.85", lw=0)
        x.axvline(TDC_ANGLE, color="0.3", lw=0.8, ls=":")
    a = sweep["angle"]
    ax[0].plot(a, sweep["t_stop"], "o-", ms=4, label="stop duration: command to carrier lock")
    ax[1].plot(a, sweep["E_h"] / 1e3, "o-", ms=4, label="carrier brake h, engaging (left)")
    ring = ax[1].twinx()
    ring.plot(a, sweep["E_b"], "s--", ms=4, color=PALETTE[1],
              label="ring brake b, releasing (right)")
    ring.set_ylabel(axis_label("ring brake", "J"), color=PALETTE[1])
    ax[2].plot(a, sweep["E_kin"] / 1e3, "o-", ms=4, color=PALETTE[2],
               label="drive's kinetic energy E_kin at the command (left)")
    twin = ax[2].twinx()
    twin.plot(a, sweep["travel"], "s--", ms=4, color=PALETTE[3],
              label="crank travel from the command to standstill (right)")
    twin.set_ylabel(axis_label("crank travel", "deg"), color=PALETTE[3])
    ax[0].set_ylabel(axis_label("stop duration", "s"))
    ax[1].set_ylabel(axis_label("carrier brake energy over the stop", "kJ"))
    ax[2].set_ylabel(axis_label("E_kin at the command", "kJ"))
    ax[2].set_xlabel(axis_label("crank angle at the stop command, after TDC", "deg"))
    ax[0].annotate("TDC", (TDC_ANGLE, 0.02), xycoords=("data", "axes fraction"),
                   xytext=(-4, 0), textcoords="offset points", ha="right", fontsize=8)
    if forging:
        ax[0].annotate("forging", (np.mean(forging), 0.02), xycoords=("data", "axes fraction"),
                       ha="center", fontsize=8, color="0.4")
    for left, right in ((ax[1], ring), (ax[2], twin)):
        h1, l1 = left.get_legend_handles_labels()
        h2, l2 = right.get_legend_handles_labels()
        left.legend(h1 + h2, l1 + l2, fontsize=7, loc="upper left")
    ax[0].legend(fontsize=7, loc="upper left")
    ax[0].set_title(f"Seed 001: stopping from a crank angle against stopping at TDC "
                    f"({sweep['scene']}, co-simulation)", fontsize=10)
    fig.tight_layout()
    return fig


def forging_window(scene_path) -> tuple[float, float] | None:
    """The press's forging window [deg after TDC] (None without effect forging_load)."""
    from ..system.load import load_scene

    press = load_scene(scene_path).components["press"]
    if "forging_load" not in press.effects:
        return None
    from ..models.stephenson_press.stephenson_press import StephensonPress
    width = math.degrees(StephensonPress(press.parameters, press.effects).p.forging_angle)
    return 180.0 - width, 180.0     # the window ends at BDC
