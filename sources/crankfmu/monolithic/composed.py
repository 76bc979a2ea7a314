"""A scene's physics models composed into ONE ODE (the monolithic reference; no FMI here).

`ComposedModel` is a `PhysicsModel` whose state is the concatenation of the components' states
and whose right-hand side evaluates, at every call, the components' outputs in dependency order,
routes them to the connected inputs, and calls each component's `derivatives`. So the coupling
is exact (no communication step) and the base class's `advance` (solve_ivp with event location)
integrates it.

Inputs of a component, by precedence: a connection (the source's output, evaluated at the same
state), an external [inputs] signal (a function of time: constant or table), else the input's
start value (what the FMU holds when nothing is set).

Outputs may depend on inputs (`Variable.depends_on`, direct feedthrough). The evaluation plan
is found once, per output: an output is ready when every input it depends on is connected to a
ready output or not connected. A component is evaluated as often as the plan needs (e.g. the
servo press: press outputs first, then the motor's torque, which depends on the press speed).
If no order exists the scene has an algebraic loop, reported with the outputs involved.

Events: each component's `event_functions` are wrapped to see its part of the state, and its
inputs as they follow from the whole state at the event time; `on_event` is routed back.
Discrete states are kept per component.

Hybrid models compose through their contract (`advance_follows_contract`, runtime/model.py):
their terminal events (locks, break-frees, contact start and end, forging-window edges) are
located by the solver with the inputs following the whole state (no hold); their non-terminal
`monitor_functions` (force extrema) are located too and handed to `observe`, as the state at
every restart and record time is; `on_input_change` runs at every restart (the time points of
[inputs] tables, and record times: every one with Radau, every hundredth with DOP853, see
monolithic/solve.py), where the FMU runs it at every communication point: in the composed ODE
the inputs are continuous between those restarts, so it only acts where an input table jumps.
A step-interpolated [inputs] table is held at its value at the restart over the whole
integration, so its jump is seen at the restart, never a rounding error before it.

Rigid couplings (a mechanism with effect `driven_crank`: no crank states, its shaft_tau and
shaft_J are feedthrough of shaft_phi/shaft_w, integrated by the driver) need nothing special:
the plan evaluates the driver's shaft outputs, then the mechanism's load, then the driver's
derivatives, so the driver and the mechanism are one body in the composed ODE.

Models that cannot be composed: those that override `advance` with more than an integrator of
their own derivatives without declaring advance_follows_contract (the linear models' exact
matrix exponential is fine, see EXACT_ADVANCE), and those with `on_input_change` that do not
declare it either (their discrete update would be skipped).
"""
from __future__ import annotations

from ..errors import CrankfmuError

from dataclasses import dataclass

import numpy as np

from ..masters.model_exchange import integration_method
from ..runtime.model import PhysicsModel
from ..models.catalog import FMU_MODELS, make_physics, physics_class
from ..system.scene import Scene, SceneError


# Classes whose advance() only integrates their own derivatives() more cheaply (the linear
# models' matrix exponential): composing them through derivatives() loses nothing. A physics
# class may also say so with the attribute advance_integrates_derivatives = True.
EXACT_ADVANCE = {"rotor.LinearModel"}


class CompositionError(CrankfmuError, ValueError):
    """The scene cannot be composed into one ODE; names the component (or loop) and why."""


@dataclass
class Part:
    """One component inside the composed model."""

    name: str
    model: PhysicsModel
    states: slice
    # per input: ("link", source part index, source output index) | ("external", signal) |
    # ("start", value)
    sources: list


def make_model(scene: Scene, name: str) -> PhysicsModel:
    """The physics object of component `name` with the scene's parameters and effects."""
    comp = scene.components[name]
    key = f"[components.{name}]"
    if comp.fmu not in FMU_MODELS:
        raise CompositionError(f"{scene.path}: {key}.fmu = {comp.fmu!r}: the reference composes "
                               f"catalog physics models only ({', '.join(FMU_MODELS)}), not FMU "
                               "files")
    _check_composable(physics_class(comp.fmu), name)
    try:
        return make_physics(comp.fmu, comp.parameters, comp.effects)
    except KeyError as err:
        raise SceneError(scene.path, f"{key}.parameters/effects", str(err.args[0])) from None
    except ValueError as err:  # ParameterError
        raise SceneError(scene.path, f"{key}.parameters", str(err)) from None


def _advance_owner(cls) -> type:
    return next(k for k in cls.__mro__ if "advance" in k.__dict__)


def _check_composable(cls, name: str) -> None:
    owner = _advance_owner(cls)
    exact = getattr(owner, "advance_integrates_derivatives", False) or \
        f"{owner.__module__.rsplit('.', 1)[-1]}.{owner.__qualname__}" in EXACT_ADVANCE
    if getattr(cls, "advance_follows_contract", False):
        return
    if owner is not PhysicsModel and not exact:
        raise CompositionError(
            f"component {name} ({cls.model_name}) cannot be composed into a monolithic "
            f"reference: it overrides advance() (it integrates itself, e.g. with monitors or "
            f"in closed form), so its equations are not fully given by derivatives/events")
    if hasattr(cls, "on_input_change"):
        raise CompositionError(
            f"component {name} ({cls.model_name}) cannot be composed into a monolithic "
            f"reference: it has on_input_change(), a discrete update at communication points "
            f"that has no monolithic equivalent")


class ComposedModel(PhysicsModel):
    """The components of a scene as one ODE; see the module docstring."""

    model_name = "Composed"
    description = "monolithic composition of a scene's physics models"
    max_derivative_calls_per_step = 10_000_000
    max_events_per_step = 100_000  # per restart (up to 100 record intervals): contacts, locks

    def __init__(self, scene: Scene):
        super().__init__()
        self.scene = scene
        order = scene.master.order or list(scene.components)
        self.order = order + [c for c in scene.components if c not in order]
        models = {n: make_model(scene, n) for n in self.order}
        self.parts = self._parts(models)
        self.index = {p.name: k for k, p in enumerate(self.parts)}
        self.needed = self._needed_outputs()
        self.plan = self._plan(self.needed)
        self.integrator = "DOP853"  # solve_reference picks Radau when choose_integrator says so
        self.n_rhs = 0
        self.n_events = 0
        self._hold_time = None  # restart time at which step-interpolated inputs are read

    # -- construction -----------------------------------------------------------------------
    def _parts(self, models: dict) -> list[Part]:
        scene, parts, offset = self.scene, [], 0
        links = {c.target: c.source for c in scene.connections}
        positions = {n: k for k, n in enumerate(models)}
        for name, model in models.items():
            n = len(model.state_names())
            # ("link", part, output), ("external", signal) or ("start", value) per input
            sources: list[tuple] = []
            for var in model.inputs:
                ref = f"{name}.{var.name}"
                if ref in links:
                    src_comp, src_var = links[ref].split(".", 1)
                    k = _output_index(scene, models[src_comp], src_comp, src_var)
                    unit = models[src_comp].outputs[k].unit
                    if (unit or "1") != (var.unit or "1"):
                        raise SceneError(scene.path, f"[[connections]] to = \"{ref}\"",
                                         f"unit mismatch: {links[ref]} is in {unit or '1'}, "
                                         f"{ref} in {var.unit or '1'}")
                    sources.append(("link", positions[src_comp], k))
                elif ref in scene.inputs:
                    sources.append(("external", scene.inputs[ref]))
                else:
                    sources.append(("start", float(var.start)))
            parts.append(Part(name, model, slice(offset, offset + n), sources))
            offset += n
        self._check_inputs_exist(models)
        self.n_states = offset
        return parts

    def _check_inputs_exist(self, models: dict) -> None:
        for ref in [c.target for c in self.scene.connections] + list(self.scene.inputs):
            comp, var = ref.split(".", 1)
            names = [v.name for v in models[comp].inputs]
            if var not in names:
                raise SceneError(self.scene.path, ref, f"{comp} ({models[comp].model_name}) has "
                                                       f"no input {var!r}; inputs: {', '.join(names)}")

    def _needed_outputs(self) -> list[set[int]]:
        """Per part, the output indices some connected input reads."""
        needed: list[set[int]] = [set() for _ in self.parts]
        for part in self.parts:
            for src in part.sources:
                if src[0] == "link":
                    needed[src[1]].add(src[2])
        return needed

    def _plan(self, wanted: list[set[int]]) -> list[tuple[int, list[int]]]:
        """Evaluation sequence [(part, outputs taken)] such that every output is evaluated after
        the outputs its feedthrough inputs come from."""
        ready: list[set[int]] = [set() for _ in self.parts]
        plan = []
        while any(wanted[k] - ready[k] for k in range(len(self.parts))):
            progress = False
            for k, part in enumerate(self.parts):
                take = [o for o in sorted(wanted[k] - ready[k])
                        if all(self._input_ready(part, i, ready)
                               for i in self._feedthrough(part, o))]
                if take:
                    plan.append((k, take))
                    ready[k].update(take)
                    progress = True
            if not progress:
                raise CompositionError(self._loop_message(wanted, ready))
        return plan

    @staticmethod
    def _feedthrough(part: Part, out: int) -> list[int]:
        names = [v.name for v in part.model.inputs]
        return [names.index(d) for d in part.model.outputs[out].depends_on]

    def _input_ready(self, part: Part, i: int, ready) -> bool:
        src = part.sources[i]
        return src[0] != "link" or src[2] in ready[src[1]]

    def _loop_message(self, wanted, ready) -> str:
        stuck = [f"{p.name}.{p.model.outputs[o].name}" for k, p in enumerate(self.parts)
                 for o in sorted(wanted[k] - ready[k])]
        return (f"{self.scene.path}: algebraic loop: the outputs {', '.join(stuck)} depend on "
                f"inputs (direct feedthrough) that are connected, in a cycle, to each other; a "
                f"monolithic reference would need an algebraic solver")

    # -- evaluation ---------------------------------------------------------------------------
    def split(self, x: np.ndarray) -> list[np.ndarray]:
        return [x[p.states] for p in self.parts]

    def inputs_at(self, t: float, x: np.ndarray) -> list[np.ndarray]:
        """The input vector of every part at time t and composed state x."""
        xs = self.split(x)
        outs: list = [None] * len(self.parts)
        for k, _ in self.plan:  # each part's outputs from the inputs its sources have so far
            part = self.parts[k]
            outs[k] = part.model.output_values(t, xs[k], self._fill(part, t, outs))
        return [self._fill(p, t, outs) for p in self.parts]

    def _held_time(self, signal, t: float) -> float:
        """A step table is read at the restart time while an integration runs (see the module
        docstring), any other signal at t."""
        if self._hold_time is not None and signal.interpolation == "step":
            return self._hold_time
        return t

    def _fill(self, part: Part, t: float, outs) -> np.ndarray:
        u = np.empty(len(part.sources))
        for i, src in enumerate(part.sources):
            if src[0] == "link":
                y = outs[src[1]]
                u[i] = y[src[2]] if y is not None else np.nan
            elif src[0] == "external":
                u[i] = src[1].value_at(self._held_time(src[1], t))
            else:
                u[i] = src[1]
        return u

    def outputs_at(self, t: float, x: np.ndarray):
        """(inputs, outputs) of every part at (t, x), all outputs evaluated."""
        us = self.inputs_at(t, x)
        return us, [p.model.output_values(t, xp, u) for p, xp, u in zip(self.parts,
                                                                         self.split(x), us)]

    def choose_integrator(self, t: float, x: np.ndarray) -> str:
        """Radau or DOP853 by the composed Jacobian's fastest rate at (t, x): the rule the
        model-exchange master applies to the FMUs' ODE (masters.model_exchange)."""
        return integration_method(self.derivatives, t, x)

    # -- PhysicsModel contract ------------------------------------------------------------------
    def state_names(self):
        return tuple(f"{p.name}.{s}" for p in self.parts for s in p.model.state_names())

    def state_nominal(self):
        return np.concatenate([p.model.state_nominal() for p in self.parts] or [np.zeros(0)])

    def initial_state(self, u=None, t0: float | None = None) -> np.ndarray:
        """As the master's initialize: every component takes its initial state from its inputs,
        passed along in sweeps (one per component + 1) until they settle."""
        t0 = self.scene.start_time if t0 is None else t0
        outs: list = [None] * len(self.parts)
        xs: list = [None] * len(self.parts)
        for _ in range(len(self.parts) + 1):
            for k, part in enumerate(self.parts):
                u_k = np.nan_to_num(self._fill(part, t0, outs), nan=0.0)
                u_k = np.where([s[0] == "link" and outs[s[1]] is None for s in part.sources],
                               part.model.default_inputs(), u_k)
                xs[k] = part.model.initial_state(u_k)
                outs[k] = part.model.output_values(t0, xs[k], u_k)
        return np.concatenate([np.asarray(x, dtype=float) for x in xs] or [np.zeros(0)])

    def derivatives(self, t, x, u=None):
        self.n_rhs += 1
        us = self.inputs_at(t, x)
        return np.concatenate([p.model.derivatives(t, x[p.states], u_k)
                               for p, u_k in zip(self.parts, us)])

    def output_values(self, t, x, u=None):
        return np.concatenate(self.outputs_at(t, x)[1])

    def event_functions(self, u_of_t):
        """The components' events, each seeing its own states and its inputs at the event."""
        current = {"x": np.asarray(self.restart_state, dtype=float)}
        events, self._event_owner = [], []
        for k, part in enumerate(self.parts):
            def u_k(t, k=k):
                return self.inputs_at(t, current["x"])[k]
            part.model.restart_state = list(self.restart_state)[part.states]
            part.model.restart_time = self.restart_time  # a driven mechanism's events need it
            for j, g in enumerate(part.model.event_functions(u_k)):
                events.append(self._wrap_event(g, part.states, current))
                self._event_owner.append((k, j))
        return events

    @staticmethod
    def _wrap_event(g, states: slice, current: dict):
        def wrapped(t, x):
            current["x"] = x
            return g(t, x[states])
        # scipy's convention, attributes on the function (mypy cannot type them)
        wrapped.terminal = getattr(g, "terminal", False)  # type: ignore[attr-defined]
        wrapped.direction = getattr(g, "direction", 0.0)  # type: ignore[attr-defined]
        return wrapped

    def monitor_functions(self, u_of_t=None) -> list:
        """The components' non-terminal monitors (force extrema), wrapped like the events."""
        current = {"x": np.asarray(self.restart_state, dtype=float)}
        monitors, self._monitor_owner = [], []
        for k, part in enumerate(self.parts):
            if not hasattr(part.model, "monitor_functions"):
                continue
            def u_k(t, k=k):
                return self.inputs_at(t, current["x"])[k]
            for g in part.model.monitor_functions(u_k):
                wrapped = self._wrap_event(g, part.states, current)
                wrapped.terminal = False
                monitors.append(wrapped)
                self._monitor_owner.append(k)
        return monitors

    def observe(self, t: float, x) -> None:
        """Hand (t, x) to every component that folds observations into its discrete state."""
        x = np.asarray(x, dtype=float)
        us = None
        for k, part in enumerate(self.parts):
            if hasattr(part.model, "observe"):
                us = self.inputs_at(t, x) if us is None else us
                part.model.observe(t, x[part.states], us[k])

    def input_changes(self, t: float, x) -> np.ndarray:
        """Each component's on_input_change at a restart, with its inputs from the whole state."""
        x = np.array(x, dtype=float)
        for k, part in enumerate(self.parts):
            if hasattr(part.model, "on_input_change"):
                u_k = self.inputs_at(t, x)[k]
                x[part.states] = part.model.on_input_change(t, x[part.states], u_k)
        return x

    def advance(self, t0, x0, h, u_of_t, rtol, atol, sample=None):
        """The hybrid contract for the whole scene: input changes at t0, then integration with
        the components' terminal events (on_event, restart) and monitors (observe).
        sample(t_from, t_to, state_at): called, where given, for each stretch between the
        restarts and the monitors' crossings, in time order, with the solver's dense output
        (state_at(t)) and the components' discrete states as they are in [t_from, t_to): the
        monolithic reference records there (solve.py)."""
        if h <= 0.0:
            return np.array(x0, dtype=float)
        t, t_end = t0, t0 + h
        self._hold_time = t0
        try:
            x = self.input_changes(t0, x0)
            for _ in range(self.max_events_per_step):
                self.restart_state, self.restart_time = x, t
                events = self.event_functions(u_of_t)
                monitors = self.monitor_functions(u_of_t)
                dense: list | None = [] if sample else None
                sol = self.integrate(u_of_t, t, x, t_end, rtol, atol, events + monitors,
                                     interpolant=dense)
                sampled_to = t
                for i, te, xe in sorted(sol.crossings, key=lambda c: c[1]):  # time order
                    if i >= len(events):
                        if dense:
                            sample(sampled_to, te, dense[0])
                            sampled_to = te
                        k = self._monitor_owner[i - len(events)]
                        part = self.parts[k]
                        part.model.observe(te, np.asarray(xe)[part.states],
                                           self.inputs_at(te, np.asarray(xe))[k])
                if dense:
                    sample(sampled_to, sol.t if sol.status else t_end, dense[0])
                if sol.status == 0:
                    self.observe(t_end, sol.x)
                    return np.array(sol.x, dtype=float)
                t = sol.t
                self.n_events += 1
                x = self.on_event(t, sol.x, None, sol.event)
                if t >= t_end:
                    self.observe(t, x)
                    return x
        finally:
            self._hold_time = None
        raise CompositionError(f"{self.scene.path}: more than {self.max_events_per_step} events "
                               f"between t = {t0:.9g} s and {t_end:.9g} s (chattering?)")

    def on_event(self, t, x, u, index):
        k, j = self._event_owner[index]
        part = self.parts[k]
        x = np.array(x, dtype=float)
        x[part.states] = part.model.on_event(t, x[part.states], self.inputs_at(t, x)[k], j)
        return x

    def discrete_state(self) -> dict:
        return {p.name: p.model.discrete_state() for p in self.parts}

    def set_discrete_state(self, state: dict) -> None:
        for p in self.parts:
            p.model.set_discrete_state(state.get(p.name, {}))


def _output_index(scene: Scene, model: PhysicsModel, comp: str, var: str) -> int:
    names = [v.name for v in model.outputs]
    if var not in names:
        raise SceneError(scene.path, f"{comp}.{var}", f"{comp} ({model.model_name}) has no "
                                                      f"output {var!r}; outputs: {', '.join(names)}")
    return names.index(var)
