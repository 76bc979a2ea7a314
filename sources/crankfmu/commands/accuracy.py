"""`crankfmu accuracy SCENE.toml`: what accuracy costs in wall time, per master setting.

Sweeps algorithm x coupling (extrapolation, or a Taylor coupling's order where the FMUs offer
output derivatives) x communication step (x FMU tolerance), compares every run with the
monolithic reference (solved once, cached in --out DIR), and prints a table (once, when the
runs and their error estimates are done; a progress bar over the runs on stderr until then; a
Python warning of a run as one line there), the observed convergence orders and, with
--meet TOL, the cheapest setting whose error is at most TOL; writes accuracy.csv with its
sidecar accuracy.json (the units of its columns) into --out DIR, and with --plot
work_precision.png and estimate_vs_error.png. Each run is kept in --out DIR/runs, so a sweep
started again resumes where it stopped (--fresh runs everything again). --reference FILE.csv
takes the reference from elsewhere.
"""
from __future__ import annotations

from pathlib import Path

from .options import (add_fmu_option, add_jobs_option, add_output_options, add_scene_options,
                      load_with_options)


def _floats(text: str) -> list[float]:
    return [float(v) for v in text.split(",") if v.strip()]


def _ints(text: str) -> list[int]:
    return [int(v) for v in text.split(",") if v.strip()]


def _names(text: str) -> list[str]:
    return [v.strip() for v in text.split(",") if v.strip()]


def register(sub) -> None:
    from ..studies.accuracy import (DEFAULT_STEP_FACTORS, DEFAULT_TAYLORS, DEFAULT_TOLERANCES,
                                    METRICS)

    p = sub.add_parser("accuracy", help="error vs wall time of master settings against the "
                                        "monolithic reference (work-precision)")
    add_scene_options(p)
    add_fmu_option(p)
    add_output_options(p, "output folder (default results/<scene name>_accuracy): "
                          "accuracy.csv and accuracy.json (its columns' units), reference.csv "
                          "(cache), runs/, and with --plot the figures",
                       "also draw work_precision.png (error against wall time and doStep "
                       "calls) and estimate_vs_error.png")
    p.add_argument("--algorithms", type=_names, metavar="NAMES",
                   help="masters, a comma list (default: every available master)")
    p.add_argument("--extrapolations", type=_ints, metavar="ORDERS",
                   help="comma list of 0, 1, 2 (default all)")
    p.add_argument("--taylors", type=_ints, metavar="ORDERS",
                   help="Taylor coupling orders ([master].taylor) for the masters that take it, "
                        "comma list of 1 .. 4, 0 for none (default without --algorithms: "
                        + ",".join(map(str, DEFAULT_TAYLORS)) + " where every FMU with "
                        "connected outputs offers their derivatives; else none)")
    p.add_argument("--steps", type=_floats, metavar="S,...",
                   help="communication steps [s], comma list (default: the scene's step x "
                        + ", ".join(f"{f:g}" for f in DEFAULT_STEP_FACTORS) + ")")
    p.add_argument("--tolerances", type=_floats, metavar="TOL,...",
                   help="tolerances [1] of a variable-step master, swept instead of the step "
                        f"(default {','.join(f'{t:g}' for t in DEFAULT_TOLERANCES)})")
    p.add_argument("--fmu-tolerances", type=_floats, metavar="TOL,...",
                   help="FMU internal tolerances [1] to sweep (default: the scene's "
                        "fmu_tolerance)")
    p.add_argument("--meet", type=float, metavar="TOL",
                   help="an error [1] (the metric's, relative) to meet: print the cheapest "
                        "setting in wall time and the one with the fewest doStep calls whose "
                        "error is at most TOL, and draw it in work_precision.png (default: "
                        "none)")
    p.add_argument("--metric", choices=METRICS,
                   help="default: the scene's [analysis].metric, else events if the scene has "
                        "[analysis].events, else max. max: max over time of "
                        "|y - y_ref|/mean|y_ref| of --variables; steady: rel. error of mean "
                        "crank speed and of delta over the last --cycles whole revolutions "
                        "(needs C.phi, C.w_crank recorded); events: the largest rel. error of "
                        "the [analysis].events figures (event times, per-event peaks)")
    p.add_argument("--reference", type=Path, metavar="FILE.csv",
                   help="reference from elsewhere (another tool, a finer run) in the CSV "
                        "layout of crankfmu run: time, then \"component.variable\" columns "
                        "(default: crankfmu's monolithic reference, solved and cached)")
    p.add_argument("--fresh", action="store_true",
                   help="run every setting again (default: keep the finished runs found in "
                        "--out DIR/runs from an earlier, interrupted sweep)")
    p.add_argument("--variables", type=_names, metavar="NAMES",
                   help="recorded variables of the metric, a comma list (default: the "
                        "*.w_crank ones, else all)")
    p.add_argument("--cycles", type=int, default=1, metavar="N",
                   help="revolutions of metric steady (default 1)")
    p.add_argument("--rtol", type=float, default=1e-10, metavar="TOL",
                   help="relative tolerance [1] of the reference's solver (default 1e-10)")
    p.add_argument("--no-estimate", action="store_true",
                   help="no estimated_error column (its companion runs at 8 and 16 x the "
                        "scene's step and a tenth of the adaptive tolerances are not run)")
    p.add_argument("--floor-factor", type=float, default=10.0, metavar="X",
                   help="orders use errors above X times the FMU tolerance [1] (default 10)")
    add_jobs_option(p, "the runs (wall times are measured per run: parallel runs share the "
                       "machine)")
    p.set_defaults(func=run_accuracy_command)


def run_accuracy_command(args) -> int:
    from ..studies.accuracy import AccuracyOptions, format_orders, format_table, run_accuracy

    scene = load_with_options(args)
    options = AccuracyOptions(
        out_dir=args.out or Path("results") / f"{scene.name}_accuracy",
        algorithms=args.algorithms,
        extrapolations=args.extrapolations or [0, 1, 2],
        taylors=None if args.taylors is None else [q for q in args.taylors if q],
        steps=args.steps,
        fmu_tolerances=args.fmu_tolerances, metric=args.metric, variables=args.variables,
        cycles=args.cycles, meet=args.meet, reference_rtol=args.rtol, plot=args.plot,
        floor_factor=args.floor_factor, fmu_dir=args.fmus,
        progress=False if args.no_progress else None, jobs=args.jobs, scheduler=args.scheduler,
        reference_csv=args.reference, resume=not args.fresh, estimate=not args.no_estimate)
    if args.tolerances:
        options.tolerances = args.tolerances
    _check_options(options)
    result = run_accuracy(scene, options)
    from ..studies.accuracy.report import format_events
    print(f"{scene.name}: error = {result.metric.describe()}")
    print(f"reference: {result.reference_csv}" + (" (cached)" if result.reference_cached else ""))
    print(format_table(result.outcomes))
    events = format_events(result.outcomes)
    if events:
        print(events)
    print(format_orders(result.orders))
    if args.meet is not None:
        _print_choice("cheapest in wall time", result.cheapest, args.meet)
        _print_choice("fewest doStep calls", result.fewest_steps, args.meet)
    if options.estimate:
        _print_estimates(result.outcomes)
    print("wrote " + ", ".join(str(p) for p in [result.csv, result.sidecar, *result.figures]))
    return 0


def _print_estimates(outcomes) -> None:
    from ..studies.accuracy.estimates import estimate_ratio
    ratios = [r for r in (estimate_ratio(o) for o in outcomes) if r == r]
    inside = sum(1 for r in ratios if 1 / 3 <= r <= 3)
    from ..masters import traits
    completed = sum(1 for o in outcomes if o.ok and not traits(o.setting.algorithm).monolithic)
    print(f"error estimate (Richardson, companion runs): within a factor 3 of the true error in "
          f"{inside} of {completed} completed runs" + (
              f" (estimate / error from {min(ratios):.2g} to {max(ratios):.2g})" if ratios
              else ""))


def _check_options(o) -> None:
    """Raises OptionError naming the option and what it allows."""
    from ..masters import MASTERS
    from ..errors import OptionError

    unknown = [a for a in o.algorithms or [] if a not in MASTERS]
    if unknown:
        raise OptionError(f"--algorithms: {', '.join(unknown)} not available; available: "
                          f"{', '.join(MASTERS)}")
    if any(x not in (0, 1, 2) for x in o.extrapolations):
        raise OptionError(f"--extrapolations: {o.extrapolations}: each must be 0, 1 or 2")
    if any(q not in (1, 2, 3, 4) for q in o.taylors or []):
        raise OptionError(f"--taylors: {o.taylors}: each must be 0 (none), 1, 2, 3 or 4")
    for name, values in (("--steps", o.steps), ("--tolerances", o.tolerances),
                         ("--fmu-tolerances", o.fmu_tolerances),
                         ("--meet", [o.meet] if o.meet is not None else []),
                         ("--rtol", [o.reference_rtol])):
        if any(not v > 0 for v in values or []):
            raise OptionError(f"{name}: every value must be > 0, got {values}")
    if o.cycles < 1:
        raise OptionError(f"--cycles must be >= 1, got {o.cycles}")


def _print_choice(what: str, o, meet: float) -> None:
    if o is None:
        print(f"{what} meeting --meet {meet:g}: none of the runs")
        return
    s = o.setting
    coupling = f"--taylor {s.taylor}" if s.taylor else f"--extrapolation {s.extrapolation}"
    print(f"{what} meeting --meet {meet:g}: --algorithm {s.algorithm} {coupling} "
          f"--step {s.step:g} --fmu-tolerance {s.fmu_tolerance:g}"
          + (f" --tolerance {s.tolerance:g}" if o.knob == "tolerance" else "")
          + f" (error {o.error:.2e}, {o.wall_seconds:.2f} s, {o.do_steps} doStep calls)")
