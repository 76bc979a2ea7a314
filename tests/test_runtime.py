"""The FMU runtime's integrators against scipy and against closed forms.

- `physics.dopri` is scipy's RK45 on plain floats: same tableau, error norm, step rule and event
  semantics, so from the same first step it takes the same steps (checked to round-off).
- The DC motor's closed-form step is exact for any lag (checked against the analytic solution at
  tau = 1e-6 s and 1e-2 s) and calls no right-hand side at all, so a stiff lag costs nothing more.
- Every catalog model on the runtime path against its scipy path (solver = "scipy": solve_ivp
  with the model's method), events included, at rtol 1e-10.
- The damped oscillator's closed form (the rocker's elastic support between contacts) against
  solve_ivp at rtol 1e-13, over many periods; the integrator's kept steps, longest step and
  moments of a rate.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from crankfmu.runtime import dopri
from crankfmu.runtime.model import InputPolynomial, IntegrationError, held
from crankfmu.models.catalog import FMU_MODELS, make_physics, physics_class
from crankfmu.runtime.closed_form import DampedOscillator, lag_step, phi_functions, poly_value
from crankfmu.models.dc_motor.dc_motor import DcServoMotor
from tests.support.full import quick_or_full


def pendulum(t, y):
    return [y[1], -math.sin(y[0])]


def test_dopri_takes_scipy_rk45s_steps():
    """Same first step selection, same steps: final state to 1e-13 (round-off of a different
    summation order) and exactly the same number of right-hand-side calls."""
    ours = dopri.integrate(pendulum, 0.0, [1.0, 0.0], 10.0, 1e-9, [1e-9, 1e-9])
    ref = solve_ivp(lambda t, y: np.array(pendulum(t, y)), (0.0, 10.0), [1.0, 0.0],
                    method="RK45", rtol=1e-9, atol=1e-9)
    assert ours.calls == ref.nfev
    np.testing.assert_allclose(ours.x, ref.y[:, -1], rtol=0, atol=1e-13)


def test_dopri_events_as_solve_ivp():
    """A terminal event (pendulum through the vertical, downwards) at the time scipy finds, to
    1e-12 s; a non-terminal one (speed extremum) before it is reported with its state."""
    def down(t, y):
        return y[0]
    down.terminal, down.direction = True, -1

    def extremum(t, y):
        return y[1] + 0.5  # speed passes -0.5 rad/s
    ours = dopri.integrate(pendulum, 0.0, [1.0, 0.0], 10.0, 1e-10, [1e-10, 1e-10],
                           events=[down, extremum])
    ref = solve_ivp(lambda t, y: np.array(pendulum(t, y)), (0.0, 10.0), [1.0, 0.0],
                    method="RK45", rtol=1e-10, atol=1e-10, events=[down, extremum])
    assert ours.status == 1 and ours.event == 0
    assert ours.t == pytest.approx(ref.t_events[0][0], abs=1e-12)
    [(index, t_cross, x_cross)] = ours.crossings
    assert index == 1 and t_cross == pytest.approx(ref.t_events[1][0], abs=1e-12)
    assert x_cross[1] == pytest.approx(-0.5, abs=1e-9)
    # at the terminal event the state is the 5th-order step to it, not the dense output
    assert abs(ours.x[0]) < 1e-9


def test_step_size_is_carried_between_calls():
    """1 ms calls on a smooth problem: after the first call each takes one step (7 calls:
    the first stage and six more), as one long call would; a fresh start pays for a step
    selection and a few small steps every time."""
    x, h = [1.0, 0.0], None
    calls = []
    for k in range(200):
        sol = dopri.integrate(pendulum, k * 1e-3, x, (k + 1) * 1e-3, 1e-8, [1e-8, 1e-8], h)
        x, h = sol.x, sol.h_next
        calls.append(sol.calls)
    assert max(calls[1:]) == 7


def test_work_limit():
    with pytest.raises(dopri.WorkLimitError, match="more than 100 derivative evaluations"):
        dopri.integrate(lambda t, y: [-1e9 * y[0]], 0.0, [1.0], 1.0, 1e-8, [1e-8],
                        max_calls=100)


@pytest.mark.parametrize("z", [-1e-8, -0.3, -1.0, -1.99, -2.0, -7.0, -1000.0])
def test_phi_functions(z):
    """phi_k(z) = int_0^1 e^{(1-s) z} s^{k-1}/(k-1)! ds, by adaptive quadrature to 1e-13
    (the series and the recurrence meet at |z| = 2: both sides are checked)."""
    from scipy.integrate import quad
    for k, value in enumerate(phi_functions(z, 4), start=1):
        exact = quad(lambda s, k=k: math.exp((1 - s) * z) * s ** (k - 1) / math.factorial(k - 1),
                     0.0, 1.0, epsabs=0, epsrel=1e-13, limit=200)[0]
        assert value == pytest.approx(exact, rel=1e-12)


def test_lag_step_for_a_cubic_forcing():
    """tau y' + y = F(s), F a cubic: the closed form against scipy's DOP853 at rtol 1e-13."""
    forcing, tau, h = [3.0, -2.0, 40.0, -500.0], 0.02, 0.05
    F = np.polynomial.Polynomial(forcing)
    ref = solve_ivp(lambda s, y: (F(s) - y) / tau, (0, h), [1.5], method="DOP853", rtol=1e-13,
                    atol=1e-15)
    assert lag_step(1.5, forcing, h, tau) == pytest.approx(ref.y[0, -1], rel=1e-12)


@pytest.mark.parametrize("L_a", [5e-7, 5e-3])   # tau = L_a/R_a = 1e-6 s, 1e-2 s
def test_stiff_lag_exact_and_free(L_a):
    """Lag on, u = 220 V, the shaft speed a ramp w(t) = w0 + a t given as the input polynomial
    (extrapolation order 1), 1000 steps of 1 ms. Exact solution (s_ = k_phi^2/R_a):
        M(t) = M_s(t) + s_ a tau + (M(0) - M_s(0) - s_ a tau) e^(-t/tau).
    The closed form meets it to 1e-12 relative at tau = 1e-6 s and 1e-2 s alike, and neither
    calls the right-hand side: a stiff lag costs what a slow one costs."""
    motor = DcServoMotor({"L_a": L_a, "M_max": 1e6}, ["electrical_lag"])
    calls = []
    original = motor.derivatives
    motor.derivatives = lambda *a: calls.append(1) or original(*a)
    w0, a, U, h = 10.0, 50.0, 220.0, 1e-3
    M0 = 100.0
    x = [M0]
    tau, s_ = motor.tau, motor.s
    for k in range(1000):
        t = k * h
        x = motor.advance(t, x, h, InputPolynomial(t, [w0 + a * t, 0.0, U, 0.0],
                                                   [a, 0.0, 0.0, 0.0]), 1e-8, [1e-8])
    t = 1000 * h
    Ms = motor.mu * U - s_ * (w0 + a * t)
    exact = Ms + s_ * a * tau + (M0 - (motor.mu * U - s_ * w0) - s_ * a * tau) * math.exp(-t / tau)
    assert x[0] == pytest.approx(exact, rel=1e-12)
    assert not calls


MOTOR_CASES = [  # (parameters, effects, w(t) = a + b t + c t^2, w_ref): limits reached and left
    ({"M_max": 300.0}, ["electrical_lag"], (10.0, -500.0, 0.0), 150.0),
    ({"U_max": 300.0}, ["electrical_lag", "speed_loop"], (0.0, 100.0, 0.0), 150.0),
    ({"U_max": 300.0, "M_max": 200.0, "L_a": 5e-7}, ["electrical_lag", "speed_loop"],
     (0.0, 150.0, -30.0), 150.0),
    ({"U_max": 300.0}, ["speed_loop"], (0.0, 60.0, 0.0), 150.0),
]


@pytest.mark.parametrize("params,effects,w,w_ref", MOTOR_CASES)
def test_motor_closed_form_through_the_limits(params, effects, w, w_ref):
    """Voltage and torque limits reached and left inside steps: the closed form against
    solve_ivp (Radau, rtol 1e-12) over 0.3 s of 1 ms steps, to 1e-8 relative."""
    out = {}
    for solver in ("dopri5", "scipy"):
        motor = DcServoMotor(params, effects)
        motor.solver = solver
        x = motor.initial_state([w[0], 0.0, 220.0, w_ref])
        for k in range(300):
            t = k * 1e-3
            u = [w[0] + w[1] * t + w[2] * t * t, 0.0, 220.0, w_ref]
            x = motor.advance(t, x, 1e-3, InputPolynomial(t, u, [w[1] + 2 * w[2] * t, 0, 0, 0],
                                                          [2 * w[2], 0, 0, 0]),
                              1e-12, [1e-12 * v for v in motor.state_nominal()])
        out[solver] = np.array(x)
    scale = np.maximum(np.abs(out["scipy"]), 1.0)
    assert np.all(np.abs(out["dopri5"] - out["scipy"]) <= 1e-8 * scale), out


# -- every model, runtime path against scipy path -----------------------------------------------
DRIVES = {  # (parameters, effects or None for the defaults, inputs): each model moves through
    # its events (limits, forging windows, brake lock, impact end, blows)
    "DcServoMotor": ({"M_max": 5000.0}, ["electrical_lag", "speed_loop"], {"flange_w": 20.0}),
    "StephensonPress": ({}, ["gravity", "forging_load"], {"flange_tau": 300.0, "flange_J": 0.05}),
    "InductionMotor": ({}, None, {"flange_w": 50.0}),
    "PlanetaryClutchDrive": ({}, None, {"command": 1.0, "sun_tau": 150.0}),
    "RockerImpact": ({}, None, {}),
    "CrankRockerHammer": ({}, None, {"flange_tau": 40.0, "flange_J": 0.05}),
    "MillStandDrive": ({}, ["rolling_load"], {"flange_tau": 800.0, "flange_J": 0.1}),
}


def _run_model(name, solver, rtol, steps=300, h=1e-3):
    cls = physics_class(name)
    params, effects, inputs = DRIVES[name]
    if effects is None:
        effects = [e.name for e in cls.effects if e.default]
    model = make_physics(name, params, effects)
    model.solver = solver
    u = [inputs.get(v.name, v.start) for v in cls.inputs]
    x = model.initial_state(u)
    atol = [rtol * v for v in model.state_nominal()]
    for k in range(steps):
        x = model.advance(k * h, x, h, held(u), rtol, atol)
    return np.array(model.output_values(steps * h, x, u), dtype=float), cls


def _worst(y, reference, cls):
    error = np.abs(y - reference) / np.maximum(np.abs(reference), 1.0)
    k = int(np.argmax(error))
    return float(error[k]), cls.outputs[k].name


# The impact units' steps (1 ms) in the quick suite: the support's ringing after the impact is
# what costs (the scipy path integrates it at rtol 1e-13: 2.6 s of CPU over 0.3 s for the rocker)
# and what the check is about; the quick span holds every event and tens of ringing periods:
# the rocker's impact (at the start) and 0.1 s after it, the crank-rocker's blow (between 0.20
# and 0.22 s) and its end. Full: 0.3 s, as every other model.
IMPACT_STEPS = {"RockerImpact": quick_or_full(100, 300),
                "CrankRockerHammer": quick_or_full(220, 300)}


@pytest.mark.parametrize("name", [m for m in FMU_MODELS if m in DRIVES])
def test_runtime_path_as_accurate_as_scipy_path(name):
    """0.3 s in 1 ms steps, held inputs that drive the model through its events. Against a
    tight reference (the scipy path at rtol 1e-13), the runtime path at rtol 1e-10 must be as
    accurate as the scipy path at rtol 1e-10, within a factor 5, or within 1e-9 (error relative
    to max(|output|, 1), worst output). Measured: the runtime path is the more accurate one,
    also on the impact units' support force T, a 1.6 kHz ringing over ~500 periods that it
    integrates in closed form out of contact (crank-rocker: 4.0e-8 against scipy's 1.0e-6;
    rocker: 1.0e-9 against 1.2e-6; before the closed form, 3.7e-6 and 6.0e-7). Quick spans
    (IMPACT_STEPS): crank-rocker to 0.22 s 9.6e-9 against 2.3e-7, rocker to 0.1 s 3.5e-9
    against 2.5e-6."""
    steps = IMPACT_STEPS.get(name, 300)
    reference, cls = _run_model(name, "scipy", 1e-13, steps)
    ours = _worst(_run_model(name, "dopri5", 1e-10, steps)[0], reference, cls)
    theirs = _worst(_run_model(name, "scipy", 1e-10, steps)[0], reference, cls)
    print(f"\n{name}: error at rtol 1e-10, runtime {ours[0]:.1e} ({ours[1]}), scipy "
          f"{theirs[0]:.1e} ({theirs[1]})")
    assert ours[0] <= max(5.0 * theirs[0], 1e-9)


def test_non_finite_derivatives_fail_with_a_reason():
    """A zero inertia makes the derivatives NaN: the step fails at once, saying so (before, the
    NaN error norm compared as an accepted step and the failure surfaced as 'cannot convert
    float NaN to integer')."""
    with pytest.raises(dopri.IntegrationFailure, match="derivatives are not finite"):
        dopri.integrate(lambda t, y: [y[1], math.nan],
                        0.0, [0.0, 0.0], 1e-3, 1e-8, [1e-8, 1e-8], 1e-3)


def test_a_step_has_one_work_limit_over_its_event_restarts():
    """`step` (what the FMU calls) counts right-hand-side calls over every restart of the step
    (here: the forging window's edges), `advance` per integration between restarts. With the
    limit just above the largest integration, `advance` finishes and `step` does not."""
    press = make_physics("StephensonPress", {}, ["forging_load"])
    u = [3000.0, 0.05, 0.0, 0.0]  # the crank passes several window edges in 0.2 s
    calls, integrate = [], press.integrate

    def counting(*args, **kwargs):
        sol = integrate(*args, **kwargs)
        calls.append(sol.calls)
        return sol
    press.integrate = counting
    press.advance(0.0, press.initial_state(u), 0.2, held(u), 1e-10, [1e-10, 1e-10])
    assert len(calls) >= 3
    press.max_derivative_calls_per_step = max(calls) + 7
    press._h_next = None
    assert press.advance(0.0, press.initial_state(u), 0.2, held(u), 1e-10, [1e-10, 1e-10])
    press._h_next = None
    with pytest.raises(IntegrationError, match="more than"):
        press.step(0.0, press.initial_state(u), 0.2, held(u), 1e-10, [1e-10, 1e-10])


@pytest.mark.parametrize("f, a, b", [
    (lambda x: math.cos(x) - x, 0.0, 1.0),
    (lambda x: x ** 3 - 2 * x - 5, 2.0, 3.0),
    (lambda x: abs(x - 0.3) ** 0.5 * math.copysign(1.0, x - 0.3), 0.0, 1.0),  # kink at root
    (lambda x: (x - 0.25) ** 3 + 1e-3 * (x - 0.25), -1.0, 1.0),               # flat near root
    (lambda x: math.exp(x) - 1e5, 0.0, 20.0),
])
def test_brent_as_scipy(f, a, b):
    """The runtime's Brent (runtime/roots.py, so FMUs need not import scipy.optimize) finds the
    root scipy.optimize.brentq finds, to the tolerance both were given, in as many calls."""
    from scipy.optimize import brentq as scipy_brentq

    from crankfmu.runtime.roots import brentq
    calls = [0, 0]

    def counted(k):
        def g(x):
            calls[k] += 1
            return f(x)
        return g
    ours = brentq(counted(0), a, b, xtol=1e-14)
    theirs = scipy_brentq(counted(1), a, b, xtol=1e-14)
    assert ours == pytest.approx(theirs, abs=2e-14)
    assert calls[0] == calls[1]


# -- the damped oscillator in closed form ----------------------------------------------------------
@pytest.mark.parametrize("alpha, u0, v0, forcing", [
    (640.0, 2e-5, -0.3, [10.0, 2e3, -5e5, 1e8]),   # the MO-100 support, 4 % damping: ringing
    (0.0, 2e-5, -0.3, [10.0, 2e3, -5e5, 1e8]),     # undamped (RockerImpact's support)
    (640.0, 0.0, 0.0, [-80.0, -7e3, 2.4e5]),       # from rest: the forcing alone
])
def test_damped_oscillator_as_solve_ivp(alpha, u0, v0, forcing):
    """u'' + 2 alpha u' + k2 u = F(s), k2 = 2.56e8 (k ~ 1.6e4 rad/s, MO-100's support), F a
    polynomial, over 1 ms (2.5 periods) and 3 ms: u, u', the work of F, the damper's loss and
    the ringing's integrals against solve_ivp (DOP853, rtol 1e-13, the integrals as extra
    states), to 1e-9 of each quantity's scale (the reference's own error is ~1e-11 of it; the
    loss, a difference of energies, to 1e-12 of the oscillator's energy)."""
    k2 = 2.56e8
    osc = DampedOscillator(alpha, k2, u0, v0, forcing)

    def rhs(s, y):  # u, u', work, loss, ringing integrated once and twice, the ringing
        u, v, _, _, once, _, ring_u, ring_v = y
        return [v, poly_value(forcing, s) - 2 * alpha * v - k2 * u, poly_value(forcing, s) * v,
                2 * alpha * v * v, ring_u, once, ring_v, -2 * alpha * ring_v - k2 * ring_u]
    q0, q1 = osc.ringing(0.0)
    for h in (1e-3, 3e-3):
        y = solve_ivp(rhs, (0.0, h), [u0, v0, 0.0, 0.0, 0.0, 0.0, q0, q1], method="DOP853",
                      rtol=1e-13, atol=1e-30).y[:, -1]
        u, v = osc.state(h)
        scale_u = max(abs(u0), abs(forcing[0]) / k2, 1e-300)
        assert abs(u - y[0]) <= 1e-9 * scale_u
        assert abs(v - y[1]) <= 1e-9 * scale_u * math.sqrt(k2)
        assert osc.work(h) == pytest.approx(y[2], rel=1e-9, abs=1e-9 * abs(forcing[0]) * scale_u)
        energy = 0.5 * (v0 * v0 + k2 * u0 * u0) + abs(forcing[0]) * scale_u  # the loss's scale
        assert osc.damping_loss(h) == pytest.approx(y[3], rel=1e-8, abs=1e-12 * energy)
        once, twice = osc.ringing_integrals(h, *osc.ringing(h))
        assert once == pytest.approx(y[4], rel=1e-9, abs=1e-9 * abs(q0) * h)
        assert twice == pytest.approx(y[5], rel=1e-9, abs=1e-9 * abs(q0) * h * h)
        assert osc.ringing_bound(0.0) >= max(abs(z) for z in (q0, y[6]))


def test_dense_output_and_longest_step():
    """dopri keeps the accepted steps on request: their interpolants (the event interpolant,
    4th order: within the steps' error of the solution) cover the integration; max_step holds
    every step to at most that length without changing the result beyond the tolerance."""
    dense = []
    sol = dopri.integrate(pendulum, 0.0, [1.0, 0.0], 2.0, 1e-10, [1e-10, 1e-10], dense=dense)
    ref = solve_ivp(lambda t, y: pendulum(t, y), (0.0, 2.0), [1.0, 0.0], method="DOP853",
                    rtol=1e-13, atol=1e-13, dense_output=True)
    assert dense[0].t0 == 0.0 and dense[-1].t0 + dense[-1].h == 2.0
    for step in dense:
        for t in (step.t0, step.t0 + 0.4 * step.h, step.t0 + step.h):
            assert np.allclose(step(t), ref.sol(t), rtol=0, atol=1e-8)
    short = dopri.integrate(pendulum, 0.0, [1.0, 0.0], 2.0, 1e-10, [1e-10, 1e-10],
                            max_step=0.01, dense=(steps := []))
    assert max(step.h for step in steps) <= 0.01 < max(step.h for step in dense)
    assert np.allclose(short.x, sol.x, rtol=0, atol=1e-8)


def test_dense_coefficients_generated_as_summed():
    """The generated dense-output coefficients are bit-identical to the sum they spell out (the
    press's forging-window events are located on them: results must not move)."""
    rng = np.random.default_rng(3)
    for n in (1, 2, 6, 12):
        k = rng.uniform(-1e3, 1e3, (7, n)).tolist()
        expected = [[sum(k[m][i] * dopri._P[m][j] for m in range(7) if dopri._P[m][j])
                     for j in range(4)] for i in range(n)]
        assert dopri._dense_coefficients(n)(k) == expected


def test_moments_of_a_rate():
    """dopri.moments: the integrals of t^k x' over the integration from the accepted steps'
    stages, as accurate as x itself. x' = cos(t) e^(-t/2) from 0 to 2 (several steps at
    rtol 1e-10): against the integrals in closed form to 1e-9 (k = 0 is x's own change)."""
    dense = []
    sol = dopri.integrate(lambda t, x: [math.cos(t) * math.exp(-0.5 * t)], 0.0, [0.0], 2.0,
                          1e-10, [1e-10], dense=dense)
    assert len(dense) > 3
    exact = [quad_moment(k) for k in range(3)]
    got = dopri.moments(dense, 0.0, 0, 3)
    assert got[0] == pytest.approx(sol.x[0], rel=1e-12)
    for a, b in zip(got, exact):
        assert a == pytest.approx(b, rel=1e-9)


def quad_moment(k):
    """The integral of t^k cos(t) e^(-t/2) over [0, 2] (scipy's quad, to 1e-14)."""
    from scipy.integrate import quad
    return quad(lambda t: t ** k * math.cos(t) * math.exp(-0.5 * t), 0.0, 2.0, epsabs=1e-14,
                epsrel=1e-14)[0]
