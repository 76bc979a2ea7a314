"""Iterative (implicit) co-simulation: repeat each step until the interface values converge.

The unknowns are the connected outputs at t + h, y. One evaluation G(y) rolls every FMU back to
t (fmi2SetFMUstate), gives each its inputs as the polynomial through the values at t (and, for
extrapolation 2, at the point before) and the iterate y at t + h, steps it, and reads its outputs
at t + h. The step is converged when the interface residual r = G(y) - y satisfies
max_i |r_i| / (tolerance * scale_i) <= 1 (scale: the output's largest magnitude so far, at least
its nominal). The first iterate is the extrapolation of order [master].extrapolation.

Plain fixed-point iteration y <- G(y) (Jacobi waveform iteration) diverges exactly where explicit
Jacobi does (stiff couplings, large steps), so the update is Newton's: y <- y - (dG/dy - I)^-1 r,
with dG/dy by finite differences (one column per connected output; only the components reading
that output are stepped). The Jacobian is kept from step to step and recomputed when a Newton
iteration reduces the residual by less than a factor 4. Converged with linear interpolation, the
interface is integrated by the trapezoidal rule: A-stable, so a stiff coupling stays stable.

A step not converged within [master].max_iterations evaluations is accepted as it is, with a
warning; the count is in the statistics (`non_converged_steps`).
"""
from __future__ import annotations

import warnings

import numpy as np

from .base import Master, evaluate
from .options import EXTRAPOLATION, TOLERANCE, Option

CONTRACTION = 0.25  # a Newton iteration must cut the residual by this factor, else new Jacobian
MAX_ITERATIONS = Option("max_iterations", int, "1", 20, "evaluations of a step before it is "
                        "accepted unconverged (with a warning)", minimum=1, maximum=10_000)


class Iterative(Master):
    name = "iterative"
    options = (EXTRAPOLATION, TOLERANCE, MAX_ITERATIONS)
    needs_rollback = True
    solves_algebraic_loops = True  # its converged step satisfies the loop at t + h
    uses_error_scale = True

    def __init__(self, system, settings):
        super().__init__(system, settings)
        self.order = max(1, self.extrapolation)  # inputs interpolate between t and t + h
        self.tolerance = self.option("tolerance")
        self.max_iterations = self.option("max_iterations")
        self.delta = max(float(settings.fmu_tolerance), 1e-14) ** 0.5  # finite-difference size
        sizes = [len(system.out_names[c]) for c in system.order]
        self.offsets = dict(zip(system.order, np.cumsum([0] + sizes[:-1]).tolist()))
        self.n = sum(sizes)
        self.readers = [[tgt for tgt in system.order if (src, k) in system.in_sources[tgt]]
                        for src in system.order for k in range(len(system.out_names[src]))]
        self.jacobian, self.jacobian_key = None, None
        self.counts = {"steps": 0, "iterations": 0, "max_iterations_in_a_step": 0,
                       "jacobians": 0, "non_converged_steps": 0}
        self.extra_statistics = self.counts

    # -- flat interface vector ------------------------------------------------------------
    def _flat(self, outputs: dict) -> np.ndarray:
        return np.concatenate([outputs[c] for c in self.system.order]) if self.n else np.zeros(0)

    def _split(self, y: np.ndarray) -> dict:
        return {c: y[o:o + len(self.system.out_names[c])] for c, o in self.offsets.items()}

    # -- one evaluation of G ----------------------------------------------------------------
    def _evaluate(self, t, h, y, states, comps) -> np.ndarray:
        """Roll `comps` back to t, step them with inputs interpolating towards y, return the
        interface vector with their new outputs."""
        system = self.system
        newest = {c: (t + h, v) for c, v in self._split(y).items()}
        coefficients = self.source_coefficients(t, self.order, newest)
        for comp in comps:
            if self._moved[comp]:
                system.fmus[comp].set_state(states[comp])
            self.advance_component(comp, t, h, self.gather(comp, coefficients))
            self._moved[comp] = True
            system.refresh_outputs(comp)
        return self._flat(system.outputs)

    def _fd_jacobian(self, t, h, y, g, states) -> np.ndarray:
        """d(G - I)/dy by forward differences."""
        jac = -np.eye(self.n)
        scale = self._scale(g)
        for j, targets in enumerate(self.readers):
            step = self.delta * scale[j]
            yp = y.copy()
            yp[j] += step
            gp = self._evaluate(t, h, yp, states, targets)
            for comp in targets:
                rows = slice(self.offsets[comp], self.offsets[comp] + len(self.system.out_names[comp]))
                jac[rows, j] += (gp[rows] - g[rows]) / step
        self.counts["jacobians"] += 1
        return jac

    def _scale(self, g: np.ndarray) -> np.ndarray:
        parts = self._split(g)
        return self._flat({c: self.error_scale(c, parts[c]) for c in self.system.order})

    # -- the step -------------------------------------------------------------------------
    def _step(self, t: float, h: float) -> float:
        system = self.system
        states = self.save_states()
        self._moved = dict.fromkeys(system.order, False)
        y = self._flat(self._predict(t, h))
        comps = system.order
        g = self._evaluate(t, h, y, states, comps)
        iterations, fresh = 1, False
        error = self._error(g - y, g)
        points = min(len(self.history.times), self.order) + 1  # in the input polynomials
        if self.jacobian_key != (h, points):  # dG/dy depends on the step and the polynomials
            self.jacobian, self.jacobian_key = None, (h, points)
        while error > 1.0 and iterations < self.max_iterations:
            if self.jacobian is None:
                self.jacobian, fresh = self._fd_jacobian(t, h, y, g, states), True
            y = y - _solve(self.jacobian, g - y)
            g = self._evaluate(t, h, y, states, comps)
            iterations += 1
            new_error = self._error(g - y, g)
            if new_error > CONTRACTION * error and not fresh:
                self.jacobian = None  # slow: a new Jacobian at the next iteration
            error, fresh = new_error, False
        self._count(t, iterations, error)
        self.free_states(states)
        return h

    def _predict(self, t: float, h: float) -> dict:
        coefficients = self.source_coefficients(t, self.extrapolation)
        return {c: evaluate(coefficients[c], h) for c in self.system.order}

    def _error(self, residual: np.ndarray, g: np.ndarray) -> float:
        if not self.n:
            return 0.0
        return float(np.max(np.abs(residual) / (self.tolerance * self._scale(g))))

    def _count(self, t: float, iterations: int, error: float) -> None:
        c = self.counts
        c["steps"] += 1
        c["iterations"] += iterations
        c["max_iterations_in_a_step"] = max(c["max_iterations_in_a_step"], iterations)
        if error > 1.0:
            c["non_converged_steps"] += 1
            if c["non_converged_steps"] == 1:
                warnings.warn(f"iterative master: step at t = {t:.6g} s not converged in "
                              f"{iterations} iterations (residual {error:.3g} x tolerance "
                              f"{self.tolerance:g}); accepted as is (further ones are counted "
                              f"in the statistics: non_converged_steps)", RuntimeWarning,
                              stacklevel=2)


def _solve(jacobian: np.ndarray, residual: np.ndarray) -> np.ndarray:
    try:
        return np.linalg.solve(jacobian, residual)
    except np.linalg.LinAlgError:  # singular interface Jacobian: least-squares step
        return np.linalg.lstsq(jacobian, residual, rcond=None)[0]
