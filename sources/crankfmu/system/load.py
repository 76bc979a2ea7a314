"""Load a scene from its file: a TOML scene (with its swap resolved) or an SSP archive."""
from __future__ import annotations

import copy
from pathlib import Path

from ..errors import MAX_TIME
from .scene import (Scene, SceneError, _number, check_run_size, parse_scene, set_input,
                    set_value)
from .swap import read_scene_table


def load_scene(path) -> Scene:
    """The scene in `path`: .ssp is an SSP archive (crankfmu export-ssp or another tool), anything
    else a TOML scene file."""
    path = Path(path)
    if path.suffix.lower() == ".ssp":
        from .ssp_load import load_ssp  # lxml and the SSP schema: not on a TOML scene's path
        return load_ssp(path)
    return parse_scene(path, read_scene_table(path))


def prepare_scene(scene, *, stop_time=None, step=None, algorithm=None, parameters=None,
                  inputs=None, **master_options):
    """A copy of `scene` (or the scene loaded from that path) with the settings applied and
    checked as a scene file's would be: parameters and inputs by "comp.name", the stop time, the
    step, the algorithm and the master's own options (extrapolation=2, tolerance=1e-4, ...)."""
    scene = copy.deepcopy(scene) if isinstance(scene, Scene) else load_scene(scene)
    for ref, value in (parameters or {}).items():
        set_value(scene, ref, value, f"parameters[{ref!r}]")
    for ref, value in (inputs or {}).items():
        set_input(scene, ref, value, f"inputs[{ref!r}]")
    if stop_time is not None:
        scene.stop_time = _number(scene.path, "stop_time", stop_time, minimum=-MAX_TIME,
                                  maximum=MAX_TIME)
        if scene.stop_time <= scene.start_time:
            raise SceneError(scene.path, "stop_time", f"must exceed start_time = "
                                                      f"{scene.start_time}")
    for name, value in (("step", step), ("algorithm", algorithm), *master_options.items()):
        if value is not None:
            set_value(scene, f"master.{name}", value, name)
    check_run_size(scene)
    return scene
