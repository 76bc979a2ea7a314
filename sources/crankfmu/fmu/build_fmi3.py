"""Build the FMI 3.0 FMUs (Co-Simulation and Model Exchange in one file) into fmus/fmi3/ and
check each with fmpy validate.

The same model code as the FMI 2.0 FMUs and the same bundle (fmu/build.py, fmu/bundle.py): an
FMU bundles the runtime with its FMI 3.0 adapter (runtime/slave3.py) and its model's folder as a
package `crankfmu_rt_<digest>` and an entry script `crankfmu_<digest>_<Model>.py` naming the
model class, with pythonfmu3's Python package; the digest hashes all of it, the loader checks it
(a patched FMU is refused), the instantiationToken is the build's, the modules' checked-hash
bytecode is in the FMU, and the file is written atomically, as for FMI 2.0. pythonfmu3's binary
comes from the installed pythonfmu3, with crankfmu's FMI 3.0 launcher (fmu/launcher/launcher3.c)
in front of it. The modelDescription is crankfmu's (model_description.model_description_fmi3).

Model Exchange exposes the model's continuous states, and those depend on the effects (an effect
that is off adds no state), while a modelDescription fixes them. So an FMU is built for an
effect set: `fmus/fmi3/<Model>.fmu` for the model's default effects, and, for an effect set
whose states differ, `fmus/fmi3/<Model>__<effect>__<effect>.fmu` (`__no_effects` for none),
built when a scene needs it (system/wiring.py resolve_fmu) or with
`crankfmu build --fmi 3 --effects a,b Model`.
Co-Simulation takes any effects in any of them.
"""
from __future__ import annotations

import functools
from pathlib import Path

from ..models.catalog import FMU_MODELS, physics_class
from . import launcher
from .build import (bundle_on_path, bundle_sources, host, instantiable_class, library_binaries,
                    model_card_html, pack, report, validate)
from .bundle import MARK, digest_of, render

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


def catalog_sources3(model_name: str, effects: tuple[str, ...]) -> dict[str, bytes]:
    """build.bundle_sources of the model's FMI 3.0 FMU for `effects`: the entry script names
    them and their states, so each effect set is its own build."""
    module, cls = FMU_MODELS[model_name].split(":")
    script = ENTRY_SCRIPT.format(digest=MARK, module=module, cls=cls,
                                 model_name=model_name, me_effects=effects,
                                 me_states=states_for(model_name, effects))
    return bundle_sources(model_name, model_name, script, 3)


@functools.lru_cache(maxsize=None)
def current_build_id(model_name: str, effects: tuple[str, ...]) -> str:
    """The digest of the FMU's bundle (fmu/bundle.py): its version and instantiationToken seed,
    computed once per process."""
    return digest_of(catalog_sources3(model_name, effects))


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
    from .model_description import model_description_fmi3

    effects = variant(model_name, effects)
    marked = catalog_sources3(model_name, effects)
    digest = current_build_id(model_name, effects)
    rendered = render(marked, digest)
    entries = {f"resources/{name}": data for name, data in rendered.items()}
    with bundle_on_path(marked, digest) as (tmp, _, script):
        slave_class = instantiable_class(script, model_name, tmp)
        entries["modelDescription.xml"] = model_description_fmi3(slave_class, digest, host())
    entries.update(library_binaries(3, model_name))
    card = model_card_html(model_name).replace("</body>", me_card_html(model_name, effects) +
                                               "</body>")
    dest = Path(dest)
    dest.mkdir(parents=True, exist_ok=True)
    target = dest / fmu_name(model_name, effects)
    pack(target, entries, rendered, model_name, 3, card)
    return target


def fmu_path(model_name: str, fmu_dir: Path, effects=None) -> Path:
    """Where the FMI 3.0 FMU of a catalog model for `effects` lies: fmu_dir/fmi3/<file>."""
    return Path(fmu_dir) / FMI3_DIR / fmu_name(model_name, effects)


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
