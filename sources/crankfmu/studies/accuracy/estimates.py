"""The error estimate of each sweep run (crankfmu.cosim.estimate), from its companion's CSV in
runs/: the same Richardson estimate `crankfmu run` reports, set beside the true error.

A run's companion (half its step; a tenth of a variable-step master's tolerance) is mostly a
run of the sweep itself (the default steps are 4, 2, 1, 0.5 x the scene's: only 0.25 x is
added, and the adaptive master's tenths); the others are run with the sweep and left out of
its table.
"""
from __future__ import annotations

import json
import math
from dataclasses import replace
from pathlib import Path

from ...cosim.estimate import companion_knobs, order_rule, richardson
from ...masters import traits
from .sweep import Outcome, Setting


def companion_settings(setting: Setting) -> list[Setting]:
    if traits(setting.algorithm).monolithic:  # no coupling error: nothing to estimate
        return []
    knob, _, values = companion_knobs(setting.algorithm, setting.step,
                                      setting.tolerance)
    if knob == "step":
        return [replace(setting, step=v) for v in values]
    return [replace(setting, tolerance=v) for v in values]


def extra_companions(settings: list[Setting]) -> list[Setting]:
    """The companions that are not settings of the sweep."""
    have = set(settings)
    return list(dict.fromkeys(c for s in settings for c in companion_settings(s) if c not in have))


def _series(runs_dir: Path, setting: Setting):
    """(times, columns) of a completed run's CSV, or None."""
    from ...cosim.results import read_result_csv
    csv, side = runs_dir / f"{setting.label}.csv", runs_dir / f"{setting.label}.json"
    try:
        if json.loads(side.read_text()).get("status") != "completed":
            return None
        names, rows = read_result_csv(csv)
    except (OSError, ValueError):
        return None
    return rows[:, 0], {n: rows[:, k + 1] for k, n in enumerate(names)}


def add_estimates(outcomes: list[Outcome], metric, runs_dir: Path) -> None:
    """Set outcome.extra["estimated_error"] (None with extra["estimate_reason"] when there is
    none) for every completed run."""
    runs_dir = Path(runs_dir)
    for o in outcomes:
        if o.status != "completed" and not o.unstable and not o.events_differ:
            continue
        s = o.setting
        if traits(s.algorithm).monolithic:
            o.extra["estimated_error"] = None
            o.extra["estimate_reason"] = "no coupling error (the FMUs as one ODE)"
            continue
        series = [_series(runs_dir, x) for x in [s] + companion_settings(s)]
        if any(x is None for x in series):
            o.extra["estimated_error"] = None
            o.extra["estimate_reason"] = "a companion run stopped or is missing"
            continue
        knob, ratio, _ = companion_knobs(s.algorithm, s.step, s.tolerance)
        est = richardson(metric, series, ratio, knob,
                         *order_rule(s.algorithm, s.extrapolation, s.taylor))
        o.extra["estimated_error"] = est.error if est.ok else None
        if not est.ok:
            o.extra["estimate_reason"] = est.reason


def estimate_ratio(o: Outcome) -> float:
    """estimate / true error of a run, nan without both."""
    est = o.extra.get("estimated_error")
    if est is None or not o.ok or o.error <= 0:
        return math.nan
    return est / o.error
