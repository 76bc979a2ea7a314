"""What `crankfmu run --jobs 2` costs against --jobs 1 (the default): the error estimate's
companion run in a worker process beside the run, or after it in this process.

    python benchmarks/jobs.py [--repeat 5] [--scenes servo_press,hammer]

Each scene is run as a user runs it (`python -m crankfmu run SCENE -q --out TMP`, a fresh
process, FMUs built and bytecode cached by an untimed first run of each), --jobs 1 and --jobs 2
alternating, --repeat times each; prints the medians of wall time and of CPU time (user +
system of the process and its workers) and their ratios jobs 2 / jobs 1, and the load average
before and after: a worker gains wall time only with a core to run on, and always costs the CPU
of its start (an interpreter and the imports of a run).
"""
from __future__ import annotations

import argparse
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def timed(command: list[str], env: dict) -> tuple[float, float]:
    """(wall, CPU) seconds of `command` in a fresh process (CPU of it and its children)."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    subprocess.run(command, env=env, cwd=ROOT, check=True, stdout=subprocess.DEVNULL,
                   stderr=subprocess.DEVNULL)
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=5, help="timed runs per setting (default 5)")
    ap.add_argument("--scenes", default="servo_press,hammer",
                    help="scene names in scenarios/, a comma list (default servo_press,hammer)")
    args = ap.parse_args(argv)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(
        filter(None, [str(ROOT / "sources"), os.environ.get("PYTHONPATH")]))}
    print(f"load average {os.getloadavg()[0]:.2f} at start; {args.repeat} alternating runs "
          f"each; {os.cpu_count()} cores")
    print("| scene | jobs | median wall [s] | median CPU [s] |")
    print("|---|---|---|---|")
    ratios = []
    with tempfile.TemporaryDirectory() as out:
        for name in args.scenes.split(","):
            commands = {jobs: [sys.executable, "-m", "crankfmu", "run",
                               str(ROOT / "scenarios" / f"{name}.toml"), "-q", "--out", out,
                               "--jobs", str(jobs)] for jobs in (1, 2)}
            for command in commands.values():
                timed(command, env)  # untimed: FMUs built, bytecode written
            times = {1: [], 2: []}
            for _ in range(args.repeat):
                for jobs, command in commands.items():
                    times[jobs].append(timed(command, env))
            medians = {j: [statistics.median(x[k] for x in t) for k in (0, 1)]
                       for j, t in times.items()}
            for jobs, (wall, cpu) in medians.items():
                print(f"| {name} | {jobs} | {wall:.2f} | {cpu:.2f} |")
            ratios.append((name, medians[2][0] / medians[1][0], medians[2][1] / medians[1][1]))
    for name, wall, cpu in ratios:
        print(f"{name}: jobs 2 / jobs 1: wall {wall:.2f}, CPU {cpu:.2f}")
    print(f"load average {os.getloadavg()[0]:.2f} at end")
    return 0


if __name__ == "__main__":
    sys.exit(main())
