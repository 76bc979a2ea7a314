"""`crankfmu run SCENE --target TOL`: choose master, coupling (extrapolation or a Taylor
coupling's order) and step for a requested global error without a reference, from the error
estimate (cosim/estimate.py).

Fixed-step masters: the steps tried are rungs h0 / 2^k of one ladder, h0 = the scene's step x
START_FACTOR (halved until the run has MIN_START_STEPS steps). Each round runs a candidate
step h and its companion h/2 and estimates the candidate's error as `crankfmu run` does
(Richardson with the design order p0 = extrapolation + 1, or taylor + 1:
cosim.estimate.richardson). The
search accepts the first candidate whose estimate meets the target and writes that run as it
ran (no run is repeated); otherwise it predicts the halvings that would bring the error to
target x SAFETY (with the order observed from three consecutive rungs once there are three,
else p0) and runs the next round. A candidate one halving down costs one new run (its
companion); a coarse start that stops moves the ladder down. Typically two runs when the start
already meets the target, three or four otherwise.
(The search used to estimate from the coarser rungs 2h and 4h, which costs no extra run but was
right less often: on the conventional press and the clutch hammer it accepted runs 1.7x and
1.4x above the target. The companion at h/2 is the form measured within 3x in 96 % of the
sweeps' runs: docs/error_estimate.md.)
With jobs > 1 a round's two runs go side by side, the finer (slower) here and the other in a
worker process (cosim/companions.py): the same runs and the same choice, in the wall time of
the slower one.
Candidates, in order: where every FMU with connected outputs offers their derivatives
(cosim/coupling.py), the scene's master with a Taylor coupling of order TAYLOR_ORDER (Gauss-Seidel
if that master does not take the option); then the scene's master with extrapolation 2, then
Gauss-Seidel with extrapolation 2 and 1 (the next is tried when one cannot meet the target). A
variable-step master in the scene is searched over its tolerance instead (companion at a tenth
of it).

It cannot meet the target when every candidate stops (diverges, events differ between rungs) or
its estimate stops falling with the step (the FMUs' tolerance floor, events that move with the
step), or the step would fall below MIN_STEP_FACTOR x the scene's step; it says which.
"""
from __future__ import annotations

import copy
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field

from ..errors import CrankfmuError

from .estimate import (STEP_RATIO, Estimate, difference, order_rule, richardson,
                       scene_metric, with_metric_record)

START_FACTOR = 32.0      # the first step, x the scene's step (the sweep's coarsest): measured
                         # against 128 on 10 scenes x 2 targets, fewer or as many runs in 19 of
                         # 20 cases (servo press at 1e-3: 4 runs against 6), the same targets met
                         # (benchmarks/target.py --jobs 1 [--start-factor 128])
MIN_STEP_FACTOR = 1 / 64  # the finest step tried, x the scene's step
SAFETY = 0.5             # aim the estimate at this fraction of the target
MAX_TOLERANCE_TRIES = 6  # variable-step master: tolerance updates
MAX_STEP_RUNS = 8        # fixed-step master: rounds (candidate and companion) per candidate
MAX_HALVINGS = 4         # the largest jump of the step at once: / 2^4
MIN_START_STEPS = 16     # the coarse start takes at least this many steps
TAYLOR_ORDER = 3         # the Taylor candidate's order: the servo press's cheapest setting
                         # for 1e-5 (docs/accuracy_tables.md: Gauss-Seidel, taylor 3, 2 ms);
                         # over whole scenes 4 gains little (orders there about 3)


class TargetNotMet(CrankfmuError):
    """No setting met the target; the message says what was tried and why it failed."""


@dataclass
class TargetReport:
    target: float
    met: bool = False
    algorithm: str = ""
    extrapolation: int = 0
    taylor: int = 0
    step: float = math.nan
    tolerance: float = math.nan
    estimate: Estimate | None = None
    runs: list = field(default_factory=list)  # (algorithm, extrapolation, taylor, step,
    #                                               tolerance, seconds)
    wall_seconds: float = 0.0
    reasons: list = field(default_factory=list)
    echo: Callable[[str], None] | None = None  # a line of progress (the command line prints it)

    def add_run(self, algorithm, coupling, step, tolerance, seconds, how="") -> None:
        """coupling: (extrapolation, taylor)."""
        self.runs.append((algorithm, *coupling, step, tolerance, seconds))
        self.say(f"run {len(self.runs)}: {algorithm}, {coupling_text(coupling)}, "
                 f"{how or f'step {step:g} s'}: {seconds:.2f} s")

    def say(self, line: str) -> None:
        if self.echo is not None:
            self.echo(line)

    def say_estimate(self, setting: str, est: Estimate) -> None:
        self.say(f"  estimated error at {setting}: " + (
            f"{est.error:.2e} (target {self.target:g})" if est.ok else f"none ({est.reason})"))

    def to_json(self) -> dict:
        return {"target": self.target, "met": self.met, "algorithm": self.algorithm,
                "extrapolation": self.extrapolation, "taylor": self.taylor, "step": self.step,
                "tolerance": self.tolerance, "search_wall_seconds": self.wall_seconds,
                "runs": [list(r) for r in self.runs], "reasons": self.reasons}


def coupling_text(coupling: tuple[int, int]) -> str:
    extrapolation, taylor = coupling
    return f"taylor {taylor}" if taylor else f"extrapolation {extrapolation}"


def candidates(scene, taylor: int = 0) -> list[tuple[str, tuple[int, int]]]:
    """(algorithm, (extrapolation, taylor)) in the order tried (module docstring); `taylor`:
    the Taylor order the scene's FMUs offer, 0 for none."""
    from ..masters import traits
    first = scene.master.algorithm
    found = []
    if taylor:
        takes = "taylor" in traits(first).options
        found.append((first if takes else "gauss-seidel", (0, taylor)))
    found += [(first, (2, 0)), ("gauss-seidel", (2, 0)), ("gauss-seidel", (1, 0))]
    return list(dict.fromkeys(found))


def search(scene, target: float, fmu_dir=None, jobs: int = 1, echo=None):
    """(RunResult of the chosen run with its estimate, TargetReport); raises TargetNotMet
    with the report's reasons when no candidate meets the target. `jobs` > 1: the companions
    of each run execute in worker processes beside it (cosim/companions.py). `echo`: called
    with a line after each run and each estimate (progress)."""
    from ..masters import traits
    from .companions import Companions
    if not (target > 0 and math.isfinite(target)):
        raise ValueError(f"--target must be a positive number, got {target!r}")
    scene = with_metric_record(scene)
    report = TargetReport(target, echo=echo)
    wall = time.perf_counter()
    pool = Companions(jobs)  # its workers start while the FMUs are checked
    try:
        fmu_dir = _built_fmus(scene, fmu_dir)
        from .coupling import taylor_orders_offered
        offered = taylor_orders_offered(scene, fmu_dir, (TAYLOR_ORDER,))
        for algorithm, coupling in candidates(scene, offered[0] if offered else 0):
            walk = _tolerance_walk if traits(algorithm).variable_step else _step_ladder
            found = walk(scene, algorithm, coupling, target, fmu_dir, report, pool)
            if found is not None:
                result, est, trial = found
                report.met = True
                report.algorithm = algorithm
                report.extrapolation, report.taylor = coupling
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


def _trial(scene, algorithm, coupling, step=None, tolerance=None):
    trial = copy.deepcopy(scene)
    m = trial.master
    m.algorithm, m.extrapolation = algorithm, coupling[0]
    if coupling[1]:
        m.taylor = coupling[1]
    else:  # not set: a master that does not take the option (iterative) would refuse it
        m.options.pop("taylor", None)
    if step is not None:
        m.step = step
    if tolerance is not None:
        m.tolerance = tolerance
    return trial


def _run(trial, fmu_dir, report, how: str = ""):
    """The run of `trial` here: a CompanionRun (result None and a reason if it stopped or its
    setting was refused)."""
    from .runner import run_companion
    done = run_companion(trial, fmu_dir)
    m = trial.master
    report.add_run(m.algorithm, (m.extrapolation, m.taylor), m.step, m.tolerance,
                   done.wall_seconds, how)
    return done


def _step_ladder(scene, algorithm, coupling, target, fmu_dir, report, pool):
    """The step search (module docstring); (result, estimate, trial) or None. Steps are
    h0 / 2^k; `rungs` maps k to the run's (series, result)."""
    metric = scene_metric(scene)
    label = f"{algorithm}, {coupling_text(coupling)}"
    nominal, _ = order_rule(algorithm, *coupling)
    h_min = scene.master.step * MIN_STEP_FACTOR
    # at least MIN_START_STEPS steps over the run: a step longer than the run is no step
    # (a power of 2 x the scene's step, so the steps tried are those of the accuracy sweep)
    h0 = scene.master.step * START_FACTOR
    while h0 > scene.master.step and h0 > (scene.stop_time - scene.start_time) / MIN_START_STEPS:
        h0 /= 2.0
    rungs: dict[int, tuple] = {}
    k, last_error = 0, math.inf  # k: the candidate rung; k + 1 is its companion
    for _ in range(MAX_STEP_RUNS):
        if h0 / 2 ** (k + 1) < h_min * (1 - 1e-9):
            return _fail(report, f"{label}: the step would fall below {h_min:g} s "
                                 f"({MIN_STEP_FACTOR:g} x the scene's step)")
        ran = _run_rungs(scene, algorithm, coupling, h0,
                         [j for j in (k, k + 1) if j not in rungs], fmu_dir, report, pool)
        if isinstance(ran.get(k), str) and not math.isfinite(last_error):
            # an unstable coarse start: below the finest rung that stopped (a companion that
            # ran is kept)
            k = max(j for j, r in ran.items() if isinstance(r, str)) + 1
            rungs.update({j: r for j, r in ran.items() if not isinstance(r, str)})
            continue
        stopped = [r for r in ran.values() if isinstance(r, str)]
        if stopped:
            return _fail(report, f"{label}: {stopped[0]}")
        rungs.update(ran)
        h = h0 / 2 ** k
        est = richardson(metric, [rungs[k][0], rungs[k + 1][0]], 1.0 / STEP_RATIO, "step",
                         nominal)  # the estimator of `crankfmu run`: a companion at h/2
        report.say_estimate(f"step {h:g} s", est)
        if est.ok and est.error <= target:
            est.companion_seconds = rungs[k + 1][1].wall_seconds
            return rungs[k][1], est, _trial(scene, algorithm, coupling, step=h)
        if not est.ok:  # e.g. the companion counts other events: both too coarse
            k += 1
            continue
        if est.error >= 0.8 * last_error:
            return _fail(report, f"{label}: the estimate stopped falling with the step "
                                 f"({last_error:.2e}, then {est.error:.2e} at {h:g} s): the "
                                 f"FMUs' tolerance floor or an error that does not follow a power "
                                 f"of the step (events that move with it) limits the error")
        last_error = est.error
        k += _halvings(est.error, _prediction_order(metric, rungs, k, nominal), target)
    return _fail(report, f"{label}: {MAX_STEP_RUNS} estimates without meeting the target")


def _prediction_order(metric, rungs: dict, k: int, nominal: float) -> float:
    """The order to predict the next step with: observed from rungs k - 1, k, k + 1 when all
    three ran (clamped to [1, nominal + 1]: an order below 1 would predict absurd steps),
    else the design order."""
    if k - 1 not in rungs:
        return nominal
    d_coarse, _ = difference(metric, rungs[k - 1][0], rungs[k][0])
    d_fine, _ = difference(metric, rungs[k][0], rungs[k + 1][0])
    if not (d_coarse > 0 and d_fine > 0 and math.isfinite(d_coarse / d_fine)):
        return nominal
    return min(nominal + 1.0, max(1.0, math.log2(d_coarse / d_fine)))


def _run_rungs(scene, algorithm, coupling, h0, ks, fmu_dir, report, pool) -> dict:
    """Runs at the steps h0 / 2^k, k in ks: the finest (the slowest) here, the others in the
    pool's workers beside it (cosim/companions.py). {k: (series, result)}, or for a run that
    stopped {k: the reason}."""
    from .runner import run_companion
    finest = max(ks)
    pending = {k: pool.submit(run_companion, _trial(scene, algorithm, coupling,
                                                    step=h0 / 2 ** k), fmu_dir)
               for k in ks if k != finest}
    ran = {finest: _rung(scene, algorithm, coupling, h0 / 2 ** finest, fmu_dir, report)}
    for k, companion in pending.items():
        done = companion.result()
        report.add_run(algorithm, coupling, h0 / 2 ** k, scene.master.tolerance,
                       done.wall_seconds)
        ran[k] = _rung_of(done, h0 / 2 ** k)
    return ran


def _rung(scene, algorithm, coupling, h, fmu_dir, report):
    """(series, result) of a run at step h here, or the reason it stopped."""
    return _rung_of(_run(_trial(scene, algorithm, coupling, step=h), fmu_dir, report), h)


def _rung_of(done, h: float):
    if done.result is None:
        return f"the run at step {h:g} s stopped: {done.reason}"
    return done.series, done.result


def _fail(report, reason: str):
    report.reasons.append(reason)
    return None


def _halvings(error: float, order: float, target: float) -> int:
    """Halvings of the step that bring `error` to target x SAFETY at `order`
    (1..MAX_HALVINGS)."""
    if error <= 0:  # the runs agree exactly: halve, the next estimate observes the order
        return 1
    k = math.ceil(math.log2(error / (SAFETY * target)) / order - 1e-9)
    return min(MAX_HALVINGS, max(1, k))


def _tolerance_walk(scene, algorithm, coupling, target, fmu_dir, report, pool):
    """A variable-step master: tolerance from the target, tightened by the estimate's ratio;
    each run's companion (a tenth of its tolerance) runs in the pool beside it."""
    from .runner import estimate_run, submit_companions
    label = f"{algorithm}, {coupling_text(coupling)}"
    tol = target
    for _ in range(MAX_TOLERANCE_TRIES):
        trial = _trial(scene, algorithm, coupling, tolerance=tol)
        pending = submit_companions(trial, fmu_dir, pool)
        done = _run(trial, fmu_dir, report, how=f"tolerance {tol:g}")
        if done.result is None:
            for _, companion in pending:
                companion.cancel()
            report.reasons.append(f"{label}: the run at tolerance {tol:g} stopped: "
                                  f"{done.reason}")
            return None
        result = done.result
        est = estimate_run(trial, done.series, fmu_dir, pending)
        report.add_run(algorithm, coupling, trial.master.step, pending[0][0],
                       est.companion_seconds, how=f"tolerance {pending[0][0]:g} (companion)")
        report.say_estimate(f"tolerance {tol:g}", est)
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
    "target", PNG on request, as one set: results.write_run_set), its trust judged with the
    search's estimate (cosim.trust), and point `result` at the files; `out` None: the
    metadata only, nothing written."""
    from pathlib import Path

    from .results import figure_png, run_figure, write_run_set
    from .runner import plot_roles
    from .trust import judge_result
    assert report.estimate is not None  # the search's accepted estimate (a met target)
    result.estimate = report.estimate
    result.metadata["error_estimate"] = report.estimate.to_json()
    result.metadata["target"] = report.to_json()
    judge_result(scene, result)
    if out is None:
        return
    png = None
    if plot_png:
        m = result.metadata["master"]
        png = figure_png(run_figure(result.recorder, f"{scene.name}: {m['algorithm']}, step "
                                    f"{m['step']:g} s (target {report.target:g})",
                                    plot_roles(scene)))
    result.csv, result.sidecar, result.png = write_run_set(Path(out), result.recorder,
                                                           result.metadata, png)
