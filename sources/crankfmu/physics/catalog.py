"""The physics models that are packaged as FMUs: FMU model name -> "module:Class"."""
from __future__ import annotations

import importlib

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
