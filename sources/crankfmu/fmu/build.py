"""Build every FMU into fmus/ for pythonfmu's binary and check each with fmpy validate; the
bundle, its digest, bytecode and atomic write that the FMI 3.0 build (fmu/build_fmi3.py) shares.

An FMU bundles what it runs and nothing else: the runtime (crankfmu/runtime: the model contract,
the integrator, the FMI adapter of its version) and its model's folder (crankfmu/models/<folder>),
as a package named `crankfmu_rt_<digest>`, with an entry script `crankfmu_<digest>_<Model>.py`; the
digest hashes exactly those files (fmu/bundle.py), and the loader checks it. All Python FMUs in
one process share one interpreter and one sys.modules: FMUs of the same model and build share the
package (same code); FMUs of other models or builds load other packages, so no FMU ever runs
code it was not built with, and an edit to one model rebuilds only that model's FMU. The
modules' bytecode is in the FMU, so loading it compiles nothing.

A build is written to a temporary file beside its target and renamed over it: an interrupted
build leaves the earlier file or none, never half an FMU, and a process reading the FMU while
another builds it reads one whole file.
"""
from __future__ import annotations

import argparse
import contextlib
import functools
import hashlib
import importlib
import io
import os
import sys
import tempfile
import zipfile
from dataclasses import dataclass
from pathlib import Path

from ..models.catalog import FMU_MODELS, model_folder
from . import launcher
from .bundle import (LIBRARIES, LIBRARY_FOLDERS, MARK, SLAVE_MODULE, check_description,
                     digest_of, entry_module, find_bundle, package_name, render)

PACKAGE_DIR = Path(__file__).resolve().parents[1]
RUNTIME_DIR = "runtime"  # bundled whole in every FMU, with the model's folder
# The runtime imports all its modules at once: a later FMU of the same build finds them in
# sys.modules even after the FMU that first loaded the package was freed and its files deleted.
# The launcher's sources, the modelDescription writer and the model card are named here so that
# a new launcher, writer or card is a new build (the FMU carries all three).
RUNTIME_INIT = '''"""crankfmu runtime bundled in FMUs (build {digest}).

Built with the FMU launcher whose sources have SHA-256 {launcher}, the modelDescription
writer whose model_description.py has SHA-256 {writer} and the model card whose files have
SHA-256 {card}.
"""
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


def bundle_sources(model_name: str | None, class_name: str, entry_script: str,
                   fmi_version: int = 2) -> dict[str, bytes]:
    """An FMU's Python, names relative to resources/, with bundle.MARK for its digest: the
    package (runtime_files(model_name, fmi_version) and its __init__), the entry script
    `entry_script` (written with MARK for the digest) defining the slave class `class_name`,
    slavemodule.txt naming it, and the FMI library's package (pythonfmu, pythonfmu3) as its
    builder copies it."""
    package = package_name(MARK)
    files = {f"{package}/{name}": data for name, data in runtime_files(model_name, fmi_version)}
    files[f"{package}/__init__.py"] = RUNTIME_INIT.format(
        digest=MARK, launcher=hashlib.sha256(launcher.source_bytes(fmi_version)).hexdigest(),
        writer=hashlib.sha256((PACKAGE_DIR / "fmu" / "model_description.py").read_bytes()
                              ).hexdigest(),
        card=_card_digest(model_name)).encode()
    files[f"{entry_module(MARK, class_name)}.py"] = entry_script.encode()
    files[SLAVE_MODULE] = entry_module(MARK, class_name).encode()
    library = library_folder(fmi_version)
    files.update({f"{LIBRARIES[fmi_version]}/{name}": (library / name).read_bytes()
                  for name in sorted(os.listdir(library))
                  if name.endswith(".py") and not name.startswith(".")})  # as its glob
    return files


def library_folder(fmi_version: int) -> Path:
    """The installed package of the FMI library (pythonfmu for FMI 2.0, pythonfmu3 for 3.0): the
    first on sys.path that carries its binaries (resources/binaries/). Not what `import` finds:
    in a process that has loaded an FMU of that version, the FMU's copy of the package (its
    Python files only) is first on sys.path and in sys.modules. Looked up, not imported."""
    name = LIBRARIES[fmi_version]
    for entry in sys.path:
        folder = Path(entry or ".") / name
        if (folder / "__init__.py").is_file() and (folder / "resources" / "binaries").is_dir():
            return folder
    raise SystemExit(f"building FMI {fmi_version}.0 FMUs needs {name} (pip install {name}; "
                     "pyproject.toml gives the version)")


def catalog_sources(model_name: str) -> dict[str, bytes]:
    """bundle_sources of a catalog model, with the generated entry script."""
    module, cls = FMU_MODELS[model_name].split(":")
    script = ENTRY_SCRIPT.format(digest=MARK, module=module, cls=cls, model_name=model_name)
    return bundle_sources(model_name, model_name, script)


@functools.lru_cache(maxsize=None)
def current_build_id(model_name: str) -> str:
    """The digest of the model's bundle (fmu/bundle.py): the FMU's version and GUID seed,
    computed once per process."""
    return digest_of(catalog_sources(model_name))


def write_bundle(dest: Path, marked: dict[str, bytes], digest: str) -> tuple[Path, Path]:
    """The bundle rendered with `digest` into `dest` (but slavemodule.txt and the library's
    package, which the import does not need), with its checked-hash bytecode (bundle.bytecode:
    what the FMU carries): the build imports it without compiling it a second time; returns
    (package folder, entry script)."""
    from .bundle import bytecode

    rendered = render(marked, digest)
    written = {name: data for name, data in rendered.items()
               if name != SLAVE_MODULE and not name.startswith(LIBRARY_FOLDERS)}
    for name, data in {**written, **bytecode(written)}.items():
        (dest / name).parent.mkdir(parents=True, exist_ok=True)
        (dest / name).write_bytes(data)
    return dest / package_name(digest), dest / f"{rendered[SLAVE_MODULE].decode()}.py"


@contextlib.contextmanager
def bundle_on_path(marked: dict[str, bytes], digest: str):
    """The bundle written into a temporary folder first on sys.path (write_bundle): yields
    (folder, package folder, entry script); afterwards the folder is off sys.path and gone, and
    what was imported from it is out of sys.modules (the runtime of FMUs of this build already
    running stays)."""
    with tempfile.TemporaryDirectory(prefix="crankfmu_build_") as tmp:
        package, script = write_bundle(Path(tmp), marked, digest)
        sys.path.insert(0, tmp)
        loaded_before = set(sys.modules)
        try:
            yield Path(tmp), package, script
        finally:
            sys.path.remove(tmp)
            for name in [m for m in sys.modules if digest in m and m not in loaded_before]:
                del sys.modules[name]


def model_card_files(model_name: str) -> list[Path]:
    """The model's card: README.md of its folder first, then the folder's other .md files
    (derivations, the hammer beside the rocker unit)."""
    folder = PACKAGE_DIR / "models" / model_folder(model_name)
    readme = folder / "README.md"
    return [readme] * readme.is_file() + sorted(p for p in folder.glob("*.md") if p != readme)


def _card_digest(model_name: str | None) -> str:
    """SHA-256 of the model card's files, each name and text (model_card_files; none for a model
    outside the catalog, whose FMU has no card)."""
    digest = hashlib.sha256()
    for path in model_card_files(model_name) if model_name in FMU_MODELS else []:
        text = path.read_bytes()
        digest.update(f"{path.name}\0{len(text)}\0".encode() + text)
    return digest.hexdigest()


def model_card_html(model_name: str) -> str:
    """documentation/index.html: the model card (models/<folder>/README.md) and a table of
    parameters, effects, inputs and outputs with units."""
    import html

    from ..models.catalog import physics_class
    from ..runtime.slave_core import variable_table
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


def library_binaries(fmi_version: int, model_identifier: str) -> dict[str, bytes]:
    """zip name -> bytes of the FMI library's binaries for every platform it carries, named as
    the FMU's (binaries/<platform>/<model_identifier>.so, .dll, .dylib), from the installed
    package (library_folder). Not from pythonfmu's builder: it copies the binaries beside the
    `pythonfmu` package that is imported, and in a process that has run an FMU that is the FMU's
    copy, Python files only (a build after a run wrote an FMU without binaries)."""
    binaries = library_folder(fmi_version) / "resources" / "binaries"
    return {f"binaries/{f.parent.relative_to(binaries).as_posix()}/{model_identifier}{f.suffix}":
            f.read_bytes()
            for f in sorted(binaries.rglob("*")) if f.suffix in (".so", ".dll", ".dylib")}


def host() -> tuple[str, str]:
    """(requirements, search) of the modelDescription's host annotation."""
    return launcher.host_requirements(), launcher.SEARCH_TEXT


def pack(target: Path, entries: dict[str, bytes], rendered: dict[str, bytes],
         model_identifier: str, fmi_version: int, card: str | None) -> None:
    """Write an FMU of `fmi_version` from its `entries` (zip name -> bytes) to `target`, with
    the checked-hash bytecode of its `rendered` bundle, the native launcher in front of the
    library's binary, and the model card `card` (if any) with the section on hosting it
    (without a launcher: what that means). Written atomically."""
    from .bundle import bytecode

    entries.update({f"resources/{name}": pyc for name, pyc in bytecode(rendered).items()})
    compiled = launcher.compile_launcher(fmi_version)
    launcher.package_binary(entries, model_identifier, compiled, fmi_version)
    if card is not None:
        entries["documentation/index.html"] = card.replace(
            "</body>", launcher.hosting_html(compiled is not None, fmi_version) + "</body>"
        ).encode()
    write_atomically(target, entries)


def write_atomically(target: Path, entries: dict[str, bytes]) -> None:
    """A zip of `entries` (sorted, fixed timestamps) at `target`, through a temporary file in
    the same folder renamed over it (a reader sees the old file or the new one, whole)."""
    fd, part = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".part", dir=target.parent)
    try:
        with os.fdopen(fd, "wb") as f, zipfile.ZipFile(f, "w", zipfile.ZIP_DEFLATED) as z:
            for name in sorted(entries):
                info = zipfile.ZipInfo(name, ZIP_DATE)
                info.compress_type = zipfile.ZIP_DEFLATED
                info.external_attr = 0o644 << 16
                z.writestr(info, entries[name])
        os.chmod(part, 0o644)  # mkstemp's 0600: the FMU is read like any built file
        os.replace(part, target)
    except BaseException:
        Path(part).unlink(missing_ok=True)
        raise


def build_bundle_fmu(dest: Path, marked: dict[str, bytes], class_name: str,
                     card: str | None = None) -> Path:
    """Build `marked` (bundle_sources) into dest/<class_name>.fmu with pythonfmu; the digest is
    the bundle's (current_build_id for a catalog model)."""
    return _build(dest, marked, class_name, digest_of(marked), card)


def _build(dest: Path, marked: dict[str, bytes], class_name: str, digest: str,
           card: str | None) -> Path:
    """The FMU of bundle `marked`: its files under resources/ as pythonfmu's builder would copy
    them (bundle_sources), our modelDescription, the library's binaries. Not through pythonfmu's
    builder: it copied them into a folder and a zip that we read again and rewrote, with its
    modelDescription replaced (a third of a build's CPU: 67-79 against 49-55 ms per FMU; the
    same files byte for byte, compared for the 9 catalog models, 2026-11-27)."""
    from .model_description import model_description

    rendered = render(marked, digest)
    entries = {f"resources/{name}": data for name, data in rendered.items()}
    with bundle_on_path(marked, digest) as (tmp, _, script):
        slave_class = instantiable_class(script, class_name, tmp)
        entries["modelDescription.xml"] = model_description(slave_class, digest, host())
    model_name = slave_class.physics_class.model_name
    entries.update(library_binaries(2, model_name))
    dest.mkdir(parents=True, exist_ok=True)
    target = dest / f"{class_name}.fmu"
    pack(target, entries, rendered, model_name, 2, card)
    return target


def instantiable_class(script: Path, class_name: str, resources: Path):
    """The slave class `class_name` of the entry script, imported from the bundle on sys.path
    (bundle_on_path); it must instantiate, as the library's binary will (what pythonfmu's
    builder checks before it writes an FMU)."""
    slave_class = getattr(importlib.import_module(script.stem), class_name)
    slave_class(instance_name="build", resources=str(resources))
    return slave_class


def build_fmu(model_name: str, dest: Path) -> Path:
    """The catalog model's FMU, built into dest/<model_name>.fmu."""
    return _build(dest, catalog_sources(model_name), model_name,
                  current_build_id(model_name), model_card_html(model_name))


@dataclass(frozen=True)
class Rebuild:
    """Why a catalog FMU in the FMU folder is built (again)."""

    reason: str
    damaged: bool  # the file there is not a whole build: a notice, not a routine rebuild


def rebuild_reason(path: Path, model_name: str, fmi_version: int = 2,
                   build_id: str | None = None) -> Rebuild | None:
    """None when `path` is a whole build of the model's current sources for `fmi_version`: a
    zip whose bundle matches its digest (fmu/bundle.py), which is the current build id
    (`build_id`; default: the FMI 2.0 one, current_build_id), with the GUID (FMI 3.0: the
    instantiationToken) of that build and this platform's binaries. Otherwise why it must be
    built."""
    from fmpy import platform, platform_tuple, sharedLibraryExtension

    from .archive import checked_fmu, inspect_fmu, parse_safe_xml, read_fmu
    if not path.is_file():
        return Rebuild("FMU missing", False)
    build_id = build_id or current_build_id(model_name)
    checked = (os.fspath(path), fmi_version, build_id, _file_signature(path))
    if checked in _CURRENT_BUILDS:
        return None
    folder = platform if fmi_version == 2 else platform_tuple
    binary = f"binaries/{folder}/{model_name}{sharedLibraryExtension}"
    library_binary = binary.replace(model_name, f"{model_name}_{launcher.REAL_SUFFIX[fmi_version]}",
                                    1)
    try:
        data, key = read_fmu(path)
        with zipfile.ZipFile(io.BytesIO(data)) as zf:
            bundle = find_bundle(zf)
            if bundle is None:
                return Rebuild("not a crankfmu build: no bundled crankfmu package", True)
            if bundle.digest != build_id:
                return Rebuild("sources changed", False)
            found = checked_fmu(key)  # this content loaded and checked before: not again
            if found is not None:
                description = found[1].description
                version, token = description.version, description.guid  # FMI 3.0: the token
            else:
                inspect_fmu(zf, key)  # names, description, and files those of its digest
                root = parse_safe_xml(zf.read("modelDescription.xml"), "modelDescription.xml")
                version = root.get("version")
                token = root.get("guid" if fmi_version == 2 else "instantiationToken")
            check_description(bundle, model_name, version, token)
            names = set(zf.namelist())
            wanted = [binary] + [library_binary] * (
                f"resources/{launcher.CONFIG_NAME}" in names)  # behind the launcher
            missing = [n for n in wanted if n not in names]
            if missing:
                return Rebuild(f"incomplete: no {', '.join(missing)}", True)
    except (OSError, KeyError, ValueError, zipfile.BadZipFile) as err:  # ValueError: refusals
        return Rebuild(f"damaged: {err}", True)
    if checked[-1] is not None:
        _CURRENT_BUILDS.add(checked)
    return None


# (path, FMI version, build id, file signature) of the FMU files rebuild_reason found whole and
# current in this process: a scene's FMUs are checked at every run, and the check reads and
# hashes the whole file (0.8 ms an FMU). The signature (_file_signature) changes with any
# write, replacement or move of the file, which is then checked again.
_CURRENT_BUILDS: set[tuple] = set()


def _file_signature(path: Path) -> tuple | None:
    """What changes when a file is written, replaced or moved: its device and inode, size, and
    modification and status-change times (ns; the latter set by the kernel, not settable
    from user space); None if it cannot be read."""
    try:
        st = os.stat(path)
    except OSError:
        return None
    return (st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns, st.st_ctime_ns)


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
    parser.add_argument("--dest", type=Path, default=Path("fmus"), metavar="DIR",
                        help="folder the FMI 2.0 FMUs are written to (default fmus/; FMI 3.0 "
                             "ones go to DIR/fmi3/)")
    parser.add_argument("models", nargs="*", help=f"FMUs to build (default all: "
                                                  f"{', '.join(FMU_MODELS)})")


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_arguments(parser)
    args = parser.parse_args(argv)
    build_all(args.dest, args.models or None)
