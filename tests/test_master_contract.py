"""The masters' contract: an example master added from the tests folder (one file, one
registration), each master's options declared once and read everywhere, and the parts the
master base composes, each alone.

The example (tests/examples/masters/iterated_gauss_seidel.py) runs on the two-mass oscillator of
test_masters.py, compared with its closed form (expm) and with the shipped masters.
"""
from __future__ import annotations

import json
import warnings
from types import SimpleNamespace

import numpy as np
import pytest

from crankfmu.masters import MASTERS, all_options, register
from crankfmu.masters.history import History
from crankfmu.masters.inputs import InputFeed
from crankfmu.masters.options import Option, OptionError
from crankfmu.masters.power import PortPower
from crankfmu.masters.rollback import Rollback
from crankfmu.masters.scale import DivergenceError, ErrorScale, check_finite
from crankfmu.system.load import load_scene
from crankfmu.system.scene import SceneError
from tests.examples.masters.iterated_gauss_seidel import IteratedGaussSeidel
from tests.test_masters import OSCILLATOR, STEPS, orders, run, scene_file, speed_error

EXAMPLE = IteratedGaussSeidel.name


@pytest.fixture
def example_master():
    """The example registered for one test (the registration line a shipped master has in
    MASTERS), removed after it."""
    register(IteratedGaussSeidel)
    yield IteratedGaussSeidel
    del MASTERS[EXAMPLE]


# -- the example master ----------------------------------------------------------------------
def test_example_master_one_sweep_is_gauss_seidel_bit_for_bit(tmp_path, fmu_dir,
                                                              example_master):
    """One pass is the Gauss-Seidel sweep with held inputs: the same floats, not just close."""
    mine = run(tmp_path, fmu_dir, {"algorithm": EXAMPLE, "sweeps": 1, "step": 5e-3})
    gs = run(tmp_path, fmu_dir, {"algorithm": "gauss-seidel", "step": 5e-3})
    assert mine.recorder.rows.tobytes() == gs.recorder.rows.tobytes()
    assert mine.master_statistics["passes"] == 200


def test_example_master_converges_to_second_order(tmp_path, fmu_dir, example_master):
    """Converged passes give the trapezoidal coupling: order 2 (within +-0.3, as the shipped
    masters' orders in test_masters.py), and at h = 5 ms the error of the iterative master with
    linear interpolation (same coupling, converged by Newton to 1e-10) within 5 %: six passes
    contract the waveform error by (w h)^6 ~ 1e-6 here (w = 17.6 rad/s)."""
    errors = [speed_error(run(tmp_path, fmu_dir, {"algorithm": EXAMPLE, "sweeps": 6,
                                                  "step": h})) for h in STEPS]
    for q in orders(errors):
        assert abs(q - 2) < 0.3, (errors, orders(errors))
    iterative = speed_error(run(tmp_path, fmu_dir, {"algorithm": "iterative", "step": STEPS[1],
                                                    "extrapolation": 0, "tolerance": 1e-10}))
    assert abs(errors[1] - iterative) < 0.05 * iterative, (errors[1], iterative)


def test_example_master_options_are_checked_where_given(tmp_path, fmu_dir, example_master,
                                                        capsys):
    from crankfmu.cli import main
    from crankfmu.system.scene import parse_scene

    def scene(master):
        return {"scene": {"stop_time": 0.1}, "master": master,
                "components": {"r1": {"fmu": "Rotor"}}}

    with pytest.raises(SceneError, match=r"x.toml: \[master\].sweeps: must be an integer from "
                                         r"1 to 50, got 0"):
        parse_scene("x.toml", scene({"algorithm": EXAMPLE, "sweeps": 0}))
    with pytest.raises(SceneError, match=r"\[master\].sweeps: not an option of the gauss-seidel "
                                         rf"master \(it is one of {EXAMPLE}\); allowed: "):
        parse_scene("x.toml", scene({"algorithm": "gauss-seidel", "sweeps": 2}))
    with pytest.raises(SceneError, match=r"\[master\].tolerance: not an option of the jacobi "
                                         r"master \(it is one of iterative, adaptive\)"):
        parse_scene("x.toml", scene({"algorithm": "jacobi", "tolerance": 1e-6}))
    path = scene_file(tmp_path, {"algorithm": EXAMPLE}, OSCILLATOR,
                      0.05, None)
    out = tmp_path / "cli"  # the output folder
    assert main(["run", str(path), "--fmus", str(fmu_dir), "--out", str(out), "--sweeps",
                 "0", "--no-progress"]) == 2
    assert "--sweeps: must be an integer from 1 to 50" in capsys.readouterr().err
    assert main(["run", str(path), "--fmus", str(fmu_dir), "--out", str(out), "--sweeps",
                 "3", "--no-progress"]) == 0
    side = json.loads((out / f"{path.stem}.json").read_text())
    assert side["master"]["sweeps"] == 3 and "tolerance" not in side["master"]
    assert side["master_statistics"]["passes"] == 3 * 50  # 50 steps of 1 ms


def test_example_master_survives_an_ssp_round_trip(tmp_path, example_master):
    from crankfmu.system.ssp_export import scene_annotation
    from crankfmu.system.ssp_load import _master

    scene = load_scene(scene_file(tmp_path, {"algorithm": EXAMPLE, "sweeps": 4},
                                  OSCILLATOR, 0.05, None))
    node = scene_annotation(scene).find("{*}Master")
    assert dict(node.attrib) == {"algorithm": EXAMPLE, "step": "0.001", "sweeps": "4",
                                 "fmu_tolerance": "1e-08"}
    assert _master("x.ssp", node) == {"algorithm": EXAMPLE, "step": 1e-3, "sweeps": 4,
                                      "fmu_tolerance": 1e-8}


def test_an_ssp_written_before_the_declarations_still_loads():
    """Files exported before this change list every master's keys whatever the algorithm; the
    keys the chosen master does not take are skipped (they were never used)."""
    from lxml import etree

    from crankfmu.system.ssp_load import _master
    node = etree.fromstring(
        '<Master algorithm="gauss-seidel" step="0.001" extrapolation="1" tolerance="1e-06" '
        'fmu_tolerance="1e-08" max_iterations="20" min_step="1e-06" max_step="0.01"/>')
    assert _master("x.ssp", node) == {"algorithm": "gauss-seidel", "step": 1e-3,
                                      "extrapolation": 1, "fmu_tolerance": 1e-8}


# -- the declarations ------------------------------------------------------------------------
def test_every_declared_default_is_allowed_and_each_key_means_one_thing():
    for cls in MASTERS.values():
        for option in cls.options:
            assert option.check(option.default) == option.default, (cls.name, option.name)
            assert all_options()[option.name] is option, (cls.name, option.name)
            assert option.unit and option.help, (cls.name, option.name)


def test_a_master_redefining_a_key_is_refused():
    class Clash(IteratedGaussSeidel):
        name = "clash"
        options = (Option("tolerance", float, "1", 1e-3, "another meaning", positive=True),)

    with pytest.raises(ValueError, match="option tolerance differs from master iterative's"):
        register(Clash)
    assert "clash" not in MASTERS


def test_a_master_may_default_a_shared_key_on_its_own(tmp_path):
    """The adaptive master's tolerance default (1e-2) differs from the shared one (1e-6, the
    iterative master's): the scene reads the chosen master's, the sidecar's table shows it, and
    a master whose own default its option would refuse cannot be registered."""
    scene = load_scene(scene_file(tmp_path, {"algorithm": "adaptive"}, OSCILLATOR, 0.05, None))
    assert scene.master.tolerance == 1e-2 == scene.master.resolved()["tolerance"]
    scene.master.algorithm = "iterative"
    assert scene.master.tolerance == all_options()["tolerance"].default == 1e-6

    class Loose(IteratedGaussSeidel):
        name = "loose"
        defaults = {"sweeps": 0}

    with pytest.raises(ValueError, match="master loose: its default sweeps = 0 is not"):
        register(Loose)
    assert "loose" not in MASTERS


def test_option_checks_name_what_is_allowed():
    step = Option("min_step", float, "s", 1e-6, "smallest step", positive=True)
    for value, words in ((0.0, "must be > 0, got 0.0"), (float("nan"), "must be a finite number"),
                         (True, "must be a finite number, got True"), ("1", "got '1'")):
        with pytest.raises(OptionError, match=words):
            step.check(value)
    assert step.check(2) == 2.0 and isinstance(step.check(2), float)
    ex = all_options()["extrapolation"]
    assert ex.check(2.0) == 2 and isinstance(ex.check(2.0), int)
    with pytest.raises(OptionError, match="must be 0, 1 or 2, got 3"):
        ex.check(3)


def test_an_option_set_in_code_is_checked_when_the_run_starts(tmp_path, fmu_dir):
    """Code may set m.tolerance unchecked (sweeps set it for every setting); the master checks
    its own options before the first step and the runner names the key."""
    from crankfmu.cosim.runner import RunOptions, run_scene
    scene = load_scene(scene_file(tmp_path, {"algorithm": "adaptive"},
                                  OSCILLATOR, 0.05, None))
    scene.master.tolerance = float("nan")
    with pytest.raises(SceneError, match=r"\[master\].tolerance: must be a finite number"):
        run_scene(scene, RunOptions(fmu_dir=fmu_dir, progress=False))


# -- the parts, each alone (fake systems: only what each part reads) -------------------------
def _fmu(name, can_rollback=True, nominal=None, inputs=()):
    variables = {n: SimpleNamespace(causality="input", nominal=None) for n in inputs}
    return SimpleNamespace(path=SimpleNamespace(name=f"{name}.fmu"), can_rollback=can_rollback,
                           variables=variables, calls=[])


def test_rollback_names_the_fmu_that_cannot():
    system = SimpleNamespace(fmus={"a": _fmu("A"), "b": _fmu("B", can_rollback=False)})
    with pytest.raises(ValueError, match=r"master m rolls FMUs back, but b \(B.fmu\) has "
                                         "canGetAndSetFMUstate = false"):
        Rollback(system, "m", required=True)
    assert Rollback(system, "m", required=False).available is False


def test_history_rows_extrapolate_a_parabola_exactly():
    """Three points of y = 1 + 2 s + 3 s^2 (s from the newest point): the rows are the Taylor
    coefficients (1, 2, 6) to round-off (1e-12 of values of order 1)."""
    history = History()
    for t in (-2e-3, -1e-3, 0.0):
        history.push(t, {"a": np.array([1 + 2 * t + 3 * t * t])})
    rows = np.asarray(history.rows("a", 0.0, 2))
    assert np.allclose(rows[:, 0], [1.0, 2.0, 6.0], rtol=0, atol=1e-9)
    assert np.asarray(history.rows("a", 0.0, 0)).tolist() == [[1.0]]


def test_newton_forms_are_exact_for_every_signal_count():
    """The generated Newton forms (one per signal count, history._NewtonForms): through points
    of n lines (2 points) and n parabolas (3 points, unevenly spaced, none at s = 0) the rows
    are the Taylor coefficients at s = 0, to 1e-9 of coefficients of order 1 (round-off of
    differences over steps of 1e-3)."""
    from crankfmu.masters.history import _line, _parabola

    rng = np.random.default_rng(5)
    for n in range(5):
        c = rng.normal(size=(3, n))  # y_i(s) = c0 + c1 s + c2 s^2 / 2
        s = (0.4e-3, -1.1e-3, -2.0e-3)
        points = [(c[0] + c[1] * x + 0.5 * c[2] * x * x).tolist() for x in s]
        rows = _parabola(*s, *points)
        assert len(rows) == 3 and all(len(r) == n for r in rows)
        assert np.allclose(np.array(rows).reshape(3, n), c, rtol=0, atol=1e-9)
        line = [(c[0] + c[1] * x).tolist() for x in s[:2]]
        assert np.allclose(np.array(_line(*s[:2], *line)).reshape(2, n), c[:2], rtol=0,
                           atol=1e-9)


def test_a_gauss_seidel_sweep_makes_each_sources_rows_once_per_kind():
    """Stepping order a, b, c; a reads c, b reads a, c reads a, b and itself: a extrapolates
    c, b interpolates a (stepped before it), c interpolates b and reuses the rows b made of a
    and those a made of c (c has not stepped yet: still extrapolated)."""
    from crankfmu.masters.base import rows_plan

    in_sources = {"a": [("c", 0)], "b": [("a", 0), ("a", 1)],
                  "c": [("a", 0), ("b", 0), ("c", 1)]}
    assert rows_plan(["a", "b", "c"], in_sources, sequential=True) == [
        (("c", False),), (("a", True),), (("b", True),)]
    # Jacobi: everything extrapolated, each source once
    assert rows_plan(["a", "b", "c"], in_sources, sequential=False) == [
        (("c", False),), (("a", False),), (("b", False),)]


def test_recorder_rows_are_a_snapshot_and_a_short_row_is_refused():
    from crankfmu.cosim.results import Recorder

    rec = Recorder(["a.x", "a.y"], ["m", None])
    rec.add(0.0, [1.0, 2.0])
    first = rec.rows
    rec.add(0.5, [3.0, 4.0])
    assert first.tolist() == [[0.0, 1.0, 2.0]]
    assert rec.rows.tolist() == [[0.0, 1.0, 2.0], [0.5, 3.0, 4.0]] and rec.count == 2
    assert rec.column("a.y").tolist() == [2.0, 4.0]
    with pytest.raises(ValueError, match="a row of 1 values for 2 recorded variables"):
        rec.add(1.0, [5.0])
    assert rec.count == 2 and rec.rows.shape == (2, 3)


def test_error_scale_is_the_largest_magnitude_at_least_the_nominal():
    system = SimpleNamespace(outputs={"a": np.zeros(2)}, out_names={"a": ["x", "y"]},
                             fmus={"a": SimpleNamespace(variables={
                                 "x": SimpleNamespace(nominal=None),
                                 "y": SimpleNamespace(nominal="1e3")})})
    scale = ErrorScale(system)
    scale.update({"a": np.array([-5.0, 2.0])})
    scale.update({"a": np.array([3.0, -7.0])})
    assert scale.of("a", np.array([0.5, 0.0])).tolist() == [5.0, 1e3]
    with pytest.raises(DivergenceError, match=r"t = 0.5 s: a.y = nan"):
        check_finite(0.5, {"a": np.array([1.0, np.nan])}, system.out_names)


def test_input_feed_gives_a_foreign_fmu_the_held_midpoint_value():
    """An FMU without companion inputs gets the polynomial at h/2 (exact for a line: the mean
    over the step), with one warning."""
    written = []
    system = SimpleNamespace(fmus={"f": _fmu("F", inputs=["u"])}, in_names={"f": ["u"]},
                             out_names={"g": ["y"]},
                             in_sources={"f": [("g", 0)]},
                             write_inputs={"f": lambda v: written.append(list(v))})
    feed = InputFeed(system)
    rows = np.array([[1.0], [4.0]])  # u(s) = 1 + 4 s
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        assert feed.write("f", rows) is None
        assert feed.write_held("f", rows, 0.5) == [[2.0]]
    assert written == [[2.0]] and len(caught) == 1 and "F.fmu" in str(caught[0].message)


def test_port_power_integrates_a_constant_port_exactly():
    """Torque 3 N.m one way, speed 2 rad/s back, held over a 0.5 s step: each side's energy is
    3 * 2 * 0.5 = 3 J exactly and the mismatch 0."""
    link = SimpleNamespace
    system = SimpleNamespace(links=[link(source="d", target="r", unit="N.m", source_var="tau",
                                         target_var="tau"),
                                    link(source="r", target="d", unit="rad/s", source_var="w",
                                         target_var="w")],
                             out_names={"d": ["tau"], "r": ["w"]})
    power = PortPower(system)
    outputs = {"d": np.array([3.0]), "r": np.array([2.0])}
    seen = {"r": (np.array([[3.0]]), 0.5), "d": (np.array([[2.0]]), 0.5)}
    power.add(0.5, outputs, outputs, seen)
    report = power.report()
    assert report["ports"][0]["energy_receiver_J"] == 3.0 == report["ports"][0]["energy_driver_J"]
    assert report["max_relative_mismatch"] == 0.0


def test_float_paths_give_numpys_floats():
    """The masters' per-step arithmetic runs on Python floats (cheaper for a few values): the
    input polynomial's value and the error scale must give the floats of their numpy form bit
    for bit (the scenes' results stay identical), and a NaN must come through as numpy's
    maximum and max let it."""
    from crankfmu.masters.history import evaluate

    rng = np.random.default_rng(3)
    for depth in (1, 2, 3):
        rows = rng.normal(size=(depth, 4)) * 10.0 ** rng.integers(-8, 8, size=(depth, 4))
        for s in (1e-3, 0.37, 2.5e-6):
            numpy_form = rows[0].copy()
            if depth > 1:
                numpy_form += rows[1] * s
            if depth > 2:
                numpy_form += rows[2] * (0.5 * s * s)
            assert evaluate(rows.tolist(), s) == numpy_form.tolist()
    system = SimpleNamespace(outputs={"a": np.zeros(4)}, out_names={"a": list("wxyz")},
                             fmus={"a": SimpleNamespace(variables={
                                 n: SimpleNamespace(nominal=nom) for n, nom in
                                 zip("wxyz", (None, "2.5", "1e-3", None))})})
    scale = ErrorScale(system)
    for _ in range(5):
        values = rng.normal(size=4) * 10.0 ** rng.integers(-4, 4, size=4)
        assert scale.of_floats("a", values.tolist()) == scale.of("a", values).tolist()
        scale.update({"a": values})
    with_nan = np.array([1.0, np.nan, 0.0, -3.0])
    got, want = scale.of_floats("a", with_nan.tolist()), scale.of("a", with_nan).tolist()
    assert np.isnan(got[1]) and np.isnan(want[1]) and got[::2] == want[::2]
