"""The FMI 3.0 adapter: pythonfmu3's slave around any `PhysicsModel`, with Co-Simulation and Model
Exchange from the same model code.

Co-Simulation is the version-free core (`slave_core.SlaveCore`), as in the FMI 2.0 adapter, so an
FMI 3.0 doStep gives the FMI 2.0 FMU's numbers. Model Exchange hands the model's contract
(runtime/model.py) to the host:

    continuous states    the model's states (`state_names()`) for the effects the FMU was built
                         with (`me_effects`; an effect that is off adds no state). The layout is
                         fixed in the modelDescription, so Model Exchange refuses other effect
                         sets that change the states, naming the FMU to build for them
                         (Co-Simulation takes any effects).
    derivatives          `derivatives(t, x, u)` at the time, states and inputs the host set.
    event indicators     the current mode's `event_functions` (terminal: a mode change) and
                         `monitor_functions` (force extrema), padded with 1.0 to the model's
                         `event_slots`.
    discrete update      fmi3UpdateDiscreteStates: an indicator whose sign differs from the one
                         it had when the mode was last entered, in the function's direction,
                         has crossed: a monitor's crossing goes to `observe`, the first
                         terminal one to `on_event`; then `on_input_change` (inputs may jump
                         only at events), and the new mode's functions are armed.

pythonfmu3 0.3.4 calls Python only for the functions above and the value accessors:
fmi3EnterEventMode, fmi3EnterContinuousTimeMode and fmi3CompletedIntegratorStep never reach
Python (so the discrete update detects its events itself, from the signs), and
fmi3EnterInitializationMode passes neither the start time nor the tolerance. crankfmu's launcher
passes both with fmi3SetFloat64 on two value references outside the modelDescription
(EXPERIMENT_VRS); without the launcher the FMU starts at t = 0 with DEFAULT_TOLERANCE.
"""
from __future__ import annotations

import math
from typing import Any

from pythonfmu3 import Fmi3SlaveBase
from pythonfmu3.cosimulation import CoSimulation
from pythonfmu3.default_experiment import DefaultExperiment
from pythonfmu3.enums import Fmi3Status
from pythonfmu3.modelexchange import ModelExchange

from .model import IntegrationError
from .slave_core import DEFAULT_TOLERANCE, SlaveCore, base_table_size

# fmi3EnterInitializationMode's startTime and tolerance, set by crankfmu's launcher (launcher3.c)
# right before it forwards that call; not variables of the modelDescription
EXPERIMENT_VRS = (1 << 30, (1 << 30) + 1)
PADDING = 1.0  # the value of an event-indicator slot the current mode does not use


def me_layout(n_base: int, n_states: int, n_slots: int, n_companions: int = 0
              ) -> dict[str, range]:
    """Value references of the FMI 3.0 variables after the shared table's base part: time, the
    states, their derivatives, the event indicators; then the table's Taylor-coupling
    companions (slave_core.variable_table), which came later (the modelDescription writer uses
    the same function)."""
    time = n_base
    states = range(time + 1, time + 1 + n_states)
    derivatives = range(states.stop, states.stop + n_states)
    indicators = range(derivatives.stop, derivatives.stop + n_slots)
    return {"time": range(time, time + 1), "states": states, "derivatives": derivatives,
            "indicators": indicators,
            "companions": range(indicators.stop, indicators.stop + n_companions)}


class DiscreteUpdate:
    """What fmi3UpdateDiscreteStates returns: pythonfmu3's C++ reads these attribute names
    (its own Fmi3UpdateDiscreteStatesResult spells two of them differently, so the host's
    flags would stay as the host left them)."""

    def __init__(self, states_changed: bool):
        self.discreteStatesNeedUpdate = False
        self.terminateSimulation = False
        self.nominalContinuousStatesChanged = False
        self.valuesOfContinuousStatesChanged = states_changed
        self.nextEventTimeDefined = False
        self.nextEventTime = 0.0


class ModelSlave3(SlaveCore, Fmi3SlaveBase, CoSimulation, ModelExchange):
    """Generic FMI 3.0 slave; the entry script sets `physics_class`, `me_effects` and
    `me_states` (the Model Exchange layout it was built for)."""

    me_effects: tuple[str, ...] = ()
    me_states: tuple[str, ...] = ()

    def __init__(self, **kwargs):
        Fmi3SlaveBase.__init__(self, **kwargs)
        self._init_core()
        offset = len(self.physics_class.parameters)  # the effects start as built
        for k, effect in enumerate(self.physics_class.effects):
            self._values[offset + k] = effect.name in self.me_effects
        self.default_experiment = DefaultExperiment(0.0, self.default_stop, self.default_step,
                                                    DEFAULT_TOLERANCE)
        n_base = base_table_size(self.physics_class)
        self._slots_count = self.physics_class.event_slots
        self._layout = me_layout(n_base, len(self.me_states), self._slots_count,
                                 len(self._table) - n_base)
        self._n_table = n_base  # below: the core's value references as they are
        self._companion_shift = self._layout["companions"].start - n_base
        self._slots: list | None = None  # [(g, index in event_functions or None, direction)]
        self._ref: list[int] = []        # each slot's sign when its mode was entered
        self._layout_checked = False

    # FMI 3.0 names the host's time `time`; ModelExchange requires the attribute
    @property
    def time(self) -> float:
        return self._time

    def _log_error(self, message: str) -> None:
        self.log(message, Fmi3Status.error)

    # -- values ----------------------------------------------------------------------------
    def get_float64(self, vrs):
        if all(vr < self._n_table for vr in vrs):
            return self.get_real(vrs)
        companions = self._layout["companions"]
        if all(vr < self._n_table or vr in companions for vr in vrs):
            return self.get_real(self._core_vrs(vrs))
        return [self._get_one(vr) for vr in vrs]

    def _core_vrs(self, vrs) -> list[int]:
        """The core's value references of table variables (a companion's moved by the FMI 3.0
        variables before it)."""
        n, shift = self._n_table, self._companion_shift
        return [vr if vr < n else vr - shift for vr in vrs]

    def _get_one(self, vr: int) -> float:
        layout = self._layout
        if vr < self._n_table or vr in layout["companions"]:
            return self.get_real(self._core_vrs([vr]))[0]
        if vr in layout["time"]:
            return self._time
        if vr in layout["states"]:
            return float(self.get_continuous_states()[vr - layout["states"].start])
        if vr in layout["derivatives"]:
            return self.get_continuous_state_derivatives()[vr - layout["derivatives"].start]
        if vr in layout["indicators"]:
            return self.get_event_indicators()[vr - layout["indicators"].start]
        raise TypeError(f"value reference {vr} is not a Float64 variable")

    def set_float64(self, vrs, values):
        if vrs and vrs[0] == EXPERIMENT_VRS[0]:  # the launcher's startTime, tolerance
            given = dict(zip(vrs, values))
            self._set_experiment(given.get(EXPERIMENT_VRS[0], 0.0), given.get(EXPERIMENT_VRS[1]))
            return
        self.set_real(self._core_vrs(vrs), values)

    def set_time(self, time: float):
        self._time = float(time)
        self._outputs_stale = True
        self._state_changed()  # output derivatives and cached state rows are of another time

    # -- Model Exchange ----------------------------------------------------------------------
    def _check_layout(self) -> None:
        """The model's states for the effects set are the ones the modelDescription lists."""
        if self._layout_checked:
            return
        model = self._model if self._model is not None else self._build_model()
        names = tuple(model.state_names())
        if names != tuple(self.me_states):
            effects = sorted(self._effects_on())
            message = (f"{self.instance_name}: Model Exchange: the effects {effects} give the "
                       f"states {list(names)}, but this FMU was built for the effects "
                       f"{sorted(self.me_effects)} with the states {list(self.me_states)}; "
                       f"use the FMU built for these effects (crankfmu build --fmi 3 --effects "
                       f"{','.join(effects) or 'none'} {self.physics_class.model_name}); "
                       f"Co-Simulation takes any effects")
            self._log_error(message)
            raise ValueError(message)
        self._layout_checked = self._model is not None

    def get_number_of_continuous_states(self) -> int:
        return len(self.me_states)

    def get_number_of_event_indicators(self) -> int:
        return self._slots_count

    def get_continuous_states(self):
        self._check_layout()
        if self._model is None:  # initialization mode: the start values from the inputs
            return list(map(float, self._build_model().initial_state(self._inputs())))
        return list(map(float, self._x))

    def set_continuous_states(self, values):
        self._check_layout()
        self._x = list(values)
        self._outputs_stale = True
        self._state_changed()

    def get_nominals_of_continuous_states(self, size: int):
        self._check_layout()
        model = self._model if self._model is not None else self._build_model()
        return list(map(float, model.state_nominal()))

    def get_continuous_state_derivatives(self):
        self._check_layout()
        model = self._model
        if model is None:
            model = self._build_model()
            x = model.initial_state(self._inputs())
        else:
            x = self._x
        return list(map(float, model.derivatives(self._time, x, self._inputs())))

    def _held_inputs(self, t: float) -> list:
        return self._inputs()  # the host sets the inputs for the time it evaluates at

    def _arm(self) -> None:
        """The current mode's event and monitor functions, and their signs at (time, x)."""
        model, t, x = self._model, self._time, list(self._x)
        assert model is not None  # armed after initialization
        model.restart_state, model.restart_time = x, t
        slots: list[tuple[Any, int | None, float]] = [
            (g, j, getattr(g, "direction", 0.0))
            for j, g in enumerate(model.event_functions(self._held_inputs))]
        if hasattr(model, "monitor_functions"):
            slots += [(g, None, getattr(g, "direction", 0.0))
                      for g in model.monitor_functions(self._held_inputs)]
        if len(slots) > self._slots_count:
            raise IntegrationError(f"{self.physics_class.model_name}: {len(slots)} event "
                                   f"functions in one mode, more than its event_slots = "
                                   f"{self._slots_count}")
        self._slots = slots
        self._ref = [_sign(g(t, x)) for g, _, _ in slots]

    def get_event_indicators(self):
        self._check_layout()
        if self._model is None:
            return [PADDING] * self._slots_count
        if self._slots is None:
            self._arm()
        t, x, ref = self._time, self._x, self._ref
        values = [float(g(t, x)) for g, _, _ in self._slots]
        for i, value in enumerate(values):
            if ref[i] == 0 and value != 0.0:  # a function that was zero when armed: its side
                ref[i] = _sign(value)
        return values + [PADDING] * (self._slots_count - len(values))

    def update_discrete_states(self):
        """One event iteration at the time and states the host set (see the module
        docstring); never needs a second one."""
        self._check_layout()
        model, t = self._model, self._time
        x = list(self._x)
        if self._slots is not None:
            u = self._inputs()
            terminal = None
            for (g, j, direction), ref in zip(self._slots, self._ref):
                if not _crossed(ref, g(t, x), direction):
                    continue
                if j is None:
                    model.observe(t, x, u)
                elif terminal is None:
                    terminal = j
            if terminal is not None:
                x = list(model.on_event(t, x, u, terminal))
        if hasattr(model, "on_input_change"):
            x = list(model.on_input_change(t, x, self._inputs()))
        changed = x != list(self._x)
        self._x = x
        self._outputs_stale = True
        self._state_changed()
        self._arm()
        return DiscreteUpdate(changed)

    # -- FMU state: the core's, and the armed mode's reference signs -------------------------
    def _get_fmu_state(self):
        state = super()._get_fmu_state()
        model = self._model
        if self._slots is not None and model is not None:
            state["events"] = {"restart_state": [float(v) for v in model.restart_state],
                               "restart_time": float(model.restart_time), "ref": list(self._ref)}
        return state

    def _set_fmu_state(self, state):
        super()._set_fmu_state(state)
        self._slots = None
        events = state.get("events")
        if events is not None and self._model is not None:
            saved_x, saved_t = self._x, self._time
            self._x, self._time = list(events["restart_state"]), float(events["restart_time"])
            self._arm()
            self._x, self._time = saved_x, saved_t
            self._ref = list(events["ref"])


def _sign(value) -> int:
    value = float(value)  # a model's function may give a numpy float
    return (value > 0.0) - (value < 0.0)


def _crossed(ref: int, value: float, direction: float) -> bool:
    """Has a function whose sign was `ref` when armed crossed zero in `direction` (+1 rising,
    -1 falling, 0 either) now that it is `value`? Reaching zero counts; a function that was
    zero when armed (ref 0) has no side to leave."""
    value = float(value)
    if ref == 0 or math.isnan(value):
        return False
    if direction > 0:
        return ref < 0 and value >= 0.0
    if direction < 0:
        return ref > 0 and value <= 0.0
    return _sign(value) != ref
