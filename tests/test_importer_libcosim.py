"""crankfmu's FMUs in libcosim (Open Simulation Platform, via libcosimpy): alone, and the servo
press as a connected two-FMU system against crankfmu's Jacobi master."""
from __future__ import annotations

import copy

import numpy as np
import pytest

from crankfmu.cosim.runner import RunOptions, run_scene
from crankfmu.runtime.model import SCIPY_SOLVER
from crankfmu.models.catalog import FMU_MODELS
from crankfmu.system.scene import SceneError

pytest.importorskip("libcosimpy")
from crankfmu.interop import libcosim  # noqa: E402
from crankfmu.interop.plan import plan_scene, plan_single_fmu  # noqa: E402
from tests.support.importer_support import IMPORTER_STOP, relative_deviation  # noqa: E402

STOP = IMPORTER_STOP  # s (importer_support: 200 Jacobi steps of 1 ms)


@pytest.mark.parametrize("model", list(FMU_MODELS))
def test_every_fmu_runs_alone_on_its_start_values(fmu_dir, model):
    """No input connected, nothing set: libcosim initializes and steps the FMU for 0.05 s."""
    plan = plan_single_fmu(fmu_dir / f"{model}.fmu", stop_time=0.05, step=1e-3)
    result = libcosim.run(plan)
    assert len(result.times) == 51 and result.times[-1] == pytest.approx(0.05, abs=1e-15)
    assert plan.record, f"{model} has no Real output"
    for name, values in result.columns.items():
        assert np.all(np.isfinite(values)), f"{name} not finite in libcosim"



@pytest.fixture(scope="module")
def crankfmu_jacobi(jacobi_scene, fmu_dir, tmp_path_factory):
    out = tmp_path_factory.mktemp("jacobi") / "servo_press.csv"
    return run_scene(jacobi_scene, RunOptions(out=out, fmu_dir=fmu_dir, progress=False)).recorder


@pytest.fixture(scope="module")
def libcosim_servo(jacobi_scene, fmu_dir):
    return libcosim.run(plan_scene(jacobi_scene, fmu_dir))


def test_servo_press_in_libcosim_equals_crankfmu_jacobi(libcosim_servo, crankfmu_jacobi):
    """Same algorithm (Jacobi), same step, same FMU tolerance (1e-8, the FMUs' default, which
    libcosim leaves in place), same initialization result: the same numbers. 1e-9 relative is
    the issue's bound; measured 1.1e-14 (libcosim's integer-nanosecond clock makes the
    doStep times differ from crankfmu's t0 + k h in the last bit)."""
    rec = crankfmu_jacobi
    np.testing.assert_allclose(libcosim_servo.times, rec.rows[:, 0], rtol=0, atol=1e-12)
    for name in rec.names:
        dev = relative_deviation(libcosim_servo.column(name), rec.column(name))
        assert dev < 1e-9, f"{name}: libcosim vs crankfmu Jacobi deviate by {dev:.3g}"
    # the run went somewhere: the crank has turned and the forging load was met
    assert rec.column("press.phi")[-1] > 1.0 and np.max(rec.column("press.F5")) > 0.0


def test_the_comparison_tells_algorithms_and_solvers_apart(
        libcosim_servo, crankfmu_jacobi, jacobi_scene, fmu_dir, tmp_path):
    """The 1e-9 agreement above is not trivial: Gauss-Seidel at the same step, or Jacobi with
    the FMUs integrating on their scipy path (scipy_solver: DOP853/Radau instead of the runtime's
    Dormand-Prince and closed form, both at tolerance 1e-8), deviate from libcosim by more than
    1e-9 (measured: 2.4e-2 and 1.2e-8 in the crank speed). (Another FMU tolerance no longer
    tells them apart: at 1 ms the press takes one internal step per doStep, well inside any
    tolerance up to 1e-2, and the motor is integrated in closed form.)"""
    for algorithm, scipy_solver in (("gauss-seidel", False), ("jacobi", True)):
        trial = copy.deepcopy(jacobi_scene)
        trial.master.algorithm = algorithm
        for comp in trial.components.values():
            comp.parameters[SCIPY_SOLVER] = scipy_solver
        rec = run_scene(trial, RunOptions(out=tmp_path / f"{algorithm}.csv", fmu_dir=fmu_dir,
                                          progress=False)).recorder
        dev = relative_deviation(libcosim_servo.column("press.w_crank"), rec.column("press.w_crank"))
        assert dev > 1e-9, f"{algorithm}, scipy_solver {scipy_solver}: only {dev:.3g}"


def test_a_scene_asking_for_another_fmu_tolerance_is_refused(jacobi_scene, fmu_dir):
    """libcosim calls fmi2SetupExperiment without a tolerance; running such a scene would
    silently use the FMUs' default 1e-8."""
    jacobi_scene.master.fmu_tolerance = 1e-6
    try:
        with pytest.raises(SceneError, match=r"fmu_tolerance.*1e-06.*default tolerance 1e-08"):
            plan_scene(jacobi_scene, fmu_dir)
    finally:
        jacobi_scene.master.fmu_tolerance = 1e-8


def test_a_time_table_input_is_refused_with_its_key(jacobi_scene, fmu_dir):
    """The adapters set constant inputs only; a table would silently become its first value."""
    from crankfmu.system.scene import InputSignal
    saved = dict(jacobi_scene.inputs)
    jacobi_scene.inputs["motor.u"] = InputSignal("motor.u", [0.0, 0.1], [0.0, 220.0])
    try:
        with pytest.raises(SceneError, match=r'\[inputs\]\."motor\.u".*constant inputs only'):
            plan_scene(jacobi_scene, fmu_dir)
    finally:
        jacobi_scene.inputs.clear()
        jacobi_scene.inputs.update(saved)


def test_impossible_parameters_are_refused_before_the_engine_starts(jacobi_scene, fmu_dir):
    """Inside libcosim (and ecos) an FMU's fatal error in initialization kills the process
    (measured: abort on an uncaught C++ exception), so the plan checks catalog parameters with
    the physics' own message first."""
    press = jacobi_scene.components["press"].parameters
    press["l"] = 0.01  # a rod shorter than the crank (r = 0.05 m) cannot assemble
    try:
        with pytest.raises(SceneError, match=r"\[components\.press\]\.parameters.*l = 0\.01"):
            plan_scene(jacobi_scene, fmu_dir)
    finally:
        press["l"] = 0.25
