"""Hostile and careless output folders (issue #27): `crankfmu run` of the short rotor scene with
`--out` naming a file, a FIFO, a link to one, a name too long, a folder where a result goes,
a FIFO or a link where a result goes, ...; of 16 kinds.

`output_cases(seed, n)` gives n cases (kinds in turn) in the layout of `scenes.scene_cases`,
with two more keys:
    out       the output folder, relative to the case's working folder ("results" by default):
              files may appear under it and nowhere else
    kept      paths (relative to the working folder) that must be exactly as before the run:
              same kind, same inode, same bytes for a regular file
Files are bytes, None (a folder), ("fifo",) or ("symlink", target) (write_case makes them).
"""
from __future__ import annotations

import random

from .scenes import ROTOR

SCENE = ROTOR.encode()  # name "rotor": its set is rotor.csv, rotor.json, rotor.png
KEPT = b"a file of the user's\n"


def _case(kind: str, files: dict, args: list, out: str = "results", kept=()) -> dict:
    return {"kind": kind, "files": {"scene.toml": SCENE, **files}, "scene": "scene.toml",
            "args": args, "out": out, "kept": list(kept), "evil": []}


def _kinds(rng: random.Random) -> list:
    name = rng.choice(["r.json", "r.png", "out.csv", "results.ssp"])
    member = rng.choice(["rotor.csv", "rotor.json", "rotor.png", "rotor.failed.csv"])
    plot = ["--plot"] if rng.random() < 0.5 else []
    depth = "/".join(f"d{k}" for k in range(rng.randint(2, 12)))
    return [
        _case("out_is_a_file", {name: KEPT}, ["--out", name], name, [name]),
        _case("out_is_a_fifo", {"fifo": ("fifo",)}, ["--out", "fifo"], "fifo", ["fifo"]),
        _case("out_links_to_a_fifo", {"fifo": ("fifo",), "link": ("symlink", "fifo")},
              ["--out", "link"], "link", ["fifo", "link"]),
        _case("out_links_to_a_file", {"kept.txt": KEPT, "link": ("symlink", "kept.txt")},
              ["--out", "link"], "link", ["kept.txt", "link"]),
        _case("member_is_a_fifo", {f"results/{member}": ("fifo",)}, plot,
              kept=[f"results/{member}"]),
        _case("member_links_to_a_fifo", {"fifo": ("fifo",),
                                         f"results/{member}": ("symlink", "../fifo")}, plot,
              kept=["fifo", f"results/{member}"]),
        _case("member_links_to_a_file", {"kept.txt": KEPT,
                                         f"results/{member}": ("symlink", "../kept.txt")}, plot,
              kept=["kept.txt", f"results/{member}"]),
        _case("member_is_a_folder", {f"results/{member}": None}, plot,
              kept=[f"results/{member}"]),
        _case("out_name_too_long", {}, ["--out", "x" * rng.randint(256, 5000)], "x"),
        _case("out_under_a_file", {"file": KEPT}, ["--out", "file/sub"], "file", ["file"]),
        _case("out_deep", {}, ["--out", depth] + plot, depth),
        _case("out_is_named_like_a_result", {}, ["--out", name] + plot, name),
        _case("out_existing_with_other_files", {"results/notes.txt": KEPT,
                                                "results/rotor.txt": KEPT}, plot,
              kept=["results/notes.txt", "results/rotor.txt"]),
        _case("out_outside_the_working_folder", {}, ["--out", "../elsewhere"] + plot,
              "../elsewhere"),
        _case("out_in_proc", {}, ["--out", "/proc/crankfmu-fuzz"], "/proc/crankfmu-fuzz"),
        _case("out_is_empty", {}, ["--out", ""], "."),
    ]


def output_cases(seed: int, n: int) -> list[dict]:
    rng = random.Random(seed)
    cases = []
    for k in range(n):
        kinds = _kinds(rng)
        case = kinds[k % len(kinds)]
        cases.append({**case, "id": f"out-{k:04d}-{case['kind']}", "family": "out"})
    return cases
