"""`crankfmu run SCENE --target TOL`: choose master, extrapolation and step for a requested
global error without a reference, from the error estimate (cosim/estimate.py).

Fixed-step masters: two runs at a coarse step h0 = the scene's step x START_FACTOR and h0/2
give a first estimate (the design order p0 = extrapolation + 1); the step h that would meet
target x SAFETY is predicted from it (as h0 / 2^k, so every step is a rung of one ladder) and
run with its companions 2h and 4h (those not run yet); the run's estimate is Richardson from
those two coarser runs with the order observed within [p0, p0 + 1] (cosim.estimate.richardson,
coarse_bounds: the search's own runs are the companions, at no extra cost; `crankfmu run`
uses a finer companion instead, which was right more often but would cost another run here).
The search stops at the first run whose estimate meets the target, else predicts again from
it. Typically three runs (two of them coarse) when the prediction lands two halvings below the
start, five when it jumps further. No run is repeated: the accepted run is written as it ran.
(An estimate from the jump itself, h0/2 to h0/32, trusted the coarse runs' order: on the servo
press it was 70x too low.)
With jobs > 1 each round's coarser runs execute in a worker process beside the finest, which
runs here (cosim/companions.py): the same runs and the same choice, in the wall time of the
slower side.
Candidates, in order: the scene's master with extrapolation 2, then Gauss-Seidel with
extrapolation 2 and 1 (the next is tried when one cannot meet the target). A variable-step
master in the scene is searched over its tolerance instead (companion at a tenth of it).

It cannot meet the target when every candidate stops (diverges, events differ between rungs) or
its estimate stops falling with the step (the FMUs' tolerance floor, an input sampled off the
step grid), or the step would fall below MIN_STEP_FACTOR x the scene's step; it says which.
"""
from __future__ import annotations

import copy
import math
import time
from dataclasses import dataclass, field

from ..errors import CrankfmuError

from .estimate import (Estimate, coarse_bounds, companion_knobs, nominal_order,
                       recorder_series, richardson, richardson_steps, scene_metric,
                       with_metric_record)

START_FACTOR = 128.0     # the first step, x the scene's step: coarse runs are cheap where the
                         # cost follows the step; an unstable start costs a run (measured
                         # against 32 in benchmarks/target.py: fewer runs on most scenes)
MIN_STEP_FACTOR = 1 / 64  # the finest step tried, x the scene's step
SAFETY = 0.5             # aim the estimate at this fraction of the target
MAX_TOLERANCE_TRIES = 6  # variable-step master: tolerance updates
MAX_STEP_RUNS = 8        # fixed-step master: runs per candidate
MAX_HALVINGS = 4         # the largest jump of the step at once: / 2^4
MIN_START_STEPS = 16     # the coarse start takes at least this many steps


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


def search(scene, target: float, fmu_dir=None, jobs: int = 1):
    """(RunResult of the chosen run with its estimate, TargetReport); raises TargetNotMet
    with the report's reasons when no candidate meets the target. `jobs` > 1: the companions
    of each run execute in worker processes beside it (cosim/companions.py)."""
    from ..masters import MASTERS
    from .companions import Companions
    if not (target > 0 and math.isfinite(target)):
        raise ValueError(f"--target must be a positive number, got {target!r}")
    scene = with_metric_record(scene)
    report = TargetReport(target)
    wall = time.perf_counter()
    pool = Companions(jobs)  # its workers start while the FMUs are checked
    try:
        fmu_dir = _built_fmus(scene, fmu_dir)
        for algorithm, extrapolation in candidates(scene):
            variable = bool(getattr(MASTERS.get(algorithm), "variable_step", False))
            walk = _tolerance_walk if variable else _step_ladder
            found = walk(scene, algorithm, extrapolation, target, fmu_dir, report, pool)
            if found is not None:
                result, est, trial = found
                report.met = True
                report.algorithm, report.extrapolation = algorithm, extrapolation
                report.step, report.tolerance = trial.master.step, trial.master.tolerance
                report.estimate = est
                result.estimate = est
                return result, report
    finally:
        pool.close(abandon=True)  # a companion still running is of no use any more
        report.wall_seconds = time.perf_counter() - wall
    raise TargetNotMet(f"no setting met the estimated error {target:g}: " +
                       "; ".join(report.reasons))


def _built_fmus(scene, fmu_dir):
    """The FMU folder, with every FMU of the scene built: the workers load them, and two
    processes must not build into one folder at once."""
    from ..system.wiring import default_fmu_dir, resolve_fmu
    from pathlib import Path
    fmu_dir = Path(fmu_dir) if fmu_dir is not None else default_fmu_dir(scene)
    for name in scene.components:
        resolve_fmu(scene, name, fmu_dir)
    return fmu_dir


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


def _step_ladder(scene, algorithm, extrapolation, target, fmu_dir, report, pool):
    """The step search (module docstring); (result, estimate, trial) or None. Steps are
    h0 / 2^k; `rungs` maps k to the run's (series, result)."""
    metric = scene_metric(scene)
    label = f"{algorithm}, extrapolation {extrapolation}"
    nominal, bounds = nominal_order(extrapolation), coarse_bounds(extrapolation)
    h_min = scene.master.step * MIN_STEP_FACTOR
    # at least MIN_START_STEPS steps over the run: a step longer than the run is no step
    # (a power of 2 x the scene's step, so the steps tried are those of the accuracy sweep)
    h0 = scene.master.step * START_FACTOR
    while h0 > scene.master.step and h0 > (scene.stop_time - scene.start_time) / MIN_START_STEPS:
        h0 /= 2.0

    def run(ks):
        return _run_rungs(scene, algorithm, extrapolation, h0, ks, fmu_dir, report, pool)

    rungs: dict[int, tuple] = {}
    k0, ks = 0, [0, 1]  # k0: the coarsest rung that ran (a coarse start that stops moves it down)
    while ks:  # two coarse runs: a first estimate with the design order
        if h0 / 2 ** max(ks) < h_min:
            return _fail(report, f"{label}: the step would fall below {h_min:g} s")
        for k, ran in sorted(run(ks).items()):
            if isinstance(ran, str) and k == k0:
                k0 += 1
            elif isinstance(ran, str):
                return _fail(report, f"{label}: {ran}")
            else:
                rungs[k] = ran
        ks = [k for k in (k0, k0 + 1) if k not in rungs]
    est = richardson_steps(metric, [(h0 / 2 ** k, rungs[k][0]) for k in (k0, k0 + 1)], nominal)
    k_run, last_error = k0 + 1, math.inf
    for _ in range(MAX_STEP_RUNS):
        # the next run: the step predicted to meet target x SAFETY, at least two halvings
        # below the coarsest rung, so that its companions (2h, 4h) are rungs too
        k_new = max(k0 + 2, k_run + _halvings(est, target) if est.ok else k_run + 1)
        if h0 / 2 ** k_new < h_min * (1 - 1e-9):
            return _fail(report, f"{label}: the step would fall below {h_min:g} s "
                                 f"({MIN_STEP_FACTOR:g} x the scene's step)")
        ran = run([k for k in (k_new - 2, k_new - 1, k_new) if k not in rungs])
        stopped = [r for r in ran.values() if isinstance(r, str)]
        if stopped:
            return _fail(report, f"{label}: {stopped[0]}")
        rungs.update(ran)
        k_run = k_new
        est = richardson(metric, [rungs[k][0] for k in (k_new, k_new - 1, k_new - 2)], 2.0,
                         "step", nominal, bounds)  # the estimator of `crankfmu run`
        h = h0 / 2 ** k_new
        if est.ok and est.error <= target:
            # the companions are the search's own runs at 2h and 4h
            est.companion_seconds = sum(rungs[k][1].wall_seconds for k in (k_new - 1, k_new - 2))
            return rungs[k_new][1], est, _trial(scene, algorithm, extrapolation, step=h)
        if est.ok and est.error >= 0.8 * last_error:
            return _fail(report, f"{label}: the estimate stopped falling with the step "
                                 f"({last_error:.2e}, then {est.error:.2e} at {h:g} s): the "
                                 f"FMUs' tolerance floor or an input sampled off the step grid "
                                 f"limits the error")
        if est.ok:
            last_error = est.error
    return _fail(report, f"{label}: {MAX_STEP_RUNS} estimates without meeting the target")


def _run_rungs(scene, algorithm, extrapolation, h0, ks, fmu_dir, report, pool) -> dict:
    """Runs at the steps h0 / 2^k, k in ks: the finest here (the one the search may accept and
    write), the others in the pool's workers beside it (cosim/companions.py). {k: (series,
    result)}, or for a run that stopped {k: the reason}."""
    finest = max(ks)
    from .runner import run_companion
    pending = {k: pool.submit(run_companion, _trial(scene, algorithm, extrapolation,
                                                    step=h0 / 2 ** k), fmu_dir)
               for k in ks if k != finest}
    ran = {finest: _rung(scene, algorithm, extrapolation, h0 / 2 ** finest, fmu_dir, report)}
    for k, companion in pending.items():
        done = companion.result()
        report.runs.append((algorithm, extrapolation, h0 / 2 ** k, scene.master.tolerance,
                            done.wall_seconds))
        ran[k] = (done.series, done) if done.series is not None else \
            f"the run at step {h0 / 2 ** k:g} s stopped: {done.reason}"
    return ran


def _rung(scene, algorithm, extrapolation, h, fmu_dir, report):
    """(series, result) of a run at step h, or the reason it stopped."""
    result, why = _run(_trial(scene, algorithm, extrapolation, step=h), fmu_dir, report)
    if result is None:
        return f"the run at step {h:g} s stopped: {why}"
    return recorder_series(result.recorder), result


def _fail(report, reason: str):
    report.reasons.append(reason)
    return None


def _halvings(est: Estimate, target: float) -> int:
    """Halvings of the step that bring `est` to target x SAFETY at its order (1..MAX_HALVINGS)."""
    if est.error <= 0:  # the runs agree exactly: halve, the next estimate observes the order
        return 1
    k = math.ceil(math.log2(est.error / (SAFETY * target)) / est.order - 1e-9)
    return min(MAX_HALVINGS, max(1, k))


def _tolerance_walk(scene, algorithm, extrapolation, target, fmu_dir, report, pool):
    """A variable-step master: tolerance from the target, tightened by the estimate's ratio;
    each run's companion (a tenth of its tolerance) runs in the pool beside it."""
    from .runner import estimate_run, submit_companions
    label = f"{algorithm}, extrapolation {extrapolation}"
    tol = target
    for _ in range(MAX_TOLERANCE_TRIES):
        trial = _trial(scene, algorithm, extrapolation, tolerance=tol)
        pending = submit_companions(trial, fmu_dir, pool)
        result, why = _run(trial, fmu_dir, report)
        if result is None:
            for _, companion in pending:
                companion.cancel()
            report.reasons.append(f"{label}: the run at tolerance {tol:g} stopped: {why}")
            return None
        est = estimate_run(trial, recorder_series(result.recorder), fmu_dir, pending)
        report.runs.append((algorithm, extrapolation, trial.master.step, pending[0][0],
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
