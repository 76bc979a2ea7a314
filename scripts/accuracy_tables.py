"""The tables of docs/accuracy_tables.md: `crankfmu accuracy` with its default grid on every scene.

    PYTHONPATH=sources python scripts/accuracy_tables.py [--out results/accuracy_tables]
        [--jobs 2] [--scenes hammer,servo_press] [--markdown docs/accuracy_tables.md]

Per scene, over the default grid of `crankfmu accuracy` extended to steps of 8, 16 and 32 x the
scene's step (where masters become unstable): the metric it is judged by ([analysis],
docs/accuracy.md), the cheapest setting in wall time for an error of 1e-3 and of 1e-5 (with its
doStep calls: timing-free), the observed order per master and extrapolation (and per event
figure), and where a master becomes unstable (error above 1 or a stopped run). Each scene's
sweep keeps its runs in OUT/<scene>/runs, so an interrupted run of this script resumes. Writes
the markdown below the mark of --markdown (the text above it is kept, the tables stamped with
the command, date and machine: scripts/generated_page.py) and copies the work-precision plots
of the scenes in PLOTS to docs/img/<scene>_work_precision.png.
"""
from __future__ import annotations

import argparse
import math
import shutil
import sys
from pathlib import Path

from generated_page import write_generated  # scripts/, beside this file

from crankfmu.masters import traits

ROOT = Path(__file__).resolve().parents[1]
PLOTS = ("planetary_engagement", "hammer")  # the servo press plot is docs/accuracy.md's 1 s sweep
TARGETS = (1e-3, 1e-5)
# x the scene's step: the default grid (4, 2, 1, 0.5) and coarser steps, to show where each
# master becomes unstable (the coarse runs are cheap; the reference grid stays the same)
STEP_FACTORS = (32.0, 16.0, 8.0, 4.0, 2.0, 1.0, 0.5)


def main(argv=None) -> int:
    from crankfmu.studies.accuracy import AccuracyOptions, cheapest, run_accuracy
    from crankfmu.system.load import load_scene

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", type=Path, default=ROOT / "results" / "accuracy_tables")
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--scenes", help="comma list of scene names (default: every scene)")
    ap.add_argument("--markdown", type=Path, default=ROOT / "docs" / "accuracy_tables.md")
    args = ap.parse_args(argv)
    paths = sorted((ROOT / "scenarios").glob("*.toml"))
    if args.scenes:
        wanted = set(args.scenes.split(","))
        paths = [p for p in paths if p.stem in wanted]
    sections = []
    for path in paths:
        scene = load_scene(path)
        print(f"== {scene.name}", flush=True)
        steps = [f * scene.master.step for f in STEP_FACTORS]
        result = run_accuracy(scene, AccuracyOptions(out_dir=args.out / scene.name, steps=steps,
                                                     jobs=args.jobs, progress=False,
                                                     plot=scene.name in PLOTS))
        sections.append(section(scene, result, [cheapest(result.outcomes, t) for t in TARGETS]))
        print(sections[-1], flush=True)
        if scene.name in PLOTS:
            images = ROOT / "docs" / "img"
            images.mkdir(parents=True, exist_ok=True)
            shutil.copy(result.png, images / f"{scene.name}_work_precision.png")
    write_generated(args.markdown, "\n\n".join(sections) + "\n", "scripts/accuracy_tables.py")
    print(f"wrote {args.markdown}")
    return 0


def setting_text(o) -> str:
    if o is None:
        return "none of the runs"
    s = o.setting
    knob = f"tol {s.tolerance:g}" if o.knob == "tolerance" else f"h {s.step:g} s"
    return (f"{s.algorithm}, {s.coupling}, {knob}: error {o.error:.1e}, "
            f"{o.wall_seconds:.2f} s, {o.do_steps} doSteps")


def run_wall(result) -> float:
    """The runs' own wall times summed (kept runs included: this script resumes)."""
    return sum(o.wall_seconds for o in result.outcomes if math.isfinite(o.wall_seconds))


def section(scene, result, best) -> str:
    lines = [f"#### {scene.name}",
             "",
             f"Metric: {result.metric.describe()}. {len(result.outcomes)} runs, their wall "
             f"times summed {run_wall(result):.0f} s.",
             "",
             "| | cheapest setting (wall time) |", "|---|---|"]
    lines += [f"| error <= {t:g} | {setting_text(o)} |" for t, o in zip(TARGETS, best)]
    lines += [f"| {o.setting.algorithm} (the FMUs' Model Exchange interfaces as one ODE, one "
              f"run) | " + (
                  f"error {o.error:.1e}, {o.wall_seconds:.2f} s" if o.ok else o.status) + " |"
              for o in result.outcomes if traits(o.setting.algorithm).monolithic]
    lines += ["", "| master | coupling | observed order | unstable (error > 1 or stopped); "
              "event count differs from the reference |",
              "|---|---|---|---|"]
    for (alg, coupling, _ft), (order, used, knob) in result.orders.items():
        group = [o for o in result.outcomes
                 if (o.setting.algorithm, o.setting.coupling) == (alg, coupling)]
        bad = sorted(o.knob_value for o in group if o.unstable)
        order_text = f"{order:.2f} (vs {knob}, {used} pts)" if math.isfinite(order) else \
            f"n/a ({used} pts above the floor)"
        where = f"at {knob} " + ", ".join(f"{v:g}" for v in bad) if bad else "never in the grid"
        differ = sorted(o.knob_value for o in group if o.events_differ)
        if differ:
            where += f"; event count differs at {knob} " + ", ".join(f"{v:g}" for v in differ)
        other = [o.status.split(":")[0] for o in group
                 if not o.ok and not o.unstable and not o.events_differ]
        if other:
            where += f" (other: {', '.join(sorted(set(other)))})"
        lines.append(f"| {alg} | {coupling} | {order_text} | {where} |")
    if result.metric.name == "events":
        lines += ["", event_order_table(result)]
    return "\n".join(lines)


EVENT_FLOOR = 1e-12  # relative: below it the figures are round-off of the FMUs' event location


def event_order_table(result) -> str:
    """Observed order of each event figure per master and extrapolation (its own error over the
    step; errors above EVENT_FLOOR: an event time located by the FMU is exact far below the
    FMU tolerance, so its coupling error stays visible below the metric's floor)."""
    from crankfmu.studies.accuracy import observed_order

    labels = [s.label for s in result.metric.events]
    lines = ["| master | coupling | " + " | ".join(f"order of {lb}" for lb in labels) + " |",
             "|---|---|" + "---|" * len(labels)]
    for alg, coupling, _ft in result.orders:
        group = [o for o in result.outcomes if o.ok and o.extra.get("events")
                 and (o.setting.algorithm, o.setting.coupling) == (alg, coupling)]
        cells = []
        for label in labels:
            order, used = observed_order([o.knob_value for o in group],
                                         [o.extra["events"][label] for o in group], EVENT_FLOOR)
            cells.append(f"{order:.2f}" if math.isfinite(order) else "n/a")
        lines.append(f"| {alg} | {coupling} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


if __name__ == "__main__":
    sys.exit(main())
