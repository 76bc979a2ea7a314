"""The registry of the models packaged as FMUs: FMU model name -> "folder.module:Class".

Adding a model is one folder under models/ (its code and README.md) and one line here. An FMU
bundles the runtime and its model's folder only (fmu/build.py), so a model imports the runtime
and its own folder, never another model's folder."""
from __future__ import annotations

import importlib

from ..runtime.model import SCIPY_SOLVER, PhysicsModel

FMU_MODELS: dict[str, str] = {
    "DcServoMotor": "dc_motor.dc_motor:DcServoMotor",
    "StephensonPress": "stephenson_press.stephenson_press:StephensonPress",
    "InductionMotor": "induction_motor.induction_motor:InductionMotor",
    "PlanetaryClutchDrive": "planetary_drive.planetary_drive:PlanetaryClutchDrive",
    "RockerImpact": "rocker_impact.rocker_impact:RockerImpact",
    "CrankRockerHammer": "rocker_impact.crank_rocker:CrankRockerHammer",
    "MillStandDrive": "mill_stand.mill_stand:MillStandDrive",
    "Rotor": "rotor.rotor:Rotor",
    "ShaftRotor": "rotor.rotor:ShaftRotor",
}

def _entry(model_name: str) -> tuple[str, str]:
    try:
        module, cls = FMU_MODELS[model_name].split(":")
    except KeyError:
        raise KeyError(f"no physics model named {model_name!r}; known: {sorted(FMU_MODELS)}")
    return module, cls


def physics_class(model_name: str):
    """The PhysicsModel subclass behind an FMU model name."""
    module, cls = _entry(model_name)
    return getattr(importlib.import_module(f"{__package__}.{module}"), cls)


def model_folder(model_name: str) -> str:
    """The name of the model's folder under models/: its code and its README.md (the card)."""
    return _entry(model_name)[0].split(".")[0]


def make_physics(model_name: str, parameters: dict, effects) -> PhysicsModel:
    """The physics model behind an FMU, from a scene's parameters and effects: the FMU's solver
    switch (scipy_solver) selects the model's solver instead of being a physics parameter."""
    physics = {k: float(v) for k, v in parameters.items() if k != SCIPY_SOLVER}
    model = physics_class(model_name)(physics, list(effects))
    if parameters.get(SCIPY_SOLVER):
        model.solver = "scipy"
    return model
