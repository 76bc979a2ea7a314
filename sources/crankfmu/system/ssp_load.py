"""Read an SSP 1.0 archive into a Scene, so `crankfmu run X.ssp` runs it like a TOML scene.

The SSD is validated against the SSP 1.0 schemas that fmpy ships, then mapped back onto the TOML
scene's shape and checked by the same `parse_scene`. Every error names the .ssp file and the
element (with its line in SystemStructure.ssd). crankfmu runs flat systems of FMUs: nested
systems, system-level connectors, signal dictionaries, parameter mappings and connection
transformations are refused with a clear error rather than half-supported. Unlike the SSP rule
"names that match no variable are ignored", a bound name that matches no FMU variable is an error
(a typo there would otherwise go unnoticed).
"""
from __future__ import annotations

import functools
import shutil
import tempfile
import weakref
import zipfile
from pathlib import Path, PurePosixPath

from lxml import etree

from ..fmu.archive import UnsafeXml, check_model_description_xml, parse_safe_xml
from ..fmu.instance3 import is_fmi3, value_type
from .scene import Scene, SceneError, parse_scene
from .ssp_export import (FMU_TYPE, NS, OSP_ANNOTATION, PARAMETER_SET_TYPE, SCENE_ANNOTATION,
                         SSD_NAME, q)

SCHEMA_DIR = Path(str(__import__("fmpy").__file__)).parent / "ssp" / "schema"
FLOAT_KEYS = ("step", "fmu_tolerance")  # the common [master] keys; the masters' own options
INT_KEYS = ("max_steps",)                # take their type from their declaration
# Limits on a (possibly hostile) archive, checked while streaming each entry out of the zip:
MAX_XML_BYTES = 16 << 20       # the SSD and each .ssv, parsed in memory
MAX_FMU_BYTES = 256 << 20      # each FMU, streamed to the run's private folder
MAX_TOTAL_BYTES = 1 << 30      # everything read from one archive
MAX_ENTRIES = 10_000


class _Budget:
    """Bytes still allowed from one archive (MAX_TOTAL_BYTES)."""

    def __init__(self):
        self.left = MAX_TOTAL_BYTES


def load_ssp(path) -> Scene:
    """The archive as a Scene. Its FMUs are copied out of the archive into a private folder
    (tempfile.mkdtemp: fresh, mode 0700) that lives as long as the Scene and is removed with
    it (and at exit); nothing is reused from an earlier run or another user."""
    path = Path(path)
    folder = Path(tempfile.mkdtemp(prefix="crankfmu-ssp-"))
    try:
        archive = _open_archive(path)
        with archive:
            budget = _Budget()
            root = _read_ssd(path, archive, budget)
            data = _scene_data(path, root, archive, folder, budget)
        try:
            scene = parse_scene(path, data)
        except SceneError as err:  # the same checks as for TOML; say where that key came from
            raise SceneError(path, f"{SSD_NAME} (scene key {err.key})",
                             str(err).split(f"{err.key}: ", 1)[-1]) from None
    except BaseException:
        shutil.rmtree(folder, ignore_errors=True)
        raise
    scene.extracted = folder  # type: ignore[attr-defined]  # what the FMU paths point into
    weakref.finalize(scene, shutil.rmtree, str(folder), True)
    return scene


# -- archive and schema --------------------------------------------------------------------------
def _open_archive(path: Path) -> zipfile.ZipFile:
    if not path.exists():
        raise SceneError(path, "(file)", "no such SSP file")
    if not path.is_file():
        raise SceneError(path, "(file)", "not a regular file (an .ssp is a zip archive)")
    try:
        archive = zipfile.ZipFile(path)
    except OSError as err:
        raise SceneError(path, "(file)", f"cannot read it: {err.strerror or err}") from None
    except (zipfile.BadZipFile, zipfile.LargeZipFile, ValueError, EOFError,
            NotImplementedError) as err:
        raise SceneError(path, "(file)", "not a zip archive; an .ssp is a zip holding "
                                         f"{SSD_NAME} and the FMUs ({err})") from None
    if len(archive.infolist()) > MAX_ENTRIES:
        archive.close()
        raise SceneError(path, "(file)", f"more than {MAX_ENTRIES} entries")
    return archive


def _stream(path: Path, archive: zipfile.ZipFile, name: str, limit: int, budget: _Budget,
            sink) -> None:
    """Copy an archive entry to `sink` (a callable taking bytes) in chunks, stopping with an
    error as soon as it passes `limit` or the archive's budget: what the zip's directory
    declares is not trusted."""
    total = 0
    try:
        with archive.open(name) as f:
            while chunk := f.read(1 << 20):
                total += len(chunk)
                budget.left -= len(chunk)
                if total > limit:
                    raise SceneError(path, name, f"entry larger than the limit of {limit >> 20} "
                                                 "MiB")
                if budget.left < 0:
                    raise SceneError(path, name, f"the archive unpacks to more than "
                                                 f"{MAX_TOTAL_BYTES >> 20} MiB")
                sink(chunk)
    except SceneError:
        raise
    except (zipfile.BadZipFile, zipfile.LargeZipFile, OSError, EOFError, ValueError,
            NotImplementedError, RuntimeError) as err:  # zlib.error is an Exception: below
        raise SceneError(path, name, f"cannot unpack the entry: {type(err).__name__}: {err}") \
            from None
    except Exception as err:  # zlib.error, lzma/bz2 errors of a damaged entry
        raise SceneError(path, name, f"cannot unpack the entry: {type(err).__name__}: {err}") \
            from None


def _read_entry(path: Path, archive: zipfile.ZipFile, name: str, budget: _Budget) -> bytes:
    parts: list[bytes] = []
    _stream(path, archive, name, MAX_XML_BYTES, budget, parts.append)
    return b"".join(parts)


def _safe_xml(path: Path, data: bytes, what: str):
    try:
        return parse_safe_xml(data, what)
    except UnsafeXml as err:
        raise SceneError(path, err.where, err.message) from None


@functools.lru_cache(maxsize=None)
def _schema(name: str) -> etree.XMLSchema:
    return etree.XMLSchema(file=str(SCHEMA_DIR / name))


def _validate(path: Path, node, schema_name: str, what: str) -> None:
    schema = _schema(schema_name)
    if not schema.validate(node):
        e = schema.error_log.filter_from_errors()[0]
        raise SceneError(path, f"{SSD_NAME} line {e.line}", f"not a valid {what} "
                                                             f"({schema_name}): {e.message}")


def _read_ssd(path: Path, archive: zipfile.ZipFile, budget: _Budget):
    if SSD_NAME not in archive.namelist():
        names = archive.namelist()
        listed = ", ".join(n[:80] for n in names[:20]) + (", ..." if len(names) > 20 else "")
        raise SceneError(path, SSD_NAME, f"missing from the archive (it holds: "
                                         f"{listed or 'nothing'})")
    text = _read_entry(path, archive, SSD_NAME, budget)
    root = _safe_xml(path, text, SSD_NAME)
    _validate(path, root, "SystemStructureDescription.xsd", "SSP 1.0 system structure description")
    for pset in root.iter(q("ssv", "ParameterSet")):  # the SSD schema skips inline content (lax)
        _validate(path, etree.fromstring(etree.tostring(pset)),
                  "SystemStructureParameterValues.xsd", "SSP 1.0 parameter set")
    return root


def _where(node) -> str:
    """'SystemStructure.ssd line 12 <ssd:Component name="motor">' for error keys."""
    qname = etree.QName(node)
    prefix = next((p for p, uri in NS.items() if uri == qname.namespace), "")
    name = f' name="{node.get("name")}"' if node.get("name") else ""
    return f"{SSD_NAME} line {node.sourceline} <{prefix}:{qname.localname}{name}>"


def _member(path: Path, archive: zipfile.ZipFile, node, source: str) -> str:
    """The archive member a relative `source` URI names (relative to the SSD at the root)."""
    if ":" in source.split("/", 1)[0] or source.startswith("/"):
        raise SceneError(path, _where(node), f"source {source!r}: only files inside the archive "
                                             "(relative paths such as resources/X.fmu) are "
                                             "supported")
    name = str(PurePosixPath(source.removeprefix("./")))
    if name not in archive.namelist():
        raise SceneError(path, _where(node), f"source {source!r} is not in the archive")
    return name


def _extract_fmu(path: Path, archive: zipfile.ZipFile, member: str, folder: Path,
                 budget: _Budget, node) -> Path:
    """The FMU as a file (fmpy needs one) in this load's private folder, streamed with the size
    limits, its modelDescription checked with the safe parser."""
    target = folder / f"{len(list(folder.iterdir()))}" / PurePosixPath(member).name
    target.parent.mkdir(mode=0o700)
    with open(target, "xb") as f:
        _stream(path, archive, member, MAX_FMU_BYTES, budget, f.write)
    try:
        check_model_description_xml(target)
    except (ValueError, zipfile.BadZipFile, OSError, EOFError, NotImplementedError) as err:
        raise SceneError(path, _where(node), f"{member} is not an FMU crankfmu can read: "
                                             f"{err}") from None
    return target


# -- SSD -> scene data ---------------------------------------------------------------------------
def _scene_data(path: Path, root, archive: zipfile.ZipFile, folder: Path, budget) -> dict:
    system = root.find("ssd:System", NS)
    _refuse(path, system, ["ssd:Connectors", "ssd:SignalDictionaries",
                           "ssd:Elements/ssd:System", "ssd:Elements/ssd:SignalDictionaryReference"],
            "crankfmu runs a flat system of FMU components")
    components: dict = {}
    variables: dict = {}
    for node in system.findall("ssd:Elements/ssd:Component", NS):
        name = node.get("name")
        if name in components:
            raise SceneError(path, _where(node), f"a second component named {name!r}")
        fmu_path = _component_fmu(path, archive, node, folder, budget)
        from fmpy import read_model_description
        try:
            md = read_model_description(str(fmu_path))
        except Exception as err:  # fmpy's own checks of the modelDescription
            raise SceneError(path, _where(node), f"{node.get('source')}: not a valid FMU: "
                                                 f"{type(err).__name__}: {err}") from None
        variables[name] = {v.name: v for v in md.modelVariables}
        components[name] = {"fmu": str(fmu_path), "parameters": {}, "effects": [],
                            "fmi": 3 if is_fmi3(fmu_path) else 2}
    connectors = {n.get("name"): [c.get("name") for c in n.findall("ssd:Connectors/ssd:Connector",
                                                                   NS)]
                  for n in system.findall("ssd:Elements/ssd:Component", NS)}
    connections = [_connection(path, node, connectors)
                   for node in system.findall("ssd:Connections/ssd:Connection", NS)]
    connected = {c["to"] for c in connections}
    inputs: dict = {}
    bound: dict[str, set] = {n: set() for n in components}
    for comp, var, value, node in _bindings(path, archive, system, components, budget):
        if comp not in components:
            raise SceneError(path, _where(node), f"no component {comp!r} for {comp}.{var}")
        _apply(path, node, components[comp], variables[comp], comp, var, value, inputs, connected)
        bound[comp].add(var)
    for comp, vars_ in variables.items():  # unbound effects keep the FMU's start value
        for name, v in vars_.items():
            if name.startswith("effect_") and name not in bound[comp] and v.start == "true":
                components[comp]["effects"].append(name[len("effect_"):])
    head, master, record = _experiment(path, root, system, components, connectors, variables,
                                       inputs)
    data = {"scene": head, "master": master, "components": components,
            "connections": connections, "inputs": inputs}
    if record is not None:
        data["record"] = record
    return data


def _refuse(path: Path, node, paths: list[str], why: str) -> None:
    for p in paths:
        found = node.find(p, NS)
        if found is not None:
            raise SceneError(path, _where(found), f"not supported: {why}")


def _component_fmu(path: Path, archive: zipfile.ZipFile, node, folder: Path, budget) -> Path:
    kind = node.get("type")
    source = node.get("source") or ""
    if kind not in (None, FMU_TYPE) or (kind is None and not source.endswith(".fmu")):
        raise SceneError(path, _where(node), f"type {kind!r} is not supported; components must be "
                                             f"FMUs ({FMU_TYPE})")
    if node.get("implementation") == "ModelExchange":
        raise SceneError(path, _where(node), "implementation ModelExchange is not supported; "
                                             "crankfmu runs co-simulation FMUs")
    return _extract_fmu(path, archive, _member(path, archive, node, source), folder, budget,
                        node)


def _connection(path: Path, node, connectors: dict[str, list]) -> dict:
    _refuse(path, node, ["ssc:LinearTransformation", "ssc:BooleanMappingTransformation",
                         "ssc:IntegerMappingTransformation",
                         "ssc:EnumerationMappingTransformation"],
            "connection transformations (crankfmu links connect equal units directly)")
    ends = []
    for end in ("start", "end"):
        element, connector = node.get(f"{end}Element"), node.get(f"{end}Connector")
        if element is None:
            raise SceneError(path, _where(node), f"{end}Element missing: connections to the "
                                                 "system's own connectors are not supported")
        if element not in connectors:
            raise SceneError(path, _where(node), f"{end}Element {element!r} is not a component; "
                                                 f"components: {', '.join(connectors)}")
        if connector not in connectors[element]:
            raise SceneError(path, _where(node), f"{end}Connector {connector!r} is not a connector "
                                                 f"of {element}; connectors: "
                                                 f"{', '.join(sorted(connectors[element]))}")
        ends.append(f"{element}.{connector}")
    return {"from": ends[0], "to": ends[1]}


def _bindings(path: Path, archive, system, components, budget):
    """(component, variable, value, node) for every bound value, component- and system-level."""
    for owner in [system] + system.findall("ssd:Elements/ssd:Component", NS):
        for binding in owner.findall("ssd:ParameterBindings/ssd:ParameterBinding", NS):
            for pset in _parameter_sets(path, archive, binding, budget):
                for p in pset.findall("ssv:Parameters/ssv:Parameter", NS):
                    name = binding.get("prefix", "") + (p.get("name") or "")
                    if owner is system:
                        if "." not in name:
                            raise SceneError(path, _where(p), "a system-level binding needs "
                                                              "\"component.variable\" names")
                        comp, var = name.split(".", 1)
                    else:
                        comp, var = owner.get("name"), name
                    yield comp, var, _value(path, p), p


def _parameter_sets(path: Path, archive, binding, budget) -> list:
    if binding.get("type", PARAMETER_SET_TYPE) != PARAMETER_SET_TYPE:
        raise SceneError(path, _where(binding), f"type {binding.get('type')!r} is not supported; "
                                                f"only {PARAMETER_SET_TYPE}")
    _refuse(path, binding, ["ssd:ParameterMapping"], "parameter mappings")
    source = binding.get("source")
    if source:
        member = _member(path, archive, binding, source)
        pset = _safe_xml(path, _read_entry(path, archive, member, budget), member)
        _validate(path, pset, "SystemStructureParameterValues.xsd", f"parameter set ({source})")
        return [pset]
    return binding.findall("ssd:ParameterValues/ssv:ParameterSet", NS)


def _value(path: Path, p) -> tuple[str, float | bool, str | None]:
    real = p.find("ssv:Real", NS)
    if real is not None:
        return "Real", _float(path, real, "value"), real.get("unit")
    boolean = p.find("ssv:Boolean", NS)
    if boolean is not None:
        text = (boolean.get("value") or "").strip()
        if text not in ("true", "false", "1", "0"):
            raise SceneError(path, f"{_where(boolean)} value", f"must be true or false, got "
                                                              f"{text[:40]!r}")
        return "Boolean", text in ("true", "1"), None
    raise SceneError(path, _where(p), "only Real and Boolean values are supported (crankfmu FMUs "
                                      "have no other types)")


def _apply(path, node, component: dict, variables: dict, comp: str, var: str, value, inputs,
           connected) -> None:
    kind, v, unit = value
    if var not in variables:
        raise SceneError(path, _where(node), f"{comp} has no variable {var!r}")
    fmu_var = variables[var]
    if kind != value_type(fmu_var):
        raise SceneError(path, _where(node), f"{comp}.{var} is {fmu_var.type}, the value {kind}")
    if unit and unit != (fmu_var.unit or "1"):
        raise SceneError(path, _where(node), f"unit {unit!r} differs from {comp}.{var}'s unit "
                                             f"{fmu_var.unit or '1'!r} (no unit conversion)")
    if fmu_var.causality == "input":
        if f"{comp}.{var}" not in connected:  # a connected input's start value is overwritten
            inputs[f"{comp}.{var}"] = v
    elif fmu_var.causality != "parameter":
        raise SceneError(path, _where(node), f"{comp}.{var} is a {fmu_var.causality}; values bind "
                                             "to parameters and inputs only")
    elif var.startswith("effect_") and kind == "Boolean":
        effect = var[len("effect_"):]
        if v and effect not in component["effects"]:
            component["effects"].append(effect)
        elif not v and effect in component["effects"]:
            component["effects"].remove(effect)
    else:
        component["parameters"][var] = v


# -- experiment and crankfmu annotation ----------------------------------------------------------
def _experiment(path, root, system, components, connectors, variables, inputs):
    experiment = root.find("ssd:DefaultExperiment", NS)
    where = _where(experiment) if experiment is not None else SSD_NAME
    if experiment is None or experiment.get("stopTime") is None:
        raise SceneError(path, f"{where} stopTime", "required: crankfmu needs the end of the run "
                                                    "(ssd:DefaultExperiment stopTime)")
    head = {"name": root.get("name"), "description": system.get("description", ""),
            "start_time": _float(path, experiment, "startTime") if experiment.get("startTime")
            is not None else 0.0,
            "stop_time": _float(path, experiment, "stopTime")}
    annotation = experiment.find(f"ssd:Annotations/ssc:Annotation[@type='{SCENE_ANNOTATION}']", NS)
    if annotation is None:
        return head, _foreign_master(path, experiment), {"variables": _output_connectors(
            components, connectors, variables)}
    node = annotation.find("crankfmu:Scene", NS)
    if node is None:
        raise SceneError(path, _where(annotation), "the annotation holds no <crankfmu:Scene>")
    master = _master(path, node.find("crankfmu:Master", NS))
    record = node.find("crankfmu:Record", NS)
    rec = None
    if record is not None:
        rec = {"variables": [v.get("name") for v in record.findall("crankfmu:Variable", NS)]}
        if record.get("interval") is not None:
            rec["interval"] = _float(path, record, "interval")
    for table in node.findall("crankfmu:InputTable", NS):
        inputs[table.get("target")] = {
            "interpolation": table.get("interpolation", "linear"),
            "table": [[_float(path, p, "time"), _float(path, p, "value")]
                      for p in table.findall("crankfmu:Point", NS)]}
    return head, master, rec


def _float(path, node, attr: str) -> float:
    try:
        return float(node.get(attr))
    except (TypeError, ValueError):
        raise SceneError(path, f"{_where(node)} {attr}", f"must be a number, got "
                                                         f"{node.get(attr)!r}") from None


def _master(path, node) -> dict:
    if node is None:
        return {}
    from ..masters import MASTERS, all_options
    options = all_options()
    float_keys = FLOAT_KEYS + tuple(n for n, o in options.items() if o.kind is float)
    int_keys = INT_KEYS + tuple(n for n, o in options.items() if o.kind is int)
    chosen = MASTERS.get(node.get("algorithm", "gauss-seidel"))
    own = {o.name for o in chosen.options} if chosen else set(options)
    master: dict = {}
    for key, text in node.attrib.items():
        if key in options and key not in own:
            continue  # files written before the masters declared their options hold every key
        if key in float_keys:
            master[key] = _float(path, node, key)
        elif key in int_keys:
            try:
                master[key] = int(text)
            except (ValueError, OverflowError):
                raise SceneError(path, f"{_where(node)} {key}",
                                 f"must be an integer, got {text!r}") from None
        else:
            master[key] = text  # algorithm; parse_scene checks it
    order = [o.get("component") for o in node.findall("crankfmu:Order", NS)]
    if order:
        master["order"] = order
    return master


def _foreign_master(path, experiment) -> dict:
    """An SSP from another tool: crankfmu's default master at libcosim's step if given."""
    step = experiment.find(f"ssd:Annotations/ssc:Annotation[@type='{OSP_ANNOTATION}']"
                           "/osp:Algorithm/osp:FixedStepAlgorithm", NS)
    return {"step": _float(path, step, "baseStepSize")} if step is not None else {}


def _output_connectors(components, connectors, variables) -> list[str]:
    """No record list in the file: every output that has a connector."""
    return [f"{comp}.{name}" for comp in components for name in connectors[comp]
            if getattr(variables[comp].get(name), "causality", None) == "output"]
