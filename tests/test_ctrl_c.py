"""Ctrl-C whenever it comes: `crankfmu run` ends with exit status 130, says "interrupted", and
prints no traceback and no "Exception ignored" (crankfmu/__main__.py).

Before: a Ctrl-C while crankfmu was imported (the first ~0.2 s) printed a traceback; one during
the interpreter's exit handlers printed "Exception ignored in atexit callback" and the exit
status stayed 0; now and then the process died by SIGINT right after writing its results; a
Ctrl-C while the error estimate's companion ran was taken for a companion that stopped, and
the command ended with exit status 0.

Each trial starts crankfmu as `python -m crankfmu` does (runpy, `__main__`), from a launcher
that tells the test when the interpreter is ready, so the random moment falls in crankfmu's
own life: its imports, its run, or its exit handlers (an exit handler registered by the
launcher, which runs last, makes that phase long enough to hit). The interpreter's own
start-up before the first line of crankfmu/__main__.py (site.py, runpy, the package's
__init__: 20-100 ms on this machine, the last part a few hundred microseconds) is Python's: a
Ctrl-C there gets Python's default handling, as for any Python program; crankfmu's first line
installs its handler.
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
import pytest

from tests.conftest import ROOT

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

ROTOR = """
[scene]
name = "rotor"
stop_time = {stop}
[master]
step = 1e-3
[components.r1]
fmu = "Rotor"
parameters = {{ J = 1.0, c = 10.0, w0 = 2.0 }}
[components.r2]
fmu = "ShaftRotor"
parameters = {{ J = 0.5, k = 100.0, d_s = 0.5 }}
[[connections]]
from = "r1.flange_w"
to = "r2.flange_w"
[[connections]]
from = "r2.flange_tau"
to = "r1.flange_tau"
[record]
variables = ["r1.flange_w", "r2.w"]
"""


def _start(scene: Path, out: Path, fmu_dir: Path, *extra) -> subprocess.Popen:
    proc = subprocess.Popen([sys.executable, "-c", LAUNCHER, "run", str(scene), "--fmus",
                             str(fmu_dir), "--out", str(out), "--no-progress", *extra],
                            cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    assert proc.stdout.read(1) == b"R"  # the interpreter is up: crankfmu starts now
    return proc


def _wait_for_shutdown(proc: subprocess.Popen) -> None:
    while True:
        c = proc.stdout.read(1)
        assert c, "ended before its exit handlers ran"
        if c == b"E":
            return


def _trial(phase: str, rng: random.Random, tmp: Path, fmu_dir: Path) -> dict:
    stop = 1000.0 if phase == "run" else 0.02
    scene = tmp / f"{phase}.toml"
    scene.write_text(ROTOR.format(stop=stop))
    out = tmp / f"out_{phase}_{rng.random():.6f}"
    proc = _start(scene, out, fmu_dir, "--no-estimate")
    if phase == "imports":
        delay = rng.uniform(0.0, 0.2)
    elif phase == "run":
        delay = rng.uniform(0.2, 4.0)  # imports, FMU loading, stepping
    else:
        _wait_for_shutdown(proc)
        delay = rng.uniform(0.0, 0.5)
    time.sleep(delay)
    proc.send_signal(signal.SIGINT)
    stdout, stderr = proc.communicate(timeout=120)
    return {"phase": phase, "delay": delay, "status": proc.returncode,
            "stderr": stderr.decode(errors="replace"), "out": out}


def test_ctrl_c_20_of_20_at_random_times(tmp_path, fmu_dir):
    rng = random.Random(27)
    phases = ["imports", "run", "shutdown"] * 7
    trials = [_trial(phase, rng, tmp_path, fmu_dir) for phase in phases[:20]]
    clean = [t for t in trials if t["status"] == 130 and "interrupted" in t["stderr"]
             and "Traceback" not in t["stderr"] and "Exception ignored" not in t["stderr"]]
    print("\n".join(f"{t['phase']:9} {t['delay']:.3f} s: status {t['status']}" for t in trials))
    assert len(clean) == 20, [(t["phase"], t["delay"], t["status"], t["stderr"][-400:])
                              for t in trials if t not in clean]
    for t in trials:  # whatever was written is finite and says how the run ended
        csv = t["out"] / "rotor.csv"
        if csv.is_file():
            rows = np.loadtxt(csv, delimiter=",", skiprows=1, ndmin=2)
            assert np.all(np.isfinite(rows))
            meta = json.loads(csv.with_suffix(".json").read_text())
            assert meta["csv"]["rows"] == len(rows)
            assert meta["outcome"] == ("interrupted" if t["phase"] == "run" else "completed")


def test_ctrl_c_during_the_estimate_companion_keeps_the_run_and_exits_130(tmp_path, fmu_dir,
                                                                          monkeypatch, capsys):
    """The companion at half the step runs here after the run (--jobs 1). A Ctrl-C there
    used to be taken for a companion that stopped: the estimate said "none" and the exit
    status was 0. Now the run's results are written without an estimate, exit status 130.
    The Ctrl-C is sent by the companion's own stepping loop (this process, SIGINT) at its
    fifth step: the same path as a key press at that moment."""
    import os

    from crankfmu.cli import main
    from crankfmu.cosim import runner
    scene = tmp_path / "rotor.toml"
    scene.write_text(ROTOR.format(stop=0.05))
    fixed_steps = runner._fixed_steps

    def steps(master, scene, progress):
        for k, item in enumerate(fixed_steps(master, scene, progress)):
            if scene.master.step < 1e-3 and k == 5:  # the companion: half the scene's step
                os.kill(os.getpid(), signal.SIGINT)
            yield item
    monkeypatch.setattr(runner, "_fixed_steps", steps)
    status = main(["run", str(scene), "--fmus", str(fmu_dir), "--out", str(tmp_path / "out"),
                   "--no-progress"])
    err = capsys.readouterr().err
    assert status == 130 and "companion" in err, err
    meta = json.loads((tmp_path / "out" / "rotor.json").read_text())
    assert meta["outcome"] == "completed" and meta["csv"]["rows"] == 51
    assert meta["error_estimate"]["estimated_error"] is None
