"""MillStandDrive: kinematics, preload and its friction, energy balance, parameter checks.

Tolerances (and why):
* kinematics against the independent loop-closure solution: 1e-12 m (brentq to 1e-15 m, the rest
  is double-precision rounding of terms of order 1 m);
* simulated revolution: the motor-side inertia 1e9 kg m^2 (reduced 1e11) keeps the crank speed
  constant to about m_s x'^2/J = 5e-9, so the stand follows the closed form with phi = w t to
  1e-7 of its stroke; the solver runs at rtol = atol = 1e-11;
* preload and friction power: closed forms evaluated by the same floating-point operations in a
  different order: 1e-12 relative (tanh(w/w_reg) = 1 to 1e-300 at w = 5 rad/s);
* friction energy per revolution against 4 mu r_pin P (pi + 2 asin(r/l)): the speed is constant
  to 5e-9 (see above) and the solver tolerance 1e-11: 1e-7 relative;
* energy balance over a revolution with friction and rolling load: the energies are integrated
  states, so the balance holds to the solver's tolerance: 1e-9 of the input work at rtol 1e-11.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import brentq

from crankfmu.runtime.model import ParameterError, held
from crankfmu.models.mill_stand.mill_stand import (MillStandDrive, Q_RANK_FREE_SKEW, Q_RANK_GUIDED,
                                                   Q_SEED, W_SEED)

PHIS = np.linspace(0.0, 2 * math.pi, 361)


def out(model, x, u):
    return dict(zip([v.name for v in model.outputs], model.output_values(0.0, x, u)))


def run(model, u, t_end, steps=20, rtol=1e-11, atol=1e-11):
    x = model.initial_state(u)
    h = t_end / steps
    for k in range(steps):
        x = model.advance(k * h, x, h, held(u), rtol, atol)
    return x


# -- kinematics --------------------------------------------------------------------------------
def loop_closure(r, l, phi):
    """Independent solution: stand pin C = (x, 0) at distance l from the crank pin A."""
    ax, ay = r * math.cos(phi), r * math.sin(phi)
    x = brentq(lambda s: (s - ax) ** 2 + ay ** 2 - l * l, ax, ax + l + 1.0, xtol=1e-15)
    # differentiate (C - A).(C - A) = l^2 twice with respect to phi (A' = r(-s, c))
    dA = np.array([-ay, ax])
    ddA = np.array([-ax, -ay])
    d = np.array([x - ax, -ay])
    dx = (d @ dA) / d[0]                       # d.(C' - A') = 0 with C' = (x', 0)
    rel = np.array([dx, 0.0]) - dA
    ddx = (d @ ddA - rel @ rel) / d[0]         # d.(C'' - A'') + |C' - A'|^2 = 0
    return x, dx, ddx


def test_stand_kinematics_against_the_loop_closure():
    m = MillStandDrive()
    r, l = m.p.r, m.p.l
    x, dx, ddx, beta, dbeta = m.kinematics(PHIS)
    ref = np.array([loop_closure(r, l, p) for p in PHIS])
    assert np.max(np.abs(x - ref[:, 0])) < 1e-12
    assert np.max(np.abs(dx - ref[:, 1])) < 1e-12
    assert np.max(np.abs(ddx - ref[:, 2])) < 1e-12
    lam = r / l
    # classic values: stroke 2r, dead-centre accelerations -r(1 + lambda), r(1 - lambda)
    assert max(x) - min(x) == pytest.approx(2 * r, abs=1e-12)
    assert m.kinematics(0.0)[2] == pytest.approx(-r * (1 + lam), abs=1e-12)
    assert m.kinematics(math.pi)[2] == pytest.approx(r * (1 - lam), abs=1e-12)
    # rod angle rate: derivative of asin(r sin(phi)/l), by central differences (h = 1e-6)
    h = 1e-6
    fd = (np.arcsin(r * np.sin(PHIS + h) / l) - np.arcsin(r * np.sin(PHIS - h) / l)) / (2 * h)
    assert np.max(np.abs(dbeta - fd)) < 1e-8


def test_simulated_revolution_follows_the_closed_form():
    w0 = 2 * math.pi                      # one revolution per second
    m = MillStandDrive({"w_start": w0})
    u = np.array([0.0, 1e9])              # huge drive inertia: constant crank speed
    r, l = m.p.r, m.p.l
    x = m.initial_state(u)
    worst = np.zeros(3)
    n = 40
    for k in range(n):
        x = m.advance(k / n, x, 1.0 / n, held(u), 1e-11, 1e-11)
        phi = w0 * (k + 1) / n
        xs, dx, ddx = loop_closure(r, l, phi)
        o = out(m, x, u)
        worst = np.maximum(worst, np.abs([o["stand_x"] - xs, o["stand_v"] - dx * w0,
                                          o["stand_a"] - ddx * w0 ** 2]))
    stroke = 2 * r
    assert worst[0] < 1e-7 * stroke
    assert worst[1] < 1e-7 * stroke * w0
    assert worst[2] < 1e-7 * stroke * w0 ** 2
    assert x[0] == pytest.approx(2 * math.pi, abs=1e-7)


# -- rod forces --------------------------------------------------------------------------------
def test_rod_forces_match_newton_euler_on_the_crank():
    """Newton-Euler on the crank alone: (i^2 J_in + J_crank) phi'' = i tau + moment of the rods."""
    m = MillStandDrive({"rod_mismatch": 2e-4, "mu_joint": 0.0},   # no friction torque here
                       effects=["assembly_preload"])
    u = np.array([4000.0, 3.0])
    for phi in (0.3, 1.2, 2.0, 4.0, 5.5):
        for w in (0.0, 7.0):
            x = np.array([phi, w, 0.0])
            o = out(m, x, u)
            acc = m.crank_acceleration(phi, w, u)
            A = m.p.r * np.array([math.cos(phi), math.sin(phi)])
            C = np.array([o["stand_x"], 0.0])
            T = o["F_rod2"] + o["F_rod4"]            # the preload cancels in the sum
            F_on_pin = T * (C - A) / m.p.l
            moment = A[0] * F_on_pin[1] - A[1] * F_on_pin[0]
            lhs = (m.p.gear_ratio ** 2 * u[1] + m.p.J_crank) * acc
            assert lhs == pytest.approx(m.p.gear_ratio * u[0] + moment, rel=1e-10, abs=1e-6)


def test_rod_force_shares_rigid_and_self_aligning():
    d = 2e-4
    u = np.array([5000.0, 2.0])
    x = np.array([1.0, 6.0, 0.0])
    rigid = MillStandDrive({"rod_mismatch": d}, effects=["assembly_preload"])
    selfal = MillStandDrive({"rod_mismatch": d, "joint_variant": 1}, effects=["assembly_preload"])
    o0, o1 = out(rigid, x, u), out(selfal, x, u)
    P = o0["preload"]
    l2, l4 = rigid.rod_lengths()
    T = o0["F_rod2"] + o0["F_rod4"]
    assert o1["F_rod2"] == o1["F_rod4"]                              # statically determinate
    assert o0["F_rod4"] - o0["F_rod2"] == pytest.approx(2 * P + T * (l2 - l4) / (l2 + l4),
                                                        rel=1e-12)
    assert o1["stand_skew"] == pytest.approx(d / selfal.p.rod_spacing, rel=1e-15)
    assert o0["stand_skew"] == 0.0


# -- preload and its friction ------------------------------------------------------------------
def preload_closed_form(m):
    return m.p.E_rod * m.p.rod_area * m.p.rod_mismatch / (2 * m.p.l)


def friction_power_closed_form(m, phi, w):
    r, l = m.p.r, m.p.l
    g = r * math.cos(phi) / math.sqrt(l * l - (r * math.sin(phi)) ** 2)
    return 2 * m.p.mu_joint * m.p.r_pin * abs(preload_closed_form(m)) * (1 + g + abs(g)) * abs(w)


@pytest.mark.parametrize("variant", [1, 2])
def test_self_aligning_variants_have_no_preload_and_no_friction_loss(variant):
    m = MillStandDrive({"rod_mismatch": 5e-4, "joint_variant": variant, "w_start": 6.0},
                       effects=["assembly_preload"])
    u = np.array([2000.0, 2.0])
    x = run(m, u, 1.0, steps=4, rtol=1e-8, atol=1e-8)
    o = out(m, x, u)
    assert o["preload"] == 0.0 and o["P_friction"] == 0.0 and o["E_friction"] == 0.0
    assert o["q_rank"] == 0 and o["q_malyshev"] == 0 and o["W_mobility"] == 5


def test_guides_that_hold_the_skew_bring_the_preload_back():
    m = MillStandDrive({"rod_mismatch": 1e-4, "joint_variant": 2, "guides_hold_skew": 1},
                       effects=["assembly_preload"])
    assert m.preload() == pytest.approx(preload_closed_form(m), rel=1e-14)
    assert out(m, np.array([0.5, 5.0, 0.0]), np.zeros(2))["q_rank"] == 1


@pytest.mark.parametrize("d", [0.0, 2e-5, 5e-5, 1e-4, 2e-4, -1e-4])
def test_rigid_variant_preload_and_friction_grow_with_the_mismatch(d):
    m = MillStandDrive({"rod_mismatch": d}, effects=["assembly_preload"])
    assert m.preload() == pytest.approx(preload_closed_form(m), rel=1e-14, abs=0.0)
    # in series: k2 k4/(k2 + k4) d with k_j = E A / l_j
    l2, l4 = m.rod_lengths()
    k2, k4 = m.p.E_rod * m.p.rod_area / l2, m.p.E_rod * m.p.rod_area / l4
    assert m.preload() == pytest.approx(k2 * k4 / (k2 + k4) * d, rel=1e-12, abs=0.0)
    for phi in (0.0, 0.7, 1.9, 3.1, 4.4, 5.9):
        for w in (5.0, -5.0):
            o = out(m, np.array([phi, w, 0.0]), np.zeros(2))
            assert o["P_friction"] == pytest.approx(friction_power_closed_form(m, phi, w),
                                                    rel=1e-12, abs=1e-9)
            assert o["M_friction"] * w <= 0.0          # always resisting


def test_friction_loss_is_linear_in_the_mismatch():
    def loss(d):
        m = MillStandDrive({"rod_mismatch": d}, effects=["assembly_preload"])
        return out(m, np.array([1.0, 6.0, 0.0]), np.zeros(2))["P_friction"]
    base = loss(5e-5)
    assert base > 0.0
    assert loss(1e-4) == pytest.approx(2 * base, rel=1e-12)
    assert loss(2e-4) == pytest.approx(4 * base, rel=1e-12)


def test_friction_energy_per_revolution_closed_form():
    """Over one revolution: E = 4 mu r_pin P (pi + 2 asin(r/l)) (sources/crankfmu/models/mill_stand/README.md)."""
    w0 = 2 * math.pi
    m = MillStandDrive({"rod_mismatch": 1e-4, "w_start": w0}, effects=["assembly_preload"])
    x = run(m, np.array([0.0, 1e9]), 1.0)
    expected = 4 * m.p.mu_joint * m.p.r_pin * m.preload() * (math.pi + 2 * math.asin(m.p.r / m.p.l))
    assert x[2] == pytest.approx(expected, rel=1e-7)


def test_energy_balance_over_a_revolution_with_friction_and_load():
    m = MillStandDrive({"rod_mismatch": 1.5e-4, "w_start": 6.0, "F_roll": 80e3},
                       effects=["assembly_preload", "rolling_load"])
    tau, J_in = 1500.0, 2.0
    u = np.array([tau, J_in])
    x0 = m.initial_state(u)
    x1 = run(m, u, 1.5)                        # a little more than one revolution
    assert x1[0] > 2 * math.pi

    def kinetic(x):
        return 0.5 * m.reduced_inertia(x[0], J_in)[0] * x[1] ** 2

    work_in = tau * m.p.gear_ratio * (x1[0] - x0[0])
    lost = x1[2] + x1[3]
    assert x1[2] > 0.05 * work_in and x1[3] > 0.05 * work_in    # both losses matter here
    assert work_in == pytest.approx(kinetic(x1) - kinetic(x0) + lost, rel=1e-9)


# -- the structure table -----------------------------------------------------------------------
def test_variant_table_matches_the_structure_analysis():
    from crankfmu.studies.structure import analyse, load_mechanism
    mech = Path(__file__).resolve().parents[1] / "scenarios" / "mechanisms"
    for v, name in enumerate(("p1", "p2p3", "p4")):
        coax = analyse(load_mechanism(mech / f"stand_drive_{name}_coaxial.toml"))
        guided = analyse(load_mechanism(mech / f"stand_drive_{name}_guided.toml"))
        generic = analyse(load_mechanism(mech / f"stand_drive_{name}.toml"))
        assert Q_RANK_FREE_SKEW[v] == coax.redundant["count"]
        assert Q_RANK_GUIDED[v] == guided.redundant["count"]
        assert W_SEED[v] == generic.dof_total and Q_SEED[v] == generic.redundant["count"]


# -- parameter checks --------------------------------------------------------------------------
@pytest.mark.parametrize("params, name", [
    ({"l": 0.2}, "l"),                      # shorter than the crank
    ({"r": 0.0}, "r"),
    ({"joint_variant": 3}, "joint_variant"),
    ({"joint_variant": 0.5}, "joint_variant"),
    ({"guides_hold_skew": 0.5}, "guides_hold_skew"),
    ({"rod_mismatch": 0.05}, "rod_mismatch"),
    ({"rod_area": 0.0}, "rod_area"),
    ({"E_rod": -1.0}, "E_rod"),
    ({"J_crank": 0.0}, "J_crank"),
    ({"gear_ratio": 0.0}, "gear_ratio"),
    ({"mu_joint": -0.1}, "mu_joint"),
    ({"w_reg": 0.0}, "w_reg"),
    ({"m_stand": float("nan")}, "m_stand"),
])
def test_bad_parameters_raise(params, name):
    with pytest.raises(ParameterError) as info:
        MillStandDrive(params)
    assert info.value.name == name


def test_pin_radius_needed_for_friction():
    with pytest.raises(ParameterError):
        MillStandDrive({"r_pin": 0.0}, effects=["assembly_preload"])
    MillStandDrive({"r_pin": 0.0, "mu_joint": 0.0}, effects=["assembly_preload"])


def test_effects_off_add_no_states():
    assert MillStandDrive().state_names() == ("phi", "w_crank")
    m = MillStandDrive(effects=["rolling_load"])
    assert m.state_names() == ("phi", "w_crank", "E_load")
    assert len(m.output_values(0.0, m.initial_state(m.default_inputs()), m.default_inputs())) \
        == len(m.outputs)
