"""The FMU side of the Taylor coupling: input polynomials of degree up to 5 (companions
X_d1 .. X_d5), and the output derivatives Y_d1 .. Y_d4 computed from the models' own equations
(runtime/taylor.py), against closed forms and independent solutions.
"""
from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from crankfmu.models.catalog import FMU_MODELS, make_physics, physics_class
from crankfmu.models.dc_motor.dc_motor import DcServoMotor
from crankfmu.models.rotor.rotor import ShaftRotor
from crankfmu.runtime import taylor
from crankfmu.runtime.model import (MAX_INPUT_DEGREE, MAX_OUTPUT_DERIVATIVE, SCIPY_SOLVER,
                                    InputPolynomial)
from crankfmu.runtime.slave_core import variable_table

QUINTIC = [0.3, -2.0, 40.0, -900.0, 2e4, -3e5]  # Taylor rows of a test signal at s = 0


def quintic(s: float, rows=QUINTIC) -> float:
    return sum(r * s ** k / math.factorial(k) for k, r in enumerate(rows))


def test_input_polynomial_of_degree_five():
    """Value and moved rows of a quintic against its power form (to 1e-13 relative): the
    polynomial an FMU integrates with and the rows it leaves at the step's end."""
    u = InputPolynomial(2.0, [QUINTIC[0], 7.0], *[[r, 0.0] for r in QUINTIC[1:]])
    for s in (0.0, 0.013, 0.05):
        assert u(2.0 + s)[0] == pytest.approx(quintic(s), rel=1e-13)
        assert u(2.0 + s)[1] == 7.0  # a held input stays exactly held
        moved = u.taylor(2.0 + s)
        for k in range(1, 6):  # row k at s: the k-th derivative of the power form there
            exact = quintic(s, QUINTIC[k:])
            assert moved[k][0] == pytest.approx(exact, rel=1e-12, abs=1e-9 * abs(QUINTIC[k]))


def test_a_quadratic_is_evaluated_the_same_with_zero_rows_above():
    """Rows of degree 3 .. 5 that are all zero change nothing, to the last bit: hosts that write
    only X_d1, X_d2 get the floats they got before the higher companions existed."""
    rows = ([0.1, -0.2], [3.0, 0.5], [-40.0, 0.0])
    plain = InputPolynomial(0.5, *rows)
    padded = InputPolynomial(0.5, *rows, [0.0, 0.0], [0.0, 0.0], [0.0, 0.0])
    for t in (0.5, 0.5013, 0.51):
        assert plain(t) == padded(t)
        assert plain.taylor(t) == padded.taylor(t)


def test_state_rows_of_a_nonlinear_equation():
    """x' = u - x^2 with u a quintic: the rows by differences of the right-hand side against
    the hand-derived chain x'' = u' - 2 x x', x''' = u'' - 2 (x'^2 + x x''),
    x'''' = u''' - 2 (3 x' x'' + x x'''). Row 1 is the right-hand side itself (to round-off);
    row k + 1 carries the forward differences' error, about (k/2) delta |x^(k+2) / x^(k+1)|
    (here delta = 1e-5 s and |x^(k+1) / x^(k+2)| from 0.05 s down to 1/40 s: 1e-4 to 6e-4),
    and round-off 2^k eps |x'| / delta^k (2e-6 relative in row 4): 2e-3 allowed."""
    x0 = 0.6
    rows = taylor.state_rows(lambda t, x, u: [u[0] - x[0] ** 2], 0.0, [x0],
                             [[r] for r in QUINTIC], 4, 1e-5)
    x = [x0, QUINTIC[0] - x0 ** 2]
    x.append(QUINTIC[1] - 2 * x[0] * x[1])
    x.append(QUINTIC[2] - 2 * (x[1] ** 2 + x[0] * x[2]))
    x.append(QUINTIC[3] - 2 * (3 * x[1] * x[2] + x[0] * x[3]))
    assert rows[1][0] == pytest.approx(x[1], rel=1e-15)
    for k in (2, 3, 4):
        assert rows[k][0] == pytest.approx(x[k], rel=2e-3), (k, rows[k][0], x[k])


def test_reused_state_rows_are_the_same_floats():
    """Rows computed in one call and rows continued from the leading ones (a master's exchange
    rounds) are identical: a reused row is not a different approximation."""
    def f(t, x, u):
        return [x[1], -math.sin(x[0]) + u[0]]
    u_rows = [[r] for r in QUINTIC]
    once = taylor.state_rows(f, 0.1, [0.4, 1.0], u_rows, 4, 1e-5)
    continued = taylor.state_rows(f, 0.1, [0.4, 1.0], u_rows, 4, 1e-5,
                                  taylor.state_rows(f, 0.1, [0.4, 1.0], u_rows, 2, 1e-5))
    assert once == continued


def derivative_models():
    """(model name, effects) of every catalog model with derivative outputs, over every
    combination of its effects."""
    for name in FMU_MODELS:
        cls = physics_class(name)
        if not cls.derivative_outputs:
            continue
        names = [e.name for e in cls.effects]
        for n in range(len(names) + 1):
            for effects in itertools.combinations(names, n):
                yield name, list(effects)


@pytest.mark.parametrize("name,effects", list(derivative_models()))
def test_declared_affine_outputs_are_affine(name, effects):
    """Where a model declares its derivative outputs affine (exact rows C x^(k) + D u^(k),
    read off at the unit vectors), the rows equal differences of output_values along the
    polynomials at random states and inputs. The paths are cubics and the differences take 4
    nodes, so they are exact up to round-off, eps |y| / delta^3 ~ 1e-10 at delta = 1e-2 (1e-7
    of the row's scale allowed); a false declaration (an output quadratic in a state, say)
    gives O(1)."""
    model = make_physics(name, {}, effects)
    if not model.derivative_outputs_affine:
        pytest.skip("rows by differences: nothing declared")
    rng = np.random.default_rng(7)
    n_x, n_u = len(model.state_names()), len(model.inputs)
    for _ in range(3):
        x_rows = [list(rng.uniform(-2, 2, n_x)) for _ in range(4)]
        u_rows = [list(rng.uniform(0.1, 2, n_u))] + [list(rng.uniform(-2, 2, n_u))
                                                     for _ in range(3)]
        exact = model.derivative_output_rows(0.0, x_rows, u_rows, 3, 1e-2)
        differenced = taylor.output_rows(model.output_values, 0.0, x_rows, u_rows, 3, 1e-2,
                                         model.DERIVATIVE_OUT)
        for row_e, row_d in zip(exact, differenced):
            scale = max(1.0, max(map(abs, row_d)))
            assert np.allclose(row_e, row_d, atol=1e-7 * scale, rtol=0), (row_e, row_d)


def press_rows_reference(model, x0, tau_rows, J_input):
    """Derivatives 1 .. 5 of the press's shaft speed i w at t = 0, independently: the
    trajectory from solve_ivp (DOP853, rtol 1e-13) at 17 points over +-4 ms, fitted by a
    polynomial of degree 10 (its derivatives at 0 to about 1e-6 relative up to the 4th)."""
    def rhs(t, x):
        return model.derivatives(t, x, [quintic(t, tau_rows), J_input, 0.0, 0.0])
    ts = np.linspace(-4e-3, 4e-3, 17)
    w = []
    for t in ts:
        if t == 0.0:
            w.append(x0[1])
            continue
        sol = solve_ivp(rhs, (0.0, t), x0, method="DOP853", rtol=1e-13, atol=1e-13)
        w.append(sol.y[1, -1])
    c = np.polynomial.polynomial.polyfit(ts / 4e-3, w, 10)
    i = model.p.gear_ratio
    return [i * c[k] * math.factorial(k) / 4e-3 ** k for k in range(1, 6)]


def test_press_output_derivatives_through_the_fmu(catalog):
    """The StephensonPress FMU's flange_w_d1 .. _d4 (set: a torque quintic's rows in
    flange_tau, flange_tau_d1 ..) against the fitted solution of its equations. d1 is one
    right-hand side: to 1e-9. d2 .. d4 are differences with delta = 1e-3 x the step h (here
    the default 1 ms), and what counts is the polynomial a master builds from them over h: it
    must stay within 1e-5 of the step's change |w'| h of the one from the reference rows, ten
    times below the tightest master tolerance the accuracy studies use (measured 6e-7: d2's
    forward-difference error (1/2) delta |w^(3)|, 6e-5 of d2; d4's round-off
    8 eps |w'| / delta^3, 1e-3 of d4). The fit's error is ~1e-6 of each row.
    flange_phi_dk = flange_w_d(k-1) to 1e-3: the same state rows, phi^(k) differenced from
    phi' = w (round-off 2^(k-1) eps |w| / delta^(k-1), 2e-4 of d4)."""
    from crankfmu.fmu.instance import FmuInstance, LogCollector
    params = {"w_start": 15.0, "phi_start": 1.2}  # inside the forging window
    fmu = FmuInstance("press", catalog["StephensonPress"], LogCollector())
    fmu.instantiate()
    fmu.setup(0.0, 1.0, 1e-8)
    fmu.slave.enterInitializationMode()
    fmu.set_start_values({**params, "effect_gravity": True, "effect_forging_load": True})
    fmu.slave.exitInitializationMode()
    try:
        tau_rows = [500.0, 1e4, -2e5, 3e6, -4e7, 5e8]
        names = ["flange_tau"] + [f"flange_tau_d{k}" for k in range(1, 6)] + ["flange_J"]
        fmu.writer(names)(tau_rows + [0.05])
        got = list(fmu.reader([f"flange_w_d{k}" for k in range(1, 5)])())
        phi = list(fmu.reader([f"flange_phi_d{k}" for k in range(2, 5)])())
    finally:
        fmu.terminate()
    model = make_physics("StephensonPress", params, ["gravity", "forging_load"])
    want = press_rows_reference(model, [1.2, 15.0], tau_rows, 0.05)
    assert got[0] == pytest.approx(want[0], rel=1e-9)
    h = 1e-3
    for s in np.linspace(0.0, h, 11):
        gap = sum((g - w) * s ** k / math.factorial(k)
                  for k, (g, w) in enumerate(zip(got, want[:4]), start=1))
        assert abs(gap) <= 1e-5 * abs(want[0]) * h, (s, gap, got, want)
    assert phi == pytest.approx(got[:3], rel=1e-3)


@pytest.mark.parametrize("effects", [["electrical_lag"], ["electrical_lag", "speed_loop"],
                                     ["speed_loop"]])
def test_motor_closed_form_with_a_quintic_speed(effects):
    """The DC motor's closed form with the shaft speed a quintic over each 5 ms step (a Taylor
    coupling of order 4 through the newest value), limits reached and left: against
    solve_ivp (Radau, rtol 1e-12) over 0.2 s, to 1e-8 relative, as the quadratic case in
    test_runtime.py."""
    params = {"U_max": 300.0, "M_max": 250.0}
    out = {}
    w_rows = [5.0, 400.0, -3000.0, 2e4, -1e5, 3e5]
    for solver in ("dopri5", "scipy"):
        motor = DcServoMotor(params, effects)
        motor.solver = solver
        x = motor.initial_state([w_rows[0], 0.0, 220.0, 150.0])
        for k in range(40):
            t = k * 5e-3
            u = InputPolynomial(t, [w_rows[0] + 40 * t, 0.0, 220.0, 150.0],
                                *[[r * (-1) ** k, 0.0, 0.0, 0.0] for r in w_rows[1:]])
            x = motor.advance(t, x, 5e-3, u, 1e-12, [1e-12 * v for v in motor.state_nominal()])
        out[solver] = np.array(x)
    scale = np.maximum(np.abs(out["scipy"]), 1.0)
    assert np.all(np.abs(out["dopri5"] - out["scipy"]) <= 1e-8 * scale), out


def test_linear_model_with_a_quintic_input():
    """The linear models' matrix exponential over the augmented chain [x, u, u', ..., u^(5)]
    against solve_ivp (DOP853, rtol 1e-13) with the same quintic input: to 1e-11."""
    model = ShaftRotor({"k": 100.0, "d_s": 0.5, "J": 0.5}, [])
    h = 0.02
    u = InputPolynomial(0.0, [QUINTIC[0]], *[[r] for r in QUINTIC[1:]])
    x = model.advance(0.0, [0.01, 0.0, 0.3], h, u, 1e-10, [1e-10] * 3)
    A, B = model.matrices()
    ref = solve_ivp(lambda t, y: A @ y + B @ [quintic(t)], (0.0, h), [0.01, 0.0, 0.3],
                    method="DOP853", rtol=1e-13, atol=1e-15)
    np.testing.assert_allclose(x, ref.y[:, -1], rtol=0, atol=1e-11)


@pytest.mark.parametrize("name", FMU_MODELS)
def test_companions_come_after_every_earlier_value_reference(name):
    """The value references that existed before the higher companions keep their numbers:
    parameters, effects, inputs, outputs, inputs' _d1 and _d2, scipy_solver; then the inputs'
    _d3 .. _d5 and the outputs' _d1 .. _d4 (a host or SSP file written for an older FMU
    addresses the same variables)."""
    cls = physics_class(name)
    table = [v.name for v in variable_table(cls)]
    earlier = ([v.name for v in cls.parameters] + [f"effect_{e.name}" for e in cls.effects]
               + [v.name for v in cls.inputs] + [v.name for v in cls.outputs]
               + [f"{v.name}_d{k}" for k in (1, 2) for v in cls.inputs] + [SCIPY_SOLVER])
    later = ([f"{v.name}_d{k}" for k in range(3, MAX_INPUT_DEGREE + 1) for v in cls.inputs]
             + [f"{n}_d{k}" for k in range(1, MAX_OUTPUT_DERIVATIVE + 1)
                for n in cls.derivative_outputs])
    assert table == earlier + later


@pytest.mark.parametrize("name", FMU_MODELS)
def test_fmi3_keeps_its_model_exchange_references_and_puts_the_companions_after(fmi3_dir,
                                                                                name):
    """The FMI 3.0 FMU: the base table at the FMI 2.0 value references, then time, the states,
    their derivatives and the event indicators where they were before the companions existed,
    then the companions in the FMI 2.0 order."""
    from fmpy import read_model_description
    cls = physics_class(name)
    md = read_model_description(str(fmi3_dir / f"{name}.fmu"))
    refs = {v.name: v.valueReference for v in md.modelVariables}
    table = [v.name for v in variable_table(cls)]
    base = len(cls.parameters) + len(cls.effects) + 3 * len(cls.inputs) + len(cls.outputs) + 1
    assert [refs[n] for n in table[:base]] == list(range(base))
    states = [v for v in md.modelVariables if v.name.startswith("state.")]
    assert refs["time"] == base and [v.valueReference for v in states] == \
        list(range(base + 1, base + 1 + len(states)))
    after = base + 1 + 2 * len(states) + cls.event_slots
    assert [refs[n] for n in table[base:]] == list(range(after, after + len(table) - base))


def test_a_constant_gives_exact_zero_rows():
    """Differences are taken of f(s) - f(0): a constant right-hand side, and a constant output
    differenced (the DC motor's flange_J without its lag), give rows of exact zeros, the same
    in every host (the weights of a k-th difference sum to 0 only up to round-off, which
    divided by delta^k made 1e7 out of nothing at delta = 1e-6)."""
    rows = taylor.state_rows(lambda t, x, u: [0.3], 0.0, [1.0], [[0.0]], 4, 1e-6)
    assert rows[2:] == [[0.0]] * 3
    motor = DcServoMotor({}, [])  # no lag: the torque is the static law, differenced
    assert not motor.derivative_outputs_affine
    u = [[150.0, 3.0, 220.0, 150.0]] + [[0.0] * 4] * 4
    y_rows = motor.derivative_output_rows(0.0, [[]] * 5, u, 4, 1e-6)
    assert [row[1] for row in y_rows] == [0.0] * 4  # flange_J
