"""`crankfmu export-ssp SCENE.toml [--out DIR]`: the scene as an SSP 1.0 archive,
DIR/<scene name>.ssp."""
from __future__ import annotations

from pathlib import Path

from .options import (add_fmu_option, add_master_options, add_output_options, add_scene_options,
                      load_with_options)


def register(sub) -> None:
    p = sub.add_parser("export-ssp", help="write a scene as an SSP archive (.ssp) with its FMUs",
                       description="Write SystemStructure.ssd (components, connectors, "
                                   "connections, parameter values, default experiment) and the "
                                   "FMUs into a .ssp that fmpy, libcosim and ecos load and "
                                   "`crankfmu run` runs back. See docs/ssp.md.")
    add_scene_options(p)
    add_master_options(p)
    add_fmu_option(p)
    add_output_options(p, "output folder (default results/): <scene name>.ssp", progress=False)
    p.set_defaults(func=run_export)


def run_export(args) -> int:
    from ..outputs import check_files
    from ..system.wiring import default_fmu_dir
    from ..system.ssp_export import describe_fmus, export_ssp, lossy_parts

    scene = load_with_options(args)
    out, = check_files(args.out or Path("results"), [f"{scene.name}.ssp"])  # before building
    fmu_dir = args.fmus or default_fmu_dir(scene)
    export_ssp(scene, out, fmu_dir)
    print(f"wrote {out} ({out.stat().st_size / 1024:.0f} KiB): {len(scene.components)} "
          f"components, {len(scene.connections)} connections")
    for note in lossy_parts(scene, describe_fmus(scene, fmu_dir)):
        print(f"  note: {note}")
    return 0
