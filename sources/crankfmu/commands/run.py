"""`crankfmu run SCENE [--out DIR] [--plot]`: co-simulate a scene with its master; the CSV, its
JSON sidecar (with the error estimate) and with --plot a PNG, into DIR (crankfmu.cosim.runner).
With --target TOL the master, the coupling (extrapolation or Taylor order) and the step are
chosen from the error estimate (crankfmu.cosim.target)."""
from __future__ import annotations

import sys
from pathlib import Path

from .options import (add_fmu_option, add_jobs_option, add_master_options, add_output_options,
                      add_scene_options, load_with_options, progress_lines)


def register(sub) -> None:
    p = sub.add_parser("run", help="run a scene",
                       description="Co-simulate a scene with its master and write its results "
                                   "(the CSV, its JSON sidecar with the error estimate, with "
                                   "--plot a PNG).")
    add_scene_options(p)
    add_master_options(p)
    add_fmu_option(p)
    add_output_options(p, "output folder (default results/): <scene name>.csv, its JSON "
                          "sidecar <scene name>.json and with --plot <scene name>.png",
                       "also write a PNG of the recorded variables (the steady state when the "
                       "scene's [analysis] names a crank and the run reaches it)")
    p.add_argument("--log", action="store_true", help="print the FMUs' log messages")
    p.add_argument("--target", type=float, metavar="TOL",
                   help="the global error wanted [1] (the scene's accuracy metric, relative): "
                        "choose master, extrapolation and step from the error estimate "
                        "(default: the scene's [master].target, else no search)")
    p.add_argument("--no-estimate", action="store_true",
                   help="skip the error estimate (its companion run at half the step costs "
                        "1.2-1.9 x the run: docs/error_estimate.md)")
    add_jobs_option(p, "the run and the companion runs of its error estimate and of "
                       "--target's search (2 pays with a free core)",
                    scheduler=False)
    p.set_defaults(func=run_command)


def run_command(args) -> int:
    from ..cosim.companions import processes
    from ..cosim.results import check_run_set
    from ..cosim.runner import RunOptions, run_scene
    from ..system.scene import _number

    scene = load_with_options(args)
    if args.target is not None:
        scene.master.target = _number(scene.path, "--target", args.target, positive=True,
                                      maximum=1.0)
    out = check_run_set((args.out or Path("results")) / f"{scene.name}.csv")  # before running
    jobs = processes(args.jobs)
    if scene.master.target is not None:
        return _run_target(scene, out, args, jobs)
    result = run_scene(scene, RunOptions(out=out, plot=args.plot, fmu_dir=args.fmus,
                                         progress=False if args.no_progress else None,
                                         verbose_log=args.log, estimate=not args.no_estimate,
                                         jobs=jobs))
    _print_run(scene, result)
    return 0


def _run_target(scene, out: Path, args, jobs: int) -> int:
    """--target: search the setting (crankfmu.cosim.target), write the chosen run."""
    from ..cosim.target import TargetNotMet, search, write_chosen
    from ..masters import traits
    try:
        result, report = search(scene, scene.master.target, args.fmus, jobs,
                                progress_lines(args))
    except TargetNotMet as err:
        print(f"{scene.name}: target not met. {err}")
        return 1
    write_chosen(scene, result, report, out, args.plot)
    m = result.metadata["master"]
    knob = f"tolerance {report.tolerance:g}" if m["step"] != report.step or \
        traits(m["algorithm"]).variable_step else f"step {m['step']:g} s"
    coupling = f"taylor {m['taylor']}" if m.get("taylor") else \
        f"extrapolation {m.get('extrapolation')}"
    print(f"{scene.name}: target {report.target:g} met by {m['algorithm']}, {coupling}, "
          f"{knob}; the search ran {len(report.runs)} runs in "
          f"{report.wall_seconds:.2f} s wall")
    _print_run(scene, result, report.estimate)
    return 0


def _print_run(scene, result, estimate=None) -> None:
    from ..masters import MASTERS, traits
    m = result.metadata.get("master", {})  # the run's setting (--target chooses it)
    own = ", ".join(f"{o.name} {m[o.name]:g}" for o in MASTERS[m["algorithm"]].options
                    if o.name in m)
    print(f"{scene.name}: {result.steps} {traits(m['algorithm']).describe_steps(m['step'])} "
          f"with {m['algorithm']}" + (f" ({own})" if own else "")
          + f" in {result.wall_seconds:.2f} s wall")
    for name, st in result.statistics.items():
        print(f"  {name}: {st['doStep_calls']} doStep calls, {st['doStep_seconds']:.3f} s, "
              f"{st['rollbacks']} rollbacks")
    extra = {k: v for k, v in result.master_statistics.items()
             if k not in ("algorithm", "extrapolation")}
    if extra:
        print("  master: " + ", ".join(f"{k} {v:.4g}" if isinstance(v, float) else f"{k} {v}"
                                       for k, v in extra.items()))
    for port in result.coupling_error.get("ports", []):
        rel = port["relative_mismatch"]
        print(f"  coupling error at {port['driver']} -> {port['receiver']}: energy mismatch "
              f"{port['mismatch_J']:.4g} J" + (f" ({rel:.3g} of {port['energy_throughput_J']:.4g}"
                                                  f" J through the port)" if rel is not None else ""))
    estimate = estimate or result.estimate
    if estimate is not None:
        from ..cosim.estimate import format_estimate
        print("  " + format_estimate(estimate))
    print(f"wrote {result.csv}, {result.sidecar}" + (f", {result.png}" if result.png else ""))
    from ..cosim.trust import warning_line
    warning = warning_line(scene.name, result.metadata)
    if warning:
        print(f"warning: {warning}", file=sys.stderr)
