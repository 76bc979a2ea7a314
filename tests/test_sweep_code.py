"""The sweeps written out per scene (crankfmu.masters.sweep_code) against the generic sweeps of
crankfmu.masters.base, in the same process: the same recorded values, doStep counts, master
statistics and port energies, bit for bit (a written sweep is an optimization: any difference is
a defect). scripts/masters_identity.py makes the same comparison over every shipped scene
against a saved run of an earlier commit.

The scenes: the servo press (two FMUs in a feedback loop, a power port) and the conventional
press (three FMUs, a clutch command as a step table with an edge inside a 1.5 ms step, so the
fixed-step masters take split steps and the adaptive one ends a step at the edge), under
Gauss-Seidel, Jacobi and the adaptive master at extrapolation 0, 1 and 2.
"""
from __future__ import annotations

import warnings

import numpy as np
import pytest

from crankfmu.cosim.runner import RunOptions, run_scene
from crankfmu.masters import sweep_code
from crankfmu.system.load import load_scene
from tests.conftest import SCENARIOS

# scene -> (step [s], stop time [s]): past the start-up (the generic sweep's first steps) and,
# for the conventional press, past the clutch command's edge at 0.1 s
SPANS = {"servo_press": (1e-3, 0.06), "conventional_press": (1.5e-3, 0.12)}
MASTERS = ["gauss-seidel", "jacobi", "adaptive"]


def _run(scene, algorithm: str, extrapolation: int):
    scene.master.step, scene.stop_time = SPANS[scene.name]
    scene.master.algorithm, scene.master.extrapolation = algorithm, extrapolation
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the adaptive master's steps at min_step, alike in both
        result = run_scene(scene, RunOptions(progress=False))
    return (result.recorder.rows, {c: s["doStep_calls"] for c, s in result.statistics.items()},
            result.master_statistics, result.coupling_error)


def _recording(monkeypatch) -> list[bool]:
    """Each write_sweep of the test from now on, as True where it wrote a sweep."""
    written: list[bool] = []
    write_sweep = sweep_code.write_sweep

    def recording(master, sequential):
        sweep = write_sweep(master, sequential)
        written.append(sweep is not None)
        return sweep
    monkeypatch.setattr(sweep_code, "write_sweep", recording)
    return written


@pytest.mark.parametrize("extrapolation", [0, 1, 2])
@pytest.mark.parametrize("algorithm", MASTERS)
@pytest.mark.parametrize("name", sorted(SPANS))
def test_a_written_sweep_gives_the_generic_sweeps_floats(name, algorithm, extrapolation,
                                                         monkeypatch):
    written = _recording(monkeypatch)
    fast = _run(load_scene(SCENARIOS / f"{name}.toml"), algorithm, extrapolation)
    assert written == [True]  # the run used a written sweep (else the comparison is empty)
    monkeypatch.setattr(sweep_code, "write_sweep", lambda master, sequential: None)
    generic = _run(load_scene(SCENARIOS / f"{name}.toml"), algorithm, extrapolation)
    assert np.array_equal(fast[0], generic[0]), np.max(np.abs(fast[0] - generic[0]))
    assert fast[1:] == generic[1:]


def test_fmi3_components_keep_the_generic_sweep(monkeypatch):
    """The written sweep calls FMI 2.0's functions: a scene of FMI 3.0 FMUs keeps the generic
    sweep (tests/test_fmi3.py: its numbers are the FMI 2.0 scene's)."""
    written = _recording(monkeypatch)
    scene = load_scene(SCENARIOS / "servo_press.toml")
    for component in scene.components.values():
        component.fmi = 3
    _run(scene, "gauss-seidel", 2)
    assert written == [False]
