"""The Python API (crankfmu/api.py): fmpy-like structured results with units, nothing written
unless asked, plots that leave the matplotlib backend alone, --set-like settings."""
from __future__ import annotations

import sys

import numpy as np
import pytest

from conftest import SCENARIOS

SERVO = SCENARIOS / "servo_press.toml"


def test_import_is_cheap():
    import subprocess
    code = ("import sys, crankfmu; heavy = [m for m in ('numpy', 'fmpy', 'matplotlib', "
            "'crankfmu.api', 'scipy') if m in sys.modules]; print(heavy)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def test_simulate_from_an_empty_folder(tmp_path, monkeypatch):
    """The issue's must-be-true item, as it reads: an empty working folder, the scene by path,
    a parameter override; fields, units, no file written, the backend unchanged."""
    import matplotlib

    import crankfmu
    monkeypatch.chdir(tmp_path)
    backend = matplotlib.get_backend()
    result = crankfmu.simulate(SERVO, stop_time=0.4, parameters={"press.F_max": 65e3})
    assert result.values.dtype.names[0] == "time"
    assert "press.w_crank" in result.values.dtype.names
    assert result.units["press.w_crank"] == "rad/s"
    assert result.units["time"] == "s" and result.units["motor.flange_tau"] == "N.m"
    assert result.values["time"][-1] == pytest.approx(0.4)
    assert result.metadata["components"]["press"]["parameters"]["F_max"] == 65e3
    assert result.coupling_error["ports"] and set(result.statistics) == {"motor", "press"}
    fig = result.plot()
    assert matplotlib.get_backend() == backend
    assert type(fig).__name__ == "Figure"
    labels = [ax.get_ylabel() for ax in fig.axes]
    assert "press.w_crank\n[rad/s]" in labels
    assert list(tmp_path.iterdir()) == []  # nothing written into the working folder
    df = pytest.importorskip("pandas") and result.to_pandas()
    assert df.index.name == "time" and df.attrs["units"]["press.w_crank"] == "rad/s"
    assert np.array_equal(df["press.w_crank"].to_numpy(), result.values["press.w_crank"])


def test_simulate_writes_with_out_and_fmpy_reads_it(tmp_path, fmu_dir):
    import json

    from fmpy.util import read_csv

    import crankfmu
    scene = crankfmu.load_scene(SERVO)
    result = crankfmu.simulate(scene, stop_time=0.05, step=2e-3, out=tmp_path / "r.csv",
                               fmu_dir=fmu_dir, inputs={"motor.u": [[0, 0], [0.05, 220]]},
                               parameters={"master.extrapolation": 1})
    assert scene.stop_time == 3.0 and "motor.u" in scene.inputs  # the caller's scene unchanged
    assert scene.inputs["motor.u"].values == [220.0]
    back = read_csv(tmp_path / "r.csv")
    assert back.dtype.names == result.values.dtype.names
    assert np.array_equal(back["press.w_crank"], result.values["press.w_crank"])
    side = json.loads((tmp_path / "r.json").read_text())
    assert side["units"] == result.units and side["master"]["extrapolation"] == 1
    assert side["master"]["step"] == 2e-3


def test_set_reaches_parameters_inputs_and_master(servo_scene):
    from crankfmu.scenario.scene import SceneError, apply_overrides
    apply_overrides(servo_scene, ["press.F_max=6e4", "motor.u=200", "master.step=2e-3",
                                  "master.algorithm=jacobi", "master.extrapolation=2"])
    assert servo_scene.components["press"].parameters["F_max"] == 6e4
    assert "u" not in servo_scene.components["motor"].parameters
    assert servo_scene.inputs["motor.u"].values == [200.0]
    m = servo_scene.master
    assert (m.step, m.algorithm, m.extrapolation) == (2e-3, "jacobi", 2)
    for bad, words in (("master.step=-1", "must be > 0"), ("master.stepp=1", "unknown master key"),
                       ("press.flange_tau=1", "is connected"),
                       ("master.algorithm=fast", "not one of")):
        with pytest.raises(SceneError, match=words):
            apply_overrides(servo_scene, [bad])


def test_reference_returns_a_result_and_writes_nothing(tmp_path, monkeypatch):
    import crankfmu
    monkeypatch.chdir(tmp_path)
    ref = crankfmu.reference(SERVO, stop_time=0.05, rtol=1e-8)
    assert ref.units["press.w_crank"] == "rad/s" and ref.values["time"][-1] == pytest.approx(0.05)
    assert list(tmp_path.iterdir()) == []
