"""The scene file (TOML): what to simulate, wired how, run by which master, recording what.

    [scene]       name, description, start_time [s], stop_time [s]
    [master]      algorithm, step [s], extrapolation (0, 1, 2), order, fmu_tolerance (each FMU's
                  internal relative tolerance, via fmi2SetupExperiment), tolerance (the iterative
                  and adaptive masters' own tolerance), max_iterations, min_step [s], max_step [s]
    [components.NAME]  fmu = "DcServoMotor" (built FMU name) or "path/to/file.fmu",
                       parameters = {name = value}, effects = ["name", ...]
    [[connections]]    from = "comp.output", to = "comp.input"
    [inputs]           "comp.input" = value | {table = [[t, v], ...], interpolation = "linear"|"step"}
    [record]           variables = ["comp.var", ...], interval [s] (default: the master step)
    [swap]             base = "other.toml", replace = ["comp", ...]: this scene is the base scene
                       with those components swapped and the tables here laid over it (rules in
                       `crankfmu.scenario.swap`)
    [analysis]         roles of recorded variables for `crankfmu compare` (crank_angle,
                       crank_speed, drive_torque, drive_power, load_torque, from_time; see
                       `crankfmu.compare`)

This module checks the file's shape and values. Whether names exist in the FMUs, and whether
connections match in causality, type and unit, is checked against the FMUs' model descriptions
in `crankfmu.cosim.wiring` before anything runs.
"""
from __future__ import annotations

import bisect
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .swap import read_scene_table

ALGORITHMS = ("gauss-seidel", "jacobi", "iterative", "adaptive")
TOP_LEVEL_KEYS = {"scene", "master", "components", "connections", "inputs", "record", "swap",
                  "analysis"}


class SceneError(ValueError):
    """A scene file problem; the message names the file and the key."""

    def __init__(self, path, key: str, message: str):
        self.path, self.key = path, key
        super().__init__(f"{path}: {key}: {message}")


@dataclass
class Component:
    name: str
    fmu: str
    parameters: dict[str, float | bool] = field(default_factory=dict)
    effects: list[str] = field(default_factory=list)


@dataclass(frozen=True)
class Connection:
    source: str  # "comp.var"
    target: str

    @property
    def source_component(self) -> str:
        return self.source.split(".", 1)[0]

    @property
    def target_component(self) -> str:
        return self.target.split(".", 1)[0]


@dataclass
class InputSignal:
    """A constant or a time table for an unconnected input."""

    target: str
    times: list[float]
    values: list[float]
    interpolation: str = "linear"  # or "step"

    def value_at(self, t: float) -> float:
        if len(self.times) == 1:
            return self.values[0]
        if self.interpolation == "step":
            return self.values[max(0, bisect.bisect_right(self.times, t) - 1)]
        return float(np.interp(t, self.times, self.values))


@dataclass
class Master:
    algorithm: str = "gauss-seidel"
    step: float = 1e-3
    extrapolation: int = 0
    tolerance: float = 1e-6       # iterative/adaptive masters: interface convergence / step error
    fmu_tolerance: float = 1e-8   # each FMU's internal solver (fmi2SetupExperiment)
    order: list[str] = field(default_factory=list)
    max_iterations: int = 20
    min_step: float = 1e-6
    max_step: float = 1e-2


@dataclass
class Scene:
    path: Path
    name: str
    description: str
    start_time: float
    stop_time: float
    master: Master
    components: dict[str, Component]
    connections: list[Connection]
    inputs: dict[str, InputSignal]
    record: list[str]
    record_interval: float | None
    raw: dict


def _number(path, key, value, *, positive=False, minimum=None) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise SceneError(path, key, f"must be a finite number, got {value!r}")
    if positive and value <= 0:
        raise SceneError(path, key, f"must be > 0, got {value!r}")
    if minimum is not None and value < minimum:
        raise SceneError(path, key, f"must be >= {minimum}, got {value!r}")
    return float(value)


def _table(path, key, value) -> dict:
    if not isinstance(value, dict):
        raise SceneError(path, key, f"must be a table, got {type(value).__name__}")
    return value


def _only_keys(path, key, table: dict, allowed: set[str]) -> None:
    unknown = set(table) - allowed
    if unknown:
        raise SceneError(path, f"{key}.{sorted(unknown)[0]}",
                         f"unknown key; allowed: {', '.join(sorted(allowed))}")


def _variable_ref(path, key, value, components) -> str:
    if not isinstance(value, str) or value.count(".") < 1:
        raise SceneError(path, key, f"must be \"component.variable\", got {value!r}")
    comp = value.split(".", 1)[0]
    if comp not in components:
        raise SceneError(path, key, f"unknown component {comp!r}; components: "
                                    f"{', '.join(components)}")
    return value


def _parse_master(path, raw: dict) -> Master:
    m = Master()
    _only_keys(path, "[master]", raw, set(Master.__dataclass_fields__))
    if "algorithm" in raw:
        if raw["algorithm"] not in ALGORITHMS:
            raise SceneError(path, "[master].algorithm",
                             f"{raw['algorithm']!r} is not one of {', '.join(ALGORITHMS)}")
        m.algorithm = raw["algorithm"]
    for key in ("step", "tolerance", "fmu_tolerance", "min_step", "max_step"):
        if key in raw:
            setattr(m, key, _number(path, f"[master].{key}", raw[key], positive=True))
    if "extrapolation" in raw:
        if raw["extrapolation"] not in (0, 1, 2) or isinstance(raw["extrapolation"], bool):
            raise SceneError(path, "[master].extrapolation",
                             f"must be 0, 1 or 2, got {raw['extrapolation']!r}")
        m.extrapolation = int(raw["extrapolation"])
    if "max_iterations" in raw:
        m.max_iterations = int(_number(path, "[master].max_iterations", raw["max_iterations"],
                                       positive=True))
    if "order" in raw:
        m.order = list(raw["order"])
    return m


def _parse_component(path, name: str, raw) -> Component:
    key = f"[components.{name}]"
    raw = _table(path, key, raw)
    _only_keys(path, key, raw, {"fmu", "parameters", "effects", "description"})
    if not isinstance(raw.get("fmu"), str):
        raise SceneError(path, f"{key}.fmu", "required: the FMU's model name (e.g. "
                                             "\"DcServoMotor\") or a path to a .fmu file")
    params = _table(path, f"{key}.parameters", raw.get("parameters", {}))
    for pname, value in params.items():
        if not isinstance(value, bool):
            _number(path, f"{key}.parameters.{pname}", value)
    effects = raw.get("effects", [])
    if not isinstance(effects, list) or not all(isinstance(e, str) for e in effects):
        raise SceneError(path, f"{key}.effects", "must be a list of effect names")
    return Component(name, raw["fmu"], dict(params), list(effects))


def _parse_input(path, target: str, raw) -> InputSignal:
    key = f"[inputs].\"{target}\""
    if isinstance(raw, (int, float)) and not isinstance(raw, bool):
        return InputSignal(target, [0.0], [_number(path, key, raw)])
    if not isinstance(raw, dict):
        raise SceneError(path, key, "must be a finite number or {table = [[t, v], ...]}, "
                                    f"got {raw!r}")
    _only_keys(path, key, raw, {"table", "interpolation"})
    rows = raw.get("table")
    if not isinstance(rows, list) or not rows or \
            not all(isinstance(r, list) and len(r) == 2 for r in rows):
        raise SceneError(path, f"{key}.table", "must be a list of [time, value] pairs")
    times = [_number(path, f"{key}.table", r[0]) for r in rows]
    values = [_number(path, f"{key}.table", r[1]) for r in rows]
    if any(b <= a for a, b in zip(times, times[1:])):
        raise SceneError(path, f"{key}.table", "times must increase strictly")
    interp = raw.get("interpolation", "linear")
    if interp not in ("linear", "step"):
        raise SceneError(path, f"{key}.interpolation", f"must be linear or step, got {interp!r}")
    return InputSignal(target, times, values, interp)


def parse_scene(path: Path, data: dict) -> Scene:
    _only_keys(path, "(top level)", data, TOP_LEVEL_KEYS)
    head = _table(path, "[scene]", data.get("scene", {}))
    _only_keys(path, "[scene]", head, {"name", "description", "start_time", "stop_time"})
    start = _number(path, "[scene].start_time", head.get("start_time", 0.0))
    if "stop_time" not in head:
        raise SceneError(path, "[scene].stop_time", "required: the end of the run in s")
    stop = _number(path, "[scene].stop_time", head["stop_time"])
    if stop <= start:
        raise SceneError(path, "[scene].stop_time", f"must exceed start_time = {start}")
    comps_raw = _table(path, "[components]", data.get("components", {}))
    if not comps_raw:
        raise SceneError(path, "[components]", "a scene needs at least one component")
    components = {n: _parse_component(path, n, c) for n, c in comps_raw.items()}
    connections = []
    for k, c in enumerate(data.get("connections", [])):
        key = f"[[connections]] #{k + 1}"
        c = _table(path, key, c)
        _only_keys(path, key, c, {"from", "to"})
        connections.append(Connection(_variable_ref(path, f"{key}.from", c.get("from"), components),
                                      _variable_ref(path, f"{key}.to", c.get("to"), components)))
    targets = [c.target for c in connections]
    for t in targets:
        if targets.count(t) > 1:
            raise SceneError(path, "[[connections]]", f"input {t} is connected more than once")
    inputs = {}
    for target, raw in _table(path, "[inputs]", data.get("inputs", {})).items():
        _variable_ref(path, f"[inputs].\"{target}\"", target, components)
        if target in targets:
            raise SceneError(path, f"[inputs].\"{target}\"", "this input is already connected")
        inputs[target] = _parse_input(path, target, raw)
    rec = _table(path, "[record]", data.get("record", {}))
    _only_keys(path, "[record]", rec, {"variables", "interval"})
    record = [_variable_ref(path, "[record].variables", v, components)
              for v in rec.get("variables", [])]
    interval = rec.get("interval")
    if interval is not None:
        interval = _number(path, "[record].interval", interval, positive=True)
    master = _parse_master(path, _table(path, "[master]", data.get("master", {})))
    for name in master.order:
        if name not in components:
            raise SceneError(path, "[master].order", f"unknown component {name!r}")
    return Scene(Path(path), head.get("name", Path(path).stem), head.get("description", ""),
                 start, stop, master, components, connections, inputs, record, interval, data)


def load_scene(path) -> Scene:
    path = Path(path)
    if path.suffix.lower() == ".ssp":  # an SSP archive (crankfmu export-ssp or another tool)
        from ..ssp.load import load_ssp
        return load_ssp(path)
    return parse_scene(path, read_scene_table(path))


def apply_overrides(scene: Scene, assignments: list[str]) -> None:
    """--set comp.param=value (numbers, true/false) on the loaded scene."""
    for text in assignments:
        if "=" not in text or "." not in text.split("=", 1)[0]:
            raise SceneError(scene.path, f"--set {text}", "must look like comp.param=value")
        ref, value = text.split("=", 1)
        comp, param = ref.split(".", 1)
        if comp not in scene.components:
            raise SceneError(scene.path, f"--set {text}", f"unknown component {comp!r}; "
                                                          f"components: {', '.join(scene.components)}")
        lowered = value.strip().lower()
        if lowered in ("true", "false"):
            parsed: float | bool = lowered == "true"
        else:
            try:
                parsed = float(value)
            except ValueError:
                raise SceneError(scene.path, f"--set {text}",
                                 f"value {value!r} is not a number or true/false") from None
        scene.components[comp].parameters[param] = parsed
