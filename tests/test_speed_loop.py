"""The speed-controlled servo press (seed 000, eq. (29)-(30), case "b"):
scenarios/servo_press_speed_loop.toml, the DC motor's PI loop holding w_ref under the forging
load, and its current limit M_max.

Over one steady revolution (between two samples where the crank angle passes a multiple of 2 pi,
taken late in the run) the checks are:
- mean motor speed = w_ref: the PI's integral of the speed error over a periodic cycle is zero,
  so the mean equals w_ref up to what is left of the start-up transient and the time quadrature
  of 1 ms samples; the issue asks for 0.1 %.
- energy: work the press receives from the motor (the torque it holds over each step times the
  shaft's turn in that step) = forging work + change of kinetic energy (J_reduced w^2/2) + change
  of the weights' potential energy (slider and base link); the forging work from the 1 ms
  samples by the trapezoid rule, which errs by ~(h/T)^2/12 ~ 1e-4 on the 31 ms pulse; bound
  1e-3 of the forging work.
- the current limit: with M_max = 80 N.m (the forging demands ~108 N.m) the torque reaches the
  limit (in the run-up, where accelerating the press from rest demands more) and never exceeds
  it, and the energy still balances.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from crankfmu.cosim.runner import RunOptions, run_scene
from crankfmu.system.load import load_scene
from crankfmu.system.scene import apply_overrides

from tests.conftest import SCENARIOS

G = 9.80665


def _run(tmp_path, fmu_dir, overrides=()):
    scene = load_scene(SCENARIOS / "servo_press_speed_loop.toml")
    apply_overrides(scene, list(overrides))
    rec = run_scene(scene, RunOptions(out=tmp_path / "run.csv", fmu_dir=fmu_dir,
                                      progress=False)).recorder
    return scene, {name: rec.column(name) for name in rec.names}, rec.rows[:, 0]


def _last_revolution(phi):
    """Sample indices (a, b) where phi last passes two consecutive multiples of 2 pi."""
    turns = np.floor(phi / (2 * math.pi))
    passes = np.flatnonzero(np.diff(turns) > 0) + 1
    return passes[-2], passes[-1]


def _balance(scene, r, t):
    a, b = _last_revolution(r["press.phi"])
    s = slice(a, b + 1)
    p = scene.components["press"].parameters
    # the press holds the motor's torque at t_k over [t_k, t_k+1] (Gauss-Seidel, press first,
    # extrapolation 0): the work it receives is that torque times the shaft's turn in the step
    shaft_turn = np.diff(r["press.phi"][s]) * p["gear_ratio"]
    work_motor = float(np.sum(r["motor.flange_tau"][a:b] * shaft_turn))
    work_forging = np.trapezoid(r["press.F5"][s] * r["press.slider_v"][s], t[s])
    kinetic = 0.5 * r["press.J_reduced"] * r["press.w_crank"] ** 2
    potential = -p["m5"] * G * r["press.slider_s"] - p["m2"] * G * p["r"] * np.sin(r["press.phi"])
    change = kinetic[b] - kinetic[a] + potential[b] - potential[a]
    return a, b, work_motor, work_forging, change


@pytest.mark.parametrize("overrides, clips", [((), False), (("motor.M_max=80",), True)])
def test_speed_loop_holds_w_ref_and_energy_balances(tmp_path, fmu_dir, overrides, clips):
    scene, r, t = _run(tmp_path, fmu_dir, overrides)
    w_ref = scene.inputs["motor.w_ref"].value_at(0.0)
    a, b, work_motor, work_forging, change = _balance(scene, r, t)
    s = slice(a, b + 1)
    mean_speed = np.trapezoid(r["press.flange_w"][s], t[s]) / (t[b] - t[a])
    imbalance = (work_motor - work_forging - change) / work_forging
    tau = r["motor.flange_tau"]
    print(f"\nspeed loop {overrides or 'as shipped'}: revolution {t[a]:.3f}-{t[b]:.3f} s, mean motor "
          f"speed {mean_speed:.5f} rad/s (w_ref {w_ref:g}, {mean_speed / w_ref - 1:+.1e}), "
          f"motor work {work_motor:.3f} J, forging {work_forging:.3f} J, dE {change:+.4f} J, "
          f"imbalance {imbalance:+.1e}, peak torque {tau[s].max():.2f} N.m")
    assert t[a] > 1.5  # a steady revolution, late in the 3 s run
    assert abs(mean_speed / w_ref - 1.0) < 1e-3
    assert abs(imbalance) < 1e-3
    if clips:
        M_max = 80.0
        assert M_max * (1 - 1e-12) <= np.max(tau) <= M_max * (1 + 1e-12)
