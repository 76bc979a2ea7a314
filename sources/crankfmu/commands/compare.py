"""`crankfmu compare A.toml B.toml [--out DIR] [--plot]`: run two scenes (a component swap) and
report the differences that matter (crankfmu/studies/compare.py): the table printed and in
DIR/compare.csv (a unit column), both runs' CSVs in DIR, with --plot the overlay DIR/compare.png."""
from __future__ import annotations

from pathlib import Path

from .options import add_fmu_option, add_jobs_option, add_output_options


def register(sub) -> None:
    p = sub.add_parser("compare", help="run two scenes (e.g. a component swap) and compare "
                                       "cycle time, speeds, delta, peak torques, energy per stroke")
    p.add_argument("scene_a", type=Path, help="scene A (.toml; needs an [analysis] table)")
    p.add_argument("scene_b", type=Path, help="scene B (.toml; e.g. one with a [swap] table)")
    p.add_argument("--stop-time", type=float, metavar="S",
                   help="end of both runs [s] (default: each scene's [scene].stop_time)")
    add_fmu_option(p)
    add_output_options(p, "output folder (default results/<A name>_vs_<B name>): compare.csv, "
                          "both runs' CSVs and sidecars, with --plot compare.png",
                       "also draw compare.png: crank speed and torques of both runs over time")
    add_jobs_option(p, "the two runs")
    p.set_defaults(func=run_compare)


def run_compare(args) -> int:
    from ..cosim.runner import RunOptions
    from ..errors import MAX_TIME
    from ..studies.compare import check_compare_outputs, compare_scenes
    from ..studies.executor import make_executor
    from ..system.load import load_scene
    from ..system.scene import SceneError, _number, check_run_size

    scenes = [load_scene(args.scene_a), load_scene(args.scene_b)]
    for sc in scenes:
        if args.stop_time is not None:
            sc.stop_time = _number(sc.path, "--stop-time", args.stop_time, minimum=-MAX_TIME,
                                   maximum=MAX_TIME)
            if sc.stop_time <= sc.start_time:
                raise SceneError(sc.path, "--stop-time", f"must exceed start_time = {sc.start_time}")
            check_run_size(sc)
    options = RunOptions(fmu_dir=args.fmus, progress=False if args.no_progress else None)
    out = check_compare_outputs(scenes[0], scenes[1], args.out or Path("results") /
                                f"{scenes[0].name}_vs_{scenes[1].name}")  # before any run
    with make_executor(args.jobs, args.scheduler) as executor:
        result = compare_scenes(scenes[0], scenes[1], out, options, executor, plot=args.plot)
    print(result.text)
    print(f"wrote {result.csv}" + (f", {result.png}" if result.png else "")
          + f" and the runs' CSVs in {out}")
    return 0
