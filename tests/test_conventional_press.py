"""The conventional press scene (induction motor + planetary drive + Stephenson press, carrier
rigidly on the press shaft through the press's driven_crank mode) against the monolithic RIGID
reference of tests/support/conventional_press_reference.py (one ODE, same physics modules, inputs
evaluated from the state, events located at rtol 1e-11).

Master and step: Gauss-Seidel, order [drive, press, motor], h = 1 ms (the scene's). The press
and motor torques and the press inertia J(phi)/i^2 are held over each step, an O(h) coupling
error. Measured at h = 1 ms over the first stroke (0.9 s), relative to each signal's maximum:
crank angle 3.7e-5, crank speed 8.8e-5, motor speed 9.3e-5, ring-brake energy 1.0e-4, carrier
brake energy 1.6e-5; event times within 1.4e-5 s; halving the step halves every error (first
order). Asserted: 5e-4 for the signals, 1e-4 s for the event times (about 5x the measured, far
below a lock one step late or a missed event), error ratio h/(h/2) within [1.6, 2.4].
Stability: the same 6 mode events as the reference (two command edges, two break-frees, two
locks) and the locked members exactly at 0.0, i.e. no chatter at the locks.
"""
from __future__ import annotations

import numpy as np
import pytest

from tests.support import conventional_press_reference as C
from tests.conftest import SCENARIOS
from crankfmu.cosim.runner import RunOptions, run_scene
from crankfmu.system.load import load_scene

SCENE = SCENARIOS / "conventional_press.toml"
T = 0.9  # s: the first stroke, engage at 0.1 s to the carrier's lock at ~0.78 s
SIGNAL_TOL, TIME_TOL = 5e-4, 1e-4
SIGNALS = {"phi": "press.phi", "w_crank": "press.w_crank", "w_a": "drive.w_a",
           "E_brake_b": "drive.E_brake_b", "E_brake_h": "drive.E_brake_h"}
EVENTS = ("t_slip_h", "t_lock_b", "t_slip_b", "t_lock_h")


@pytest.fixture(scope="module")
def fmus(fmu_dir):
    return fmu_dir  # the session's catalog (tests/conftest.py)


@pytest.fixture(scope="module")
def reference():
    return C.run(SCENE, T)


def run(fmus, tmp_path_factory, h):
    sc = load_scene(SCENE)
    sc.stop_time, sc.master.step, sc.record_interval = T, h, 1e-3
    sc.record = list(dict.fromkeys(sc.record + list(SIGNALS.values())
                                   + [f"drive.{k}" for k in EVENTS + ("n_events",)]))
    out = tmp_path_factory.mktemp("conventional") / f"h{h:g}.csv"
    rec = run_scene(sc, RunOptions(out=out, fmu_dir=fmus, progress=False)).recorder
    return {n: rec.column(n) for n in rec.names} | {"time": rec.rows[:, 0]}


@pytest.fixture(scope="module")
def runs(fmus, tmp_path_factory):
    assert load_scene(SCENE).master.step == 1e-3 and load_scene(SCENE).master.algorithm == \
        "gauss-seidel"
    return {h: run(fmus, tmp_path_factory, h) for h in (1e-3, 5e-4)}


def errors(r, ref):
    e = {k: float(np.max(np.abs(np.interp(ref["time"], r["time"], r[c]) - ref[k]))
                  / np.max(np.abs(ref[k]))) for k, c in SIGNALS.items()}
    e.update({k: abs(float(r[f"drive.{k}"][-1]) - ref[k][-1]) for k in EVENTS})
    return e


def test_agrees_with_rigid_reference(runs, reference):
    e1, e2 = errors(runs[1e-3], reference), errors(runs[5e-4], reference)
    print("\nconventional press vs rigid reference, h = 1 ms: "
          + ", ".join(f"{k} {v:.1e}" for k, v in e1.items()))
    print("h = 0.5 ms: " + ", ".join(f"{k} {v:.1e}" for k, v in e2.items()))
    assert max(e1[k] for k in SIGNALS) < SIGNAL_TOL
    assert max(e1[k] for k in EVENTS) < TIME_TOL
    for k in SIGNALS:  # first order in the step: the difference is the coupling, not the model
        assert 1.6 < e1[k] / e2[k] < 2.4, k
    # the stroke happened: one crank revolution (+-0.2 rad) and a forging pulse
    assert abs(reference["phi"][-1] - reference["phi"][0] - 2 * np.pi) < 0.2
    assert np.min(reference["M_C"]) < -500.0


def test_stable_locks(runs, reference):
    r = runs[1e-3]
    assert r["drive.n_events"][-1] == reference["n_events"][-1] == 6
    held_h = r["drive.period"] == 1
    held_b = r["drive.period"] == 3
    assert held_h.sum() > 100 and held_b.sum() > 100
    assert np.all(r["drive.w_h"][held_h] == 0.0)
    assert np.all(r["drive.w_b"][held_b] == 0.0)
    assert np.all(r["press.w_crank"][held_h] == 0.0)
    assert np.all(r["press.w_crank"] >= 0.0)  # never turns backwards: no sign flips
