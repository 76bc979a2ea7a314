"""Write a complete, deterministic FMI 2.0 modelDescription.xml for a ModelSlave.

pythonfmu 0.7.0 writes no units, ranges or InitialUnknowns (fmpy validate rejects that) and stamps
a random GUID and the build time (every build differs). This writer produces the whole file from
the physics class, so units, ranges, dependencies and a content-derived GUID are always there.
"""
from __future__ import annotations

from xml.etree.ElementTree import Element, SubElement, indent, tostring

from ..runtime.slave import DEFAULT_TOLERANCE, ModelSlave, variable_table
from .bundle import guid as build_guid
from .units import base_unit_attributes


def _number(x: float) -> str:
    return repr(float(x))


def _variables(root: Element, table) -> None:
    node = SubElement(root, "ModelVariables")
    for vr, var in enumerate(table):
        attrs = {"name": var.name, "valueReference": str(vr), "description": var.description,
                 "causality": var.causality, "variability": var.variability}
        if var.initial:
            attrs["initial"] = var.initial
        sv = SubElement(node, "ScalarVariable", attrs)
        if var.kind == "Boolean":
            SubElement(sv, "Boolean", {"start": str(bool(var.start)).lower()})
            continue
        real = {}
        if var.unit:
            real["unit"] = var.unit
        if var.min is not None:
            real["min"] = _number(var.min)
        if var.max is not None:
            real["max"] = _number(var.max)
        if var.start is not None:
            real["start"] = _number(var.start)
        SubElement(sv, "Real", real)


def _unit_definitions(root: Element, table) -> None:
    units = sorted({v.unit for v in table if v.unit})
    node = SubElement(root, "UnitDefinitions")
    for unit in units:
        u = SubElement(node, "Unit", {"name": unit})
        base = base_unit_attributes(unit)
        if base is not None:  # every unit whose SI exponents are integers (fmu/units.py)
            SubElement(u, "BaseUnit", base)


def _model_structure(root: Element, table) -> None:
    index = {v.name: i + 1 for i, v in enumerate(table)}
    structure = SubElement(root, "ModelStructure")
    outputs = [v for v in table if v.causality == "output"]
    out_node = SubElement(structure, "Outputs")
    for v in outputs:
        deps = " ".join(str(index[d]) for d in v.depends_on)
        SubElement(out_node, "Unknown", {"index": str(index[v.name]), "dependencies": deps})
    init_node = SubElement(structure, "InitialUnknowns")
    for v in outputs:  # depend on all knowns in initialization mode (attribute omitted)
        SubElement(init_node, "Unknown", {"index": str(index[v.name])})


def model_description(slave_class: type[ModelSlave], build_id: str) -> bytes:
    """The modelDescription.xml bytes; `build_id` (a hash of the bundled sources) fixes the
    GUID, so identical sources give an identical file."""
    physics = slave_class.physics_class
    table = variable_table(physics)
    root = Element("fmiModelDescription", {
        "fmiVersion": "2.0", "modelName": physics.model_name,
        "guid": build_guid(physics.model_name, build_id),
        "description": physics.description, "author": "crankfmu",
        "version": build_id, "generationTool": "crankfmu build (pythonfmu 0.7)",
        "variableNamingConvention": "structured", "numberOfEventIndicators": "0"})
    SubElement(root, "CoSimulation", {
        "modelIdentifier": physics.model_name, "needsExecutionTool": "true",
        "canHandleVariableCommunicationStepSize": "true", "canInterpolateInputs": "false",
        "canBeInstantiatedOnlyOncePerProcess": "false", "canNotUseMemoryManagementFunctions":
            "true", "canGetAndSetFMUstate": "true", "canSerializeFMUstate": "true"})
    _unit_definitions(root, table)
    cats = SubElement(root, "LogCategories")
    for name, text in slave_class.log_categories.items():
        SubElement(cats, "Category", {"name": name, "description": text})
    SubElement(root, "DefaultExperiment", {
        "startTime": "0.0", "stopTime": _number(slave_class.default_stop),
        "stepSize": _number(slave_class.default_step), "tolerance": _number(DEFAULT_TOLERANCE)})
    _variables(root, table)
    _model_structure(root, table)
    indent(root)
    return b'<?xml version="1.0" encoding="UTF-8"?>\n' + tostring(root, encoding="utf-8") + b"\n"
