"""The driven-crank port (rigid coupling, docs/ports.md), shared by the crank models: with the
effect driven_crank a model has no crank states; its crank follows the driver's shaft over the
gear, and the driver takes the model's shaft_tau and shaft_J."""
from __future__ import annotations

from .model import Variable

SHAFT_INPUTS = (
    Variable("shaft_phi", "rad", "Input shaft angle i*(phi - phi_start) from the driver "
             "(effect driven_crank)", 0.0),
    Variable("shaft_w", "rad/s", "Input shaft angular velocity i*phi' from the driver "
             "(effect driven_crank)", 0.0),
)
SHAFT_NAMES = ("shaft_phi", "shaft_w")  # feedthrough with effect driven_crank only


def crank_from_shaft(model, u) -> tuple[float, float]:
    """(phi, phi') of a driven crank: the driver's shaft over the model's gear_ratio, from
    phi_start."""
    i = model.p.gear_ratio
    return model.p.phi_start + u[model.IN.shaft_phi] / i, u[model.IN.shaft_w] / i
