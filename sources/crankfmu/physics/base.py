"""The contract every physics model implements (no FMI here: numpy and scipy only).

A model is a set of ODEs with inputs, outputs, parameters and switchable effects. The same model
object serves the FMU (through `crankfmu.slaves.base.ModelSlave`) and the monolithic reference
(`crankfmu.studies.reference`), so the equations exist once.

Implementers subclass `PhysicsModel` and provide:

Class attributes
    model_name   FMU model name (CamelCase), e.g. "DcServoMotor".
    description  one line.
    seed         the source paper (file in shared/seeds) and equation numbers.
    parameters   tuple of `Variable` (unit, description, start = default value, min/max range).
    effects      tuple of `Effect`; each becomes the Boolean FMU parameter `effect_<name>`.
    inputs       tuple of `Variable`; `start` is the value used when nothing is connected.
    outputs      tuple of `Variable`; `depends_on` lists the inputs with direct feedthrough.

Methods
    check(p)                       raise `ParameterError` for impossible parameter values.
    state_names()                  names of the continuous states *for the enabled effects*:
                                   an effect that is off adds no state (it costs nothing).
    initial_state(u)               state vector at the start time, given the input vector u.
    derivatives(t, x, u)           dx/dt (u: input vector in `inputs` order).
    output_values(t, x, u)         output vector in `outputs` order.

Optional (hybrid models)
    event_functions(u_of_t)        list of g(t, x) for scipy's event location in the current
                                   mode (attributes `terminal`, `direction` as in solve_ivp).
    on_event(t, x, u, index)       apply the discrete change for event `index`; return new x.
    discrete_state() / set_discrete_state(d)   JSON-serialisable modes, saved with FMU state.
    state_nominal()                typical magnitude per state (absolute tolerance = rtol * it).
    advance(...)                   override to integrate in closed form.

Inputs reach `advance` as a callable u_of_t(t) -> input vector, so a master may hand over an
input polynomial (extrapolation) instead of a held value.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from types import SimpleNamespace
from typing import Callable, Sequence

import numpy as np
from scipy.integrate import solve_ivp

InputFunction = Callable[[float], np.ndarray]


class ParameterError(ValueError):
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


class PhysicsModel:
    """Base class; see the module docstring for the contract."""

    model_name: str = ""
    description: str = ""
    seed: str = ""
    parameters: tuple[Variable, ...] = ()
    effects: tuple[Effect, ...] = ()
    inputs: tuple[Variable, ...] = ()
    outputs: tuple[Variable, ...] = ()
    integrator: str = "DOP853"  # scipy solve_ivp method suited to the model's stiffness
    max_events_per_step: int = 1000
    # Work limit per communication step (as CVODE's mxstep): a diverging coupling can drive a
    # state so far that integrating one step would take hours; failing fast lets the master
    # report where and when it happened.
    max_derivative_calls_per_step: int = 200_000

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

    def initial_state(self, u: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def derivatives(self, t: float, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def output_values(self, t: float, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def state_nominal(self) -> np.ndarray:
        """Typical magnitude of each state; the absolute tolerance is rtol * nominal."""
        return np.ones(len(self.state_names()))

    def jacobian(self, t: float, x: np.ndarray, u: np.ndarray):
        """d(derivatives)/dx for implicit solvers; None lets scipy use finite differences."""
        return None

    def event_functions(self, u_of_t: InputFunction) -> list:
        return []

    def on_event(self, t: float, x: np.ndarray, u: np.ndarray, index: int) -> np.ndarray:
        return x

    def discrete_state(self) -> dict:
        return {}

    def set_discrete_state(self, state: dict) -> None:
        pass

    # -- conveniences built on the contract ----------------------------------------------
    def default_inputs(self) -> np.ndarray:
        return np.array([v.start for v in self.inputs], dtype=float)

    def input_index(self, name: str) -> int:
        return [v.name for v in self.inputs].index(name)

    def output_index(self, name: str) -> int:
        return [v.name for v in self.outputs].index(name)

    def advance(self, t0: float, x0: np.ndarray, h: float, u_of_t: InputFunction,
                rtol: float, atol: float) -> np.ndarray:
        """Integrate the states from t0 to t0 + h, locating events on the way."""
        if x0.size == 0 or h <= 0.0:
            return x0
        if not np.all(np.isfinite(u_of_t(t0))):
            raise IntegrationError(f"{self.model_name}: input not finite at t = {t0:.9g} s")
        t, x, t_end = t0, np.asarray(x0, dtype=float), t0 + h
        calls = [0]

        def rhs(s, y):
            calls[0] += 1
            if calls[0] > self.max_derivative_calls_per_step:
                raise IntegrationError(
                    f"{self.model_name}: more than {self.max_derivative_calls_per_step} "
                    f"derivative evaluations in the step from t = {t0:.9g} s (states "
                    f"{dict(zip(self.state_names(), np.round(y, 6)))}): diverging or too stiff")
            return self.derivatives(s, y, u_of_t(s))
        for _ in range(self.max_events_per_step):
            events = self.event_functions(u_of_t) or None
            options = {"jac": self._jac_for(u_of_t)} if self._has_jacobian() else {}
            sol = solve_ivp(rhs, (t, t_end), x,
                            method=self.integrator, rtol=rtol, atol=atol, events=events,
                            **options)
            if sol.status < 0:
                raise IntegrationError(f"{self.model_name}: {sol.message} at t = {t:.9g} s")
            if sol.status == 0:
                return sol.y[:, -1]
            index = next(i for i, te in enumerate(sol.t_events) if len(te))
            t, x = float(sol.t_events[index][0]), sol.y_events[index][0]
            x = self.on_event(t, x, u_of_t(t), index)
            if t >= t_end:
                return x
        raise IntegrationError(f"{self.model_name}: more than {self.max_events_per_step} "
                               f"events in one step at t = {t:.9g} s")

    def _has_jacobian(self) -> bool:
        """True when the solver is implicit and the subclass gives an analytic Jacobian."""
        return self.integrator in ("Radau", "BDF", "LSODA") and \
            type(self).jacobian is not PhysicsModel.jacobian

    def _jac_for(self, u_of_t: InputFunction):
        return lambda s, y: self.jacobian(s, y, u_of_t(s))


def held(u: np.ndarray) -> InputFunction:
    """Zero-order hold: the input vector stays at u over the step."""
    frozen = np.array(u, dtype=float)
    return lambda t: frozen
