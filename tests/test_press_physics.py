"""Physics of the servo press: kinematics, energy, the paper's analytic results vs the time domain.

Every tolerance is stated with the figure measured when the test was written and why it is set
where it is. The time-domain reference is the monolithic ODE of tests/support/servo_press_monolithic.py
(DcServoMotor + StephensonPress composed, solve_ivp at rtol 1e-10). The measured figures are
collected in docs/stephenson_press_analysis.md.
"""
from __future__ import annotations

import functools
import itertools
import math

import numpy as np
import pytest
from scipy.optimize import minimize_scalar

from crankfmu.studies import press_analysis as pa
from crankfmu.runtime.model import ParameterError, held
from tests.support.servo_press_monolithic import (SERVO_MOTOR, SERVO_PRESS, SERVO_U, TWO_PI,
                                                  MonolithicServoPress)
from crankfmu.models.dc_motor.dc_motor import DcServoMotor
from crankfmu.models.stephenson_press.stephenson_press import G_STANDARD, StephensonPress

LAG = {False: (), True: ("electrical_lag",)}


# ---------------------------------------------------------------------------------------------
# cached runs (each periodic steady state costs 0.3-1.5 s)
# ---------------------------------------------------------------------------------------------
@functools.lru_cache(maxsize=None)
def _steady(lag: bool, press_items: tuple = (), motor_items: tuple = (),
            press_effects: tuple = ("gravity", "forging_load"), start_near: bool = False):
    model = MonolithicServoPress(motor_params=dict(motor_items), motor_effects=LAG[lag],
                                 press_params=dict(press_items), press_effects=press_effects)
    x0 = None
    if start_near:  # start at the analytic mean speed: the slow overdamped mode starts small
        x0 = model.initial_state(0.0, pa.mean_speed(_drive(model)))
    return model, model.periodic_steady_state(n_last=1, x0=x0)


def steady(lag: bool, press: dict | None = None, motor: dict | None = None,
           press_effects: tuple = ("gravity", "forging_load"), start_near: bool = False):
    """Cached periodic steady state (model, SteadyState); arguments normalised for the cache."""
    return _steady(lag, tuple(sorted((press or {}).items())),
                   tuple(sorted((motor or {}).items())), tuple(press_effects), start_near)


def _drive(model: MonolithicServoPress) -> pa.ReducedDrive:
    return pa.ReducedDrive.from_models(model.press, model.motor, model.u)


@functools.lru_cache(maxsize=None)
def comparison(lag: bool, press_items: tuple = ()):
    """Discrepancies of the first approximation against the time domain."""
    start_near = dict(press_items).get("J1", 0.0) > 10.0
    model, ss = steady(lag, dict(press_items), start_near=start_near)
    err = pa.dynamic_error(_drive(model), lag=lag)
    V1 = err.speed_error.complex[0]
    W_angle, W_time = ss.speed_harmonic(1), ss.speed_harmonic_in_time(1)
    delta_sim = ss.nonuniformity()
    return dict(
        omega0=err.omega0, err=err, ss=ss, model=model,
        delta_sim=delta_sim, delta_1=err.delta,
        delta_rel=abs(err.delta / delta_sim - 1.0),
        W1_angle_rel=abs(W_angle - V1) / abs(W_angle),
        W1_time_rel=abs(W_time - V1) / abs(W_time),
        W1_amp_rel=abs(V1) / abs(W_angle) - 1.0,
        W1_phase=float(np.angle(V1 / W_angle)),
    )


def servo_press(effects=("gravity", "forging_load"), **params) -> StephensonPress:
    return StephensonPress(dict(SERVO_PRESS, **params), list(effects))


# ---------------------------------------------------------------------------------------------
# kinematics and reduced inertia against finite differences
# ---------------------------------------------------------------------------------------------
def central(f, phi, h):
    return (f(phi + h) - f(phi - h)) / (2.0 * h)


# Central differences with h = 1e-5 rad: truncation h^2 |f'''|/6 ~ 2e-11 |f'''| and round-off
# ~ 1e-16 |f|/h ~ 1e-11 |f|; the functions are O(1) in units of r, l. Measured worst case
# 1.3e-10 (kinematics) and 4.3e-10 (J' with rods) of the scale max|f'|; tolerance 1e-8 of the
# scale leaves margin for other platforms and still catches any sign or factor error (O(1)).
FD_H, FD_TOL = 1e-5, 1e-8
PHI = np.linspace(0.0, TWO_PI, 97)


@pytest.mark.parametrize("geometry", [dict(r=0.05, l=0.25), dict(r=0.10, l=0.13)])
def test_kinematics_against_finite_differences(geometry):
    press = servo_press(**geometry)
    S, dS, ddS, psi, dpsi, ddpsi = press.kinematics(PHI)
    pairs = [
        (dS, central(lambda p: press.kinematics(p)[0], PHI, FD_H), "S'"),
        (ddS, central(lambda p: press.kinematics(p)[1], PHI, FD_H), "S''"),
        (dpsi, central(lambda p: press.kinematics(p)[3], PHI, FD_H), "psi'"),
        (ddpsi, central(lambda p: press.kinematics(p)[4], PHI, FD_H), "psi''"),
    ]
    for exact, numeric, name in pairs:
        scale = np.max(np.abs(exact))
        assert np.max(np.abs(exact - numeric)) <= FD_TOL * scale, name
    # the geometry itself: BDC at phi = pi/2 with S = r + l, rod length l
    assert press.kinematics(0.5 * math.pi)[0] == pytest.approx(press.p.r + press.p.l, rel=1e-15)
    Ax, Ay = press.p.r * np.cos(PHI), press.p.r * np.sin(PHI)
    np.testing.assert_allclose(np.hypot(Ax, S - Ay), press.p.l, rtol=1e-14)


def test_array_core_is_the_float_core():
    """The core over an array of angles (numpy's functions, the analyses' grids) gives what it
    gives at each angle alone (math's functions, the FMU's right-hand side), every combination
    of effects, angles over several revolutions and both signs (the forging window wraps).
    Tolerance 1e-14 of each term's largest magnitude: numpy's and math's sin may differ in the
    last bit (measured 1.3e-16); a term missed or masked wrong over the array is O(1)."""
    phi = np.linspace(-7.0, 20.0, 2001)
    effects = ("gravity", "forging_load", "rod_inertia")
    for k in range(len(effects) + 1):
        for chosen in itertools.combinations(effects, k):
            press = servo_press(chosen, a=0.01)
            per_angle = [press.crank_terms(float(x), 0.03) for x in phi]
            terms = (press.reduced_inertia(phi, 0.03) + (press.resistance_moment(phi),
                     press.forging_force(phi)) + press.kinematics(phi))
            for n, term in enumerate(terms):
                alone = np.array([t[n] for t in per_angle])
                scale = max(np.max(np.abs(alone)), 1e-300)
                assert term.shape == phi.shape, (chosen, n)
                assert np.max(np.abs(term - alone)) <= 1e-14 * scale, (chosen, n)


@pytest.mark.parametrize("rods", [False, True])
def test_reduced_inertia_derivative(rods):
    """J'(phi) = 2 (J'/2 from the model) against d/dphi of J(phi); with rod_inertia on, the rods
    add translation and rotation terms whose derivative is checked the same way."""
    effects = ("gravity", "rod_inertia") if rods else ("gravity",)
    press = servo_press(effects, m_rod=5.0)
    J_input = 0.05
    J, half_dJ = press.reduced_inertia(PHI, J_input)
    numeric = central(lambda p: press.reduced_inertia(p, J_input)[0], PHI, FD_H)
    scale = np.max(np.abs(2.0 * half_dJ))
    assert np.max(np.abs(2.0 * half_dJ - numeric)) <= FD_TOL * scale
    # the constant part: i^2 J_input + J1 + m2 r^2 (base link in circular translation)
    p = press.p
    assert press.J_constant(J_input) == pytest.approx(
        p.gear_ratio ** 2 * J_input + p.J1 + p.m2 * p.r ** 2, rel=1e-15)


@pytest.mark.parametrize("rods", [False, True])
def test_gravity_moment_is_minus_gradient_of_potential(rods):
    """M_C with only gravity equals -dV/dphi, V = -g (m5 S + m2 r sin phi + 2 m_rod y_C) (y down):
    an independent check of the weights' generalized forces (same FD tolerance as above)."""
    effects = ("gravity", "rod_inertia") if rods else ("gravity",)
    press = servo_press(effects, m_rod=5.0)
    p = press.p

    def V(phi):
        S, _, _, psi, _, _ = press.kinematics(phi)
        yC = p.r * np.sin(phi) + 0.5 * p.l * np.sin(psi)
        return -p.g * (p.m5 * S + p.m2 * p.r * np.sin(phi) + (2 * p.m_rod * yC if rods else 0))

    M = press.resistance_moment(PHI)
    numeric = -central(V, PHI, FD_H)
    assert np.max(np.abs(M - numeric)) <= FD_TOL * np.max(np.abs(M))


# ---------------------------------------------------------------------------------------------
# energy balance in the monolithic model
# ---------------------------------------------------------------------------------------------
ENERGY_CASES = {
    "static law": dict(lag=False),
    "lag + rods": dict(lag=True, press_effects=("gravity", "forging_load", "rod_inertia")),
    # the PI loop settles slowly: take the third revolution from rest (not periodic: Delta KE of
    # the revolution is large, which makes the check harder, not easier)
    "lag + speed loop + rods, start-up": dict(
        lag=True, motor_effects=("electrical_lag", "speed_loop"), transient=True,
        press_effects=("gravity", "forging_load", "rod_inertia")),
}


@pytest.mark.parametrize("case", list(ENERGY_CASES))
def test_energy_balance_over_a_revolution(case):
    """Motor shaft work = forging work + Delta KE - gravity work, over one revolution in periodic
    steady state and over eight pieces of it (where Delta KE and the gravity work are large).

    Tolerance 1e-6 of the motor work per revolution (255 J; the brief's figure). Measured worst
    residual: 1.6e-10 (static law), 2.5e-12 (lag + rods), 1.3e-13 (start-up); the pieces carry
    Delta KE up to 167 J and gravity work up to 29 J. The gravity work over the revolution is
    2e-12 of the weights' work over a stroke (tolerance 1e-6). The integration at rtol 1e-10 is
    the only error: the balance is an identity of the equations, so any physics error -- a wrong
    sign in J'/2, a missing factor i -- shows at O(1)."""
    spec = ENERGY_CASES[case]
    press_effects = spec.get("press_effects", ("gravity", "forging_load"))
    if spec.get("transient"):
        model = MonolithicServoPress(motor_effects=spec["motor_effects"],
                                     press_effects=press_effects)
        traj = model.simulate(model.initial_state(), 0.0, 3)
    else:  # the cached periodic revolution (the static law's is the other tests' too)
        model, ss = steady(spec["lag"], press_effects=press_effects)
        traj = ss.traj
    phi0 = traj.x_end[0] - TWO_PI
    k = model.k_work
    t_edges = traj.t_at_phi(phi0 + TWO_PI * np.arange(9) / 8)
    X = traj(t_edges)
    X[:, -1] = traj.x_end  # exact end point of the revolution
    KE = model.kinetic_energy(X)
    W = X[k:k + 3]
    W_rev = W[0, -1] - W[0, 0]
    assert W_rev > 0.0
    for a, b in [(0, 8)] + [(j, j + 1) for j in range(8)]:
        W_motor, W_forge, W_grav = W[:, b] - W[:, a]
        residual = W_motor - W_forge + W_grav - (KE[b] - KE[a])
        assert abs(residual) <= 1e-6 * W_rev, (a, b, residual)
    # gravity is conservative: over the revolution its work nets zero (relative to the work of
    # the weights over a half stroke); over a piece it equals -Delta V
    p = model.press.p
    stroke_work = p.g * (p.m5 + p.m2 + 2 * p.m_rod) * 2 * p.r
    assert abs(W[2, -1] - W[2, 0]) <= 1e-6 * stroke_work
    S = model.press.kinematics(X[0])[0]
    psi = model.press.kinematics(X[0])[3]
    rods = model.press.on("rod_inertia")
    V = -p.g * (p.m5 * S + p.m2 * p.r * np.sin(X[0])
                + (2 * p.m_rod * (p.r * np.sin(X[0]) + 0.5 * p.l * np.sin(psi)) if rods else 0))
    np.testing.assert_allclose(W[2] - W[2, 0], -(V - V[0]), atol=1e-6 * stroke_work)


# ---------------------------------------------------------------------------------------------
# mean speed (eq. 11-14 and the energy balance)
# ---------------------------------------------------------------------------------------------
@pytest.mark.parametrize("n", [360, 361, 97, 1000])
def test_quadratic_12_degenerates(n):
    """sum_k J'(phi_k) = 0 over equally spaced positions (to round-off, ~1e-16 of sum |J'|;
    exactly 0 for even n by the symmetry J(pi - phi) = J(phi)): the quadratic (12) has infinite
    coefficients, the printed root formula (13) is meaningless, and its finite root is the energy
    balance (n D + sum M_C)/(n s) (to round-off: 1e-12)."""
    model, _ = steady(False)
    drive = _drive(model)
    q = pa.mean_speed_quadratic(drive, n)
    assert abs(q.sum_dJ) <= 1e-13 * q.sum_abs_dJ
    assert abs(q.p) > 1e12 * drive.s / q.sum_abs_dJ or math.isinf(q.p)
    phi = TWO_PI * np.arange(n) / n
    linear = (n * drive.D + np.sum(drive.M_C(phi))) / (n * drive.s)
    assert q.root_finite == pytest.approx(linear, rel=1e-12)
    assert not (abs(q.roots_printed[0] - linear) <= 1e-6 * linear), \
        "the printed formula (13) should lose the root to cancellation"
    # and the finite root is the steady mean speed (to the sampling of M_C: 1e-4 at n = 97)
    assert q.root_finite == pytest.approx(pa.mean_speed(drive), rel=1e-4)


@pytest.mark.parametrize("lag", [False, True])
def test_mean_speed(lag):
    """omega0 = (i mu u0 + <M_C>)/(i^2 s) against the time domain.

    Without lag the angle mean (1/2pi) int w dphi equals omega0 exactly (energy balance);
    measured 1e-11, tolerance 1e-9 (integration error). The time mean 2pi/T is lower by
    var(w)/omega0: measured -2.72e-4 (static law), -3.41e-4 (lag); tolerance |.| < 4e-4. With the
    lag the angle mean is above omega0 (+1.06e-4). The second-order prediction of
    `mean_speed_second_order` matches the offsets of the time mean to 6.1 % (static) and 8.7 %
    (lag), of the lag's angle mean to 7.5 %; tolerance 10 %: the prediction is built from first-
    approximation amplitudes, which are themselves a few per cent off."""
    c = comparison(lag)
    ss, err = c["ss"], c["err"]
    omega0 = c["omega0"]
    assert omega0 == pytest.approx((SERVO_PRESS["gear_ratio"] * SERVO_MOTOR["k_phi"] / 0.5 * SERVO_U
                                    + pa.mean_resistance(_drive(c["model"])))
                                   / (SERVO_PRESS["gear_ratio"] ** 2 * 1.3 ** 2 / 0.5), rel=1e-14)
    w_angle, w_time = ss.angle_mean_speed(), ss.time_mean_speed()
    pred_time, pred_angle = pa.mean_speed_second_order(err)
    if not lag:
        assert w_angle == pytest.approx(omega0, rel=1e-9)
    else:
        assert (w_angle - omega0) == pytest.approx(pred_angle - omega0, rel=0.10)
    assert abs(w_time / omega0 - 1.0) < 4e-4
    assert (w_time - omega0) == pytest.approx(pred_time - omega0, rel=0.10)


def test_voltage_for_a_mean_speed():
    """Problem 3 of the paper: the voltage that gives a mean speed inverts `mean_speed`
    (u0 = 220 V back to 1e-12)."""
    model, _ = steady(False)
    unit = pa.ReducedDrive.from_models(model.press, model.motor, 1.0)
    assert pa.solve_for_voltage(unit, pa.mean_speed(_drive(model))) == pytest.approx(SERVO_U,
                                                                                  rel=1e-12)


# ---------------------------------------------------------------------------------------------
# first approximation (eq. 19-20, 33-35) against the time domain
# ---------------------------------------------------------------------------------------------
# Measured discrepancies of the first approximation for the servo press (set when written):
#                                    static law   with lag
#   delta (w_max - w_min)/w_mean       2.26 %      3.08 %    (first approximation is low)
#   first harmonic, angle reading      0.83 %      2.10 %    |V1 - W1|/|W1|, complex
#   first harmonic, time reading       3.48 %      4.39 %
# Angle reading: w(phi) from the simulation against omega0 + psi'(phi/omega0); time reading:
# w(t) with t = 0 where the crank passes phi = 0, against omega0 + psi'(t). Both are legitimate
# readings of a first approximation; the angle reading is better because it evaluates the
# forces at the true crank angle (see the docs).
# The first approximation drops terms of relative size ~ the disturbance (see the docs): the
# forging pulse evaluated at omega0 t instead of the true angle (time reading), J~ phi'' and
# J'(phi'^2 - omega0^2)/2. Tolerances are set just above the measured values.
FIRST_APPROX_TOL = {
    False: dict(delta_rel=0.025, W1_angle_rel=0.010, W1_time_rel=0.040),
    True: dict(delta_rel=0.035, W1_angle_rel=0.025, W1_time_rel=0.050),
}


@pytest.mark.parametrize("lag", [False, True])
def test_first_approximation_against_time_domain(lag):
    c = comparison(lag)
    for key, tol in FIRST_APPROX_TOL[lag].items():
        assert c[key] < tol, (key, c[key])
    # sanity of the numbers themselves: delta 7.8 % (static law), 10.1 % (lag)
    assert c["delta_sim"] == pytest.approx(0.0779 if not lag else 0.1007, abs=5e-4)


SMALLER = {"F_max / 4": (("F_max", 12.5e3),), "J1 = 50": (("J1", 50.0),)}


@pytest.mark.parametrize("lag", [False, True])
@pytest.mark.parametrize("smaller", list(SMALLER))
def test_first_approximation_improves_with_smaller_disturbance(lag, smaller):
    """A smaller disturbance (F_max/4, or the inertia of a bigger crank J1 = 50 kg m^2) shrinks
    every discrepancy by more than half (measured factors 3.0 to 76): the error is the truncation
    of the approximation, not a wrong formula (a wrong formula would keep a relative error)."""
    base, small = comparison(lag), comparison(lag, SMALLER[smaller])
    assert small["delta_sim"] < 0.4 * base["delta_sim"]
    for key in ("delta_rel", "W1_angle_rel", "W1_time_rel"):
        assert small[key] < 0.5 * base[key], (key, small[key], base[key])


@pytest.mark.parametrize("lag", [False, True])
def test_successive_approximations_converge_to_time_domain(lag):
    """The paper's iteration (9)-(10), carried on: each approximation gains a factor ~0.05, and
    the fixed point is the time-domain periodic motion. Measured max |w_k(phi) - w_sim(phi)| over
    the revolution, relative to w_max - w_min, for k = 1..8: 9.8e-2, 4.2e-3, 4.0e-4, 1.6e-5,
    1.7e-6, 1.7e-7, 1.3e-7, 1.3e-7 (static); 1.0e-1, 6.0e-3, 5.9e-4, 3.3e-5, 3.4e-6, 1.8e-7,
    4.0e-8, 4.1e-8 (lag). The floor is the FFT of the kinked forging force at n = 32768 (it falls
    as 1/n^2: 1.8e-6 at 8192). Tolerance 3e-7 at k = 8; time mean speed to 1e-8 (measured 6e-10,
    2e-10); delta to 1e-6 (2e-8, 1.2e-7). This
    validates L(t), its Fourier series and both transfer functions (eq. 20, 33-34) to 1e-7."""
    c = comparison(lag)
    ss, model = c["ss"], c["model"]
    approx = pa.successive_approximations(_drive(model), lag=lag, iterations=8, n=32768)
    w_sim = ss.on_angle_grid(4096)[2][1]
    errors = [np.max(np.abs(a.speed_on_angle_grid(4096) - w_sim)) / np.ptp(w_sim) for a in approx]
    assert all(b < 0.2 * a for a, b in zip(errors[:5], errors[1:6])), errors
    assert errors[-1] < 3e-7, errors
    assert approx[-1].Omega == pytest.approx(ss.time_mean_speed(), rel=1e-8)
    assert approx[-1].delta == pytest.approx(ss.nonuniformity(), rel=1e-6)
    # approximation 1 is the first approximation of eq. (19)/(33)
    first = c["err"]
    # (same up to the mean of M_C: trapezoidal on the FFT grid here, Gauss-Legendre there;
    # measured 2.5e-10)
    assert approx[0].Omega == pytest.approx(first.omega0, rel=1e-9)
    assert approx[0].delta == pytest.approx(first.delta, rel=1e-3)


def test_closed_form_eq20_matches_transfer_function():
    """Eq. (20) as printed (with delta_l = atan((s+theta)/(J0 l nu)) + pi) is the same function as
    the transfer-function solution, and solves J0 psi'' + s psi' = L (checked by differentiating
    the series: residual 1e-12 of max |L|)."""
    model, _ = steady(False)
    err = pa.dynamic_error(_drive(model))
    L, J0, s, nu = err.L, err.J0, err.s, err.omega0
    t = np.linspace(0.0, TWO_PI / nu, 501)
    l = L.l[:, None]
    arg = l * nu * t + L.phase[:, None] + np.arctan(s / (J0 * l * nu)) + math.pi
    root = np.sqrt(J0 ** 2 * l ** 2 * nu ** 2 + s ** 2)
    psi20 = np.sum(L.amp[:, None] * np.cos(arg) / (l * nu * root), axis=0)
    dpsi20 = -np.sum(L.amp[:, None] * np.sin(arg) / root, axis=0)
    np.testing.assert_allclose(psi20, err.psi(t), atol=1e-12)
    np.testing.assert_allclose(dpsi20, err.psi_dot(t), atol=1e-12)
    ddpsi = np.sum(-L.amp[:, None] * l * nu * np.cos(arg) / root, axis=0)
    residual = J0 * ddpsi + s * dpsi20 - L(t)
    assert np.max(np.abs(residual)) < 1e-12 * np.max(np.abs(L(t)))
    # with the lag: tau J0 psi''' + J0 psi'' + s psi' = tau L' + L (eq. 34, theta = 0)
    lagged = pa.dynamic_error(_drive(model), lag=True)
    V, Lc, Om = lagged.speed_error.complex, L.complex, L.l * nu
    tau = lagged.tau
    lhs = (tau * J0 * (1j * Om) ** 2 + J0 * 1j * Om + s) * V
    np.testing.assert_allclose(lhs, (1 + 1j * Om * tau) * Lc, rtol=1e-12)


# ---------------------------------------------------------------------------------------------
# the motor: static-characteristic limit and the stiff lag
# ---------------------------------------------------------------------------------------------
def test_lag_tends_to_static_law():
    """electrical_lag on with tau = L_a/R_a -> 0 equals lag off (Radau, chosen automatically).
    One revolution from the static law's periodic state (M starts in equilibrium, so the start
    costs nothing) against the static law's periodic revolution.
    Measured max |w_lag(phi) - w_static(phi)| = 4.13e-4 rad/s at tau = 1e-5 s and 4.13e-5 at
    1e-6 s (3.2e-5 of w_max - w_min), M - M_static 5.7e-4 and 5.7e-5 of the range of M: first
    order in tau, so the limit is the static law. Tolerances: ratio 10 +- 5 %, 5e-5 of the speed
    range at tau = 1e-6 s, 1e-3 (tau/1e-5 s) of the range of M."""
    model0, ss0 = steady(False)
    phi_rel, _, x_static = ss0.on_angle_grid(2048)
    M_static = np.array([model0.drive_torque(0.0, x_static[:, j]) for j in range(0, 2048, 16)])
    diffs = []
    for L_a in (5e-6, 5e-7):
        model = MonolithicServoPress(motor_params=dict(L_a=L_a), motor_effects=LAG[True])
        assert model.method == "Radau"
        traj = model.simulate(model.initial_state(0.0, float(ss0.x0[1])), 0.0, 1)
        x = traj(traj.t_at_phi(phi_rel))
        diffs.append(np.max(np.abs(x[1] - x_static[1])))
        assert np.max(np.abs(x[2, ::16] - M_static)) < 1e-3 * np.ptp(M_static) * L_a / 5e-6
    assert diffs[0] / diffs[1] == pytest.approx(10.0, rel=0.05)
    assert diffs[1] < 5e-5 * np.ptp(x_static[1])


def test_stiff_lag_with_held_inputs():
    """tau = 1e-6 s, DcServoMotor.advance over steps of 1e-3 s (1000 tau) with held inputs that
    jump every step: the solver (Radau, L-stable) stays stable and M equals the static law
    mu U - s w at the end of every step. The exact value differs from it by exp(-1000) = 0, so
    the only error is the solver's; tolerance = the rtol handed to advance (1e-6), measured
    7e-15."""
    params = dict(SERVO_MOTOR, L_a=5e-7)
    motor = DcServoMotor(params, ["electrical_lag"])
    static = DcServoMotor(params, [])
    assert motor.tau == pytest.approx(1e-6)
    u = np.array([0.0, 0.0, SERVO_U, 150.0])
    x = motor.initial_state(u)
    t, rng = 0.0, np.random.default_rng(1)
    for k in range(100):
        u = np.array([rng.uniform(0.0, 200.0), 0.0, rng.uniform(100.0, 250.0), 150.0])
        x = motor.advance(t, x, 1e-3, held(u), rtol=1e-6, atol=1e-8)
        t += 1e-3
        M_static = static.output_values(t, np.zeros(0), u)[0]
        assert np.all(np.isfinite(x))
        assert x[0] == pytest.approx(M_static, rel=1e-6, abs=1e-6)
        assert motor.output_values(t, x, u)[0] == x[0]


# ---------------------------------------------------------------------------------------------
# flywheel (26)-(28) and counterweight (24)-(25)
# ---------------------------------------------------------------------------------------------
def _servo_constants():
    model, _ = steady(False)
    err = pa.dynamic_error(_drive(model))
    J_D = _drive(model).J_D
    return err.omega0, J_D, err.J0 - J_D, err.s


@pytest.mark.parametrize("theta", [0.0, 50.0, 400.0])
def test_flywheel_27_minimises_26(theta):
    """(27) is the minimiser of (26) with J0* = J_D + J_M0 + J_Mx: d(26)/dJ_Mx = 0 there (central
    difference below 1e-6 of a typical slope; measured 2.4e-9, 1.2e-9, 6.6e-11: the round-off
    of the difference quotient), a bounded numerical minimiser agrees to 1e-5
    (it stops on a flat minimum at ~sqrt(eps) relative), and (28) equals (27) at theta = 0 to
    1e-12. With the printed J0* = J_M0 + J_Mx the same formula is not stationary (slope 1.04,
    2.5, 0.12 of the typical one; tolerance > 1e-2)."""
    W, J_D, J_M0, s = _servo_constants()
    Jx = pa.flywheel_inertia(W, J_D, J_M0, s, theta)

    def R(x):
        return pa.flywheel_ratio(x, W, J_D, J_M0, s, theta)
    h = 1e-4 * (J_D + J_M0)
    slope_scale = abs(central(R, Jx + 0.5 * (J_D + J_M0 + s / W), h))  # a typical slope
    assert abs(central(R, Jx, h)) < 1e-6 * slope_scale
    assert R(Jx - 10 * h) > R(Jx) < R(Jx + 10 * h)
    res = minimize_scalar(R, bounds=(-J_D + 1e-9, 20 * (J_D + J_M0 + s / W)), method="bounded",
                          options=dict(xatol=1e-10))
    assert res.x == pytest.approx(Jx, rel=1e-5, abs=1e-6 * (J_D + J_M0))
    if theta == 0.0:
        assert pa.flywheel_inertia_theta0(W, J_D, J_M0, s) == pytest.approx(Jx, rel=1e-12)

    def R_printed(x):  # the printed reading J0* = J_M0 + J_Mx (J_D missing)
        return pa.transmission_moment_ratio(W, J_D + x, J_M0 + x, s, theta)
    assert abs(central(R_printed, Jx, h)) > 1e-2 * slope_scale


def test_flywheel_in_the_time_domain():
    """Servo press, l = 1: J_Mx = 14.09 kg m^2 at the crank (0.1409 kg m^2 on the motor shaft).
    In the time domain the first harmonic of the moment through the gear, M_p = i M_D - J_D phi'',
    over L_1 is (measured) 0.9703 without flywheel, 0.9481 with J_Mx, 0.9629 with 3 J_Mx, against
    sqrt(23) = 0.9715, 0.9489, 0.9634: agreement 0.13 %, 0.08 %, 0.05 %, tolerance 0.5 %; the
    optimum is the lowest of the three in the time domain too. The flywheel of (28) halves delta
    (7.79 % -> 3.45 %), three times it brings 1.59 %: (26) is not the speed criterion."""
    W, J_D, J_M0, s = _servo_constants()
    Jx = pa.flywheel_inertia_theta0(W, J_D, J_M0, s)
    assert Jx == pytest.approx(14.0866, rel=1e-4)
    i = SERVO_PRESS["gear_ratio"]
    ratios, deltas = [], []
    for Jf in (0.0, Jx / i ** 2, 3 * Jx / i ** 2):
        model, ss = steady(False, motor=dict(J_flywheel=Jf))
        drive = _drive(model)
        err = pa.dynamic_error(drive)
        _, t, x = ss.on_angle_grid(1024)
        Mp = np.array([i * model.drive_torque(t[j], x[:, j])
                       - drive.J_D * model.rhs(t[j], x[:, j])[1] for j in range(x.shape[1])])
        ratio = abs(2 * np.fft.rfft(Mp)[1] / Mp.size) / err.L.amp[0]
        predicted = math.sqrt(pa.transmission_moment_ratio(err.omega0, drive.J_D, err.J0, s))
        assert ratio == pytest.approx(predicted, rel=5e-3)
        ratios.append(ratio)
        deltas.append(ss.nonuniformity())
    assert ratios[1] < ratios[0] and ratios[1] < ratios[2]
    assert deltas[1] < 0.5 * deltas[0] and deltas[2] < deltas[1]


def test_counterweight_25_is_a_negative_maximum():
    """m2 = -(i^2 J_D + J1)/r^2 of (25) is where d(24)/dJ_2O = 0, but (24) has its MAXIMUM there
    (second derivative < 0, neighbours lower) and the mass is negative: -2800 kg for the servo
    press. For m2 >= 0, (24) falls monotonically: a heavier base link always helps. The press
    model refuses the value."""
    W, J_D, J_M0, s = _servo_constants()
    J1, r = SERVO_PRESS["J1"], SERVO_PRESS["r"]
    m2 = pa.counterweight_mass(J_D, J1, r)
    assert m2 == pytest.approx(-2800.0, rel=1e-12)
    assert m2 < 0.0
    for theta in (0.0, 50.0):
        sp = pa.counterweight_stationary_point(W, J_D, J1, r, s, theta)
        assert sp.m2 == pytest.approx(m2, rel=1e-12) and sp.d1 == 0.0
        assert sp.kind == "maximum" and sp.d2 < 0.0

        def f(J2O, theta=theta):
            return pa.transmission_moment_ratio(W, J_D, J_D + J1 + J2O, s, theta)
        x, h = sp.J_2O, 1e-3 * (J_D + J1)
        assert f(x) == pytest.approx(sp.value, rel=1e-12)
        assert abs(central(f, x, h)) < 1e-9 * f(x) / h
        assert f(x - h) < f(x) > f(x + h)
        assert (f(x + h) - 2 * f(x) + f(x - h)) / h ** 2 == pytest.approx(sp.d2, rel=1e-4)
        m2_grid = np.linspace(0.0, 5000.0, 51)
        values = f(m2_grid * r ** 2)
        assert np.all(np.diff(values) < 0.0)
    # at theta = 0 the maximum exceeds 1: the gear would carry more than the whole disturbance
    assert pa.counterweight_stationary_point(W, J_D, J1, r, s, 0.0).value > 1.0
    with pytest.raises(ParameterError) as info:  # and the model refuses a negative mass
        servo_press(m2=m2)
    assert info.value.name == "m2"


# ---------------------------------------------------------------------------------------------
# bad parameters
# ---------------------------------------------------------------------------------------------
@pytest.mark.parametrize("params, name", [
    (dict(l=0.05), "l"),          # l == r: the rod cannot reach past the crank pin
    (dict(l=0.04), "l"),          # l < r
    (dict(m5=-1.0), "m5"),
    (dict(m2=-20.0), "m2"),
    (dict(J1=-1.0), "J1"),
    (dict(gear_ratio=0.0), "gear_ratio"),
    (dict(r=0.0), "r"),
])
def test_bad_press_parameters(params, name):
    with pytest.raises(ParameterError) as info:
        servo_press(**params)
    assert info.value.name == name
    assert name in str(info.value)


@pytest.mark.parametrize("params, effects, name", [
    (dict(R_a=0.0), (), "R_a"),
    (dict(k_phi=0.0), (), "k_phi"),
    (dict(J_rotor=-0.1), (), "J_rotor"),
    (dict(L_a=0.0), ("electrical_lag",), "L_a"),
])
def test_bad_motor_parameters(params, effects, name):
    with pytest.raises(ParameterError) as info:
        DcServoMotor(dict(SERVO_MOTOR, **params), list(effects))
    assert info.value.name == name


def test_gravity_constant_default():
    assert servo_press().p.g == G_STANDARD
