"""The contract every master algorithm implements (after scipy's OdeSolver).

A master advances a wired `System` (FMUs, links, external inputs) over communication steps.
Implementers subclass `Master` and provide:

    name              the algorithm's name in scenes and on the command line (a key of MASTERS).
    _step(t, h)       advance every FMU from t; on return every FMU is at t + taken and
                      `system.outputs` holds the connected outputs at t + taken, and
                      `self.seen[comp]` = (rows, taken): the inputs each FMU saw over the step
                      as Taylor rows at its start (one row, held, for an FMU without companion
                      inputs; `advance_component` fills it). Return `taken` (= h unless the
                      class sets `variable_step`).
    needs_rollback    True if _step calls `save_states`/`restore_states`; the base then checks
                      canGetAndSetFMUstate for every FMU and names the one that cannot.
    variable_step     True if the master chooses its steps: the runner then asks `next_step`
                      for the next step to try and records at the accepted points.
    extra_statistics  dict of master-level figures for the JSON sidecar (iterations, rejections).
    uses_error_scale  True if the class calls `error_scale` (the base then tracks each output's
                      largest magnitude).

The base class provides `initialize(t0)`, the public `step(t, h)` (calls `_step`, then keeps the
communication-point history and the port energies), the input polynomials (`source_coefficients`,
`gather`, `advance_component`), the two sweeps (`parallel_sweep`: Jacobi, `sequential_sweep`:
Gauss-Seidel), `check_finite`, and statistics per FMU.

Inputs over a step are polynomials of degree <= 2, given as Taylor rows at the step start
(value, first and second derivative). They reach crankfmu FMUs through the companion inputs
`X_d1`, `X_d2` (docs/architecture.md); an FMU without them gets the polynomial's value at the
step's midpoint, held (one warning per FMU: the order of accuracy drops to at most 2 there).
"""
from __future__ import annotations

import math
import warnings

import numpy as np

from .power import PortPower

RUNAWAY_LIMIT = 1e12  # |value| beyond this in a connected output is taken as divergence
HISTORY_DEPTH = 3     # communication points kept: enough for a quadratic


class DivergenceError(RuntimeError):
    """The run left the finite, bounded range; names time, component and variable."""

    def __init__(self, time: float, component: str, variable: str, value: float):
        self.time, self.component, self.variable, self.value = time, component, variable, value
        super().__init__(f"diverged at t = {time:.6g} s: {component}.{variable} = {value!r}")


def taylor_rows(s, values) -> np.ndarray:
    """Taylor rows at s = 0 (value, 1st, 2nd derivative) of the polynomial through the points
    (s[i], values[i]) (1 to 3 points; put the point nearest 0 first). Newton's divided
    differences, in Python floats: for a few values per component cheaper than numpy (a
    Vandermonde solve cost more than the rest of a step). Built on differences, the rows of a
    constant signal are exact (derivatives exactly 0: an FMU sees it held), and the value row
    is values[0] exactly when s[0] = 0."""
    if len(s) == 1:
        return np.array([values[0]], dtype=float)
    columns = zip(*[np.asarray(v).tolist() for v in values])
    if len(s) == 2:
        x0, x1 = s
        a = 1.0 / (x1 - x0)
        r0, r1 = [], []
        for p, q in columns:
            f01 = a * (q - p)
            r0.append(p - x0 * f01)
            r1.append(f01)
        return np.array([r0, r1]) if r0 else np.zeros((2, 0))
    x0, x1, x2 = s
    a, b, c = 1.0 / (x1 - x0), 1.0 / (x2 - x1), 1.0 / (x2 - x0)
    r0, r1, r2 = [], [], []
    for p, q, r in columns:  # p(s) = p + f01 (s - x0) + f012 (s - x0)(s - x1)
        f01 = a * (q - p)
        f012 = c * (b * (r - q) - f01)
        r0.append(p - x0 * f01 + x0 * x1 * f012)
        r1.append(f01 - (x0 + x1) * f012)
        r2.append(2.0 * f012)
    return np.array([r0, r1, r2]) if r0 else np.zeros((3, 0))


def evaluate(rows: np.ndarray, s: float) -> np.ndarray:
    """The polynomial given by Taylor rows, at s after their origin."""
    out = rows[0].copy()
    if len(rows) > 1:
        out += rows[1] * s
    if len(rows) > 2:
        out += rows[2] * (0.5 * s * s)
    return out


class History:
    """The last communication points: times and each component's connected outputs."""

    def __init__(self, depth: int = HISTORY_DEPTH):
        self.depth = depth
        self.times: list[float] = []
        self.values: list[dict[str, np.ndarray]] = []

    def push(self, t: float, outputs: dict[str, np.ndarray]) -> None:
        """Keep the arrays themselves: System.refresh_outputs makes a new one per read."""
        self.times.append(t)
        self.values.append(dict(outputs))
        if len(self.times) > self.depth:
            del self.times[0], self.values[0]

    def rows(self, comp: str, t: float, order: int, newest=None) -> np.ndarray:
        """Taylor rows at t of comp's outputs: the polynomial through the last order + 1 points
        (fewer at the start of a run); `newest` = (t_new, values) is a point after t that comes
        first (interpolation)."""
        if order == 0:  # the common case, kept cheap: hold the newest value
            return (newest[1] if newest is not None else self.values[-1][comp])[None, :]
        k = min(order + (newest is None), len(self.times))  # points taken from the history
        # Newton order: the point at t (the newest in the history) first, then t + h if given
        times = self.times[-1:-k - 1:-1]
        values = [v[comp] for v in self.values[-1:-k - 1:-1]]
        if newest is not None:
            times.insert(1, newest[0])
            values.insert(1, newest[1])
        return taylor_rows([x - t for x in times], values)


class Coefficients(dict):
    """Taylor rows at t of each component's connected outputs, computed when first read (a
    Gauss-Seidel sweep never reads the first component's extrapolation or the last one's
    interpolation)."""

    def __init__(self, history: History, t: float, order: int, newest: dict | None = None):
        super().__init__()
        self.history, self.t, self.order = history, t, order
        self.newest = dict(newest) if newest else {}

    def __missing__(self, comp: str) -> np.ndarray:
        rows = self[comp] = self.history.rows(comp, self.t, self.order, self.newest.get(comp))
        return rows

    def reached(self, comp: str, t_new: float, values: np.ndarray) -> None:
        """comp is at t_new with `values`: from now on its rows interpolate through that point."""
        self.newest[comp] = (t_new, values)
        self.pop(comp, None)


class Master:
    name = "base"
    needs_rollback = False
    variable_step = False
    startup_corrector = False  # fixed-step masters: see _corrected_first_step
    uses_error_scale = False   # True: keep `scale` (each output's largest magnitude) per step

    def __init__(self, system, settings):
        self.system = system
        self.settings = settings
        self.extrapolation = int(settings.extrapolation)
        if self.needs_rollback:
            for name, fmu in system.fmus.items():
                if not fmu.can_rollback:
                    raise ValueError(f"master {self.name} rolls FMUs back, but {name} "
                                     f"({fmu.path.name}) has canGetAndSetFMUstate = false")
        self.can_rollback = all(f.can_rollback for f in system.fmus.values())
        self.history = History()
        self.power = PortPower(system)
        self.seen: dict[str, tuple] = {}
        self.extra_statistics: dict = {}
        self.time = None
        self._groups = {c: _input_groups(system, c) for c in system.fmus}
        self._derivative_writer = {c: _derivative_writer(system, c) for c in system.fmus}
        self._derivatives_set = dict.fromkeys(system.fmus, False)
        self._warned_foreign: set[str] = set()
        self.scale = {c: np.zeros(len(v)) for c, v in system.outputs.items()}
        self._nominal = {c: np.array([_nominal(system.fmus[c], n) for n in system.out_names[c]])
                         for c in system.fmus}

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
        before = self.history.values[-1]
        self.time = t  # where a failing FMU call happened
        if self.startup_corrector and len(self.history.times) == 1 and self.extrapolation == 2 \
                and self.can_rollback:
            taken = self._corrected_first_step(t, h)
        else:
            taken = self._step(t, h)
        self.power.add(taken, before, self.system.outputs, self.seen)
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
        newest = {c: (t + taken, v.copy()) for c, v in self.system.outputs.items()}
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
        point too), computed when first read."""
        return Coefficients(self.history, t, order, newest)

    def gather(self, comp: str, coefficients: dict) -> np.ndarray:
        """Taylor rows of comp's inputs, from the rows of their sources."""
        groups = self._groups[comp]
        if len(groups) == 1:  # one source feeds every input: a column selection
            src, _, indices = groups[0]
            return coefficients[src].take(indices, axis=1)
        depth = max((len(coefficients[src]) for src, _, _ in groups), default=1)
        rows = np.zeros((depth, len(self.system.in_names[comp])))
        for src, positions, indices in groups:
            c = coefficients[src]
            rows[:len(c), positions] = c.take(indices, axis=1)
        return rows

    def advance_component(self, comp: str, t: float, h: float, rows: np.ndarray) -> None:
        """Give comp its inputs as the polynomial `rows` over [t, t + h] and step it."""
        system = self.system
        if system.external_varies[comp]:  # constant external inputs were written at start
            system.set_external(comp, t)
        write_derivatives = self._derivative_writer[comp]
        if write_derivatives is not None:
            system.write_inputs[comp](rows[0])
            if len(rows) > 1 or self._derivatives_set[comp]:  # zeros once after a held step
                write_derivatives(rows)
                self._derivatives_set[comp] = len(rows) > 1
            self.seen[comp] = (rows, h)
        else:
            if len(rows) > 1:
                self._warn_foreign(comp)
            value = evaluate(rows, 0.5 * h)
            system.write_inputs[comp](value)
            self.seen[comp] = (value[None, :], h)
        system.fmus[comp].do_step(t, h)

    def _warn_foreign(self, comp: str) -> None:
        if comp not in self._warned_foreign:
            self._warned_foreign.add(comp)
            warnings.warn(f"{comp} ({self.system.fmus[comp].path.name}) has no input-derivative "
                          f"inputs (<input>_d1, _d2): it gets the extrapolated inputs' midpoint "
                          f"value, held over each step, so the order of accuracy drops to at most "
                          f"2 at its inputs", RuntimeWarning, stacklevel=3)

    # -- the two sweeps -------------------------------------------------------------------
    def parallel_sweep(self, t: float, h: float, order: int) -> None:
        """Jacobi: every component steps from t with inputs extrapolated from the history."""
        system = self.system
        coefficients = self.source_coefficients(t, order)
        for comp in system.order:
            self.advance_component(comp, t, h, self.gather(comp, coefficients))
        for comp in system.order:
            system.refresh_outputs(comp)

    def sequential_sweep(self, t: float, h: float, order: int) -> None:
        """Gauss-Seidel: components step in order; a source that already reached t + h
        contributes that newest point (interpolation), the others are extrapolated."""
        system = self.system
        coefficients = self.source_coefficients(t, order)
        for comp in system.order:
            self.advance_component(comp, t, h, self.gather(comp, coefficients))
            coefficients.reached(comp, t + h, system.refresh_outputs(comp))

    # -- rollback -------------------------------------------------------------------------
    def save_states(self) -> dict:
        return {c: f.get_state() for c, f in self.system.fmus.items()}

    def restore_states(self, states: dict, comps=None) -> None:
        for c in comps or states:
            self.system.fmus[c].set_state(states[c])

    def free_states(self, states: dict) -> None:
        for c, s in states.items():
            self.system.fmus[c].free_state(s)

    # -- bookkeeping ----------------------------------------------------------------------
    def _remember(self, t: float) -> None:
        self.history.push(t, self.system.outputs)
        if self.uses_error_scale:
            for c, v in self.system.outputs.items():
                np.maximum(self.scale[c], np.abs(v), out=self.scale[c])

    def error_scale(self, comp: str, values: np.ndarray) -> np.ndarray:
        """What a tolerance is relative to: the largest magnitude the output has had so far,
        and at least its nominal (the FMU's `nominal` attribute, else 1 in its SI unit)."""
        return np.maximum(np.maximum(self.scale[comp], np.abs(values)), self._nominal[comp])

    def check_finite(self, t: float) -> None:
        for comp, values in self.system.outputs.items():
            # in Python floats (cheaper than numpy for a few values): a NaN makes the sum NaN
            if not sum(map(abs, values.tolist())) < RUNAWAY_LIMIT and not all(
                    -RUNAWAY_LIMIT < x < RUNAWAY_LIMIT for x in values.tolist()):
                k = int(np.argmax(~np.isfinite(values) | (np.abs(values) >= RUNAWAY_LIMIT)))
                raise DivergenceError(t, comp, self.system.out_names[comp][k], float(values[k]))

    def statistics(self) -> dict:
        """Per FMU: doStep calls and seconds, rollbacks, state saves."""
        return {name: fmu.stats.as_dict() for name, fmu in self.system.fmus.items()}

    def master_statistics(self) -> dict:
        return {"algorithm": self.name, "extrapolation": self.extrapolation,
                **self.extra_statistics}

    def coupling_error(self) -> dict:
        return self.power.report()


def _input_groups(system, comp: str) -> list[tuple[str, np.ndarray, np.ndarray]]:
    """comp's inputs grouped by source: (source, input positions, source output indices)."""
    groups: dict[str, tuple[list, list]] = {}
    for pos, (src, k) in enumerate(system.in_sources[comp]):
        groups.setdefault(src, ([], []))[0].append(pos)
        groups[src][1].append(k)
    return [(src, np.array(p), np.array(i)) for src, (p, i) in groups.items()]


def _derivative_writer(system, comp: str):
    """For comp's companion inputs X_d1..., X_d2... (crankfmu FMUs): a function writing them
    from Taylor rows (derivatives the rows lack are 0), else None."""
    fmu, names = system.fmus[comp], system.in_names[comp]
    companions = [f"{n}_d1" for n in names] + [f"{n}_d2" for n in names]
    if not names or not all(n in fmu.variables and fmu.variables[n].causality == "input"
                            for n in companions):
        return None
    write = fmu.writer(companions)
    padded = np.zeros((2, len(names)))  # d1, d2 for rows without a 2nd derivative (d2 = 0)
    flat = padded.ravel()               # a view: the companions' order is d1..., d2...

    def write_rows(rows: np.ndarray) -> None:
        if len(rows) == 3:
            write(rows[1:].ravel())
        else:
            padded[0] = rows[1] if len(rows) == 2 else 0.0
            write(flat)
    return write_rows


def _nominal(fmu, name: str) -> float:
    nominal = getattr(fmu.variables[name], "nominal", None)
    try:
        return abs(float(nominal)) if nominal else 1.0
    except (TypeError, ValueError):
        return 1.0


def finite(x: float) -> bool:
    return math.isfinite(x) and abs(x) < RUNAWAY_LIMIT
