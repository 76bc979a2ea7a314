"""Input history and extrapolation: the last communication points and the Taylor rows
(value, 1st, 2nd derivative at a step's start) of the polynomials through them. A part the
master base composes; testable alone (tests/test_master_parts.py)."""
from __future__ import annotations

import numpy as np

HISTORY_DEPTH = 3     # communication points kept: enough for a quadratic


def taylor_rows(s, values) -> np.ndarray:
    """Taylor rows at s = 0 (value, 1st, 2nd derivative) of the polynomial through the points
    (s[i], values[i]) (1 to 3 points; put the point nearest 0 first). Newton's divided
    differences, in Python floats: for a few values per component cheaper than numpy (a
    Vandermonde solve cost more than the rest of a step). Built on differences, the rows of a
    constant signal are exact (derivatives exactly 0: an FMU sees it held), and the value row
    is values[0] exactly when s[0] = 0."""
    if len(s) == 1:
        return np.array([values[0]], dtype=float)
    columns = zip(*[v if type(v) is list else v.tolist() if type(v) is np.ndarray
                    else np.asarray(v).tolist() for v in values])
    if len(s) == 2:
        x0, x1 = s
        a = 1.0 / (x1 - x0)
        r0, r1 = [], []
        for p, q in columns:
            f01 = a * (q - p)
            r0.append(p - x0 * f01)
            r1.append(f01)
        return np.array([r0, r1]) if r0 else np.zeros((2, 0))
    x0, x1, x2 = s
    a, b, c = 1.0 / (x1 - x0), 1.0 / (x2 - x1), 1.0 / (x2 - x0)
    r0, r1, r2 = [], [], []
    for p, q, r in columns:  # p(s) = p + f01 (s - x0) + f012 (s - x0)(s - x1)
        f01 = a * (q - p)
        f012 = c * (b * (r - q) - f01)
        r0.append(p - x0 * f01 + x0 * x1 * f012)
        r1.append(f01 - (x0 + x1) * f012)
        r2.append(2.0 * f012)
    return np.array([r0, r1, r2]) if r0 else np.zeros((3, 0))


def evaluate(rows: np.ndarray, s: float) -> np.ndarray:
    """The polynomial given by Taylor rows, at s after their origin."""
    out = rows[0].copy()
    if len(rows) > 1:
        out += rows[1] * s
    if len(rows) > 2:
        out += rows[2] * (0.5 * s * s)
    return out


class History:
    """The last communication points: times and each component's connected outputs."""

    def __init__(self, depth: int = HISTORY_DEPTH):
        self.depth = depth
        self.times: list[float] = []
        self.values: list[dict[str, np.ndarray]] = []
        self.floats: list[dict[str, list]] = []  # the same values as lists, made when first read

    def push(self, t: float, outputs: dict[str, np.ndarray]) -> None:
        """Keep the arrays themselves: System.refresh_outputs makes a new one per read."""
        self.times.append(t)
        self.values.append(dict(outputs))
        self.floats.append({})
        if len(self.times) > self.depth:
            del self.times[0], self.values[0], self.floats[0]

    def _floats(self, i: int, comp: str) -> list:
        """Point i's values of comp as Python floats (a point serves up to three steps'
        polynomials: converted once)."""
        cache = self.floats[i]
        found = cache.get(comp)
        if found is None:
            found = cache[comp] = self.values[i][comp].tolist()
        return found

    def rows(self, comp: str, t: float, order: int, newest=None) -> np.ndarray:
        """Taylor rows at t of comp's outputs: the polynomial through the last order + 1 points
        (fewer at the start of a run); `newest` = (t_new, values) is a point after t that comes
        first (interpolation)."""
        if order == 0:  # the common case, kept cheap: hold the newest value
            return (newest[1] if newest is not None else self.values[-1][comp])[None, :]
        k = min(order + (newest is None), len(self.times))  # points taken from the history
        # Newton order: the point at t (the newest in the history) first, then t + h if given
        times = self.times[-1:-k - 1:-1]
        values = [self._floats(i, comp) for i in range(-1, -k - 1, -1)]
        if newest is not None:
            times.insert(1, newest[0])
            values.insert(1, newest[1])
        return taylor_rows([x - t for x in times], values)


class Coefficients(dict):
    """Taylor rows at t of each component's connected outputs, computed when first read (a
    Gauss-Seidel sweep never reads the first component's extrapolation or the last one's
    interpolation)."""

    def __init__(self, history: History, t: float, order: int, newest: dict | None = None):
        super().__init__()
        self.history, self.t, self.order = history, t, order
        self.newest = dict(newest) if newest else {}

    def __missing__(self, comp: str) -> np.ndarray:
        rows = self[comp] = self.history.rows(comp, self.t, self.order, self.newest.get(comp))
        return rows

    def reached(self, comp: str, t_new: float, values: np.ndarray) -> None:
        """comp is at t_new with `values`: from now on its rows interpolate through that point."""
        self.newest[comp] = (t_new, values)
        self.pop(comp, None)
