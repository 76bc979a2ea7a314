"""Base-link offset a of the Stephenson press (seed 000, eq. 21-22, Fig. 3; model card
sources/crankfmu/models/stephenson_press/geometry.md).

The independent computation is `crankfmu.studies.papers.press_body_positions`: the bodies'
positions from the assembly constraints alone (two rods of length l between link 2, an
equilateral triangle of height a with the crank pin at its apex, and the slider on the vertical
through O; link 2's rotation theta and the slider position S solved by Newton), never from the
model's psi, S, S' formulas. Velocities are central differences of those positions in phi, so
the kinetic energy 2T/phi'^2 = J(phi) is checked without the model's kinematics.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from crankfmu.models.stephenson_press.stephenson_press import StephensonPress
from crankfmu.studies.papers import (base_link_inertia_printed, press_body_positions,
                                     press_kinetic_inertia)
from tests.support.servo_press_monolithic import SERVO_PRESS, TWO_PI, MonolithicServoPress

EFFECTS = ["gravity", "forging_load", "rod_inertia"]
PHI = np.linspace(0.0, TWO_PI, 49)
OFFSETS = [0.08, 0.02, -0.05]   # m: triangle below A (up to ~l/3), small, and above A
# Central differences with h = 1e-5 rad of positions solved to ~1e-16 m: truncation
# h^2 |x'''|/6 ~ 2e-11 of the scale, round-off 1e-16/h ~ 1e-11. Measured 9e-12 of max J; the
# tolerance 1e-8 leaves margin and still sees any term of order m2 a r (~1e-1 of J here).
FD_TOL = 1e-8


def press(a: float) -> StephensonPress:
    return StephensonPress(dict(SERVO_PRESS, a=a, m_rod=5.0), EFFECTS)


@pytest.mark.parametrize("a", OFFSETS)
def test_reduced_inertia_with_offset_is_the_kinetic_energy_of_the_bodies(a):
    model = press(a)
    J_model = model.reduced_inertia(PHI, 0.05)[0]
    J_fd, J2O_fd = press_kinetic_inertia(model, PHI, J_input=0.05)
    assert np.max(np.abs(J_model - J_fd)) <= FD_TOL * np.max(J_model)
    # link 2 translates: its kinetic energy is m2 r^2 phi'^2/2 whatever the offset ...
    p = model.p
    np.testing.assert_allclose(J2O_fd, p.m2 * p.r ** 2, rtol=FD_TOL)
    thetas = [press_body_positions(model, x)["theta"] for x in PHI]
    assert max(abs(t) for t in thetas) < 1e-12   # rad: the constraints keep its orientation
    # ... while the printed (21) moves by m2 (4/3) a r sin(phi) + m2 4a^2/9 around it: the
    # printed formula is not this mechanism's kinetic energy (the model card shows why)
    printed = base_link_inertia_printed(PHI, p.m2, p.r, a)
    assert np.max(np.abs(printed - J2O_fd)) > 0.9 * p.m2 * (4 / 3 * abs(a) * p.r + 4 * a * a / 9)


@pytest.mark.parametrize("a", OFFSETS)
def test_offset_shifts_the_slider_and_nothing_else(a):
    """S from the constraints equals the model's S (to 1e-12 m, the solve's accuracy) and is
    the S of a = 0 plus a;
    S', S'', psi', J, J'/2 and M_C are those of a = 0 bit for bit (a enters S only)."""
    shifted, plain = press(a), press(0.0)
    S_pos = np.array([press_body_positions(shifted, x)["S"] for x in PHI])
    S_model = shifted.kinematics(PHI)[0]
    assert np.max(np.abs(S_model - S_pos)) <= 1e-12
    # (S + a) - a is S up to one rounding of S + a: 1e-15 m
    np.testing.assert_allclose(S_model - a, plain.kinematics(PHI)[0], rtol=0, atol=1e-15)
    for k in range(1, 6):
        np.testing.assert_array_equal(shifted.kinematics(PHI)[k], plain.kinematics(PHI)[k])
    for f in (lambda m: m.reduced_inertia(PHI, 0.05), lambda m: (m.resistance_moment(PHI),)):
        for x, y in zip(f(shifted), f(plain)):
            np.testing.assert_array_equal(x, y)


def test_energy_balance_with_offset_from_the_bodies():
    """One revolution from a start-up state of motor + press with a = 0.08 m (rods, gravity,
    forging): motor work - forging work = Delta T + Delta V over eight pieces and the whole,
    with T and V from the bodies' positions (not the model's J or S). Tolerance 1e-6 of the
    motor work per revolution, as test_press_physics's balance; the finite-difference T carries
    ~1e-11 relative, the integration (rtol 1e-10) the rest. And the motion equals that of
    a = 0 exactly: the offset enters no term of eq. (1)."""
    a = 0.08
    runs = {}
    for off in (a, 0.0):
        model = MonolithicServoPress(press_params=dict(a=off, m_rod=5.0), press_effects=EFFECTS)
        runs[off] = (model, model.simulate(model.initial_state(0.0, 10.0), 0.0, 2))
    model, traj = runs[a]
    np.testing.assert_array_equal(traj.x_end, runs[0.0][1].x_end)
    phi0 = traj.x_end[0] - TWO_PI
    X = traj(traj.t_at_phi(phi0 + TWO_PI * np.arange(9) / 8))
    X[:, -1] = traj.x_end
    press_ = model.press
    J_fd, _ = press_kinetic_inertia(press_, X[0], J_input=model.motor.p.J_rotor)
    T = 0.5 * J_fd * X[1] ** 2
    p = press_.p

    def V(phi):  # y downward: V = -g sum m y
        b = press_body_positions(press_, float(phi))
        return -p.g * (p.m5 * b["S"] + p.m2 * b["S2"][1] + p.m_rod * (b["C"][0][1] + b["C"][1][1]))
    Vs = np.array([V(x) for x in X[0]])
    k = model.k_work
    W_motor, W_forge = X[k], X[k + 1]
    W_rev = W_motor[-1] - W_motor[0]
    assert W_rev > 100.0
    for i, j in [(0, 8)] + [(m, m + 1) for m in range(8)]:
        residual = (W_motor[j] - W_motor[i]) - (W_forge[j] - W_forge[i]) \
            - (T[j] - T[i]) - (Vs[j] - Vs[i])
        assert abs(residual) <= 1e-6 * W_rev, (i, j, residual)


def test_offset_default_is_zero():
    assert StephensonPress().p.a == 0.0
    assert math.isclose(press(0.0).kinematics(math.pi / 2)[0], SERVO_PRESS["r"] + SERVO_PRESS["l"])
