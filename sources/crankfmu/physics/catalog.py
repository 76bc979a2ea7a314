"""The physics models that are packaged as FMUs: FMU model name -> "module:Class"."""
from __future__ import annotations

import importlib

from .base import SCIPY_SOLVER, PhysicsModel

FMU_MODELS: dict[str, str] = {
    "DcServoMotor": "dc_motor:DcServoMotor",
    "StephensonPress": "stephenson_press:StephensonPress",
    "InductionMotor": "induction_motor:InductionMotor",
    "PlanetaryClutchDrive": "planetary_drive:PlanetaryClutchDrive",
    "RockerImpact": "rocker_impact:RockerImpact",
    "CrankRockerHammer": "crank_rocker:CrankRockerHammer",
    "MillStandDrive": "mill_stand:MillStandDrive",
    "Rotor": "rotor:Rotor",
    "ShaftRotor": "rotor:ShaftRotor",
}


def physics_class(model_name: str):
    """The PhysicsModel subclass behind an FMU model name."""
    try:
        module, cls = FMU_MODELS[model_name].split(":")
    except KeyError:
        raise KeyError(f"no physics model named {model_name!r}; known: {sorted(FMU_MODELS)}")
    return getattr(importlib.import_module(f"{__package__}.{module}"), cls)


def make_physics(model_name: str, parameters: dict, effects) -> PhysicsModel:
    """The physics model behind an FMU, from a scene's parameters and effects: the FMU's solver
    switch (scipy_solver) selects the model's solver instead of being a physics parameter."""
    physics = {k: float(v) for k, v in parameters.items() if k != SCIPY_SOLVER}
    model = physics_class(model_name)(physics, list(effects))
    if parameters.get(SCIPY_SOLVER):
        model.solver = "scipy"
    return model
