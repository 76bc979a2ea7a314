"""The build: valid FMUs with units and a model card, and the same bytes from the same sources."""
from __future__ import annotations

import html
import zipfile

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
