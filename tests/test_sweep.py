"""Parameter sweeps (crankfmu.studies): grid expansion, failed runs as rows, resume, and the same
table from one process, a local pool of 2 and a Dask LocalCluster of 2 worker processes on
127.0.0.1, also when a worker process is killed mid-sweep; and `accuracy` and `compare` on that
cluster (the one cluster of the suite: test_executor.py runs them on local pools).

The physics does not matter here, so the scene is one Rotor (exact matrix-exponential steps)
spun up by a constant torque against a damper: its angle grows by more than a revolution after
from_time at every grid point (30 N.m: the slowest point, J = 0.9, d = 1.0, turns 8.6 rad in
the 0.5 s window of stop = 1.0, the runs' stop), so the [analysis] figures (strokes, mean
speed, delta, ...) are all defined: a row without them would say "figures missing". The
failed-run test uses the servo press with a rod shorter than the crank (press.l < press.r),
which the press refuses.
"""
from __future__ import annotations

import copy
import itertools
import math
import multiprocessing
import os
import signal
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from crankfmu.studies.sweep import SweepError, expand, parse_vary, read_table, sweep
from crankfmu.system.load import load_scene

from tests.conftest import SCENARIOS
from tests.support.full import FULL

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module", autouse=True)
def fork_server():
    """The process's fork server, started before this module's first pool with distributed
    imported: the local pools fork their workers from it (pytest-xdist's worker runs other
    threads: cosim/workers.py), and so do the Dask cluster's nannies (the cluster fixture)."""
    from tests.support import fresh_python
    fresh_python.start_server(("distributed",))


@pytest.fixture(scope="module")
def one_worker():
    """The executor `jobs=1` makes (every run in this process), kept for the module."""
    from crankfmu.studies.executor import InProcessExecutor, make_executor
    with make_executor(1) as executor:
        assert isinstance(executor, InProcessExecutor)
        yield executor


def spinner(tmp_path: Path, stop: float = 1.0) -> Path:
    path = tmp_path / "spinner.toml"
    path.write_text(f"""
[scene]
name = "spinner"
stop_time = {stop}
[master]
step = 1e-3
[components.r]
fmu = "Rotor"
parameters = {{ J = 0.5, d = 0.4, w0 = 6.0 }}
[inputs]
"r.flange_tau" = 30.0
[record]
variables = ["r.flange_phi", "r.flange_w"]
interval = 1e-2
[analysis]
crank_angle = "r.flange_phi"
crank_speed = "r.flange_w"
drive_torque = "r.flange_tau"
drive_power = "r.E"
from_time = 0.5
events = ["r.E"]
""")
    return path


VARY = ["r.J=0.3:0.9:4", "r.d=0.2,0.6,1.0"]  # 12 runs


def same_table(a, b) -> None:
    """Every column but wall time equal, floats identical (NaN where NaN)."""
    assert a.columns == b.columns
    same_rows(a.columns, a.rows, b.rows)


def same_rows(columns, rows_a, rows_b) -> None:
    assert len(rows_a) == len(rows_b)
    for ra, rb in zip(rows_a, rows_b):
        for c in columns:
            if c == "wall_time":
                continue
            va, vb = ra[c], rb[c]
            if isinstance(va, float) and math.isnan(va):
                assert isinstance(vb, float) and math.isnan(vb), (c, ra, rb)
            else:
                assert va == vb, (c, va, vb)


def test_vary_and_grid():
    assert parse_vary("press.l=0.2,0.25").grid == [0.2, 0.25]
    assert parse_vary("motor.J_flywheel=0:0.3:4").grid == pytest.approx([0.0, 0.1, 0.2, 0.3])
    points = expand([parse_vary(v) for v in VARY])
    assert len(points) == 12 and points[1] == {"r.J": 0.3, "r.d": 0.6}  # last varies fastest
    lhs = expand([parse_vary("a.x=0:1"), parse_vary("b.y=10,20,30")], samples=8, seed=3)
    assert lhs == expand([parse_vary("a.x=0:1"), parse_vary("b.y=10,20,30")], samples=8, seed=3)
    xs = sorted(p["a.x"] for p in lhs)
    assert len(lhs) == 8 and all(k / 8 <= x < (k + 1) / 8 for k, x in enumerate(xs))  # one per stratum
    assert all(10 <= p["b.y"] <= 30 for p in lhs)
    for bad in ("press.l", "l=1,2", "press.l=a,b", "press.l=0:1:0"):
        with pytest.raises(SweepError):
            parse_vary(bad)


def test_latin_hypercube_gives_scipys_numbers():
    """Seeded sweeps keep their points: latin_hypercube is scipy.stats.qmc's plain Latin
    hypercube, whose numbers for two designs are written here (scipy 1.17.1,
    LatinHypercube(d, seed=seed).random(n)). Full (against the installed scipy, whose import
    the quick suite spares): 150 designs, d 1-8, n 1-1000, five seeds, exactly;
    `python scripts/full_checks.py tests/test_sweep.py -k latin_hypercube_gives`."""
    from crankfmu.studies.sweep import latin_hypercube
    if FULL:
        from scipy.stats import qmc
        for d, n, seed in itertools.product((1, 2, 3, 5, 8), (1, 2, 7, 20, 100, 1000),
                                            (0, 1, 16, 12345, 2 ** 40)):
            assert np.array_equal(latin_hypercube(d, n, seed),
                                  qmc.LatinHypercube(d=d, seed=seed).random(n)), (d, n, seed)

    scipy_numbers = {
        (2, 4, 0): [[0.09075957816963642, 0.6825533215590325],
                    [0.7397566190159514, 0.9958680911178677],
                    [0.2966824401999319, 0.27181110568056954],
                    [0.848341056058205, 0.0676258597540004]],
        (3, 5, 16): [[0.086616632224127, 0.3138511709019629, 0.1811852349076951],
                     [0.5303840899128008, 0.07569819232386413, 0.3956689993634579],
                     [0.6250735244108925, 0.42919009369461153, 0.791139156842343],
                     [0.8395158074268192, 0.7630409677026303, 0.46087521702028117],
                     [0.36899994902686667, 0.8616760488033467, 0.8082732337871159]]}
    for (d, n, seed), expected in scipy_numbers.items():
        assert latin_hypercube(d, n, seed).tolist() == expected


def test_failed_run_is_a_row_and_the_sweep_resumes(tmp_path, fmu_dir, one_worker):
    """press.l = 0.04 < r = 0.05 cannot assemble: that row says refused (the runner checks the
    parameters with the physics before any FMU starts) with the press's reason, the other rows
    are complete; a second call runs nothing and gives the same table."""
    out = tmp_path / "sweep"
    kw = dict(stop_time=0.05, from_time=0.0, executor=one_worker, fmu_dir=fmu_dir,
              progress=False)
    table = sweep(ROOT / "scenarios/servo_press.toml", ["press.l=0.25,0.04,0.3"], out, **kw)
    status = [r["status"] for r in table.rows]
    # 0.05 s is no whole revolution: those figures are missing, and the rows say so
    assert status == ["figures missing", "refused", "figures missing"]
    assert table.rows[0]["reason"] == ("cycle_time, energy_per_stroke: no whole crank revolution "
                                       "between from_time = 0 s and the run's end at 0.05 s")
    bad = table.rows[1]
    assert "l = 0.04 is not allowed" in bad["reason"] and "\n" not in bad["reason"]
    assert math.isnan(bad["mean_crank_speed"])
    assert all(math.isfinite(r["mean_crank_speed"]) for r in (table.rows[0], table.rows[2]))
    header, rows = read_table(out / "sweep.csv")
    assert header[:2] == ["run", "press.l"] and header[-3:] == ["status", "reason", "wall_time"]
    assert [r["status"] for r in rows] == status
    again = sweep(ROOT / "scenarios/servo_press.toml", ["press.l=0.25,0.04,0.3"], out, **kw)
    assert again.executed == 0
    same_table(table, again)
    with pytest.raises(SweepError, match="another study"):
        sweep(ROOT / "scenarios/servo_press.toml", ["press.l=0.25,0.3"], out, **kw)


def test_resume_after_interruption(tmp_path, fmu_dir, one_worker):
    """Rows already in sweep.csv (an interrupted sweep) are kept; only the others run."""
    scene = spinner(tmp_path)
    out = tmp_path / "s"
    full = sweep(scene, VARY, out, executor=one_worker, fmu_dir=fmu_dir, progress=False,
                 plot=False)
    lines = (out / "sweep.csv").read_text().splitlines()
    (out / "sweep.csv").write_text("\n".join(lines[:6]) + "\n" + lines[6][:10])  # 5 rows + a cut one
    resumed = sweep(scene, VARY, out, executor=one_worker, fmu_dir=fmu_dir,
                    progress=False, plot=False)
    assert resumed.executed == 7
    same_table(full, resumed)

@pytest.fixture(scope="module")
def serial_run(tmp_path_factory, fmu_dir, one_worker):
    """(scene, table): the 12 runs of 1 s in one worker, the table every other way of running
    them must give."""
    tmp = tmp_path_factory.mktemp("serial")
    scene = spinner(tmp)
    return scene, sweep(scene, VARY, tmp / "out", executor=one_worker, fmu_dir=fmu_dir,
                        progress=False)


@pytest.fixture(scope="module")
def serial_table(serial_run):
    return serial_run[1]


def test_local_pool_equals_serial(tmp_path, fmu_dir, serial_table):
    table = sweep(spinner(tmp_path), VARY, tmp_path / "out", jobs=2, fmu_dir=fmu_dir,
                  progress=False, plot=False)
    same_table(serial_table, table)


def _kill_when_rows(csv: Path, pick_pid, rows: int = 2, timeout: float = 120.0) -> dict:
    """In a thread: when `csv` has `rows` data rows, SIGKILL the process pick_pid() names."""
    info = {}

    def watch():
        end = time.time() + timeout
        while time.time() < end:
            if csv.is_file() and len(csv.read_text().splitlines()) > rows:
                pid = pick_pid()
                if pid:
                    os.kill(pid, signal.SIGKILL)
                    info["killed"] = pid
                    return
            time.sleep(0.02)
    thread = threading.Thread(target=watch, daemon=True)
    thread.start()
    info["thread"] = thread
    return info


# The killed-worker tests kill a worker when the first row is written (polled every 20 ms): the
# other 11 runs of 1 s (about 0.1 s of CPU each) are still to do then.
def test_killed_local_worker_loses_nothing(tmp_path, fmu_dir, serial_run):
    """SIGKILL of one pool worker mid-sweep (after the first row): the pool is restarted, the
    runs it lost run again, every row is there and equals the serial table."""
    scene, serial = serial_run
    others = {p.pid for p in multiprocessing.active_children()}  # e.g. the one_worker pool's

    def a_worker():
        kids = [p for p in multiprocessing.active_children()  # the pool's start method's
                if p.name.startswith(("ForkServerProcess", "SpawnProcess", "ForkProcess"))
                and p.pid not in others]
        return kids[0].pid if kids else None
    info = _kill_when_rows(tmp_path / "pool" / "sweep.csv", a_worker, rows=1)
    table = sweep(scene, VARY, tmp_path / "pool", jobs=2, fmu_dir=fmu_dir,
                  progress=False, plot=False)
    info["thread"].join(1)
    assert "killed" in info
    assert [r["status"] for r in table.rows] == ["completed"] * 12
    same_table(serial, table)


def _session_processes(sid: int) -> list[tuple[int, str]]:
    """(pid, command line) of every live process of the session `sid` (Linux /proc). A zombie
    (state Z) has ended: it waits only for its new parent to collect its exit status, which
    here took up to 1.4 s after the kill (the session's leader, their parent, was killed)."""
    found = []
    for pid in filter(str.isdigit, os.listdir("/proc")):
        try:
            stat = Path(f"/proc/{pid}/stat").read_text()
            command = Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode()
        except OSError:  # ended meanwhile
            continue
        state, _, _, session = stat[stat.rindex(")") + 2:].split()[:4]
        if int(session) == sid and state != "Z":
            found.append((int(pid), command[:120]))
    return found


@pytest.mark.skipif(not Path("/proc/self/stat").is_file(), reason="reads /proc (Linux)")
@pytest.mark.parametrize("start_method", ["fork", "forkserver", "spawn"])
def test_kill_9_of_a_sweep_leaves_no_process_and_no_temporary_folder(tmp_path, fmu_dir,
                                                                     start_method, short_tmp):
    """Issue #27. Before: after `kill -9` of `crankfmu sweep --jobs 2`, its 2 workers waited on
    their task queue for good, and with them multiprocessing's resource tracker (one set was
    still alive after 14 minutes). Now each worker ends when the pipe only its parent writes to
    closes, removing its temporary folders, and the tracker ends after them. The sweep runs in
    its own session; every process of that session must be gone within 30 s of the kill (the
    workers see the pipe close at once; the bound is for a loaded machine). Forked workers too:
    each closes its copy of the pipe's write end (without that, the pipe stayed open and they
    waited for good). The fork server too: it ends with its parent, and its workers with the
    pipe."""
    scene = spinner(tmp_path, stop=200.0)  # runs of seconds: the sweep is killed mid-run
    before, left, tmp = kill_9_mid_run(
        ["sweep", str(scene), *(f"--vary={v}" for v in VARY), "--jobs", "2", "--fmus",
         str(fmu_dir), "--out", str(tmp_path / "out"), "--no-progress"],
        short_tmp, start_method, workers=2)
    print(f"\nkilled the sweep; its session held {len(before)} processes: {before}")
    assert left == [], left
    assert not [p.name for p in tmp.iterdir() if p.name.startswith("crankfmu-")]
    # the server and the workers it forked (theirs is its command line)
    served = [c for _, c in before if "multiprocessing.forkserver" in c]
    assert bool(served) == (start_method == "forkserver"), before


def _fmu_loaded(pid: int) -> bool:
    """Whether process `pid` has an FMU's binary mapped (it is in a run: Linux /proc)."""
    try:
        return "/binaries/linux64/" in Path(f"/proc/{pid}/maps").read_text()
    except OSError:  # ended meanwhile
        return False


def kill_9_mid_run(args: list[str], tmp: Path, start_method: str, workers: int):
    """Start `crankfmu ARGS` in its own session (temporary folders in `tmp`, an empty folder
    with a short path: tests/conftest.short_tmp; workers started by `start_method`), wait
    until `workers` worker processes have loaded an FMU (they are mid-run: before, a fixed
    1 s), kill -9 the crankfmu process and wait up to 30 s (a loaded machine's bound) for the
    session to empty. Returns (the session's processes before the kill, those left, `tmp`)."""
    import subprocess
    import sys
    process = subprocess.Popen(
        [sys.executable, "-m", "crankfmu", *args], start_new_session=True,
        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
        env={**os.environ, "TMPDIR": str(tmp), "CRANKFMU_START_METHOD": start_method})
    sid = process.pid
    try:
        end = time.time() + 120
        while len([p for p, c in _session_processes(sid)  # the workers, in a run
                   if p != sid and "resource_tracker" not in c and _fmu_loaded(p)]) < workers:
            assert time.time() < end and process.poll() is None, \
                process.stderr.read().decode()[-2000:]
            time.sleep(0.05)
        before = _session_processes(sid)
        os.kill(process.pid, signal.SIGKILL)
        process.wait()
        end = time.time() + 30
        while _session_processes(sid) and time.time() < end:
            time.sleep(0.05)
        left = _session_processes(sid)
    finally:
        for pid, _ in _session_processes(sid):  # what the test started, by its id
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:  # ended meanwhile
                pass
    return before, left, tmp


@pytest.fixture(scope="module")
def hybrid_fmus(fmu_dir):
    return fmu_dir  # the session's catalog (tests/conftest.py)


def test_hybrid_scene_reports_its_event_figures(tmp_path, hybrid_fmus, one_worker):
    """The conventional press ([analysis].events): brake energies and the number of mode events
    at the run's end are columns; a stronger ring brake engages faster and dissipates less."""
    table = sweep(ROOT / "scenarios/conventional_press.toml", ["drive.Mp_b=800,1200"],
                  tmp_path / "out", stop_time=0.6, executor=one_worker, fmu_dir=hybrid_fmus,
                  progress=False, plot=False)
    for name in ("drive.E_brake_b", "drive.E_brake_h", "drive.n_events"):
        assert name in table.columns
    # 0.6 s holds no whole revolution of the press: its cycle figures are missing, saying why
    assert [r["status"] for r in table.rows] == ["figures missing"] * 2
    assert all(r["reason"].startswith("cycle_time, energy_per_stroke: no whole crank")
               for r in table.rows)
    E = table.column("drive.E_brake_b")
    assert np.all(E > 0) and E[1] != E[0]
    assert np.all(table.column("drive.n_events") >= 1)


def test_flywheel_report_marks_eq_28(tmp_path, servo_scene, monkeypatch):
    """`crankfmu analyze flywheel`: eq. (28) from press_analysis, 0.1409 kg.m2 on the motor
    shaft (docs/stephenson_press_analysis.md section 8); delta_1 falls with J_f and
    sqrt(26) is lowest at J_Mx."""
    from crankfmu.studies import flywheel
    from crankfmu.studies.flywheel import analytic, report

    if not FULL:
        # The figure's curve: report computes `analytic` on a 61-point grid, the dynamic error
        # at each point (the test: 5.4 s of CPU; with the subset 1.8 s). The figure is only
        # checked for being drawn; delta_1 and sqrt(26) are checked on the three points below.
        # Quick: every 10th grid point, the rest interpolated in J (the curves are smooth and
        # monotone on each side of J_Mx). The whole grid under CRANKFMU_FULL_TESTS=1.
        def every_tenth(scene, J_f, **kw):
            if len(J_f) <= 3:
                return analytic(scene, J_f, **kw)
            a = analytic(scene, J_f[::10], **kw)
            return {**a, **{k: np.interp(J_f, J_f[::10], a[k]) for k in ("delta_1", "ratio_26")}}
        monkeypatch.setattr(flywheel, "analytic", every_tenth)

    J = np.array([0.0, 0.1409, 0.42])
    a = analytic(servo_scene, J)
    assert a["J_Mx"] == pytest.approx(0.140866, rel=1e-4) and a["lag"]
    assert a["delta_1"][0] > a["delta_1"][1] > a["delta_1"][2]
    assert a["ratio_26"][1] < min(a["ratio_26"][0], a["ratio_26"][2])
    csv = tmp_path / "sweep.csv"
    csv.write_text("run,motor.J_flywheel,delta,status,reason,wall_time\n"
                   "0,0.0,0.1007,completed,,1.0\n1,0.2,0.03,completed,,1.0\n"
                   "2,0.1,nan,failed,x,1.0\n")
    text, written = report(csv, servo_scene, tmp_path, plot=True)
    # units as the FMUs spell them (before: "kg m^2")
    assert "J_Mx = 14.09 kg.m2 at the crank = 0.1409 kg.m2" in text and "m^2" not in text
    assert written == [tmp_path / "flywheel.csv", tmp_path / "flywheel.png"]
    assert (tmp_path / "flywheel.png").stat().st_size > 10_000


def kill_me(names, rows, status, victim, key):
    """A task's post-processing that kills its own worker process for one run, every time."""
    if key == victim:
        os.kill(os.getpid(), signal.SIGKILL)
    return {}


def _tasks(tmp_path, victim):
    from crankfmu.studies.executor import RunTask
    scene = load_scene(spinner(tmp_path, stop=0.5))
    return [RunTask(k, scene, post=kill_me, post_args={"victim": victim, "key": k})
            for k in range(4)]


def test_a_run_that_always_kills_its_local_worker_is_a_lost_row(tmp_path, fmu_dir):
    """The pool is restarted after each break and the lost runs run again one at a time; the
    run that kills its worker alone is returned as lost with the reason, every other run
    completes."""
    from crankfmu.studies.executor import LocalPoolExecutor
    with LocalPoolExecutor(2) as pool:
        outputs = pool.run(_tasks(tmp_path, victim=2), fmu_dir, progress=False)
    assert [o.status for o in outputs] == ["completed", "completed", "lost", "completed"]
    assert "a worker process died while this run was in flight (2 times, the last time alone)" \
        in outputs[2].reason


def test_latin_hypercube_sweep(tmp_path, fmu_dir, one_worker):
    """--samples: N points, one per stratum of each range, the same on a second call (resumed)."""
    scene = spinner(tmp_path)
    kw = dict(samples=5, seed=1, executor=one_worker, fmu_dir=fmu_dir, progress=False,
              plot=False)
    table = sweep(scene, ["r.J=0.3:0.9", "r.d=0.2,1.0"], tmp_path / "lhs", **kw)
    assert len(table) == 5 and all(r["status"] == "completed" for r in table.rows)
    J = np.sort(table.column("r.J"))
    assert np.all((J >= 0.3 + 0.12 * np.arange(5)) & (J < 0.3 + 0.12 * np.arange(1, 6)))
    assert np.all((table.column("r.d") >= 0.2) & (table.column("r.d") <= 1.0))
    assert sweep(scene, ["r.J=0.3:0.9", "r.d=0.2,1.0"], tmp_path / "lhs", **kw).executed == 0


# -- on a Dask LocalCluster: last in the module, because the cluster's scheduler runs in
# this process until the module ends and its event loop takes this process's GIL (and ~15 % of
# a core with its workers, measured idle) from every test after it
@pytest.fixture(scope="module")
def cluster():
    distributed = pytest.importorskip("distributed")
    import dask
    # read at start: a run survives one worker death; a worker holds only the run it executes.
    # Read at each worker's start, so for the module: the nannies start their workers from a
    # forkserver that imported distributed (and numpy, ...) once, not each a fresh interpreter
    # that imports them again (the two first and the three the kill tests restart): the
    # process's one fork server, started by the fork_server fixture.
    with dask.config.set({"distributed.worker.multiprocessing-method": "forkserver"}):
        with dask.config.set({"distributed.scheduler.allowed-failures": 1,
                              "distributed.scheduler.worker-saturation": 1.0}):
            lc = distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                          host="127.0.0.1", dashboard_address=None)
        with lc:
            with distributed.Client(lc) as client:
                yield client


def test_dask_cluster_equals_serial(tmp_path, fmu_dir, serial_table, cluster):
    """A LocalCluster of 2 worker processes on 127.0.0.1 gives the --jobs 1 table exactly, and
    both workers took runs (they get the FMUs' bytes, not a path)."""
    assert all(r["status"] == "completed" for r in serial_table.rows)
    assert len(serial_table.rows) == 12
    table = sweep(spinner(tmp_path), VARY, tmp_path / "out", client=cluster,
                  fmu_dir=fmu_dir, progress=False, plot=False)
    same_table(serial_table, table)  # the plot of a cluster's sweep: the CLI test below


def test_accuracy_and_compare_on_a_dask_cluster_equal_serial(fmu_dir, tmp_path, cluster,
                                                             one_worker):
    """`accuracy` and `compare` (tests/test_executor.py: on a local pool) on the cluster: the
    numbers and the run files equal the serial path's."""
    from crankfmu.studies.accuracy import AccuracyOptions, run_accuracy
    from crankfmu.studies.compare import compare_scenes
    from crankfmu.cosim.runner import RunOptions
    from crankfmu.studies.executor import DaskExecutor

    def scene(stop):
        s = load_scene(SCENARIOS / "servo_press.toml")
        s.stop_time = stop
        return s

    def options(out, **kw):
        return AccuracyOptions(out_dir=out, algorithms=["gauss-seidel"], extrapolations=[0, 1],
                               steps=[2e-3, 1e-3], fmu_dir=fmu_dir, progress=False,
                               estimate=False, **kw)
    serial = run_accuracy(scene(0.1), options(tmp_path / "serial", executor=one_worker))
    b = scene(0.7)
    b.name = "with_flywheel"
    b.components["motor"].parameters["J_flywheel"] = 0.1
    run_opts = RunOptions(fmu_dir=fmu_dir, progress=False)
    serial_cmp = compare_scenes(scene(0.7), copy.deepcopy(b), tmp_path / "cmp_serial", run_opts)
    dask = DaskExecutor(client=cluster)
    on_dask = run_accuracy(scene(0.1), options(tmp_path / "dask", executor=dask))
    dask_cmp = compare_scenes(scene(0.7), copy.deepcopy(b), tmp_path / "cmp_dask", run_opts, dask)
    for oa, ob in zip(serial.outcomes, on_dask.outcomes):
        assert (oa.setting, oa.status, oa.error, oa.do_steps) == \
            (ob.setting, ob.status, ob.error, ob.do_steps)
        name = f"runs/{oa.setting.label}.csv"
        assert (tmp_path / "serial" / name).read_bytes() == (tmp_path / "dask" / name).read_bytes()
    assert serial_cmp.text == dask_cmp.text
    assert (tmp_path / "cmp_serial" / "compare.csv").read_bytes() == \
        (tmp_path / "cmp_dask" / "compare.csv").read_bytes()


def test_killed_dask_worker_loses_nothing(tmp_path, fmu_dir, cluster, serial_run):
    """SIGKILL of one Dask worker process mid-sweep: the nanny restarts it, the scheduler
    reschedules its run; every row is there, equal to the serial table."""
    scene, serial = serial_run
    pids = list(cluster.run(os.getpid).values())
    info = _kill_when_rows(tmp_path / "dask" / "sweep.csv", lambda: pids[0], rows=1)
    table = sweep(scene, VARY, tmp_path / "dask", client=cluster, fmu_dir=fmu_dir,
                  progress=False, plot=False)
    info["thread"].join(1)
    assert info.get("killed") == pids[0]
    assert [r["status"] for r in table.rows] == ["completed"] * 12
    same_table(serial, table)


def test_cli_on_a_scheduler_address(tmp_path, fmu_dir, cluster, one_worker, capsys):
    """`crankfmu sweep --scheduler tcp://127.0.0.1:PORT` (the address, not a client object):
    the serial table, and its plot."""
    from crankfmu.cli import main

    scene = spinner(tmp_path)
    out = tmp_path / "cli"
    assert main(["sweep", str(scene), "--vary", "r.J=0.3,0.6", "--vary", "r.d=0.2:1.0:2",
                 "--out", str(out), "--scheduler", cluster.scheduler.address,
                 "--fmus", str(fmu_dir), "--no-progress", "--plot"]) == 0
    assert "4 runs (4 executed now, 0 kept" in capsys.readouterr().out
    serial = sweep(scene, ["r.J=0.3,0.6", "r.d=0.2:1.0:2"], tmp_path / "serial",
                   executor=one_worker, fmu_dir=fmu_dir, progress=False, plot=False)
    header, rows = read_table(out / "sweep.csv")
    assert header == serial.columns
    same_rows(header, rows, serial.rows)
    assert (out / "sweep.png").is_file()


def test_a_run_that_always_kills_its_dask_worker_is_a_lost_row(tmp_path, fmu_dir, cluster):
    """Dask reschedules it (allowed-failures, 1 in this cluster), then gives up: KilledWorker,
    reported as a lost row; the other runs complete."""
    from crankfmu.studies.executor import DaskExecutor
    outputs = DaskExecutor(client=cluster).run(_tasks(tmp_path, victim=1), fmu_dir,
                                               progress=False)
    assert [o.status for o in outputs] == ["completed", "lost", "completed", "completed"]
    assert "KilledWorker" in outputs[1].reason or "died" in outputs[1].reason
