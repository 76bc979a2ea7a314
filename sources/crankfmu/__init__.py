"""crankfmu: FMI 2.0 co-simulation components for crank-driven forming machines."""
__version__ = "0.1.0"


def sweep(scene, vary, out, **options):
    """Parameter sweep of a scene; returns the table (crankfmu.studies.sweep.sweep)."""
    from .studies.sweep import sweep as _sweep
    return _sweep(scene, vary, out, **options)
