"""The command line end to end, in a subprocess as a user runs it."""
from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
from fmpy.util import read_csv

from tests.conftest import ROOT, SCENARIOS


def crankfmu(*args, cwd=ROOT):
    return subprocess.run([sys.executable, "-m", "crankfmu", *map(str, args)], cwd=cwd,
                          capture_output=True, text=True, timeout=300)


def test_run_writes_csv_sidecar_and_plot(tmp_path, fmu_dir):
    out = tmp_path / "servo_press.csv"  # --out names the folder; the file is <scene name>.csv
    done = crankfmu("run", SCENARIOS / "servo_press.toml", "--fmus", fmu_dir, "--out", tmp_path,
                    "--stop-time", 0.5, "--step", 2e-3, "--set", "press.F_max=2e4", "--plot",
                    "--no-progress")
    assert done.returncode == 0, done.stderr
    rows = read_csv(out)
    assert rows["time"][-1] == 0.5 and len(rows) == 251
    assert {"press.phi", "press.w_crank", "press.slider_s", "motor.flange_tau"} <= set(
        rows.dtype.names)
    assert np.all(np.diff(rows["press.phi"]) > 0)
    meta = json.loads(out.with_suffix(".json").read_text())
    assert meta["status"] == "completed" and meta["master"]["step"] == 2e-3
    assert meta["components"]["press"]["parameters"]["F_max"] == 2e4
    assert meta["statistics"]["press"]["doStep_calls"] == 250
    assert out.with_suffix(".png").stat().st_size > 10_000


def test_errors_exit_2_with_the_reason(tmp_path, fmu_dir):
    done = crankfmu("run", SCENARIOS / "servo_press.toml", "--fmus", fmu_dir, "--out",
                    tmp_path, "--set", "press.l=0.01", "--no-progress")
    assert done.returncode == 2
    assert "parameter l = 0.01 is not allowed" in done.stderr
    done = crankfmu("run", tmp_path / "missing.toml")
    assert done.returncode == 2 and "no such scene file" in done.stderr


def test_structure_and_analyze_commands(tmp_path):
    done = crankfmu("structure", SCENARIOS / "mechanisms" / "stand_drive_p1.toml", "--json")
    assert done.returncode == 0, done.stderr
    result = json.loads(done.stdout)
    assert (result["W_chebyshev"], result["q_malyshev"], result["q_ozol"]) == (2, 3, 3)
    done = crankfmu("analyze", "impact", "--k-n", 8e7, "--s-factor", 1.1, "--out", tmp_path)
    assert done.returncode == 0, done.stderr
    assert "905.3" in done.stdout  # Pm [kN] of the first approximation (see test_rocker_impact)
