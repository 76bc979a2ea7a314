"""What `crankfmu run --target TOL` costs against the cheapest setting of the offline sweep.

    PYTHONPATH=sources python benchmarks/target.py [--out results/accuracy_tables]
        [--scenes hammer,servo_press] [--targets 1e-3,1e-5] [--jobs 1,2] [--start-factor 128]

Per scene and target: the search (crankfmu.cosim.target.search, in this process, wall time of
all its runs), the setting it chose, its estimate and its true error against the cached
monolithic reference of the accuracy sweep (OUT/<scene>/reference.csv: run
scripts/accuracy_tables.py first); and the cheapest setting of that sweep (steps 32 .. 0.5 x the
scene's, every master) whose true error meets the target, timed again here in this process
(the sweep's own wall times were taken two runs at a time), median of 3. The search runs once
per --jobs value (1: one run after another in this process; 2: each run's companions in a
worker beside it, cosim/companions.py); prints each one's wall time and its ratio to the
cheapest setting, which the issue wants at most 2, and the runs' summed wall times (the work).
"""
from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

from crankfmu.masters import traits

ROOT = Path(__file__).resolve().parents[1]


def true_error(scene, metric, result, ref) -> tuple[float, str]:
    t = result.recorder.rows[:, 0]
    run = {n: result.recorder.column(n) for n in result.recorder.names}
    if metric.name == "events":
        details = metric.event_details(t, run, ref)
        reasons = [d.reason for d in details if d.reason]
        if reasons:
            return float("inf"), reasons[0]
    return metric.error(t, run, ref), ""


SWEEP_TOLERANCES = (1e-2, 1e-3, 1e-4)  # the adaptive master's grid in the sweep


def cheapest_offline(runs: Path, target: float):
    """The least wall time among the sweep's settings (not the estimate's extra companions)."""
    best = None
    for path in runs.glob("*.outcome.json"):
        o = json.loads(path.read_text())["outcome"]
        s = o["setting"]
        if traits(s[0]).variable_step and not any(abs(s[4] / t - 1) < 1e-9 for t in SWEEP_TOLERANCES):
            continue
        if o["status"] == "completed" and o["error"] is not None and o["error"] <= target:
            if best is None or o["wall_seconds"] < best["wall_seconds"]:
                best = o
    return best


def timed_run(scene, setting, fmu_dir, repeats: int = 3) -> float:
    from crankfmu.cosim.runner import RunOptions, run_scene
    from crankfmu.studies.accuracy.sweep import Setting, trial_scene
    trial = trial_scene(scene, Setting(*setting))
    walls = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        run_scene(trial, RunOptions(out=None, fmu_dir=fmu_dir, progress=False))
        walls.append(time.perf_counter() - t0)
    return statistics.median(walls)


def main(argv=None) -> int:
    from crankfmu.cosim.estimate import scene_metric, with_metric_record
    from crankfmu.cosim import target as target_module
    from crankfmu.cosim.target import TargetNotMet, search
    from crankfmu.studies.accuracy.sweep import _read_reference
    from crankfmu.system.load import load_scene
    from crankfmu.system.wiring import default_fmu_dir

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", type=Path, default=ROOT / "results" / "accuracy_tables")
    ap.add_argument("--scenes")
    ap.add_argument("--targets", default="1e-3,1e-5")
    ap.add_argument("--jobs", default="1,2", help="the search's processes, each timed")
    ap.add_argument("--start-factor", type=float,
                    help="the search's first step x the scene's step (default: START_FACTOR)")
    args = ap.parse_args(argv)
    if args.start_factor:
        target_module.START_FACTOR = args.start_factor
    targets = [float(x) for x in args.targets.split(",")]
    jobs_list = [int(x) for x in args.jobs.split(",")]
    paths = sorted((ROOT / "scenarios").glob("*.toml"))
    if args.scenes:
        paths = [p for p in paths if p.stem in set(args.scenes.split(","))]
    per_jobs = " | ".join(f"search wall [s], jobs {j} | ratio, jobs {j}" for j in jobs_list)
    lines = [f"| scene | target | --target chose | estimate | true error | met | runs (their "
             f"summed wall [s]) | cheapest offline setting (true error) | its wall [s] | "
             f"{per_jobs} |", "|---" * (9 + 2 * len(jobs_list)) + "|"]
    for path in paths:
        scene = with_metric_record(load_scene(path))
        out = args.out / scene.name
        if not (out / "reference.csv").is_file():
            print(f"== {scene.name}: no sweep in {out}")
            continue
        ref = _read_reference(out / "reference.csv")
        metric = scene_metric(scene)
        fmu_dir = default_fmu_dir(scene)
        for target in targets:
            best = cheapest_offline(out / "runs", target)
            best_text, best_wall = "none in the sweep", float("nan")
            if best is not None:
                s = best["setting"]
                knob = f"tol {s[4]:g}" if traits(s[0]).variable_step else f"h {s[2]:g}"
                coupling = f"t{s[5]}" if len(s) > 5 and s[5] else f"x{s[1]}"
                best_text = f"{s[0]} {coupling} {knob} ({best['error']:.1e})"
                best_wall = timed_run(scene, s, fmu_dir)
            walls, found = [], None
            for jobs in jobs_list:  # the same runs and choice whatever jobs is (bit-identical)
                t0 = time.perf_counter()
                try:
                    found = search(scene, target, fmu_dir, jobs)
                except TargetNotMet as err:
                    found = err
                walls.append(time.perf_counter() - t0)
            timing = " | ".join(f"{w:.2f} | {w / best_wall:.1f}" for w in walls)
            if isinstance(found, TargetNotMet):
                lines.append(f"| {scene.name} | {target:g} | not met: {str(found)[:160]} | | | "
                             f"| | {best_text} | {best_wall:.2f} | {timing} |")
                print(lines[-1], flush=True)
                continue
            result, report = found
            err, why = true_error(scene, metric, result, ref)
            m = result.metadata["master"]
            knob = f"tol {m['tolerance']:g}" if traits(m["algorithm"]).variable_step else \
                f"h {m['step']:g}"
            summed = sum(r[-1] for r in report.runs)
            coupling = f"t{m['taylor']}" if m.get("taylor") else f"x{m['extrapolation']}"
            lines.append(
                f"| {scene.name} | {target:g} | {m['algorithm']} {coupling} {knob} | "
                f"{report.estimate.error:.1e} | {err:.1e}{' ' + why if why else ''} | "
                f"{'yes' if err <= target else 'NO'} | {len(report.runs)} ({summed:.2f}) | "
                f"{best_text} | {best_wall:.2f} | {timing} |")
            print(lines[-1], flush=True)
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
