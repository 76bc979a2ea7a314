"""Input history and extrapolation: the last communication points and the Taylor rows
(value, 1st, 2nd derivative at a step's start) of the polynomials through them. A part the
master base composes; testable alone (tests/test_master_contract.py).

Everything here is Python floats: a component has a few connected outputs, and numpy's cost per
call (array creation, ufunc dispatch) was larger than the arithmetic on them. Taylor rows are a
list of rows (value row first), each a sequence of floats, one entry per signal.
"""
from __future__ import annotations

from collections import deque

HISTORY_DEPTH = 3     # communication points kept: enough for a quadratic


def taylor_rows(s, values) -> list[list[float]]:
    """Taylor rows at s = 0 (value, 1st, 2nd derivative) of the polynomial through the points
    (s[i], values[i]) (1 to 3 points; put the point nearest 0 first). Newton's divided
    differences (a Vandermonde solve cost more than the rest of a step). Built on differences,
    the rows of a constant signal are exact (derivatives exactly 0: an FMU sees it held), and
    the value row is values[0] exactly when s[0] = 0."""
    if len(s) == 1:
        return [_floats(values[0])]
    return (_line if len(s) == 2 else _parabola)(*s, *map(_floats, values))


def _line(x0: float, x1: float, p_values: list, q_values: list) -> list[list[float]]:
    """taylor_rows through two points: p(s) = p + f01 (s - x0)."""
    return _LINES[len(p_values)](x0, x1, p_values, q_values)


def _parabola(x0: float, x1: float, x2: float, p_values: list, q_values: list,
              r_values: list) -> list[list[float]]:
    """taylor_rows through three points: p(s) = p + f01 (s - x0) + f012 (s - x0)(s - x1)."""
    return _PARABOLAS[len(p_values)](x0, x1, x2, p_values, q_values, r_values)


class _NewtonForms(dict):
    """signal count n -> the Newton form for n signals, generated on first use with every
    signal spelled out (as runtime/dopri.stepper): a loop over zip() with three appends per
    signal cost more than the arithmetic, and these run for every source in every step. Per
    signal the operations and their order are those of the formulas in the docstrings."""

    def __init__(self, points: int):
        super().__init__()
        self.points = points

    def __missing__(self, n: int):
        form = self[n] = _newton_form(self.points, n)
        return form


def _newton_form(points: int, n: int):
    def unpack(name: str, letter: str) -> str:
        names = ", ".join(f"{letter}{i}" for i in range(n))
        return f"    {names}{',' if n == 1 else ''} = {name}" if n else ""

    def row(term: str) -> str:
        return "[" + ", ".join(term.format(i=i) for i in range(n)) + "]"
    if points == 2:
        lines = ["def line(x0, x1, P, Q):", "    a = 1.0 / (x1 - x0)",
                 unpack("P", "p"), unpack("Q", "q")]
        lines += [f"    f{i} = a * (q{i} - p{i})" for i in range(n)]
        lines.append(f"    return [{row('p{i} - x0 * f{i}')}, {row('f{i}')}]")
    else:
        lines = ["def parabola(x0, x1, x2, P, Q, R):",
                 "    a, b, c = 1.0 / (x1 - x0), 1.0 / (x2 - x1), 1.0 / (x2 - x0)",
                 "    x0x1, x01 = x0 * x1, x0 + x1",
                 unpack("P", "p"), unpack("Q", "q"), unpack("R", "r")]
        for i in range(n):
            lines += [f"    f{i} = a * (q{i} - p{i})", f"    g{i} = c * (b * (r{i} - q{i}) - f{i})"]
        lines.append(f"    return [{row('p{i} - x0 * f{i} + x0x1 * g{i}')}, "
                     f"{row('f{i} - x01 * g{i}')}, {row('2.0 * g{i}')}]")
    namespace: dict = {}
    exec("\n".join(lines), namespace)  # noqa: S102 - source built above, from n alone
    return namespace["line" if points == 2 else "parabola"]


_LINES, _PARABOLAS = _NewtonForms(2), _NewtonForms(3)


def _floats(values) -> list:
    """A point's values as a list of Python floats (a numpy array, e.g. the iterative master's
    iterate, is converted; a list is taken as it is)."""
    return values if type(values) is list else values.tolist() if hasattr(values, "tolist") \
        else list(values)


def evaluate(rows, s: float) -> list[float]:
    """The polynomial given by Taylor rows, at s after their origin (a row given as it is when
    there is only the value row)."""
    if len(rows) == 1:
        return rows[0]
    if len(rows) == 2:
        return [a + b * s for a, b in zip(rows[0], rows[1])]
    c = 0.5 * s * s
    out = [a + b * s + d * c for a, b, d in zip(rows[0], rows[1], rows[2])]
    for k in range(3, len(rows)):  # a Taylor coupling's higher rows
        c *= s / k
        out = [a + d * c for a, d in zip(out, rows[k])]
    return out


class History:
    """The last communication points: times and each component's connected outputs (the
    newest last; deques that drop the oldest point themselves)."""

    def __init__(self, depth: int = HISTORY_DEPTH):
        self.depth = depth
        self.times: deque[float] = deque(maxlen=depth)
        self.values: deque[dict[str, list[float]]] = deque(maxlen=depth)

    def push(self, t: float, outputs: dict) -> None:
        """Keep the value lists themselves: System.refresh_outputs makes a new one per read and
        none is ever changed in place."""
        self.times.append(t)
        self.values.append(outputs.copy())

    def rows(self, comp: str, t: float, order: int, newest=None) -> list:
        """Taylor rows at t of comp's outputs: the polynomial through the last order + 1 points
        (fewer at the start of a run); `newest` = (t_new, values) is a point after t that comes
        second, after the point at t (interpolation). Called for every source in every step:
        the points go to the Newton forms directly."""
        if order == 0:  # the common case, kept cheap: hold the newest value
            return [newest[1] if newest is not None else self.values[-1][comp]]
        times, values = self.times, self.values
        k = min(order + (newest is None), len(times))  # points taken from the history
        if newest is None:
            newest_values = values[-1][comp]
            if k == 1:
                return [newest_values]
            if k == 2:
                return _LINES[len(newest_values)](times[-1] - t, times[-2] - t, newest_values,
                                                  values[-2][comp])
            return _PARABOLAS[len(newest_values)](times[-1] - t, times[-2] - t, times[-3] - t,
                                                  newest_values, values[-2][comp],
                                                  values[-3][comp])
        t_new, new = newest
        if type(new) is not list:
            new = _floats(new)
        if k == 1:
            return _LINES[len(new)](times[-1] - t, t_new - t, values[-1][comp], new)
        return _PARABOLAS[len(new)](times[-1] - t, t_new - t, times[-2] - t, values[-1][comp],
                                    new, values[-2][comp])


class Coefficients(dict):
    """Taylor rows at t of each component's connected outputs, computed when first read (a
    Gauss-Seidel sweep never reads the first component's extrapolation or the last one's
    interpolation)."""

    __slots__ = ("history", "t", "order", "newest")

    def __init__(self, history: History, t: float, order: int, newest: dict | None = None):
        self.history, self.t, self.order = history, t, order
        self.newest = dict(newest) if newest else {}
        if order == 0:  # every row is a held value, cheaper made at once
            for comp, values in history.values[-1].items():
                self[comp] = [values]
            if newest:
                for comp, (_, values) in newest.items():
                    self[comp] = [values]

    def __missing__(self, comp: str) -> list:
        rows = self[comp] = self.history.rows(comp, self.t, self.order, self.newest.get(comp))
        return rows

    def reached(self, comp: str, t_new: float, values) -> None:
        """comp is at t_new with `values`: from now on its rows interpolate through that point
        (at order 0 they are that point's values, held: set at once)."""
        if self.order == 0:
            self[comp] = [values]
        else:
            self.newest[comp] = (t_new, values)
            self.pop(comp, None)
