"""Co-simulation against a monolithic solve at equal error, and the Taylor coupling's orders:
the figures of issue 25, in one run.

    python benchmarks/coupling.py [--repeats R] [--target 1e-4] [--scenes servo_press,...]
        [--out DIR] [--quick] [--skip a,b,c]

(a) Per scene (default: servo_press and servo_press_speed_loop, each from 0 to 1 s), the error of
    every candidate in crankfmu accuracy's "max" metric on the crank speed (max over the record
    points of |w - w_ref| / mean|w_ref|, against the rtol 1e-10 reference) and its CPU:
    - co-simulations: a few master settings, the Taylor coupling (masters/taylor.py) among
      them; CPU = the run's cpu_seconds (FMU initialization, the steps, recording, release; not
      loading the FMUs), as benchmarks/runtime.py (d) counts it;
    - scipy's solve_ivp of the same equations (the composed monolithic model,
      reference/composed.py) in ONE call, with RK45, DOP853 and LSODA at rtol 1e-3 ... 1e-6
      (atol = rtol x the states' nominal); CPU = the solve_ivp call, not building the model.
    Every candidate runs R times, the candidates interleaved round by round (a machine shared
    with other jobs slows every candidate alike); the figure is the median. Then the cheapest
    candidate of each side that reaches the target and their ratio (the issue's target:
    co-simulation <= 1).
(b) The floor of that cheapest co-simulation: the CPU inside its FMI calls (doStep, the
    exchange's and the sweeps' setReal/getReal, state save/restore, recording reads) plus its
    setup (instantiation, initialization): what the run would cost with a master that cost
    nothing, against the same scipy solve, run after each instrumented run.
(c) The observed order of the Taylor coupling (and of extrapolation, for comparison) per master
    on the two-mass oscillator (tests/test_taylor_coupling.py), against its closed form: error
    at h = 1e-2, 5e-3, 2.5e-3 s and the slopes.

CPU is time.process_time (the FMUs run in this process). Printed, not asserted.
"""
from __future__ import annotations

import argparse
import copy
import statistics
import sys
import tempfile
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
CLOCK = time.process_time
SCENES = ("servo_press", "servo_press_speed_loop")
STOP_TIME = 1.0
SCIPY_METHODS = ("RK45", "DOP853", "LSODA")
SCIPY_RTOLS = (1e-3, 3e-4, 1e-4, 3e-5, 1e-5, 3e-6, 1e-6)
def adaptive_taylor(q: int, tolerance: float, fmu_tolerance: float, max_step: float = 0.05):
    """(label, [master] settings) of an adaptive master with a Taylor coupling."""
    label = f"adaptive taylor {q} tol {tolerance:g} max {max_step:g} ft {fmu_tolerance:g}"
    return label, dict(algorithm="adaptive", taylor=q, tolerance=tolerance, max_step=max_step,
                       fmu_tolerance=fmu_tolerance)


# (label, [master] settings): the co-simulations tried
COSIMULATIONS = (
    ("gauss-seidel ex2 h 1e-3", dict(algorithm="gauss-seidel", extrapolation=2, step=1e-3)),
    ("adaptive ex2 tol 3e-4", dict(algorithm="adaptive", extrapolation=2, tolerance=3e-4)),
    ("gauss-seidel taylor 3 h 4e-3", dict(algorithm="gauss-seidel", taylor=3, step=4e-3,
                                          fmu_tolerance=1e-6)),
    adaptive_taylor(3, 1e-3, 1e-6, max_step=1e-2),
    adaptive_taylor(3, 5e-4, 1e-6),
    adaptive_taylor(3, 2e-4, 1e-6),
    adaptive_taylor(4, 5e-4, 1e-6),
    adaptive_taylor(3, 5e-4, 1e-5),
    adaptive_taylor(4, 3e-4, 1e-5),
)


@dataclass
class Candidate:
    label: str
    run: object                       # () -> (cpu seconds, error)
    cpus: list = field(default_factory=list)
    error: float = float("nan")
    extra: str = ""

    @property
    def cpu(self) -> float:
        return statistics.median(self.cpus) if self.cpus else float("nan")


def scene_setup(name: str, out: Path):
    from crankfmu.monolithic.solve import record_times
    from crankfmu.studies.accuracy import make_metric
    from crankfmu.studies.accuracy.sweep import load_or_solve_reference
    from crankfmu.system.load import load_scene

    scene = load_scene(ROOT / "scenarios" / f"{name}.toml")
    scene.stop_time = STOP_TIME
    metric = make_metric("max", scene.record)
    folder = out / name / "reference"
    folder.mkdir(parents=True, exist_ok=True)  # write_run_set writes into an existing folder
    ref, _, _ = load_or_solve_reference(scene, record_times(scene), folder, 1e-10)
    return scene, metric, ref


def cosimulation(scene, metric, ref, settings: dict, out: Path):
    from crankfmu.cosim.runner import RunOptions, run_scene

    trial = copy.deepcopy(scene)
    for key, value in settings.items():
        setattr(trial.master, key, value)

    def run():
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # the adaptive master's first-step warning
            result = run_scene(copy.deepcopy(trial), RunOptions(out=None, fmu_dir=ROOT / "fmus",
                                                                progress=False))
        rec = result.recorder
        error = metric.error(rec.rows[:, 0], {k: rec.column(k) for k in rec.names}, ref)
        steps = result.statistics
        calls = max(s["doStep_calls"] for s in steps.values())
        return result.cpu_seconds, error, f"{result.steps} steps, {calls} doSteps per FMU"
    return run


def monolithic(scene, metric, ref, method: str, rtol: float):
    from scipy.integrate import solve_ivp

    from crankfmu.monolithic.composed import ComposedModel
    from crankfmu.monolithic.solve import RecordMap, record_times

    model = ComposedModel(scene)
    rows = RecordMap(model)
    names = list(scene.record)
    grid = record_times(scene)
    x0 = np.asarray(model.initial_state(t0=scene.start_time), dtype=float)
    atol = rtol * np.asarray(model.state_nominal(), dtype=float)

    def rhs(t, y):
        return model.derivatives(t, y, [])

    def run():
        start = CLOCK()
        sol = solve_ivp(rhs, (scene.start_time, scene.stop_time), x0, method=method, rtol=rtol,
                        atol=atol, t_eval=grid)
        cpu = CLOCK() - start
        values = np.array([rows.row(t, y) for t, y in zip(sol.t, sol.y.T)])
        error = metric.error(sol.t, {n: values[:, k] for k, n in enumerate(names)}, ref)
        return cpu, error, f"{sol.nfev} right-hand sides"
    return run


def measure(candidates: list[Candidate], repeats: int) -> None:
    for candidate in candidates:  # warm-up: first loads, imports, builds
        candidate.run()
    for _ in range(repeats):
        for candidate in candidates:
            cpu, candidate.error, candidate.extra = candidate.run()
            candidate.cpus.append(cpu)


def cheapest(candidates: list[Candidate], target: float) -> Candidate | None:
    meeting = [c for c in candidates if c.error <= target]
    return min(meeting, key=lambda c: c.cpu) if meeting else None


def report(name: str, cosims: list[Candidate], scipys: list[Candidate], target: float,
           metric) -> tuple:
    print(f"== {name}, 0-{STOP_TIME:g} s, error <= {target:g} ({metric.describe()})")
    for c in cosims + scipys:
        mark = "*" if c.error <= target else " "
        print(f"  {mark} {c.label:<42} error {c.error:8.2e}  CPU {c.cpu * 1e3:7.1f} ms  "
              f"({c.extra})")
    best, mono = cheapest(cosims, target), cheapest(scipys, target)
    if best and mono:
        print(f"  cheapest co-simulation: {best.label} {best.cpu * 1e3:.1f} ms; cheapest scipy: "
              f"{mono.label} {mono.cpu * 1e3:.1f} ms; ratio co-simulation/scipy "
              f"{best.cpu / mono.cpu:.2f} (target <= 1)")
    return best, mono


# -- (b) the floor ------------------------------------------------------------------------------
def floor(scene, settings: dict, repeats: int, beside
          ) -> tuple[float, float, float, float, float]:
    """(run CPU, CPU inside the FMI calls, setup CPU, floor = the two, CPU of `beside`) of the
    co-simulation `settings`, medians over `repeats`: every FmuInstance call that reaches an FMU
    (readers, writers, doStep, FMU state) timed, and the runner's setup and the master's
    initialization counted whole (their Python is a few lines around FMI calls). `beside` (a
    Candidate's run: the scipy solve) runs after each, so the ratio is of one moment's load."""
    from crankfmu.cosim import runner
    from crankfmu.cosim.runner import RunOptions, run_scene
    from crankfmu.fmu import instance
    from crankfmu.masters import sweep_code
    from crankfmu.masters.base import Master

    inside, setup_cpu = [0.0], [0.0]

    def timed(function, total=inside):
        def call(*args, **kwargs):
            start = CLOCK()
            try:
                return function(*args, **kwargs)
            finally:
                total[0] += CLOCK() - start
        return call
    patches = [(instance.FmuInstance, name) for name in ("do_step", "get_state", "set_state",
                                                         "free_state")]
    originals = {p: getattr(*p) for p in patches}
    reader, writer = instance.FmuInstance.reader, instance.FmuInstance.writer
    setup, initialize = runner._setup, Master.initialize
    for (owner, name), function in originals.items():
        setattr(owner, name, timed(function))
    instance.FmuInstance.reader = lambda self, names: timed(reader(self, names))
    instance.FmuInstance.writer = lambda self, names: timed(writer(self, names))
    runner._setup = timed(setup, setup_cpu)
    Master.initialize = timed(initialize, setup_cpu)
    # the generic sweeps, whose FMI calls go through the wrappers timed above (a written sweep,
    # masters/sweep_code.py, calls the same FMI functions directly)
    write_sweep, sweep_code.write_sweep = sweep_code.write_sweep, lambda master, sequential: None
    trial = copy.deepcopy(scene)
    for key, value in settings.items():
        setattr(trial.master, key, value)
    runs = []
    try:
        for _ in range(repeats):
            inside[0] = setup_cpu[0] = 0.0
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                result = run_scene(copy.deepcopy(trial), RunOptions(
                    out=None, fmu_dir=ROOT / "fmus", progress=False))
            runs.append((result.cpu_seconds, inside[0], setup_cpu[0], beside()[0]))
    finally:
        for (owner, name), function in originals.items():
            setattr(owner, name, function)
        instance.FmuInstance.reader, instance.FmuInstance.writer = reader, writer
        runner._setup, Master.initialize = setup, initialize
        sweep_code.write_sweep = write_sweep
    cpu, calls, setup_time, other = (statistics.median(r[k] for r in runs) for k in range(4))
    return cpu, calls, setup_time, calls + setup_time, other


def print_floor(best, mono, settings: dict, scene, repeats: int) -> None:
    cpu, calls, setup, bound, mono_cpu = floor(scene, settings, repeats, mono.run)
    print(f"  floor of {best.label}: {calls * 1e3:.1f} ms inside the FMI calls + {setup * 1e3:.1f}"
          f" ms setup = {bound * 1e3:.1f} ms (the run, its calls timed: {cpu * 1e3:.1f} ms, so "
          f"the master's own Python {(cpu - bound) * 1e3:.1f} ms); {mono.label} beside it: "
          f"{mono_cpu * 1e3:.1f} ms; floor / that: {bound / mono_cpu:.2f}")


# -- (c) orders on the two-mass oscillator -----------------------------------------------------
def oscillator_orders(out: Path) -> None:
    sys.path.insert(0, str(ROOT))
    from tests.test_masters import orders, run, speed_error

    steps = (1e-2, 5e-3, 2.5e-3)
    print("(c) two-mass oscillator (tests/test_masters.py), error against its closed form at "
          f"h = {', '.join(f'{h:g}' for h in steps)} s, observed orders")
    folder = out / "oscillator"
    folder.mkdir(parents=True, exist_ok=True)
    for algorithm in ("jacobi", "gauss-seidel"):
        couplings = [("extrapolation", p) for p in (0, 1, 2)] + [("taylor", q)
                                                                for q in (1, 2, 3, 4)]
        for key, value in couplings:
            errors = [speed_error(run(folder, ROOT / "fmus", {"algorithm": algorithm, "step": h,
                                                              key: value})) for h in steps]
            text = " ".join(f"{e:.2e}" for e in errors)
            slopes = " / ".join(f"{o:.2f}" for o in orders(errors))
            print(f"  {algorithm:<13} {key} {value}:  {text}   orders {slopes}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--target", type=float, default=1e-4)
    ap.add_argument("--scenes", default=",".join(SCENES))
    ap.add_argument("--out", type=Path, default=Path(tempfile.gettempdir()) / "crankfmu_coupling")
    ap.add_argument("--quick", action="store_true", help="3 repeats, fewer scipy tolerances")
    ap.add_argument("--skip", default="", help="parts to skip, e.g. b,c")
    args = ap.parse_args(argv)
    skip = set(args.skip.split(","))
    repeats = 3 if args.quick else args.repeats
    rtols = SCIPY_RTOLS[::2] if args.quick else SCIPY_RTOLS
    settings = dict(COSIMULATIONS)
    for name in args.scenes.split(",") if "a" not in skip else ():
        scene, metric, ref = scene_setup(name, args.out)
        cosims = [Candidate(label, cosimulation(scene, metric, ref, s, args.out))
                  for label, s in COSIMULATIONS]
        scipys = [Candidate(f"scipy {m} one call, rtol {r:g}", monolithic(scene, metric, ref, m, r))
                  for m in SCIPY_METHODS for r in rtols]
        measure(cosims + scipys, repeats)
        best, mono = report(name, cosims, scipys, args.target, metric)
        if best and mono and "b" not in skip:
            print_floor(best, mono, settings[best.label], scene, repeats)
    if "c" not in skip:
        oscillator_orders(args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
