"""The contract every master algorithm implements (after scipy's OdeSolver).

A master advances a wired `System` (FMUs, links, external inputs) over communication steps.
A new master is one file with a `Master` subclass and one line in MASTERS
(crankfmu/masters/__init__.py); docs/masters.md, "Adding a master", walks through an example
(tests/examples/masters/iterated_gauss_seidel.py). Implementers provide:

    name              the algorithm's name in scenes and on the command line (a key of MASTERS).
    options           the [master] keys it takes, a tuple of `Option` (name, type, unit, default,
                      allowed range, help; crankfmu.masters.options). The scene, the
                      command line, the Python API, SSP files and the sidecar read them from
                      here; the master reads the checked values with `self.option(name)`.
    defaults          (optional) {key: value}: this master's own default for an option it
                      shares with other masters, where the shared default does not fit it (the
                      adaptive master's tolerance); the key keeps its meaning, type and range.
    _step(t, h)       advance every FMU from t; on return every FMU is at t + taken and
                      `system.outputs` holds the connected outputs at t + taken, and
                      `self.seen[comp]` = (rows, taken): the inputs each FMU saw over the step
                      as Taylor rows at its start (one row, held, for an FMU without companion
                      inputs; `advance_component` fills it). Return `taken` (= h unless the
                      class sets `variable_step`).
    needs_rollback    True if _step calls `save_states`/`restore_states`; the base then checks
                      canGetAndSetFMUstate for every FMU and names the one that cannot.
    variable_step     True if the master chooses its steps: the runner then asks `next_step`
                      for the next step to try and records at the accepted points; such a
                      master declares the options min_step and max_step [s] (the runner and
                      the step-count check read them).
    startup_corrector True for a fixed-step master whose first order-2 step is repeated with
                      interpolated inputs (`_corrected_first_step`).
    uses_error_scale  True if the class calls `error_scale` (the base then tracks each output's
                      largest magnitude).
    solves_algebraic_loops  True if a converged step satisfies an algebraic loop at t + h.
    extra_statistics  dict of master-level figures for the JSON sidecar (iterations, rejections).
    check_options(values)   (classmethod, optional) checks between options (min_step <=
                      max_step); raises OptionError naming the key.

The base class composes parts that are each testable alone:
    history.History, Coefficients   the last communication points; Taylor rows of the input
                                    polynomials (extrapolation, interpolation)
    inputs.InputFeed                rows to each FMU: companion inputs X_d1, X_d2, or the held
                                    midpoint value for a foreign FMU (with one warning)
    rollback.Rollback               get/set/free FMU states
    power.PortPower                 the port energies (the run's coupling-error figure)
    taylor.TaylorCoupling           with [master].taylor = q: the output derivatives exchanged
                                    at a communication point, the rows that replace
                                    extrapolation
    scale.ErrorScale, check_finite  what tolerances are relative to; divergence
and provides `initialize(t0)`, the public `step(t, h)` (calls `_step`, then keeps the
communication-point history and the port energies), the two sweeps (`parallel_sweep`: Jacobi,
`sequential_sweep`: Gauss-Seidel), and statistics per FMU. The sweeps run each FMU's gather and
advance functions made once at construction (the ones `gather` and `advance_component` call),
not those methods, or, over FMI 2.0 FMUs, the same calls with the same floats written out for
the scene as one function (masters/sweep_code.py): a master that needs other inputs overrides
the sweep or writes its own.

Inputs over a step are polynomials of degree <= 2 (extrapolation), or up to 5 (a Taylor
coupling, masters/taylor.py), given as Taylor rows at the step start (value, first, second ...
derivative): a list of rows, each a sequence of Python floats with one entry per signal.
`system.outputs[comp]` is a list of floats, replaced (never changed in place) at every read, so
the history keeps it as it is. A component has a few connected values: on those, Python floats
cost less than numpy's per-call overhead, with the same operations and so the same floats
(scripts/masters_identity.py).
"""
from __future__ import annotations

from typing import Callable

from .history import HISTORY_DEPTH, Coefficients, History, evaluate, taylor_rows
from .inputs import InputFeed
from .options import Option, OptionError, check_coupling
from .power import PortPower
from .rollback import Rollback
from .scale import RUNAWAY_LIMIT, DivergenceError, ErrorScale, check_finite
from .taylor import TaylorCoupling

__all__ = ["Coefficients", "DivergenceError", "HISTORY_DEPTH", "History", "Master",
           "RUNAWAY_LIMIT", "evaluate", "taylor_rows"]


class Master:
    name = "base"
    options: tuple[Option, ...] = ()
    defaults: dict = {}        # own defaults of shared options (see the module's docstring)
    needs_rollback = False
    variable_step = False
    startup_corrector = False  # fixed-step masters: see _corrected_first_step
    uses_error_scale = False   # True: keep `scale` (each output's largest magnitude) per step
    solves_algebraic_loops = False

    def __init__(self, system, settings):
        """`settings`: the scene's [master] (crankfmu.system.scene.Master); this master
        reads its own options from it, checked against their declaration."""
        self.system = system
        self.settings = settings
        self.values = self.read_options(settings)
        self.extrapolation = self.values.get("extrapolation", 0)
        taylor = self.values.get("taylor", 0)  # masters/taylor.py: its rows replace extrapolation
        self.taylor = TaylorCoupling(system, taylor, self.name) if taylor else None
        self.rollback = Rollback(system, self.name, self.needs_rollback)
        self.can_rollback = self.rollback.available
        self.history = History()
        self.inputs = InputFeed(system)
        self.power = PortPower(system)
        self.scales = ErrorScale(system)
        self.seen: dict[str, tuple] = {}
        self.extra_statistics: dict = {}
        self.time = None
        self._advancers = {c: self._advancer(c) for c in system.fmus}
        # the sweeps' per-FMU work in the stepping order: (name, gather, advance_component,
        # the reader of System.refresh_outputs), looked up once
        self._sweep_plan = [(c, self.inputs.takers[c], self._advancers[c], system.read_outputs[c])
                            for c in system.order]
        self._sequential_rows = rows_plan(system.order, system.in_sources, sequential=True)
        self._parallel_rows = rows_plan(system.order, system.in_sources, sequential=False)
        # sequential? -> the sweep written out for the scene (sweep_code.py), or None
        self._written_sweeps: dict[bool, Callable[[float, float], None] | None] = {}

    # -- options --------------------------------------------------------------------------
    @classmethod
    def read_options(cls, settings) -> dict:
        """{key: checked value} of this master's options (its default where the settings give
        none); OptionError names the key."""
        values = {}
        for option in cls.options:
            try:
                values[option.name] = option.check(getattr(settings, option.name,
                                                           cls.default(option)))
            except OptionError as err:
                raise OptionError(f"[master].{option.name}: {err}") from None
        check_coupling(values)
        cls.check_options(values)
        return values

    @classmethod
    def default(cls, option: Option):
        """This master's default for `option`: its own (`defaults`), else the declared one."""
        return cls.defaults.get(option.name, option.default)

    @classmethod
    def check_options(cls, values: dict) -> None:
        """Checks between options; a subclass raises OptionError naming the key."""

    def option(self, name: str):
        return self.values[name]

    # -- initialization -------------------------------------------------------------------
    def initialize(self, t0: float) -> None:
        """In initialization mode, pass connected values along until they settle (one sweep per
        component covers any loop-free chain of direct feedthrough)."""
        system = self.system
        for comp in system.order:
            system.set_external(comp, t0, initial=True)
        for _ in range(len(system.order) + 1):
            for comp in system.order:
                system.write_inputs[comp](system.gather_inputs(comp))
                system.refresh_outputs(comp)
        for fmu in system.fmus.values():
            fmu.slave.exitInitializationMode()
        for comp in system.order:
            system.write_inputs[comp](system.gather_inputs(comp))
            system.refresh_outputs(comp)
        self.check_finite(t0)
        self._remember(t0)

    # -- contract -------------------------------------------------------------------------
    def step(self, t: float, h: float) -> float:
        """Advance from t by h (or less, for a variable-step master); return the step taken."""
        self.time = t  # where a failing FMU call happened
        history = self.history
        if len(history.times) == 1 and self.startup_corrector and self.extrapolation == 2 \
                and self.can_rollback:
            taken = self._corrected_first_step(t, h)
        else:
            taken = self._step(t, h)
        power = self.power
        if power.ports:  # history.values[-1]: the outputs at t (pushed below)
            power.add(taken, history.values[-1], self.system.outputs, self.seen)
        self._remember(t + taken)
        return taken

    def _step(self, t: float, h: float) -> float:
        raise NotImplementedError

    def _corrected_first_step(self, t: float, h: float) -> float:
        """The first step of an order-2 run has only the point at t: its held inputs (error
        O(h)) would leave a local error O(h^2) and cap the global order at 2. So it is taken
        twice: once as usual, then rolled back and repeated with the inputs interpolated
        linearly towards the outputs the first pass gave at t + h (error O(h^2), local O(h^3))."""
        states = self.save_states()
        taken = self._step(t, h)
        newest = {c: (t + taken, v) for c, v in self.system.outputs.items()}
        self.restore_states(states)
        self.free_states(states)
        coefficients = self.source_coefficients(t, 1, newest)
        for comp in self.system.order:
            self.advance_component(comp, t, taken, self.gather(comp, coefficients))
        for comp in self.system.order:
            self.system.refresh_outputs(comp)
        self.extra_statistics["startup_corrections"] = 1
        return taken

    # -- input polynomials ----------------------------------------------------------------
    def source_coefficients(self, t: float, order: int, newest: dict | None = None
                            ) -> Coefficients:
        """Taylor rows at t of every component's connected outputs (extrapolation of `order`
        from the history; a component in `newest` (comp -> (t_new, values)) contributes that
        point too), computed when first read. With a Taylor coupling: the Taylor rows
        exchanged at t (masters/taylor.py), whatever the order."""
        if self.taylor is not None and newest is None:
            return self.taylor.coefficients(t)
        return Coefficients(self.history, t, order, newest)

    def gather(self, comp: str, coefficients: dict) -> list:
        """Taylor rows of comp's inputs, from the rows of their sources."""
        return self.inputs.takers[comp](coefficients)

    def advance_component(self, comp: str, t: float, h: float, rows: list) -> None:
        """Give comp its inputs as the polynomial `rows` over [t, t + h] and step it."""
        self._advancers[comp](t, h, rows)

    def _advancer(self, comp: str):
        """advance_component of comp as a function of (t, h, rows), with what it needs looked
        up once (the sweeps call it for every FMU in every step)."""
        system, inputs, seen = self.system, self.inputs, self.seen
        fmu, write_rows = system.fmus[comp], inputs.writers[comp]
        varies = system.external_varies[comp]

        def advance(t: float, h: float, rows: list) -> None:
            if varies:  # constant external inputs were written at start
                system.set_external(comp, t)
            if write_rows is not None:
                seen[comp] = (write_rows(rows), h)
            else:  # a foreign FMU: the midpoint value, held (InputFeed.write warns once)
                inputs.write(comp, rows)
                seen[comp] = (inputs.write_held(comp, rows, h), h)
            fmu.do_step(t, h)
        return advance

    # -- the two sweeps -------------------------------------------------------------------
    def parallel_sweep(self, t: float, h: float, order: int) -> None:
        """Jacobi: every component steps from t with inputs extrapolated from the history (or
        the Taylor coupling's rows)."""
        if self.taylor is not None:
            return self.taylor.sweep(self, t, h, sequential=False)
        written = self._written_sweep(False, order)
        if written is not None:
            return written(t, h)
        rows_of, rows, plan = self.history.rows, {}, self._sweep_plan
        for (_, gather, advance, _), make in zip(plan, self._parallel_rows):
            for src, _ in make:  # extrapolated, each once (rows_plan)
                rows[src] = rows_of(src, t, order)
            advance(t, h, gather(rows))
        outputs = self.system.outputs
        for comp, _, _, read in plan:
            outputs[comp] = read()  # System.refresh_outputs

    def sequential_sweep(self, t: float, h: float, order: int, start_rows: dict | None = None
                         ) -> None:
        """Gauss-Seidel: components step in order; a source that already reached t + h
        contributes that newest point (interpolation), the others are extrapolated.
        `start_rows`: the extrapolation rows already computed (comp -> rows), reused."""
        if self.taylor is not None:  # its rows at t are kept: start_rows are those
            return self.taylor.sweep(self, t, h, sequential=True)
        if not start_rows:
            return self._planned_sequential_sweep(t, h, order)
        coefficients = Coefficients(self.history, t, order)
        coefficients.update(start_rows)
        end, outputs, reached = t + h, self.system.outputs, coefficients.reached
        for comp, gather, advance, read in self._sweep_plan:
            advance(t, h, gather(coefficients))
            values = outputs[comp] = read()  # System.refresh_outputs
            reached(comp, end, values)

    def _planned_sequential_sweep(self, t: float, h: float, order: int) -> None:
        """sequential_sweep without rows given: the same rows as Coefficients makes (History.rows,
        extrapolated or through a source's newest point), made in the order the plan fixed once
        (rows_plan) into a plain dict: the lazy dict's lookups and bookkeeping cost
        about as much as the two FMI calls of a no-op step."""
        written = self._written_sweep(True, order)
        if written is not None:
            return written(t, h)
        rows_of, rows = self.history.rows, {}
        newest: dict[str, list] = {}  # comp -> its outputs at t + h, once it has stepped
        end, outputs = t + h, self.system.outputs
        for (comp, gather, advance, read), make in zip(self._sweep_plan, self._sequential_rows):
            for src, interpolate in make:
                rows[src] = rows_of(src, t, order, (end, newest[src]) if interpolate else None)
            advance(t, h, gather(rows))
            newest[comp] = outputs[comp] = read()  # System.refresh_outputs

    def _written_sweep(self, sequential: bool, order: int
                       ) -> Callable[[float, float], None] | None:
        """The sweep written out for this scene (masters/sweep_code.py), where it applies: at
        the master's own order, once the history holds the order + 1 points it takes; else
        None (the generic sweep)."""
        if order != self.extrapolation or len(self.history.times) <= order:
            return None
        if sequential not in self._written_sweeps:
            from .sweep_code import write_sweep
            self._written_sweeps[sequential] = write_sweep(self, sequential)
        return self._written_sweeps[sequential]

    # -- rollback -------------------------------------------------------------------------
    def save_states(self) -> dict:
        return self.rollback.save()

    def restore_states(self, states: dict, comps=None) -> None:
        self.rollback.restore(states, comps)

    def free_states(self, states: dict) -> None:
        self.rollback.free(states)

    # -- bookkeeping ----------------------------------------------------------------------
    def _remember(self, t: float) -> None:
        self.history.push(t, self.system.outputs)
        if self.uses_error_scale:
            self.scales.update(self.system.outputs)

    def error_scale(self, comp: str, values):
        """What a tolerance is relative to: the largest magnitude the output has had so far,
        and at least its nominal (the FMU's `nominal` attribute, else 1 in its SI unit)."""
        return self.scales.of(comp, values)

    def check_finite(self, t: float) -> None:
        """DivergenceError naming the first connected output that is not finite or beyond
        RUNAWAY_LIMIT (masters.scale.check_finite)."""
        check_finite(t, self.system.outputs, self.system.out_names)

    def statistics(self) -> dict:
        """Per FMU: doStep calls and seconds, rollbacks, state saves."""
        return {name: fmu.stats.as_dict() for name, fmu in self.system.fmus.items()}

    def master_statistics(self) -> dict:
        taylor = {} if self.taylor is None else {"taylor": self.taylor.order,
                                                 "exchange_rounds": self.taylor.rounds}
        return {"algorithm": self.name, "extrapolation": self.extrapolation, **taylor,
                **self.extra_statistics}

    def coupling_error(self) -> dict:
        return self.power.report()


def rows_plan(order: list, in_sources: dict, sequential: bool) -> list[tuple]:
    """Per component in the stepping order, the sources whose rows a sweep makes before
    gathering that component's inputs: (source, True) through the source's point at t + h (a
    Gauss-Seidel sweep, `sequential`, stepped it earlier), (source, False) extrapolated from
    the history; each made once per sweep and kept for the components after (as Coefficients
    makes them when first read)."""
    position = {comp: k for k, comp in enumerate(order)}
    made: dict[str, bool] = {}
    plan = []
    for k, comp in enumerate(order):
        make = []
        for src in dict.fromkeys(src for src, _ in in_sources[comp]):
            interpolate = sequential and position[src] < k
            if made.get(src) is not interpolate:
                make.append((src, interpolate))
                made[src] = interpolate
        plan.append(tuple(make))
    return plan
