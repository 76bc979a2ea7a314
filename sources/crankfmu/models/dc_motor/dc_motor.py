"""Separately excited DC servo motor with optional armature lag and PI speed loop (seed
stephenson_press_servo_drive, eq. (4), (29)-(30)), integrated in closed form.
Equations, integration, variables and tests: the model card README.md in this folder.
"""
from __future__ import annotations

import math

import numpy as np

from ...runtime import closed_form as cf
from ...runtime.model import (Effect, IntegrationError, ParameterError, PhysicsModel, Variable,
                              input_rows)

SATURATION_SAMPLES = 8  # bracketing points for leaving the voltage limit (a smooth function)
AT_LIMIT = 1e-12       # relative band in which U_c counts as at the voltage limit
MAX_PIECES = 64        # limit and loop switches in one step before it is called chattering


class DcServoMotor(PhysicsModel):
    model_name = "DcServoMotor"
    description = "Separately excited DC servo motor with optional electrical lag and PI speed loop"
    seed = "stephenson_press_servo_drive.txt, eq. (4), (29)-(30)"
    integrator = "Radau"  # with solver = "scipy": the lag may be very stiff (tau to 1e-6 s)
    advance_integrates_derivatives = True  # the closed form solves derivatives() exactly

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
    derivative_outputs = ("flange_tau", "flange_J")  # the shaft port (flange_J is constant)

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

    @property  # read-only here: the answer follows the effects (runtime/model.py: a class flag)
    def derivative_outputs_affine(self) -> bool:  # type: ignore[override]
        """With the lag the torque is the state M; without it, the clipped static law."""
        return self.on("electrical_lag")

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
        IN = self.IN
        if not self.on("speed_loop"):
            return u[IN.u], u[IN.u]
        integral = x[-1]
        u_cmd = self.p.k_p * (u[IN.w_ref] - u[IN.flange_w]) + integral
        return min(max(u_cmd, -self.p.U_max), self.p.U_max), u_cmd

    def static_torque(self, U: float, w: float) -> float:
        return min(max(self.mu * U - self.s * w, -self.p.M_max), self.p.M_max)

    def _torque(self, x, u):
        if self.on("electrical_lag"):
            return x[0]
        return self.static_torque(self._voltage(x, u)[0], u[self.IN.flange_w])

    # -- contract --------------------------------------------------------------------------
    def initial_state(self, u):
        """Start in electrical equilibrium with the inputs: M = M_s for the voltage applied at
        the start; the speed loop's integral starts at I = 0."""
        x = []
        if self.on("electrical_lag"):
            U = self._voltage([0.0], u)[0]
            x.append(self.static_torque(U, u[self.IN.flange_w]))
        if self.on("speed_loop"):
            x.append(0.0)
        return x

    def derivatives(self, t, x, u):
        IN = self.IN
        dx = [0.0] * len(x)
        U, u_cmd = self._voltage(x, u)
        k = 0
        if self.on("electrical_lag"):
            dx[0] = (self.static_torque(U, u[IN.flange_w]) - x[0]) / self.tau
            k = 1
        if self.on("speed_loop"):
            dx[k] = self.p.k_i * (u[IN.w_ref] - u[IN.flange_w]) + \
                (U - u_cmd) * self.p.k_i / self.p.k_p
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
                unclipped = abs(self.mu * U - self.s * u[self.IN.flange_w]) < self.p.M_max
                jac[0, 1] = (self.mu * dU_dI if unclipped else 0.0) / self.tau
            jac[-1, -1] = (dU_dI - 1.0) * self.p.k_i / self.p.k_p
        return jac

    def output_values(self, t, x, u):
        M = self._torque(x, u)
        U = self._voltage(x, u)[0]
        return [M, self.p.J_rotor + self.p.J_flywheel, M / self.p.k_phi, U,
                M * u[self.IN.flange_w]]

    # -- closed-form step ------------------------------------------------------------------
    def advance(self, t0, x0, h, u_of_t, rtol, atol):
        rows = input_rows(u_of_t, t0, h) if self.solver != "scipy" else None
        if not x0 or h <= 0.0 or rows is None:
            return super().advance(t0, x0, h, u_of_t, rtol, atol)
        self._check_inputs(t0, u_of_t)
        i_w, i_u = self.IN.flange_w, self.IN.u
        w = cf.taylor_polynomial(rows, i_w)    # shaft speed over the step, in s = t - t0
        lag, loop = self.on("electrical_lag"), self.on("speed_loop")
        M = x0[0] if lag else 0.0
        I = x0[-1] if loop else 0.0
        s = 0.0
        for _ in range(MAX_PIECES):
            U, s_end, I_end = self._voltage_piece(s, h, I, rows) if loop else \
                (cf.taylor_polynomial(rows, i_u), h, 0.0)
            if lag:
                M = self._lag_over(M, U, w, s, s_end)
            I, s = I_end, s_end
            if s >= h:
                return ([M] if lag else []) + ([I] if loop else [])
        raise IntegrationError(f"{self.model_name}: more than {MAX_PIECES} voltage-limit "
                               f"switches in the step from t = {t0:.9g} s")

    def _voltage_piece(self, s, h, I, rows):
        """(U(s') as a polynomial, end of the piece, I at its end) for the speed loop from s:
        up to h or to where the voltage limit is reached or left (`rows`: the inputs' Taylor
        rows at the step's start)."""
        p = self.p
        e = cf.taylor_polynomial(rows, self.IN.w_ref, self.IN.flange_w)  # w_ref - w
        e_local = cf.poly_shift(e, s)
        I_poly = cf.poly_add([I], cf.poly_integral(e_local), scales=[1.0, p.k_i])
        U_free = cf.poly_add(I_poly, e_local, scales=[1.0, p.k_p])   # in sigma = s' - s
        level = cf.poly_value(U_free, 0.0)
        slope = cf.poly_value(cf.poly_derivative(U_free), 0.0)
        limit = p.U_max
        at_limit = abs(abs(level) - limit) <= AT_LIMIT * limit
        saturated = slope * level > 0.0 if at_limit else abs(level) > limit
        if not saturated:
            criticals = cf.poly_critical_points(U_free, 0.0, h - s)
            edges = [r for c in (limit, -limit) for r in cf.sign_changes(
                lambda x, c=c: cf.poly_value(U_free, x) - c, 0.0, h - s, criticals)]
            end = min([h - s] + [r for r in edges if r > 0.0])
            return _unshift(U_free, s), s + end, cf.poly_value(I_poly, end)
        sign = 1.0 if level > 0.0 else -1.0
        rate = p.k_i / p.k_p

        def I_sat(x):
            return sign * limit + (I - sign * limit) * math.exp(-rate * x)

        def inside(x):  # > 0 while U_c stays beyond the limit
            return sign * (p.k_p * cf.poly_value(e_local, x) + I_sat(x)) - limit
        grid = [(h - s) * k / SATURATION_SAMPLES for k in range(1, SATURATION_SAMPLES)]
        end = min([h - s] + [r for r in cf.sign_changes(inside, 0.0, h - s, grid) if r > 0.0])
        return [sign * limit], s + end, I_sat(end)

    def _lag_over(self, M, U, w, s, s_end):
        """M at s_end from M at s, with U and w polynomials in the step time."""
        target = cf.poly_add(U, w, scales=[self.mu, -self.s])   # mu U - s w, unclipped
        limit = self.p.M_max
        local = cf.poly_shift(target, s)
        span = s_end - s
        if sum(abs(a) * span ** k for k, a in enumerate(local)) < limit:  # no limit in reach
            return cf.lag_step(M, local, span, self.tau)
        criticals = cf.poly_critical_points(local, 0.0, span)
        cuts = [r for c in (limit, -limit) for r in cf.sign_changes(
            lambda x, c=c: cf.poly_value(local, x) - c, 0.0, span, criticals)]
        points = [0.0] + sorted(cuts) + [span]
        for a, b in zip(points, points[1:]):
            if b <= a:
                continue
            level = cf.poly_value(local, 0.5 * (a + b))
            forcing = [math.copysign(limit, level)] if abs(level) > limit else \
                cf.poly_shift(local, a)
            M = cf.lag_step(M, forcing, b - a, self.tau)
        return M


def _unshift(c, s0):
    """Coefficients in s of a polynomial given in sigma = s - s0."""
    return cf.poly_shift(c, -s0)
