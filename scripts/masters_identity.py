"""Bit-identity check for changes to the masters: run every scene in scenarios/ with every
master setting (each algorithm x extrapolation 0, 1, 2, plus the scene's own [master]) over a
short span, and store or compare the recorded values, the per-FMU doStep counts, the master
statistics and the port-energy figures.

    python scripts/masters_identity.py save DIR      # before a change
    python scripts/masters_identity.py compare DIR   # after it: prints the worst difference

A refactoring of the masters must leave every value bit-identical (compare prints "identical");
a change that alters last bits prints the largest relative difference per scene and setting.
"""
from __future__ import annotations

import json
import sys
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
STEPS = 120  # communication steps per short run: past the start-up corrector and history fill


def settings():
    yield "scene", {}
    yield "full", None  # the scene's own [master] over its whole span
    for algorithm in ("gauss-seidel", "jacobi", "iterative", "adaptive"):
        for extrapolation in (0, 1, 2):
            yield f"{algorithm}-x{extrapolation}", {"algorithm": algorithm,
                                                    "extrapolation": extrapolation}


def run_all():
    from crankfmu import api
    out = {}
    for path in sorted((ROOT / "scenarios").glob("*.toml")):
        scene = api.load_scene(path)
        stop = min(scene.stop_time, scene.start_time + STEPS * scene.master.step)
        for label, kw in settings():
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                r = api.simulate(scene) if kw is None else api.simulate(scene, stop_time=stop,
                                                                        **kw)
            meta = {"statistics": {k: v["doStep_calls"] for k, v in r.statistics.items()},
                    "coupling": r.coupling_error,
                    "master": r.metadata.get("master_statistics")}
            out[f"{path.stem}/{label}"] = (np.asarray(r.values.tolist(), dtype=float), meta)
            print(f"{path.stem}/{label}: {len(r.values)} rows", flush=True)
    return out


def main(argv):
    mode, folder = argv[1], Path(argv[2])
    results = run_all()
    if mode == "save":
        folder.mkdir(parents=True, exist_ok=True)
        for key, (values, meta) in results.items():
            name = key.replace("/", "__")
            np.save(folder / f"{name}.npy", values)
            (folder / f"{name}.json").write_text(json.dumps(meta, sort_keys=True, default=str))
        return 0
    worst, different = 0.0, []
    for key, (values, meta) in results.items():
        name = key.replace("/", "__")
        before = np.load(folder / f"{name}.npy")
        meta_before = json.loads((folder / f"{name}.json").read_text())
        same_meta = json.dumps(meta, sort_keys=True, default=str) == json.dumps(
            meta_before, sort_keys=True)
        if before.shape != values.shape:
            different.append(f"{key}: shape {before.shape} -> {values.shape}")
            continue
        if before.tobytes() != values.tobytes() or not same_meta:
            rel = float(np.max(np.abs(values - before) / np.maximum(np.abs(before), 1e-300)))
            worst = max(worst, rel)
            different.append(f"{key}: max relative difference {rel:.3g}"
                             + ("" if same_meta else " (statistics/energies differ)"))
    print("\n".join(different) if different else
          f"identical: {len(results)} runs bit for bit (values, doStep counts, statistics, "
          "port energies)")
    return 1 if different else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
