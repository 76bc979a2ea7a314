"""What the FMU runtime costs: the figures of the fast-runtime issue, side by side in one run.

    python benchmarks/runtime.py [--steps N] [--repeats R] [--out DIR] [--skip a,b,c,d]

(a) Servo press (Gauss-Seidel, 1 ms) against the same master over two no-op FMUs with the same
    variables (DcServoMotor and StephensonPress with their physics replaced by constant outputs):
    CPU per macro step of each, their ratio (target <= 2.5), and the servo press's wall time per
    simulated second over its full 3 s scene (target <= 0.1 s).
(b) One no-op crankfmu FMU's fmi2SetReal + fmi2DoStep + fmi2GetReal against the same on a minimal
    pythonfmu slave (plain Fmi2Slave, same number of inputs and outputs, attributes as variables):
    CPU per call triple, raw ctypes calls (target: ratio <= 1.5).
(c) The cost of each effect: every catalog FMU alone on its start values, 1 ms steps, with no
    effect, with each effect alone and with all: CPU per doStep.
(d) The servo press's first second to a relative error of 1e-4 (crankfmu accuracy's "max"
    metric on the crank speed, against the rtol 1e-10 reference): the cheapest co-simulation
    found among a few settings against scipy's solve_ivp of the same equations (the composed
    monolithic model) in ONE call, at the loosest rtol that reaches 1e-4 (target: co-simulation
    CPU below scipy's). CPU of the solve only on both sides: the run's cpu_seconds (FMU
    initialization, steps, release), not loading the FMUs; solve_ivp's call, not building the
    composed model.

CPU is time.process_time (the FMUs run in this process); per-step figures are differences of a
2N- and an N-step run (loading and setup cancel), the median of the repeats. Printed, not
asserted: the machine is shared.
"""
from __future__ import annotations

import argparse
import copy
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from masters import BareFmu, build_script_fmu  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
CLOCK = time.process_time
SERVO_PRESS = ROOT / "scenarios" / "servo_press.toml"

NOOP_LIKE = '''"""A {cls} with its physics replaced by constant outputs (benchmarks/runtime.py)."""
if locals() is not globals():  # see crankfmu/fmu/build.py ENTRY_SCRIPT
    import ctypes as _ctypes
    _ctypes.pythonapi.Py_IncRef(_ctypes.py_object(globals()))
from crankfmu_rt_{digest}.runtime.slave import ModelSlave as Fmi2Slave
from crankfmu_rt_{digest}.models.{module} import {cls} as _Physics


class _NoOp(_Physics):
    model_name = "{name}"

    def state_names(self):
        return ()

    def initial_state(self, u):
        return []

    def advance(self, t0, x0, h, u_of_t, rtol, atol):
        return x0

    def output_values(self, t, x, u):
        return [1.0] * len(self.outputs)


class {name}(Fmi2Slave):
    physics_class = _NoOp
'''

MINIMAL_PYTHONFMU = '''"""A minimal pythonfmu slave: {n_in} inputs, {n_out} outputs, doStep does nothing."""
from pythonfmu import Fmi2Causality, Fmi2Slave, Fmi2Variability, Real


class {name}(Fmi2Slave):
    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        for k in range({n_in}):
            setattr(self, f"in_{{k}}", 0.0)
            self.register_variable(Real(f"in_{{k}}", causality=Fmi2Causality.input,
                                        variability=Fmi2Variability.continuous))
        for k in range({n_out}):
            setattr(self, f"out_{{k}}", 1.0)
            self.register_variable(Real(f"out_{{k}}", causality=Fmi2Causality.output,
                                        variability=Fmi2Variability.continuous))

    def do_step(self, current_time, step_size):
        return True
'''


def median_of(repeats: int, measure) -> float:
    return statistics.median(measure() for _ in range(repeats))


def run_cpu_per_step(scene, n: int, folder: Path, fmu_dir: Path | None = None) -> float:
    """CPU per macro step of the runner: a 2n-step run minus an n-step run."""
    from crankfmu.cosim.runner import RunOptions, run_scene

    cpu = []
    for k in (1, 2):
        trial = copy.deepcopy(scene)
        trial.stop_time = trial.start_time + k * n * trial.master.step
        start = CLOCK()
        run_scene(trial, RunOptions(out=folder / "run.csv", fmu_dir=fmu_dir, progress=False))
        cpu.append(CLOCK() - start)
    return (cpu[1] - cpu[0]) / n


# -- (a) ---------------------------------------------------------------------------------------
def part_a(out: Path, n: int, repeats: int) -> None:
    from crankfmu.cosim.runner import RunOptions, run_scene
    from crankfmu.system.load import load_scene

    scene = load_scene(SERVO_PRESS)
    noop_dir = out / "noop_like"
    for cls, module in (("DcServoMotor", "dc_motor.dc_motor"),
                        ("StephensonPress", "stephenson_press.stephenson_press")):
        build_script_fmu(noop_dir, f"NoOp{cls}", NOOP_LIKE, cls=cls, module=module)
    noop = copy.deepcopy(scene)
    for comp in noop.components.values():
        comp.fmu = str(noop_dir / f"NoOp{comp.fmu}.fmu")
        comp.parameters, comp.effects = {}, []
    run_cpu_per_step(scene, n // 10, out)  # warm-up: builds, first loads
    press = median_of(repeats, lambda: run_cpu_per_step(scene, n, out))
    base = median_of(repeats, lambda: run_cpu_per_step(noop, n, out))
    walls = []
    for _ in range(repeats):
        result = run_scene(copy.deepcopy(scene), RunOptions(out=out / "full.csv", progress=False))
        walls.append(result.wall_seconds / (scene.stop_time - scene.start_time))
    print(f"(a) servo press, Gauss-Seidel 1 ms, CPU per macro step (median of {repeats}, "
          f"{n} steps)")
    print(f"    servo press {press * 1e6:8.1f} us   two no-op FMUs, same variables "
          f"{base * 1e6:8.1f} us   ratio {press / base:5.2f}   (target <= 2.5)")
    print(f"    wall per simulated second, full 3 s scene: {statistics.median(walls):.3f} s "
          f"(target <= 0.1)\n")


# -- (b) ---------------------------------------------------------------------------------------
def _triple_seconds(fmu: BareFmu, n: int) -> float:
    set_real, get_real, do_step, c = fmu.set_real, fmu.get_real, fmu.do_step, fmu.c
    n_in, n_out = len(fmu.vr_in), len(fmu.vr_out)
    start = CLOCK()
    t = 0.0
    for _ in range(n):
        set_real(c, fmu.vr_in, n_in, fmu.buf_in)
        do_step(c, t, 1e-3, 1)
        get_real(c, fmu.vr_out, n_out, fmu.buf_out)
        t += 1e-3
    return (CLOCK() - start) / n


class _PlainFmu(BareFmu):
    """BareFmu for an FMU without crankfmu's companions or parameters."""

    def __init__(self, name, path, inputs, outputs):
        from fmpy import read_model_description
        from fmpy.fmi2 import FMU2Slave

        from fmpy import extract
        md = read_model_description(str(path), validate=False)
        self.refs = {v.name: v.valueReference for v in md.modelVariables}
        self.slave = FMU2Slave(guid=md.guid, unzipDirectory=extract(str(path)),
                               modelIdentifier=md.coSimulation.modelIdentifier,
                               instanceName=name)
        self.slave.instantiate()
        self.slave.setupExperiment(startTime=0.0)
        self.slave.enterInitializationMode()
        self.slave.exitInitializationMode()
        f = self.slave._functions
        self.c = self.slave.component
        self.set_real, self.get_real, self.do_step = (f["fmi2SetReal"], f["fmi2GetReal"],
                                                      f["fmi2DoStep"])
        self.vr_in, self.buf_in = self._vrs(inputs)
        self.vr_out, self.buf_out = self._vrs(outputs)

    def _vrs(self, names):
        from fmpy.fmi2 import fmi2Real, fmi2ValueReference
        return ((fmi2ValueReference * len(names))(*[self.refs[n] for n in names]),
                (fmi2Real * len(names))())

    def close(self) -> None:
        self.slave.terminate()


def part_b(out: Path, n: int, repeats: int) -> None:
    from masters import build_noop
    noop = build_noop(out / "noop")
    inputs, outputs = ["in_a", "in_b", "in_u"], ["out_a", "out_b", "out_c"]
    plain = build_script_fmu(out / "plain", "MinimalBench", MINIMAL_PYTHONFMU, runtime=False,
                             n_in=len(inputs), n_out=len(outputs))
    ours = BareFmu("ours", noop, inputs[:2], outputs[:2], outputs)
    ours.vr_in, ours.buf_in = ours._vrs(inputs)
    ours.vr_out, ours.buf_out = ours._vrs(outputs)
    theirs = _PlainFmu("plain", plain, [f"in_{k}" for k in range(3)],
                       [f"out_{k}" for k in range(3)])
    try:
        for fmu in (ours, theirs):
            _triple_seconds(fmu, n // 10)
        a = median_of(repeats, lambda: _triple_seconds(ours, n))
        b = median_of(repeats, lambda: _triple_seconds(theirs, n))
    finally:
        ours.close()
        theirs.close()
    print(f"(b) setReal(3) + doStep + getReal(3), CPU per triple (median of {repeats}, {n} calls)")
    print(f"    no-op crankfmu FMU {a * 1e6:6.1f} us   minimal pythonfmu slave {b * 1e6:6.1f} us"
          f"   ratio {a / b:5.2f}   (target <= 1.5)\n")


# -- (c) ---------------------------------------------------------------------------------------
def _alone_seconds(fmu_path: Path, model, effects: list[str], n: int,
                   parameters: dict | None = None) -> float | str:
    from crankfmu.fmu.instance import FmuInstance, LogCollector

    log = LogCollector()
    fmu = FmuInstance("alone", fmu_path, log)
    try:
        fmu.instantiate()
        fmu.setup(0.0, 1e9, 1e-8)
        fmu.slave.enterInitializationMode()
        fmu.set_start_values({f"effect_{e.name}": e.name in effects for e in model.effects}
                             | (parameters or {}))
        fmu.slave.exitInitializationMode()
        do_step, c = fmu.slave._functions["fmi2DoStep"], fmu.slave.component
        start = CLOCK()
        for k in range(n):
            if do_step(c, k * 1e-3, 1e-3, 1) > 1:
                return "fails: " + "; ".join(log.errors_of("alone"))[:60]
        return (CLOCK() - start) / n
    except Exception as err:  # noqa: BLE001 - a model that cannot run alone is reported
        return f"fails: {str(err)[:60]}"
    finally:
        try:
            fmu.terminate()
        except Exception:  # noqa: BLE001 - an FMU in error state refuses fmi2Terminate
            pass


def part_c(n: int) -> None:
    from crankfmu.fmu.build import build_all
    from crankfmu.models.catalog import FMU_MODELS, physics_class

    fmu_dir = ROOT / "fmus"
    build_all(fmu_dir, check=False) if not all(
        (fmu_dir / f"{m}.fmu").is_file() for m in FMU_MODELS) else None
    print(f"(c) each FMU alone on its start values, 1 ms steps: CPU per doStep [us] ({n} steps)")
    for name in FMU_MODELS:
        model = physics_class(name)
        cases = [("no effect", [])] + [(e.name, [e.name]) for e in model.effects]
        if len(model.effects) > 1:
            cases.append(("all", [e.name for e in model.effects]))
        cells = []
        for label, effects in cases:
            seconds = _alone_seconds(fmu_dir / f"{name}.fmu", model, effects, n)
            cells.append(f"{label} {seconds * 1e6:.1f}" if isinstance(seconds, float)
                         else f"{label} {seconds}")
        print(f"    {name:<21} " + " | ".join(cells))
    motor = physics_class("DcServoMotor")
    lag = [min(_alone_seconds(fmu_dir / "DcServoMotor.fmu", motor, ["electrical_lag"], n,
                              {"L_a": tau * 0.5, "flange_w": 10.0}) for _ in range(3))
           for tau in (1e-6, 1e-2)]  # best of 3: the first call of a process pays for imports
    print(f"    DcServoMotor, electrical_lag with tau = 1e-6 s: {lag[0] * 1e6:.1f} us, with "
          f"tau = 1e-2 s: {lag[1] * 1e6:.1f} us (R_a = 0.5 ohm; ratio {lag[0] / lag[1]:.2f})")
    print()


# -- (d) ---------------------------------------------------------------------------------------
def part_d(out: Path, target: float = 1e-4) -> None:
    from scipy.integrate import solve_ivp

    from crankfmu.studies.accuracy import make_metric
    from crankfmu.studies.accuracy.sweep import load_or_solve_reference
    from crankfmu.cosim.runner import RunOptions, run_scene
    from crankfmu.monolithic.composed import ComposedModel
    from crankfmu.monolithic.solve import RecordMap, record_times
    from crankfmu.system.load import load_scene

    scene = load_scene(SERVO_PRESS)
    scene.stop_time = 1.0
    metric = make_metric("max", scene.record)
    grid = record_times(scene)
    (out / "reference").mkdir(parents=True, exist_ok=True)  # write_run_set needs the folder
    ref, _, _ = load_or_solve_reference(scene, grid, out / "reference", 1e-10)
    candidates = [("adaptive", 2, 1e-3, tol) for tol in (1e-3, 3e-4, 1e-4)] + \
        [("gauss-seidel", 2, h, None) for h in (2e-3, 1e-3, 5e-4)] + \
        [("jacobi", 2, h, None) for h in (1e-3, 5e-4)]
    print(f"(d) servo press 0-1 s to error <= {target:g} ({metric.describe()})")
    best = None
    for algorithm, ex, step, tol in candidates:
        trial = copy.deepcopy(scene)
        m = trial.master
        m.algorithm, m.extrapolation, m.step = algorithm, ex, step
        if tol is not None:
            m.tolerance = tol
        result = run_scene(trial, RunOptions(out=out / "cosim.csv", progress=False))
        cpu = result.cpu_seconds  # initialization, steps, release; not loading the FMUs
        rec = result.recorder
        error = metric.error(rec.rows[:, 0], {k: rec.column(k) for k in rec.names}, ref)
        label = f"{algorithm} ex{ex} " + (f"tol {tol:g}" if tol else f"h {step:g}")
        print(f"    co-simulation {label:<26} error {error:8.2e}  CPU {cpu:6.3f} s")
        if error <= target and (best is None or cpu < best[1]):
            best = (label, cpu, error)
    model = ComposedModel(scene)
    rows = RecordMap(model)
    names = list(scene.record)
    x0 = np.asarray(model.initial_state(t0=scene.start_time), dtype=float)
    mono = None
    for rtol in (1e-4, 1e-5, 1e-6, 1e-7, 1e-8, 1e-9):
        for method in ("DOP853", "RK45"):
            start = CLOCK()
            sol = solve_ivp(lambda t, y: model.derivatives(t, y, []), (scene.start_time, 1.0), x0,
                            method=method, rtol=rtol, atol=rtol * model.state_nominal(),
                            t_eval=grid)
            cpu = CLOCK() - start
            values = np.array([rows.row(t, y) for t, y in zip(sol.t, sol.y.T)])
            run = {name: values[:, k] for k, name in enumerate(names)}
            error = metric.error(sol.t, run, ref)
            print(f"    scipy {method:<6} one call, rtol {rtol:g}: error {error:8.2e}  "
                  f"CPU {cpu:6.3f} s")
            if error <= target and (mono is None or cpu < mono[1]):
                mono = (f"{method} rtol {rtol:g}", cpu, error)
    if best and mono:
        print(f"    cheapest co-simulation: {best[0]} {best[1]:.3f} s; cheapest scipy: {mono[0]} "
              f"{mono[1]:.3f} s; ratio co-simulation/scipy {best[1] / mono[1]:.2f} "
              f"(target < 1)")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=3000, help="macro steps per timing")
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--out", type=Path, default=Path(tempfile.gettempdir()) / "crankfmu_rt")
    parser.add_argument("--skip", default="", help="parts to skip, e.g. c,d")
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    skip = set(args.skip.split(","))
    if "a" not in skip:
        part_a(args.out, args.steps, args.repeats)
    if "b" not in skip:
        part_b(args.out, args.steps * 3, args.repeats)
    if "c" not in skip:
        part_c(args.steps)
    if "d" not in skip:
        part_d(args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
