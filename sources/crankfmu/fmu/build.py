"""Build every FMU into fmus/ with pythonfmu and check each with fmpy validate.

An FMU bundles what it runs and nothing else: the runtime (crankfmu/runtime: the model contract,
the integrator, the pythonfmu adapter) and its model's folder (crankfmu/models/<folder>), as a
package named `crankfmu_rt_<digest>`, where the digest hashes exactly those sources. All Python
FMUs in one process share one interpreter and one sys.modules: FMUs of the same model and build
share the package (same code); FMUs of other models or builds load other packages, so no FMU
ever runs code it was not built with, and an edit to one model rebuilds only that model's FMU.
"""
from __future__ import annotations

import argparse
import functools
import html
import shutil
import sys
import tempfile
import zipfile
from pathlib import Path

from ..models.catalog import FMU_MODELS, model_folder, physics_class
from ..runtime.slave import ModelSlave, variable_table
from . import launcher
from .launcher import compile_launcher, hosting_html, package_binary
from .model_description import model_description, sources_digest

PACKAGE_DIR = Path(__file__).resolve().parents[1]
RUNTIME_DIR = "runtime"  # bundled whole in every FMU, with the model's folder
# The runtime imports all its modules at once: a later FMU of the same build finds them in
# sys.modules even after the FMU that first loaded the package was freed and its files deleted.
RUNTIME_INIT = '''"""crankfmu runtime bundled in FMUs (build {digest})."""
import importlib
import pkgutil

for _module in pkgutil.walk_packages(__path__, prefix=f"{{__name__}}."):
    importlib.import_module(_module.name)
'''
# The FMU's entry script. pythonfmu 0.7.0's binary (findClass, run by every fmi2Instantiate)
# imports this module, runs its code once more with the module's namespace as globals and a
# fresh dict as locals, and then calls Py_DECREF on that namespace, which it only borrowed
# (PyModule_GetDict). One reference per instantiation is thus released that nobody took; the
# namespace is freed while functions still use it as __globals__, and the process crashes
# (second instance of a class-only script, or heap corruption at interpreter exit). The first
# statement takes, on that second run only (locals is not globals there), the reference the
# binary will release. Measured: tests/test_exit_crash.py.
ENTRY_SCRIPT = '''"""FMU entry point written by crankfmu build {digest}."""
if locals() is not globals():  # run by pythonfmu's findClass, which then releases globals()
    import ctypes as _ctypes
    _ctypes.pythonapi.Py_IncRef(_ctypes.py_object(globals()))
# pythonfmu's loader finds the class by the literal text "class X(Fmi2Slave):"
from crankfmu_rt_{digest}.runtime.slave import ModelSlave as Fmi2Slave
from crankfmu_rt_{digest}.models.{module} import {cls} as _Physics


class {model_name}(Fmi2Slave):
    physics_class = _Physics
'''
ZIP_DATE = (1980, 1, 1, 0, 0, 0)  # fixed timestamps: same sources give the same FMU bytes


def _package_files(folder: Path) -> list[Path]:
    return sorted(p for p in folder.rglob("*.py") if "__pycache__" not in p.parts)


# The runtime's FMI adapters: an FMU bundles its own version's and not the other, whose library
# (pythonfmu for FMI 2.0, pythonfmu3 for FMI 3.0) it does not carry.
FMI_ADAPTERS = {2: f"{RUNTIME_DIR}/slave.py", 3: f"{RUNTIME_DIR}/slave3.py"}


def runtime_files(model_name: str | None, fmi_version: int = 2) -> list[tuple[str, bytes]]:
    """(path in the bundle, bytes): the runtime and the model's folder (models/<folder>/), with
    models/__init__.py; nothing else of crankfmu (the catalog, the analyses, the runner). With
    model None, the runtime alone (an FMU whose model is in its entry script). The runtime
    carries the FMI adapter of `fmi_version` only."""
    other = {path for version, path in FMI_ADAPTERS.items() if version != fmi_version}
    paths = [p for p in _package_files(PACKAGE_DIR / RUNTIME_DIR)
             if p.relative_to(PACKAGE_DIR).as_posix() not in other]
    if model_name is not None:
        paths += _package_files(PACKAGE_DIR / "models" / model_folder(model_name))
        paths.append(PACKAGE_DIR / "models" / "__init__.py")
    names = sorted(path.relative_to(PACKAGE_DIR).as_posix() for path in paths)
    return [(name, (PACKAGE_DIR / name).read_bytes()) for name in names]


@functools.lru_cache(maxsize=None)
def current_build_id(model_name: str | None) -> str:
    """Hash of the model's bundled sources: the FMU's version and GUID seed (computed once)."""
    templates = [("<entry script>", ENTRY_SCRIPT.encode()),
                 ("<runtime init>", RUNTIME_INIT.encode()),
                 ("<launcher>", launcher.source_bytes(2))]  # changed: a new build
    return sources_digest(runtime_files(model_name) + templates)


def _write_runtime(dest: Path, model_name: str | None, digest: str) -> Path:
    package = dest / f"crankfmu_rt_{digest}"
    for name, data in runtime_files(model_name):
        target = package / name
        target.parent.mkdir(parents=True, exist_ok=True)
        target.write_bytes(data)
    (package / "__init__.py").write_text(RUNTIME_INIT.format(digest=digest))
    return package


def _write_script(dest: Path, model_name: str, digest: str) -> Path:
    module, cls = FMU_MODELS[model_name].split(":")
    script = dest / f"crankfmu_{digest}_{model_name}.py"
    script.write_text(ENTRY_SCRIPT.format(digest=digest, module=module, cls=cls,
                                          model_name=model_name))
    return script


def model_card_files(model_name: str) -> list[Path]:
    """The model's card: README.md of its folder first, then the folder's other .md files
    (derivations, the hammer beside the rocker unit)."""
    folder = PACKAGE_DIR / "models" / model_folder(model_name)
    readme = folder / "README.md"
    return [readme] * readme.is_file() + sorted(p for p in folder.glob("*.md") if p != readme)


def model_card_html(model_name: str) -> str:
    """documentation/index.html: the model card (models/<folder>/README.md) and a table of
    parameters, effects, inputs and outputs with units."""
    cls = physics_class(model_name)
    rows = []
    for v in variable_table(cls):
        rng = "" if v.min is None and v.max is None else f"[{v.min}, {v.max}]"
        rows.append(f"<tr><td>{v.name}</td><td>{v.causality}</td><td>{v.unit or ''}</td>"
                    f"<td>{v.start if v.start is not None else ''}</td><td>{rng}</td>"
                    f"<td>{html.escape(v.description)}</td></tr>")
    cards = "".join(f"<h2>{path.name}</h2><pre>{html.escape(path.read_text())}</pre>"
                    for path in model_card_files(model_name))
    return (f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>{model_name}</title>"
            f"</head><body><h1>{model_name}</h1><p>{html.escape(cls.description)}</p>"
            f"<p>Source: seed {html.escape(cls.seed)}</p>{cards}<h2>Variables</h2>"
            "<table border='1'><tr><th>name</th><th>causality</th><th>unit</th><th>start</th>"
            f"<th>range</th><th>description</th></tr>{''.join(rows)}</table></body></html>")


def _repack(built: Path, target: Path, model_name: str, slave_class, digest: str) -> None:
    """Rewrite pythonfmu's zip: our modelDescription, the model card, fixed timestamps."""
    entries = {}
    with zipfile.ZipFile(built) as z:
        for info in z.infolist():
            if info.filename != "modelDescription.xml" and not info.is_dir():
                entries[info.filename] = z.read(info)
    entries["modelDescription.xml"] = model_description(
        slave_class, digest, (launcher.host_requirements(), launcher.SEARCH_TEXT))
    entries["documentation/index.html"] = model_card_html(model_name).encode()
    _package_launcher(entries, slave_class.physics_class.model_name)
    with zipfile.ZipFile(target, "w", zipfile.ZIP_DEFLATED) as z:
        for name in sorted(entries):
            info = zipfile.ZipInfo(name, ZIP_DATE)
            info.compress_type = zipfile.ZIP_DEFLATED
            info.external_attr = 0o644 << 16
            z.writestr(info, entries[name])


def _package_launcher(entries: dict[str, bytes], model_identifier: str) -> None:
    """The native launcher in front of pythonfmu's binary (fmu/launcher), and the model card's
    section on hosting the FMU; without a C compiler the binary stays (the card says so)."""
    launcher = compile_launcher()
    package_binary(entries, model_identifier, launcher)
    card = entries["documentation/index.html"].decode()
    entries["documentation/index.html"] = card.replace(
        "</body>", hosting_html(launcher is not None) + "</body>").encode()


def build_fmu(model_name: str, dest: Path) -> Path:
    from pythonfmu.builder import FmuBuilder

    digest = current_build_id(model_name)
    dest.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="crankfmu_build_") as tmp:
        tmp = Path(tmp)
        runtime = _write_runtime(tmp, model_name, digest)
        script = _write_script(tmp, model_name, digest)
        sys.path.insert(0, str(tmp))
        loaded_before = set(sys.modules)  # e.g. the runtime of FMUs of this build already running
        try:
            built = FmuBuilder.build_FMU(script, dest=tmp / "out", project_files=[runtime])
            module = sys.modules[script.stem]
            slave_class = getattr(module, model_name)
            target = dest / f"{model_name}.fmu"
            _repack(built, target, model_name, slave_class, digest)
        finally:
            sys.path.remove(str(tmp))
            for name in [m for m in sys.modules if digest in m and m not in loaded_before]:
                del sys.modules[name]  # what the build imported from the temporary folder
    return target


def validate(fmu: Path) -> list[str]:
    from fmpy.validation import validate_fmu

    return list(validate_fmu(str(fmu)))


def build_all(dest: Path, names=None, check: bool = True) -> list[Path]:
    built = []
    for name in names or FMU_MODELS:
        path = build_fmu(name, dest)
        report(path, validate(path) if check else [])
        built.append(path)
    return built


def report(path: Path, problems: list[str]) -> None:
    """Say what was built and what fmpy validate found; stop when it found anything."""
    status = "ok" if not problems else f"{len(problems)} problem(s)"
    print(f"built {path} ({path.stat().st_size // 1024} KiB): fmpy validate {status}")
    for p in problems:
        print(f"  - {p}")
    if problems:
        raise SystemExit(f"fmpy validate found problems in {path}")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--dest", type=Path, default=Path("fmus"), help="output folder")
    parser.add_argument("models", nargs="*", help=f"FMUs to build (default all: "
                                                  f"{', '.join(FMU_MODELS)})")


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_arguments(parser)
    args = parser.parse_args(argv)
    build_all(args.dest, args.models or None)
