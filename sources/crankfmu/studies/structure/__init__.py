"""Mechanism description format and structural analysis (mobility, redundant constraints).

    from crankfmu.studies.structure import load_mechanism, analyse, structure_report
    result = analyse(load_mechanism("scenarios/mechanisms/stand_drive_p1.toml"))
    result["redundant"]   # {"count": 3, "directions": ["rotation about y", ...]}

See docs/structure.md for the format, the method and the results of the shipped mechanisms.
"""
from .analysis import StructureResult, analyse
from .description import (Joint, Mechanism, MechanismError, load_mechanism, loads_mechanism,
                          mechanism_from_dict)
from .report import format_report, structure_report

__all__ = ["StructureResult", "analyse", "Joint", "Mechanism", "MechanismError",
           "load_mechanism", "loads_mechanism", "mechanism_from_dict", "format_report",
           "structure_report"]
