"""`crankfmu run SCENE --target TOL`: choose master, extrapolation and step for a requested
global error without a reference, from the error estimate (cosim/estimate.py).

Fixed-step masters walk a ladder of steps h0, h0/2, h0/4, ... from a coarse start (the scene's
step x START_FACTOR): each rung is the companion of the next two, so the estimate of a rung
(Richardson with the order observed from the two rungs above) costs no extra run. The ladder
goes down one halving at a time (a skipped rung would have to run anyway as the companion of
the next) and stops at the first rung whose estimate meets target x SAFETY. The whole ladder costs about 2x its last rung (a geometric sum).
Candidates, in order: the scene's master with extrapolation 2, then Gauss-Seidel with
extrapolation 2 and 1 (the next is tried when one cannot meet the target). A variable-step
master in the scene is searched over its tolerance instead (companion at a tenth of it).

It cannot meet the target when every candidate stops (diverges, events differ between rungs) or
its estimate stops falling with the step (the FMUs' tolerance floor, an input sampled off the
step grid), or the step would fall below MIN_STEP_FACTOR x the scene's step; it says which.
"""
from __future__ import annotations

import copy

from ..errors import CrankfmuError
import math
import time
from dataclasses import dataclass, field

from .estimate import (Estimate, companion_knobs, order_rule, recorder_series, richardson,
                       scene_metric, with_metric_record)

START_FACTOR = 32.0      # the ladder's first step, x the scene's step (accuracy_tables: no master
                         # became unstable on the hybrid scenes within 32 x)
MIN_STEP_FACTOR = 1 / 64  # the finest step tried, x the scene's step
SAFETY = 0.5             # aim the estimate at this fraction of the target
MAX_TOLERANCE_TRIES = 6  # variable-step master: tolerance updates


class TargetNotMet(CrankfmuError):
    """No setting met the target; the message says what was tried and why it failed."""


@dataclass
class TargetReport:
    target: float
    met: bool = False
    algorithm: str = ""
    extrapolation: int = 0
    step: float = math.nan
    tolerance: float = math.nan
    estimate: Estimate | None = None
    runs: list = field(default_factory=list)  # (algorithm, extrapolation, step, tol, seconds)
    wall_seconds: float = 0.0
    reasons: list = field(default_factory=list)

    def to_json(self) -> dict:
        return {"target": self.target, "met": self.met, "algorithm": self.algorithm,
                "extrapolation": self.extrapolation, "step": self.step,
                "tolerance": self.tolerance, "search_wall_seconds": self.wall_seconds,
                "runs": [list(r) for r in self.runs], "reasons": self.reasons}


def candidates(scene) -> list[tuple[str, int]]:
    first = (scene.master.algorithm, 2)
    return list(dict.fromkeys([first, ("gauss-seidel", 2), ("gauss-seidel", 1)]))


def search(scene, target: float, fmu_dir=None):
    """(RunResult of the chosen run with its estimate, TargetReport); raises TargetNotMet
    with the report's reasons when no candidate meets the target."""
    from .masters import MASTERS
    if not (target > 0 and math.isfinite(target)):
        raise ValueError(f"--target must be a positive number, got {target!r}")
    scene = with_metric_record(scene)
    report = TargetReport(target)
    wall = time.perf_counter()
    try:
        for algorithm, extrapolation in candidates(scene):
            variable = bool(getattr(MASTERS.get(algorithm), "variable_step", False))
            walk = _tolerance_walk if variable else _step_ladder
            found = walk(scene, algorithm, extrapolation, target, fmu_dir, report)
            if found is not None:
                result, est, trial = found
                report.met = True
                report.algorithm, report.extrapolation = algorithm, extrapolation
                report.step, report.tolerance = trial.master.step, trial.master.tolerance
                report.estimate = est
                result.estimate = est
                return result, report
    finally:
        report.wall_seconds = time.perf_counter() - wall
    raise TargetNotMet(f"no setting met the estimated error {target:g}: " +
                       "; ".join(report.reasons))


def _trial(scene, algorithm, extrapolation, step=None, tolerance=None):
    trial = copy.deepcopy(scene)
    m = trial.master
    m.algorithm, m.extrapolation = algorithm, extrapolation
    if step is not None:
        m.step = step
    if tolerance is not None:
        m.tolerance = tolerance
    return trial


def _run(trial, fmu_dir, report):
    """(RunResult, None) or (None, reason)."""
    from .runner import RunError, RunOptions, check_run_size, run_scene
    m = trial.master
    t0 = time.perf_counter()
    try:
        check_run_size(trial)
        result = run_scene(trial, RunOptions(out=None, fmu_dir=fmu_dir, progress=False))
        return result, None
    except RunError as err:
        return None, str(err)
    except Exception as err:  # a refused setting (SceneError: too many steps, a master's check)
        from ..errors import CrankfmuError
        if not isinstance(err, CrankfmuError):
            raise
        return None, str(err)
    finally:
        report.runs.append((m.algorithm, m.extrapolation, m.step, m.tolerance,
                            time.perf_counter() - t0))


def _step_ladder(scene, algorithm, extrapolation, target, fmu_dir, report):
    """The ladder of steps (module docstring); (result, estimate, trial) or None."""
    metric = scene_metric(scene)
    label = f"{algorithm}, extrapolation {extrapolation}"
    h_min = scene.master.step * MIN_STEP_FACTOR
    h = scene.master.step * START_FACTOR
    rungs = []  # (step, series, result)
    last_estimate, count = math.inf, 0
    while h >= h_min * (1 - 1e-9):
        trial = _trial(scene, algorithm, extrapolation, step=h)
        result, why = _run(trial, fmu_dir, report)
        if result is None:
            if rungs:  # a finer step stopped after coarser ones ran: not a coarse instability
                report.reasons.append(f"{label}: the run at step {h:g} s stopped: {why}")
                return None
            h /= 2.0  # a coarse start that is unstable: start finer
            continue
        rungs.append((h, recorder_series(result.recorder), result))
        count += 1
        if len(rungs) >= 3:
            est = richardson(metric, [r[1] for r in rungs[-1:-4:-1]], 2.0, "step",
                             *order_rule(False, extrapolation))
            if not est.ok:
                if count >= 5:  # finer rungs did not settle it (events keep differing)
                    report.reasons.append(f"{label}: no estimate at step {h:g} s: {est.reason}")
                    return None
            elif est.error <= target * SAFETY or (est.error <= target and h <= h_min * 1.5):
                return result, est, trial
            elif est.error >= last_estimate * 0.8 and count >= 4:
                report.reasons.append(
                    f"{label}: the estimate stopped falling with the step ({last_estimate:.2e} "
                    f"at {2 * h:g} s, {est.error:.2e} at {h:g} s): the FMUs' tolerance floor "
                    f"or an input sampled off the step grid limits the error")
                return None
            else:
                last_estimate = est.error
                rungs = rungs[-2:]  # the next rung's companions
            if not est.ok:
                rungs = rungs[-2:]
        h = rungs[-1][0] / 2.0
    report.reasons.append(f"{label}: the step would fall below {h_min:g} s "
                          f"({MIN_STEP_FACTOR:g} x the scene's step)")
    return None


def _tolerance_walk(scene, algorithm, extrapolation, target, fmu_dir, report):
    """A variable-step master: tolerance from the target, tightened by the estimate's ratio."""
    from .runner import estimate_run
    label = f"{algorithm}, extrapolation {extrapolation}"
    tol = target
    for _ in range(MAX_TOLERANCE_TRIES):
        trial = _trial(scene, algorithm, extrapolation, tolerance=tol)
        result, why = _run(trial, fmu_dir, report)
        if result is None:
            report.reasons.append(f"{label}: the run at tolerance {tol:g} stopped: {why}")
            return None
        est = estimate_run(trial, recorder_series(result.recorder), fmu_dir)
        _, _, (companion,) = companion_knobs(True, trial.master.step, tol)
        report.runs.append((algorithm, extrapolation, trial.master.step, companion,
                            est.companion_seconds))
        if not est.ok:
            report.reasons.append(f"{label}: no estimate at tolerance {tol:g}: {est.reason}")
            return None
        if est.error <= target:
            return result, est, trial
        tol *= max(0.01, min(0.5, SAFETY * target / est.error))
    report.reasons.append(f"{label}: {MAX_TOLERANCE_TRIES} tolerances tried down to {tol:g}")
    return None


def write_chosen(scene, result, report: TargetReport, out, plot_png: bool = False) -> None:
    """Write the chosen run as `crankfmu run` would (CSV, sidecar with "error_estimate" and
    "target", PNG on request) and point `result` at the files."""
    from pathlib import Path

    from .results import plot, write_csv, write_sidecar
    from .runner import plot_roles
    out = Path(out)
    write_csv(out, result.recorder)
    result.metadata["error_estimate"] = report.estimate.to_json()
    result.metadata["target"] = report.to_json()
    result.csv, result.sidecar = out, out.with_suffix(".json")
    write_sidecar(result.sidecar, result.metadata)
    if plot_png:
        result.png = out.with_suffix(".png")
        m = result.metadata["master"]
        plot(result.png, result.recorder, f"{scene.name}: {m['algorithm']}, step {m['step']:g} s"
             f" (target {report.target:g})", plot_roles(scene))
