"""Every catalog FMU alone in fmpy's simulate_fmu: its start values are a valid standalone
configuration (no input connected: inputs keep their start values), it initializes and runs its
DefaultExperiment's step and tolerance, and its outputs are the physics model's own numbers.

Checks per FMU (over the first RUN_STEPS steps of the DefaultExperiment, to keep the test fast):
- it runs; every output is finite;
- outputs equal, bit for bit, the physics class stepped directly in this process without FMI
  (same parameters, inputs held at their start values, same steps and tolerance as simulate_fmu
  gives the FMU): the FMI layer adds nothing;
- where a closed form is cheap, the outputs agree with the physics (analytic values at the start
  values, or a conservation law).
"""
from __future__ import annotations

import math
import time

import numpy as np
import pytest
from fmpy import read_model_description, simulate_fmu

from crankfmu.runtime.model import MAX_OUTPUT_DERIVATIVE, held
from crankfmu.models.catalog import FMU_MODELS, physics_class
from crankfmu.runtime.slave import DEFAULT_TOLERANCE
from tests.support.importer_support import real_outputs

RUN_STEPS = 300  # steps run and compared (0.3 s at the default 1 ms)


@pytest.fixture(scope="module")
def runs(catalog):
    """simulate_fmu on each FMU with its DefaultExperiment's step and tolerance (stopped after
    RUN_STEPS steps), nothing connected, nothing set."""
    out = {}
    for model, fmu in catalog.items():
        de = read_model_description(str(fmu)).defaultExperiment
        stop = min(float(de.stopTime), RUN_STEPS * float(de.stepSize))
        wall = time.perf_counter()
        result = simulate_fmu(str(fmu), stop_time=stop)
        out[model] = (result, time.perf_counter() - wall)
    return out


def physics_at_start_values(model: str):
    """The physics model with the FMU's start values: (model, inputs u0)."""
    cls = physics_class(model)
    params = {v.name: v.start for v in cls.parameters}
    model_obj = cls(params, [e.name for e in cls.effects if e.default])
    return model_obj, np.array([v.start for v in cls.inputs], dtype=float)


def direct_physics(model: str, h: float, n_steps: int, rtol: float) -> np.ndarray:
    """Rows of outputs at t = k h, k = 0..n_steps, stepping the physics class itself the way an
    FMU is stepped (inputs held over a step, atol = rtol x state nominal), with the step sizes
    fmpy's simulate_fmu uses ((k + 1) h - k h)."""
    m, u = physics_at_start_values(model)
    x = m.initial_state(u)
    rows = [m.output_values(0.0, x, u)]
    atol = rtol * m.state_nominal()
    for k in range(n_steps):
        t, t_next = k * h, (k + 1) * h
        x = m.advance(t, x, t_next - t, held(u), rtol, atol)
        rows.append(m.output_values(t_next, x, u))
    return np.array(rows, dtype=float)


@pytest.mark.parametrize("model", list(FMU_MODELS))
def test_every_fmu_alone_runs_in_simulate_fmu(model, catalog, runs):
    md = read_model_description(str(catalog[model]))
    result, wall = runs[model]
    names = [v.name for v in real_outputs(md)]
    de = md.defaultExperiment
    h = float(de.stepSize)
    stop = min(float(de.stopTime), RUN_STEPS * h)
    print(f"\n{model}: simulate_fmu {stop:g} s at {h:g} s in {wall:.2f} s wall")
    assert result["time"][-1] == pytest.approx(stop, abs=1e-12)
    assert len(result) == round(stop / h) + 1
    for name in names:
        assert np.all(np.isfinite(result[name])), f"{model}.{name} not finite"


@pytest.mark.parametrize("model", list(FMU_MODELS))
def test_every_fmu_gives_its_physics_numbers_bit_for_bit(model, catalog, runs):
    md = read_model_description(str(catalog[model]))
    result, _ = runs[model]
    h, rtol = float(md.defaultExperiment.stepSize), float(md.defaultExperiment.tolerance)
    assert rtol == DEFAULT_TOLERANCE
    names = [v.name for v in real_outputs(md)]
    cls = physics_class(model)
    companions = [f"{n}_d{k}" for k in range(1, MAX_OUTPUT_DERIVATIVE + 1)
                  for n in cls.derivative_outputs]  # a Taylor coupling's, after the outputs
    assert names == [v.name for v in cls.outputs] + companions
    names = names[:len(cls.outputs)]
    expected = direct_physics(model, h, len(result) - 1, rtol)
    got = np.column_stack([result[n] for n in names])
    # Same code on the same numbers in the same process: no tolerance.
    np.testing.assert_array_equal(got, expected)


# -- physics at the start values, where a closed form is cheap ------------------------------

def start(md, name):
    return next(float(v.start) for v in md.modelVariables if v.name == name)


def check_dc_servo_motor(r, md):
    """Stalled (flange_w = 0), static law: M = k_phi u/R_a, i_a = u/R_a, no shaft power."""
    k_phi, R_a, u = start(md, "k_phi"), start(md, "R_a"), start(md, "u")
    np.testing.assert_allclose(r["flange_tau"], k_phi * u / R_a, rtol=1e-14)
    np.testing.assert_allclose(r["i_a"], u / R_a, rtol=1e-14)
    assert np.all(r["P_shaft"] == 0.0)


def check_induction_motor(r, md):
    """At standstill slip = 1 and the Kloss formula M = 2 M_k/(s/s_k + s_k/s) with
    M_k = lambda_k P/w_n, s_k = s_n (lambda_k + sqrt(lambda_k^2 - 1)) (textbook, from rated data)."""
    w_n = start(md, "n_rated") * math.pi / 30.0
    s_n = 1.0 - start(md, "n_rated") / start(md, "n_sync")
    lam = start(md, "lambda_k")
    M_k = lam * start(md, "P_rated") / w_n
    s_k = s_n * (lam + math.sqrt(lam * lam - 1.0))
    np.testing.assert_allclose(r["slip"], 1.0, rtol=1e-15)
    np.testing.assert_allclose(r["flange_tau"], 2.0 * M_k / (1.0 / s_k + s_k), rtol=1e-12)


def check_stephenson_press(r, md):
    """No drive torque and no effect on: the press stays at rest where it starts."""
    assert np.all(r["w_crank"] == 0.0) and np.all(r["phi"] == r["phi"][0])


def check_planetary_clutch_drive(r, md):
    """Energy: E_kin(t) - E_kin(0) = W_sun + W_flange - E_brake_b - E_brake_h - E_resist. Each
    term is integrated by the internal solver at rtol 1e-8; measured |imbalance| 2e-9 J on 22 kJ,
    so 1e-9 of E_kin(0) is a bound with margin that still catches any missing term."""
    balance = r["E_kin"] - r["E_kin"][0] - (r["W_sun"] + r["W_flange"] - r["E_brake_b"]
                                            - r["E_brake_h"] - r["E_resist"])
    assert np.max(np.abs(balance)) < 1e-9 * r["E_kin"][0]


def check_rocker_impact(r, md):
    """No drive torque, the rocker starts in contact: at the end of the impact the mechanical
    energy lost equals the energy radiated into the rod, E_mech(0) - E_mech = E_radiated, to
    a few times the internal solver's rtol (1e-8) of E_mech(0): the runtime's Dormand-Prince
    5(4) keeps the local error per step at rtol, and over the pulse's steps the balance closes
    to 2.8e-8 at rtol 1e-8 and 2.1e-10 at rtol 1e-10 (proportional to rtol; scipy's 8th-order
    DOP853 gives 2.1e-9 and -1.3e-11). Bound: 5 x rtol."""
    assert r["contact"][0] == 1.0 and r["E_radiated"][-1] > 0.0
    end = int(np.argmax(r["contact"] == 0.0))  # first sample after the impact
    assert end > 0
    lost = r["E_mech"][0] - r["E_mech"][end]
    assert abs(lost - r["E_radiated"][end]) < 5e-8 * r["E_mech"][0]


PHYSICS_CHECKS = {
    "DcServoMotor": check_dc_servo_motor,
    "InductionMotor": check_induction_motor,
    "StephensonPress": check_stephenson_press,
    "PlanetaryClutchDrive": check_planetary_clutch_drive,
    "RockerImpact": check_rocker_impact,
}


@pytest.mark.parametrize("model", [m for m in FMU_MODELS if m in PHYSICS_CHECKS])
def test_standalone_outputs_agree_with_closed_form_physics(model, catalog, runs):
    PHYSICS_CHECKS[model](runs[model][0], read_model_description(str(catalog[model])))
