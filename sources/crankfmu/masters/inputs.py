"""Inputs over a step: how each FMU receives the polynomial its sources' outputs follow.

A part the master base composes; testable alone (tests/test_master_contract.py). Inputs are given
as Taylor rows at the step's start (value, 1st, 2nd derivative). A crankfmu FMU takes them
through its companion inputs `X_d1`, `X_d2` (docs/architecture.md); an FMU without them (a
foreign FMU) gets the polynomial's value at the step's midpoint, held (one warning per FMU: the
order of accuracy drops to at most 2 there).
"""
from __future__ import annotations

import bisect
import math
import warnings
from operator import itemgetter

from .history import evaluate


class InputFeed:
    """Per FMU: which source outputs feed which inputs, and how the rows are written (a
    function of each, made once per FMU: they run for every FMU in every step)."""

    def __init__(self, system):
        self.system = system
        self.takers = {c: _taker(system, c) for c in system.fmus}
        self.writers = {c: _rows_writer(system, c) for c in system.fmus}
        self.warned_foreign: set[str] = set()

    def gather(self, comp: str, coefficients: dict) -> list:
        """Taylor rows of comp's inputs, from the rows of their sources."""
        return self.takers[comp](coefficients)

    def write(self, comp: str, rows) -> list | None:
        """Write comp's inputs from `rows`; return the rows the FMU sees over the step (None
        for an FMU without companion inputs: see write_held)."""
        write_rows = self.writers[comp]
        if write_rows is not None:
            return write_rows(rows)
        if len(rows) > 1:
            self._warn_foreign(comp)
        return None

    def write_held(self, comp: str, rows, h: float) -> list:
        """A foreign FMU: the polynomial's value at the step's midpoint, held."""
        value = evaluate(rows, 0.5 * h)
        self.system.write_inputs[comp](value)
        return [value]

    def _warn_foreign(self, comp: str) -> None:
        if comp not in self.warned_foreign:
            self.warned_foreign.add(comp)
            warnings.warn(f"{comp} ({self.system.fmus[comp].path.name}) has no input-derivative "
                          f"inputs (<input>_d1, _d2): it gets the extrapolated inputs' midpoint "
                          f"value, held over each step, so the order of accuracy drops to at most "
                          f"2 at its inputs", RuntimeWarning, stacklevel=5)


def _taker(system, comp: str):
    """A function from the sources' Taylor rows (comp -> rows) to comp's input rows: the
    source's rows themselves when one source feeds its outputs, all and in order; a selection
    of their columns when one source feeds some; else input by input (a source with fewer
    rows contributes 0 to the missing derivatives)."""
    feeds = system.in_sources[comp]
    sources = {src for src, _ in feeds}
    if len(sources) != 1:
        def by_input(coefficients: dict) -> list:
            rows = [coefficients[src] for src, _ in feeds]
            return [[r[d][k] if d < len(r) else 0.0 for r, (_, k) in zip(rows, feeds)]
                    for d in range(max(map(len, rows), default=1))]
        return by_input
    src, = sources
    indices = [k for _, k in feeds]
    if indices == list(range(len(system.out_names[src]))):
        return lambda coefficients: coefficients[src]
    if len(indices) == 1:
        k, = indices
        return lambda coefficients: [[row[k]] for row in coefficients[src]]
    pick = itemgetter(*indices)
    return lambda coefficients: [list(pick(row)) for row in coefficients[src]]


def _rows_writer(system, comp: str):
    """A function writing comp's inputs from Taylor rows and returning the rows: the value row,
    and the companion inputs X_d1..., X_d2... of a crankfmu FMU (derivatives the rows lack are
    0; zeros are written once after a step with derivatives). None for an FMU without the
    companions (a foreign FMU)."""
    fmu, names = system.fmus[comp], system.in_names[comp]
    if not names:
        return lambda rows: rows  # nothing to write
    companions = [f"{n}_d1" for n in names] + [f"{n}_d2" for n in names]
    if not all(n in fmu.variables and fmu.variables[n].causality == "input"
               for n in companions):
        return None
    write_values = system.write_inputs[comp]
    write_derivatives = fmu.writer(companions)  # the companions' order is d1..., d2...
    zeros = [0.0] * len(names)
    no_derivatives = zeros + zeros
    derivatives_set = False  # the FMU's companion inputs hold nonzero derivatives

    def write_rows(rows) -> list:
        nonlocal derivatives_set
        write_values(rows[0])
        depth = len(rows)
        if depth == 1:
            if derivatives_set:
                write_derivatives(no_derivatives)
                derivatives_set = False
            return rows
        write_derivatives([*rows[1], *rows[2]] if depth == 3 else [*rows[1], *zeros])
        derivatives_set = True
        return rows
    return write_rows


def step_edges(system) -> list[float]:
    """The times [s] where an external input given as a step table jumps (value_at changes
    there: the new value holds from the edge on), sorted, without repeats. The masters write
    external inputs at a step's start and hold them over the step, so a step that crosses an
    edge shifts it to the step's end; a variable-step master ends its steps at these times."""
    edges: set[float] = set()
    for signals in system.external.values():
        for _, s in signals:
            if s.interpolation == "step":
                edges.update(t for t, before, after in zip(s.times[1:], s.values, s.values[1:])
                             if after != before)
    return sorted(edges)


# A step table's edge within this many ulps after a time counts as reached at that time: a
# fixed-step master's grid point t0 + k h can land an ulp or two before an edge meant to be on
# it, and the new value must then hold from that point, not from a step later.
EDGE_ULPS = 64


def edge_reading_time(t: float) -> float:
    """The time at which a step table is read for time t (InputSignal.value_at): t plus
    EDGE_ULPS ulps, so that an edge a rounding error after t counts as reached."""
    return t + EDGE_ULPS * math.ulp(t)


def step_to(t: float, edge: float) -> float:
    """The step from t that ends at `edge` in floats: edge - t, rounded up by an ulp or two
    where needed so that t + step >= edge (the next step's start then reads the new value)."""
    step = edge - t
    while t + step < edge:
        step = math.nextafter(step, math.inf)
    return step


def split_at_edges(t: float, h: float, edges: list[float]) -> list[float]:
    """The pieces [s] a fixed-step master takes for the grid step (t, t + h) so that each edge
    strictly inside it ends a piece (external inputs are written at a step's start and held:
    a step across an edge would apply it up to a step late). Edges within EDGE_ULPS ulps of
    the step's ends are on them (edge_reading_time). A piece that ends at an edge reaches it in
    floats (t + piece >= edge), so the next piece reads the new value. [h] when no edge is
    inside, the same float h the grid gives."""
    if not edges:
        return [h]
    i = bisect.bisect_right(edges, edge_reading_time(t))
    end = t + h
    pieces, start = [], t
    while i < len(edges) and edge_reading_time(edges[i]) < end:
        piece = step_to(start, edges[i])
        pieces.append(piece)
        start += piece
        i += 1
    if not pieces:
        return [h]
    pieces.append(end - start)
    return pieces
