"""Where does each shipped scene stop being trustworthy as the step grows, and does the run say
so itself? Per scene, fixed-step master and step (1 to 32 x the scene's step, the scene's
extrapolation): the true error against the monolithic reference (the scene's metric), the run's
own error estimate (crankfmu run's: a companion at half the step) and its port energy mismatch,
and whether the run is marked unreliable (crankfmu.cosim.trust).

    PYTHONPATH=sources python scripts/large_steps.py [--scenes servo_press,hammer]
        [--factors 1,2,4,8,16,32] [--masters gauss-seidel,jacobi,iterative] [--json FILE]

The table is what the thresholds of crankfmu.cosim.trust were chosen from (a run whose true
error exceeds 1 should be marked; no shipped scene at its own settings may be) and what
tests/test_large_steps.py holds.
"""
from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path


ROOT = Path(__file__).resolve().parents[1]
FACTORS = (1.0, 2.0, 4.0, 8.0, 16.0, 32.0)
MASTERS = ("gauss-seidel", "jacobi", "iterative")


def true_error(scene, metric, recorder, ref) -> tuple[float, str]:
    """The run's error against the reference in the scene's metric (inf: events differ)."""
    from crankfmu.cosim.metrics import MetricError
    t = recorder.rows[:, 0]
    run = {n: recorder.column(n) for n in recorder.names}
    try:
        if metric.name == "events":
            reasons = [d.reason for d in metric.event_details(t, run, ref) if d.reason]
            if reasons:
                return math.inf, "events differ"
        return float(metric.error(t, run, ref)), ""
    except MetricError as err:
        return math.nan, str(err)


def measure(path: Path, factors, masters) -> list[dict]:
    import copy

    from crankfmu.cosim.estimate import scene_metric, with_metric_record
    from crankfmu.cosim.metrics import ReferenceSamples
    from crankfmu.cosim.runner import RunError, RunOptions, run_scene
    from crankfmu.errors import CrankfmuError
    from crankfmu.monolithic import solve_reference
    from crankfmu.studies.accuracy.sweep import Setting, reference_grid
    from crankfmu.system.load import load_scene

    scene = with_metric_record(load_scene(path))
    metric = scene_metric(scene)
    h0 = scene.master.step
    settings = [Setting(m, scene.master.extrapolation, f * h0, scene.master.fmu_tolerance,
                        scene.master.tolerance) for m in masters for f in factors]
    grid = reference_grid(scene, settings + [Setting("jacobi", 0, f * h0 / 2, 0, 0)
                                             for f in factors])
    solved = solve_reference(scene, rtol=1e-10, times=grid, progress=False)
    rec = solved.recorder
    ref = ReferenceSamples(rec.rows[:, 0], {n: rec.column(n) for n in rec.names})
    rows = []
    for master in masters:
        for f in factors:
            trial = copy.deepcopy(scene)
            trial.master.algorithm, trial.master.step = master, f * h0
            row = {"scene": scene.name, "master": master, "factor": f, "step": f * h0}
            try:
                result = run_scene(trial, RunOptions(progress=False, estimate=True))
            except RunError as err:
                rows.append({**row, "outcome": "stopped", "reason": str(err)[:120]})
                continue
            except CrankfmuError as err:
                rows.append({**row, "outcome": "refused", "reason": str(err)[:120]})
                continue
            error, why = true_error(trial, metric, result.recorder, ref)
            est = result.estimate
            rows.append({**row, "outcome": result.metadata["outcome"],
                         "true_error": error, "estimate": est.error if est else math.nan,
                         "estimate_reason": est.reason if est else "",
                         "mismatch": result.coupling_error.get("max_relative_mismatch"),
                         "unreliable": result.metadata.get("unreliable", []), "reason": why})
            print(_line(rows[-1]), flush=True)
    return rows


def _line(r: dict) -> str:
    def num(x):
        return f"{x:9.2e}" if isinstance(x, float) and math.isfinite(x) else f"{str(x):>9}"
    if r["outcome"] in ("stopped", "refused"):
        return f"{r['scene']:24} {r['master']:13} {r['factor']:4g}x  {r['outcome']}: {r['reason']}"
    return (f"{r['scene']:24} {r['master']:13} {r['factor']:4g}x  error {num(r['true_error'])}"
            f"  estimate {num(r['estimate'])}  mismatch {num(r['mismatch'])}  "
            f"{r['outcome']}" + (f" ({r['reason']})" if r["reason"] else ""))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", help="comma list of scene names (default: every shipped scene)")
    ap.add_argument("--factors", default=",".join(f"{f:g}" for f in FACTORS))
    ap.add_argument("--masters", default=",".join(MASTERS))
    ap.add_argument("--json", type=Path, help="write the rows here")
    args = ap.parse_args()
    paths = sorted((ROOT / "scenarios").glob("*.toml"))
    if args.scenes:
        wanted = set(args.scenes.split(","))
        paths = [p for p in paths if p.stem in wanted]
    factors = [float(f) for f in args.factors.split(",")]
    rows = []
    for path in paths:
        rows += measure(path, factors, args.masters.split(","))
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1, default=float) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
