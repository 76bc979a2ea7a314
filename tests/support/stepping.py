"""A physics model stepped as the FMU adapter steps it, counting its right-hand-side calls (the
rocker models' free-flight tests)."""
from __future__ import annotations

import json

import numpy as np

from crankfmu.runtime.model import held


def stepped(model, t_end: float, h: float, u, rtol: float):
    """(outputs after each step of h with held inputs u, right-hand-side calls per step, the
    state, discrete state and solver state before the last step, for a repeat of it)."""
    x = model.initial_state(u)
    calls, rows, integrate = [], [], model.integrate

    def counting(*args, **kwargs):
        sol = integrate(*args, **kwargs)
        calls[-1] += sol.calls
        return sol
    model.integrate = counting
    n = int(round(t_end / h))
    for k in range(n):
        if k == n - 1:
            before = (list(x), json.loads(json.dumps(model.discrete_state())),
                      json.loads(json.dumps(model.solver_state())))
        calls.append(0)
        x = model.advance(k * h, x, h, held(u), rtol, rtol * model.state_nominal())
        rows.append(model.output_values((k + 1) * h, x, u))
    return np.array(rows), calls, before
