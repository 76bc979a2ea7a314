"""Shared fixtures: the FMUs are built once per test session into a temporary folder."""
from __future__ import annotations

from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SCENARIOS = ROOT / "scenarios"


def pytest_configure(config) -> None:
    """The FMUs the tests load unpack into a cache of this test run (crankfmu.fmu.archive), not
    the user's; the processes the tests start inherit it (xdist's workers: the controller's)."""
    import os
    import tempfile
    if "CRANKFMU_CACHE_DIR" not in os.environ:
        os.environ["CRANKFMU_CACHE_DIR"] = config._crankfmu_cache = tempfile.mkdtemp(
            prefix="crankfmu-test-fmus-")


def pytest_unconfigure(config) -> None:
    import shutil
    if getattr(config, "_crankfmu_cache", None):
        shutil.rmtree(config._crankfmu_cache, ignore_errors=True)


def pytest_sessionstart(session) -> None:
    """With pytest-xdist (pyproject.toml's addopts: one worker process per core, whole test files
    per worker), the controller brings the repository's fmus/ up to date before the workers
    start. Scenes run without --fmus build their FMUs there on first use: two workers meeting a
    missing FMU at once would both build it (each renames its own whole file over the target,
    so readers are safe, but the work is done twice). Serially nothing changes: the first test
    that needs an FMU builds it."""
    config = session.config
    if hasattr(config, "workerinput") or not getattr(config.option, "numprocesses", None):
        return
    from crankfmu.fmu.build import build_fmu, rebuild_reason
    from crankfmu.models.catalog import FMU_MODELS

    for model in FMU_MODELS:
        if rebuild_reason(ROOT / "fmus" / f"{model}.fmu", model) is not None:  # as resolve_fmu
            build_fmu(model, ROOT / "fmus")


@pytest.fixture(scope="session")
def fmu_dir(tmp_path_factory) -> Path:
    """Every FMU of the catalog, built once for the session and checked with fmpy validate
    (2 s; the test modules used to build their own, 17 builds of up to 9 FMUs). Tests only read
    these files: a test that needs other builds makes them in its own folder."""
    from crankfmu.fmu.build import build_all

    dest = tmp_path_factory.mktemp("fmus")
    build_all(dest)
    return dest


@pytest.fixture(scope="session")
def fmi3_dir(tmp_path_factory) -> Path:
    """Every catalog model's FMI 3.0 FMU (Co-Simulation and Model Exchange, default effects),
    built once for the session and checked with fmpy validate."""
    from crankfmu.fmu.build_fmi3 import build_all3

    dest = tmp_path_factory.mktemp("fmus")
    build_all3(dest)
    return dest / "fmi3"


@pytest.fixture(scope="session")
def catalog(fmu_dir) -> dict[str, Path]:
    """model name -> the session's FMU file (new models are picked up automatically)."""
    from crankfmu.models.catalog import FMU_MODELS

    return {model: fmu_dir / f"{model}.fmu" for model in FMU_MODELS}


@pytest.fixture
def servo_scene():
    from crankfmu.system.load import load_scene

    return load_scene(SCENARIOS / "servo_press.toml")


@pytest.fixture(scope="session")
def no_scipy_env(tmp_path_factory) -> Path:
    """A venv of this Python without scipy: every other package of this environment linked in
    (numpy, fmpy and their dependencies), scipy left out."""
    import subprocess
    import sys
    import sysconfig

    env = tmp_path_factory.mktemp("no_scipy") / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(env)], check=True)
    site = Path(sysconfig.get_paths()["purelib"])
    target = Path(sysconfig.get_paths(vars={"base": str(env), "platbase": str(env)})["purelib"])
    for entry in site.iterdir():
        name = entry.name
        if name.startswith(("scipy", "__editable__", "crankfmu")) or name.endswith(".pth"):
            continue
        (target / name).symlink_to(entry)
    done = subprocess.run([str(env / "bin" / "python"), "-c", "import numpy, scipy"],
                          capture_output=True, text=True)
    assert "No module named 'scipy'" in done.stderr, done.stderr  # numpy is there, scipy not
    return env
