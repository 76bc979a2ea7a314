"""How good is the error estimate? Per scene and setting of the default accuracy sweep: the
estimate (crankfmu.cosim.estimate), the true error against the monolithic reference, the ratio.

    PYTHONPATH=sources python scripts/error_estimate.py [--out results/accuracy_tables]
        [--scenes hammer,servo_press] [--jobs 2] [--markdown docs/error_estimate.md]

Reads the sweeps of `scripts/accuracy_tables.py` (OUT/<scene>/runs; run that first, it
resumes) and runs the companions it lacks (the adaptive master at 1e-5 and 1e-1) into the same
folder. The estimate of a run uses the same code as `crankfmu run`'s: its
companions are the sweep's own runs at other steps (runs are deterministic: a run's numbers
are a function of its scene and FMU bytes). Prints, per scene, each variant of the estimator
(fixed step: one companion at h/2 with the design order p = extrapolation + 1 (crankfmu run's
and --target's), against companions at 2h and 4h with the order observed clamped to [p, p + 1]
or to [0.5, 5], and one at 2h with p; adaptive: a companion at a tenth of the tolerance, against
one at 10x, both with p = 1) with the share of completed runs whose estimate lies within a
factor 3 of the truth.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from crankfmu.masters import traits
from generated_page import write_generated  # scripts/, beside this file

ROOT = Path(__file__).resolve().parents[1]
FACTORS = (4.0, 2.0, 1.0, 0.5)     # the default sweep: x the scene's step
TOLERANCES = (1e-2, 1e-3, 1e-4)    # the default sweep of the adaptive master
WITHIN = 3.0                       # the criterion: estimate within a factor 3


RUN_DIRS: list[Path] = []  # where load_run also looks (the fine companions' folder)


def load_run(runs: Path, label: str):
    for folder in [runs] + [d for d in RUN_DIRS if d != runs]:
        csv = folder / f"{label}.csv"
        side = folder / f"{label}.outcome.json"
        if csv.is_file() and side.is_file():
            break
    else:
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
                                        tolerances=tols, jobs=jobs, progress=False,
                                        estimate=False))


FIXED = ("gauss-seidel", "jacobi", "iterative")


def run_fine_companions(scene, companions: Path, jobs: int) -> None:
    """The h/2 companions of the sweep's finest runs (0.25 x the scene's step), in their own
    folder (its reference grid differs from the sweep's, so the sweep's cache stays valid)."""
    from crankfmu.studies.accuracy import AccuracyOptions, run_accuracy
    print(f"  running the h/2 companions of the 0.5 x step runs into {companions}", flush=True)
    run_accuracy(scene, AccuracyOptions(out_dir=companions, algorithms=list(FIXED),
                                        extrapolations=[0, 1, 2],
                                        steps=[0.25 * scene.master.step], jobs=jobs,
                                        progress=False, estimate=False))


def rows_for_scene(scene, out: Path, jobs: int):
    """Per default-sweep run: (setting, true error, {variant: Estimate or None}, status)."""
    from crankfmu.cosim.estimate import RATIO_TOLERANCE, coarse_bounds, order_rule, richardson
    from crankfmu.masters import MASTERS
    from crankfmu.studies.accuracy import Setting

    metric, _ = scene_metric(scene)
    m = scene.master
    rows, adaptive_companions = [], []
    for alg in MASTERS:
        if traits(alg).monolithic:
            continue  # no coupling error: nothing to estimate
        for ex in (0, 1, 2):
            variable = traits(alg).variable_step
            if variable and ex == 0:
                continue  # left out of the default grid (studies/accuracy)
            knobs = TOLERANCES if variable else [f * m.step for f in FACTORS]
            for x in knobs:
                if variable:
                    at = {r: Setting(alg, ex, m.step, m.fmu_tolerance, x * r)
                          for r in (1.0, 1 / RATIO_TOLERANCE, RATIO_TOLERANCE)}
                    adaptive_companions += [at[1 / RATIO_TOLERANCE], at[RATIO_TOLERANCE]]
                else:
                    at = {r: Setting(alg, ex, x * r, m.fmu_tolerance, m.tolerance)
                          for r in (1.0, 0.5, 2.0, 4.0)}
                rows.append((alg, ex, at))
    ensure_companions(scene, adaptive_companions, out, jobs)
    table = []
    for alg, ex, at in rows:
        run, outcome = load_run(out / "runs", at[1.0].label)
        if outcome is None or outcome["status"] != "completed" or outcome["error"] is None:
            table.append((at[1.0], None, {}, outcome and outcome["status"]))
            continue
        series = {r: load_run(out / "runs", s.label)[0] for r, s in at.items()}

        def est(rs, ratio, knob, nominal, bounds=None, series=series):
            runs = [series[r] for r in rs]
            return None if any(x is None for x in runs) else \
                richardson(metric, runs, ratio, knob, nominal, bounds)
        if traits(alg).variable_step:  # a tenth of the tolerance (crankfmu's), else 10 x (p = 1)
            finer = est((1.0, 1 / RATIO_TOLERANCE), 1 / RATIO_TOLERANCE, "tolerance", 1.0)
            coarser = est((1.0, RATIO_TOLERANCE), RATIO_TOLERANCE, "tolerance", 1.0)
            variants = {"fine": finer, "bounded": finer, "observed": coarser,
                        "nominal": coarser}
        else:
            p0, _ = order_rule(alg, ex)
            variants = {"fine": est((1.0, 0.5), 0.5, "step", p0),
                        "bounded": est((1.0, 2.0, 4.0), 2.0, "step", p0,
                                       coarse_bounds(alg, ex)),
                        "observed": est((1.0, 2.0, 4.0), 2.0, "step", p0),
                        "nominal": est((1.0, 2.0), 2.0, "step", p0)}
        table.append((at[1.0], outcome["error"], variants, ""))
    return metric, table


def within(est, truth) -> bool:
    return est is not None and est.ok and truth > 0 and 1 / WITHIN <= est.error / truth <= WITHIN


VARIANTS = ("fine", "bounded", "observed", "nominal")  # the first is crankfmu run's estimator
LABELS = {"fine": "h/2 companion, order p0 (crankfmu run's and --target's)",
          "bounded": "2h and 4h, order observed in [p0, p0+1]",
          "observed": "2h and 4h, order observed in [0.5, 5]",
          "nominal": "2h, order p0"}
FLOOR = 10 * 1e-8  # FLOOR_FACTOR x the FMUs' tolerance of every shipped scene (studies/accuracy)


def table(scene, metric, rows) -> tuple[str, dict]:
    lines = [f"#### {scene.name}", "", f"Metric: {metric.name}. Estimate (ratio to the true "
             f"error, order used) per variant; adaptive master: fine = a tenth of the tolerance, "
             f"the 2h columns = 10 x the tolerance.", "",
             "| master | extrap. | step or tol | true error | " +
             " | ".join(LABELS[v] for v in VARIANTS) + " |", "|---|---|---|---|" +
             "---|" * len(VARIANTS)]
    counts = {k: 0 for k in ("completed", "above_floor") + VARIANTS +
              tuple(f"{v}_above" for v in VARIANTS) + tuple(f"{v}_measured" for v in VARIANTS)}
    for s, truth, est, status in rows:
        knob = f"tol {s.tolerance:g}" if traits(s.algorithm).variable_step else f"h {s.step:g}"
        if truth is None:
            lines.append(f"| {s.algorithm} | {s.extrapolation} | {knob} | {status} |" +
                         " |" * len(VARIANTS))
            continue
        counts["completed"] += 1
        above = truth > FLOOR
        counts["above_floor"] += above
        for name in VARIANTS:
            e = est.get(name)
            counts[f"{name}_measured"] += e is not None
            counts[name] += within(e, truth)
            counts[f"{name}_above"] += above and within(e, truth)

        def fmt(e, truth=truth):
            if e is None:
                return "no companion run"
            if not e.ok:
                return f"none ({e.reason[:60]})"
            return (f"{e.error:.2e} ({e.error / truth:.2f}" if truth > 0 else "inf") + \
                f", p {e.order:.2f})"
        lines.append(f"| {s.algorithm} | {s.extrapolation} | {knob} | {truth:.2e} | " +
                     " | ".join(fmt(est.get(v)) for v in VARIANTS) + " |")
    lines += ["", summary_text(counts)]
    return "\n".join(lines), counts


def summary_text(c: dict) -> str:
    n, a = c["completed"] or 1, c["above_floor"] or 1
    return (f"Within a factor {WITHIN:g} of the truth, of {c['completed']} completed runs "
            f"({c['above_floor']} with a true error above the floor {FLOOR:g}): " +
            "; ".join(f"{v} {c[v]} ({100 * c[v] / n:.0f} %; {c[v + '_measured']} had their "
                      f"companions), above the floor {c[v + '_above']} "
                      f"({100 * c[v + '_above'] / a:.0f} %)" for v in VARIANTS))


def plot_scene(scene, rows, path: Path) -> None:
    """The estimate-against-truth plot of `crankfmu accuracy`, from these rows."""
    from crankfmu.studies.accuracy import Outcome
    from crankfmu.studies.accuracy.report import plot_estimates
    outcomes = []
    for s, truth, est, _ in rows:
        if truth is None:
            continue
        fine = est.get("fine")
        o = Outcome(s, traits(s.algorithm).knob or "step", truth)
        o.extra["estimated_error"] = fine.error if fine is not None and fine.ok else None
        outcomes.append(o)
    path.parent.mkdir(parents=True, exist_ok=True)
    plot_estimates(path, outcomes, f"{scene.name}: estimated against true error, default "
                                   f"sweep, t = {scene.start_time:g} to {scene.stop_time:g} s")


def main(argv=None) -> int:
    from crankfmu.system.load import load_scene

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", type=Path, default=ROOT / "results" / "accuracy_tables")
    ap.add_argument("--scenes")
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--markdown", type=Path, default=None)
    ap.add_argument("--companions", type=Path,
                    default=ROOT / "results" / "estimate_companions",
                    help="where the h/2 companions of the finest sweep runs are (--run-fine)")
    ap.add_argument("--plots", type=Path, default=None,
                    help="folder for <scene>_estimate_vs_error.png (crankfmu run's estimate)")
    ap.add_argument("--run-fine", action="store_true",
                    help="run the h/2 companions of the 0.5 x step runs first (into --companions)")
    args = ap.parse_args(argv)
    paths = sorted((ROOT / "scenarios").glob("*.toml"))
    if args.scenes:
        paths = [p for p in paths if p.stem in set(args.scenes.split(","))]
    sections, total = [], {}
    summary = ["| scene | completed runs | " + " | ".join(
        f"within 3x: {LABELS[v]}" for v in VARIANTS) + " | runs above the floor | within 3x "
        "above the floor (crankfmu run's) |", "|---|---|" + "---|" * len(VARIANTS) + "---|---|"]

    def line(name, c):
        n, a = c["completed"] or 1, c["above_floor"] or 1
        return (f"| {name} | {c['completed']} | " + " | ".join(
            f"{c[v]} ({100 * c[v] / n:.0f} %)" for v in VARIANTS) +
            f" | {c['above_floor']} | {c['fine_above']} ({100 * c['fine_above'] / a:.0f} %) |")
    for path in paths:
        scene = load_scene(path)
        out = args.out / scene.name
        if not (out / "runs").is_dir():
            print(f"== {scene.name}: no sweep in {out} (run scripts/accuracy_tables.py)")
            continue
        if args.run_fine:
            run_fine_companions(scene, args.companions / scene.name, args.jobs)
        RUN_DIRS[:] = [out / "runs", args.companions / scene.name / "runs"]
        metric, rows = rows_for_scene(scene, out, args.jobs)
        text, counts = table(scene, metric, rows)
        if args.plots:
            plot_scene(scene, rows, args.plots / f"{scene.name}_estimate_vs_error.png")
        print(text + "\n", flush=True)
        sections.append(text)
        for k, v in counts.items():
            total[k] = total.get(k, 0) + v
        summary.append(line(scene.name, counts))
    summary.append(line("all", total))
    print("\n".join(summary))
    if args.markdown:
        write_generated(args.markdown, "\n".join(summary) + "\n\n" + "\n\n".join(sections) + "\n",
                        "scripts/error_estimate.py")
        print(f"wrote {args.markdown}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
