"""The error estimate of a run (crankfmu.cosim.estimate) and `--target` (crankfmu.cosim.target)
on the two-mass oscillator of test_masters.py, whose exact solution is known (both FMUs step
exactly, so the whole error is the coupling's): the estimate is compared with the true error in
the same metric (`max`: max_t |w - w_exact| / mean|w_exact| over both speeds).

Measured (stop 1 s, record 10 ms), estimate / true error, the companion at h/2:
    jacobi 0        1.029 (5 ms), 1.015 (2.5 ms), 1.008 (1.25 ms)
    jacobi 2, gauss-seidel 0/1/2, iterative 2: 0.996-1.001 at 5, 2.5 and 1.25 ms
(with companions at 2h and 4h and the order observed, the form the --target search uses:
jacobi 0 0.73 / 0.82 / 0.91, the others 0.99-1.003).
"""
from __future__ import annotations

import csv

import pytest

from crankfmu.cosim.estimate import scene_metric
from crankfmu.cosim.metrics import ReferenceSamples
from crankfmu.cosim.runner import RunOptions, run_scene
from crankfmu.cosim.target import TargetNotMet, search
from crankfmu.system.load import load_scene
from tests.test_masters import OSCILLATOR, exact_speeds, scene_file

SPEEDS = ["r1.flange_w", "r2.w"]


def oscillator(tmp_path, master: dict, stop: float = 1.0):
    path = scene_file(tmp_path, master, OSCILLATOR, stop, 1e-2)
    path.write_text(path.read_text().replace('"r1.E", "r2.E"', "").replace(', ]', "]"))
    scene = load_scene(path)
    assert scene.record == SPEEDS
    return scene


def true_error(scene, recorder) -> float:
    """The scene's metric against the exact solution at the run's record times."""
    t = recorder.rows[:, 0]
    w = exact_speeds(OSCILLATOR, t)
    ref = ReferenceSamples(t, {SPEEDS[0]: w[:, 0], SPEEDS[1]: w[:, 1]})
    return scene_metric(scene).error(t, {n: recorder.column(n) for n in SPEEDS}, ref)


@pytest.mark.parametrize("algorithm, extrapolation", [
    ("jacobi", 0), ("jacobi", 2), ("gauss-seidel", 0), ("gauss-seidel", 1),
    ("gauss-seidel", 2), ("iterative", 2)])
def test_estimate_tracks_the_true_error_across_steps_and_orders(tmp_path, fmu_dir,
                                                                algorithm, extrapolation):
    truths, estimates = [], []
    for h in (2.5e-3, 1.25e-3):
        master = {"algorithm": algorithm, "step": h, "extrapolation": extrapolation}
        if algorithm == "iterative":
            master["tolerance"] = 1e-10  # iterated to convergence (test_masters.py)
        scene = oscillator(tmp_path, master)
        result = run_scene(scene, RunOptions(out=tmp_path / "osc.csv", fmu_dir=fmu_dir,
                                             progress=False, estimate=True))
        truths.append(true_error(scene, result.recorder))
        estimates.append(result.estimate.error)
        # Within 10 % (the issue asks for a factor 3): Richardson's remainder is the next
        # error term, O(w h) relative to the leading one (w h = 0.044 at 2.5 ms, w = 17.6
        # rad/s) times its constant; measured up to 0.015 (Jacobi/0), 0.002 for the others.
        assert 0.9 < estimates[-1] / truths[-1] < 1.1, (h, truths, estimates)
    # tracking: halving the step divides estimate and truth alike (by 2^order)
    assert estimates[0] / estimates[1] == pytest.approx(truths[0] / truths[1], rel=0.15)


def test_estimate_is_in_the_sidecar(tmp_path, fmu_dir):
    import json
    scene = oscillator(tmp_path, {"algorithm": "gauss-seidel", "step": 5e-3,
                                  "extrapolation": 1}, stop=0.3)
    result = run_scene(scene, RunOptions(out=tmp_path / "osc.csv", fmu_dir=fmu_dir,
                                         progress=False, estimate=True))
    side = json.loads((tmp_path / "osc.json").read_text())["error_estimate"]
    assert side["estimated_error"] == result.estimate.error > 0
    # one finer companion (h/2) with the design order extrapolation + 1
    assert side["knob"] == "step" and side["ratio"] == 0.5
    assert side["order_source"] == "nominal" and side["order"] == 2.0
    # the metric it estimates, named (before: a bare number), and so the terminal line
    assert side["metric"] == "max" and side["metric_description"] == \
        "max_t |y - y_ref| / mean|y_ref| over r1.flange_w, r2.w"
    from crankfmu.cosim.estimate import format_estimate
    assert format_estimate(result.estimate).startswith(
        f"estimated error {result.estimate.error:.2e} of r1.flange_w, r2.w "
        "(max_t |y - y_ref| / mean|y_ref|): Richardson from a companion at 0.5 x the step")


def test_accuracy_column_matches_the_run_estimate(tmp_path, fmu_dir):
    """The sweep's estimated_error (companions from the sweep's own runs' CSVs) is the number
    `crankfmu run` reports (companions run in process): runs are deterministic and CSVs
    hold repr floats, so they agree to round-off (1e-12 relative)."""
    from crankfmu.studies.accuracy import AccuracyOptions, run_accuracy
    scene = oscillator(tmp_path, {"algorithm": "gauss-seidel", "step": 5e-3,
                                  "extrapolation": 2}, stop=0.3)
    result = run_accuracy(scene, AccuracyOptions(
        out_dir=tmp_path / "acc", algorithms=["gauss-seidel"], extrapolations=[2],
        steps=[5e-3], fmu_dir=fmu_dir, progress=False, jobs=1, plot=True))
    with open(result.csv) as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == 1  # the companion (2.5 ms) is not a row of the table
    run = run_scene(scene, RunOptions(out=None, fmu_dir=fmu_dir, progress=False,
                                      estimate=True))
    assert float(rows[0]["estimated_error"]) == pytest.approx(run.estimate.error, rel=1e-12)
    assert (tmp_path / "acc" / "estimate_vs_error.png").is_file()


def test_target_is_met_without_a_reference(tmp_path, fmu_dir):
    scene = oscillator(tmp_path, {"algorithm": "gauss-seidel", "step": 5e-3}, stop=0.5)
    progress = []
    result, report = search(scene, 1e-4, fmu_dir, echo=progress.append)
    assert report.met and report.estimate.error <= 1e-4
    # a line per run and per estimate, the last estimate the accepted one's
    assert sum(line.startswith("run ") for line in progress) == len(report.runs)
    assert progress[-1] == (f"  estimated error at step {report.step:g} s: "
                            f"{report.estimate.error:.2e} (target 0.0001)")
    chosen = result.metadata["master"]  # the rotors offer output derivatives: Taylor first
    assert (chosen["algorithm"], chosen["taylor"]) == ("gauss-seidel", 3)
    # the truth, from the exact solution the search never saw
    assert true_error(scene, result.recorder) <= 1e-4


def test_target_that_cannot_be_met_says_why(tmp_path, fmu_dir):
    # 1e-14 is below what a step of 5e-3/64 s gives (about 1e-9 at extrapolation 2)
    scene = oscillator(tmp_path, {"algorithm": "gauss-seidel", "step": 5e-3}, stop=0.05)
    with pytest.raises(TargetNotMet, match=r"step would fall below|stopped falling"):
        search(scene, 1e-14, fmu_dir)
