"""Helpers shared by the importer tests (fmpy, C host, mixing, ecos, SSP): the catalog,
step an FMU, unpack an FMU once, load ecospy."""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest


def require_ecospy() -> None:
    """Skip (outside CI) when ecospy's library cannot load: its binaries need Debian's libtbb12,
    which .ci/run installs; in CI a failure to load is an error, never a skip."""
    try:
        import ecospy  # noqa: F401
    except OSError as err:
        if os.environ.get("CI"):
            raise
        pytest.skip(f"ecospy cannot load its library ({err}); apt-get install libtbb12",
                    allow_module_level=True)


IMPORTER_STOP = 0.2  # s: 200 Jacobi steps of 1 ms, through the start-up transient


def unpacked_once(root: Path):
    """A function giving the folder fmpy's extract makes of an FMU under `root`, once per FMU:
    for hosts that take an unpacked FMU and only read it (fmpy's simulate_fmu takes one as it
    takes the file; given the file it unzips it at every call, 45 ms of CPU, and removes it)."""
    from fmpy import extract

    folders: dict[Path, str] = {}

    def folder(fmu: Path) -> str:
        if fmu not in folders:
            unzip = root / f"{len(folders)}_{fmu.stem}"
            folders[fmu] = str(extract(str(fmu), unzipdir=str(unzip)))
        return folders[fmu]
    return folder


def servo_press_as_the_peers_run_it():
    """The servo press as the peers run it: Jacobi, inputs held over the step, the FMUs' default
    tolerance (1e-8), stopped after IMPORTER_STOP (the importer tests' jacobi_scene fixture,
    tests/conftest.py)."""
    from crankfmu.system.load import load_scene
    scene = load_scene(Path(__file__).resolve().parents[2] / "scenarios" / "servo_press.toml")
    scene.stop_time = IMPORTER_STOP
    scene.master.algorithm, scene.master.extrapolation = "jacobi", 0
    scene.master.fmu_tolerance = 1e-8
    return scene


def relative_deviation(a: np.ndarray, b: np.ndarray) -> float:
    """max |a - b| over the run, relative to max |b| (pointwise relative error is meaningless
    where a signal crosses zero)."""
    return float(np.max(np.abs(a - b)) / max(np.max(np.abs(b)), 1e-300))


def real_outputs(model_description) -> list:
    """The Real outputs (FMI 3.0: Float64)."""
    from crankfmu.fmu.instance3 import value_type
    return [v for v in model_description.modelVariables
            if v.causality == "output" and value_type(v) == "Real"]


def step_together(specs, h: float, n_steps: int, rtol: float) -> dict[str, tuple[list, np.ndarray]]:
    """Instantiate every FMU of `specs` [(instance name, FMU path, start values)] in this process
    with fmpy (through crankfmu's FmuInstance; an FMI 3.0 file as Co-Simulation), initialize
    them, then step them interleaved: doStep(n h, h) for each in turn, n = 0 .. n_steps - 1.
    All Real outputs are sampled after initialization and after every step. Returns
    {name: (output names, rows of [t, outputs])}."""
    from crankfmu.fmu.instance3 import open_fmu

    fmus = {name: open_fmu(name, path) for name, path, _ in specs}
    names = {n: [v.name for v in real_outputs(f.model_description)] for n, f in fmus.items()}
    rows = {n: np.empty((n_steps + 1, len(names[n]) + 1)) for n in fmus}
    try:
        for name, _, start_values in specs:
            fmus[name].instantiate()
            fmus[name].setup(0.0, n_steps * h, rtol)
            fmus[name].set_start_values(start_values or {})
            fmus[name].slave.enterInitializationMode()
            fmus[name].slave.exitInitializationMode()
        read = {n: f.reader(names[n]) for n, f in fmus.items()}
        for n in fmus:
            rows[n][0] = [0.0, *read[n]()]
        for k in range(n_steps):
            for n, fmu in fmus.items():
                fmu.do_step(k * h, h)
                rows[n][k + 1] = [(k + 1) * h, *read[n]()]
    finally:
        for fmu in fmus.values():
            if fmu._component is not None:
                fmu.terminate()
    return {n: (names[n], rows[n]) for n in fmus}


def step_in_process(fmu_path: Path, h: float, n_steps: int, rtol: float,
                    start_values: dict | None = None, name: str = "fmu") -> tuple[list, np.ndarray]:
    """One FMU alone (see step_together): (output names, rows of [t, outputs...])."""
    return step_together([(name, fmu_path, start_values)], h, n_steps, rtol)[name]
