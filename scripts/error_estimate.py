"""How good is the error estimate? Per scene and setting of the default accuracy sweep: the
estimate (crankfmu.cosim.estimate), the true error against the monolithic reference, the ratio.

    PYTHONPATH=sources python scripts/error_estimate.py [--out results/accuracy_tables]
        [--scenes hammer,servo_press] [--jobs 2] [--markdown docs/error_estimate.md]

Reads the sweeps of `scripts/accuracy_tables.py` (OUT/<scene>/runs; run that first, it
resumes) and runs the companions it lacks (the adaptive master at 1e-5 and 1e-1) into the same
folder. The estimate of a run uses the same code as `crankfmu run`'s: its
companions are the sweep's runs at 2x and 4x its step (runs are deterministic: a run's numbers
are a function of its scene and FMU bytes). Prints, per scene, each variant of the estimator
(fixed step: the order observed from the second companion, against the nominal order
extrapolation + 1 from one companion; adaptive: a companion at a tenth of the tolerance, against
one at 10x, both with p = 1) with the share of completed runs whose estimate lies within a factor 3 of the truth.
"""
from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
FACTORS = (4.0, 2.0, 1.0, 0.5)     # the default sweep: x the scene's step
TOLERANCES = (1e-2, 1e-3, 1e-4)    # the default sweep of the adaptive master
WITHIN = 3.0                       # the criterion: estimate within a factor 3


def load_run(runs: Path, label: str):
    csv = runs / f"{label}.csv"
    side = runs / f"{label}.outcome.json"
    if not csv.is_file() or not side.is_file():
        return None, None
    outcome = json.loads(side.read_text())["outcome"]
    from crankfmu.cosim.results import read_result_csv
    names, rows = read_result_csv(csv)
    return (rows[:, 0], {n: rows[:, k + 1] for k, n in enumerate(names)}), outcome


def scene_metric(scene):
    from crankfmu.cosim.metrics import make_metric, scene_event_specs, scene_metric_name
    specs = scene_event_specs(scene)
    name = scene_metric_name(scene)
    record = list(dict.fromkeys(scene.record + [v for s in specs for v in s.needs]))
    return make_metric(name, record, None, 1, specs), record


def ensure_companions(scene, settings, out: Path, jobs: int) -> None:
    """Run the settings whose CSV is missing in out/runs (the adaptive companions)."""
    from crankfmu.studies.accuracy import run_accuracy, AccuracyOptions
    missing = [s for s in settings if not (out / "runs" / f"{s.label}.csv").is_file()]
    if not missing:
        return
    tols = sorted({s.tolerance for s in missing})
    exts = sorted({s.extrapolation for s in missing})
    print(f"  running companions: adaptive, extrapolation {exts}, tolerance {tols}", flush=True)
    run_accuracy(scene, AccuracyOptions(out_dir=out, algorithms=["adaptive"], extrapolations=exts,
                                        tolerances=tols, jobs=jobs, progress=False))


def rows_for_scene(scene, out: Path, jobs: int):
    from crankfmu.cosim.estimate import RATIO_TOLERANCE, STEP_RATIO, nominal_order, richardson
    from crankfmu.cosim.masters import MASTERS
    from crankfmu.studies.accuracy import Setting

    metric, _ = scene_metric(scene)
    m = scene.master
    plan = []
    for alg in MASTERS:
        for ex in (0, 1, 2):
            if alg == "adaptive":
                if ex == 0:
                    continue  # left out of the default grid (studies/accuracy)
                for tol in TOLERANCES:  # the estimator: a finer companion; else a coarser one
                    chain = [Setting(alg, ex, m.step, m.fmu_tolerance, tol / RATIO_TOLERANCE),
                             Setting(alg, ex, m.step, m.fmu_tolerance, tol * RATIO_TOLERANCE)]
                    plan.append(([Setting(alg, ex, m.step, m.fmu_tolerance, tol)] + chain,
                                 RATIO_TOLERANCE, "tolerance", 1.0))
            else:
                for f in FACTORS:
                    chain = [Setting(alg, ex, f * m.step * STEP_RATIO ** k, m.fmu_tolerance,
                                     m.tolerance) for k in range(3)]
                    plan.append((chain, STEP_RATIO, "step", nominal_order(ex)))
    ensure_companions(scene, [s for chain, *_ in plan for s in chain[1:]
                              if s.algorithm == "adaptive"], out, jobs)
    rows = []
    for chain, ratio, knob, nominal in plan:
        loaded = [load_run(out / "runs", s.label) for s in chain]
        run, outcome = loaded[0]
        if outcome is None or outcome["status"] != "completed" or outcome["error"] is None:
            rows.append((chain[0], None, None, None, None, outcome and outcome["status"]))
            continue
        truth = outcome["error"]
        series = [x[0] for x in loaded if x[0] is not None]
        variants = {}
        if knob == "tolerance":  # finer companion (chosen), coarser companion (alternative)
            pairs = {"observed": (loaded[1][0], 1 / ratio), "nominal": (loaded[2][0], ratio)}
            for name, (other, r) in pairs.items():
                variants[name] = None if run is None or other is None else \
                    richardson(metric, [run, other], r, knob, 1.0)
        for name, use in (("observed", 3), ("nominal", 2)):
            if knob == "tolerance":
                break
            if len(series) < use:
                variants[name] = None
                continue
            variants[name] = richardson(metric, series[:use], ratio, knob, nominal)
        rows.append((chain[0], truth, variants["observed"], variants["nominal"],
                     outcome["wall_seconds"], ""))
    return metric, rows


def within(est, truth) -> bool:
    return est is not None and est.ok and truth > 0 and 1 / WITHIN <= est.error / truth <= WITHIN


def table(scene, metric, rows) -> tuple[str, dict]:
    lines = [f"#### {scene.name}", "", f"Metric: {metric.name}.", "",
             "| master | extrap. | step or tol | true error | estimate | ratio | order "
             "| nominal-order estimate (ratio) |", "|---|---|---|---|---|---|---|---|"]
    counts = {"completed": 0, "observed": 0, "nominal": 0}
    for s, truth, obs, nom, wall, status in rows:
        knob = f"tol {s.tolerance:g}" if s.algorithm == "adaptive" else f"h {s.step:g}"
        if truth is None:
            lines.append(f"| {s.algorithm} | {s.extrapolation} | {knob} | {status} | | | | |")
            continue
        counts["completed"] += 1
        counts["observed"] += within(obs, truth)
        counts["nominal"] += within(nom, truth)

        def fmt(e):
            if e is None:
                return "no companion", ""
            if not e.ok:
                return f"none ({e.reason})", ""
            return f"{e.error:.2e}", f"{e.error / truth:.2f}" if truth > 0 else "inf"
        o_text, o_ratio = fmt(obs)
        n_text, n_ratio = fmt(nom)
        order = f"{obs.order:.2f}" if obs is not None and math.isfinite(obs.order) else ""
        lines.append(f"| {s.algorithm} | {s.extrapolation} | {knob} | {truth:.2e} | {o_text} | "
                     f"{o_ratio} | {order} | {n_text} ({n_ratio}) |")
    c = counts["completed"] or 1
    lines += ["", f"Within a factor {WITHIN:g} of the truth: {counts['observed']}/"
              f"{counts['completed']} ({100 * counts['observed'] / c:.0f} %) with the observed "
              f"order, {counts['nominal']}/{counts['completed']} "
              f"({100 * counts['nominal'] / c:.0f} %) with the nominal order."]
    return "\n".join(lines), counts


def main(argv=None) -> int:
    from crankfmu.system.load import load_scene

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", type=Path, default=ROOT / "results" / "accuracy_tables")
    ap.add_argument("--scenes")
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--markdown", type=Path, default=None)
    args = ap.parse_args(argv)
    paths = sorted((ROOT / "scenarios").glob("*.toml"))
    if args.scenes:
        paths = [p for p in paths if p.stem in set(args.scenes.split(","))]
    sections, total = [], {"completed": 0, "observed": 0, "nominal": 0}
    summary = ["| scene | completed runs | within 3x (observed order) | within 3x (nominal) |",
               "|---|---|---|---|"]
    for path in paths:
        scene = load_scene(path)
        out = args.out / scene.name
        if not (out / "runs").is_dir():
            print(f"== {scene.name}: no sweep in {out} (run scripts/accuracy_tables.py)")
            continue
        metric, rows = rows_for_scene(scene, out, args.jobs)
        text, counts = table(scene, metric, rows)
        print(text + "\n", flush=True)
        sections.append(text)
        for k in total:
            total[k] += counts[k]
        summary.append(f"| {scene.name} | {counts['completed']} | {counts['observed']} | "
                       f"{counts['nominal']} |")
    c = total["completed"] or 1
    summary.append(f"| all | {total['completed']} | {total['observed']} "
                   f"({100 * total['observed'] / c:.0f} %) | {total['nominal']} "
                   f"({100 * total['nominal'] / c:.0f} %) |")
    print("\n".join(summary))
    if args.markdown:
        args.markdown.write_text("\n".join(summary) + "\n\n" + "\n\n".join(sections) + "\n")
        print(f"wrote {args.markdown}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
