"""BaseUnit exponents are derived from the unit string (fmu/units.py), for every unit any FMU
uses: checked on the modelDescription each FMU gets, without building the FMUs."""
from __future__ import annotations

import math
from fractions import Fraction
from xml.etree.ElementTree import fromstring

import pytest

from crankfmu.fmu.model_description import model_description
from crankfmu.fmu.units import UnitError, base_unit_attributes, parse_unit
from crankfmu.models.catalog import FMU_MODELS, physics_class
from crankfmu.runtime.slave import ModelSlave


def _description(model: str):
    slave = type(model, (ModelSlave,), {"physics_class": physics_class(model)})
    return fromstring(model_description(slave, "0" * 12))


@pytest.mark.parametrize("model", list(FMU_MODELS))
def test_every_unit_of_every_fmu_has_a_base_unit(model):
    """Every unit a variable uses is defined, and has a BaseUnit unless its SI exponents are not
    integers (FMI's BaseUnit cannot say N^(2/3)/m); the exponents equal the parsed ones."""
    root = _description(model)
    used = {r.get("unit") for r in root.iter("Real") if r.get("unit")}
    defined = {u.get("name"): u for u in root.find("UnitDefinitions")}
    assert used <= set(defined), f"units used but not defined: {used - set(defined)}"
    for name in sorted(used):
        exps, factor = parse_unit(name)
        base = defined[name].find("BaseUnit")
        if any(e.denominator != 1 for e in exps.values()):
            assert base is None, name
            continue
        assert base is not None, f"{model}: unit {name!r} has no BaseUnit"
        got = {k: int(v) for k, v in base.attrib.items() if k != "factor"}
        assert got == {k: int(e) for k, e in exps.items()}, name
        assert float(base.get("factor", "1")) == pytest.approx(factor, rel=1e-15)


@pytest.mark.parametrize("unit, expected", [
    ("N.m/rad", {"kg": 1, "m": 2, "s": -2, "rad": -1}),
    ("N.s/m", {"kg": 1, "s": -1}),
    ("kg.m2/s", {"kg": 1, "m": 2, "s": -1}),
    ("V/s", {"kg": 1, "m": 2, "s": -4, "A": -1}),
    ("rad/s3", {"rad": 1, "s": -3}),
    ("N.m.s/rad", {"kg": 1, "m": 2, "s": -1, "rad": -1}),
    ("1/s2", {"s": -2}),
    ("1", {}),
    ("ohm", {"kg": 1, "m": 2, "s": -3, "A": -2}),
])
def test_exponents(unit, expected):
    assert {k: str(v) for k, v in expected.items()} == base_unit_attributes(unit)


def test_fractional_factor_and_errors():
    assert parse_unit("N(2/3)/m")[0] == {"kg": Fraction(2, 3), "m": Fraction(-1, 3),
                                         "s": Fraction(-4, 3)}
    assert parse_unit("N/m1.5")[0]["m"] == Fraction(-1, 2)  # N has m1
    assert base_unit_attributes("N(2/3)/m") is None
    assert float(base_unit_attributes("rpm")["factor"]) == 2 * math.pi / 60
    with pytest.raises(UnitError, match="unknown symbol 'furlong'"):
        parse_unit("furlong/s")
    with pytest.raises(UnitError):
        parse_unit("m//s")
