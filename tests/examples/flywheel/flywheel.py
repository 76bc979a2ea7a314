"""A flywheel with viscous friction, driven by a torque: the example of adding a model
(README.md here; the walk-through is docs/models.md, section "Adding a model")."""
from __future__ import annotations

from ...runtime.model import ParameterError, PhysicsModel, Variable


class Flywheel(PhysicsModel):
    model_name = "Flywheel"
    description = "Flywheel with viscous bearing friction, driven by a flange torque"
    seed = "textbook (the example model of the contributor guide)"
    parameters = (
        Variable("J", "kg.m2", "Flywheel inertia", 0.5, min=0.0),
        Variable("b", "N.m.s/rad", "Viscous friction in the bearings", 0.1, min=0.0),
        Variable("w_start", "rad/s", "Angular velocity at the start time", 0.0),
    )
    inputs = (
        Variable("flange_tau", "N.m", "Drive torque on the flange", 0.0),
        Variable("flange_J", "kg.m2", "Inertia rigidly on the flange (the driver's rotor)", 0.0,
                 min=0.0),
    )
    outputs = (
        Variable("flange_w", "rad/s", "Angular velocity"),
        Variable("flange_phi", "rad", "Angle"),
    )

    def check(self, p):
        if p.J <= 0.0:
            raise ParameterError(self.model_name, "J", p.J, "> 0 kg.m2")

    def state_names(self):
        return ("phi", "w")

    def initial_state(self, u):
        return [0.0, self.p.w_start]

    def derivatives(self, t, x, u):
        tau, J_driver = u[self.IN.flange_tau], u[self.IN.flange_J]
        return (x[1], (tau - self.p.b * x[1]) / (self.p.J + J_driver))

    def output_values(self, t, x, u):
        return [x[1], x[0]]
