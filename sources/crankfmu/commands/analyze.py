"""`crankfmu analyze SUBJECT [--out DIR] [--plot]`: the papers' analyses, each beside the
simulation it approximates (docs/papers.md lists every table and figure and the doc page that
discusses it). Every subcommand prints its tables, writes them as CSV into --out (default
results/analyze-SUBJECT/) and, with --plot, its figures there too:

    press      seed 000: (28) in both conventions, the base-link mass sweep (Fig. 4) with its
               claim; figures of the dynamic errors, the base-link offset, the flywheel
    impact     seed 004: the MO-100 table and claims; figures P(t), T(t) and Figs. 2-3 for the
               three k_n; --hertz-peak: the support stiffness iterated on the Hertz peak
    planetary  seed 001: the four periods, engagement time against alpha_b, brake torques
    stopping   seed 001: stopping from a range of crank angles against stopping at TDC
    mill-stand seed 002: the mobility tables and schemes, seed's reading against the rank
    hammer     the blows of hammer runs (CSV of hammer.toml, hammer_bearings.toml)
    flywheel   the servo press's delta against the flywheel from a sweep's sweep.csv
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

MECHANISMS = ("stand_drive_p1", "stand_drive_p2p3", "stand_drive_p4", "stand_drive_p1_coaxial",
              "stand_drive_p2p3_coaxial", "stand_drive_p4_coaxial")


def _outputs(p, name: str, plot_help: str) -> None:
    p.add_argument("--out", type=Path, metavar="DIR",
                   help=f"folder for the tables (CSV) and figures (default "
                        f"results/analyze-{name}/)")
    p.add_argument("--plot", action="store_true", help=f"also draw the figures: {plot_help}")


def _scene_option(p, default: str, what: str) -> None:
    p.add_argument("--scene", type=Path, default=Path("scenarios") / default,
                   help=f"{what} (default scenarios/{default})")


def register(sub) -> None:
    p = sub.add_parser("analyze", help="the papers' analyses beside the simulations")
    what = p.add_subparsers(dest="analysis", required=True)

    press = what.add_parser("press", help="seed 000: eq. (28) in both conventions, the "
                                          "base-link mass sweep (Fig. 4); figures")
    _scene_option(press, "servo_press.toml", "the servo press scene whose parameters are used")
    press.add_argument("--masses", type=float, nargs="+", metavar="KG",
                       help="base-link and counterweight masses of the Fig. 4 sweep [kg] "
                            "(default 0, 20, ..., 400)")
    _outputs(press, "press", "press_dynamic_error.png, press_base_link.png, "
                             "press_flywheel.png, press_base_link_mass.png")
    press.set_defaults(func=run_press)

    impact = what.add_parser("impact", help="seed 004: MO-100 table, the paper's claims; "
                                            "figures P(t), T(t) and Figs. 2-3")
    for dest, name, unit in (("J", "J", "kg.m2"), ("m", "m", "kg"), ("r", "r", "m"),
                             ("r_c", "R_c, radius of the striking sphere", "m"),
                             ("d", "d, tool diameter", "m"), ("E", "E", "Pa"),
                             ("rho", "rho", "kg/m3"), ("nu", "nu", "1"),
                             ("v0", "V0, impact speed", "m/s")):
        impact.add_argument(f"--{dest.replace('_', '-')}", dest=dest, type=float,
                            help=f"{name} [{unit}] (default: MO-100)")
    impact.add_argument("--k-n", type=float, nargs="+", default=[40e6, 80e6, 160e6],
                        help="bearing constants k_n [N(2/3)/m] (table and Figs. 2-3; default "
                             "40e6 80e6 160e6)")
    impact.add_argument("--s-factor", type=float, nargs="+", default=[1.1, 0.9],
                        help="strike distance S as a multiple of the centre of percussion "
                             "J/(m r) [1] (default 1.1 0.9)")
    impact.add_argument("--hertz-peak", action="store_true",
                        help="also iterate the support stiffness c0 = k_n Tm^(1/3) on the peak "
                             "of the Hertz-contact impact (the model stepped) and compare")
    _scene_option(impact, "mo100_impact.toml", "the impact scene run for the figures")
    _outputs(impact, "impact", "impact_forces.png, impact_stiffness.png")
    impact.set_defaults(func=run_impact)

    planetary = what.add_parser("planetary", help="seed 001: the four periods, engagement time "
                                                  "against alpha_b, brake torque (~10 s)")
    _scene_option(planetary, "planetary_engagement.toml",
                  "the planetary drive scene (motor and drive parameters)")
    _outputs(planetary, "planetary", "planetary.png")
    planetary.set_defaults(func=run_planetary)

    stopping = what.add_parser("stopping", help="seed 001: stopping from a range of crank "
                                                "angles against stopping at TDC (~10 s)")
    _scene_option(stopping, "conventional_press.toml",
                  "motor + planetary drive + press scene with an engage edge in its command")
    stopping.add_argument("--angles", type=float, nargs="+", metavar="DEG",
                          help="crank angles after TDC at the stop command [deg] (default 90, "
                               "105, ..., 360)")
    _outputs(stopping, "stopping", "stopping.png")
    stopping.set_defaults(func=run_stopping)

    mill = what.add_parser("mill-stand", help="seed 002: mobility tables and kinematic schemes "
                                              "of the stand drive variants")
    mill.add_argument("--mechanisms", type=Path, nargs="+", metavar="TOML",
                      help="mechanism descriptions (default the six stand_drive_p1/p2p3/p4 "
                           "files, generic and coaxial, in scenarios/mechanisms/)")
    _outputs(mill, "mill-stand", "one <mechanism>.png per mechanism")
    mill.set_defaults(func=run_mill_stand)

    hammer = what.add_parser("hammer", help="blow table of hammer runs (CSV of hammer.toml or "
                                            "hammer_bearings.toml)")
    hammer.add_argument("csv", type=Path, nargs="+", help="result CSV(s) of a hammer scene")
    hammer.add_argument("--component", default="hammer",
                        help="the CrankRockerHammer component's name in the runs (default "
                             "hammer)")
    _outputs(hammer, "hammer", "hammer.png (motor torque, crank speed, P and T peaks)")
    hammer.set_defaults(func=run_hammer)

    fly = what.add_parser("flywheel", help="servo press delta against motor.J_flywheel from a "
                                           "sweep's sweep.csv, with eq. (28) and the first "
                                           "approximation")
    fly.add_argument("csv", type=Path, help="sweep.csv of crankfmu sweep --vary motor.J_flywheel=...")
    _scene_option(fly, "servo_press.toml", "the swept scene")
    _outputs(fly, "flywheel", "flywheel.png (delta against J_flywheel, (28) marked)")
    fly.set_defaults(func=run_flywheel)


def _out_dir(out: Path | None, name: str, files) -> Path:
    """--out DIR (default results/analyze-NAME), created if missing, and the names of `files`
    the analysis writes there checked before it computes anything (crankfmu.outputs: a folder
    that is a file or cannot be written, a name that exists as anything but a regular file, a
    FIFO, a symbolic link, a folder, is refused, exit 2). The tables are then written with
    outputs.write_table and the figures with cosim.results.save_figure: each a whole regular
    file, renamed over the name."""
    from ..outputs import check_files

    folder = out or Path("results") / f"analyze-{name}"
    check_files(folder, files)
    return folder


def _scene_file(path: Path) -> Path:
    from ..errors import CrankfmuError

    if not path.is_file():
        raise CrankfmuError(f"--scene {path}: no such scene file (run from the repository root "
                            "or give --scene)")
    return path


def _positive(values, option: str, unit: str) -> None:
    from ..errors import CrankfmuError

    bad = [v for v in values or () if not (np.isfinite(v) and v >= 0.0)]
    if bad:
        raise CrankfmuError(f"{option} {bad[0]:g}: must be a finite number >= 0 [{unit}]")


def _written(paths) -> None:
    for path in paths:
        print(f"wrote {path}")


def run_press(args) -> int:
    from ..system.load import load_scene
    from ..studies import base_link, papers
    from ..studies.flywheel import eq28_conventions, format_conventions, write_conventions

    _positive(args.masses, "--masses", "kg")
    scene = load_scene(_scene_file(args.scene))
    figures = [*papers.PRESS_FIGURES, "press_base_link_mass.png"]
    out = _out_dir(args.out, "press",
                   ["press_flywheel_28.csv", "press_base_link_mass.csv"] + figures * args.plot)
    press, m_static, _, u0 = papers.press_models(scene)
    conv = eq28_conventions(press, m_static, u0)
    print(format_conventions(conv, scene.name))
    written = [write_conventions(conv, out / "press_flywheel_28.csv")]
    sweep = base_link.mass_sweep(scene, args.masses or base_link.DEFAULT_MASSES)
    print()
    print(base_link.format_table(sweep))
    print("\n".join(base_link.claim_verdict(sweep)))
    written.append(base_link.write_csv(sweep, out / "press_base_link_mass.csv"))
    if args.plot:
        written += papers.press_figures(scene, out)
        written += papers.save_figures({"press_base_link_mass.png": base_link.figure(sweep)}, out)
    _written(written)
    return 0


def run_impact(args) -> int:
    from ..studies import rocker_analysis as ra
    from ..studies.papers import progress

    scene = _scene_file(args.scene) if args.plot else None   # before the table is computed
    out = _out_dir(args.out, "impact", ["impact_table.csv"]
                   + ["impact_hertz_peak.csv"] * args.hertz_peak
                   + ["impact_forces.png", "impact_stiffness.png"] * args.plot)
    changes = {field: getattr(args, dest) for field, dest in
               (("J", "J"), ("m", "m"), ("r", "r"), ("R_c", "r_c"), ("d", "d"), ("E", "E"),
                ("rho", "rho"), ("nu", "nu"), ("V0", "v0")) if getattr(args, dest) is not None}
    base = ra.RockerData(**changes)
    progress(f"analyze impact: the table, {len(args.s_factor) * len(args.k_n)} row(s)")
    rows = ra.impact_table(base, args.s_factor, args.k_n)
    print(ra.format_impact_table(rows))
    print()
    print(ra.format_claims(ra.claims(rows)))
    written = [ra.write_impact_table(rows, out / "impact_table.csv")]
    if args.hertz_peak:
        progress("analyze impact: the support stiffness on the Hertz peak")
        peaks = ra.hertz_peak_table(base, args.s_factor, args.k_n)
        print()
        print(ra.format_hertz_peak_table(peaks))
        written.append(ra.write_hertz_peak_table(peaks, out / "impact_hertz_peak.csv"))
    if args.plot:
        from ..studies.papers import impact_figures
        written += impact_figures(scene, out, args.k_n)
    _written(written)
    return 0


def run_planetary(args) -> int:
    from ..studies import papers

    scene = _scene_file(args.scene)
    out = _out_dir(args.out, "planetary", ["planetary.csv"] + ["planetary.png"] * args.plot)
    data = papers.planetary_data(scene)
    print(papers.format_planetary(data))
    written = [papers.write_planetary_csv(data, out / "planetary.csv")]
    if args.plot:
        written += papers.save_figures({"planetary.png": papers.figure_planetary(data)}, out)
    _written(written)
    return 0


def run_stopping(args) -> int:
    from ..studies import planetary_stopping as ps
    from ..studies.papers import save_figures

    scene = _scene_file(args.scene)
    out = _out_dir(args.out, "stopping", ["stopping.csv"] + ["stopping.png"] * args.plot)
    sweep = ps.stopping_sweep(scene, args.angles or ps.DEFAULT_ANGLES)
    print(ps.format_table(sweep))
    print("\n".join(ps.verdict(sweep)))
    written = [ps.write_csv(sweep, out / "stopping.csv")]
    if args.plot:
        written += save_figures({"stopping.png": ps.figure(sweep, ps.forging_window(scene))}, out)
    _written(written)
    return 0


def run_mill_stand(args) -> int:
    from ..studies.papers import save_figures
    from ..studies.structure import mobility
    from ..studies.structure.analysis import analyse
    from ..studies.structure.description import load_mechanism

    paths = args.mechanisms or [Path("scenarios") / "mechanisms" / f"{m}.toml"
                                for m in MECHANISMS]
    items = [(m, analyse(m)) for m in (load_mechanism(p) for p in paths)]
    out = _out_dir(args.out, "mill-stand",
                   ["mobility.csv"] + [f"{m.name}.png" for m, _ in items] * args.plot)
    print("\n\n".join(mobility.format_mobility(m, r) for m, r in items))
    written = [mobility.write_csv(items, out / "mobility.csv")]
    if args.plot:
        written += save_figures({f"{m.name}.png": mobility.figure(m, r) for m, r in items}, out)
    _written(written)
    return 0


def run_flywheel(args) -> int:
    from ..system.load import load_scene
    from ..studies.flywheel import report
    from ..studies.papers import progress

    scene = load_scene(_scene_file(args.scene))
    progress("analyze flywheel: the first approximation at each flywheel")
    out = _out_dir(args.out, "flywheel", ["flywheel.csv"] + ["flywheel.png"] * args.plot)
    text, written = report(args.csv, scene, out, args.plot)
    print(text)
    _written(written)
    return 0


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


def hammer_figure(runs: dict[str, dict], comp: str = "hammer"):
    """The hammer figure (a matplotlib Figure; the backend is left alone). Curves that
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
    from ..studies.papers import save_figures

    out = _out_dir(args.out, "hammer", ["hammer_blows.csv"] + ["hammer.png"] * args.plot)
    runs, rows = {}, []
    for csv in args.csv:
        col = read_columns(csv)
        runs[csv.stem] = col
        blows = hammer_blows(col, args.component)
        rows += [{"run": csv.stem, **b} for b in blows]
        print(format_blows(blows, f"{csv}:"))
    written = [_write_blows(rows, out / "hammer_blows.csv")]
    if args.plot:
        written += save_figures({"hammer.png": hammer_figure(runs, args.component)}, out)
    _written(written)
    return 0


def _write_blows(rows: list[dict], path: Path) -> Path:
    from ..outputs import write_table
    keys = (("run", ""), ("n", "1"), ("t", "s"), ("phi", "rad"), ("V_impact", "m/s"),
            ("P_peak", "N"), ("T_peak", "N"))
    return write_table(path, [f"{k} [{u}]" if u else k for k, u in keys],
                       ([r[k] for k, _ in keys] for r in rows))
