"""Python FMUs sharing one process: instances of one FMU, and FMUs from different builds.

All pythonfmu FMUs in a process share one interpreter and one sys.modules. crankfmu bundles its
runtime and model folder as `crankfmu_rt_<digest>` (digest = hash of those sources, the build
id), so
- two instances of one FMU share code but no state: each gives what it gives alone;
- FMUs of two builds load two runtime packages: each runs its own build's code. Build B here is
  built from a copy of the sources with one behavioural change (DcServoMotor's flange_J output
  + 1 kg.m2), so using the wrong build's code cannot go unnoticed.
"""
from __future__ import annotations

import json
import shutil
import zipfile
from pathlib import Path

import numpy as np
import pytest
from fmpy import read_model_description

from crankfmu.fmu import build
from crankfmu.models.catalog import FMU_MODELS
from tests.support import fresh_python
from tests.support.importer_support import step_in_process, step_together

TESTS = Path(__file__).resolve().parent
H, N_STEPS, RTOL = 1e-3, 100, 1e-8
J_MARK = 1.0  # kg.m2 added to flange_J by build B
MARKER = f'''

# test_mixing: build B's behavioural marker (flange_J + {J_MARK} kg.m2)
_original_output_values = DcServoMotor.output_values


def _marked_output_values(self, t, x, u):
    y = np.array(_original_output_values(self, t, x, u), dtype=float)
    y[[v.name for v in self.outputs].index("flange_J")] += {J_MARK}
    return y


DcServoMotor.output_values = _marked_output_values
'''


def build_from_copy(tmp: Path, dest: Path, build_id: str | None = None) -> Path:
    """DcServoMotor built from a copy of the sources carrying MARKER. `build_id` forces the id
    (the control case); by default it is the copy's own digest."""
    package = tmp / "src" / "crankfmu"
    shutil.copytree(build.PACKAGE_DIR, package, ignore=shutil.ignore_patterns("__pycache__"))
    with open(package / "models" / "dc_motor" / "dc_motor.py", "a") as f:
        f.write(MARKER)
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(build, "PACKAGE_DIR", package)
        digest = build_id or build.digest_of(build.catalog_sources("DcServoMotor"))  # its own
        mp.setattr(build, "current_build_id", lambda model: digest)  # the cached real id stays intact
        return build.build_fmu("DcServoMotor", dest)


def run_in_fresh_process(fmus: list[tuple[str, Path]]) -> dict:
    """Load the FMUs in this order in a new interpreter (tests/support/fresh_python.py: no FMU
    loaded before), then step those that loaded; last outputs, the runtime packages it
    imported, and the refusals (name -> message)."""
    script = (
        "import json, sys\n"
        "from crankfmu.fmu.archive import FmuRefused\n"
        "from crankfmu.fmu.instance3 import open_fmu\n"
        "from tests.support.importer_support import step_together\n"
        "specs, refused = [], {}\n"
        "for n, p in json.loads(sys.argv[1]):\n"
        "    try:\n"
        "        open_fmu(n, p)\n"
        "        specs.append((n, p, None))\n"
        "    except FmuRefused as err:\n"
        "        refused[n] = str(err)\n"
        f"res = step_together(specs, {H!r}, {N_STEPS}, {RTOL!r})\n"
        "out = {n: dict(zip(names, rows[-1, 1:].tolist())) for n, (names, rows) in res.items()}\n"
        "rt = sorted(m for m in sys.modules if m.startswith('crankfmu_rt_') and '.' not in m)\n"
        "print(json.dumps({'outputs': out, 'runtimes': rt, 'refused': refused}))\n")
    done = fresh_python.run(script, [json.dumps([(n, str(p)) for n, p in fmus])], timeout=120,
                            cwd=TESTS.parent)  # `python -c` puts the working folder first: tests.*
    assert done.returncode == 0, done.stderr[-3000:]
    return json.loads(done.stdout.splitlines()[-1])


@pytest.mark.parametrize("model", list(FMU_MODELS))
def test_two_instances_of_every_fmu_interleaved_equal_a_lone_instance(model, catalog):
    fmu = catalog[model]
    both = step_together([("a", fmu, None), ("b", fmu, None)], H, N_STEPS, RTOL)
    _, alone = step_in_process(fmu, H, N_STEPS, RTOL)
    # No shared state: stepping another instance in between changes no double.
    np.testing.assert_array_equal(both["a"][1], alone)
    np.testing.assert_array_equal(both["b"][1], alone)


def test_two_instances_with_different_settings_keep_their_own(catalog):
    """Motor a: static law at u = 220 V; motor b: armature lag, u = 110 V, flywheel 0.2 kg.m2.
    Stalled (flange_w = 0), i_a must settle at u/R_a in each (440 A and 220 A)."""
    fmu = catalog["DcServoMotor"]
    a = {"u": 220.0, "effect_electrical_lag": False}
    b = {"u": 110.0, "effect_electrical_lag": True, "J_flywheel": 0.2}
    both = step_together([("a", fmu, a), ("b", fmu, b)], H, N_STEPS, RTOL)
    for name, values in (("a", a), ("b", b)):
        names, rows = both[name]
        _, alone = step_in_process(fmu, H, N_STEPS, RTOL, values)
        np.testing.assert_array_equal(rows, alone)
        # R_a = 0.5 ohm (start value): the stall current u/R_a, exact up to rounding (1e-12)
        assert rows[-1, 1 + names.index("i_a")] == pytest.approx(values["u"] / 0.5, rel=1e-12)
    assert both["b"][1][-1, 1 + both["b"][0].index("flange_J")] == pytest.approx(0.25, rel=1e-15)


@pytest.fixture(scope="module")
def two_builds(catalog, tmp_path_factory) -> tuple[Path, Path]:
    tmp = tmp_path_factory.mktemp("build_b")
    return catalog["DcServoMotor"], build_from_copy(tmp, tmp / "fmus")


def test_builds_differ_in_id_and_guid(two_builds):
    a, b = (read_model_description(str(p)) for p in two_builds)
    assert a.version == build.current_build_id("DcServoMotor")
    assert b.version != a.version and b.guid != a.guid


@pytest.mark.parametrize("order", ["AB", "BA"])
def test_fmus_of_two_builds_in_one_process_each_run_their_own_code(two_builds, order):
    paths = dict(zip("AB", two_builds))
    result = run_in_fresh_process([(k, paths[k]) for k in order])
    out = result["outputs"]
    ids = {k: read_model_description(str(p)).version for k, p in paths.items()}
    print(f"\norder {order}: runtimes loaded {result['runtimes']}; flange_J A = "
          f"{out['A']['flange_J']}, B = {out['B']['flange_J']} kg.m2")
    assert result["runtimes"] == sorted(f"crankfmu_rt_{ids[k]}" for k in "AB")
    # J_rotor = 0.05 kg.m2 (start value); B adds its marker, A must not see it (exact sums)
    assert out["A"]["flange_J"] == 0.05
    assert out["B"]["flange_J"] == 0.05 + J_MARK
    assert {k: v for k, v in out["A"].items() if k != "flange_J"} == \
           {k: v for k, v in out["B"].items() if k != "flange_J"}


def patched_copy(fmu: Path, dest: Path) -> Path:
    """The FMU with MARKER appended to its bundled dc_motor.py, every other byte and name kept
    (a hand patch: unzip, edit, zip). Its bytecode is left as built: Python finds the source
    changed (checked-hash pycs) and compiles the patched source."""
    with zipfile.ZipFile(fmu) as z:
        entries = {i.filename: z.read(i) for i in z.infolist()}
    source = next(n for n in entries if n.endswith("/models/dc_motor/dc_motor.py"))
    entries[source] += MARKER.encode()
    dest.parent.mkdir(parents=True, exist_ok=True)
    with zipfile.ZipFile(dest, "w", zipfile.ZIP_DEFLATED) as z:
        for name, data in entries.items():
            z.writestr(name, data)
    return dest


@pytest.mark.parametrize("fmi", [2, 3])
@pytest.mark.parametrize("order", ["patched first", "genuine first"])
def test_a_patched_fmu_is_refused_and_never_lends_its_code(catalog, fmi3_dir, tmp_path, order,
                                                           fmi):
    """Issue #27: a DcServoMotor patched by hand keeps its names (model, build id, package), so
    in one process whichever loaded first decided the code of both: before, loaded first it
    gave the genuine FMU its flange_J + 1 kg.m2 (and in the servo press, press.phi 9.682
    instead of 4.839 rad at 0.3 s). Now the patched file is refused, naming what is wrong, and
    the genuine one runs its own code. The same for the FMI 3.0 FMU (before its loader shared
    the check: loaded, and the code of whichever was instantiated first ran in both)."""
    genuine = catalog["DcServoMotor"] if fmi == 2 else fmi3_dir / "DcServoMotor.fmu"
    patched = patched_copy(genuine, tmp_path / "patched" / "DcServoMotor.fmu")
    fmus = [("B", patched), ("A", genuine)]
    result = run_in_fresh_process(fmus if order == "patched first" else fmus[::-1])
    assert "is not the code its digest" in result["refused"].get("B", ""), result
    assert result["outputs"]["A"]["flange_J"] == 0.05  # J_rotor's start value, exactly


def test_the_same_build_id_with_other_code_is_refused(two_builds, tmp_path):
    """Build B's code stamped with A's build id gets A's module names: before, in one process
    whichever loaded first won, silently (B ran A's code). Now the forged FMU is refused: its
    code is not what the digest in its names stands for."""
    a = two_builds[0]
    forged = build_from_copy(tmp_path, tmp_path / "fmus",
                             build_id=read_model_description(str(a)).version)
    result = run_in_fresh_process([("A", a), ("B", forged)])
    assert "is not the code its digest" in result["refused"].get("B", ""), result
    assert result["outputs"]["A"]["flange_J"] == 0.05
