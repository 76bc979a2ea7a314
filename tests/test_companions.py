"""Companion runs in a worker process beside the main run (crankfmu.cosim.companions): the
estimate and the `--target` search get the same numbers wherever a companion ran, and a worker
left running is stopped, not waited for."""
from __future__ import annotations

import time
from pathlib import Path

import pytest

from tests.conftest import SCENARIOS
from tests.test_sweep import kill_9_mid_run, spinner
from crankfmu.cosim.companions import Companions
from crankfmu.cosim.runner import RunOptions, run_companion, run_scene
from crankfmu.cosim.target import search
from crankfmu.system.load import load_scene


def _short_servo_press():
    scene = load_scene(SCENARIOS / "servo_press.toml")
    scene.stop_time = 0.3  # s: the run-up; enough steps for a Richardson difference
    scene.master.extrapolation = 1
    return scene


def test_a_companion_in_a_worker_gives_the_series_it_gives_here(fmu_dir):
    """A run's numbers are a function of its scene and FMU files: bit-identical series."""
    scene = _short_servo_press()
    here = run_companion(scene, fmu_dir)
    with Companions(2) as pool:
        there = pool.submit(run_companion, scene, fmu_dir).result()
    times_here, columns_here = here.series
    times_there, columns_there = there.series
    assert times_here.tolist() == times_there.tolist()
    assert columns_here.keys() == columns_there.keys()
    for name in columns_here:
        assert columns_here[name].tolist() == columns_there[name].tolist(), name


def test_the_estimate_is_the_same_with_the_companion_beside_the_run(fmu_dir):
    scene = _short_servo_press()
    estimates = [run_scene(scene, RunOptions(fmu_dir=fmu_dir, progress=False, estimate=True,
                                             jobs=jobs)).estimate for jobs in (1, 2)]
    assert estimates[0].ok and estimates[0].error > 0
    assert estimates[0].error == estimates[1].error
    assert estimates[0].differences == estimates[1].differences


def test_the_target_search_chooses_the_same_run_with_workers(fmu_dir):
    scene = _short_servo_press()
    (result_1, report_1), (result_2, report_2) = (search(scene, 1e-3, fmu_dir, jobs)
                                                  for jobs in (1, 2))
    assert (report_1.algorithm, report_1.step) == (report_2.algorithm, report_2.step)
    assert report_1.estimate.error == report_2.estimate.error
    assert sorted(r[2] for r in report_1.runs) == sorted(r[2] for r in report_2.runs)


def _sleep(seconds: float, started: str) -> float:
    Path(started).touch()
    time.sleep(seconds)
    return seconds


def test_an_abandoned_worker_is_stopped_not_waited_for(tmp_path):
    t0 = time.perf_counter()
    pool = Companions(2)
    started = tmp_path / "started"
    pending = pool.submit(_sleep, 60.0, str(started))
    while not started.exists() and time.perf_counter() - t0 < 60:  # the worker sleeps
        time.sleep(0.01)
    pool.close(abandon=True)
    pending.cancel()
    # a hang would wait out the 60 s sleep; the worker's start-up and termination take ~1 s
    assert time.perf_counter() - t0 < 20.0


def test_a_run_that_stops_does_not_wait_for_its_companion(fmu_dir, monkeypatch):
    """The main run fails at once; its companion (30 s of the press, several seconds of work)
    is stopped with it: run_scene raises the run's error without waiting it out."""
    import pytest

    from crankfmu.cosim import runner
    scene = _short_servo_press()
    scene.stop_time = 30.0

    def fail(*args, **kwargs):
        raise runner.RunError("the main run stopped", None)
    monkeypatch.setattr(runner, "_step", fail)  # the stepping (cosim.runner._step)
    t0 = time.perf_counter()
    with pytest.raises(runner.RunError, match="the main run stopped"):
        run_scene(scene, RunOptions(fmu_dir=fmu_dir, progress=False, estimate=True, jobs=2))
    # the companion alone takes ~10 s here (60000 steps of 0.5 ms); start-up and stop ~1 s
    assert time.perf_counter() - t0 < 5.0


@pytest.mark.skipif(not Path("/proc/self/stat").is_file(), reason="reads /proc (Linux)")
@pytest.mark.parametrize("start_method", ["fork", "spawn"])
def test_kill_9_of_a_run_ends_its_companion_worker(tmp_path, fmu_dir, start_method,
                                                   short_tmp):
    """`crankfmu run --jobs 2` runs its estimate's companion in a worker; killed with kill -9
    mid-run, the run leaves no process and no temporary folder behind within 30 s (a loaded
    machine's bound): the worker ends when the pipe only its parent writes to closes
    (cosim/workers.py), as a sweep's workers do. Before, that worker (the standard library's
    pool, spawned) went on with its companion run and waited on its task queue for good."""
    scene = spinner(tmp_path, stop=200.0)  # a run of seconds: killed mid-run
    _, left, tmp = kill_9_mid_run(["run", str(scene), "--jobs", "2", "--fmus",
                                   str(fmu_dir), "--out", str(tmp_path / "out"),
                                   "--no-progress"], short_tmp, start_method, workers=1)
    assert left == [], left
    assert not [p.name for p in tmp.iterdir() if p.name.startswith("crankfmu-")]
