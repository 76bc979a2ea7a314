"""`crankfmu sweep SCENE --vary COMP.PARAM=V1,V2,... [--out DIR] [--plot]`: many runs of one
scene (in this process, or on worker processes or a Dask cluster with --jobs, --scheduler), one
row each in DIR/sweep.csv with the scene's [analysis] figures; DIR/sweep.json names the study and
the units of sweep.csv's columns; with --plot DIR/sweep.png (crankfmu/studies/sweep.py)."""
from __future__ import annotations

from pathlib import Path

from .options import add_fmu_option, add_jobs_option, add_output_options, add_scene_options


def register(sub) -> None:
    p = sub.add_parser("sweep", help="parameter sweep of a scene: one row of [analysis] figures "
                                     "per run")
    add_scene_options(p, "scene file (.toml, with an [analysis] table)")
    p.add_argument("--vary", action="append", required=True, metavar="COMP.PARAM=VALUES",
                   help="V1,V2,... or START:STOP:N (linear, ends included), in the parameter's "
                        "unit; repeatable: the full-factorial grid")
    p.add_argument("--samples", type=int, metavar="N",
                   help="Latin hypercube of N points over the --vary ranges instead of the grid")
    p.add_argument("--seed", type=int, default=0, help="seed of the Latin hypercube (default 0)")
    p.add_argument("--from-time", type=float, metavar="S",
                   help="start of the analysis window [s] (default: the scene's "
                        "[analysis].from_time)")
    add_fmu_option(p)
    add_output_options(p, "output folder (default results/<scene name>_sweep; an interrupted "
                          "sweep resumes there): sweep.csv, sweep.json (the study and the units "
                          "of sweep.csv's columns), with --plot sweep.png",
                       "also draw sweep.png: each figure against each varied parameter")
    add_jobs_option(p, "the runs")
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
                  progress=False if args.no_progress else None, plot=args.plot)
    bad = [r for r in table.rows if r["status"] != "completed"]
    print(f"{len(table)} runs ({table.executed} executed now, {len(table) - table.executed} "
          f"kept from {table.csv}); {len(table) - len(bad)} completed")
    for r in bad:
        point = ", ".join(f"{p} = {r[p]:g}" for p in table.parameters)
        print(f"  run {r['run']} ({point}): {r['status']}: {r['reason']}")
    print(f"wrote {table.csv}, {table.sidecar}" + (f", {table.png}" if table.png else ""))
    return 0
