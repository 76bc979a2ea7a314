"""Rocker impact unit: the linear theory the FMU needs at initialization (seed
rocker_impact_unit, eq. 1-13): the rocker data, the coefficients of the paper's pair (1)-(2), its
first approximation, the exact linear solution and the fixed-point linearisation of the contact
and support stiffnesses. The paper's further analysis (second approximation, validity, the MO-100
table and claims) is in `rocker_analysis`, outside the FMU runtime.

Coordinates (sources/crankfmu/models/rocker_impact/README.md has the derivation): u0 is the pivot's displacement
along the tool axis, theta the rocker angle (the strike point moves by S theta), w the tool end.

    m (u0'' + r theta'') = -P - T,    m r u0'' + J theta'' = -P S          (Lagrange)
    T = c0 u0,   P = c (u0 + S theta - w) while > 0,   w' = P/Z,   Z = E F/a

eliminate to the paper's pair (1)-(2):

    T'' + k1^2 T = a1 P,                 k1^2 = c0 J/(m J_C),  a1 = c0 (m r S - J)/(m J_C)
    P'' + 2 h P' + k2^2 P = a2 T,        2h = c/Z,  k2^2 = c [1/m + (S - r)^2/J_C],
                                         a2 = c (m r S - J)/(m J_C),  J_C = J - m r^2
    P(0) = 0, P'(0) = c V0, T(0) = T'(0) = 0 (the rocker touches the tool at t = 0).

Pinned rocker (c0 -> infinity): P'' + 2h P' + (c S^2/J) P = 0 and T = (m r S/J - 1) P exactly.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Callable

import numpy as np

from ...runtime.roots import brentq

# Defaults of the paper's iteration: the start guess "from experience" and the stop criterion.
P_GUESS = 1.0e6          # N, first guess of Pm (the paper: "about 1 MN")
T_GUESS_RATIO = 0.2      # first guess Tm = 0.2 Pm
ITERATION_RTOL = 1.0e-3  # stop when successive cycles differ by less than 0.1 %
K_N_VALUES = (40e6, 80e6, 160e6)   # N^(2/3)/m, the paper's three bearings
S_FACTORS = (1.1, 0.9)             # "S 10 % off the optimum J/(m r)": both readings


class AnalysisError(RuntimeError):
    """An iteration did not converge or a response has no end of contact."""


@dataclass(frozen=True)
class RockerData:
    """Rocker (J about the pivot, m, r, S), rod tool (d, E, rho), sphere R_c, bearing k_n."""

    J: float = 0.734
    m: float = 35.1
    r: float = 0.106
    S: float = 1.1 * 0.734 / (35.1 * 0.106)
    R_c: float = 0.060
    d: float = 0.080
    E: float = 2.04e11
    rho: float = 7850.0
    nu: float = 0.3
    V0: float = 10.0
    k_n: float = 80e6

    @classmethod
    def mo100(cls, S_factor: float = 1.1, k_n: float = 80e6, **changes) -> "RockerData":
        """MO-100 hammer data with S = S_factor * J/(m r) (the centre of percussion at 1)."""
        base = cls(k_n=k_n, **changes)
        return replace(base, S=S_factor * base.S_percussion)

    def replace(self, **changes) -> "RockerData":
        return replace(self, **changes)

    @property
    def J_C(self) -> float:
        """Inertia about the centre of mass."""
        return self.J - self.m * self.r ** 2

    @property
    def S_percussion(self) -> float:
        """Strike distance of the centre of percussion, m r S = J."""
        return self.J / (self.m * self.r)

    @property
    def F(self) -> float:
        return math.pi * self.d ** 2 / 4.0

    @property
    def wave_speed(self) -> float:
        return math.sqrt(self.E / self.rho)

    @property
    def Z(self) -> float:
        """Wave impedance of the rod E F/a (N.s/m)."""
        return self.E * self.F / self.wave_speed

    @property
    def K(self) -> float:
        """Hertz constant of a sphere R_c on a flat end, same material: P = K delta^1.5."""
        return hertz_constant(self.E, self.nu, self.R_c)

    @property
    def mass_free(self) -> float:
        """Strike-point mass of the free rocker, 1/(1/m + (S - r)^2/J_C)."""
        return 1.0 / (1.0 / self.m + (self.S - self.r) ** 2 / self.J_C)

    @property
    def mass_pinned(self) -> float:
        """Strike-point mass of the pinned rocker, J/S^2."""
        return self.J / self.S ** 2

    @property
    def eps(self) -> float:
        """Coupling (m r S - J)^2/(J (J_C + m (S - r)^2)) = 1 - M_free/M_pinned."""
        off = self.m * self.r * self.S - self.J
        return off ** 2 / (self.J * (self.J_C + self.m * (self.S - self.r) ** 2))


def hertz_constant(E: float, nu: float, R_c: float) -> float:
    """K = 2 E sqrt(R_c)/(3 (1 - nu^2)): sphere on a flat, both of modulus E."""
    return 2.0 * E * math.sqrt(R_c) / (3.0 * (1.0 - nu ** 2))


def linearised_contact_stiffness(K: float, P_m: float) -> float:
    """c = 1.25 K^(2/3) Pm^(1/3): the linear spring storing the Hertz energy at the same Pm."""
    return 1.25 * K ** (2.0 / 3.0) * P_m ** (1.0 / 3.0)


def support_stiffness(k_n: float, T_m: float) -> float:
    """c0 = k_n Tm^(1/3) (ball bearings, [2] of the seed)."""
    return k_n * abs(T_m) ** (1.0 / 3.0)


@dataclass(frozen=True)
class Coefficients:
    """Coefficients of (1)-(2); c0 = inf is the pinned rocker (k1, a1 unused)."""

    c: float
    c0: float
    k1s: float
    a1: float
    h: float
    k2s: float
    a2: float

    @property
    def pinned(self) -> bool:
        return math.isinf(self.c0)

    @property
    def k1(self) -> float:
        return math.sqrt(self.k1s)

    @property
    def k2(self) -> float:
        return math.sqrt(self.k2s)

    @property
    def lam(self) -> float:
        if self.k2s <= self.h ** 2:
            raise AnalysisError(f"overdamped contact: k2^2 = {self.k2s:.6g} <= h^2 = "
                                f"{self.h ** 2:.6g}; the impact has no half-sine (8) form")
        return math.sqrt(self.k2s - self.h ** 2)

    def matrix(self) -> np.ndarray:
        """A of y' = A y for y = (T, T', P, P') (the coupled system (1)-(2))."""
        return np.array([[0.0, 1.0, 0.0, 0.0],
                         [-self.k1s, 0.0, self.a1, 0.0],
                         [0.0, 0.0, 0.0, 1.0],
                         [self.a2, 0.0, -self.k2s, -2.0 * self.h]])


def coefficients(data: RockerData, c: float, c0: float) -> Coefficients:
    """k1^2, a1, h, k2^2, a2 of (1)-(2); c0 = math.inf gives the pinned rocker."""
    h = c / (2.0 * data.Z)
    if math.isinf(c0):
        return Coefficients(c, c0, math.inf, 0.0, h, c * data.S ** 2 / data.J, 0.0)
    mJC = data.m * data.J_C
    off = data.m * data.r * data.S - data.J
    return Coefficients(c=c, c0=c0, k1s=c0 * data.J / mJC, a1=c0 * off / mJC, h=h,
                        k2s=c * (1.0 / data.m + (data.S - data.r) ** 2 / data.J_C),
                        a2=c * off / mJC)


# -- extrema and zeros of smooth signals ----------------------------------------------------
class Signal:
    """A smooth scalar signal: at(t) -> (value, derivative) for an array t; grid(t0, t1, n)
    -> (t, value, derivative) on n + 1 equally spaced points."""

    def __init__(self, at: Callable[[np.ndarray], tuple], grid: Callable | None = None):
        self._at = at
        self._grid = grid  # a faster grid(t0, t1, n) than at() on a linspace, if given

    def at(self, t):
        return self._at(np.atleast_1d(np.asarray(t, dtype=float)))

    def grid(self, t0: float, t1: float, n: int):
        if self._grid is not None:
            return self._grid(t0, t1, n)
        t = np.linspace(t0, t1, n + 1)
        v, dv = self.at(t)
        return t, v, dv

    def value(self, t: float) -> float:
        return float(self.at(t)[0][0])

    def slope(self, t: float) -> float:
        return float(self.at(t)[1][0])


def _grid_size(omega_max: float, t_end: float) -> int:
    return int(max(400, 60 * omega_max * t_end / (2 * math.pi)))


_XTOL, _RTOL = 1e-16, 4 * np.finfo(float).eps


def extremum(signal: Signal, t0: float, t1: float, n: int = 400,
             absolute: bool = False) -> tuple[float, float]:
    """(t, value) of the largest value (or |value|) of a smooth signal on [t0, t1]: a grid,
    the sign changes of the derivative refined by brentq, and both ends."""
    t, v, dv = signal.grid(t0, t1, n)
    key = (lambda x: abs(x)) if absolute else (lambda x: x)
    cands = [(t0, float(v[0])), (t1, float(v[-1]))]
    for k in np.nonzero(np.sign(dv[:-1]) * np.sign(dv[1:]) < 0)[0]:
        tk = brentq(signal.slope, t[k], t[k + 1], xtol=_XTOL, rtol=_RTOL, maxiter=200)
        cands.append((tk, signal.value(tk)))
    best = max(cands, key=lambda tv: key(tv[1]))
    return best[0], best[1]


def first_return_to_zero(signal: Signal, t_guess: float, omega_max: float) -> float:
    """First t > 0 where a signal starting at 0 upwards returns to 0 (end of contact)."""
    t_hi = 1.5 * t_guess
    for _ in range(8):
        t, v, _ = signal.grid(0.0, t_hi, _grid_size(omega_max, t_hi))
        t, v = t[1:], v[1:]
        down = np.nonzero((v[:-1] > 0.0) & (v[1:] <= 0.0))[0]
        if len(down):
            k = down[0]
            return brentq(signal.value, t[k], t[k + 1], xtol=_XTOL, rtol=_RTOL, maxiter=200)
        t_hi *= 2.0
    raise AnalysisError(f"P does not return to zero before t = {t_hi:.3g} s")


class LinearFlow:
    """y(t) = expm(A t) y0 for a constant linear system."""

    def __init__(self, A: np.ndarray, y0):
        self.A = np.asarray(A, dtype=float)
        self.y0 = np.asarray(y0, dtype=float)
        eig = np.linalg.eigvals(self.A)
        self.omega_max = float(np.max(np.abs(eig.imag))) if len(eig) else 0.0

    def __call__(self, t) -> np.ndarray:
        """States at the times t: shape (len(t), n) for an array, (n,) for a scalar."""
        t_arr = np.atleast_1d(np.asarray(t, dtype=float))
        from scipy.linalg import expm  # imported when used: ~0.3 s in every FMU process
        y = np.array([expm(self.A * s) @ self.y0 for s in t_arr])
        return y if np.ndim(t) else y[0]

    def grid(self, t0: float, t1: float, n: int) -> tuple[np.ndarray, np.ndarray]:
        """(t, states) on n + 1 equally spaced points: one expm for the step, then products."""
        t = np.linspace(t0, t1, n + 1)
        from scipy.linalg import expm
        phi = expm(self.A * ((t1 - t0) / n))
        y = np.empty((n + 1, len(self.y0)))
        y[0] = self(t0)
        for k in range(n):
            y[k + 1] = phi @ y[k]
        return t, y

    def signal(self, index: int, d_index: int, other: tuple[int, int] | None = None) -> Signal:
        """Component index with derivative d_index (plus the pair `other`, if given)."""
        def pick(y):
            if other is None:
                return y[:, index], y[:, d_index]
            return y[:, index] + y[:, other[0]], y[:, d_index] + y[:, other[1]]
        sig = Signal(lambda t: pick(self(t)),
                     lambda t0, t1, n: (lambda ty: (ty[0], *pick(ty[1])))(self.grid(t0, t1, n)))
        return sig


# -- first approximation (T = 0 in (2)) -------------------------------------------------------
@dataclass(frozen=True)
class FirstApproximation:
    coef: Coefficients
    V0: float
    B11: float        # c V0/lambda
    Pm: float         # (8)
    t_Pm: float       # arctan(lambda/h)/lambda
    tau: float        # (7) pi/lambda
    Tm: float         # max |T1| on [0, tau] (signed value at that time)
    t_Tm: float

    def P(self, t):
        """(6): P1 = (c V0/lambda) exp(-h t) sin(lambda t)."""
        c, t = self.coef, np.asarray(t, dtype=float)
        return self.B11 * np.exp(-c.h * t) * np.sin(c.lam * t)

    def dP(self, t):
        c, t = self.coef, np.asarray(t, dtype=float)
        return self.B11 * np.exp(-c.h * t) * (c.lam * np.cos(c.lam * t) - c.h * np.sin(c.lam * t))

    def _T_terms(self):
        c = self.coef
        k1, lam, h = c.k1, c.lam, c.h
        H0 = (c.k1s + h * h - lam * lam) ** 2 + 4.0 * h * h * lam * lam
        g = c.a1 * self.B11 / H0
        return g, lam * (c.k2s - c.k1s) / k1, -2.0 * h * lam, c.k1s + h * h - lam * lam, \
            2.0 * h * lam

    def T(self, t):
        """(12): T1 = a1 B11/(H0 k1) [lambda (k2^2 - k1^2) sin k1 t - 2 h lambda k1 cos k1 t
        + k1 exp(-h t)((h^2 + k1^2 - lambda^2) sin lambda t + 2 h lambda cos lambda t)],
        H0 = (h^2 + k1^2 - lambda^2)^2 + 4 h^2 lambda^2. Pinned: T = (m r S/J - 1) P1."""
        t = np.asarray(t, dtype=float)
        c = self.coef
        if c.pinned:
            return self._pinned_ratio * self.P(t)
        g, A, B, C, D = self._T_terms()
        k1, lam, h = c.k1, c.lam, c.h
        return g * (A * np.sin(k1 * t) + B * np.cos(k1 * t)
                    + np.exp(-h * t) * (C * np.sin(lam * t) + D * np.cos(lam * t)))

    def dT(self, t):
        t = np.asarray(t, dtype=float)
        c = self.coef
        if c.pinned:
            return self._pinned_ratio * self.dP(t)
        g, A, B, C, D = self._T_terms()
        k1, lam, h = c.k1, c.lam, c.h
        return g * (A * k1 * np.cos(k1 * t) - B * k1 * np.sin(k1 * t)
                    + np.exp(-h * t) * ((-h * C - lam * D) * np.sin(lam * t)
                                        + (lam * C - h * D) * np.cos(lam * t)))

    _pinned_ratio: float = 0.0


def first_approximation(data: RockerData, c: float, c0: float) -> FirstApproximation:
    """P1 (6), tau (7), Pm (8) and T1 (12) with its largest |T1| over the impact [0, tau]."""
    coef = coefficients(data, c, c0)
    lam, h = coef.lam, coef.h
    B11 = c * data.V0 / lam
    t_Pm = math.atan2(lam, h) / lam
    Pm = c * data.V0 / coef.k2 * math.exp(-(h / lam) * math.atan2(lam, h))
    tau = math.pi / lam
    ratio = (data.m * data.r * data.S / data.J - 1.0) if coef.pinned else 0.0
    fa = FirstApproximation(coef, data.V0, B11, Pm, t_Pm, tau, 0.0, 0.0, _pinned_ratio=ratio)
    if coef.pinned:
        return replace(fa, Tm=ratio * Pm, t_Tm=t_Pm)
    n = _grid_size(max(coef.k1, lam), tau)
    t_Tm, Tm = extremum(Signal(lambda t: (fa.T(t), fa.dT(t))), 0.0, tau, n, absolute=True)
    return replace(fa, Tm=Tm, t_Tm=t_Tm)


# -- the paper's iterations -------------------------------------------------------------------
@dataclass(frozen=True)
class Linearisation:
    c: float
    c0: float                        # inf for the pinned rocker
    Pm: float                        # the converged peaks the stiffnesses were taken at
    Tm: float
    history_P: tuple[float, ...] = ()
    history_T: tuple[float, ...] = ()
    method: str = "first"


def _peaks(data, c, c0, method):
    if method == "first":
        fa = first_approximation(data, c, c0)
        return fa.Pm, abs(fa.Tm)
    ex = exact_linear(data, c, c0)
    return ex.Pm, abs(ex.Tm)


def linearise(data: RockerData, *, pinned: bool = False, method: str = "first",
              rtol: float = ITERATION_RTOL, P_guess: float = P_GUESS,
              T_guess_ratio: float = T_GUESS_RATIO, max_iter: int = 200,
              c0: float | None = None) -> Linearisation:
    """The paper's procedure: guess Pm, c = 1.25 K^(2/3) Pm^(1/3), Pm by (8), repeat until two
    cycles differ by less than rtol; then guess Tm, c0 = k_n Tm^(1/3), Tm = max |T1| on
    [0, tau] by (12), repeat likewise. method="exact" takes both peaks from the exact coupled
    solution instead (then the two iterations are coupled and run together).
    pinned=True: c0 = inf and only c is iterated (k2^2 = c S^2/J). A given c0 is kept (only c
    is iterated). At the centre of percussion (m r S = J) T vanishes and c0 = k_n Tm^(1/3) has
    no positive fixed point: the support iteration then raises AnalysisError (give c0)."""
    if method not in ("first", "exact"):
        raise ValueError(f"method must be 'first' or 'exact', not {method!r}")
    K = data.K
    Pm, hist_P = P_guess, [P_guess]
    Tm, hist_T = T_guess_ratio * P_guess, [T_guess_ratio * P_guess]
    if c0 is not None and not pinned and c0 <= 0.0:
        raise ValueError(f"c0 must be > 0, not {c0!r}")
    fixed_c0 = c0
    if pinned or method == "first" or fixed_c0 is not None:
        # contact iteration; in the first approximation Pm does not depend on c0
        if pinned:
            c0 = math.inf
        elif fixed_c0 is None:
            c0 = support_stiffness(data.k_n, Tm)
        for _ in range(max_iter):
            new_P = _peaks(data, linearised_contact_stiffness(K, Pm), c0, method)[0]
            hist_P.append(new_P)
            done = abs(new_P - Pm) < rtol * abs(new_P)
            Pm = new_P
            if done:
                break
        else:
            raise AnalysisError(f"contact stiffness iteration did not converge in {max_iter} "
                                f"cycles (Pm history {hist_P[-4:]})")
        c = linearised_contact_stiffness(K, Pm)
        if pinned or fixed_c0 is not None:
            assert c0 is not None  # inf when pinned, else the given one
            return Linearisation(c, c0, Pm, _peaks(data, c, c0, method)[1],
                                 tuple(hist_P), (), method)
        if data.m * data.r * data.S == data.J or data.eps < 1e-24:
            raise AnalysisError("centre of percussion (m r S = J): T = 0, so c0 = k_n Tm^(1/3) "
                                "has no positive fixed point; give c0 (c_support)")
        for _ in range(max_iter):
            new_T = _peaks(data, c, support_stiffness(data.k_n, Tm), method)[1]
            hist_T.append(new_T)
            done = abs(new_T - Tm) < rtol * new_T
            Tm = new_T
            if done:
                break
        else:
            raise AnalysisError(f"support stiffness iteration did not converge in {max_iter} "
                                f"cycles (Tm history {hist_T[-4:]})")
    else:
        # exact peaks depend on both stiffnesses: iterate them together
        for _ in range(max_iter):
            new_P, new_T = _peaks(data, linearised_contact_stiffness(K, Pm),
                                  support_stiffness(data.k_n, Tm), method)
            hist_P.append(new_P)
            hist_T.append(new_T)
            done = abs(new_P - Pm) < rtol * new_P and abs(new_T - Tm) < rtol * new_T
            Pm, Tm = new_P, new_T
            if done:
                break
        else:
            raise AnalysisError(f"coupled stiffness iteration did not converge in {max_iter} "
                                f"cycles (Pm {hist_P[-3:]}, Tm {hist_T[-3:]})")
        c = linearised_contact_stiffness(K, Pm)
    c0 = support_stiffness(data.k_n, Tm)
    return Linearisation(c, c0, Pm, Tm, tuple(hist_P), tuple(hist_T), method)


# -- exact coupled linear solution ----------------------------------------------------------
@dataclass(frozen=True)
class ImpactResult:
    Pm: float
    t_Pm: float
    tau: float       # P returns to zero
    Tm: float        # signed T at the largest |T| on [0, tau]
    t_Tm: float
    flow: LinearFlow | None = field(repr=False, default=None)

    def P(self, t):
        return self.flow(t)[..., 2]

    def T(self, t):
        return self.flow(t)[..., 0]


def exact_linear(data: RockerData, c: float, c0: float) -> ImpactResult:
    """The coupled linear system (1)-(2) solved exactly (matrix exponential) until P returns to
    zero. Pinned (c0 = inf): the 2nd-order P equation with T = (m r S/J - 1) P."""
    coef = coefficients(data, c, c0)
    if coef.pinned:
        A = np.array([[0.0, 1.0], [-coef.k2s, -2.0 * coef.h]])
        flow = LinearFlow(A, [0.0, c * data.V0])
        ratio = data.m * data.r * data.S / data.J - 1.0
        P = flow.signal(0, 1)
        tau = first_return_to_zero(P, math.pi / coef.lam, flow.omega_max)
        t_Pm, Pm = extremum(P, 0.0, tau, _grid_size(flow.omega_max, tau))
        A4 = np.zeros((4, 4))
        A4[2:, 2:] = A
        return ImpactResult(Pm, t_Pm, tau, ratio * Pm, t_Pm,
                            LinearFlow(A4, [0.0, 0.0, 0.0, c * data.V0]))
    flow = LinearFlow(coef.matrix(), [0.0, 0.0, 0.0, c * data.V0])
    tau = first_return_to_zero(flow.signal(2, 3), math.pi / coef.lam, flow.omega_max)
    n = _grid_size(flow.omega_max, tau)
    t_Pm, Pm = extremum(flow.signal(2, 3), 0.0, tau, n)
    t_Tm, Tm = extremum(flow.signal(0, 1), 0.0, tau, n, absolute=True)
    return ImpactResult(Pm, t_Pm, tau, Tm, t_Tm, flow)
