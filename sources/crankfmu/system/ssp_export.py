"""Write a scene as an SSP 1.0 archive: SystemStructure.ssd + the FMUs in resources/.

What goes where (docs/ssp.md has the full table):
- each component -> ssd:Component (application/x-fmu-sharedlibrary, resources/<Model>.fmu) with
  ssd:Connectors for its connected and recorded variables, scene parameters and effect_ flags;
- [[connections]] -> ssd:Connections;
- parameters, every effect_<name> Boolean (on or off, as crankfmu sets them all) and the start
  values of the scene's constant [inputs] -> one inline ssv:ParameterSet per component. SSP binds
  parameter values to FMU variables by name, so unconnected inputs get no connector: fmpy's SSP
  runner overwrites every input connector with its connection value (0 when unconnected) each step;
- start/stop time -> ssd:DefaultExperiment; the master settings, record list and input time tables
  -> an annotation of type `org.crankfmu.scene` there (plus the step as libcosim's OSP annotation).
"""
from __future__ import annotations

import io
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import cast

from lxml import etree

from ..version import __version__
from ..errors import MAX_STEPS
from ..fmu.instance3 import value_type
from ..outputs import atomic_write
from ..fmu.units import base_unit_attributes
from .scene import Scene
from ..runtime.slave import DEFAULT_TOLERANCE

NS = {
    "ssd": "http://ssp-standard.org/SSP1/SystemStructureDescription",
    "ssc": "http://ssp-standard.org/SSP1/SystemStructureCommon",
    "ssv": "http://ssp-standard.org/SSP1/SystemStructureParameterValues",
    "osp": "http://opensimulationplatform.com/SSP/OSPAnnotations",
    "crankfmu": "urn:crankfmu:ssp:1",
}
SSD_NAME = "SystemStructure.ssd"
FMU_TYPE = "application/x-fmu-sharedlibrary"
PARAMETER_SET_TYPE = "application/x-ssp-parameter-set"
SCENE_ANNOTATION = "org.crankfmu.scene"
OSP_ANNOTATION = "com.opensimulationplatform"
ZIP_DATE = (1980, 1, 1, 0, 0, 0)  # fixed timestamps: the same scene gives the same bytes
CAUSALITY_KIND = {"input": "input", "output": "output", "parameter": "parameter"}


def q(prefix: str, tag: str) -> str:
    """Clark name {namespace}tag for lxml."""
    return f"{{{NS[prefix]}}}{tag}"


def number(x: float) -> str:
    """repr of a float: xs:double text that reads back to the same bits."""
    return repr(float(x))


@dataclass
class DescribedFmu:
    """What the wiring checks need of an FMU, from its model description only (no library load)."""

    name: str
    path: Path
    variables: dict


def describe_fmus(scene: Scene, fmu_dir: Path) -> dict[str, DescribedFmu]:
    from fmpy import read_model_description

    from .wiring import resolve_fmu
    fmus = {}
    for name in scene.components:
        path = resolve_fmu(scene, name, fmu_dir)
        md = read_model_description(str(path))
        fmus[name] = DescribedFmu(name, path, {v.name: v for v in md.modelVariables})
    return fmus


def export_ssp(scene: Scene, path, fmu_dir=None) -> Path:
    """Write `scene` as the SSP archive `path` (FMUs built or taken from `fmu_dir`, default as
    for `crankfmu run`); the scene is checked against the FMUs first. Returns the path."""
    from .wiring import check_components, check_links, default_fmu_dir

    path = Path(path)
    fmus = describe_fmus(scene, Path(fmu_dir) if fmu_dir else default_fmu_dir(scene))
    loaded = cast(dict, fmus)  # a DescribedFmu offers what the checks read of an FmuInstance
    check_components(scene, loaded)
    check_links(scene, loaded)
    sources = resource_names(scene, fmus)
    ssd = ssd_document(scene, fmus, sources)
    write_archive(path, ssd, {sources[c]: fmus[c].path for c in scene.components})
    return path


def lossy_parts(scene: Scene, fmus: dict[str, DescribedFmu]) -> list[str]:
    """What other SSP tools will not see of this scene (crankfmu reads it all back)."""
    m = scene.master
    coupling = f"taylor {m.taylor}" if m.taylor else f"extrapolation {m.extrapolation}"
    notes = [f"master settings (algorithm {m.algorithm}, {coupling}, order) are in the "
             f"{SCENE_ANNOTATION} annotation; "
             "other tools use their own master (libcosim takes the step from the OSP annotation)"]
    if scene.master.fmu_tolerance != DEFAULT_TOLERANCE:
        notes.append(f"fmu_tolerance {scene.master.fmu_tolerance:g}: other tools give the FMUs no "
                     f"tolerance, so they use their default {DEFAULT_TOLERANCE:g}")
    notes += [f"input {s.target} is a time table: other tools hold it at its start value "
              f"{s.value_at(scene.start_time):g}; the table is in the {SCENE_ANNOTATION} annotation"
              for s in scene.inputs.values() if len(s.times) > 1]
    if "analysis" in scene.raw:  # ([swap] is resolved when the scene loads: nothing lost)
        notes.append("[analysis] (roles for `crankfmu compare`) is not exported")
    for comp, fmu in fmus.items():
        for name in connector_names(scene, comp, fmu) + list(bound_values(scene, comp, fmu)):
            var = fmu.variables[name]
            if value_type(var) == "Real" and var.unit and not _unit(var):
                notes.append(f"{comp}.{name} is in {var.unit}, which SSP cannot declare (base-unit "
                             "exponents must be integers): written without a unit")
    return list(dict.fromkeys(notes))


def resource_names(scene: Scene, fmus: dict[str, DescribedFmu]) -> dict[str, str]:
    """resources/<file name> per component; a different file with a taken name gets the
    component name in front."""
    taken: dict[str, Path] = {}
    names = {}
    for comp, fmu in fmus.items():
        name = f"resources/{fmu.path.name}"
        if name in taken and taken[name].resolve() != fmu.path.resolve():
            name = f"resources/{comp}_{fmu.path.name}"
        taken[name] = fmu.path
        names[comp] = name
    return names


def ssd_document(scene: Scene, fmus: dict[str, DescribedFmu], sources: dict[str, str]) -> bytes:
    root = etree.Element(q("ssd", "SystemStructureDescription"),
                         # osp declared here: libcosim reads any attribute of osp:Algorithm
                         # (an xmlns one too) as an algorithm and fails on it
                         nsmap={k: NS[k] for k in ("ssd", "ssc", "ssv", "osp")},
                         version="1.0", name=scene.name,
                         generationTool=f"crankfmu {__version__}")
    system = etree.SubElement(root, q("ssd", "System"), name=scene.name)
    if scene.description:
        system.set("description", scene.description)
    elements = etree.SubElement(system, q("ssd", "Elements"))
    units: set[str] = set()
    for comp in scene.components:
        _component(elements, scene, comp, fmus[comp], sources[comp], units)
    if scene.connections:
        connections = etree.SubElement(system, q("ssd", "Connections"))
        for c in scene.connections:
            (src, src_var), (dst, dst_var) = c.source.split(".", 1), c.target.split(".", 1)
            etree.SubElement(connections, q("ssd", "Connection"), startElement=src,
                             startConnector=src_var, endElement=dst, endConnector=dst_var)
    if units:
        _units(root, "ssd", units)
    _default_experiment(root, scene)
    etree.indent(root)
    return etree.tostring(root, xml_declaration=True, encoding="UTF-8") + b"\n"


def _unit(var) -> str | None:
    """The variable's unit if SSP can declare it (integer base-unit exponents), else None."""
    return var.unit if var.unit and base_unit_attributes(var.unit) is not None else None


def _units(parent, prefix: str, units: set[str]) -> None:
    node = etree.SubElement(parent, q(prefix, "Units"))
    for unit in sorted(units):
        u = etree.SubElement(node, q("ssc", "Unit"), name=unit)
        etree.SubElement(u, q("ssc", "BaseUnit"), base_unit_attributes(unit))


def connector_names(scene: Scene, comp: str, fmu: DescribedFmu) -> list[str]:
    """Connected inputs and outputs, recorded outputs, scene parameters, all effect_ flags."""
    names = [c.target.split(".", 1)[1] for c in scene.connections if c.target_component == comp]
    names += [c.source.split(".", 1)[1] for c in scene.connections if c.source_component == comp]
    names += [r.split(".", 1)[1] for r in scene.record if r.split(".", 1)[0] == comp
              and fmu.variables[r.split(".", 1)[1]].causality == "output"]
    names += list(scene.components[comp].parameters)
    names += [v for v in fmu.variables if v.startswith("effect_")]
    return list(dict.fromkeys(names))


def bound_values(scene: Scene, comp: str, fmu: DescribedFmu) -> dict[str, float | bool]:
    """Start values crankfmu sets before initialization: scene parameters, every effect flag,
    and the constant (or, lossy for other tools, the initial) value of unconnected inputs."""
    component = scene.components[comp]
    values: dict[str, float | bool] = {v: v[len("effect_"):] in component.effects
                                       for v in fmu.variables if v.startswith("effect_")}
    values.update(component.parameters)
    for signal in scene.inputs.values():
        target_comp, var = signal.target.split(".", 1)
        if target_comp == comp:
            values[var] = signal.value_at(scene.start_time)
    return values


def _component(elements, scene: Scene, comp: str, fmu: DescribedFmu, source: str,
               units: set[str]) -> None:
    node = etree.SubElement(elements, q("ssd", "Component"), name=comp, type=FMU_TYPE,
                            source=source)
    connectors = etree.SubElement(node, q("ssd", "Connectors"))
    for name in connector_names(scene, comp, fmu):
        var = fmu.variables[name]
        attrs = {"name": name, "kind": CAUSALITY_KIND[var.causality]}
        if var.description:
            attrs["description"] = var.description
        c = etree.SubElement(connectors, q("ssd", "Connector"), attrs)
        unit = _unit(var)
        kind = value_type(var)  # SSP 1.0 knows Real, as FMI 2.0 (FMI 3.0: Float64)
        if kind == "Real" and unit:
            units.add(unit)
        etree.SubElement(c, q("ssc", kind), {"unit": unit} if kind == "Real" and unit else {})
    bindings = etree.SubElement(node, q("ssd", "ParameterBindings"))
    binding = etree.SubElement(bindings, q("ssd", "ParameterBinding"), type=PARAMETER_SET_TYPE)
    values = etree.SubElement(binding, q("ssd", "ParameterValues"))
    _parameter_set(values, scene.name, fmu, bound_values(scene, comp, fmu))


def _parameter_set(parent, set_name: str, fmu: DescribedFmu, values: dict) -> None:
    pset = etree.SubElement(parent, q("ssv", "ParameterSet"), version="1.0", name=set_name)
    params = etree.SubElement(pset, q("ssv", "Parameters"))
    units = set()
    for name, value in values.items():
        var = fmu.variables[name]
        p = etree.SubElement(params, q("ssv", "Parameter"), name=name)
        if var.type == "Boolean":
            etree.SubElement(p, q("ssv", "Boolean"), value="true" if value else "false")
            continue
        attrs = {"value": number(value)}
        unit = _unit(var)
        if unit:
            attrs["unit"] = unit
            units.add(unit)
        etree.SubElement(p, q("ssv", "Real"), attrs)
    if units:  # a parameter's unit references the Units of its enclosing parameter set
        _units(pset, "ssv", units)


def _default_experiment(root, scene: Scene) -> None:
    experiment = etree.SubElement(root, q("ssd", "DefaultExperiment"),
                                  startTime=number(scene.start_time),
                                  stopTime=number(scene.stop_time))
    annotations = etree.SubElement(experiment, q("ssd", "Annotations"))
    crank = etree.SubElement(annotations, q("ssc", "Annotation"), type=SCENE_ANNOTATION)
    crank.append(scene_annotation(scene))
    osp = etree.SubElement(annotations, q("ssc", "Annotation"), type=OSP_ANNOTATION)
    algorithm = etree.SubElement(osp, q("osp", "Algorithm"))
    etree.SubElement(algorithm, q("osp", "FixedStepAlgorithm"),
                     baseStepSize=number(scene.master.step))


def _master_attributes(m) -> dict:
    """algorithm, step, fmu_tolerance and the chosen master's own options (its declaration)."""
    values = m.resolved()
    out = {"algorithm": m.algorithm, "step": number(m.step)}
    for key, value in values.items():
        if key not in ("algorithm", "step", "fmu_tolerance", "max_steps", "order"):
            out[key] = str(value) if isinstance(value, int) else number(value)
    out["fmu_tolerance"] = number(m.fmu_tolerance)
    return out


def scene_annotation(scene: Scene):
    """<crankfmu:Scene>: master settings, record list and input tables, read back by load_ssp."""
    m = scene.master
    node = etree.Element(q("crankfmu", "Scene"), nsmap={"crankfmu": NS["crankfmu"]})
    master = etree.SubElement(node, q("crankfmu", "Master"), _master_attributes(m))
    if m.max_steps != MAX_STEPS:  # only when raised or lowered: default files stay as they were
        master.set("max_steps", str(m.max_steps))
    for name in m.order:
        etree.SubElement(master, q("crankfmu", "Order"), component=name)
    record = etree.SubElement(node, q("crankfmu", "Record"))
    if scene.record_interval is not None:
        record.set("interval", number(scene.record_interval))
    for ref in scene.record:
        etree.SubElement(record, q("crankfmu", "Variable"), name=ref)
    for signal in scene.inputs.values():
        if len(signal.times) > 1:
            table = etree.SubElement(node, q("crankfmu", "InputTable"), target=signal.target,
                                     interpolation=signal.interpolation)
            for t, v in zip(signal.times, signal.values):
                etree.SubElement(table, q("crankfmu", "Point"), time=number(t), value=number(v))
    return node


def write_archive(path: Path, ssd: bytes, resources: dict[str, Path]) -> None:
    """The zip, built in memory and written through crankfmu.outputs.atomic_write: a reader
    never sees half a file, and a name that is not a regular file is never replaced."""
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w") as zf:
        zf.writestr(zipfile.ZipInfo(SSD_NAME, ZIP_DATE), ssd, zipfile.ZIP_DEFLATED)
        for name in sorted(resources):  # FMUs are zips already: stored, not recompressed
            zf.writestr(zipfile.ZipInfo(name, ZIP_DATE), resources[name].read_bytes(),
                        zipfile.ZIP_STORED)
    atomic_write(path, lambda f: f.write(buffer.getvalue()))


def fmpy_parameter_set(ssp_path):
    """The SSD's parameter bindings as one fmpy ParameterSet for fmpy.ssp.simulate_ssp, which
    ignores the bindings in the file: names "component.variable", values as Python float/bool
    (fmpy sets a Boolean as `value != 0.0`, so the text "false" would become true)."""
    from fmpy.ssp.ssd import Parameter, ParameterSet, find_components, read_ssd

    ssd = read_ssd(str(ssp_path))
    merged = ParameterSet(name="crankfmu")
    for component in find_components(ssd.system):
        for binding in component.parameterBindings:
            for pset in binding.parameterValues:
                for p in pset.parameters:
                    value = p.value in ("true", "1") if p.type == "Boolean" else float(p.value)
                    merged.parameters.append(Parameter(name=f"{component.name}.{p.name}",
                                                       type=p.type, value=value))
    return merged
