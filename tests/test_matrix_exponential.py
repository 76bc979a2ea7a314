"""The FMU runtime's matrix exponential (crankfmu/runtime/matrix_exponential.py: Higham's scaling
and squaring, numpy alone) against closed forms and an independent long-double series, and the
reason it exists: an FMU process never imports scipy."""
from __future__ import annotations

import math

import numpy as np
import pytest

from crankfmu.runtime.matrix_exponential import expm


def _series_expm(A: np.ndarray) -> np.ndarray:
    """exp(A) in long double (64-bit mantissa, unit round-off 5.4e-20 on x86-64, 11 bits more
    than double): A scaled by 2^-s to a 1-norm below 0.05, 30 terms of the Taylor series
    (truncation below 0.05^31/31!, nothing in long double) and s squarings."""
    X = A.astype(np.longdouble)
    norm = float(np.max(np.sum(np.abs(X), axis=0)))
    squarings = max(0, math.ceil(math.log2(norm / 0.05))) if norm > 0.0 else 0
    X = X / np.longdouble(2.0) ** squarings
    term = np.eye(len(A), dtype=np.longdouble)
    total = term.copy()
    for k in range(1, 31):
        term = term @ X / k
        total = total + term
    for _ in range(squarings):
        total = total @ total
    return total


def _relative(a, b) -> float:
    return float(np.max(np.abs(np.asarray(a, dtype=np.longdouble) - b)) / np.max(np.abs(b)))


def test_closed_forms():
    """A rotation (w t up to 23 rad: 3 squarings), a nilpotent Jordan block (the series ends:
    the input chain of a Rotor's step), a diagonal, the zero matrix: to 8 units of round-off of
    the largest entry where 3 squarings double the error 3 times (measured 6.5 and 4.1), to 2
    without squarings (measured 0.5 and 1)."""
    eps = np.finfo(float).eps
    for w, t in ((7.0, 3.3), (1.0, 1e-3), (50.0, 0.02)):
        exact = np.array([[math.cos(w * t), math.sin(w * t)], [-math.sin(w * t), math.cos(w * t)]])
        assert np.max(np.abs(expm(np.array([[0.0, w], [-w, 0.0]]) * t) - exact)) <= (
            8 if w * t > 5.37 else 2) * eps
    jordan = np.diag([1.0, 1.0, 1.0], 1) * 2.0  # exp = I + N + N^2/2 + N^3/6, N = 2 J
    exact = np.array([[1, 2, 2, 4 / 3], [0, 1, 2, 2], [0, 0, 1, 2], [0, 0, 0, 1]], dtype=float)
    assert np.max(np.abs(expm(jordan) - exact)) <= 2 * eps * 2
    diagonal = np.array([-30.0, -1.0, 0.5, 4.0])  # normwise: e^-30 is 1e-15 of e^4
    assert _relative(expm(np.diag(diagonal)), np.diag(np.exp(diagonal))) <= 8 * eps
    assert np.array_equal(expm(np.zeros((3, 3))), np.eye(3))
    assert expm([[2.0]])[0, 0] == pytest.approx(math.exp(2.0), rel=2 * eps)


@pytest.mark.parametrize("size", [1, 2, 3, 5, 8])
def test_random_matrices_against_a_long_double_series(size):
    """20 random matrices per scale, 1-norms from 1e-3 to 60 (all five Pade degrees, up to 4
    squarings): within 1e-13 of the largest entry (measured at most 1.9e-14; the error grows
    with the norm through the squarings, so the bound is the largest norm's with a factor 5).
    scipy.linalg.expm, the previous implementation, within 1e-11 (measured 1.8e-12, which is
    scipy's own error against the series)."""
    from scipy.linalg import expm as scipy_expm
    rng = np.random.default_rng(size)
    for scale in (1e-3, 0.1, 0.5, 2.0, 5.0, 20.0 / size):
        for _ in range(20):
            A = rng.standard_normal((size, size)) * scale
            reference = _series_expm(A)
            assert _relative(expm(A), reference) <= 1e-13, (scale, A)
            assert _relative(expm(A), scipy_expm(A)) <= 1e-11


def test_rejects_what_is_not_a_finite_square_matrix():
    with pytest.raises(ValueError, match="square"):
        expm(np.ones((2, 3)))
    with pytest.raises(ValueError, match="finite"):
        expm(np.array([[0.0, np.nan], [0.0, 0.0]]))


FMU_STEPS = """
import sys
from fmpy import read_model_description, extract
from fmpy.fmi2 import FMU2Slave
for path in sys.argv[1:]:
    description = read_model_description(path)
    fmu = FMU2Slave(guid=description.guid, unzipDirectory=extract(path),
                    modelIdentifier=description.coSimulation.modelIdentifier,
                    instanceName="probe")
    fmu.instantiate()
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    fmu.exitInitializationMode()
    for k in range(5):
        fmu.doStep(currentCommunicationPoint=k * 1e-3, communicationStepSize=1e-3)
    fmu.terminate()
    fmu.freeInstance()
print(sorted(m for m in sys.modules if m == "scipy" or m.startswith("scipy.")))
"""


def test_no_catalog_fmu_imports_scipy(fmu_dir):
    """Every catalog FMU instantiated, initialized and stepped 5 ms (a fresh interpreter,
    tests/support/fresh_python.py, whose preloads import no scipy) leaves scipy unimported:
    `import scipy.linalg` alone costs 0.24-0.29 s of CPU, which Rotor and ShaftRotor paid at
    their first step in every process that ran them (17 processes of the test suite)."""
    from crankfmu.models.catalog import FMU_MODELS
    from tests.support import fresh_python
    fmus = [str(fmu_dir / f"{model}.fmu") for model in FMU_MODELS]
    done = fresh_python.run(FMU_STEPS, fmus, timeout=120)
    assert done.returncode == 0, done.stderr[-3000:]
    assert done.stdout.strip().splitlines()[-1] == "[]"
