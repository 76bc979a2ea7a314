"""Write a complete, deterministic modelDescription.xml: FMI 2.0 for a ModelSlave (pythonfmu), FMI
3.0 for a ModelSlave3 (pythonfmu3; Co-Simulation and Model Exchange).

pythonfmu 0.7.0 writes no units, ranges or InitialUnknowns (fmpy validate rejects that) and stamps
a random GUID and the build time (every build differs). This writer produces the whole file from
the physics class, so units, ranges, dependencies and a content-derived GUID are always there.
"""
from __future__ import annotations

from xml.etree.ElementTree import Element, SubElement, indent, tostring

from ..runtime.slave_core import (DEFAULT_TOLERANCE, base_table_size, derivative_unit,
                                  variable_table)
from .bundle import guid as build_guid
from .units import base_unit_attributes


def _number(x: float) -> str:
    return repr(float(x))


def _attributes(vr: int, var) -> dict:
    """The attributes every version's variable element has."""
    attrs = {"name": var.name, "valueReference": str(vr), "description": var.description,
             "causality": var.causality, "variability": var.variability}
    if var.initial:
        attrs["initial"] = var.initial
    return attrs


def _variables(root: Element, table) -> None:
    node = SubElement(root, "ModelVariables")
    for vr, var in enumerate(table):
        sv = SubElement(node, "ScalarVariable", _attributes(vr, var))
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


def _categories_and_experiment(root: Element, slave_class) -> None:
    """LogCategories and DefaultExperiment, the same in both versions."""
    cats = SubElement(root, "LogCategories")
    for name, text in slave_class.log_categories.items():
        SubElement(cats, "Category", {"name": name, "description": text})
    SubElement(root, "DefaultExperiment", {
        "startTime": "0.0", "stopTime": _number(slave_class.default_stop),
        "stepSize": _number(slave_class.default_step), "tolerance": _number(DEFAULT_TOLERANCE)})


def _unit_definitions(root: Element, table, extra=()) -> None:
    """The units of the table's variables and the `extra` ones."""
    units = sorted({v.unit for v in table if v.unit} | set(extra))
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


def model_description(slave_class, build_id: str, host: tuple[str, str] | None = None) -> bytes:
    """The FMI 2.0 modelDescription.xml bytes of a ModelSlave class; `build_id` (a hash of the
    bundled sources) fixes the GUID, so identical sources give an identical file. `host`:
    (requirements, search) for the host annotation (VendorAnnotations), or None."""
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
    _categories_and_experiment(root, slave_class)
    if host is not None:
        host_annotation(SubElement(SubElement(root, "VendorAnnotations"), "Tool",
                                   {"name": HOST_ANNOTATION}), *host)
    _variables(root, table)
    _model_structure(root, table)
    indent(root)
    return b'<?xml version="1.0" encoding="UTF-8"?>\n' + tostring(root, encoding="utf-8") + b"\n"


# -- FMI 3.0: Co-Simulation and Model Exchange in one modelDescription ----------------------------
HOST_ANNOTATION = "org.crankfmu.host"  # the annotation type saying what a host machine needs


def host_annotation(parent: Element, requirements: str, search: str) -> None:
    """What the host needs to run the FMU, under `parent` (FMI 2.0 VendorAnnotations/Tool, FMI
    3.0 Annotations/Annotation): the Python and packages, and how the launcher finds them."""
    SubElement(parent, "Host", {"requires": requirements, "pythonSearch": search})


def state_units(physics, states) -> list[str | None]:
    """A state's unit where an output of the same name declares one (phi: rad, impulse: N.s),
    else None: the models declare states by name only."""
    units = {v.name: v.unit for v in physics.outputs}
    return [units.get(name) for name in states]


def _fmi3_references(table, layout) -> list[int]:
    """The FMI 3.0 value reference of each table variable: the base part as in FMI 2.0, the
    companions after the Model Exchange variables (runtime/slave3.me_layout)."""
    n_base = layout["time"][0]
    return list(range(n_base)) + list(layout["companions"])


def _variables3(root: Element, table, effects_on, states, units, slots: int, layout) -> None:
    node = SubElement(root, "ModelVariables")
    for vr, var in zip(_fmi3_references(table, layout), table):
        attrs = _attributes(vr, var)
        if var.kind == "Boolean":
            start = var.start if not var.name.startswith("effect_") else \
                var.name[len("effect_"):] in effects_on
            SubElement(node, "Boolean", {**attrs, "start": str(bool(start)).lower()})
            continue
        for key in ("unit", "min", "max", "start"):
            value = getattr(var, key)
            if value is not None:
                attrs[key] = value if key == "unit" else _number(value)
        SubElement(node, "Float64", attrs)
    SubElement(node, "Float64", {"name": "time", "valueReference": str(layout["time"][0]),
                                 "description": "Simulation time", "causality": "independent",
                                 "variability": "continuous", "unit": "s"})
    for k, (name, unit) in enumerate(zip(states, units)):
        attrs = {"name": f"state.{name}", "valueReference": str(layout["states"][k]),
                 "description": f"Continuous state {name} (Model Exchange)",
                 "causality": "local", "variability": "continuous", "initial": "calculated"}
        SubElement(node, "Float64", {**attrs, **({"unit": unit} if unit else {})})
    for k, (name, unit) in enumerate(zip(states, units)):
        attrs = {"name": f"der(state.{name})", "valueReference": str(layout["derivatives"][k]),
                 "description": f"Time derivative of the state {name}", "causality": "local",
                 "variability": "continuous", "initial": "calculated",
                 "derivative": str(layout["states"][k])}
        SubElement(node, "Float64",
                   {**attrs, **({"unit": derivative_unit(unit, 1)} if unit else {})})
    for k in range(slots):
        SubElement(node, "Float64", {
            "name": f"event_indicator_{k + 1}", "valueReference": str(layout["indicators"][k]),
            "description": "Event indicator: a mode switch or force extremum of the current "
                           "mode crosses zero (1.0 where the mode has fewer)",
            "causality": "local", "variability": "continuous", "initial": "calculated"})


def _model_structure3(root: Element, table, layout) -> None:
    vrs = {v.name: vr for vr, v in zip(_fmi3_references(table, layout), table)}
    states = " ".join(map(str, layout["states"]))
    structure = SubElement(root, "ModelStructure")
    outputs = [v for v in table if v.causality == "output"]
    for v in outputs:  # the knowns in continuous-time mode: inputs (feedthrough) and states
        deps = " ".join([str(vrs[d]) for d in v.depends_on] + ([states] if states else []))
        SubElement(structure, "Output", {"valueReference": str(vrs[v.name]),
                                         "dependencies": deps})
    for vr in layout["derivatives"]:
        SubElement(structure, "ContinuousStateDerivative", {"valueReference": str(vr)})
    for v in outputs:
        SubElement(structure, "InitialUnknown", {"valueReference": str(vrs[v.name])})
    for vr in list(layout["states"]) + list(layout["derivatives"]):
        SubElement(structure, "InitialUnknown", {"valueReference": str(vr)})
    for vr in layout["indicators"]:
        SubElement(structure, "EventIndicator", {"valueReference": str(vr)})


def model_description_fmi3(slave_class, build_id: str, host: tuple[str, str]) -> bytes:
    """The FMI 3.0 modelDescription.xml of an FMI 3.0 slave class (runtime/slave3.py): the
    shared variable table at the FMI 2.0 value references, then time, the Model Exchange
    states, their derivatives and the event indicators (slave3.me_layout). `host`:
    (requirements, search) for the host annotation."""
    from ..runtime.slave3 import me_layout

    physics = slave_class.physics_class
    table = variable_table(physics)
    states, slots = tuple(slave_class.me_states), physics.event_slots
    n_base = base_table_size(physics)
    layout = me_layout(n_base, len(states), slots, len(table) - n_base)
    root = Element("fmiModelDescription", {
        "fmiVersion": "3.0", "modelName": physics.model_name,
        "instantiationToken": build_guid(physics.model_name, build_id),
        "description": physics.description,
        "author": "crankfmu", "version": build_id,
        "generationTool": "crankfmu build (pythonfmu3 0.3)",
        "variableNamingConvention": "structured"})
    common = {"modelIdentifier": physics.model_name, "needsExecutionTool": "true",
              "canBeInstantiatedOnlyOncePerProcess": "false", "canGetAndSetFMUState": "true",
              "canSerializeFMUState": "true", "providesDirectionalDerivatives": "false"}
    SubElement(root, "ModelExchange", {**common, "needsCompletedIntegratorStep": "false"})
    SubElement(root, "CoSimulation", {**common, "canHandleVariableCommunicationStepSize": "true",
                                      "hasEventMode": "false",
                                      "providesIntermediateUpdate": "false"})
    units = state_units(physics, states)
    _unit_definitions(root, table, ["s"] + [u for u in units if u] +
                      [derivative_unit(u, 1) for u in units if u])
    _categories_and_experiment(root, slave_class)
    _variables3(root, table, set(slave_class.me_effects), states, units, slots, layout)
    _model_structure3(root, table, layout)
    annotation = SubElement(SubElement(root, "Annotations"), "Annotation",
                            {"type": HOST_ANNOTATION})
    host_annotation(annotation, *host)
    indent(root)
    return b'<?xml version="1.0" encoding="UTF-8"?>\n' + tostring(root, encoding="utf-8") + b"\n"
