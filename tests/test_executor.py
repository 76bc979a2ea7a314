"""`accuracy` and `compare` through the executor: a local pool of 2 gives the serial path's
numbers and files exactly (wall times aside; on a Dask cluster: tests/test_sweep.py, beside
the sweeps on the same cluster). The accuracy studies run without the error
estimate's companion runs (estimate=False): they are more runs of the same kind, cost more than
the runs compared (half the step), and the estimates are not compared here
(tests/test_error_estimate.py checks them)."""
from __future__ import annotations

import copy
import json
import math
import os
import sys
from pathlib import Path

import pytest

from crankfmu.system.load import load_scene
from crankfmu.studies.executor import LocalPoolExecutor

from tests.conftest import SCENARIOS


def test_accuracy_on_a_pool_equals_serial(fmu_dir, tmp_path):
    from crankfmu.studies.accuracy import AccuracyOptions, run_accuracy

    results = {}
    for jobs in (1, 2):
        scene = load_scene(SCENARIOS / "servo_press.toml")
        scene.stop_time = 0.1
        results[jobs] = run_accuracy(scene, AccuracyOptions(
            out_dir=tmp_path / f"j{jobs}", algorithms=["gauss-seidel", "jacobi"],
            extrapolations=[0, 2], steps=[2e-3, 1e-3], fmu_dir=fmu_dir, progress=False,
            jobs=jobs, estimate=False))
    a, b = results[1].outcomes, results[2].outcomes
    assert len(a) == len(b) == 8
    for oa, ob in zip(a, b):
        assert oa.setting == ob.setting and oa.status == ob.status == "completed"
        assert oa.error == ob.error and math.isfinite(oa.error)
        assert (oa.do_steps, oa.rollbacks, oa.communication_steps) == \
            (ob.do_steps, ob.rollbacks, ob.communication_steps)
        name = f"runs/{oa.setting.label}.csv"
        assert (tmp_path / "j1" / name).read_bytes() == (tmp_path / "j2" / name).read_bytes()
        side = json.loads((tmp_path / "j2" / name).with_suffix(".json").read_text())
        serial = json.loads((tmp_path / "j1" / name).with_suffix(".json").read_text())
        # completed, or unreliable (Jacobi at 2 ms over the 0.05 s start-up: port energy
        # mismatch 0.14, crankfmu.cosim.trust): the same on both, with the same CSV
        assert side["status"] in ("completed", "unreliable")
        assert side["status"] == serial["status"] and side["csv"] == serial["csv"]
        assert side["communication_steps"] == oa.communication_steps
    assert results[1].orders == results[2].orders


def test_compare_on_a_pool_equals_serial(fmu_dir, tmp_path):
    from crankfmu.studies.compare import compare_scenes
    from crankfmu.cosim.runner import RunOptions

    def scenes():
        a = load_scene(SCENARIOS / "servo_press.toml")
        a.stop_time = 1.0
        b = copy.deepcopy(a)
        b.name = "with_flywheel"
        b.components["motor"].parameters["J_flywheel"] = 0.1
        return a, b
    options = RunOptions(fmu_dir=fmu_dir, progress=False)
    serial = compare_scenes(*scenes(), tmp_path / "serial", options)
    with LocalPoolExecutor(2) as pool:
        parallel = compare_scenes(*scenes(), tmp_path / "pool", options, pool)
    assert serial.text == parallel.text
    for name in ("compare.csv", "servo_press.csv", "with_flywheel.csv"):
        assert (tmp_path / "serial" / name).read_bytes() == (tmp_path / "pool" / name).read_bytes()


def pid_and_worker_folder(meeting: str) -> tuple[int, str]:
    """In a pool worker: its pid and its temporary folder (made now, with a private folder of
    unpacked FMUs beside it, as a run without a cache makes), once two such tasks have
    started (each leaves its pid in the folder `meeting`): the one that started first holds its
    worker until the other has taken the second, so each of two such tasks runs on its own
    worker (before: a fixed 1 s pause, which mostly did the same)."""
    import os
    import time

    from crankfmu.cosim.workers import worker_dir
    from crankfmu.fmu.archive import PRIVATE_PREFIX, _new_private
    folder = str(worker_dir())
    _new_private(PRIVATE_PREFIX)
    Path(meeting, str(os.getpid())).touch()
    deadline = time.monotonic() + 60  # a loaded machine's bound for the other worker's start
    while len(os.listdir(meeting)) < 2 and time.monotonic() < deadline:
        time.sleep(0.01)
    return os.getpid(), folder


def run_pool_script(script: str, tmp: Path, start_method: str):
    """Run `script` in a fresh interpreter from the project's root (tests/support/fresh_python.py:
    its imports done, nothing else), its temporary folders in `tmp`, its pools' workers started
    by `start_method`; it must succeed. The script finds `meeting`, an empty folder outside
    `tmp` for pid_and_worker_folder, in its namespace."""
    import os

    from tests.conftest import ROOT
    from tests.support import fresh_python
    meeting = tmp.parent / f"{tmp.name}-meeting"
    meeting.mkdir()
    script = f"meeting = {str(meeting)!r}\n" + script
    done = fresh_python.run(script, cwd=ROOT, timeout=120, env={
        **os.environ, "TMPDIR": str(tmp), "CRANKFMU_START_METHOD": start_method})
    assert done.returncode == 0, done.stderr[-3000:]
    return done


@pytest.mark.parametrize("start_method", ["fork", "forkserver", "spawn"])
def test_workers_that_the_pool_ends_remove_their_folders(short_tmp, start_method):
    """When a worker dies (here SIGKILL), the pool ends the others with SIGTERM, whose default
    action runs no exit handler: before, they left their temporary folders. The killed worker
    removes nothing: its folders (its worker folder, its privately unpacked FMUs) are removed
    by the parent as it closes the pool (before, they stayed for good: one per killed worker)."""

    script = (
        "import os, signal\n"
        "from crankfmu.studies.executor import LocalPoolExecutor\n"
        "from tests.test_executor import pid_and_worker_folder\n"
        "pool = LocalPoolExecutor(2)\n"
        "workers = [f.result() for f in [pool._pool.submit(pid_and_worker_folder, meeting)\n"
        "                                for _ in range(2)]]\n"
        "os.kill(workers[0][0], signal.SIGKILL)\n"
        "import time\n"
        "try:\n"  # a task still running when the pool sees the death: it breaks (a short
        "    pool._pool.submit(time.sleep, 5).result()\n"  # one could end on the survivor first)
        "except Exception as err:\n"
        "    print(type(err).__name__)\n"
        "pool.close()\n"  # the survivor removes its folder on SIGTERM: wait until it has ended
        "deadline = time.monotonic() + 60\n"
        "for pid, _ in workers:\n"
        "    while time.monotonic() < deadline:\n"
        "        try:\n"
        "            os.kill(pid, 0)\n"
        "        except ProcessLookupError:\n"
        "            break\n"
        "        time.sleep(0.05)\n"
        "import pathlib, tempfile\n"
        "print(sorted(p.name for p in pathlib.Path(tempfile.gettempdir()).iterdir()))\n")
    done = run_pool_script(script, short_tmp, start_method)
    broken = done.stdout.splitlines()[0]
    assert broken == "BrokenProcessPool"
    # the folders left before the parent's exit (at its exit it removes its own)
    assert done.stdout.splitlines()[1] == "[]", done.stdout
    assert list(short_tmp.iterdir()) == [], [p.name for p in short_tmp.iterdir()]


@pytest.mark.parametrize("start_method", ["fork", "spawn"])
def test_workers_of_a_closed_pool_leave_no_folder_and_not_the_parents(short_tmp,
                                                                       start_method):
    """A pool closed as a study ends: its workers remove their own temporary folders, and a
    forked worker leaves its parent's alone. Before the start method was chosen, a forked
    worker would have left its folders (it exits without running atexit's handlers), or
    removed the parent's (it inherits the parent's record of its private folders)."""

    script = (
        "from crankfmu.studies.executor import LocalPoolExecutor\n"
        "from crankfmu.fmu.archive import _new_private\n"
        "from tests.test_executor import pid_and_worker_folder\n"
        "mine = _new_private('crankfmu-parent-')\n"  # the parent's own private folder
        "pool = LocalPoolExecutor(2)\n"
        "workers = [f.result() for f in [pool._pool.submit(pid_and_worker_folder, meeting)\n"
        "                                for _ in range(2)]]\n"
        "pool.close()\n"
        "import os\n"
        "print(mine, os.path.isdir(mine), len({pid for pid, _ in workers}))\n")
    done = run_pool_script(script, short_tmp, start_method)
    mine, kept, workers = done.stdout.split()
    assert kept == "True" and workers == "2"  # the parent's folder outlived the pool
    # at the parent's exit its own folder goes too: nothing is left
    assert list(short_tmp.iterdir()) == [], [p.name for p in short_tmp.iterdir()]


def worker_environment(name: str) -> tuple[str, str | None, str]:
    """In a pool worker: how it was started (its process's name), the variable `name` and the
    temporary folder."""
    import multiprocessing
    import tempfile
    return (multiprocessing.current_process().name.split("-")[0], os.environ.get(name),
            tempfile.gettempdir())


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the fork server: Linux")
def test_a_fork_servers_workers_take_the_environment_the_parent_has_now(short_tmp):
    """The fork server keeps the environment of its start (the first pool's); a later pool's
    workers must have the parent's of their own start, as forked and spawned ones do: a
    changed temporary folder (where the workers put their folders, and the parent looks for
    those of killed workers) and a variable set since (crankfmu's cache folder, say). And the
    server, started by the pool, imported the pool's module, not the main script: crankfmu
    chooses that through multiprocessing's private `_forkserver` (cosim.workers
    ._fork_server_running), which a later Python may rename: then this fails."""
    later = short_tmp / "later"
    later.mkdir()
    script = (
        "import os\n"
        "from crankfmu.cosim.workers import new_pool, close_pool\n"
        "from tests.test_executor import worker_environment\n"
        "def ask():\n"
        "    pool, lifeline = new_pool(1)\n"
        "    try:\n"
        "        return pool.submit(worker_environment, 'CRANKFMU_PROBE').result()\n"
        "    finally:\n"
        "        close_pool(pool, lifeline)\n"
        "first = ask()\n"
        f"os.environ['TMPDIR'] = {str(later)!r}\n"
        "os.environ['CRANKFMU_PROBE'] = 'set since'\n"
        "from multiprocessing import forkserver\n"
        "print(*first, *ask(), *forkserver._forkserver._preload_modules)\n")
    done = run_pool_script(script, short_tmp, "forkserver")
    assert done.stdout.split() == ["ForkServerProcess", "None", str(short_tmp),
                                   "ForkServerProcess", "set", "since", str(later),
                                   "crankfmu.cosim.runner"], done.stdout


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="forked workers: Linux")
def test_workers_are_forked_unless_an_fmu_call_failed_or_a_thread_runs(tmp_path, fmu_dir):
    """start_method: fork from a process that runs one thread, after a run too; the fork
    server while another thread runs (a copy could inherit a lock that thread holds) and after
    an FMU call failed in the process (a pythonfmu binary can leave the interpreter that ran an
    exception inside it corrupt: a copy would inherit that). The failure is a doStep that
    returns fmi2Error, as a failing FMU's does, in the runner's stepping (the generic sweep and
    the written one, masters/sweep_code.py, both call the FMU's raw function)."""
    scene = str(SCENARIOS / "servo_press.toml")
    script = (
        "import threading, crankfmu\n"
        "from crankfmu.fmu.instance import FmuInstance\n"
        "from crankfmu.cosim.workers import start_method\n"
        "first = start_method()\n"
        "stop = threading.Event()\n"
        "thread = threading.Thread(target=stop.wait)\n"
        "thread.start()\n"
        "with_thread = start_method()\n"
        "stop.set(); thread.join()\n"
        f"crankfmu.simulate({scene!r}, stop_time=0.01, fmu_dir={str(fmu_dir)!r}, "
        "estimate=False)\n"
        "after_run = start_method()\n"
        "instantiate = FmuInstance.instantiate\n"
        "def failing(self, logging_on=False):\n"
        "    instantiate(self, logging_on)\n"
        "    self.slave._functions['fmi2DoStep'] = self._fmi2_do_step = lambda *args: 3\n"
        "FmuInstance.instantiate = failing\n"
        "try:\n"
        f"    crankfmu.simulate({scene!r}, stop_time=0.01, fmu_dir={str(fmu_dir)!r}, "
        "estimate=False)\n"
        "except Exception as err:\n"
        "    print(type(err).__name__)\n"
        "print(first, with_thread, after_run, start_method())\n")
    done = run_pool_script(script, tmp_path, "")  # "": no start method chosen
    assert done.stdout.split()[-4:] == ["fork", "forkserver", "fork", "forkserver"], \
        done.stdout


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the fork server: Linux")
def test_a_temporary_folder_too_long_for_the_fork_server_is_named_when_workers_are_spawned(
        short_tmp):
    """The fork server's socket lies in the temporary folder, and AF_UNIX takes 108 bytes of
    path at most: under a longer TMPDIR the pool's workers are spawned (slower to start), and
    the run says so, naming the folder (before, silently)."""
    long_tmp = short_tmp / ("x" * 60) / ("y" * 60)
    long_tmp.mkdir(parents=True)
    script = (
        "import logging, multiprocessing, sys\n"
        # as in a new interpreter, multiprocessing's temporary folder (where the server's socket
        # goes) is made under TMPDIR (fresh_python's child has its server's)
        "multiprocessing.process.current_process()._config.pop('tempdir', None)\n"
        "logging.basicConfig(stream=sys.stdout, level=logging.INFO, format='%(message)s')\n"
        "from crankfmu.cosim.workers import new_pool, close_pool\n"
        "pool, lifeline = new_pool(1)\n"
        "try:\n"
        "    print('method', pool._mp_context.get_start_method(), pool.submit(abs, -2).result())\n"
        "finally:\n"
        "    close_pool(pool, lifeline)\n")
    done = run_pool_script(script, long_tmp, "forkserver")
    assert "method spawn 2" in done.stdout, done.stdout
    assert "the workers are spawned" in done.stdout and str(long_tmp) in done.stdout, \
        done.stdout
