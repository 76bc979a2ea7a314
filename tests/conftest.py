"""Shared fixtures: the FMUs are built once per test session into a temporary folder."""
from __future__ import annotations

from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SCENARIOS = ROOT / "scenarios"


@pytest.fixture(scope="session")
def fmu_dir(tmp_path_factory) -> Path:
    from crankfmu.fmi.build import build_all

    dest = tmp_path_factory.mktemp("fmus")
    build_all(dest, ["DcServoMotor", "StephensonPress"])
    return dest


@pytest.fixture
def servo_scene():
    from crankfmu.scenario import load_scene

    return load_scene(SCENARIOS / "servo_press.toml")
