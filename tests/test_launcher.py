"""The native launcher in front of pythonfmu's binary (crankfmu/fmu/launcher): what the FMU
carries, and how it fails, seen from fmpy. Hosts without Python: tests/test_importer_c.py (the
bare C host) and tests/test_importer_ecos.py (the native ecos command line)."""
from __future__ import annotations

import os
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

from tests.conftest import recorded_python


def _zip(fmu: Path) -> dict[str, bytes]:
    with zipfile.ZipFile(fmu) as z:
        return {n: z.read(n) for n in z.namelist()}


def test_the_fmu_binary_is_the_launcher_without_python_symbols(fmu_dir, tmp_path):
    files = _zip(fmu_dir / "DcServoMotor.fmu")
    launcher = tmp_path / "DcServoMotor.so"
    launcher.write_bytes(files["binaries/linux64/DcServoMotor.so"])
    assert "binaries/linux64/DcServoMotor_pythonfmu.so" in files
    config = files["resources/crankfmu_launcher.txt"].decode()
    recorded = recorded_python(config)
    assert recorded is not None and os.path.samefile(recorded, sys.executable)  # this Python
    assert "requires = numpy scipy\n" in config
    dynamic = subprocess.run(["readelf", "-d", str(launcher)], capture_output=True,
                             text=True).stdout
    assert "libpython" not in dynamic
    undefined = subprocess.run(["nm", "-D", "--undefined-only", str(launcher)],
                               capture_output=True, text=True).stdout.split()
    assert not [s for s in undefined if s.startswith(("Py", "_Py"))]
    exported = subprocess.run(["nm", "-D", "--defined-only", str(launcher)], capture_output=True,
                              text=True).stdout
    real = tmp_path / "real.so"
    real.write_bytes(files["binaries/linux64/DcServoMotor_pythonfmu.so"])
    real_fmi = {w for w in subprocess.run(["nm", "-D", "--defined-only", str(real)],
                                          capture_output=True, text=True).stdout.split()
                if w.startswith("fmi2")}
    assert real_fmi and real_fmi <= set(exported.split())  # every fmi2 function forwarded
    card = files["documentation/index.html"].decode()
    assert "Using the FMUs in other tools" in card and "CRANKFMU_PYTHON" in card


def test_the_builder_python_is_recorded_by_one_name_however_python_was_started(monkeypatch):
    """An FMU records the python that built it. `crankfmu run` (a console script: it starts the
    environment's python3.11) and `python -m pytest` (python) recorded two names of one
    interpreter, so the README's run command followed by its test command in one checkout
    failed three tests (a rebuilt FMU's bytes against the session catalog's, copied from the
    fmus/ the run had built; the recorded python against the tests'). Every name of this
    interpreter beside it now records one: the versioned one."""
    from crankfmu.fmu import launcher

    folder = Path(sys.executable).parent
    names = [folder / n for n in ("python", "python3", f"python{launcher.python_version()}")]
    names = [n for n in names if n.exists() and os.path.samefile(n, sys.executable)]
    assert len(names) >= 2, names  # a venv has all three
    configs = set()
    for name in names:
        monkeypatch.setattr(sys, "executable", str(name))
        configs.add(launcher.launcher_config("DcServoMotor"))
    assert len(configs) == 1, configs
    assert f"python = {names[-1]}\n".encode() in configs.pop()


FAILING_INIT = r'''
import sys
from fmpy import extract, read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import FMU2Slave
path = sys.argv[1]
md = read_model_description(path)
vr = {v.name: v.valueReference for v in md.modelVariables}
s = FMU2Slave(guid=md.guid, unzipDirectory=extract(path), modelIdentifier=md.coSimulation.modelIdentifier, instanceName="press")
s.instantiate()  # default callbacks: fmpy prints every message it is given, no debug logging
s.setupExperiment(startTime=0.0)
s.setReal([vr["l"]], [0.01])
s.enterInitializationMode()
try:
    s.exitInitializationMode()
except FMICallException as err:
    print("exitInitializationMode status", err.status, flush=True)
s.reset()  # a fresh instance: now with a rod that fits
s.setupExperiment(startTime=0.0)
s.setReal([vr["l"]], [0.25])
s.enterInitializationMode()
s.exitInitializationMode()
s.doStep(0.0, 1e-3)
print("after reset: phi", s.getReal([vr["phi"]])[0], flush=True)
s.terminate()
s.freeInstance()
print("freed", flush=True)
'''


def test_fmpy_gets_fmi2error_for_impossible_parameters_then_resets_and_frees(fmu_dir):
    """--set press.l=0.01 (rod shorter than the crank) in a fresh fmpy process: fmi2Error
    (3), the reason printed by fmpy's default logger without debug logging, then fmi2Reset gives
    a working instance, fmi2FreeInstance succeeds, and the process exits with 0."""
    done = subprocess.run([sys.executable, "-c", FAILING_INIT,
                           str(fmu_dir / "StephensonPress.fmu")],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stdout + done.stderr
    out = done.stdout.splitlines()
    assert "exitInitializationMode status 3" in out  # fmi2Error, not fmi2Fatal (4)
    assert any(line.startswith("[ERROR]") and "parameter l = 0.01 is not allowed" in line
               for line in out), done.stdout
    assert not any(line.startswith("[FATAL]") for line in out), done.stdout
    assert any(line.startswith("after reset: phi") for line in out) and out[-1] == "freed"


def test_fmpy_in_an_environment_without_scipy_names_scipy(fmu_dir, no_scipy_env):
    """fmpy run by an environment without scipy: the FMU uses that process's interpreter; the
    launcher's pre-flight fails fmi2Instantiate, and fmpy prints why without debug logging."""
    code = ("import sys, fmpy\n"
            "fmpy.simulate_fmu(sys.argv[1], stop_time=0.01)\n")
    done = subprocess.run([str(no_scipy_env / "bin" / "python"), "-c", code,
                           str(fmu_dir / "DcServoMotor.fmu")],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode != 0 and "Failed to instantiate model" in done.stderr
    message = next(line for line in done.stdout.splitlines() if "fmi2Instantiate" in line)
    assert message.startswith("[ERROR]") and "No module named 'scipy'" in message, message
    assert str(no_scipy_env) in message  # which Python it looked in


def test_without_a_c_compiler_the_build_keeps_pythonfmus_binary_and_says_so(
        tmp_path, monkeypatch, capsys):
    from crankfmu.fmu import launcher
    from crankfmu.fmu.build import build_fmu, validate

    monkeypatch.setenv("CC", str(tmp_path / "no-such-cc"))
    monkeypatch.setattr(launcher, "_WARNED", [])
    fmu = build_fmu("Rotor", tmp_path)
    assert "WARNING: crankfmu build: no C compiler found" in capsys.readouterr().err
    files = _zip(fmu)
    assert "binaries/linux64/Rotor_pythonfmu.so" not in files
    assert "resources/crankfmu_launcher.txt" not in files
    from crankfmu.fmu.build import library_folder  # the installed package: after a run in
    # this process `import pythonfmu` gives an FMU's copy, without binaries
    export = library_folder(2) / "resources" / "binaries" / "linux64" / "libpythonfmu-export.so"
    assert files["binaries/linux64/Rotor.so"] == export.read_bytes()
    assert "built without a C compiler" in files["documentation/index.html"].decode()
    assert validate(fmu) == []


def test_launcher_compile_is_deterministic():
    """A compile now gives the bytes of an earlier one: the launcher kept in the cache folder
    (compiled by whichever process built an FMU first; one compile here, 0.4 s of CPU, instead
    of two), or, none kept, the one compile_launcher makes and keeps."""
    from crankfmu.fmu import launcher

    if launcher.find_compiler() is None:
        pytest.skip("no C compiler")
    for version in (2, 3):
        earlier = launcher.compile_launcher(version)
        launcher._compile.cache_clear()  # not the bytes compile_launcher may have compiled
        assert launcher._compile(tuple(launcher.find_compiler()), launcher.sources(version)) \
            == earlier


def test_a_compiled_launcher_is_kept_for_later_processes_of_the_same_compiler(
        tmp_path, monkeypatch):
    """A build in a later process takes the launcher from the per-user cache folder instead of
    compiling it again (here: the in-process cache cleared, and the compiler made to fail);
    other sources, or a compiler that says it is another version, compile again. Without a
    private cache folder nothing is kept."""
    from crankfmu.fmu import archive, launcher

    if launcher.find_compiler() is None:
        pytest.skip("no C compiler")
    monkeypatch.setenv(archive.CACHE_ENV, str(tmp_path))
    launcher._compile_kept.cache_clear()
    first = launcher.compile_launcher(2)
    kept = [p.name for p in tmp_path.iterdir()]
    assert len(kept) == 1 and kept[0].startswith("launcher-") and kept[0].endswith(".so")
    assert (tmp_path / kept[0]).read_bytes() == first

    def compiled_again(*args):
        raise AssertionError("compiled again")
    monkeypatch.setattr(launcher, "_compile", compiled_again)

    def later_process(version: int) -> bytes:
        launcher._compile_kept.cache_clear()
        return launcher.compile_launcher(version)
    assert later_process(2) == first
    with pytest.raises(AssertionError, match="compiled again"):
        later_process(3)  # other sources
    monkeypatch.setattr(launcher, "_compiler_identity", lambda compiler: "cc (Other) 99.1\n")
    with pytest.raises(AssertionError, match="compiled again"):
        later_process(2)
    monkeypatch.undo()
    monkeypatch.setenv(archive.CACHE_ENV, "")  # no cache folder: compiled in each process
    monkeypatch.setattr(launcher, "_compile", compiled_again)
    with pytest.raises(AssertionError, match="compiled again"):
        later_process(2)
    launcher._compile_kept.cache_clear()  # nothing of this test's stays for the next


def test_kept_launchers_are_removed_with_the_cache_folders_unused_fmus(tmp_path):
    """A kept launcher is removed CACHE_KEEP_SECONDS after it was compiled (it is compiled
    again at the next build), one left half written after an hour; newer ones stay."""
    import os
    import time

    from crankfmu.fmu import archive
    now = time.time()
    ages = {"launcher-old.so": archive.CACHE_KEEP_SECONDS + 60, "launcher-new.so": 60,
            ".launcher-new.so.x.part": 3600 + 60, ".launcher-new.so.y.part": 60}
    for name, age in ages.items():
        (tmp_path / name).write_bytes(b"\x7fELF")
        os.utime(tmp_path / name, (now - age, now - age))
    archive._evict(tmp_path, keep=tmp_path / "in-use")
    assert sorted(p.name for p in tmp_path.iterdir()) == [".launcher-new.so.y.part",
                                                          "launcher-new.so"]
