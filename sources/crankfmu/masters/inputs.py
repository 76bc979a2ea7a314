"""Inputs over a step: how each FMU receives the polynomial its sources' outputs follow.

A part the master base composes; testable alone (tests/test_master_parts.py). Inputs are given
as Taylor rows at the step's start (value, 1st, 2nd derivative). A crankfmu FMU takes them
through its companion inputs `X_d1`, `X_d2` (docs/architecture.md); an FMU without them (a
foreign FMU) gets the polynomial's value at the step's midpoint, held (one warning per FMU: the
order of accuracy drops to at most 2 there).
"""
from __future__ import annotations

import bisect
import math
import warnings

import numpy as np

from .history import evaluate


class InputFeed:
    """Per FMU: which source outputs feed which inputs, and how the rows are written."""

    def __init__(self, system):
        self.system = system
        self.groups = {c: _input_groups(system, c) for c in system.fmus}
        self.derivative_writer = {c: _derivative_writer(system, c) for c in system.fmus}
        self.derivatives_set = dict.fromkeys(system.fmus, False)
        self.warned_foreign: set[str] = set()

    def gather(self, comp: str, coefficients: dict) -> np.ndarray:
        """Taylor rows of comp's inputs, from the rows of their sources."""
        groups = self.groups[comp]
        if len(groups) == 1:  # one source feeds every input: a column selection
            src, _, indices = groups[0]
            if indices is None:  # all its outputs in order: the rows themselves (never written)
                return coefficients[src]
            return coefficients[src].take(indices, axis=1)
        depth = max((len(coefficients[src]) for src, _, _ in groups), default=1)
        rows = np.zeros((depth, len(self.system.in_names[comp])))
        for src, positions, indices in groups:
            c = coefficients[src]
            rows[:len(c), positions] = c.take(indices, axis=1)
        return rows

    def write(self, comp: str, rows: np.ndarray) -> np.ndarray:
        """Write comp's inputs from `rows`; return the rows the FMU sees over the step (one
        held row for an FMU without companion inputs)."""
        write_derivatives = self.derivative_writer[comp]
        if write_derivatives is not None:
            self.system.write_inputs[comp](rows[0])
            if len(rows) > 1 or self.derivatives_set[comp]:  # zeros once after a held step
                write_derivatives(rows)
                self.derivatives_set[comp] = len(rows) > 1
            return rows
        if len(rows) > 1:
            self._warn_foreign(comp)
        return None

    def write_held(self, comp: str, rows: np.ndarray, h: float) -> np.ndarray:
        """A foreign FMU: the polynomial's value at the step's midpoint, held."""
        value = evaluate(rows, 0.5 * h)
        self.system.write_inputs[comp](value)
        return value[None, :]

    def _warn_foreign(self, comp: str) -> None:
        if comp not in self.warned_foreign:
            self.warned_foreign.add(comp)
            warnings.warn(f"{comp} ({self.system.fmus[comp].path.name}) has no input-derivative "
                          f"inputs (<input>_d1, _d2): it gets the extrapolated inputs' midpoint "
                          f"value, held over each step, so the order of accuracy drops to at most "
                          f"2 at its inputs", RuntimeWarning, stacklevel=5)


def _input_groups(system, comp: str) -> list[tuple[str, np.ndarray, np.ndarray]]:
    """comp's inputs grouped by source: (source, input positions, source output indices)."""
    groups: dict[str, tuple[list, list]] = {}
    for pos, (src, k) in enumerate(system.in_sources[comp]):
        groups.setdefault(src, ([], []))[0].append(pos)
        groups[src][1].append(k)
    out = [(src, np.array(p), np.array(i)) for src, (p, i) in groups.items()]
    if len(out) == 1 and out[0][2].tolist() == list(range(len(system.out_names[out[0][0]]))):
        out = [(out[0][0], out[0][1], None)]  # the source's outputs, all and in order
    return out


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


def step_edges(system) -> list[float]:
    """The times [s] where an external input given as a step table jumps (value_at changes
    there: the new value holds from the edge on), sorted, without repeats. The masters write
    external inputs at a step's start and hold them over the step, so a step that crosses an
    edge shifts it to the step's end; a variable-step master ends its steps at these times."""
    edges = set()
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
