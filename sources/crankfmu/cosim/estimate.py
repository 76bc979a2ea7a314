"""An estimate of a run's global error without a reference: Richardson extrapolation from
companion runs of the same master at another step (or tolerance).

The error is the scene's own accuracy metric (`cosim/metrics.py`: the trajectory metric or the
event figures its [analysis] names), evaluated between the run and a companion run of the same
master at another setting r x (step or tolerance). With a global error e(x) ~ C x^p, the
difference between the run and its companion is d = |e(r x) - e(x)| ~ |r^p - 1| e(x), so

    estimate = d / |r^p - 1|.

`crankfmu run`: one finer companion, at h/2 (fixed step, p = p0 = extrapolation + 1, or
taylor + 1 for a Taylor coupling: the estimate is d 2^p / (2^p - 1), between 1.03 d and 2 d
whatever p is) or at a tenth of a
variable-step master's tolerance (p = 1: about 1.1 d). The finer run is nearer the asymptotic
range than the run, so d measures the run's own error; coarse companions (2h and 4h, the order
observed from the three runs) were cheaper but off more often: scripts/error_estimate.py
measured the variants over the accuracy sweeps (docs/error_estimate.md, "How
often it is right"). The `--target` search (cosim/target.py) uses the same form on its own runs.

Cost: the companion takes twice the run's communication steps (fixed step) or the steps of a
tenth of the tolerance (about 10^(1/(extrapolation + 1)) x); the FMUs' own integration does not
grow with the step count, so the wall time grows less (docs/error_estimate.md). With a spare core it runs in a
worker beside the run (cosim/companions.py; `crankfmu run --jobs`). When it is wrong: the
companion counts other events than the run (no estimate, the reason says so) or stops (no
estimate), the run sits at the FMUs' tolerance floor (the difference is solver noise).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .metrics import Metric, MetricError, ReferenceSamples

STEP_RATIO = 2.0          # run step / companion step (and the --target search's rungs)
RATIO_TOLERANCE = 10.0    # variable-step master: run tolerance / companion tolerance
ORDER_MIN, ORDER_MAX = 0.5, 5.0  # default clamp of an observed order (coarse_bounds narrows it)
EVENTS_DIFFER = "event count differs between the run and its companion"  # a reason (no estimate)


@dataclass
class Estimate:
    """The estimated global error of one run in the scene's metric; `error` is nan when there
    is none, and `reason` says why."""
    error: float = math.nan
    order: float = math.nan         # p used in d / |r^p - 1| [1]
    order_source: str = ""          # "observed" (from the second companion) or "nominal"
    ratio: float = STEP_RATIO
    knob: str = "step"              # what the companions vary: "step" or "tolerance"
    differences: list[float] = field(default_factory=list)  # d(run, c1), d(c1, c2) [1]
    companion_seconds: float = 0.0  # wall time of the companion runs
    reason: str = ""
    metric: str = ""                # the metric's key (cosim/metrics.py: max, steady, events)
    metric_description: str = ""    # Metric.describe(): what the error is of, and how formed
    subject: str = ""               # Metric.subject: what the error is of
    formula: str = ""               # Metric.formula, with y_ref the exact solution

    @property
    def ok(self) -> bool:
        return math.isfinite(self.error)

    @property
    def events_differ(self) -> bool:
        """No estimate because the companion counts other events than the run."""
        return self.reason.startswith(EVENTS_DIFFER)

    def to_json(self) -> dict:
        def num(x):
            return x if isinstance(x, (int, float)) and math.isfinite(x) else None
        return {"estimated_error": num(self.error), "metric": self.metric,
                "metric_description": self.metric_description, "method": "richardson",
                "order": num(self.order), "order_source": self.order_source,
                "ratio": self.ratio, "knob": self.knob,
                "differences": [num(d) for d in self.differences],
                "companion_seconds": self.companion_seconds, "reason": self.reason}


def order_rule(algorithm: str, extrapolation: int, taylor: int = 0
               ) -> tuple[float, tuple | None]:
    """(order, bounds of an observed order) of `crankfmu run`'s estimator: one companion, so
    the order is the master's design order p0 (crankfmu.masters.Traits.design_order:
    extrapolation + 1 at a fixed step, taylor + 1 with a Taylor coupling, 1 at a variable
    step). ValueError for a monolithic master: it has no coupling error to estimate."""
    from ..masters import traits
    order = traits(algorithm).design_order(extrapolation, taylor)
    if order is None:
        raise ValueError(f"{algorithm} has no coupling error, so no design order")
    return order, None


def coarse_bounds(algorithm: str, extrapolation: int, taylor: int = 0) -> tuple[float, float]:
    """Bounds of the order observed from companions at 2h and 4h (the --target search):
    [p0, p0 + 1] (Gauss-Seidel and the iterative master gain an order on some scenes; outside
    that range the observed ratio was noise: scripts/error_estimate.py)."""
    p0, _ = order_rule(algorithm, extrapolation, taylor)
    return p0, p0 + 1.0


def difference(metric: Metric, a: tuple, b: tuple) -> tuple[float, str]:
    """(the metric between runs `a` and `b`, reason if none). Runs are (times [s], {column:
    values}); the one with more record points serves as the reference, looked up at the other's
    record times (exact grid points when one grid is a subset of the other, as for steps h and
    2h; else a cubic spline through the denser grid). Infinite with the reason when the runs
    count different events."""
    fine, coarse = (a, b) if len(a[0]) >= len(b[0]) else (b, a)
    t_c, cols_c = coarse
    t_f, cols_f = fine
    ref = ReferenceSamples(np.asarray(t_f, dtype=float), cols_f)
    try:
        if metric.name == "events":
            details = metric.event_details(np.asarray(t_c, dtype=float), cols_c, ref)
            reasons = [d.reason for d in details if d.reason]
            if reasons:
                return math.inf, f"{EVENTS_DIFFER}: " + "; ".join(reasons)
        return float(metric.error(np.asarray(t_c, dtype=float), cols_c, ref)), ""
    except MetricError as err:
        return math.nan, str(err)


def richardson(metric: Metric, runs: list[tuple], ratio: float, knob: str,
               nominal: float, bounds: tuple[float, float] | None = None) -> Estimate:
    """The estimate from `runs` = [run, companion 1, (companion 2)], each (times, columns), the
    companions at ratio and ratio^2 x the run's step (knob "step") or tolerance ("tolerance").
    With two companions the order is observed, clamped to `bounds` (default
    [ORDER_MIN, ORDER_MAX]), else `nominal`."""
    lo, hi = bounds or (ORDER_MIN, ORDER_MAX)
    est = Estimate(ratio=ratio, knob=knob, metric=metric.name,
                   metric_description=metric.describe(), subject=metric.subject,
                   formula=metric.formula)
    d1, why = difference(metric, runs[0], runs[1])
    est.differences.append(d1)
    if not math.isfinite(d1):
        est.reason = why or "the companion run differs without bound"
        return est
    est.order, est.order_source = nominal, "nominal"
    if len(runs) > 2:
        d2, why2 = difference(metric, runs[1], runs[2])
        est.differences.append(d2)
        if math.isfinite(d2) and d1 > 0 and d2 > 0:
            observed = math.log(d2 / d1) / math.log(ratio)
            est.order = min(hi, max(lo, observed))
            est.order_source = "observed"
            if abs(observed - est.order) > 0.25:  # not the noise of an order at its bound
                est.reason = f"observed order {observed:.2f} clamped to {est.order:g}"
        elif why2:
            est.reason = f"order not observed ({why2}); nominal order used"
    est.error = d1 / abs(ratio ** est.order - 1.0)
    return est


def companion_knobs(algorithm: str, step: float, tolerance: float
                    ) -> tuple[str, float, list[float]]:
    """(knob, ratio, companion values) of `crankfmu run`'s estimate for a run of the master
    `algorithm` at `step` and `tolerance`: a finer companion, at half the step or (a
    variable-step master) a tenth of the tolerance."""
    from ..masters import traits
    if traits(algorithm).knob == "tolerance":
        return "tolerance", 1.0 / RATIO_TOLERANCE, [tolerance / RATIO_TOLERANCE]
    return "step", 1.0 / STEP_RATIO, [step / STEP_RATIO]


# -- helpers of a run's estimate (the companions are run by cosim.runner.estimate_run) ---------
def scene_metric(scene) -> Metric:
    """The metric the scene is judged by ([analysis]; cosim/metrics.py), on its recorded
    variables plus the event figures' variables."""
    from .metrics import make_metric, scene_event_specs, scene_metric_name
    specs = scene_event_specs(scene)
    record = list(dict.fromkeys(scene.record + [v for s in specs for v in s.needs]))
    return make_metric(scene_metric_name(scene), record, None, 1, specs)


def with_metric_record(scene):
    """`scene` (a copy if anything is added) recording what its metric needs."""
    import copy
    from .metrics import scene_event_specs
    needs = [v for s in scene_event_specs(scene) for v in s.needs if v not in scene.record]
    if not needs:
        return scene
    scene = copy.deepcopy(scene)
    scene.record = scene.record + needs
    return scene


def recorder_series(recorder) -> tuple:
    return recorder.rows[:, 0], {n: recorder.column(n) for n in recorder.names}


def companion_scene(scene, knob: str, value: float):
    import copy
    trial = copy.deepcopy(scene)
    setattr(trial.master, knob, value)
    return trial


def format_estimate(est: Estimate) -> str:
    """One line for the terminal."""
    if not est.ok:
        return f"estimated error: none ({est.reason})"
    if est.knob == "tolerance":
        where = f"a companion at {est.ratio:g} x the tolerance"
    elif est.ratio < 1:
        where = f"a companion at {est.ratio:g} x the step"
    else:
        where = f"companions at {est.ratio:g} and {est.ratio ** 2:g} x the step"
    of = f" of {est.subject} ({est.formula})" if est.subject else ""
    return (f"estimated error {est.error:.2e}{of}: Richardson from {where}, order "
            f"{est.order:.2f} {est.order_source}; the companion runs took "
            f"{est.companion_seconds:.2f} s" + (f"; {est.reason}" if est.reason else ""))
