"""Three-phase induction motor, static torque-slip characteristic (Kloss law, or its linear
low-slip limit with effect linear_law). Equations and their derivation: README.md here."""
from __future__ import annotations

import math

import numpy as np

from ...runtime.model import Effect, ParameterError, PhysicsModel, Variable

RPM = math.pi / 30.0  # rad/s per rpm


class InductionMotor(PhysicsModel):
    model_name = "InductionMotor"
    description = "Induction motor, Kloss torque-slip characteristic (or its low-slip linear law)"
    seed = "planetary_drive_friction_clutch.txt, eq. (2)-(3)"
    integrator = "DOP853"

    parameters = (
        Variable("P_rated", "W", "Rated (nameplate) shaft power", 5500.0, min=0.0),
        Variable("n_rated", "rpm", "Rated speed (below n_sync)", 960.0, min=0.0),
        Variable("n_sync", "rpm", "Synchronous speed 60 f/(pole pairs)", 1000.0, min=0.0),
        Variable("lambda_k", "1", "Breakdown torque ratio M_k/M_n (> 1)", 2.2, min=1.0),
        Variable("J_rotor", "kg.m2", "Rotor inertia", 0.06, min=0.0),
        Variable("J_flywheel", "kg.m2", "Flywheel inertia on the motor shaft", 0.0, min=0.0),
    )
    effects = (
        Effect("linear_law", "Low-slip linear law M = 2 M_k s/s_k instead of the Kloss formula"),
    )
    inputs = (
        Variable("flange_w", "rad/s", "Motor shaft angular velocity (from the mechanism)", 0.0),
        Variable("flange_phi", "rad", "Motor shaft angle (from the mechanism; not used)", 0.0),
    )
    outputs = (
        Variable("flange_tau", "N.m", "Air-gap torque M delivered to the shaft",
                 depends_on=("flange_w",)),
        Variable("flange_J", "kg.m2", "Inertia rigidly on the motor shaft (rotor + flywheel)"),
        Variable("slip", "1", "Slip s = 1 - w/w_s", depends_on=("flange_w",)),
        Variable("P_shaft", "W", "Mechanical power M*w delivered to the shaft",
                 depends_on=("flange_w",)),
    )

    def check(self, p):
        if p.P_rated <= 0.0:
            raise ParameterError(self.model_name, "P_rated", p.P_rated, "> 0 W")
        if p.n_sync <= 0.0:
            raise ParameterError(self.model_name, "n_sync", p.n_sync, "> 0 rpm")
        if not 0.0 < p.n_rated < p.n_sync:
            raise ParameterError(self.model_name, "n_rated", p.n_rated,
                                 f"0 < n_rated < n_sync = {p.n_sync} rpm (a motor delivers its "
                                 "rated torque at a positive slip)")
        if p.lambda_k <= 1.0:
            raise ParameterError(self.model_name, "lambda_k", p.lambda_k,
                                 "> 1 (the breakdown torque exceeds the rated torque)")

    def __init__(self, parameters=None, effects=None):
        super().__init__(parameters, effects)
        self._derive()

    def _derive(self) -> None:
        """(w_s, M_k, s_k, linear law?) once per parameter set, for `torque` (again in
        initial_state, so a host that sets parameters on self.p after construction is safe)."""
        self._characteristic = (self.w_s, self.M_k, self.s_k, self.on("linear_law"))

    # -- nameplate-derived constants -----------------------------------------------------
    @property
    def w_s(self) -> float:
        """Synchronous angular velocity [rad/s]."""
        return self.p.n_sync * RPM

    @property
    def w_n(self) -> float:
        """Rated angular velocity [rad/s]."""
        return self.p.n_rated * RPM

    @property
    def s_n(self) -> float:
        """Rated slip."""
        return 1.0 - self.p.n_rated / self.p.n_sync

    @property
    def M_n(self) -> float:
        """Rated torque P_rated/w_n [N m]."""
        return self.p.P_rated / self.w_n

    @property
    def M_k(self) -> float:
        """Breakdown (critical) torque lambda_k M_n [N m]."""
        return self.p.lambda_k * self.M_n

    @property
    def s_k(self) -> float:
        """Critical slip s_n (lambda_k + sqrt(lambda_k^2 - 1))."""
        lam = self.p.lambda_k
        return self.s_n * (lam + math.sqrt(lam * lam - 1.0))

    @property
    def J_shaft(self) -> float:
        return self.p.J_rotor + self.p.J_flywheel

    def linear_coefficients(self) -> tuple[float, float]:
        """(c0, c1) of the linear law M = c0 - c1 w (c0 = 2 M_k/s_k, c1 = c0/w_s)."""
        c0 = 2.0 * self.M_k / self.s_k
        return c0, c0 / self.w_s

    # -- the characteristic ----------------------------------------------------------------
    def torque(self, w):
        """Air-gap torque at shaft speed w (scalar or array) for the enabled law. A float
        stays a float (the FMU's step: no numpy for one number), anything else goes through
        numpy elementwise; the same formula either way."""
        if not isinstance(w, float):
            M = self._torque(np.asarray(w, dtype=float))
            return float(M) if np.ndim(M) == 0 else M
        return self._torque(w)

    def _torque(self, w):
        w_s, M_k, s_k, linear = self._characteristic
        s = 1.0 - w / w_s
        if linear:
            return 2.0 * M_k * s / s_k
        return 2.0 * M_k * s * s_k / (s * s + s_k ** 2)

    def dtorque_dw(self, w: float) -> float:
        """dM/dw at speed w (negative on the stable branch)."""
        s = 1.0 - w / self.w_s
        if self.on("linear_law"):
            return -2.0 * self.M_k / (self.s_k * self.w_s)
        sk = self.s_k
        dM_ds = 2.0 * self.M_k * sk * (sk * sk - s * s) / (s * s + sk * sk) ** 2
        return -dM_ds / self.w_s

    def speed_at_torque(self, M: float) -> float:
        """Shaft speed on the stable branch (0 <= s < s_k for M >= 0) where the motor delivers M.

        Kloss: M (s^2 + s_k^2) = 2 M_k s_k s  ->  s = s_k (M_k/M - sqrt((M_k/M)^2 - 1)).
        Linear law: s = M s_k/(2 M_k)."""
        if self.on("linear_law"):
            return self.w_s * (1.0 - M * self.s_k / (2.0 * self.M_k))
        if abs(M) > self.M_k:
            raise ValueError(f"{self.model_name}: torque {M} N m exceeds the breakdown torque "
                             f"M_k = {self.M_k:.6g} N m: no steady speed")
        if M == 0.0:
            return self.w_s
        q = self.M_k / abs(M)
        s = self.s_k / (q + math.sqrt(q * q - 1.0))  # = s_k (q - sqrt(q^2 - 1)), no cancellation
        return self.w_s * (1.0 - math.copysign(s, M))

    # -- contract --------------------------------------------------------------------------
    def state_names(self):
        return ()

    def initial_state(self, u):
        self._derive()
        return []

    def derivatives(self, t, x, u):
        return ()

    def output_values(self, t, x, u):
        w = float(u[self.IN.flange_w])
        M = self.torque(w)
        return [M, self.J_shaft, 1.0 - w / self._characteristic[0], M * w]
