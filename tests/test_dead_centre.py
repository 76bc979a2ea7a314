"""The press near its dead centres, where the rods are almost as short as the crank (l/r = 1.01
and 1.001; at l = r the rods fold and check() refuses it). At phi = 0 and pi, sin(psi) falls to
sqrt(1 - (r/l)^2) (0.14 and 0.045), so psi', psi'' and J'(phi) grow (max |psi''| 7.1 and 22 rad):
the model stays regular and must stay accurate there.

- Kinematics against central differences (h = 1e-6 rad) on 179 angles, 82 of them within 0.05 rad
  of a dead centre: S', S'', psi', psi'' agree to 1e-8 relative to max(|value|, 1) (measured worst
  4.1e-9 for psi'' at l/r = 1.001; the difference quotient's own error is h^2 |f'''|/6 ~ 1e-9).
- A free-running press (no load, no gravity, w_start = 10 rad/s) over two revolutions in 1 ms
  steps at rtol 1e-10: the kinetic energy J(phi) w^2/2 is conserved to 1e-9 (measured 1.5e-11 on
  the runtime path, 6.5e-12 on the scipy path at l/r = 1.001).
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from crankfmu.runtime.model import ParameterError, held
from crankfmu.models.catalog import make_physics

RATIOS = (1.01, 1.001)
R = 0.05  # m


def press_at(ratio: float, **parameters):
    return make_physics("StephensonPress", {"r": R, "l": R * ratio, **parameters}, [])


@pytest.mark.parametrize("ratio", RATIOS)
def test_kinematics_near_the_dead_centres(ratio):
    press = press_at(ratio)
    angles = np.concatenate([np.linspace(-0.05, 0.05, 41), math.pi + np.linspace(-0.05, 0.05, 41),
                             np.linspace(0.0, 2 * math.pi, 97)])
    h, worst = 1e-6, 0.0
    for phi in angles:
        _, dS, ddS, _, dpsi, ddpsi = press.kinematics(float(phi))
        plus, minus = press.kinematics(float(phi) + h), press.kinematics(float(phi) - h)
        for exact, k in ((dS, 0), (ddS, 1), (dpsi, 3), (ddpsi, 4)):
            difference = (plus[k] - minus[k]) / (2 * h)
            worst = max(worst, abs(difference - exact) / max(abs(exact), 1.0))
    print(f"\nl/r = {ratio}: kinematics vs central differences, worst {worst:.1e}")
    assert worst < 1e-8


@pytest.mark.parametrize("solver", ["dopri5", "scipy"])
@pytest.mark.parametrize("ratio", RATIOS)
def test_free_run_conserves_energy_through_the_dead_centres(ratio, solver):
    press = press_at(ratio, w_start=10.0)
    press.solver = solver
    u = [0.0, 0.05, 0.0, 0.0]
    x = press.initial_state(u)

    def energy(x):
        return 0.5 * press.crank_terms(x[0], u[1])[0] * x[1] ** 2
    start, drift, k = energy(x), 0.0, 0
    while x[0] < 4 * math.pi:
        x = press.step(k * 1e-3, x, 1e-3, held(u), 1e-10, [1e-10, 1e-10])
        drift = max(drift, abs(energy(x) / start - 1.0))
        k += 1
    print(f"\nl/r = {ratio}, {solver}: two revolutions in {k} steps, energy drift {drift:.1e}")
    assert drift < 1e-9


def test_rods_as_short_as_the_crank_are_refused():
    with pytest.raises(ParameterError, match="a rod shorter than the crank cannot assemble"):
        press_at(1.0)
