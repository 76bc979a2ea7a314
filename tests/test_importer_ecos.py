"""crankfmu's FMUs in ecos (via ecospy): alone, and the servo press as a connected two-FMU system
against crankfmu's Jacobi master."""
from __future__ import annotations

import numpy as np
import pytest

from crankfmu.cosim.runner import RunOptions, run_scene
from crankfmu.physics.catalog import FMU_MODELS

from importer_support import require_ecospy

require_ecospy()
from crankfmu.interop import ecos  # noqa: E402
from crankfmu.interop.plan import plan_scene, plan_single_fmu  # noqa: E402
from importer_support import (IMPORTER_STOP, catalog_fmus, jacobi_scene,  # noqa: E402,F401
                              relative_deviation)

STOP = IMPORTER_STOP  # s (importer_support: 200 Jacobi steps of 1 ms)


@pytest.mark.parametrize("model", list(FMU_MODELS))
def test_every_fmu_runs_alone_on_its_start_values(catalog_fmus, model):
    """No input connected, nothing set: ecos initializes and steps the FMU for 0.05 s, and gives
    the numbers libcosim gives (when libcosimpy is installed): two independent importers, the
    same FMU, step and default tolerance. 1e-9 relative as for the connected scene; measured
    0 for most FMUs, 5.5e-13 at most (RockerImpact; the engines' clocks differ in the last
    bits)."""
    plan = plan_single_fmu(catalog_fmus / f"{model}.fmu", stop_time=0.05, step=1e-3)
    result = ecos.run(plan)
    assert len(result.times) == 51 and result.times[-1] == pytest.approx(0.05, abs=1e-15)
    assert plan.record, f"{model} has no Real output"
    for name, values in result.columns.items():
        assert np.all(np.isfinite(values)), f"{name} not finite in ecos"
    try:
        from crankfmu.interop import libcosim
        import libcosimpy  # noqa: F401
    except ImportError:
        return
    other = libcosim.run(plan)
    for name, values in result.columns.items():
        dev = relative_deviation(values, other.column(name))
        assert dev < 1e-9, f"{name}: ecos vs libcosim deviate by {dev:.3g}"



def test_servo_press_in_ecos_equals_crankfmu_jacobi(jacobi_scene, fmu_dir, tmp_path):
    """Same algorithm (Jacobi), same step, same FMU tolerance (1e-8, the FMUs' default, which
    ecos leaves in place), same initialization result: the same numbers. 1e-9 relative is the
    issue's bound; measured 2.9e-16."""
    rec = run_scene(jacobi_scene, RunOptions(out=tmp_path / "jacobi.csv", fmu_dir=fmu_dir,
                                             progress=False)).recorder
    result = ecos.run(plan_scene(jacobi_scene, fmu_dir))
    np.testing.assert_allclose(result.times, rec.rows[:, 0], rtol=0, atol=1e-12)
    for name in rec.names:
        dev = relative_deviation(result.column(name), rec.column(name))
        assert dev < 1e-9, f"{name}: ecos vs crankfmu Jacobi deviate by {dev:.3g}"
    assert rec.column("press.phi")[-1] > 1.0 and np.max(rec.column("press.F5")) > 0.0
    # and not trivially: Gauss-Seidel at the same step is far from ecos's Jacobi
    jacobi_scene.master.algorithm = "gauss-seidel"
    try:
        gs = run_scene(jacobi_scene, RunOptions(out=tmp_path / "gs.csv", fmu_dir=fmu_dir,
                                                progress=False)).recorder
    finally:
        jacobi_scene.master.algorithm = "jacobi"
    assert relative_deviation(result.column("press.w_crank"), gs.column("press.w_crank")) > 1e-7


def test_two_ecos_runs_in_one_process_give_the_same_numbers(jacobi_scene, fmu_dir):
    """ecos steps FMUs on TBB threads; Python FMUs take the interpreter lock there. A second
    simulation of the same FMUs in the same process repeats the first bit for bit."""
    jacobi_scene.stop_time = 0.02
    try:
        plan = plan_scene(jacobi_scene, fmu_dir)
    finally:
        jacobi_scene.stop_time = STOP
    first, second = ecos.run(plan), ecos.run(plan)
    for name in first.columns:
        np.testing.assert_array_equal(first.column(name), second.column(name))
