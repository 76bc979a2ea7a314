"""The accuracy sweep's outputs: terminal table, CSV, work-precision plot."""
from __future__ import annotations

import math
from pathlib import Path

from .sweep import Outcome

# accuracy.csv's columns and their units (accuracy.json: "units"; None: text); taylor last:
# the columns before it keep the places they had before it existed
UNITS = {"metric": None, "algorithm": None, "extrapolation": "1", "step": "s",
         "fmu_tolerance": "1", "tolerance": "1", "error": "1", "estimated_error": "1",
         "wall_time": "s", "doStep_calls": "1", "rollbacks": "1", "communication_steps": "1",
         "status": None, "taylor": "1"}
COLUMNS = tuple(UNITS)


def table_row(o: Outcome, metric: str) -> dict:
    """A run's row of accuracy.csv (and of AccuracyResult.to_pandas): column -> value; an error
    that is no number ("unstable", "events differ": the figure or the reason is in the status)
    is that word, an estimate that is none is empty."""
    s = o.setting
    error = "unstable" if o.unstable else "events differ" if o.events_differ else o.error
    estimate = o.extra.get("estimated_error")  # cosim.estimate: empty when there is none
    return dict(zip(COLUMNS, [metric, s.algorithm, s.extrapolation, s.step, s.fmu_tolerance,
                              s.tolerance, error, "" if estimate is None else estimate,
                              o.wall_seconds, o.do_steps, o.rollbacks, o.communication_steps,
                              o.status, s.taylor]))


def write_table_csv(path: Path, outcomes: list[Outcome], metric) -> Path:
    """accuracy.csv and its sidecar accuracy.json (the metric, the units of the columns),
    each written whole (crankfmu.outputs); returns the sidecar's path."""
    import json

    from ...outputs import atomic_write, write_table
    write_table(path, COLUMNS, (table_row(o, metric.name).values() for o in outcomes))
    sidecar = Path(path).with_suffix(".json")
    text = json.dumps({"csv": Path(path).name, "metric": metric.name,
                       "metric_description": metric.describe(), "units": UNITS},
                      indent=2) + "\n"
    atomic_write(sidecar, lambda f: f.write(text))
    return sidecar


TABLE_HEAD = (f"{'algorithm':<13} {'ex':>3} {'step [s]':>9} {'fmu tol':>7} {'tol':>7} "
              f"{'error [1]':>10} {'estimate':>9} {'wall [s]':>8} {'doSteps':>8} {'rollb.':>6}  status")


def format_outcome(o: Outcome) -> str:
    """One table row; an unstable run shows 'unstable', its figure or reason in the status."""
    s = o.setting
    status = o.status if len(o.status) < 60 else o.status[:57] + "..."
    error = f"{'unstable':>10}" if o.unstable else f"{'events ≠':>10}" if o.events_differ \
        else f"{o.error:>10.3e}"
    est = o.extra.get("estimated_error")
    est = f"{est:>9.2e}" if est is not None else f"{'-':>9}"
    return (f"{s.algorithm:<13} {_short(s):>3} {s.step:>9.3g} "
            f"{s.fmu_tolerance:>7.0e} {s.tolerance:>7.0e} {error} {est} "
            f"{o.wall_seconds:>8.3f} {o.do_steps:>8d} {o.rollbacks:>6d}  {status}")


def _short(s) -> str:
    """The coupling in a table column: the extrapolation order, or t<q> for a Taylor
    coupling."""
    return f"t{s.taylor}" if s.taylor else str(s.extrapolation)


def format_table(outcomes: list[Outcome]) -> str:
    lines = [TABLE_HEAD, "-" * len(TABLE_HEAD)] + [format_outcome(o) for o in outcomes]
    return "\n".join(lines)


def format_events(outcomes: list[Outcome]) -> str:
    """Per run, the error of each [analysis].events figure (metric events only)."""
    rows = [o for o in outcomes if o.extra.get("events")]
    if not rows:
        return ""
    labels = list(rows[0].extra["events"])
    lines = ["event figures, relative error per run:"]
    for o in rows:
        s = o.setting
        figures = ", ".join(f"{k} {v:.2e}" for k, v in o.extra["events"].items()
                            if k in labels)
        lines.append(f"  {s.algorithm} {s.coupling} h {s.step:g}: {figures}")
    return "\n".join(lines)


def format_orders(orders: dict) -> str:
    lines = ["observed order (slope of log error over log step; for a variable-step master over "
             "log tolerance):"]
    for (alg, coupling, ft), (order, used, knob) in orders.items():
        text = f"{order:.2f}" if math.isfinite(order) else "n/a"
        lines.append(f"  {alg:<13} {coupling:<15} fmu tol {ft:.0e}: {text} "
                     f"(vs {knob}, {used} points above the floor)")
    return "\n".join(lines)


# line style and marker per coupling (Setting.coupling)
COUPLING_STYLES = {"extrapolation 0": ("-", "o"), "extrapolation 1": ("--", "s"),
                   "extrapolation 2": (":", "^"), "taylor 1": ("-.", "v"),
                   "taylor 2": ("-.", "D"), "taylor 3": ("-.", "P"), "taylor 4": ("-.", "X")}


def plot_work_precision(path: Path, outcomes: list[Outcome], metric_text: str,
                        target: float | None, title: str) -> None:
    """Error against wall time (left) and against doStep calls (right), log-log, one line per
    master / coupling (extrapolation or Taylor order) / FMU tolerance."""
    from ...cosim.results import PALETTE, new_figure, save_figure

    groups: dict[tuple, list[Outcome]] = {}
    for o in outcomes:
        if o.ok and o.error > 0 and o.wall_seconds > 0:
            s = o.setting
            groups.setdefault((s.algorithm, s.coupling, s.fmu_tolerance), []).append(o)
    several_ft = len({k[2] for k in groups}) > 1
    fig = new_figure(figsize=(12, 5.5))
    axes = fig.subplots(1, 2, sharey=True)
    # colour per master, line style and marker per coupling
    masters = sorted({k[0] for k in groups})
    colours = {m: PALETTE[i % len(PALETTE)] for i, m in enumerate(masters)}
    for key, group in sorted(groups.items()):
        # along the knob (coarse to fine), so timing noise shows as noise, not as a new order
        group.sort(key=lambda o: -o.knob_value)
        label = f"{key[0]}, {key[1]}" + (f", fmu tol {key[2]:.0e}" if several_ft else "")
        ls, marker = COUPLING_STYLES.get(key[1], ("-.", "D"))
        style = dict(color=colours[key[0]], ls=ls, marker=marker, lw=1.2, ms=5, label=label)
        axes[0].loglog([o.wall_seconds for o in group], [o.error for o in group], **style)
        axes[1].loglog([o.do_steps for o in group], [o.error for o in group], **style)
    for ax in axes:
        if target:
            ax.axhline(target, color="k", ls="--", lw=0.8, label=f"target {target:g}")
        ax.grid(True, which="both", alpha=0.3)
    axes[0].set_xlabel("wall time of the run [s]")
    axes[1].set_xlabel("doStep calls, all FMUs [1] (timing-free)")
    axes[0].set_ylabel("error [1]")
    axes[1].legend(fontsize=7)
    fig.suptitle(f"{title}\nerror = {metric_text}", fontsize=9)
    fig.tight_layout()
    save_figure(fig, path)


def plot_estimates(path: Path, outcomes: list[Outcome], title: str) -> None:
    """Estimated against true error, log-log, one marker per master and coupling, with the
    diagonal and the band of a factor 3 either side."""
    from ...cosim.results import PALETTE, new_figure, save_figure

    estimates = [(o, o.extra.get("estimated_error")) for o in outcomes]
    points: list[tuple[Outcome, float]] = [(o, e) for o, e in estimates
                                            if o.ok and o.error > 0 and e is not None and e > 0]
    fig = new_figure(figsize=(6.5, 6))
    ax = fig.subplots()
    masters = sorted({o.setting.algorithm for o, _ in points})
    colours = {m: PALETTE[i % len(PALETTE)] for i, m in enumerate(masters)}
    seen = set()
    for o, e in points:
        key = (o.setting.algorithm, o.setting.coupling)
        ax.loglog(o.error, e, ls="", marker=COUPLING_STYLES.get(key[1], ("", "D"))[1],
                  color=colours[key[0]], label=None if key in seen else f"{key[0]}, {key[1]}")
        seen.add(key)
    if points:
        values = [v for o, e in points for v in (o.error, e)]
        lo, hi = min(values) / 3, max(values) * 3
        ax.loglog([lo, hi], [lo, hi], "k-", lw=0.8, label="estimate = error")
        for f in (3.0, 1 / 3.0):
            ax.loglog([lo, hi], [lo * f, hi * f], "k:", lw=0.8)
    inside = sum(1 for o, e in points if 1 / 3 <= e / o.error <= 3)
    ax.set_xlabel("true error against the monolithic reference [1]")
    ax.set_ylabel("estimated error (Richardson, companion runs) [1]")
    ax.set_title(f"{title}\n{inside} of {len(points)} within a factor 3 (dotted)", fontsize=9)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    save_figure(fig, path)
