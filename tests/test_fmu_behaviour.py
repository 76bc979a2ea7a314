"""The FMUs through fmpy: stiff lag, state rollback, tolerance, bad parameters."""
from __future__ import annotations

import numpy as np
import pytest
from fmpy.fmi1 import FMICallException

from crankfmu.fmu.instance import FmuInstance, LogCollector


def start(fmu_dir, model, values, name="x", tolerance=1e-8, log=None):
    fmu = FmuInstance(name, fmu_dir / f"{model}.fmu", log)
    fmu.instantiate(logging_on=log is not None)
    fmu.setup(0.0, 10.0, tolerance)
    fmu.set_start_values(values)
    fmu.slave.enterInitializationMode()
    fmu.slave.exitInitializationMode()
    return fmu


def test_stiff_lag_is_stable_and_equals_the_static_law(fmu_dir):
    """tau = L_a/R_a = 1e-6 s at a 1e-3 s step (1000 time constants per step)."""
    k_phi, R_a, U = 1.3, 0.5, 220.0
    fmu = start(fmu_dir, "DcServoMotor", {"effect_electrical_lag": True, "L_a": 5e-7,
                                           "R_a": R_a, "k_phi": k_phi})
    write, read = fmu.writer(["flange_w", "u"]), fmu.reader(["flange_tau"])
    worst = 0.0
    for k, w in enumerate(np.linspace(0.0, 160.0, 400)):
        write([w, U])
        fmu.do_step(k * 1e-3, 1e-3)
        static = k_phi / R_a * U - k_phi ** 2 / R_a * w
        worst = max(worst, abs(read()[0] - static) / (k_phi / R_a * U))
    fmu.terminate()
    # After a step the lag has decayed by exp(-1000); what remains is the solver's tolerance
    # (rtol 1e-8) on a state of magnitude 572 N m: 1e-7 relative bounds it with margin.
    assert worst < 1e-7


def test_static_characteristic_when_the_lag_is_off(fmu_dir):
    fmu = start(fmu_dir, "DcServoMotor", {"effect_electrical_lag": False})
    fmu.writer(["flange_w", "u"])([100.0, 220.0])
    # direct feedthrough: the output follows the input at once, no step needed
    assert fmu.reader(["flange_tau"])()[0] == pytest.approx(1.3 / 0.5 * 220 - 1.3 ** 2 / 0.5 * 100,
                                                            rel=1e-15)
    fmu.terminate()


def test_state_rollback_restores_internal_states_exactly(fmu_dir):
    fmu = start(fmu_dir, "StephensonPress", {"effect_gravity": True, "effect_forging_load": True,
                                              "w_start": 15.0})
    fmu.writer(["flange_tau", "flange_J"])([50.0, 0.05])
    read = fmu.reader(["phi", "w_crank", "F5"])
    for k in range(30):
        fmu.do_step(k * 1e-3, 1e-3)
    state = fmu.get_state()
    fmu.do_step(0.030, 0.1)
    first = read().copy()
    fmu.set_state(state)
    fmu.do_step(0.030, 0.1)
    assert np.array_equal(read(), first)
    fmu.free_state(state)
    fmu.terminate()


def test_instances_of_one_fmu_at_once_are_apart_and_a_freed_ones_calls_are_reused(fmu_dir):
    """Two instances of one FMU live at once (two components of one file): each has its own
    fmpy object, its own parameters and its own outputs; a later instance takes the fmpy object
    of a freed one (fmu.instance._take_slave: its FMI functions are not loaded again)."""
    def law(fmu, w):  # the static law: the torque follows the input at once
        fmu.writer(["flange_w", "u"])([w, 220.0])
        return fmu.reader(["flange_tau"])()[0]
    a = start(fmu_dir, "DcServoMotor", {"effect_electrical_lag": False, "k_phi": 1.3}, "a")
    b = start(fmu_dir, "DcServoMotor", {"effect_electrical_lag": False, "k_phi": 2.6}, "b")
    assert a.slave is not b.slave
    assert law(a, 100.0) == pytest.approx(1.3 / 0.5 * 220 - 1.3 ** 2 / 0.5 * 100, rel=1e-15)
    assert law(b, 100.0) == pytest.approx(2.6 / 0.5 * 220 - 2.6 ** 2 / 0.5 * 100, rel=1e-15)
    freed = a.slave
    a.terminate()
    c = start(fmu_dir, "DcServoMotor", {"effect_electrical_lag": False, "k_phi": 0.65}, "c")
    assert c.slave is freed and c.slave.instanceName == "c"
    assert law(c, 50.0) == pytest.approx(0.65 / 0.5 * 220 - 0.65 ** 2 / 0.5 * 50, rel=1e-15)
    assert law(b, 50.0) == pytest.approx(2.6 / 0.5 * 220 - 2.6 ** 2 / 0.5 * 50, rel=1e-15)
    b.terminate()
    c.terminate()


def test_tolerance_from_setup_experiment_is_honoured(fmu_dir):
    """A loose tolerance must give a visibly different (worse) answer than a tight one."""
    results = {}
    for tol in (1e-3, 1e-11, 1e-12):  # 1e-12 serves as the reference
        fmu = start(fmu_dir, "StephensonPress", {"effect_forging_load": True, "w_start": 17.0},
                    tolerance=tol)
        fmu.writer(["flange_tau", "flange_J"])([0.0, 0.05])
        fmu.do_step(0.0, 1.0)
        results[tol] = fmu.reader(["phi"])()[0]
        fmu.terminate()
    reference = results[1e-12]
    assert abs(results[1e-11] - reference) < 1e-8
    assert abs(results[1e-3] - reference) > 100 * abs(results[1e-11] - reference)


@pytest.mark.parametrize("model, values, name", [
    ("StephensonPress", {"l": 0.04, "r": 0.05}, "l"),
    ("StephensonPress", {"m5": -1.0}, "m5"),
    ("StephensonPress", {"gear_ratio": 0.0}, "gear_ratio"),
    ("StephensonPress", {"J1": -2.0}, "J1"),
    ("DcServoMotor", {"R_a": 0.0}, "R_a"),
    ("DcServoMotor", {"J_rotor": -0.1}, "J_rotor"),
])
def test_impossible_parameters_fail_at_initialization_with_a_logged_reason(fmu_dir, model,
                                                                           values, name):
    log = LogCollector()
    fmu = FmuInstance("bad", fmu_dir / f"{model}.fmu", log)
    fmu.instantiate(logging_on=True)
    fmu.setup(0.0, 1.0, 1e-8)
    fmu.set_start_values(values)
    fmu.slave.enterInitializationMode()
    with pytest.raises(FMICallException) as failure:
        fmu.slave.exitInitializationMode()
    # pythonfmu 0.7.0's binary reports any Python exception as fmi2Fatal (status 4); the
    # reason reaches the host's logger at fmi2Error status.
    assert failure.value.status >= 3
    reasons = " ".join(log.errors_of("bad"))
    assert f"parameter {name} = " in reasons and "not allowed" in reasons
