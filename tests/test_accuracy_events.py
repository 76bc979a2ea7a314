"""Event-aware accuracy (crankfmu.cosim.events, `crankfmu accuracy` on the hybrid scenes):
the per-event figures, an external --reference file, resuming a sweep, unstable runs, and the
convergence of event figures through the FMUs on short runs (the full tables are made by
scripts/accuracy_tables.py)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from tests.conftest import SCENARIOS
from crankfmu.studies.accuracy import (AccuracyOptions, EventSpec, Setting, event_error,
                                       parse_event_specs, run_accuracy)
from crankfmu.cosim.events import EventSpecError, event_values
from crankfmu.system.load import load_scene


@pytest.fixture(scope="module")
def hybrid_fmus(fmu_dir):
    return fmu_dir  # the session's catalog (tests/conftest.py)


@pytest.fixture(scope="module")
def one_worker():
    """The executor the default jobs=1 makes (every run in this process), kept for the
    module."""
    from crankfmu.studies.executor import make_executor
    with make_executor(1) as executor:
        yield executor


# -- the figures, on hand-made columns (exact values known) -------------------------------------
def blows(peaks, times_per_blow=3):
    """A counter rising 0, 1, 2, ... and a peak frozen after each blow, as the hammer reports."""
    n, y = [0, 0], [0.0, 0.0]
    for k, p in enumerate(peaks, start=1):
        n += [k] * times_per_blow
        y += [0.5 * p, p, p]  # mid-blow (not final), then the frozen figure
    return {"h.n": np.array(n, dtype=float), "h.P": np.array(y)}


def test_per_event_values_are_the_final_figure_of_each_blow():
    spec = EventSpec("h.P", per="h.n")
    assert event_values(spec, blows([10.0, 12.0, 11.0])).tolist() == [10.0, 12.0, 11.0]
    err = event_error(spec, blows([10.0, 12.3, 11.0]), blows([10.0, 12.0, 11.0]))
    assert err.error == pytest.approx(0.3 / 11.0, rel=1e-12)  # max |d| / mean |ref|


def test_a_missed_blow_is_no_number():
    err = event_error(EventSpec("h.P", per="h.n"), blows([10.0, 12.0]), blows([10.0, 12.0, 9.0]))
    assert err.error == math.inf and "2 events in the run, 3 in the reference" in err.reason


def test_end_value_error_is_relative():
    run, ref = {"d.t_lock": np.array([-1.0, 0.2362])}, {"d.t_lock": np.array([-1.0, 0.2360])}
    assert event_error(EventSpec("d.t_lock"), run, ref).error == pytest.approx(0.0002 / 0.236)


@pytest.mark.parametrize("raw, where", [
    ("d.t", "must be a list"), ([3], "[0]: 3 is not"), ([{"per": "h.n"}], "[0]:"),
    ([{"variable": "hP", "per": "h.n"}], "[0].variable: must be \"component.variable\""),
    ([{"variable": "h.P", "every": "h.n"}], "[0]:")])
def test_bad_event_entries_name_the_key(raw, where):
    with pytest.raises(EventSpecError, match=None) as err:
        parse_event_specs(raw)
    assert "[analysis].events" in str(err.value) and where in str(err.value)


def test_shipped_scenes_name_their_metric():
    from crankfmu.studies.accuracy import scene_event_specs, scene_metric_name
    expected = {"planetary_engagement": "events", "planetary_stopping": "events",
                "hammer": "events", "hammer_bearings": "events", "mo100_impact": "events",
                "conventional_press": "events", "servo_press": "max", "mill_stand": "max"}
    for name, metric in expected.items():
        scene = load_scene(SCENARIOS / f"{name}.toml")
        assert scene_metric_name(scene) == metric, name
        for spec in scene_event_specs(scene):  # every named figure exists in the model
            from crankfmu.monolithic.composed import ComposedModel
            model = ComposedModel(scene)
            for ref in spec.needs:
                comp, var = ref.split(".", 1)
                outputs = [v.name for v in model.parts[model.index[comp]].model.outputs]
                assert var in outputs, ref


# -- through the FMUs: short runs ----------------------------------------------------------------
# These check the runs' figures, not the error estimates (tests/test_error_estimate.py does):
# estimate=False leaves out the companion runs at half the step, which cost as much as the runs
# checked. The reference is solved at rtol 1e-8, not the default 1e-10: the errors checked are
# co-simulation errors of 1e-5 to 3e-4, and the 1e-8 reference moves them by at most 1.5e-4 of
# themselves (measured against the 1e-10 reference: planetary lock-time errors identical to
# 10 digits; hammer peak figures 8.3536e-5 against 8.3524e-5, the largest change), for half the
# reference's cost.
REFERENCE_RTOL = 1e-8


def planetary(tmp_path, fmus, executor, steps, **options):
    scene = load_scene(SCENARIOS / "planetary_engagement.toml")
    scene.stop_time = 0.3
    return run_accuracy(scene, AccuracyOptions(
        out_dir=tmp_path, algorithms=["gauss-seidel"], extrapolations=[0], steps=steps,
        fmu_dir=fmus, progress=False, estimate=False, reference_rtol=REFERENCE_RTOL,
        executor=executor, **options))


@pytest.fixture(scope="module")
def planetary_sweep(tmp_path_factory, hybrid_fmus, one_worker):
    """(folder, result) of the sweep at 4e-4 and 2e-4 s: the first order's two runs, and the
    first sweep the resume and --reference checks repeat (its reference and its 4e-4 run)."""
    folder = tmp_path_factory.mktemp("planetary_sweep")
    return folder, planetary(folder, hybrid_fmus, one_worker, [4e-4, 2e-4])


def test_planetary_lock_time_converges_first_order(planetary_sweep):
    """Gauss-Seidel with the held motor torque: the lock-time error is first order in the step
    (docs/accuracy.md). Slope between 4e-4 and 2e-4 s within 0.8-1.2: measured 1.00."""
    _, result = planetary_sweep
    lock = [o.extra["events"]["drive.t_lock_b at end"] for o in result.outcomes]
    assert all(o.status == "completed" for o in result.outcomes)
    order = math.log(lock[0] / lock[1]) / math.log(2.0)
    assert 0.8 < order < 1.2 and lock[1] < 1e-4


def test_resume_and_external_reference(tmp_path, planetary_sweep, hybrid_fmus, one_worker):
    """A second sweep over the same folder takes every run from there (same figures); the
    reference file written by the first, given as --reference, gives the same errors."""
    folder, first = planetary_sweep
    seen = []
    again = planetary(folder, hybrid_fmus, one_worker, [4e-4, 2e-4],
                      report=lambda o, kept: seen.append(kept))
    assert seen == [True, True]
    assert [o.error for o in again.outcomes] == [o.error for o in first.outcomes]
    external = planetary(tmp_path / "b", hybrid_fmus, one_worker, [4e-4],
                         reference_csv=folder / "reference.csv")
    assert external.outcomes[0].error == first.outcomes[0].error
    assert not (tmp_path / "b" / "reference.csv").exists()


def test_bad_reference_file_is_refused(tmp_path, capsys):
    from crankfmu.cli import main
    bad = tmp_path / "ref.csv"
    bad.write_text("time,\"drive.t_lock_b\"\n0.0,-1\n0.3,0.236\n")
    assert main(["accuracy", str(SCENARIOS / "planetary_engagement.toml"), "--reference",
                 str(bad), "--out", str(tmp_path / "o"), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert f"--reference {bad}: no column drive.t_slip_h, drive.E_brake_b" in err
    short = tmp_path / "short.csv"
    short.write_text("time,\"drive.t_slip_h\",\"drive.t_lock_b\",\"drive.E_brake_b\"\n"
                     "0.0,-1,-1,0\n0.2,0.02,-1,5\n")
    assert main(["accuracy", str(SCENARIOS / "planetary_engagement.toml"), "--reference",
                 str(short), "--out", str(tmp_path / "o"), "--no-progress"]) == 2
    assert "covers t = 0 to 0.2 s; the runs need 0 to 0.4 s" in capsys.readouterr().err


def test_hammer_blow_figures_converge_with_the_step(tmp_path, hybrid_fmus, one_worker):
    """Peak contact force and bearing load (elastic support) per blow, two blows in 0.4 s:
    Gauss-Seidel's error falls with the step, at least halving per halved step (measured
    3.4e-4 and 8.4e-5: second order)."""
    scene = load_scene(SCENARIOS / "hammer_bearings.toml")
    scene.stop_time = 0.4
    result = run_accuracy(scene, AccuracyOptions(
        out_dir=tmp_path, algorithms=["gauss-seidel"], extrapolations=[0], steps=[4e-3, 2e-3],
        fmu_dir=hybrid_fmus, progress=False, estimate=False, reference_rtol=REFERENCE_RTOL,
        executor=one_worker))
    figures = [o.extra["events"] for o in result.outcomes]
    for label in ("hammer.P_peak per hammer.n_impacts", "hammer.T_peak per hammer.n_impacts"):
        assert figures[1][label] < 0.5 * figures[0][label] < 1e-3


def test_unstable_runs_are_reported_as_such():
    """A run whose error exceeds 1 or that stopped is 'unstable', never a number in the table
    or the CSV (the figure or the reason goes into the status)."""
    from crankfmu.cosim.metrics import ReferenceSamples, make_metric
    from crankfmu.studies.accuracy.report import format_outcome, table_row
    from crankfmu.studies.accuracy.sweep import _outcome
    from crankfmu.studies.executor import RunOutput, RunTask

    t = np.linspace(0.0, 1.0, 11)
    ref = ReferenceSamples(t, {"c.w_crank": np.ones_like(t)})
    metric = make_metric("max", ["c.w_crank"])
    setting = Setting("jacobi", 0, 1e-3, 1e-8, 1e-6)
    diverged = RunOutput(0, "completed", names=["c.w_crank"],
                         rows=np.column_stack([t, 1.0 + 3.0 * t]), sidecar={"x": 1})
    import tempfile
    from pathlib import Path
    with tempfile.TemporaryDirectory() as tmp:
        o = _outcome(setting, diverged, RunTask(0, None), metric, ref, Path(tmp), {})
        stopped = RunOutput(0, "failed", reason="master: state not finite at t = 0.4 s")
        s = _outcome(setting, stopped, RunTask(0, None), metric, ref, Path(tmp), {})
    assert o.status == "unstable: error 3 > 1" and not o.ok
    assert "unstable" in format_outcome(o) and table_row(o, "max")["error"] == "unstable"
    assert s.status.startswith("unstable (stopped): master: state not finite")
    assert not s.ok and table_row(s, "max")["error"] == "unstable"


def test_a_run_with_an_extra_blow_says_so(tmp_path):
    """A blow more than the reference by the stop time: 'events differ', no number, not
    'unstable' (the run is stable; its blows drifted)."""
    from crankfmu.cosim.metrics import ReferenceSamples, make_metric
    from crankfmu.studies.accuracy.report import table_row
    from crankfmu.studies.accuracy.sweep import _outcome
    from crankfmu.studies.executor import RunOutput, RunTask

    ref_cols, run_cols = blows([10.0, 12.0]), blows([10.0, 12.0, 11.0])
    t_ref, t_run = np.linspace(0, 1, len(ref_cols["h.n"])), np.linspace(0, 1, len(run_cols["h.n"]))
    ref = ReferenceSamples(t_ref, ref_cols)
    metric = make_metric("events", ["h.P", "h.n"], events=[EventSpec("h.P", per="h.n")])
    output = RunOutput(0, "completed", names=["h.P", "h.n"],
                       rows=np.column_stack([t_run, run_cols["h.P"], run_cols["h.n"]]),
                       sidecar={"x": 1})
    o = _outcome(Setting("jacobi", 0, 4e-3, 1e-8, 1e-6), output, RunTask(0, None), metric, ref,
                 tmp_path, {})
    assert o.status == "events differ: h.n: 3 events in the run, 2 in the reference"
    assert o.events_differ and not o.unstable and not o.ok and table_row(o, "events")["error"] == "events differ"
