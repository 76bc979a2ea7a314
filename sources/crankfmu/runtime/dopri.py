"""Dormand-Prince 5(4) on plain Python floats: the integrator that runs inside the FMUs.

Why not scipy's solve_ivp in every doStep: for the two or four states of a crankfmu model its
per-call setup (~160 us), its initial-step selection (2 extra right-hand-side calls per call) and
numpy arithmetic on tiny arrays cost 10-50x the physics. This integrator's cost is its
right-hand-side calls: vectors are lists of floats, the step size is carried from one doStep to
the next (`Integration.h_next`), and nothing is set up per call.

The method and its controls are those of scipy's RK45 (same tableau, error estimate, dense output
and step-size rule: SAFETY 0.9, factor in [0.2, 10], RMS error norm with atol + rtol max|y|):
from the same first step it takes scipy's steps (tests/test_runtime.py). scipy stays available
as the cross-check (`solver = "scipy"` in `PhysicsModel`). Events follow solve_ivp's semantics:
functions g(t, x) with attributes `terminal` and `direction`, sign changes found at step ends
and located on the 4th-order dense output with Brent's method; the first terminal event ends
the integration, its state from a 5th-order step to the event time.
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field
from typing import Callable, Sequence

from .roots import brentq

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


class IntegrationFailure(RuntimeError):
    """The integration cannot go on; the message says where and why."""


class WorkLimitError(IntegrationFailure):
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


def per_state(atol, n: int) -> list:
    """The absolute tolerance per state, from one number for all or a sequence."""
    return [float(atol)] * n if isinstance(atol, (int, float)) else list(atol)


def _rms(values: Sequence[float]) -> float:
    return math.sqrt(sum(float(v) * float(v) for v in values) / len(values))


def initial_step(f, t0: float, x0: Sequence[float], f0: Sequence[float], span: float,
                 rtol: float, atol) -> float:
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
        self.t0, self.h, self.x0, self.stages = t0, h, x0, stages
        self.q: list | None = None

    def __call__(self, t: float) -> Vector:
        q = self.q
        if q is None:  # q[i][j] = sum_k K[k][i] P[k][j]
            q = self.q = _dense_coefficients(len(self.x0))(self.stages)
        s = (t - self.t0) / self.h
        h = self.h
        return [x + h * s * (q0 + s * (q1 + s * (q2 + s * q3)))
                for x, (q0, q1, q2, q3) in zip(self.x0, q)]


@functools.lru_cache(maxsize=None)
def _dense_coefficients(n: int):
    """stages -> q, q[i][j] = sum_m stages[m][i] _P[m][j] over the nonzero _P[m][j] in order
    of m (the sum as Python's sum() forms it), generated per state count as `stepper`."""
    rows = []
    for i in range(n):
        terms = [" + ".join(f"k[{m}][{i}] * {_P[m][j]!r}" for m in range(7) if _P[m][j])
                 for j in range(4)]
        rows.append("[" + ", ".join(terms) + "]")
    namespace: dict = {}
    exec(f"def coefficients(k):\n    return [{', '.join(rows)}]", namespace)  # noqa: S102
    return namespace["coefficients"]


@functools.lru_cache(maxsize=None)
def stepper(n: int):
    """One Dormand-Prince attempt for n states: step(f, t, x, k1, h, t_new, rtol, atol) ->
    (stages k1..k7, x_new, RMS error norm), with k7 = f(t_new, x_new) (first same as last).

    Generated per state count with every component and coefficient spelled out: for the 2 to 9
    states of a crankfmu model, list comprehensions over zip(...) (one hidden function call
    each in CPython) cost more than the arithmetic. Measured with valgrind's instruction count
    on 1 ms calls of a 2-state linear oscillator (7,500 instructions of right-hand side per
    step): 81,600 instructions per step with comprehensions, 52,100 generated."""
    rows = range(n)

    def names(stage):
        return [f"k{stage}_{i}" for i in rows]

    def combo(coefficients, stages, i):
        return " + ".join(f"{c!r} * k{j}_{i}" for c, j in zip(coefficients, stages) if c)

    def vector(items):
        return "(" + ", ".join(items) + ("," if n == 1 else "") + ")"
    lines = ["def step(f, t, x, k1, h, t_new, rtol, atol):",
             f"    {vector([f'x_{i}' for i in rows])} = x",
             f"    {vector(names(1))} = k1"]
    for stage in range(2, 7):
        a = _A[stage - 1]
        args = [f"x_{i} + h * ({combo(a, range(1, stage), i)})" for i in rows]
        lines += [f"    k{stage} = f(t + {_C[stage - 1]!r} * h, {vector(args)})",
                  f"    {vector(names(stage))} = k{stage}"]
    new = [f"x_{i} + h * ({combo(_B, range(1, 7), i)})" for i in rows]
    lines += [f"    x_new = [{', '.join(new)}]",
              "    k7 = f(t_new, x_new)",
              f"    {vector(names(7))} = k7",
              "    total = 0.0"]
    for i in rows:
        lines += [f"    e = h * ({combo(_E, range(1, 8), i)})",
                  f"    scale = atol[{i}] + rtol * max(abs(x_{i}), abs(x_new[{i}]))",
                  "    total += (e / scale) * (e / scale)"]
    lines.append(f"    return (k1, k2, k3, k4, k5, k6, k7), x_new, math.sqrt(total / {n})")
    namespace = {"math": math}
    exec("\n".join(lines), namespace)  # noqa: S102 - source built above from the tableau
    return namespace["step"]


def integrate(f: Callable[[float, Vector], Sequence[float]], t0: float, x0: Sequence[float],
              t_end: float, rtol: float, atol: Sequence[float] | float, h_start: float | None = None,
              events: Sequence[Callable] = (), max_calls: int = 200_000,
              dense: list | None = None, max_step: float = math.inf) -> Integration:
    """Integrate x' = f(t, x) from t0 to t_end (> t0).

    h_start: the step to try first (the previous call's `h_next`); None selects one as scipy
    does. atol: per state, or one for all. events: g(t, x) with optional attributes `terminal`
    (bool) and `direction` (-1, 0, +1). Raises WorkLimitError past max_calls right-hand-side
    evaluations (checked before each step attempt). dense: a list to which each accepted step is
    appended (its interpolant, callable on [t0, t0 + h]; its stages, for `moments`). max_step:
    no step longer (for a right-hand side with a known fast term the error estimate would
    not see between the stages).
    """
    x = list(x0)
    atol = per_state(atol, len(x))
    t = float(t0)
    k1 = f(t, x)
    calls = 1
    attempt = stepper(len(x))
    if h_start and h_start > 0.0:
        h = h_start
    else:
        h = initial_step(f, t, x, k1, t_end - t, rtol, atol)
        calls += 1
    h_next = h
    g_old = [g(t, x) for g in events] if events else ()
    crossings: list = []
    rejected = False
    while t < t_end:
        if h > max_step:
            h = max_step
        if h < 10.0 * EPS * max(abs(t), 1e-300):
            raise WorkLimitError(f"step size {h:.3g} s below round-off at t = {t:.9g} s")
        if calls > max_calls:  # counted per attempt: a wrapper per call would cost more
            raise WorkLimitError(f"more than {max_calls} derivative evaluations between "
                                 f"t = {t0:.9g} s and {t_end:.9g} s (states {x}): diverging "
                                 "or too stiff")
        h_try = min(h, t_end - t)
        last = h_try >= t_end - t
        t_new = t_end if last else t + h_try
        stages, x_new, err = attempt(f, t, x, k1, h_try, t_new, rtol, atol)
        calls += 6
        if err != err:  # NaN: a derivative is not finite (a zero inertia, an overflow)
            raise IntegrationFailure(f"the derivatives are not finite in the step from "
                                     f"t = {t:.9g} s (states there "
                                     f"{[round(float(v), 9) for v in x]})")
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
        step = None
        if dense is not None:
            step = _Step(t, h_try, x, stages)
            dense.append(step)
        if events:
            g_new = [g(t_new, x_new) for g in events]
            hit = None
            if any(a * b <= 0.0 for a, b in zip(g_old, g_new)):  # a sign change or a zero
                step = step or _Step(t, h_try, x, stages)
                hit = _locate(events, g_old, g_new, t, t_new, step, crossings)
            if hit is not None:  # step again to the event: the 5th-order solution there,
                index, te = hit  # not the 4th-order dense output, which the error test skips
                x_event = attempt(f, t, x, k1, te - t, te, rtol, atol)[1] if te > t else x
                return Integration(1, te, x_event, _coarse(h_next), index, crossings,
                                   calls + 6)
            g_old = g_new
        t, x, k1 = t_new, x_new, stages[6]
    return Integration(0, t, x, _coarse(h_next), None, crossings, calls)


def moments(dense: list, origin: float, index: int, count: int) -> list:
    """The integrals of (t - origin)^k x_index'(t) over the integration that appended the steps
    to `dense`, k = 0 ... count - 1: the method's own quadrature (its weights on the stages),
    as accurate as the state x_index itself (k = 0: its change)."""
    out = [0.0] * count
    for step in dense:
        for b, c, rates in zip(_B, _C, step.stages):
            if b:
                s, weight = step.t0 - origin + c * step.h, b * step.h * rates[index]
                for j in range(count):
                    out[j] += weight
                    weight *= s
    return out


def _coarse(h: float) -> float:
    """h to 20 significant bits. The step carried to the next call must not depend on the last
    bits of the call's interval: hosts count time differently (t0 + k h, integer nanoseconds),
    and a last-bit difference in the carried step would change every later step (measured:
    ecos against fmpy, 4e-11 relative in the rocker's support force)."""
    mantissa, exponent = math.frexp(h)
    return math.ldexp(round(mantissa * 1048576.0) / 1048576.0, exponent)


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
            def along(s: float, g=g) -> float:  # g along the step's dense output
                return g(s, step(s))
            te = brentq(along, t_old, t_new, xtol=4 * EPS, rtol=4 * EPS)
        roots.append((te, i))
    for te, i in sorted(roots):
        if getattr(events[i], "terminal", False):
            return i, te
        crossings.append((i, te, step(te)))
    return None
