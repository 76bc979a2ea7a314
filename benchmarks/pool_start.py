"""What a pool of 2 worker processes costs to start, by start method (cosim/workers.py).

    python benchmarks/pool_start.py [--pools 5] [--repeat 3]

In a process that runs a second thread (as a notebook's kernel does, or pytest-xdist's worker;
crankfmu then does not fork the process itself), each start method makes --pools pools of 2
workers one after another (cosim.workers.new_pool, both workers started and ready, then
close_pool), --repeat times, each repetition in a fresh process. Prints per method the median
wall time of the first pool and of the later ones, and the CPU of everything it started per
pool (the workers, reaped at close, and for "forkserver" the server, read from /proc at the
end: it starts once per process, with the first pool). "fork" (the parent forked while it runs
one thread, as `crankfmu sweep` is) is printed for reference, measured without the thread.
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _children_cpu() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def _server_cpu() -> float:
    """The fork server's CPU so far (0 if there is none): utime + stime from /proc."""
    from multiprocessing import forkserver
    pid = getattr(forkserver._forkserver, "_forkserver_pid", None)
    if pid is None:
        return 0.0
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def measure(method: str, pools: int) -> dict:
    """In this process: `pools` pools of 2 by `method`; wall seconds per pool, CPU in total."""
    os.environ["CRANKFMU_START_METHOD"] = method
    from crankfmu.cosim.workers import close_pool, new_pool, ready
    stop = threading.Event()
    if method != "fork":  # a second thread, as in a notebook: crankfmu would not fork here
        threading.Thread(target=stop.wait, daemon=True).start()
    walls = []
    cpu = _children_cpu()
    for _ in range(pools):
        start = time.perf_counter()
        pool, lifeline = new_pool(2)
        for future in [pool.submit(ready) for _ in range(2)]:
            future.result()
        walls.append(time.perf_counter() - start)
        close_pool(pool, lifeline)
    stop.set()
    return {"walls": walls, "cpu": _children_cpu() - cpu + _server_cpu()}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--pools", type=int, default=5)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--one", help=argparse.SUPPRESS)  # internal: one measurement
    args = parser.parse_args()
    if args.one:
        print(json.dumps(measure(args.one, args.pools)))
        return 0
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(
        filter(None, [str(ROOT / "sources"), os.environ.get("PYTHONPATH")]))}
    print(f"load average {os.getloadavg()[0]:.2f}; {args.pools} pools of 2 workers per "
          f"process, {args.repeat} processes per method (alternated)")
    results: dict = {m: [] for m in ("spawn", "forkserver", "fork")}
    for _ in range(args.repeat):
        for method in results:
            out = subprocess.run([sys.executable, __file__, "--one", method, "--pools",
                                  str(args.pools)], env=env, capture_output=True, text=True,
                                 check=True)
            results[method].append(json.loads(out.stdout.splitlines()[-1]))
    print(f"{'method':<11} {'first pool [s]':>15} {'later pools [s]':>16} "
          f"{'CPU per pool [s]':>17}")
    for method, runs in results.items():
        first = statistics.median(r["walls"][0] for r in runs)
        later = statistics.median(w for r in runs for w in r["walls"][1:])
        cpu = statistics.median(r["cpu"] / args.pools for r in runs)
        print(f"{method:<11} {first:15.3f} {later:16.3f} {cpu:17.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
