"""A quick seeded subset of the fuzz campaign (scripts/fuzz.py runs the full one): one scene
file of each of the 56 kinds, the SSP archives of the cheap kinds, a sample of `--set` values
and one hostile output folder of each kind, each through `crankfmu run` in this process. Every
case must end with exit 0 or a clear error (exit 2), write no NaN or inf, write nothing
outside its output folder and leave the files it keeps as they were."""
from __future__ import annotations

import math
import os
import random
import time
from pathlib import Path

import pytest

from crankfmu.cli import main
from tests.support.fuzz.overrides import override_cases
from tests.support.fuzz.outputs import output_cases
from tests.support.fuzz.scenes import KINDS, ROTOR, TEXT_KINDS, scene_cases, snapshot, write_case
from tests.support.fuzz.ssp import ssp_cases

SEED = 16
SLOW_SSP_KINDS = {"fmu_entry_huge", "many_entries", "ssd_huge", "external_ssv_huge"}


@pytest.fixture(scope="module")
def fuzz_fmus(fmu_dir) -> Path:
    return fmu_dir  # the session's catalog: Rotor and ShaftRotor beside the motor and press


def run_case(case: dict, folder: Path, fmus: Path, monkeypatch, capsys) -> tuple[int, str]:
    work = folder / case["id"]
    write_case({**case, "files": {f"work/{n}": d for n, d in case["files"].items()}}, work)
    kept = snapshot(work / "work", case.get("kept", []))
    before = {p for p in work.rglob("*")}
    monkeypatch.chdir(work / "work")
    status = main(["run", case["scene"], "--fmus", str(fmus), "--no-progress",
                   *case.get("args", [])])
    err = capsys.readouterr().err
    assert status in (0, 2), (case["kind"], status, err)
    assert status == 0 or err.startswith("error: "), (case["kind"], err)
    out = os.path.normpath(work / "work" / case.get("out", "results")) + os.sep
    for path in set(work.rglob("*")) - before:  # nowhere but the output folder (and the
        path = os.path.normpath(path) + os.sep   # folders made on the way to it)
        assert path.startswith(out) or out.startswith(path), (case["kind"], path)
    for csv in (work / "work").rglob("*.csv"):
        if not csv.is_file() or csv.is_symlink():
            continue  # a FIFO or a link the case made (and that must be kept)
        for line in csv.read_text().splitlines()[1:]:
            assert all(math.isfinite(float(x)) for x in line.split(",")), (case["kind"], csv)
    assert snapshot(work / "work", case.get("kept", [])) == kept, case["kind"]
    for evil in case.get("evil", []):
        path = Path(evil) if evil.startswith("/") else work / "work" / evil
        assert not path.exists() or path.resolve().parent == (work / "work" / "results").resolve()
    return status, err


def test_one_scene_file_of_each_kind(tmp_path, fuzz_fmus, monkeypatch, capsys):
    start = time.monotonic()
    cases = scene_cases(SEED, len(KINDS) + len(TEXT_KINDS))
    statuses = [run_case(c, tmp_path, fuzz_fmus, monkeypatch, capsys)[0] for c in cases]
    assert len({c["kind"] for c in cases}) >= 30 and statuses.count(2) > len(cases) // 2
    print(f"{len(cases)} scene cases in {time.monotonic() - start:.1f} s")


def test_hostile_ssp_archives(tmp_path, fuzz_fmus, monkeypatch, capsys):
    from crankfmu.system.load import load_scene
    from crankfmu.system.ssp_export import export_ssp
    (tmp_path / "rotor.toml").write_text(ROTOR)
    base = export_ssp(load_scene(tmp_path / "rotor.toml"), tmp_path / "rotor.ssp",
                      fuzz_fmus).read_bytes()
    kinds = 40 - len(SLOW_SSP_KINDS)  # the slow ones (100s of MiB to compress): scripts/fuzz.py
    cases = ssp_cases(SEED, kinds, base, skip=SLOW_SSP_KINDS)
    for case in cases:
        run_case(case, tmp_path, fuzz_fmus, monkeypatch, capsys)
    assert len({c["kind"] for c in cases}) == kinds >= 30


def test_a_sample_of_set_values(tmp_path, fuzz_fmus, monkeypatch, capsys):
    cases = override_cases(fuzz_fmus, models=["Rotor", "ShaftRotor", "StephensonPress"])
    sample = random.Random(SEED).sample(cases, 12)
    for case in sample:
        run_case(case, tmp_path, fuzz_fmus, monkeypatch, capsys)


def test_hostile_output_folders(tmp_path, fuzz_fmus, monkeypatch, capsys):
    """One case of each kind of tests/support/fuzz/outputs.py (issue #27): a FIFO, a link, a
    file or a folder where the output folder or a result goes, a name too long, a folder out
    of reach: exit 0 or a clear error, files only in the output folder, the kept ones kept."""
    cases = output_cases(SEED, 16)
    statuses = {c["kind"]: run_case(c, tmp_path, fuzz_fmus, monkeypatch, capsys)[0]
                for c in cases}
    assert len(statuses) == 16
    assert statuses["out_is_a_fifo"] == statuses["member_is_a_fifo"] == 2
    assert statuses["out_deep"] == statuses["out_existing_with_other_files"] == 0
