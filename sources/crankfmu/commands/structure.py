"""`crankfmu structure MECH.toml [--json]`: mobility and redundant constraints of a mechanism."""
from __future__ import annotations

from pathlib import Path


def register(sub) -> None:
    p = sub.add_parser("structure", help="mobility and redundant constraints of a mechanism "
                                         "description (scenarios/mechanisms/*.toml)")
    p.add_argument("mechanism", type=Path,
                   help="mechanism description (.toml: links, joints and their classes; e.g. "
                        "scenarios/mechanisms/stephenson_press.toml)")
    p.add_argument("--json", action="store_true", help="print the result as JSON")
    p.set_defaults(func=run)


def run(args) -> int:
    from ..studies.structure.report import structure_report

    print(structure_report(args.mechanism, args.json))
    return 0
