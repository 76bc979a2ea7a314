"""The Hertzian bearing (seed 004; effect hertz_support of RockerImpact and CrankRockerHammer).

The paper linearises the rocker's support as c0 = k_n Tm^(1/3); the bearing itself follows the
Hertz law T = kappa |u0|^1.5 sgn(u0), kappa = (k_n/1.25)^1.5. With both hertz_contact and
hertz_support on, the MO-100 impact (k_n = 80e6, S = 1.1 J/(m r), V0 = 10 m/s) is solved here a
second time, independently: the same equations (Lagrange, sources/crankfmu/models/rocker_impact/README.md) written
out below and integrated by scipy's DOP853 at rtol 1e-12 with the peaks located as events, and
compared with the model stepped as its FMU steps it (0.1 ms steps, the runtime's integrator at
rtol 1e-10). Peak contact force and peak bearing load agree to 1e-6 relative (measured below
1e-9). The constants K (Hertz contact) and Z (rod impedance) are the paper's data, taken from
RockerData; the test checks the dynamics, not the data.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from crankfmu.runtime.model import held
from crankfmu.models.catalog import make_physics

EFFECTS = ["support_compliance", "hertz_contact", "hertz_support"]


def independent_peaks(model, c0: float | None = None):
    """(P peak, |T| peak) of the first impact from the equations written out here: the Hertzian
    bearing, or with `c0` [N/m] the linear one T = c0 u0 (tests/test_papers_claims.py)."""
    p, data = model.p, model.data()
    K, Z, kappa = data.K, data.Z, (p.k_n / 1.25) ** 1.5
    mass = np.array([[p.m, p.m * p.r], [p.m * p.r, p.J]])

    def forces(y):
        u0, v0, th, om, w = y
        delta = u0 + p.S * th - w
        P = K * delta ** 1.5 if delta > 0.0 else 0.0
        T = kappa * math.copysign(abs(u0) ** 1.5, u0) if c0 is None else c0 * u0
        return P, T

    def rhs(t, y):
        P, T = forces(y)
        ddu, ddth = np.linalg.solve(mass, [-P - T, -P * p.S])
        return [y[1], ddu, y[3], ddth, P / Z]

    def contact_end(t, y):
        return y[0] + p.S * y[2] - y[4]
    contact_end.terminal, contact_end.direction = True, -1

    def p_extremum(t, y):  # delta' = 0
        return y[1] + p.S * y[3] - forces(y)[0] / Z

    def t_extremum(t, y):  # u0' = 0
        return y[1]
    y0 = [0.0, 0.0, 0.0, p.V0 / p.S, 0.0]
    sol = solve_ivp(rhs, (0.0, 2e-3), y0, method="DOP853", rtol=1e-12, atol=1e-16,
                    events=[contact_end, p_extremum, t_extremum])
    assert sol.status == 1  # the contact ended
    P_peak = max(forces(y)[0] for y in sol.y_events[1])
    T_candidates = list(sol.y_events[2]) + [sol.y_events[0][0]]
    T_peak = max(abs(forces(y)[1]) for y in T_candidates)
    return P_peak, T_peak


def stepped_peaks(model, h=1e-4):
    u = model.default_inputs()
    x = model.initial_state(u)
    names = [v.name for v in model.outputs]
    atol = [1e-10 * v for v in model.state_nominal()]
    for k in range(100):
        x = model.step(k * h, x, h, held(u), 1e-10, atol)
        y = model.output_values((k + 1) * h, x, u)
        if y[names.index("contact")] == 0.0:
            return y[names.index("P_peak")], y[names.index("T_peak")]
    raise AssertionError("the impact did not end in 10 ms")


def test_hertzian_bearing_against_an_independent_solution():
    model = make_physics("RockerImpact", {"k_n": 80e6}, EFFECTS)
    P_ref, T_ref = independent_peaks(model)
    P, T = stepped_peaks(make_physics("RockerImpact", {"k_n": 80e6}, EFFECTS))
    linear = stepped_peaks(make_physics("RockerImpact", {"k_n": 80e6}, EFFECTS[:2]))
    print(f"\nMO-100, k_n = 80e6, Hertz contact: Hertzian bearing Pm {P / 1e3:.2f} kN, Tm "
          f"{T / 1e3:.2f} kN (Tm/Pm {T / P:.4f}; independent solution: {abs(P / P_ref - 1):.1e}, "
          f"{abs(T / T_ref - 1):.1e}); linearised bearing Pm {linear[0] / 1e3:.2f} kN, Tm "
          f"{linear[1] / 1e3:.2f} kN (Tm/Pm {linear[1] / linear[0]:.4f})")
    assert P == pytest.approx(P_ref, rel=1e-6)
    assert T == pytest.approx(T_ref, rel=1e-6)
    assert T / linear[1] - 1.0 > 0.2  # the nonlinear bearing carries ~25 % more (seed 004)


def test_hertz_support_needs_the_elastic_support():
    from crankfmu.runtime.model import ParameterError
    with pytest.raises(ParameterError, match="only with effect support_compliance"):
        make_physics("RockerImpact", {}, ["hertz_support"])


def test_energy_closes_with_the_hertzian_bearing():
    """Mechanical energy lost over the impact = energy radiated into the rod, with the bearing's
    potential energy 0.4 kappa |u0|^2.5 in E_mech: to 1e-8 of E_mech(0) at rtol 1e-10."""
    model = make_physics("RockerImpact", {"k_n": 80e6}, EFFECTS)
    u = model.default_inputs()
    x = model.initial_state(u)
    names = [v.name for v in model.outputs]
    start = model.output_values(0.0, x, u)[names.index("E_mech")]
    atol = [1e-10 * v for v in model.state_nominal()]
    for k in range(10):
        x = model.step(k * 1e-4, x, 1e-4, held(u), 1e-10, atol)
    y = model.output_values(1e-3, x, u)
    lost = start - y[names.index("E_mech")]
    assert abs(lost - y[names.index("E_radiated")]) < 1e-8 * start
