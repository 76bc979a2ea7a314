"""Stephenson six-bar crank press (seed stephenson_press_servo_drive, eq. (1)-(3), (21)-(22)):
J(phi) phi'' + J'(phi)/2 phi'^2 = i M_D + M_C(phi), forging-window edges as events.
Equations, variables and tests: the model card README.md here (base-link offset a: geometry.md).
"""
from __future__ import annotations

import math

import numpy as np

from ...runtime.model import Effect, ParameterError, PhysicsModel, Variable
from ...runtime.driven_crank import SHAFT_INPUTS, SHAFT_NAMES, crank_from_shaft

G_STANDARD = 9.80665  # m/s^2
EDGE_BAND = 1e-12      # rad per rad of |phi|: an edge this close to the restart was just passed


class ON_FLOATS:
    """The core's functions on one float (math's)."""
    sin, cos, sqrt, atan2 = math.sin, math.cos, math.sqrt, math.atan2


class ELEMENTWISE:
    """The core's functions elementwise on arrays (numpy's)."""
    sin, cos, sqrt, atan2 = np.sin, np.cos, np.sqrt, np.arctan2


class StephensonPress(PhysicsModel):
    model_name = "StephensonPress"
    description = "Stephenson six-bar crank press: one-DOF reduced dynamics of the crank"
    seed = "stephenson_press_servo_drive.txt, eq. (1)-(3), (21)-(22)"
    integrator = "DOP853"

    event_slots = 2  # the forging window's next edge ahead and last edge behind

    parameters = (
        Variable("r", "m", "Crank radius", 0.05, min=0.0),
        Variable("l", "m", "Length of the parallel rods 3 and 4 (must exceed r)", 0.25, min=0.0),
        Variable("J1", "kg.m2", "Crank inertia about O", 2.0, min=0.0),
        Variable("m2", "kg", "Mass of base link 2 (centre 2a/3 below hinge A; a = 0: at A)",
                 20.0, min=0.0),
        Variable("m5", "kg", "Slider mass", 50.0, min=0.0),
        Variable("m_rod", "kg", "Mass of each rod (used with effect rod_inertia)", 5.0, min=0.0),
        Variable("gear_ratio", "1", "Gear ratio i = motor speed / crank speed", 10.0, min=0.0),
        Variable("F_max", "N", "Forging force amplitude (effect forging_load)", 50e3, min=0.0),
        Variable("forging_angle", "rad", "Crank angle of the forging window ending at BDC",
                 math.radians(30.0), min=0.0, max=2 * math.pi),
        Variable("g", "m/s2", "Gravitational acceleration (effect gravity)", G_STANDARD, min=0.0),
        Variable("phi_start", "rad", "Crank angle at the start time", 0.0),
        Variable("w_start", "rad/s", "Crank angular velocity at the start time", 0.0),
        Variable("a", "m", "Base-link offset: height of the triangular link 2 from hinge A to the "
                 "rods' hinges (eq. 21); shifts the slider by a, leaves J(phi) and M_C unchanged",
                 0.0),
    )
    effects = (
        Effect("gravity", "Weights of slider, base link (and rods) in M_C"),
        Effect("forging_load", "Half-sine forging force on the slider over the window"),
        Effect("rod_inertia", "Mass and inertia of the two rods in J(phi) and M_C"),
        Effect("driven_crank", "No states: the input shaft follows shaft_phi/shaft_w of a rigidly "
               "coupled driver, which takes shaft_tau and shaft_J (rigid coupling)"),
    )
    inputs = (
        Variable("flange_tau", "N.m", "Drive torque M_D on the motor shaft", 0.0),
        Variable("flange_J", "kg.m2", "Inertia rigidly on the motor shaft (J_input)", 0.0,
                 min=0.0),
    ) + SHAFT_INPUTS
    _driven = SHAFT_NAMES  # feedthrough with effect driven_crank only
    outputs = (
        Variable("flange_w", "rad/s", "Motor shaft angular velocity i*phi'", depends_on=_driven),
        Variable("flange_phi", "rad", "Motor shaft angle i*phi", depends_on=_driven),
        Variable("phi", "rad", "Crank angle (continuous, not wrapped)", depends_on=_driven),
        Variable("w_crank", "rad/s", "Crank angular velocity phi'", depends_on=_driven),
        Variable("slider_s", "m", "Slider position S, downward, r + l + a at BDC",
                 depends_on=_driven),
        Variable("slider_v", "m/s", "Slider velocity S' phi'", depends_on=_driven),
        Variable("F5", "N", "Forging force on the slider", depends_on=_driven),
        Variable("J_reduced", "kg.m2", "Reduced inertia J(phi) at the crank",
                 depends_on=("flange_J",) + _driven),
        Variable("M_C", "N.m", "Reduced resistance moment M_C(phi) at the crank",
                 depends_on=_driven),
        Variable("shaft_tau", "N.m", "Torque of the press on its input shaft apart from inertia, "
                 "(M_C - J'/2 phi'^2)/i (for a rigidly coupled driver)", depends_on=_driven),
        Variable("shaft_J", "kg.m2", "Press inertia at its input shaft J(phi)/i^2 (for a rigidly "
                 "coupled driver)", depends_on=("flange_J",) + _driven),
    )
    # the shaft's motion, i phi' and i phi: affine in the state (and in the driver's shaft)
    derivative_outputs = ("flange_w", "flange_phi")
    derivative_outputs_affine = True

    def check(self, p):
        if p.r <= 0.0:
            raise ParameterError(self.model_name, "r", p.r, "> 0 m")
        if p.l <= p.r:
            raise ParameterError(self.model_name, "l", p.l,
                                 f"> r = {p.r} m (a rod shorter than the crank cannot assemble)")
        if p.gear_ratio <= 0.0:
            raise ParameterError(self.model_name, "gear_ratio", p.gear_ratio, "> 0")
        if self.on("forging_load") and p.forging_angle <= 0.0:
            raise ParameterError(self.model_name, "forging_angle", p.forging_angle,
                                 "> 0 rad when effect forging_load is on")

    def __init__(self, parameters=None, effects=None):
        super().__init__(parameters, effects)
        # the effect switches, read in every right-hand-side call
        self._driven, self._forging = self.on("driven_crank"), self.on("forging_load")
        self._gravity, self._rods = self.on("gravity"), self.on("rod_inertia")
        self._edge_events = (None, [])  # (edges, their event functions): see event_functions
        p = self.p  # r, l, r/l, i^2, J1 + m2 r^2 (base link in circular translation), m5
        self._constants = (p.r, p.l, p.r / p.l, p.gear_ratio ** 2, p.J1 + p.m2 * p.r ** 2, p.m5)

    # -- the equations: one core, for a float or an array --------------------------------
    # The right-hand side calls `crank_terms` on floats with math's functions (~20x cheaper
    # than numpy on one value); the public functions below take a scalar or an array phi (the
    # analyses' grids) and reach the same core, over an array with numpy's functions (~50x
    # cheaper than the core called per element), so each equation is written once.
    def crank_terms(self, phi, J_input: float, f=ON_FLOATS) -> tuple:
        """(J, J'/2, M_C, F5, S, S', S'', psi, psi', psi'') at one crank angle: eq. (1)-(3),
        (21)-(22). One function, not one per quantity: the right-hand side calls it 7 times per
        step, and in Python the calls would cost as much as the arithmetic. phi a float, or with
        f = ELEMENTWISE an array (the terms then arrays, or floats where constant: F5 = 0.0
        without forging_load)."""
        p = self.p
        r, l, r_l, i2_, J_fixed, m5 = self._constants
        sin_phi, cos_phi = f.sin(phi), f.cos(phi)
        cos_psi = -r_l * cos_phi
        sin_psi = f.sqrt(1.0 - cos_psi * cos_psi)
        dpsi = -r_l * sin_phi / sin_psi
        ddpsi = -(r_l * cos_phi + dpsi * dpsi * cos_psi) / sin_psi
        S = r * sin_phi + l * sin_psi + p.a  # + a last: a = 0 leaves S bit-identical
        dS = r * cos_phi + l * dpsi * cos_psi
        ddS = -r * sin_phi - l * dpsi * dpsi * sin_psi + l * ddpsi * cos_psi
        J = i2_ * J_input + J_fixed + m5 * dS * dS
        half_dJ = m5 * dS * ddS
        F5 = 0.0
        if self._forging:  # half sine over the window ending at BDC
            x = (phi - (0.5 * math.pi - p.forging_angle)) % (2 * math.pi)
            inside = x <= p.forging_angle  # a bool, or an array of them
            if f is ELEMENTWISE or inside:  # on a float, the sine only inside the window
                F5 = p.F_max * f.sin(math.pi * x / p.forging_angle) * inside  # * True: exact
        M_C = -F5 * dS
        if self._gravity:
            M_C += m5 * p.g * dS + p.m2 * p.g * r * cos_phi
        if self._rods:  # two uniform bars, centre C; C' and C'' as functions of phi
            dCx, dCy = -0.5 * r * sin_phi, r * cos_phi + 0.5 * l * cos_psi * dpsi
            ddCx = -0.5 * r * cos_phi
            ddCy = -r * sin_phi + 0.5 * l * (ddpsi * cos_psi - dpsi * dpsi * sin_psi)
            J_rod = p.m_rod * l * l / 12.0
            J += 2.0 * (p.m_rod * (dCx * dCx + dCy * dCy) + J_rod * dpsi * dpsi)
            half_dJ += 2.0 * (p.m_rod * (dCx * ddCx + dCy * ddCy) + J_rod * dpsi * ddpsi)
            if self._gravity:
                M_C += 2.0 * p.m_rod * p.g * dCy
        return (J, half_dJ, M_C, F5, S, dS, ddS, f.atan2(sin_psi, cos_psi), dpsi, ddpsi)

    def kinematics(self, phi):
        """(S, S', S'', psi, psi', psi'') for scalar or array phi."""
        return _over(lambda a, f: self.crank_terms(a, 0.0, f)[4:], phi, 6)

    def reduced_inertia(self, phi, J_input: float):
        """(J(phi), J'(phi)/2) at the crank."""
        return _over(lambda a, f: self.crank_terms(a, J_input, f)[:2], phi, 2)

    def resistance_moment(self, phi):
        """M_C(phi) at the crank: forging force and weights (their generalized forces)."""
        return _over(lambda a, f: self.crank_terms(a, 0.0, f)[2], phi, 1)

    def forging_force(self, phi):
        return _over(lambda a, f: self.crank_terms(a, 0.0, f)[3], phi, 1)

    def J_constant(self, J_input: float) -> float:
        """J_c = i^2 J_input + J1 + m2 r^2 (base link in circular translation, eq. 21-22)."""
        i2_, J_fixed = self._constants[3:5]
        return i2_ * J_input + J_fixed

    # -- contract --------------------------------------------------------------------------
    def state_names(self):
        return () if self.on("driven_crank") else ("phi", "w_crank")

    def initial_state(self, u):
        if self.on("driven_crank"):
            return []
        return [self.p.phi_start, self.p.w_start]

    def crank_motion(self, x, u) -> tuple[float, float]:
        """(phi, phi'): the states, or with driven_crank the driver's shaft over the gear."""
        if self.on("driven_crank"):
            return crank_from_shaft(self, u)
        return x[0], x[1]

    def shaft_load(self, phi, w, J_input: float = 0.0) -> tuple[float, float]:
        """(shaft_tau, shaft_J) at the input shaft for crank angle phi and speed w = phi'."""
        i = self.p.gear_ratio
        J, half_dJ, M_C = self.crank_terms(phi, J_input)[:3]
        return (M_C - half_dJ * w * w) / i, J / (i * i)

    def derivatives(self, t, x, u):
        if self._driven:
            return ()
        phi, w = x
        J, half_dJ, M_C = self.crank_terms(phi, u[self.IN.flange_J])[:3]
        return (w, (self.p.gear_ratio * u[self.IN.flange_tau] + M_C - half_dJ * w * w) / J)

    def event_functions(self, u_of_t):
        """The forging window's edges (phi = start and start + forging_angle, mod 2 pi), where
        M_C has a kink: the integrator stops there and restarts, instead of stepping across.
        Two events: the next edge ahead of the restart angle (crossed upwards) and the last one
        behind it (crossed downwards, if the crank turns back); an edge within EDGE_BAND of the
        restart angle is the one just passed and does not count."""
        if not self._forging:
            return []
        if self._driven:
            return self._driven_edge_events(u_of_t)
        phi = self.restart_state[0]
        band = EDGE_BAND * max(1.0, abs(phi))
        cached = self._edge_events[0]
        if cached and cached[1] + band < phi < cached[0] - band:
            return self._edge_events[1]
        pair = self._edge_pair(phi, band)
        self._edge_events = (pair, [_crossing(pair[0], +1), _crossing(pair[1], -1)])
        return self._edge_events[1]

    def _edge_pair(self, phi: float, band: float) -> tuple[float, float]:
        """The next forging-window edge ahead of phi and the last one behind it (outside band)."""
        start = 0.5 * math.pi - self.p.forging_angle
        edges = [e + 2 * math.pi * k for k in (math.floor((phi - start) / (2 * math.pi)) + j
                                              for j in (-1, 0, 1))
                 for e in (start, start + self.p.forging_angle)]
        return (min(e for e in edges if e > phi + band), max(e for e in edges if e < phi - band))

    def _driven_edge_events(self, u_of_t):
        """With driven_crank the crank angle is an input (the driver's shaft): the same two
        edges, as functions of the input at the event time. Only a host that integrates the
        driver with this model (the monolithic reference, which sets restart_time) asks for
        them: the FMU has no states in this mode, so its advance never looks for events."""
        phi = self.crank_motion((), u_of_t(self.restart_time))[0]
        pair = self._edge_pair(phi, EDGE_BAND * max(1.0, abs(phi)))

        def crossing(angle, direction):
            def g(t, x):
                return self.crank_motion((), u_of_t(t))[0] - angle
            g.terminal, g.direction = True, direction
            return g
        return [crossing(pair[0], +1), crossing(pair[1], -1)]

    def output_values(self, t, x, u):
        phi, w = self.crank_motion(x, u)
        i = self.p.gear_ratio
        J, half_dJ, M_C, F5, S, dS = self.crank_terms(phi, u[self.IN.flange_J])[:6]
        return [i * w, i * phi, phi, w, S, dS * w, F5, J, M_C, (M_C - half_dJ * w * w) / i,
                J / (i * i)]


def _crossing(angle: float, direction: int):
    """A terminal event where phi crosses `angle` in `direction`."""
    def g(t, x):
        return x[0] - angle
    g.terminal, g.direction = True, direction  # type: ignore[attr-defined]  # scipy's convention
    return g


def _over(terms, phi, n_out: int):
    """terms(phi, functions) (a float, or a tuple of n_out floats) at a scalar phi, or over an
    array of phi: float arrays of phi's shape (a term that is a constant, such as F5 = 0
    without forging_load, broadcast)."""
    if isinstance(phi, (float, int)):
        return terms(float(phi), ON_FLOATS)
    phi = np.asarray(phi, dtype=float)
    values = terms(phi, ELEMENTWISE)
    if n_out == 1:
        return np.broadcast_to(np.asarray(values, dtype=float), phi.shape).copy()
    return tuple(np.broadcast_to(np.asarray(v, dtype=float), phi.shape).copy() for v in values)
