"""Studies of many runs: parameter sweeps, on one executor (this process, a local process pool
or a Dask cluster: `executor.py`). Imported lazily: `import crankfmu` stays cheap."""
from __future__ import annotations


def __getattr__(name):
    if name in ("SweepTable", "Vary", "parse_vary", "expand", "SweepError"):  # the function:
        # crankfmu.sweep (crankfmu.studies.sweep is the module)
        from . import sweep as _sweep
        return getattr(_sweep, name)
    if name in ("Executor", "InProcessExecutor", "LocalPoolExecutor", "DaskExecutor", "make_executor", "RunTask",
                "RunOutput"):
        from . import executor as _executor
        return getattr(_executor, name)
    raise AttributeError(name)
