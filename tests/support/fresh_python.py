"""`python -c SCRIPT ARGS...` for tests that need a fresh interpreter (no FMU loaded yet, a
sys.modules of its own), without paying each time for the interpreter's start and the imports
of numpy, fmpy and crankfmu (0.25-0.3 s of CPU a process, measured 2026-11-26).

The script runs in a process forked from multiprocessing's fork server, which started from a
fresh interpreter and imported PRELOAD once: the fork has those modules imported and nothing else
done (no FMU unpacked or loaded, nothing of the test process: the server is not a fork of it).
As in `python -c`: sys.argv is ["-c", *args], the working folder is first on sys.path, file
descriptors 1 and 2 are the captured stdout and stderr (output of C code too), the exit status
is SystemExit's (1 after an uncaught exception, its traceback on stderr), and the atexit
functions run at the end (crankfmu.fmu.archive removes its private folders there).

`crankfmu(ARGS...)`: `python -m crankfmu ARGS...` so (crankfmu/__main__.py run by runpy, as -m
does). What needs the interpreter's own start (its flags and environment read at start-up, the
signals it gets then, a command line as a user types it) runs with subprocess instead."""
from __future__ import annotations

import atexit
import multiprocessing
import os
import subprocess
import sys
import tempfile
import traceback
from pathlib import Path

PRELOAD = ["numpy", "fmpy", "crankfmu.fmu.instance3", "tests.support.importer_support"]
_context = multiprocessing.get_context("forkserver")


def declare_preload(extra: tuple[str, ...] = ()) -> None:
    """What this process's fork server imports when it starts, whoever starts it: PRELOAD and
    `extra`. The server is the process's one (multiprocessing's): crankfmu's worker pools fork
    their workers from it too where the process runs other threads (cosim/workers.py, which
    leaves a preload chosen here as it is), and a Dask LocalCluster its workers (test_sweep.py).
    A running server keeps what it imported."""
    from multiprocessing import forkserver
    if getattr(forkserver._forkserver, "_forkserver_pid", None) is None:
        _context.set_forkserver_preload([*PRELOAD, *extra])


def start_server(extra: tuple[str, ...] = ()) -> None:
    """Start this process's fork server now (if it is not running) with PRELOAD and `extra`
    imported: for a user of the same server that needs more (a Dask LocalCluster whose
    workers start from it: "distributed"), which then serves both."""
    import multiprocessing.forkserver
    declare_preload(extra)
    multiprocessing.forkserver.ensure_running()


def _child(script: str, args: list[str], cwd: str, env: dict, out: str, err: str) -> None:
    """In the fork: the `python -c` of the module docstring; never returns."""
    os.chdir(cwd)
    os.environ.clear()
    os.environ.update(env)
    tempfile.tempdir = None  # read from TMPDIR again at first use, as in a new interpreter
    sys.argv = ["-c", *args]
    sys.path.insert(0, cwd)
    for fd, path in ((1, out), (2, err)):
        target = os.open(path, os.O_WRONLY | os.O_TRUNC)
        os.dup2(target, fd)
        os.close(target)
    sys.stdout = open(1, "w", closefd=False)
    sys.stderr = open(2, "w", closefd=False)
    status = 0
    try:
        exec(compile(script, "<string>", "exec"), {"__name__": "__main__"})
    except SystemExit as stop:  # as the interpreter: None 0, an int itself, else printed, 1
        status = stop.code if isinstance(stop.code, int) else int(stop.code is not None)
        if status and not isinstance(stop.code, int):
            print(stop.code, file=sys.stderr)
    except BaseException:  # noqa: BLE001 - as the interpreter: traceback, status 1
        traceback.print_exc()
        status = 1
    atexit._run_exitfuncs()
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(status)


class Started:
    """A started script: `communicate` waits for it (as subprocess.Popen's: stdout, stderr)."""

    def __init__(self, script: str, args, cwd, env):
        self._folder = tempfile.TemporaryDirectory(prefix="fresh_python_")
        self._out, self._err = (str(Path(self._folder.name) / n) for n in ("out", "err"))
        for path in (self._out, self._err):
            Path(path).touch()
        self.process = _context.Process(target=_child, args=(
            script, [str(a) for a in args], str(cwd or os.getcwd()),
            dict(os.environ if env is None else env), self._out, self._err))
        self.process.start()
        self.returncode: int | None = None

    def communicate(self, timeout: float | None = None) -> tuple[str, str]:
        self.process.join(timeout)
        if self.process.exitcode is None:
            self.process.kill()
            self.process.join()
            raise subprocess.TimeoutExpired(["python", "-c"], timeout)
        self.returncode = self.process.exitcode
        out, err = (Path(p).read_text() for p in (self._out, self._err))
        self._folder.cleanup()
        return out, err


def start(script: str, args=(), cwd=None, env: dict | None = None) -> Started:
    """Start `python -c script *args` (see the module docstring); `env` replaces os.environ."""
    return Started(script, args, cwd, env)


def run(script: str, args=(), cwd=None, env: dict | None = None,
        timeout: float | None = None) -> subprocess.CompletedProcess:
    """`script` run to its end, as subprocess.run(..., capture_output=True, text=True)."""
    started = start(script, args, cwd, env)
    out, err = started.communicate(timeout)
    return subprocess.CompletedProcess(["python", "-c", script, *map(str, args)],
                                       started.returncode, out, err)


CRANKFMU = "import runpy\nrunpy.run_module('crankfmu', run_name='__main__', alter_sys=True)\n"


def crankfmu(args, cwd=None, env: dict | None = None,
             timeout: float | None = None) -> subprocess.CompletedProcess:
    """`python -m crankfmu *args` run to its end (see the module docstring); start(CRANKFMU,
    args) starts it."""
    return run(CRANKFMU, args, cwd, env, timeout)
