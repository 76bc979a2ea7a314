"""A scene (or one FMU alone) as engine-neutral facts: FMU paths, start values, links, recording.

The adapters for other engines (libcosim.py, ecos.py) consume a `Plan`, so what a scene means
(which effects are on, which values are set before initialization, what is recorded) is decided
once, here, exactly as crankfmu's runner decides it:
- every `effect_<name>` switch of a component is set, True iff the scene lists the effect (an
  effect the scene does not list is off, whatever the FMU's default);
- parameters and constant [inputs] are start values, set before the first doStep;
- names are checked with crankfmu's own checks (`cosim.wiring`) against the model descriptions,
  so a bad scene fails with the same message in every engine.

Limits, each failing with a clear error: time-table inputs (the adapters set constants only), and
an `[master].fmu_tolerance` other than the FMUs' default (libcosim and ecos call
fmi2SetupExperiment without a tolerance, so each FMU uses its DefaultExperiment tolerance).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
from fmpy import read_model_description

from ..system.wiring import check_components, check_links, resolve_fmu
from ..system.scene import Scene, SceneError


@dataclass
class ComponentPlan:
    name: str
    path: Path
    variables: dict  # name -> fmpy ScalarVariable
    start_values: dict[str, float | bool] = field(default_factory=dict)
    default_tolerance: float | None = None

    def typed(self, name: str, value):
        """`value` as the variable's FMI type (TOML gives ints for whole numbers)."""
        kind = self.variables[name].type
        if kind == "Boolean":
            return bool(value)
        if kind == "Real":
            return float(value)
        raise ValueError(f"{self.name}.{name} is an FMI {kind}; the adapters set Real and "
                         "Boolean variables only")


@dataclass
class Plan:
    name: str
    components: dict[str, ComponentPlan]
    links: list[tuple[str, str, str, str]]  # (source comp, source var, target comp, target var)
    record: list[str]                       # "comp.var", Real variables
    start_time: float
    step: float
    n_steps: int
    record_every: int = 1                   # record every n-th communication point

    @property
    def stop_time(self) -> float:
        return self.start_time + self.n_steps * self.step

    def sample_steps(self) -> np.ndarray:
        """The communication points (0 .. n_steps) that are recorded, as crankfmu's runner
        records them: the start, every `record_every`-th step, and the last."""
        k = np.arange(0, self.n_steps + 1, self.record_every)
        return k if k[-1] == self.n_steps else np.append(k, self.n_steps)


@dataclass
class PeerResult:
    """Time series from one engine: `times` [s] and one column per recorded variable."""

    engine: str
    times: np.ndarray
    columns: dict[str, np.ndarray]
    wall_seconds: float  # loading, initialization and stepping (not reading the recording out)
    steps: int

    def column(self, name: str) -> np.ndarray:
        return self.columns[name]


def _description(name: str, path: Path) -> SimpleNamespace:
    """The attributes crankfmu's wiring checks read from an FmuInstance, from the XML alone
    (no binary is loaded)."""
    md = read_model_description(str(path))
    return SimpleNamespace(name=name, path=path, model_description=md,
                           variables={v.name: v for v in md.modelVariables})


def _n_steps(t0: float, stop: float, h: float) -> int:
    return max(1, math.ceil((stop - t0) / h - 1e-9))  # as cosim/runner.py


def plan_scene(scene: Scene, fmu_dir: Path, stop_time: float | None = None) -> Plan:
    """Check `scene` against its FMUs (built into `fmu_dir` when missing) and plan it. The
    scene's [master] algorithm and extrapolation do not apply: the engines run their own
    fixed-step Jacobi scheme with inputs held over each step (crankfmu's jacobi master at
    extrapolation 0 is the same algorithm)."""
    # stand-ins for FmuInstance: the attributes the wiring's checks read (_description)
    descs: dict[str, Any] = {name: _description(name, resolve_fmu(scene, name, Path(fmu_dir)))
                             for name in scene.components}
    check_components(scene, descs)
    links = check_links(scene, descs)
    comps = {name: _component_plan(descs[name], comp.effects, comp.parameters)
             for name, comp in scene.components.items()}
    _add_constant_inputs(scene, comps)
    _check_tolerance(scene, comps)
    _check_parameters(scene, descs)
    h, t0 = scene.master.step, scene.start_time
    stop = scene.stop_time if stop_time is None else stop_time
    return Plan(scene.name, comps, [(l.source, l.source_var, l.target, l.target_var) for l in links],
                [r for r in scene.record if _is_real(comps, r)], t0, h, _n_steps(t0, stop, h),
                max(1, round((scene.record_interval or h) / h)))


def _component_plan(desc, effects: list[str], parameters: dict) -> ComponentPlan:
    """Every effect switch set (on iff listed, as crankfmu's runner does), then parameters."""
    switches = {v: v[len("effect_"):] in effects for v in desc.variables if v.startswith("effect_")}
    de = desc.model_description.defaultExperiment
    plan = ComponentPlan(desc.name, desc.path, desc.variables,
                         default_tolerance=None if de is None or de.tolerance is None
                         else float(de.tolerance))
    plan.start_values = {k: plan.typed(k, v) for k, v in {**switches, **parameters}.items()}
    return plan


def _add_constant_inputs(scene: Scene, comps: dict[str, ComponentPlan]) -> None:
    for target, signal in scene.inputs.items():
        if len(signal.times) > 1:
            raise SceneError(scene.path, f"[inputs].\"{target}\"", "the libcosim and ecos "
                             "adapters set constant inputs only, not time tables")
        comp, var = target.split(".", 1)
        comps[comp].start_values[var] = comps[comp].typed(var, signal.values[0])


def _check_parameters(scene: Scene, descs: dict) -> None:
    """Impossible parameters of catalog FMUs, refused here with the physics' own message:
    inside libcosim an FMU's failed initialization kills the whole process (measured: libcosim
    aborts on an uncaught C++ exception, for fmi2Fatal and for the launcher's fmi2Error alike),
    and ecos used to segfault on it (now it runs on with a failed instance)."""
    from ..runtime.model import ParameterError
    from ..models.catalog import FMU_MODELS, make_physics
    for name, comp in scene.components.items():
        model = descs[name].model_description.modelName
        if model not in FMU_MODELS:
            continue
        try:
            make_physics(model, comp.parameters, comp.effects)
        except ParameterError as err:
            raise SceneError(scene.path, f"[components.{name}].parameters", str(err)) from None


def _is_real(comps: dict[str, ComponentPlan], ref: str) -> bool:
    comp, var = ref.split(".", 1)
    return comps[comp].variables[var].type == "Real"


def _check_tolerance(scene: Scene, comps: dict[str, ComponentPlan]) -> None:
    """libcosim and ecos give no tolerance to fmi2SetupExperiment; the FMU then integrates with
    its DefaultExperiment tolerance. A scene asking for another one would silently differ."""
    wanted = scene.master.fmu_tolerance
    for name, comp in comps.items():
        if comp.default_tolerance is not None and not math.isclose(comp.default_tolerance, wanted,
                                                                   rel_tol=1e-12):
            raise SceneError(scene.path, "[master].fmu_tolerance",
                             f"{wanted:g} differs from {name}'s default tolerance "
                             f"{comp.default_tolerance:g}: libcosim and ecos call "
                             "fmi2SetupExperiment without a tolerance, so the FMU would use "
                             f"{comp.default_tolerance:g}; set fmu_tolerance = "
                             f"{comp.default_tolerance:g} to compare")


def plan_single_fmu(path: Path, stop_time: float = 0.1, step: float = 1e-3,
                    name: str = "fmu") -> Plan:
    """One FMU alone on its start values (no input connected, nothing set): records every
    output."""
    d = _description(name, Path(path))
    comp = ComponentPlan(name, d.path, d.variables)
    outputs = [f"{name}.{v}" for v, var in d.variables.items()
               if var.causality == "output" and var.type == "Real"]
    return Plan(d.model_description.modelName, {name: comp}, [], outputs, 0.0, step,
                _n_steps(0.0, stop_time, step))
