"""The accuracy sweep (crankfmu.studies.accuracy, `crankfmu accuracy`): metrics, observed order, the
choice of the cheapest setting, and a short sweep on the servo press producing table, CSV, PNG."""
from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np
import pytest

from crankfmu.studies.accuracy import (Outcome, Setting, cheapest, fewest_steps, make_metric,
                                       observed_order, steady_figures)
from crankfmu.cosim.metrics import MetricError, ReferenceSamples
from crankfmu.studies.accuracy.sweep import load_or_solve_reference, orders

SCENARIOS = Path(__file__).resolve().parents[1] / "scenarios"


@pytest.mark.parametrize("p", [1.0, 2.0, 3.0])
def test_observed_order_recovers_a_known_order(p):
    """e = C h^p exactly: the log-log slope is p to rounding; errors at or below the floor (the
    FMU tolerance regime) and failed runs (inf, nan) are left out of the fit."""
    h = np.array([8e-3, 4e-3, 2e-3, 1e-3, 5e-4])
    e = 3.0 * h ** p
    order, used = observed_order(h, e, floor=0.0)
    assert order == pytest.approx(p, abs=1e-12) and used == 5
    floor = float(e[2])  # the three smallest steps sit at or below the floor
    e_floored = np.maximum(e, floor)
    order, used = observed_order(np.append(h, 1e-2), np.append(e_floored, math.inf), floor)
    assert order == pytest.approx(p, abs=1e-12) and used == 2
    assert math.isnan(observed_order(h[:1], e[:1], 0.0)[0])


def test_observed_order_of_noisy_data_is_the_least_squares_slope():
    h = np.array([4e-3, 2e-3, 1e-3])
    e = h ** 2 * np.array([1.0, 1.1, 1.0])
    # least squares through (log h, log e): symmetric bump in the middle leaves the slope at 2
    assert observed_order(h, e, 0.0)[0] == pytest.approx(2.0, abs=1e-12)


def outcome(alg, step, error, wall, do_steps, status="completed"):
    return Outcome(Setting(alg, 0, step, 1e-8, 1e-6), "step", error, wall, do_steps,
                   status=status)


def test_cheapest_setting_meets_the_target_at_least_wall_time():
    runs = [outcome("jacobi", 1e-3, 2e-3, 0.5, 2000),               # misses the target
            outcome("gauss-seidel", 2e-3, 8e-4, 0.9, 1000),         # meets, slower
            outcome("gauss-seidel", 4e-3, 9e-4, 0.7, 500),          # meets, cheapest
            outcome("iterative", 4e-3, 1e-6, 0.1, 400, status="failed: diverged"),
            outcome("adaptive", 4e-3, 5e-4, 0.8, 300)]              # fewest doSteps
    best = cheapest(runs, target=1e-3)
    assert (best.setting.algorithm, best.setting.step) == ("gauss-seidel", 4e-3)
    assert fewest_steps(runs, 1e-3).setting.algorithm == "adaptive"
    assert cheapest(runs, target=1e-5) is None
    # ties in wall time go to fewer doStep calls
    tie = [outcome("a", 1e-3, 1e-4, 1.0, 900), outcome("b", 1e-3, 1e-4, 1.0, 800)]
    assert cheapest(tie, 1e-3).setting.algorithm == "b"


def test_orders_group_by_master_and_coupling():
    """One order per master, coupling (extrapolation p or Taylor order q) and FMU tolerance."""
    runs = [outcome("jacobi", h, 5.0 * h, 1.0, 1) for h in (4e-3, 2e-3, 1e-3)] + \
           [outcome("gauss-seidel", h, 7.0 * h ** 2, 1.0, 1) for h in (4e-3, 2e-3, 1e-3)] + \
           [Outcome(Setting("gauss-seidel", 0, h, 1e-8, 1e-6, taylor=3), "step", 3e6 * h ** 4,
                    1.0, 1) for h in (4e-3, 2e-3, 1e-3)]
    got = orders(runs, floor_factor=10.0)  # floor 1e-7: every error is above it
    assert got[("jacobi", "extrapolation 0", 1e-8)][0] == pytest.approx(1.0)
    assert got[("gauss-seidel", "extrapolation 0", 1e-8)][0] == pytest.approx(2.0)
    assert got[("gauss-seidel", "taylor 3", 1e-8)][0] == pytest.approx(4.0)


def synthetic_run(time_scale=1.0, n=20001, t_end=2.0):
    """A crank at about 10 rad/s with a 20 % speed ripple, phi(s t): a run that goes through the
    same motion time_scale times faster."""
    t = np.linspace(0.0, t_end, n)
    s = time_scale * t
    return t, 10.0 * s + 0.2 * np.sin(10.0 * s), time_scale * (10.0 + 2.0 * np.cos(10.0 * s))


def test_steady_metric_sees_a_motion_faster_by_epsilon():
    """The same motion (1 + eps) times faster, over the same revolutions (k_end = 3 in both):
    mean speed off by eps, delta (a ratio of speeds) unchanged, so the metric is eps, up to the
    linear interpolation of the revolution ends (dt 1e-4 s: ~1e-9 relative in T) and the sampled
    w_max, w_min (~1e-8): asserted 1e-4 of eps."""
    eps = 1e-4
    t, phi, w = synthetic_run()
    _, phi2, w2 = synthetic_run(1.0 + eps)
    ref = ReferenceSamples(t, {"c.phi": phi, "c.w_crank": w})
    metric = make_metric("steady", ["c.phi", "c.w_crank"])
    mean, delta = steady_figures(t, phi, w)
    assert mean == pytest.approx(10.0, rel=1e-3) and delta == pytest.approx(0.4, rel=1e-3)
    err = metric.error(t, {"c.phi": phi2, "c.w_crank": w2}, ref)
    assert err == pytest.approx(eps, rel=1e-4)
    with pytest.raises(MetricError, match="whole crank revolution"):
        steady_figures(t[:100], phi[:100], w[:100])


def test_max_metric_and_reference_lookup_off_the_grid():
    """On grid points the reference is taken as is; between them, by a cubic spline (error of a
    spline through sin at spacing 1e-3: ~1e-13)."""
    t = np.linspace(0.0, 1.0, 1001)
    ref = ReferenceSamples(t, {"c.w_crank": 2.0 + np.sin(t)})
    metric = make_metric("max", ["c.w_crank", "c.phi"])
    assert metric.variables == ["c.w_crank"]
    run = {"c.w_crank": 2.0 + np.sin(t) + 1e-3}
    assert metric.error(t, run, ref) == pytest.approx(1e-3 / np.mean(2.0 + np.sin(t)))
    t_off = np.linspace(0.0005, 0.9995, 50)
    assert np.max(np.abs(ref.at("c.w_crank", t_off) - (2.0 + np.sin(t_off)))) < 1e-10
    with pytest.raises(MetricError, match="not recorded"):
        make_metric("max", ["c.w_crank"], variables=["c.torque"])
    with pytest.raises(MetricError, match="C.phi and C.w_crank"):
        make_metric("steady", ["c.w_crank"])


def test_short_servo_press_sweep_writes_table_csv_and_plot(fmu_dir, tmp_path, capsys):
    """Gauss-Seidel and Jacobi, extrapolation 0, steps 2 and 1 ms over 0.3 s of run-up. The
    table is printed once (before: row by row, then again whole), the choice only for --meet
    (before: "cheapest meeting --target 0.001" always), accuracy.csv's columns without units in
    their names and accuracy.json with each column's unit (before: step_s, wall_s)."""
    import json

    from crankfmu.cli import main
    from crankfmu.studies.accuracy.report import TABLE_HEAD
    from crankfmu.system.load import load_scene

    out = tmp_path / "acc"
    command = ["accuracy", str(SCENARIOS / "servo_press.toml"), "--stop-time", "0.3",
               "--algorithms", "gauss-seidel,jacobi", "--extrapolations", "0",
               "--steps", "2e-3,1e-3", "--out", str(out), "--fmus", str(fmu_dir),
               "--no-progress"]
    assert main(command + ["--meet", "1e-2", "--plot"]) == 0
    text = capsys.readouterr().out
    assert "observed order" in text and "cheapest in wall time meeting --meet 0.01" in text
    assert text.count(TABLE_HEAD) == 1
    rows = list(csv.DictReader(open(out / "accuracy.csv")))
    assert [(r["algorithm"], float(r["step"])) for r in rows] == [
        ("gauss-seidel", 2e-3), ("gauss-seidel", 1e-3), ("jacobi", 2e-3), ("jacobi", 1e-3)]
    assert all(r["status"] == "completed" for r in rows)
    side = json.loads((out / "accuracy.json").read_text())
    assert side["units"] == {c: side["units"][c] for c in rows[0]}  # every column, in order
    assert (side["units"]["step"], side["units"]["wall_time"], side["units"]["error"]) == \
        ("s", "s", "1") and side["metric"] == "max" == rows[0]["metric"]
    assert not [c for c in rows[0] if "_s" in c[-2:] or "[" in c]
    err = {(r["algorithm"], float(r["step"])): float(r["error"]) for r in rows}
    # a finer step is more accurate with either master, and the reference is not the run
    for alg in ("gauss-seidel", "jacobi"):
        assert 0.0 < err[(alg, 1e-3)] < err[(alg, 2e-3)]
    assert int(rows[1]["doStep_calls"]) == 2 * 300  # two FMUs, 300 steps
    assert (out / "work_precision.png").stat().st_size > 10_000
    # the reference is cached: the same scene and grid read it back instead of solving
    scene = load_scene(SCENARIOS / "servo_press.toml")
    scene.stop_time = 0.3
    grid = np.loadtxt(out / "reference.csv", delimiter=",", skiprows=1)[:, 0]
    _, _, cached = load_or_solve_reference(scene, grid, out, 1e-10, progress=False)
    assert cached
    assert main(command) == 0  # kept runs: no choice asked for, none printed
    text = capsys.readouterr().out
    assert "meeting" not in text and text.count(TABLE_HEAD) == 1


@pytest.mark.parametrize("option, message", [
    (["--algorithms", "gauss-seidel,foo"], "--algorithms: foo not available; available: "),
    (["--extrapolations", "0,3"], "--extrapolations: [0, 3]: each must be 0, 1 or 2"),
    (["--steps", "1e-3,0"], "--steps: every value must be > 0"),
    (["--metric", "steady", "--variables", "motor.i_a"], "metric steady needs the crank angle"),
])
def test_bad_sweep_options_are_refused_before_running(option, message, tmp_path, capsys):
    from crankfmu.cli import main

    assert main(["accuracy", str(SCENARIOS / "servo_press.toml"), "--out", str(tmp_path)]
                + option) == 2
    assert message in capsys.readouterr().err
