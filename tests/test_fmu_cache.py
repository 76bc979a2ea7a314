"""The per-user cache FMUs are unpacked into (crankfmu.fmu.archive): one folder per FMU content,
used by every later process, never stale, never half-written, safe for processes that unpack
at once. Each case loads FMUs in fresh processes (a process unpacks a content once; started as
tests/support/fresh_python.py says, with the imports done, no FMU loaded)."""
from __future__ import annotations

import json
import os
import zipfile
from pathlib import Path

import pytest

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


# Load the FMU with archive.load_fmu, counting the checks and parses it does; print them and
# what the model description says.
CHECKS = """
import fmpy, json, sys
from crankfmu.fmu import archive
calls = {"inspect": 0, "parse": 0}
def counted(name, function):
    def call(*args, **kwargs):
        calls[name] += 1
        return function(*args, **kwargs)
    return call
archive.inspect_fmu = counted("inspect", archive.inspect_fmu)
fmpy.read_model_description = counted("parse", fmpy.read_model_description)
try:
    folder, md = archive.load_fmu(sys.argv[1])
except ValueError as err:
    print(json.dumps({"refused": str(err), **calls}))
    raise SystemExit(0)
print(json.dumps({**calls, "folder": folder, "description": [
    md.guid, md.version, md.modelName, md.coSimulation.modelIdentifier,
    [[v.name, v.valueReference, v.causality, v.variability, v.type, v.start, v.unit,
      v.description] for v in md.modelVariables]]}))
"""


def checks(fmu: Path, cache: Path) -> dict:
    return loaded(fresh_python.start(CHECKS, [fmu], cwd=ROOT,
                                     env={**os.environ, "CRANKFMU_CACHE_DIR": str(cache)}))


def test_a_later_process_loads_a_checked_fmu_without_checking_it_again(fmu_dir, tmp_path):
    """The first process checks the FMU (member names, the description's XML, the bundle's
    digest, the GUID) and parses its description, then records what it found in the cached
    folder (archive.CHECKED); a later one loads the record: no check, no parse, the same
    description (every variable's name, reference, causality, variability, type, start, unit
    and description; GUID, version, names). Before, every process checked and parsed again
    (2 FMUs: about 15 ms of each run's start)."""
    first = checks(fmu_dir / "StephensonPress.fmu", tmp_path)
    second = checks(fmu_dir / "StephensonPress.fmu", tmp_path)
    assert (first["inspect"], first["parse"]) == (1, 1)
    assert (second["inspect"], second["parse"]) == (0, 0)
    assert second["description"] == first["description"] and second["folder"] == first["folder"]


def test_a_record_of_other_checks_or_damaged_is_checked_again(fmu_dir, tmp_path):
    """A record written by other code (another crankfmu or fmpy: its `checks` differ) or damaged
    (here: cut short) is not used: the process checks the FMU again and writes a new record."""
    import pickle

    from crankfmu.fmu.archive import CHECKED
    folder = Path(checks(fmu_dir / "DcServoMotor.fmu", tmp_path)["folder"])
    record = pickle.loads((folder / CHECKED).read_bytes())
    record.checks = "another crankfmu"
    (folder / CHECKED).write_bytes(pickle.dumps(record))
    again = checks(fmu_dir / "DcServoMotor.fmu", tmp_path)
    assert (again["inspect"], again["parse"]) == (1, 1)
    (folder / CHECKED).write_bytes((folder / CHECKED).read_bytes()[:100])
    assert (checks(fmu_dir / "DcServoMotor.fmu", tmp_path)["parse"]) == 1
    assert (checks(fmu_dir / "DcServoMotor.fmu", tmp_path)["parse"]) == 0  # recorded again


def test_a_refused_fmu_gets_no_record_and_stays_refused(fmu_dir, tmp_path):
    """An FMU whose description carries another GUID than its build's passes the checks made
    before unpacking and is refused after (the GUID against the bundle): no record is written,
    and a later process refuses it again."""
    from crankfmu.fmu.archive import CHECKED
    from tests.test_hostile_input import _other_guid
    with zipfile.ZipFile(fmu_dir / "DcServoMotor.fmu") as z:
        entries = {i.filename: z.read(i) for i in z.infolist()}
    _other_guid(entries)
    forged = tmp_path / "forged.fmu"
    with zipfile.ZipFile(forged, "w", zipfile.ZIP_DEFLATED) as z:
        for name, data in entries.items():
            z.writestr(name, data)
    cache = tmp_path / "cache"
    cache.mkdir(mode=0o700)
    for _ in range(2):
        assert "modelDescription.xml has guid {12345678-" in checks(forged, cache)["refused"]
    assert not list(cache.glob(f"*/{CHECKED}"))


# rebuild_reason of a catalog FMU (FMI 2.0 or, with its default effects, 3.0), counting the
# modelDescription parses it makes.
REBUILD = """
import json, sys
from pathlib import Path
from crankfmu.fmu import archive, build_fmi3
from crankfmu.fmu.build import rebuild_reason
from crankfmu.models.catalog import physics_class
calls = {"parse": 0}
real = archive.parse_safe_xml
def parse(*args, **kwargs):
    calls["parse"] += 1
    return real(*args, **kwargs)
archive.parse_safe_xml = parse
path, model, version = Path(sys.argv[1]), sys.argv[2], int(sys.argv[3])
effects = tuple(e.name for e in physics_class(model).effects if e.default)
build_id = build_fmi3.current_build_id(model, effects) if version == 3 else None
reason = rebuild_reason(path, model, version, build_id)
print(json.dumps({"reason": None if reason is None else reason.reason, **calls}))
"""


@pytest.mark.parametrize("version", [2, 3])
def test_the_check_for_a_rebuild_uses_the_record_of_a_loaded_fmu(fmu_dir, fmi3_dir, tmp_path,
                                                                 version):
    """Whether a catalog FMU is a whole build of the current sources (build.rebuild_reason,
    before every run) reads its description from the record load_fmu wrote for that content:
    no parse (before: two, the safety check and the reading of GUID and version), the same
    answer, for FMI 3.0's instantiationToken too."""
    fmu = (fmu_dir if version == 2 else fmi3_dir) / "StephensonPress.fmu"
    env = {**os.environ, "CRANKFMU_CACHE_DIR": str(tmp_path)}
    args = [fmu, "StephensonPress", version]
    before = loaded(fresh_python.start(REBUILD, args, cwd=ROOT, env=env))
    checks(fmu, tmp_path)
    after = loaded(fresh_python.start(REBUILD, args, cwd=ROOT, env=env))
    assert before == {"reason": None, "parse": 2} and after == {"reason": None, "parse": 0}
