"""`crankfmu reference SCENE.toml`: the scene's physics models as one ODE, solved by scipy at
tight tolerance, written in the CSV layout of `crankfmu run` (same record grid)."""
from __future__ import annotations

from pathlib import Path

from .options import add_output_options, add_scene_options, add_step_option, load_with_options


def register(sub) -> None:
    from ..monolithic import DEFAULT_RTOL

    p = sub.add_parser("reference", help="monolithic reference of a scene (one ODE, scipy)")
    add_scene_options(p)
    add_step_option(p, "record grid: the run's communication step [s] (default: the scene's "
                       "[master].step), so reference and run CSVs line up row by row")
    add_output_options(p, "output folder (default results/): <scene name>_reference.csv, its "
                          "JSON sidecar <scene name>_reference.json and with --plot "
                          "<scene name>_reference.png",
                       "also write a PNG of the recorded variables")
    p.add_argument("--rtol", type=float, default=DEFAULT_RTOL, metavar="TOL",
                   help=f"relative tolerance [1] of the solver (default {DEFAULT_RTOL:g}; absolute "
                        "tolerance rtol times each state's nominal value)")
    p.add_argument("--method", choices=("DOP853", "Radau", "BDF", "LSODA", "RK45"),
                   help="scipy solve_ivp method (default: Radau if the composed Jacobian has a "
                        "time constant below 0.1 ms, else DOP853)")
    p.set_defaults(func=run_reference_command)


def run_reference_command(args) -> int:
    from ..cosim.results import check_run_set, figure_png, run_figure
    from ..errors import OptionError
    from ..monolithic import solve_reference, write_reference

    scene = load_with_options(args)
    if args.rtol <= 0:
        raise OptionError(f"--rtol must be > 0, got {args.rtol}")
    out = check_run_set((args.out or Path("results")) / f"{scene.name}_reference.csv")
    result = solve_reference(scene, rtol=args.rtol, method=args.method,
                             progress=False if args.no_progress else None)
    png = figure_png(run_figure(result.recorder, f"{scene.name}: monolithic reference, "
                                f"{result.method} rtol {result.rtol:g}")) if args.plot else None
    write_reference(scene, out, result, png)
    print(f"{scene.name} reference: {result.method} at rtol {result.rtol:g}, "
          f"{result.rhs_calls} right-hand side calls, {result.wall_seconds:.2f} s wall")
    print("wrote " + ", ".join(str(w) for w in (result.csv, result.sidecar, result.png) if w))
    return 0
