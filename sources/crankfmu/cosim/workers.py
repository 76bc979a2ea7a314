"""Worker processes on this machine: how they start, what they drop of their parent, how they
end. Shared by the studies' local pool (crankfmu.studies.executor) and the error estimate's
companion worker (cosim/companions.py).

    new_pool(jobs) -> (pool, Lifeline)   a concurrent.futures.ProcessPoolExecutor whose workers
                                         run start_worker first; closing the Lifeline (or the
                                         parent's death) ends them
    close_pool(pool, lifeline)           shut it down, and remove the temporary folders of
                                         workers that were killed
    start_method()                       "fork", "forkserver" or "spawn" (its docstring says
                                         when)
    worker_dir()                         this process's temporary folder, removed at its exit

On Linux the workers are forked while the parent runs one thread and no FMU call has failed in
it: a copy of the parent starts with crankfmu, fmpy and numpy imported, where a spawned
interpreter spends about 0.25-0.3 s of CPU importing them (benchmarks/sweep.py), and a script
without a main guard is not run again in it. A forked worker drops what is its parent's
(_forget_parent). Otherwise on Linux they come from multiprocessing's fork server: one fresh
interpreter per parent process, started with the first such pool and kept for the next, that
has imported the pool's module and nothing else and forks each worker from there (a few ms; it
never ran an FMU nor another thread). Its workers take the parent's environment as they start
(_adopt_environment), as forked and spawned ones have it. On macOS and Windows they are
spawned (start_method says why).
"""
from __future__ import annotations

import logging
import os
import sys
import tempfile
import threading
from pathlib import Path

WORKER_PREFIX = "crankfmu-worker-"  # a process's temporary folder: <prefix><pid>-<random>
_WORKER_DIR: Path | None = None
_WORKER_DIR_LOCK = threading.Lock()  # made, or removed when the parent is gone: one at a time


def worker_dir(under: Path | None = None) -> Path:
    """This process's temporary folder, made on first use (inside `under` if given: a Dask
    worker's own folder, which Dask removes with it) and removed at the process's exit."""
    global _WORKER_DIR
    with _WORKER_DIR_LOCK:
        if _WORKER_DIR is None:
            import atexit
            import shutil
            _WORKER_DIR = Path(tempfile.mkdtemp(prefix=f"{WORKER_PREFIX}{os.getpid()}-",
                                                dir=under))
            atexit.register(shutil.rmtree, _WORKER_DIR, True)
    return _WORKER_DIR


START_METHODS = ("fork", "forkserver", "spawn")


def start_method() -> str:
    """The workers' start method on Linux: "fork" while this process runs one thread and no
    FMU call has failed in it, else "forkserver"; "spawn" on macOS and Windows. Forking this
    process when it runs other threads can copy a lock another thread holds, and a pythonfmu
    binary can leave the interpreter that ran an exception inside it corrupt
    (fmu.instance.note_failed_call); the fork server is a fresh interpreter that did neither.
    macOS offers no safe fork of a process that has loaded its system libraries (numpy's
    Accelerate), the fork server's included. CRANKFMU_START_METHOD (one of START_METHODS)
    chooses (the tests run each)."""
    import multiprocessing

    from ..fmu.instance import failed_calls
    chosen = os.environ.get("CRANKFMU_START_METHOD", "")
    if chosen in START_METHODS:
        return chosen
    if not sys.platform.startswith("linux") or \
            "forkserver" not in multiprocessing.get_all_start_methods():
        return "spawn"
    return "fork" if threading.active_count() == 1 and not failed_calls() else "forkserver"


class Lifeline:
    """A pipe whose only write end the parent holds and nobody writes to: each worker waits on
    its read end (_end_with_parent), so the workers end when the parent closes it or ends,
    however it ends (kill -9 included: the kernel closes its files)."""

    def __init__(self, context):
        self.reader, self.writer = context.Pipe(duplex=False)

    def close(self) -> None:
        self.reader.close()
        self.writer.close()


def new_pool(jobs: int, preload: str = "crankfmu.cosim.runner"):
    """(a ProcessPoolExecutor of `jobs` workers started by start_method(), its Lifeline). Each
    worker imports the module `preload` as it starts (what its tasks need: by default fmpy,
    lxml, the masters, the wiring)."""
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    method = start_method()
    if method == "forkserver" and not _fork_server_running(preload):
        logging.getLogger("crankfmu").info(
            "the workers are spawned (each imports crankfmu afresh): the fork server "
            "cannot start, its socket's path in the temporary folder %s is longer than the "
            "system allows (set TMPDIR to a shorter one)", tempfile.gettempdir())
        method = "spawn"
    context = multiprocessing.get_context(method)
    lifeline = Lifeline(context)
    pool = ProcessPoolExecutor(max_workers=jobs, mp_context=context, initializer=start_worker,
                               initargs=(lifeline.reader, preload,
                                         lifeline.writer if method == "fork" else None,
                                         dict(os.environ) if method == "forkserver" else None))
    return pool, lifeline


def _fork_server_running(preload: str) -> bool:
    """Start this process's fork server if it is not running; False if it cannot start (its
    socket lies in the temporary folder, and a path longer than AF_UNIX allows, 108 bytes on
    Linux, fails: the pool's workers are then spawned). Started here, it imports `preload` (its
    workers are forked with it imported) instead of multiprocessing's default, the parent's main
    script: run in the server, a script without a main guard would start its study there. A
    server whose imports this process chose otherwise (the tests' own) keeps them: its workers
    import `preload` in start_worker."""
    from multiprocessing import forkserver
    server = getattr(forkserver, "_forkserver", None)
    if getattr(server, "_forkserver_pid", None) is None and \
            getattr(server, "_preload_modules", None) == ["__main__"]:
        forkserver.set_forkserver_preload([preload])
    try:
        forkserver.ensure_running()
    except OSError:
        return False
    return True


def close_pool(pool, lifeline: Lifeline, abandon: bool = False) -> None:
    """Shut `pool` (of new_pool) down and close its `lifeline`; `abandon`: stop its workers even
    in the middle of a task, and do not wait for them. Then remove the temporary folders of
    every worker that has ended without removing them: a SIGKILL (kill -9, the kernel's
    out-of-memory killer) runs no exit handler, and each such death in a study left a folder
    in the temporary folder for good. A worker still ending (on the SIGTERM of `abandon`)
    removes its own."""
    # the pool has no public list of its processes, nor a kill: its worker processes are these
    workers = dict(getattr(pool, "_processes", None) or {})
    if abandon:
        for process in workers.values():
            process.terminate()
    pool.shutdown(wait=not abandon, cancel_futures=True)
    lifeline.close()
    _remove_folders_of_ended(workers)


def _remove_folders_of_ended(workers: dict) -> None:
    """The folders (worker_dir's, the FMUs a worker unpacked privately) of the processes in
    `workers` (pid -> multiprocessing.Process) that have ended. Their names carry the pid; one
    that ended normally left none to find."""
    from ..fmu.archive import PRIVATE_PREFIX, remove_tree
    tmp = Path(tempfile.gettempdir())  # where a worker makes them: it inherits the setting
    for pid, process in workers.items():
        if process.exitcode is None:  # still ending
            continue
        for prefix in (WORKER_PREFIX, PRIVATE_PREFIX):
            for folder in tmp.glob(f"{prefix}{pid}-*"):
                remove_tree(folder)


def ready() -> int:
    """A task that does nothing: submitted once per worker when a pool starts, so that every
    worker starts (and imports, in start_worker) at once; returns the worker's pid."""
    return os.getpid()


def start_worker(lifeline, preload: str, parent_end=None, environment=None) -> None:
    """A pool worker's initializer. It imports `preload`, as the pool starts (beside the
    parent's own preparation, not after it; a forked worker has it already, and drops what is
    the parent's: _forget_parent, given `parent_end`, its copy of the lifeline's write end; a
    fork server's worker takes the parent's `environment`: _adopt_environment); it
    shows Python warnings on one line each, as the command line does (not with the source line
    of the warning, between a study's table rows); it skips the last garbage collections at
    exit (gc.freeze, as crankfmu.cli does: the parent waits for its workers to end); it removes
    its temporary folders at exit (_remove_own_folders) and ends with its parent
    (_end_with_parent), and on SIGTERM (what a pool sends the other workers when one died, and
    an abandoned companion worker gets) with its temporary folders."""
    import atexit
    import gc
    import signal
    import warnings
    from multiprocessing.util import Finalize

    if parent_end is not None:
        _forget_parent(parent_end)
    if environment is not None:
        _adopt_environment(environment)
    import importlib
    importlib.import_module(preload)
    from ..errors import warning_text
    warnings.showwarning = lambda message, category, *where, **_: print(
        f"warning: {warning_text(message, category)}", file=sys.stderr, flush=True)
    atexit.register(gc.freeze)
    # multiprocessing's own exit handlers run in a forked worker too (it leaves by os._exit,
    # without atexit's)
    Finalize(None, _remove_own_folders, exitpriority=0)
    signal.signal(signal.SIGTERM, lambda signum, frame: threading.Thread(
        target=_leave, args=(128 + signum,), daemon=True).start())  # the lock may be held here
    _end_with_parent(lifeline)


def _adopt_environment(environment: dict) -> None:
    """In a fork server's worker: the parent's environment variables as the pool started (the
    server has those of its own start, and the parent may have set others since: its temporary
    folder, crankfmu's cache folder), as a forked or spawned worker has them; the temporary
    folder is read from them again at its first use."""
    os.environ.clear()
    os.environ.update(environment)
    tempfile.tempdir = None


def _forget_parent(parent_end) -> None:
    """In a forked worker: close its copy of the lifeline's write end (else the pipe would not
    close when the parent ends), and forget the parent's temporary folders (its worker folder,
    its private unpacked FMUs: the parent removes them, not this worker) and its Ctrl-C
    handler (a spawned worker has Python's default: KeyboardInterrupt)."""
    import signal

    from ..fmu.archive import forget_private
    global _WORKER_DIR
    parent_end.close()
    _WORKER_DIR = None
    forget_private()
    signal.signal(signal.SIGINT, signal.default_int_handler)


def _remove_own_folders() -> None:
    """At a worker's exit: its temporary folders."""
    from ..fmu.archive import remove_tree, remove_unpacked
    with _WORKER_DIR_LOCK:
        if _WORKER_DIR is not None:
            remove_tree(_WORKER_DIR)
    remove_unpacked()


def _end_with_parent(lifeline) -> None:
    """A thread that waits on `lifeline` (the read end of the Lifeline's pipe) and ends this
    worker when the pipe closes. Without it, a sweep killed with kill -9 left its workers
    waiting on their task queue for good, and with them the resource tracker that
    multiprocessing starts for the pool's queues (it ends when the last process holding its
    pipe ends)."""
    def watch() -> None:
        try:
            lifeline.recv_bytes()
        except (EOFError, OSError):
            pass
        _leave(0)
    threading.Thread(target=watch, name="crankfmu-parent-watch", daemon=True).start()


def _leave(status: int) -> None:
    """End this worker now, with its temporary folders (os._exit runs no exit handler)."""
    from ..fmu.archive import remove_tree, remove_unpacked
    _WORKER_DIR_LOCK.acquire()  # kept: no folder is made after this
    if _WORKER_DIR is not None:
        remove_tree(_WORKER_DIR)
    remove_unpacked(for_good=True)
    os._exit(status)
