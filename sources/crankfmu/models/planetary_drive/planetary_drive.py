"""Planetary drive of a crank press with friction brakes on the ring and the carrier (seed
planetary_drive_friction_clutch, eq. (1)-(10)): three coupled Coulomb
elements that lock and break free, brake laws, the four periods, a carrier port for a press.
Equations, modes, events, variables, tests and the exact step (held inputs, exponential laws):
the model card README.md in this folder.
"""
from __future__ import annotations

import enum
import itertools
import math
import operator
from math import exp
from dataclasses import dataclass

import numpy as np

from ...runtime.closed_form import phi_functions
from ...runtime.dopri import EPS
from ...runtime.model import (Effect, InputPolynomial, IntegrationError, ParameterError,
                              PhysicsModel, Variable, name_indices)
from ...runtime.roots import brentq

MEMBERS = ("b", "h")      # braked members
ELEMENTS = ("a", "b", "h")  # friction elements: sun resistance, ring and carrier brakes
STATE_NAMES = ("phi_b", "phi_h", "w_b", "w_h", "E_brake_b", "E_brake_h", "E_resist", "W_sun",
               "W_flange")
X = name_indices("PlanetaryClutchDrive", "state", STATE_NAMES)  # x[X.w_b]: state by name

NEVER = -1.0  # event-time outputs before the first such event


class Direction(enum.Enum):
    """How a friction element moves. `sign` is the sign of its speed while sliding, 0 while
    locked: the d of F_k = -C_k d and of the slip power d w. The step path reads the three
    signs as a tuple of ints, derived once per mode change (`_mode_changed`)."""

    BACKWARD = -1
    LOCKED = 0
    FORWARD = 1

    def __init__(self, sign: int):
        self.sign = sign


@dataclass
class ElementState:
    """Mode of one friction element (sun a, ring b, carrier h) and its lock history."""

    direction: Direction
    t_lock: float = NEVER  # s, when it last locked
    t_slip: float = NEVER  # s, when it last broke free
    n_lock: int = 0
    n_slip: int = 0


@dataclass
class BrakeState:
    """A brake's law since the last command edge: engaging or releasing from M0 at t0."""

    engaging: bool
    t0: float = 0.0  # s, start of the law (the command edge)
    M0: float = 0.0  # N.m, torque at t0


@dataclass
class Modes:
    """The discrete state: everything but the continuous states that the motion depends on.
    `to_json`/`from_json` give the JSON-safe form the FMU saves (floats exact, -inf as None).
    The model changes it only through its own methods, each followed by `_mode_changed`, which
    derives what the step path reads from it."""

    command: int
    brakes: dict[str, BrakeState]
    elements: dict[str, ElementState]
    t_command: float = NEVER  # s, time of the last command edge
    t_last: float = -math.inf  # s, time of the last discrete update (power-law breakpoints)
    n_pass: int = 0  # passes of a member through zero speed without locking
    n_events: int = 0

    def to_json(self) -> dict:
        return {"command": self.command, "t_command": self.t_command,
                "t_last": None if self.t_last == -math.inf else self.t_last,
                "n_pass": self.n_pass, "n_events": self.n_events,
                "brakes": {k: {"engaging": b.engaging, "t0": b.t0, "M0": b.M0}
                           for k, b in self.brakes.items()},
                "elements": {k: {"direction": e.direction.sign, "t_lock": e.t_lock,
                                 "t_slip": e.t_slip, "n_lock": e.n_lock, "n_slip": e.n_slip}
                             for k, e in self.elements.items()}}

    @classmethod
    def from_json(cls, d: dict) -> "Modes":
        return cls(command=int(d["command"]), t_command=float(d["t_command"]),
                   t_last=-math.inf if d["t_last"] is None else float(d["t_last"]),
                   n_pass=int(d["n_pass"]), n_events=int(d["n_events"]),
                   brakes={k: BrakeState(bool(b["engaging"]), float(b["t0"]), float(b["M0"]))
                           for k, b in d["brakes"].items()},
                   elements={k: ElementState(Direction(e["direction"]), float(e["t_lock"]),
                                             float(e["t_slip"]), int(e["n_lock"]),
                                             int(e["n_slip"]))
                             for k, e in d["elements"].items()})


class EventKind(enum.Enum):
    BREAK_REST = "break_rest"  # all at rest: the feasible interval of F_a closes
    SLIP = "slip"              # the single locked element breaks free in `direction`
    ZERO = "zero"              # a sliding element reaches zero speed
    COMMAND = "command"        # the command input crosses 0.5
    TIME = "time"              # a kink of a power-law brake torque (at `time`)


@dataclass(frozen=True)
class Event:
    """What an event function's zero means (on_event reads it by the function's index)."""

    kind: EventKind
    element: str | None = None
    direction: Direction = Direction.LOCKED
    time: float | None = None  # s, TIME events only


LOCKED = Direction.LOCKED  # a module name: reading it off the Enum class costs ~50 ns, often
# The lock of the current modes, as the step path reads it: an element's index in ELEMENTS (one
# locked), or one of these
NO_LOCK, ALL_LOCKED = -1, 3

# Events are values: built once here, not at every integration restart (constructing a frozen
# dataclass costs ~1 us). TIME events carry their time and are built when needed.
BREAK_REST_EVENT = Event(EventKind.BREAK_REST)
COMMAND_EVENT = Event(EventKind.COMMAND)
ZERO_EVENTS = {k: Event(EventKind.ZERO, k) for k in ELEMENTS}
SLIP_EVENTS = {(k, d): Event(EventKind.SLIP, k, d) for k in ELEMENTS
               for d in (Direction.FORWARD, Direction.BACKWARD)}

# The exact step (`_advance_exactly`) looks for sign changes of the event functions at samples
# EVENT_SAMPLE/rate apart while the fastest brake decay e^(-rate s) lasts (DECAYED/rate:
# e^-40 = 4e-18), then at the step's end: after the decays every event function is linear or
# constant in time (one zero at most).
EVENT_SAMPLE, DECAYED = 0.1, 40.0
_INTEGRALS: dict = {}  # (rate, span) -> exponential_integrals: fixed steps repeat them


def exponential_integrals(rate: float, span: float) -> tuple[float, float, float]:
    """(E1, E2, J1) of the decay e^(-rate s) over [0, span]: E1 = int e^(-rate s) ds,
    E2 = int E1(s) ds, J1 = int s e^(-rate s) ds. From the phi-functions, E1 = span phi_1(z),
    E2 = span^2 phi_2(z) with z = -rate span, which do not cancel for a small rate span (rate 0:
    span, span^2/2, span^2/2)."""
    value = _INTEGRALS.get((rate, span))
    if value is None:
        phi_1, phi_2 = phi_functions(-rate * span, 2)
        E1, E2 = span * phi_1, span * span * phi_2
        value = (E1, E2, span * E1 - E2)
        if len(_INTEGRALS) > 1024:  # event location and variable steps: keep it small
            _INTEGRALS.clear()
        _INTEGRALS[(rate, span)] = value
    return value


def decay_product(rate: float, other: float, span: float, E1: float, J1: float) -> float:
    """int_0^span e^(-rate s) E1(other, s) ds, E1(other, s) = int_0^s e^(-other r) dr: a decay
    times the speed another decay gives; E1, J1: exponential_integrals(rate, span)'s."""
    if other == 0.0:  # E1(0, s) = s
        return J1
    return (E1 - exponential_integrals(rate + other, span)[0]) / other


class PlanetaryClutchDrive(PhysicsModel):
    model_name = "PlanetaryClutchDrive"
    description = ("Type-A planetary drive with friction brakes on ring and carrier: engagement, "
                   "working stroke, stopping, idle; stick-slip locking")
    seed = "planetary_drive_friction_clutch.txt, eq. (1)-(10)"
    integrator = "DOP853"
    # advance() = on_input_change at the step start + the base event loop, on the exact solution
    # of derivatives() where it exists (held inputs, exponential laws): the composed reference
    # does the same at every restart, integrating derivatives()
    advance_follows_contract = True

    # one member locked: 2 break-free + 2 zero speed + command + 2 power-law kinks
    event_slots = 7

    parameters = (
        Variable("r_a", "m", "Pitch radius of the sun gear a", 0.10, min=0.0),
        Variable("r_b", "m", "Pitch radius of the ring gear b (p = r_b/r_a)", 0.25, min=0.0),
        Variable("J_a", "kg.m2", "Inertia of the sun a with everything rigidly on it (rotor, "
                 "flywheel); the port input sun_J is added", 4.0, min=0.0),
        Variable("J_b", "kg.m2", "Inertia of the ring b", 0.5, min=0.0),
        Variable("J_h", "kg.m2", "Inertia of the carrier h with the planets lumped in; the port "
                 "input flange_J is added", 5.0, min=0.0),
        Variable("M_ca", "N.m", "Resistance torque on the sun (Coulomb, opposes w_a; holds the "
                 "sun at rest up to M_ca)", 5.0, min=0.0),
        Variable("M_cb", "N.m", "Resistance torque on the ring (Coulomb, opposes w_b)", 3.0,
                 min=0.0),
        Variable("M_ch", "N.m", "Resistance torque on the carrier (Coulomb, opposes w_h; the "
                 "press load for now)", 40.0, min=0.0),
        Variable("Mp_b", "N.m", "Brake b (ring) design torque M_p, fully engaged", 1000.0,
                 min=0.0),
        Variable("alpha_b", "1/s", "Brake b engagement rate (exponential law)", 30.0, min=0.0),
        Variable("beta_b", "1/s", "Brake b release rate (exponential law)", 40.0, min=0.0),
        Variable("Mp_h", "N.m", "Brake h (carrier) design torque M_p, fully engaged", 1500.0,
                 min=0.0),
        Variable("alpha_h", "1/s", "Brake h engagement rate (exponential law)", 30.0, min=0.0),
        Variable("beta_h", "1/s", "Brake h release rate (exponential law)", 40.0, min=0.0),
        Variable("tc_b", "s", "Brake b engagement time t_c (effect power_law)", 0.1, min=0.0),
        Variable("tr_b", "s", "Brake b release time t_r (effect power_law)", 0.075, min=0.0),
        Variable("z_b", "1", "Brake b exponent z of B t^z (effect power_law)", 1.5, min=0.0),
        Variable("tc_h", "s", "Brake h engagement time t_c (effect power_law)", 0.1, min=0.0),
        Variable("tr_h", "s", "Brake h release time t_r (effect power_law)", 0.075, min=0.0),
        Variable("z_h", "1", "Brake h exponent z of B t^z (effect power_law)", 1.5, min=0.0),
        Variable("initial_period", "1", "Start state: 1 = idle (carrier held by its engaged "
                 "brake, ring free, command 0), 3 = working stroke (ring held, command 1)", 1.0,
                 min=1.0, max=3.0),
        Variable("w_a_start", "rad/s", "Sun (motor) speed at the start; the free member follows "
                 "from Willis, the held one is at rest", 104.0),
        Variable("phi_b_start", "rad", "Ring angle at the start", 0.0),
        Variable("phi_h_start", "rad", "Carrier angle at the start", 0.0),
    )
    effects = (
        Effect("power_law", "Brake torques follow B t^z (engage) and its retrace (release) "
               "instead of the exponential laws"),
    )
    inputs = (
        Variable("command", "1", "1 = engage / working stroke, 0 = stop; a change of value "
                 "(threshold 0.5) starts engagement or stopping", 0.0, min=0.0, max=1.0),
        Variable("sun_tau", "N.m", "Motor torque on the sun (port)", 0.0),
        Variable("sun_J", "kg.m2", "Inertia rigidly on the sun from the motor (port, added to "
                 "J_a)", 0.0, min=0.0),
        Variable("flange_tau", "N.m", "External torque on the carrier from a coupled press "
                 "(port)", 0.0),
        Variable("flange_J", "kg.m2", "Inertia rigidly on the carrier from a coupled press "
                 "(port, added to J_h)", 0.0, min=0.0),
    )
    _ff = ("sun_tau", "sun_J", "flange_tau", "flange_J")
    outputs = (
        Variable("sun_w", "rad/s", "Sun angular velocity w_a (port)"),
        Variable("sun_phi", "rad", "Sun angle -p phi_b + (1+p) phi_h (port)"),
        Variable("flange_w", "rad/s", "Carrier angular velocity w_h (port)"),
        Variable("flange_phi", "rad", "Carrier angle phi_h (port)"),
        Variable("w_a", "rad/s", "Sun angular velocity"),
        Variable("w_b", "rad/s", "Ring angular velocity (exactly 0 while locked)"),
        Variable("w_h", "rad/s", "Carrier angular velocity (exactly 0 while locked)"),
        Variable("M_tb", "N.m", "Brake b torque capacity M_tb(t) from its law"),
        Variable("M_th", "N.m", "Brake h torque capacity M_th(t) from its law"),
        Variable("tau_b", "N.m", "Friction torque acting on the ring (brake + resistance; the "
                 "constraint torque while locked)", depends_on=_ff),
        Variable("tau_h", "N.m", "Friction torque acting on the carrier (brake + resistance; the "
                 "constraint torque while locked)", depends_on=_ff),
        Variable("tau_a", "N.m", "Resistance torque acting on the sun (-M_ca while turning "
                 "forwards; the constraint torque while at rest)", depends_on=_ff),
        Variable("E_brake_b", "J", "Energy dissipated in brake b (cumulative)"),
        Variable("E_brake_h", "J", "Energy dissipated in brake h (cumulative)"),
        Variable("E_resist", "J", "Energy lost to the resistance torques M_ca, M_cb, M_ch "
                 "(cumulative)"),
        Variable("W_sun", "J", "Work done on the sun through the port (cumulative)"),
        Variable("W_flange", "J", "Work done on the carrier through the port (cumulative)"),
        Variable("E_kin", "J", "Kinetic energy of sun, ring and carrier (with port inertias)",
                 depends_on=("sun_J", "flange_J")),
        Variable("period", "1", "1 idle, 2 engagement, 3 working stroke, 4 stopping"),
        Variable("t_command", "s", "Time of the last command edge (-1: none yet)"),
        Variable("t_lock_b", "s", "Time the ring last locked (-1: none yet)"),
        Variable("t_slip_b", "s", "Time the ring last broke free (-1: none yet)"),
        Variable("t_lock_h", "s", "Time the carrier last locked (-1: none yet)"),
        Variable("t_slip_h", "s", "Time the carrier last broke free (-1: none yet)"),
        Variable("n_lock_b", "1", "Number of ring locks"),
        Variable("n_lock_h", "1", "Number of carrier locks"),
        Variable("n_events", "1", "Number of mode events (locks, break-frees, passes through "
                 "zero speed, command edges)"),
    )

    # -- parameters ------------------------------------------------------------------------
    def check(self, p):
        if p.r_a <= 0.0:
            raise ParameterError(self.model_name, "r_a", p.r_a, "> 0 m")
        if p.r_b <= p.r_a:
            raise ParameterError(self.model_name, "r_b", p.r_b,
                                 f"> r_a = {p.r_a} m (the ring surrounds sun and planets)")
        if p.J_a + p.J_b <= 0.0 or p.J_h <= 0.0:
            name, val = ("J_h", p.J_h) if p.J_h <= 0.0 else ("J_a", p.J_a)
            raise ParameterError(self.model_name, name, val,
                                 "> 0 (the mass matrix must stay positive definite)")
        if p.initial_period not in (1.0, 3.0):
            raise ParameterError(self.model_name, "initial_period", p.initial_period,
                                 "1 (idle) or 3 (working stroke)")
        law = ("tc_b", "tr_b", "z_b", "tc_h", "tr_h", "z_h") if self.on("power_law") else \
              ("alpha_b", "beta_b", "alpha_h", "beta_h")
        for name in law:
            if getattr(p, name) <= 0.0:
                raise ParameterError(self.model_name, name, getattr(p, name),
                                     "> 0 for the chosen brake law")

    @property
    def ratio(self) -> float:
        """p = r_b/r_a = -i_ab^h."""
        return self.p.r_b / self.p.r_a

    # -- discrete state --------------------------------------------------------------------
    def _fresh_modes(self) -> Modes:
        """Brakes fully on (held member) or off at t = 0 (initial_state sets the directions)."""
        p = self.p
        stroke = p.initial_period == 3.0
        return Modes(
            command=1 if stroke else 0,
            brakes={"b": BrakeState(True, 0.0, p.Mp_b) if stroke else BrakeState(False),
                    "h": BrakeState(False) if stroke else BrakeState(True, 0.0, p.Mp_h)},
            elements={"a": ElementState(Direction.FORWARD),
                      "b": ElementState(LOCKED), "h": ElementState(LOCKED)})

    def discrete_state(self) -> dict:
        return self.modes.to_json()

    def set_discrete_state(self, state: dict) -> None:
        self.modes = Modes.from_json(state)
        self._mode_changed()

    def __init__(self, parameters=None, effects=None):
        super().__init__(parameters, effects)
        self._derive()
        self.modes = self._fresh_modes()
        self._u_of_t = None  # the inputs of the integration under way (its event functions)
        self._events: list[Event] = []
        IN = self.IN  # the port inputs of an input vector, by name, in one C call
        self._ports = operator.itemgetter(IN.sun_tau, IN.sun_J, IN.flange_tau, IN.flange_J)
        self._mode_changed()

    def _derive(self) -> None:
        """Constants derived from the parameters (again in initial_state, so a host that sets
        parameters on self.p after construction is safe)."""
        p = self.p
        pr = self.ratio
        self._constants = (pr, 1.0 + pr, p.M_ca, p.M_cb, p.M_ch)
        # G_k (w_k = G_k . v, v = (w_b, w_h)) and N_k (G_k . N_k = 0), in ELEMENTS order
        self._G = ((-pr, 1.0 + pr), (1.0, 0.0), (0.0, 1.0))
        self._N = ((1.0 + pr, pr), (0.0, 1.0), (1.0, 0.0))
        self._laws = {k: (getattr(p, "Mp_" + k), getattr(p, "alpha_" + k),
                          getattr(p, "beta_" + k), getattr(p, "tc_" + k),
                          getattr(p, "tr_" + k), getattr(p, "z_" + k)) for k in MEMBERS}
        self._power = self.on("power_law")

    def _mode_changed(self) -> None:
        """Derive from `modes` what the step path reads, after every change of the discrete
        state: the elements' signs (a tuple of ints), the lock (NO_LOCK, an element's index or
        ALL_LOCKED), the two brake laws as functions of time; and forget what belonged to the
        old modes (the mass map, the last friction torques, the event functions)."""
        elements = self.modes.elements
        self._signs_now = tuple(elements[k].direction.sign for k in ELEMENTS)
        locked = [i for i, s in enumerate(self._signs_now) if not s]
        self._lock = NO_LOCK if not locked else locked[0] if len(locked) == 1 else ALL_LOCKED
        self._torque_b, self._decay_b = self._brake_law("b")
        self._torque_h, self._decay_h = self._brake_law("h")
        self._map_key: tuple[float, float] | None = None
        self._map_value: tuple[float, ...] = ()  # K and f of the map for _map_key
        self._frictions_key: tuple | None = None
        self._frictions_value: tuple[float, ...] = ()
        self._event_list = None

    # -- brake laws ------------------------------------------------------------------------
    def _law(self, k):
        """(M_p, alpha, beta, t_c, t_r, z) of brake k."""
        return self._laws[k]

    def _brake_law(self, k: str):
        """(M_tk, decay): brake k's torque capacity as a function of time t, from its law and
        its state at the last command edge (t0, M0); and, unless it follows the power law, the
        same law as decay = (P, R0, rate, t0): M_tk(t) = P + R0 e^(-rate (t - t0)), t >= t0
        (engaging: P = M_p, R0 = M0 - M_p, rate = alpha; releasing: P = 0, R0 = M0, rate =
        beta; at its end value: P = M0, R0 = rate = 0). Built once per edge: the right-hand
        side calls M_tk, so the branches on the law are taken here, not in every call."""
        brake = self.modes.brakes[k]
        engaging, t0, M0 = brake.engaging, brake.t0, brake.M0
        Mp, alpha, beta, tc, tr, z = self._law(k)
        # tau = t - t0 >= 0 written as a conditional expression: max() costs as much as exp()
        if (engaging and M0 == Mp) or (not engaging and M0 == 0.0):
            return (lambda t: M0), (M0, 0.0, 0.0, t0)  # at the law's end value already
        if self._power and engaging:
            rise = Mp - M0
            return (lambda t: M0 + rise * min((t - t0 if t > t0 else 0.0) / tc, 1.0) ** z), None
        if self._power:
            return (lambda t: M0 * (1.0 - min((t - t0 if t > t0 else 0.0) / tr, 1.0)) ** z), None
        P, R0, rate = (Mp, M0 - Mp, alpha) if engaging else (0.0, M0, beta)
        return (lambda t: P + R0 * exp(-rate * (t - t0 if t > t0 else 0.0))), (P, R0, rate, t0)

    def brake_torque(self, k: str, t: float) -> float:
        """Torque capacity M_tk(t) of brake k from its law and the last command edge."""
        return self._brake_law(k)[0](t)

    def _breakpoints(self) -> list[float]:
        """Kinks of the power law (t0 + t_c, t0 + t_r) after the last discrete update."""
        if not self._power:
            return []
        out = []
        for k in MEMBERS:
            brake = self.modes.brakes[k]
            engaging, t0, M0 = brake.engaging, brake.t0, brake.M0
            Mp, _, _, tc, tr, _ = self._law(k)
            if (engaging and M0 != Mp) or (not engaging and M0 != 0.0):
                tb = t0 + (tc if engaging else tr)
                if tb > self.modes.t_last:
                    out.append(tb)
        return out

    # -- mechanics: plain floats (outputs, event functions, the integrator's right-hand side) --
    def _mass(self, sun_J: float, flange_J: float) -> tuple[float, float, float]:
        """(M_bb, M_bh, M_hh) of the mass matrix M of v = (w_b, w_h) (model card section 2)."""
        p = self.p
        pr, q = self._constants[:2]
        Ja = p.J_a + sun_J
        Jh = p.J_h + flange_J
        return Ja * pr * pr + p.J_b, -Ja * pr * q, Ja * q * q + Jh

    def _forces(self, u, signs, M_tb: float, M_th: float) -> tuple[float, float]:
        """(Qt_b, Qt_h): the generalised forces on (w_b, w_h) of the port torques and of the
        friction of the elements that slide in `signs` (F_k = -C_k d_k; 0 = locked) with the
        brake torques M_tb, M_th. With M_A = sun_tau + F_a:
        Qt_b = -p M_A + F_b, Qt_h = (1 + p) M_A + flange_tau + F_h."""
        pr, q, M_ca, M_cb, M_ch = self._constants
        sun_tau, _, flange_tau, _ = self._ports(u)
        s_a, s_b, s_h = signs
        M_A = sun_tau - M_ca * s_a
        return -pr * M_A - (M_tb + M_cb) * s_b, q * M_A + flange_tau - (M_th + M_ch) * s_h

    def _loads(self, t, u, signs) -> tuple[float, float, float, float]:
        """(Qt_b, Qt_h, M_tb, M_th): `_forces` with the brake torques at t, and those."""
        M_tb, M_th = self._torque_b(t), self._torque_h(t)
        return (*self._forces(u, signs, M_tb, M_th), M_tb, M_th)

    def _map(self, sun_J: float, flange_J: float) -> tuple[float, ...]:
        """(K_bb, K_bh, K_hb, K_hh, f_b, f_h): in the current lock, the accelerations are
        v' = K Qt and the locked element's constraint torque is F_j = f . Qt, both linear in
        the generalised forces. No lock: K = M^-1. One element j locked (G_j . v' = 0):
        v' = lambda N_j with lambda = N_j . Qt / N_j.M.N_j, and F_j = G_j.(M v' - Qt)/G_j.G_j.
        All locked: K = 0 (F from `_rest_interval`). K depends on the mode and the port
        inertias only, so it is kept until one of them changes: within a mode the state does
        not enter the accelerations at all."""
        if self._map_key == (sun_J, flange_J):
            return self._map_value
        m_bb, m_bh, m_hh = self._mass(sun_J, flange_J)
        lock = self._lock
        f = (0.0, 0.0)
        if lock == NO_LOCK:
            det = m_bb * m_hh - m_bh * m_bh
            K = (m_hh / det, -m_bh / det, -m_bh / det, m_bb / det)
        elif lock == ALL_LOCKED:
            K = (0.0, 0.0, 0.0, 0.0)
        else:
            (g_b, g_h), (n_b, n_h) = self._G[lock], self._N[lock]
            nMn = n_b * (m_bb * n_b + m_bh * n_h) + n_h * (m_bh * n_b + m_hh * n_h)
            K = (n_b * n_b / nMn, n_b * n_h / nMn, n_h * n_b / nMn, n_h * n_h / nMn)
            # rows of M K - 1, projected on G_j
            r_bb, r_bh = m_bb * K[0] + m_bh * K[2] - 1.0, m_bb * K[1] + m_bh * K[3]
            r_hb, r_hh = m_bh * K[0] + m_hh * K[2], m_bh * K[1] + m_hh * K[3] - 1.0
            gg = g_b * g_b + g_h * g_h
            f = ((g_b * r_bb + g_h * r_hb) / gg, (g_b * r_bh + g_h * r_hh) / gg)
        self._map_key, self._map_value = (sun_J, flange_J), K + f
        return self._map_value

    def _frictions(self, t, u) -> tuple[float, ...]:
        """(F_a, F_b, F_h, C_a, C_b, C_h, slack) in the current modes: friction torques F_k
        and capacities C_k (C_a = M_ca, C_b = M_tb + M_cb, C_h = M_th + M_ch). Sliding:
        F_k = -C_k d_k; one element locked: its constraint torque; all locked (two locked
        members hold the third at rest by Willis): the torques are statically indeterminate,
        F_a is chosen closest to 0 in its feasible interval and `slack` is the interval's width
        (negative: the rest cannot be held; +inf in the other modes).
        A function of t and the port inputs in a mode, so the last value is kept: within a step
        the hold check, both break-free event functions and the outputs ask at the same time."""
        sun_tau, sun_J, flange_tau, flange_J = self._ports(u)
        key = (t, sun_tau, sun_J, flange_tau, flange_J)
        if key == self._frictions_key:
            return self._frictions_value
        pr, q, M_ca, M_cb, M_ch = self._constants
        signs = self._signs_now
        Qt_b, Qt_h, M_tb, M_th = self._loads(t, u, signs)
        C = (M_ca, M_tb + M_cb, M_th + M_ch)
        F = [-C[0] * signs[0], -C[1] * signs[1], -C[2] * signs[2]]
        slack = math.inf
        lock = self._lock
        if lock == ALL_LOCKED:
            lo, hi, F_a = self._rest_interval(Qt_b, Qt_h, C)
            slack = hi - lo
            F = [F_a, -Qt_b + pr * F_a, -Qt_h - q * F_a]
        elif lock != NO_LOCK:
            f_b, f_h = self._map(sun_J, flange_J)[4:]
            F[lock] = f_b * Qt_b + f_h * Qt_h
        self._frictions_key, self._frictions_value = key, (*F, *C, slack)
        return self._frictions_value

    def _rest_interval(self, Q_b, Q_h, C):
        """All at rest: F_b = -Q_b + p F_a, F_h = -Q_h - (1+p) F_a; the F_a that keep every
        |F_k| <= C_k form [lo, hi]. Returns (lo, hi, F_a closest to 0 within it)."""
        pr, q = self._constants[:2]
        C_a, C_b, C_h = C
        lo = max(-C_a, (Q_b - C_b) / pr, (-Q_h - C_h) / q)
        hi = min(C_a, (Q_b + C_b) / pr, (-Q_h + C_h) / q)
        F_a = min(max(0.0, lo), hi) if lo <= hi else 0.5 * (lo + hi)
        return lo, hi, F_a

    # -- mode decisions (at events only) --------------------------------------------------
    def _choose_modes(self, t, u, zero, forced=None, shrink=1.0) -> None:
        """Modes of the members in `zero` (speed exactly zero now), the others keeping theirs
        (`forced`: members made to slide in a given direction). Coulomb friction with
        given capacities has a unique acceleration: the minimiser of the convex function
            f(a) = 1/2 a.M.a - Qt.a + sum_{k in zero} C_k |G_k.a|
        (Gauss's principle with maximum dissipation; Qt includes the sliding frictions). Its
        minimiser is one of: a = 0 (all of `zero` stuck), a on the line G_j.a = 0 (j stuck,
        the others slide), or a smooth point of one sign pattern (all slide): evaluate f at
        each candidate and keep the least. `shrink` < 1 scales the stuck capacities (used at a
        break-free event to decide on the side of breaking free)."""
        elements = self.modes.elements
        for k, direction in (forced or {}).items():
            elements[k].direction = direction
        zero = [k for k in ELEMENTS if k in zero and k not in (forced or {})]
        signs = tuple(0 if k in zero else elements[k].direction.sign for k in ELEMENTS)
        Qt_b, Qt_h, M_tb, M_th = self._loads(t, u, signs)
        _, _, M_ca, M_cb, M_ch = self._constants
        _, sun_J, _, flange_J = self._ports(u)
        m_bb, m_bh, m_hh = self._mass(sun_J, flange_J)
        M, Qt = np.array([[m_bb, m_bh], [m_bh, m_hh]]), np.array([Qt_b, Qt_h])
        C = dict(zip(ELEMENTS, (M_ca, M_tb + M_cb, M_th + M_ch)))
        G = {k: np.array(g) for k, g in zip(ELEMENTS, self._G)}
        N = {k: np.array(n) for k, n in zip(ELEMENTS, self._N)}
        Cz = {k: shrink * C[k] for k in zero}

        def f(a):
            return 0.5 * a @ M @ a - Qt @ a + sum(Cz[k] * abs(G[k] @ a) for k in zero)

        candidates = [(np.zeros(2), set(zero))]
        for j in zero:
            n = N[j]
            q = float(Qt @ n)
            c = sum(Cz[k] * abs(G[k] @ n) for k in zero if k != j)
            lam = math.copysign(max(abs(q) - c, 0.0), q) / float(n @ M @ n)
            if lam != 0.0:
                candidates.append((lam * n, {j}))
        for pattern in itertools.product((-1.0, 1.0), repeat=len(zero)):
            rhs = Qt - sum((Cz[k] * s * G[k] for k, s in zip(zero, pattern)), np.zeros(2))
            a = np.linalg.solve(M, rhs)
            if all(s * (G[k] @ a) > 0.0 for k, s in zip(zero, pattern)):
                candidates.append((a, set()))
        a, stuck = min(candidates, key=lambda c: (f(c[0]), -len(c[1])))
        if len(stuck) == 2:  # two stuck hold the third (cannot happen for the minimiser)
            stuck = set(ELEMENTS)
        for k in zero:
            elements[k].direction = LOCKED if k in stuck else \
                (Direction.FORWARD if G[k] @ a > 0.0 else Direction.BACKWARD)
        self._mode_changed()

    def _lock_set(self) -> list[str]:
        elements = self.modes.elements
        return [k for k in ELEMENTS if elements[k].direction is LOCKED]

    def _signs(self) -> dict[str, int]:
        """Direction.sign of each friction element (+1/-1 sliding, 0 locked)."""
        elements = self.modes.elements
        return {k: elements[k].direction.sign for k in ELEMENTS}

    def _record(self, t, before: dict) -> None:
        """Count locks and break-frees between the modes `before` (`_signs()`) and now."""
        for k in ELEMENTS:
            element = self.modes.elements[k]
            old, new = before[k], element.direction.sign
            if old and not new:
                element.n_lock += 1
                element.t_lock = float(t)
            elif not old and new:
                element.n_slip += 1
                element.t_slip = float(t)

    def _zero_speeds(self, x):
        """Put the locked members' speeds exactly at zero (all locked: everything at rest)."""
        locked = self._lock_set()
        if len(locked) >= 2:
            x[X.w_b] = x[X.w_h] = 0.0
        elif locked == ["b"]:
            x[X.w_b] = 0.0
        elif locked == ["h"]:
            x[X.w_h] = 0.0
        elif locked == ["a"]:  # w_a = -p w_b + (1+p) w_h = 0
            pr = self.ratio
            x[X.w_b] = (1 + pr) * x[X.w_h] / pr
        return x

    def period(self) -> int:
        """1 idle, 2 engagement, 3 working stroke, 4 stopping."""
        elements = self.modes.elements
        if self.modes.command:
            return 3 if elements["b"].direction is LOCKED else 2
        return 1 if elements["h"].direction is LOCKED else 4

    def _apply_command(self, t, value: int) -> None:
        modes = self.modes
        for k in MEMBERS:
            M_now = self.brake_torque(k, t)
            engage = (k == "b") == bool(value)
            modes.brakes[k] = BrakeState(engage, float(t), M_now)
        modes.command = int(value)
        modes.t_command = float(t)
        modes.n_events += 1
        self._mode_changed()

    def _holds(self, t, u) -> bool:
        """Do the present locks hold (friction torques within capacity)?"""
        lock = self._lock
        if lock == NO_LOCK:
            return True
        frictions = self._frictions(t, u)
        if lock == ALL_LOCKED:
            return frictions[6] >= 0.0
        return abs(frictions[lock]) <= frictions[3 + lock]

    def on_input_change(self, t, x, u):
        """Discrete update for inputs that jumped at time t (a communication point): a command
        edge starts engagement/stopping, and locks that no longer hold break free. Hosts that
        integrate the model themselves (monolithic references) call this after every input
        discontinuity."""
        value = 1 if u[self.IN.command] >= 0.5 else 0
        if value != self.modes.command:
            self._apply_command(t, value)
        if not self._holds(t, u):
            before = self._signs()
            self._choose_modes(t, u, self._lock_set(), shrink=1.0 - 1e-9)
            self._record(t, before)
            self.modes.n_events += 1
        return x

    # -- contract --------------------------------------------------------------------------
    def state_names(self):
        return STATE_NAMES

    def initial_state(self, u):
        p, pr = self.p, self.ratio
        u = np.asarray(u, dtype=float)
        self._derive()
        self.modes = self._fresh_modes()
        x = np.zeros(len(STATE_NAMES))
        x[X.phi_b], x[X.phi_h] = p.phi_b_start, p.phi_h_start
        if p.initial_period == 1.0:  # carrier held, ring turns backwards
            x[X.w_b] = -p.w_a_start / pr
        else:  # ring held, carrier forwards
            x[X.w_h] = p.w_a_start / (1 + pr)
        w = {"a": p.w_a_start, "b": x[X.w_b], "h": x[X.w_h]}
        for k in ELEMENTS:
            self.modes.elements[k].direction = Direction(int(np.sign(w[k])))
        self._mode_changed()
        zero = [k for k in ELEMENTS if w[k] == 0.0]
        self._choose_modes(0.0, u, zero)
        return self._zero_speeds(x)

    def state_nominal(self) -> np.ndarray:
        """Angles ~10 rad, speeds ~ the ring's idle speed, energies ~ the sun's kinetic
        energy at the start speed (absolute tolerance = rtol * nominal)."""
        p = self.p
        w = max(abs(p.w_a_start), 10.0)
        E = max(0.5 * (p.J_a + p.J_b + p.J_h) * w * w, 1.0)
        return np.array([10.0, 10.0, w / self.ratio, w / (1 + self.ratio), E, E, E, E, E])

    def sun_speed(self, x) -> float:
        """w_a = -p w_b + (1 + p) w_h (Willis); exactly 0.0 while the sun is locked."""
        if not self._signs_now[0]:
            return 0.0
        pr, q = self._constants[:2]
        return -pr * x[X.w_b] + q * x[X.w_h]

    def derivatives(self, t, x, u):
        _, _, w_b, w_h, _, _, _, _, _ = x
        sun_tau, sun_J, flange_tau, flange_J = self._ports(u)
        Qt_b, Qt_h, M_tb, M_th = self._loads(t, u, self._signs_now)
        K_bb, K_bh, K_hb, K_hh, _, _ = self._map(sun_J, flange_J)
        pr, q, M_ca, M_cb, M_ch = self._constants
        s_a, s_b, s_h = self._signs_now
        w_a = -pr * w_b + q * w_h if s_a else 0.0
        slip_b, slip_h = s_b * w_b, s_h * w_h
        return (  # in the order of STATE_NAMES
            w_b, w_h, K_bb * Qt_b + K_bh * Qt_h, K_hb * Qt_b + K_hh * Qt_h,
            M_tb * slip_b,
            M_th * slip_h,
            M_ca * s_a * w_a + M_cb * slip_b + M_ch * slip_h,
            sun_tau * w_a,
            flange_tau * w_h,
        )

    def kinetic_energy(self, x, u) -> float:
        """1/2 v.M.v."""
        _, sun_J, _, flange_J = self._ports(u)
        m_bb, m_bh, m_hh = self._mass(sun_J, flange_J)
        w_b, w_h = x[X.w_b], x[X.w_h]
        return 0.5 * (m_bb * w_b * w_b + 2.0 * m_bh * w_b * w_h + m_hh * w_h * w_h)

    def output_values(self, t, x, u):
        phi_b, phi_h, w_b, w_h, E_brake_b, E_brake_h, E_resist, W_sun, W_flange = x
        pr, q = self._constants[:2]
        F_a, F_b, F_h = self._frictions(t, u)[:3]
        w_a = self.sun_speed(x)
        m = self.modes
        b, h = m.elements["b"], m.elements["h"]
        return self.output_vector(dict(
            sun_w=w_a, sun_phi=-pr * phi_b + q * phi_h, flange_w=w_h, flange_phi=phi_h,
            w_a=w_a, w_b=w_b, w_h=w_h, M_tb=self._torque_b(t), M_th=self._torque_h(t),
            tau_b=F_b, tau_h=F_h, tau_a=F_a,
            E_brake_b=E_brake_b, E_brake_h=E_brake_h, E_resist=E_resist,
            W_sun=W_sun, W_flange=W_flange, E_kin=self.kinetic_energy(x, u),
            period=float(self.period()), t_command=m.t_command,
            t_lock_b=b.t_lock, t_slip_b=b.t_slip, t_lock_h=h.t_lock, t_slip_h=h.t_slip,
            n_lock_b=float(b.n_lock), n_lock_h=float(h.n_lock), n_events=float(m.n_events),
        ))

    # -- events ----------------------------------------------------------------------------
    def event_functions(self, u_of_t):
        """The current modes' event functions, built once per mode (they read the inputs of
        the integration under way, `u_of_t`, through the model)."""
        self._u_of_t = u_of_t
        if self._event_list is None:
            self._event_list = self._mode_events()
        self._events = self._event_list[0]
        return self._event_list[1]

    def _mode_events(self) -> tuple[list, list]:
        """(events, functions) of the current modes: a sliding element's zero speed, the single
        locked element's break-free either way, the end of the rest when all are locked, the
        command edge and the power law's kinks. Each function costs one `_frictions` call at
        most (no mode decision)."""
        events, funcs = [], []

        def add(event, g, direction):
            g.terminal, g.direction = True, direction
            events.append(event)
            funcs.append(g)

        def frictions(t):
            return self._frictions(t, self._u_of_t(t))

        lock = self._lock
        if lock == ALL_LOCKED:  # all at rest: the feasible interval of F_a closes
            add(BREAK_REST_EVENT, lambda t, x: frictions(t)[6], -1)
        for i, k in enumerate(ELEMENTS):
            sign = self._signs_now[i]
            if not sign:
                if lock == i:
                    def g_fwd(t, x, i=i):  # F_k -> -C_k: breaks free forwards
                        F = frictions(t)
                        return F[3 + i] + F[i]

                    def g_bwd(t, x, i=i):  # F_k -> +C_k: breaks free backwards
                        F = frictions(t)
                        return F[3 + i] - F[i]

                    add(SLIP_EVENTS[k, Direction.FORWARD], g_fwd, -1)
                    add(SLIP_EVENTS[k, Direction.BACKWARD], g_bwd, -1)
            else:  # w_k = G_k . (w_b, w_h) falls to zero
                g_b, g_h = self._G[i]
                add(ZERO_EVENTS[k], lambda t, x, g_b=g_b, g_h=g_h: g_b * x[X.w_b] + g_h * x[X.w_h],
                    -sign)
        command_sign = 1.0 if self.modes.command == 0 else -1.0
        i_cmd = self.IN.command
        add(COMMAND_EVENT, lambda t, x: command_sign * (self._u_of_t(t)[i_cmd] - 0.5), 1)
        for tb in self._breakpoints():
            add(Event(EventKind.TIME, time=tb), lambda t, x, tb=tb: t - tb, 1)
        return events, funcs

    def on_event(self, t, x, u, index):
        event = self._events[index]
        x = list(x)
        modes, elements = self.modes, self.modes.elements
        modes.t_last = float(t)
        if event.kind is EventKind.TIME:
            self._mode_changed()  # the kink is passed: the next integration has no event at it
            return x
        modes.n_events += 1
        before = self._signs()
        if event.kind is EventKind.SLIP:  # the single locked member breaks free
            self._choose_modes(t, u, [], forced={event.element: event.direction})
        elif event.kind is EventKind.BREAK_REST:
            self._choose_modes(t, u, list(ELEMENTS), shrink=1.0 - 1e-9)
        elif event.kind is EventKind.ZERO:  # member reaches zero speed: lock it if it can
            k = event.element
            elements[k].direction = LOCKED
            zero = self._lock_set()
            if len(zero) >= 2:
                zero = list(ELEMENTS)
            for j in zero:
                elements[j].direction = LOCKED
            x = self._zero_speeds(x)
            self._choose_modes(t, u, zero)
            if elements[k].direction is not LOCKED and k in MEMBERS:
                # passed through zero without locking
                modes.n_pass += 1
        elif event.kind is EventKind.COMMAND:
            modes.n_events -= 1  # _apply_command counts it
            self._apply_command(t, 0 if modes.command else 1)
            if not self._holds(t, u):
                self._choose_modes(t, u, self._lock_set(), shrink=1.0 - 1e-9)
        self._record(t, before)
        self._mode_changed()
        return self._zero_speeds(x)

    def advance(self, t0, x0, h, u_of_t, rtol, atol):
        """on_input_change at t0, then the event loop: in closed form (`_advance_exactly`)
        when the inputs are held over the step and both brakes follow the exponential law
        (every shipped scene), else with the runtime's integrator on `derivatives`."""
        if h <= 0.0:
            return list(x0)
        x = self.on_input_change(t0, x0, u_of_t(t0))
        if self.solver == "scipy" or not isinstance(u_of_t, InputPolynomial) or \
                u_of_t.moving or self._decay_b is None or self._decay_h is None:
            return super().advance(t0, x, h, u_of_t, rtol, atol)
        return self._advance_exactly(t0, x, h, u_of_t, rtol, atol)

    # -- the exact step (held inputs, exponential laws) --------------------------------------
    def _advance_exactly(self, t0, x, h, u_of_t, rtol, atol):
        """The base class's event loop with the exact solution (`_trajectory`) in place of an
        integrator: from each restart, the earliest event of the current modes within the step
        (`_first_event`), on_event there, and on in the new modes."""
        self._check_inputs(t0, u_of_t)
        u = u_of_t(t0)
        t, t_end = t0, t0 + h
        for _ in range(self.max_events_per_step):
            if self._decay_b is None or self._decay_h is None:  # a power law began mid-step
                return PhysicsModel.advance(self, t, x, t_end - t, u_of_t, rtol, atol)
            span = h if t == t0 else t_end - t  # h itself: the integrals are cached per span
            state = self._trajectory(t, x, u)
            x_end = state(span)
            hit = self._first_event(self.event_functions(u_of_t), t, x, span, state, x_end)
            if hit is None:
                return x_end
            sigma, index = hit
            t_event = t_end if sigma == span else t + sigma
            x = self.on_event(t_event, state(sigma), u, index)
            t = t_event
            if t >= t_end:
                return x
        raise IntegrationError(f"{self.model_name}: more than {self.max_events_per_step} "
                               f"events in one step at t = {t:.9g} s")

    def _trajectory(self, t_a, x_a, u):
        """The solution of `derivatives` from (t_a, x_a) in the current modes with the inputs
        u held, as a function of sigma = t - t_a (model card section 11). With the brake
        torques M_tk(t_a + sigma) = P_k + R_k e^(-l_k sigma), Qt is affine in them (the sliding
        member k adds -s_k M_tk G_k, G_b = (1, 0), G_h = (0, 1)), so the accelerations are
        v' = K Qt = c + d_b e^(-l_b sigma) + d_h e^(-l_h sigma) and every state is an integral
        of exponentials and polynomials in sigma."""
        phi_b, phi_h, w_b, w_h, E_b, E_h, E_r, W_s, W_f = x_a
        sun_tau, sun_J, flange_tau, flange_J = self._ports(u)
        pr, q, M_ca, M_cb, M_ch = self._constants
        s_a, s_b, s_h = signs = self._signs_now
        K_bb, K_bh, K_hb, K_hh = self._map(sun_J, flange_J)[:4]
        P_b, R_b, l_b = _decay_from(self._decay_b, t_a)
        P_h, R_h, l_h = _decay_from(self._decay_h, t_a)
        Q_b, Q_h = self._forces(u, signs, P_b, P_h)
        c_b, c_h = K_bb * Q_b + K_bh * Q_h, K_hb * Q_b + K_hh * Q_h
        r_b, r_h = -s_b * R_b, -s_h * R_h
        db_b, db_h, dh_b, dh_h = K_bb * r_b, K_hb * r_b, K_bh * r_h, K_hh * r_h

        def brake_energy(s_k, P_k, R_k, l_k, E1_k, J1_k, w_k, c_k, db_k, dh_k, dphi_k, sigma):
            """int M_tk s_k w_k = s_k (P_k dphi_k + R_k int e^(-l_k s) w_k(s) ds)."""
            if not (s_k and R_k):
                return s_k * P_k * dphi_k
            decayed = w_k * E1_k + c_k * J1_k + \
                db_k * decay_product(l_k, l_b, sigma, E1_k, J1_k) + \
                dh_k * decay_product(l_k, l_h, sigma, E1_k, J1_k)
            return s_k * (P_k * dphi_k + R_k * decayed)

        def state(sigma):
            E1_b, E2_b, J1_b = exponential_integrals(l_b, sigma)
            E1_h, E2_h, J1_h = exponential_integrals(l_h, sigma)
            half_square = 0.5 * sigma * sigma
            dphi_b = w_b * sigma + c_b * half_square + db_b * E2_b + dh_b * E2_h
            dphi_h = w_h * sigma + c_h * half_square + db_h * E2_b + dh_h * E2_h
            dphi_a = -pr * dphi_b + q * dphi_h if s_a else 0.0
            return [phi_b + dphi_b, phi_h + dphi_h,
                    w_b + c_b * sigma + db_b * E1_b + dh_b * E1_h,
                    w_h + c_h * sigma + db_h * E1_b + dh_h * E1_h,
                    E_b + brake_energy(s_b, P_b, R_b, l_b, E1_b, J1_b, w_b, c_b, db_b, dh_b,
                                       dphi_b, sigma),
                    E_h + brake_energy(s_h, P_h, R_h, l_h, E1_h, J1_h, w_h, c_h, db_h, dh_h,
                                       dphi_h, sigma),
                    E_r + M_ca * s_a * dphi_a + M_cb * s_b * dphi_b + M_ch * s_h * dphi_h,
                    W_s + sun_tau * dphi_a, W_f + flange_tau * dphi_h]
        return state

    def _first_event(self, events, t_a, x_a, span, state, x_end):
        """(sigma, index) of the earliest event in [t_a, t_a + span] by the rule of the
        runtime's integrators (solve_ivp's: a sign change in the function's direction between
        two samples, a zero at either counts; located with Brent's method to 4 eps), or None.
        The samples: see EVENT_SAMPLE (in the shipped scenes, rate x step <= 0.04: the step's
        ends only, where the Dormand-Prince checked its one step per communication step)."""
        rate, decaying = 0.0, 0.0  # the fastest decay still on, how long the decays last
        for _, R0, l_k, t0 in (self._decay_b, self._decay_h):
            if R0 and t0 + DECAYED / l_k > t_a:
                rate, decaying = max(rate, l_k), max(decaying, t0 + DECAYED / l_k - t_a)
        decaying = min(span, decaying)
        pieces = math.ceil(rate * decaying / EVENT_SAMPLE)
        samples = [decaying * k / pieces for k in range(1, pieces)]
        if 0.0 < decaying < span:
            samples.append(decaying)
        samples.append(span)
        sigma_old, g_old = 0.0, [g(t_a, x_a) for g in events]
        for sigma in samples:
            x_new = x_end if sigma == span else state(sigma)
            g_new = [g(t_a + sigma, x_new) for g in events]
            roots = []
            for i, (g, a, b) in enumerate(zip(events, g_old, g_new)):
                if not ((a <= 0.0 <= b and g.direction >= 0) or
                        (a >= 0.0 >= b and g.direction <= 0)):
                    continue
                if a == 0.0:
                    roots.append((sigma_old, i))
                elif b == 0.0:
                    roots.append((sigma, i))
                else:
                    roots.append((brentq(lambda s, g=g: g(t_a + s, state(s)), sigma_old, sigma,
                                         xtol=4 * EPS, rtol=4 * EPS), i))
            if roots:
                return min(roots)
            sigma_old, g_old = sigma, g_new
        return None

    # -- steady states ---------------------------------------------------------------------
    def steady_sun_torque(self, period: int, flange_tau: float = 0.0) -> float:
        """Motor torque on the sun that keeps the drive in steady motion (released brake fully
        off, resistances constant, w_a > 0):
          period 1 (carrier held, ring turning backwards, w_b = -w_a/p < 0):
              0 = -p (M - M_ca) + M_cb          ->  M = M_ca + M_cb/p
          period 3 (ring held, carrier forward, w_h = w_a/(1+p) > 0):
              0 = (1+p)(M - M_ca) + tau_fl - M_ch  ->  M = M_ca + (M_ch - tau_fl)/(1+p)"""
        p, pr = self.p, self.ratio
        if period == 1:
            return p.M_ca + p.M_cb / pr
        if period == 3:
            return p.M_ca + (p.M_ch - flange_tau) / (1 + pr)
        raise ValueError("steady states exist in periods 1 and 3 only")

    def holding_torque(self, period: int, flange_tau: float = 0.0) -> float:
        """Constraint torque F_k on the held member in the steady state of `period` (carrier in
        period 1, ring in period 3); it must stay within the capacity M_p + M_ck."""
        pr = self.ratio
        M_A = self.steady_sun_torque(period, flange_tau) - self.p.M_ca
        if period == 1:
            return -(1 + pr) * M_A - flange_tau
        return pr * M_A


def _decay_from(decay, t_a: float) -> tuple[float, float, float]:
    """(P, R, rate) with M_t(t_a + sigma) = P + R e^(-rate sigma), from a brake law's decay
    (P, R0, rate, t0)."""
    P, R0, rate, t0 = decay
    return P, R0 * exp(-rate * (t_a - t0 if t_a > t0 else 0.0)), rate


def steady_state(drive: PlanetaryClutchDrive, motor, period: int,
                 flange_tau: float = 0.0) -> dict:
    """Steady state of drive + motor in period 1 (idle) or 3 (working stroke).

    `motor` is anything with speed_at_torque(M) (e.g. InductionMotor). Returns the speeds, the
    motor torque and the holding torque of the held member."""
    M = drive.steady_sun_torque(period, flange_tau)
    w_a = motor.speed_at_torque(M)
    pr = drive.ratio
    if period == 1:
        w_b, w_h = -w_a / pr, 0.0
    else:
        w_b, w_h = 0.0, w_a / (1 + pr)
    return {"w_a": w_a, "w_b": w_b, "w_h": w_h, "M_motor": M,
            "holding_torque": drive.holding_torque(period, flange_tau)}
