"""Hostile scene files: seeded mutations of small scenes, of 49 kinds.

`scene_cases(seed, n)` gives n cases, kinds taken in turn (so every kind appears), each a dict:
    kind    the mutation's name
    files   {relative path: bytes | None (a folder)} to write into the case's folder
    scene   the scene file to run (relative path)
    evil    paths (absolute, or relative to the case's working folder) that must not exist after
            the run: where a scene name that is a path would put its results
The base scenes are short (0.05 s) so a valid mutation runs in about a second.
"""
from __future__ import annotations

import copy
import random
import tomllib
from pathlib import Path

from .toml_writer import dumps

ROOT = Path(__file__).resolve().parents[3]

ROTOR = """
[scene]
name = "rotor"
stop_time = 0.05
[master]
algorithm = "gauss-seidel"
step = 1e-3
order = ["r1", "r2"]
[components.r1]
fmu = "Rotor"
parameters = { J = 1.0, c = 10.0, w0 = 2.0 }
[components.r2]
fmu = "ShaftRotor"
parameters = { J = 0.5, k = 100.0, d_s = 0.5 }
effects = []
[[connections]]
from = "r1.flange_w"
to = "r2.flange_w"
[[connections]]
from = "r2.flange_tau"
to = "r1.flange_tau"
[record]
variables = ["r1.flange_w", "r2.w", "r1.E"]
interval = 1e-3
"""

LOOP = """
[scene]
name = "loop"
stop_time = 0.02
[master]
algorithm = "{algorithm}"
step = 1e-3
[components.a]
fmu = "StephensonPress"
effects = ["driven_crank"]
[components.b]
fmu = "StephensonPress"
effects = ["driven_crank"]
[[connections]]
from = "a.flange_w"
to = "b.shaft_w"
[[connections]]
from = "b.flange_w"
to = "a.shaft_w"
[record]
variables = ["a.flange_w", "b.flange_w"]
"""  # two presses in driven_crank, each speed feeding the other: an algebraic loop


def _servo() -> dict:
    data = tomllib.loads((ROOT / "scenarios" / "servo_press.toml").read_text())
    data["scene"]["stop_time"] = 0.05
    return data


def bases() -> dict[str, dict]:
    swap = {"swap": {"base": "servo.toml", "replace": []},
            "scene": {"name": "swapped"},
            "components": {"press": {"parameters": {"m5": 60.0}}}}
    return {"rotor": tomllib.loads(ROTOR), "servo": _servo(), "swap": swap}


# -- helpers over a nested table -----------------------------------------------------------------
def _paths(data, prefix=()):
    """Every (path, value) below data (dict keys and list indices)."""
    items = data.items() if isinstance(data, dict) else enumerate(data)
    for k, v in items:
        yield prefix + (k,), v
        if isinstance(v, (dict, list)):
            yield from _paths(v, prefix + (k,))


def _set(data, path, value):
    for k in path[:-1]:
        data = data[k]
    data[path[-1]] = value


def _delete(data, path):
    for k in path[:-1]:
        data = data[k]
    del data[path[-1]]


def _pick(rng, data, want=None):
    choices = [(p, v) for p, v in _paths(data) if want is None or want(v)]
    return rng.choice(choices) if choices else (None, None)


def _number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _replace_number(value):
    def mutate(rng, data, case):
        path, _ = _pick(rng, data, _number)
        if path is None:
            data.setdefault("scene", {})["stop_time"] = value
        else:
            _set(data, path, value)
    return mutate


def _replace_any(make):
    def mutate(rng, data, case):
        path, v = _pick(rng, data)
        if path is not None:
            _set(data, path, make(v))
    return mutate


def _components(data) -> list[str]:
    comps = data.get("components", {})
    return list(comps) if isinstance(comps, dict) else []


# -- the table-level kinds -----------------------------------------------------------------------
def delete_key(rng, data, case):
    path, _ = _pick(rng, data)
    if path is not None:
        _delete(data, path)


def table_to_scalar(rng, data, case):
    path, _ = _pick(rng, data, lambda v: isinstance(v, dict))
    if path is not None:
        _set(data, path, rng.choice([3, "x", 1.5, True]))


def list_to_scalar(rng, data, case):
    path, _ = _pick(rng, data, lambda v: isinstance(v, list))
    if path is None:
        data.setdefault("master", {})["order"] = "r1"
    else:
        _set(data, path, rng.choice(["x", 7, {"a": 1}]))


def unknown_key(rng, data, case):
    path, table = _pick(rng, data, lambda v: isinstance(v, dict))
    (table if table is not None else data)["bogus_key"] = 1


def _connections(data) -> list:
    conns = data.setdefault("connections", [])
    if not isinstance(conns, list) or not conns:
        conns = data["connections"] = [{"from": "r1.flange_w", "to": "r2.flange_w"}]
    return conns


def unknown_component_ref(rng, data, case):
    rng.choice(_connections(data))[rng.choice(["from", "to"])] = "ghost.flange_w"


def bad_port(rng, data, case):
    c = rng.choice(_connections(data))
    c["from"], c["to"] = c.get("to"), c.get("from")


def unknown_variable(rng, data, case):
    c = rng.choice(_connections(data))
    c["from"] = str(c.get("from", "x.y")).split(".")[0] + ".no_such_output"


def duplicate_target(rng, data, case):
    conns = _connections(data)
    conns.append(dict(rng.choice(conns)))


def self_connection(rng, data, case):
    comps = _components(data) or ["r1"]
    c = rng.choice(comps)
    _connections(data).append({"from": f"{c}.flange_tau", "to": f"{c}.flange_w"})


def order_duplicate(rng, data, case):
    comps = _components(data) or ["press"]
    data.setdefault("master", {})["order"] = comps + [rng.choice(comps)]


def order_unknown(rng, data, case):
    data.setdefault("master", {})["order"] = _components(data) + ["ghost"]


def record_duplicate(rng, data, case):
    rec = data.setdefault("record", {})
    variables = rec.get("variables") or ["r1.flange_w"]
    rec["variables"] = list(variables) + [rng.choice(variables)]


def record_unknown(rng, data, case):
    rec = data.setdefault("record", {})
    rec["variables"] = list(rec.get("variables", [])) + [
        rng.choice(["ghost.x", "r1.nope", "press.F6", "novariable", ""])]


def name_path(rng, data, case):
    evil = rng.choice([f"/tmp/crankfmu-fuzz-evil-{case['id']}", f"../evil-{case['id']}",
                       f"../../evil-{case['id']}", "x" * 5000, ".hidden", "a/b", "nul\x01"])
    data.setdefault("scene", {})["name"] = evil
    case["evil"] += [f"{evil}.csv", f"results/{evil}.csv"] if len(evil) < 200 else []


def effect_unknown(rng, data, case):
    comps = _components(data) or ["r1"]
    comp = data.setdefault("components", {}).setdefault(rng.choice(comps), {})
    comp["effects"] = ["no_such_effect"]


def parameter_unknown(rng, data, case):
    comps = _components(data) or ["r1"]
    comp = data.setdefault("components", {}).setdefault(rng.choice(comps), {})
    comp.setdefault("parameters", {})["no_such_parameter"] = 1.0


def parameter_bad(rng, data, case):
    comps = _components(data) or ["r1"]
    comp = data.setdefault("components", {}).setdefault(rng.choice(comps), {})
    params = comp.setdefault("parameters", {})
    name = rng.choice(list(params) or ["J"])
    params[name] = rng.choice([float("nan"), float("inf"), "x", True, -1.0, 0.0, 1e300, [1]])


def fmu_missing_file(rng, data, case):
    comps = _components(data) or ["r1"]
    data.setdefault("components", {}).setdefault(rng.choice(comps), {})["fmu"] = "nope.fmu"


def fmu_directory(rng, data, case):
    case["files"]["d.fmu"] = None
    comps = _components(data) or ["r1"]
    data.setdefault("components", {}).setdefault(rng.choice(comps), {})["fmu"] = "d.fmu"


def fmu_not_zip(rng, data, case):
    case["files"]["x.fmu"] = b"this is not a zip archive"
    comps = _components(data) or ["r1"]
    data.setdefault("components", {}).setdefault(rng.choice(comps), {})["fmu"] = "x.fmu"


def fmu_device(rng, data, case):
    comps = _components(data) or ["r1"]
    data.setdefault("components", {}).setdefault(rng.choice(comps), {})["fmu"] = "/dev/zero"


def input_table_bad(rng, data, case):
    comps = _components(data) or ["r1"]
    target = f"{rng.choice(comps)}.{rng.choice(['u', 'flange_tau', 'nope', 'w'])}"
    data.setdefault("inputs", {})[target] = rng.choice([
        {"table": [[1.0, 0.0], [0.0, 1.0]]}, {"table": []}, {"table": [[0.0]]},
        {"table": [[0.0, 1.0]], "interpolation": "cubic"}, "220", float("nan"),
        {"table": [[0.0, float("inf")]]}])


def algorithm_unknown(rng, data, case):
    data.setdefault("master", {})["algorithm"] = rng.choice(["rk4", "", "JACOBI", 3, None and 1])


def extrapolation_bad(rng, data, case):
    data.setdefault("master", {})["extrapolation"] = rng.choice([3, -1, 1.5, "2", True, 10**30])


def start_after_stop(rng, data, case):
    scene = data.setdefault("scene", {})
    scene["start_time"], scene["stop_time"] = 1.0, rng.choice([0.5, 1.0, -1e308])


def step_tiny(rng, data, case):
    master = data.setdefault("master", {})
    if rng.random() < 0.5:
        master["step"] = rng.choice([1e-12, 5e-324, 1e-300])
    else:
        master["algorithm"], master["min_step"] = "adaptive", rng.choice([1e-12, 1e-300])


def iterations_bad(rng, data, case):
    master = data.setdefault("master", {})
    master["algorithm"] = "iterative"
    master[rng.choice(["max_iterations", "tolerance", "max_steps"])] = rng.choice(
        [0, -1, 10**12, 1e300, float("nan"), 0.5, "many"])


def times_extreme(rng, data, case):
    scene = data.setdefault("scene", {})
    scene[rng.choice(["start_time", "stop_time"])] = rng.choice(
        [-1e308, 1e308, 1e20, -1e20, float("inf"), 10**400])


def record_interval_bad(rng, data, case):
    data.setdefault("record", {})["interval"] = rng.choice([0.0, -1.0, 1e300, 5e-324,
                                                            float("nan"), "1ms"])


def swap_of(kind):
    def mutate(rng, data, case):
        if kind == "cycle":
            data["swap"] = {"base": "scene.toml", "replace": []}
        elif kind == "dev_zero":
            data["swap"] = {"base": "/dev/zero", "replace": []}
        elif kind == "directory":
            case["files"]["basedir.toml"] = None
            data["swap"] = {"base": "basedir.toml", "replace": []}
        elif kind == "missing":
            data["swap"] = {"base": "missing.toml", "replace": []}
        elif kind == "replace_bad":
            data["swap"] = {"base": "servo.toml", "replace": rng.choice(
                [["ghost"], "motor", [1], ["motor", "press"]])}
    return mutate


KINDS = {
    "delete_key": delete_key,
    "to_string": _replace_any(lambda v: "text"),
    "to_list": _replace_any(lambda v: [v, v]),
    "to_table": _replace_any(lambda v: {"x": v} if not isinstance(v, dict) else 1),
    "to_bool": _replace_any(lambda v: True),
    "huge_int": _replace_number(10 ** 400),
    "zero": _replace_number(0),
    "negative": _replace_number(-1),
    "nan": _replace_number(float("nan")),
    "inf": _replace_number(float("inf")),
    "big": _replace_number(1e300),
    "tiny": _replace_number(5e-324),
    "very_negative": _replace_number(-1e308),
    "table_to_scalar": table_to_scalar,
    "list_to_scalar": list_to_scalar,
    "unknown_key": unknown_key,
    "unknown_component_ref": unknown_component_ref,
    "bad_port": bad_port,
    "unknown_variable": unknown_variable,
    "duplicate_target": duplicate_target,
    "self_connection": self_connection,
    "order_duplicate": order_duplicate,
    "order_unknown": order_unknown,
    "record_duplicate": record_duplicate,
    "record_unknown": record_unknown,
    "name_path": name_path,
    "effect_unknown": effect_unknown,
    "parameter_unknown": parameter_unknown,
    "parameter_bad": parameter_bad,
    "fmu_missing_file": fmu_missing_file,
    "fmu_directory": fmu_directory,
    "fmu_not_zip": fmu_not_zip,
    "fmu_device": fmu_device,
    "input_table_bad": input_table_bad,
    "algorithm_unknown": algorithm_unknown,
    "extrapolation_bad": extrapolation_bad,
    "start_after_stop": start_after_stop,
    "step_tiny": step_tiny,
    "iterations_bad": iterations_bad,
    "times_extreme": times_extreme,
    "record_interval_bad": record_interval_bad,
    "swap_cycle": swap_of("cycle"),
    "swap_dev_zero": swap_of("dev_zero"),
    "swap_directory": swap_of("directory"),
    "swap_missing": swap_of("missing"),
    "swap_replace_bad": swap_of("replace_bad"),
}
# kinds on the file's bytes rather than its table
TEXT_KINDS = ("truncate", "garbage_bytes", "non_utf8", "empty", "directory", "duplicate_key",
              "deep_nesting", "huge_file", "broken_bracket", "algebraic_loop")


def _text_case(rng, kind, text: str, case) -> bytes | None:
    raw = text.encode()
    if kind == "truncate":
        return raw[:rng.randrange(1, max(2, len(raw)))]
    if kind == "garbage_bytes":
        at = rng.randrange(len(raw))
        return raw[:at] + bytes(rng.randrange(256) for _ in range(rng.randrange(1, 8))) + raw[at:]
    if kind == "non_utf8":
        return raw + b"\n# \xff\xfe\xc0\n"
    if kind == "empty":
        return b""
    if kind == "directory":
        return None
    if kind == "duplicate_key":
        return raw + b"\n[scene]\nname = \"again\"\n"
    if kind == "deep_nesting":
        depth = rng.choice([100, 5000, 100000])
        return raw + b"\nextra = " + b"[" * depth + b"]" * depth + b"\n"
    if kind == "huge_file":
        return raw + b"\n#" + b"x" * (5 << 20) + b"\n"
    if kind == "broken_bracket":
        return raw.replace(b"[master]", b"[master", 1)
    if kind == "algebraic_loop":
        return LOOP.format(algorithm="jacobi").encode()
    raise ValueError(kind)


def scene_cases(seed: int, n: int) -> list[dict]:
    rng = random.Random(seed)
    base = bases()
    servo_text = dumps(base["servo"]).encode()
    kinds = list(KINDS) + list(TEXT_KINDS)
    cases = []
    for i in range(n):
        kind = kinds[i % len(kinds)]
        which = rng.choice(list(base))
        case = {"id": f"scene-{seed}-{i}", "family": "scene", "kind": f"{kind}",
                "base": which, "files": {"servo.toml": servo_text}, "scene": "scene.toml",
                "evil": []}
        data = copy.deepcopy(base[which])
        if kind in KINDS:
            KINDS[kind](rng, data, case)
            case["files"]["scene.toml"] = dumps(data).encode()
        else:
            case["files"]["scene.toml"] = _text_case(rng, kind, dumps(data), case)
        cases.append(case)
    return cases


def write_case(case: dict, folder: Path) -> Path:
    """The case's files in `folder` (bytes, None: a folder, ("fifo",), ("symlink", target));
    returns the scene file's path."""
    import os
    folder.mkdir(parents=True, exist_ok=True)
    for name, data in case["files"].items():
        path = folder / name
        path.parent.mkdir(parents=True, exist_ok=True)
        if data is None:
            path.mkdir(exist_ok=True)
        elif data == ("fifo",):
            os.mkfifo(path)
        elif isinstance(data, tuple) and data[0] == "symlink":
            path.symlink_to(data[1])
        else:
            path.write_bytes(data)
    return folder / case["scene"]


def snapshot(folder: Path, paths) -> dict:
    """What `paths` (relative to `folder`) are: kind, inode and, for a regular file, bytes."""
    import os
    import stat
    found = {}
    for name in paths:
        path = folder / name
        try:
            st = os.lstat(path)
        except OSError:
            found[name] = None
            continue
        data = path.read_bytes() if stat.S_ISREG(st.st_mode) else None
        found[name] = (stat.S_IFMT(st.st_mode), st.st_ino, data)
    return found
