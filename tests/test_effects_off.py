"""An effect that is off changes nothing and costs nothing, for every FMU model that has
effects (README: "the others are off and cost nothing"; until issue #27 held by a test for the
mill stand's states only).

Each model runs through its FMU step (`PhysicsModel.step`, the call a doStep makes, with the
FMU's tolerances) for a stretch that exercises the effect, twice with the effect off: once
with the effect's parameters at their defaults, once changed (each to a value that changes the
run when the effect is on). Held:

    changes nothing   the outputs of every step are bit for bit the same;
    no state          the states the effect adds when on (named per effect below, from the
                      model cards) are not there when it is off;
    no cost           the steps never read one of the effect's parameters (the parameter
                      namespace is wrapped to record what the steps read; a model that keeps
                      derived constants from its set-up reads them there), so the off path
                      computes nothing of the effect with them; and the right-hand-side calls
                      and the Python function calls of every step (sys.setprofile: a count of
                      work, not a time) are the same, so a stiff or costly value of one (a
                      contact stiffness, a brake law) cannot slow it down.

And with the effect on, the changed parameters change the outputs: the parameters listed are
the effect's, so the first check could fail. Effects without parameters of their own (the
press's driven_crank, the induction motor's linear_law, the rocker's hertz_contact and
hertz_support, whose constants also set the linearised stiffnesses) are held for their states.
"""
from __future__ import annotations

import sys

import numpy as np
import pytest

from crankfmu.models.catalog import make_physics
from crankfmu.runtime.model import InputPolynomial

RTOL = 1e-6  # the FMUs' default tolerance (runtime.slave.DEFAULT_TOLERANCE)

# model: (fixed parameters, inputs, step [s], steps) that make the effects act in the stretch
RUNS = {
    "DcServoMotor": ({}, {}, 1e-3, 60),
    "StephensonPress": ({"w_start": 30.0}, {}, 1e-3, 110),  # through the forging window
    "InductionMotor": ({}, {"flange_w": 90.0}, 1e-3, 50),
    "PlanetaryClutchDrive": ({}, {"command": 1.0}, 1e-3, 150),  # engages a brake
    "RockerImpact": ({}, {}, 2e-5, 60),  # the impact at the start
    "CrankRockerHammer": ({}, {"flange_tau": 200.0}, 1e-3, 80),
    "MillStandDrive": ({"rod_mismatch": 2e-4, "w_start": 5.0}, {}, 1e-3, 60),
}

# (model, effect, effects also on, the effect's own parameters changed, states it adds)
EFFECTS = [
    ("DcServoMotor", "electrical_lag", [], {"L_a": 0.0075}, ["M"]),
    ("DcServoMotor", "speed_loop", [], {"k_p": 7.5, "k_i": 75.0, "U_max": 300.0}, ["I_speed"]),
    ("StephensonPress", "gravity", [], {"g": 14.0}, []),
    ("StephensonPress", "forging_load", [], {"F_max": 75e3, "forging_angle": 0.8}, []),
    ("StephensonPress", "rod_inertia", [], {"m_rod": 7.5}, []),
    ("StephensonPress", "driven_crank", [], {}, []),
    ("InductionMotor", "linear_law", [], {}, []),
    ("PlanetaryClutchDrive", "power_law", [],
     {"tc_b": 0.15, "tr_b": 0.11, "z_b": 2.25, "tc_h": 0.15, "tr_h": 0.11, "z_h": 2.25}, []),
    ("RockerImpact", "support_compliance", [], {"c_support": 5e8, "k_n": 1.2e8}, ["u0", "v0"]),
    ("RockerImpact", "hertz_contact", [], {}, []),
    ("RockerImpact", "hertz_support", ["support_compliance"], {}, []),
    ("CrankRockerHammer", "support_compliance", [],
     {"c_support": 5e8, "k_n": 1.2e8, "support_damping": 100.0}, ["u0", "v0"]),
    ("CrankRockerHammer", "hertz_contact", [], {}, []),
    ("CrankRockerHammer", "hertz_support", ["support_compliance"], {}, []),
    ("MillStandDrive", "assembly_preload", [],  # rod_mismatch is geometry: it also splits
     {"rod_area": 0.012, "E_rod": 3.1e11, "mu_joint": 0.12,  # the load between the rods
      "r_pin": 0.135, "w_reg": 0.015}, ["E_friction"]),
    ("MillStandDrive", "rolling_load", [], {"F_roll": 225e3, "v_reg": 0.0015}, ["E_load"]),
]


class ReadRecorder:
    """A model's parameter namespace that records the names read through it."""

    def __init__(self, namespace):
        object.__setattr__(self, "_namespace", namespace)
        object.__setattr__(self, "read", set())

    def __getattr__(self, name):
        self.read.add(name)
        return getattr(self._namespace, name)


def run(model_name: str, parameters: dict, effects: list) -> dict:
    """The model stepped as its FMU steps it: outputs per step, states, the parameters the
    steps read, and the work."""
    fixed, inputs, h, steps = RUNS[model_name]
    model = make_physics(model_name, {**fixed, **parameters}, effects)
    u = [float(v) for v in model.default_inputs()]
    for name, value in inputs.items():
        u[model.input_index(name)] = value
    x = list(model.initial_state(u))  # (setting up may read every parameter once)
    atol = [RTOL * v for v in model.state_nominal()]
    model.p = ReadRecorder(model.p)  # from here on: what the steps read
    rhs_calls = [0]
    derivatives = model.derivatives

    def counted(t, x, u):
        rhs_calls[0] += 1
        return derivatives(t, x, u)
    model.derivatives = counted  # integrate() reads self.derivatives
    calls = [0]

    def profile(frame, event, arg):
        if event in ("call", "c_call"):
            calls[0] += 1
    outputs, t = [], 0.0
    for k in range(steps):
        sys.setprofile(profile)
        try:
            x = model.step(t, x, h, InputPolynomial(t, u), RTOL, atol)
        finally:
            sys.setprofile(None)
        t = (k + 1) * h
        outputs.append([float(v) for v in model.output_values(t, x, u)])
    return {"outputs": np.array(outputs), "states": model.state_names(),
            "rhs_calls": rhs_calls[0], "calls": calls[0], "read": model.p.read}


@pytest.mark.parametrize("model_name, effect, also, changed, adds", EFFECTS,
                         ids=[f"{m}-{e}" for m, e, *_ in EFFECTS])
def test_an_effect_that_is_off_changes_nothing_adds_no_state_and_costs_nothing(
        model_name, effect, also, changed, adds):
    run(model_name, {}, also)  # first calls fill caches (imports, lazily built tables)
    off = run(model_name, {}, also)
    off_changed = run(model_name, changed, also)
    assert np.array_equal(off["outputs"], off_changed["outputs"])
    assert off_changed["states"] == off["states"]
    assert (off_changed["rhs_calls"], off_changed["calls"]) == (off["rhs_calls"], off["calls"])
    assert not set(changed) & off["read"], set(changed) & off["read"]
    on = run(model_name, {}, also + [effect])
    assert [s for s in adds if s in on["states"]] == adds  # the model card's states ...
    assert not set(adds) & set(off["states"])              # ... absent when off
    if effect != "driven_crank":  # which takes the crank's states away instead
        assert set(on["states"]) - set(off["states"]) == set(adds)
    if changed:  # the parameters are the effect's: they change the run when it is on
        on_changed = run(model_name, changed, also + [effect])
        assert not np.array_equal(on["outputs"], on_changed["outputs"])
