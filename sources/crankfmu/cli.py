"""The `crankfmu` command: run, build, and the commands in crankfmu/commands/."""
from __future__ import annotations

import argparse
import importlib
import pkgutil
import sys
from pathlib import Path

from .version import __version__


# -- shared options: one helper per family; each command takes the families that mean something
# -- to it (tests/test_cli_options.py checks that every option a command accepts is read by it)
def add_scene_options(p: argparse.ArgumentParser, scene_help: str = "scene file (.toml or .ssp)"
                      ) -> None:
    """The scene and what changes it: --set, --stop-time (every command that loads one)."""
    p.add_argument("scene", type=Path, help=scene_help)
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="REF=V",
                   help="override comp.param=V (a parameter), comp.input=V (an unconnected "
                        "input, held constant) or master.key=V (a [master] key, e.g. "
                        "master.step=2e-3); repeatable")
    p.add_argument("--stop-time", type=float, help="end of the run [s]")


def add_step_option(p: argparse.ArgumentParser, help: str = "communication step [s] "
                    "([master].step)") -> None:
    p.add_argument("--step", type=float, help=help)


def add_master_options(p: argparse.ArgumentParser) -> None:
    """How the master runs the scene (run, export-ssp)."""
    add_step_option(p)
    from .masters import MASTERS, all_options
    p.add_argument("--algorithm", choices=sorted(MASTERS),
                   help="master algorithm ([master].algorithm)")
    for option in all_options().values():  # each master's own options, from its declaration
        takers = [n for n, c in MASTERS.items() if option in c.options]
        own = "".join(f"; {n}'s default {c.defaults[option.name]:g}" for n, c in MASTERS.items()
                      if option.name in c.defaults)
        p.add_argument(f"--{option.name.replace('_', '-')}", type=option.kind,
                       choices=option.choices, dest=f"master_{option.name}",
                       metavar=None if option.choices else option.name.upper(),
                       help=f"{option.describe()}{own} (masters: {', '.join(takers)}; "
                            f"[master].{option.name})")
    p.add_argument("--fmu-tolerance", type=float,
                   help="each FMU's internal relative tolerance ([master].fmu_tolerance)")
    p.add_argument("--max-steps", type=int, help="the most communication steps the run may take "
                   "([master].max_steps; default 10,000,000)")


def add_fmu_option(p: argparse.ArgumentParser) -> None:
    """Where the built FMUs are (every command that loads FMUs)."""
    p.add_argument("--fmus", type=Path, help="folder of built FMUs (default fmus/ beside "
                                             "scenarios/; catalog FMUs are built there if stale)")


def add_output_options(p: argparse.ArgumentParser, out_help: str, plot_help: str | None = None,
                       progress: bool = True) -> None:
    """--out DIR (always the output folder, with a default under results/: the command writes
    its files there under names it chooses, and nothing outside it), --plot, --no-progress."""
    p.add_argument("--out", type=Path, metavar="DIR", help=out_help)
    if plot_help:
        p.add_argument("--plot", action="store_true", help=plot_help)
    if progress:
        p.add_argument("--no-progress", action="store_true", help="no progress bar")


def _add_run_options(p: argparse.ArgumentParser) -> None:
    """`crankfmu run`'s options."""
    add_scene_options(p)
    add_master_options(p)
    add_fmu_option(p)
    add_output_options(p, "output folder (default results/): <scene name>.csv, its JSON "
                          "sidecar <scene name>.json and with --plot <scene name>.png",
                       "also write a PNG of the recorded variables")
    p.add_argument("--log", action="store_true", help="print the FMUs' log messages")
    p.add_argument("--target", type=float, metavar="TOL",
                   help="the global error wanted (the scene's accuracy metric): choose master, "
                        "extrapolation and step from the error estimate ([master].target)")
    p.add_argument("--no-estimate", action="store_true",
                   help="skip the error estimate (its companion at half the step costs "
                        "1.1-1.7 x the run: README, \"What it costs\")")
    p.add_argument("--jobs", type=positive_integer, default=1,
                   help="processes for the run and the companion runs of its estimate (and of "
                        "--target's search): 2 runs the companions in a worker beside the run "
                        "(pays on runs of seconds with a free core); 1 (default) after it, here")


def positive_integer(text: str) -> int:
    """An argparse type: an integer >= 1 (--jobs)."""
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1, got {value}")
    return value


def load_with_options(args):
    """The scene with command-line overrides applied (shared by run-like commands); every value
    is checked as the same key in a scene file would be."""
    from .errors import MAX_TIME
    from .system.load import load_scene
    from .system.scene import SceneError, _integer, _number, apply_overrides, check_run_size

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
    _master_options_from(args, scene)
    check_run_size(scene, "--step" if getattr(args, "step", None) is not None else "[master].step")
    return scene


def _master_options_from(args, scene) -> None:
    """--extrapolation, --tolerance, ...: the options the masters declare, each checked
    against its declaration (a master that does not take one ignores it)."""
    from .masters import all_options
    from .system.scene import set_value
    for name in all_options():
        value = getattr(args, f"master_{name}", None)
        if value is not None:
            set_value(scene, f"master.{name}", value, f"--{name.replace('_', '-')}")


def cmd_run(args) -> int:
    from .cosim.results import check_run_set
    from .cosim.runner import RunOptions, run_scene
    from .system.scene import _number

    scene = load_with_options(args)
    if args.target is not None:
        scene.master.target = _number(scene.path, "--target", args.target, positive=True,
                                      maximum=1.0)
    out = check_run_set((args.out or Path("results")) / f"{scene.name}.csv")  # before running
    if scene.master.target is not None:
        return _run_target(scene, out, args)
    result = run_scene(scene, RunOptions(out=out, plot=args.plot, fmu_dir=args.fmus,
                                         progress=False if args.no_progress else None,
                                         verbose_log=args.log, estimate=not args.no_estimate,
                                         jobs=args.jobs))
    _print_run(scene, result)
    return 0


def _run_target(scene, out: Path, args) -> int:
    """--target: search the setting (crankfmu.cosim.target), write the chosen run."""
    from .cosim.target import TargetNotMet, search, write_chosen
    try:
        echo = None if args.no_progress else lambda line: print(line, file=sys.stderr)
        result, report = search(scene, scene.master.target, args.fmus, args.jobs, echo)
    except TargetNotMet as err:
        print(f"{scene.name}: target not met. {err}")
        return 1
    write_chosen(scene, result, report, out, args.plot)
    m = result.metadata["master"]
    knob = f"tolerance {report.tolerance:g}" if m["step"] != report.step or \
        m["algorithm"] == "adaptive" else f"step {m['step']:g} s"
    coupling = f"taylor {m['taylor']}" if m.get("taylor") else \
        f"extrapolation {m.get('extrapolation')}"
    print(f"{scene.name}: target {report.target:g} met by {m['algorithm']}, {coupling}, "
          f"{knob}; the search ran {len(report.runs)} runs in "
          f"{report.wall_seconds:.2f} s wall")
    _print_run(scene, result, report.estimate)
    return 0


def _print_run(scene, result, estimate=None) -> None:
    from .masters import MASTERS
    m = result.metadata.get("master", {})  # the run's setting (--target chooses it)
    cls = MASTERS[m["algorithm"]]
    size = "variable steps" if cls.variable_step else f"steps of {m['step']:g} s"
    own = ", ".join(f"{o.name} {m[o.name]:g}" for o in cls.options if o.name in m)
    print(f"{scene.name}: {result.steps} {size} with {m['algorithm']}" + (f" ({own})" if own
                                                                           else "")
          + f" in {result.wall_seconds:.2f} s wall")
    for name, st in result.statistics.items():
        print(f"  {name}: {st['doStep_calls']} doStep calls, {st['doStep_seconds']:.3f} s, "
              f"{st['rollbacks']} rollbacks")
    extra = {k: v for k, v in result.master_statistics.items()
             if k not in ("algorithm", "extrapolation")}
    if extra:
        print("  master: " + ", ".join(f"{k} {v:.4g}" if isinstance(v, float) else f"{k} {v}"
                                       for k, v in extra.items()))
    for port in result.coupling_error.get("ports", []):
        rel = port["relative_mismatch"]
        print(f"  coupling error at {port['driver']} -> {port['receiver']}: energy mismatch "
              f"{port['mismatch_J']:.4g} J" + (f" ({rel:.3g} of {port['energy_throughput_J']:.4g}"
                                                  f" J through the port)" if rel is not None else ""))
    estimate = estimate or result.estimate
    if estimate is not None:
        from .cosim.estimate import format_estimate
        print("  " + format_estimate(estimate))
    print(f"wrote {result.csv}, {result.sidecar}" + (f", {result.png}" if result.png else ""))
    from .cosim.trust import warning_line
    warning = warning_line(scene.name, result.metadata)
    if warning:
        print(f"warning: {warning}", file=sys.stderr)


def cmd_build(args) -> int:
    import logging

    from .fmu.build import PACKAGE_DIR
    from .fmu.build_fmi3 import build_selected

    logging.getLogger("crankfmu").info("building FMUs from the crankfmu sources at %s",
                                       PACKAGE_DIR)
    from .system.wiring import warn_if_tree_differs
    warn_if_tree_differs(Path.cwd())
    build_selected(args.dest, args.models, args.fmi, args.effects, args.portable)
    return 0


def setup_logging(verbosity: int) -> None:
    """crankfmu's messages (logger "crankfmu": FMU builds, notes) on stderr without file paths:
    -q warnings and errors only, default also progress notes, -v debug details. Python
    warnings go the same way, as `warning: <message>` (`warning: <Category>: <message>` for
    other categories than UserWarning), without the file path and line of the warning."""
    import logging
    import warnings
    level = {-2: logging.ERROR, -1: logging.WARNING, 0: logging.INFO}.get(
        max(-2, min(verbosity, 1)), logging.DEBUG)
    logger = logging.getLogger("crankfmu")
    logger.setLevel(level)
    if not any(getattr(h, "_crankfmu", False) for h in logger.handlers):
        handler = _StderrHandler()
        handler._crankfmu = True
        logger.addHandler(handler)
        logger.propagate = False

    def show(message, category, filename, lineno, file=None, line=None):
        kind = "" if category is UserWarning else f"{category.__name__}: "
        logging.getLogger("crankfmu.warnings").warning("%s%s", kind, message)
    warnings.showwarning = show


def _StderrHandler():
    """A logging handler writing to the current sys.stderr (as print does): `message` for
    notes, `warning: message` / `error: message` above them."""
    import logging

    class Handler(logging.Handler):
        def emit(self, record) -> None:
            try:
                print(_format(record), file=sys.stderr)
            except Exception:  # noqa: BLE001 - as logging.Handler.handleError does
                self.handleError(record)
    return Handler()


def _format(record) -> str:
    import logging
    text = record.getMessage()
    if record.levelno >= logging.ERROR:
        return f"error: {text}"
    if record.levelno >= logging.WARNING:
        return f"warning: {text}"
    return text


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The whole command line; with `command` (a command's name) only that command is
    registered, so `crankfmu run` imports nothing of the studies (`python -X importtime`)."""
    parser = argparse.ArgumentParser(prog="crankfmu", description=__doc__.splitlines()[0])
    parser.add_argument("--version", action="version", version=f"crankfmu {__version__}")
    parser.add_argument("-v", "--verbose", action="count", default=0,
                        help="more messages (debug details)")
    parser.add_argument("-q", "--quiet", action="count", default=0,
                        help="fewer messages: warnings and errors only (-qq: errors only); "
                             "no progress bars")
    sub = parser.add_subparsers(dest="command", required=True)
    if command in (None, "run"):
        run = sub.add_parser("run", help="run a scene")
        _add_run_options(run)
        run.set_defaults(func=cmd_run)
    if command in (None, "build"):
        build = sub.add_parser("build", help="build every FMU into fmus/ (FMI 2.0) and "
                                             "fmus/fmi3/ (FMI 3.0) and validate it")
        from .fmu.build_fmi3 import add_arguments
        add_arguments(build)
        build.set_defaults(func=cmd_build)
    from . import commands
    for mod in pkgutil.iter_modules(commands.__path__):
        if command in (None, mod.name.replace("_", "-")):
            importlib.import_module(f"{commands.__name__}.{mod.name}").register(sub)
    return parser


def _command_named(argv: list[str]) -> str | None:
    """The command `argv` names (its first word after the global options), if it is one;
    None otherwise (then every command is registered: help, or the error listing them)."""
    from . import commands
    words = [a for a in argv if not a.startswith("-")]
    known = {"run", "build"} | {m.name.replace("_", "-")
                                for m in pkgutil.iter_modules(commands.__path__)}
    return words[0] if words and words[0] in known else None


def _skip_final_collection() -> None:
    """At exit the interpreter's last garbage collections walk every object of numpy, fmpy and
    the FMUs' runtimes: ~35 ms of a short run's ~0.3 s of CPU (measured). Objects frozen by an
    exit handler (gc.freeze; exit handlers run before the interpreter's teardown) are not
    walked; the process's memory goes back to the system at its end in any case."""
    import atexit
    import gc
    atexit.unregister(gc.freeze)  # once, however often main runs in a process
    atexit.register(gc.freeze)


def main(argv=None) -> int:
    """Exit status 0, 2 for every crankfmu error (`crankfmu.errors.CrankfmuError`: a bad scene,
    option or archive, a failed run), 130 for Ctrl-C; no traceback for anything a user can do."""
    try:
        args = parse(argv)
    except KeyboardInterrupt:  # Ctrl-C while the commands are imported
        print("error: interrupted (Ctrl-C)", file=sys.stderr)
        return 130
    return run_command(args)


def parse(argv=None):
    """The command line parsed (the named command's module imported: most of start-up)."""
    from . import errors  # noqa: F401 - imported here with the rest (numpy): run_command needs it
    _skip_final_collection()
    argv = sys.argv[1:] if argv is None else list(argv)
    return build_parser(_command_named(argv)).parse_args(argv)


def run_command(args) -> int:
    """Run the parsed command: main's exit statuses."""
    from .errors import CrankfmuError
    setup_logging(args.verbose - args.quiet)
    if args.quiet and hasattr(args, "no_progress"):
        args.no_progress = True
    try:
        return args.func(args)
    except CrankfmuError as err:
        print(f"error: {err}", file=sys.stderr)
        return getattr(err, "exit_status", 2)
    except KeyboardInterrupt:  # Ctrl-C outside a run's stepping loop (loading, building)
        print("error: interrupted (Ctrl-C)", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
