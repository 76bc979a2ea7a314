"""`crankfmu export-ssp SCENE.toml [--out X.ssp]`: the scene as an SSP 1.0 archive."""
from __future__ import annotations

from pathlib import Path


def register(sub) -> None:
    p = sub.add_parser("export-ssp", help="write a scene as an SSP archive (.ssp) with its FMUs",
                       description="Write SystemStructure.ssd (components, connectors, "
                                   "connections, parameter values, default experiment) and the "
                                   "FMUs into a .ssp that fmpy, libcosim and ecos load and "
                                   "`crankfmu run` runs back. See docs/ssp.md.")
    p.add_argument("scene", type=Path, help="scene file (.toml or .ssp)")
    p.add_argument("--out", type=Path, help="archive to write (default results/<scene name>.ssp)")
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="COMP.PARAM=V",
                   help="override a parameter before export (repeatable)")
    p.add_argument("--stop-time", type=float, help="end of the run [s]")
    p.add_argument("--step", type=float, help="communication step [s]")
    p.add_argument("--algorithm", help="master algorithm")
    p.add_argument("--extrapolation", type=int, choices=(0, 1, 2), help="input extrapolation order")
    p.add_argument("--tolerance", type=float, help="[master].tolerance")
    p.add_argument("--fmu-tolerance", type=float, help="[master].fmu_tolerance")
    p.add_argument("--fmus", type=Path, help="folder of built FMUs (default fmus/ beside "
                                             "scenarios/); catalog FMUs are built there if stale")
    p.set_defaults(func=run_export)


def run_export(args) -> int:
    from ..cli import load_with_options
    from ..cosim.wiring import default_fmu_dir
    from ..ssp.export import describe_fmus, export_ssp, lossy_parts

    scene = load_with_options(args)
    out = args.out or Path("results") / f"{scene.name}.ssp"
    fmu_dir = args.fmus or default_fmu_dir(scene)
    export_ssp(scene, out, fmu_dir)
    print(f"wrote {out} ({out.stat().st_size / 1024:.0f} KiB): {len(scene.components)} "
          f"components, {len(scene.connections)} connections")
    for note in lossy_parts(scene, describe_fmus(scene, fmu_dir)):
        print(f"  note: {note}")
    return 0
