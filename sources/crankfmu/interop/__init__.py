"""crankfmu scenes and FMUs in other co-simulation engines, for cross-tool tests and benchmarks.

    plan.py      a scene (or one FMU alone) as engine-neutral facts, checked like `crankfmu run`
    libcosim.py  run a plan in libcosim (libcosimpy)      -> PeerResult (times, named columns)
    ecos.py      run a plan in ecos (ecospy; libtbb12)    -> PeerResult

Both engines run the fixed-step Jacobi scheme, so their results equal crankfmu's Jacobi master at
the same step (tests/test_importer_libcosim.py, tests/test_importer_ecos.py). The engine
packages are imported only when a run starts.
"""
