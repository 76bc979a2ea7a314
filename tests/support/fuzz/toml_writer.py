"""A small TOML writer for the fuzzer (the standard library reads TOML but does not write it)."""
from __future__ import annotations

import json
import math
import re

_BARE = re.compile(r"^[A-Za-z0-9_-]+$")


def key(k) -> str:
    k = str(k)
    return k if _BARE.match(k) else json.dumps(k, ensure_ascii=False)


def value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v, ensure_ascii=False)
    if isinstance(v, list):
        return "[" + ", ".join(value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{ " + ", ".join(f"{key(k)} = {value(x)}" for k, x in v.items()) + " }"
    return json.dumps(str(v))


def _is_table_array(v) -> bool:
    return isinstance(v, list) and bool(v) and all(isinstance(x, dict) for x in v)


def dumps(data: dict) -> str:
    lines: list[str] = []
    _table(lines, [], data)
    return "\n".join(lines) + "\n"


def _table(lines, prefix: list, table: dict) -> None:
    for k, v in table.items():
        if not isinstance(v, dict) and not (_is_table_array(v) and not prefix):
            lines.append(f"{key(k)} = {value(v)}")
    for k, v in table.items():
        if isinstance(v, dict):
            name = ".".join(key(p) for p in prefix + [k])
            lines.append(f"\n[{name}]")
            _table(lines, prefix + [k], v)
    if not prefix:
        for k, v in table.items():
            if _is_table_array(v):
                for item in v:
                    lines.append(f"\n[[{key(k)}]]")
                    for ik, iv in item.items():
                        lines.append(f"{key(ik)} = {value(iv)}")
