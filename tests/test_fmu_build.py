"""The build: valid FMUs with units and a model card, and the same bytes from the same sources."""
from __future__ import annotations

import html
import io
import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest
from fmpy import read_model_description

from crankfmu.fmu.build import build_fmu, validate
from crankfmu.models.catalog import FMU_MODELS
from tests.support import fresh_python

MODELS = ("DcServoMotor", "StephensonPress")
SERVO_PRESS = Path(__file__).resolve().parents[1] / "scenarios" / "servo_press.toml"


@pytest.mark.parametrize("version", [2, 3])
@pytest.mark.parametrize("name", list(FMU_MODELS))
def test_every_fmu_passes_fmpy_validate(fmu_dir, fmi3_dir, name, version):
    """Every catalog FMU of the session (tests/conftest.py builds them without the check),
    FMI 2.0 and FMI 3.0: fmpy validate finds no problem."""
    folder = fmu_dir if version == 2 else fmi3_dir
    assert validate(folder / f"{name}.fmu") == []


def test_every_real_variable_has_a_unit_and_a_description(fmu_dir):
    for name in MODELS:
        md = read_model_description(str(fmu_dir / f"{name}.fmu"))
        assert md.defaultExperiment is not None and md.defaultExperiment.stepSize
        declared = {u.name for u in md.unitDefinitions}
        for v in md.modelVariables:
            assert v.description, f"{name}.{v.name} has no description"
            if v.type == "Real":
                assert v.unit in declared, f"{name}.{v.name} has no declared unit"


def test_effects_are_fixed_boolean_parameters(fmu_dir):
    md = read_model_description(str(fmu_dir / "StephensonPress.fmu"))
    effects = {v.name: v for v in md.modelVariables if v.name.startswith("effect_")}
    assert set(effects) == {"effect_gravity", "effect_forging_load", "effect_rod_inertia",
                            "effect_driven_crank"}
    for v in effects.values():
        assert (v.type, v.causality, v.variability) == ("Boolean", "parameter", "fixed")


def test_model_card_carries_equations_and_seed(fmu_dir):
    with zipfile.ZipFile(fmu_dir / "StephensonPress.fmu") as z:
        card = html.unescape(z.read("documentation/index.html").decode())
    assert "J(phi) phi'' + J'(phi)/2 phi'^2 = i M_D + M_C(phi)" in card
    assert "stephenson_press_servo_drive" in card


def test_building_twice_gives_identical_files(tmp_path):
    first = build_fmu("DcServoMotor", tmp_path / "a")
    second = build_fmu("DcServoMotor", tmp_path / "b")
    with zipfile.ZipFile(first) as a, zipfile.ZipFile(second) as b:
        assert a.read("modelDescription.xml") == b.read("modelDescription.xml")
    assert first.read_bytes() == second.read_bytes()


def test_builds_compile_each_bundled_module_once(tmp_path, monkeypatch):
    """The bytecode an FMU carries is compiled once per module and process: the FMI 2.0 and 3.0
    builds of a model share its runtime and model files, two FMI 2.0 builds pythonfmu's package
    (before: each build compiled all of them again). And the build imports its bundle from that
    bytecode (before: compiled from source a second time, for the import)."""
    import importlib._bootstrap_external as ext

    from crankfmu.fmu import bundle
    from crankfmu.fmu.build_fmi3 import build_fmu3
    compiled, imported = [], []
    original_compile, original_source_to_code = compile, ext.SourceLoader.source_to_code

    def recorded_compile(source, name, *args, **kwargs):
        compiled.append((name, source))
        return original_compile(source, name, *args, **kwargs)

    def recorded_import(self, data, path, *, _optimize=-1):
        imported.append(str(path))
        return original_source_to_code(self, data, path, _optimize=_optimize)
    monkeypatch.setattr(bundle, "compile", recorded_compile, raising=False)
    monkeypatch.setattr(ext.SourceLoader, "source_to_code", recorded_import)
    bundle._pyc.cache_clear()
    build_fmu("DcServoMotor", tmp_path)
    build_fmu("Rotor", tmp_path)
    build_fmu3("DcServoMotor", tmp_path / "fmi3")
    again = sorted({name for name, source in compiled if compiled.count((name, source)) > 1})
    assert again == [] and len(compiled) > 40, again
    assert [p for p in imported if "crankfmu_build_" in p] == []  # bundle_on_path's folder


def test_a_build_after_a_run_in_the_same_process_carries_the_binaries(fmu_dir, tmp_path):
    """A run imports the FMU's own copy of pythonfmu (Python files only) as `pythonfmu`, and
    pythonfmu's builder copies the binaries found beside the imported package: a build in that
    process wrote an FMU without binaries (fmpy then failed with "Cannot find shared library";
    two tests of test_cli_options.py did so after another file's runs on the same xdist
    worker). In a fresh interpreter (tests/support/fresh_python.py: crankfmu imported, nothing
    run): a run, then a build, whose FMU carries this platform's
    binary and is the same file as a build in a process that ran nothing."""
    script = (
        "import sys, crankfmu\n"
        "from pathlib import Path\n"
        "from crankfmu.fmu.build import build_fmu\n"
        f"crankfmu.simulate({str(SERVO_PRESS)!r}, stop_time=0.01, fmu_dir={str(fmu_dir)!r}, "
        "estimate=False)\n"
        f"build_fmu('DcServoMotor', Path({str(tmp_path / 'after_run')!r}))\n")
    done = fresh_python.run(script, timeout=120)
    assert done.returncode == 0, done.stderr[-3000:]
    built = tmp_path / "after_run" / "DcServoMotor.fmu"
    with zipfile.ZipFile(built) as z:
        assert "binaries/linux64/DcServoMotor.so" in z.namelist() or sys.platform != "linux"
    assert built.read_bytes() == build_fmu("DcServoMotor", tmp_path / "fresh").read_bytes()


@pytest.mark.parametrize("version", [2, 3])
def test_an_fmu_bundles_the_runtime_and_its_model_folder_only(fmu_dir, fmi3_dir, version):
    """StephensonPress.fmu: runtime/ and models/stephenson_press/, nothing of the catalog, the
    other models, the analyses or the runner (they would be dead weight and rebuild causes);
    of the two FMI adapters only its own version's (the other's library is not in the FMU)."""
    from crankfmu.fmu.build import PACKAGE_DIR
    folder = fmu_dir if version == 2 else fmi3_dir
    with zipfile.ZipFile(folder / "StephensonPress.fmu") as z:
        bundled = {n.split("/", 2)[2] for n in z.namelist()
                   if n.startswith("resources/crankfmu_rt_") and n.endswith(".py")}
    expected = {p.relative_to(PACKAGE_DIR).as_posix() for folder in ("runtime",
                "models/stephenson_press") for p in (PACKAGE_DIR / folder).glob("*.py")}
    other = {2: "runtime/slave3.py", 3: "runtime/slave.py"}[version]
    assert bundled == (expected - {other}) | {"__init__.py", "models/__init__.py"}


@pytest.mark.parametrize("edited", ["dc_motor.py", "README.md"])
def test_an_edit_to_one_model_changes_only_its_build_id(tmp_path, monkeypatch, edited):
    """Per-model digests: a copy of the sources with the DC motor's code or its model card (which
    the FMU carries as documentation/index.html) edited gives DcServoMotor a new build id and
    leaves StephensonPress's as it was."""
    import shutil

    from crankfmu.fmu import build
    copy = tmp_path / "crankfmu"
    shutil.copytree(build.PACKAGE_DIR, copy, ignore=shutil.ignore_patterns("__pycache__"))
    motor = copy / "models" / "dc_motor" / edited
    motor.write_text(motor.read_text() + "\n# an edit\n")
    before = {m: build.digest_of(build.catalog_sources(m))
              for m in ("DcServoMotor", "StephensonPress")}
    monkeypatch.setattr(build, "PACKAGE_DIR", copy)
    after = {m: build.digest_of(build.catalog_sources(m))
             for m in ("DcServoMotor", "StephensonPress")}
    assert after["DcServoMotor"] != before["DcServoMotor"]
    assert after["StephensonPress"] == before["StephensonPress"]


# -- cached catalog FMUs (issue #27) -------------------------------------------------------------
def _run_servo_press(fmus: Path, scene: Path = SERVO_PRESS) -> subprocess.CompletedProcess:
    """`crankfmu run` of `scene` in a fresh interpreter (tests/support/fresh_python.py)."""
    return fresh_python.crankfmu(["run", scene, "--stop-time", "0.002", "--no-estimate",
                                  "--fmus", fmus, "--out", fmus / "run.csv"], timeout=300)


def _truncated(data: bytes) -> bytes:
    return data[:len(data) // 2]


def _without_binaries(data: bytes) -> bytes:
    """What an interrupted build of the old writer could leave: every member but binaries/."""
    out = io.BytesIO()
    with zipfile.ZipFile(io.BytesIO(data)) as src, zipfile.ZipFile(out, "w") as dst:
        for info in src.infolist():
            if not info.filename.startswith("binaries/"):
                dst.writestr(info, src.read(info))
    return out.getvalue()


def test_the_session_catalog_builds_again_what_another_python_built(fmu_dir, tmp_path):
    """The catalog (tests/conftest.py) copies fmus/ where it is current; an FMU there that
    records another builder's python (another environment's, or this interpreter by another
    name, as `crankfmu run` recorded it before launcher.builder_python) is built again: the
    tests check the session's builds. Before, the README's run command followed by its test
    command in one checkout failed three tests on such files."""
    from tests.conftest import _built_elsewhere

    genuine = fmu_dir / "DcServoMotor.fmu"
    assert not _built_elsewhere(genuine)
    other = tmp_path / "DcServoMotor.fmu"
    with zipfile.ZipFile(genuine) as src, zipfile.ZipFile(other, "w") as dst:
        for info in src.infolist():
            data = src.read(info)
            if info.filename.endswith("crankfmu_launcher.txt"):
                data = b"\n".join(b"python = /elsewhere/venv/bin/python3.11"
                                  if line.startswith(b"python =") else line
                                  for line in data.split(b"\n"))
            dst.writestr(info, data)
    assert _built_elsewhere(other)


@pytest.mark.parametrize("fmi", [2, 3])
@pytest.mark.parametrize("damage, words", [
    (_truncated, "damaged: File is not a zip file"),
    (_without_binaries, "incomplete: no binaries/{platform}/DcServoMotor.so"),
])
def test_a_damaged_cached_fmu_is_rebuilt_with_a_notice(fmu_dir, fmi3_dir, tmp_path, damage,
                                                       words, fmi):
    """Before: a truncated DcServoMotor.fmu in the FMU folder was rebuilt with the note
    "sources changed"; one without binaries/ (the build's modelDescription intact) was reused
    and failed with fmpy's raw "Cannot find shared library" and a traceback. Now both are built
    again, with one warning line that says why, and the run completes. The same for the FMI
    3.0 motor in fmus/fmi3/ (a scene with fmi = 3; before the FMI 3.0 build shared the check,
    the truncated file was rebuilt without a notice, and the one without binaries reused and
    refused by fmpy)."""
    for name in ("DcServoMotor", "StephensonPress"):
        shutil.copy(fmu_dir / f"{name}.fmu", tmp_path / f"{name}.fmu")
    scene, motor, genuine = SERVO_PRESS, tmp_path / "DcServoMotor.fmu", fmu_dir / "DcServoMotor.fmu"
    if fmi == 3:
        scene = tmp_path / "servo_press_fmi3.toml"
        scene.write_text(SERVO_PRESS.read_text().replace('fmu = "DcServoMotor"',
                                                         'fmu = "DcServoMotor"\nfmi = 3'))
        motor, genuine = tmp_path / "fmi3" / "DcServoMotor.fmu", fmi3_dir / "DcServoMotor.fmu"
        motor.parent.mkdir()
    motor.write_bytes(damage(genuine.read_bytes()))
    done = _run_servo_press(tmp_path, scene)
    assert done.returncode == 0, done.stderr[-3000:]
    notices = [line for line in done.stderr.splitlines() if "DcServoMotor.fmu" in line]
    words = words.format(platform={2: "linux64", 3: "x86_64-linux"}[fmi])
    assert len(notices) == 1 and notices[0].startswith("warning: building") \
        and words in notices[0] and str(motor) in notices[0], done.stderr
    assert "StephensonPress" not in done.stderr  # the whole one is used as it is
    assert motor.read_bytes() == genuine.read_bytes()


def test_a_cached_fmu_of_other_sources_is_rebuilt_quietly_and_a_whole_one_used(fmu_dir,
                                                                               tmp_path):
    from crankfmu.fmu.build import current_build_id, rebuild_reason
    whole = fmu_dir / "DcServoMotor.fmu"
    assert rebuild_reason(whole, "DcServoMotor") is None
    assert rebuild_reason(tmp_path / "none.fmu", "DcServoMotor").reason == "FMU missing"
    stale = shutil.copy(fmu_dir / "StephensonPress.fmu", tmp_path / "DcServoMotor.fmu")
    other = rebuild_reason(Path(stale), "DcServoMotor")  # another model's build id
    assert (other.reason, other.damaged) == ("sources changed", False)
    assert current_build_id("DcServoMotor") != current_build_id("StephensonPress")


def test_an_interrupted_build_leaves_the_earlier_file_and_no_part(fmu_dir, tmp_path,
                                                                  monkeypatch):
    """Before: the build wrote its zip in place, so Ctrl-C (or a crash) during the write left
    half an FMU under the final name. Now it writes a temporary file beside it and renames."""
    from crankfmu.fmu import build
    target = shutil.copy(fmu_dir / "DcServoMotor.fmu", tmp_path / "DcServoMotor.fmu")
    before = Path(target).read_bytes()
    written = []
    original = zipfile.ZipFile.writestr

    def interrupted(self, info, data, *args, **kwargs):
        written.append(info)
        if len(written) == 5:
            raise KeyboardInterrupt
        return original(self, info, data, *args, **kwargs)
    monkeypatch.setattr(zipfile.ZipFile, "writestr", interrupted)
    with pytest.raises(KeyboardInterrupt):
        build.build_fmu("DcServoMotor", tmp_path)
    assert len(written) == 5  # the write was under way
    assert sorted(p.name for p in tmp_path.iterdir()) == ["DcServoMotor.fmu"]
    assert Path(target).read_bytes() == before


@pytest.mark.parametrize("fmi", [2, 3])
def test_the_bundled_code_loads_from_its_bytecode_without_compiling(fmu_dir, fmi3_dir, fmi):
    """Before: every load compiled the FMU's bundled sources (no bytecode in the FMU; a fresh
    folder per process). Now the FMU carries checked-hash pycs of its package, entry script and
    pythonfmu (FMI 3.0: pythonfmu3), used even where bytecode is not written
    (PYTHONDONTWRITEBYTECODE)."""
    fmu = (fmu_dir if fmi == 2 else fmi3_dir) / "StephensonPress.fmu"
    script = (
        "import importlib._bootstrap_external as ext, sys\n"
        "compiled = []\n"
        "original = ext.SourceLoader.source_to_code\n"
        "def recorded(self, data, path, *, _optimize=-1):\n"
        "    compiled.append(str(path))\n"
        "    return original(self, data, path, _optimize=_optimize)\n"
        "ext.SourceLoader.source_to_code = recorded\n"
        "from crankfmu.fmu.instance3 import open_fmu\n"
        f"fmu = open_fmu('m', {str(fmu)!r})\n"
        "fmu.instantiate()\n"
        "fmu.terminate()\n"
        "bundled = [p for p in compiled if fmu.unzip_dir in p]\n"
        "loaded = [m for m in sys.modules if m.startswith(('crankfmu_rt_', 'crankfmu_'))\n"
        "          and getattr(sys.modules[m], '__file__', '').startswith(fmu.unzip_dir)]\n"
        "print(len(loaded), bundled)\n")
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                          timeout=120, env={**os.environ, "PYTHONDONTWRITEBYTECODE": "1"})
    assert done.returncode == 0, done.stderr[-2000:]
    count, bundled = done.stdout.split(maxsplit=1)
    assert int(count) >= 8 and bundled.strip() == "[]", done.stdout
