"""Load a scene from its file: a TOML scene (with its swap resolved) or an SSP archive."""
from __future__ import annotations

from pathlib import Path

from .scene import Scene, parse_scene
from .ssp_load import load_ssp
from .swap import read_scene_table


def load_scene(path) -> Scene:
    """The scene in `path`: .ssp is an SSP archive (crankfmu export-ssp or another tool), anything
    else a TOML scene file."""
    path = Path(path)
    if path.suffix.lower() == ".ssp":
        return load_ssp(path)
    return parse_scene(path, read_scene_table(path))
