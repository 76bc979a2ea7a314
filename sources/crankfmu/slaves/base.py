"""A pythonfmu Fmi2Slave around any `PhysicsModel` (the FMI layer; the physics stays apart).

Every FMU of crankfmu is this adapter with a different `physics_class`, so the plumbing
(variable table, initialization, stepping, state save/restore, error reporting) exists once.
The variable table below fixes the value references; `crankfmu.fmi.model_description` writes the
modelDescription.xml from the same table, so the two cannot disagree.

Value references, in this order: parameters, effect switches (`effect_<name>`), inputs, outputs.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from pythonfmu import Boolean, Fmi2Causality, Fmi2Slave, Fmi2Variability, Real
from pythonfmu.enums import Fmi2Status
from pythonfmu.default_experiment import DefaultExperiment

from ..physics.base import IntegrationError, ParameterError, PhysicsModel, held

DEFAULT_TOLERANCE = 1e-8  # relative tolerance of the internal solver when the host gives none


@dataclass(frozen=True)
class FmiVariable:
    name: str
    kind: str  # "Real" or "Boolean"
    causality: str  # parameter | input | output
    variability: str  # fixed | continuous
    initial: str | None  # exact | calculated | None (inputs)
    unit: str | None
    description: str
    start: float | bool | None
    min: float | None = None
    max: float | None = None
    depends_on: tuple[str, ...] = ()


def variable_table(physics_class: type[PhysicsModel]) -> list[FmiVariable]:
    """The FMU's variables in value-reference order."""
    table = [FmiVariable(v.name, "Real", "parameter", "fixed", "exact", v.unit, v.description,
                         float(v.start), v.min, v.max) for v in physics_class.parameters]
    table += [FmiVariable(f"effect_{e.name}", "Boolean", "parameter", "fixed", "exact", None,
                          f"Effect switch: {e.description}", bool(e.default))
              for e in physics_class.effects]
    table += [FmiVariable(v.name, "Real", "input", "continuous", None, v.unit, v.description,
                          float(v.start), v.min, v.max) for v in physics_class.inputs]
    table += [FmiVariable(v.name, "Real", "output", "continuous", "calculated", v.unit,
                          v.description, None, v.min, v.max, v.depends_on)
              for v in physics_class.outputs]
    return table


class ModelSlave(Fmi2Slave):
    """Generic co-simulation slave; subclasses set `physics_class`."""

    physics_class: type[PhysicsModel] = PhysicsModel
    default_step = 1e-3
    default_stop = 1.0

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        cls = self.physics_class
        self.modelName = cls.model_name
        self.description = cls.description
        self.author = "crankfmu"
        self.default_experiment = DefaultExperiment(0.0, self.default_stop, self.default_step,
                                                    DEFAULT_TOLERANCE)
        self._table = variable_table(cls)
        self._values = [v.start if v.start is not None else 0.0 for v in self._table]
        n_par, n_eff, n_in = len(cls.parameters), len(cls.effects), len(cls.inputs)
        self._input_slice = slice(n_par + n_eff, n_par + n_eff + n_in)
        self._output_slice = slice(n_par + n_eff + n_in, len(self._table))
        for vr, var in enumerate(self._table):
            self._register(vr, var)
        self._model: PhysicsModel | None = None
        self._x = np.zeros(0)
        self._time = 0.0
        self._rtol = DEFAULT_TOLERANCE
        self._outputs_stale = True

    def _register(self, vr: int, var: FmiVariable) -> None:
        getter = lambda: self._read(vr)  # noqa: E731 - one closure per value reference
        setter = lambda value: self._write([vr], [value])  # noqa: E731
        kind = Real if var.kind == "Real" else Boolean
        self.register_variable(kind(var.name, causality=Fmi2Causality[var.causality],
                                    variability=Fmi2Variability[var.variability],
                                    description=var.description, getter=getter,
                                    setter=setter), nested=False)

    # -- values ----------------------------------------------------------------------------
    def _read(self, vr: int):
        if self._outputs_stale and vr >= self._output_slice.start:
            self._refresh_outputs()
        return self._values[vr]

    def _write(self, vrs, values) -> None:
        for vr, value in zip(vrs, values):
            self._values[vr] = value
        self._outputs_stale = True

    def get_real(self, vrs):
        return [float(self._read(vr)) for vr in vrs]

    def set_real(self, vrs, values):
        self._write(vrs, [float(v) for v in values])

    def get_boolean(self, vrs):
        return [bool(self._read(vr)) for vr in vrs]

    def set_boolean(self, vrs, values):
        self._write(vrs, [bool(v) for v in values])

    def _inputs(self) -> np.ndarray:
        return np.array(self._values[self._input_slice], dtype=float)

    def _build_model(self) -> PhysicsModel:
        cls = self.physics_class
        params = {v.name: self._values[i] for i, v in enumerate(cls.parameters)}
        offset = len(cls.parameters)
        effects = [e.name for k, e in enumerate(cls.effects) if self._values[offset + k]]
        return cls(params, effects)

    def _refresh_outputs(self) -> None:
        if self._model is None:  # initialization mode: outputs from the current parameters
            model = self._build_model()
            x = model.initial_state(self._inputs())
        else:
            model, x = self._model, self._x
        y = model.output_values(self._time, x, self._inputs())
        self._values[self._output_slice] = [float(v) for v in y]
        self._outputs_stale = False

    # -- FMI life cycle --------------------------------------------------------------------
    def setup_experiment(self, start_time, stop_time=None, tolerance=None):
        self._time = float(start_time)
        if tolerance is not None and tolerance > 0.0:
            self._rtol = float(tolerance)

    def exit_initialization_mode(self):
        try:
            self._model = self._build_model()
        except (ParameterError, KeyError) as err:
            self.log(f"{self.instance_name}: {err}", Fmi2Status.error)
            raise
        self._x = self._model.initial_state(self._inputs())
        self._outputs_stale = True

    def do_step(self, current_time, step_size):
        model = self._model
        u_of_t = held(self._inputs())
        atol = self._rtol * model.state_nominal()
        try:
            x = model.advance(current_time, self._x, step_size, u_of_t, self._rtol, atol)
        except (IntegrationError, FloatingPointError, ValueError) as err:
            self.log(f"{self.instance_name}: step at t = {current_time:.9g} s failed: {err}",
                     Fmi2Status.error)
            return False
        if not np.all(np.isfinite(x)):
            bad = [n for n, v in zip(model.state_names(), x) if not math.isfinite(v)]
            self.log(f"{self.instance_name}: state {', '.join(bad)} not finite at "
                     f"t = {current_time + step_size:.9g} s", Fmi2Status.error)
            return False
        self._x = x
        self._time = current_time + step_size
        self._outputs_stale = True
        return True

    # -- state save / restore (internal states and modes too) -----------------------------
    def _get_fmu_state(self):
        discrete = self._model.discrete_state() if self._model is not None else {}
        return {"time": self._time, "x": [float(v) for v in self._x],
                "values": list(self._values), "discrete": discrete,
                "initialized": self._model is not None}

    def _set_fmu_state(self, state):
        self._values = list(state["values"])
        self._time = float(state["time"])
        self._x = np.array(state["x"], dtype=float)
        if state["initialized"] and self._model is None:
            self._model = self._build_model()
        if self._model is not None:
            self._model.set_discrete_state(state["discrete"])
        self._outputs_stale = True
