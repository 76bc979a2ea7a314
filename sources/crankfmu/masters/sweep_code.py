"""A sweep written out for one wired scene: Gauss-Seidel's (also the adaptive master's, which
makes the same rows) or Jacobi's, with the same floats and the same FMI calls as the generic
sweeps of masters.base.

Why: per FMU and step the generic sweep makes about nine Python calls (the sources' Taylor rows,
the gather, the advance, the rows writer, two buffer writers, doStep, the read) and lists for
the rows. Over two no-op FMUs at extrapolation 2 that was 10 us of a 34 us step, the bare FMI
calls 24 us (`python benchmarks/masters.py --skip b,c`); spelled out in one function, every
FMU's value references, buffers and raw FMI functions bound once, the master's own share about
halves (docs/performance.md, "The masters' own cost").

What it covers: a sweep once the history holds every point the extrapolation order takes (the
run's first steps, with fewer points, and the Gauss-Seidel start-up corrector stay generic), of
FMI 2.0 FMUs (FmuInstance) that take their inputs' derivatives (`<input>_d1`, `_d2`) or have no
inputs. Elsewhere `write_sweep` gives None and the generic sweep runs: a Taylor coupling, a
foreign FMU (its inputs held at the midpoint), FMI 3.0 FMUs (their calls take other arguments).

Same floats: each source's rows are History.rows's (the Newton forms of masters.history, every
expression as written there) at the same points; the inputs written are the generic rows
writer's (masters.inputs: the value row, then d1 and d2, d2 zero at order 1); the rows kept in
`seen` for the port energies (only when the scene has ports) are the rows the generic sweep
keeps. scripts/masters_identity.py compares every scene under every master and order.
"""
from __future__ import annotations

import functools
import hashlib
import linecache
import time
from typing import Callable

from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import fmi2Real, fmi2ValueReference

from ..fmu.instance import FMI2_WARNING, FmuInstance


def write_sweep(master, sequential: bool) -> Callable[[float, float], None] | None:
    """sweep(t, h) for `master` (Gauss-Seidel: `sequential`; Jacobi: not) at its extrapolation
    order, for a history of at least order + 1 points; None where the generic sweep must run
    (the module's docstring)."""
    system = master.system
    if master.taylor is not None or any(type(system.fmus[c]) is not FmuInstance
                                        or master.inputs.writers[c] is None
                                        for c in system.order):
        return None
    plans = master._sequential_rows if sequential else master._parallel_rows  # base.rows_plan
    source = _source(system, plans, master.extrapolation, sequential, bool(master.power.ports))
    namespace = _bindings(master)
    exec(_compiled(source), namespace)  # noqa: S102 - source written from the wiring alone
    return namespace["sweep"]


@functools.lru_cache(maxsize=64)
def _compiled(source: str):
    """A sweep's code, compiled once per process (0.75 ms for four FMUs at order 2; a study
    runs one scene many times), its lines in linecache so that a traceback shows them."""
    name = f"<written sweep {hashlib.sha256(source.encode()).hexdigest()[:12]}>"
    linecache.cache[name] = (len(source), None, source.splitlines(True), name)
    return compile(source, name, "exec")


def _bindings(master) -> dict:
    """The names the written sweep uses: per FMU (by its position k in the stepping order) the
    instance F{k}, its statistics S{k}, raw FMI functions, value references and buffers."""
    system = master.system
    names = {"history": master.history, "outputs": system.outputs, "seen": master.seen,
             "clock": time.perf_counter, "WARNING": FMI2_WARNING,
             "FMICallException": FMICallException, "set_external": system.set_external}
    for k, comp in enumerate(system.order):
        fmu = system.fmus[comp]
        functions = fmu.slave._functions
        inputs = system.in_names[comp]
        companions = [f"{n}_d1" for n in inputs] + [f"{n}_d2" for n in inputs]
        for tag, variables in (("IN", inputs), ("D", companions), ("OUT", system.out_names[comp])):
            names[f"VR_{tag}{k}"] = (fmi2ValueReference * len(variables))(
                *[fmu.variable(v).valueReference for v in variables])
            names[f"B_{tag}{k}"] = (fmi2Real * len(variables))()
        names[f"VIEW{k}"] = memoryview(names[f"B_OUT{k}"]).cast("B").cast("d")
        names.update({f"F{k}": fmu, f"S{k}": fmu.stats, f"SET{k}": functions["fmi2SetReal"],
                      f"GET{k}": functions["fmi2GetReal"], f"STEP{k}": functions["fmi2DoStep"]})
    return names


def _source(system, plans: list, order: int, sequential: bool, ports: bool) -> str:
    """The sweep's Python source: per FMU in the stepping order, the rows its sources need (made
    as `plans`, masters.base.rows_plan, orders them), its inputs written, doStep, its outputs
    read; Jacobi reads every FMU's outputs after all have stepped."""
    lines = ["def sweep(t, h):", "    times, values = history.times, history.values"]
    if order:  # the points' times from t (held values at order 0 need none)
        if sequential:  # the newest point's: (t + h) - t, as History.rows takes it
            lines.append("    iv = (t + h) - t")
        lines += [f"    e{j} = times[-{j + 1}] - t" for j in range(order + 1)]
    lines += [f"    V{j} = values[-{j + 1}]" for j in range(order + 1)]
    current: dict[str, str] = {}  # source -> the prefix of its rows' names in use
    for k, (comp, make) in enumerate(zip(system.order, plans)):
        for m, (src, interpolate) in enumerate(make):
            prefix = current[src] = f"r{k}_{m}_"
            lines += _rows(prefix, src, len(system.out_names[src]), order,
                           f"N{system.order.index(src)}" if interpolate else None)
        lines += _advance(k, comp, system, order, current, ports)
        if sequential:
            lines += _read(k, comp, len(system.out_names[comp]))
    if not sequential:
        for k, comp in enumerate(system.order):
            lines += _read(k, comp, len(system.out_names[comp]))
    return "\n".join(lines) + "\n"


def _rows(prefix: str, src: str, n: int, order: int, newest: str | None) -> list[str]:
    """Locals {prefix}v{i}, d{i}, s{i}: the value, 1st and 2nd derivative rows of src's n
    connected outputs at t, as History.rows makes them: the polynomial through the last
    order + 1 points, or (`newest`: the name of src's outputs at t + h) through that point,
    second, and the last `order` ones."""
    p = f"V0[{src!r}]" if newest is None else newest
    if order == 0:
        return [f"    {prefix}v{i} = {p}[{i}]" for i in range(n)]
    if newest is None:  # extrapolation: x = times[-1] - t, times[-2] - t, ...
        xs, points = ["e0", "e1", "e2"], [f"V{j}[{src!r}]" for j in range(order + 1)]
    else:  # interpolation: the newest point second, as History.rows passes it
        xs, points = ["e0", "iv", "e1"], [f"V0[{src!r}]", newest, f"V1[{src!r}]"][:order + 1]
    lines = []
    for letter, point in zip("pqr", points):
        lines += [f"    {letter}{i} = {point}[{i}]" for i in range(n)]
    if order == 1:  # history._newton_form(2, n), line by line
        lines.append(f"    a = 1.0 / ({xs[1]} - {xs[0]})")
        for i in range(n):
            lines += [f"    {prefix}d{i} = a * (q{i} - p{i})",
                      f"    {prefix}v{i} = p{i} - {xs[0]} * {prefix}d{i}"]
        return lines
    x0, x1, x2 = xs  # history._newton_form(3, n)
    lines += [f"    a, b, c = 1.0 / ({x1} - {x0}), 1.0 / ({x2} - {x1}), 1.0 / ({x2} - {x0})",
              f"    x0x1, x01 = {x0} * {x1}, {x0} + {x1}"]
    for i in range(n):
        lines += [f"    f = a * (q{i} - p{i})", f"    g = c * (b * (r{i} - q{i}) - f)",
                  f"    {prefix}v{i} = p{i} - {x0} * f + x0x1 * g",
                  f"    {prefix}d{i} = f - x01 * g", f"    {prefix}s{i} = 2.0 * g"]
    return lines


def _advance(k: int, comp: str, system, order: int, current: dict, ports: bool) -> list[str]:
    """FMU k's external inputs (a time table), its inputs' rows written, its doStep (timed into
    its statistics as FmuInstance.do_step), and the rows it saw kept for the port energies."""
    lines = [f"    fmu_c = F{k}._component"]
    if system.external_varies[comp]:
        lines.insert(0, f"    set_external({comp!r}, t)")
    feeds = [(current[src], i) for src, i in system.in_sources[comp]]
    rows = {"v": [f"{p}v{i}" for p, i in feeds]}
    if order >= 1:
        rows["d"] = [f"{p}d{i}" for p, i in feeds]
    if order == 2:
        rows["s"] = [f"{p}s{i}" for p, i in feeds]
    if feeds:
        lines += [f"    B_IN{k}[{j}] = {name}" for j, name in enumerate(rows["v"])]
        lines += _call(f"SET{k}(fmu_c, VR_IN{k}, {len(feeds)}, B_IN{k})", "fmi2SetReal")
        if order >= 1:  # d2 stays 0.0 at order 1: the generic writer's zeros
            derivatives = rows["d"] + rows.get("s", [])
            lines += [f"    B_D{k}[{j}] = {name}" for j, name in enumerate(derivatives)]
            lines += _call(f"SET{k}(fmu_c, VR_D{k}, {2 * len(feeds)}, B_D{k})", "fmi2SetReal")
    lines += ["    start = clock()", f"    status = STEP{k}(fmu_c, t, h, 1)",
              f"    S{k}.do_step_seconds += clock() - start",
              "    if status > WARNING:",
              "        raise FMICallException(function='fmi2DoStep', status=status)",
              f"    S{k}.do_step_calls += 1"]
    if ports:  # the gathered rows, as the generic sweep keeps them (a value row at order 0)
        kept = ", ".join("[" + ", ".join(names) + "]" for names in rows.values()) \
            if feeds else "[]"
        lines.append(f"    seen[{comp!r}] = ([{kept}], h)")
    return lines


def _read(k: int, comp: str, n: int) -> list[str]:
    """FMU k's n connected outputs read into a new list (System.refresh_outputs): N{k}."""
    if not n:  # nothing to read: no FMI call (FmuInstance.reader)
        return [f"    N{k} = outputs[{comp!r}] = []"]
    return [*_call(f"GET{k}(F{k}._component, VR_OUT{k}, {n}, B_OUT{k})",
                   "fmi2GetReal"), f"    N{k} = outputs[{comp!r}] = VIEW{k}.tolist()"]


def _call(call: str, function: str) -> list[str]:
    return [f"    status = {call}", "    if status > WARNING:",
            f"        raise FMICallException(function={function!r}, status=status)"]
