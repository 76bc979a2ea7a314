"""Adding a model is one folder plus one registration line (docs/models.md, "Adding a model").

The example folder tests/examples/flywheel is put into a copy of the package, with one line in
models/catalog.py; a fresh interpreter on that copy builds its FMU and runs
tests/examples/servo_flywheel.toml: the DC servo motor (static law M = mu U - s w) spins up
the flywheel, (J + J_m) w' = mu U - (s + b) w, so w(t) = w_inf (1 - exp(-t/T)) with
w_inf = mu U/(s + b) and T = (J + J_m)/(s + b), the FMU driven by the real runner."""
from __future__ import annotations

import math
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np

from crankfmu.fmu.build import PACKAGE_DIR

EXAMPLES = Path(__file__).resolve().parent / "examples"
REGISTRATION = '    "Flywheel": "flywheel.flywheel:Flywheel",\n'


def package_with_the_example(tmp: Path) -> Path:
    """A copy of crankfmu with the example folder and its one registration line."""
    package = tmp / "src" / "crankfmu"
    shutil.copytree(PACKAGE_DIR, package, ignore=shutil.ignore_patterns("__pycache__"))
    shutil.copytree(EXAMPLES / "flywheel", package / "models" / "flywheel")
    catalog = package / "models" / "catalog.py"
    head = "FMU_MODELS: dict[str, str] = {\n"
    text = catalog.read_text()
    assert head in text, "the registry moved: update this test and docs/models.md"
    catalog.write_text(text.replace(head, head + REGISTRATION))
    return package


def run_example(package: Path, tmp: Path, h: float) -> tuple[np.ndarray, np.ndarray]:
    """A run of the example scene at step h in a fresh interpreter on the package copy (its
    FMUs are built into tmp/fmus by the first run and reused by the next)."""
    folder = tmp / f"run_{h:g}"  # --out names the output folder: <scene name>.csv in it
    env = dict(os.environ, PYTHONPATH=str(package.parent))
    done = subprocess.run([sys.executable, "-m", "crankfmu", "run",
                           str(EXAMPLES / "servo_flywheel.toml"), "--step", repr(h),
                           "--fmus", str(tmp / "fmus"), "--out", str(folder), "--no-progress"],
                          capture_output=True, text=True, env=env, timeout=300)
    assert done.returncode == 0, done.stderr[-3000:]
    data = np.genfromtxt(folder / "servo_flywheel.csv", delimiter=",", names=True)
    return data["time"], data["flywheelflange_w"]


def exact_speed(t: np.ndarray) -> np.ndarray:
    """The DC motor's start values (R_a = 0.5 ohm, k_phi = 1.3 V.s/rad, J_rotor = 0.05 kg.m2)
    and the scene's U = 100 V, J = 0.5 kg.m2, b = 0.1 N.m.s/rad."""
    mu, s = 1.3 / 0.5, 1.3 ** 2 / 0.5
    w_inf, T = mu * 100.0 / (s + 0.1), (0.5 + 0.05) / (s + 0.1)
    return w_inf * (1.0 - np.exp(-t / T))


def test_an_added_model_builds_and_runs_against_the_exact_spin_up(tmp_path):
    package = package_with_the_example(tmp_path)
    errors = {}
    for h in (2e-3, 1e-3):
        t, w = run_example(package, tmp_path, h)
        errors[h] = float(np.max(np.abs(w - exact_speed(t)))) / float(np.max(np.abs(w)))
    order = math.log2(errors[2e-3] / errors[1e-3])
    print(f"\nflywheel example: relative error {errors[2e-3]:.2e} at h = 2 ms, "
          f"{errors[1e-3]:.2e} at 1 ms, observed order {order:.2f}")
    # Gauss-Seidel with extrapolation 0 holds the motor torque over a step: a first-order
    # error of about h/(2T) = 3e-3 relative at 1 ms (T = 0.158 s); bound 1e-2, order 1 +- 0.2
    assert errors[1e-3] < 1e-2
    assert abs(order - 1.0) < 0.2
