"""`crankfmu sweep SCENE --vary COMP.PARAM=V1,V2,... [--out DIR]`: many runs of one scene on all
cores (or a Dask cluster), one row each in DIR/sweep.csv with the scene's [analysis] figures,
and DIR/sweep.png (crankfmu/studies/sweep.py)."""
from __future__ import annotations

from pathlib import Path


def add_executor_options(p, what: str = "runs") -> None:
    from ..cli import positive_integer
    p.add_argument("--jobs", type=positive_integer, default=None,
                   help=f"local worker processes for the {what} (default: the number of cores; "
                        "1: one worker, runs one after another)")
    p.add_argument("--scheduler", metavar="ADDRESS",
                   help="run on a Dask distributed cluster, e.g. tcp://HOST:8786 (workers need "
                        "the same crankfmu; FMUs and scenes are sent to them)")


def register(sub) -> None:
    p = sub.add_parser("sweep", help="parameter sweep of a scene on all cores or a Dask cluster: "
                                     "one row of [analysis] figures per run")
    from ..cli import add_fmu_option, add_scene_options
    add_scene_options(p, "scene file (.toml, with an [analysis] table)")
    p.add_argument("--vary", action="append", required=True, metavar="COMP.PARAM=VALUES",
                   help="V1,V2,... or START:STOP:N (linear, ends included); repeatable: the "
                        "full-factorial grid")
    p.add_argument("--samples", type=int,
                   help="Latin hypercube of N points over the --vary ranges instead of the grid")
    p.add_argument("--seed", type=int, default=0, help="seed of the Latin hypercube (default 0)")
    p.add_argument("--out", type=Path, metavar="DIR",
                   help="output folder: sweep.csv, sweep.json, sweep.png (default "
                        "results/<scene name>_sweep; an interrupted sweep resumes)")
    p.add_argument("--from-time", type=float,
                   help="start of the analysis window [s] (default [analysis].from_time)")
    add_fmu_option(p)
    add_executor_options(p)
    p.add_argument("--no-plot", action="store_true", help="no sweep.png")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=run_sweep)


def run_sweep(args) -> int:
    from ..studies.sweep import sweep
    from ..system.load import load_scene

    out = args.out
    if out is None:
        out = Path("results") / f"{load_scene(args.scene).name}_sweep"
    table = sweep(args.scene, args.vary, out, jobs=args.jobs, scheduler=args.scheduler,
                  stop_time=args.stop_time, from_time=args.from_time, samples=args.samples,
                  seed=args.seed, overrides=args.overrides, fmu_dir=args.fmus,
                  progress=False if args.no_progress else None, plot=not args.no_plot)
    bad = [r for r in table.rows if r["status"] != "completed"]
    print(f"{len(table)} runs ({table.executed} executed now, {len(table) - table.executed} "
          f"kept from {table.csv}); {len(table) - len(bad)} completed")
    for r in bad:
        point = ", ".join(f"{p} = {r[p]:g}" for p in table.parameters)
        print(f"  run {r['run']} ({point}): {r['status']}: {r['reason']}")
    print(f"wrote {table.csv}" + (f", {table.png}" if table.png else ""))
    return 0
