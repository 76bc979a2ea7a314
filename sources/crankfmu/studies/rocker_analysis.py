"""Rocker impact unit: the paper's analysis (seed rocker_impact_unit, eq. 1-18).

The equations, (1)-(2) and the pinned rocker, are in `rocker_linear` (the FMU's share of the
theory); sources/crankfmu/models/rocker_impact/README.md has the derivation.

What is here
    RockerData                 the rocker, the contact, the rod and the bearing constant k_n.
    coefficients(data, c, c0)  k1^2, a1, h, k2^2, a2, lambda of (1)-(2).
    first_approximation        T = 0 in (2): P1 (6), tau (7), Pm (8), T1 (12), Tm1 = max |T1|.
    linearise                  the paper's fixed-point iterations for c (on Pm) and c0 (on Tm).
    second_approximation       dP, dT of (14)-(18) as the exact linear cascade
                                   dP'' + 2h dP' + k2^2 dP = a2 T1,  dT'' + k1^2 dT = a1 dP
                               (zero initial values), evaluated by a matrix exponential.
    exact_linear               the coupled 4th-order system (1)-(2) by matrix exponential until
                               P returns to zero: Pm, tau, Tm.
    validity                   coupling measures that bound the approximations.
    impact_table, format_impact_table   the MO-100 table for both readings of "S 10 % off".

Validity window of the approximations (derived in the model card): the coupling enters only
through the product a1 a2 = eps k1^2 k2^2 with eps = (m r S - J)^2/(J (J_C + m (S - r)^2))
= 1 - M_free/M_pinned (the relative difference of the strike-point masses of a free and of a
pinned rocker). The n-th approximation is the n-th partial sum of a Neumann series in a1 a2;
its error over the impact is of order mu^n with mu = eps k1^2 k2/(2 lambda |s0^2 + k1^2|),
s0 = -h + i lambda (the relative shift of the impact eigenvalue), and it grows like
(t/tau)^n after the impact (secular terms t sin(k1 t), t exp(-h t) sin(lambda t)). So the
approximations hold for mu << 1 over 0 <= t <= tau (the impact), not for the ringing after it,
and they fail near the resonance k1 -> lambda.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

# the linear theory lives in the FMU runtime (rocker_linear); re-exported for the analyses
from ..models.rocker_impact.rocker_linear import (ITERATION_RTOL, K_N_VALUES, S_FACTORS,
                                                  AnalysisError, Coefficients,
                                                  FirstApproximation, LinearFlow,
                                                  Linearisation, RockerData, _grid_size,
                                                  coefficients, exact_linear, extremum,
                                                  first_approximation, first_return_to_zero,
                                                  linearise, support_stiffness)
from ..outputs import write_table


# -- second approximation -------------------------------------------------------------------
@dataclass(frozen=True)
class SecondApproximation:
    """P2 = P1 + dP, T2 = T1 + dT; dP, dT of (14)-(18) as the exact linear cascade."""

    first: FirstApproximation
    flow: LinearFlow = field(repr=False)
    max_dP: float      # max |dP| on [0, tau1]
    t_max_dP: float
    max_dT: float      # max |dT| on [0, tau1]
    t_max_dT: float
    Pm2: float         # max P2
    tau2: float        # P2 returns to zero
    Tm2: float         # signed T2 at max |T2| on [0, tau2]

    def dP(self, t):
        return self.flow(t)[..., 4]

    def dT(self, t):
        return self.flow(t)[..., 6]

    def P1(self, t):
        return self.flow(t)[..., 0]

    def T1(self, t):
        return self.flow(t)[..., 2]


def cascade_matrix(coef: Coefficients) -> np.ndarray:
    """y = (P1, P1', T1, T1', dP, dP', dT, dT'):
        P1'' + 2h P1' + k2^2 P1 = 0,   T1'' + k1^2 T1 = a1 P1,
        dP'' + 2h dP' + k2^2 dP = a2 T1,   dT'' + k1^2 dT = a1 dP."""
    A = np.zeros((8, 8))
    for i in (0, 4):
        A[i, i + 1] = 1.0
        A[i + 1, i] = -coef.k2s
        A[i + 1, i + 1] = -2.0 * coef.h
    for i in (2, 6):
        A[i, i + 1] = 1.0
        A[i + 1, i] = -coef.k1s
    A[3, 0] = coef.a1
    A[5, 2] = coef.a2
    A[7, 4] = coef.a1
    return A


def second_approximation(data: RockerData, c: float, c0: float) -> SecondApproximation:
    """Corrections dP, dT of the second approximation, (14)-(18): solve (14) with the right
    side a2 T1 and (17) with a1 dP, zero initial values (P1 carries P'(0) = c V0). The cascade is
    linear with constant coefficients, so the matrix exponential is its closed form (it holds
    the secular t exp(-h t) sin(lambda t) and t sin(k1 t) terms of (15)-(18) exactly)."""
    fa = first_approximation(data, c, c0)
    coef = fa.coef
    if coef.pinned:
        raise AnalysisError("the pinned rocker has no second approximation: (2) is exact")
    y0 = np.zeros(8)
    y0[1] = c * data.V0
    flow = LinearFlow(cascade_matrix(coef), y0)
    n = _grid_size(max(coef.k1, coef.lam), fa.tau)
    t_dP, dP = extremum(flow.signal(4, 5), 0.0, fa.tau, n, absolute=True)
    t_dT, dT = extremum(flow.signal(6, 7), 0.0, fa.tau, n, absolute=True)

    P2 = flow.signal(0, 1, other=(4, 5))
    T2 = flow.signal(2, 3, other=(6, 7))
    tau2 = first_return_to_zero(P2, fa.tau, flow.omega_max)
    _, Pm2 = extremum(P2, 0.0, tau2, n)
    _, Tm2 = extremum(T2, 0.0, tau2, n, absolute=True)
    return SecondApproximation(fa, flow, abs(dP), t_dP, abs(dT), t_dT, Pm2, tau2, Tm2)


def validity(data: RockerData, c: float, c0: float) -> dict:
    """Coupling measures: eps = 1 - M_free/M_pinned (a1 a2 = eps k1^2 k2^2) and
    mu = eps k1^2 k2/(2 lambda |s0^2 + k1^2|), s0 = -h + i lambda, the relative shift of the
    impact eigenvalue; also the support-to-impact frequency ratio k1/lambda."""
    coef = coefficients(data, c, c0)
    if coef.pinned:
        return {"eps": data.eps, "mu": 0.0, "k1_over_lambda": math.inf}
    s0 = complex(-coef.h, coef.lam)
    mu = data.eps * coef.k1s * coef.k2 / (2.0 * coef.lam * abs(s0 * s0 + coef.k1s))
    return {"eps": data.eps, "mu": mu, "k1_over_lambda": coef.k1 / coef.lam}


# -- the paper's table -------------------------------------------------------------------------
@dataclass(frozen=True)
class TableRow:
    S_factor: float
    k_n: float
    S: float
    c: float
    c0: float
    Pm: float          # first approximation (8)
    tau: float         # (7)
    Tm: float          # max |T1| on [0, tau], signed
    max_dP: float
    t_max_dP: float
    max_dT: float
    Pm2: float
    tau2: float
    Tm2: float
    Pm_exact: float
    tau_exact: float
    Tm_exact: float
    eps: float
    mu: float
    T1_changes_sign: bool
    T1_opposite: float     # largest excursion of T1 against the sign of Tm, / |Tm| (on [0, tau])
    T_opposite_exact: float   # the same of the exact linear T on [0, tau_exact]

    @property
    def ratio(self) -> float:
        """Tm/Pm of the first approximation."""
        return abs(self.Tm) / self.Pm


ALTERNATION = 0.05   # an opposite lobe of 5 % of Tm or more counts as a sign-alternating T: three
#                      times the second approximation's largest correction of T (dT <= 1.5 % of
#                      Tm in the MO-100 table), so it is no artefact of the first approximation


def opposite_lobe(T: np.ndarray) -> float:
    """The largest excursion of a sampled T against the sign of its largest |T|, as a fraction
    of that |T| [1] (0: T keeps one sign)."""
    k = int(np.argmax(np.abs(T)))
    peak = float(T[k])
    if peak == 0.0:
        return 0.0
    return float(max(0.0, np.max(-np.sign(peak) * T)) / abs(peak))


def impact_row(data: RockerData, S_factor: float = math.nan,
               lin: Linearisation | None = None) -> TableRow:
    lin = lin or linearise(data)
    fa = first_approximation(data, lin.c, lin.c0)
    sa = second_approximation(data, lin.c, lin.c0)
    ex = exact_linear(data, lin.c, lin.c0)
    val = validity(data, lin.c, lin.c0)
    t = np.linspace(0.0, fa.tau, 2001)
    T1 = fa.T(t)
    changes = bool(np.any(T1 < -1e-6 * abs(fa.Tm)) and np.any(T1 > 1e-6 * abs(fa.Tm)))
    T_exact = ex.T(np.linspace(0.0, ex.tau, 2001))
    return TableRow(S_factor, data.k_n, data.S, lin.c, lin.c0, fa.Pm, fa.tau, fa.Tm, sa.max_dP,
                    sa.t_max_dP, sa.max_dT, sa.Pm2, sa.tau2, sa.Tm2, ex.Pm, ex.tau, ex.Tm,
                    val["eps"], val["mu"], changes, opposite_lobe(T1), opposite_lobe(T_exact))


def impact_table(base: RockerData | None = None, S_factors: Sequence[float] = S_FACTORS,
                 k_n_values: Sequence[float] = K_N_VALUES) -> list[TableRow]:
    """One row per (S factor, k_n): c and c0 from the paper's iterations, then the first
    approximation, the second-approximation corrections and the exact linear solution."""
    base = base or RockerData()
    rows = []
    for f in S_factors:
        for k_n in k_n_values:
            data = base.replace(S=f * base.S_percussion, k_n=k_n)
            rows.append(impact_row(data, f))
    return rows


def format_impact_table(rows: Sequence[TableRow] | None = None) -> str:
    """Plain-text table (for the CLI): first approximation Pm, tau, Tm, Tm/Pm; the largest
    second-approximation corrections dP, dT over [0, tau]; the exact linear Pm, tau, Tm."""
    rows = impact_table() if rows is None else rows
    head = (f"{'S/S_p':>6} {'k_n':>5} {'c':>9} {'c0':>9} | {'Pm':>8} {'tau':>6} {'Tm':>8} "
            f"{'Tm/Pm':>6} | {'max dP':>7} {'dP/Pm':>6} {'max dT':>6} | {'Pm ex':>8} "
            f"{'tau ex':>6} {'Tm ex':>8} | {'eps':>6} {'mu':>6}")
    units = (f"{'':>6} {'1e6':>5} {'GN/m':>9} {'GN/m':>9} | {'kN':>8} {'ms':>6} {'kN':>8} "
             f"{'%':>6} | {'kN':>7} {'%':>6} {'kN':>6} | {'kN':>8} {'ms':>6} {'kN':>8} | "
             f"{'':>6} {'':>6}")
    lines = ["Rocker impact (MO-100): first approximation (6)-(8), (12); corrections (14)-(18); "
             "exact coupled linear solution",
             "S_p = J/(m r) is the centre of percussion; c, c0 from the paper's iterations "
             "(0.1 %); Tm = largest |T| during the impact", head, units]
    for r in rows:
        lines.append(
            f"{r.S_factor:>6.2f} {r.k_n / 1e6:>5.0f} {r.c / 1e9:>9.4f} {r.c0 / 1e9:>9.4f} | "
            f"{r.Pm / 1e3:>8.1f} {r.tau * 1e3:>6.4f} {abs(r.Tm) / 1e3:>8.2f} "
            f"{100 * r.ratio:>6.2f} | {r.max_dP / 1e3:>7.2f} {100 * r.max_dP / r.Pm:>6.2f} "
            f"{r.max_dT / 1e3:>6.2f} | {r.Pm_exact / 1e3:>8.1f} {r.tau_exact * 1e3:>6.4f} "
            f"{abs(r.Tm_exact) / 1e3:>8.2f} | {r.eps:>6.4f} {r.mu:>6.4f}")
    return "\n".join(lines)


TABLE_UNITS = {"S_factor": "1", "k_n": "N(2/3)/m", "S": "m", "c": "N/m", "c0": "N/m", "Pm": "N",
               "tau": "s", "Tm": "N", "max_dP": "N", "t_max_dP": "s", "max_dT": "N", "Pm2": "N",
               "tau2": "s", "Tm2": "N", "Pm_exact": "N", "tau_exact": "s", "Tm_exact": "N",
               "eps": "1", "mu": "1", "T1_changes_sign": "1", "T1_opposite": "1",
               "T_opposite_exact": "1"}


def write_impact_table(rows: Sequence[TableRow], path):
    """The table's rows as CSV, every field with its unit."""
    return write_table(path, [f"{k} [{u}]" for k, u in TABLE_UNITS.items()],
                       ([getattr(r, k) for k in TABLE_UNITS] for r in rows))


# -- the paper's claims ------------------------------------------------------------------------
@dataclass(frozen=True)
class Claim:
    S_factor: float
    text: str
    holds: bool
    measured: str


def _pct(x: float) -> str:
    return f"{100 * x:.2f} %"


def claims(rows: Sequence[TableRow]) -> list[Claim]:
    """The paper's statements about MO-100 (and the issue's agreement bounds of the first
    approximation with the exact linear solution), checked per reading of S."""
    out = []
    for f in dict.fromkeys(r.S_factor for r in rows):
        rs = sorted((r for r in rows if r.S_factor == f), key=lambda r: r.k_n)

        def add(text, holds, measured, f=f):  # called at once: f is this reading's
            out.append(Claim(f, text, bool(holds), measured))
        add("Pm about 1 MN (within 10 %)", all(0.9e6 < r.Pm < 1.1e6 for r in rs),
            ", ".join(f"{r.Pm / 1e3:.0f} kN" for r in rs))
        ratios = ", ".join(_pct(r.ratio) for r in rs)
        add("Tm about 17-18 % of Pm (within 16.5-18.5 %)",
            all(0.165 <= r.ratio <= 0.185 for r in rs), ratios)
        add("Tm strictly within 17-18 % of Pm", all(0.17 <= r.ratio <= 0.18 for r in rs), ratios)
        mid = [r for r in rs if r.k_n == 80e6]
        if mid:
            r = mid[0]
            add("dP <= 20 kN, about 2 % of Pm at k_n = 80e6",
                r.max_dP <= 20e3 and 0.015 <= r.max_dP / r.Pm <= 0.025,
                f"{r.max_dP / 1e3:.1f} kN = {_pct(r.max_dP / r.Pm)}")
        dPs = [r.max_dP for r in rs]
        add("dP decreases as the support stiffens", all(a > b for a, b in zip(dPs, dPs[1:])),
            " -> ".join(f"{x / 1e3:.1f}" for x in dPs) + " kN")
        add("2nd approximation lengthens the impact by < 1 %",
            all(0.0 <= r.tau2 / r.tau - 1.0 < 0.01 for r in rs),
            ", ".join(_pct(r.tau2 / r.tau - 1.0) for r in rs))
        add("2nd approximation changes Pm by <= 0.2 %",
            all(abs(r.Pm2 / r.Pm - 1.0) <= 2e-3 for r in rs),
            ", ".join(_pct(r.Pm2 / r.Pm - 1.0) for r in rs))
        add("dT <= 2 kN", all(r.max_dT <= 2e3 for r in rs),
            ", ".join(f"{r.max_dT / 1e3:.2f} kN" for r in rs))
        add("2nd approximation changes Tm by < 1 %",
            all(abs(abs(r.Tm2) / abs(r.Tm) - 1.0) < 0.01 for r in rs),
            ", ".join(_pct(abs(r.Tm2) / abs(r.Tm) - 1.0) for r in rs))
        add("1st approx. vs exact: Pm and Tm within 0.5 %",
            all(abs(r.Pm / r.Pm_exact - 1) < 5e-3 and abs(abs(r.Tm) / abs(r.Tm_exact) - 1) < 5e-3
                for r in rs),
            ", ".join(f"{_pct(abs(r.Pm / r.Pm_exact - 1))}/{_pct(abs(r.Tm / r.Tm_exact - 1))}"
                      for r in rs))
        if mid:
            lobes = ", ".join(f"{100 * r.T1_opposite:.1f} %" for r in rs)
            add(f"T alternates in sign at k_n = 80e6, curve 2 (opposite lobe >= "
                f"{100 * ALTERNATION:.0f} % of Tm)", mid[0].T1_opposite >= ALTERNATION, lobes)
            add("curve 2 is the sign-alternating one (the largest opposite lobe of the three)",
                max(rs, key=lambda r: r.T1_opposite) is mid[0], lobes)
        add("1st approx. vs exact: contact duration tau within 1 %",
            all(abs(r.tau / r.tau_exact - 1) < 1e-2 for r in rs),
            ", ".join(_pct(1 - r.tau / r.tau_exact) for r in rs) + " short")
    return out


def format_claims(items: Sequence[Claim]) -> str:
    lines = ["The paper's claims (and the issue's first-approximation bounds), per reading of S; "
             "values per k_n in the table's order:"]
    for c in items:
        lines.append(f"  S = {c.S_factor:.2f} S_p  {'holds' if c.holds else 'FAILS':>5}  "
                     f"{c.text}: {c.measured}")
    return "\n".join(lines)


# -- the support stiffness iterated on the peak of the Hertz-contact impact -----------------------
HERTZ_EFFECTS = ("support_compliance", "hertz_contact")
PARAMETERS = ("J", "m", "r", "S", "R_c", "d", "E", "rho", "nu", "V0", "k_n")


def hertz_impact(data: RockerData, c0: float | None = None, step: float = 1e-4,
                 rtol: float = 1e-10) -> dict:
    """The impact with Hertz contact P = K delta^1.5 on the linear support c0 [N/m] (None: the
    model's own c0, the paper's iteration on (12) with the linearised contact), by the
    RockerImpact model stepped as its FMU steps it (`step` [s] per call, its own integrator
    at `rtol`, the peaks located by the model): P_peak, T_peak [N], impact_duration [s],
    c_support_used [N/m] once the contact has ended."""
    from ..models.catalog import make_physics
    from ..runtime.model import held

    params = {k: getattr(data, k) for k in PARAMETERS}
    if c0 is not None:
        params["c_support"] = c0
    model = make_physics("RockerImpact", params, HERTZ_EFFECTS)
    u = model.default_inputs()
    x = model.initial_state(u)
    names = [v.name for v in model.outputs]
    atol = [rtol * v for v in model.state_nominal()]
    for k in range(1000):
        x = model.step(k * step, x, step, held(u), rtol, atol)
        y = dict(zip(names, model.output_values((k + 1) * step, x, u)))
        if y["contact"] == 0.0:
            return {key: float(y[key]) for key in ("P_peak", "T_peak", "impact_duration",
                                                   "c_support_used")}
    raise AnalysisError(f"the Hertz impact did not end within {1000 * step:g} s")


def hertz_peak_support(data: RockerData, rtol: float = ITERATION_RTOL,
                       max_iter: int = 50) -> dict:
    """The paper's support iteration c0 = k_n Tm^(1/3), with Tm the peak bearing load of the
    impact itself (Hertz contact, `hertz_impact`) instead of the first approximation's (12):
    start from the model's c0, repeat until two cycles' Tm differ by less than rtol (the
    paper's 0.1 %). Returns both c0 [N/m], the Hertz impact with each, and the history of Tm."""
    linear = hertz_impact(data)
    T_m, history = linear["T_peak"], [linear["T_peak"]]
    for _ in range(max_iter):
        run = hertz_impact(data, support_stiffness(data.k_n, T_m))
        history.append(run["T_peak"])
        done = abs(run["T_peak"] - T_m) < rtol * run["T_peak"]
        T_m = run["T_peak"]
        if done:
            return {"linear": linear, "hertz_peak": run, "history": tuple(history)}
    raise AnalysisError(f"the Hertz-peak support iteration did not converge in {max_iter} "
                        f"cycles (Tm history {history[-4:]})")


def hertz_peak_table(base: RockerData | None = None, S_factors: Sequence[float] = S_FACTORS,
                     k_n_values: Sequence[float] = K_N_VALUES) -> list[dict]:
    """One row per (S factor, k_n): `hertz_peak_support` with the row's data."""
    base = base or RockerData()
    rows = []
    for f in S_factors:
        for k_n in k_n_values:
            data = base.replace(S=f * base.S_percussion, k_n=k_n)
            rows.append({"S_factor": f, "k_n": k_n, **hertz_peak_support(data)})
    return rows


def format_hertz_peak_table(rows: Sequence[dict]) -> str:
    lines = ["Support stiffness with Hertz contact: c0 = k_n Tm^(1/3) iterated on (12) of the "
             "linearised contact (the model's default) and on the peak of the Hertz impact "
             "itself (--hertz-peak; RockerImpact stepped, 0.1 % as the paper)",
             f"{'S/S_p':>6} {'k_n':>5} | {'c0 (12)':>9} {'c0 Hertz':>9} {'diff':>7} | "
             f"{'Tm (12)':>8} {'Tm Hertz':>8} {'diff':>7} | {'Pm (12)':>8} {'diff':>7} | cycles",
             f"{'':>6} {'1e6':>5} | {'GN/m':>9} {'GN/m':>9} {'%':>7} | {'kN':>8} {'kN':>8} "
             f"{'%':>7} | {'kN':>8} {'%':>7} |"]
    for r in rows:
        a, b = r["linear"], r["hertz_peak"]
        lines.append(
            f"{r['S_factor']:>6.2f} {r['k_n'] / 1e6:>5.0f} | {a['c_support_used'] / 1e9:>9.4f} "
            f"{b['c_support_used'] / 1e9:>9.4f} "
            f"{100 * (b['c_support_used'] / a['c_support_used'] - 1):>+7.3f} | "
            f"{a['T_peak'] / 1e3:>8.2f} {b['T_peak'] / 1e3:>8.2f} "
            f"{100 * (b['T_peak'] / a['T_peak'] - 1):>+7.3f} | {a['P_peak'] / 1e3:>8.1f} "
            f"{100 * (b['P_peak'] / a['P_peak'] - 1):>+7.4f} | {len(r['history']) - 1:>6}")
    return "\n".join(lines)


def write_hertz_peak_table(rows: Sequence[dict], path):
    return write_table(path, ["S_factor [1]", "k_n [N(2/3)/m]", "iteration", "c0 [N/m]",
                              "T_peak [N]", "P_peak [N]", "impact_duration [s]"],
                       ([r["S_factor"], r["k_n"], name, r[name]["c_support_used"],
                         r[name]["T_peak"], r[name]["P_peak"], r[name]["impact_duration"]]
                        for r in rows for name in ("linear", "hertz_peak")))
