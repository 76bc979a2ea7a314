"""Peers benchmark: one scene on crankfmu's masters, libcosim, ecos and fmpy's SSP runner.

    python benchmarks/peers.py [SCENE.toml] [--stop-time S] [--repeat N] [--fmus DIR]

Every engine runs the same FMUs at the same fixed communication step with the same FMU
tolerance (the FMUs' default 1e-8: libcosim, ecos and fmpy's SSP runner pass none), each run in
a fresh Python process (isolation: fmpy's SSP runner unloads the FMU libraries, and thread pools
do not carry over). In that process a 2-step crankfmu run first imports scipy and the FMUs'
bundled runtime, so no engine pays the ~1 s import; then the runtime's ModelSlave methods are
wrapped with CPU timers (the same FMU code in every engine, see FmuTimer), and the engine runs
the scene twice, from the FMU files to the recorded series in memory: 10 steps (fixed costs),
then the full run. Printed per engine (the run with the best wall time of --repeat):

    wall/sim        wall-clock seconds per simulated second (load, initialize, step, record);
                    the figure a user sees, and the noisiest on a shared machine
    CPU/sim         process CPU seconds (all threads) per simulated second
    fixed CPU       CPU outside the FMUs' Python that does not grow with the run (load, unzip,
                    instantiate, initialize), from the 10-step run
    doStep CPU      CPU inside the FMUs' do_step (the physics: scipy solve_ivp) per simulated s
    FMU get/set     CPU inside the FMUs' get/set per step (output equations are evaluated there)
    engine+FMI      the remaining CPU per step: the engine's own work (master, transfers,
                    recording) plus the FMI crossing (pythonfmu's C++ <-> Python call)
    err w           max |w - w_ref| / max |w_ref| of the crank speed press.w_crank against the
                    monolithic reference (`crankfmu reference`: scipy at rtol 1e-10) on the
                    sample times both have
    x best          ratio to crankfmu's best master in the same run (wall, CPU, error)
"""
from __future__ import annotations

import argparse
import contextlib
import copy
import json
import math
import os
import random
import shutil
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_SCENE = ROOT / "scenarios" / "servo_press.toml"
PEERS = ("libcosim", "ecos", "fmpy-ssp")
SHORT_STEPS = 10  # a run this long measures the fixed costs (load, instantiate, initialize)


# -- worker: one engine, one run, in its own process ---------------------------------------------
class FmuTimer:
    """Sums the CPU time the FMUs' own Python code takes, split into `do_step` (the physics
    step: scipy solve_ivp) and `io` (get_real/set_real and the Boolean pair: the output
    equations run there), by wrapping the methods of every loaded crankfmu runtime's ModelSlave.
    The calling thread's CPU time, not wall time: in libcosim and ecos two FMUs step on two
    threads and wait for the interpreter lock, which a wall clock would count twice. What is
    left of the process's CPU time is the engine's own work plus the FMI crossing (pythonfmu's
    C++ <-> Python call, argument conversion)."""

    METHODS = {"do_step": "step", "get_real": "io", "set_real": "io", "get_boolean": "io",
               "set_boolean": "io"}

    def __init__(self):
        self.cpu = {"step": 0.0, "io": 0.0}
        self.calls = 0
        for name, module in list(sys.modules.items()):
            if name.startswith("crankfmu_rt_") and name.endswith(".runtime.slave"):
                for method, bucket in self.METHODS.items():
                    self._wrap(module.ModelSlave, method, bucket)

    def reset(self) -> None:
        self.cpu = {"step": 0.0, "io": 0.0}
        self.calls = 0

    def _wrap(self, cls, method: str, bucket: str) -> None:
        inner, timer = getattr(cls, method), self

        def timed(slave, *args):
            start = time.thread_time()
            try:
                return inner(slave, *args)
            finally:
                timer.cpu[bucket] += time.thread_time() - start
                timer.calls += bucket == "step"
        setattr(cls, method, timed)


def load(scene_path: Path, stop_time: float | None, fmu_dir: Path):
    """The scene with every component's FMU given as a file in `fmu_dir`, so every engine runs
    the FMUs built once at the start (sources edited meanwhile do not trigger a rebuild)."""
    from crankfmu.system.load import load_scene
    scene = load_scene(scene_path)
    if stop_time is not None:
        scene.stop_time = stop_time
    for comp in scene.components.values():
        if not comp.fmu.endswith(".fmu"):
            comp.fmu = str(fmu_dir / f"{comp.fmu}.fmu")
    return scene


def warm_up(scene, fmu_dir: Path, tmp: Path) -> None:
    from crankfmu.cosim.runner import RunOptions, run_scene
    short = copy.deepcopy(scene)
    short.stop_time = short.start_time + 2 * short.master.step
    short.master.algorithm = "jacobi"
    run_scene(short, RunOptions(out=tmp / "warm_up.csv", fmu_dir=fmu_dir, progress=False))


def run_engine(engine: str, scene, fmu_dir: Path, ssp: Path | None, tmp: Path):
    """(times, {name: values}) of one run; everything from the FMU files on is timed."""
    if engine.startswith("crankfmu:"):
        from crankfmu.cosim.runner import RunOptions, run_scene
        scene.master.algorithm = engine.split(":", 1)[1]
        rec = run_scene(scene, RunOptions(out=tmp / "run.csv", fmu_dir=fmu_dir,
                                          progress=False)).recorder
        return rec.rows[:, 0], {n: rec.column(n) for n in rec.names}
    if engine in ("libcosim", "ecos"):
        from crankfmu.interop import ecos, libcosim
        from crankfmu.interop.plan import plan_scene
        result = (libcosim if engine == "libcosim" else ecos).run(plan_scene(scene, fmu_dir))
        return result.times, result.columns
    if engine == "fmpy-ssp":
        return run_fmpy_ssp(scene, ssp)
    raise ValueError(f"unknown engine {engine!r}")


def run_fmpy_ssp(scene, ssp: Path):
    """fmpy.ssp.simulation.simulate_ssp: Jacobi, with every connector 0 at the first step (no
    initialization-mode propagation). Its row `time` is the step's start while the values are
    those after the step, so the rows are relabelled t + h."""
    from fmpy.ssp.simulation import simulate_ssp

    from crankfmu.system.ssp_export import fmpy_parameter_set
    h = scene.master.step
    rows = simulate_ssp(str(ssp), start_time=scene.start_time, stop_time=scene.stop_time,
                        step_size=h, parameter_set=fmpy_parameter_set(ssp))
    names = [r for r in scene.record if r in rows.dtype.names]
    return rows["time"] + h, {n: np.asarray(rows[n], dtype=float) for n in names}


def worker(args) -> None:
    import scipy.integrate  # noqa: F401 - the import every engine would otherwise pay once
    scene = load(args.scene, args.stop_time, args.fmus)
    tmp = Path(tempfile.mkdtemp(prefix="peers_"))
    warm_up(scene, args.fmus, tmp)
    timer = FmuTimer()
    figures = {}
    short = copy.deepcopy(scene)
    short.stop_time = short.start_time + SHORT_STEPS * short.master.step
    for label, run in (("short", short), ("long", scene)):  # short: the fixed costs
        timer.reset()
        wall, cpu = time.perf_counter(), time.process_time()
        times, columns = run_engine(args.worker, run, args.fmus, args.ssp, tmp)
        figures[label] = {"wall": time.perf_counter() - wall, "cpu": time.process_time() - cpu,
                          "do_step_cpu": timer.cpu["step"], "io_cpu": timer.cpu["io"],
                          "do_step_calls": timer.calls}
    np.savez(args.result, times=times, **{k: v for k, v in columns.items()})
    print(json.dumps(figures), flush=True)
    shutil.rmtree(tmp, ignore_errors=True)
    os._exit(0)  # no interpreter teardown: fmpy's SSP runner unloaded Python FMU libraries


# -- parent: reference, workers, table -----------------------------------------------------------
def reference(scene):
    """The monolithic reference (`crankfmu reference`: the scene's physics models as one ODE,
    scipy at rtol 1e-10) on the scene's record grid."""
    from crankfmu.monolithic import solve_reference
    rec = solve_reference(scene, rtol=1e-10).recorder
    return rec.rows[:, 0], {n: rec.column(n) for n in rec.names}


def error_vs(times, values, ref_times, ref_values) -> float:
    """max |v - v_ref| / max |v_ref| over the sample times both have (1e-9 s matching)."""
    idx = np.searchsorted(ref_times, times - 1e-9)
    ok = (idx < len(ref_times)) & (np.abs(ref_times[np.minimum(idx, len(ref_times) - 1)]
                                          - times) < 1e-9)
    if not np.any(ok):
        return float("nan")
    diff = np.abs(values[ok] - ref_values[idx[ok]])
    return float(np.max(diff) / max(np.max(np.abs(ref_values)), 1e-300))


def spawn(engine: str, args, ssp: Path | None, result: Path) -> dict:
    cmd = [sys.executable, __file__, str(args.scene), "--worker", engine, "--fmus",
           str(args.fmus), "--result", str(result)]
    if args.stop_time is not None:
        cmd += ["--stop-time", repr(args.stop_time)]
    if ssp is not None:
        cmd += ["--ssp", str(ssp)]
    try:
        proc = subprocess.run(cmd, capture_output=True, text=True, timeout=args.timeout)
    except subprocess.TimeoutExpired:
        return {"failed": f"no result within --timeout {args.timeout:g} s"}
    lines = [l for l in proc.stdout.splitlines() if l.startswith("{")]
    if proc.returncode != 0 or not lines:
        tail = (proc.stderr.strip().splitlines() or ["(no output)"])[-1]
        return {"failed": f"exit {proc.returncode}: {tail}"}
    return json.loads(lines[-1])


def engines() -> list[str]:
    from crankfmu.masters import MASTERS
    return [f"crankfmu:{name}" for name in MASTERS] + list(PEERS)


def measure(args, names: list[str], ssp: Path | None, tmp: Path) -> dict[str, dict]:
    from tqdm import tqdm
    out = {}
    jobs = []  # interleaved, each round in another order: load drift hits every engine alike
    for k in range(args.repeat):
        jobs += [(e, k) for e in random.Random(k).sample(names, len(names))]
    for engine, k in tqdm(jobs, desc="peers", unit="run", disable=None):
        path = tmp / f"{engine.replace(':', '_')}_{k}.npz"
        got = spawn(engine, args, ssp, path)
        best = out.get(engine)
        if "failed" in got:
            out.setdefault(engine, got)
            continue
        got["result"] = path
        if best is None or "failed" in best or got["long"]["wall"] < best["long"]["wall"]:
            out[engine] = got
    return out


@dataclass
class Row:
    engine: str
    wall: float = math.nan       # s per simulated s
    cpu: float = math.nan        # s per simulated s, all threads
    fixed_ms: float = math.nan   # CPU outside the FMUs' Python that does not grow with the steps
    do_step: float = math.nan    # CPU s per simulated s inside the FMUs' do_step
    io_us: float = math.nan      # CPU us per step inside the FMUs' get/set
    engine_us: float = math.nan  # CPU us per step outside the FMUs' Python
    error: float = math.nan
    failed: str = ""


def make_row(engine: str, r: dict, n_steps: int, sim_seconds: float, var: str, ref) -> Row:
    if "failed" in r:
        return Row(engine, failed=r["failed"])
    data = np.load(r["result"])
    err = error_vs(data["times"], data[var], ref[0], ref[1][var]) if var in data else math.nan
    long, short = r["long"], r["short"]
    rest_long = long["cpu"] - long["do_step_cpu"] - long["io_cpu"]
    rest_short = short["cpu"] - short["do_step_cpu"] - short["io_cpu"]
    per_step = (rest_long - rest_short) / (n_steps - SHORT_STEPS)
    return Row(engine, long["wall"] / sim_seconds, long["cpu"] / sim_seconds,
               (rest_short - SHORT_STEPS * per_step) * 1e3, long["do_step_cpu"] / sim_seconds,
               long["io_cpu"] / n_steps * 1e6, per_step * 1e6, err)


def table(scene, runs: dict[str, dict], ref, var: str = "press.w_crank") -> str:
    sim_seconds = scene.stop_time - scene.start_time
    n_steps = round(sim_seconds / scene.master.step)
    rows = [make_row(e, r, n_steps, sim_seconds, var, ref) for e, r in runs.items()]
    ours = [r for r in rows if r.engine.startswith("crankfmu:") and not r.failed]
    best = {k: min((getattr(r, k) for r in ours), default=math.nan)
            for k in ("wall", "cpu", "error")}
    lines = [f"scene {scene.name}: {sim_seconds:g} s simulated, step {scene.master.step:g} s, "
             f"FMU tolerance {scene.master.fmu_tolerance:g}; error in {var} against the "
             "monolithic reference; x best = ratio to crankfmu's best master in this run", "",
             "| engine | wall/sim [s/s] | x best | CPU/sim [s/s] | x best | fixed CPU [ms] "
             "| doStep CPU [s/s] | FMU get/set CPU [us/step] | engine+FMI CPU [us/step] "
             "| err w (max, rel.) | x best |",
             "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for r in rows:
        if r.failed:
            lines.append(f"| {r.engine} | failed: {r.failed} |" + " |" * 9)
            continue
        lines.append(f"| {r.engine} | {r.wall:.3f} | {r.wall / best['wall']:.2f} | "
                     f"{r.cpu:.3f} | {r.cpu / best['cpu']:.2f} | {r.fixed_ms:.0f} | "
                     f"{r.do_step:.3f} | {r.io_us:.0f} | {r.engine_us:.0f} | {r.error:.2e} | "
                     f"{r.error / best['error']:.3g} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("scene", type=Path, nargs="?", default=DEFAULT_SCENE)
    p.add_argument("--stop-time", type=float, help="simulated seconds (default: the scene's)")
    p.add_argument("--repeat", type=int, default=3, help="runs per engine; the fastest counts")
    p.add_argument("--fmus", type=Path, help="folder for the built FMUs (default: a temporary one)")
    p.add_argument("--timeout", type=float, default=300.0,
                   help="seconds one run may take before it counts as failed (default 300)")
    p.add_argument("--engines", help="comma-separated subset of: " + ", ".join(engines()))
    p.add_argument("--worker", help=argparse.SUPPRESS)
    p.add_argument("--result", type=Path, help=argparse.SUPPRESS)
    p.add_argument("--ssp", type=Path, help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args.worker:
        worker(args)
    tmp = Path(tempfile.mkdtemp(prefix="peers_"))
    try:
        print(run_all(args, tmp))
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return 0


def run_all(args, tmp: Path) -> str:
    from crankfmu.fmu.build import build_all
    from crankfmu.system.load import load_scene
    args.fmus = (args.fmus or tmp / "fmus").resolve()
    with contextlib.redirect_stdout(sys.stderr):
        build_all(args.fmus, sorted({c.fmu for c in load_scene(args.scene).components.values()}),
                  check=False)
    scene = load(args.scene, args.stop_time, args.fmus)
    names = args.engines.split(",") if args.engines else engines()
    ssp = None
    if "fmpy-ssp" in names:
        from crankfmu.system.ssp_export import export_ssp
        ssp = export_ssp(scene, tmp / f"{scene.name}.ssp", args.fmus)
    ref_scene = load_scene(args.scene)  # catalog names: the reference composes their physics
    ref_scene.stop_time = scene.stop_time
    wall = time.perf_counter()
    ref = reference(ref_scene)
    print(f"reference: {time.perf_counter() - wall:.1f} s wall", file=sys.stderr)
    runs = measure(args, names, ssp, tmp)
    command = " ".join(["python benchmarks/peers.py"] + sys.argv[1:])
    return f"$ {command}\n" + table(scene, runs, ref)


if __name__ == "__main__":
    sys.exit(main())
