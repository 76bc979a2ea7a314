"""The scene file (TOML): what to simulate, wired how, run by which master, recording what.

    [scene]       name, description, start_time [s], stop_time [s]
    [master]      algorithm, step [s], order, fmu_tolerance (each FMU's internal relative
                  tolerance, via fmi2SetupExperiment), max_steps (the most communication steps a
                  run may take; default crankfmu.errors.MAX_STEPS: a step that would need more is
                  refused up front), and the chosen algorithm's own options, as its master
                  declares them (crankfmu.masters: extrapolation; tolerance,
                  max_iterations for iterative; tolerance, min_step [s], max_step [s] for
                  adaptive; `crankfmu run --help` lists them); target (a requested global
                  error: `crankfmu run` then chooses master, extrapolation and step)
    [components.NAME]  fmu = "DcServoMotor" (built FMU name) or "path/to/file.fmu",
                       parameters = {name = value}, effects = ["name", ...],
                       fmi = 2 | 3 (the FMI version of a catalog FMU: fmus/X.fmu or
                       fmus/fmi3/X.fmu; default 2; an FMU file's version is the file's)
    [[connections]]    from = "comp.output", to = "comp.input"
    [inputs]           "comp.input" = value | {table = [[t, v], ...], interpolation = "linear"|"step"}
    [record]           variables = ["comp.var", ...], interval [s] (default: the master step)
    [swap]             base = "other.toml", replace = ["comp", ...]: this scene is the base scene
                       with those components swapped and the tables here laid over it (rules in
                       `crankfmu.system.swap`)
    [analysis]         roles of recorded variables for `crankfmu compare` (crank_angle,
                       crank_speed, drive_torque, drive_power, load_torque, from_time; see
                       `crankfmu.studies.compare`)

This module checks the file's shape and values. Whether names exist in the FMUs, and whether
connections match in causality, type and unit, is checked against the FMUs' model descriptions
in `crankfmu.system.wiring` before anything runs.
"""
from __future__ import annotations

import bisect
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import MAX_NAME_LENGTH, MAX_STEPS, MAX_TIME, SceneError
from ..masters.inputs import edge_reading_time

TOP_LEVEL_KEYS = {"scene", "master", "components", "connections", "inputs", "record", "swap",
                  "analysis"}


@dataclass
class Component:
    name: str
    fmu: str
    parameters: dict[str, float | bool] = field(default_factory=dict)
    effects: list[str] = field(default_factory=list)
    fmi: int = 2  # FMI version: 2 or 3 (docs/fmi3.md)


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
        if self.interpolation == "step":  # an edge a few ulps after t counts as reached
            i = bisect.bisect_right(self.times, edge_reading_time(t))
            return self.values[max(0, i - 1)]
        return float(np.interp(t, self.times, self.values))


FMI_VERSIONS = (2, 3)  # [components.X].fmi
COMMON_MASTER_KEYS = ("algorithm", "step", "fmu_tolerance", "order", "max_steps", "target")


@dataclass(eq=False)
class Master:
    """The [master] table: the keys every master shares, and `options`, the values given for
    the masters' own options (extrapolation, tolerance, ...: declared by each master class in
    crankfmu.masters). An option reads as an attribute (`m.tolerance`): the value given,
    else the chosen master's default (crankfmu.masters.option_default); setting one
    (`m.tolerance = 1e-4`) stores it unchecked (the master checks it when the run starts, the
    scene reader and `set_value` before)."""
    algorithm: str = "gauss-seidel"
    step: float = 1e-3
    fmu_tolerance: float = 1e-8   # each FMU's internal solver (fmi2SetupExperiment)
    order: list[str] = field(default_factory=list)
    max_steps: int = MAX_STEPS    # communication steps a run may take (checked before it starts)
    # the requested global error (the scene's accuracy metric): `crankfmu run` then chooses
    # master, extrapolation and step from the error estimate (crankfmu.cosim.target)
    target: float | None = None
    options: dict = field(default_factory=dict)

    def __getattr__(self, name: str):
        if name.startswith("_"):
            raise AttributeError(name)
        options = self.__dict__.get("options", {})
        if name in options:
            return options[name]
        declared = _master_options().get(name)
        if declared is None:
            raise AttributeError(f"[master] has no key {name!r}")
        from ..masters import option_default
        return option_default(self.algorithm, declared)

    def __setattr__(self, name: str, value) -> None:
        if name in self.__dataclass_fields__:
            object.__setattr__(self, name, value)
        elif name in _master_options():
            self.options[name] = value
        else:
            raise AttributeError(f"[master] has no key {name!r}")

    def resolved(self) -> dict:
        """The common keys and the chosen master's options (given or default): what the run
        uses (the sidecar's "master" table, SSP export)."""
        from ..masters import MASTERS
        cls = MASTERS.get(self.algorithm)
        own = {o.name: getattr(self, o.name) for o in (cls.options if cls else ())}
        return {"algorithm": self.algorithm, "step": self.step, **own,
                "fmu_tolerance": self.fmu_tolerance, "max_steps": self.max_steps,
                "order": list(self.order)}

    def __eq__(self, other) -> bool:
        return isinstance(other, Master) and self.resolved() == other.resolved()


def _master_options() -> dict:
    """Every option some master declares, by key. The one place the scene reader consults the
    master registry (crankfmu.masters): which keys [master] takes depends on which
    masters exist."""
    from ..masters import all_options
    return all_options()


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


def _number(path, key, value, *, positive=False, minimum=None, maximum=None) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise SceneError(path, key, f"must be a finite number, got {_show(value)}")
    try:
        value = float(value)  # a TOML integer beyond a float's range
    except OverflowError:
        raise SceneError(path, key, f"must be a finite number, got {_show(value)}") from None
    if not math.isfinite(value):
        raise SceneError(path, key, f"must be a finite number, got {value!r}")
    if positive and value <= 0:
        raise SceneError(path, key, f"must be > 0, got {value!r}")
    if minimum is not None and value < minimum:
        raise SceneError(path, key, f"must be >= {minimum:g}, got {value!r}")
    if maximum is not None and value > maximum:
        raise SceneError(path, key, f"must be <= {maximum:g}, got {value!r}")
    return value


def _show(value, limit: int = 60) -> str:
    """repr(value), shortened: error messages quote what the user gave, not all of it."""
    text = repr(value)
    return text if len(text) <= limit else text[:limit] + f"... ({len(text)} characters)"


def _integer(path, key, value, *, minimum: int, maximum: int) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or \
            (isinstance(value, float) and not value.is_integer()):
        raise SceneError(path, key, f"must be an integer, got {_show(value)}")
    if not minimum <= value <= maximum:
        raise SceneError(path, key, f"must be an integer from {minimum} to {maximum}, "
                                    f"got {_show(value)}")
    return int(value)


def _list(path, key, value, what: str) -> list:
    if not isinstance(value, list):
        raise SceneError(path, key, f"must be a list of {what}, got {type(value).__name__} "
                                    f"{_show(value)}")
    return value


def check_name(path, key, value, what: str = "name") -> str:
    """A name that becomes a file name (results/<name>.csv) or an FMU instance name: a plain
    name, never a path."""
    if not isinstance(value, str) or not value:
        raise SceneError(path, key, f"must be a non-empty string, got {_show(value)}")
    if len(value) > MAX_NAME_LENGTH:
        raise SceneError(path, key, f"a {what} has at most {MAX_NAME_LENGTH} characters, got "
                                    f"{len(value)}")
    bad = [c for c in value if c in '/\\' or ord(c) < 32 or ord(c) == 127]
    if bad or value.startswith(".") or value != value.strip():
        raise SceneError(path, key, f"{_show(value)} is not a plain {what}: no /, \\, control "
                                    "characters, leading dot or surrounding spaces (it becomes a "
                                    "file name)")
    return value


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
        raise SceneError(path, key, f"must be \"component.variable\", got {_show(value)}")
    comp = value.split(".", 1)[0]
    if comp not in components:
        raise SceneError(path, key, f"unknown component {comp!r}; components: "
                                    f"{', '.join(components)}")
    return value


def _parse_master(path, raw: dict) -> Master:
    """[master]: the common keys, then exactly the chosen master's own options."""
    from ..masters import OptionError, master_class
    m = Master()
    if "algorithm" in raw:
        try:
            master_class(raw["algorithm"])
        except OptionError as err:
            raise SceneError(path, "[master].algorithm", str(err)) from None
        m.algorithm = raw["algorithm"]
    cls = master_class(m.algorithm)
    own = {o.name: o for o in cls.options}
    unknown = set(raw) - set(COMMON_MASTER_KEYS) - set(own)
    if unknown:
        key = sorted(unknown)[0]
        raise SceneError(path, f"[master].{key}", _not_an_option(m.algorithm, key, own))
    _parse_common_master_keys(path, raw, m)
    for name, option in own.items():
        if name in raw:
            m.options[name] = _master_option(path, f"[master].{name}", option, raw[name])
    _check_between_options(path, m)
    return m


def _not_an_option(algorithm: str, key: str, own: dict) -> str:
    allowed = ", ".join(list(COMMON_MASTER_KEYS) + list(own))
    other = [n for n, c in _masters().items() if key in {o.name for o in c.options}]
    return (f"not an option of the {algorithm} master" + (
        f" (it is one of {', '.join(other)})" if other else "") + f"; allowed: {allowed}")


def _masters() -> dict:
    from ..masters import MASTERS
    return MASTERS


def _master_option(path, key: str, option, value):
    from ..masters import OptionError
    try:
        return option.check(value)
    except OptionError as err:
        raise SceneError(path, key, str(err)) from None


def _check_between_options(path, m: Master) -> None:
    from ..masters import OptionError, master_class
    cls = master_class(m.algorithm)
    try:
        cls.check_options({o.name: getattr(m, o.name) for o in cls.options})
    except OptionError as err:
        key, _, message = str(err).partition(": ")
        raise SceneError(path, key, message) from None


def _parse_common_master_keys(path, raw: dict, m: Master) -> None:
    if "step" in raw:
        m.step = _number(path, "[master].step", raw["step"], positive=True)
    if "fmu_tolerance" in raw:  # a relative tolerance
        m.fmu_tolerance = _number(path, "[master].fmu_tolerance", raw["fmu_tolerance"],
                                  positive=True, maximum=1.0)
    if "max_steps" in raw:
        m.max_steps = _integer(path, "[master].max_steps", raw["max_steps"], minimum=1,
                               maximum=10**12)
    if "order" in raw:
        m.order = _list(path, "[master].order", raw["order"], "component names")
    if "target" in raw:  # a relative error
        m.target = _number(path, "[master].target", raw["target"], positive=True, maximum=1.0)


def check_run_size(scene: "Scene", key: str = "[master].step") -> None:
    """The run fits the step-count limit and its steps are not lost in the time's rounding;
    checked after every override (command line, sweeps), before anything is loaded or run."""
    m, span = scene.master, scene.stop_time - scene.start_time
    limit = m.max_steps
    biggest = max(abs(scene.start_time), abs(scene.stop_time), 1.0)
    from ..masters import traits
    variable = traits(m.algorithm).variable_step
    smallest, which = (m.min_step, "[master].min_step") if variable else (m.step, key)
    if not (math.isfinite(span) and span > 1e-13 * biggest):
        raise SceneError(scene.path, "[scene].stop_time", f"must exceed start_time = "
                                                          f"{scene.start_time!r} by more than "
                                                          "the time's resolution")
    if not smallest > 1e-10 * biggest * 1e-3:  # 1e-13 relative: a step the time can resolve
        raise SceneError(scene.path, which, f"{smallest!r} s is below the time's resolution at "
                                            f"t = {biggest:g} s")
    count = span / smallest
    if not count <= limit:
        raise SceneError(scene.path, which, f"{smallest!r} s from start_time {scene.start_time:g} "
                         f"to stop_time {scene.stop_time:g} s means up to {count:.3g} "
                         f"communication steps, more than the limit of {limit} "
                         "([master].max_steps or --max-steps raises it)")
    if m.algorithm in _masters():
        _check_between_options(scene.path, m)


def _parse_component(path, name: str, raw) -> Component:
    key = f"[components.{name}]"
    raw = _table(path, key, raw)
    _only_keys(path, key, raw, {"fmu", "parameters", "effects", "description", "fmi"})
    check_name(path, key, name, "component name")
    if "." in name:
        raise SceneError(path, key, f"a component name holds no dot (\"{name}.x\" would be "
                                    "ambiguous)")
    if not isinstance(raw.get("fmu"), str) or not raw["fmu"] or "\0" in raw["fmu"]:
        raise SceneError(path, f"{key}.fmu", "required: the FMU's model name (e.g. "
                                             "\"DcServoMotor\") or a path to a .fmu file")
    params = _table(path, f"{key}.parameters", raw.get("parameters", {}))
    for pname, value in params.items():
        if not isinstance(value, bool):
            params[pname] = _number(path, f"{key}.parameters.{pname}", value)
    effects = raw.get("effects", [])
    if not isinstance(effects, list) or not all(isinstance(e, str) for e in effects):
        raise SceneError(path, f"{key}.effects", "must be a list of effect names")
    if not isinstance(raw.get("description", ""), str):
        raise SceneError(path, f"{key}.description", "must be a string")
    fmi = raw.get("fmi", 2)
    if isinstance(fmi, bool) or fmi not in FMI_VERSIONS:
        raise SceneError(path, f"{key}.fmi", f"the FMI version of the component's FMU: "
                                             f"{' or '.join(map(str, FMI_VERSIONS))}, got {fmi!r}")
    return Component(name, raw["fmu"], dict(params), list(effects), int(fmi))


def _parse_input(path, target: str, raw) -> InputSignal:
    key = f"[inputs].\"{target}\""
    if isinstance(raw, (int, float)) and not isinstance(raw, bool):
        return InputSignal(target, [0.0], [_number(path, key, raw)])
    if not isinstance(raw, dict):
        raise SceneError(path, key, "must be a finite number or {table = [[t, v], ...]}, "
                                    f"got {raw!r}")
    _only_keys(path, key, raw, {"table", "interpolation"})
    rows = raw.get("table")
    if not isinstance(rows, list) or not rows or len(rows) > 1_000_000 or \
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
    name = check_name(path, "[scene].name", head["name"], "scene name") \
        if head.get("name") is not None else check_name(path, "(file name)", Path(path).stem,
                                                         "scene name")
    if not isinstance(head.get("description", ""), str):
        raise SceneError(path, "[scene].description", "must be a string")
    start = _number(path, "[scene].start_time", head.get("start_time", 0.0), minimum=-MAX_TIME,
                    maximum=MAX_TIME)
    if "stop_time" not in head:
        raise SceneError(path, "[scene].stop_time", "required: the end of the run in s")
    stop = _number(path, "[scene].stop_time", head["stop_time"], minimum=-MAX_TIME,
                   maximum=MAX_TIME)
    if stop <= start:
        raise SceneError(path, "[scene].stop_time", f"must exceed start_time = {start}")
    comps_raw = _table(path, "[components]", data.get("components", {}))
    if not comps_raw:
        raise SceneError(path, "[components]", "a scene needs at least one component")
    components = {n: _parse_component(path, n, c) for n, c in comps_raw.items()}
    connections = []
    for k, c in enumerate(_list(path, "[[connections]]", data.get("connections", []),
                                "tables {from = \"comp.output\", to = \"comp.input\"}")):
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
              for v in _list(path, "[record].variables", rec.get("variables", []),
                             "\"component.variable\" names")]
    for ref in record:
        if record.count(ref) > 1:
            raise SceneError(path, "[record].variables", f"{ref} is listed more than once")
    interval = rec.get("interval")
    if interval is not None:
        interval = _number(path, "[record].interval", interval, positive=True)
    master = _parse_master(path, _table(path, "[master]", data.get("master", {})))
    for comp in master.order:
        if not isinstance(comp, str) or comp not in components:
            raise SceneError(path, "[master].order", f"unknown component {_show(comp)}; "
                                                     f"components: {', '.join(components)}")
        if master.order.count(comp) > 1:
            raise SceneError(path, "[master].order", f"{comp!r} is listed more than once (each "
                                                     "component steps once per step)")
    _table(path, "[analysis]", data.get("analysis", {}))
    scene = Scene(Path(path), name, head.get("description", ""), start, stop, master,
                  components, connections, inputs, record, interval, data)
    check_run_size(scene)
    return scene


def apply_overrides(scene: Scene, assignments: list[str]) -> None:
    """--set REF=VALUE on the loaded scene, REF one of

        comp.param=value    a parameter (finite number, true/false)
        comp.input=value    an input that is not connected: held constant at value
        master.key=value    a [master] key (step, algorithm, extrapolation, tolerance, ...)

    Values are checked as the same key in a scene file would be; whether a parameter exists
    and takes that type is checked against the FMU (crankfmu.system.wiring)."""
    for text in assignments:
        key = f"--set {_show(text)[1:-1]}"
        if not isinstance(text, str) or "=" not in text or "." not in text.split("=", 1)[0]:
            raise SceneError(scene.path, key, "must look like comp.param=value, "
                                              "comp.input=value or master.key=value")
        ref, value = text.split("=", 1)
        set_value(scene, ref.strip(), _parse_value(scene, key, value), key)


def _parse_value(scene: Scene, key: str, value: str):
    lowered = value.strip().lower()
    if lowered in ("true", "false"):
        return lowered == "true"
    try:
        parsed = float(value)
    except ValueError:
        return value.strip()  # a word: only a master key (algorithm) takes one
    if not math.isfinite(parsed):
        raise SceneError(scene.path, key, f"value {_show(value)} is not a finite number")
    return parsed


def set_value(scene: Scene, ref: str, value, key: str | None = None) -> None:
    """Set "comp.param", "comp.input" (constant) or "master.key" to `value` (the Python API's
    parameters= and the command line's --set)."""
    key = key or f"{ref!r}"
    comp, name = ref.split(".", 1) if "." in ref else (ref, "")
    if comp == "master" and comp not in scene.components:
        _set_master(scene, name, value, key)
        return
    if comp not in scene.components:
        raise SceneError(scene.path, key, f"unknown component {_show(comp)}; components: "
                                          f"{', '.join(scene.components)} (or master.KEY)")
    if not name:
        raise SceneError(scene.path, key, "no parameter name after the component")
    if isinstance(value, str):
        raise SceneError(scene.path, key, f"value {_show(value)} is not a number or true/false")
    if ref in scene.inputs or variable_causality(scene, comp, name) == "input":
        set_input(scene, ref, value, key)
        return
    scene.components[comp].parameters[name] = value


def set_input(scene: Scene, ref: str, value, key: str | None = None) -> None:
    """Drive the unconnected input `ref` with a constant, a table [[t, v], ...], a scene file's
    {"table": ..., "interpolation": "step"} or an InputSignal (the Python API's inputs=; --set
    comp.input=value)."""
    key = key or f"[inputs].\"{ref}\""
    _variable_ref(scene.path, key, ref, scene.components)
    if any(c.target == ref for c in scene.connections):
        raise SceneError(scene.path, key, f"{ref} is connected; only an unconnected input can "
                                          "be set")
    if isinstance(value, InputSignal):
        signal = InputSignal(ref, list(value.times), list(value.values), value.interpolation)
    elif isinstance(value, bool):
        raise SceneError(scene.path, key, f"an input takes a number, got {value!r}")
    elif isinstance(value, (int, float)):
        signal = _parse_input(scene.path, ref, float(value))
    elif isinstance(value, dict):  # as in a scene file: {"table": [[t, v], ...], "interpolation"}
        signal = _parse_input(scene.path, ref, value)
    elif isinstance(value, (list, tuple)):
        signal = _parse_input(scene.path, ref, {"table": [list(r) if isinstance(r, (list, tuple))
                                                          else r for r in value]})
    else:
        raise SceneError(scene.path, key, "an input takes a number, a table [[t, v], ...] or "
                                          f"{{'table': ..., 'interpolation': ...}}, got {value!r}")
    scene.inputs[ref] = signal


def variable_causality(scene: Scene, comp: str, name: str) -> str | None:
    """The causality of comp.name from the FMU's variable table (catalog FMUs: from the physics
    model, without building; an FMU file: its modelDescription); None when unknown."""
    fmu = scene.components[comp].fmu
    try:
        if fmu.endswith(".fmu"):
            from fmpy import read_model_description
            path = (Path(scene.path).parent / fmu).resolve()
            md = read_model_description(str(path))
            found = [v.causality for v in md.modelVariables if v.name == name]
        else:
            from ..models.catalog import FMU_MODELS, physics_class
            if fmu not in FMU_MODELS:
                return None
            from ..runtime.slave import variable_table
            found = [v.causality for v in variable_table(physics_class(fmu)) if v.name == name]
    except Exception:  # noqa: BLE001 - unreadable FMU: the wiring check reports it later
        return None
    return found[0] if found else None


def _set_master(scene: Scene, name: str, value, key: str) -> None:
    """`master.KEY = value`: a common key, or an option some master declares (checked against
    that declaration; a master that does not take it ignores it, so settings can be given
    before the algorithm that uses them)."""
    options = _master_options()
    settable = sorted((set(COMMON_MASTER_KEYS) - {"order"}) | set(options))
    if name not in settable:
        raise SceneError(scene.path, key, f"unknown master key {_show(name)}; keys: "
                                          f"{', '.join(settable)}")
    if name in options:
        setattr(scene.master, name, _master_option(scene.path, key, options[name], value))
        return
    if isinstance(value, float) and value.is_integer() and name == "max_steps":
        value = int(value)
    checked = _parse_master(scene.path, {name: value})  # same checks as a [master] table
    setattr(scene.master, name, getattr(checked, name))
