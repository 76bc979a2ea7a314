"""Build the FMI 3.0 FMUs (Co-Simulation and Model Exchange in one file) into fmus/fmi3/ and
check each with fmpy validate.

The same model code as the FMI 2.0 FMUs (fmu/build.py): an FMU bundles the runtime with its FMI
3.0 adapter (runtime/slave3.py) and its model's folder as a package `crankfmu_rt_<digest>`, the
entry script names the model class, pythonfmu3's Python package and binary come from the
installed pythonfmu3, and crankfmu's FMI 3.0 launcher (fmu/launcher/launcher3.c) stands in front
of that binary. The modelDescription is crankfmu's (model_description.model_description_fmi3).

Model Exchange exposes the model's continuous states, and those depend on the effects (an effect
that is off adds no state), while a modelDescription fixes them. So an FMU is built for an
effect set: `fmus/fmi3/<Model>.fmu` for the model's default effects, and, for an effect set
whose states differ, `fmus/fmi3/<Model>__<effect>__<effect>.fmu` (`__no_effects` for none),
built when a scene needs it (`fmu_for`) or with `crankfmu build --fmi 3 --effects a,b Model`.
Co-Simulation takes any effects in any of them.
"""
from __future__ import annotations

import functools
import importlib
import os
import shutil
import sys
import tempfile
import zipfile
from pathlib import Path

from ..models.catalog import FMU_MODELS, physics_class
from . import launcher
from .build import (PACKAGE_DIR, RUNTIME_INIT, ZIP_DATE, model_card_html, report, runtime_files,
                    validate)
from .model_description import model_description_fmi3, sources_digest

FMI3_DIR = "fmi3"  # under the FMU folder: fmus/fmi3/
ENTRY_SCRIPT = '''"""FMU entry point written by crankfmu build (FMI 3.0) {digest}."""
# pythonfmu3's loader finds the class by the literal text "class X(Fmi3Slave):"
from crankfmu_rt_{digest}.runtime.slave3 import ModelSlave3 as Fmi3Slave
from crankfmu_rt_{digest}.models.{module} import {cls} as _Physics


class {model_name}(Fmi3Slave):
    physics_class = _Physics
    me_effects = {me_effects!r}
    me_states = {me_states!r}
'''


def default_effects(model_name: str) -> tuple[str, ...]:
    return tuple(sorted(e.name for e in physics_class(model_name).effects if e.default))


def states_for(model_name: str, effects) -> tuple[str, ...]:
    """The model's continuous states with `effects` on (default parameters)."""
    return tuple(physics_class(model_name)(None, sorted(effects)).state_names())


def variant(model_name: str, effects=None) -> tuple[str, ...]:
    """The effect set the FMU for `effects` is built with: the defaults when they give the same
    states (then the default FMU serves), else `effects` itself."""
    defaults = default_effects(model_name)
    if effects is None:
        return defaults
    effects = tuple(sorted(set(effects)))
    return defaults if states_for(model_name, effects) == states_for(model_name, defaults) \
        else effects


def fmu_name(model_name: str, effects=None) -> str:
    """The file name of the FMU for `effects` (None: the defaults)."""
    chosen = variant(model_name, effects)
    if chosen == default_effects(model_name):
        return f"{model_name}.fmu"
    return f"{model_name}__{'__'.join(chosen) or 'no_effects'}.fmu"


@functools.lru_cache(maxsize=None)
def current_build_id(model_name: str, effects: tuple[str, ...]) -> str:
    """Hash of what the FMU is made of: the bundled sources, the templates, the launcher, the
    modelDescription writer and the effect set it is built for."""
    writer = (PACKAGE_DIR / "fmu" / "model_description.py").read_bytes()
    extra = [("<entry script 3>", ENTRY_SCRIPT.encode()), ("<runtime init>", RUNTIME_INIT.encode()),
             ("<launcher 3>", launcher.source_bytes(3)), ("<writer>", writer),
             ("<effects>", repr(effects).encode())]
    return sources_digest(runtime_files(model_name, 3) + extra)


def _bundle(model_name: str, effects: tuple[str, ...], digest: str) -> dict[str, bytes]:
    """resources/: the runtime package, the entry script, pythonfmu3's package."""
    module, cls = FMU_MODELS[model_name].split(":")
    entries = {f"resources/crankfmu_rt_{digest}/{name}": data
               for name, data in runtime_files(model_name, 3)}
    entries[f"resources/crankfmu_rt_{digest}/__init__.py"] = RUNTIME_INIT.format(
        digest=digest).encode()
    script = f"crankfmu3_{digest}_{model_name}"
    entries[f"resources/{script}.py"] = ENTRY_SCRIPT.format(
        digest=digest, module=module, cls=cls, model_name=model_name, me_effects=effects,
        me_states=states_for(model_name, effects)).encode()
    entries["resources/slavemodule.txt"] = script.encode()
    package = installed_pythonfmu3()
    for path in sorted(package.glob("*.py")):
        entries[f"resources/pythonfmu3/{path.name}"] = path.read_bytes()
    binaries = package / "resources" / "binaries"
    entries[f"binaries/x86_64-linux/{model_name}.so"] = \
        (binaries / "x86_64-linux" / "libpythonfmu-export.so").read_bytes()
    entries[f"binaries/x86_64-windows/{model_name}.dll"] = \
        (binaries / "x86_64-windows" / "pythonfmu-export.dll").read_bytes()
    return entries


def installed_pythonfmu3() -> Path:
    """The installed pythonfmu3 package's folder, from its distribution's record: not
    `pythonfmu3.__file__`, which in a process that has loaded an FMI 3.0 FMU may be the copy in
    that FMU's resources (pythonfmu3's binary puts them first on sys.path), without binaries."""
    from importlib.metadata import PackageNotFoundError, distribution
    try:
        folder = Path(distribution("pythonfmu3").locate_file("pythonfmu3"))
    except PackageNotFoundError:
        raise SystemExit("building FMI 3.0 FMUs needs pythonfmu3 (pip install "
                         "pythonfmu3==0.3.4)") from None
    return folder


def _unpack_python(entries: dict[str, bytes]) -> str:
    """A temporary folder with the bundle's Python files, laid out as the FMU's resources/ (to
    import the entry script as the FMU will)."""
    tmp = tempfile.mkdtemp(prefix="crankfmu_build3_")
    for name, data in entries.items():
        if name.startswith("resources/") and name.endswith(".py"):
            target = Path(tmp) / name[len("resources/"):]
            target.parent.mkdir(parents=True, exist_ok=True)
            target.write_bytes(data)
    return tmp


def me_card_html(model_name: str, effects: tuple[str, ...]) -> str:
    """The model card's Model Exchange section: the states and event indicators of this FMU."""
    cls = physics_class(model_name)
    states = states_for(model_name, effects)
    return (f"<h2>FMI 3.0: Co-Simulation and Model Exchange</h2>"
            f"<p>Co-Simulation takes any effects. Model Exchange exposes the continuous states "
            f"of the effects this FMU was built for: {', '.join(effects) or 'none'} "
            f"(states: {', '.join(states) or 'none'}); other effects that change the states "
            f"are refused at the first Model Exchange call, naming the FMU to use. "
            f"{cls.event_slots} event indicators: the current mode's switches (locks, "
            f"break-frees, contact start and end, forging-window edges) and force extrema; "
            f"fmi3UpdateDiscreteStates applies the mode change of the indicator that crossed "
            f"zero. Inputs may jump only in event mode. See docs/fmi3.md.</p>")


def build_fmu3(model_name: str, dest: Path, effects=None) -> Path:
    """The FMI 3.0 FMU of `model_name` for `effects` (None: the defaults) in dest/; written to
    a temporary file and renamed, so a reader never sees half an FMU."""
    effects = variant(model_name, effects)
    digest = current_build_id(model_name, effects)
    entries = _bundle(model_name, effects, digest)
    tmp, script = _unpack_python(entries), entries["resources/slavemodule.txt"].decode()
    sys.path.insert(0, tmp)
    loaded_before = set(sys.modules)
    try:
        slave_class = getattr(importlib.import_module(script), model_name)
        slave_class(instance_name="build", resources=tmp)  # the class must instantiate
        host = (launcher.host_requirements(), launcher.SEARCH_TEXT)
        entries["modelDescription.xml"] = model_description_fmi3(slave_class, digest, host)
    finally:
        sys.path.remove(tmp)
        for name in [m for m in sys.modules if digest in m and m not in loaded_before]:
            del sys.modules[name]
        shutil.rmtree(tmp, ignore_errors=True)
    binary = compile_launcher3()
    launcher.package_binary(entries, model_name, binary, fmi_version=3)
    entries["documentation/index.html"] = model_card_html(model_name).replace(
        "</body>", me_card_html(model_name, effects) +
        launcher.hosting_html(binary is not None, 3) + "</body>").encode()
    dest = Path(dest)
    dest.mkdir(parents=True, exist_ok=True)
    target = dest / fmu_name(model_name, effects)
    write_fmu_zip(target, entries)
    return target


def compile_launcher3() -> bytes | None:
    return launcher.compile_launcher(3)


def write_fmu_zip(target: Path, entries: dict[str, bytes]) -> None:
    """The FMU file from `entries` (zip name -> bytes): sorted names, fixed timestamps and
    modes (the same entries give the same bytes), written beside `target` and renamed onto it."""
    fd, partial = tempfile.mkstemp(prefix=f".{target.name}.", dir=target.parent)
    try:
        with os.fdopen(fd, "wb") as f, zipfile.ZipFile(f, "w", zipfile.ZIP_DEFLATED) as z:
            for name in sorted(entries):
                info = zipfile.ZipInfo(name, ZIP_DATE)
                info.compress_type = zipfile.ZIP_DEFLATED
                info.external_attr = 0o644 << 16
                z.writestr(info, entries[name])
        os.replace(partial, target)
    except BaseException:
        Path(partial).unlink(missing_ok=True)
        raise


def _build_id_of(path: Path) -> str | None:
    from fmpy import read_model_description
    try:
        return read_model_description(str(path)).version
    except Exception:  # an unreadable FMU is rebuilt
        return None


def fmu_for(model_name: str, fmu_dir: Path, effects=None) -> Path:
    """The FMI 3.0 FMU of a catalog model for `effects` in fmu_dir/fmi3/, built when missing or
    stale (what a scene's component with fmi = 3 runs)."""
    chosen = variant(model_name, effects)
    path = Path(fmu_dir) / FMI3_DIR / fmu_name(model_name, chosen)
    if not path.is_file() or _build_id_of(path) != current_build_id(model_name, chosen):
        build_fmu3(model_name, path.parent, chosen)
    return path


def build_all3(dest: Path, names=None, check: bool = True) -> list[Path]:
    """Every model's FMI 3.0 FMU for its default effects, into dest/fmi3/, each validated."""
    built = []
    for name in names or FMU_MODELS:
        path = build_fmu3(name, Path(dest) / FMI3_DIR)
        report(path, validate(path) if check else [])
        built.append(path)
    return built


# -- the build command (python build.py, crankfmu build): FMI 2.0 and FMI 3.0 ---------------------
def add_arguments(parser) -> None:
    """fmu/build.py's arguments (--dest, models) and the FMI version, effects, portability."""
    from .build import add_arguments as add_fmi2_arguments

    add_fmi2_arguments(parser)
    parser.add_argument("--fmi", choices=("2", "3", "both"), default="both",
                        help="FMI version to build: 2 (fmus/), 3 (fmus/fmi3/: Co-Simulation "
                             "and Model Exchange) or both (default)")
    parser.add_argument("--effects", default=None,
                        help="FMI 3.0: the effects (comma separated, 'none' for none) whose "
                             "Model Exchange states the FMUs expose (default: each model's "
                             "default effects)")
    parser.add_argument("--portable", action="store_true",
                        help="record no builder's python in the FMUs: byte-identical wherever "
                             "the build runs; the FMUs then find Python by CRANKFMU_PYTHON or "
                             "on PATH")


def build_selected(dest: Path, models=None, fmi: str = "both", effects: str | None = None,
                   portable: bool = False) -> list[Path]:
    """What add_arguments' options ask for (models None: all); returns the FMU files."""
    from .build import build_all

    launcher.set_portable(portable)
    built = []
    if fmi in ("2", "both"):
        built += build_all(dest, models or None)
    if fmi in ("3", "both"):
        if effects is None:
            built += build_all3(dest, models or None)
        else:
            chosen = [] if effects == "none" else [e.strip() for e in effects.split(",")
                                                   if e.strip()]
            for name in models or FMU_MODELS:
                path = build_fmu3(name, Path(dest) / FMI3_DIR, chosen)
                report(path, validate(path))
                built.append(path)
    return built


def main(argv=None) -> None:
    import argparse

    parser = argparse.ArgumentParser(description="Build every crankfmu FMU (FMI 2.0 into fmus/, "
                                                 "FMI 3.0 into fmus/fmi3/) and validate it")
    add_arguments(parser)
    args = parser.parse_args(argv)
    build_selected(args.dest, args.models, args.fmi, args.effects, args.portable)
