"""The clutch-driven mill stand (scenarios/clutch_mill_stand.toml: induction motor + planetary
clutch drive + mill stand in mode driven_crank, carrier rigidly on the crank shaft) against the
monolithic RIGID reference of tests/support/clutch_reference.py (the stand in its integrating mode, its
load read from crank_acceleration and reduced_inertia, inputs from the state, one ODE at rtol
1e-11), and its energy balance.

Master and step: Gauss-Seidel [drive, stand, motor], h = 1 ms (the scene's): the stand's torque
and inertia J(phi)/i^2, the motor torque and the carrier's angle and speed are held over the
step, O(h) coupling errors. Window: engagement at 0.1 s, 1.4 s of strokes, stop at 1.5 s, the
carrier locks at 1.79 s; 1.9 s covers it all.
"""
from __future__ import annotations

import numpy as np
import pytest

from tests.support import clutch_reference as C
from tests.conftest import SCENARIOS
from crankfmu.cosim.runner import RunOptions, run_scene
from crankfmu.system.load import load_scene

SCENE = SCENARIOS / "clutch_mill_stand.toml"
T = 1.9  # s
SIGNALS = ("stand.phi", "stand.w_crank", "stand.stand_x", "drive.w_a", "drive.E_brake_b",
           "drive.E_brake_h", "stand.E_friction", "stand.E_load")
ENERGY = ("drive.W_sun", "drive.E_kin", "drive.E_resist")
# Measured at h = 1 ms (printed): <= 1.7e-3 of each signal's maximum (the ring brake's energy,
# which integrates the slip during the engagement of the 37-70 kg m^2 stand; the others
# <= 1.3e-3);
# asserted 4e-3; each halves at 0.5 ms (asserted: ratio within [1.5, 2.5]). Energy balance
# (motor work against the kinetic energy, brakes, resistances, pin friction and rolling work),
# relative to the motor work: measured 1.1e-3, asserted 2e-3 and the same ratio; the reference
# closes it to its tolerance.
SIGNAL_TOL, BALANCE_TOL, REFERENCE_BALANCE_TOL = 4e-3, 2e-3, 1e-8


def run(fmus, tmp_path_factory, h):
    sc = load_scene(SCENE)
    sc.stop_time, sc.master.step, sc.record_interval = T, h, 1e-3
    sc.record = list(dict.fromkeys(sc.record + list(SIGNALS + ENERGY)))
    out = tmp_path_factory.mktemp("clutch_stand") / f"h{h:g}.csv"
    rec = run_scene(sc, RunOptions(out=out, fmu_dir=fmus, progress=False)).recorder
    return {n: rec.column(n) for n in rec.names} | {"time": rec.rows[:, 0]}


@pytest.fixture(scope="module")
def runs(tmp_path_factory, fmu_dir):
    fmus = fmu_dir
    sc = load_scene(SCENE)
    assert sc.master.step == 1e-3 and sc.master.algorithm == "gauss-seidel"
    return {h: run(fmus, tmp_path_factory, h) for h in (1e-3, 5e-4)}


@pytest.fixture(scope="module")
def cosim(runs):
    return runs[1e-3]


@pytest.fixture(scope="module")
def reference():
    names = [n.replace("stand.", "mech.") for n in SIGNALS + ENERGY] + ["drive.n_events"]
    ref = C.run(SCENE, "stand", T, names)
    return {k.replace("mech.", "stand."): v for k, v in ref.items()}


def balance(r):
    def d(k):
        return r[k] - r[k][0]
    sinks = (d("drive.E_kin") + r["drive.E_brake_b"] + r["drive.E_brake_h"]
             + r["drive.E_resist"] + r["stand.E_friction"] + r["stand.E_load"])
    return float(np.max(np.abs(r["drive.W_sun"] - sinks)) / np.max(np.abs(r["drive.W_sun"])))


def errors(r, ref):
    return {k: float(np.max(np.abs(np.interp(ref["time"], r["time"], r[k]) - ref[k]))
                     / np.max(np.abs(ref[k]))) for k in SIGNALS}


def test_agrees_with_rigid_reference(runs, cosim, reference):
    e, e2 = errors(cosim, reference), errors(runs[5e-4], reference)
    print("\nclutch mill stand vs rigid reference, h = 1 ms: "
          + ", ".join(f"{k} {v:.1e}" for k, v in e.items()))
    print("h = 0.5 ms: " + ", ".join(f"{k} {v:.1e}" for k, v in e2.items()))
    assert max(e.values()) < SIGNAL_TOL
    for k in SIGNALS:  # first order in the step: the difference is the coupling, not the model
        assert 1.5 < e[k] / e2[k] < 2.5, k
    # the run happened: about 2.5 crank revolutions (2.48), engaged, stopped and locked (6 events:
    # two command edges, carrier free, ring locks, ring free, carrier locks) in both
    assert 2.3 < (reference["stand.phi"][-1] - reference["stand.phi"][0]) / (2 * np.pi) < 2.7
    assert reference["drive.n_events"][-1] == cosim["drive.n_events"][-1] == 6
    assert reference["stand.w_crank"][-1] == cosim["stand.w_crank"][-1] == 0.0


def test_energy_balance(runs, cosim, reference):
    """motor work = change of kinetic energy (sun, ring, carrier with the stand's J(phi)/i^2)
    + brake losses + drive resistances + pin friction + work against the rolling force. Exact
    for the reference; O(h) for the co-simulation (the stand's torque and inertia held over the
    step: the drive's E_kin jumps with J(phi) at each communication point)."""
    b_ref, b, b2 = balance(reference), balance(cosim), balance(runs[5e-4])
    print(f"\nenergy balance, relative to the motor work {cosim['drive.W_sun'][-1]:.0f} J: "
          f"reference {b_ref:.1e}, co-simulation h = 1 ms {b:.1e}, 0.5 ms {b2:.1e}")
    assert b_ref < REFERENCE_BALANCE_TOL
    assert b < BALANCE_TOL
    assert 1.5 < b / b2 < 2.5
