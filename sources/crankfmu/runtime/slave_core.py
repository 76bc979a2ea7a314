"""What every crankfmu FMU does around a `PhysicsModel`, whatever FMI version carries it.

The FMI 2.0 adapter (`slave.ModelSlave`, on pythonfmu) and the FMI 3.0 adapter
(`slave3.ModelSlave3`, on pythonfmu3) are this core plus their library's registration and log
status: the variable table, the values, initialization, the co-simulation step and the FMU state
exist once, so an FMU of either version gives the same numbers.

Value references, in this order: parameters, effect switches (`effect_<name>`), inputs, outputs,
then the input-derivative companions `<input>_d1` and `<input>_d2` (a crankfmu extension, see
docs/architecture.md "Input extrapolation inside a step"): the first and second time derivative of
each input at the current time; the solver switch `scipy_solver`; the input companions
`<input>_d3` .. `_d5` (MAX_INPUT_DEGREE); the output-derivative companions `<output>_d1` ..
`_d4` of the model's derivative_outputs (MAX_OUTPUT_DERIVATIVE; docs/architecture.md "Output
derivatives"). do_step integrates with the input polynomial
u(t0 + s) = sum_k u_dk s^k / k! and leaves the input and its derivatives at their values at the
step's end (outputs at t0 + h then see the input at t0 + h). They start at 0, so a host that
ignores them gets a held input. Each group came after the variables that existed before it, so
adding it left every other value reference unchanged. The output derivatives are the time
derivatives of the outputs at the current time with the inputs following their rows (values and
companions as last set), computed from the model's equations when first read (runtime/taylor.py)
and only to the highest order read. The FMI 3 adapter adds its own variables (time, states,
derivatives, event indicators) after these.

Cost: a get/set/doStep here should cost little more than the library's own call, so the core
works on a flat list of Python values (no numpy for a handful of numbers), computes the outputs
once per step (eagerly at the end of doStep, where it also checks them; again only if an input
is set before they are read) and resolves everything by index.
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass

from .model import (MAX_INPUT_DEGREE, MAX_OUTPUT_DERIVATIVE, SCIPY_SOLVER, InputPolynomial,
                    IntegrationError, ParameterError, PhysicsModel)
from .taylor import DIFFERENCE_FRACTION

DEFAULT_TOLERANCE = 1e-8  # relative tolerance of the internal solver when the host gives none
DEFAULT_STEP = 1e-3       # s, the DefaultExperiment's step
DEFAULT_STOP = 1.0        # s, the DefaultExperiment's stop time


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
    """The FMU's variables in value-reference order (FMI 2.0): the base table, then the
    companions of a Taylor coupling (the FMI 3.0 adapter puts its own variables between the
    two, so no value reference of an earlier build moved)."""
    return list(_tables(physics_class))  # type: ignore[arg-type]  # mypy: a class is not Hashable


def base_table_size(physics_class: type[PhysicsModel]) -> int:
    """The variables before the Taylor coupling's companions."""
    return _tables(physics_class).base  # type: ignore[arg-type]  # mypy: a class is not Hashable


class _Tables(tuple):
    """The table with the size of its base part."""
    base: int


@functools.lru_cache(maxsize=None)  # fixed per class; every instantiation asks for it
def _tables(physics_class: type[PhysicsModel]) -> _Tables:
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
    table += [FmiVariable(f"{v.name}_d{k}", "Real", "input", "continuous", None,
                          derivative_unit(v.unit, k),
                          f"d{k}/dt{k} of {v.name} at the current time (crankfmu input "
                          f"extrapolation; 0 = input held over the step)", 0.0)
              for k in (1, 2) for v in physics_class.inputs]
    table.append(FmiVariable(SCIPY_SOLVER, "Boolean", "parameter", "fixed", "exact", None,
                             "Integrate with scipy's solve_ivp instead of the built-in "
                             "Dormand-Prince 5(4) / closed forms (slower; a cross-check)", False))
    base = len(table)
    table += [FmiVariable(f"{v.name}_d{k}", "Real", "input", "continuous", None,
                          derivative_unit(v.unit, k),
                          f"d{k}/dt{k} of {v.name} at the current time (crankfmu input "
                          f"polynomial of degree {k}; 0 = a lower degree)", 0.0)
              for k in range(3, MAX_INPUT_DEGREE + 1) for v in physics_class.inputs]
    outputs = {v.name: v for v in physics_class.outputs}
    inputs = [v.name for v in physics_class.inputs]
    table += [FmiVariable(f"{name}_d{k}", "Real", "output", "continuous", "calculated",
                          derivative_unit(outputs[name].unit, k),
                          f"d{k}/dt{k} of {name} at the current time, from the model's "
                          f"equations with the inputs following their companions (crankfmu "
                          f"output derivatives)", None,
                          depends_on=tuple(inputs) + tuple(
                              f"{i}_d{j}" for j in range(1, min(k, MAX_INPUT_DEGREE) + 1)
                              for i in inputs))
              for k in range(1, MAX_OUTPUT_DERIVATIVE + 1)
              for name in physics_class.derivative_outputs]
    tables = _Tables(table)
    tables.base = base
    return tables


def derivative_unit(unit: str | None, order: int) -> str:
    """The unit of the order-th time derivative: rad/s -> rad/s2, N.m -> N.m/s2."""
    unit = unit or "1"
    if unit.endswith("/s"):
        return f"{unit}{order + 1}"
    return f"{unit}/s" if order == 1 else f"{unit}/s{order}"


class SlaveCore:
    """The FMI-version-free part of a crankfmu FMU; an adapter class mixes it in front of its
    library's slave class, calls `_init_core()` in its constructor and provides
    `_log_error(message)`. Subclasses (the FMUs' entry scripts) set `physics_class`."""

    physics_class: type[PhysicsModel] = PhysicsModel
    instance_name: str  # set by the library's slave class
    default_step = DEFAULT_STEP
    default_stop = DEFAULT_STOP

    def _init_core(self) -> None:
        cls = self.physics_class
        self.modelName = cls.model_name
        self.description = cls.description
        self.author = "crankfmu"
        self._table = variable_table(cls)
        self._values = [v.start if v.start is not None else 0.0 for v in self._table]
        n_par, n_eff, n_in = len(cls.parameters), len(cls.effects), len(cls.inputs)
        n_out = len(cls.outputs)
        self._input_slice = slice(n_par + n_eff, n_par + n_eff + n_in)
        self._output_slice = slice(self._input_slice.stop, self._input_slice.stop + n_out)
        self._d1_slice = slice(self._output_slice.stop, self._output_slice.stop + n_in)
        self._d2_slice = slice(self._d1_slice.stop, self._d1_slice.stop + n_in)
        self._scipy_vr = self._d2_slice.stop
        higher = self._scipy_vr + 1
        self._input_row_slices = [self._d1_slice, self._d2_slice] + [
            slice(higher + k * n_in, higher + (k + 1) * n_in)
            for k in range(MAX_INPUT_DEGREE - 2)]
        self._output_rows_start = higher + (MAX_INPUT_DEGREE - 2) * n_in
        self._derivative_count = len(cls.derivative_outputs)
        self._output_names = [v.name for v in cls.outputs]
        self._real_vrs = frozenset(vr for vr, v in enumerate(self._table) if v.kind == "Real")
        self._rows_valid = 0     # output derivatives valid up to this order (0: none)
        # (stamp, input rows, state rows) of the last derivatives
        self._state_rows: tuple[int | None, list, list] | None = None
        self._stamp = 0          # changes whenever the state does
        self._last_step = DEFAULT_STEP  # s, the difference step's scale (runtime/taylor.py)
        self._model: PhysicsModel | None = None
        self._x: list = []
        self._time = 0.0
        self._rtol = DEFAULT_TOLERANCE
        self._atol: list = []
        self._outputs_stale = True

    def _log_error(self, message: str) -> None:
        raise NotImplementedError

    # -- values ----------------------------------------------------------------------------
    def _read(self, vr: int):
        if self._outputs_stale and self._output_slice.start <= vr < self._output_slice.stop:
            self._refresh_outputs()
        if vr >= self._output_rows_start:
            self._need_rows(vr)
        return self._values[vr]

    def _write(self, vrs, values) -> None:
        for vr, value in zip(vrs, values):
            self._values[vr] = value
        self._outputs_stale = True
        self._rows_valid = 0

    def get_real(self, vrs):
        if self._outputs_stale:
            self._refresh_outputs()
        values, reals = self._values, self._real_vrs
        if not reals.issuperset(vrs):
            raise TypeError(f"value references {sorted(set(vrs) - reals)} are not Real")
        if vrs and max(vrs) >= self._output_rows_start:
            self._need_rows(max(vrs))
        return [values[vr] for vr in vrs]

    def set_real(self, vrs, values):
        if not self._real_vrs.issuperset(vrs):
            raise TypeError(f"value references {sorted(set(vrs) - self._real_vrs)} are not Real")
        self._write(vrs, [float(v) for v in values])

    def get_boolean(self, vrs):
        return [bool(self._read(vr)) for vr in vrs]

    def set_boolean(self, vrs, values):
        self._write(vrs, [bool(v) for v in values])

    def _inputs(self) -> list:
        return self._values[self._input_slice]

    def _effects_on(self) -> list[str]:
        offset = len(self.physics_class.parameters)
        return [e.name for k, e in enumerate(self.physics_class.effects)
                if self._values[offset + k]]

    def _build_model(self) -> PhysicsModel:
        cls = self.physics_class
        params = {v.name: self._values[i] for i, v in enumerate(cls.parameters)}
        model = cls(params, self._effects_on())
        if self._values[self._scipy_vr]:
            model.solver = "scipy"
        return model

    def _refresh_outputs(self) -> None:
        if self._model is None:  # initialization mode: outputs from the current parameters
            model = self._build_model()
            x = model.initial_state(self._inputs())
        else:
            model, x = self._model, self._x
        y = model.output_values(self._time, x, self._inputs())
        self._values[self._output_slice] = list(map(float, y))
        self._outputs_stale = False

    # -- output derivatives (runtime/taylor.py) -------------------------------------------------
    def _need_rows(self, vr: int) -> None:
        """Compute the output derivatives up to the order of `vr` (the highest value reference
        read; companions are ordered by derivative order) if not yet done."""
        order = (vr - self._output_rows_start) // self._derivative_count + 1
        if order > self._rows_valid:
            self._refresh_rows(order)

    def _input_rows(self) -> list:
        values = self._values
        return [values[self._input_slice]] + [values[sl] for sl in self._input_row_slices]

    def _refresh_rows(self, order: int) -> None:
        """The rows 1 .. order of the derivative outputs, from the state's rows; state rows
        from an earlier call at the same state are reused as far as the input rows they need
        are unchanged (a master's exchange rounds change the higher input rows only)."""
        if self._model is None:  # initialization mode: from the current parameters
            model = self._build_model()
            x, stamp = model.initial_state(self._inputs()), None
        else:
            model, x, stamp = self._model, self._x, self._stamp
        u_rows = self._input_rows()
        known: list = []
        if self._state_rows is not None and stamp is not None and self._state_rows[0] == stamp:
            _, old_inputs, old_rows = self._state_rows
            same = 0  # leading input rows unchanged: state rows 0 .. same stay valid
            while same < len(u_rows) and u_rows[same] == old_inputs[same]:
                same += 1
            known = old_rows[:same + 1]
        delta = DIFFERENCE_FRACTION * self._last_step
        x_rows = model.state_rows(self._time, x, u_rows, order, delta, known)
        self._state_rows = (stamp, u_rows, x_rows)
        y_rows = model.derivative_output_rows(self._time, x_rows, u_rows, order, delta)
        start, n = self._output_rows_start, self._derivative_count
        for k, row in enumerate(y_rows):
            self._values[start + k * n:start + (k + 1) * n] = list(map(float, row))
        self._rows_valid = order

    def _bad_outputs(self) -> list[str]:
        return [name for name, v in zip(self._output_names, self._values[self._output_slice])
                if not math.isfinite(v)]

    # -- life cycle --------------------------------------------------------------------------
    def _set_experiment(self, start_time, tolerance) -> None:
        self._time = float(start_time)
        if tolerance is not None and tolerance > 0.0:
            self._rtol = float(tolerance)

    def exit_initialization_mode(self):
        try:
            self._model = self._build_model()
        except (ParameterError, KeyError) as err:
            self._log_error(f"{self.instance_name}: {err}")
            raise
        self._x = list(self._model.initial_state(self._inputs()))
        self._atol = [self._rtol * v for v in self._model.state_nominal()]
        self._state_changed()
        self._refresh_outputs()
        bad = self._bad_outputs()
        if bad:
            message = f"{self.instance_name}: output {', '.join(bad)} not finite at the start"
            self._log_error(message)
            raise IntegrationError(message)

    def do_step(self, current_time, step_size):
        values = self._values
        u_of_t = InputPolynomial(current_time, values[self._input_slice],
                                 *[values[sl] for sl in self._input_row_slices])
        t_end = current_time + step_size
        if self._x:  # a model without states has nothing to integrate
            if not self._advance(current_time, step_size, u_of_t):
                return False
        self._time = t_end
        self._last_step = step_size
        self._state_changed()
        if u_of_t.moving:  # the input (and its derivatives) now stand at the step's end
            values[self._input_slice] = u_of_t(t_end)
            for sl, row in zip(self._input_row_slices, u_of_t.shifted(step_size)):
                values[sl] = row
        self._refresh_outputs()
        if not all(map(math.isfinite, values[self._output_slice])):
            self._log_error(f"{self.instance_name}: output {', '.join(self._bad_outputs())} not "
                            f"finite at t = {t_end:.9g} s")
            return False
        return True

    def _advance(self, current_time: float, step_size: float, u_of_t) -> bool:
        """The states over the step; False (with the reason logged) if that fails."""
        model = self._model
        assert model is not None  # stepping: initialization is over
        try:
            x = model.step(current_time, self._x, step_size, u_of_t, self._rtol, self._atol)
        except Exception as err:  # noqa: BLE001 - an exception must not reach the library
            # (it reports fmiFatal, and repeated ones have corrupted the shared interpreter)
            reason = err if isinstance(err, IntegrationError) else \
                f"{type(err).__name__}: {err}"
            self._log_error(f"{self.instance_name}: step at t = {current_time:.9g} s failed: "
                            f"{reason}")
            return False
        if not all(map(math.isfinite, x)):
            bad = [n for n, v in zip(model.state_names(), x) if not math.isfinite(v)]
            self._log_error(f"{self.instance_name}: state {', '.join(bad)} not finite at "
                            f"t = {current_time + step_size:.9g} s")
            return False
        self._x = x
        return True

    def _state_changed(self) -> None:
        """The state moved (a step, a restore, initialization): output derivatives are stale
        and cached state rows no longer apply."""
        self._stamp += 1
        self._rows_valid = 0

    # -- state save / restore (internal states, modes and the step size too) --------------
    def _get_fmu_state(self):
        model = self._model
        return {"time": self._time, "x": [float(v) for v in self._x],
                "values": list(self._values),
                "discrete": model.discrete_state() if model is not None else {},
                "solver": model.solver_state() if model is not None else {},
                "initialized": model is not None, "last_step": self._last_step}

    def _set_fmu_state(self, state):
        self._values = list(state["values"])
        self._time = float(state["time"])
        self._x = list(state["x"])
        self._last_step = float(state.get("last_step", DEFAULT_STEP))
        self._state_changed()
        if state["initialized"] and self._model is None:
            self._model = self._build_model()
            self._atol = [self._rtol * v for v in self._model.state_nominal()]
        if self._model is not None:
            self._model.set_discrete_state(state["discrete"])
            self._model.set_solver_state(state["solver"])
        self._outputs_stale = True
