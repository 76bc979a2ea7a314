"""Rocker impact scenes through the FMUs and the runner: the MO-100 single impact
(scenarios/mo100_impact.toml) and the crank-rocker hammer (scenarios/hammer.toml,
hammer_bearings.toml). Model cards: sources/crankfmu/models/rocker_impact/README.md, sources/crankfmu/models/rocker_impact/crank_rocker.md.
Run with -s to print the measured figures."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from crankfmu.commands.analyze import hammer_blows
from crankfmu.cosim.runner import RunOptions, run_scene
from crankfmu.runtime.model import held
from crankfmu.studies.rocker_analysis import RockerData, exact_linear, linearise
from crankfmu.models.rocker_impact.crank_rocker import CrankRockerHammer
from crankfmu.models.rocker_impact.rocker_impact import RockerImpact
from crankfmu.system.load import load_scene
from crankfmu.system.scene import apply_overrides
from tests.support.stepping import stepped

SCENARIOS = Path(__file__).resolve().parents[1] / "scenarios"
S_P = RockerData().S_percussion


@pytest.fixture(scope="module")
def fmus(fmu_dir) -> Path:
    return fmu_dir  # the session's catalog (tests/conftest.py)


def run(fmus, tmp_path, name, *overrides, stop_time=None, step=None):
    scene = load_scene(SCENARIOS / name)
    apply_overrides(scene, list(overrides))
    if stop_time:
        scene.stop_time = stop_time
    if step:
        scene.master.step = step
    result = run_scene(scene, RunOptions(out=tmp_path / f"{scene.name}.csv", fmu_dir=fmus,
                                         progress=False))
    rec = result.recorder
    return {"time": rec.rows[:, 0], **{n: rec.column(n) for n in rec.names}}


def rel(a, b):
    return abs(a / b - 1.0)


# -- MO-100 single impact ------------------------------------------------------------------------
def test_mo100_scene_reproduces_the_exact_linear_impact(fmus, tmp_path):
    """The scene as shipped: >= 100 recorded points across the pulse; P_peak, T_peak,
    impact_duration against the exact coupled linear solution (matrix exponential) with the same
    c, c0 (the paper's iterations): the issue's 0.5 % (Pm, Tm) and 1 % (tau), and 1e-7, which
    the FMU meets by a wide margin (same ODE at rtol 1e-10, events located; measured ~1e-15).
    Energy: rocker kinetic energy before = rocker + support energy after + energy radiated into
    the rod, to the issue's 1e-6, computed here from the recorded speeds and displacement."""
    col = run(fmus, tmp_path, "mo100_impact.toml")
    data = RockerData.mo100(1.1, 80e6)
    lin = linearise(data)
    ex = exact_linear(data, lin.c, lin.c0)
    points = int(col["impact.contact"].sum())
    Pm, Tm = col["impact.P_peak"][-1], col["impact.T_peak"][-1]
    tau = col["impact.impact_duration"][-1]
    print(f"\nMO-100 scene: {points} points in the pulse; Pm {Pm / 1e3:.2f} kN ({rel(Pm, ex.Pm):.1e}),"
          f" Tm {Tm / 1e3:.2f} kN ({rel(Tm, abs(ex.Tm)):.1e}), tau {tau * 1e3:.5f} ms "
          f"({rel(tau, ex.tau):.1e}) vs exact linear")
    assert points >= 100
    assert rel(col["impact.c_contact_used"][-1], lin.c) < 1e-12
    assert rel(Pm, ex.Pm) < 5e-3 and rel(Tm, abs(ex.Tm)) < 5e-3 and rel(tau, ex.tau) < 1e-2
    assert rel(Pm, ex.Pm) < 1e-7 and rel(Tm, abs(ex.Tm)) < 1e-7 and rel(tau, ex.tau) < 1e-7
    # the recorded pulse itself: its largest sample is below the located peak and within the
    # change of P over one 2 us step (P' <= c V0 = 1.3e10 N/s -> 2.7e4 N; measured far less)
    assert Pm - 2.7e4 < col["impact.P"].max() <= Pm
    # energy from the recorded states, with the model's equations of section 2
    m, r, J, S = data.m, data.r, data.J, data.S
    E0 = 0.5 * J * (data.V0 / S) ** 2
    om, u0, v0 = (col[f"impact.{n}"][-1] for n in ("flange_w", "u_support", "v_support"))
    E1 = (0.5 * m * v0 ** 2 + m * r * v0 * om + 0.5 * J * om ** 2
          + 0.5 * col["impact.c_support_used"][-1] * u0 ** 2)
    E_rad = col["impact.E_radiated"][-1]
    print(f"energy: E0 = {E0:.4f} J, after {E1:.4f} J + radiated {E_rad:.4f} J, "
          f"relative error {abs(E1 + E_rad - E0) / E0:.1e}")
    assert col["impact.contact"][-1] == 0.0
    assert abs(E1 + E_rad - E0) < 1e-6 * E0
    assert rel(col["impact.E_mech"][-1], E1) < 1e-12       # the model's own E_mech agrees


@pytest.mark.parametrize("f", [1.1, 0.9])
@pytest.mark.parametrize("k_n", [40e6, 80e6, 160e6])
def test_mo100_table_through_the_fmu_at_1ms(fmus, tmp_path, f, k_n):
    """All six rows of the table through the FMU at a 1 ms communication step (the impact is
    inside the first step): exact linear solution to 1e-7 (as above)."""
    col = run(fmus, tmp_path, "mo100_impact.toml", f"impact.S={f * S_P!r}", f"impact.k_n={k_n}",
              step=1e-3, stop_time=2e-3)
    data = RockerData.mo100(f, k_n)
    lin = linearise(data)
    ex = exact_linear(data, lin.c, lin.c0)
    assert len(col["time"]) == 3
    assert rel(col["impact.P_peak"][-1], ex.Pm) < 1e-7
    assert rel(col["impact.T_peak"][-1], abs(ex.Tm)) < 1e-7
    assert rel(col["impact.impact_duration"][-1], ex.tau) < 1e-7


def test_mo100_scene_step_does_not_change_the_impact(fmus, tmp_path):
    """Communication steps 1e-6 ... 1e-2 s give the same located impact (1e-7: the runs differ
    only in where the FMU's integrator restarts, at rtol 1e-10). Hertz contact on."""
    out = {}
    for h in (1e-6, 1e-5, 1e-4, 1e-3, 1e-2):
        col = run(fmus, tmp_path, "mo100_impact.toml", "impact.effect_hertz_contact=true",
                  step=h, stop_time=max(1e-3, h))
        out[h] = {k: col[f"impact.{k}"][-1] for k in
                  ("P_peak", "T_peak", "impact_duration", "impulse", "E_radiated")}
    ref = out[1e-3]
    worst = max(rel(o[k], ref[k]) for o in out.values() for k in ref)
    print(f"\nsteps 1e-6..1e-2 s: largest relative spread of the impact figures {worst:.1e}")
    assert worst < 1e-7


# -- the hammer ------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def hammer_runs(fmus, tmp_path_factory):
    out = tmp_path_factory.mktemp("hammer_runs")
    return {name: run(fmus, out, f"{name}.toml") for name in ("hammer", "hammer_bearings")}


@pytest.mark.parametrize("name", ["hammer", "hammer_bearings"])
def test_hammer_strikes_repeatedly_near_the_outer_dead_centre(hammer_runs, name):
    """At least 5 blows; after spin-up one blow per crank revolution, struck near the outer dead
    centre phi = pi (the design: the rocker over-swings the kinematic extreme on its spring rod).
    +-0.3 rad is the band the design aims at; measured 2.90-3.02 rad."""
    col = hammer_runs[name]
    blows = hammer_blows(col)
    print(f"\n{name}: " + "; ".join(f"V {b['V_impact']:.2f} m/s P {b['P_peak'] / 1e3:.0f} kN "
                                    f"T {b['T_peak'] / 1e3:.1f} kN" for b in blows))
    assert len(blows) >= 5
    steady = [b for b in blows if b["t"] > 0.3]
    revolutions = (col["hammer.phi"][-1] - np.interp(steady[0]["t"], col["time"],
                                                      col["hammer.phi"])) / (2 * math.pi)
    assert len(steady) == math.floor(revolutions) + 1        # one blow per revolution
    assert all(abs(b["phi"] - math.pi) < 0.3 for b in steady)
    assert all(3.0 < b["V_impact"] < 10.0 for b in steady)


@pytest.mark.parametrize("name", ["hammer", "hammer_bearings"])
def test_hammer_energy_and_port_work(hammer_runs, name):
    """W_drive (work of the motor torque, integrated in the FMU) = E_mech - E_mech(0) + radiated
    + damped, to 1e-6 of W (the FMU's rtol is 1e-8; each blow's events are located). The port
    work seen by the master, sum tau_j (flange_phi_{j+1} - flange_phi_j) (torque held over the
    step, Gauss-Seidel with the hammer first), equals W_drive to 1e-9."""
    col = hammer_runs[name]
    W = col["hammer.W_drive"]
    balance = (col["hammer.E_mech"] - col["hammer.E_mech"][0] + col["hammer.E_radiated"]
               + col["hammer.E_damped"] - W)
    W_port = np.concatenate([[0.0], np.cumsum(col["motor.flange_tau"][:-1]
                                              * np.diff(col["hammer.flange_phi"]))])
    print(f"\n{name}: W = {W[-1]:.2f} J, radiated {col['hammer.E_radiated'][-1]:.2f} J, balance "
          f"{abs(balance).max() / W[-1]:.1e}, port work {abs(W_port[-1] / W[-1] - 1):.1e}")
    assert abs(balance).max() < 1e-6 * W[-1]
    assert abs(W_port[-1] - W[-1]) < 1e-9 * W[-1]


def test_hammer_blow_equals_a_single_impact_at_the_same_speed(hammer_runs):
    """Pinned rocker: each blow of the hammer is the RockerImpact single impact at the blow's
    strike speed (Hertz), up to the rod's force during the 0.4 ms impact (about 100-200 N against
    ~500 kN; measured < 1e-4); 1e-3 is the bound. T/P = m r S/J - 1 = 0.1 to the same order."""
    for b in hammer_blows(hammer_runs["hammer"])[1:]:
        model = RockerImpact({"S": 1.1 * S_P, "V0": b["V_impact"]}, ["hertz_contact"])
        u = model.default_inputs()
        x = model.advance(0.0, model.initial_state(u), 2e-3, held(u), 1e-10,
                          1e-10 * model.state_nominal())
        out = dict(zip([v.name for v in model.outputs], model.output_values(2e-3, x, u)))
        assert rel(b["P_peak"], out["P_peak"]) < 1e-3
        assert abs(b["T_peak"] / b["P_peak"] - 0.1) < 1e-3


def test_bearing_loads_with_the_elastic_support(hammer_runs):
    """The elastic support raises the bearing load per blow from 10 % of P (pinned: m r S/J - 1)
    to the paper's order of 17-18 % (Hertz, 4 % support damping: measured 16.8 %); the contact
    force is the same within 0.5 % (the support hardly changes P: the paper's finding)."""
    pinned = hammer_blows(hammer_runs["hammer"])
    elastic = hammer_blows(hammer_runs["hammer_bearings"])
    for bp, be in zip(pinned[1:], elastic[1:]):
        assert rel(be["P_peak"], bp["P_peak"]) < 5e-3
        assert 0.15 < be["T_peak"] / be["P_peak"] < 0.19


# -- the physics model on its own -------------------------------------------------------------------
def bearing_hammer(solver):
    """hammer_bearings.toml's hammer (Hertz contact, elastic support with 4 % damping)."""
    comp = load_scene(SCENARIOS / "hammer_bearings.toml").components["hammer"]
    model = CrankRockerHammer(comp.parameters, comp.effects)
    model.solver = solver
    return model


def test_hammer_free_flight_with_the_elastic_support():
    """20 N.m on the motor shaft swings the bearings scene's hammer into a blow at 0.166 s
    (2.1 m/s), then 34 ms of its support ringing down (d0 = 2e4 N.s/m, ~4 % of critical). Out of
    contact the support is integrated in closed form (support_flight.py). Against the full
    equations by solve_ivp at rtol 1e-12 (the scipy path), every output within 1e-7 of its
    largest value at rtol 1e-10 (measured 1.0e-8, E_damped; the full equations on the runtime
    path before the closed form: 7.4e-8, v_support). Between blows a step takes one
    Dormand-Prince step of the slow states (7 calls; the full equations took 45-60 per
    millisecond, held by the support's stability limit). A step repeated from its saved state
    (x, discrete and solver state: the forcing carried between steps) is bit-identical."""
    u = [20.0, 0.0, 0.0, 0.0]
    expected, _, _ = stepped(bearing_hammer("scipy"), 0.2, 1e-3, u, 1e-12)
    model = bearing_hammer("dopri5")
    rows, calls, (x, discrete, solver) = stepped(model, 0.2, 1e-3, u, 1e-10)
    n_impacts = rows[:, model.output_index("n_impacts")]
    scale = np.maximum(np.abs(expected).max(axis=0), 1e-300)
    worst = np.abs(rows - expected).max(axis=0) / scale
    print(f"\nbearings hammer: worst {worst.max():.1e} ({model.outputs[int(worst.argmax())].name}),"
          f" calls per step median {np.median(calls):.0f}, max {max(calls)}")
    assert n_impacts[-1] == 1 and n_impacts[150] == 0
    assert worst.max() <= 1e-7
    assert np.median(calls) <= 7
    model.set_discrete_state(discrete)
    model.set_solver_state(solver)
    x = model.advance(0.199, x, 1e-3, held(u), 1e-10, 1e-10 * model.state_nominal())
    assert np.array_equal(model.output_values(0.2, x, u), rows[-1])
