"""Resolve a scene into loaded FMUs and checked links, before anything runs.

Checks, each with an error naming the scene file and the key: the FMU exists (a catalog name is
built on demand), parameters and effects exist in it, every connection runs from an output to an
input of the same type and unit, inputs given in [inputs] exist and are inputs, recorded
variables exist.
"""
from __future__ import annotations

import functools
import logging
import math
from dataclasses import dataclass
from pathlib import Path

from .scene import Scene, SceneError
from ..fmu.archive import fmu_file_problem
from ..fmu.instance import FmuInstance
from ..fmu.instance3 import feedthrough, value_type

log = logging.getLogger(__name__)


def default_fmu_dir(scene: Scene) -> Path:
    """fmus/ beside the scene's scenarios/ folder, else ./fmus."""
    beside = scene.path.resolve().parent.parent / "fmus"
    return beside if (beside.parent / "scenarios").is_dir() else Path("fmus").resolve()


def resolve_fmu(scene: Scene, comp_name: str, fmu_dir: Path,
                model_exchange: bool = False) -> Path:
    """A path to the component's FMU; builds catalog FMUs that are missing or stale. A catalog
    component with fmi = 3 takes fmus/fmi3/<Model>.fmu; `model_exchange` (the model-exchange
    master) takes every catalog component's FMI 3.0 FMU for its effects (fmu/build_fmi3.py)."""
    comp = scene.components[comp_name]
    ref = comp.fmu
    key = f"[components.{comp_name}].fmu"
    if ref.endswith(".fmu"):
        path = (scene.path.parent / ref).resolve()
        problem = fmu_file_problem(path)
        if problem is not None:
            raise SceneError(scene.path, key, problem)
        _check_fmi_version(scene, comp_name, path)
        return path
    from ..fmu.build import build_fmu, rebuild_reason
    from ..models.catalog import FMU_MODELS
    if ref not in FMU_MODELS:
        raise SceneError(scene.path, key, f"unknown FMU {ref!r}; known: {', '.join(FMU_MODELS)}"
                                          " or a path ending in .fmu")
    if comp.fmi == 3 or model_exchange:
        from ..fmu import build_fmi3
        effects = build_fmi3.variant(ref, comp.effects if model_exchange else None)
        path = build_fmi3.fmu_path(ref, fmu_dir, effects)
        rebuild = rebuild_reason(path, ref, 3, build_fmi3.current_build_id(ref, effects))
        build = functools.partial(build_fmi3.build_fmu3, ref, path.parent, effects)
    else:
        path = fmu_dir / f"{ref}.fmu"
        rebuild = rebuild_reason(path, ref)
        build = functools.partial(build_fmu, ref, fmu_dir)
    warn_once_if_tree_differs(scene.path.resolve().parent.parent)
    if rebuild is not None:
        from ..fmu.build import PACKAGE_DIR
        (log.warning if rebuild.damaged else log.info)(
            "building %s (%s) from %s", path, rebuild.reason, PACKAGE_DIR)
        build()
    return path


def _check_fmi_version(scene: Scene, comp_name: str, path: Path) -> None:
    """An FMU file's FMI version is the file's; `fmi = 3` on an FMI 2.0 file is a mistake."""
    from ..fmu.instance3 import is_fmi3
    try:
        version = 3 if is_fmi3(path) else 2
    except (OSError, KeyError, ValueError, __import__("zipfile").BadZipFile):
        return  # not an FMU: loading it says why
    if scene.components[comp_name].fmi == 3 and version != 3:
        raise SceneError(scene.path, f"[components.{comp_name}].fmi",
                         f"fmi = 3, but {path.name} is an FMI 2.0 FMU (the file decides)")


def tree_differences(other: Path) -> list[str]:
    """The FMU sources (fmu.build.runtime_files of every model) that differ between the imported crankfmu
    package and another copy of it at `other` (a folder holding crankfmu's modules); [] when it
    is the same folder or holds no crankfmu."""
    from ..fmu.build import PACKAGE_DIR, runtime_files
    from ..models.catalog import FMU_MODELS
    other = Path(other).resolve()
    if not (other / "__init__.py").is_file() or other == PACKAGE_DIR.resolve():
        return []
    files = dict(item for model in FMU_MODELS for item in runtime_files(model))
    return [name for name, data in sorted(files.items())
            if not (other / name).is_file() or (other / name).read_bytes() != data]


def warn_if_tree_differs(tree: Path) -> None:
    """A non-editable install builds FMUs from its own copy: say so when the source tree beside
    the scene holds other FMU sources (an edit there would be silently ignored)."""
    from ..fmu.build import PACKAGE_DIR
    differ = tree_differences(Path(tree) / "sources" / "crankfmu")
    if differ:
        log.warning("the FMUs are built from the installed crankfmu at %s, which differs from "
                    "the source tree %s (%s%s): edits there are not used; install the tree "
                    "editable (pip install -e %s)", PACKAGE_DIR, tree / "sources" / "crankfmu",
                    ", ".join(differ[:3]), f" and {len(differ) - 3} more" if len(differ) > 3
                    else "", tree)


_TREES_CHECKED: set[Path] = set()


def warn_once_if_tree_differs(tree: Path) -> None:
    """warn_if_tree_differs, once per source tree and process: every command that uses a
    catalog FMU says that an edit in the tree beside the scene is not used, built or not (after
    a plain `pip install .` the FMUs in fmus/ are current for the installed copy, so nothing
    was rebuilt and nothing said so). In a tree the package was imported from (an editable
    install, PYTHONPATH) it costs two stats."""
    if tree not in _TREES_CHECKED:
        _TREES_CHECKED.add(tree)
        warn_if_tree_differs(tree)


@dataclass
class Link:
    """One connection, resolved to indices of the source's connected-output buffer."""

    source: str
    source_var: str
    target: str
    target_var: str
    unit: str | None


def _check_variable(scene, key, fmu: FmuInstance, name: str, causalities: tuple[str, ...]):
    if name not in fmu.variables:
        candidates = sorted(v for v, var in fmu.variables.items() if var.causality in causalities)
        raise SceneError(scene.path, key, f"{fmu.name} ({fmu.path.name}) has no variable "
                                          f"{name!r}; {'/'.join(causalities)}s: {', '.join(candidates)}")
    var = fmu.variables[name]
    if var.causality not in causalities:
        raise SceneError(scene.path, key, f"{fmu.name}.{name} is a {var.causality}, "
                                          f"expected {' or '.join(causalities)}")
    return var


def check_components(scene: Scene, fmus: dict[str, FmuInstance]) -> None:
    for name, comp in scene.components.items():
        fmu = fmus[name]
        for pname, value in comp.parameters.items():
            key = f"[components.{name}].parameters.{pname}"
            var = _check_variable(scene, key, fmu, pname, ("parameter",))
            _check_value(scene, key, f"{name}.{pname}", var, value)
        known_effects = sorted(v[len("effect_"):] for v in fmu.variables if v.startswith("effect_"))
        for effect in comp.effects:
            if effect not in known_effects:
                raise SceneError(scene.path, f"[components.{name}].effects",
                                 f"{effect!r} is not an effect of {comp.fmu}; effects: "
                                 f"{', '.join(known_effects) or '(none)'}")


def check_physics(scene: Scene, fmus: dict[str, FmuInstance]) -> None:
    """Impossible parameter values of catalog FMUs, refused before any FMU is instantiated,
    with the physics model's own message (as the libcosim/ecos adapters do). Inside the FMU the
    same check raises a Python exception in pythonfmu 0.7.0's binary, whose error path damages
    the shared interpreter: after a few such failures a long-lived process crashes (measured:
    a segmentation fault in garbage collection after some tens of failed runs in one process)."""
    from ..runtime.model import ParameterError
    from ..models.catalog import FMU_MODELS, physics_class
    for name, comp in scene.components.items():
        model = fmus[name].model_description.modelName
        if model not in FMU_MODELS:
            continue
        key = f"[components.{name}].parameters"
        effects = set(comp.effects)
        values = {}
        for k, v in comp.parameters.items():
            if k.startswith("effect_"):  # an effect switched by its Boolean parameter
                (effects.add if v else effects.discard)(k[len("effect_"):])
            else:
                values[k] = float(v)
        try:
            physics_class(model)(values, sorted(effects))
        except (KeyError, TypeError):  # a model whose constructor differs: the FMU checks
            continue
        except ParameterError as err:
            raise SceneError(scene.path, key, str(err)) from None
        except (ArithmeticError, ValueError) as err:  # e.g. an overflow from 1e300
            raise SceneError(scene.path, key, f"{model} cannot take these values: "
                                              f"{type(err).__name__}: {err}") from None


def _check_value(scene, key, ref: str, var, value) -> None:
    """The value fits the parameter's type (a Boolean takes true/false, a Real a finite
    number: `--set press.m5=true` is not 1 kg) and the range its modelDescription declares."""
    kind = value_type(var)
    if kind == "Boolean":
        if not isinstance(value, bool):
            raise SceneError(scene.path, key, f"{ref} is a Boolean parameter: true or false, got "
                                              f"{value!r}")
        return
    if kind not in ("Real", "Integer"):
        raise SceneError(scene.path, key, f"{ref} is of type {var.type}; crankfmu sets Real and "
                                          "Boolean parameters only")
    if isinstance(value, bool) or not isinstance(value, (int, float)) or \
            not math.isfinite(value):
        raise SceneError(scene.path, key, f"{ref} is a {kind} parameter"
                                          f"{f' [{var.unit}]' if var.unit else ''}: a finite "
                                          f"number, got {value!r}")
    if kind == "Integer" and not float(value).is_integer():
        raise SceneError(scene.path, key, f"{ref} is an Integer parameter, got {value!r}")
    for bound, ok in (("min", lambda b: value >= b), ("max", lambda b: value <= b)):
        limit = _float_or_none(getattr(var, bound, None))
        if limit is not None and not ok(limit):
            raise SceneError(scene.path, key, f"{ref} = {value!r} is outside its range: "
                                              f"{bound} = {limit!r}"
                                              f"{f' {var.unit}' if var.unit else ''} "
                                              "(the FMU's modelDescription)")


def _float_or_none(x) -> float | None:
    try:
        value = float(x) if x not in (None, "") else None
    except (TypeError, ValueError):
        return None
    return value if value is not None and math.isfinite(value) else None


def check_links(scene: Scene, fmus: dict[str, FmuInstance]) -> list[Link]:
    links = []
    for k, c in enumerate(scene.connections):
        key = f"[[connections]] #{k + 1}"
        src_comp, src_var = c.source.split(".", 1)
        dst_comp, dst_var = c.target.split(".", 1)
        src = _check_variable(scene, f"{key}.from", fmus[src_comp], src_var, ("output",))
        dst = _check_variable(scene, f"{key}.to", fmus[dst_comp], dst_var, ("input",))
        if value_type(src) != value_type(dst):
            raise SceneError(scene.path, key, f"type mismatch: {c.source} is {src.type}, "
                                              f"{c.target} is {dst.type}")
        if (src.unit or "1") != (dst.unit or "1"):
            raise SceneError(scene.path, key, f"unit mismatch: {c.source} is in "
                                              f"{src.unit or '1'}, {c.target} in {dst.unit or '1'}")
        links.append(Link(src_comp, src_var, dst_comp, dst_var, src.unit))
    for target in scene.inputs:
        comp, var = target.split(".", 1)
        _check_variable(scene, f"[inputs].\"{target}\"", fmus[comp], var, ("input",))
    for ref in scene.record:
        comp, var = ref.split(".", 1)
        _check_variable(scene, "[record].variables", fmus[comp], var,
                        ("output", "input", "parameter", "local"))
    return links


def algebraic_loops(fmus: dict[str, FmuInstance], links: list[Link]) -> list[list[str]]:
    """Cycles of direct feedthrough through the connections: each as the list of variables
    around it ("comp.output", "comp.input", ...). A cycle of connections is a loop only where
    every component on it passes its input straight to the output that closes it."""
    deps = {c: feedthrough(f) for c, f in fmus.items()}
    succ: dict[str, list[str]] = {}
    for l in links:  # output -> connected input
        succ.setdefault(f"{l.source}.{l.source_var}", []).append(f"{l.target}.{l.target_var}")
    connected_outputs = {f"{l.source}.{l.source_var}" for l in links}
    for comp, table in deps.items():  # input -> output with feedthrough
        for output, inputs in table.items():
            if f"{comp}.{output}" in connected_outputs:
                for i in inputs:
                    succ.setdefault(f"{comp}.{i}", []).append(f"{comp}.{output}")
    loops, state, stack = [], {}, []

    def visit(node: str) -> None:  # depth-first search; a back edge closes a cycle
        state[node] = 1
        stack.append(node)
        for nxt in succ.get(node, []):
            if state.get(nxt) == 1:
                loops.append(stack[stack.index(nxt):] + [nxt])
            elif nxt not in state:
                visit(nxt)
        stack.pop()
        state[node] = 2
    for node in sorted(succ):
        if node not in state:
            visit(node)
    return loops


def check_loops(scene: Scene, fmus: dict[str, FmuInstance], links: list[Link], master) -> None:
    """An algebraic loop (a cycle of direct feedthrough) has no explicit solution: a master that
    steps each FMU once per step (Jacobi, Gauss-Seidel, adaptive) would run it with values one
    step old and no error; refuse it and name the loop. The iterative master solves the loop
    at every communication point (its fixed point satisfies it)."""
    if getattr(master, "solves_algebraic_loops", False):
        return
    loops = algebraic_loops(fmus, links)
    if loops:
        raise SceneError(scene.path, "[[connections]]",
                         f"algebraic loop (direct feedthrough all the way round, declared in the "
                         f"FMUs' ModelStructure): {' -> '.join(loops[0])}; master "
                         f"{master.name} cannot solve it: use algorithm = \"iterative\", or "
                         "break the loop")


class System:
    """The wired scene: FMUs, links and external inputs, with buffers for a master to use."""

    def __init__(self, scene: Scene, fmus: dict[str, FmuInstance], links: list[Link]):
        self.scene, self.fmus, self.links = scene, fmus, links
        order = scene.master.order or list(scene.components)
        self.order = order + [c for c in scene.components if c not in order]
        # per component: the outputs others need, and the inputs it receives
        self.out_names = {c: sorted({l.source_var for l in links if l.source == c}) for c in fmus}
        self.in_names = {c: [l.target_var for l in links if l.target == c] for c in fmus}
        self.in_sources = {c: [(l.source, self.out_names[l.source].index(l.source_var))
                               for l in links if l.target == c] for c in fmus}
        self.read_outputs = {c: fmus[c].reader(self.out_names[c]) for c in fmus}
        self.write_inputs = {c: fmus[c].writer(self.in_names[c]) for c in fmus}
        # each component's connected outputs as a list of floats, replaced at every read
        self.outputs = {c: [0.0] * len(self.out_names[c]) for c in fmus}
        self.external = {c: [(s.target.split(".", 1)[1], s) for s in scene.inputs.values()
                             if s.target.split(".", 1)[0] == c] for c in fmus}
        self.write_external = {c: fmus[c].writer([n for n, _ in self.external[c]]) for c in fmus}
        # constants are written once at initialization; only time tables change during a run
        self.external_varies = {c: any(len(s.times) > 1 for _, s in self.external[c])
                                for c in fmus}

    def refresh_outputs(self, comp: str) -> list[float]:
        """Read comp's connected outputs into a new list (the masters' history keeps the
        old one)."""
        values = self.outputs[comp] = self.read_outputs[comp]()
        return values

    def gather_inputs(self, comp: str, outputs: dict | None = None) -> list[float]:
        outputs = self.outputs if outputs is None else outputs
        return [outputs[src][k] for src, k in self.in_sources[comp]]

    def set_external(self, comp: str, t: float, initial: bool = False) -> None:
        if self.external[comp] and (initial or self.external_varies[comp]):
            self.write_external[comp]([s.value_at(t) for _, s in self.external[comp]])
