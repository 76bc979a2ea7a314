"""Ctrl-C at a random moment of `crankfmu run` (tests/test_ctrl_c.py, scripts/fuzz.py --ctrl-c).

Each trial starts crankfmu as `python -m crankfmu` does (runpy, `__main__`), from a launcher
that tells the caller when the interpreter is ready, so the moment falls in crankfmu's own life:
its imports ("imports": 0 to 0.2 s after the interpreter is up), its run ("run": 0.2 to 4 s,
a 1000 s scene: loading, stepping), or its exit handlers ("shutdown": an exit handler the
launcher registers first runs last and takes 0.6 s; 0 to 0.5 s into it). The interpreter's own
start-up before crankfmu/__main__.py's first line (site.py, runpy, the package's __init__) is
Python's, as for any Python program.

A trial is clean when the status is 130, stderr says "interrupted" and holds no traceback and
no "Exception ignored", and a CSV written (if any) is finite with a sidecar that counts its rows
and says how the run ended.
"""
from __future__ import annotations

import json
import random
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from .scenes import ROTOR  # the fuzz's short scene: "rotor", 0.05 s at 1 ms steps

LAUNCHER = """
import atexit, runpy, sys, time
def last_exit_handler():  # registered first, so it runs last: a long shutdown to interrupt
    sys.stdout.write("E"); sys.stdout.flush(); time.sleep(0.6)
atexit.register(last_exit_handler)
import crankfmu  # what runpy imports first: the package's __init__ (its version only)
sys.stdout.write("R"); sys.stdout.flush()
sys.argv = ["crankfmu"] + sys.argv[1:]
runpy.run_module("crankfmu", run_name="__main__", alter_sys=True)
"""

PHASES = ("imports", "run", "shutdown")
STOP_TIMES = {"imports": 0.02, "run": 1000.0, "shutdown": 0.02}  # s: each phase's scene


def rotor(stop: float) -> str:
    """The fuzz's rotor scene with another stop time [s]."""
    return ROTOR.replace("stop_time = 0.05", f"stop_time = {stop!r}")


def start(scene: Path, out: Path, fmu_dir: Path, cwd: Path, *extra) -> subprocess.Popen:
    """`crankfmu run` through the launcher, returned once the interpreter is up."""
    proc = subprocess.Popen([sys.executable, "-c", LAUNCHER, "run", str(scene), "--fmus",
                             str(fmu_dir), "--out", str(out), "--no-progress", *extra],
                            cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    assert proc.stdout.read(1) == b"R"
    return proc


def _wait_for_shutdown(proc: subprocess.Popen) -> None:
    while True:
        c = proc.stdout.read(1)
        assert c, "ended before its exit handlers ran"
        if c == b"E":
            return


DELAYS = {"imports": (0.0, 0.2), "run": (0.2, 4.0), "shutdown": (0.0, 0.5)}  # s: the moment


def plan(phase: str, rng: random.Random) -> tuple[str, str, float]:
    """(phase, the output folder's name, the delay [s] of the Ctrl-C in it), drawn from `rng`."""
    name = f"ctrl_c_{phase}_{rng.random():.9f}"
    return phase, name, rng.uniform(*DELAYS[phase])


def trial(planned: tuple[str, str, float], work: Path, fmu_dir: Path, cwd: Path) -> dict:
    """One Ctrl-C as `planned`; returns phase, delay, status, stderr, clean (the docstring)."""
    phase, name, delay = planned
    scene = work / f"ctrl_c_{phase}.toml"  # written by campaign
    out = work / name
    proc = start(scene, out, fmu_dir, cwd, "--no-estimate")
    if phase == "shutdown":
        _wait_for_shutdown(proc)
    time.sleep(delay)
    proc.send_signal(signal.SIGINT)
    _, stderr = proc.communicate(timeout=120)
    stderr = stderr.decode(errors="replace")
    clean = proc.returncode == 130 and "interrupted" in stderr and "Traceback" not in stderr \
        and "Exception ignored" not in stderr and _written_is_whole(out / "rotor.csv", phase,
                                                                    stderr)
    return {"phase": phase, "delay": delay, "status": proc.returncode, "stderr": stderr,
            "clean": clean}


def _written_is_whole(csv: Path, phase: str, stderr: str) -> bool:
    """No CSV (interrupted before anything was written), or a whole one whose sidecar counts
    its rows and says how the run ended, as it did: completed (the CSV reaches the scene's stop
    time) or interrupted (it does not). Where the Ctrl-C landed decides which, not the phase it
    was meant for: a Ctrl-C meant for the imports lands in the run, or after it once crankfmu
    starts and runs the 0.02 s scene in less than its delay (0.18 s in trial 7 of seed 27: it
    interrupted the run on 2026-11-26, it came after the results on 2026-11-27). One in the
    exit handlers (the phase "shutdown", or any that stderr reports there) finds the run
    completed."""
    finished = "the command had finished" in stderr  # __main__._exit: in the exit handlers
    if phase == "shutdown" and not finished:
        return False
    if not csv.is_file():
        return not finished
    rows = np.loadtxt(csv, delimiter=",", skiprows=1, ndmin=2)
    meta = json.loads(csv.with_suffix(".json").read_text())
    reached_stop = len(rows) > 0 and abs(rows[-1, 0] - STOP_TIMES[phase]) <= 1e-12
    outcome = "completed" if reached_stop else "interrupted"
    return bool(np.all(np.isfinite(rows))) and meta["csv"]["rows"] == len(rows) and \
        meta["outcome"] == outcome and (outcome == "completed" or not finished)


def campaign(n: int, seed: int, work: Path, fmu_dir: Path, cwd: Path,
             at_once: int = 1) -> list[dict]:
    """n trials, the phases in turn, `at_once` of them at a time (each is mostly waiting: the
    interpreter's start, the delay), in the order of the plan: the delays drawn for a seed
    are the same however many run at once."""
    from concurrent.futures import ThreadPoolExecutor

    rng = random.Random(seed)
    for phase in PHASES:  # written before the trials start: they share them
        (work / f"ctrl_c_{phase}.toml").write_text(rotor(STOP_TIMES[phase]))
    plans = [plan(PHASES[k % len(PHASES)], rng) for k in range(n)]
    with ThreadPoolExecutor(max(1, at_once)) as pool:
        return list(pool.map(lambda planned: trial(planned, work, fmu_dir, cwd), plans))
