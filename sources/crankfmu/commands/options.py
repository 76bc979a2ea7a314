"""The options the commands share, one helper per family (docs/cli.md states the convention;
tests/test_cli_options.py checks it on the parsers): each command takes the families that mean
something to it, and every option it accepts is read by it.

    scene      SCENE, --set REF=V, --stop-time S      (every command that loads a scene)
    master     --step, --algorithm, the masters' own options, --fmu-tolerance, --max-steps
    fmus       --fmus DIR
    output     --out DIR (the output folder), --plot (a flag: figures are opt-in), --no-progress
    jobs       --jobs N (1: in this process; N > 1: worker processes; 0: one per core),
               --scheduler ADDRESS (a Dask cluster; studies only)
"""
from __future__ import annotations

import argparse
from pathlib import Path


def add_scene_options(p: argparse.ArgumentParser, scene_help: str = "scene file (.toml or .ssp)"
                      ) -> None:
    """The scene and what changes it: --set, --stop-time (every command that loads one)."""
    p.add_argument("scene", type=Path, help=scene_help)
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="REF=V",
                   help="override comp.param=V (a parameter), comp.input=V (an unconnected "
                        "input, held constant) or master.key=V (a [master] key, e.g. "
                        "master.step=2e-3); repeatable")
    p.add_argument("--stop-time", type=float, metavar="S",
                   help="end of the run [s] (default: the scene's [scene].stop_time)")


def add_step_option(p: argparse.ArgumentParser, help: str = "communication step [s] "
                    "(default: the scene's [master].step)") -> None:
    p.add_argument("--step", type=float, metavar="S", help=help)


def add_master_options(p: argparse.ArgumentParser) -> None:
    """How the master runs the scene (run, export-ssp)."""
    add_step_option(p)
    from ..masters import MASTERS, all_options
    p.add_argument("--algorithm", choices=sorted(MASTERS),
                   help="master algorithm (default: the scene's [master].algorithm)")
    for option in all_options().values():  # each master's own options, from its declaration
        takers = [n for n, c in MASTERS.items() if option in c.options]
        own = "".join(f"; {n}'s default {c.defaults[option.name]:g}" for n, c in MASTERS.items()
                      if option.name in c.defaults)
        p.add_argument(f"--{option.name.replace('_', '-')}", type=option.kind,
                       choices=option.choices, dest=f"master_{option.name}",
                       metavar=None if option.choices else option.name.upper(),
                       help=f"{option.describe()}{own} (masters: {', '.join(takers)}; "
                            f"[master].{option.name})")
    p.add_argument("--fmu-tolerance", type=float, metavar="TOL",
                   help="each FMU's internal relative tolerance [1] (default: the scene's "
                        "[master].fmu_tolerance)")
    p.add_argument("--max-steps", type=int, metavar="N",
                   help="the most communication steps the run may take (default: the scene's "
                        "[master].max_steps, else 10,000,000)")


def add_fmu_option(p: argparse.ArgumentParser) -> None:
    """Where the built FMUs are (every command that loads FMUs)."""
    p.add_argument("--fmus", type=Path, metavar="DIR",
                   help="folder of built FMUs (default fmus/ beside scenarios/; catalog FMUs are "
                        "built there if stale)")


def add_output_options(p: argparse.ArgumentParser, out_help: str, plot_help: str | None = None,
                       progress: bool = True) -> None:
    """--out DIR (always the output folder, with a default under results/: the command writes
    its files there under names it chooses, and nothing outside it), --plot (a flag: figures
    are written only when asked for), --no-progress."""
    p.add_argument("--out", type=Path, metavar="DIR", help=out_help)
    if plot_help:
        p.add_argument("--plot", action="store_true", help=plot_help)
    if progress:
        p.add_argument("--no-progress", action="store_true",
                       help="no progress bars or progress lines on stderr")


def add_jobs_option(p: argparse.ArgumentParser, what: str, scheduler: bool = True) -> None:
    """--jobs N, one meaning everywhere (run, sweep, accuracy, compare): the processes to use,
    1 (default) this one; and for the studies (`scheduler`) --scheduler ADDRESS."""
    more = "N processes" if scheduler else "this process and N - 1 workers beside it"
    p.add_argument("--jobs", type=jobs_count, default=1, metavar="N",
                   help=f"processes for {what}: 1 (default) runs everything in this process, "
                        f"one run after another; N > 1 {more}; 0 one per core")
    if scheduler:
        p.add_argument("--scheduler", metavar="ADDRESS",
                       help="run on a Dask distributed cluster, e.g. tcp://HOST:8786, instead of "
                            "local processes (workers need the same crankfmu; FMUs and scenes are "
                            "sent to them)")


def jobs_count(text: str) -> int:
    """An argparse type: --jobs N, an integer >= 0 (0: one per core)."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"a whole number >= 0, got {text!r}") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be >= 0 (0: one per core), got {value}")
    return value


def load_with_options(args):
    """The scene with command-line overrides applied (shared by run-like commands); every value
    is checked as the same key in a scene file would be."""
    from ..errors import MAX_TIME
    from ..system.load import load_scene
    from ..system.scene import SceneError, _integer, _number, apply_overrides, check_run_size

    scene = load_scene(args.scene)
    apply_overrides(scene, args.overrides)
    m = scene.master
    if args.stop_time is not None:
        scene.stop_time = _number(scene.path, "--stop-time", args.stop_time,
                                  minimum=-MAX_TIME, maximum=MAX_TIME)
        if scene.stop_time <= scene.start_time:
            raise SceneError(scene.path, "--stop-time", f"must exceed start_time = {scene.start_time}")
    for key in ("step", "fmu_tolerance"):
        value = getattr(args, key, None)
        if value is not None:
            setattr(m, key, _number(scene.path, f"--{key.replace('_', '-')}", value,
                                    positive=True, maximum=None if key == "step" else 1.0))
    if getattr(args, "max_steps", None) is not None:
        m.max_steps = _integer(scene.path, "--max-steps", args.max_steps, minimum=1,
                               maximum=10**12)
    if getattr(args, "algorithm", None):
        m.algorithm = args.algorithm
    master_options_from(args, scene)
    check_run_size(scene, "--step" if getattr(args, "step", None) is not None else "[master].step")
    return scene


def master_options_from(args, scene) -> None:
    """--extrapolation, --tolerance, ...: the options the masters declare, each checked
    against its declaration (a master that does not take one ignores it)."""
    from ..masters import all_options
    from ..system.scene import set_value
    for name in all_options():
        value = getattr(args, f"master_{name}", None)
        if value is not None:
            set_value(scene, f"master.{name}", value, f"--{name.replace('_', '-')}")


def progress_lines(args):
    """A callable printing a line of progress on stderr, or None with --no-progress (and -q)."""
    if getattr(args, "no_progress", False):
        return None
    import sys
    return lambda line: print(line, file=sys.stderr, flush=True)
