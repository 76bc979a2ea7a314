"""One executor for every multi-run command (sweep, accuracy, compare).

Python FMUs share one interpreter lock inside a process, so the unit of parallel work is a whole
run (`RunTask`: a parsed scene with its parameters set, plus the FMU files it needs) in its own
process. Three implementations of one interface (make_executor chooses by --jobs N and
--scheduler, docs/cli.md):

    InProcessExecutor()         jobs = 1: every run in this process, one after another, as
                                `crankfmu run` runs: no worker to start, and a script calling
                                the API needs no main guard.
    LocalPoolExecutor(jobs)     concurrent.futures.ProcessPoolExecutor of cosim/workers.py: on
                                Linux its workers are forked from the parent (with its
                                imports) while it runs one thread, else from a fork server;
                                elsewhere spawned, fresh interpreters. Those not forked from
                                the parent import the calling script again: it then needs
                                `if __name__ == "__main__":` (cosim.companions.MAIN_GUARD;
                                a missing one is a WorkerStartError, not a study of lost
                                runs).
    DaskExecutor(address)       a Dask distributed cluster (distributed.Client). No shared disk is
                                assumed: each FMU file is sent once with Client.upload_file
                                (kept by the scheduler for workers that restart or join later;
                                checked against its digest on the worker); the scene travels
                                inside the task (pickled), so swap bases and
                                scene files need not exist there. Dask does the scheduling,
                                retries (`retries=` on submit: a task that raises) and
                                rescheduling after a worker dies (up to the scheduler's
                                `allowed-failures`; then KilledWorker, reported as a lost run).

Every run goes through `execute`, wherever it executes: it writes the run's CSV and sidecar into
a private temp folder, reads them back and returns a `RunOutput` (arrays, statistics, sidecar,
status). Only the parent writes the study's output folder (`write_run_files`). Results do not
depend on where or in which order runs execute: a run's numbers are a function of its scene and
FMU bytes only, and outputs are returned in task order.

Failures never stop a study: a run that fails (RunError: divergence, an FMU that refuses its
parameters) returns status "failed" with the reason and the rows up to then; a scene or master
that refuses the setting returns "refused"; an unexpected exception "error"; a run whose worker
process died (twice, with the local pool; after Dask's rescheduling) returns "lost".
"""
from __future__ import annotations

import copy
import hashlib
import json
import os
import socket
import tempfile
import threading
import time
import traceback
from collections import deque
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, Iterable

import numpy as np

from ..cosim.workers import worker_dir

if TYPE_CHECKING:
    from ..cosim.workers import Lifeline
    from ..system.scene import Scene

STATUSES = ("completed", "failed", "refused", "error", "lost")


@dataclass
class RunTask:
    """One run. `scene` is a parsed Scene (parameters applied); `fmus` maps each component to
    (digest, file name) of its FMU file, filled by `prepare_tasks`. `post` is a module-level
    function post(names, rows, status, **post_args) -> dict, called in the worker on the run's
    recorded arrays (also on the partial rows of a failed run); `keep_series` False drops the arrays from
    the output (a sweep needs its figures only)."""

    key: Any  # the study's name for the run (a setting's index, a case's label)
    scene: Scene
    post: Callable | None = None
    post_args: dict = field(default_factory=dict)
    keep_series: bool = True
    fmus: dict = field(default_factory=dict)


@dataclass
class RunOutput:
    key: Any
    status: str                       # one of STATUSES
    reason: str = ""
    names: list = field(default_factory=list)
    units: list = field(default_factory=list)
    rows: np.ndarray | None = None    # time + recorded variables, as the runner's Recorder
    sidecar: dict = field(default_factory=dict)
    statistics: dict = field(default_factory=dict)
    master_statistics: dict = field(default_factory=dict)
    coupling_error: dict = field(default_factory=dict)
    steps: int = 0
    wall_seconds: float = float("nan")
    figures: dict = field(default_factory=dict)
    worker: str = ""

    @property
    def ok(self) -> bool:
        return self.status == "completed"

    def column(self, name: str) -> np.ndarray:
        if self.rows is None:
            raise ValueError(f"run {self.key}: no recorded rows (status {self.status})")
        return self.rows[:, 1 + self.names.index(name)]


# -- the parent's side: FMU files ------------------------------------------------------------------
_DIGESTS: dict[tuple, str] = {}


def file_digest(path: Path) -> str:
    st = path.stat()
    key = (str(path), st.st_mtime_ns, st.st_size)
    if key not in _DIGESTS:
        _DIGESTS[key] = hashlib.sha256(path.read_bytes()).hexdigest()
    return _DIGESTS[key]


def prepare_tasks(tasks: list[RunTask], fmu_dir: Path | None) -> dict[str, Path]:
    """Resolve (and build, once, in the parent) every FMU the tasks need; fill task.fmus.
    Returns digest -> path of the parent's file."""
    from ..fmu.instance3 import MODEL_EXCHANGE
    from ..masters import traits
    from ..system.wiring import default_fmu_dir, resolve_fmu

    files: dict[str, Path] = {}
    resolved: dict[tuple, Path] = {}
    for task in tasks:
        scene = task.scene
        folder = Path(fmu_dir) if fmu_dir else default_fmu_dir(scene)
        me = traits(scene.master.algorithm).interface == MODEL_EXCHANGE
        for name, comp in scene.components.items():
            ref = (str(scene.path.parent), comp.fmu, str(folder), comp.fmi, me,
                   tuple(sorted(comp.effects)) if me else ())  # an FMI 3.0 FMU per effects
            if ref not in resolved:
                resolved[ref] = resolve_fmu(scene, name, folder, model_exchange=me)
            path = resolved[ref]
            digest = file_digest(path)
            files[digest] = path
            task.fmus[name] = (digest, path.name)
    return files


# -- the worker's side -----------------------------------------------------------------------------
_RUN_LOCK = threading.Lock()  # one run at a time per process (threads would share the GIL anyway)
def _materialize(task: RunTask, files: dict) -> dict[str, Path]:
    """component -> local FMU path. `files` maps digest to a path (same machine) or to the
    file's bytes (shipped), which are written once per process into a private folder."""
    out = {}
    for comp, (digest, filename) in task.fmus.items():
        source = files[digest]
        if isinstance(source, (bytes, bytearray)):
            path = worker_dir() / "fmus" / digest / filename
            if not path.is_file():
                path.parent.mkdir(parents=True, exist_ok=True)
                part = path.with_suffix(f".part{threading.get_ident()}")
                part.write_bytes(source)
                os.replace(part, path)
            out[comp] = path
        else:
            out[comp] = Path(source)
    return out


def _read_csv(path: Path) -> tuple[list[str], np.ndarray]:
    with open(path) as f:
        names = [n.strip('"') for n in f.readline().strip().split(",")]
    import warnings
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # a run that failed before its first row
        rows = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
    if rows.size == 0:
        rows = np.empty((0, len(names)))
    return names[1:], rows


def execute(task: RunTask, files: dict) -> RunOutput:
    """Run one task here (any process); never raises for a run's own failure."""
    with _RUN_LOCK:
        return _execute(task, files)


def _execute(task: RunTask, files: dict) -> RunOutput:
    from ..cosim.runner import RunError, RunOptions, run_scene
    from ..errors import InterruptedRun

    out = RunOutput(task.key, "completed", worker=f"{socket.gethostname()}:{os.getpid()}")
    scene = copy.deepcopy(task.scene)
    run_dir = Path(tempfile.mkdtemp(prefix="run-", dir=worker_dir()))
    csv = run_dir / "run.csv"
    t0 = time.perf_counter()
    try:
        for comp, path in _materialize(task, files).items():
            scene.components[comp].fmu = str(path)  # absolute: resolve_fmu takes it as is
        result = run_scene(scene, RunOptions(out=csv, progress=False))
        out.wall_seconds, out.steps = result.wall_seconds, result.steps
        out.statistics, out.master_statistics = result.statistics, result.master_statistics
        out.coupling_error = result.coupling_error
        out.units = list(result.recorder.units)
    except InterruptedRun:  # Ctrl-C: the study stops (InProcessExecutor), no failed row
        raise
    except RunError as err:
        out.status = "failed"
        out.reason = str(err).replace(f" (results up to then: {err.csv})", "")
    except (ValueError, NotImplementedError) as err:  # the scene or master refuses the setting
        out.status, out.reason = "refused", str(err)
    except Exception as err:  # noqa: BLE001 - reported in the row, the study goes on
        out.status = "error"
        out.reason = f"{type(err).__name__}: {err} [{traceback.format_exc(limit=3).strip()}]"
    try:
        if csv.is_file():
            out.names, out.rows = _read_csv(csv)
        if csv.with_suffix(".json").is_file():
            out.sidecar = json.loads(csv.with_suffix(".json").read_text())
            if out.status != "completed":
                out.wall_seconds = out.sidecar.get("wall_seconds", out.wall_seconds)
                out.statistics = out.sidecar.get("statistics", {})
                out.steps = out.sidecar.get("communication_steps", 0)
        if not out.units:
            out.units = [None] * len(out.names)
        if task.post is not None and out.rows is not None:
            try:
                out.figures = task.post(out.names, out.rows, out.status, **task.post_args)
            except Exception as err:  # noqa: BLE001
                if out.status == "completed":
                    out.status = "failed"
                    out.reason = f"figures: {type(err).__name__}: {err}"
        if not task.keep_series:
            out.rows = None
    finally:
        for p in run_dir.iterdir():
            p.unlink()
        run_dir.rmdir()
    if out.wall_seconds != out.wall_seconds:  # nan: the run never started
        out.wall_seconds = time.perf_counter() - t0
    return out


def write_run_files(output: RunOutput, csv: Path, fmu_paths: dict | None = None) -> Path:
    """The parent writes a run's CSV (the runner's layout, floats exact) and JSON sidecar, as
    one set (cosim.results.write_run_set)."""
    from ..cosim.results import Recorder, write_run_set

    rec = Recorder(list(output.names), list(output.units))
    for row in (output.rows if output.rows is not None else []):
        rec.add(row[0], row[1:])
    side = dict(output.sidecar)
    if fmu_paths and "components" in side:  # name the parent's files, not the worker's copies
        side["components"] = {n: {**c, "fmu": str(fmu_paths.get(n, c.get("fmu")))}
                              for n, c in side["components"].items()}
    side["worker"] = output.worker
    write_run_set(csv, rec, side)
    return csv


# -- executors -------------------------------------------------------------------------------------
def _bar(total: int, progress, label: str):
    if progress is False:
        return None
    from ..cosim.runner import progress_bar
    return progress_bar(total=total, desc=label, unit="run",
                        disable=None if progress is None else False)


class Executor:
    """run(tasks, fmu_dir, on_done, progress, label) -> outputs in task order. `on_done(output)`
    is called in the parent as each run finishes (a sweep appends its row there)."""

    description = "executor"

    def run(self, tasks: Iterable[RunTask], fmu_dir: Path | None = None,
            on_done: Callable[[RunOutput], None] | None = None, progress=None,
            label: str = "runs") -> list[RunOutput]:
        tasks = list(tasks)
        files = prepare_tasks(tasks, fmu_dir)
        self.fmu_files = files
        bar = _bar(len(tasks), progress, label)
        results: dict[int, RunOutput] = {}

        def done(index: int, output: RunOutput) -> None:
            results[index] = output
            if on_done is not None:
                on_done(output)
            if bar is not None:
                bar.update(1)
        try:
            self._run(tasks, files, done)
        finally:
            if bar is not None:
                bar.close()
        return [results[i] for i in range(len(tasks))]

    def _run(self, tasks, files, done) -> None:
        raise NotImplementedError

    def close(self) -> None:
        pass

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


class InProcessExecutor(Executor):
    """Every run in this process, one after another (jobs = 1): what `crankfmu run` does, so a
    study costs no worker start-up (an interpreter and the imports a run needs: about 0.3 s of
    CPU) and a plain script calling crankfmu.sweep or crankfmu.accuracy works without a main
    guard. A run that kills its process takes the study with it: jobs >= 2 isolates the runs in
    worker processes."""

    description = "this process"

    def _run(self, tasks, files, done) -> None:
        local = {d: str(p) for d, p in files.items()}
        for i, task in enumerate(tasks):
            done(i, execute(task, local))


class LocalPoolExecutor(Executor):
    """A local process pool of `jobs` workers (default: the number of cores): the parent never
    loads an FMU, so nothing an FMU does (pythonfmu 0.7.0 can leave the interpreter corrupt
    after a Python exception in an FMU: a later run in the same process has segfaulted in the
    garbage collector) can take the study down. A worker process that dies
    breaks the pool (BrokenProcessPool): the pool is restarted and the runs that were in flight
    are run again, one at a time (so the one that kills its worker is found); a run lost a
    second time, alone, is returned as "lost" with the reason. At most `jobs` runs are in
    flight, so a break loses only the runs that were executing.

    The workers start with the executor, so that their start (an interpreter, the imports a run
    needs: about 0.3 s of CPU each) overlaps what the parent does before the first run. Each
    worker ends with the parent, however the parent ends (cosim/workers.py)."""

    def __init__(self, jobs: int | None = None, max_losses: int = 2):
        self.jobs = max(1, int(jobs or os.cpu_count() or 1))
        self.max_losses = max_losses
        self.description = f"{self.jobs} local worker process{'es' if self.jobs > 1 else ''}"
        self._lifeline: Lifeline | None = None  # the pipe whose closing ends the workers
        self._pool = self._new_pool()

    def _new_pool(self):
        from ..cosim.companions import guarded_start
        from ..cosim.workers import new_pool, ready
        with guarded_start():  # each submit to a pool without an idle worker starts one
            pool, self._lifeline = new_pool(self.jobs)
            self._started = [pool.submit(ready) for _ in range(self.jobs)]
        return pool

    def _check_started(self) -> None:
        """After the pool broke: if no worker of it ever started (each died while it imported
        the script or crankfmu), raise WorkerStartError; running the study again would only
        start more workers that die the same way."""
        from ..cosim.companions import MAIN_GUARD, WorkerStartError
        if not any(f.done() and f.exception() is None for f in self._started):
            raise WorkerStartError(f"the worker processes ended as they started, before any "
                                   f"run; {MAIN_GUARD} (the workers' own messages are above)")

    def _close_pool(self) -> None:
        from ..cosim.workers import close_pool
        assert self._lifeline is not None  # made with the pool
        close_pool(self._pool, self._lifeline)
        self._pool = None

    def _run(self, tasks, files, done) -> None:
        from concurrent.futures import FIRST_COMPLETED, wait
        from concurrent.futures.process import BrokenProcessPool

        local = {d: str(p) for d, p in files.items()}
        queue = deque(range(len(tasks)))
        suspects: deque = deque()  # runs lost in a break: run again alone, to find the culprit
        losses = [0] * len(tasks)
        running: dict = {}
        while queue or suspects or running:
            if self._pool is None:
                self._pool = self._new_pool()
            broken = False
            while not broken and (suspects or queue) and (
                    len(running) < (1 if suspects else self.jobs)) and \
                    not (suspects and running):
                i = (suspects or queue).popleft()
                try:
                    running[self._pool.submit(execute, tasks[i], local)] = i
                except BrokenProcessPool:
                    (suspects if losses[i] else queue).appendleft(i)
                    broken = True
            finished, _ = wait(list(running), return_when=FIRST_COMPLETED) if running \
                else (set(), set())
            lost = []
            for fut in finished:
                i = running.pop(fut)
                err = fut.exception()
                if err is None:
                    done(i, fut.result())
                elif isinstance(err, BrokenProcessPool):
                    lost.append(i)
                else:  # e.g. a task that cannot be pickled
                    done(i, RunOutput(tasks[i].key, "error", f"{type(err).__name__}: {err}"))
            if lost or broken:
                for fut, i in running.items():  # the pool is gone: so are the other runs
                    fut.exception()
                    lost.append(i)
                running.clear()
                started = self._started
                self._close_pool()
                self._started = started
                self._check_started()
                for i in sorted(lost, reverse=True):
                    losses[i] += 1
                    if losses[i] >= self.max_losses:
                        done(i, RunOutput(tasks[i].key, "lost",
                                          f"a worker process died while this run was in flight "
                                          f"({losses[i]} times, the last time alone); the pool "
                                          "was restarted"))
                    else:
                        suspects.appendleft(i)

    def close(self) -> None:
        if self._pool is not None:
            self._close_pool()


def environment_fingerprint() -> dict:
    """What must match between the parent and the workers for identical numbers."""
    from ..cosim.results import versions
    return versions()


_VERIFIED: set = set()


def _execute_shipped(task: RunTask, names: dict) -> RunOutput:
    """On a Dask worker: the FMUs were uploaded into the worker's local directory (digest ->
    file name there); check their digests once per process, then run."""
    from distributed import get_worker

    folder = Path(get_worker().local_directory)
    # the worker folder inside Dask's own: Dask removes it with the worker, also when the
    # nanny ends the process without running atexit handlers
    worker_dir(under=folder)
    files = {}
    for digest, name in names.items():
        path = folder / name
        if digest not in _VERIFIED:
            if not path.is_file():
                return RunOutput(task.key, "error", f"FMU {name} is missing on worker "
                                                    f"{get_worker().address}")
            if hashlib.sha256(path.read_bytes()).hexdigest() != digest:
                return RunOutput(task.key, "error", f"FMU {name} on worker "
                                                    f"{get_worker().address} has other bytes")
            _VERIFIED.add(digest)
        files[digest] = str(path)
    return execute(task, files)


class DaskExecutor(Executor):
    """Runs on a Dask distributed cluster: `address` ("tcp://HOST:PORT") or an existing
    `client`. Workers need the same crankfmu, fmpy, pythonfmu, numpy and scipy (checked at
    start); start them with one thread each (`dask worker ADDRESS --nthreads 1`): a worker
    process runs one run at a time anyway (the FMUs hold its interpreter lock).

    The FMU files go to the workers with `Client.upload_file` (a plugin the scheduler keeps, so
    a worker that restarts or joins later gets them too; scattered data would be lost with the
    last worker holding it), under names that carry their digest, once per file and client."""

    def __init__(self, address: str | None = None, client=None, retries: int = 1):
        from distributed import Client
        self._own = client is None
        self.client = client if client is not None else Client(address)
        self.retries = retries
        self._uploaded: dict[str, str] = {}
        self.description = f"Dask cluster at {self.client.scheduler.address}"
        self._check_workers()

    def _check_workers(self) -> None:
        here = environment_fingerprint()
        for worker, theirs in self.client.run(environment_fingerprint).items():
            if theirs != here:
                diff = {k: (here.get(k), theirs.get(k)) for k in here if here.get(k) != theirs.get(k)}
                raise RuntimeError(f"Dask worker {worker} runs other versions than this process "
                                   f"(here, there): {diff}; results would differ")

    def _run(self, tasks, files, done) -> None:
        from distributed import as_completed
        from distributed.scheduler import KilledWorker

        import shutil
        import uuid
        batch = uuid.uuid4().hex
        for digest, path in files.items():
            if digest not in self._uploaded:
                name = f"crankfmu-{digest[:24]}-{path.name}"
                with tempfile.TemporaryDirectory() as tmp:
                    shutil.copyfile(path, Path(tmp) / name)
                    self.client.upload_file(str(Path(tmp) / name), load=False)
                self._uploaded[digest] = name
        futures = {}
        for i, task in enumerate(tasks):
            need = {d: self._uploaded[d] for d, _ in task.fmus.values()}
            fut = self.client.submit(_execute_shipped, task, need, retries=self.retries,
                                     pure=False, key=f"crankfmu-run-{batch}-{i}")
            futures[fut] = i
        try:
            for fut in as_completed(list(futures)):
                i = futures[fut]
                if fut.status == "finished":
                    done(i, fut.result())
                    continue
                try:
                    err = fut.exception()
                except Exception as cancelled:  # noqa: BLE001 - e.g. CancelledError
                    err = cancelled
                if isinstance(err, KilledWorker):
                    done(i, RunOutput(tasks[i].key, "lost", f"Dask: {err}"))
                else:
                    done(i, RunOutput(tasks[i].key, "error", f"{type(err).__name__}: {err}"))
        finally:
            for fut in futures:
                fut.release()

    def close(self) -> None:
        if self._own:
            self.client.close()


def make_executor(jobs: int | None = 1, scheduler: str | None = None, client=None) -> Executor:
    """--scheduler ADDRESS (or a distributed.Client) gives a DaskExecutor; else --jobs N
    (cosim.companions.processes: 0 is one per core; None is 1): 1 an InProcessExecutor, more a
    LocalPoolExecutor of that many workers."""
    from ..cosim.companions import processes
    if client is not None or scheduler:
        return DaskExecutor(scheduler, client=client)
    count = processes(1 if jobs is None else jobs)
    return InProcessExecutor() if count == 1 else LocalPoolExecutor(count)
