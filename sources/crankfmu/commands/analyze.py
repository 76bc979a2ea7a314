"""`crankfmu analyze impact`: the rocker impact paper's table and which of its claims hold;
`crankfmu analyze hammer CSV`: the blows of a hammer run (hammer.toml, hammer_bearings.toml);
`crankfmu analyze flywheel DIR/sweep.csv`: the servo press's delta against the flywheel from a
sweep, with the paper's eq. (28) (crankfmu/studies/flywheel.py);
`crankfmu analyze press|impact|planetary --plot DIR`: the papers' figures, each analytic curve
beside the simulation it approximates (crankfmu/studies/papers.py)."""
from __future__ import annotations

from pathlib import Path

import numpy as np


def register(sub) -> None:
    p = sub.add_parser("analyze", help="analytic results of the papers")
    what = p.add_subparsers(dest="analysis", required=True)
    impact = what.add_parser("impact", help="MO-100 table: Pm, tau, Tm, Tm/Pm, max dP, max dT "
                                            "per k_n, both readings of S, and the paper's claims")
    for name, unit in (("J", "kg.m2"), ("m", "kg"), ("r", "m"), ("R_c", "m"), ("d", "m"),
                       ("E", "Pa"), ("rho", "kg/m3"), ("nu", "1"), ("V0", "m/s")):
        impact.add_argument(f"--{name}", type=float, help=f"[{unit}] (default: MO-100)")
    impact.add_argument("--k-n", type=float, nargs="+", default=[40e6, 80e6, 160e6],
                        help="support constants k_n [N(2/3)/m]")
    impact.add_argument("--S-factor", type=float, nargs="+", default=[1.1, 0.9],
                        help="strike distance S as a multiple of the centre of percussion J/(m r)")
    impact.add_argument("--plot", type=Path, metavar="DIR",
                        help="write impact_forces.png (seed 004, Fig. 2-3: P(t), T(t), first and "
                             "second approximation against the run of --scene) into DIR")
    impact.add_argument("--scene", type=Path, default=Path("scenarios/mo100_impact.toml"),
                        help="the impact scene run for --plot (default "
                             "scenarios/mo100_impact.toml)")
    impact.set_defaults(func=run_impact)
    press = what.add_parser("press", help="seed 000's figures: dynamic errors, base-link "
                                          "inertia with offset a, flywheel (--plot DIR)")
    press.add_argument("--plot", type=Path, metavar="DIR", required=True,
                       help="directory for press_dynamic_error.png, press_base_link.png, "
                            "press_flywheel.png")
    press.add_argument("--scene", type=Path, default=Path("scenarios/servo_press.toml"),
                       help="the servo press scene whose parameters are used (default "
                            "scenarios/servo_press.toml)")
    press.set_defaults(func=run_press)
    planetary = what.add_parser("planetary", help="seed 001's figures: the four periods, "
                                                  "engagement time against alpha_b, brake "
                                                  "torque for an engagement time (--plot DIR)")
    planetary.add_argument("--plot", type=Path, metavar="DIR", required=True,
                           help="directory for planetary.png")
    planetary.add_argument("--scene", type=Path,
                           default=Path("scenarios/planetary_engagement.toml"),
                           help="the planetary drive scene (motor and drive parameters; default "
                                "scenarios/planetary_engagement.toml)")
    planetary.set_defaults(func=run_planetary)
    hammer = what.add_parser("hammer", help="blow table of a hammer run (CSV of hammer.toml or "
                                            "hammer_bearings.toml); --plot PNG")
    hammer.add_argument("csv", type=Path, nargs="+", help="result CSV(s) of a hammer scene")
    hammer.add_argument("--component", default="hammer", help="the CrankRockerHammer component")
    hammer.add_argument("--plot", type=Path, help="PNG: motor torque, crank speed, P and T peaks")
    hammer.set_defaults(func=run_hammer)
    fly = what.add_parser("flywheel", help="servo press delta against motor.J_flywheel from a "
                                           "sweep's sweep.csv, with eq. (28) and the first "
                                           "approximation; --plot PNG")
    fly.add_argument("csv", type=Path, help="sweep.csv of crankfmu sweep --vary motor.J_flywheel=...")
    fly.add_argument("--scene", type=Path, default=Path("scenarios/servo_press.toml"),
                     help="the swept scene (default scenarios/servo_press.toml)")
    fly.add_argument("--plot", type=Path, help="PNG: delta against J_flywheel, (28) marked")
    fly.set_defaults(func=run_flywheel)


def run_flywheel(args) -> int:
    from ..system.load import load_scene
    from ..studies.flywheel import report

    print(report(args.csv, load_scene(args.scene), args.plot))
    if args.plot:
        print(f"wrote {args.plot}")
    return 0


def run_impact(args) -> int:
    from ..studies.rocker_analysis import (RockerData, claims, format_claims, format_impact_table,
                                           impact_table)

    if args.plot:  # bad --plot or --scene fails before the table is computed
        out, scene = _plot_dir(args.plot), _scene_file(args.scene)
    changes = {k: getattr(args, k) for k in ("J", "m", "r", "R_c", "d", "E", "rho", "nu", "V0")
               if getattr(args, k) is not None}
    rows = impact_table(RockerData(**changes), args.S_factor, args.k_n)
    print(format_impact_table(rows))
    print()
    print(format_claims(claims(rows)))
    if args.plot:
        from ..studies.papers import impact_figures
        _written(impact_figures(scene, out))
    return 0


def run_press(args) -> int:
    from ..system.load import load_scene
    from ..studies.papers import press_figures

    out = _plot_dir(args.plot)
    _written(press_figures(load_scene(_scene_file(args.scene)), out))
    return 0


def run_planetary(args) -> int:
    from ..studies.papers import planetary_figures

    out = _plot_dir(args.plot)
    _written(planetary_figures(_scene_file(args.scene), out))
    return 0


def _plot_dir(path: Path) -> Path:
    """--plot DIR: created if missing; an existing file there is an error (exit 2)."""
    from ..errors import CrankfmuError

    if path.exists() and not path.is_dir():
        raise CrankfmuError(f"--plot {path}: is a file; --plot takes a directory for the PNGs")
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise CrankfmuError(f"--plot {path}: cannot create the directory ({err.strerror})")
    return path


def _scene_file(path: Path) -> Path:
    from ..errors import CrankfmuError

    if not path.is_file():
        raise CrankfmuError(f"--scene {path}: no such scene file (run from the repository root "
                            "or give --scene)")
    return path


def _written(paths) -> None:
    for path in paths:
        print(f"wrote {path}")


# -- hammer runs -------------------------------------------------------------------------------
def read_columns(csv: Path) -> dict[str, np.ndarray]:
    """Columns of a result CSV by name (the runner's layout: a header row, then numbers)."""
    with open(csv) as f:
        names = f.readline().strip().split(",")
    data = np.loadtxt(csv, delimiter=",", skiprows=1, ndmin=2)
    return {n.strip('"'): data[:, k] for k, n in enumerate(names)}


def hammer_blows(col: dict[str, np.ndarray], comp: str = "hammer") -> list[dict]:
    """One row per impact: time of the first sample that saw it, strike speed, and the exact
    peaks the FMU located, read at the last sample of that impact's record (before the next
    impact begins, with the contact over, so the peaks are final)."""
    n = col[f"{comp}.n_impacts"]
    contact = col.get(f"{comp}.contact", np.zeros_like(n))
    first = np.nonzero(np.diff(n) > 0)[0] + 1
    blows = []
    for k, i in enumerate(first):
        j = (first[k + 1] - 1) if k + 1 < len(first) else len(n) - 1
        if contact[j]:
            continue          # the run ended inside this impact: its peaks are not final
        blows.append({"n": int(n[i]), "t": float(col["time"][i]),
                      "V_impact": float(col[f"{comp}.V_impact"][j]),
                      "P_peak": float(col[f"{comp}.P_peak"][j]),
                      "T_peak": float(col[f"{comp}.T_peak"][j]),
                      "phi": float(col[f"{comp}.phi"][i] % (2 * np.pi))
                      if f"{comp}.phi" in col else float("nan")})
    return blows


def format_blows(blows: list[dict], title: str) -> str:
    lines = [title, f"{'blow':>4} {'t [s]':>7} {'crank [rad]':>11} {'V [m/s]':>8} "
                    f"{'P_peak [kN]':>11} {'T_peak [kN]':>11} {'T/P [%]':>8}"]
    for b in blows:
        lines.append(f"{b['n']:>4} {b['t']:>7.3f} {b['phi']:>11.3f} {b['V_impact']:>8.3f} "
                     f"{b['P_peak'] / 1e3:>11.1f} {b['T_peak'] / 1e3:>11.2f} "
                     f"{100 * b['T_peak'] / b['P_peak']:>8.2f}")
    return "\n".join(lines)


def plot_hammer(runs: dict[str, dict], png: Path, comp: str = "hammer") -> None:
    """Motor torque and load torque; crank speed; P and T peaks of each blow (markers at the
    time the blow was seen) for one or more runs."""
    hammer_figure(runs, comp).savefig(png, dpi=110)


def hammer_figure(runs: dict[str, dict], comp: str = "hammer"):
    """The figure of plot_hammer (a matplotlib Figure; the backend is left alone). Curves that
    lie on top of each other (the same torque in two runs, a T peak equal to the P peak) get
    one legend entry saying they coincide."""
    from ..cosim.results import axis_label, mark_coinciding, new_figure, style_axes

    fig = new_figure(figsize=(9, 7.5))
    ax = fig.subplots(3, 1, sharex=True)
    for a in ax:
        style_axes(a)
    for label, col in runs.items():
        t = col["time"]
        ax[0].plot(t, col["motor.flange_tau"], lw=1.0, label=f"motor torque ({label})")
        ax[0].plot(t, col[f"{comp}.M_load"], lw=0.8, ls="--", label=f"rod load torque ({label})")
        ax[1].plot(t, col[f"{comp}.w_crank"], lw=1.0, label=label)
        blows = hammer_blows(col, comp)
        tb = [b["t"] for b in blows]
        ax[2].plot(tb, [b["P_peak"] / 1e3 for b in blows], "o-", ms=4, label=f"P peak ({label})")
        ax[2].plot(tb, [b["T_peak"] / 1e3 for b in blows], "s--", ms=4, label=f"T peak ({label})")
    ax[0].set_ylabel(axis_label("torque on the\nmotor shaft", "N.m"))
    ax[0].set_ylim(-60, 120)
    ax[1].set_ylabel(axis_label("crank speed", "rad/s"))
    ax[2].set_ylabel(axis_label("force per blow", "kN"))
    ax[2].set_xlabel(axis_label("time", "s"))
    for a in ax:
        mark_coinciding(a)
        a.legend(fontsize=7, loc="best")
    ax[0].set_title("Crank-rocker hammer: DC motor, spring rod, MO-100 rocker (Hertz contact)")
    fig.tight_layout()
    return fig


def run_hammer(args) -> int:
    runs = {}
    for csv in args.csv:
        col = read_columns(csv)
        runs[csv.stem] = col
        print(format_blows(hammer_blows(col, args.component), f"{csv}:"))
    if args.plot:
        plot_hammer(runs, args.plot, args.component)
        print(f"wrote {args.plot}")
    return 0
