"""Taylor rows: the input polynomials an FMU steps with, and the time derivatives at a
communication point from a model's own equations, the rows behind the output-derivative
companions `<output>_d1`, `_d2`, ... (docs/architecture.md, "Output derivatives").

Rows are Taylor rows: rows[k] is the k-th time derivative at t, a list of floats. An
`InputPolynomial` is the inputs over a step, given by their rows at its start.

States. With x' = f(t, x, u(t)) and the inputs u a polynomial (the rows the master wrote), the
state's derivatives follow from f alone:

    x^(k+1)(t) = d^k/ds^k f(t + s, X(s), U(s)) at s = 0,

where X is the state's Taylor polynomial to degree k (its terms of higher degree do not reach the
k-th derivative at s = 0) and U the inputs' polynomial. So order k + 1 is a k-th difference of
f along the polynomials: forward (s >= 0, the side the next step integrates, so a kink just
behind t is not seen) on the k + 1 nodes s = 0, delta, ..., k delta. No second copy of the
equations: only derivatives() is called (k new calls for order k + 1, 1 + 1 + 2 + 3 = 7 for the
4th derivative). The differences are taken of f(s) - f(0) (the weights sum to 0): a constant
right-hand side or output gives rows of exact zeros, not round-off over delta^k.

The node spacing delta is DIFFERENCE_FRACTION x the communication step h: the rows serve a
polynomial over [t, t + h], whose term of degree k + 1 then carries a difference error of about
(k/2) delta/T relative to it (T: the time scale of the motion; at most 1e-3 where the step
resolves the motion) and a round-off of about 2^k eps (h/delta)^k / (k + 1)! of the step's change
|x'| h (7e-8 for k = 3, the 4th derivative), whatever h is.

Outputs. An output that is affine in the state and the inputs (and does not depend on time
itself), y = g(x, u) = g(0, 0) + C x + D u, has the exact rows y^(k) = C x^(k) + D u^(k); C and D
are read off output_values() once, at the unit vectors (`AffineOutputs`). Any other output is
differenced along the polynomials as the states are.
"""
from __future__ import annotations

import functools
import math
from typing import Callable, Sequence

DIFFERENCE_FRACTION = 1e-3  # node spacing of the differences, x the communication step
Rows = list  # list[list[float]]
INVERSE_FACTORIALS = tuple(1.0 / math.factorial(k) for k in range(12))


class InputPolynomial:
    """u(t) = sum_k rows[k] (t - t0)^k / k! on plain floats: the input as the master
    extrapolates it over a step, from its Taylor rows at t0 (rows[0] = u, rows[k] = the k-th
    time derivative; at most MAX_INPUT_DEGREE). Closed-form models read the rows (`taylor`).
    u and the derivative rows: lists of floats (taken as they are: the adapter calls this in
    every doStep); None or missing rows are zero. Rows beyond the second that are all zero are
    dropped, so a quadratic is evaluated with the same float operations whatever rows the
    host wrote."""

    __slots__ = ("t0", "u", "derivatives", "_quadratic", "_high", "moving")
    _quadratic: tuple[list, list] | None

    def __init__(self, t0: float, u: list, *derivatives):
        self.t0, self.u = t0, u
        rows = [d if d is not None else [0.0] * len(u) for d in derivatives]
        rows += [[0.0] * len(u)] * (2 - len(rows))
        while len(rows) > 2 and not any(rows[-1]):
            rows.pop()
        self.derivatives = rows  # [u', u'', ...] at t0, at least two rows
        self.moving = any(map(any, rows))
        if self.moving and len(rows) == 2:  # u + s (u' + s u''/2)
            self._quadratic = (rows[0], [0.5 * v for v in rows[1]])
        elif self.moving:  # degree > 2: per moving input, rows[k]/k! highest degree first
            self._quadratic = None
            inverse = INVERSE_FACTORIALS[1:len(rows) + 1]
            self._high = [(i, [row[i] * f for row, f in zip(rows, inverse)][::-1])
                          for i in range(len(u)) if any(row[i] for row in rows)]

    def __call__(self, t: float) -> list:
        if not self.moving:
            return self.u
        s = t - self.t0
        if self._quadratic is not None:
            d1, half_d2 = self._quadratic
            return [a + s * (b + s * c) for a, b, c in zip(self.u, d1, half_d2)]
        out = list(self.u)
        for i, coefficients in self._high:  # only the inputs that move (Horner)
            total = 0.0
            for c in coefficients:
                total = c + s * total
            out[i] += s * total
        return out

    @property
    def d1(self) -> list:
        return self.derivatives[0]

    @property
    def d2(self) -> list:
        return self.derivatives[1]

    def taylor(self, t: float) -> list[list]:
        """[u, u', u'', ...] at t: the rows of the same polynomial, moved from t0 to t (at least
        three rows)."""
        return [self(t)] + self.shifted(t - self.t0)

    def shifted(self, s: float) -> list[list]:
        """[u', u'', ...] at t0 + s."""
        return moved_rows(self.derivatives, s)


def moved_rows(rows: Rows, s: float) -> Rows:
    """The Taylor rows of the same polynomial at s: row k is sum_j rows[k + j] s^j / j! (by
    Horner; the rows of a quadratic moved as d1 + s d2, d2)."""
    moved = []
    for k in range(len(rows)):
        out = rows[-1]
        for j in range(len(rows) - 2, k - 1, -1):
            c = s / (j - k + 1)
            out = [a + c * b for a, b in zip(rows[j], out)]
        moved.append(out)
    return moved



@functools.lru_cache(maxsize=None)
def forward_weights(order: int, nodes: int) -> tuple[float, ...]:
    """Weights w_j such that sum_j w_j g(j delta) / delta^order is the order-th derivative of
    g at 0 (the derivative of the polynomial interpolating g at j = 0 .. nodes - 1), exact for
    polynomials of degree < nodes. From the Lagrange basis, in exact fractions (made when an
    order is first asked for: the fractions for every order cost 3 ms, in every FMU's start)."""
    from fractions import Fraction

    weights = []
    for j in range(nodes):
        poly = [Fraction(1)]  # prod_{m != j} (s - m) / (j - m), lowest power first
        for m in range(nodes):
            if m != j:
                scale = Fraction(1, j - m)
                poly = [scale * (b - m * a) for a, b in zip(poly + [Fraction(0)],
                                                            [Fraction(0)] + poly)]
        factorial = 1
        for q in range(2, order + 1):
            factorial *= q
        weights.append(float(poly[order] * factorial))
    return tuple(weights)


def polynomial_value(rows: Sequence[Sequence[float]], s: float) -> list[float]:
    """sum_k rows[k] s^k / k! (Horner)."""
    top = len(rows) - 1
    out = list(rows[top])
    for k in range(top - 1, -1, -1):
        c = s / (k + 1)
        out = [a + c * b for a, b in zip(rows[k], out)]
    return out


def state_rows(f: Callable, t: float, x: Sequence[float], u_rows: Rows, order: int,
               delta: float, known: Sequence = ()) -> Rows:
    """[x, x', ..., x^(order)] at t for x' = f(t, x, u), the inputs following the Taylor rows
    u_rows. `known`: leading rows already found for this x with the same leading input rows
    (row k + 1 depends on the input rows 0 .. k only), reused; the rows do not depend on
    whether they were."""
    rows = [list(r) for r in known[:order + 1]] or [list(x)]
    if len(rows) > order:
        return rows
    u = InputPolynomial(t, list(u_rows[0]), *u_rows[1:])
    if len(rows) < 2:
        rows.append(list(f(t, rows[0], u(t))))
    for k in range(len(rows) - 1, order):  # rows[k + 1]: the k-th difference of f
        weights, at_zero = forward_weights(k, k + 1), rows[1]  # the k-th difference
        total = [0.0] * len(at_zero)
        for j in range(1, k + 1):
            s = j * delta
            xs, c = rows[0], 1.0  # X(s) = sum_m rows[m] s^m / m!, m <= k
            for m in range(1, k + 1):
                c *= s / m
                xs = [a + c * b for a, b in zip(xs, rows[m])]
            w = weights[j]  # on f(s) - f(0): the weights sum to 0, so a constant gives 0
            total = [a + w * (v - v0) for a, v, v0 in zip(total, f(t + s, xs, u(t + s)),
                                                          at_zero)]
        scale = delta ** -k
        rows.append([scale * v for v in total])
    return rows


class AffineOutputs:
    """y = g(0, 0) + C x + D u for the outputs at `indices` of output_values(t, x, u), affine in
    x and u: the nonzero entries of C and D, read off at the unit vectors."""

    def __init__(self, output_values: Callable, t: float, n_x: int, n_u: int,
                 indices: Sequence[int]):
        base = output_values(t, [0.0] * n_x, [0.0] * n_u)
        # per output: (0 = state | 1 = input, index, coef)
        self.terms: list[list] = [[] for _ in indices]
        for kind, n in ((0, n_x), (1, n_u)):
            for j in range(n):
                unit = [0.0] * n
                unit[j] = 1.0
                y = output_values(t, unit, [0.0] * n_u) if kind == 0 else \
                    output_values(t, [0.0] * n_x, unit)
                for terms, i in zip(self.terms, indices):
                    if y[i] != base[i]:
                        terms.append((kind, j, float(y[i] - base[i])))

    def rows(self, x_rows: Rows, u_rows: Rows, order: int) -> Rows:
        """[y', ..., y^(order)]: C x^(k) + D u^(k) (input rows beyond u_rows are 0)."""
        out = []
        for k in range(1, order + 1):
            sources: tuple = (x_rows[k], u_rows[k] if k < len(u_rows) else None)
            out.append([sum(c * sources[kind][j] for kind, j, c in terms
                            if sources[kind] is not None) for terms in self.terms])
        return out


def output_rows(output_values: Callable, t: float, x_rows: Rows, u_rows: Rows, order: int,
                delta: float, indices: Sequence[int]) -> Rows:
    """[y', ..., y^(order)] of the outputs at `indices` of output_values(t, x, u), differenced
    along the state rows x_rows (at least order + 1 of them) and the input rows u_rows."""
    nodes = order + 1  # as for the states: error O(delta) in the highest derivative
    values = []
    u = InputPolynomial(t, list(u_rows[0]), *u_rows[1:])
    for j in range(nodes):
        s = j * delta
        y = output_values(t + s, polynomial_value(x_rows[:order + 1], s), u(t + s))
        values.append([y[i] for i in indices])
    first = values[0]  # on y(s) - y(0), as for the states: a constant output gives 0
    out = []
    for k in range(1, order + 1):
        weights, scale = forward_weights(k, nodes), delta ** -k
        out.append([scale * sum(w * (v[i] - first[i]) for w, v in zip(weights[1:], values[1:]))
                    for i in range(len(indices))])
    return out
