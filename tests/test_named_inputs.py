"""Named input access: every physics model reads its inputs by name (`u[self.IN.flange_w]`),
through the tables IN/OUT that PhysicsModel derives from each class's declarations.

The decisive check: a subclass that declares the same inputs in REVERSED order, fed the same
values in that order, must compute bit-identical derivatives, outputs, event functions and
steps. A model that still read an input by position (`u[2]`) would read another input there
and differ. Tolerance: none (the same floating-point operations on the same values)."""
from __future__ import annotations

import math

import pytest

from crankfmu.models.catalog import FMU_MODELS, physics_class
from crankfmu.runtime.model import ParameterError, PhysicsModel, Variable, held

RTOL = 1e-8
STEP_S = 1e-3


@pytest.mark.parametrize("name", sorted(FMU_MODELS))
def test_index_tables_follow_the_declarations(name):
    cls = physics_class(name)
    assert cls.IN._fields == tuple(v.name for v in cls.inputs)
    assert list(cls.IN) == list(range(len(cls.inputs)))
    assert cls.OUT._fields == tuple(v.name for v in cls.outputs)
    assert list(cls.OUT) == list(range(len(cls.outputs)))
    for v in cls.inputs:
        assert getattr(cls.IN, v.name) == cls().input_index(v.name)


def test_a_subclass_with_other_inputs_gets_its_own_table():
    """CrankRockerHammer extends RockerImpact's inputs: each class has the table of its own
    declaration, and the shared methods of RockerImpact read the subclass's."""
    rocker, hammer = physics_class("RockerImpact"), physics_class("CrankRockerHammer")
    assert "shaft_w" in hammer.IN._fields and "shaft_w" not in rocker.IN._fields
    assert rocker.IN.flange_J == hammer.IN.flange_J == 1


@pytest.mark.parametrize("bad", [("a.b",), ("_hidden",), ("lambda",), ("w", "w")])
def test_an_input_name_that_cannot_be_an_attribute_is_refused(bad):
    with pytest.raises(TypeError, match=f"Broken: input {bad[-1]!r} must be a unique"):
        type("Broken", (PhysicsModel,), {"inputs": tuple(Variable(n, "1", "") for n in bad)})


def _input_values(cls) -> dict[str, float]:
    """Distinct values inside each input's range (a swapped read cannot go unnoticed)."""
    values = {}
    for i, v in enumerate(cls.inputs):
        x = v.start + 0.37 * (i + 1)
        x = x if v.max is None else min(x, v.max)
        values[v.name] = x if v.min is None else max(x, v.min)
    return values


def _effect_sets(cls) -> list:
    """The defaults, each effect alone, and all together (a combination a model refuses is
    compared as the error type)."""
    every = [[e.name for e in cls.effects]] if len(cls.effects) > 1 else []
    return [None] + [[e.name] for e in cls.effects] + every


def _run(cls, effects, values: dict):
    """What a host sees of the model over one step, as plain numbers; or the error type."""
    try:
        model = cls(effects=effects)
        u = [values[v.name] for v in cls.inputs]
        x0 = list(model.initial_state(u))
    except (ParameterError, ValueError) as err:
        return type(err).__name__
    out = {"x0": x0, "y0": list(model.output_values(0.0, x0, u))}
    if x0:
        out["dx"] = list(model.derivatives(0.0, x0, u))
    model.restart_state = x0  # as advance sets it before asking for the event functions
    out["g"] = [g(0.0, x0) for g in model.event_functions(held(u))]
    atol = [RTOL * v for v in model.state_nominal()]
    x1 = list(model.step(0.0, x0, STEP_S, held(u), RTOL, atol))
    out["x1"] = x1
    out["y1"] = list(model.output_values(STEP_S, x1, u))
    out["discrete"] = model.discrete_state()
    return out


def _same(a, b) -> bool:
    if isinstance(a, dict):
        return a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, list):
        return len(a) == len(b) and all(_same(p, q) for p, q in zip(a, b))
    if isinstance(a, float) and math.isnan(a):
        return isinstance(b, float) and math.isnan(b)
    return a == b


@pytest.mark.parametrize("name", sorted(FMU_MODELS))
def test_models_read_inputs_by_name_not_position(name):
    cls = physics_class(name)
    if len(cls.inputs) < 2:
        pytest.skip("one input: every order is the same")
    reversed_cls = type(cls.__name__, (cls,), {"inputs": tuple(reversed(cls.inputs))})
    assert reversed_cls.IN._fields == tuple(reversed(cls.IN._fields))
    values = _input_values(cls)
    ran = 0
    for effects in _effect_sets(cls):
        expected = _run(cls, effects, values)
        got = _run(reversed_cls, effects, values)
        assert _same(expected, got), (name, effects)
        ran += not isinstance(expected, str)
    assert ran >= 1  # at least the default effects ran through a step


@pytest.mark.parametrize("name", ["PlanetaryClutchDrive", "MillStandDrive", "RockerImpact",
                                  "CrankRockerHammer"])
def test_models_that_name_their_outputs_follow_the_declaration(name):
    """These models build their many outputs by name (output_vector or a dict): declared in
    reversed order, each output keeps its value (exact: the same computation)."""
    cls = physics_class(name)
    reversed_cls = type(cls.__name__, (cls,), {"outputs": tuple(reversed(cls.outputs))})
    values = _input_values(cls)
    u = [values[v.name] for v in cls.inputs]
    model, other = cls(), reversed_cls()
    x0 = list(model.initial_state(u))
    assert list(other.initial_state(u)) == x0
    y, y_reversed = model.output_values(0.0, x0, u), other.output_values(0.0, x0, u)
    assert [y_reversed[other.output_index(v.name)] for v in cls.outputs] == list(y)


def test_output_vector_names_what_is_missing_or_undeclared():
    model = physics_class("PlanetaryClutchDrive")()
    full = {name: 1.0 for name in model.OUT._fields}
    assert model.output_vector(full) == [1.0] * len(full)
    with pytest.raises(KeyError, match=r"PlanetaryClutchDrive: output values missing "
                                       r"\['w_a'\], undeclared \['w_sun'\]"):
        model.output_vector({("w_sun" if k == "w_a" else k): v for k, v in full.items()})
    with pytest.raises(KeyError, match=r"missing \[\], undeclared \['spare'\]"):
        model.output_vector(full | {"spare": 0.0})
