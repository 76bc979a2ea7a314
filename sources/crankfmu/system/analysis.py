"""A scene's [analysis] table: which recorded variable plays which role (crank angle, crank
speed, drive torque and power, load torque), from when the steady state counts, the event
figures and the accuracy metric the scene is judged by. Read by the runner (its plot), compare,
sweep and the accuracy study."""
from __future__ import annotations

from .scene import SceneError, _variable_ref

ROLES = ("crank_angle", "crank_speed", "drive_torque", "drive_power")
OPTIONAL = ("load_torque",)
NUMBERS = ("from_time",)
LISTS = ("events",)
ACCURACY = ("metric",)  # the metric the scene is judged by (crankfmu.cosim.metrics)


def analysis_roles(scene) -> dict:
    """The [analysis] table of `scene`, checked: role -> variable, plus from_time."""
    raw = scene.raw.get("analysis")
    if not isinstance(raw, dict):
        raise SceneError(scene.path, "[analysis]", "required by compare and sweep: name the "
                         f"variables for {', '.join(ROLES)} (optional: "
                         f"{', '.join(OPTIONAL + NUMBERS + LISTS)})")
    allowed = ROLES + OPTIONAL + NUMBERS + LISTS + ACCURACY
    unknown = set(raw) - set(allowed)
    if unknown:
        raise SceneError(scene.path, f"[analysis].{sorted(unknown)[0]}",
                         f"unknown key; allowed: {', '.join(allowed)}")
    out: dict = {}
    for role in ROLES + OPTIONAL:
        if role in raw:
            out[role] = _variable_ref(scene.path, f"[analysis].{role}", raw[role],
                                      scene.components)
        elif role in ROLES:
            raise SceneError(scene.path, f"[analysis].{role}", "required by compare and sweep: "
                             "the recorded variable (\"component.variable\") with this role")
    out["from_time"] = float(raw.get("from_time", scene.start_time))
    events = raw.get("events", [])
    if not isinstance(events, list):
        raise SceneError(scene.path, "[analysis].events", "must be a list of "
                         "\"component.variable\" (values reported at the run's end)")
    # an entry is "comp.var" or { variable = "comp.var", per = "comp.counter" } (a figure per
    # event for the accuracy metric, crankfmu.cosim.events); here: the variable's end value
    out["events"] = [_variable_ref(scene.path, "[analysis].events",
                                   v.get("variable") if isinstance(v, dict) else v,
                                   scene.components) for v in events]
    return out
