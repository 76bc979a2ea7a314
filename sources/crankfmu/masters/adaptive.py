"""Adaptive Gauss-Seidel: step-size control with an extrapolation-error estimate.

Each step is a Gauss-Seidel sweep with extrapolation order p ([master].extrapolation; lower while
the run has fewer than p + 1 points). Its error estimate costs no extra doStep: for every connected
output, the gap between the value the FMU delivered at t + h and the value the extrapolation
polynomial predicted for it,
    err = max_i |y_i(t + h) - P_i(t + h)| / (tolerance * scale_i)
(scale: the output's largest magnitude so far, at least its nominal). That gap is the input error
the coupling makes over the step, O(h^(p+1)). A step with err > 1 is rejected: every FMU is rolled
back to t and the step retried with h * max(0.2, 0.9 err^(-1/(p+1))); an accepted step proposes
the next one as h * min(5, 0.9 err^(-1/(p+1))), always within [min_step, max_step]. A step at
min_step is accepted whatever its error (counted in `accepted_above_tolerance`).

The tolerance bounds an input error, so the global error follows it at every order (measured
0.06-0.25 x tolerance on the servo press) while the cost grows as tolerance^(-1/(p+1)). With held
inputs (p = 0) the estimate is the output's change over the step: a tolerance of 1e-6, the
shared default that fits the iterative master's interface convergence, asks for steps of
1e-6 x the outputs' time scale (an output rising from rest changes by h / t relative to itself
per step), below min_step: the servo press took 300,000 steps for 0.3 s, each accepted above
tolerance. The adaptive master's own default is therefore 1e-2 (DEFAULT_TOLERANCE): there the
shipped scenes' errors measured at most 5e-3 at extrapolation 1 and 2 (docs/error_estimate.md),
and the servo press's first 0.3 s take 1,100 steps at extrapolation 0 (error 6e-4, no step
above tolerance), 61 at extrapolation 2 (error 2.3e-3).

External inputs are written at a step's start and held over it, so a step across the edge of a
step table (a clutch command) would move the edge to the step's end, by up to max_step, and the
error estimate cannot see it (the input is no connected output). Steps therefore end exactly at
the tables' edges (masters.inputs.step_edges); a step that would stop less than min_step short
of an edge is stretched to it, as the runner does at stop_time.
"""
from __future__ import annotations

import bisect
import warnings

from .base import Master, evaluate
from .inputs import edge_reading_time, step_edges, step_to
from .options import EXTRAPOLATION, TAYLOR, TOLERANCE, Option, OptionError

SAFETY, MIN_FACTOR, MAX_FACTOR = 0.9, 0.2, 5.0
MIN_STEP = Option("min_step", float, "s", 1e-6, "the smallest step a variable-step master "
                  "takes (accepted whatever its error)", positive=True)
MAX_STEP = Option("max_step", float, "s", 1e-2, "the largest step a variable-step master takes",
                  positive=True)


DEFAULT_TOLERANCE = 1e-2  # the module's docstring: a step error reachable at every order


class Adaptive(Master):
    name = "adaptive"
    options = (EXTRAPOLATION, TAYLOR, TOLERANCE, MIN_STEP, MAX_STEP)
    defaults = {"tolerance": DEFAULT_TOLERANCE}
    needs_rollback = True
    variable_step = True
    uses_error_scale = True

    def __init__(self, system, settings):
        super().__init__(system, settings)
        self.tolerance = self.option("tolerance")
        self.min_step, self.max_step = self.option("min_step"), self.option("max_step")
        self.next_step = self._clip(float(settings.step))
        self.counts = {"accepted_steps": 0, "rejected_steps": 0, "accepted_above_tolerance": 0,
                       "smallest_step": None, "largest_step": None}
        self.extra_statistics = self.counts
        self.edges = step_edges(system)  # s: steps end here (the module's docstring)

    @classmethod
    def check_options(cls, values: dict) -> None:
        if values["min_step"] > values["max_step"]:
            raise OptionError(f"[master].min_step: {values['min_step']!r} exceeds max_step = "
                              f"{values['max_step']!r}")

    def _clip(self, h: float) -> float:
        return min(max(h, self.min_step), self.max_step)

    def _to_edge(self, t: float, h: float) -> float:
        """h, shortened (or stretched by less than min_step) so that the step ends at the first
        input edge after t if it would cross it: t + h >= edge in floats, so the next step's
        start reads the new value (InputSignal.value_at holds it from the edge on)."""
        if not self.edges:
            return h
        i = bisect.bisect_right(self.edges, edge_reading_time(t))  # as value_at reads
        if i == len(self.edges) or t + h < self.edges[i] - self.min_step:
            return h
        return step_to(t, self.edges[i])

    def _step(self, t: float, h: float) -> float:
        h = self._to_edge(t, h)
        order = min(self.extrapolation, len(self.history.times) - 1) if self.taylor is None \
            else self.taylor.order  # the error of order `order` + 1 in h
        states = self.save_states()
        coefficients = self.source_coefficients(t, order)
        rows = {c: coefficients[c] for c in self.system.order}  # the same rows as the sweep's
        # the sweep written out makes these rows itself, with the same floats (sweep_code.py)
        written = self._written_sweep(True, order)
        while True:
            predicted = {c: evaluate(r, h) for c, r in rows.items()}
            if written is not None:
                written(t, h)
            else:
                self.sequential_sweep(t, h, self.extrapolation, rows)
            error = self._error(predicted)
            factor = SAFETY * error ** (-1.0 / (order + 1)) if error > 0 else MAX_FACTOR
            if error <= 1.0 or h <= self.min_step * (1 + 1e-9):
                break
            self.counts["rejected_steps"] += 1
            self.restore_states(states)
            h = max(self.min_step, h * max(MIN_FACTOR, factor))
        self.free_states(states)
        self._count(t, h, error)
        self.next_step = self._clip(h * min(MAX_FACTOR, factor))
        return h

    def _error(self, predicted: dict) -> float:
        """max(|y - P| / (tolerance * scale)) over the connected outputs; a NaN makes a
        component's error NaN, as numpy's max does."""
        errors = []
        tolerance = self.tolerance
        for c, values in self.system.outputs.items():
            if not values:
                continue
            worst = -1.0
            for v, p, s in zip(values, predicted[c], self.scales.of_floats(c, values)):
                e = abs(v - p) / (tolerance * s)
                if e != e:  # NaN
                    worst = e
                    break
                if e > worst:
                    worst = e
            errors.append(worst)
        return float(max(errors, default=0.0))

    def _count(self, t: float, h: float, error: float) -> None:
        c = self.counts
        c["accepted_steps"] += 1
        c["smallest_step"] = min(h, c["smallest_step"] or h)
        c["largest_step"] = max(h, c["largest_step"] or h)
        if error > 1.0:
            c["accepted_above_tolerance"] += 1
            if c["accepted_above_tolerance"] == 1:
                warnings.warn(f"adaptive master: step at t = {t:.6g} s accepted at min_step = "
                              f"{self.min_step:g} s with error {error:.3g} x tolerance (further "
                              f"ones are counted in the statistics: accepted_above_tolerance)",
                              RuntimeWarning, stacklevel=2)

