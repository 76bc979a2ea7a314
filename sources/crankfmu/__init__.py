"""crankfmu: FMI 2.0 and 3.0 components for crank-driven forming machines, and a runner.

The Python API (crankfmu/api.py; imported on first use, so `import crankfmu` stays cheap):
simulate, reference, accuracy, compare, sweep, load_scene and Result. No subpackage shares a
name with a function here (the monolithic reference's code is crankfmu.monolithic), so importing
any part of crankfmu leaves these functions in place."""
from .version import __version__  # noqa: F401

__all__ = ["Result", "accuracy", "compare", "load_scene", "reference", "simulate", "sweep"]


def sweep(scene, vary, out=None, **options):
    """Parameter sweep of a scene: a SweepTable (crankfmu.api.sweep: `vary` one
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
    """Error against the reference and wall time per master setting: an AccuracyResult
    (crankfmu.api.accuracy: out, stop_time, parameters, inputs and AccuracyOptions' fields)."""
    from .api import accuracy as _accuracy
    return _accuracy(scene, **options)


def compare(scene_a, scene_b, **options):
    """Run two scenes and compare them: a CompareResult (crankfmu.api.compare: stop_time, out,
    fmu_dir, jobs, scheduler, progress, plot)."""
    from .api import compare as _compare
    return _compare(scene_a, scene_b, **options)


def __getattr__(name):
    if name in ("Result", "load_scene", "simulate"):
        from . import api
        return getattr(api, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(__all__))
