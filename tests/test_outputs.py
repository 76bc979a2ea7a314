"""Where results go (crankfmu.outputs, issue #27): `--out DIR` always names the output folder,
checked with every file name a command will write there before anything is computed; results
are written only as regular files and never replace anything else; a run's CSV, sidecar and
plot are one set.

Before: `--out` named the CSV, and `--out r.json` wrote the CSV and then the sidecar over it
("wrote r.json, r.json"); a read-only folder, `--out` an existing folder, a sidecar path that
was a folder ended in tracebacks after the whole run (15 cases across run, reference, sweep,
accuracy, compare), the results lost; `--out` naming a FIFO or a device replaced it with a
regular file (as root, /dev/null); two runs writing one folder at once left a sidecar that
described the other run's CSV in 4 of 15 trials. FIFOs and symbolic links are made in the
test's folder, never at real /dev files.
"""
from __future__ import annotations

import fcntl
import hashlib
import json
import math
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from crankfmu.cli import main
from tests.conftest import ROOT, SCENARIOS
from tests.support import fresh_python

SERVO = SCENARIOS / "servo_press.toml"
CONVENTIONAL = SCENARIOS / "conventional_press.toml"


@pytest.fixture
def no_computation(monkeypatch):
    """Every command's first piece of work fails the test: the outputs must be refused first."""
    def computed(*args, **kwargs):
        raise AssertionError("computed before the outputs were checked")
    import crankfmu.studies.accuracy
    import crankfmu.studies.compare
    import crankfmu.studies.executor
    import crankfmu.studies.rocker_analysis
    from crankfmu.cosim import runner
    from crankfmu.system import ssp_export
    monkeypatch.setattr(runner, "load_fmus", computed)
    from crankfmu.monolithic import solve_reference  # noqa: F401 - the subpackage, loaded
    monkeypatch.setattr(sys.modules["crankfmu.monolithic"], "solve_reference", computed)
    monkeypatch.setattr(crankfmu.studies.executor, "prepare_tasks", computed)
    monkeypatch.setattr(crankfmu.studies.accuracy, "load_or_solve_reference", computed)
    monkeypatch.setattr(crankfmu.studies.compare, "run_for_comparison", computed)
    monkeypatch.setattr(ssp_export, "describe_fmus", computed)
    monkeypatch.setattr(crankfmu.studies.rocker_analysis, "impact_table", computed)


def command(name: str, out: Path) -> list[str]:
    """A short invocation of each command that writes results, into `out`."""
    stop = ["--stop-time", "0.6"]
    return {
        "run": ["run", str(SERVO), *stop],
        "reference": ["reference", str(SERVO), *stop],
        "sweep": ["sweep", str(SERVO), "--vary", "press.F_max=6e4,7e4", *stop, "--jobs", "1"],
        "accuracy": ["accuracy", str(SERVO), *stop, "--algorithms", "jacobi", "--steps", "2e-3",
                     "--extrapolations", "0", "--jobs", "1"],
        "compare": ["compare", str(SERVO), str(CONVENTIONAL), *stop, "--jobs", "1"],
        "export-ssp": ["export-ssp", str(SERVO), *stop],
        "analyze": ["analyze", "impact", "--plot", "--scene", str(SCENARIOS / "mo100_impact.toml")],
    }[name] + ["--out", str(out)] + ([] if name in ("export-ssp", "analyze") else ["--no-progress"])


# the name each command writes in its folder, to be taken by something else in the test
WRITES = {"run": "servo_press.json", "reference": "servo_press_reference.json",
          "sweep": "sweep.json", "accuracy": "accuracy.csv", "compare": "compare.csv",
          "export-ssp": "servo_press.ssp", "analyze": "impact_forces.png"}
COMMANDS = list(WRITES)


def refused(capsys, argv, *words) -> str:
    start = time.monotonic()
    status = main(argv)
    err = capsys.readouterr().err
    assert status == 2 and err.startswith("error: --out"), err
    assert all(w in err for w in words), err
    assert time.monotonic() - start < 30  # at once: nothing was run
    return err


@pytest.mark.parametrize("name", COMMANDS)
def test_out_that_is_an_existing_file_is_refused_before_anything_runs(name, tmp_path, capsys,
                                                                      no_computation):
    out = tmp_path / "r.json"
    out.write_text("a file the user keeps\n")
    refused(capsys, command(name, out), str(out), "exists and is a regular file, not a folder")
    assert out.read_text() == "a file the user keeps\n"


@pytest.mark.parametrize("name", COMMANDS)
def test_a_folder_that_cannot_be_written_is_refused_before_anything_runs(name, tmp_path, capsys,
                                                                         no_computation):
    if os.geteuid() == 0:  # root writes through permissions: a read-only filesystem instead
        out = Path("/proc/crankfmu-out")
        words = "cannot create the output folder"
    else:
        locked = tmp_path / "locked"
        locked.mkdir()
        locked.chmod(0o555)
        out = locked / "out"
        words = "cannot create the output folder"
    refused(capsys, command(name, out), str(out), words)
    if os.geteuid() == 0:  # an existing folder this process cannot write in
        refused(capsys, command(name, Path("/proc")), "cannot write in the output folder")


@pytest.mark.parametrize("name", COMMANDS)
def test_a_file_name_taken_by_a_folder_is_refused_before_anything_runs(name, tmp_path, capsys,
                                                                       no_computation):
    (tmp_path / WRITES[name]).mkdir()
    refused(capsys, command(name, tmp_path), str(tmp_path / WRITES[name]), "is a folder")
    assert (tmp_path / WRITES[name]).is_dir()


@pytest.mark.parametrize("name", COMMANDS)
def test_a_fifo_or_a_link_is_never_replaced(name, tmp_path, capsys, no_computation):
    """A FIFO where a result goes, a symbolic link to a FIFO, a link to a regular file: each is
    refused, left as it was, and nothing blocks on the FIFO."""
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    target = tmp_path / "kept.txt"
    target.write_text("kept\n")
    for make, kind in ((lambda p: os.mkfifo(p), "is a FIFO"),
                       (lambda p: p.symlink_to(fifo), "is a symbolic link"),
                       (lambda p: p.symlink_to(target), "is a symbolic link")):
        out = tmp_path / f"out{kind[-4:]}{len(list(tmp_path.iterdir()))}"
        out.mkdir()
        taken = out / WRITES[name]
        make(taken)
        before = os.lstat(taken)
        refused(capsys, command(name, out), str(taken), kind)
        after = os.lstat(taken)
        assert (after.st_mode, after.st_ino) == (before.st_mode, before.st_ino)
    assert target.read_text() == "kept\n"


@pytest.mark.parametrize("name", COMMANDS)
def test_out_naming_a_fifo_or_a_link_to_one_is_refused(name, tmp_path, capsys, no_computation):
    """`--out /dev/null` replaced /dev/null when run as root; here a FIFO and a link to it
    stand in for the device (--out names a folder, and neither is one)."""
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    link = tmp_path / "link"
    link.symlink_to(fifo)
    for out in (fifo, link):
        refused(capsys, command(name, out), "exists and is a FIFO, not a folder")
        assert os.path.exists(fifo) and os.stat(fifo).st_mode == os.stat(link).st_mode


def test_out_r_json_is_a_folder_with_the_set_in_it(tmp_path, fmu_dir, capsys):
    """Before: `--out r.json` (and `--out r.png --plot`) wrote the CSV, then the sidecar (and
    the plot) over it, exit 0. Now r.json is the folder and the three files are
    <scene>.csv, <scene>.json, <scene>.png in it. Two members of one set cannot collide by
    construction: they share the scene's name and differ in their suffix, and a scene name is
    a plain name (no "/", at most 100 characters: crankfmu.system.scene.check_name)."""
    out = tmp_path / "r.json"
    assert main(["run", str(SERVO), "--stop-time", "0.05", "--fmus", str(fmu_dir), "--out",
                 str(out), "--plot", "--no-progress", "--no-estimate"]) == 0
    assert sorted(p.name for p in out.iterdir()) == ["servo_press.csv", "servo_press.json",
                                                     "servo_press.png"]
    csv = out / "servo_press.csv"
    assert csv.read_text().startswith("time,")
    side = json.loads((out / "servo_press.json").read_text())
    assert side["csv"] == {"file": "servo_press.csv", "rows": 51,
                           "sha256": hashlib.sha256(csv.read_bytes()).hexdigest()}
    assert side["plot"] == "servo_press.png"
    assert (out / "servo_press.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    from crankfmu.cosim.results import run_set_paths
    with pytest.raises(ValueError, match="ends in .csv"):
        run_set_paths(out / "r.json")


def test_a_rerun_without_plot_removes_the_earlier_plot(tmp_path, fmu_dir):
    """The PNG of an earlier run would describe another CSV: a set has no member of another."""
    args = ["run", str(SERVO), "--stop-time", "0.02", "--fmus", str(fmu_dir), "--out",
            str(tmp_path), "--no-progress", "--no-estimate"]
    assert main(args + ["--plot"]) == 0 and (tmp_path / "servo_press.png").is_file()
    assert main(args) == 0
    assert not (tmp_path / "servo_press.png").exists()
    assert json.loads((tmp_path / "servo_press.json").read_text())["plot"] is None


def test_the_set_is_written_under_a_lock_on_the_folder(tmp_path, fmu_dir):
    """While another process holds the folder's lock, a run waits to write its set, then
    writes all of it; the sidecar names its CSV's digest."""
    out = tmp_path / "out"
    out.mkdir()
    fd = os.open(out, os.O_RDONLY)
    fcntl.flock(fd, fcntl.LOCK_EX)
    try:
        proc = subprocess.Popen([sys.executable, "-m", "crankfmu", "run", str(SERVO),
                                 "--stop-time", "0.02", "--fmus", str(fmu_dir), "--out",
                                 str(out), "--no-progress", "--no-estimate"], cwd=ROOT,
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        deadline = time.monotonic() + 120
        while "waiting for another crankfmu process" not in _peek(proc) and \
                time.monotonic() < deadline and proc.poll() is None:
            time.sleep(0.1)
        assert proc.poll() is None and not (out / "servo_press.csv").exists()
    finally:
        fcntl.flock(fd, fcntl.LOCK_UN)
        os.close(fd)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 0, err
    _same_set(out / "servo_press.csv")


_PEEKED: dict[int, str] = {}


def _peek(proc) -> str:
    """What the process wrote on stderr so far (non-blocking)."""
    os.set_blocking(proc.stderr.fileno(), False)
    try:
        chunk = proc.stderr.read()
    except (TypeError, BlockingIOError):
        chunk = None
    _PEEKED[proc.pid] = _PEEKED.get(proc.pid, "") + (chunk or "")
    return _PEEKED[proc.pid]


def _same_set(csv: Path) -> dict:
    side = json.loads(csv.with_suffix(".json").read_text())
    rows = np.loadtxt(csv, delimiter=",", skiprows=1, ndmin=2)
    assert side["csv"]["sha256"] == hashlib.sha256(csv.read_bytes()).hexdigest()
    assert side["csv"]["rows"] == side["rows"] == len(rows)
    return side


def test_two_runs_into_one_folder_leave_one_consistent_set(tmp_path, fmu_dir):
    """Two runs of one scene with different parameters write the same names at once: the
    folder ends with the CSV, sidecar and plot of one of them, the sidecar naming that CSV's
    digest and that run's parameter."""
    out = tmp_path / "out"
    procs = [fresh_python.start(fresh_python.CRANKFMU, [
        "run", SERVO, "--stop-time", "0.3", "--fmus", fmu_dir, "--out", out,
        "--set", f"press.F_max={f}", "--no-progress", "--plot"], cwd=ROOT) for f in (5e4, 6e4)]
    for proc in procs:
        _, err = proc.communicate(timeout=300)
        assert proc.returncode == 0, err
    side = _same_set(out / "servo_press.csv")
    assert side["components"]["press"]["parameters"]["F_max"] in (5e4, 6e4)


def test_a_plot_is_drawn_once_and_its_png_is_the_one_savefig_writes(monkeypatch):
    """A run's plot, laid out by tight_layout, was drawn twice at its save: tight_layout leaves
    a placeholder layout engine on the figure, and matplotlib's savefig draws a figure that has
    any engine once to lay it out before the draw that renders it (a third of the save's CPU).
    figure_png draws it once; its PNG is byte for byte what savefig writes of the same figure
    with the placeholder left on."""
    import io

    from matplotlib.figure import Figure

    from crankfmu.cosim.results import figure, figure_png

    t = np.linspace(0.0, 0.3, 301)
    rows = np.column_stack([t, 40.0 * t, np.sin(40.0 * t), 2e4 * np.cos(40.0 * t)])

    def made():
        return figure(["press.phi", "press.w_crank", "press.F"], ["rad", "rad/s", "N"], rows,
                      "servo_press")

    saved = io.BytesIO()
    made().savefig(saved, format="png", dpi=110)
    draws = []
    draw = Figure.draw

    def counted(self, renderer):
        draws.append(self)
        return draw(self, renderer)
    monkeypatch.setattr(Figure, "draw", counted)
    assert figure_png(made(), dpi=110) == saved.getvalue()
    assert len(draws) == 1


def test_the_csv_holds_the_recorded_doubles_exactly(tmp_path):
    """Each value is written as Python's shortest repr of the double (read back, the same bits),
    the header quotes the names: awkward doubles (subnormal, -0.0, 0.1 + 0.2, huge, an
    integral value) included."""
    from crankfmu.cosim.results import Recorder, write_csv
    values = [5e-324, -0.0, 0.1 + 0.2, 1.7976931348623157e308, 3.0, -2.5e-17]
    rec = Recorder(["a.x", "b.y"], [None, "m"])
    for k in range(0, len(values), 2):
        rec.add(k * 0.1, values[k:k + 2])
    csv = tmp_path / "r.csv"
    write_csv(csv, rec)
    header, *lines = csv.read_text().splitlines()
    assert header == 'time,"a.x","b.y"'
    read = [[float(v) for v in line.split(",")] for line in lines]
    assert [[math.copysign(1, v) for v in row] for row in read] == \
        [[math.copysign(1, v) for v in row] for row in rec.rows.tolist()]
    assert read == rec.rows.tolist() and lines[0] == "0.0,5e-324,-0.0"


def test_an_analysis_table_is_written_whole_or_not_at_all(tmp_path):
    """An analysis's CSV table (here the base-link mass sweep's) is written through a temporary
    file renamed over the name: a failure while its rows are made leaves the earlier table
    as it was and no temporary file. Before, the tables were truncated first and written in
    place: the same failure left a header and one row where the earlier table had been."""
    from crankfmu.studies import base_link

    path = tmp_path / "press_base_link_mass.csv"
    path.write_text("the earlier table\n")
    broken = {case: {"mass": np.array([0.0, 20.0]), "delta_sim": np.zeros(2),
                     "delta_1": np.zeros(2), "L1": np.zeros(1), "J0": np.zeros(2)}
              for case in base_link.CASES}  # L1 one short: the second row fails
    with pytest.raises(IndexError):
        base_link.write_csv(broken, path)
    assert path.read_text() == "the earlier table\n"
    assert [p.name for p in tmp_path.iterdir()] == [path.name]
