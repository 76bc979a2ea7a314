"""`[swap]` scenes and `crankfmu compare`: swap resolution, the metrics on signals with known
answers, and the docs example (docs/compare.md: servo_press vs conventional_press) end to end on
short runs."""
from __future__ import annotations

import csv
import math

import numpy as np
import pytest

from tests.conftest import SCENARIOS
from crankfmu.studies.compare import Series, metrics, stroke_ends
from crankfmu.system.scene import SceneError
from crankfmu.system.load import load_scene


# -- [swap] ------------------------------------------------------------------------------------
def test_conventional_press_is_the_servo_press_with_the_drive_swapped():
    base, swap = load_scene(SCENARIOS / "servo_press.toml"), load_scene(SCENARIOS /
                                                                        "conventional_press.toml")
    assert swap.components["motor"].fmu == "InductionMotor"
    assert swap.components["drive"].fmu == "PlanetaryClutchDrive"
    press, base_press = swap.components["press"].parameters, base.components["press"].parameters
    # the press keeps the base's parameters except those the swap changes
    changed = ("gear_ratio", "phi_start")
    assert {k: v for k, v in press.items() if k not in changed} == \
        {k: v for k, v in base_press.items() if k not in changed}
    assert press["gear_ratio"] == 3.0 and "driven_crank" in swap.components["press"].effects
    # everything naming the replaced DC motor is gone: its input, its record entries, its links
    assert "motor.u" not in swap.inputs and "motor.i_a" not in swap.record
    assert {c.target for c in swap.connections} == {
        "drive.sun_tau", "drive.sun_J", "motor.flange_w", "motor.flange_phi", "drive.flange_tau",
        "drive.flange_J", "press.shaft_phi", "press.shaft_w"}
    assert swap.record[:4] == base.record[:4]  # the press's recorded variables stay
    assert swap.master.order == ["drive", "press", "motor"]
    assert swap.raw["analysis"]["from_time"] == 0.0  # key by key over the base's 0.5


def write(path, text):
    path.write_text(text)
    return path


def test_swap_parameter_change_connection_replacement_and_errors(tmp_path):
    base = (SCENARIOS / "servo_press.toml").read_text()
    write(tmp_path / "base.toml", base)
    s = load_scene(write(tmp_path / "heavy.toml", '[swap]\nbase = "base.toml"\n'
                         '[scene]\nname = "heavy"\n'
                         '[components.press]\nparameters = { m5 = 80.0 }\n'
                         '[[connections]]\nfrom = "press.flange_phi"\nto = "motor.flange_w"\n'))
    ref = load_scene(tmp_path / "base.toml")
    assert s.name == "heavy" and s.components["press"].parameters["m5"] == 80.0
    assert s.components["press"].parameters["r"] == ref.components["press"].parameters["r"]
    assert s.components["press"].effects == ref.components["press"].effects
    assert s.components["motor"].effects == ["electrical_lag"]
    sources = {c.target: c.source for c in s.connections}
    assert sources["motor.flange_w"] == "press.flange_phi" and len(s.connections) == 4
    with pytest.raises(SceneError, match=r"\[swap\]\.replace.*'gearbox' is not a component"):
        load_scene(write(tmp_path / "bad.toml", '[swap]\nbase = "base.toml"\n'
                         'replace = ["gearbox"]\n'))
    write(tmp_path / "a.toml", '[swap]\nbase = "b.toml"\n')
    write(tmp_path / "b.toml", '[swap]\nbase = "a.toml"\n')
    with pytest.raises(SceneError, match="cycle"):
        load_scene(tmp_path / "a.toml")
    with pytest.raises(SceneError, match="no such scene file"):
        load_scene(write(tmp_path / "c.toml", '[swap]\nbase = "missing.toml"\n'))
    with pytest.raises(SceneError, match=r"\[swap\]\.into.*allowed: base, replace"):
        load_scene(write(tmp_path / "d.toml", '[swap]\nbase = "base.toml"\ninto = 1\n'))


# -- metrics on signals with known answers ------------------------------------------------------
def series(w0=2 * math.pi, eps=0.1, P=100.0, T=3.0, t0=0.0):
    """Crank speed w0 (1 + eps sin(w0 t)) (period 1 s for w0 = 2 pi): angle
    w0 t + eps (1 - cos w0 t), so one stroke per second exactly; constant power P."""
    t = np.linspace(0.0, T, 30001)
    return Series("s", t, {"crank_angle": w0 * t + eps * (1 - np.cos(w0 * t)),
                           "crank_speed": w0 * (1 + eps * np.sin(w0 * t)),
                           "drive_torque": -3.0 + np.sin(w0 * t),
                           "drive_power": np.full_like(t, P)}, t0)


def test_metrics_known_answers():
    m = metrics(series())
    # the angle gains 2 pi exactly at t = 1, 2, 3 s; tolerances: linear interpolation on a
    # 1e-4 s grid and the trapezoid rule, both ~1e-8 here
    assert m["strokes"] == 3
    assert m["cycle_time"] == pytest.approx(1.0, abs=1e-8)
    assert m["mean_crank_speed"] == pytest.approx(2 * math.pi, rel=1e-8)
    assert m["delta"] == pytest.approx(0.2, rel=1e-7)  # (w0(1+eps) - w0(1-eps))/w0
    assert m["peak_drive_torque"] == pytest.approx(4.0, rel=1e-8)
    assert m["energy_per_stroke"] == pytest.approx(100.0, rel=1e-8)
    assert stroke_ends(*(lambda s: (s.time, s.values["crank_angle"]))(series()), 0.5) == \
        pytest.approx([1.5, 2.5], abs=1e-6)
    still = series(w0=0.5)  # not one revolution: no stroke, cycle time undefined
    assert metrics(still)["strokes"] == 0 and math.isnan(metrics(still)["cycle_time"])


# -- the docs example, short --------------------------------------------------------------------
@pytest.fixture(scope="module")
def fmus(fmu_dir):
    return fmu_dir  # the session's catalog (tests/conftest.py)


def test_compare_command_servo_vs_conventional(fmus, tmp_path, capsys):
    from crankfmu.cli import main
    out = tmp_path / "swap"
    assert main(["compare", str(SCENARIOS / "servo_press.toml"),
                 str(SCENARIOS / "conventional_press.toml"), "--out", str(out),
                 "--stop-time", "1.0", "--fmus", str(fmus), "--no-progress", "--plot"]) == 0
    text = capsys.readouterr().out
    assert "cycle_time" in text and "energy_per_stroke" in text
    for name in ("compare.csv", "compare.png", "servo_press.csv", "conventional_press.csv"):
        assert (out / name).stat().st_size > 0
    with open(out / "compare.csv") as f:
        rows = {r["metric"]: r for r in csv.DictReader(f)}
    for label in ("servo_press", "conventional_press"):
        strokes = float(rows["strokes"][label])
        assert strokes == 1  # to 1 s: one revolution after 0.5 s (servo), one single stroke
        # the table's own consistency: cycle time x mean crank speed = 2 pi per stroke (1e-3:
        # the window ends at an interpolated crossing, the mean is a trapezoid on 1 ms samples)
        assert float(rows["cycle_time"][label]) * float(rows["mean_crank_speed"][label]) == \
            pytest.approx(2 * math.pi, rel=1e-3)
    # the swap's story: single strokes cost clutch and brake energy, far above the servo's
    assert float(rows["energy_per_stroke"]["conventional_press"]) > \
        10 * float(rows["energy_per_stroke"]["servo_press"])


def test_compare_needs_analysis(tmp_path):
    from crankfmu.studies.compare import analysis_roles
    s = load_scene(SCENARIOS / "planetary_engagement.toml")
    with pytest.raises(SceneError, match=r"\[analysis\].*required by compare"):
        analysis_roles(s)
    s.raw["analysis"] = {"crank_speed": "drive.w_h"}
    with pytest.raises(SceneError, match=r"\[analysis\]\.crank_angle"):
        analysis_roles(s)
