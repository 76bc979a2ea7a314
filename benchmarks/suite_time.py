"""The test suite's wall time and CPU, this checkout against another commit or Python, alternated.

    python benchmarks/suite_time.py [--against REV | --python PYTHON] [--repeat 3] [--fresh]
                                    [--idle SECONDS] [PYTEST ARGS]

Runs `python -m pytest -q -p no:cacheprovider [PYTEST ARGS]` (the README's test command) in
this checkout and, with --against, in a temporary git worktree of REV (removed at the end),
taking turns: REV, this, REV, this, ... --repeat times each. With --python, the other runs are
a temporary worktree of HEAD's under the interpreter PYTHON (a venv's python with the test
extras installed, `PYTHON -m pip install -e ".[test]"`; its own worktree because a build
records the Python that made it, and the tests check that against theirs): what the
interpreter's build costs (docs/testing.md, "How long the suite takes"). A shared machine's
speed drifts by 5-10 % over an hour, so only runs made in turn compare. Prints each run's
wall time and the CPU the whole machine was busy for meanwhile (user + nice + system + irq +
softirq from /proc/stat, in core-seconds: every process the suite starts, fork servers'
children included, which `/usr/bin/time` misses; run it on an otherwise idle machine), then
the medians and their ratio. Linux only (/proc/stat). Each checkout's first run may build its
FMUs into its fmus/: a run before the measured ones warms both (--no-warm-up skips it).

--fresh measures what CI and the README's test command run: a fresh clone. This checkout's
runs are then made in a temporary clone of HEAD (its committed state), and before each run
every checkout is cleaned of what is not in git (`git clean -xdf`: no fmus/, no bytecode) and
given an empty user cache (XDG_CACHE_HOME); no warm-up. --idle SECONDS leaves the machine idle
that long before each run (a run right after another may find a shared machine slower) and
prints the load average each run starts at.

Before each run, a plain Python loop (PROBE, best of 5, about 2 s) by the run's interpreter
says how fast the machine is at that moment: runs of other days compare through it.
"""
from __future__ import annotations

import argparse
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


# the machine's speed of the moment: `python -m timeit` of a loop of integer arithmetic
PROBE = ["-m", "timeit", "-n", "3", "-r", "5", "-s", "r = range(3_000_000)", "s = 0",
         "for i in r: s += i * i % 7"]


def probe_ms(python: str) -> float:
    """The best of five times of the PROBE loop by `python`, in ms."""
    out = subprocess.run([python, *PROBE], capture_output=True, text=True, check=True).stdout
    value, unit = out.split(":", 1)[1].split()[:2]  # "3 loops, best of 5: 129 msec per loop"
    return float(value) * {"sec": 1e3, "msec": 1.0, "usec": 1e-3}[unit]


def busy_seconds() -> float:
    """Core-seconds the machine has been busy since boot (the first line of /proc/stat)."""
    fields = [int(v) for v in Path("/proc/stat").read_text().split("\n", 1)[0].split()[1:]]
    user, nice, system, _idle, _iowait, irq, softirq = fields[:7]
    return (user + nice + system + irq + softirq) / os.sysconf("SC_CLK_TCK")


def run_suite(checkout: Path, pytest_args: list[str], python: str = sys.executable,
              env: dict[str, str] | None = None) -> tuple[float, float, str]:
    """(wall s, busy core-s, pytest's last line) of one run of the suite in `checkout` by the
    interpreter `python`, with `env` added to the environment."""
    env = {**os.environ, "PYTHONPATH": str(checkout / "sources"), **(env or {})}
    busy, start = busy_seconds(), time.perf_counter()
    done = subprocess.run([python, "-m", "pytest", "-q", "-p", "no:cacheprovider",
                           *pytest_args], cwd=checkout, env=env, capture_output=True, text=True)
    wall, cpu = time.perf_counter() - start, busy_seconds() - busy
    last = (done.stdout.strip().splitlines() or ["(no output)"])[-1]
    return wall, cpu, last


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--against", help="a git revision to compare with (a worktree of it)")
    parser.add_argument("--python", help="another interpreter to run this checkout's suite with")
    parser.add_argument("--repeat", type=int, default=3, help="measured runs per checkout")
    parser.add_argument("--no-warm-up", action="store_true", help="no unmeasured first run")
    parser.add_argument("--fresh", action="store_true",
                        help="each run from a fresh clone: this checkout's HEAD cloned, every "
                             "checkout cleaned (git clean -xdf) and an empty user cache before "
                             "each run")
    parser.add_argument("--idle", type=float, default=0.0, metavar="SECONDS",
                        help="wait this long, the machine idle, before each run")
    args, pytest_args = parser.parse_known_args()
    if args.against and args.python:
        parser.error("--against or --python, not both")
    python = sys.executable
    if args.python:
        python = shutil.which(args.python) or args.python
        if not Path(python).is_file():
            parser.error(f"--python: no interpreter at {args.python}")
        if _uncommitted():
            print("note: the other interpreter runs HEAD, without this checkout's uncommitted "
                  "changes", flush=True)
    if args.fresh and _uncommitted():
        print("note: --fresh runs HEAD, without this checkout's uncommitted changes", flush=True)
    revision = args.against or ("HEAD" if args.python else None)
    with tempfile.TemporaryDirectory(prefix="suite_time_") as tmp:
        checkouts = {"this": (ROOT, sys.executable)}
        if args.fresh:  # never clean this checkout itself: a clone of it is cleaned instead
            clone = Path(tmp) / "this"
            subprocess.run(["git", "clone", "-q", str(ROOT), str(clone)], check=True)
            checkouts = {"this": (clone, sys.executable)}
        if revision:  # a checkout of its own: its fmus/ built by its interpreter
            other = Path(tmp) / "other"
            subprocess.run(["git", "worktree", "add", "--detach", "-q", str(other), revision],
                           cwd=ROOT, check=True)
            checkouts = {args.python or revision: (other, python), "this": checkouts["this"]}
        try:
            return _measure(checkouts, args, pytest_args)
        finally:
            if revision:
                subprocess.run(["git", "worktree", "remove", "--force", str(other)], cwd=ROOT)


def _measure(checkouts: dict[str, tuple[Path, str]], args, pytest_args: list[str]) -> int:
    """Each named (checkout, interpreter) in turn, the last one named "this"."""
    if not (args.no_warm_up or args.fresh):
        for name, (checkout, python) in checkouts.items():
            print(f"warm-up {name}: {run_suite(checkout, pytest_args, python)[2]}", flush=True)
    runs: dict[str, list[tuple[float, float]]] = {name: [] for name in checkouts}
    for _ in range(args.repeat):
        for name, (checkout, python) in checkouts.items():
            env = _fresh(checkout) if args.fresh else {}
            time.sleep(args.idle)
            load = os.getloadavg()[0]
            speed = probe_ms(python)
            wall, cpu, last = run_suite(checkout, pytest_args, python, env)
            runs[name].append((wall, cpu))
            print(f"{name:>12}: {wall:6.1f} s wall, {cpu:6.1f} core-s busy   "
                  f"[{last}] {time.strftime('%H:%M:%S')}, load {load:.2f} and probe "
                  f"{speed:.0f} ms at its start", flush=True)
    medians = {name: (statistics.median(w for w, _ in r), statistics.median(c for _, c in r))
               for name, r in runs.items()}
    for name, (wall, cpu) in medians.items():
        print(f"median {name:>12}: {wall:6.1f} s wall, {cpu:6.1f} core-s busy")
    if len(medians) == 2:
        (other, (w0, c0)), (_, (w1, c1)) = medians.items()
        print(f"ratio this / {other}: wall {w1 / w0:.3f}, busy {c1 / c0:.3f}")
    return 0


def _uncommitted() -> bool:
    return bool(subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"],
                               cwd=ROOT, capture_output=True, text=True).stdout.strip())


def _fresh(checkout: Path) -> dict[str, str]:
    """Clean a temporary checkout as a fresh clone is (git clean -xdf); the environment of an
    empty user cache (a new folder in the checkout: the next clean removes it)."""
    subprocess.run(["git", "clean", "-q", "-xdf"], cwd=checkout, check=True)
    cache = checkout / ".suite_time_cache"
    cache.mkdir()
    return {"XDG_CACHE_HOME": str(cache)}


if __name__ == "__main__":
    sys.exit(main())
