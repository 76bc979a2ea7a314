"""The package's imports point one way (docs/architecture.md opens with the picture):

    runtime <- models <- errors <- fmu <- masters <- system <- cosim <- monolithic, interop
            <- studies <- commands, cli, api

A module may import its own layer or a lower one, never a higher one, and no set of modules
imports itself round a cycle. Inside the bottom two: the runtime (bundled in every FMU) imports
nothing else of crankfmu, and a model's folder (bundled with the runtime in its FMU) imports the
runtime and its own folder only. Read from the source with ast: every import counts, including
those inside functions (a lazy import is still a dependency)."""
from __future__ import annotations

import ast
import functools
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "sources" / "crankfmu"
LAYERS = (("runtime", "version"), ("models",), ("errors", "outputs"), ("fmu",), ("masters",),
          ("system",), ("cosim",), ("monolithic", "interop"), ("studies",),
          ("commands", "cli", "api", "__main__", ""))
RANK = {top: rank for rank, tops in enumerate(LAYERS) for top in tops}


def module_name(path: Path) -> str:
    parts = list(path.relative_to(PACKAGE).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def imports(path: Path) -> set[str]:
    """The crankfmu modules (names relative to crankfmu, "" = the package) `path` imports."""
    name = module_name(path)
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found = set()
    for node in ast.walk(parsed(path)):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".") if package else []
                base = base[:len(base) - (node.level - 1)]
                target = ".".join(base + ([node.module] if node.module else []))
            elif (node.module or "").split(".")[0] == "crankfmu":
                target = node.module[len("crankfmu") + 1:]
            else:
                continue
            for alias in node.names:  # `from . import x`: x may be a module
                sub = f"{target}.{alias.name}" if target else alias.name
                found.add(sub if sub in MODULES else target)
        elif isinstance(node, ast.Import):
            found.update(a.name[len("crankfmu") + 1:] for a in node.names
                         if a.name.split(".")[0] == "crankfmu")
    return found - {name}


@functools.cache
def parsed(path: Path) -> ast.Module:
    return ast.parse(path.read_text(), str(path))


@pytest.fixture(scope="module", autouse=True)
def _trees_freed_at_the_end():
    """The parsed modules go when this file's tests are done: some 250,000 ast objects that,
    kept to the session's end, every later full garbage collection of the worker traversed."""
    yield
    parsed.cache_clear()


MODULES = {module_name(p): p for p in PACKAGE.rglob("*.py")}


@functools.cache
def graph() -> dict[str, set[str]]:
    """module -> the modules it imports; parsed when a test first asks (0.8 s of CPU: made at
    import, it was paid by every test process as it collected the tests)."""
    return {name: imports(path) for name, path in MODULES.items()}


def top(name: str) -> str:
    return name.split(".")[0]


def test_every_top_level_package_has_a_layer():
    assert {top(m) for m in MODULES} <= set(RANK), set(map(top, MODULES)) - set(RANK)


def test_no_import_points_up_a_layer():
    upward = [f"{m} -> {d}" for m, deps in graph().items() for d in deps
              if RANK[top(d)] > RANK[top(m)]]
    assert not upward, "imports pointing up a layer:\n" + "\n".join(sorted(upward))


def test_runtime_and_models_import_only_what_their_fmus_bundle():
    """runtime: itself; a model folder: the runtime and itself (fmu/build.py bundles exactly
    that); the registry models/catalog.py is not bundled and may import any model."""
    wrong = []
    for m, deps in graph().items():
        if top(m) == "runtime":
            wrong += [f"{m} -> {d}" for d in deps if top(d) != "runtime"]
        elif top(m) == "models" and m.count(".") >= 1 and m != "models.catalog":
            folder = m.split(".")[1]
            wrong += [f"{m} -> {d}" for d in deps if top(d) != "runtime"
                      and not d.startswith(f"models.{folder}")]
    assert not wrong, "\n".join(wrong)


def strongly_connected(graph: dict[str, set[str]]) -> list[list[str]]:
    """Tarjan's algorithm: the cycles of the import graph (components with > 1 module)."""
    index, low, stack, on, out, counter = {}, {}, [], set(), [], [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in graph.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                out.append(sorted(component))

    for v in graph:
        if v not in index:
            visit(v)
    return out


def test_no_import_cycle():
    cycles = strongly_connected(graph())
    assert not cycles, "import cycles: " + "; ".join(" <-> ".join(c) for c in cycles)


def test_the_checker_sees_a_cycle_and_an_upward_import():
    """The checks above can fail: a made-up graph with a cycle is caught, and the real graph
    holds imports the rank table orders (runtime is imported from above)."""
    assert strongly_connected({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert any(top(d) == "runtime" and top(m) != "runtime" for m, deps in graph().items()
               for d in deps)


@pytest.mark.parametrize("model", sorted({m.split(".")[1] for m in MODULES
                                          if m.startswith("models.") and m != "models.catalog"}))
def test_every_model_folder_has_its_readme(model):
    readme = PACKAGE / "models" / model / "README.md"
    assert readme.is_file() and "## " in readme.read_text(), f"{readme}: the model card is missing"


def test_one_place_maps_errors_to_exit_status_2():
    """Every user error derives from crankfmu.errors.CrankfmuError and cli.main alone turns it
    into `error: ...` and exit 2: no command returns 2 on its own or catches its own error."""
    own_exits = [f"{m}:{node.lineno}" for m, path in MODULES.items() if m != "cli"
                 for node in ast.walk(parsed(path))
                 if isinstance(node, ast.Return) and isinstance(node.value, ast.Constant)
                 and node.value.value == 2]
    assert not own_exits, own_exits


@pytest.mark.parametrize("name", ["MechanismError", "MetricError", "EventSpecError", "SweepError",
                                  "CompositionError", "SceneError", "OptionError"])
def test_user_errors_derive_from_the_one_base(name):
    import crankfmu.errors as errors
    from crankfmu.monolithic.composed import CompositionError
    from crankfmu.cosim.events import EventSpecError
    from crankfmu.cosim.metrics import MetricError
    from crankfmu.studies.structure.description import MechanismError
    from crankfmu.studies.sweep import SweepError
    found = {**vars(errors), "CompositionError": CompositionError, "MetricError": MetricError,
             "EventSpecError": EventSpecError, "MechanismError": MechanismError,
             "SweepError": SweepError}
    assert issubclass(found[name], errors.CrankfmuError)


def test_cli_and_the_commands_do_not_import_each_other():
    """cli.py builds the parser and dispatches, naming each command's module (importlib); the
    commands take their shared options from commands/options.py. Before: 18 imports between
    cli.py and commands/, both ways, and run and build lived in cli.py."""
    both_ways = [f"{m} -> {d}" for m, deps in graph().items() for d in deps
                 if (m == "cli" and top(d) == "commands") or (top(m) == "commands" and d == "cli")]
    assert both_ways == []
    from crankfmu.cli import COMMANDS
    modules = {m.split(".")[1] for m in MODULES if m.startswith("commands.")}
    assert set(COMMANDS.values()) == modules - {"options"}
