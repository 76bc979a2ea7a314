"""The per-user cache FMUs are unpacked into (crankfmu.fmu.archive): one folder per FMU content,
used by every later process, never stale, never half-written, safe for processes that unpack
at once. Each case loads FMUs in fresh processes (a process unpacks a content once; started as
tests/support/fresh_python.py says, with the imports done, no FMU loaded)."""
from __future__ import annotations

import json
import os
import zipfile
from pathlib import Path

from tests.support import fresh_python

ROOT = Path(__file__).resolve().parents[1]
# Load the FMU, step it once after initialization, print where it was unpacked and flange_J.
LOAD = """
import json, sys
from crankfmu.fmu.instance import FmuInstance
fmu = FmuInstance("m", sys.argv[1])
fmu.instantiate()
fmu.setup(0.0, 1.0, 1e-8)
fmu.slave.enterInitializationMode()
fmu.slave.exitInitializationMode()
fmu.do_step(0.0, 1e-3)
value = float(fmu.reader(["flange_J"])()[0])
fmu.terminate()
print(json.dumps({"folder": fmu.unzip_dir, "flange_J": value}))
"""


def load(fmu: Path, cache: Path | str) -> fresh_python.Started:
    return fresh_python.start(LOAD, [fmu], cwd=ROOT,
                              env={**os.environ, "CRANKFMU_CACHE_DIR": str(cache)})


def loaded(process: fresh_python.Started) -> dict:
    out, err = process.communicate(timeout=120)
    assert process.returncode == 0, err[-3000:]
    return json.loads(out.splitlines()[-1])


def entries(cache: Path) -> list[str]:
    return sorted(p.name for p in cache.iterdir())


def test_later_processes_use_the_folder_the_first_unpacked(fmu_dir, tmp_path):
    first = loaded(load(fmu_dir / "DcServoMotor.fmu", tmp_path))
    stamp = Path(first["folder"], "modelDescription.xml").stat().st_mtime_ns
    second = loaded(load(fmu_dir / "DcServoMotor.fmu", tmp_path))
    assert first["folder"] == second["folder"] and Path(first["folder"]).parent == tmp_path
    assert Path(second["folder"], "modelDescription.xml").stat().st_mtime_ns == stamp
    assert len(entries(tmp_path)) == 1 and first["flange_J"] == second["flange_J"] == 0.05


def test_a_changed_cached_file_is_never_run_but_unpacked_again(fmu_dir, tmp_path):
    """A cached folder whose model source was edited (here: flange_J + 1 kg.m2, appended to the
    cached dc_motor.py) or whose file was removed is unpacked again before it is used."""
    from tests.test_mixing import MARKER
    folder = Path(loaded(load(fmu_dir / "DcServoMotor.fmu", tmp_path))["folder"])
    source = next(folder.glob("resources/crankfmu_rt_*/models/dc_motor/dc_motor.py"))
    genuine = source.read_bytes()
    source.write_bytes(genuine + MARKER.encode())
    again = loaded(load(fmu_dir / "DcServoMotor.fmu", tmp_path))
    assert again["flange_J"] == 0.05 and source.read_bytes() == genuine
    next(folder.glob("binaries/*/*_pythonfmu.so")).unlink()
    assert loaded(load(fmu_dir / "DcServoMotor.fmu", tmp_path))["flange_J"] == 0.05
    assert entries(tmp_path) == [folder.name]


def test_processes_unpacking_at_once_each_get_a_whole_folder(fmu_dir, tmp_path):
    """Four processes meet an empty cache at once: each unpacks into its own temporary folder
    and renames it; the first rename wins, the others use that folder."""
    processes = [load(fmu_dir / "StephensonPress.fmu", tmp_path) for _ in range(4)]
    results = [loaded(p) for p in processes]
    assert len({r["folder"] for r in results}) == 1
    assert entries(tmp_path) == [Path(results[0]["folder"]).name]  # no part-done folder left
    with zipfile.ZipFile(fmu_dir / "StephensonPress.fmu") as z:
        member = next(n for n in z.namelist() if n.endswith("stephenson_press.py"))
        assert Path(results[0]["folder"], member).read_bytes() == z.read(member)


def test_without_a_private_cache_each_process_unpacks_into_its_own_folder(fmu_dir, tmp_path):
    """A cache folder others may write to is not used (its files would be run), nor the cache
    when CRANKFMU_CACHE_DIR is empty: the FMU unpacks into a private temporary folder that is
    removed at exit."""
    shared = tmp_path / "shared"
    shared.mkdir(mode=0o777)
    shared.chmod(0o777)
    for cache in (shared, ""):
        folder = loaded(load(fmu_dir / "DcServoMotor.fmu", cache))["folder"]
        assert not folder.startswith(str(shared)) and not Path(folder).exists()
    assert entries(shared) == []
