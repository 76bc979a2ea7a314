"""SSP 1.0 (System Structure and Parameterization): export a scene as a .ssp, load one back.

`export_ssp(scene, path, fmu_dir)` writes SystemStructure.ssd plus the FMUs in resources/;
`load_ssp(path)` returns a Scene that `crankfmu run` runs like the TOML it came from.
See docs/ssp.md for what maps to what and what is lossy.
"""
from .export import export_ssp, fmpy_parameter_set
from .load import load_ssp

__all__ = ["export_ssp", "fmpy_parameter_set", "load_ssp"]
