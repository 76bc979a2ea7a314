"""`crankfmu build [MODEL ...] [--dest DIR]`: build the FMUs (FMI 2.0 into DIR, FMI 3.0 into
DIR/fmi3/) from the imported crankfmu's sources and validate them (crankfmu.fmu.build,
crankfmu.fmu.build_fmi3)."""
from __future__ import annotations

from pathlib import Path


def register(sub) -> None:
    from ..fmu.build_fmi3 import add_arguments
    build = sub.add_parser("build", help="build every FMU into fmus/ (FMI 2.0) and fmus/fmi3/ "
                                         "(FMI 3.0) and validate it")
    add_arguments(build)
    build.set_defaults(func=run_build)


def run_build(args) -> int:
    import logging

    from ..fmu.build import PACKAGE_DIR
    from ..fmu.build_fmi3 import build_selected
    from ..system.wiring import warn_if_tree_differs

    logging.getLogger("crankfmu").info("building FMUs from the crankfmu sources at %s",
                                       PACKAGE_DIR)
    warn_if_tree_differs(Path.cwd())
    build_selected(args.dest, args.models, args.fmi, args.effects, args.portable)
    return 0
