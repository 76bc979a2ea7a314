"""crankfmu: FMI 2.0 co-simulation components for crank-driven forming machines.

The Python API (crankfmu/api.py; imported on first use, so `import crankfmu` stays cheap):
simulate, reference, accuracy, compare, sweep, load_scene and Result."""
__version__ = "0.1.0"

__all__ = ["Result", "accuracy", "compare", "load_scene", "reference", "simulate", "sweep"]


def sweep(scene, vary, out=None, **options):
    """Parameter sweep of a scene; returns the table (crankfmu.studies.sweep.sweep). Without
    `out` the sweep runs in a temporary folder that is removed (the table's paths are None)."""
    from .studies.sweep import sweep as _sweep
    if out is not None:
        return _sweep(scene, vary, out, **options)
    import tempfile
    from pathlib import Path
    with tempfile.TemporaryDirectory(prefix="crankfmu-sweep-") as tmp:
        table = _sweep(scene, vary, Path(tmp), **options)
    table.csv = table.png = None
    return table


def __getattr__(name):
    if name in ("Result", "accuracy", "compare", "load_scene", "reference", "simulate"):
        from . import api
        return getattr(api, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__():
    return sorted(list(globals()) + __all__)
