"""Exact integration of a first-order lag and of a damped oscillator driven by a polynomial, and
polynomial helpers.

A lag tau y' + y = F(s) with F a polynomial on [0, h] (the master's input polynomial through a
static law) has the closed form (variation of constants, z = -h/tau)

    y(h) = e^z y(0) - z sum_k a_k k! h^k phi_{k+1}(z),   F(s) = sum_k a_k s^k,

with the phi-functions phi_0(z) = e^z, phi_{k+1}(z) = (phi_k(z) - 1/k!)/z. It is exact for any
tau > 0: at tau = 1e-6 s and h = 1e-3 s (z = -1000) y follows F with the lag's delay, where an
explicit method would need thousands of steps and an implicit one a Newton iteration per step.
`DampedOscillator` is the second-order counterpart (u'' + 2 alpha u' + k^2 u = F(s)): exact over
any number of periods, where an explicit method must follow each one.
Polynomials are coefficient lists, lowest power first, in the time s since the step's start.
"""
from __future__ import annotations

import math
from typing import Sequence

from .roots import brentq

Poly = Sequence[float]


def phi_functions(z: float, count: int) -> list[float]:
    """[phi_1(z), ..., phi_count(z)] to round-off for z <= 0."""
    if abs(z) < 2.0:  # the recurrence cancels here: the series sum_j z^j/(j+k)!
        out = []
        for k in range(1, count + 1):
            term = 1.0 / math.factorial(k)
            total, j = term, 0
            while abs(term) > 1e-17 * abs(total):
                j += 1
                term *= z / (j + k)
                total += term
            out.append(total)
        return out
    out, previous = [], math.exp(z)
    for k in range(count):
        previous = (previous - 1.0 / math.factorial(k)) / z
        out.append(previous)
    return out


_WEIGHTS: dict = {}  # (h, tau) -> [e^z, -z k! h^k phi_{k+1}(z) ...]: fixed steps repeat them
MAX_FORCING_DEGREE = 6  # an input polynomial of degree 5 integrated once (a PI loop's integral)


def lag_step(y0: float, forcing: Poly, h: float, tau: float) -> float:
    """y(h) for tau y' + y = F(s), F(s) = sum_k forcing[k] s^k on [0, h] (degree <=
    MAX_FORCING_DEGREE)."""
    weights = _WEIGHTS.get((h, tau))
    if weights is None:
        z = -h / tau
        weights = [math.exp(z)] + [-z * math.factorial(k) * h ** k * phi
                                   for k, phi in enumerate(phi_functions(
                                       z, MAX_FORCING_DEGREE + 1))]
        if len(_WEIGHTS) > 1024:  # variable steps: keep the cache small
            _WEIGHTS.clear()
        _WEIGHTS[(h, tau)] = weights
    total = weights[0] * y0
    for a, weight in zip(forcing, weights[1:]):
        total += a * weight
    return total


def taylor_polynomial(rows: Sequence[Sequence[float]], index: int,
                      minus: int | None = None) -> list[float]:
    """The coefficients in s (lowest power first) of input `index` (minus input `minus`) over a
    step, from the inputs' Taylor rows at its start: rows[k][index] / k!."""
    out, factorial = [], 1.0
    for k, row in enumerate(rows):
        factorial *= max(k, 1)
        value = row[index] if minus is None else row[index] - row[minus]
        out.append(value if k < 2 else 0.5 * value if k == 2 else value / factorial)
    return out


def poly_value(c: Poly, s: float) -> float:
    total = 0.0
    for a in reversed(c):
        total = total * s + a
    return total


def poly_derivative(c: Poly) -> list[float]:
    return [k * a for k, a in enumerate(c)][1:]


def poly_integral(c: Poly) -> list[float]:
    return [0.0] + [a / (k + 1) for k, a in enumerate(c)]


def poly_shift(c: Poly, s0: float) -> list[float]:
    """Coefficients of c(s0 + sigma) in sigma (Taylor expansion at s0)."""
    if s0 == 0.0:
        return list(c)
    out, d, factorial = [], list(c), 1.0
    for k in range(len(c)):
        out.append(poly_value(d, s0) / factorial)
        d = poly_derivative(d)
        factorial *= k + 1
    return out


def poly_add(*polys: Poly, scales: Sequence[float] | None = None) -> list[float]:
    scales = scales or [1.0] * len(polys)
    out = [0.0] * max(len(p) for p in polys)
    for p, w in zip(polys, scales):
        for k, a in enumerate(p):
            out[k] += w * a
    return out


def sign_changes(f, a: float, b: float, samples: Sequence[float] = ()) -> list[float]:
    """The points in (a, b) where f changes sign, one per piece between a, b and the given
    interior points (exact when f is monotone on each piece, as a polynomial is between its
    critical points), in order."""
    points = sorted({a, b, *[s for s in samples if a < s < b]})
    values = [f(x) for x in points]
    roots = []
    for left, right, f_left, f_right in zip(points, points[1:], values, values[1:]):
        if f_left * f_right < 0.0:
            roots.append(brentq(f, left, right, xtol=1e-15, rtol=4.4e-16))
        elif f_right == 0.0 and right < b:
            roots.append(right)
    return roots


def poly_critical_points(c: Poly, a: float = -math.inf, b: float = math.inf) -> list[float]:
    """Real roots of c': the points that split c into monotone pieces. Degree <= 3: all of
    them, in closed form; higher degree: those in (a, b) (a finite interval), each found by
    Brent's method between the critical points of c' (recursively: c' is monotone between
    them, so each piece holds at most one root)."""
    d = poly_derivative(c)
    while d and d[-1] == 0.0:
        d.pop()
    if len(d) <= 1:
        return []
    if len(d) == 2:
        return [-d[0] / d[1]]
    if len(d) > 3:
        return sign_changes(lambda x: poly_value(d, x), a, b, poly_critical_points(d, a, b))
    a, b, cc = d[2], d[1], d[0]
    disc = b * b - 4 * a * cc
    if disc < 0.0:
        return []
    q = -0.5 * (b + math.copysign(math.sqrt(disc), b))
    roots = [q / a]
    if q != 0.0:
        roots.append(cc / q)
    return roots


def oscillator_particular(alpha: float, k2: float, forcing: Poly) -> list[float]:
    """The polynomial p with p'' + 2 alpha p' + k2 p = F (coefficients, lowest power first; at
    least two, so that p(0) and p'(0) are p[0] and p[1])."""
    p = [0.0] * (len(forcing) + 2)  # p[j] for j > deg F stay 0
    for j in range(len(forcing) - 1, -1, -1):
        p[j] = (forcing[j] - 2.0 * alpha * (j + 1) * p[j + 1] - (j + 2) * (j + 1) * p[j + 2]) / k2
    return p[:max(len(forcing), 2)]


class DampedOscillator:
    """u'' + 2 alpha u' + k2 u = F(s) on s >= 0 from u(0) = u0, u'(0) = v0, for a polynomial
    forcing F (coefficients, lowest power first) and an underdamped oscillator (k2 > alpha^2),
    in closed form:

        u(s) = p(s) + e^(-alpha s) (q0 cos(omega s) + (q1 + alpha q0) sin(omega s)/omega),

    omega = sqrt(k2 - alpha^2), p the polynomial particular solution (p'' + 2 alpha p' + k2 p = F,
    same degree as F), q0 = u0 - p(0), q1 = v0 - p'(0): the homogeneous part is the ringing,
    p follows the forcing. Exact for any s, however many periods: no step-size limit.
    negligible: a ringing whose amplitude is below it is left out (its trigonometry skipped)."""

    __slots__ = ("alpha", "k2", "omega", "forcing", "particular", "q0", "q1", "_b", "_c",
                 "rings")

    def __init__(self, alpha: float, k2: float, u0: float, v0: float, forcing: Poly,
                 negligible: float = 0.0):
        if not k2 > alpha * alpha:
            raise ValueError(f"not underdamped: k2 = {k2!r} <= alpha^2 = {alpha * alpha!r}")
        self.alpha, self.k2, self.omega = alpha, k2, math.sqrt(k2 - alpha * alpha)
        self.forcing = list(forcing)
        self.particular = p = oscillator_particular(alpha, k2, forcing)
        self.q0, self.q1 = u0 - p[0], v0 - p[1]
        self._b = self.q1 + alpha * self.q0      # u = e^(-alpha s) (q0 cos + _b sin/omega)
        self._c = k2 * self.q0 + alpha * self.q1  # u' = e^(-alpha s) (q1 cos - _c sin/omega)
        self.rings = self.ringing_bound(0.0) >= negligible
        if not self.rings:
            self.q0 = self.q1 = self._b = self._c = 0.0

    def ringing(self, s: float) -> tuple[float, float]:
        """(u, u') of the homogeneous part at s."""
        if not self.rings:
            return 0.0, 0.0
        decay = math.exp(-self.alpha * s)
        c, sn = decay * math.cos(self.omega * s), decay * math.sin(self.omega * s) / self.omega
        return self.q0 * c + self._b * sn, self.q1 * c - self._c * sn

    def ringing_integrals(self, s: float, u: float, v: float) -> tuple[float, float]:
        """(the ringing's u integrated over [0, s], and integrated twice), for its (u, u') = (u, v)
        at s: an antiderivative of a homogeneous solution y is the homogeneous solution
        Y = -(y' + 2 alpha y)/k2, and Y's is -(y + 2 alpha Y)/k2."""
        k2, two_alpha = self.k2, 2.0 * self.alpha
        once_0 = -(self.q1 + two_alpha * self.q0) / k2
        once = -(v + two_alpha * u) / k2
        return once - once_0, -(u + two_alpha * once - self.q0 - two_alpha * once_0) / k2 \
            - once_0 * s

    def forced(self, s: float) -> tuple[float, float]:
        """(p, p') at s: the part that follows the forcing."""
        p = self.particular
        if len(p) == 4:  # a cubic forcing, spelled out: the common case, and a hot path
            p0, p1, p2, p3 = p
            return p0 + s * (p1 + s * (p2 + s * p3)), p1 + s * (2.0 * p2 + s * 3.0 * p3)
        value = slope = 0.0
        for j in range(len(p) - 1, -1, -1):  # Horner for p and p'
            slope = slope * s + value
            value = value * s + p[j]
        return value, slope

    def state(self, s: float) -> tuple[float, float]:
        """(u, u') at s."""
        value, slope = self.forced(s)
        if not self.rings:
            return value, slope
        u, v = self.ringing(s)
        return value + u, slope + v

    def ringing_bound(self, s: float) -> float:
        """An upper bound of |u - p| on [s, infinity): the ringing's amplitude at s."""
        amplitude = math.hypot(self.q0, self._b / self.omega)
        return amplitude * math.exp(-self.alpha * s) if amplitude else 0.0

    def work(self, h: float) -> float:
        """The integral of F u' over [0, h]: for the polynomial part exactly; for the ringing
        by parts, each antiderivative of a homogeneous solution y being the homogeneous solution
        -(y' + 2 alpha y)/k2."""
        F, p = self.forcing, self.particular
        total = poly_value(poly_integral(_poly_product(F, poly_derivative(p))), h)
        if not self.rings:
            return total
        ends = (self.ringing(0.0), self.ringing(h))
        a, b = 0.0, 1.0  # the ringing's u' as a u_h + b u_h' (u_h: the ringing's u)
        derivative, sign = list(F), 1.0
        while derivative:
            a, b = b - 2.0 * self.alpha * a / self.k2, -a / self.k2  # one antiderivative
            (u_a, v_a), (u_b, v_b) = ends
            total += sign * (poly_value(derivative, h) * (a * u_b + b * v_b)
                             - derivative[0] * (a * u_a + b * v_a))
            derivative, sign = poly_derivative(derivative), -sign
        return total

    def damping_loss(self, h: float, end: tuple[float, float] | None = None) -> float:
        """The integral of 2 alpha u'^2 over [0, h] (per unit mass: the damper's dissipated
        energy over the mass), from the energy balance
        d/ds (u'^2/2 + k2 u^2/2) = F u' - 2 alpha u'^2. end: state(h), if at hand."""
        (u_a, v_a), (u_b, v_b) = self.state(0.0), end or self.state(h)
        return self.work(h) - 0.5 * (v_b * v_b - v_a * v_a + self.k2 * (u_b * u_b - u_a * u_a))


def _poly_product(a: Poly, b: Poly) -> list[float]:
    out = [0.0] * max(len(a) + len(b) - 1, 0)
    for i, x in enumerate(a):
        for j, y in enumerate(b):
            out[i + j] += x * y
    return out
