"""What the error estimate of `crankfmu run` costs: each scene at its own setting without the
estimate, with it (jobs 1: the companion after the run, in this process) and with the companion
in a worker beside the run (jobs 2, the command line's default on 2 cores), in one process, the
three back to back per repeat; medians and ratios to the run without the estimate.

    PYTHONPATH=sources python benchmarks/estimate_cost.py [--scenes hammer,servo_press]
        [--repeats 3]

A worker is a spawned interpreter: each run with jobs 2 pays its start-up (~0.4 s here), which
overlaps the parent loading the FMUs. On a machine whose cores are busy with other work the
worker cannot run beside the run, and jobs 2 costs what jobs 1 does.
"""
from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
MODES = (("no estimate", False, 1), ("estimate, jobs 1", True, 1), ("estimate, jobs 2", True, 2))


def main(argv=None) -> int:
    from crankfmu.cosim.runner import RunOptions, run_scene
    from crankfmu.system.load import load_scene
    from crankfmu.system.wiring import default_fmu_dir

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--scenes")
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args(argv)
    paths = sorted((ROOT / "scenarios").glob("*.toml"))
    if args.scenes:
        paths = [p for p in paths if p.stem in set(args.scenes.split(","))]
    lines = ["| scene | " + " | ".join(f"{m[0]} [s]" for m in MODES) +
             " | ratio jobs 1 | ratio jobs 2 |", "|---" * (3 + len(MODES)) + "|"]
    for path in paths:
        scene = load_scene(path)
        fmu_dir = default_fmu_dir(scene)
        run_scene(scene, RunOptions(fmu_dir=fmu_dir, progress=False))  # build and warm up
        walls = {m[0]: [] for m in MODES}
        for _ in range(args.repeats):
            for label, estimate, jobs in MODES:
                t0 = time.perf_counter()
                run_scene(scene, RunOptions(fmu_dir=fmu_dir, progress=False,
                                            estimate=estimate, jobs=jobs))
                walls[label].append(time.perf_counter() - t0)
        med = [statistics.median(walls[m[0]]) for m in MODES]
        lines.append(f"| {scene.name} | " + " | ".join(f"{w:.2f}" for w in med) +
                     f" | {med[1] / med[0]:.2f} | {med[2] / med[0]:.2f} |")
        print(lines[-1], flush=True)
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
