"""Taylor coupling: the inputs over a step follow the Taylor polynomial of their sources' outputs
at the step's start, built from the output derivatives the FMUs compute from their own equations
(the companion outputs `<output>_d1` .. `_dq`, docs/architecture.md "Output derivatives"). A part
the masters compose ([master].taylor = q); testable alone.

Why: an extrapolation through past points of order p misses the signal by
y^(p+1) h (2h) ... ((p+1) h) / (p+1)! = y^(p+1) h^(p+1) at the step's end, the Taylor polynomial
of the same order by y^(p+1) h^(p+1) / (p+1)!: (p+1)! times less (6x at p = 2, 24x at 3), and
its order is not capped by how many past points are smooth (a kink behind t spoils an
extrapolation for p + 1 steps, a Taylor polynomial for none).

Exchange rounds. The derivatives of an output depend on the derivatives of the FMU's inputs (the
press's acceleration on the motor torque, the torque's rate on the press's speed), so they are
exchanged at each communication point in rounds, components in the master's order: a round
writes a component's input rows (values and derivatives as its sources last gave them) and reads
its connected outputs' values and derivatives (one setReal, one getReal). An output's derivative
of order k needs its inputs' derivatives up to k - 1 (k with direct feedthrough), so from any
start, after round r every derivative up to order r is that of the coupled solution at t, for any
wiring without an algebraic loop: q rounds make the rows exact. At the first point (and where an
external step-table input changes, so the derivatives jump) the master takes those q rounds from
rows of zeros. At every other point it starts from a guess, the derivatives at t of the
polynomial each output followed over the last step (for a Gauss-Seidel source, the one through
its newest value), which already misses by O(h^(q+1-k)) in derivative k, and takes ONE round:
measured on the servo press (steps 2 and 4 ms, adaptive at 1e-3) and the two-mass oscillator, the
errors equal those of q rounds to 2-3 digits (oscillator, h = 5 ms: within 0.03-0.24 % at
q = 2-4), for 2 FMI calls per component and step instead of 2q. Without the round the guess
alone diverged on the oscillator; reading each FMU's derivatives right after its doStep (its
inputs at their extrapolated end values) cost 4-5x the error on the servo press; a round that
skips the last component, or takes them in reverse order, let the press step with a wrong
torque polynomial and fail, or cost 4x the error.

Gauss-Seidel: a component that steps after its source reached t + h gets the Taylor polynomial
plus the term of degree q + 1 that takes it through the newest value (Hermite interpolation), as
an extrapolation of order p becomes an interpolation through the newest point.
"""
from __future__ import annotations

from ..runtime.taylor import moved_rows

MAX_ORDER = 4  # the FMUs' output derivatives (runtime.model.MAX_OUTPUT_DERIVATIVE)


class TaylorError(ValueError):
    """The scene's FMUs cannot give what a Taylor coupling needs; names the FMU and variables."""


def companions(names: list[str], order: int) -> list[str]:
    """The companion variables of `names` for derivatives 1 .. order, lowest order first."""
    return [f"{n}_d{k}" for k in range(1, order + 1) for n in names]


class TaylorCoupling:
    """The Taylor rows of every component's connected outputs at a communication point, and
    the sweeps that step the FMUs with them."""

    def __init__(self, system, order: int, master_name: str):
        self.system, self.order = system, order
        self._check(master_name)
        outputs = [c for c in system.order if system.out_names[c]]
        self.round_readers = {c: [system.fmus[c].reader(system.out_names[c]
                                                        + companions(system.out_names[c], r))
                                  for r in range(1, order + 1)] for c in outputs}
        # rows of degree q + 1 reach the FMUs (a sweep through the newest value)
        self.writers = {c: _row_writer(system, c, order + 1) for c in system.order}
        self.guess: dict[str, list] = {}  # rows at the end of the last step, from its polynomial
        self.externals: list | None = None  # the external inputs' values at the last point
        self.rounds = 0
        self._at: tuple[float | None, dict[str, list]] = (None, {})  # (t, rows): a rejected step is retried from the same rows

    def _check(self, master_name: str) -> None:
        """Every component whose outputs are connected must offer their derivatives."""
        for comp in self.system.order:
            fmu, names = self.system.fmus[comp], self.system.out_names[comp]
            missing = [n for n in companions(names, self.order) if n not in fmu.variables
                       or fmu.variables[n].causality != "output"]
            if missing:
                raise TaylorError(
                    f"master {master_name} with taylor = {self.order}: {comp} "
                    f"({fmu.path.name}) has no output derivatives {', '.join(missing[:4])}"
                    f"{' ...' if len(missing) > 4 else ''} (its model declares none for these "
                    f"outputs): use extrapolation instead")

    # -- the communication point ----------------------------------------------------------
    def rows_at(self, t: float) -> dict[str, list]:
        """comp -> Taylor rows at t (lists; value, then derivatives 1 .. q) of its connected
        outputs: the guess refreshed by one round, or q rounds from zeros where there is no
        guess (the module docstring). The same rows for every attempt at t."""
        if self._at[0] != t:
            externals = self._external_values(t)
            if externals != self.externals:
                rows = self.exchange(t, {c: [v] for c, v in self.system.outputs.items()},
                                     self.order)
            else:
                rows = self.exchange(t, dict(self.guess), 1)
            self.externals = externals
            empty: list[list] = [[] for _ in range(self.order + 1)]
            self._at = (t, {c: rows.get(c, empty) for c in self.system.order})
        return self._at[1]

    def coefficients(self, t: float) -> "TaylorCoefficients":
        """rows_at(t) as the masters' `Coefficients`."""
        return TaylorCoefficients(t, self.rows_at(t))

    def _external_values(self, t: float) -> list:
        """The external inputs' values as the masters write them at t (a change, e.g. a step
        table's edge, makes the derivatives jump)."""
        return [s.value_at(t) for signals in self.system.external.values() for _, s in signals]

    def exchange(self, t: float, rows: dict, count: int) -> dict:
        """`count` exchange rounds at t from `rows` (comp -> rows as far as known, lists): each
        component in order gets its inputs' rows and gives its outputs' values and
        derivatives up to the order of the round (all q in a last round). In Python floats: a
        few values per component, where numpy's per-call cost dominates."""
        system, q = self.system, self.order
        for comp in system.order:  # the external inputs as they hold from t on (constants
            if system.external_varies[comp]:  # were written at the start)
                system.set_external(comp, t)
        for r in range(q - count + 1, q + 1):
            for comp in system.order:
                write = self.writers[comp]
                if write is not None:
                    write(_gather(system.in_sources[comp], rows, q + 1))
                readers = self.round_readers.get(comp)
                if readers is not None:
                    flat, n = readers[r - 1](), len(system.out_names[comp])
                    rows[comp] = [flat[k * n:(k + 1) * n] for k in range(r + 1)]
        self.rounds += count
        return rows

    # -- the sweeps -------------------------------------------------------------------------
    def sweep(self, master, t: float, h: float, sequential: bool) -> None:
        """Step every FMU from t by h with its inputs' Taylor rows at t (Gauss-Seidel,
        `sequential`: through the newest value of a source that already reached t + h);
        master.seen and system.outputs as the masters' sweeps leave them."""
        system, q = self.system, self.order
        rows = dict(self.rows_at(t))
        for comp in system.order:
            if system.external_varies[comp]:
                system.set_external(comp, t)
            write = self.writers[comp]
            if write is not None:
                flat = _gather(system.in_sources[comp], rows, q + 1)
                write(flat)
                n = len(system.in_sources[comp])
                master.seen[comp] = ([flat[k * n:(k + 1) * n] for k in range(q + 2)], h)
            else:
                master.seen[comp] = ([[]], h)
            system.fmus[comp].do_step(t, h)
            if sequential and comp in self.round_readers:
                rows[comp] = through_newest(rows[comp], system.refresh_outputs(comp), h)
        if not sequential:
            for comp in system.order:
                system.refresh_outputs(comp)
        start = self.rows_at(t)  # the guess at t + h: the polynomial through the new value
        for comp in self.round_readers:
            new = rows[comp] if sequential else \
                through_newest(start[comp], system.outputs[comp], h)
            self.guess[comp] = moved_rows(new, h)[:q + 1]


class TaylorCoefficients(dict):
    """comp -> Taylor rows at t of its connected outputs (the masters' `Coefficients`
    interface)."""

    def __init__(self, t: float, rows: dict[str, list]):
        super().__init__(rows)
        self.t = t


def through_newest(rows: list, values: list, h: float) -> list:
    """Taylor rows of degree q + 1 that keep `rows` (degree q) and reach `values` at s = h:
    p(s) = T(s) + c s^(q+1), c = (values - T(h)) / h^(q+1), row q + 1 = c (q + 1)!."""
    q = len(rows) - 1
    end = rows[q]
    for k in range(q - 1, -1, -1):  # T(h) by Horner
        c = h / (k + 1)
        end = [a + c * b for a, b in zip(rows[k], end)]
    factorial = 1.0
    for k in range(2, q + 2):
        factorial *= k
    scale = factorial / h ** (q + 1)
    return rows + [[(v - e) * scale for v, e in zip(values, end)]]


def _gather(sources: list, rows: dict, depth: int) -> list[float]:
    """Taylor rows 0 .. depth of a component's connected inputs from its sources' rows (a row
    a source does not have is 0), flat: the values, then each derivative."""
    out = []
    for level in range(depth + 1):
        out += [rows[src][level][k] if level < len(rows[src]) else 0.0 for src, k in sources]
    return out


def _row_writer(system, comp: str, order: int):
    """Writes comp's connected inputs and their companions up to `order` from flat Taylor rows
    (a foreign FMU without companions: the values only); None without connected inputs."""
    fmu, names = system.fmus[comp], system.in_names[comp]
    if not names:
        return None
    wanted = names + companions(names, order)
    if all(n in fmu.variables for n in wanted):
        return fmu.writer(wanted)
    write_values = system.write_inputs[comp]
    return lambda flat: write_values(flat[:len(names)])
