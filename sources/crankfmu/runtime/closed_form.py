"""Exact integration of a first-order lag driven by a polynomial, and polynomial helpers.

A lag tau y' + y = F(s) with F a polynomial on [0, h] (the master's input polynomial through a
static law) has the closed form (variation of constants, z = -h/tau)

    y(h) = e^z y(0) - z sum_k a_k k! h^k phi_{k+1}(z),   F(s) = sum_k a_k s^k,

with the phi-functions phi_0(z) = e^z, phi_{k+1}(z) = (phi_k(z) - 1/k!)/z. It is exact for any
tau > 0: at tau = 1e-6 s and h = 1e-3 s (z = -1000) y follows F with the lag's delay, where an
explicit method would need thousands of steps and an implicit one a Newton iteration per step.
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


def lag_step(y0: float, forcing: Poly, h: float, tau: float) -> float:
    """y(h) for tau y' + y = F(s), F(s) = sum_k forcing[k] s^k on [0, h] (degree <= 3)."""
    weights = _WEIGHTS.get((h, tau))
    if weights is None:
        z = -h / tau
        weights = [math.exp(z)] + [-z * math.factorial(k) * h ** k * phi
                                   for k, phi in enumerate(phi_functions(z, 4))]
        if len(_WEIGHTS) > 1024:  # variable steps: keep the cache small
            _WEIGHTS.clear()
        _WEIGHTS[(h, tau)] = weights
    total = weights[0] * y0
    for a, weight in zip(forcing, weights[1:]):
        total += a * weight
    return total


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


def poly_critical_points(c: Poly) -> list[float]:
    """Real roots of c' for degree <= 3 (closed form): the points that split c into monotone
    pieces."""
    d = poly_derivative(c)
    while d and d[-1] == 0.0:
        d.pop()
    if len(d) <= 1:
        return []
    if len(d) == 2:
        return [-d[0] / d[1]]
    a, b, cc = d[2], d[1], d[0]
    disc = b * b - 4 * a * cc
    if disc < 0.0:
        return []
    q = -0.5 * (b + math.copysign(math.sqrt(disc), b))
    roots = [q / a]
    if q != 0.0:
        roots.append(cc / q)
    return roots
