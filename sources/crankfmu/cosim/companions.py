"""Companion runs (the error estimate's, the `--target` search's) beside the main run.

An estimate needs the run and at least one companion run of the same scene at another setting
(cosim/estimate.py), and on most scenes a companion costs about what the run costs (the FMUs'
own integration dominates, not the communication steps). The runs are independent, so with a
spare core the companions run in a worker process while this process runs the main run: the
estimate then costs the slower of the two in wall time instead of their sum.

    Companions(jobs)      jobs = 1: each companion runs in this process when its result is
                          asked for (after the main run); jobs > 1: a pool of jobs - 1 workers
                          (cosim/workers.py: forked on Linux, else fresh interpreters; they end
                          with this process however it ends; the pool starts when the object is
                          made, so its start-up overlaps the parent's own work).
    submit(run, *args) -> Pending; Pending.result() -> run(*args), a CompanionRun
                          (run: a module-level function, cosim.runner.run_companion)

Measured (benchmarks/estimate_cost.py, benchmarks/target.py; docs/error_estimate.md, "What it
costs"): a spawned worker takes about 0.35 s to start, a forked one little; either needs a free
core, so the command line's default is 1.

A run's numbers are a function of its scene and the FMU files only, so a companion gives the same
series wherever it ran (tests/test_companions.py). The FMUs must exist in fmu_dir before a worker
loads them (the parent builds them: two processes would otherwise build into one folder).
"""
from __future__ import annotations

import contextlib
import os
import sys
from dataclasses import dataclass
from typing import TYPE_CHECKING

from ..errors import CrankfmuError

if TYPE_CHECKING:
    from .workers import Lifeline

# what a script must do for worker processes (multiprocessing's spawn and forkserver import the
# script again in each worker, as the module __mp_main__: its body runs there up to the call
# that starts them)
MAIN_GUARD = ("worker processes (jobs > 1) import the calling script again, so a script that "
              "starts them must make its calls under `if __name__ == \"__main__\":`; or use "
              "jobs=1, which runs everything in the calling process")


class WorkerStartError(CrankfmuError, RuntimeError):
    """Worker processes could not start (a script without a main guard, MAIN_GUARD)."""


@contextlib.contextmanager
def guarded_start():
    """Around the calls that make a pool and start its worker processes: in a worker (spawned,
    or from a fork server) still importing the script (the script's body ran again there,
    without a main guard) it raises WorkerStartError saying so, before the pool is made. Made
    there, the pool's semaphores outlived the worker, and the resource tracker's warning about
    them could come after the parent's error, as the last line a user reads.
    multiprocessing's own RuntimeError for that case becomes the same WorkerStartError."""
    refuse_in_importing_worker()
    try:
        yield
    except RuntimeError as err:
        if "bootstrapping phase" not in str(err):
            raise
        raise _importing_worker_error() from None


def refuse_in_importing_worker() -> None:
    """WorkerStartError in a worker process that is still importing the calling script (its
    body ran again there, without a main guard): the API's studies ask first, before they make
    a temporary folder, which a worker stopped while it imports (before its exit handlers are
    set) left behind in the system's temporary folder."""
    multiprocessing = sys.modules.get("multiprocessing")  # not imported: not such a worker
    # spawn's own test (multiprocessing.spawn._check_not_importing_main)
    if multiprocessing is not None and \
            getattr(multiprocessing.current_process(), "_inheriting", False):
        raise _importing_worker_error()


def _importing_worker_error() -> WorkerStartError:
    return WorkerStartError(f"crankfmu was called while a worker process imported the script: "
                            f"{MAIN_GUARD}")


def processes(jobs: int) -> int:
    """The processes `--jobs N` (and the API's `jobs`) means: N, or one per core for 0
    (docs/cli.md: one meaning of --jobs for every command)."""
    return jobs if jobs >= 1 else max(1, os.cpu_count() or 1)


@dataclass
class CompanionRun:
    series: tuple | None   # (times, columns) as estimate.recorder_series gives; None: it stopped
    wall_seconds: float
    reason: str = ""       # why it stopped
    result: object = None  # the cosim.runner.RunResult (the --target search may choose it)


class Pending:
    """A companion submitted: in a worker (a future; `started`, the future of the pool's first
    task) or to run here when asked for."""

    def __init__(self, future=None, call=None, started=None):
        self._future, self._call, self._done = future, call, None
        self._started = started

    def result(self) -> CompanionRun:
        """The companion's CompanionRun; WorkerStartError when the worker ended as it started
        (a script without a main guard)."""
        if self._done is None:
            self._done = self._call() if self._future is None else self._from_worker()
        return self._done

    def _from_worker(self) -> CompanionRun:
        from concurrent.futures.process import BrokenProcessPool
        try:
            return self._future.result()
        except BrokenProcessPool:
            if self._started.done() and self._started.exception() is None:
                raise  # the worker started and died in the run
            raise WorkerStartError(f"the companion runs' worker process ended as it started; "
                                   f"{MAIN_GUARD}") from None

    def cancel(self) -> None:
        if self._future is not None:
            self._future.cancel()


class Companions:
    """Where companion runs execute (module docstring). Use as a context manager."""

    def __init__(self, jobs: int = 1):
        self.jobs = processes(int(jobs))
        self._pool = None
        self._lifeline: Lifeline | None = None
        if self.jobs > 1:  # multiprocessing imported here: a run without workers skips it
            from .workers import new_pool, ready
            with guarded_start():  # start the workers now, while the parent loads the FMUs
                self._pool, self._lifeline = new_pool(self.jobs - 1)
                self._started = self._pool.submit(ready)

    def submit(self, run, *args) -> Pending:
        if self._pool is None:
            return Pending(call=lambda: run(*args))
        return Pending(future=self._pool.submit(run, *args), started=self._started)

    def close(self, abandon: bool = False) -> None:
        """Shut the workers down; `abandon`: stop them even in the middle of a run (the main
        run stopped, or the search is done: nobody will ask for the result)."""
        if self._pool is None or self._lifeline is None:  # no workers (both are set together)
            return
        from .workers import close_pool
        close_pool(self._pool, self._lifeline, abandon)
        self._pool = None

    def __enter__(self):
        return self

    def __exit__(self, exc_type, *exc):
        self.close(abandon=exc_type is not None)
