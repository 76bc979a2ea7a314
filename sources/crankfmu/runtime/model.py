"""The contract every physics model implements (no FMI here: plain Python, numpy; scipy only on
the scipy path).

A model is a set of ODEs with inputs, outputs, parameters and switchable effects. The same model
object serves the FMU (through `crankfmu.runtime.slave.ModelSlave`) and the monolithic reference
(`crankfmu.monolithic`), so the equations exist once.

Implementers subclass `PhysicsModel` and provide:

Class attributes
    model_name   FMU model name (CamelCase), e.g. "DcServoMotor".
    description  one line.
    seed         the source paper (file in shared/seeds) and equation numbers.
    parameters   tuple of `Variable` (unit, description, start = default value, min/max range).
    effects      tuple of `Effect`; each becomes the Boolean FMU parameter `effect_<name>`.
    inputs       tuple of `Variable`; `start` is the value used when nothing is connected.
    outputs      tuple of `Variable`; `depends_on` lists the inputs with direct feedthrough.

Derived for every subclass from those declarations (`PhysicsModel.__init_subclass__`):
    IN, OUT      the position of each input and output by name, read as `u[self.IN.flange_w]`
                 (a namedtuple of ints: one C-level attribute read, no index kept by hand).

Methods
    check(p)                       raise `ParameterError` for impossible parameter values.
    state_names()                  names of the continuous states *for the enabled effects*:
                                   an effect that is off adds no state (it costs nothing).
    initial_state(u)               state vector at the start time, given the input vector u.
    derivatives(t, x, u)           dx/dt (u: input vector in `inputs` order). Called ~7 times
                                   per step by the runtime's integrator: work on floats (math,
                                   not numpy, for scalars) and return a list or tuple.
    output_values(t, x, u)         output vector in `outputs` order.

Optional (hybrid models)
    event_functions(u_of_t)        list of g(t, x) for event location in the current mode
                                   (attributes `terminal`, `direction` as in solve_ivp; a zero
                                   at the start counts, so a function that is zero where the
                                   last event left the state must exclude that point, e.g.
                                   from `self.restart_state`, the state the step restarts from).
    on_event(t, x, u, index)       apply the discrete change for event `index`; return new x.
    event_slots                    the most event_functions + monitor_functions any mode
                                   returns: the number of event indicators a Model Exchange
                                   FMU declares (runtime/slave3.py; it fails naming the model
                                   when a mode returns more).
    discrete_state() / set_discrete_state(d)   JSON-serialisable modes, saved with FMU state
                                   (with solver_state(): the integrator's step size).
    state_nominal()                typical magnitude per state (absolute tolerance = rtol * it).
    advance(...)                   override to integrate in closed form (set
                                   advance_integrates_derivatives = True when it solves
                                   derivatives() exactly, so the monolithic reference may
                                   compose the model).
    advance_follows_contract       True when an overriding advance() does nothing but what the
                                   hybrid contract below says, so the monolithic reference
                                   composes the model through that contract:
    on_input_change(t, x, u)       discrete update at the start of every advance (inputs that
                                   may have jumped since the last one); returns the new x.
    monitor_functions(u_of_t)      non-terminal events (e.g. force extrema) whose crossings
    observe(t, x, u)               are handed to observe(), as is the state at every step end.

Optional (output derivatives: the companions a master's Taylor coupling reads)
    derivative_outputs             names of outputs whose time derivatives 1 .. MAX_OUTPUT_
                                   DERIVATIVE the FMU offers as outputs <name>_d1, _d2, ...
    derivative_outputs_affine      True (per effect, a property) when those outputs are affine
                                   in the state and the inputs and not in time: their rows are
                                   then exact (runtime/taylor.py); else differenced.
    state_rows(...)                the state's Taylor rows from derivatives() (runtime/
                                   taylor.py); a model with exact rows (a linear one) overrides.

Inputs reach `advance` as a callable u_of_t(t) -> input vector, so a master may hand over an
input polynomial (extrapolation) instead of a held value; from the FMU it is an
`InputPolynomial`, whose `taylor(t)` gives the Taylor rows a closed form needs.

What the base class does with that: `step` (what the FMU calls) runs `advance` under one work
limit; `advance` integrates between events with `integrate`, which uses the runtime's
Dormand-Prince 5(4) (`runtime/dopri.py`, solver = "dopri5") or scipy's solve_ivp with the method
in `integrator` (solver = "scipy": the cross-check; the FMU parameter `scipy_solver`).
"""
from __future__ import annotations

import keyword
import math
from collections import namedtuple
from dataclasses import dataclass
from types import SimpleNamespace
from typing import Callable, Sequence

import numpy as np

from . import dopri, taylor
from .dopri import Integration
from .taylor import InputPolynomial

InputFunction = Callable[[float], Sequence[float]]
# The state and input vectors of the contract: lists of floats on the FMU's own path (cheaper
# per step than numpy arrays), numpy arrays on scipy's
Vector = Sequence[float] | np.ndarray
# An FMU parameter of every crankfmu FMU that is not physics: integrate with scipy's solve_ivp
SCIPY_SOLVER = "scipy_solver"
# The runtime's Dormand-Prince 5(4) holds its local error to TOLERANCE_FACTOR x the requested
# tolerance. Measured on the shipped scenes against the same scenes at tolerance 1e-12: at the
# requested tolerance it is 3-20x less accurate than scipy's 8th-order DOP853 (the scipy path);
# at a tenth of it, as accurate or better (hammer, 0.5 s at 1e-8: E_radiated 2.7e-7 vs 9.4e-8,
# w_crank 1.5e-10 vs 7.0e-10; servo press: w_crank 4.0e-8 vs 3.0e-8) for 10-30 % more work.
TOLERANCE_FACTOR = 0.1
# The companions of crankfmu FMUs (runtime/slave_core.py): input polynomials over a step of
# degree up to MAX_INPUT_DEGREE (inputs X_d1 .. X_d5), and the derivatives 1 .. MAX_OUTPUT_
# DERIVATIVE of each derivative output (outputs Y_d1 .. Y_d4: a Taylor coupling of order 4; a
# Gauss-Seidel step through the newest value raises the degree by one)
MAX_INPUT_DEGREE = 5
MAX_OUTPUT_DERIVATIVE = 4


class CrankfmuError(Exception):
    """Base of the errors crankfmu reports to a user (exit status 2 from the command line).
    Defined here, in the bottom layer, so the physics' own errors derive from it too;
    `crankfmu.errors` re-exports it with the limits and the other user-facing errors."""

    exit_status = 2


class ParameterError(CrankfmuError, ValueError):
    """A parameter value the physics cannot accept; names the parameter and what is allowed."""

    def __init__(self, model: str, name: str, value, allowed: str):
        self.model, self.name, self.value, self.allowed = model, name, value, allowed
        super().__init__(f"{model}: parameter {name} = {value!r} is not allowed: {allowed}")


class IntegrationError(RuntimeError):
    """The internal solver failed on a step; carries time and reason."""


@dataclass(frozen=True)
class Variable:
    """A named real quantity with its SI unit (FMI unit string, e.g. "N.m", "kg.m2")."""

    name: str
    unit: str
    description: str
    start: float = 0.0
    min: float | None = None
    max: float | None = None
    depends_on: tuple[str, ...] = ()  # outputs only: inputs with direct feedthrough


@dataclass(frozen=True)
class Effect:
    """An optional piece of physics a scene can switch on (`effect_<name>` in the FMU)."""

    name: str
    description: str
    default: bool = False


def name_indices(owner: str, kind: str, names: Sequence[str]):
    """The position of each name, as attributes of a namedtuple of ints (so a model reads
    `u[self.IN.shaft_w]`, not `u[2]`: one C-level attribute read). Raises TypeError naming the
    class and the name when it cannot be an attribute (not an identifier, a leading underscore,
    a keyword) or is declared twice."""
    names = list(names)
    for name in names:
        if not name.isidentifier() or keyword.iskeyword(name) or name.startswith("_") or \
                names.count(name) > 1:
            raise TypeError(f"{owner}: {kind} {name!r} must be a unique Python identifier "
                            f"without a leading underscore")
    return namedtuple(f"{owner}{kind.capitalize()}s", names)(*range(len(names)))


def variable_indices(owner: str, kind: str, variables: Sequence[Variable]):
    """`name_indices` of declared variables (`kind`: "input" or "output")."""
    return name_indices(owner, kind, [v.name for v in variables])


class PhysicsModel:
    """Base class; see the module docstring for the contract."""

    model_name: str = ""
    description: str = ""
    seed: str = ""
    parameters: tuple[Variable, ...] = ()
    effects: tuple[Effect, ...] = ()
    inputs: tuple[Variable, ...] = ()
    outputs: tuple[Variable, ...] = ()
    solver: str = "dopri5"  # "dopri5": the runtime's own integrator; "scipy": solve_ivp
    integrator: str = "DOP853"  # solve_ivp's method with solver = "scipy" (model's stiffness)
    _h_next: float | None = None  # dopri5's step size, carried from one advance to the next
    restart_state: Sequence[float] = ()  # the state advance (re)starts from, for event_functions
    restart_time: float = 0.0  # s, when it (re)starts (set by hosts that need it: the reference)
    _work_left: int | None = None  # right-hand-side calls left in this step (see `step`)
    max_events_per_step: int = 1000
    # Work limit per communication step (as CVODE's mxstep): a diverging coupling can drive a
    # state so far that integrating one step would take hours; failing fast lets the master
    # report where and when it happened.
    max_derivative_calls_per_step: int = 200_000
    # advance() overridden only to run the hybrid contract (on_input_change, event_functions,
    # monitor_functions/observe): see the module docstring; the monolithic reference relies on it
    advance_follows_contract: bool = False
    event_slots: int = 0  # see the module docstring: Model Exchange's event indicators
    # output derivatives (see the module docstring and runtime/taylor.py)
    derivative_outputs: tuple[str, ...] = ()
    derivative_outputs_affine: bool = False

    IN = variable_indices("PhysicsModel", "input", ())
    OUT = variable_indices("PhysicsModel", "output", ())
    DERIVATIVE_OUT: tuple[int, ...] = ()  # positions of derivative_outputs among the outputs

    def __init_subclass__(cls, **kwargs):
        """Derive the name -> position tables IN and OUT from the class's declarations."""
        super().__init_subclass__(**kwargs)
        cls.IN = variable_indices(cls.__name__, "input", cls.inputs)
        cls.OUT = variable_indices(cls.__name__, "output", cls.outputs)
        unknown = [n for n in cls.derivative_outputs if n not in cls.OUT._fields]
        if unknown:
            raise TypeError(f"{cls.__name__}: derivative_outputs {unknown} are not outputs")
        cls.DERIVATIVE_OUT = tuple(cls.OUT._fields.index(n) for n in cls.derivative_outputs)

    def __init__(self, parameters: dict | None = None, effects: Sequence[str] | dict | None = None):
        values = {v.name: float(v.start) for v in self.parameters}
        unknown = set(parameters or {}) - set(values)
        if unknown:
            raise KeyError(f"{self.model_name}: unknown parameter(s) {sorted(unknown)}; "
                           f"known: {sorted(values)}")
        values.update({k: float(v) for k, v in (parameters or {}).items()})
        self.p = SimpleNamespace(**values)
        self.enabled = self._effect_set(effects)
        self._check_ranges()
        self.check(self.p)

    # -- construction helpers -------------------------------------------------------------
    def _effect_set(self, effects) -> frozenset[str]:
        known = {e.name for e in self.effects}
        if effects is None:
            chosen = {e.name for e in self.effects if e.default}
        elif isinstance(effects, dict):
            chosen = {k for k, on in effects.items() if on}
        else:
            chosen = set(effects)
        unknown = (set(effects) if effects is not None else set()) - known
        if unknown:
            raise KeyError(f"{self.model_name}: unknown effect(s) {sorted(unknown)}; "
                           f"known: {sorted(known)}")
        return frozenset(chosen)

    def _check_ranges(self) -> None:
        for v in self.parameters:
            x = getattr(self.p, v.name)
            if not math.isfinite(x):
                raise ParameterError(self.model_name, v.name, x, "a finite number")
            if v.min is not None and x < v.min:
                raise ParameterError(self.model_name, v.name, x, f">= {v.min} {v.unit}")
            if v.max is not None and x > v.max:
                raise ParameterError(self.model_name, v.name, x, f"<= {v.max} {v.unit}")

    def on(self, effect: str) -> bool:
        return effect in self.enabled

    # -- contract -------------------------------------------------------------------------
    def check(self, p: SimpleNamespace) -> None:
        """Raise ParameterError for combinations the ranges cannot express (e.g. l <= r)."""

    def state_names(self) -> tuple[str, ...]:
        raise NotImplementedError

    def initial_state(self, u: Vector) -> Vector:
        raise NotImplementedError

    def derivatives(self, t: float, x: Vector, u: Vector) -> Vector:
        raise NotImplementedError

    def output_values(self, t: float, x: Vector, u: Vector) -> Vector:
        raise NotImplementedError

    def state_nominal(self) -> Vector:
        """Typical magnitude of each state; the absolute tolerance is rtol * nominal."""
        return np.ones(len(self.state_names()))

    def jacobian(self, t: float, x: Vector, u: Vector):
        """d(derivatives)/dx for implicit solvers; None lets scipy use finite differences."""
        return None

    def event_functions(self, u_of_t: InputFunction) -> list:
        return []

    def on_event(self, t: float, x: Vector, u: Vector, index: int) -> Vector:
        return x

    def discrete_state(self) -> dict:
        return {}

    def set_discrete_state(self, state: dict) -> None:
        pass

    def solver_state(self) -> dict:
        """What the integrator carries between steps (its step size): saved with the FMU state
        so that a rolled-back step repeats bit for bit."""
        return {"h_next": self._h_next}

    def set_solver_state(self, state: dict) -> None:
        self._h_next = state.get("h_next")

    # -- output derivatives (runtime/taylor.py) ---------------------------------------------
    def state_rows(self, t: float, x, u_rows: list, order: int, delta: float,
                   known: Sequence = ()) -> list:
        """[x, x', ..., x^(order)] at t, the inputs following the Taylor rows u_rows:
        differences of derivatives() along the polynomials. `known`: leading rows already
        computed for this x with the same leading input rows (row k + 1 needs input rows
        0 .. k), reused."""
        return taylor.state_rows(self.derivatives, t, x, u_rows, order, delta, known)

    def derivative_output_rows(self, t: float, x_rows: list, u_rows: list, order: int,
                               delta: float) -> list:
        """[y', ..., y^(order)] at t of the outputs in derivative_outputs (in that order), from
        the state rows (at least order + 1) and the input rows."""
        if not self.derivative_outputs_affine:
            return taylor.output_rows(self.output_values, t, x_rows, u_rows, order, delta,
                                      self.DERIVATIVE_OUT)
        affine = self.__dict__.get("_affine_outputs")
        if affine is None:  # read off once: C and D are fixed by parameters and effects
            affine = self._affine_outputs = taylor.AffineOutputs(
                self.output_values, t, len(x_rows[0]), len(u_rows[0]), self.DERIVATIVE_OUT)
        return affine.rows(x_rows, u_rows, order)

    # -- conveniences built on the contract ----------------------------------------------
    def default_inputs(self) -> np.ndarray:
        return np.array([v.start for v in self.inputs], dtype=float)

    def input_index(self, name: str) -> int:
        return [v.name for v in self.inputs].index(name)

    def output_index(self, name: str) -> int:
        return [v.name for v in self.outputs].index(name)

    def output_vector(self, values: dict) -> list:
        """The outputs in declaration order from a dict by name, for a model that builds many
        outputs (a long positional list is as unclear as u[2]). KeyError naming the model and
        the outputs it misses or does not declare."""
        names = self.OUT._fields
        if len(values) == len(names):
            try:
                return [values[name] for name in names]
            except KeyError:
                pass
        missing, extra = sorted(set(names) - set(values)), sorted(set(values) - set(names))
        raise KeyError(f"{self.model_name}: output values missing {missing}, undeclared {extra}")

    def step(self, t0: float, x0, h: float, u_of_t: InputFunction, rtol: float, atol) -> list:
        """`advance` under one work limit for the whole step (what the FMU calls): at most
        max_derivative_calls_per_step right-hand-side calls over all its event restarts, so a
        step that cannot finish (a diverging coupling, a parameter that makes the model
        absurdly stiff) fails with a reason in bounded time. A direct `advance` has the limit
        per integration between events."""
        self._work_left = self.max_derivative_calls_per_step
        try:
            return self.advance(t0, x0, h, u_of_t, rtol, atol)
        finally:
            self._work_left = None

    def advance(self, t0: float, x0, h: float, u_of_t: InputFunction,
                rtol: float, atol) -> list:
        """Integrate the states from t0 to t0 + h, locating events on the way."""
        if len(x0) == 0 or h <= 0.0:
            return list(x0)
        self._check_inputs(t0, u_of_t)
        t, x, t_end = t0, x0, t0 + h
        for _ in range(self.max_events_per_step):
            self.restart_state = x
            sol = self.integrate(u_of_t, t, x, t_end, rtol, atol, self.event_functions(u_of_t))
            if sol.status == 0:
                return sol.x
            t, index = sol.t, sol.event
            assert index is not None  # status 1: stopped at this terminal event
            x = self.on_event(t, sol.x, u_of_t(t), index)
            if t >= t_end:
                return list(x)
        raise IntegrationError(f"{self.model_name}: more than {self.max_events_per_step} "
                               f"events in one step at t = {t:.9g} s")

    # -- the integrators behind advance -------------------------------------------------------
    def _check_inputs(self, t0: float, u_of_t: InputFunction) -> None:
        if not all(map(math.isfinite, u_of_t(t0))):
            raise IntegrationError(f"{self.model_name}: input not finite at t = {t0:.9g} s")

    def integrate(self, u_of_t: InputFunction, t: float, x, t_end: float, rtol: float, atol,
                  events=(), derivatives=None, dense: list | None = None,
                  max_step: float = math.inf, interpolant: list | None = None) -> Integration:
        """One integration from t to t_end (or the first terminal event) with the model's
        solver: the runtime's Dormand-Prince (default), or scipy's solve_ivp with the method in
        `integrator` (solver = "scipy": the cross-check, and the monolithic reference).
        derivatives: a right-hand side (t, x, u) other than the model's `derivatives` (a model
        that integrates part of its states in closed form); dense, max_step: the accepted
        steps' dense output and the longest step (runtime solver only, see dopri.integrate);
        interpolant: a list to which the scipy path appends solve_ivp's dense output of this
        integration (a callable of t; the monolithic reference samples its record times on
        it)."""
        derivatives = derivatives or self.derivatives
        if getattr(u_of_t, "moving", True):
            def rhs(s, y):
                return derivatives(s, y, u_of_t(s))
        else:  # held inputs: one list for the whole step
            u = u_of_t(t)

            def rhs(s, y):
                return derivatives(s, y, u)
        limit = self.max_derivative_calls_per_step if self._work_left is None else \
            self._work_left
        try:
            if self.solver == "scipy":
                sol = self._integrate_scipy(rhs, u_of_t, t, x, t_end, rtol, atol, events, limit,
                                            interpolant)
            else:
                sol = dopri.integrate(rhs, t, x, t_end, TOLERANCE_FACTOR * rtol,
                                      [TOLERANCE_FACTOR * a for a in dopri.per_state(atol,
                                                                                   len(x))],
                                      self._h_next, events, limit, dense, max_step)
                self._h_next = sol.h_next
        except dopri.IntegrationFailure as err:
            raise IntegrationError(f"{self.model_name}: {err}") from None
        if self._work_left is not None:
            self._work_left -= sol.calls
        return sol

    def _integrate_scipy(self, rhs, u_of_t, t, x, t_end, rtol, atol, events,
                         limit: int, interpolant: list | None = None) -> Integration:
        calls = [0]

        def counted(s, y):
            calls[0] += 1
            if calls[0] > limit:
                raise IntegrationError(
                    f"{self.model_name}: more than {limit} "
                    f"derivative evaluations in the step from t = {t:.9g} s (states "
                    f"{dict(zip(self.state_names(), np.round(y, 6)))}): diverging or too stiff")
            return rhs(s, y)
        from scipy.integrate import solve_ivp  # ~0.3 s to import: only on this path
        options = {"jac": self._jac_for(u_of_t)} if self._has_jacobian() else {}
        sol = solve_ivp(counted, (t, t_end), np.asarray(x, dtype=float), method=self.integrator,
                        rtol=rtol, atol=np.asarray(atol, dtype=float), events=list(events) or None,
                        dense_output=interpolant is not None, **options)
        if sol.status < 0:
            raise IntegrationError(f"{self.model_name}: {sol.message} at t = {t:.9g} s")
        if interpolant is not None:
            interpolant.append(sol.sol)
        crossings = [(i, te, list(ye)) for i in range(len(events))
                     for te, ye in zip(sol.t_events[i], sol.y_events[i])
                     if not getattr(events[i], "terminal", False)]
        if sol.status == 0:
            return Integration(0, t_end, list(sol.y[:, -1]), 0.0, None, crossings, calls[0])
        index = next(i for i, te in enumerate(sol.t_events)
                     if len(te) and getattr(events[i], "terminal", False))
        te = float(sol.t_events[index][-1])
        crossings = [c for c in crossings if c[1] <= te]
        return Integration(1, te, list(sol.y_events[index][-1]), 0.0, index, crossings,
                           calls[0])

    def _has_jacobian(self) -> bool:
        """True when the solver is implicit and the subclass gives an analytic Jacobian."""
        return self.integrator in ("Radau", "BDF", "LSODA") and \
            type(self).jacobian is not PhysicsModel.jacobian

    def _jac_for(self, u_of_t: InputFunction):
        return lambda s, y: self.jacobian(s, y, u_of_t(s))




def held(u) -> InputFunction:
    """Zero-order hold: the input vector stays at u over the step."""
    return InputPolynomial(0.0, [float(v) for v in u])


def input_rows(u_of_t: InputFunction, t0: float, h: float) -> list[list] | None:
    """The Taylor rows [u, u', u'', ...] at t0 (at least three) if u_of_t is a polynomial on
    [t0, t0 + h], else None. Exact for an `InputPolynomial`; any other function is fitted as a
    quadratic at three points and checked at a fourth, to round-off."""
    if isinstance(u_of_t, InputPolynomial):
        return u_of_t.taylor(t0)
    s = np.array([0.0, 0.5 * h, h])
    values = np.array([u_of_t(t0 + si) for si in s], dtype=float)
    a0 = values[0]
    a2 = 4.0 * (values[2] - 2.0 * values[1] + values[0]) / h ** 2  # second derivative
    a1 = (values[2] - values[0]) / h - 0.5 * a2 * h
    check = np.asarray(u_of_t(t0 + 0.25 * h), dtype=float)
    guess = a0 + a1 * 0.25 * h + 0.5 * a2 * (0.25 * h) ** 2
    scale = np.max(np.abs(values), axis=0) + 1e-300
    if np.any(np.abs(check - guess) > 1e-9 * scale):
        return None
    return [list(a0), list(a1), list(a2)]
