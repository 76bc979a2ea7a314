"""The FMUs in a plain C host (tests/c_host/host.c), compiled here with gcc two ways.

`host` (-DHOST_OWNS_PYTHON, linked with libpython) owns the Python interpreter: it starts Python
before it dlopens an FMU, pointed at this test's Python environment; the FMU's launcher finds the
interpreter running and uses it. `bare_host` does not link libpython and knows nothing of Python
(dlopen and fmi2 calls only, run with `env -i`): the launcher loads libpython and starts Python in
the environment recorded at build time (this test's). Checks:
- every catalog FMU, alone with its start values, gives bit-for-bit the outputs fmpy gives when
  stepping the same FMU in this process (same code, same libraries, same floating-point ops), in
  both hosts;
- the servo press scene wired by the host (Jacobi, 1 ms) agrees with crankfmu's Jacobi master;
- in the bare host, impossible parameters end fmi2ExitInitializationMode with fmi2Error, the
  reason logged, and the instance is freed; an environment without scipy fails at
  fmi2Instantiate with a message naming scipy.
"""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
import sysconfig
import time
from pathlib import Path

import numpy as np
import pytest
from fmpy import read_model_description

from crankfmu.models.catalog import FMU_MODELS
from tests.support.importer_support import real_outputs, step_in_process, unpacked_once

HOST_SOURCE = Path(__file__).resolve().parent / "c_host" / "host.c"
SCENARIOS = Path(__file__).resolve().parents[1] / "scenarios"
N_STEPS = 200  # 0.2 s at the default 1 ms step: enough to pass impacts, clutch and load events


def libpython_flags() -> list[str]:
    """gcc flags that link libpython: the shared library when there is one (also beside a static
    build, e.g. Debian's in LIBPL), else the static archive with its symbols exported so that
    the FMU binary (dlopened later, with undefined Py* symbols) and extension modules see them."""
    cfg = sysconfig.get_config_var
    version = f"{cfg('VERSION')}{getattr(sys, 'abiflags', '')}"
    for folder in dict.fromkeys(filter(None, [cfg("LIBDIR"), cfg("LIBPL")])):
        if (Path(folder) / f"libpython{version}.so").exists():
            return [f"-L{folder}", f"-lpython{version}", f"-Wl,-rpath,{folder}"]
    for folder in filter(None, [cfg("LIBPL"), cfg("LIBDIR")]):
        archive = Path(folder) / (cfg("LIBRARY") or f"libpython{version}.a")
        if archive.exists():
            return [str(archive), "-Wl,--export-dynamic", *(cfg("LIBS") or "").split(),
                    *(cfg("SYSLIBS") or "").split()]
    pytest.skip(f"no libpython{version}.so or .a in LIBDIR={cfg('LIBDIR')} or LIBPL={cfg('LIBPL')}"
                f": this Python ({sys.executable}) cannot be embedded")


@pytest.fixture(scope="module")
def host(tmp_path_factory) -> Path:
    gcc = shutil.which("gcc")
    if gcc is None:
        pytest.skip("gcc not found on PATH: cannot compile the C host")
    include = sysconfig.get_paths()["include"]
    if not (Path(include) / "Python.h").exists():
        pytest.skip(f"Python.h not in {include}: install this Python's development headers")
    exe = tmp_path_factory.mktemp("c_host") / "host"
    cmd = [gcc, "-O2", "-Wall", "-Wextra", "-Werror", "-DHOST_OWNS_PYTHON", "-o", str(exe),
           str(HOST_SOURCE), f"-I{include}", *libpython_flags(), "-ldl", "-lm"]
    done = subprocess.run(cmd, capture_output=True, text=True)
    assert done.returncode == 0, f"{' '.join(cmd)}\n{done.stderr}"
    return exe


@pytest.fixture(scope="module")
def unzipped(tmp_path_factory):
    """Each FMU unpacked once for the module (the hosts only read the folder)."""
    return unpacked_once(tmp_path_factory.mktemp("unzipped"))


def fmu_line(name: str, fmu: Path, unzipped, md=None) -> str:
    """The host's `fmu` line; `md`: the FMU's model description where the caller read it."""
    md = md or read_model_description(str(fmu))
    return f"fmu {name} {unzipped(fmu)} {md.coSimulation.modelIdentifier} {md.guid}"


def run_host(host: Path, config: list[str], tmp: Path, env: dict | None = None,
             returncode: int = 0) -> tuple[list[str], np.ndarray, str]:
    """Run the host on a config (lines); returns (column names, rows, stderr). `env` replaces
    the environment (default: this one without PYTHON* variables)."""
    path = tmp / "host.cfg"
    # The venv's python as program name: Python reads its pyvenv.cfg and adds its site-packages.
    path.write_text("\n".join([f"python {sys.executable}", *config]) + "\n")
    if env is None:
        env = {k: v for k, v in os.environ.items() if not k.startswith("PYTHON")}
    done = subprocess.run([str(host), str(path)], capture_output=True, text=True, env=env,
                          timeout=120)
    assert done.returncode == returncode, f"host exit {done.returncode}:\n{done.stderr[-3000:]}"
    if returncode:
        return [], np.empty((0, 0)), done.stderr
    header, *lines = done.stdout.splitlines()
    rows = np.array([[float(v) for v in line.split(",")] for line in lines])
    return header.split(",")[1:], rows, done.stderr


_FMPY_RUNS: dict = {}


def fmpy_reference(fmu: Path, h: float, rtol: float, model: str):
    """fmpy's run of one FMU alone (step_in_process, N_STEPS steps), computed once per module
    for both C hosts."""
    key = (str(fmu), h, rtol)
    if key not in _FMPY_RUNS:
        _FMPY_RUNS[key] = step_in_process(fmu, h, N_STEPS, rtol, name=model)
    return _FMPY_RUNS[key]


def test_host_embeds_this_python_environment(host, catalog, unzipped, tmp_path):
    """The embedded interpreter is this environment's (same sys.prefix): the FMUs import the same
    numpy/scipy/pythonfmu as fmpy in this process, which the bit-for-bit test relies on."""
    _, _, stderr = run_host(host, [fmu_line("m", catalog["DcServoMotor"], unzipped), "steps 1"],
                            tmp_path)
    expected = f"host: python {sys.version.split()[0]} prefix {sys.prefix}"
    assert expected in stderr.splitlines(), stderr


def every_fmu_alone(host: Path, catalog, unzipped, tmp_path, env: dict | None = None) -> str:
    """All catalog FMUs unconnected in one host process, so each runs alone on its start values
    at its DefaultExperiment's step and tolerance (1 ms and 1e-8 for all): the outputs must be
    fmpy's in this process, bit for bit (same code, same libraries, same inputs, same steps;
    the host prints %.17g, which round-trips exactly). One process for all: a Python start
    and its imports for each FMU were most of this check's time. Returns a summary line."""
    config, columns = [f"step {1e-3!r}", f"steps {N_STEPS}", f"tolerance {1e-8!r}"], {}
    for k, model in enumerate(FMU_MODELS):
        md = read_model_description(str(catalog[model]))
        assert float(md.defaultExperiment.stepSize) == 1e-3, model  # one step for all
        assert float(md.defaultExperiment.tolerance) == 1e-8, model
        config.append(fmu_line(model, catalog[model], unzipped, md))
        outs = real_outputs(md)
        config += [f"output {k} {v.valueReference} {model}.{v.name}" for v in outs]
        columns[model] = [f"{model}.{v.name}" for v in outs]
    wall = time.perf_counter()
    names, rows, _ = run_host(host, config, tmp_path, env=env)
    wall = time.perf_counter() - wall
    worst = 0.0
    for model, cols in columns.items():
        _, ref = fmpy_reference(catalog[model], 1e-3, 1e-8, model)
        got = rows[:, [0] + [1 + names.index(c) for c in cols]]
        assert np.all(np.isfinite(got)), model
        worst = max(worst, float(np.max(np.abs(got - ref))))
        np.testing.assert_array_equal(got, ref, err_msg=model)
    return (f"{len(columns)} FMUs x {N_STEPS} steps in {wall:.2f} s wall incl. Python start; "
            f"max |C - fmpy| = {worst:.3g}")


def test_every_fmu_alone_in_the_c_host_matches_fmpy_bit_for_bit(host, catalog, unzipped,
                                                                tmp_path):
    """In the host that owns Python: the launchers use its running interpreter."""
    print("\nC host: " + every_fmu_alone(host, catalog, unzipped, tmp_path))


def test_servo_press_pair_wired_by_the_c_host_matches_crankfmu_jacobi(host, catalog, unzipped,
                                                                     tmp_path):
    """The host wires DcServoMotor and StephensonPress itself (Jacobi, 1 ms, the scene's
    parameters, effects, inputs and connections) and must agree with crankfmu's Jacobi master."""
    from crankfmu.cosim.runner import RunOptions, run_scene
    from crankfmu.system.load import load_scene

    scene = load_scene(SCENARIOS / "servo_press.toml")
    scene.master.algorithm = "jacobi"
    scene.stop_time = 0.3  # s: the run-up, with the forging load hit near the end
    h = scene.master.step
    scene.record_interval = h
    result = run_scene(scene, RunOptions(out=tmp_path / "jacobi.csv", fmu_dir=catalog["DcServoMotor"].parent,
                                         progress=False))
    order = scene.master.order + [c for c in scene.components if c not in scene.master.order]
    mds = {c: read_model_description(str(catalog[scene.components[c].fmu])) for c in order}
    vr = {c: {v.name: v.valueReference for v in md.modelVariables} for c, md in mds.items()}
    index = {c: k for k, c in enumerate(order)}
    config = [f"step {h!r}", f"steps {round(scene.stop_time / h)}",
              f"tolerance {scene.master.fmu_tolerance!r}"]
    for c in order:
        comp = scene.components[c]
        config.append(fmu_line(c, catalog[comp.fmu], unzipped))
        config += [f"bool {index[c]} {vr[c][name]} {int(name[7:] in comp.effects)}"
                   for name in vr[c] if name.startswith("effect_")]
        config += [f"real {index[c]} {vr[c][p]} {float(v)!r}" for p, v in comp.parameters.items()]
    for target, signal in scene.inputs.items():
        assert len(signal.times) == 1, "the host takes constant inputs only"
        c, var = target.split(".", 1)
        config.append(f"real {index[c]} {vr[c][var]} {signal.values[0]!r}")
    for con in scene.connections:
        (sc, sv), (tc, tv) = con.source.split(".", 1), con.target.split(".", 1)
        config.append(f"link {index[sc]} {vr[sc][sv]} {index[tc]} {vr[tc][tv]}")
    for ref in scene.record:
        c, var = ref.split(".", 1)
        config.append(f"output {index[c]} {vr[c][var]} {ref}")
    names, rows, _ = run_host(host, config, tmp_path)

    expected = result.recorder.rows
    assert names == scene.record and rows.shape == expected.shape
    scale = np.maximum(np.abs(expected), 1e-300)
    worst = np.max(np.abs(rows - expected) / scale)
    print(f"\nservo press, C host Jacobi vs crankfmu Jacobi at {h:g} s, {len(rows) - 1} steps: "
          f"max relative difference {worst:.3g}; w_crank at {scene.stop_time} s = "
          f"{rows[-1, 1 + names.index('press.w_crank')]:.9g} rad/s")
    # The bound: same algorithm, same numbers, 1e-9 relative (zeros must match exactly).
    np.testing.assert_allclose(rows, expected, rtol=1e-9, atol=0.0)
    assert rows[-1, 1 + names.index("press.phi")] > 1.0  # the press really turned (rad)


# -- the bare host: no libpython, nothing preloaded, an empty environment -----------------------
# As `env -i PATH=/usr/bin:/bin`, but for this machine's OPENBLAS_* settings (e.g.
# OPENBLAS_CORETYPE): without them OpenBLAS picks other kernels, and PlanetaryClutchDrive's numbers
# differ from fmpy's in this process in the last bit (4e-16, measured), which has nothing to do
# with the host.
BARE_ENV = {"PATH": "/usr/bin:/bin",
            **{k: v for k, v in os.environ.items() if k.startswith("OPENBLAS_")}}


@pytest.fixture(scope="module")
def bare_host(tmp_path_factory) -> Path:
    """host.c without HOST_OWNS_PYTHON: no Python header, not linked with libpython."""
    gcc = shutil.which("gcc")
    if gcc is None:
        if os.environ.get("CI"):
            raise AssertionError("gcc not found on PATH (CI must have it)")
        pytest.skip("gcc not found on PATH: cannot compile the C host")
    exe = tmp_path_factory.mktemp("bare_host") / "bare_host"
    cmd = [gcc, "-O2", "-Wall", "-Wextra", "-Werror", "-o", str(exe), str(HOST_SOURCE), "-ldl",
           "-lm"]
    done = subprocess.run(cmd, capture_output=True, text=True)
    assert done.returncode == 0, f"{' '.join(cmd)}\n{done.stderr}"
    needed = subprocess.run(["readelf", "-d", str(exe)], capture_output=True, text=True).stdout
    assert "NEEDED" in needed and "libpython" not in needed, needed
    return exe


def test_every_fmu_in_the_bare_c_host_matches_fmpy_bit_for_bit(bare_host, catalog, unzipped,
                                                               tmp_path):
    """In the bare host, in an empty environment: the launchers start Python in the build's
    environment (this one)."""
    print("\nbare C host (no libpython, env -i): "
          + every_fmu_alone(bare_host, catalog, unzipped, tmp_path, env=BARE_ENV))


def test_bare_host_gets_fmi2error_for_impossible_parameters_and_frees(bare_host, catalog,
                                                                      unzipped, tmp_path):
    md = read_model_description(str(catalog["StephensonPress"]))
    l_vr = next(v.valueReference for v in md.modelVariables if v.name == "l")
    config = [fmu_line("press", catalog["StephensonPress"], unzipped), f"real 0 {l_vr} 0.01"]
    _, _, stderr = run_host(bare_host, config, tmp_path, env=BARE_ENV, returncode=3)
    assert "host: fmi2ExitInitializationMode returned status 3 for FMU 0" in stderr  # fmi2Error
    assert "parameter l = 0.01 is not allowed" in stderr  # the reason, logged at error level
    assert "host: freed" in stderr.splitlines()[-1]  # fmi2FreeInstance returned, clean exit


def test_bare_host_without_scipy_fails_at_instantiate_naming_scipy(bare_host, catalog, unzipped,
                                                                   tmp_path, no_scipy_env):
    config = [fmu_line("m", catalog["DcServoMotor"], unzipped), "steps 1"]
    env = {**BARE_ENV, "CRANKFMU_PYTHON": str(no_scipy_env)}
    _, _, stderr = run_host(bare_host, config, tmp_path, env=env, returncode=2)
    assert "fmi2Instantiate returned NULL" in stderr
    message = next(line for line in stderr.splitlines() if "fmi2Instantiate:" in line)
    assert "No module named 'scipy'" in message and str(no_scipy_env) in message
    assert "CRANKFMU_PYTHON" in message  # how to point the FMU at another environment


def test_bare_host_with_no_python_there_fails_at_instantiate_saying_so(bare_host, catalog,
                                                                      unzipped, tmp_path):
    config = [fmu_line("m", catalog["DcServoMotor"], unzipped), "steps 1"]
    nowhere = tmp_path / "no-such-python"
    env = {**BARE_ENV, "CRANKFMU_PYTHON": str(nowhere)}
    _, _, stderr = run_host(bare_host, config, tmp_path, env=env, returncode=2)
    message = next(line for line in stderr.splitlines() if "fmi2Instantiate:" in line)
    assert f"CRANKFMU_PYTHON gives {nowhere}: no python executable there" in message, message


# -- FMUs that travel: the launcher's search for Python when the builder's is not there -----------
@pytest.fixture(scope="module")
def portable_motor(tmp_path_factory) -> Path:
    """The DC motor built portable: no builder's python recorded in the FMU."""
    from crankfmu.fmu import launcher
    from crankfmu.fmu.build import build_fmu

    launcher.set_portable(True)
    try:
        fmu = build_fmu("DcServoMotor", tmp_path_factory.mktemp("portable"))
    finally:
        launcher.set_portable(False)
    import zipfile
    config = zipfile.ZipFile(fmu).read("resources/crankfmu_launcher.txt").decode()
    assert "python =" not in config and "python_version = " in config
    return fmu


def test_a_portable_fmu_finds_python_on_path(bare_host, portable_motor, unzipped, tmp_path):
    """No builder's environment in the FMU, no CRANKFMU_PYTHON, an empty environment: the
    launcher takes the first suitable python on PATH (this environment's bin first) and the
    numbers are fmpy's in this process, bit for bit."""
    config = [fmu_line("m", portable_motor, unzipped), f"step {1e-3!r}", f"steps {N_STEPS}",
              f"tolerance {1e-8!r}"]
    md = read_model_description(str(portable_motor))
    outs = real_outputs(md)
    config += [f"output 0 {v.valueReference} m.{v.name}" for v in outs]
    env = {**BARE_ENV, "PATH": f"{Path(sys.executable).parent}:/usr/bin:/bin"}
    names, rows, _ = run_host(bare_host, config, tmp_path, env=env)
    _, ref = fmpy_reference(portable_motor, 1e-3, 1e-8, "m")
    np.testing.assert_array_equal(rows, ref)


def test_the_search_says_what_it_tried(bare_host, portable_motor, unzipped, tmp_path):
    """A PATH with pythons that will not do: a Python without numpy and scipy (a venv of this
    Python, made empty), and a python of another version (a script answering 3.9): instantiate
    fails, and the message names each candidate and why."""
    import venv
    empty = tmp_path / "empty_venv"
    venv.EnvBuilder(with_pip=False, symlinks=True).create(empty)
    other = tmp_path / "other"
    other.mkdir()
    fake = other / "python3"
    fake.write_text("#!/bin/sh\nprintf '3.9\\n/opt/py39/bin/python3\\n\\n\\n'\n")
    fake.chmod(0o755)
    config = [fmu_line("m", portable_motor, unzipped), "steps 1"]
    env = {**BARE_ENV, "PATH": f"{empty / 'bin'}:{other}"}
    _, _, stderr = run_host(bare_host, config, tmp_path, env=env, returncode=2)
    message = next(line for line in stderr.splitlines() if "fmi2Instantiate:" in line)
    assert "no suitable Python 3.11 found" in message, message
    assert f"{empty / 'bin' / 'python3.11'}: Python package(s) missing: numpy" in message
    assert f"{fake}: is Python 3.9, not 3.11" in message
    assert "(a portable build: no builder's environment recorded)" in message
    assert "CRANKFMU_PYTHON" in message  # how to point the FMU at a Python


def test_portable_builds_are_byte_identical_wherever_the_builder_lies(tmp_path, monkeypatch):
    """Two builders whose environments lie elsewhere (sys.executable differs): portable FMUs of
    both FMI versions are byte-identical; default builds differ only in the `python =` line of
    resources/crankfmu_launcher.txt."""
    from crankfmu.fmu import launcher
    from crankfmu.fmu.build import build_fmu
    from crankfmu.fmu.build_fmi3 import build_fmu3

    def build(where: str, portable: bool) -> dict[str, bytes]:
        monkeypatch.setattr(sys, "executable", f"/{where}/venv/bin/python")
        launcher.set_portable(portable)
        try:
            dest = tmp_path / f"{where}_{portable}"
            paths = [build_fmu("Rotor", dest), build_fmu3("Rotor", dest / "fmi3")]
        finally:
            launcher.set_portable(False)
        return {str(p.relative_to(dest)): p.read_bytes() for p in paths}

    assert build("home/a", True) == build("srv/b", True)
    a, b = build("home/a", False), build("srv/b", False)
    for name in a:
        files_a, files_b = _unzip(a[name]), _unzip(b[name])
        differ = [n for n in files_a if files_a[n] != files_b.get(n)]
        assert differ == ["resources/crankfmu_launcher.txt"], (name, differ)
        assert b"python = /home/a/venv/bin/python\n" in files_a[differ[0]]


def _unzip(data: bytes) -> dict[str, bytes]:
    import io
    import zipfile
    with zipfile.ZipFile(io.BytesIO(data)) as z:
        return {n: z.read(n) for n in z.namelist()}
