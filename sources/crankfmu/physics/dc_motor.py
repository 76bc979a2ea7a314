"""Separately excited DC servo motor (seed stephenson_press_servo_drive, eq. 4, 29-30).

    tau dM/dt + M = M_s,   M_s = clip(mu U - s w, -M_max, M_max)   (effect electrical_lag)
    M = M_s                                                          (lag off: static law)
    tau = L_a/R_a,  mu = k_phi/R_a,  s = k_phi^2/R_a

The torque limit acts on the torque the armature current may build (a current limit), so it
bounds both the static law and the target of the lag.

Speed loop (effect speed_loop): PI controller on the motor speed with back-calculation
anti-windup (tracking time T_t = k_p/k_i):
    U_c = k_p (w_ref - w) + I,   U = clip(U_c, -U_max, U_max),
    dI/dt = k_i (w_ref - w) + (U - U_c)/T_t.
Off: U is the input `u`.
"""
from __future__ import annotations

import numpy as np

from .base import Effect, ParameterError, PhysicsModel, Variable


class DcServoMotor(PhysicsModel):
    model_name = "DcServoMotor"
    description = "Separately excited DC servo motor with optional electrical lag and PI speed loop"
    seed = "stephenson_press_servo_drive.txt, eq. (4), (29)-(30)"
    integrator = "Radau"  # the electrical lag may be very stiff (tau down to 1e-6 s)

    parameters = (
        Variable("R_a", "ohm", "Armature resistance", 0.5, min=0.0),
        Variable("L_a", "H", "Armature inductance (electrical time constant tau = L_a/R_a)", 5e-3,
                 min=0.0),
        Variable("k_phi", "V.s/rad", "Torque constant k*Phi (= back-emf constant)", 1.3, min=0.0),
        Variable("J_rotor", "kg.m2", "Rotor inertia", 0.05, min=0.0),
        Variable("J_flywheel", "kg.m2", "Flywheel inertia on the motor shaft", 0.0, min=0.0),
        Variable("M_max", "N.m", "Torque limit (armature current limit times k_phi)", 1000.0,
                 min=0.0),
        Variable("k_p", "V.s/rad", "Speed loop proportional gain", 5.0, min=0.0),
        Variable("k_i", "V/rad", "Speed loop integral gain", 50.0, min=0.0),
        Variable("U_max", "V", "Speed loop voltage limit", 440.0, min=0.0),
    )
    effects = (
        Effect("electrical_lag", "Armature lag tau dM/dt + M = mu U - s w (off: static law)"),
        Effect("speed_loop", "PI speed controller sets U from w_ref (off: U is the input u)"),
    )
    inputs = (
        Variable("flange_w", "rad/s", "Motor shaft angular velocity (from the mechanism)", 0.0),
        Variable("flange_phi", "rad", "Motor shaft angle (from the mechanism)", 0.0),
        Variable("u", "V", "Armature voltage when the speed loop is off", 220.0),
        Variable("w_ref", "rad/s", "Speed reference of the speed loop", 150.0),
    )
    outputs = (
        Variable("flange_tau", "N.m", "Air-gap torque M delivered to the shaft",
                 depends_on=("flange_w", "u", "w_ref")),
        Variable("flange_J", "kg.m2", "Inertia rigidly on the motor shaft (rotor + flywheel)"),
        Variable("i_a", "A", "Armature current M/k_phi", depends_on=("flange_w", "u", "w_ref")),
        Variable("U_a", "V", "Armature voltage applied", depends_on=("flange_w", "u", "w_ref")),
        Variable("P_shaft", "W", "Mechanical power M*w delivered to the shaft",
                 depends_on=("flange_w", "u", "w_ref")),
    )

    def check(self, p):
        if p.R_a <= 0.0:
            raise ParameterError(self.model_name, "R_a", p.R_a, "> 0 ohm")
        if p.k_phi <= 0.0:
            raise ParameterError(self.model_name, "k_phi", p.k_phi, "> 0 V.s/rad")
        if self.on("electrical_lag") and p.L_a <= 0.0:
            raise ParameterError(self.model_name, "L_a", p.L_a,
                                 "> 0 H when effect electrical_lag is on")
        if self.on("speed_loop") and (p.k_p <= 0.0 or p.k_i <= 0.0):
            raise ParameterError(self.model_name, "k_p" if p.k_p <= 0 else "k_i",
                                 p.k_p if p.k_p <= 0 else p.k_i,
                                 "> 0 when effect speed_loop is on")

    # derived constants of eq. (4)
    @property
    def tau(self) -> float:
        return self.p.L_a / self.p.R_a

    @property
    def mu(self) -> float:
        return self.p.k_phi / self.p.R_a

    @property
    def s(self) -> float:
        return self.p.k_phi ** 2 / self.p.R_a

    def state_names(self):
        return (("M",) if self.on("electrical_lag") else ()) + \
               (("I_speed",) if self.on("speed_loop") else ())

    # -- algebraic parts -------------------------------------------------------------------
    def _voltage(self, x, u):
        """(U applied, U before the limit) for the current state and inputs."""
        if not self.on("speed_loop"):
            return u[2], u[2]
        integral = x[-1]
        u_cmd = self.p.k_p * (u[3] - u[0]) + integral
        return float(np.clip(u_cmd, -self.p.U_max, self.p.U_max)), u_cmd

    def static_torque(self, U: float, w: float) -> float:
        return float(np.clip(self.mu * U - self.s * w, -self.p.M_max, self.p.M_max))

    def _torque(self, x, u):
        if self.on("electrical_lag"):
            return x[0]
        return self.static_torque(self._voltage(x, u)[0], u[0])

    # -- contract --------------------------------------------------------------------------
    def initial_state(self, u):
        """Start in electrical equilibrium with the inputs: M = M_s for the voltage applied at
        the start; the speed loop's integral starts at I = 0."""
        x = []
        if self.on("electrical_lag"):
            U = u[2] if not self.on("speed_loop") else float(np.clip(
                self.p.k_p * (u[3] - u[0]), -self.p.U_max, self.p.U_max))
            x.append(self.static_torque(U, u[0]))
        if self.on("speed_loop"):
            x.append(0.0)
        return np.array(x, dtype=float)

    def derivatives(self, t, x, u):
        dx = np.empty(len(x))
        U, u_cmd = self._voltage(x, u)
        k = 0
        if self.on("electrical_lag"):
            dx[0] = (self.static_torque(U, u[0]) - x[0]) / self.tau
            k = 1
        if self.on("speed_loop"):
            dx[k] = self.p.k_i * (u[3] - u[0]) + (U - u_cmd) * self.p.k_i / self.p.k_p
        return dx

    def jacobian(self, t, x, u):
        n = len(x)
        jac = np.zeros((n, n))
        if self.on("electrical_lag"):
            jac[0, 0] = -1.0 / self.tau
        if self.on("speed_loop"):
            U, u_cmd = self._voltage(x, u)
            saturated = U != u_cmd
            dU_dI = 0.0 if saturated else 1.0
            if self.on("electrical_lag"):
                unclipped = abs(self.mu * U - self.s * u[0]) < self.p.M_max
                jac[0, 1] = (self.mu * dU_dI if unclipped else 0.0) / self.tau
            jac[-1, -1] = (dU_dI - 1.0) * self.p.k_i / self.p.k_p
        return jac

    def output_values(self, t, x, u):
        M = self._torque(x, u)
        U = self._voltage(x, u)[0]
        return np.array([M, self.p.J_rotor + self.p.J_flywheel, M / self.p.k_phi, U, M * u[0]])
