"""Planetary drive of a crank press with friction brakes on the ring and the carrier (seed
planetary_drive_friction_clutch, eq. (1)-(10); MODELS.md section 3): three coupled Coulomb
elements that lock and break free, brake laws, the four periods, a carrier port for a press.
Equations, modes, events, variables and tests: the model card README.md in this folder.
"""
from __future__ import annotations

import enum
import itertools
import math
from dataclasses import dataclass

import numpy as np

from ...runtime.model import Effect, ParameterError, PhysicsModel, Variable, name_indices

MEMBERS = ("b", "h")      # braked members
ELEMENTS = ("a", "b", "h")  # friction elements: sun resistance, ring and carrier brakes
STATE_NAMES = ("phi_b", "phi_h", "w_b", "w_h", "E_brake_b", "E_brake_h", "E_resist", "W_sun",
               "W_flange")
X = name_indices("PlanetaryClutchDrive", "state", STATE_NAMES)  # x[X.w_b]: state by name

NEVER = -1.0  # event-time outputs before the first such event


class Direction(enum.Enum):
    """How a friction element moves. `sign` is the sign of its speed while sliding, 0 while
    locked: the d of F_k = -C_k d and of the slip power d w. A plain int attribute, not an
    IntEnum: an IntEnum times a numpy float costs ~1.5 us (numpy's slow path), in every
    right-hand side."""

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
    `to_json`/`from_json` give the JSON-safe form the FMU saves (floats exact, -inf as None)."""

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

# Events are values: built once here, not at every integration restart (constructing a frozen
# dataclass costs ~1 us). TIME events carry their time and are built when needed.
BREAK_REST_EVENT = Event(EventKind.BREAK_REST)
COMMAND_EVENT = Event(EventKind.COMMAND)
ZERO_EVENTS = {k: Event(EventKind.ZERO, k) for k in ELEMENTS}
SLIP_EVENTS = {(k, d): Event(EventKind.SLIP, k, d) for k in ELEMENTS
               for d in (Direction.FORWARD, Direction.BACKWARD)}


class PlanetaryClutchDrive(PhysicsModel):
    model_name = "PlanetaryClutchDrive"
    description = ("Type-A planetary drive with friction brakes on ring and carrier: engagement, "
                   "working stroke, stopping, idle; stick-slip locking")
    seed = "planetary_drive_friction_clutch.txt, eq. (1)-(10)"
    integrator = "DOP853"
    # advance() = on_input_change at the step start + the base event loop (the composed
    # reference does the same at every restart)
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

    def __init__(self, parameters=None, effects=None):
        super().__init__(parameters, effects)
        self._derive()
        self.modes = self._fresh_modes()
        self._events: list[Event] = []

    def _derive(self) -> None:
        """Constants derived from the parameters (again in initial_state, so a host that sets
        parameters on self.p after construction is safe)."""
        pr = self.ratio
        self._G = {"a": np.array([-pr, 1.0 + pr]), "b": np.array([1.0, 0.0]),
                   "h": np.array([0.0, 1.0])}
        self._N = {"a": np.array([1.0 + pr, pr]), "b": np.array([0.0, 1.0]),
                   "h": np.array([1.0, 0.0])}
        p = self.p
        self._laws = {k: (getattr(p, "Mp_" + k), getattr(p, "alpha_" + k),
                          getattr(p, "beta_" + k), getattr(p, "tc_" + k),
                          getattr(p, "tr_" + k), getattr(p, "z_" + k)) for k in MEMBERS}
        self._power = self.on("power_law")

    # -- brake laws ------------------------------------------------------------------------
    def _law(self, k):
        """(M_p, alpha, beta, t_c, t_r, z) of brake k."""
        return self._laws[k]

    def brake_torque(self, k: str, t: float) -> float:
        """Torque capacity M_tk(t) of brake k from its law and the last command edge."""
        brake = self.modes.brakes[k]
        engaging, t0, M0 = brake.engaging, brake.t0, brake.M0
        Mp, alpha, beta, tc, tr, z = self._law(k)
        tau = max(t - t0, 0.0)
        if engaging:
            if M0 == Mp:
                return Mp
            if self._power:
                return M0 + (Mp - M0) * min(tau / tc, 1.0) ** z
            return Mp - (Mp - M0) * math.exp(-alpha * tau)
        if M0 == 0.0:
            return 0.0
        if self._power:
            return M0 * (1.0 - min(tau / tr, 1.0)) ** z
        return M0 * math.exp(-beta * tau)

    def _breakpoints(self) -> list[float]:
        """Kinks of the power law (t0 + t_c, t0 + t_r) after the last discrete update."""
        if not self.on("power_law"):
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

    # -- mechanics -------------------------------------------------------------------------
    def mass_matrix(self, u) -> np.ndarray:
        p, pr = self.p, self.ratio
        Ja = p.J_a + u[self.IN.sun_J]
        Jh = p.J_h + u[self.IN.flange_J]
        return np.array([[Ja * pr * pr + p.J_b, -Ja * pr * (1 + pr)],
                         [-Ja * pr * (1 + pr), Ja * (1 + pr) ** 2 + Jh]])

    def _geometry(self):
        """G_k (w_k = G_k . v, v = (w_b, w_h)) and N_k (G_k . N_k = 0) of the friction elements."""
        return self._G, self._N

    def _loads(self, t, u):
        """(M, Q, C): mass matrix, generalised port torques, friction capacities."""
        p = self.p
        Q = u[self.IN.sun_tau] * self._G["a"] + np.array([0.0, u[self.IN.flange_tau]])
        C = {"a": p.M_ca, "b": self.brake_torque("b", t) + p.M_cb,
             "h": self.brake_torque("h", t) + p.M_ch}
        return self.mass_matrix(u), Q, C

    def _signs(self) -> dict[str, int]:
        """Direction.sign of each friction element (+1/-1 sliding, 0 locked)."""
        elements = self.modes.elements
        return {k: elements[k].direction.sign for k in ELEMENTS}

    def _solve(self, t, u, signs=None):
        """Accelerations (dw_b, dw_h), friction torques F_k and capacities C_k in the modes
        `signs` (Direction.sign per element; default: the current ones). Locked sets are {}, {j} or all three (two locked
        members hold the third at rest by Willis); with all three locked the friction torques
        are statically indeterminate: F_a is chosen closest to 0 in its feasible interval and
        `slack` is the interval's width (negative: the rest cannot be held)."""
        signs = self._signs() if signs is None else signs
        M, Q, C = self._loads(t, u)
        G, N = self._geometry()
        F = {k: -C[k] * d for k, d in signs.items() if d}
        Qt = Q + sum((F[k] * G[k] for k in F), np.zeros(2))
        locked = [k for k in ELEMENTS if not signs[k]]
        slack = math.inf
        if not locked:
            det = M[0, 0] * M[1, 1] - M[0, 1] * M[1, 0]
            a = np.array([M[1, 1] * Qt[0] - M[0, 1] * Qt[1],
                          M[0, 0] * Qt[1] - M[1, 0] * Qt[0]]) / det
        elif len(locked) == 1:
            j = locked[0]
            n = N[j]
            a = (n @ Qt) / (n @ M @ n) * n
            F[j] = float(G[j] @ (M @ a - Qt)) / float(G[j] @ G[j])
        else:
            a = np.zeros(2)
            lo, hi, F_a = self._rest_interval(Qt, C)
            slack = hi - lo
            pr = self.ratio
            F["a"], F["b"], F["h"] = F_a, -Qt[0] + pr * F_a, -Qt[1] - (1 + pr) * F_a
        return a, F, C, slack

    def _rest_interval(self, Q, C):
        """All at rest: F_b = -Q_b + p F_a, F_h = -Q_h - (1+p) F_a; the F_a that keep every
        |F_k| <= C_k form [lo, hi]. Returns (lo, hi, F_a closest to 0 within it)."""
        pr = self.ratio
        lo = max(-C["a"], (Q[0] - C["b"]) / pr, (-Q[1] - C["h"]) / (1 + pr))
        hi = min(C["a"], (Q[0] + C["b"]) / pr, (-Q[1] + C["h"]) / (1 + pr))
        F_a = min(max(0.0, lo), hi) if lo <= hi else 0.5 * (lo + hi)
        return lo, hi, F_a

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
        for k, direction in (forced or {}).items():
            self.modes.elements[k].direction = direction
        signs = self._signs()
        zero = [k for k in ELEMENTS if k in zero and k not in (forced or {})]
        M, Q, C = self._loads(t, u)
        G, N = self._geometry()
        Qt = Q + sum((-C[k] * signs[k] * G[k] for k in ELEMENTS
                      if k not in zero and signs[k]), np.zeros(2))
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
        for signs in itertools.product((-1.0, 1.0), repeat=len(zero)):
            rhs = Qt - sum((Cz[k] * s * G[k] for k, s in zip(zero, signs)), np.zeros(2))
            a = np.linalg.solve(M, rhs)
            if all(s * (G[k] @ a) > 0.0 for k, s in zip(zero, signs)):
                candidates.append((a, set()))
        a, stuck = min(candidates, key=lambda c: (f(c[0]), -len(c[1])))
        if len(stuck) == 2:  # two stuck hold the third (cannot happen for the minimiser)
            stuck = set(ELEMENTS)
        for k in zero:
            self.modes.elements[k].direction = LOCKED if k in stuck else \
                (Direction.FORWARD if G[k] @ a > 0.0 else Direction.BACKWARD)

    def _lock_set(self) -> list[str]:
        elements = self.modes.elements
        return [k for k in ELEMENTS if elements[k].direction is LOCKED]

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

    def _zero_speeds(self, x) -> np.ndarray:
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

    def _holds(self, t, u) -> bool:
        """Do the present locks hold (friction torques within capacity)?"""
        _, F, C, slack = self._solve(t, u)
        locked = self._lock_set()
        if len(locked) == 3:
            return slack >= 0.0
        return all(abs(F[k]) <= C[k] for k in locked)

    def on_input_change(self, t, x, u) -> np.ndarray:
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
        if self.modes.elements["a"].direction is LOCKED:
            return 0.0
        pr = self.ratio
        return -pr * x[X.w_b] + (1 + pr) * x[X.w_h]

    def derivatives(self, t, x, u):
        p = self.p
        a, _, C, _ = self._solve(t, u)
        w_b, w_h = x[X.w_b], x[X.w_h]
        e = self.modes.elements
        w_a = self.sun_speed(x)
        slip_a, slip_b, slip_h = (e["a"].direction.sign * w_a, e["b"].direction.sign * w_b,
                                  e["h"].direction.sign * w_h)
        return np.array([  # in the order of STATE_NAMES
            w_b, w_h, a[0], a[1],
            (C["b"] - p.M_cb) * slip_b,
            (C["h"] - p.M_ch) * slip_h,
            p.M_ca * slip_a + p.M_cb * slip_b + p.M_ch * slip_h,
            u[self.IN.sun_tau] * w_a,
            u[self.IN.flange_tau] * w_h,
        ])

    def kinetic_energy(self, x, u) -> float:
        w = np.array([x[X.w_b], x[X.w_h]])
        return 0.5 * float(w @ self.mass_matrix(u) @ w)

    def output_values(self, t, x, u):
        pr = self.ratio
        _, F, _, _ = self._solve(t, u)
        w_a = self.sun_speed(x)
        phi_a = -pr * x[X.phi_b] + (1 + pr) * x[X.phi_h]
        m = self.modes
        b, h = m.elements["b"], m.elements["h"]
        return np.array(self.output_vector(dict(
            sun_w=w_a, sun_phi=phi_a, flange_w=x[X.w_h], flange_phi=x[X.phi_h],
            w_a=w_a, w_b=x[X.w_b], w_h=x[X.w_h],
            M_tb=self.brake_torque("b", t), M_th=self.brake_torque("h", t),
            tau_b=F["b"], tau_h=F["h"], tau_a=F["a"],
            E_brake_b=x[X.E_brake_b], E_brake_h=x[X.E_brake_h], E_resist=x[X.E_resist],
            W_sun=x[X.W_sun], W_flange=x[X.W_flange], E_kin=self.kinetic_energy(x, u),
            period=float(self.period()), t_command=m.t_command,
            t_lock_b=b.t_lock, t_slip_b=b.t_slip, t_lock_h=h.t_lock, t_slip_h=h.t_slip,
            n_lock_b=float(b.n_lock), n_lock_h=float(h.n_lock), n_events=float(m.n_events),
        )), dtype=float)

    # -- events ----------------------------------------------------------------------------
    def event_functions(self, u_of_t):
        events, funcs = [], []
        G, _ = self._geometry()

        def add(event, g, direction):
            g.terminal, g.direction = True, direction
            events.append(event)
            funcs.append(g)

        locked = self._lock_set()
        if len(locked) == 3:  # all at rest: the feasible interval of F_a closes
            add(BREAK_REST_EVENT, lambda t, x: self._solve(t, u_of_t(t))[3], -1)
        for k in ELEMENTS:
            direction = self.modes.elements[k].direction
            if direction is LOCKED:
                if len(locked) == 1:
                    def g_fwd(t, x, k=k):  # F_k -> -C_k: breaks free forwards
                        _, F, C, _ = self._solve(t, u_of_t(t))
                        return C[k] + F[k]

                    def g_bwd(t, x, k=k):  # F_k -> +C_k: breaks free backwards
                        _, F, C, _ = self._solve(t, u_of_t(t))
                        return C[k] - F[k]

                    add(SLIP_EVENTS[k, Direction.FORWARD], g_fwd, -1)
                    add(SLIP_EVENTS[k, Direction.BACKWARD], g_bwd, -1)
            else:  # w_k = G_k . (w_b, w_h) falls to zero
                add(ZERO_EVENTS[k], lambda t, x, gk=G[k]: float(gk @ x[X.w_b:X.w_h + 1]),
                    -direction.sign)
        sign = 1.0 if self.modes.command == 0 else -1.0
        i_cmd = self.IN.command
        add(COMMAND_EVENT, lambda t, x: sign * (u_of_t(t)[i_cmd] - 0.5), 1)
        for tb in self._breakpoints():
            add(Event(EventKind.TIME, time=tb), lambda t, x, tb=tb: t - tb, 1)
        self._events = events
        return funcs

    def on_event(self, t, x, u, index):
        event = self._events[index]
        x = np.array(x, dtype=float)
        modes, elements = self.modes, self.modes.elements
        modes.t_last = float(t)
        if event.kind is EventKind.TIME:
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
        return self._zero_speeds(x)

    def advance(self, t0, x0, h, u_of_t, rtol, atol):
        x = np.array(x0, dtype=float)
        if h <= 0.0:
            return x
        x = self.on_input_change(t0, x, u_of_t(t0))
        return super().advance(t0, x, h, u_of_t, rtol, atol)

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
