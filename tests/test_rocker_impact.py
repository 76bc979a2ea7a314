"""RockerImpact model and the paper's analysis (seed rocker_impact_unit; model card
sources/crankfmu/models/rocker_impact/README.md).

The MO-100 table is computed once (module fixture); the model runs through its own `advance`
over coarse communication steps, as the FMU adapter calls it. Every tolerance has its reason in
a comment. Internal tolerances: rtol = 1e-10 for the model with atol = rtol * state_nominal()
(as the FMU adapter passes them), rtol = 1e-12 for the independent reference written here.
"""
from __future__ import annotations

import json
import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.optimize import minimize_scalar

from crankfmu.runtime.model import ParameterError, held
from crankfmu.studies.rocker_analysis import (K_N_VALUES, RockerData, cascade_matrix, coefficients,
                                              exact_linear, first_approximation,
                                              format_impact_table, impact_table, linearise,
                                              second_approximation, validity)
from crankfmu.models.rocker_impact.rocker_impact import RockerImpact
from tests.support.stepping import stepped

RTOL = 1e-10                 # model's internal relative tolerance in these tests
MO100 = RockerData()         # J, m, r, R_c, d, V0, E, rho, nu of the seed; S = 1.1 J/(m r)
S_P = MO100.S_percussion     # centre of percussion J/(m r)
COMPLIANT = ["support_compliance"]
HERTZ = ["support_compliance", "hertz_contact"]


@pytest.fixture(scope="module")
def table():
    return {(r.S_factor, r.k_n): r for r in impact_table()}


def make(effects=COMPLIANT, **params):
    params.setdefault("S", 1.1 * S_P)
    return RockerImpact(params, effects)


def run(model, t_end, h, tau=0.0, J_drive=0.0, record=False):
    """Drive the model as a co-simulation master would: advance over steps h, held inputs."""
    u = np.array([tau, J_drive])
    x = model.initial_state(u)
    t, n = 0.0, int(round(t_end / h))
    rows = []
    for k in range(n):
        x = model.advance(t, x, h, held(u), RTOL, RTOL * model.state_nominal())
        t = (k + 1) * h
        if record:
            rows.append(model.output_values(t, x, u))
    out = dict(zip([v.name for v in model.outputs], model.output_values(t, x, u)))
    return out, x, (np.array(rows) if record else None)


def rel(a, b):
    return abs(a / b - 1.0)


# -- independent reference: generalized coordinates, mass matrix, dense output ---------------
def reference(data: RockerData, *, c=None, c0=None, hertz=False, tau=0.0, q0=None, qd0=None,
              gap=0.0, t_end=1e-3):
    """Hybrid integration at rtol 1e-12 written apart from the model: q = (u0, theta) with the
    mass matrix [[m, m r], [m r, J]] (or q = (theta,) pinned), contact begin/end as solve_ivp
    events, peaks from the dense output refined by bounded minimisation."""
    pinned = c0 is None
    K = 2 * data.E * math.sqrt(data.R_c) / (3 * (1 - data.nu ** 2))
    Z = math.pi * data.d ** 2 / 4 * math.sqrt(data.E * data.rho)
    if pinned:
        M, G = np.array([[data.J]]), np.array([data.S])
    else:
        M = np.array([[data.m, data.m * data.r], [data.m * data.r, data.J]])
        G = np.array([1.0, data.S])
    Minv, nq = np.linalg.inv(M), len(G)
    q0 = np.zeros(nq) if q0 is None else np.asarray(q0, float)
    if qd0 is None:      # strike at start: theta' = V0/S, pivot at rest
        qd0 = np.r_[np.zeros(nq - 1), data.V0 / data.S]
    qd0 = np.asarray(qd0, float)

    def force(dl):
        return K * np.sign(dl) * abs(dl) ** 1.5 if hertz else c * dl

    def rhs(t, y, touching):
        q, qd, w = y[:nq], y[nq:2 * nq], y[2 * nq]
        P = force(G @ q - w - gap) if touching else 0.0
        Q = -P * G + (np.array([tau]) if pinned else np.array([-c0 * q[0], tau]))
        return np.r_[qd, Minv @ Q, P / Z, P, P * P / Z]

    def support(y, touching):
        q, w = y[:nq], y[2 * nq]
        if not pinned:
            return c0 * q[0]
        P = force(G @ q - w - gap) if touching else 0.0
        return -P - data.m * data.r * (-P * data.S + tau) / data.J

    y = np.r_[q0, qd0, 0.0, 0.0, 0.0]
    dl0 = G @ q0 - gap
    touching = dl0 > 0 or (dl0 == 0 and G @ qd0 > 0)
    t, impacts, start = 0.0, [], (0.0 if touching else None)
    scale = np.r_[np.full(nq, 1e-3), np.full(nq, 10.0), 1e-3, 100.0, 100.0]
    while t < t_end:
        def ev(s, yy, _touching):
            return G @ yy[:nq] - yy[2 * nq] - gap
        ev.terminal, ev.direction = True, (-1 if touching else 1)
        sol = solve_ivp(rhs, (t, t_end), y, method="DOP853", rtol=1e-12, atol=1e-14 * scale,
                        events=ev, args=(touching,), dense_output=True)
        t1 = sol.t_events[0][0] if sol.status == 1 else t_end
        if touching:
            ts = np.linspace(t, t1, 4001)
            Ys = sol.sol(ts)
            Ps = np.array([max(force(G @ yy[:nq] - yy[2 * nq] - gap), 0.0) for yy in Ys.T])
            Ts = np.array([support(yy, True) for yy in Ys.T])

            def peak(fun, k, ts=ts, sol=sol):
                lo, hi = ts[max(k - 1, 0)], ts[min(k + 1, len(ts) - 1)]
                res = minimize_scalar(lambda s: -fun(sol.sol(s)), bounds=(lo, hi),
                                      method="bounded", options={"xatol": 1e-16})
                return max(-res.fun, fun(sol.sol(ts[k])))
            P_peak = peak(lambda yy: force(G @ yy[:nq] - yy[2 * nq] - gap), int(np.argmax(Ps)))
            T_peak = peak(lambda yy: abs(support(yy, True)), int(np.argmax(abs(Ts))))
            impacts.append({"t_start": start, "t_end": t1 if sol.status == 1 else None,
                            "P_peak": P_peak, "T_peak": T_peak,
                            "impulse": sol.sol(t1)[2 * nq + 1] - y[2 * nq + 1]})
        y = sol.sol(t1) if sol.status == 1 else sol.y[:, -1]
        t = t1
        if sol.status == 1:
            touching = not touching
            if touching:
                start = t
    return impacts, y, touching


# -- analysis -------------------------------------------------------------------------------
def test_closed_forms_agree_with_the_exact_cascade():
    """(6), (8), (12) in closed form against the matrix-exponential cascade and a dense grid."""
    lin = linearise(MO100)
    fa = first_approximation(MO100, lin.c, lin.c0)
    coef = coefficients(MO100, lin.c, lin.c0)
    # the reconstruction of the garbled (12) is checked against the cascade
    # T1'' + k1^2 T1 = a1 P1, which is the definition; 1e-9 of Tm is round-off of expm.
    y0 = np.zeros(8)
    y0[1] = lin.c * MO100.V0
    from scipy.linalg import expm
    for t in np.linspace(0, 2 * fa.tau, 9):
        y = expm(cascade_matrix(coef) * t) @ y0
        assert abs(y[0] - fa.P(t)) < 1e-9 * fa.Pm
        assert abs(y[2] - fa.T(t)) < 1e-9 * abs(fa.Tm)
    # (8) is the maximum of (6): a 200001-point grid finds the same to its resolution
    t = np.linspace(0, fa.tau, 200001)
    assert rel(fa.P(t).max(), fa.Pm) < 1e-9
    assert rel(fa.t_Pm, t[np.argmax(fa.P(t))]) < 1e-4
    assert rel(abs(fa.T(t)).max(), abs(fa.Tm)) < 1e-9


def test_linearised_stiffness_is_the_energy_equivalent_spring():
    """c = 1.25 K^(2/3) Pm^(1/3) stores at Pm the Hertz energy 0.4 K delta_m^2.5 (to round-off);
    the iterations stop when two cycles differ by < 0.1 % (the paper's criterion)."""
    lin = linearise(MO100)
    K = MO100.K
    dm = (lin.Pm / K) ** (2 / 3)
    assert rel(lin.Pm ** 2 / (2 * lin.c), 0.4 * K * dm ** 2.5) < 1e-12
    assert rel(lin.history_P[-1], lin.history_P[-2]) < 1e-3
    assert rel(lin.history_T[-1], lin.history_T[-2]) < 1e-3
    assert rel(lin.c0, MO100.k_n * lin.Tm ** (1 / 3)) < 1e-12
    # the fixed point contracts by about 1/6 per cycle: 0.1 % between cycles leaves < 0.05 %
    tight = linearise(MO100, rtol=1e-12)
    assert rel(lin.c, tight.c) < 5e-4 and rel(lin.c0, tight.c0) < 5e-4


def test_coupling_is_the_mass_defect_and_small_for_mo100(table):
    """a1 a2 = eps k1^2 k2^2 with eps = 1 - M_free/M_pinned (identity, to round-off); for MO-100
    eps ~ 1 % and mu < 1 %: the approximations are inside their validity window."""
    for (f, k_n), row in table.items():
        data = MO100.replace(S=f * S_P, k_n=k_n)
        coef = coefficients(data, row.c, row.c0)
        assert rel(coef.a1 * coef.a2, data.eps * coef.k1s * coef.k2s) < 1e-12
        assert rel(data.eps, 1 - data.mass_free / data.mass_pinned) < 1e-12
        assert 0.005 < row.eps < 0.02 and row.mu < 0.01


@pytest.mark.parametrize("f", [1.1, 0.9])
@pytest.mark.parametrize("k_n", K_N_VALUES)
def test_mo100_table_three_ways(table, f, k_n):
    """First approximation, exact coupled linear solution and the model's own integration over
    1 ms communication steps, with the same c, c0 (the paper's iterations)."""
    row = table[(f, k_n)]
    model = make(S=f * S_P, k_n=k_n)
    out, _, _ = run(model, 3e-3, 1e-3)
    # the model runs the same iteration at initialization: the same c, c0 to round-off
    assert rel(out["c_contact_used"], row.c) < 1e-12 and rel(out["c_support_used"], row.c0) < 1e-12
    assert out["n_impacts"] == 1 and out["contact"] == 0
    # model vs exact: the same linear ODE, integrated at rtol 1e-10 with located events against a
    # matrix exponential; 1e-7 leaves a factor 30 over the measured 3.4e-9 (Tm; Pm, tau ~3e-11).
    assert rel(out["P_peak"], row.Pm_exact) < 1e-7
    assert rel(out["T_peak"], abs(row.Tm_exact)) < 1e-7
    assert rel(out["impact_duration"], row.tau_exact) < 1e-7
    # first approximation vs exact: the brief's 0.5 % on Pm and Tm holds everywhere (measured
    # at most 0.25 % in Pm, 0.19 % in Tm: the neglected coupling is mu < 1 %).
    assert rel(row.Pm, row.Pm_exact) < 5e-3
    assert rel(abs(row.Tm), abs(row.Tm_exact)) < 5e-3
    # tau: the first approximation always ends early (T delays the end of contact). The brief's
    # 1 % holds for S = 1.1 J/(m r) (at most 0.92 %) and for 0.9 at k_n = 160e6 (0.87 %), NOT for
    # 0.9 at k_n = 40e6 (1.68 %) and 80e6 (1.19 %): there the bound that holds is 2 %.
    assert row.tau < row.tau_exact
    bound = 2e-2 if (f == 0.9 and k_n < 160e6) else 1e-2
    assert rel(row.tau, row.tau_exact) < bound
    if bound > 1e-2:
        assert rel(row.tau, row.tau_exact) > 1e-2      # the 1 % claim fails here: say so
    # the second approximation closes the gap: its remaining error is O(mu^2) ~ 1e-4
    assert rel(row.tau2, row.tau_exact) < 2e-4
    assert rel(row.Pm2, row.Pm_exact) < 1e-6
    assert rel(abs(row.Tm2), abs(row.Tm_exact)) < 1e-6


def test_paper_claims(table):
    """Which of the paper's statements hold for MO-100, for each reading of 'S 10 % off'."""
    rows = list(table.values())
    def by(f):
        return [table[(f, k)] for k in K_N_VALUES]
    # "Pm about 1 MN": 0.905 MN (S = 1.1) and 1.031 MN (S = 0.9); within 10 %.
    assert all(0.9e6 < r.Pm < 1.1e6 for r in rows)
    # "Tm about 17-18 % of Pm": measured 16.87 ... 18.13 %; it holds to +-0.2 points (three of
    # six rows are strictly inside 17-18 %), and the three Tm differ little (< 8 %).
    ratios = [100 * r.ratio for r in rows]
    assert all(16.8 < x < 18.2 for x in ratios)
    assert sum(17.0 <= x <= 18.0 for x in ratios) == 3
    for f in (1.1, 0.9):
        Tms = [abs(r.Tm) for r in by(f)]
        assert max(Tms) / min(Tms) < 1.08
    # "dP at most 20 kN, about 2 % of Pm at k_n = 80e6": 13.3 kN = 1.47 % (S = 1.1) and
    # 18.8 kN = 1.82 % (S = 0.9); <= 20 kN holds for both, "about 2 %" fits S = 0.9 better.
    assert table[(1.1, 80e6)].max_dP < 20e3 and table[(0.9, 80e6)].max_dP < 20e3
    assert 0.014 < table[(1.1, 80e6)].max_dP / table[(1.1, 80e6)].Pm < 0.015
    assert 0.018 < table[(0.9, 80e6)].max_dP / table[(0.9, 80e6)].Pm < 0.019
    assert all(0.01 < r.max_dP / r.Pm < 0.025 for r in rows)
    # "dP decreases as the support stiffens": true for S = 0.9, not for S = 1.1 (40 -> 80 grows)
    d09 = [r.max_dP for r in by(0.9)]
    d11 = [r.max_dP for r in by(1.1)]
    assert d09[0] > d09[1] > d09[2]
    assert d11[1] > d11[0] > d11[2]
    # "for the soft support the largest dP is at the end of the pulse": true (at t = tau1).
    assert all(r.t_max_dP > 0.99 * r.tau for r in (table[(1.1, 40e6)], table[(0.9, 40e6)]))
    # "duration grows by less than 1 %": true for S = 1.1 (<= 0.93 %); for S = 0.9 only at
    # k_n = 160e6 (1.70 % and 1.19 % at 40e6, 80e6).
    assert all(0 < r.tau2 / r.tau - 1 < 0.01 for r in by(1.1))
    assert [r.tau2 / r.tau - 1 < 0.01 for r in by(0.9)] == [False, False, True]
    # "the correction of Pm is at most 0.2 %": true for S = 1.1 (<= 0.15 %), for S = 0.9 except
    # k_n = 160e6 (0.25 %).
    assert all(r.Pm2 / r.Pm - 1 < 2e-3 for r in by(1.1))
    assert [r.Pm2 / r.Pm - 1 < 2e-3 for r in by(0.9)] == [True, True, False]
    # "dT at most 2 kN, the correction of Tm below 1 %": dT <= 2 kN holds for S = 1.1 (<= 1.61 kN)
    # and fails for S = 0.9 (2.06 ... 2.86 kN); the Tm correction is < 0.2 % everywhere.
    assert all(r.max_dT < 2e3 for r in by(1.1))
    assert all(r.max_dT > 2e3 for r in by(0.9))
    assert all(abs(abs(r.Tm2) / abs(r.Tm) - 1) < 2e-3 for r in rows)
    # "T may alternate in sign (curve 2, k_n = 80e6)": T1 changes sign during the impact at
    # k_n = 80e6 for both readings.
    assert table[(1.1, 80e6)].T1_changes_sign and table[(0.9, 80e6)].T1_changes_sign


def test_format_impact_table(table):
    text = format_impact_table(list(table.values()))
    assert text.count("\n") == 3 + 6
    assert "905.3" in text and "1030.6" in text


# -- model: Hertz, energy, communication steps, rollback, re-contact, centre of percussion ---
@pytest.mark.parametrize("effects", [HERTZ, ["hertz_contact"]])
def test_hertz_matches_independent_reference(effects):
    """Hertz contact over 1 ms steps against the reference above (rtol 1e-12). The brief asks
    0.5 % in Pm and 1 % in tau; both integrate the same ODE to rtol <= 1e-10 with located
    events, so 1e-7 holds with a factor ~100 over the measured ~1e-9 and is asserted too."""
    model = make(effects)
    out, _, _ = run(model, 2e-3, 1e-3)
    c0 = out["c_support_used"] or None
    impacts, _, _ = reference(model.data(), c0=c0, hertz=True, t_end=2e-3)
    assert len(impacts) == 1 and out["n_impacts"] == 1
    ref = impacts[0]
    tau = ref["t_end"] - ref["t_start"]
    assert rel(out["P_peak"], ref["P_peak"]) < 5e-3 and rel(out["impact_duration"], tau) < 1e-2
    assert rel(out["P_peak"], ref["P_peak"]) < 1e-7
    assert rel(out["impact_duration"], tau) < 1e-7
    assert rel(out["T_peak"], ref["T_peak"]) < 1e-7
    assert rel(out["impulse"], ref["impulse"]) < 1e-7


def test_linear_matches_independent_reference_pinned():
    """Pinned rocker, linear contact: model, reference and the closed form (6)-(8) with
    k2^2 = c S^2/J, T = (m r S/J - 1) P (exact here). Tolerances as above."""
    model = make([])
    out, _, _ = run(model, 2e-3, 1e-3)
    c = out["c_contact_used"]
    ex = exact_linear(model.data(), c, math.inf)
    fa = first_approximation(model.data(), c, math.inf)
    impacts, _, _ = reference(model.data(), c=c, t_end=2e-3)
    assert rel(out["P_peak"], ex.Pm) < 1e-7 and rel(out["P_peak"], impacts[0]["P_peak"]) < 1e-7
    assert rel(out["P_peak"], fa.Pm) < 1e-7 and rel(out["impact_duration"], fa.tau) < 1e-7
    assert rel(out["T_peak"], abs(ex.Tm)) < 1e-7
    assert rel(out["T_peak"], impacts[0]["T_peak"]) < 1e-7


@pytest.mark.parametrize("effects", [COMPLIANT, HERTZ, [], ["hertz_contact"]])
def test_energy_balance(effects):
    """Rocker kinetic energy before = rocker + support energy after + energy radiated into the
    rod, to 1e-6 relative (the brief's; measured ~1e-11 linear, ~1e-9 Hertz: the budget is the
    integration at rtol 1e-10). Energy computed here from the states, not by the model."""
    model = make(effects)
    out, x, _ = run(model, 3e-3, 1e-3)
    p = model.p
    E0 = 0.5 * p.J * (p.V0 / p.S) ** 2
    s = dict(zip(model.state_names(), x))
    u0, v0 = s.get("u0", 0.0), s.get("v0", 0.0)
    c0 = out["c_support_used"]
    E1 = (0.5 * p.m * v0 ** 2 + p.m * p.r * v0 * s["omega"] + 0.5 * p.J * s["omega"] ** 2
          + 0.5 * c0 * u0 ** 2)
    assert out["contact"] == 0
    assert abs(E1 + out["E_radiated"] - E0) < 1e-6 * E0
    assert out["E_radiated"] / E0 > 0.8      # most of the energy goes into the rod


@pytest.mark.parametrize("effects,steps", [
    (COMPLIANT, [1e-6, 1e-5, 1e-4, 1e-3, 1e-2]),
    (HERTZ, [1e-6, 1e-4, 1e-3, 1e-2]),
])
def test_communication_step_does_not_change_the_impact(effects, steps):
    """Peaks, duration, impulse and radiated energy of the impact are the same for communication
    steps from 1e-6 to 1e-2 s (0.4 ms impact): relative 1e-7, two decades above the integration
    tolerance (the runs differ only in where the integrator restarts)."""
    results = []
    for h in steps:
        out, _, _ = run(make(effects), max(2e-3, h), h)
        results.append(out)
    ref = results[steps.index(1e-3)]
    for out in results:
        for key in ("P_peak", "T_peak", "impact_duration", "impulse", "E_radiated"):
            assert rel(out[key], ref[key]) < 1e-7, key
        assert out["n_impacts"] == 1


def test_outputs_during_the_impact_and_rollback():
    """Steps of 0.1 ms inside the impact: P, T, contact and the running peaks; a saved
    (x, discrete_state) restores the model exactly (FMU state rollback)."""
    model = make()
    u = model.default_inputs()
    x = model.initial_state(u)
    assert model.output_values(0.0, x, u)[model.output_index("contact")] == 1.0
    x = model.advance(0.0, x, 1e-4, held(u), RTOL, RTOL * model.state_nominal())
    saved_x, saved_d = list(x), json.loads(json.dumps(model.discrete_state()))
    saved_solver = model.solver_state()
    y1 = model.output_values(1e-4, x, u)
    assert y1[model.output_index("contact")] == 1.0
    P = y1[model.output_index("P")]
    assert y1[model.output_index("P_peak")] == pytest.approx(P, rel=1e-12)   # still rising
    assert y1[model.output_index("impact_duration")] == pytest.approx(1e-4, rel=1e-12)
    xa = model.advance(1e-4, x, 9e-4, held(u), RTOL, RTOL * model.state_nominal())
    ya = model.output_values(1e-3, xa, u)
    model.set_discrete_state(saved_d)
    model.set_solver_state(saved_solver)
    xb = model.advance(1e-4, saved_x, 9e-4, held(u), RTOL, RTOL * model.state_nominal())
    yb = model.output_values(1e-3, xb, u)
    assert np.array_equal(xa, xb) and np.array_equal(ya, yb)    # deterministic: bit-identical


def test_recontact_after_rebound():
    """Swung by a constant drive torque from theta_start, the rocker strikes, rebounds, is driven
    back and strikes again. Impact count and final state agree with the reference (1e-6: after
    several impacts the state is sensitive to the separation times, each located to ~1e-12 s);
    energy: E(0) + work of the torque = E(t) + radiated, to 1e-6; the 1 ms and 0.1 ms
    communication steps agree to 1e-7."""
    tau, theta0, t_end = 2000.0, -0.05, 15e-3
    params = dict(strike_at_start=0.0, theta_start=theta0, w_start=0.0, tool_gap=0.0)
    model = make(**params)
    out, x, rows = run(model, t_end, 1e-3, tau=tau, record=True)
    out_fine, x_fine, _ = run(make(**params), t_end, 1e-4, tau=tau)
    assert out["n_impacts"] >= 3
    assert rows[:, model.output_index("n_impacts")].max() == out["n_impacts"]
    for key in ("n_impacts", "P_peak", "T_peak", "impact_duration", "E_radiated"):
        assert rel(out_fine[key], out[key]) < 1e-7 if out[key] else out_fine[key] == 0, key
    c, c0 = out["c_contact_used"], out["c_support_used"]
    impacts, y_ref, touching = reference(model.data(), c=c, c0=c0, tau=tau,
                                         q0=[0.0, theta0], qd0=[0.0, 0.0], t_end=t_end)
    assert len(impacts) == out["n_impacts"]
    assert bool(out["contact"]) == touching
    s = dict(zip(model.state_names(), x))
    assert rel(s["theta"], y_ref[1]) < 1e-6 and abs(s["omega"] - y_ref[3]) < 1e-6 * 10
    # the model reports the last impact, finished or ongoing at t_end
    assert rel(out["P_peak"], impacts[-1]["P_peak"]) < 1e-6
    assert rel(out["T_peak"], impacts[-1]["T_peak"]) < 1e-6
    # energy with the work of the drive torque
    p = model.p
    u0, v0, th, om = s["u0"], s["v0"], s["theta"], s["omega"]
    E = 0.5 * p.m * v0 ** 2 + p.m * p.r * v0 * om + 0.5 * p.J * om ** 2 + 0.5 * c0 * u0 ** 2
    if out["contact"]:
        E += 0.5 * c * (u0 + p.S * th - s["w_tool"]) ** 2
    W = tau * (th - theta0)
    assert abs(E + out["E_radiated"] - W) < 1e-6 * W


def test_free_flight_support_in_closed_form():
    """After the MO-100 impact the elastic support rings on (undamped) while a drive torque
    pulls the rocker back (-500 N.m on J + 0.1 kg.m2): 11 ms of free flight in 1 ms steps.
    The support is integrated in closed form there (support_flight.py): against the full
    equations by solve_ivp at rtol 1e-12 (the scipy path), every output within 1e-8 of its
    largest value (measured 1.2e-9 on T and u_support; the full equations on the runtime path
    at rtol 1e-10 before the closed form: 4.1e-8 on v_support), and at most 7 right-hand-side
    calls per free step, one Dormand-Prince step (the full equations took ~1200 per step)."""
    u = [-500.0, 0.1]
    reference = make()
    reference.solver = "scipy"
    expected, _, _ = stepped(reference, 12e-3, 1e-3, u, 1e-12)
    model = make()
    rows, calls, _ = stepped(model, 12e-3, 1e-3, u, RTOL)
    scale = np.maximum(np.abs(expected).max(axis=0), 1e-300)
    worst = np.abs(rows - expected).max(axis=0) / scale
    print(f"\nfree flight: worst {worst.max():.1e} ({model.outputs[int(worst.argmax())].name}), "
          f"calls per step {calls}")
    assert expected[-1, model.output_index("contact")] == 0.0
    assert worst.max() <= 1e-8
    assert max(calls[1:]) <= 7

@pytest.mark.parametrize("effects", [COMPLIANT, HERTZ])
def test_centre_of_percussion_support_feels_nothing(effects):
    """m r S = J: a1 = a2 = 0, T stays zero. Tolerance 1e-9 Pm: m r S - J is zero to round-off
    (~1e-16 J), so T is round-off times the impact force (measured below 1e-12 Pm). 10 % off,
    the same impact gives T of 17-18 % of P."""
    model = make(effects, S=S_P, c_support=4.4e9)     # c_support given: no Tm to iterate on
    out, x, rows = run(model, 3e-3, 1e-4, record=True)
    assert out["T_peak"] < 1e-9 * out["P_peak"]
    assert np.abs(rows[:, model.output_index("T")]).max() < 1e-9 * out["P_peak"]
    assert abs(dict(zip(model.state_names(), x))["u0"]) < 1e-9 * 1e-3
    off, _, _ = run(make(effects, S=1.1 * S_P, c_support=4.4e9), 3e-3, 1e-3)
    assert 0.15 < off["T_peak"] / off["P_peak"] < 0.20
    # the analysis agrees: at the centre of percussion the coupling vanishes
    data = MO100.replace(S=S_P)
    assert data.eps < 1e-28 and abs(exact_linear(data, 1.33e9, 4.4e9).Tm) < 1e-9 * 1e6


def test_drive_inertia_and_parameter_checks():
    """flange_J adds to J (pinned: strike-point mass (J + J_d)/S^2); impossible data raise."""
    m1 = make([], c_contact=1.3e9)
    m2 = make([], c_contact=1.3e9, J=0.734 + 0.2)
    o1, _, _ = run(m1, 2e-3, 1e-3, J_drive=0.2)
    o2, _, _ = run(m2, 2e-3, 1e-3)
    assert rel(o1["P_peak"], o2["P_peak"]) < 1e-9 and rel(o1["impulse"], o2["impulse"]) < 1e-9
    with pytest.raises(ParameterError, match="J"):
        RockerImpact({"J": 0.3})                         # J < m r^2
    with pytest.raises(ParameterError, match="theta_start"):
        RockerImpact({"strike_at_start": 0.0, "theta_start": 0.01})   # inside the tool
    with pytest.raises(ParameterError, match="strike_at_start"):
        RockerImpact({"strike_at_start": 0.5})
    with pytest.raises(ParameterError, match="c_support"):   # centre of percussion: Tm = 0
        RockerImpact({"S": S_P}).initial_state(np.zeros(2))
    assert make(COMPLIANT).state_names() == ("u0", "v0", "theta", "omega", "w_tool", "impulse",
                                             "E_radiated", "t_contact")
    assert len(make([]).state_names()) == 6             # pinned: no support states


def test_second_approximation_matches_validity_estimate(table):
    """The first approximation's relative error in Pm is of the order of mu (and the second's of
    mu^2): measured |Pm1/Pm - 1| <= 0.4 mu and |Pm2/Pm - 1| <= mu^2 for all six rows."""
    for row in table.values():
        assert rel(row.Pm, row.Pm_exact) < 0.4 * row.mu
        assert rel(row.Pm2, row.Pm_exact) < row.mu ** 2
        assert validity(MO100.replace(S=row.S, k_n=row.k_n), row.c, row.c0)["mu"] == row.mu
    sa = second_approximation(MO100, table[(1.1, 80e6)].c, table[(1.1, 80e6)].c0)
    assert sa.dP(0.0) == 0.0 and sa.dT(0.0) == 0.0


def test_claims_verdicts(table):
    """`crankfmu analyze impact` states per reading which claims hold: the issue's tau bound of
    the first approximation holds for S = 1.1 J/(m r) and fails for 0.9 (rows measured above)."""
    from crankfmu.studies.rocker_analysis import claims, format_claims
    items = claims(list(table.values()))
    verdict = {(c.S_factor, c.text): c.holds for c in items}
    tau = "1st approx. vs exact: contact duration tau within 1 %"
    assert verdict[(1.1, tau)] and not verdict[(0.9, tau)]
    pm_tm = "1st approx. vs exact: Pm and Tm within 0.5 %"
    assert verdict[(1.1, pm_tm)] and verdict[(0.9, pm_tm)]
    assert verdict[(1.1, "dT <= 2 kN")] and not verdict[(0.9, "dT <= 2 kN")]
    assert format_claims(items).count("FAILS") == sum(not c.holds for c in items)
