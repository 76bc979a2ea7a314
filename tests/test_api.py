"""The Python API (crankfmu/api.py): fmpy-like structured results with units, nothing written
unless asked, plots that leave the matplotlib backend alone, --set-like settings."""
from __future__ import annotations

import sys

import numpy as np
import pytest

from tests.conftest import SCENARIOS

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
    result = crankfmu.simulate(scene, stop_time=0.05, step=2e-3, out=tmp_path,
                               fmu_dir=fmu_dir, inputs={"motor.u": [[0, 0], [0.05, 220]]},
                               parameters={"master.extrapolation": 1})
    assert scene.stop_time == 3.0 and "motor.u" in scene.inputs  # the caller's scene unchanged
    assert scene.inputs["motor.u"].values == [220.0]
    back = read_csv(tmp_path / "servo_press.csv")  # out is the folder: <scene name>.csv
    assert back.dtype.names == result.values.dtype.names
    assert np.array_equal(back["press.w_crank"], result.values["press.w_crank"])
    side = json.loads((tmp_path / "servo_press.json").read_text())
    assert side["units"] == result.units and side["master"]["extrapolation"] == 1
    assert side["master"]["step"] == 2e-3


def test_set_reaches_parameters_inputs_and_master(servo_scene):
    from crankfmu.system.scene import SceneError, apply_overrides
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


def test_steady_state_plot_with_the_reference(tmp_path, fmu_dir):
    """The servo press at steady state: speed and torque over the last revolutions, the
    reference drawn over it; coinciding curves get one legend entry saying so."""
    import matplotlib

    import crankfmu
    backend = matplotlib.get_backend()
    run = crankfmu.simulate(SERVO, stop_time=1.3, fmu_dir=fmu_dir,
                            estimate=False)  # the plot draws no estimate: no companion
    ref = crankfmu.reference(SERVO, stop_time=1.3, rtol=1e-8)
    fig = run.plot(steady=True, reference=ref)
    assert matplotlib.get_backend() == backend
    assert [ax.get_ylabel() for ax in fig.axes] == ["crank speed\npress.w_crank [rad/s]",
                                                   "drive torque\nmotor.flange_tau [N.m]"]
    assert "steady state: the last 2 revolutions" in fig.texts[0].get_text()
    speed_legend = [t.get_text() for t in fig.axes[0].get_legend().get_texts()]
    assert speed_legend == ["co-simulation = monolithic reference (curves coincide)"]
    t0 = fig.axes[0].get_lines()[0].get_xdata()[0]
    assert 0.5 <= t0 < 0.6  # the run-up from rest ([analysis].from_time = 0.5) is left out
    phi = run.plot().axes[0]  # the whole run: the crank angle within the revolution
    assert phi.get_ylabel() == "press.phi mod 2 pi\n[rad]"
    assert max(phi.get_lines()[0].get_ydata()) < 2 * np.pi


def test_coinciding_curves_share_one_legend_entry():
    from crankfmu.cosim.results import mark_coinciding, new_figure
    ax = new_figure().subplots()
    t = np.linspace(0, 1, 50)
    ax.plot(t, np.sin(t), label="a")
    ax.plot(t[::7], np.sin(t[::7]) + 1e-6, label="b")
    ax.plot(t, np.cos(t), label="c")
    assert mark_coinciding(ax) == [("a", "b")]
    assert ax.get_legend_handles_labels()[1] == ["a = b (curves coincide)", "c"]
    assert [ln.get_visible() for ln in ax.get_lines()] == [True, False, True]


def test_run_plot_draws_the_steady_state_with_the_reference_beside(tmp_path, fmu_dir):
    from crankfmu.cli import main
    scene = str(SERVO)
    assert main(["-q", "reference", scene, "--stop-time", "0.8", "--out", str(tmp_path),
                 "--rtol", "1e-8"]) == 0  # tmp_path/servo_press_reference.csv
    assert main(["-q", "run", scene, "--stop-time", "0.8", "--fmus", str(fmu_dir), "--out",
                 str(tmp_path), "--plot"]) == 0  # tmp_path/servo_press.csv, .json, .png
    assert (tmp_path / "servo_press.png").stat().st_size > 10_000
    from crankfmu.cosim.runner import _reference_beside
    from crankfmu.cosim.results import Recorder
    found = _reference_beside(tmp_path / "servo_press.csv", Recorder(["press.w_crank"], ["rad/s"]))
    assert found is not None and "press.w_crank" in found[0]


def test_compare_accuracy_and_sweep_write_only_into_out(tmp_path, monkeypatch, fmu_dir):
    import copy

    import crankfmu
    monkeypatch.chdir(tmp_path)
    a = crankfmu.load_scene(SERVO)
    b = copy.deepcopy(a)
    b.name = "with_flywheel"
    b.components["motor"].parameters["J_flywheel"] = 0.1
    cmp = crankfmu.compare(a, b, stop_time=0.7, fmu_dir=fmu_dir)
    assert "N.m" in cmp.text and cmp.csv is None
    acc = crankfmu.accuracy(SERVO, stop_time=0.05, algorithms=["gauss-seidel"],
                            extrapolations=[0], steps=[2e-3], fmu_dir=fmu_dir,
                            reference_rtol=1e-8)
    assert acc.outcomes[0].ok and acc.csv is None
    table = crankfmu.sweep(SERVO, ["motor.J_flywheel=0,0.1"], stop_time=0.7, jobs=1,
                           fmu_dir=fmu_dir, progress=False)
    assert len(table) == 2 and table.csv is None
    # each an object with its units and to_pandas (before: compare gave a dict, none had it)
    df = cmp.to_pandas()
    assert df.loc["mean_crank_speed", "unit"] == "rad/s" == df.attrs["units"]["mean_crank_speed"]
    assert df.loc["strokes", a.name] == cmp.table[0][2]
    df = acc.to_pandas()
    assert list(df.columns) == acc.columns and df.attrs["units"]["step"] == "s"
    assert df["step"].tolist() == [2e-3] and df["error"].tolist() == [acc.outcomes[0].error]
    df = table.to_pandas()
    assert df.attrs["units"]["motor.J_flywheel"] == "kg.m2" and \
        df.attrs["units"]["mean_crank_speed"] == "rad/s"
    assert df["motor.J_flywheel"].tolist() == [0.0, 0.1]
    # 0.5 to 0.7 s holds no whole revolution: those figures are missing, and the row says why
    assert table.rows[1]["status"] == "figures missing"
    assert table.rows[1]["reason"].startswith("cycle_time, energy_per_stroke: no whole crank "
                                              "revolution between from_time = 0.5 s")
    assert list(tmp_path.iterdir()) == []
    crankfmu.accuracy(SERVO, out=tmp_path / "acc", stop_time=0.05, algorithms=["jacobi"],
                      extrapolations=[0], steps=[2e-3], fmu_dir=fmu_dir, reference_rtol=1e-8)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["acc"]
    assert (tmp_path / "acc" / "accuracy.csv").is_file()


def test_inputs_take_a_table_with_its_interpolation_as_a_scene_file_does(servo_scene):
    """inputs={ref: {"table": ..., "interpolation": "step"}} is the scene file's form; it raised
    a ValueError traceback (the dict was read as rows); bad forms name the key."""
    from crankfmu.system.scene import SceneError, set_input
    set_input(servo_scene, "motor.u", {"table": [[0.0, 0.0], [0.1, 220.0]],
                                       "interpolation": "step"})
    signal = servo_scene.inputs["motor.u"]
    assert (signal.times, signal.values, signal.interpolation) == ([0.0, 0.1], [0.0, 220.0],
                                                                     "step")
    set_input(servo_scene, "motor.u", [[0.0, 1.0], [1.0, 2.0]])
    assert servo_scene.inputs["motor.u"].interpolation == "linear"
    for bad in ({"table": [[0.0, 1.0]], "interpolation": "cubic"}, "220", [[0.0, "x"]]):
        with pytest.raises(SceneError, match="motor.u"):
            set_input(servo_scene, "motor.u", bad)


NO_GUARD = """
import sys
import crankfmu
print("the script's body ran", flush=True)
jobs, scene, fmus = int(sys.argv[1]), sys.argv[2], sys.argv[3]
table = crankfmu.sweep(scene, ["motor.J_flywheel=0,0.1"], stop_time=0.7, jobs=jobs,
                       fmu_dir=fmus)
acc = crankfmu.accuracy(scene, stop_time=0.05, algorithms=["jacobi"], extrapolations=[1],
                        steps=[2e-3], reference_rtol=1e-8, jobs=jobs, fmu_dir=fmus)
print("done:", len(table), "sweep runs,", len(acc.outcomes), "accuracy runs", flush=True)
"""


def _script(tmp_path, jobs: int, fmu_dir, start_method: str = ""):
    import subprocess

    from tests.conftest import ROOT
    script = tmp_path / "study.py"
    script.write_text(NO_GUARD)
    env = {**__import__("os").environ, "PYTHONPATH": str(ROOT / "sources"),
           "CRANKFMU_START_METHOD": start_method}
    return subprocess.run([sys.executable, str(script), str(jobs), str(SERVO), str(fmu_dir)],
                          cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300)


def test_a_script_without_a_main_guard_runs_once_with_jobs_1(tmp_path, fmu_dir):
    """Before: crankfmu.sweep and crankfmu.accuracy started a worker pool with jobs=1 too, whose
    worker imported the script again: its body ran twice and multiprocessing's bootstrapping
    RuntimeError ended it. jobs=1 now runs in the calling process."""
    done = _script(tmp_path, 1, fmu_dir)
    assert done.returncode == 0, done.stderr
    assert done.stdout.count("the script's body ran") == 1
    assert "done: 2 sweep runs, 1 accuracy runs" in done.stdout


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="forked workers: Linux")
def test_forked_workers_run_a_script_without_a_main_guard_once(tmp_path, fmu_dir):
    """On Linux the pool's workers are forked from the calling process (cosim.workers.start_method):
    they do not import the script again, so its body runs once with jobs=2 too (before, with
    spawned workers: the WorkerStartError of the next test)."""
    done = _script(tmp_path, 2, fmu_dir)
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.count("the script's body ran") == 1
    assert "done: 2 sweep runs, 1 accuracy runs" in done.stdout


@pytest.mark.parametrize("start_method", ["forkserver", "spawn"])
def test_a_pool_from_a_script_without_a_main_guard_says_what_to_do(tmp_path, fmu_dir,
                                                                   start_method):
    """With jobs=2 workers from a fork server (Linux, where the script runs other threads) or
    spawned (macOS, Windows) import the script again: crankfmu stops with a WorkerStartError
    that names the guard (before: multiprocessing's RuntimeError in every worker, and lost
    runs)."""
    done = _script(tmp_path, 2, fmu_dir, start_method)
    assert done.returncode == 1 and "done:" not in done.stdout
    last = done.stderr.strip().splitlines()[-1]
    assert last.startswith("crankfmu.cosim.companions.WorkerStartError: ") and \
        'if __name__ == "__main__":' in last, done.stderr[-2000:]
    assert "leaked semaphore" not in done.stderr


@pytest.mark.parametrize("start", ["executor", "companions"])
def test_a_worker_importing_the_script_makes_no_pool(monkeypatch, start):
    """In a spawned worker still importing the script (multiprocessing marks it `_inheriting`)
    crankfmu raises WorkerStartError before it makes a pool. Before, it made one (its
    semaphores registered with the resource tracker) and failed as the pool started a worker:
    under load the tracker's "leaked semaphore" warning came after the parent's error, the last
    line of the test above (it failed so twice in a row in the suite)."""
    import multiprocessing

    from crankfmu.cosim import workers
    from crankfmu.cosim.companions import Companions, WorkerStartError
    from crankfmu.studies.executor import LocalPoolExecutor

    def new_pool(*args, **kwargs):
        raise AssertionError("a pool was made")
    monkeypatch.setattr(workers, "new_pool", new_pool)
    monkeypatch.setattr(multiprocessing.current_process(), "_inheriting", True, raising=False)
    with pytest.raises(WorkerStartError, match="__main__"):
        LocalPoolExecutor(2) if start == "executor" else Companions(2)


@pytest.mark.parametrize("study", ["sweep", "accuracy", "compare"])
def test_a_worker_importing_the_script_makes_no_temporary_folder(monkeypatch, study):
    """The API's studies without `out` work in a temporary folder: in a worker still importing
    the script they raise WorkerStartError before they make it. Before, sweep and accuracy made
    it first; a worker that the parent stopped while it imported (before its exit handlers are
    set) left it in /tmp: 7 empty crankfmu-sweep-* folders after a day of test runs."""
    import multiprocessing
    import tempfile

    import crankfmu
    from crankfmu.cosim.companions import WorkerStartError

    def mkdtemp(*args, **kwargs):
        raise AssertionError("a temporary folder was made")
    monkeypatch.setattr(tempfile, "mkdtemp", mkdtemp)
    monkeypatch.setattr(multiprocessing.current_process(), "_inheriting", True, raising=False)
    call = {"sweep": lambda: crankfmu.sweep(SERVO, "motor.J_flywheel=0,0.1", jobs=2),
            "accuracy": lambda: crankfmu.accuracy(SERVO, jobs=2),
            "compare": lambda: crankfmu.compare(SERVO, SERVO)}[study]
    with pytest.raises(WorkerStartError, match="__main__"):
        call()


def test_the_api_functions_stay_whatever_is_imported():
    """crankfmu.reference, accuracy, compare and sweep stay the API's functions when every
    subpackage and module is imported, and the package is a plain module: no subpackage shares
    their names (before: crankfmu/reference/ did, and the package swapped its module class so
    that importing it would not replace the function)."""
    import importlib
    import pkgutil
    import types

    import crankfmu
    for module in pkgutil.iter_modules(crankfmu.__path__, "crankfmu."):
        if module.name != "crankfmu.__main__":
            importlib.import_module(module.name)
    for name in ("crankfmu.studies.accuracy", "crankfmu.studies.compare",
                 "crankfmu.studies.sweep", "crankfmu.monolithic.solve"):
        importlib.import_module(name)
    assert type(crankfmu) is types.ModuleType
    for name in ("reference", "accuracy", "compare", "sweep"):
        assert isinstance(getattr(crankfmu, name), types.FunctionType), name
