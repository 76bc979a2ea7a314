"""The driven_crank port convention (docs/ports.md) on every mechanism: the driven mode's
equations are the integrating mode's with the crank taken from the driver, and every output that
reads the driver's shaft declares it (FMI direct feedthrough, so a master orders the chain and
finds loops through it).

Compared at the physics level at the same point (no integration): the tolerance is rounding,
1e-12 relative.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from crankfmu.models.rocker_impact.crank_rocker import CrankRockerHammer
from crankfmu.models.mill_stand.mill_stand import MillStandDrive
from crankfmu.models.stephenson_press.stephenson_press import StephensonPress

RTOL = 1e-12
GEAR = 2.5
PHI_START = 0.3
MECHANISMS = {
    "hammer": (CrankRockerHammer, {"gear_ratio": GEAR, "phi_start": PHI_START, "c_rod": 50.0,
                                   "support_damping": 20.0},
               ["hertz_contact", "support_compliance", "hertz_support"]),
    "stand": (MillStandDrive, {"gear_ratio": GEAR, "phi_start": PHI_START,
                               "rod_mismatch": 2e-4}, ["assembly_preload", "rolling_load"]),
    "press": (StephensonPress, {"gear_ratio": GEAR, "phi_start": PHI_START},
              ["gravity", "forging_load", "rod_inertia"]),
}


def pair(name):
    cls, params, effects = MECHANISMS[name]
    return cls(params, effects), cls(params, effects + ["driven_crank"])


def crank_inertia(model, phi, J_input):
    if isinstance(model, CrankRockerHammer):
        return model.p.J_crank + GEAR ** 2 * J_input
    return float(model.reduced_inertia(phi, J_input)[0])


def states(free, driven, phi, w):
    """An integrating-mode state with crank (phi, w) and the matching driven-mode state."""
    names = free.state_names()
    x = np.asarray(free.initial_state(np.zeros(len(free.inputs))), dtype=float)
    rng = np.random.default_rng(7)
    x = x + 1e-3 * rng.standard_normal(len(x)) * np.asarray(free.state_nominal())
    x[names.index("phi")], x[names.index("w_crank")] = phi, w
    driven.initial_state(np.zeros(len(driven.inputs)))  # the discrete state (contact off)
    keep = [k for k, n in enumerate(names) if n not in ("phi", "w_crank")]
    return x, x[keep], keep


@pytest.mark.parametrize("name", sorted(MECHANISMS))
def test_driven_mode_is_the_integrating_mode_on_the_drivers_shaft(name):
    """shaft_J = J(phi)/i^2 and shaft_tau = J(phi) phi''|_{M_D = 0}/i (the reduced equation
    without the drive torque, from the integrating mode's own derivatives); the other states'
    derivatives are the integrating mode's."""
    free, driven = pair(name)
    assert driven.state_names() == tuple(n for n in free.state_names()
                                         if n not in ("phi", "w_crank"))
    J_input = 0.02
    for phi, w in ((1.0, 3.0), (2.9, -1.5), (4.4, 12.0)):
        x, xd, keep = states(free, driven, phi, w)
        u_free = np.zeros(len(free.inputs))
        u_free[1] = J_input
        u_drv = u_free.copy()
        u_drv[2], u_drv[3] = GEAR * (phi - PHI_START), GEAR * w
        dx = np.asarray(free.derivatives(0.0, x, u_free), dtype=float)
        dxd = np.asarray(driven.derivatives(0.0, xd, u_drv), dtype=float)
        y = dict(zip((v.name for v in driven.outputs), driven.output_values(0.0, xd, u_drv)))
        J = crank_inertia(free, phi, J_input)
        i_w = free.state_names().index("w_crank")
        assert math.isclose(y["shaft_J"], J / GEAR ** 2, rel_tol=RTOL)
        assert math.isclose(y["shaft_tau"], J * dx[i_w] / GEAR, rel_tol=RTOL, abs_tol=1e-9)
        assert math.isclose(y["phi"], phi, rel_tol=RTOL)
        assert math.isclose(y["w_crank"], w, rel_tol=RTOL)
        names = [free.state_names()[k] for k in keep]
        for j, n in enumerate(names):
            if n == "W_drive":  # the crank's work on the rod: -M_rod phi'
                assert math.isclose(dxd[j], -J * dx[i_w] * w, rel_tol=1e-9)
            else:
                assert math.isclose(dxd[j], dx[keep[j]], rel_tol=RTOL, abs_tol=1e-12), n


@pytest.mark.parametrize("name", sorted(MECHANISMS))
def test_every_output_that_reads_the_shaft_declares_it(name):
    """Probe: an output that changes when shaft_phi or shaft_w changes must list both in
    depends_on (the FMU's ModelStructure); one that does not may not be a state's."""
    _, driven = pair(name)
    names = [v.name for v in driven.inputs]
    u = np.zeros(len(names))
    x0 = np.asarray(driven.initial_state(u), dtype=float)
    base = np.asarray(driven.output_values(0.0, x0, u), dtype=float)
    changed = np.zeros(len(base), dtype=bool)
    for k, step in ((names.index("shaft_phi"), 0.7), (names.index("shaft_w"), 9.0)):
        v = u.copy()
        v[k] = step
        changed |= np.asarray(driven.output_values(0.0, x0, v), dtype=float) != base
    for out, moved in zip(driven.outputs, changed):
        if moved:
            assert {"shaft_phi", "shaft_w"} <= set(out.depends_on), out.name
    assert changed[[o.name for o in driven.outputs].index("shaft_tau")]
