"""The papers' data (crankfmu.studies.papers, base_link), computed once per test process for
tests/test_papers_figures.py and tests/test_papers_claims.py: one xdist group, so one worker
runs both files. The command tests patch the study functions with these (the command's own
computation is the same call on the same scene), so each is computed once in the suite."""
from __future__ import annotations

import functools
from pathlib import Path

import numpy as np

from crankfmu.studies import base_link, papers
from crankfmu.system.load import load_scene

ROOT = Path(__file__).resolve().parents[2]
PRESS_SCENE = ROOT / "scenarios" / "servo_press.toml"
IMPACT_SCENE = ROOT / "scenarios" / "mo100_impact.toml"
PLANETARY_SCENE = ROOT / "scenarios" / "planetary_engagement.toml"
MASSES = (0.0, 20.0, 80.0, 200.0, 400.0)  # kg: the base link's masses of the claim's sweep

# the real ones, kept before any test patches the module
_DYNAMIC_ERROR_DATA, _FLYWHEEL_DATA = papers.dynamic_error_data, papers.flywheel_data
_IMPACT_DATA, _PLANETARY_DATA = papers.impact_data, papers.planetary_data
_MASS_SWEEP = base_link.mass_sweep


@functools.lru_cache(maxsize=None)
def press_models():
    """(press, motor with the static law, motor with the lag, u0) of the servo press scene."""
    return papers.press_models(load_scene(PRESS_SCENE))


@functools.lru_cache(maxsize=None)
def press_data():
    """(dynamic_error_data, flywheel_data) of the servo press scene."""
    press, m_static, m_lag, u0 = press_models()
    return (_DYNAMIC_ERROR_DATA(press, m_static, m_lag, u0),
            _FLYWHEEL_DATA(press, m_static, u0))


@functools.lru_cache(maxsize=None)
def mass_sweep():
    """base_link.mass_sweep of the servo press scene over MASSES."""
    return _MASS_SWEEP(load_scene(PRESS_SCENE), MASSES)


def mass_sweep_at(scene, masses, cases=base_link.CASES) -> dict:
    """base_link.mass_sweep(scene, masses) for the servo press scene and masses of MASSES: the
    rows of `mass_sweep` at those masses (each mass is computed on its own, so a sweep over
    fewer masses gives these rows)."""
    assert Path(scene.path).resolve() == PRESS_SCENE.resolve() and tuple(cases) == base_link.CASES
    full = mass_sweep()
    keep = np.isin(full[cases[0]]["mass"], np.asarray(masses, dtype=float))
    assert keep.sum() == np.unique(masses).size, f"{masses} not all in {MASSES}"
    return {key: {c: column[keep] for c, column in value.items()} if key in cases else value
            for key, value in full.items()}


def impact_data(k_n=None):
    """papers.impact_data of the MO-100 scene (its own k_n, or k_n [N/m^(3/2)]). The scene's
    own k_n given explicitly is the same run (the parameter set to the value it has): one
    computation for both."""
    if k_n is None:
        k_n = next(c for c in load_scene(IMPACT_SCENE).components.values()
                   if c.fmu == "RockerImpact").parameters["k_n"]
    return _impact_data_at(float(k_n))


@functools.lru_cache(maxsize=None)
def _impact_data_at(k_n: float):
    return _IMPACT_DATA(IMPACT_SCENE, k_n)


def impact_stiffness_data() -> list[dict]:
    """papers.impact_stiffness_data of the MO-100 scene, on the cached impacts."""
    real = papers.impact_data
    papers.impact_data = lambda scene, k_n=None: impact_data(k_n)
    try:
        return papers.impact_stiffness_data(IMPACT_SCENE)
    finally:
        papers.impact_data = real


@functools.lru_cache(maxsize=None)
def planetary_data():
    """papers.planetary_data of the planetary engagement scene."""
    return _PLANETARY_DATA(PLANETARY_SCENE)
