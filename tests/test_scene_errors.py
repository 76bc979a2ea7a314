"""Bad scene files give errors that name the file, the key and what is allowed."""
from __future__ import annotations

import pytest

from crankfmu.cosim.runner import RunOptions, run_scene
from crankfmu.system.scene import SceneError
from crankfmu.system.load import load_scene
from crankfmu.system.scene import apply_overrides

from tests.conftest import SCENARIOS

GOOD = (SCENARIOS / "servo_press.toml").read_text()


def assert_names(error: SceneError, path, key: str, words: str) -> None:
    """The message names the file, the key, and what is allowed or wrong."""
    message = str(error)
    assert str(path) in message and key in message and words in message, message


def scene_file(tmp_path, text):
    path = tmp_path / "bad.toml"
    path.write_text(text)
    return path


@pytest.mark.parametrize("change, key, words", [
    (lambda s: s.replace("stop_time = 3.0", ""), "[scene].stop_time", "required"),
    (lambda s: s.replace('algorithm = "gauss-seidel"', 'algorithm = "rk4"'),
     "[master].algorithm", "gauss-seidel, jacobi"),
    (lambda s: s.replace("step = 1e-3", "step = -1e-3"), "[master].step", "> 0"),
    (lambda s: s.replace("extrapolation = 0", "extrapolation = 3"), "[master].extrapolation",
     "0, 1 or 2"),
    (lambda s: s.replace('from = "motor.flange_tau"', 'from = "engine.flange_tau"'),
     "[[connections]] #1.from", "unknown component 'engine'"),
    (lambda s: s.replace("[record]", "[recording]"), "(top level).recording", "allowed"),
    (lambda s: s.replace('"motor.u" = 220.0', '"motor.u" = {table = [[1, 0], [0, 1]]}'),
     "table", "increase"),
    (lambda s: s + '\n[[connections]]\nfrom = "motor.i_a"\nto = "press.flange_tau"\n',
     "[[connections]]", "connected more than once"),
    (lambda s: s.replace("= 220.0", "= \"220\""), "[inputs]", "finite number"),
    (lambda s: s.replace("[scene]", "[scene"), "(syntax)", "not valid TOML"),
])
def test_schema_errors_name_file_key_and_what_is_allowed(tmp_path, change, key, words):
    path = scene_file(tmp_path, change(GOOD))
    with pytest.raises(SceneError) as err:
        load_scene(path)
    assert_names(err.value, path, key, words)


@pytest.mark.parametrize("change, key, words", [
    (lambda s: s.replace('from = "motor.flange_tau"', 'from = "motor.torque"'),
     "[[connections]] #1.from", "has no variable 'torque'"),
    (lambda s: s.replace('from = "motor.flange_tau"', 'from = "press.flange_w"'),
     "[[connections]] #1", "unit mismatch: press.flange_w is in rad/s, press.flange_tau in N.m"),
    (lambda s: s.replace('to = "press.flange_tau"', 'to = "press.phi"'),
     "[[connections]] #1.to", "is a output, expected input"),
    (lambda s: s.replace("k_phi = 1.30", "k_fi = 1.30"),
     "[components.motor].parameters.k_fi", "has no variable 'k_fi'"),
    (lambda s: s.replace('effects = ["electrical_lag"]', 'effects = ["saturation"]'),
     "[components.motor].effects", "effects: electrical_lag, speed_loop"),
    (lambda s: s.replace('fmu = "DcServoMotor"', 'fmu = "DcMotor"'),
     "[components.motor].fmu", "unknown FMU 'DcMotor'"),
    (lambda s: s.replace('"press.F5"', '"press.F6"'), "[record].variables", "no variable 'F6'"),
])
def test_wiring_errors_are_found_before_anything_runs(tmp_path, fmu_dir, change, key, words):
    path = scene_file(tmp_path, change(GOOD))
    out = tmp_path / "out.csv"
    with pytest.raises(SceneError) as err:
        run_scene(load_scene(path), RunOptions(out=out, fmu_dir=fmu_dir, progress=False))
    assert_names(err.value, path, key, words)
    assert not out.exists()


def test_overrides_are_checked(servo_scene):
    with pytest.raises(SceneError, match="unknown component 'pres'"):
        apply_overrides(servo_scene, ["pres.r=0.1"])
    with pytest.raises(SceneError, match="not a number or true/false"):
        apply_overrides(servo_scene, ["press.r=big"])
    apply_overrides(servo_scene, ["press.r=0.06", "press.effect_gravity=false"])
    assert servo_scene.components["press"].parameters["r"] == 0.06
