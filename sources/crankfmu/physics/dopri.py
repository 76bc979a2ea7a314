"""Dormand-Prince 5(4) on plain Python floats: the integrator that runs inside the FMUs.

Why not scipy's solve_ivp in every doStep: for the two or four states of a crankfmu model its
per-call setup (~160 us), its initial-step selection (2 extra right-hand-side calls per call) and
numpy arithmetic on tiny arrays cost 10-50x the physics. This integrator's cost is its
right-hand-side calls: vectors are lists of floats, the step size is carried from one doStep to
the next (`Integration.h_next`), and nothing is set up per call.

The method and its controls are those of scipy's RK45 (same tableau, error estimate, dense output
and step-size rule: SAFETY 0.9, factor in [0.2, 10], RMS error norm with atol + rtol max|y|), so
the two paths agree to the tolerance and scipy stays available as the cross-check (`solver =
"scipy"` in `PhysicsModel`). Events follow solve_ivp's semantics: functions g(t, x) with
attributes `terminal` and `direction`, sign changes found at step ends and located on the
4th-order dense output with Brent's method; the first terminal event ends the integration.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable, Sequence

from scipy.optimize import brentq

Vector = list  # list[float]

# Dormand-Prince 5(4) tableau, as in scipy.integrate.RK45
_C = (0.0, 1 / 5, 3 / 10, 4 / 5, 8 / 9, 1.0)
_A = ((),
      (1 / 5,),
      (3 / 40, 9 / 40),
      (44 / 45, -56 / 15, 32 / 9),
      (19372 / 6561, -25360 / 2187, 64448 / 6561, -212 / 729),
      (9017 / 3168, -355 / 33, 46732 / 5247, 49 / 176, -5103 / 18656))
_B = (35 / 384, 0.0, 500 / 1113, 125 / 192, -2187 / 6784, 11 / 84)
_E = (-71 / 57600, 0.0, 71 / 16695, -71 / 1920, 17253 / 339200, -22 / 525, 1 / 40)
_P = ((1.0, -8048581381 / 2820520608, 8663915743 / 2820520608, -12715105075 / 11282082432),
      (0.0, 0.0, 0.0, 0.0),
      (0.0, 131558114200 / 32700410799, -68118460800 / 10900136933,
       87487479700 / 32700410799),
      (0.0, -1754552775 / 470086768, 14199869525 / 1410260304, -10690763975 / 1880347072),
      (0.0, 127303824393 / 49829197408, -318862633887 / 49829197408,
       701980252875 / 199316789632),
      (0.0, -282668133 / 205662961, 2019193451 / 616988883, -1453857185 / 822651844),
      (0.0, 40617522 / 29380423, -110615467 / 29380423, 69997945 / 29380423))
SAFETY, MIN_FACTOR, MAX_FACTOR = 0.9, 0.2, 10.0
ERROR_EXPONENT = -1.0 / 5.0
EPS = 2.220446049250313e-16


class WorkLimitError(RuntimeError):
    """More right-hand-side calls than allowed, or a step size below round-off."""


@dataclass
class Integration:
    """Outcome of `integrate`: status 0 = reached t_end, 1 = stopped at a terminal event."""

    status: int
    t: float
    x: Vector
    h_next: float                      # the step size to start the next call with
    event: int | None = None           # index of the terminal event that stopped it
    crossings: list = field(default_factory=list)  # (index, t, x) of non-terminal events
    calls: int = 0                     # right-hand-side evaluations


def _rms(values: Sequence[float]) -> float:
    return math.sqrt(sum(v * v for v in values) / len(values))


def initial_step(f, t0: float, x0: Vector, f0: Vector, span: float, rtol: float, atol) -> float:
    """Hairer, Norsett & Wanner's starting step (Sec. II.4), as scipy's select_initial_step."""
    scale = [a + abs(v) * rtol for v, a in zip(x0, atol)]
    d0 = _rms([v / s for v, s in zip(x0, scale)])
    d1 = _rms([v / s for v, s in zip(f0, scale)])
    h0 = 1e-6 if d0 < 1e-5 or d1 < 1e-5 else 0.01 * d0 / d1
    h0 = min(h0, span)
    x1 = [v + h0 * d for v, d in zip(x0, f0)]
    f1 = f(t0 + h0, x1)
    d2 = _rms([(b - a) / s for a, b, s in zip(f0, f1, scale)]) / h0
    if d1 <= 1e-15 and d2 <= 1e-15:
        h1 = max(1e-6, h0 * 1e-3)
    else:
        h1 = (0.01 / max(d1, d2)) ** 0.2
    return min(100 * h0, h1, span)


class _Step:
    """One accepted step: its endpoints and stages, for dense output between them (the
    interpolant's coefficients are formed on first use: most steps locate no event)."""

    __slots__ = ("t0", "h", "x0", "stages", "q")

    def __init__(self, t0: float, h: float, x0: Vector, stages: list):
        self.t0, self.h, self.x0, self.stages, self.q = t0, h, x0, stages, None

    def __call__(self, t: float) -> Vector:
        if self.q is None:  # q[i][j] = sum_k K[k][i] P[k][j]
            k = self.stages
            self.q = [[sum(k[m][i] * _P[m][j] for m in range(7) if _P[m][j]) for j in range(4)]
                      for i in range(len(self.x0))]
        s = (t - self.t0) / self.h
        h = self.h
        return [x + h * s * (q0 + s * (q1 + s * (q2 + s * q3)))
                for x, (q0, q1, q2, q3) in zip(self.x0, self.q)]


_A21 = _A[1][0]
_A31, _A32 = _A[2]
_A41, _A42, _A43 = _A[3]
_A51, _A52, _A53, _A54 = _A[4]
_A61, _A62, _A63, _A64, _A65 = _A[5]
_B1, _, _B3, _B4, _B5, _B6 = _B
_E1, _, _E3, _E4, _E5, _E6, _E7 = _E


def _attempt(f, t: float, x: Vector, k1: Vector, h: float):
    """The six stages and the fifth-order solution of one Dormand-Prince step (unrolled: for a
    few states, Python's loops and generator sums would cost more than the arithmetic)."""
    k2 = f(t + _C[1] * h, [a + h * _A21 * b for a, b in zip(x, k1)])
    k3 = f(t + _C[2] * h, [a + h * (_A31 * b + _A32 * c) for a, b, c in zip(x, k1, k2)])
    k4 = f(t + _C[3] * h, [a + h * (_A41 * b + _A42 * c + _A43 * d)
                           for a, b, c, d in zip(x, k1, k2, k3)])
    k5 = f(t + _C[4] * h, [a + h * (_A51 * b + _A52 * c + _A53 * d + _A54 * e)
                           for a, b, c, d, e in zip(x, k1, k2, k3, k4)])
    k6 = f(t + h, [a + h * (_A61 * b + _A62 * c + _A63 * d + _A64 * e + _A65 * g)
                   for a, b, c, d, e, g in zip(x, k1, k2, k3, k4, k5)])
    x_new = [a + h * (_B1 * b + _B3 * d + _B4 * e + _B5 * g + _B6 * k)
             for a, b, d, e, g, k in zip(x, k1, k3, k4, k5, k6)]
    return [k1, k2, k3, k4, k5, k6], x_new


def integrate(f: Callable[[float, Vector], Sequence[float]], t0: float, x0: Sequence[float],
              t_end: float, rtol: float, atol: Sequence[float] | float, h_start: float | None = None,
              events: Sequence[Callable] = (), max_calls: int = 200_000) -> Integration:
    """Integrate x' = f(t, x) from t0 to t_end (> t0).

    h_start: the step to try first (the previous call's `h_next`); None selects one as scipy
    does. atol: per state, or one for all. events: g(t, x) with optional attributes `terminal` (bool) and
    `direction` (-1, 0, +1). Raises WorkLimitError past max_calls right-hand-side evaluations.
    """
    x = [float(v) for v in x0]
    atol = [float(atol)] * len(x) if isinstance(atol, (int, float)) else list(atol)
    calls = 0

    def rhs(t, y):
        nonlocal calls
        calls += 1
        if calls > max_calls:
            raise WorkLimitError(f"more than {max_calls} derivative evaluations between "
                                 f"t = {t0:.9g} s and {t_end:.9g} s (states {y}): diverging "
                                 "or too stiff")
        return f(t, y)

    t = float(t0)
    k1 = list(rhs(t, x))
    h = h_start if h_start and h_start > 0.0 else initial_step(rhs, t, x, k1, t_end - t,
                                                               rtol, atol)
    h_next = h
    g_old = [g(t, x) for g in events]
    crossings = []
    rejected = False
    while t < t_end:
        min_h = 10.0 * EPS * max(abs(t), 1e-300)
        if h < min_h:
            raise WorkLimitError(f"step size {h:.3g} s below round-off at t = {t:.9g} s")
        h_try = min(h, t_end - t)
        last = h_try >= t_end - t
        stages, x_new = _attempt(rhs, t, x, k1, h_try)
        t_new = t_end if last else t + h_try
        k7 = list(rhs(t_new, x_new))
        stages.append(k7)
        err = _error_norm(stages, h_try, x, x_new, rtol, atol)
        if err >= 1.0:
            h = h_try * max(MIN_FACTOR, SAFETY * err ** ERROR_EXPONENT)
            rejected = True
            continue
        factor = MAX_FACTOR if err == 0.0 else min(MAX_FACTOR, SAFETY * err ** ERROR_EXPONENT)
        if rejected:
            factor = min(1.0, factor)
        rejected = False
        # a step cut short by t_end says nothing about the step size the problem allows
        h_next = h * factor if not last or h_try >= h else max(h, h_try * factor)
        h = h_next
        if events:
            step = _Step(t, h_try, x, stages)
            g_new = [g(t_new, x_new) for g in events]
            hit = _locate(events, g_old, g_new, t, t_new, step, crossings)
            if hit is not None:  # step again to the event: the 5th-order solution there,
                index, te = hit  # not the 4th-order dense output, which the error test skips
                x_event = _attempt(rhs, t, x, k1, te - t)[1] if te > t else x
                return Integration(1, te, x_event, h_next, index, crossings, calls)
            g_old = g_new
        t, x, k1 = t_new, x_new, k7
    return Integration(0, t, x, h_next, None, crossings, calls)


def _error_norm(stages, h, x, x_new, rtol, atol) -> float:
    """RMS of the embedded error estimate scaled by atol + rtol max(|x|, |x_new|)."""
    k1, _, k3, k4, k5, k6, k7 = stages
    total = 0.0
    for a, b, tol, c1, c3, c4, c5, c6, c7 in zip(x, x_new, atol, k1, k3, k4, k5, k6, k7):
        e = h * (_E1 * c1 + _E3 * c3 + _E4 * c4 + _E5 * c5 + _E6 * c6 + _E7 * c7)
        scale = tol + rtol * max(abs(a), abs(b))
        total += (e / scale) ** 2
    return math.sqrt(total / len(x)) if x else 0.0


def _locate(events, g_old, g_new, t_old, t_new, step: _Step, crossings: list):
    """Roots of the events that changed sign over the step, in time order (solve_ivp's rule:
    a zero at either end counts). Non-terminal ones are recorded up to the first terminal one,
    whose (index, time) is returned."""
    roots = []
    for i, (g, a, b) in enumerate(zip(events, g_old, g_new)):
        direction = getattr(g, "direction", 0)
        up, down = a <= 0.0 <= b, a >= 0.0 >= b
        if not ((up and direction >= 0) or (down and direction <= 0)):
            continue
        if a == 0.0:
            te = t_old
        elif b == 0.0:
            te = t_new
        else:
            te = brentq(lambda s, g=g: g(s, step(s)), t_old, t_new, xtol=4 * EPS, rtol=4 * EPS)
        roots.append((te, i))
    for te, i in sorted(roots):
        if getattr(events[i], "terminal", False):
            return i, te
        crossings.append((i, te, step(te)))
    return None
