"""How good is the error estimate? Per scene and setting of the default accuracy sweep: the
estimate (crankfmu.cosim.estimate), the true error against the monolithic reference, the ratio.

    PYTHONPATH=sources python scripts/error_estimate.py [--out results/accuracy_tables]
        [--scenes hammer,servo_press] [--jobs 2] [--markdown docs/error_estimate.md]

Reads the sweeps of `scripts/accuracy_tables.py` (OUT/<scene>/runs; run that first, it
resumes) and runs the companions it lacks (the adaptive master at 1e-5 and 1e-1) into the same
folder. The estimate of a run uses the same code as `crankfmu run`'s: its
companions are the sweep's runs at 2x and 4x its step (runs are deterministic: a run's numbers
are a function of its scene and FMU bytes). Prints, per scene, each variant of the estimator
(fixed step: the order observed from the second companion clamped to [p, p + 1], p =
extrapolation + 1 (crankfmu's), against clamping to [0.5, 5] and against the nominal order p
from one companion; adaptive: a companion at a tenth of the tolerance, against
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
    from crankfmu.masters import MASTERS
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
            rows.append((chain[0], None, None, None, None, None, outcome and outcome["status"]))
            continue
        truth = outcome["error"]
        series = [x[0] for x in loaded if x[0] is not None]
        variants = {}
        if knob == "tolerance":  # finer companion (chosen), coarser companion (alternative)
            pairs = {"observed": (loaded[1][0], 1 / ratio), "nominal": (loaded[2][0], ratio)}
            for name, (other, r) in pairs.items():
                variants[name] = None if run is None or other is None else \
                    richardson(metric, [run, other], r, knob, 1.0)
        for name, use, bounds in (("observed", 3, None), ("nominal", 2, None),
                                  ("bounded", 3, (nominal, nominal + 1))):
            if knob == "tolerance":
                variants.setdefault("bounded", variants["observed"])
                break
            if len(series) < use:
                variants[name] = None
                continue
            variants[name] = richardson(metric, series[:use], ratio, knob, nominal, bounds)
        rows.append((chain[0], truth, variants["observed"], variants["nominal"],
                     variants["bounded"], outcome["wall_seconds"], ""))
    return metric, rows


def within(est, truth) -> bool:
    return est is not None and est.ok and truth > 0 and 1 / WITHIN <= est.error / truth <= WITHIN


VARIANTS = ("bounded", "observed", "nominal")  # the first is crankfmu's estimator
FLOOR = 10 * 1e-8  # FLOOR_FACTOR x the FMUs' tolerance of every shipped scene (studies/accuracy)


def table(scene, metric, rows) -> tuple[str, dict]:
    lines = [f"#### {scene.name}", "", f"Metric: {metric.name}.", "",
             "| master | extrap. | step or tol | true error | estimate, order in [p, p+1] (ratio, "
             "order) | order in [0.5, 5] | nominal order p |", "|---|---|---|---|---|---|---|"]
    counts = {k: 0 for k in ("completed", "above_floor") + VARIANTS +
              tuple(f"{v}_above" for v in VARIANTS)}
    for s, truth, obs, nom, bounded, wall, status in rows:
        est = [bounded, obs, nom]
        knob = f"tol {s.tolerance:g}" if s.algorithm == "adaptive" else f"h {s.step:g}"
        if truth is None:
            lines.append(f"| {s.algorithm} | {s.extrapolation} | {knob} | {status} | | | |")
            continue
        counts["completed"] += 1
        above = truth > FLOOR
        counts["above_floor"] += above
        for name, e in zip(VARIANTS, est):
            counts[name] += within(e, truth)
            counts[f"{name}_above"] += above and within(e, truth)

        def fmt(e):
            if e is None:
                return "no companion"
            if not e.ok:
                return f"none ({e.reason[:60]})"
            return (f"{e.error:.2e} ({e.error / truth:.2f}" if truth > 0 else "inf") + \
                f", p {e.order:.2f})"
        lines.append(f"| {s.algorithm} | {s.extrapolation} | {knob} | {truth:.2e} | " +
                     " | ".join(fmt(e) for e in est) + " |")
    lines += ["", summary_text(counts)]
    return "\n".join(lines), counts


def summary_text(c: dict) -> str:
    n, a = c["completed"] or 1, c["above_floor"] or 1
    return (f"Within a factor {WITHIN:g} of the truth, of {c['completed']} completed runs "
            f"({c['above_floor']} with a true error above the floor {FLOOR:g}): " +
            "; ".join(f"{v} {c[v]} ({100 * c[v] / n:.0f} %), above the floor "
                      f"{c[v + '_above']} ({100 * c[v + '_above'] / a:.0f} %)" for v in VARIANTS))


def finer_comparison(scene, out: Path) -> dict:
    """The alternative of a finer companion (h/2, order p0; 2x the run's cost) against
    crankfmu's estimator, on the fixed-step runs at 4, 2 and 1 x the scene's step (the sweep
    has their h/2, h, 2h and 4h)."""
    from crankfmu.cosim.estimate import order_rule, richardson
    from crankfmu.studies.accuracy import Setting

    metric, _ = scene_metric(scene)
    m = scene.master
    counts = {"runs": 0, "finer": 0, "crankfmu": 0}
    for alg in ("gauss-seidel", "jacobi", "iterative"):
        for ex in (0, 1, 2):
            for f in (4.0, 2.0, 1.0):
                h = f * m.step
                loaded = [load_run(out / "runs", Setting(alg, ex, x, m.fmu_tolerance,
                                                         m.tolerance).label)
                          for x in (h, h / 2, 2 * h, 4 * h)]
                (run, outcome), (fine, _), (c1, _), (c2, _) = loaded
                if outcome is None or outcome["status"] != "completed" or \
                        outcome["error"] is None or None in (fine, c1, c2):
                    continue
                truth = outcome["error"]
                counts["runs"] += 1
                p0, bounds = order_rule(False, ex)
                counts["finer"] += within(richardson(metric, [run, fine], 0.5, "step", p0),
                                          truth)
                counts["crankfmu"] += within(richardson(metric, [run, c1, c2], 2.0, "step", p0,
                                                        bounds), truth)
    return counts


def main(argv=None) -> int:
    from crankfmu.system.load import load_scene

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", type=Path, default=ROOT / "results" / "accuracy_tables")
    ap.add_argument("--scenes")
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--markdown", type=Path, default=None)
    ap.add_argument("--finer", action="store_true",
                    help="also compare with a finer companion (h/2) on the fixed-step runs")
    args = ap.parse_args(argv)
    paths = sorted((ROOT / "scenarios").glob("*.toml"))
    if args.scenes:
        paths = [p for p in paths if p.stem in set(args.scenes.split(","))]
    sections, total = [], {}
    summary = ["| scene | completed runs | within 3x: order observed in [p, p+1] (crankfmu's) "
               "| order observed in [0.5, 5] | nominal order p | runs above the floor "
               "| within 3x above the floor (crankfmu's) |", "|---|---|---|---|---|---|---|"]

    def line(name, c):
        n, a = c["completed"] or 1, c["above_floor"] or 1
        return (f"| {name} | {c['completed']} | " + " | ".join(
            f"{c[v]} ({100 * c[v] / n:.0f} %)" for v in VARIANTS) +
            f" | {c['above_floor']} | {c['bounded_above']} "
            f"({100 * c['bounded_above'] / a:.0f} %) |")
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
        for k, v in counts.items():
            total[k] = total.get(k, 0) + v
        summary.append(line(scene.name, counts))
    summary.append(line("all", total))
    print("\n".join(summary))
    if args.finer:
        rows = ["| scene | fixed-step runs at 4, 2, 1 x step | within 3x: crankfmu's (2h, 4h) "
                "| finer companion (h/2, 2x the cost) |", "|---|---|---|---|"]
        all_ = {"runs": 0, "finer": 0, "crankfmu": 0}
        for path in paths:
            scene = load_scene(path)
            if (args.out / scene.name / "runs").is_dir():
                c = finer_comparison(scene, args.out / scene.name)
                rows.append(f"| {scene.name} | {c['runs']} | {c['crankfmu']} | {c['finer']} |")
                for k in all_:
                    all_[k] += c[k]
        rows.append(f"| all | {all_['runs']} | {all_['crankfmu']} "
                    f"({100 * all_['crankfmu'] / max(1, all_['runs']):.0f} %) | {all_['finer']} "
                    f"({100 * all_['finer'] / max(1, all_['runs']):.0f} %) |")
        print("\n".join(rows))
        summary += [""] + rows
    if args.markdown:
        args.markdown.write_text("\n".join(summary) + "\n\n" + "\n\n".join(sections) + "\n")
        print(f"wrote {args.markdown}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
