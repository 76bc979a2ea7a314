"""Rocker impact unit (seed rocker_impact_unit, eq. (1)-(2), (5)-(8)): a
rigid rocker on an elastic pivot support strikes a semi-infinite elastic rod; unilateral
contact, linearised or Hertzian contact and bearing, events at contact begin/end and the peaks.
Equations, events, variables and tests: the model card README.md in this folder.
"""
from __future__ import annotations

import functools
import math

import numpy as np

from ...runtime import dopri
from ...runtime.model import Effect, IntegrationError, ParameterError, PhysicsModel, Variable
from .rocker_linear import AnalysisError, Linearisation, RockerData, linearise
from .support_flight import SupportFlight

_MO100_S = 1.1 * 0.734 / (35.1 * 0.106)   # 10 % beyond the centre of percussion J/(m r)


@functools.lru_cache(maxsize=64)
def _linearised(data: RockerData, pinned: bool, rtol: float, c0: float | None) -> Linearisation:
    """linearise, once per parameter set in a process: a run asks for the stiffnesses at each
    initialization call (four for the hammer, 5 ms of CPU each), a study for every run."""
    return linearise(data, pinned=pinned, rtol=rtol, c0=c0)


class RockerImpact(PhysicsModel):
    model_name = "RockerImpact"
    description = ("Rocker striking an elastic rod tool: unilateral contact P, elastic pivot "
                   "support reaction T, events at contact begin/end and at the force peaks")
    seed = "rocker_impact_unit.txt, eq. (1)-(2), (5)-(8); MO-100 data"
    integrator = "DOP853"   # oscillatory, not stiff: k1, k2 ~ 1e4 rad/s, no fast decay
    max_events_per_step = 10000
    # advance() = the event loop with the contact switch terminal, the force extrema as
    # monitor_functions handed to observe(), and observe() at the step end; in free flight it
    # integrates derivatives() in another form (support_flight.py), which a monolithic
    # reference may integrate as they are
    advance_follows_contract = True

    event_slots = 3  # the contact switch; in contact the P and T extrema (monitors)

    parameters: tuple[Variable, ...] = (
        Variable("J", "kg.m2", "Rocker moment of inertia about the pivot axis", 0.734, min=0.0),
        Variable("m", "kg", "Rocker mass", 35.1, min=0.0),
        Variable("r", "m", "Distance pivot - centre of mass (along the pivot-strike line)", 0.106),
        Variable("S", "m", "Distance pivot - tool axis (strike point); MO-100: 1.1 J/(m r)",
                 _MO100_S, min=0.0),
        Variable("R_c", "m", "Radius of the rocker's spherical striking face", 0.060, min=0.0),
        Variable("d", "m", "Tool (rod) diameter", 0.080, min=0.0),
        Variable("E", "Pa", "Young's modulus of rocker, tool and bearings", 2.04e11, min=0.0),
        Variable("rho", "kg/m3", "Density of the tool", 7850.0, min=0.0),
        Variable("nu", "1", "Poisson's ratio", 0.3, min=0.0, max=0.5),
        Variable("V0", "m/s", "Impact speed V0 = omega0 S: start speed when strike_at_start = 1 "
                 "and the speed the linearised stiffnesses are computed for", 10.0, min=0.0),
        Variable("k_n", "N(2/3)/m", "Bearing constant of the support, c0 = k_n Tm^(1/3)", 80e6,
                 min=0.0),
        Variable("c_contact", "N/m", "Linear contact stiffness c; 0: from the paper's iteration "
                 "c = 1.25 K^(2/3) Pm^(1/3)", 0.0, min=0.0),
        Variable("c_support", "N/m", "Support stiffness c0; 0: from the paper's iteration "
                 "c0 = k_n Tm^(1/3)", 0.0, min=0.0),
        Variable("iteration_tol", "1", "Relative stop criterion of the stiffness iterations",
                 1e-3, min=1e-12, max=0.1),
        Variable("strike_at_start", "1", "1: the rocker touches the tool at the start time with "
                 "angular speed V0/S; 0: start from theta_start, w_start, tool_gap", 1.0,
                 min=0.0, max=1.0),
        Variable("theta_start", "rad", "Rocker angle at the start (strike_at_start = 0); the "
                 "strike position is theta = tool_gap/S", 0.0),
        Variable("w_start", "rad/s", "Rocker angular speed at the start (strike_at_start = 0)",
                 0.0),
        Variable("tool_gap", "m", "Tool end position at theta = 0 (strike_at_start = 0)", 0.0,
                 min=0.0),
    )
    effects: tuple[Effect, ...] = (
        Effect("hertz_contact", "Contact P = K delta^1.5 instead of the linearised spring c"),
        Effect("support_compliance", "Elastic pivot support c0 (off: pinned rocker, "
                                     "c0 -> infinity, strike-point mass J/S^2)", default=True),
        Effect("hertz_support", "Hertzian bearing T = kappa |u0|^1.5 sgn(u0), kappa = "
                                "(k_n/1.25)^1.5, instead of the linearised c0 (needs "
                                "support_compliance)"),
    )
    inputs: tuple[Variable, ...] = (
        Variable("flange_tau", "N.m", "Drive torque on the rocker shaft", 0.0),
        Variable("flange_J", "kg.m2", "Drive inertia rigidly on the rocker shaft (added to J)",
                 0.0, min=0.0),
    )
    outputs: tuple[Variable, ...] = (
        Variable("flange_w", "rad/s", "Rocker angular velocity theta'"),
        Variable("flange_phi", "rad", "Rocker angle theta"),
        Variable("P", "N", "Contact force rocker - tool"),
        Variable("T", "N", "Support reaction (force on the support along the tool axis); "
                 "pinned: -P - m r theta'', which feeds through the drive torque",
                 depends_on=("flange_tau", "flange_J")),
        Variable("contact", "1", "1 while the rocker touches the tool, else 0"),
        Variable("impulse", "N.s", "Impulse of P over the last (or ongoing) impact"),
        Variable("E_radiated", "J", "Energy radiated into the rod, integral of P^2/Z, cumulative"),
        Variable("P_peak", "N", "Largest P of the last (or ongoing) impact"),
        Variable("T_peak", "N", "Largest |T| during the last (or ongoing) impact"),
        Variable("impact_duration", "s", "Duration of the last impact (elapsed if ongoing)"),
        Variable("n_impacts", "1", "Number of impacts so far"),
        Variable("c_contact_used", "N/m", "Linear contact stiffness in use (0 with Hertz)"),
        Variable("c_support_used", "N/m", "Support stiffness in use (0 when pinned)"),
        Variable("V_impact", "m/s", "Approach speed u0' + S theta' of the strike point when the "
                 "last (or ongoing) impact began"),
        Variable("u_support", "m", "Pivot displacement u0 along the tool axis (0 when pinned)"),
        Variable("v_support", "m/s", "Pivot speed u0' (0 when pinned)"),
        Variable("E_mech", "J", "Kinetic energy of rocker (+ drive inertia) + support and contact "
                 "potential energy", depends_on=("flange_J",)),
    )

    def __init__(self, parameters=None, effects=None):
        super().__init__(parameters, effects)
        p = self.p
        # effect switches and constants, read in every right-hand-side call (floats, not numpy)
        self._compliant = self.on("support_compliance")
        self._hertz = self.on("hertz_contact")
        self._hertz_support = self.on("hertz_support")
        self._kappa = (p.k_n / 1.25) ** 1.5  # N/m^1.5, the Hertzian bearing's constant
        data = self.data()
        self._K, self._Z = data.K, data.Z    # the parameters are fixed from here on
        self._mr = p.m * p.r
        self._theta = 2 if self._compliant else 0   # position of theta in the state
        self._support_damping = 0.0                 # N.s/m (CrankRockerHammer: a parameter)
        self._damper_state = None                   # state that sums the damper's losses
        self._length = max(p.V0, 1.0) * 1e-4        # m, the length scale of state_nominal
        self._d = self._fresh_discrete(c=0.0, c0=None, contact=False)
        self._use_stiffnesses()
        self._carried = None  # the free flight's forcing, carried to the next step (see there)

    def check(self, p):
        self._check_rocker(p, needs_V0=p.strike_at_start == 1.0)
        if p.strike_at_start not in (0.0, 1.0):
            raise ParameterError(self.model_name, "strike_at_start", p.strike_at_start, "0 or 1")
        if p.strike_at_start == 0.0 and p.S * p.theta_start - p.tool_gap > 0.0:
            raise ParameterError(self.model_name, "theta_start", p.theta_start,
                                 f"<= tool_gap/S = {p.tool_gap / p.S:.6g} rad (the rocker may "
                                 f"not start inside the tool)")

    def _check_rocker(self, p, needs_V0: bool) -> None:
        """Rocker, contact, rod and support data; V0 when the iterations (or the start) need it."""
        for name in ("m", "S", "R_c", "d", "E", "rho"):
            if getattr(p, name) <= 0.0:
                raise ParameterError(self.model_name, name, getattr(p, name), "> 0")
        if p.J <= p.m * p.r ** 2:
            raise ParameterError(self.model_name, "J", p.J,
                                 f"> m r^2 = {p.m * p.r ** 2:.6g} kg.m2 (inertia about the "
                                 f"pivot exceeds m r^2 by the central inertia J_C)")
        if p.nu >= 0.5:
            raise ParameterError(self.model_name, "nu", p.nu, "< 0.5")
        needs_c = not self.on("hertz_contact") and p.c_contact == 0.0
        needs_c0 = self.on("support_compliance") and p.c_support == 0.0
        if (needs_c or needs_c0 or needs_V0) and p.V0 <= 0.0:
            raise ParameterError(self.model_name, "V0", p.V0,
                                 "> 0 m/s (start speed / speed of the stiffness iteration)")
        if needs_c0 and p.k_n <= 0.0:
            raise ParameterError(self.model_name, "k_n", p.k_n,
                                 "> 0 when support_compliance is on and c_support = 0")
        if self.on("hertz_support") and not self.on("support_compliance"):
            raise ParameterError(self.model_name, "effect_hertz_support", True,
                                 "only with effect support_compliance (a pinned pivot has no "
                                 "bearing law)")
        if self.on("hertz_support") and p.k_n <= 0.0:
            raise ParameterError(self.model_name, "k_n", p.k_n, "> 0 with effect hertz_support")

    # -- helpers ---------------------------------------------------------------------------
    @property
    def gap(self) -> float:
        return 0.0 if self.p.strike_at_start == 1.0 else self.p.tool_gap

    def data(self, flange_J: float = 0.0) -> RockerData:
        p = self.p
        return RockerData(J=p.J + flange_J, m=p.m, r=p.r, S=p.S, R_c=p.R_c, d=p.d, E=p.E,
                          rho=p.rho, nu=p.nu, V0=p.V0, k_n=p.k_n)

    @property
    def Z(self) -> float:
        return self._Z

    @property
    def K(self) -> float:
        return self._K

    def _fresh_discrete(self, c, c0, contact):
        return {"contact": bool(contact), "n_impacts": 1 if contact else 0, "P_peak": 0.0,
                "T_peak": 0.0, "c": c, "c0": c0, "V_impact": 0.0}

    def _use_stiffnesses(self) -> None:
        """c and c0 of the discrete state (fixed at initialization) as plain attributes."""
        self._c, self._c0 = self._d["c"] or 0.0, self._d["c0"] or 0.0
        self._gap = self.gap

    def _support(self, x) -> tuple[float, float]:
        """(u0, v0): the support's states, 0 when pinned."""
        return (x[0], x[1]) if self._compliant else (0.0, 0.0)

    # -- the equations, on floats ----------------------------------------------------------
    def delta(self, x) -> float:
        o = self._theta
        return (x[0] if o else 0.0) + self.p.S * x[o] - x[o + 2] - self._gap

    def contact_force(self, delta: float) -> float:
        """P for the deflection delta, in contact mode: the smooth extension (c delta, or
        K |delta|^1.5 sign(delta)) so the integrator sees a smooth right side up to the event."""
        if self._hertz:
            return self._K * math.copysign(abs(delta) ** 1.5, delta)
        return self._c * delta

    def _force(self, x) -> float:
        return self.contact_force(self.delta(x)) if self._d["contact"] else 0.0

    def _spring(self, u0: float) -> float:
        """The bearing's spring force: c0 u0, or kappa |u0|^1.5 sgn(u0) (hertz_support)."""
        if self._hertz_support:
            return self._kappa * math.copysign(abs(u0) ** 1.5, u0)
        return self._c0 * u0

    def spring_rate(self, u0: float) -> float:
        """dT/du0 of the bearing's spring."""
        return 1.5 * self._kappa * math.sqrt(abs(u0)) if self._hertz_support else self._c0

    def _spring_energy(self, u0: float) -> float:
        if self._hertz_support:
            return 0.4 * self._kappa * abs(u0) ** 2.5
        return 0.5 * self._c0 * u0 * u0

    def _accelerations(self, u0, v0, P, torque, J_t, F_axis):
        """(u0'', theta'', T) for the contact force P, a torque on the rocker about the pivot,
        the inertia J_t about the pivot and a further force F_axis on the rocker along the tool
        axis (toward the tool). Pinned: T = -P - m r theta'' + F_axis is the pivot reaction."""
        S, m, mr = self.p.S, self.p.m, self._mr
        if self._compliant:
            T = self._spring(u0) + self._support_damping * v0
            det = m * J_t - mr * mr  # m J_C
            f1, f2 = -P - T + F_axis, -P * S + torque
            return (J_t * f1 - mr * f2) / det, (m * f2 - mr * f1) / det, T
        ddth = (-P * S + torque) / J_t
        return 0.0, ddth, -P - mr * ddth + F_axis

    def _pull(self, t, u0, v0, th, om, tail, u) -> tuple[float, float]:
        """(torque on the rocker about the pivot, force on it along the tool axis) apart from
        the contact and the support; tail: the states after the rocker's (a subclass's)."""
        return u[self.IN.flange_tau], 0.0

    def _load(self, t, u0, v0, th, om, tail, u, support_power):
        """(torque, force along the tool axis, inertia J_t about the pivot, the derivatives of
        tail): `_pull` and what the subclass integrates with it; support_power: the support
        damper's dissipated power, for a subclass that sums it."""
        return u[self.IN.flange_tau], 0.0, self.p.J + u[self.IN.flange_J], []

    def _rocker_inertia(self, u) -> float:
        return self.p.J + u[self.IN.flange_J]

    def derivatives(self, t, x, u):
        o = self._theta
        u0, v0 = self._support(x)
        th, om = x[o], x[o + 1]
        torque, F_axis, J_t, tail = self._load(t, u0, v0, th, om, x[o + 6:], u,
                                               self._support_damping * v0 * v0)
        P = self._force(x)
        ddu, ddth, _ = self._accelerations(u0, v0, P, torque, J_t, F_axis)
        Z = self._Z
        rocker = [om, ddth, P / Z, P, P * P / Z, 1.0 if self._d["contact"] else 0.0]
        return ([v0, ddu] + rocker + tail) if o else (rocker + tail)

    def _rocker_energy(self, x, J_t: float) -> float:
        """Kinetic energy of the rocker with the inertia J_t, support and contact energy."""
        o = self._theta
        u0, v = self._support(x)
        om = x[o + 1]
        E = 0.5 * self.p.m * v * v + self._mr * v * om + 0.5 * J_t * om * om
        if self._compliant:
            E += self._spring_energy(u0)
        if self._d["contact"]:
            dl = max(self.delta(x), 0.0)
            E += 0.4 * self._K * dl ** 2.5 if self._hertz else 0.5 * self._c * dl * dl
        return E

    def mechanical_energy(self, x, u) -> float:
        """Kinetic energy of rocker (+ drive inertia) + support and contact potential energy."""
        return self._rocker_energy(x, self._rocker_inertia(u))

    def state_nominal(self) -> np.ndarray:
        """Typical magnitudes (atol = rtol * nominal): lengths V0 * 0.1 ms, speeds V0, impulse
        and energy of a 10 kg mass at V0, time 1 ms."""
        V = max(self.p.V0, 1.0)
        L, S = V * 1e-4, self.p.S
        scale = [L, V, L / S, V / S, L, 10.0 * V, 5.0 * V * V, 1e-3]
        return np.array(scale if self._compliant else scale[2:])

    # -- contract --------------------------------------------------------------------------
    def state_names(self):
        rocker = ("theta", "omega", "w_tool", "impulse", "E_radiated", "t_contact")
        return (("u0", "v0") + rocker) if self._compliant else rocker

    def stiffnesses(self, flange_J: float = 0.0) -> tuple[float, float | None]:
        """(c, c0) in use: parameters if given, else the paper's iterations (c0 None: pinned)."""
        p = self.p
        c = 0.0 if self._hertz else p.c_contact
        c0 = p.c_support if self._compliant else None
        if (c == 0.0 and not self._hertz) or c0 == 0.0:
            try:
                lin = _linearised(self.data(flange_J), not self._compliant, p.iteration_tol,
                                  c0 or None)
            except AnalysisError as err:
                raise ParameterError(self.model_name, "c_support", p.c_support,
                                     f"> 0 N/m here: {err}") from err
            c = lin.c if (c == 0.0 and not self._hertz) else c
            c0 = lin.c0 if c0 == 0.0 else c0
        return float(c), (None if c0 is None else float(c0))

    def initial_state(self, u):
        p = self.p
        c, c0 = self.stiffnesses(float(u[self.IN.flange_J]))
        if p.strike_at_start == 1.0:
            theta, omega = 0.0, p.V0 / p.S
        else:
            theta, omega = p.theta_start, p.w_start
        x = ([0.0, 0.0] if self._compliant else []) + [theta, omega, 0.0, 0.0, 0.0, 0.0]
        d0 = p.S * theta - self.gap
        touching = d0 > 0.0 or (d0 == 0.0 and omega > 0.0)
        self._d = self._fresh_discrete(c, c0, touching)
        if touching:
            self._d["V_impact"] = float(p.S * omega)
        self._use_stiffnesses()
        self._carried = None
        return x

    def output_values(self, t, x, u):
        return self.output_vector(self._output_dict(t, x, u))

    def _output_dict(self, t, x, u) -> dict:
        o = self._theta
        u0, v0 = self._support(x)
        torque, F_axis = self._pull(t, u0, v0, x[o], x[o + 1], x[o + 6:], u)
        return self._rocker_outputs(x, torque, F_axis, self._rocker_inertia(u))

    def _rocker_outputs(self, x, torque, F_axis, J_t) -> dict:
        """RockerImpact's outputs (E_mech with the inertia J_t) for the given loads."""
        d = self._d
        P = max(self._force(x), 0.0)
        u0, v0 = self._support(x)
        T = self._accelerations(u0, v0, P, torque, J_t, F_axis)[2]
        o = self._theta
        P_peak, T_peak = d["P_peak"], d["T_peak"]
        if d["contact"]:
            P_peak, T_peak = max(P_peak, P), max(T_peak, abs(T))
        return {"flange_w": x[o + 1], "flange_phi": x[o], "P": P, "T": T,
                "contact": 1.0 if d["contact"] else 0.0, "impulse": x[o + 3],
                "E_radiated": x[o + 4], "P_peak": P_peak, "T_peak": T_peak,
                "impact_duration": x[o + 5], "n_impacts": float(d["n_impacts"]),
                "c_contact_used": self._c, "c_support_used": 0.0 if self._hertz_support
                else self._c0, "V_impact": d.get("V_impact", 0.0), "u_support": u0,
                "v_support": v0, "E_mech": self._rocker_energy(x, J_t)}

    # -- hybrid part -----------------------------------------------------------------------
    def event_functions(self, u_of_t):
        """The mode switch: contact begins (delta rises through 0) or ends (falls to 0)."""
        def switch(t, x):
            return self.delta(x)
        switch.terminal = True
        switch.direction = -1.0 if self._d["contact"] else 1.0
        return [switch]

    def monitor_functions(self, u_of_t):
        """Non-terminal events located during contact for the exact peaks: delta' = 0 (P' = 0)
        and, with the elastic support, u0' = 0 (T' = 0)."""
        if not self._d["contact"]:
            return []
        o, S, Z = self._theta, self.p.S, self._Z

        def p_peak(t, x):
            return (x[1] if o else 0.0) + S * x[o + 1] - self._force(x) / Z
        p_peak.terminal, p_peak.direction = False, -1.0
        if not self._compliant:
            return [p_peak]

        def t_extremum(t, x):
            return x[1]
        t_extremum.terminal, t_extremum.direction = False, 0.0
        return [p_peak, t_extremum]

    def observe(self, t, x, u) -> None:
        """Fold P and |T| at (t, x) into the peaks of the ongoing impact."""
        d = self._d
        if not d["contact"]:
            return
        o = self._theta
        u0, v0 = self._support(x)
        torque, F_axis = self._pull(t, u0, v0, x[o], x[o + 1], x[o + 6:], u)
        P = max(self._force(x), 0.0)
        T = self._accelerations(u0, v0, P, torque, self._rocker_inertia(u), F_axis)[2]
        d["P_peak"] = max(d["P_peak"], P)
        d["T_peak"] = max(d["T_peak"], abs(T))

    def on_event(self, t, x, u, index):
        d = self._d
        x = [float(v) for v in x]
        if d["contact"]:          # end of contact: P returned to zero
            self.observe(t, x, u)
            d["contact"] = False
        else:                     # contact begins: a new impact, fresh statistics
            o = self._theta
            v0 = x[1] if o else 0.0
            d.update(contact=True, n_impacts=d["n_impacts"] + 1, P_peak=0.0, T_peak=0.0,
                     V_impact=float(v0 + self.p.S * x[o + 1]))
            x[o + 3] = x[o + 5] = 0.0   # impulse and t_contact of the new impact
            self.observe(t, x, u)
        return x

    def discrete_state(self) -> dict:
        return dict(self._d)

    def set_discrete_state(self, state: dict) -> None:
        self._d = dict(state)
        self._use_stiffnesses()

    def solver_state(self) -> dict:
        """The step size and the free flight's forcing carried to the next step."""
        return {"h_next": self._h_next, "carried": self._carried}

    def set_solver_state(self, state: dict) -> None:
        self._h_next = state.get("h_next")
        carried = state.get("carried")
        self._carried = None if carried is None else \
            (carried[0], list(carried[1]), tuple(carried[2]), carried[3])

    def advance(self, t0, x0, h, u_of_t, rtol, atol):
        """Integrate from t0 to t0 + h with the mode switches as terminal events and the force
        extrema as non-terminal events that do not restart the integrator. Free flight takes
        the cheaper path of `_free_flight` where it applies."""
        if h <= 0.0:
            return list(x0)
        t, x, t_end = t0, list(x0), t0 + h
        atol = dopri.per_state(atol, len(x))
        for _ in range(self.max_events_per_step):
            t_full = t_end  # the full equations integrate up to here
            if not self._d["contact"] and self.solver == "dopri5":
                free = self._free_flight(t, x, t_end, u_of_t, rtol, atol)
                if isinstance(free, float):
                    t_full = free
                else:
                    t, x, stopped = free
                    if not stopped:
                        if t >= t_end:
                            return x
                        continue      # a segment shorter than the step: the next one
                    if not self._compliant:   # stopped where contact begins
                        x = self.on_event(t, x, u_of_t(t), 0)
                        if t >= t_end:
                            return x
                        continue
                    # elastic support: contact is possible from here; the full equations
            switch = self.event_functions(u_of_t)
            sol = self.integrate(u_of_t, t, x, t_full, rtol, atol,
                                 switch + self.monitor_functions(u_of_t))
            for _, te, xe in sol.crossings:
                self.observe(te, xe, u_of_t(te))
            if sol.status == 0:
                if sol.t >= t_end:
                    self.observe(t_end, sol.x, u_of_t(t_end))
                    return sol.x
                t, x = sol.t, sol.x   # free flight, where the cheaper path may apply again
                continue
            t = sol.t
            x = self.on_event(t, sol.x, u_of_t(t), 0)
            if t >= t_end:
                return x
        raise IntegrationError(f"{self.model_name}: more than {self.max_events_per_step} "
                               f"contact changes in one step at t = {t:.9g} s (chattering)")

    # -- free flight -----------------------------------------------------------------------
    # Out of contact the tool's states (w_tool, impulse, E_radiated, t_contact) stand still and
    # are not integrated. Pinned, the rest is integrated as it is. With the elastic support,
    # the support is a linear oscillator (k1 ~ 1.6e4 rad/s for MO-100) that an explicit method
    # can only cross in steps of ~0.2 ms, and must follow in far smaller ones while it rings:
    # it is integrated in closed form instead (model card, "Free flight").
    def _free_flight(self, t, x, t_end, u_of_t, rtol, atol):
        """(t, x, stopped) after integrating free flight from t toward t_end, or the time up
        to which the full equations must integrate instead. stopped: the integration ended
        before t_end, pinned where contact begins, with the elastic support where it may."""
        if not self._compliant:
            return self._free_pinned(t, x, t_end, u_of_t, rtol, atol)
        if self._hertz_support:   # a nonlinear spring: no closed form
            return t_end
        J_t = self._rocker_inertia(u_of_t(t))
        if getattr(u_of_t, "moving", True) and \
                any(self._rocker_inertia(u_of_t(s)) != J_t for s in (0.5 * (t + t_end), t_end)):
            return t_end  # a drive inertia that changes over the step changes the oscillator
        return SupportFlight(self, t, x, J_t, u_of_t, rtol, atol).run(t_end)

    def _free_pinned(self, t, x, t_end, u_of_t, rtol, atol):
        """Pinned: the rocker and the subclass's states, up to t_end or where contact begins."""
        S, w_tool, gap, load = self.p.S, x[2], self._gap, self._load

        def rates(s, z, u):
            torque, _, J_t, tail = load(s, 0.0, 0.0, z[0], z[1], z[2:], u, 0.0)
            return [z[1], torque / J_t] + tail

        def switch(s, z):
            return S * z[0] - w_tool - gap
        switch.terminal, switch.direction = True, 1.0
        sol = self.integrate(u_of_t, t, x[:2] + x[6:], t_end, rtol, atol[:2] + atol[6:],
                             [switch], rates)
        return sol.t, sol.x[:2] + x[2:6] + sol.x[2:], sol.status == 1
