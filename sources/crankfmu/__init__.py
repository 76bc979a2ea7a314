"""crankfmu: FMI 2.0 co-simulation components for crank-driven forming machines.

The Python API (crankfmu/api.py; imported on first use, so `import crankfmu` stays cheap):
simulate, reference, accuracy, compare, sweep, load_scene and Result."""
import sys as _sys
import types as _types

from .version import __version__  # noqa: F401

__all__ = ["Result", "accuracy", "compare", "load_scene", "reference", "simulate", "sweep"]
# Functions named like a subpackage or module of crankfmu (crankfmu/reference/, studies/accuracy/,
# compare.py): importing that submodule must not replace the function on the package
_SHADOWED = ("reference",)  # the function crankfmu.reference over the subpackage


def sweep(scene, vary, out=None, **options):
    """Parameter sweep of a scene; returns the table (crankfmu.api.sweep: `vary` one
    "COMP.PARAM=..." string or a list of them; without `out` the sweep runs in a temporary
    folder that is removed, and the table's paths are None)."""
    from .api import sweep as _sweep
    return _sweep(scene, vary, out, **options)


def reference(scene, **options):
    """The scene's monolithic reference as a Result (crankfmu.api.reference: stop_time,
    parameters, inputs, rtol, method, out, progress)."""
    from .api import reference as _reference
    return _reference(scene, **options)


def accuracy(scene, **options):
    """Error against the reference and wall time per master setting (crankfmu.api.accuracy:
    out, stop_time, parameters, inputs and AccuracyOptions' fields)."""
    from .api import accuracy as _accuracy
    return _accuracy(scene, **options)


def compare(scene_a, scene_b, **options):
    """Run two scenes and compare them (crankfmu.api.compare: stop_time, out, fmu_dir, jobs,
    scheduler, progress)."""
    from .api import compare as _compare
    return _compare(scene_a, scene_b, **options)


def __getattr__(name):
    if name in ("Result", "load_scene", "simulate"):
        from . import api
        return getattr(api, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(__all__))


class _Package(_types.ModuleType):
    def __setattr__(self, name, value):
        if name in _SHADOWED and isinstance(value, _types.ModuleType):
            return  # the submodule stays reachable: sys.modules, `from crankfmu.x import y`
        super().__setattr__(name, value)


_sys.modules[__name__].__class__ = _Package
