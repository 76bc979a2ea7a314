"""Error metrics of a run against the monolithic reference, and the observed convergence order.

Metrics (all relative, dimensionless; the reference is sampled at the run's own record times,
so sampling effects are the same on both sides and only the coupling error remains):

    max     max over the record grid and the chosen variables of |y - y_ref| / mean|y_ref|
            (default variables: the recorded crank speeds `*.w_crank`, else every recorded
            variable). The default metric: it sees the whole run, run-up included.
    steady  over the last `cycles` whole crank revolutions (needs `C.phi` and `C.w_crank` of one
            component recorded): the larger of the relative errors of the mean crank speed
            2 pi n / T_n and of the non-uniformity delta = (w_max - w_min) / w_mean.
    events  the largest error over the scene's [analysis].events entries (event times, event
            quantities, per-event figures; cosim/events.py), each taken on the run's and the
            reference's own grids. The default metric of a scene whose [analysis] says
            metric = "events".

`scene_metric_name(scene)` is the metric a scene is judged by when none is asked for:
[analysis].metric if given, else "events" if [analysis].events is given, else "max".
"""
from __future__ import annotations

from ..errors import CrankfmuError

import math
from dataclasses import dataclass, field

import numpy as np

from .events import EventError, EventSpec, EventSpecError, event_errors, parse_event_specs

TWO_PI = 2.0 * math.pi
METRICS = ("max", "steady", "events")


class MetricError(CrankfmuError, ValueError):
    """A metric that cannot be evaluated on this scene; says what is missing."""


class ReferenceSamples:
    """The reference's recorded columns, looked up at a run's record times: exact where the
    times are reference grid points (the usual case: the grid is the union of the runs' grids),
    else by a cubic spline through the grid."""

    def __init__(self, times: np.ndarray, columns: dict[str, np.ndarray]):
        self.times, self.columns = np.asarray(times, dtype=float), columns
        self._splines: dict = {}

    def at(self, name: str, t: np.ndarray) -> np.ndarray:
        t = np.asarray(t, dtype=float)
        k = np.clip(np.searchsorted(self.times, t), 0, len(self.times) - 1)
        k_left = np.clip(k - 1, 0, None)
        k = np.where(np.abs(self.times[k_left] - t) < np.abs(self.times[k] - t), k_left, k)
        scale = max(1.0, float(np.max(np.abs(self.times))))
        if np.all(np.abs(self.times[k] - t) <= 1e-12 * scale):
            return self.columns[name][k]
        if name not in self._splines:
            from scipy.interpolate import CubicSpline
            self._splines[name] = CubicSpline(self.times, self.columns[name])
        return self._splines[name](t)


@dataclass
class Metric:
    name: str
    variables: list[str]
    cycles: int = 1
    events: list[EventSpec] = field(default_factory=list)  # metric events: its figures

    def describe(self) -> str:
        """What the error is, in one line: `formula` over `subject`."""
        return f"{self.formula} over {self.subject}"

    @property
    def subject(self) -> str:
        """What the error is of: the variables, the event figures, a crank's steady state."""
        if self.name == "events":
            return "the event figures " + "; ".join(s.label for s in self.events)
        if self.name == "max":
            return ", ".join(self.variables)
        return (f"the last {self.cycles} revolution(s) of "
                f"{self.variables[0].rsplit('.', 1)[0]}")

    @property
    def formula(self) -> str:
        """How the error is formed from a run y and the reference y_ref (relative, [1])."""
        if self.name == "events":
            return "max of the relative errors"
        if self.name == "max":
            return "max_t |y - y_ref| / mean|y_ref|"
        return "max(rel. error of mean speed, rel. error of delta)"

    def event_details(self, t: np.ndarray, run: dict[str, np.ndarray],
                      ref: ReferenceSamples) -> list[EventError]:
        """Per [analysis].events entry, the run's and the reference's figures and the error
        (each on its own record grid; both must end at the same time)."""
        t_end, t_ref_end = float(t[-1]), float(ref.times[-1])
        if abs(t_end - t_ref_end) > 1e-9 * max(1.0, abs(t_end)):
            raise MetricError(f"the reference ends at t = {t_ref_end:g} s, the run at "
                              f"{t_end:g} s: event figures need both over the same span")
        return event_errors(self.events, run, ref.columns)

    def error(self, t: np.ndarray, run: dict[str, np.ndarray], ref: ReferenceSamples) -> float:
        if self.name == "events":
            return max((e.error for e in self.event_details(t, run, ref)), default=0.0)
        if self.name == "max":
            return max(_max_relative(run[v], ref.at(v, t)) for v in self.variables)
        phi_name, w_name = self.variables
        mine = steady_figures(t, run[phi_name], run[w_name], self.cycles)
        theirs = steady_figures(t, ref.at(phi_name, t), ref.at(w_name, t), self.cycles)
        return max(abs(a / b - 1.0) for a, b in zip(mine, theirs))


def scene_event_specs(scene) -> list[EventSpec]:
    """The scene's [analysis].events as EventSpecs; a bad entry is a MetricError naming the
    scene file and the key."""
    raw = scene.raw.get("analysis") or {}
    try:
        return parse_event_specs(raw.get("events"))
    except EventSpecError as err:
        raise MetricError(f"{scene.path}: {err}") from None


def scene_metric_name(scene) -> str:
    """The metric the scene is judged by (see the module docstring)."""
    raw = scene.raw.get("analysis") or {}
    name = raw.get("metric", "events" if raw.get("events") else "max")
    if name not in METRICS:
        raise MetricError(f"{scene.path}: [analysis].metric = {name!r}; allowed: "
                          f"{', '.join(METRICS)}")
    return name


def make_metric(name: str, recorded: list[str], variables: list[str] | None = None,
                cycles: int = 1, events: list[EventSpec] | None = None) -> Metric:
    if name not in METRICS:
        raise MetricError(f"unknown metric {name!r}; metrics: {', '.join(METRICS)}")
    if name == "events":
        if not events:
            raise MetricError("metric events needs [analysis].events in the scene: event "
                              "times or quantities (\"comp.var\") or per-event figures "
                              "({ variable = \"comp.var\", per = \"comp.counter\" })")
        return Metric("events", [v for s in events for v in s.needs], cycles, events)
    for v in variables or []:
        if v not in recorded:
            raise MetricError(f"--variables: {v} is not recorded; [record].variables: "
                              f"{', '.join(recorded)}")
    if name == "max":
        chosen = variables or [v for v in recorded if v.endswith(".w_crank")] or list(recorded)
        if not chosen:
            raise MetricError("the scene records no variables ([record].variables)")
        return Metric("max", chosen)
    comps = [v.rsplit(".", 1)[0] for v in recorded if v.endswith(".w_crank")
             and v.replace(".w_crank", ".phi") in recorded]
    if variables:
        comps = [v.rsplit(".", 1)[0] for v in variables if v.rsplit(".", 1)[0] in comps]
    if not comps:
        raise MetricError("metric steady needs the crank angle and speed of one component "
                          "recorded (C.phi and C.w_crank in [record].variables)")
    return Metric("steady", [f"{comps[0]}.phi", f"{comps[0]}.w_crank"], cycles)


def _max_relative(y: np.ndarray, y_ref: np.ndarray) -> float:
    scale = float(np.mean(np.abs(y_ref)))
    if scale == 0.0:
        scale = 1.0  # a variable that is zero in the reference: absolute error
    return float(np.max(np.abs(y - y_ref)) / scale)


def steady_figures(t, phi, w, cycles: int = 1) -> tuple[float, float]:
    """(mean speed 2 pi n / T [rad/s], delta [1]) over the last n whole revolutions; the
    crossings of phi = 2 pi k are located by linear interpolation in time."""
    k_end = math.floor(phi[-1] / TWO_PI)
    if k_end - cycles < math.ceil(phi[0] / TWO_PI) or not np.all(np.diff(phi) > 0):
        raise MetricError(f"the run covers no {cycles} whole crank revolution(s) with the "
                          f"crank turning forwards: lengthen --stop-time or use --metric max")
    ends = [float(np.interp(TWO_PI * k, phi, t)) for k in (k_end - cycles, k_end)]
    inside = (t >= ends[0]) & (t <= ends[1])
    mean = TWO_PI * cycles / (ends[1] - ends[0])
    return mean, float((w[inside].max() - w[inside].min()) / mean)


def observed_order(steps, errors, floor: float) -> tuple[float, int]:
    """(slope of log error over log step, points used), over the finite errors above `floor`
    (below it the FMUs' own tolerance, not the coupling, sets the error). nan with < 2 points."""
    h = np.asarray(steps, dtype=float)
    e = np.asarray(errors, dtype=float)
    use = np.isfinite(e) & (e > floor) & (h > 0)
    if np.count_nonzero(use) < 2 or len(np.unique(h[use])) < 2:
        return float("nan"), int(np.count_nonzero(use))
    slope = np.polyfit(np.log(h[use]), np.log(e[use]), 1)[0]
    return float(slope), int(np.count_nonzero(use))
