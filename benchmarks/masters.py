"""What the masters cost: their own overhead per macro step, and wall time per accuracy.

    python benchmarks/masters.py [--steps N] [--stop-time T] [--out DIR] [--quick] [--skip a,b,c]

(a) Master overhead. Two no-op FMUs (no states, constant outputs: doStep returns at once),
    built by crankfmu's build machinery from the benchmark-local physics class below, are wired
    like the servo press (two connections each way, one constant external input, three recorded
    outputs each) and run through crankfmu's runner with the fixed-step masters and the adaptive
    one. In the same process the SAME FMU binaries are driven by the bare call sequence those
    masters make (fmi2SetReal of the inputs and of their derivative companions, fmi2DoStep,
    fmi2GetReal of the coupled and of the recorded outputs; for the adaptive master also
    fmi2GetFMUstate and fmi2FreeFMUstate of every FMU, every step) through fmpy's raw ctypes
    function pointers, with nothing else in the loop. The ratio crankfmu / bare is the master's
    (and runner's) own cost; targets <= 1.3 for Gauss-Seidel, <= 2 for the adaptive master.
    Per-step CPU times (time.process_time: the FMUs run in this process) are differences of a
    2N-step and an N-step run (so loading and setup cancel), medians of 7 repeats; the ratio is
    the median of the repeats' ratios (each repeat runs the runner and then the bare sequence). The runner writes no CSV here (the bare sequence writes
    no file); the CSV's cost per row is printed beside the table.
(b) Wall time to reach relative errors 1e-3 and 1e-5 (metric max of crankfmu accuracy: max over
    time of |w - w_ref| / mean|w_ref| of the crank speed) on the servo press scene, per master and
    extrapolation, read off the work-precision curve (log-log interpolation between the two runs
    that bracket the target; marked ~ when extrapolated beyond the sweep), and as ratios to the
    fastest master.
(c) The floor of issue 11's target (d) (the co-simulation reaching 1e-4 on the servo press's
    first second uses less CPU than scipy's one call): the cheapest co-simulation found by
    benchmarks/runtime.py (d) (--floor-setting), its CPU split into the FMUs' doStep and the
    rest, against scipy's RK45 in one call at rtol 1e-4, and the floor: its doStep count times
    (the bare FMI calls per step of two no-op FMUs + 6 right-hand-side calls, the fewest a
    Dormand-Prince step makes, at the composed model's cost per call).

Figures are printed, not asserted: timings depend on the machine.
"""
from __future__ import annotations

import argparse
import copy
import ctypes
import math
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
NOOP = "NoOpBench"
# (a) measures CPU time of this process (the FMUs run in it): on a shared machine wall time
# mostly measures the other processes
CLOCK = time.process_time

NOOP_SCRIPT = '''"""No-op FMU for benchmarks/masters.py (build {digest}): no states, constant outputs."""
if locals() is not globals():  # pythonfmu's findClass releases globals() after this run: see
    import ctypes as _ctypes  # crankfmu/fmu/build.py ENTRY_SCRIPT
    _ctypes.pythonapi.Py_IncRef(_ctypes.py_object(globals()))
import numpy as np
from crankfmu_rt_{digest}.runtime.slave import ModelSlave as Fmi2Slave
from crankfmu_rt_{digest}.runtime.model import PhysicsModel, Variable

_OUT = np.array([1.0, 2.0, 3.0])


class _NoOpPhysics(PhysicsModel):
    model_name = "{name}"
    description = "benchmark no-op: no states, constant outputs"
    seed = "none"
    inputs = (Variable("in_a", "1", "coupled input a"), Variable("in_b", "1", "coupled input b"),
              Variable("in_u", "1", "external input"))
    outputs = (Variable("out_a", "1", "coupled output a"), Variable("out_b", "1", "coupled output b"),
               Variable("out_c", "1", "recorded output"))

    def state_names(self):
        return ()

    def initial_state(self, u):
        return np.zeros(0)

    def derivatives(self, t, x, u):
        return np.zeros(0)

    def output_values(self, t, x, u):
        return _OUT


class {name}(Fmi2Slave):
    physics_class = _NoOpPhysics

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
'''

NOOP_SCENE = """
[scene]
name = "noop_pair"
stop_time = {stop}
[master]
algorithm = "gauss-seidel"
step = {step}
order = ["a", "b"]
[components.a]
fmu = "{fmu}"
[components.b]
fmu = "{fmu}"
[[connections]]
from = "a.out_a"
to = "b.in_a"
[[connections]]
from = "a.out_b"
to = "b.in_b"
[[connections]]
from = "b.out_a"
to = "a.in_a"
[[connections]]
from = "b.out_b"
to = "a.in_b"
[inputs]
"a.in_u" = 220.0
[record]
variables = ["a.out_a", "a.out_b", "a.out_c", "b.out_a", "b.out_b", "b.out_c"]
"""


# -- the no-op FMU, built like the catalog FMUs ------------------------------------------------
def build_noop(dest: Path) -> Path:
    return build_script_fmu(dest, NOOP, NOOP_SCRIPT)


def build_script_fmu(dest: Path, name: str, template: str, runtime: bool = True,
                     **fields) -> Path:
    """An FMU `name` from an entry-script template (formatted with digest, name and `fields`),
    with crankfmu's runtime bundled (runtime=True) and its modelDescription, or as pythonfmu
    writes it (runtime=False: a plain pythonfmu slave)."""
    from crankfmu.fmu.build import build_bundle_fmu, bundle_sources
    from crankfmu.fmu.bundle import MARK

    if runtime:  # the digest is this bundle's: its names stand for its content (fmu/bundle.py)
        model = fields.get("cls")  # a catalog model the script subclasses: bundled as well
        script = template.format(digest=MARK, name=name, **fields)
        return build_bundle_fmu(dest, bundle_sources(model, name, script), name)
    from pythonfmu.builder import FmuBuilder
    dest.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="crankfmu_bench_") as tmp:
        script = Path(tmp) / f"{name}.py"
        script.write_text(template.format(name=name, **fields))
        try:
            built = FmuBuilder.build_FMU(script, dest=Path(tmp) / "out")
            target = dest / f"{name}.fmu"
            target.write_bytes(built.read_bytes())
        finally:  # what the builder left: its folder on sys.path, the script imported from it
            if tmp in sys.path:
                sys.path.remove(tmp)
            sys.modules.pop(name, None)
    return target


def noop_scene(fmu: Path, folder: Path, step: float, stop: float):
    from crankfmu.system.load import load_scene

    path = folder / "noop_pair.toml"
    path.write_text(NOOP_SCENE.format(stop=stop, step=step, fmu=fmu.as_posix()))
    return load_scene(path)


# -- (a) master overhead ---------------------------------------------------------------------------
def crankfmu_seconds(scene, algorithm: str, extrapolation: int, n: int) -> tuple[float, int]:
    """(CPU time, communication steps) of the runner between an n-grid-step run and a 2n one
    (so loading and initialization cancel). No CSV is written: the bare sequence writes no
    file either, and writing one is output, not stepping (its cost: csv_seconds)."""
    from crankfmu.cosim.runner import RunOptions, run_scene

    cpu, steps = [], []
    for k in (1, 2):
        trial = copy.deepcopy(scene)
        trial.master.algorithm, trial.master.extrapolation = algorithm, extrapolation
        trial.stop_time = trial.start_time + k * n * trial.master.step
        trial.master.max_steps = 10**12  # the adaptive master's min_step bound, not its steps
        if algorithm == "adaptive":  # rows the run may record are bounded by stop / min_step
            trial.master.min_step = trial.master.step
        start = CLOCK()
        result = run_scene(trial, RunOptions(out=None, progress=False))
        cpu.append(CLOCK() - start)
        steps.append(result.steps)
    return cpu[1] - cpu[0], steps[1] - steps[0]


def csv_seconds(scene, n: int, out: Path, repeats: int = 5) -> float:
    """CPU per row of writing the run's CSV (Gauss-Seidel, extrapolation 0, a row per step):
    the runner with `out` minus without, both of n steps (median of `repeats`)."""
    from crankfmu.cosim.runner import RunOptions, run_scene

    per_row = []
    for _ in range(repeats):
        cpu = []
        for options in (RunOptions(out=None, progress=False),
                        RunOptions(out=out / "noop.csv", progress=False)):
            trial = copy.deepcopy(scene)
            trial.stop_time = trial.start_time + n * trial.master.step
            start = CLOCK()
            run_scene(trial, options)
            cpu.append(CLOCK() - start)
        per_row.append((cpu[1] - cpu[0]) / n)
    return statistics.median(per_row)


class BareFmu:
    """One initialized FMU instance with raw ctypes calls for a fixed value-reference set."""

    def __init__(self, name: str, path: Path, inputs, coupled, recorded):
        from crankfmu.fmu.instance import FmuInstance, LogCollector

        self.log = LogCollector()  # same callbacks as the runner gives its instances
        self.fmu = FmuInstance(name, path, self.log)
        self.fmu.instantiate(logging_on=True)
        self.fmu.setup(0.0, 1e9, 1e-8)
        self.fmu.slave.enterInitializationMode()
        self.fmu.set_start_values({"in_u": 220.0})
        self.fmu.slave.exitInitializationMode()
        f = self.fmu.slave._functions
        self.c = self.fmu.slave.component
        self.set_real, self.get_real, self.do_step = (f["fmi2SetReal"], f["fmi2GetReal"],
                                                      f["fmi2DoStep"])
        self.get_state, self.free_state = f["fmi2GetFMUstate"], f["fmi2FreeFMUstate"]
        self.vr_in, self.buf_in = self._vrs(inputs)
        self.vr_out, self.buf_out = self._vrs(coupled)
        self.vr_rec, self.buf_rec = self._vrs(recorded)
        self.vr_d, self.buf_d = self._vrs([f"{n}_{d}" for d in ("d1", "d2") for n in inputs])

    def _vrs(self, names):
        from fmpy.fmi2 import fmi2Real, fmi2ValueReference
        vr = (fmi2ValueReference * len(names))(*[self.fmu.variable(n).valueReference
                                                 for n in names])
        return vr, (fmi2Real * len(names))()

    def close(self) -> None:
        self.fmu.terminate()


def bare_seconds(fmu_path: Path, algorithm: str, extrapolation: int, n: int,
                 step: float) -> float:
    """The same FMI calls per step as the masters (Gauss-Seidel: set, doStep, get per FMU in
    order; Jacobi: set+doStep for both, then get for both; with extrapolation >= 1 also the set
    of the input-derivative companions <input>_d1, _d2), then the recorded outputs. The adaptive
    master's accepted step (no step is rejected here: the outputs are constant, the error 0) is
    Gauss-Seidel's between fmi2GetFMUstate of every FMU (the state it could roll back to) and
    fmi2FreeFMUstate of every FMU."""
    from fmpy.fmi2 import fmi2FMUstate

    a = BareFmu("a", fmu_path, ["in_a", "in_b"], ["out_a", "out_b"], ["out_a", "out_b", "out_c"])
    b = BareFmu("b", fmu_path, ["in_a", "in_b"], ["out_a", "out_b"], ["out_a", "out_b", "out_c"])
    pairs = ((a, b), (b, a))  # (fmu, the fmu its inputs come from)
    rollback = algorithm == "adaptive"
    states = [fmi2FMUstate() for _ in pairs]
    try:
        for fmu, _ in pairs:
            fmu.get_real(fmu.c, fmu.vr_out, 2, fmu.buf_out)
        start = CLOCK()
        t = 0.0
        for _ in range(n):
            if rollback:
                for (fmu, _), state in zip(pairs, states):
                    _check(fmu.get_state(fmu.c, ctypes.byref(state)))
            if algorithm == "jacobi":
                for fmu, src in pairs:
                    fmu.buf_in[0], fmu.buf_in[1] = src.buf_out[0], src.buf_out[1]
            for fmu, src in pairs:
                if algorithm != "jacobi":
                    fmu.buf_in[0], fmu.buf_in[1] = src.buf_out[0], src.buf_out[1]
                _check(fmu.set_real(fmu.c, fmu.vr_in, 2, fmu.buf_in))
                if extrapolation:
                    _check(fmu.set_real(fmu.c, fmu.vr_d, 4, fmu.buf_d))
                _check(fmu.do_step(fmu.c, t, step, 1))
                if algorithm != "jacobi":
                    _check(fmu.get_real(fmu.c, fmu.vr_out, 2, fmu.buf_out))
            if algorithm == "jacobi":
                for fmu, _ in pairs:
                    _check(fmu.get_real(fmu.c, fmu.vr_out, 2, fmu.buf_out))
            if rollback:
                for (fmu, _), state in zip(pairs, states):
                    _check(fmu.free_state(fmu.c, ctypes.byref(state)))
            for fmu, _ in pairs:
                _check(fmu.get_real(fmu.c, fmu.vr_rec, 3, fmu.buf_rec))
            t += step
        return CLOCK() - start
    finally:
        a.close()
        b.close()


def _check(status: int) -> None:
    if status > 1:
        raise RuntimeError(f"FMI call returned status {status}")


OVERHEAD_MASTERS = ("gauss-seidel", "jacobi", "adaptive")


def overhead_table(fmu: Path, folder: Path, n: int, repeats: int = 7) -> list[tuple]:
    """(master, extrapolation, crankfmu per step, bare per step, ratio) per row: medians over
    `repeats`, each repeat running the runner and the bare sequence one after the other and
    giving one ratio (a load on the machine then falls on both alike). The adaptive master's
    steps grow to max_step on the constant outputs: its figures are per step it took, the bare
    sequence makes as many."""
    from crankfmu.masters import MASTERS

    step = 1e-3
    scene = noop_scene(fmu, folder, step, n * step)
    rows = []
    bare_seconds(fmu, "gauss-seidel", 0, n // 10, step)  # warm-up: first calls load code
    for algorithm in [a for a in OVERHEAD_MASTERS if a in MASTERS]:
        for ex in (0, 1, 2):
            ours, bare = [], []
            for _ in range(repeats):
                seconds, steps = crankfmu_seconds(scene, algorithm, ex, n)
                ours.append(seconds / steps)
                bare.append(bare_seconds(fmu, algorithm, ex, steps, step) / steps)
            rows.append((algorithm, ex, statistics.median(ours), statistics.median(bare),
                         statistics.median(a / b for a, b in zip(ours, bare))))
    return rows


# -- (b) wall time per accuracy --------------------------------------------------------------------
def time_to_reach(points: list[tuple[float, float]], target: float) -> tuple[float, bool]:
    """(wall time at which the work-precision curve reaches `target`, extrapolated?) from
    (wall, error) points: log-log interpolation between the cheapest run meeting the target and
    the most accurate run missing it; beyond the sweep, the line through the two most accurate
    (or the two cheapest) runs."""
    pts = sorted((w, e) for w, e in points if math.isfinite(e) and e > 0 and w > 0)
    if len(pts) < 2:
        return math.nan, True
    meet = [p for p in pts if p[1] <= target]
    miss = [p for p in pts if p[1] > target]
    if meet and miss:
        lo = min(meet)
        hi = min(miss, key=lambda p: p[1])
        pair, extrapolated = (hi, lo), False
    elif meet:   # every run meets it: extrapolate towards cheaper runs
        pair, extrapolated = tuple(sorted(pts)[:2]), True
    else:        # none does: extrapolate from the most accurate two
        pair, extrapolated = tuple(sorted(pts, key=lambda p: p[1])[:2]), True
    (w1, e1), (w2, e2) = pair
    if e1 == e2 or w1 == w2:
        return (w1 if e1 <= target else math.nan), extrapolated
    slope = math.log(w2 / w1) / math.log(e2 / e1)
    return w1 * (target / e1) ** slope, extrapolated


def accuracy_table(out: Path, stop: float, fmu_dir: Path | None, quick: bool):
    from crankfmu.studies.accuracy import AccuracyOptions, format_orders, run_accuracy
    from crankfmu.system.load import load_scene

    scene = load_scene(ROOT / "scenarios" / "servo_press.toml")
    scene.stop_time = stop
    steps = [8e-3, 4e-3, 2e-3, 1e-3] + ([] if quick else [5e-4, 2.5e-4])
    result = run_accuracy(scene, AccuracyOptions(out_dir=out, steps=steps, fmu_dir=fmu_dir,
                                                 tolerances=[1e-2, 1e-3, 1e-4]))
    curves: dict[tuple, list] = {}
    for o in result.outcomes:
        if o.ok:
            curves.setdefault((o.setting.algorithm, o.setting.extrapolation), []).append(
                (o.wall_seconds, o.error))
    return result, curves, format_orders(result.orders)


def print_accuracy(curves: dict, targets=(1e-3, 1e-5)) -> None:
    reach = {key: [time_to_reach(pts, t) for t in targets] for key, pts in curves.items()}
    best = [min((r[k][0] for r in reach.values() if math.isfinite(r[k][0])), default=math.nan)
            for k in range(len(targets))]
    head = f"{'master':<13} {'ex':>2}" + "".join(
        f"  {'wall @ %g [s]' % t:>16} {'ratio':>7}" for t in targets)
    print(head)
    print("-" * len(head))
    for (alg, ex), r in sorted(reach.items()):
        cells = ""
        for k, (wall, extrapolated) in enumerate(r):
            mark = "~" if extrapolated else " "
            cells += f"  {mark}{wall:>15.3g} {wall / best[k]:>7.2f}"
        print(f"{alg:<13} {ex:>2}{cells}")
    print("(~: outside the swept range, extrapolated along the work-precision line; ratio: to "
          "the fastest setting for that target)")


# -- (c) the floor of the co-simulation's CPU against scipy's one call (issue 11, target d) ------
RK_STAGES = 6  # new right-hand-side calls per Dormand-Prince 5(4) step (FSAL): the fewest an
#                FMU's doStep can make (one internal step per communication step)


def floor_table(out: Path, setting: tuple, target: float = 1e-4, repeats: int = 3) -> None:
    """The servo press's first second: the co-simulation `setting` = (algorithm,
    extrapolation, step, tolerance) and scipy's RK45 in one call at rtol `target` (both reach
    `target` in benchmarks/runtime.py (d)), with the co-simulation's CPU split into the FMUs'
    doStep and the rest (master, runner, fmi2Set/GetReal), and its floor:
        doStep calls x (bare FMI calls per step of 2 no-op FMUs + RK_STAGES x the composed
        right-hand side's cost per call),
    what a co-simulation with that many communication steps costs with a master and an FMU
    runtime that cost nothing beyond the FMI calls and the fewest right-hand-side calls."""
    from scipy.integrate import solve_ivp

    from crankfmu.studies.accuracy import make_metric
    from crankfmu.studies.accuracy.sweep import load_or_solve_reference
    from crankfmu.fmu import instance as fmu_module
    from crankfmu.masters import sweep_code
    from crankfmu.cosim.runner import RunOptions, run_scene
    from crankfmu.monolithic.composed import ComposedModel
    from crankfmu.monolithic.solve import RecordMap, record_times
    from crankfmu.system.load import load_scene

    scene = load_scene(ROOT / "scenarios" / "servo_press.toml")
    scene.stop_time = 1.0
    metric = make_metric("max", scene.record)
    grid = record_times(scene)
    (out / "reference").mkdir(parents=True, exist_ok=True)  # write_run_set needs the folder
    ref, _, _ = load_or_solve_reference(scene, grid, out / "reference", 1e-10)
    algorithm, ex, step, tol = setting
    trial = copy.deepcopy(scene)
    m = trial.master
    m.algorithm, m.extrapolation, m.step = algorithm, ex, step
    if tol is not None:
        m.tolerance = tol
    in_do_step = [0.0]
    original = fmu_module.FmuInstance.do_step

    def timed_do_step(self, t, h):
        start = CLOCK()
        try:
            original(self, t, h)
        finally:
            in_do_step[0] += CLOCK() - start
    runs = []
    fmu_module.FmuInstance.do_step = timed_do_step
    # the generic sweep, whose doStep goes through the wrapper timed above (a written sweep,
    # masters/sweep_code.py, calls the same FMI function directly)
    write_sweep, sweep_code.write_sweep = sweep_code.write_sweep, lambda master, sequential: None
    try:
        for _ in range(repeats):
            in_do_step[0] = 0.0
            result = run_scene(copy.deepcopy(trial), RunOptions(out=out / "floor.csv",
                                                                progress=False))
            runs.append((result.cpu_seconds, in_do_step[0], result))
    finally:
        fmu_module.FmuInstance.do_step = original
        sweep_code.write_sweep = write_sweep
    cpu, inside, result = sorted(runs, key=lambda r: r[0])[len(runs) // 2]
    rec = result.recorder
    error = metric.error(rec.rows[:, 0], {k: rec.column(k) for k in rec.names}, ref)
    calls = max(s["doStep_calls"] for s in result.statistics.values())
    noop = build_noop(out / "noop_fmu")
    bare = min(bare_seconds(noop, "gauss-seidel", min(ex, 1), 2000, step) for _ in range(5)) / 2000
    model = ComposedModel(scene)
    x0 = np.asarray(model.initial_state(t0=scene.start_time), dtype=float)
    rhs = min(_per_call(lambda: model.derivatives(0.0, x0, []), 2000) for _ in range(5))
    scipy_runs = []
    for _ in range(5):
        start = CLOCK()
        sol = solve_ivp(lambda t, y: model.derivatives(t, y, []), (scene.start_time, 1.0), x0,
                        method="RK45", rtol=target, atol=target * model.state_nominal(),
                        t_eval=grid)
        scipy_runs.append(CLOCK() - start)
    rows = RecordMap(model)
    values = np.array([rows.row(t, y) for t, y in zip(sol.t, sol.y.T)])
    scipy_error = metric.error(sol.t, {n: values[:, k] for k, n in enumerate(scene.record)}, ref)
    scipy_cpu = sorted(scipy_runs)[2]
    floor = calls * (bare + RK_STAGES * rhs)
    label = f"{algorithm} ex{ex} " + (f"tol {tol:g}" if tol is not None else f"h {step:g}")
    print(f"co-simulation {label}: error {error:.2e}, {calls} doStep calls per FMU, CPU "
          f"{cpu:.4f} s = {inside:.4f} s in doStep (FMU runtime and physics) + "
          f"{cpu - inside:.4f} s master, runner, set/get")
    print(f"scipy RK45 one call, rtol {target:g}: error {scipy_error:.2e}, {sol.nfev} right-hand "
          f"side calls ({sol.nfev / RK_STAGES:.0f} steps), CPU {scipy_cpu:.4f} s")
    print(f"composed right-hand side: {rhs * 1e6:.1f} us per call; bare FMI calls of 2 no-op "
          f"FMUs: {bare * 1e6:.1f} us per communication step")
    print(f"floor of this co-simulation: {calls} x ({bare * 1e6:.1f} + {RK_STAGES} x "
          f"{rhs * 1e6:.1f}) us = {floor:.4f} s")
    print(f"ratios to scipy: co-simulation {cpu / scipy_cpu:.2f}, doStep alone "
          f"{inside / scipy_cpu:.2f}, floor {floor / scipy_cpu:.2f} (target < 1)")


def _per_call(call, n: int) -> float:
    start = CLOCK()
    for _ in range(n):
        call()
    return (CLOCK() - start) / n


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=10000, help="macro steps for (a)")
    parser.add_argument("--stop-time", type=float, default=0.5, help="servo press run [s], (b)")
    parser.add_argument("--out", type=Path, default=Path(tempfile.gettempdir()) / "crankfmu_bench")
    parser.add_argument("--fmus", type=Path, help="folder of built catalog FMUs for (b)")
    parser.add_argument("--quick", action="store_true", help="fewer steps in (b)")
    parser.add_argument("--skip", default="", help="parts to skip, e.g. a,b")
    parser.add_argument("--floor-setting", default="adaptive,2,1e-3,3e-4",
                        help="(c): algorithm,extrapolation,step,tolerance ('-': none) of the "
                             "cheapest co-simulation reaching 1e-4 (benchmarks/runtime.py (d))")
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    skip = set(args.skip.split(","))
    if "a" not in skip:
        fmu = build_noop(args.out / "noop_fmu")
        print(f"(a) master overhead per macro step, 2 no-op FMUs ({fmu.name}), "
              f"{args.steps} grid steps, CPU time per step and their ratio, medians of 7")
        print(f"{'master':<13} {'ex':>2} {'crankfmu [us]':>14} {'bare FMI [us]':>14} {'ratio':>6}")
        for alg, ex, ours, bare, ratio in overhead_table(fmu, args.out, args.steps):
            print(f"{alg:<13} {ex:>2} {ours * 1e6:>14.1f} {bare * 1e6:>14.1f} {ratio:>6.2f}")
        scene = noop_scene(fmu, args.out, 1e-3, args.steps * 1e-3)
        print(f"targets: ratio <= 1.3 (Gauss-Seidel), <= 2 (adaptive: its bare sequence saves "
              f"and frees every FMU's state each step). Not in the figures: writing the CSV, "
              f"{csv_seconds(scene, args.steps, args.out) * 1e6:.1f} us per row\n")
    if "b" not in skip:
        print(f"(b) servo press, 0 to {args.stop_time:g} s: wall time to reach a relative error")
        result, curves, orders = accuracy_table(args.out / "accuracy", args.stop_time,
                                                args.fmus, args.quick)
        print(f"error = {result.metric.describe()}")
        print_accuracy(curves)
        print(orders)
        print(f"work-precision plot: {result.png}")
    if "c" not in skip:
        alg, ex, step, tol = args.floor_setting.split(",")
        print("\n(c) servo press 0-1 s at 1e-4: the co-simulation's CPU, its floor, scipy's "
              "one call")
        floor_table(args.out, (alg, int(ex), float(step), None if tol == "-" else float(tol)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
