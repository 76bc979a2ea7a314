"""The build: valid FMUs with units and a model card, and the same bytes from the same sources."""
from __future__ import annotations

import html
import zipfile

import pytest
from fmpy import read_model_description

from crankfmu.fmu.build import build_fmu, validate

MODELS = ("DcServoMotor", "StephensonPress")


def test_every_fmu_passes_fmpy_validate(fmu_dir):
    for name in MODELS:
        assert validate(fmu_dir / f"{name}.fmu") == []


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


def test_an_edit_to_one_model_changes_only_its_build_id(tmp_path, monkeypatch):
    """Per-model digests: a copy of the sources with dc_motor.py edited gives DcServoMotor a new
    build id and leaves StephensonPress's as it was."""
    import shutil

    from crankfmu.fmu import build
    copy = tmp_path / "crankfmu"
    shutil.copytree(build.PACKAGE_DIR, copy, ignore=shutil.ignore_patterns("__pycache__"))
    motor = copy / "models" / "dc_motor" / "dc_motor.py"
    motor.write_text(motor.read_text() + "# an edit\n")
    before = {m: build.sources_digest(build.runtime_files(m))
              for m in ("DcServoMotor", "StephensonPress")}
    monkeypatch.setattr(build, "PACKAGE_DIR", copy)
    after = {m: build.sources_digest(build.runtime_files(m))
             for m in ("DcServoMotor", "StephensonPress")}
    assert after["DcServoMotor"] != before["DcServoMotor"]
    assert after["StephensonPress"] == before["StephensonPress"]
