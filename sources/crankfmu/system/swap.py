"""`[swap]`: a scene written as a base scene with components swapped (component swaps as an
experiment: the same press with another drive, the same drive with another motor law, ...).

    [swap]
    base = "servo_press.toml"     # the base scene, relative to this file (may itself be a swap)
    replace = ["motor"]           # base components removed together with every connection,
                                  # [inputs] entry and recorded variable that names them

Everything else in the file is laid over the base:
* [scene], [master], [analysis], [record].interval: key by key (this file wins);
* [components.X]: X in `replace` or new: taken from this file (needs `fmu`); X kept from the base
  and also given here: `fmu` and `effects` replace the base's if given, `parameters` are updated
  key by key (so `[components.press] parameters = {m5 = 80.0}` changes one value);
* [[connections]]: the base's (minus the replaced components') plus this file's; a connection
  here to an input the base already connects replaces the base's;
* [inputs]: the base's (minus replaced components' and inputs connected here) updated by this
  file's;
* [record].variables: the base's (minus replaced components') followed by this file's, once each.
The result is an ordinary scene (the merged table, with `swap` kept for the record).
"""
from __future__ import annotations

import copy
import tomllib
from pathlib import Path

from ..errors import MAX_SCENE_FILE_BYTES, SceneError

MAX_SWAP_DEPTH = 16  # bases of bases
TABLES = ("scene", "master", "components", "inputs", "record", "analysis", "swap")


def _error(path, key, msg):
    return SceneError(path, key, msg)


def _names(ref) -> str | None:
    return ref.split(".", 1)[0] if isinstance(ref, str) else None


def read_text(path: Path, what: str = "scene file") -> str:
    """A scene file's text: a regular file, at most MAX_SCENE_FILE_BYTES, UTF-8."""
    try:
        if not path.exists():
            raise _error(path, "(file)", f"no such {what}")
        if not path.is_file():
            raise _error(path, "(file)", f"not a regular file (a {what} is a TOML file)")
        with open(path, "rb") as f:
            data = f.read(MAX_SCENE_FILE_BYTES + 1)
    except OSError as err:
        raise _error(path, "(file)", f"cannot read it: {err.strerror or err}") from None
    if len(data) > MAX_SCENE_FILE_BYTES:
        raise _error(path, "(file)", f"larger than {MAX_SCENE_FILE_BYTES >> 20} MiB; a {what} "
                                     "is a short TOML file")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as err:
        raise _error(path, "(file)", f"not UTF-8 text (byte {err.start}: "
                                     f"{data[err.start:err.start + 1]!r}); TOML is UTF-8") from None


def check_shape(path, data: dict) -> None:
    """The types of the tables that [swap] merges, so merging never meets a wrong type (the
    values inside are checked by parse_scene)."""
    for key in TABLES:
        if key in data and not isinstance(data[key], dict):
            raise _error(path, f"[{key}]", f"must be a table, got {type(data[key]).__name__}")
    if not isinstance(data.get("connections", []), list) or \
            not all(isinstance(c, dict) for c in data.get("connections", [])):
        raise _error(path, "[[connections]]", "must be an array of tables "
                                              "{from = \"comp.output\", to = \"comp.input\"}")
    for name, comp in data.get("components", {}).items():
        if not isinstance(comp, dict):
            raise _error(path, f"[components.{name}]", f"must be a table, got "
                                                       f"{type(comp).__name__}")
        if not isinstance(comp.get("parameters", {}), dict):
            raise _error(path, f"[components.{name}].parameters", "must be a table "
                                                                  "{name = value, ...}")
    if not isinstance(data.get("record", {}).get("variables", []), list):
        raise _error(path, "[record].variables", "must be a list of \"component.variable\" "
                                                 "names")


def read_scene_table(path: Path, seen: tuple = ()) -> dict:
    """The scene file's TOML table, with a `[swap]` resolved against its base (recursively;
    `seen` holds the files on the way, to report a cycle)."""
    path = Path(path)
    if path.resolve() in seen:
        raise _error(path, "[swap].base", "the swap bases form a cycle: "
                     + " -> ".join(str(p) for p in seen + (path.resolve(),)))
    if len(seen) > MAX_SWAP_DEPTH:
        raise _error(path, "[swap].base", f"more than {MAX_SWAP_DEPTH} swap bases in a chain")
    text = read_text(path)
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        raise _error(path, "(syntax)", f"not valid TOML: {err}") from None
    except RecursionError:
        raise _error(path, "(syntax)", "nested too deeply") from None
    check_shape(path, data)
    if "swap" in data:
        data = resolve_swap(path, data, seen + (path.resolve(),))
    return data


def resolve_swap(path, data: dict, seen: tuple = ()) -> dict:
    """The scene table `data` (read from `path`) with its [swap] resolved against its base."""
    path = Path(path)
    swap = data["swap"]
    check_shape(path, data)
    if not isinstance(swap, dict) or not isinstance(swap.get("base"), str) or not swap["base"] \
            or "\0" in swap["base"]:
        raise _error(path, "[swap].base", "required: the base scene file, relative to this one")
    unknown = set(swap) - {"base", "replace"}
    if unknown:
        raise _error(path, f"[swap].{sorted(unknown)[0]}", "unknown key; allowed: base, replace")
    replace = swap.get("replace", [])
    if not isinstance(replace, list) or not all(isinstance(r, str) for r in replace):
        raise _error(path, "[swap].replace", "must be a list of component names of the base")
    base_path = (path.parent / swap["base"])
    try:
        if not base_path.exists():
            raise _error(path, "[swap].base", f"{base_path}: no such scene file (the base scene, "
                                              "relative to this file)")
        if not base_path.is_file():
            raise _error(path, "[swap].base", f"{base_path} is not a regular file (a folder or "
                                              "device): the base scene's TOML file")
    except OSError as err:
        raise _error(path, "[swap].base", f"{base_path}: {err.strerror or err}") from None
    base = copy.deepcopy(read_scene_table(base_path, seen or (path.resolve(),)))
    missing = [r for r in replace if r not in base.get("components", {})]
    if missing:
        raise _error(path, "[swap].replace", f"{missing[0]!r} is not a component of {base_path}; "
                     f"its components: {', '.join(base.get('components', {}))}")
    gone = set(replace)
    out = {k: v for k, v in base.items() if k not in ("components", "connections", "inputs",
                                                      "record", "swap")}
    for key in ("scene", "master", "analysis"):
        if key in data:
            out[key] = {**base.get(key, {}), **data[key]}
    out["components"] = _components(path, base.get("components", {}), data.get("components", {}),
                                    gone)
    new_conn = data.get("connections", [])
    connected_here = {c.get("to") for c in new_conn if isinstance(c.get("to"), str)}
    out["connections"] = [c for c in base.get("connections", [])
                          if _names(c.get("from", "")) not in gone
                          and _names(c.get("to", "")) not in gone
                          and c.get("to") not in connected_here] + list(new_conn)
    out["inputs"] = {k: v for k, v in base.get("inputs", {}).items()
                     if _names(k) not in gone and k not in connected_here}
    out["inputs"].update(data.get("inputs", {}))
    rec_base, rec_new = base.get("record", {}), data.get("record", {})
    variables = [v for v in rec_base.get("variables", []) if _names(v) not in gone]
    variables += [v for v in rec_new.get("variables", []) if v not in variables]
    if not all(isinstance(v, str) for v in variables):
        raise _error(path, "[record].variables", "must be a list of \"component.variable\" names")
    out["record"] = {**rec_base, **rec_new, "variables": variables}
    out["swap"] = swap
    return out


def _components(path, base: dict, new: dict, gone: set) -> dict:
    comps = {n: c for n, c in base.items() if n not in gone}
    for name, comp in new.items():
        if not isinstance(comp, dict):
            raise _error(path, f"[components.{name}]", "must be a table")
        if name not in comps:
            comps[name] = comp
            continue
        merged = dict(comps[name])
        for key, value in comp.items():
            if key == "parameters":
                merged["parameters"] = {**merged.get("parameters", {}), **value}
            else:
                merged[key] = value
        comps[name] = merged
    return comps
