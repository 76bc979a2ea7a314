"""Run a scene: load the FMUs it names, wire them, initialize, step a master, write results."""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from pathlib import Path

from fmpy.fmi1 import FMICallException

from ..scenario.scene import Scene, SceneError
from .fmu import FmuInstance, LogCollector
from .masters import DivergenceError, make_master
from .results import Recorder, plot, versions, write_csv, write_sidecar
from .wiring import System, check_components, check_links, default_fmu_dir, resolve_fmu


class RunError(RuntimeError):
    """A run that stopped early; the rows computed so far were written to `csv`."""

    def __init__(self, message: str, csv: Path | None):
        self.csv = csv
        super().__init__(message + (f" (results up to then: {csv})" if csv else ""))


@dataclass
class RunResult:
    csv: Path
    sidecar: Path
    png: Path | None
    recorder: Recorder
    statistics: dict
    wall_seconds: float
    steps: int
    master_statistics: dict = field(default_factory=dict)
    coupling_error: dict = field(default_factory=dict)


@dataclass
class RunOptions:
    out: Path | None = None
    plot: bool = False
    fmu_dir: Path | None = None
    progress: bool | None = None  # None: a bar when stderr is a terminal
    verbose_log: bool = False
    extra_sidecar: dict = field(default_factory=dict)


def load_fmus(scene: Scene, fmu_dir: Path, log: LogCollector) -> dict[str, FmuInstance]:
    return {name: FmuInstance(name, resolve_fmu(scene, name, fmu_dir), log)
            for name in scene.components}


def _setup(scene: Scene, fmus: dict[str, FmuInstance], log: LogCollector) -> None:
    for name, comp in scene.components.items():
        fmu = fmus[name]
        fmu.instantiate(logging_on=True)
        fmu.setup(scene.start_time, scene.stop_time, scene.master.fmu_tolerance)
        effects = {v: v[len("effect_"):] in comp.effects for v in fmu.variables
                   if v.startswith("effect_")}
        fmu.set_start_values({**effects, **comp.parameters})
        fmu.slave.enterInitializationMode()


def _recorder(scene: Scene, fmus) -> tuple[Recorder, list]:
    names = scene.record
    units = [fmus[r.split(".", 1)[0]].variable(r.split(".", 1)[1]).unit for r in names]
    readers = []
    for comp in dict.fromkeys(r.split(".", 1)[0] for r in names):
        vars_ = [r.split(".", 1)[1] for r in names if r.split(".", 1)[0] == comp]
        readers.append((fmus[comp].reader(vars_), [names.index(f"{comp}.{v}") for v in vars_]))
    return Recorder(names, units), readers


def _sample(recorder: Recorder, readers, t: float) -> None:
    row = [0.0] * len(recorder.names)
    for read, where in readers:
        for k, v in zip(where, read().tolist()):  # Python floats: cheaper than numpy scalars
            row[k] = v
    recorder.add(t, row)


def run_scene(scene: Scene, options: RunOptions | None = None) -> RunResult:
    options = options or RunOptions()
    out = options.out or Path("results") / f"{scene.name}.csv"
    log = LogCollector(echo=options.verbose_log)
    fmus = load_fmus(scene, options.fmu_dir or default_fmu_dir(scene), log)
    check_components(scene, fmus)
    links = check_links(scene, fmus)
    system = System(scene, fmus, links)
    try:
        master = make_master(scene.master.algorithm, system, scene.master)
    except ValueError as err:  # e.g. an FMU that cannot roll back, for a master that must
        raise SceneError(scene.path, "[master]", str(err)) from None
    recorder, readers = _recorder(scene, fmus)
    h, t0 = scene.master.step, scene.start_time
    wall = time.perf_counter()
    failure = None
    step, t = 0, t0
    try:
        _setup(scene, fmus, log)
        master.initialize(t0)
        _sample(recorder, readers, t0)
        loop = _variable_steps if master.variable_step else _fixed_steps
        for step, t, t_new, record in loop(master, scene, options.progress):
            master.check_finite(t_new)
            if record:
                _sample(recorder, readers, t_new)
    except DivergenceError as err:
        failure = str(err)
    except FMICallException as err:
        failure = _fmi_failure(err, fmus, log, master.time if master.time is not None else t)
    finally:
        wall = time.perf_counter() - wall
        for fmu in fmus.values():
            try:
                fmu.terminate()
            except Exception:  # an FMU that failed may refuse to terminate; results still count
                pass
    write_csv(out, recorder)
    sidecar = out.with_suffix(".json")
    statistics = master.statistics()
    m = scene.master
    write_sidecar(sidecar, {
        "scene": str(scene.path), "name": scene.name, "status": failure or "completed",
        "start_time": t0, "stop_time": scene.stop_time,
        "master": {"algorithm": m.algorithm, "step": h, "extrapolation": m.extrapolation,
                   "tolerance": m.tolerance, "fmu_tolerance": m.fmu_tolerance,
                   "max_iterations": m.max_iterations, "min_step": m.min_step,
                   "max_step": m.max_step, "order": system.order},
        "components": {n: {"fmu": str(f.path), "parameters": scene.components[n].parameters,
                           "effects": scene.components[n].effects} for n, f in fmus.items()},
        "versions": versions(), "wall_seconds": wall, "communication_steps": step,
        "statistics": statistics, "master_statistics": master.master_statistics(),
        "coupling_error": master.coupling_error(), **options.extra_sidecar})
    if failure:
        raise RunError(failure, out)
    png = out.with_suffix(".png") if options.plot else None
    if png:
        plot(png, recorder, f"{scene.name}: {scene.master.algorithm}, step {h:g} s")
    return RunResult(out, sidecar, png, recorder, statistics, wall, step,
                     master.master_statistics(), master.coupling_error())


def _fixed_steps(master, scene: Scene, progress):
    """Steps of [master].step on the grid t0 + k h (the last one shortened to end at
    stop_time); yields (step, t, t_new, record?) with rows every [record].interval."""
    h, t0, stop = scene.master.step, scene.start_time, scene.stop_time
    n_steps = max(1, math.ceil((stop - t0) / h - 1e-9))
    every = max(1, round((scene.record_interval or h) / h))
    for step in _progress(range(1, n_steps + 1), progress, scene.name):
        t = t0 + (step - 1) * h
        master.step(t, min(h, stop - t))
        yield step, t, min(t0 + step * h, stop), step % every == 0 or step == n_steps


def _variable_steps(master, scene: Scene, progress):
    """Steps the master chooses (`next_step`); a row at every accepted point at least
    [record].interval after the last row (every accepted point without an interval), and at
    stop_time. A step that would leave less than min_step before stop_time is stretched to it."""
    t, stop = scene.start_time, scene.stop_time
    interval = scene.record_interval or 0.0
    last_row, step = t, 0
    bar = _progress(None, progress, scene.name, total=stop - t)
    while t < stop:
        h = master.next_step
        if t + h > stop - scene.master.min_step:
            h = stop - t
        taken = master.step(t, h)
        t_new = stop if taken == h and t + h >= stop - scene.master.min_step else t + taken
        step += 1
        if bar is not None:
            bar.update(t_new - t)
        record = t_new == stop or t_new - last_row >= interval * (1 - 1e-9)
        if record:
            last_row = t_new
        yield step, t, t_new, record
        t = t_new
    if bar is not None:
        bar.close()


def _fmi_failure(err, fmus, log: LogCollector, t: float) -> str:
    reasons = [f"{name}: {msg}" for name in fmus for msg in log.errors_of(name)]
    return f"FMU call failed near t = {t:.6g} s: {err}" + \
        (f"; the FMU said: {' | '.join(reasons)}" if reasons else "")


def _progress(steps, enabled, label, total=None):
    """A tqdm bar over `steps`, or (steps None) a bar over `total` seconds of simulated time."""
    if enabled is False:
        return steps
    from tqdm import tqdm
    if steps is None:
        return tqdm(total=total, desc=label, unit="s", disable=None if enabled is None else False,
                    mininterval=0.5, leave=False, bar_format="{l_bar}{bar}| {n:.3g}/{total:.3g} s")
    return tqdm(steps, desc=label, unit="step", disable=None if enabled is None else False,
                mininterval=0.5, leave=False)
