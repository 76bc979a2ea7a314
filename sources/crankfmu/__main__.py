"""`python -m crankfmu` (and the `crankfmu` script): the command line, with Ctrl-C handled
whenever it comes.

Exit status 130 after any Ctrl-C, and never a traceback for one:
- while Python imports crankfmu's commands and parses the command line (the first ~0.2-1 s)
  nothing has started: leave at once, before any exception can arise inside an import (the
  handler is this module's first statement; before it, the interpreter's own start-up,
  site.py and runpy, handle Ctrl-C as for any Python program);
- while a command runs, the first Ctrl-C raises KeyboardInterrupt (a run's stepping loop
  turns it into "interrupted, partial results written": crankfmu.cosim.runner), and any later
  one only counts, so the command's own clean-up is not cut short;
- after the command, the interpreter's exit handlers (removing unpacked FMUs, releasing the
  FMU binaries, stopping worker pools) run here with Ctrl-C only counted, and the process ends
  with os._exit: nothing runs after the last check of the count, so an interrupt can neither
  print "Exception ignored in atexit" nor leave the exit status at 0, nor kill the process by
  SIGINT after its results were written.
"""
import _signal  # the C module: its import takes microseconds (signal's imports enum first)
import os


def _leave_now(signum, frame):  # during the imports: nothing to save or clean up
    os.write(2, b"error: interrupted (Ctrl-C)\n")
    os._exit(130)


if __name__ == "__main__":  # the first thing `python -m crankfmu` runs
    _signal.signal(_signal.SIGINT, _leave_now)

import signal  # noqa: E402 - after the handler: enum takes milliseconds to import
import sys  # noqa: E402

_INTERRUPTED = "error: interrupted (Ctrl-C)\n"


class _Interrupts:
    """The Ctrl-Cs received while the command runs; only the first one raises."""

    count = 0

    @classmethod
    def first_raises(cls, signum, frame):
        cls.count += 1
        if cls.count == 1:
            raise KeyboardInterrupt

    @classmethod
    def only_count(cls, signum, frame):
        cls.count += 1


def run() -> None:
    signal.signal(signal.SIGINT, _leave_now)  # (again, for the `crankfmu` script's import)
    status, finished = None, False
    try:
        from .cli import parse, run_command
        args = parse()  # imports every command: Ctrl-C still leaves at once
        signal.signal(signal.SIGINT, _Interrupts.first_raises)
        status = run_command(args)
        finished = not _Interrupts.count  # uncut: a Ctrl-C from here on is after it
        # switched inside the try: the one KeyboardInterrupt first_raises raises is caught
        # here wherever it lands, and none comes after this line
        signal.signal(signal.SIGINT, _Interrupts.only_count)
    except SystemExit as exc:  # argparse: --help, --version, a usage error
        signal.signal(signal.SIGINT, _Interrupts.only_count)
        status = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 2)
        if not isinstance(exc.code, (int, type(None))):
            sys.stderr.write(f"{exc.code}\n")
    except BaseException:
        if not _Interrupts.count:
            raise  # not an interrupt: a fault of crankfmu's, shown with its traceback
        # the KeyboardInterrupt itself, or what an import made of it (numpy's C extension
        # turns one into an ImportError); after the command finished, its status stands
        status = status if finished else None
    if _Interrupts.count and not finished and status != 130:  # the command was cut short
        sys.stderr.write(_INTERRUPTED)
        status = 130
    _exit(130 if status is None else status)  # None only after an interrupt


def _exit(status: int) -> None:
    """Run the exit handlers with Ctrl-C counted only, flush, and leave (module docstring)."""
    import atexit
    signal.signal(signal.SIGINT, _Interrupts.only_count)
    try:
        atexit._run_exitfuncs()
    except BaseException:  # noqa: BLE001 - a failing clean-up does not change the result
        pass
    if _Interrupts.count and status != 130:  # after the command: what it wrote is complete
        sys.stderr.write("error: interrupted (Ctrl-C) while exiting; the command had "
                         "finished\n")
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):
            pass
    os._exit(130 if _Interrupts.count else status)


if __name__ == "__main__":
    run()
