"""The Python an FMU of crankfmu carries, and the digest that ties its module names to its content.

An FMU carries its code under resources/: a package `crankfmu_rt_<digest>` (the runtime and its
model's folder, fmu/build.py), an entry script `crankfmu_<digest>_<Model>.py`, which
resources/slavemodule.txt names for the library's binary, and the library's Python package
(pythonfmu for FMI 2.0, pythonfmu3 for FMI 3.0; the first FMU loaded in a process provides it to
all of its version). FMI 2.0 and 3.0 FMUs are bundled and checked alike; an FMI 3.0 FMU's GUID
is its instantiationToken. All Python FMUs in a process share one
sys.modules, where a module is known by its name alone: the first FMU to import a name decides
the code every later FMU gets under it. So a name must stand for one content. The digest is a
hash of every file of the bundle (those four) with the digest itself written as MARK wherever it
occurs (a hash cannot contain itself); `read_bundle` recomputes it from an FMU's files before
the FMU is loaded, so an FMU changed after its build (a patched model, a half-written copy) is
refused instead of sharing, or replacing, the code of another FMU of the same name and build.

Bytecode: each module's `__pycache__/<module>.<tag>.pyc` is derived from its source and not
hashed. It is a checked-hash pyc (PEP 552): Python compares the source's hash recorded in it
with the source before using it, so a stale pyc is never run. (A pyc made on purpose to carry
other code under a source's hash would be: the digest guards against changed FMUs, not against
forged bytecode.)
"""
from __future__ import annotations

import functools
import hashlib
import importlib.util
import marshal
import re
import sys
import uuid
import zipfile
from dataclasses import dataclass
from pathlib import PurePosixPath

PACKAGE_PREFIX = "crankfmu_rt_"
MARK = "<digest>"  # the digest's place in the hashed text
ENTRY_MODULE = re.compile(r"crankfmu_([0-9a-f]{12})_([A-Za-z_][A-Za-z0-9_]*)")
RESOURCES = "resources/"
SLAVE_MODULE = "slavemodule.txt"  # the library's binary imports the module named here
# The FMI library's Python side, in every FMU of its version: FMI version -> package name
LIBRARIES = {2: "pythonfmu", 3: "pythonfmu3"}
LIBRARY_FOLDERS = tuple(f"{name}/" for name in LIBRARIES.values())


class BundleError(ValueError):
    """An FMU whose bundled Python does not match the digest in its names."""


def package_name(digest: str) -> str:
    return f"{PACKAGE_PREFIX}{digest}"


def entry_module(digest: str, class_name: str) -> str:
    return f"crankfmu_{digest}_{class_name}"


def _is_bytecode(name: str) -> bool:
    return "__pycache__" in PurePosixPath(name).parts


def digest_of(marked: dict[str, bytes]) -> str:
    """The digest of a bundle written with MARK for its digest: names relative to resources/ ->
    bytes; bytecode is not hashed."""
    h = hashlib.sha256()
    for name in sorted(marked):
        if not _is_bytecode(name):
            h.update(name.encode() + b"\0" + marked[name] + b"\0")
    return h.hexdigest()[:12]


def render(marked: dict[str, bytes], digest: str) -> dict[str, bytes]:
    """The bundle with its digest written in: MARK replaced in names and contents."""
    mark = MARK.encode()
    return {name.replace(MARK, digest): data.replace(mark, digest.encode())
            for name, data in marked.items()}


def _unmark(files: dict[str, bytes], digest: str) -> dict[str, bytes]:
    return {name.replace(digest, MARK): data.replace(digest.encode(), MARK.encode())
            for name, data in files.items()}


def guid(model_name: str, digest: str) -> str:
    """The modelDescription's GUID of a build: fixed by the model's name and the digest."""
    return "{%s}" % uuid.uuid5(uuid.NAMESPACE_URL, f"crankfmu:{model_name}:{digest}")


def bytecode(files: dict[str, bytes]) -> dict[str, bytes]:
    """Checked-hash pycs of every module in `files` (rendered), for this Python. Marshal format 2
    writes no back-references, whose use depends on reference counts in the writing process:
    the same sources give the same bytes in any process (a build is reproducible)."""
    out = {}
    for name, source in files.items():
        path = PurePosixPath(name)
        if path.suffix != ".py" or _is_bytecode(name):
            continue
        pyc = path.parent / "__pycache__" / f"{path.stem}.{sys.implementation.cache_tag}.pyc"
        out[str(pyc)] = _pyc(name, source)
    return out


@functools.lru_cache(maxsize=512)
def _pyc(name: str, source: bytes) -> bytes:
    """The checked-hash pyc of module `name` (its path in the bundle) with `source`, compiled
    once per process: builds share modules (the library's package in every FMU of an FMI
    version, a model's files in its FMI 2.0 and 3.0 FMUs): the catalog's 18 FMUs compile 507
    modules, 291 of them distinct (measured 2026-11-26)."""
    code = compile(source, name, "exec", dont_inherit=True, optimize=0)  # the plain .pyc
    header = importlib.util.MAGIC_NUMBER + (0b11).to_bytes(4, "little")  # hash, checked
    return header + importlib.util.source_hash(source) + marshal.dumps(code, 2)


@dataclass(frozen=True)
class Bundle:
    digest: str
    class_name: str  # the entry script's slave class: the FMU's model identifier

    @property
    def module(self) -> str:
        return entry_module(self.digest, self.class_name)


def find_bundle(zf: zipfile.ZipFile) -> Bundle | None:
    """The crankfmu bundle an FMU (its open zip) names, not yet checked against its digest
    (`read_bundle` does); None for an FMU without one (no crankfmu_ module named in
    slavemodule.txt, no crankfmu_rt_ package). Raises BundleError when the names disagree."""
    try:
        module = zf.read(RESOURCES + SLAVE_MODULE).decode().strip()
    except (KeyError, UnicodeDecodeError):
        module = ""
    packages = {n[len(RESOURCES):].split("/", 1)[0] for n in zf.namelist()
                if n.startswith(RESOURCES + PACKAGE_PREFIX) and "/" in n[len(RESOURCES):]}
    if not module.startswith("crankfmu_") and not packages:
        return None
    match = ENTRY_MODULE.fullmatch(module)
    if match is None or packages != {package_name(match[1])}:
        raise BundleError(f"resources/{SLAVE_MODULE} names {module[:80]!r} beside the "
                          f"package(s) {sorted(packages)}: a crankfmu FMU names "
                          f"crankfmu_<digest>_<Model> and carries crankfmu_rt_<digest> only")
    return Bundle(match[1], match[2])


def read_bundle(zf: zipfile.ZipFile) -> Bundle | None:
    """find_bundle, checked: the bundle's files (the package, the entry script, slavemodule.txt,
    the library's package) must be those its digest stands for (BundleError otherwise)."""
    bundle = find_bundle(zf)
    if bundle is None:
        return None
    package, script = package_name(bundle.digest), f"{bundle.module}.py"
    files = {}
    for name in zf.namelist():
        inner = name[len(RESOURCES):]
        if name.startswith(RESOURCES) and not name.endswith("/") and not _is_bytecode(inner) and (
                inner.startswith((package + "/", *LIBRARY_FOLDERS)) or
                inner in (script, SLAVE_MODULE)):
            files[inner] = zf.read(name)
    if script not in files:
        raise BundleError(f"no entry script resources/{script}")
    if digest_of(_unmark(files, bundle.digest)) != bundle.digest:
        raise BundleError(f"its Python (resources/{package}/, {script}, the FMI library's "
                          f"package) is not the code its digest {bundle.digest} stands for: "
                          "changed after its build, or built by another crankfmu version; "
                          "rebuild it")
    return bundle


def check_description(bundle: Bundle, model_name: str, version: str | None,
                      md_guid: str) -> None:
    """The modelDescription must be the one written with the bundle: the build's GUID (FMI 3.0:
    instantiationToken; a modelDescription from another build or edited by hand is refused:
    neither pythonfmu's fmi2Instantiate nor pythonfmu3's instantiate compares them)."""
    expected = guid(model_name, bundle.digest)
    if md_guid != expected or version != bundle.digest:
        raise BundleError(f"modelDescription.xml has guid {md_guid} and version "
                          f"{version}; its bundled code (build {bundle.digest}) was built with "
                          f"guid {expected} and version {bundle.digest}")
