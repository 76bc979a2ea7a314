"""Taylor coupling ([master].taylor = q, masters/taylor.py) on the two-mass oscillator of
test_masters.py, against its closed form: the observed order, the exchanged derivatives against
the monolithic system's, and what a scene that cannot use it is told.

Both FMUs integrate their steps exactly (matrix exponential, for input polynomials of any
degree), so every error measured here is the coupling's. Measured on this machine (stop 1 s,
steps 1e-2, 5e-3, 2.5e-3; error as in test_masters.py):

    master        taylor   error at h = 5e-3   observed orders
    jacobi        1 .. 4   2.0e-3, 4.2e-5, 7.4e-7, 1.0e-8   2.00/2.00, 2.98/3.00, 3.98/3.99, 4.95/4.98
    gauss-seidel  1 .. 4   1.1e-3, 2.1e-5, 4.0e-7, 5.2e-9   2.00/2.00, 3.00/3.00, 4.00/4.00, 4.99/4.99

(extrapolation 2, the same order as taylor 2: 3.7e-4 and 1.6e-4, 9x and 8x the error.)
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from crankfmu.masters import taylor as taylor_module
from crankfmu.masters.options import OptionError
from crankfmu.system.load import load_scene
from crankfmu.system.scene import SceneError
from tests.test_masters import OSCILLATOR, STEPS, orders, run, speed_error

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize("algorithm", ["jacobi", "gauss-seidel"])
@pytest.mark.parametrize("q", [1, 2, 3, 4])
def test_taylor_coupling_order_is_q_plus_one(tmp_path, fmu_dir, algorithm, q):
    """Global order q + 1 (an input error O(h^(q+1)) per step): within +-0.3 of it, as the
    extrapolating masters' orders in test_masters.py (measured 1.99 to 5.00, module
    docstring). Errors at h = 2.5 ms stay above 1e-10, far above round-off."""
    errors = [speed_error(run(tmp_path, fmu_dir, {"algorithm": algorithm, "step": h,
                                                  "taylor": q})) for h in STEPS]
    for order in orders(errors):
        assert abs(order - (q + 1)) < 0.3, (errors, orders(errors))


@pytest.mark.parametrize("algorithm", ["jacobi", "gauss-seidel"])
def test_taylor_polynomial_beats_extrapolation_of_the_same_order(tmp_path, fmu_dir,
                                                                 algorithm):
    """A Taylor polynomial misses a signal by y''' h^3/3! at the step's end, the parabola
    through the last three points by y''' h^3: asymptotically 6x. Measured 8.9x (Jacobi) and
    7.7x (Gauss-Seidel) at h = 5 ms; at least 4x required."""
    h = STEPS[1]
    extrapolated = speed_error(run(tmp_path, fmu_dir, {"algorithm": algorithm, "step": h,
                                                       "extrapolation": 2}))
    taylor = speed_error(run(tmp_path, fmu_dir, {"algorithm": algorithm, "step": h,
                                                 "taylor": 2}))
    assert taylor * 4 < extrapolated, (taylor, extrapolated)


def monolithic_matrix(p: dict) -> np.ndarray:
    """x' = A x for x = [phi1, w1, theta, phi2, w2] (test_masters.exact_speeds)."""
    J1, c1, d1, J2, k, ds, c2, d2 = (p[n] for n in "J1 c1 d1 J2 k ds c2 d2".split())
    return np.array([[0, 1, 0, 0, 0],
                     [-c1 / J1, -(d1 + ds) / J1, -k / J1, 0, ds / J1],
                     [0, 1, 0, 0, -1],
                     [0, 0, 0, 0, 1],
                     [0, ds / J2, k / J2, -c2 / J2, -(ds + d2) / J2]])


def test_exchange_rounds_give_the_monolithic_derivatives(tmp_path, fmu_dir, monkeypatch):
    """q rounds make every exchanged derivative that of the coupled system: at each point of a
    Gauss-Seidel run, the rows of r1.flange_w (= w1) and r2.flange_tau (= -(k theta +
    d_s (w1 - w2))) equal C A^k x, x the FMUs' state at that point (phi1, w1 from r1's outputs,
    theta, phi2, w2 from r2's: their states, so the check needs no reference). To 1e-9 of the
    row's scale: both FMUs' rows are exact (linear models), so only round-off differs."""
    q = 4
    p = OSCILLATOR
    A = monolithic_matrix(p)
    checked = []
    original = taylor_module.TaylorCoupling.rows_at

    def rows_at(self, t):
        if self._at[0] == t:  # asked again within the step: the rows of its start
            return original(self, t)
        system = self.system
        r1, r2 = system.fmus["r1"], system.fmus["r2"]
        phi1, w1 = r1.reader(["flange_phi", "flange_w"])()
        tau, phi2, w2 = r2.reader(["flange_tau", "phi", "w"])()
        theta = (-tau - p["ds"] * (w1 - w2)) / p["k"]
        x = np.array([phi1, w1, theta, phi2, w2])
        exact = self.exchange(t, {c: [list(v)] for c, v in system.outputs.items()}, q)
        for k in range(q + 1):
            xk = np.linalg.matrix_power(A, k) @ x
            want = {"r1": xk[1], "r2": -(p["k"] * xk[2] + p["ds"] * (xk[1] - xk[4]))}
            for comp, value in want.items():
                got = exact[comp][k][0]
                scale = np.max(np.abs(np.linalg.matrix_power(A, k))) * np.max(np.abs(x)) * \
                    (1 + p["k"])
                assert abs(got - value) <= 1e-9 * scale, (t, comp, k, got, value)
        checked.append(t)
        return original(self, t)
    monkeypatch.setattr(taylor_module.TaylorCoupling, "rows_at", rows_at)
    run(tmp_path, fmu_dir, {"algorithm": "gauss-seidel", "step": 1e-2, "taylor": q},
        stop=0.2)
    assert len(checked) == 20


def test_one_round_from_the_guess_as_accurate_as_q_rounds(tmp_path, fmu_dir, monkeypatch):
    """The master refreshes its guess with one round (masters/taylor.py); q rounds at every
    point (forced here: the external inputs count as changed at every point) give the
    coupled derivatives exactly. The run's error agrees within 10 % (measured: 0.03 %, 0.08 %,
    0.24 % at taylor 2, 3, 4, h = 5 ms; taking the guess without the round, the run diverged)."""
    settings = {"algorithm": "gauss-seidel", "step": STEPS[1], "taylor": 3}
    one_round = speed_error(run(tmp_path, fmu_dir, settings))
    monkeypatch.setattr(taylor_module.TaylorCoupling, "_external_values",
                        lambda self, t: [object()])
    exchanged = speed_error(run(tmp_path, fmu_dir, settings))
    assert abs(one_round - exchanged) < 0.1 * exchanged, (one_round, exchanged)


def test_taylor_and_extrapolation_are_not_both_taken(tmp_path):
    from crankfmu.masters.gauss_seidel import GaussSeidel
    settings = type("S", (), {"extrapolation": 2, "taylor": 3})()
    with pytest.raises(OptionError, match=r"\[master\].extrapolation: must be 0 with taylor = 3"):
        GaussSeidel.read_options(settings)


def test_a_scene_whose_fmus_give_no_derivatives_is_told_which(fmu_dir):
    """The crank-rocker hammer declares no output derivatives: a Taylor coupling of its scene
    is refused before any step, naming the component, its FMU and the missing variables."""
    from crankfmu.cosim.runner import RunOptions, run_scene
    scene = load_scene(ROOT / "scenarios" / "hammer.toml")
    scene.master.taylor, scene.master.extrapolation = 2, 0
    with pytest.raises(SceneError, match=r"hammer.toml: \[master\]: master gauss-seidel with "
                                         r"taylor = 2: hammer \(CrankRockerHammer.fmu\) has no "
                                         r"output derivatives flange_phi_d1, flange_w_d1"):
        run_scene(scene, RunOptions(out=None, fmu_dir=fmu_dir, progress=False))


def test_taylor_coupling_with_fmi3_components_gives_the_fmi2_numbers():
    """The servo press, adaptive with taylor 3, its press and motor as FMI 3.0 FMUs: every
    recorded value as with the FMI 2.0 FMUs, to 1e-12 of its largest magnitude (the same core
    computes the same derivatives; measured: equal)."""
    from crankfmu.cosim.runner import RunOptions, run_scene
    scene = load_scene(ROOT / "scenarios" / "servo_press.toml")
    scene.stop_time = 0.3
    scene.master.algorithm, scene.master.taylor, scene.master.tolerance = "adaptive", 3, 1e-3
    two = run_scene(scene, RunOptions(out=None, progress=False)).recorder
    for comp in scene.components.values():
        comp.fmi = 3
    three = run_scene(scene, RunOptions(out=None, progress=False)).recorder
    assert three.names == two.names and len(three.rows) == len(two.rows)
    scale = np.maximum(np.max(np.abs(two.rows), axis=0), 1e-300)
    assert float(np.max(np.abs(three.rows - two.rows) / scale)) <= 1e-12
