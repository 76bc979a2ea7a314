"""crankfmu: run co-simulation scenes of FMUs of crank-driven machines and study them.

This module builds the command line and dispatches to the command named (each command is a
module of crankfmu.commands with register(subparsers) and its handler; the options they share
are crankfmu.commands.options); it imports no command but the one named.
"""
from __future__ import annotations

import argparse
import importlib
import sys

from .version import __version__

# command name -> its module in crankfmu.commands (in the order `crankfmu --help` lists them)
COMMANDS = {"run": "run", "build": "build", "reference": "reference", "accuracy": "accuracy",
            "sweep": "sweep", "compare": "compare", "analyze": "analyze",
            "structure": "structure", "export-ssp": "export_ssp"}
DESCRIPTION = __doc__.splitlines()[0].split(": ", 1)[1].rstrip(".")


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

    from .errors import warning_text

    def show(message, category, filename, lineno, file=None, line=None):
        logging.getLogger("crankfmu.warnings").warning("%s", warning_text(message, category))
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
    parser = argparse.ArgumentParser(prog="crankfmu", description=DESCRIPTION[0].upper()
                                     + DESCRIPTION[1:] + " (every option: docs/cli.md)")
    parser.add_argument("--version", action="version", version=f"crankfmu {__version__}")
    add_verbosity_options(parser)
    sub = parser.add_subparsers(dest="command", required=True)
    for name, module in COMMANDS.items():
        if command in (None, name):
            importlib.import_module(f"{__package__}.commands.{module}").register(sub)
    for leaf in _leaves(sub):  # -q and -v after the command too: `crankfmu run SCENE -q`
        add_verbosity_options(leaf, after=True)
    return parser


def add_verbosity_options(parser: argparse.ArgumentParser, after: bool = False) -> None:
    """-v/--verbose and -q/--quiet, counted; before the command (`after` False) and after it
    (dest verbose_after, quiet_after: run_command adds them up)."""
    suffix = "_after" if after else ""
    parser.add_argument("-v", "--verbose", action="count", default=0, dest=f"verbose{suffix}",
                        help="more messages (debug details)")
    parser.add_argument("-q", "--quiet", action="count", default=0, dest=f"quiet{suffix}",
                        help="fewer messages: warnings and errors only (-qq: errors only); "
                             "no progress bars")


def _leaves(sub: argparse._SubParsersAction):
    """The parsers of the commands (and of an analyze subject): the ones that take the
    command's own options."""
    for parser in dict.fromkeys(sub.choices.values()):
        inner = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
        yield from (_leaves(inner[0]) if inner else [parser])


def _command_named(argv: list[str]) -> str | None:
    """The command `argv` names (its first word after the global options), if it is one;
    None otherwise (then every command is registered: help, or the error listing them)."""
    words = [a for a in argv if not a.startswith("-")]
    return words[0] if words and words[0] in COMMANDS else None


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
    verbosity = args.verbose + args.verbose_after - args.quiet - args.quiet_after
    setup_logging(verbosity)
    if verbosity < 0 and hasattr(args, "no_progress"):
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
