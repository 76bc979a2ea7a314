"""Monolithic RIGID reference for the conventional press (induction motor + planetary drive +
Stephenson press with the carrier rigidly on the press shaft): one ODE, the same physics modules.

The drive's equations (PlanetaryClutchDrive: Willis, friction elements, locks as acceleration
constraints, events) are integrated with its port inputs evaluated from the CURRENT state at every
right-hand-side and event-function call, instead of being held over a communication step:

    sun_tau    = motor.torque(w_a(x))                 sun_J    = motor.J_shaft
    flange_tau = press.shaft_load(phi(x), w(x))[0]    flange_J = press.shaft_load(...)[1]
    phi = phi_start + phi_h/i,  w = w_h/i

So the carrier, the press shaft and the crank are one rigid body of inertia J_h + J(phi)/i^2 with
the exact term (M_C - J'/2 phi'^2)/i: the rigid system's Lagrange equation. The command table is
applied at its switching times (integration restarted there, as the drive's on_input_change
does); events (locks, break-frees) are located by solve_ivp at tight tolerance.
"""
from __future__ import annotations

import tomllib

import numpy as np

from crankfmu.models.induction_motor.induction_motor import InductionMotor
from crankfmu.models.planetary_drive.planetary_drive import X as DRIVE_STATE
from crankfmu.models.planetary_drive.planetary_drive import PlanetaryClutchDrive
from crankfmu.models.stephenson_press.stephenson_press import StephensonPress
from crankfmu.system.load import load_scene


EVENT_TIMES = ("t_slip_h", "t_lock_b", "t_slip_b", "t_lock_h", "n_events")


class RigidPlanetaryPress(PlanetaryClutchDrive):
    """The drive with motor and press closed around it through the state (no held inputs)."""

    def __init__(self, drive_params, motor: InductionMotor, press: StephensonPress):
        super().__init__(drive_params)
        self.motor, self.press = motor, press
        self.command = 0.0

    def crank(self, x):
        i = self.press.p.gear_ratio
        return self.press.p.phi_start + x[DRIVE_STATE.phi_h] / i, x[DRIVE_STATE.w_h] / i

    def inputs_at(self, t, x) -> np.ndarray:
        phi, w = self.crank(x)
        tau, J = self.press.shaft_load(phi, w)
        return np.array([self.command, self.motor.torque(self.sun_speed(x)), self.motor.J_shaft,
                         tau, J])

    def derivatives(self, t, x, u):
        return super().derivatives(t, x, self.inputs_at(t, x))

    def event_functions(self, u_of_t):
        held = {}
        funcs = super().event_functions(lambda s: held["u"])
        wrapped = []
        for g in funcs:
            def w(t, x, g=g):
                held["u"] = self.inputs_at(t, x)
                return g(t, x)
            w.terminal, w.direction = g.terminal, g.direction
            wrapped.append(w)
        return wrapped

    def on_event(self, t, x, u, index):
        return super().on_event(t, x, self.inputs_at(t, x), index)

    def advance(self, t0, x0, h, u_of_t, rtol, atol):
        x = np.array(x0, dtype=float)
        x = self.on_input_change(t0, x, self.inputs_at(t0, x))
        return super(PlanetaryClutchDrive, self).advance(t0, x, h, u_of_t, rtol, atol)


def from_scene(path):
    """(model, command table rows, scene) built from the scene file's parameters."""
    scene = load_scene(path)
    comp = scene.components
    motor = InductionMotor(comp["motor"].parameters, comp["motor"].effects)
    press = StephensonPress({k: v for k, v in comp["press"].parameters.items()},
                            [e for e in comp["press"].effects if e != "driven_crank"])
    model = RigidPlanetaryPress(comp["drive"].parameters, motor, press)
    table = tomllib.loads(scene.path.read_text())["inputs"]["drive.command"]["table"]
    return model, table, scene


def run(path, t_end: float, dt: float = 1e-3, rtol: float = 1e-11, table=None):
    """Samples every dt to t_end: dict of arrays time, phi, w_crank, w_a, w_b, w_h, M_C,
    E_brake_b, E_brake_h, period, motor torque, the drive's last event times and event count; plus the drive's discrete state at the end.
    `table`: command rows [[t, value], ...] instead of the scene's (switch times on the dt grid)."""
    model, scene_table, _ = from_scene(path)
    table = scene_table if table is None else table
    switches = {round(t / dt): v for t, v in table}
    names = [v.name for v in model.outputs]
    x = model.initial_state(model.inputs_at(0.0, np.zeros(9)))
    x = model.initial_state(model.inputs_at(0.0, x))
    n = int(round(t_end / dt))
    atol = rtol * model.state_nominal()
    rows = []

    def sample(t, x):
        u = model.inputs_at(t, x)
        y = dict(zip(names, model.output_values(t, x, u)))
        phi, w = model.crank(x)
        rows.append([t, phi, w, y["w_a"], y["w_b"], y["w_h"],
                     float(model.press.resistance_moment(phi)), y["E_brake_b"], y["E_brake_h"],
                     y["period"], u[1]] + [y[k] for k in EVENT_TIMES])
    for k in range(n):
        if k in switches:
            model.command = float(switches[k])
        sample(k * dt, x)
        x = model.advance(k * dt, x, dt, lambda s, x=x: model.inputs_at(s, x), rtol, atol)
    sample(n * dt, x)
    cols = ("time", "phi", "w_crank", "w_a", "w_b", "w_h", "M_C", "E_brake_b", "E_brake_h",
            "period", "motor_tau") + EVENT_TIMES
    data = np.array(rows)
    out = {c: data[:, j] for j, c in enumerate(cols)}
    out["discrete"] = model.discrete_state()
    return out
