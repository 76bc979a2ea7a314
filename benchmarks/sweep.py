"""Wall time of a 12-run servo press sweep with --jobs 1 and --jobs 2, and the ratio.

    python benchmarks/sweep.py [--stop-time 1.0] [--repeat 3]

The sweep varies the flywheel (4 values) and the forging force (3 values) of
scenarios/servo_press.toml, each run --stop-time seconds of simulated time (default 1 s, the
analysis window from 0.5 s). Each repetition runs the two settings back to back into fresh
folders, timed around `crankfmu.sweep` (pool start-up included; the FMUs are built beforehand),
and checks that both tables are equal (wall time aside). Prints each repetition (with the load
average before it: on a shared machine other work takes cores, and with the kernel's autogroup
scheduling a session gets its share whatever its process count) and the medians.
"""
from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "sources"))

VARY = ["motor.J_flywheel=0,0.05,0.1,0.2", "press.F_max=40e3,50e3,60e3"]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--stop-time", type=float, default=1.0)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--jobs", type=int, nargs=2, default=[1, 2], metavar=("A", "B"))
    args = ap.parse_args()

    import os

    import crankfmu
    from crankfmu.system.wiring import resolve_fmu
    from crankfmu.system.load import load_scene

    scene_path = ROOT / "scenarios" / "servo_press.toml"
    scene = load_scene(scene_path)
    for name in scene.components:  # build once, outside the timing
        resolve_fmu(scene, name, ROOT / "fmus")
    from crankfmu.cosim.workers import start_method
    print(f"servo press, 12 runs of {args.stop_time:g} s, {os.cpu_count()} cores, "
          f"load average {os.getloadavg()[0]:.2f} at start; workers started by "
          f"{start_method()} (CRANKFMU_START_METHOD=spawn or fork to choose)")
    import resource

    def cpu() -> float:
        own, kids = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(
            resource.RUSAGE_CHILDREN)
        return own.ru_utime + own.ru_stime + kids.ru_utime + kids.ru_stime
    times = {j: [] for j in args.jobs}
    cpus = {j: [] for j in args.jobs}
    ratios = []
    for k in range(args.repeat):
        load = os.getloadavg()[0]
        tables = {}
        for jobs in args.jobs:
            with tempfile.TemporaryDirectory() as tmp:
                t, c = time.perf_counter(), cpu()
                tables[jobs] = crankfmu.sweep(scene_path, VARY, Path(tmp) / "out", jobs=jobs,
                                              stop_time=args.stop_time, progress=False,
                                              plot=False)
                times[jobs].append(time.perf_counter() - t)
                cpus[jobs].append(cpu() - c)
        a, b = (tables[j] for j in args.jobs)
        same = all({c: ra[c] for c in a.columns if c != "wall_time"}
                   == {c: rb[c] for c in a.columns if c != "wall_time"}
                   for ra, rb in zip(a.rows, b.rows))
        ok = sum(r["status"] == "completed" for r in a.rows)
        j1, j2 = args.jobs
        ratios.append(times[j1][-1] / times[j2][-1])
        print(f"repeat {k + 1}: --jobs {j1} {times[j1][-1]:.2f} s ({cpus[j1][-1]:.1f} s CPU), "
              f"--jobs {j2} {times[j2][-1]:.2f} s ({cpus[j2][-1]:.1f} s CPU), ratio "
              f"{ratios[-1]:.2f}; "
              f"{ok}/12 completed, tables equal: {same}; load average {load:.2f} before")
    j1, j2 = args.jobs
    m1, m2 = statistics.median(times[j1]), statistics.median(times[j2])
    print(f"median of {args.repeat}: --jobs {j1} {m1:.2f} s, --jobs {j2} {m2:.2f} s, "
          f"ratio of the medians {m1 / m2:.2f}, median of the ratios "
          f"{statistics.median(ratios):.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
