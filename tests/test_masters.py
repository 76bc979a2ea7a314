"""Master algorithms on a linear two-mass oscillator split over two FMUs, against its closed form.

FMU r1 = Rotor (J1, spring c1 to ground; torque in, speed out), FMU r2 = ShaftRotor (shaft k, d_s
and rotor J2; speed in, torque out): sources/crankfmu/models/rotor/README.md. With x = [phi1, w1, theta, phi2, w2]
the monolithic system is x' = A x, solved exactly by x(t) = expm(A t) x0. Both FMUs integrate
their steps exactly (matrix exponential), so every error measured here is the coupling's.

Error metric: max over the recorded points of |w - w_exact| for both rotors, divided by the
peak exact speed. Measured on this machine (stop 1 s, steps 1e-2, 5e-3, 2.5e-3):

    master        extrapolation   error at h = 5e-3   observed orders
    jacobi        0, 1, 2         7.8e-2, 5.0e-3, 3.7e-4   1.17/1.08, 2.01/2.00, 2.99/3.00
    gauss-seidel  0, 1, 2         1.2e-2, 2.0e-3, 1.6e-4   0.99/1.00, 2.01/2.00, 3.00/3.00
    iterative     0 (=1), 2       9.8e-4, 4.0e-5           2.00/2.00, 3.00/3.00

(iterative: tolerance 1e-10; its inputs interpolate towards the iterate at t + h, order >= 1.)
"""
from __future__ import annotations

import json
import math

import numpy as np
import pytest
from scipy.linalg import expm

from crankfmu.cosim import runner
from crankfmu.cosim.runner import RunError, RunOptions, run_scene
from crankfmu.system.load import load_scene
from crankfmu.system.scene import SceneError

OSCILLATOR = dict(J1=1.0, c1=10.0, d1=0.0, J2=0.5, k=100.0, ds=0.5, c2=0.0, d2=0.0, w10=2.0)
STEPS = (1e-2, 5e-3, 2.5e-3)  # s; the record grid 1e-2 s is common to all three


def scene_file(tmp_path, master: dict, p: dict, stop: float, record: float | None):
    lines = "\n".join(f"{k} = {json.dumps(v)}" for k, v in master.items())
    interval = f"interval = {record}" if record else ""
    text = f"""
[scene]
name = "oscillator"
stop_time = {stop}
[master]
{lines}
[components.r1]
fmu = "Rotor"
parameters = {{ J = {p['J1']}, c = {p['c1']}, d = {p['d1']}, w0 = {p['w10']} }}
[components.r2]
fmu = "ShaftRotor"
parameters = {{ J = {p['J2']}, k = {p['k']}, d_s = {p['ds']}, c = {p['c2']}, d = {p['d2']} }}
[[connections]]
from = "r1.flange_w"
to = "r2.flange_w"
[[connections]]
from = "r2.flange_tau"
to = "r1.flange_tau"
[record]
variables = ["r1.flange_w", "r2.w", "r1.E", "r2.E"]
{interval}
"""
    path = tmp_path / "oscillator.toml"
    path.write_text(text)
    return path


def run(tmp_path, fmus, master: dict, p=OSCILLATOR, stop=1.0, record=1e-2):
    scene = load_scene(scene_file(tmp_path, master, p, stop, record))
    return run_scene(scene, RunOptions(out=tmp_path / "osc.csv", fmu_dir=fmus, progress=False))


def exact_speeds(p: dict, times: np.ndarray) -> np.ndarray:
    """(w1, w2) of x' = A x, x = [phi1, w1, theta, phi2, w2], theta = phi1 - phi2."""
    J1, c1, d1, J2, k, ds, c2, d2 = (p[n] for n in "J1 c1 d1 J2 k ds c2 d2".split())
    A = np.array([[0, 1, 0, 0, 0],
                  [-c1 / J1, -(d1 + ds) / J1, -k / J1, 0, ds / J1],
                  [0, 1, 0, 0, -1],
                  [0, 0, 0, 0, 1],
                  [0, ds / J2, k / J2, -c2 / J2, -(ds + d2) / J2]])
    x0 = np.array([0.0, p["w10"], 0.0, 0.0, 0.0])
    x = np.array([expm(A * t) @ x0 for t in times])
    return x[:, [1, 4]]


def speed_error(result, p=OSCILLATOR) -> float:
    rows = result.recorder.rows
    ref = exact_speeds(p, rows[:, 0])
    return float(np.max(np.abs(rows[:, 1:3] - ref)) / np.max(np.abs(ref)))


def orders(errors) -> list[float]:
    return [math.log2(a / b) for a, b in zip(errors, errors[1:])]


def omega_max(p=OSCILLATOR) -> float:
    """Highest natural frequency of the undamped oscillator [rad/s] (17.6 here)."""
    K = np.array([[p["c1"] + p["k"], -p["k"]], [-p["k"], p["k"] + p["c2"]]])
    M = np.diag([p["J1"], p["J2"]])
    return float(np.sqrt(np.max(np.linalg.eigvals(np.linalg.solve(M, K)).real)))


@pytest.mark.parametrize("algorithm", ["jacobi", "gauss-seidel"])
@pytest.mark.parametrize("extrapolation", [0, 1, 2])
def test_fixed_step_masters_error_and_order(tmp_path, fmu_dir, algorithm, extrapolation):
    errors = [speed_error(run(tmp_path, fmu_dir, {"algorithm": algorithm, "step": h,
                                                  "extrapolation": extrapolation}))
              for h in STEPS]
    # Bound: an input extrapolated with order p misses a signal of frequency w by about
    # (w h)^(p+1) of its amplitude per step; the global error stays below that size here.
    assert errors[1] < (omega_max() * STEPS[1]) ** (extrapolation + 1), errors
    # Observed order within +-0.3 of p + 1 (measured values in the module docstring).
    for q in orders(errors):
        assert abs(q - (extrapolation + 1)) < 0.3, (errors, orders(errors))


def test_iterative_master_converges_to_the_reference(tmp_path, fmu_dir):
    results = {k: [run(tmp_path, fmu_dir, {"algorithm": "iterative", "step": h,
                                           "extrapolation": k, "tolerance": 1e-10})
                   for h in STEPS[:2]] for k in (0, 2)}
    for k, expected in ((0, 2), (2, 3)):  # linear (trapezoidal) / quadratic interpolation
        errors = [speed_error(r) for r in results[k]]
        assert abs(orders(errors)[0] - expected) < 0.3, errors
        for r in results[k]:
            assert r.master_statistics["non_converged_steps"] == 0
            assert r.statistics["r1"]["rollbacks"] > 0
    # A given accuracy at a larger step: at h = 1e-2 s the iterative master (order 3) is more
    # than 3 times as accurate as Gauss-Seidel with extrapolation 2 (measured 3.2e-4 against
    # 1.3e-3), i.e. Gauss-Seidel needs a step below 0.7 h to match it.
    gs = speed_error(run(tmp_path, fmu_dir, {"algorithm": "gauss-seidel", "step": STEPS[0],
                                             "extrapolation": 2}))
    assert speed_error(results[2][0]) < gs / 3


def test_adaptive_master_meets_tolerance_with_fewer_steps(tmp_path, fmu_dir):
    """A damped oscillation (decays within about 1 s of 3 s): the adaptive master takes small
    steps while it rings and long ones after. Measured: tolerance 1e-4 -> error 3.0e-5 in 584
    accepted + 16 rejected steps; fixed-step Gauss-Seidel with 600 steps: error 1.0e-4."""
    damped = dict(OSCILLATOR, d1=0.3, ds=1.0)
    tol = 1e-4
    adaptive = run(tmp_path, fmu_dir, {"algorithm": "adaptive", "extrapolation": 2,
                                       "tolerance": tol, "step": 1e-3, "min_step": 1e-6,
                                       "max_step": 0.1}, damped, stop=3.0, record=None)
    stats = adaptive.master_statistics
    tries = stats["accepted_steps"] + stats["rejected_steps"]
    times = adaptive.recorder.rows[:, 0]
    assert times[-1] == 3.0 and np.all(np.diff(times) > 0)
    assert stats["rejected_steps"] > 0 and stats["largest_step"] > 5 * stats["smallest_step"]
    error = speed_error(adaptive, damped)
    # The tolerance bounds each step's input error relative to the signal's peak; the global
    # error is that size too (measured 0.3 tol), so the bound is tol.
    assert error < tol
    # Fixed step with as many doSteps as the adaptive master made (rejected ones included):
    fixed = run(tmp_path, fmu_dir, {"algorithm": "gauss-seidel", "extrapolation": 2,
                                    "step": 3.0 / tries}, damped, stop=3.0, record=None)
    assert speed_error(fixed, damped) > 2 * error


def test_adaptive_master_with_its_defaults_runs_the_servo_press_in_reachable_steps(fmu_dir):
    """`crankfmu run scenarios/servo_press.toml --algorithm adaptive`: the scene's
    extrapolation 0 (held inputs) and the adaptive master's defaults. With held inputs its error
    estimate is each output's change over the step, first order in h; the shared default
    tolerance 1e-6 (the iterative master's interface convergence) asked for steps below
    min_step: 300,000 steps of 1 us for 0.3 s, every one accepted above tolerance. With the
    adaptive master's own default (1e-2): at most 3,000 steps for 0.3 s (measured 1,100), none
    above tolerance, and the crank speed within the tolerance of the hand-built monolithic
    solution (scipy, rtol 1e-10; max |w - w_ref| / mean |w_ref|, measured 6e-4: the tolerance
    bounds each step's input error relative to the signal's scale, and the global error is
    that size or smaller, as in the test above)."""
    from tests.conftest import SCENARIOS
    from tests.support.servo_press_monolithic import MonolithicServoPress

    scene = load_scene(SCENARIOS / "servo_press.toml")
    scene.master.algorithm, scene.stop_time = "adaptive", 0.3
    assert "tolerance" not in scene.master.options and scene.master.extrapolation == 0
    result = run_scene(scene, RunOptions(fmu_dir=fmu_dir, progress=False))
    stats, tolerance = result.master_statistics, result.metadata["master"]["tolerance"]
    assert stats["accepted_steps"] + stats["rejected_steps"] <= 3000, stats
    assert stats["accepted_above_tolerance"] == 0, stats
    hand = MonolithicServoPress(motor_effects=("electrical_lag",))
    times = result.recorder.rows[:, 0]
    w_ref = hand.simulate(hand.initial_state(), 0.0, 2)(times)[1]
    error = np.max(np.abs(result.recorder.column("press.w_crank") - w_ref)) / np.mean(
        np.abs(w_ref))
    print(f"\nservo press 0.3 s, adaptive defaults (tolerance {tolerance:g}): "
          f"{stats['accepted_steps']} steps ({stats['rejected_steps']} rejected), crank speed "
          f"error {error:.1e}")
    assert error < tolerance


STIFF = dict(OSCILLATOR, J2=0.01, k=1e5, ds=0.0, w10=1.0)  # w_max = 3178 rad/s, w h = 3.2


def total_energy(result_or_csv) -> np.ndarray:
    rows = result_or_csv.recorder.rows if hasattr(result_or_csv, "recorder") else \
        np.loadtxt(result_or_csv, delimiter=",", skiprows=1, ndmin=2)
    return rows[:, 3] + rows[:, 4]


def test_stiff_coupling_jacobi_unstable_iterative_stable(tmp_path, fmu_dir):
    """Stiff shaft, light rotor, no damping: the exact solution keeps E = J1 w1^2/2 + c1 phi1^2/2
    + J2 w2^2/2 + k theta^2/2 constant (= E0 = 0.5 J). At h = 1e-3 s (w_max h = 3.2) explicit
    Jacobi with held inputs pumps energy in (measured: x3.8 in 0.2 s, x4e10 in 1 s); the
    iterative master stays within 5 % of E0 (measured max 1.041 E0: interface error at 3 steps
    per period of the stiff mode) with no growth from the first to the last fifth."""
    h, stop = 1e-3, 0.5
    try:
        energy = total_energy(run(tmp_path, fmu_dir, {"algorithm": "jacobi", "step": h},
                                  STIFF, stop=stop, record=h))
    except RunError as err:  # diverged: the rows up to then are in the CSV
        energy = total_energy(err.csv)
    assert energy[0] == pytest.approx(0.5)
    assert energy.max() > 10 * energy[0]

    result = run(tmp_path, fmu_dir, {"algorithm": "iterative", "step": h, "tolerance": 1e-8},
                 STIFF, stop=stop, record=h)
    energy = total_energy(result)
    assert result.master_statistics["non_converged_steps"] == 0
    assert energy.max() < 1.05 * energy[0]
    fifth = len(energy) // 5
    assert energy[-fifth:].max() <= energy[:fifth].max() * 1.001


def test_port_power_mismatch_in_sidecar(tmp_path, fmu_dir):
    """The port r2.flange_tau -> r1.flange_tau / r1.flange_w -> r2.flange_w is found; its energy
    mismatch shrinks with the coupling error (Jacobi is first order: it at least about halves
    with the step) and almost vanishes when the interface converges (measured 2e-15 J)."""
    mismatch = []
    for h in STEPS[:2]:
        result = run(tmp_path, fmu_dir, {"algorithm": "jacobi", "step": h})
        port, = result.coupling_error["ports"]
        assert (port["driver"], port["receiver"]) == ("r2", "r1")
        mismatch.append(abs(port["mismatch_J"]))
    assert mismatch[0] / mismatch[1] > 1.6  # at least first order (ratio 2); measured 2.55
    sidecar = json.loads(result.sidecar.read_text())
    assert sidecar["coupling_error"]["ports"][0]["mismatch_J"] == port["mismatch_J"]
    assert sidecar["statistics"]["r1"]["doStep_calls"] == 200
    converged = run(tmp_path, fmu_dir, {"algorithm": "iterative", "step": STEPS[0],
                                        "tolerance": 1e-10})
    assert abs(converged.coupling_error["ports"][0]["mismatch_J"]) < 1e-3 * mismatch[0]


def test_rollback_master_names_the_fmu_that_cannot(tmp_path, fmu_dir, monkeypatch):
    load = runner.load_fmus

    def without_rollback(scene, fmu_dir, log):
        fmus = load(scene, fmu_dir, log)
        fmus["r2"].can_rollback = False
        return fmus
    monkeypatch.setattr(runner, "load_fmus", without_rollback)
    with pytest.raises(SceneError, match=r"r2 \(ShaftRotor.fmu\) has canGetAndSetFMUstate"):
        run(tmp_path, fmu_dir, {"algorithm": "iterative", "step": 1e-2})


def test_cli_run_prints_coupling_error(tmp_path, fmu_dir, capsys):
    from crankfmu.cli import main

    path = scene_file(tmp_path, {"algorithm": "gauss-seidel", "step": 1e-2}, OSCILLATOR, 0.2,
                      None)
    code = main(["run", str(path), "--fmus", str(fmu_dir), "--out", str(tmp_path / "o"),
                 "--algorithm", "adaptive", "--extrapolation", "1", "--tolerance", "1e-3",
                 "--no-progress"])
    out = capsys.readouterr().out
    assert code == 0
    assert "with adaptive (extrapolation 1, taylor 0, tolerance 0.001, min_step 1e-06, max_step "\
           "0.01)" \
        in out and "accepted_steps" in out
    assert "coupling error at r2 -> r1: energy mismatch" in out


@pytest.mark.parametrize("s", [(0.0, -1e-3), (0.0, 1e-3), (0.0, -1e-3, -2e-3),
                               (0.0, 1e-3, -1e-3), (0.0, 3e-4, -1.7e-3)])
def test_taylor_rows_match_a_vandermonde_solve(s):
    """The closed-form Newton rows against an independent Vandermonde solve of the same
    interpolation problem. Row k is compared times h^k (h = the largest |s|): that is its
    contribution to the input over a step, and the scaled problem is well conditioned, so both
    agree to round-off (1e-12 of values of order 1; a wrong coefficient gives O(1))."""
    from crankfmu.masters.base import taylor_rows

    values = np.random.default_rng(7).normal(size=(len(s), 3))
    h = max(abs(x) for x in s)
    coeffs = np.linalg.solve(np.vander(np.array(s) / h, len(s), increasing=True), values)
    factorials = np.array([1.0, 1.0, 2.0])[:len(s), None]
    rows = taylor_rows(s, values) * (h ** np.arange(len(s)))[:, None]
    assert np.max(np.abs(rows - coeffs * factorials)) < 1e-12


def test_taylor_rows_hold_a_constant_exactly():
    """A constant signal must reach the FMU with derivatives exactly 0 (it then integrates a
    held input), and the value row must be the value itself: no round-off allowed."""
    from crankfmu.masters.base import taylor_rows

    rows = taylor_rows((0.0, -1e-3, -2e-3), np.array([[0.05, 572.0]] * 3))
    assert rows[0] == [0.05, 572.0] and not np.any(rows[1:])
