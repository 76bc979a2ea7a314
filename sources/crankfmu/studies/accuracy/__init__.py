"""What accuracy costs: a sweep of master settings against the monolithic reference.

`run_accuracy(scene, AccuracyOptions(...))` computes (or reads from the cache in the output
folder) the reference, runs every setting with a tqdm bar, and writes accuracy.csv with its
sidecar accuracy.json (the metric, the columns' units) and with `plot` work_precision.png and
estimate_vs_error.png; `crankfmu accuracy` prints the table, the observed orders and, given an
error to meet (`meet`), the cheapest setting that meets it.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from ..table import Table
from ...cosim.events import EventError, EventSpec, event_error, event_errors, parse_event_specs
from ...cosim.metrics import (METRICS, Metric, MetricError, make_metric, observed_order, scene_event_specs,
                      scene_metric_name, steady_figures)
from .report import (COLUMNS, UNITS, format_orders, format_outcome, format_table, plot_estimates,
                     plot_work_precision, table_row, write_table_csv)
from .sweep import (FLOOR_FACTOR, UNSTABLE_ERROR, Outcome, Setting, check_run_files, cheapest,
                    fewest_steps, load_or_solve_reference, orders,
                    read_reference_file, reference_grid, resume_key, run_settings,
                    settings_for)

if TYPE_CHECKING:
    from ..executor import Executor

DEFAULT_STEP_FACTORS = (4.0, 2.0, 1.0, 0.5)          # x the scene's step
DEFAULT_TOLERANCES = (1e-2, 1e-3, 1e-4)              # a variable-step master's sweep
# Left out of the default grid: a variable-step master with extrapolation 0 bounds a held
# input's error, which is first order in the step, so tight tolerances cost ~1/tol steps
# (servo press, 1 s, tolerance 1e-4: 150,000 doStep calls and 38 s, against 802 calls with
# extrapolation 2). Asked for explicitly (--algorithms adaptive --extrapolations 0) it runs.
DEFAULT_GRID_EXCLUDES = {("variable-step", 0)}
# Taylor couplings in the default grid, for the masters that take [master].taylor, on scenes
# whose FMUs offer the output derivatives (cosim/coupling.py)
DEFAULT_TAYLORS = (2, 3, 4)


@dataclass
class AccuracyOptions:
    out_dir: Path
    algorithms: list[str] | None = None        # default: every master in MASTERS
    extrapolations: list[int] = field(default_factory=lambda: [0, 1, 2])
    taylors: list[int] | None = None           # default: with algorithms None (the default
                                               # grid), the DEFAULT_TAYLORS the FMUs offer
    steps: list[float] | None = None           # default: DEFAULT_STEP_FACTORS x scene step
    tolerances: list[float] = field(default_factory=lambda: list(DEFAULT_TOLERANCES))
    fmu_tolerances: list[float] | None = None  # default: the scene's
    metric: str | None = None                  # default: the scene's (scene_metric_name)
    reference_csv: Path | None = None          # a reference from elsewhere, run CSV layout
    report: object | None = None               # report(outcome, kept) as each run finishes
    resume: bool = True                        # take finished runs from out_dir/runs
    variables: list[str] | None = None
    cycles: int = 1
    meet: float | None = None                  # an error to meet: cheapest, fewest_steps
    plot: bool = False                         # work_precision.png, estimate_vs_error.png
    reference_rtol: float = 1e-10
    floor_factor: float = FLOOR_FACTOR
    fmu_dir: Path | None = None
    progress: bool | None = None
    jobs: int | None = 1                       # 1: in this process; N > 1 worker processes;
    #                                            0: one per core (cosim.companions.processes)
    scheduler: str | None = None               # a Dask scheduler's address instead
    executor: Executor | None = None           # default: make_executor(jobs, scheduler)
    estimate: bool = True                      # the error estimate of each run (its companions)
    out_option: str = "--out"                  # how errors name out_dir (the API: "out")


@dataclass
class AccuracyResult(Table):
    """The sweep's outcomes and what was learnt from them; as a table (`rows`, `units`,
    `to_pandas()`) the rows of accuracy.csv. `cheapest` and `fewest_steps`: the settings meeting
    options.meet (None without it). Paths are None where nothing was written (the API without
    `out`; `figures` without `plot`)."""

    outcomes: list[Outcome]
    orders: dict
    cheapest: Outcome | None
    fewest_steps: Outcome | None
    metric: Metric
    reference_csv: Path | None
    reference_cached: bool
    csv: Path | None
    sidecar: Path | None = None
    figures: list[Path] = field(default_factory=list)

    @property
    def png(self) -> Path | None:
        """work_precision.png, if drawn."""
        return self.figures[0] if self.figures else None

    @property
    def columns(self) -> list[str]:
        return list(COLUMNS)

    @property
    def units(self) -> dict:
        return dict(UNITS)

    @property
    def rows(self) -> list[dict]:
        return [table_row(o, self.metric.name) for o in self.outcomes]


def run_accuracy(scene, options: AccuracyOptions) -> AccuracyResult:
    import copy

    from ...masters import MASTERS

    specs = scene_event_specs(scene)
    name = options.metric or scene_metric_name(scene)
    if name == "events":  # the event figures are recorded by the runs and the reference
        scene = copy.deepcopy(scene)
        scene.record = list(dict.fromkeys(scene.record + [v for s in specs for v in s.needs]))
    metric = make_metric(name, scene.record, options.variables, options.cycles, specs)
    taylors = options.taylors
    if taylors is None:  # the default grid (every master) has those the FMUs offer
        from ...cosim.coupling import taylor_orders_offered
        taylors = [] if options.algorithms is not None else \
            taylor_orders_offered(scene, options.fmu_dir, DEFAULT_TAYLORS)
    settings = settings_for(
        scene, options.algorithms or list(MASTERS), options.extrapolations,
        options.steps or [f * scene.master.step for f in DEFAULT_STEP_FACTORS],
        options.fmu_tolerances or [scene.master.fmu_tolerance], options.tolerances, taylors)
    if options.algorithms is None:
        settings = [s for s in settings if not _excluded_by_default(s)]
    from .estimates import add_estimates, extra_companions
    companions = extra_companions(settings) if options.estimate else []
    out = check_outputs(Path(options.out_dir), settings + companions, options)
    ref, ref_csv, cached, ref_key = _reference(scene, settings + companions, metric, out,
                                               options)
    from ..executor import make_executor
    executor = options.executor or make_executor(options.jobs, options.scheduler)
    try:
        outcomes = run_settings(scene, settings + companions, metric, ref, options.fmu_dir,
                                out / "runs",
                                executor, options.progress, f"{scene.name} accuracy sweep",
                                _rows_only(options.report, set(companions)),
                                resume_key(ref_key, metric) if options.resume else None)
    finally:
        if options.executor is None:
            executor.close()
    outcomes = outcomes[:len(settings)]  # the companions only serve the estimates
    if options.estimate:
        add_estimates(outcomes, metric, out / "runs")
    csv = out / "accuracy.csv"
    sidecar = write_table_csv(csv, outcomes, metric)
    figures = _figures(scene, outcomes, metric, out, options) if options.plot else []
    meet = options.meet
    return AccuracyResult(outcomes, orders(outcomes, options.floor_factor),
                          None if meet is None else cheapest(outcomes, meet),
                          None if meet is None else fewest_steps(outcomes, meet), metric,
                          ref_csv, cached, csv, sidecar, figures)


def _figures(scene, outcomes, metric, out: Path, options: AccuracyOptions) -> list[Path]:
    """work_precision.png and (with the estimate) estimate_vs_error.png."""
    span = f"t = {scene.start_time:g} to {scene.stop_time:g} s"
    figures = [out / "work_precision.png"]
    plot_work_precision(figures[0], outcomes, metric.describe(), options.meet,
                        f"{scene.name}: work-precision, {span}")
    if options.estimate:
        figures.append(out / "estimate_vs_error.png")
        plot_estimates(figures[1], outcomes, f"{scene.name}: estimated against true error, "
                                             f"{span}")
    return figures


def check_outputs(out: Path, settings: list[Setting], options: AccuracyOptions) -> Path:
    """Before the reference and the runs: at most MAX_STUDY_RUNS runs, the output folder and
    every name written there and in runs/ (crankfmu.outputs); returns the folder."""
    from ...cosim.results import check_run_set
    from ...errors import MAX_STUDY_RUNS, OptionError
    from ...outputs import check_files
    if len(settings) > MAX_STUDY_RUNS:
        raise OptionError(f"{len(settings)} runs (algorithms x extrapolations x steps or "
                          f"tolerances x FMU tolerances, with the estimates' companions), more "
                          f"than the limit of {MAX_STUDY_RUNS} runs of one study")
    check_files(out, ["accuracy.csv", "accuracy.json", "work_precision.png",
                      "estimate_vs_error.png"],
                options.out_option)
    check_run_set(out / "reference.csv", options.out_option)
    check_run_files(out / "runs", settings, options.out_option)
    return out


def _reference(scene, settings, metric: Metric, out: Path, options: AccuracyOptions):
    """(samples, csv, cached, key): the reference file given, or crankfmu's own (cached)."""
    import hashlib
    import json

    if options.reference_csv is not None:
        path = Path(options.reference_csv)
        ref = read_reference_file(path, metric.variables, scene.start_time, scene.stop_time)
        return ref, path, False, hashlib.sha256(path.read_bytes()).hexdigest()
    ref, csv, cached = load_or_solve_reference(scene, reference_grid(scene, settings), out,
                                               options.reference_rtol, options.progress)
    key = json.loads(csv.with_suffix(".json").read_text()).get("cache_key", "")
    return ref, csv, cached, key


def _rows_only(report, companions: set):
    """`report` called for the table's runs only (the companions are not rows)."""
    if report is None or not companions:
        return report
    return lambda outcome, kept: None if outcome.setting in companions else report(outcome, kept)


def _excluded_by_default(setting: Setting) -> bool:
    from ...masters import traits
    kind = "variable-step" if traits(setting.algorithm).variable_step else setting.algorithm
    return (kind, setting.extrapolation) in DEFAULT_GRID_EXCLUDES and not setting.taylor


__all__ = ["AccuracyOptions", "AccuracyResult", "DEFAULT_TAYLORS", "EventError", "EventSpec",
           "METRICS", "Metric", "MetricError", "Outcome", "Setting", "UNSTABLE_ERROR", "cheapest", "event_error",
           "event_errors", "fewest_steps", "format_orders", "format_outcome", "format_table",
           "make_metric", "observed_order", "orders", "parse_event_specs", "run_accuracy",
           "scene_event_specs", "scene_metric_name", "steady_figures"]
