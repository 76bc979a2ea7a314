"""Shared fixtures: the catalog's FMUs, made once per test session (the repository's fmus/ brought
up to date and copied into a temporary folder), and the order of the test files on the workers."""
from __future__ import annotations

from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SCENARIOS = ROOT / "scenarios"


@pytest.hookimpl(trylast=True)  # after pytest's own: its temporary folder exists
def pytest_configure(config) -> None:
    """The FMUs the tests load unpack into a cache of this test run (crankfmu.fmu.archive), not
    the user's; the processes the tests start inherit it (xdist's workers: the controller's).
    It lies in pytest's temporary folder of the session (as the catalog, pytest_sessionstart):
    removed at the session's end, and by pytest's retention of the last three sessions' folders
    if the session was killed (in /tmp itself they stayed for good). So does the temporary
    folder (TMPDIR) of the session's processes: what the tools the tests drive unpack there and
    keep (fmpy's extract, an fmpy.simulate_fmu that raises, ecos's SSP folders: 62 folders a
    run in /tmp before) stays in pytest's folder, however a process ends.
    The process's fork server (tests/support/fresh_python.py, and crankfmu's worker pools in a
    process that runs other threads, as pytest-xdist's workers do) imports fresh_python's
    PRELOAD as it starts.

    crankfmu's bytecode is written before any test process starts (_package_bytecode).

    OpenBLAS runs on one thread (unless OPENBLAS_NUM_THREADS says otherwise), set before numpy
    loads it, for this process and every process the tests start: the tests' matrices are a
    few rows (a Rotor's exact step, the oscillator's exact solution), and on a busy machine
    OpenBLAS's second thread made a 5 x 5 expm take 8 ms of CPU instead of 0.015 ms (waiting
    for a thread the scheduler had not run; test_masters.py: 8.4 s of CPU, 1.4 s on one)."""
    import os
    import tempfile

    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    if not hasattr(config, "workerinput"):  # the workers inherit it
        _package_bytecode()
        # this process's multiprocessing folder (its fork server's socket) in the temporary
        # folder it had: a passing session's folder goes at its end (tmp_path_retention_policy
        # = "failed"), before multiprocessing removes its own at the process's exit
        import multiprocessing.util
        multiprocessing.util.get_temp_dir()
        session_tmp = config._tmp_path_factory.getbasetemp() / "tmp"
        session_tmp.mkdir()
        os.environ["TMPDIR"] = str(session_tmp)
        tempfile.tempdir = None  # read again
    else:
        _rewrite_my_share(config)
    if "CRANKFMU_CACHE_DIR" not in os.environ:
        cache = config._tmp_path_factory.getbasetemp() / "crankfmu-fmus"
        cache.mkdir()
        os.environ["CRANKFMU_CACHE_DIR"] = config._crankfmu_cache = str(cache)
    from tests.support import fresh_python
    fresh_python.declare_preload()  # the fork server's imports, whoever starts it first


def _package_bytecode() -> None:
    """crankfmu's bytecode written beside its sources (`__pycache__`, where Python itself writes
    it when allowed) before the session's processes start. Under PYTHONDONTWRITEBYTECODE=1 (set
    on the project's CI machines) nothing else writes it in a fresh checkout, and each process
    the session starts (the two workers, some 60 interpreters of the command-line, Ctrl-C,
    script and sweep tests, the fork servers) compiled the modules it imports from source:
    6.3 s of CPU in compile over a fresh clone's run, 0.6 s with this (py-spy over every
    process of the run, 2026-11-27). compileall skips what is up to date (0.24 s of CPU the
    first time); an installed package was compiled by pip; a folder that cannot be written is
    left as it is.
    Only the package: a cache folder for every module (PYTHONPYCACHEPREFIX) makes each process
    compile numpy, scipy and the rest again, 72-82 s against 68-72 s."""
    import compileall
    import importlib.util

    spec = importlib.util.find_spec("crankfmu")
    if spec is None or not spec.submodule_search_locations:
        return
    try:
        compileall.compile_dir(spec.submodule_search_locations[0], quiet=2)
    except OSError:
        pass


def _rewrite_my_share(config) -> None:
    """In a pytest-xdist worker, before it collects: pytest's assertion rewriting of this
    worker's share of the session's test files (_my_share), written to pytest's cache of
    rewritten modules (`__pycache__/*-pytest-*.pyc`: what pytest itself writes where bytecode
    may be written, and reads in any case). Each worker imports every test file to collect it,
    and rewrote every one: 1.3 s of CPU each (py-spy over a fresh clone's run, 2026-11-27),
    every run where bytecode is not written (PYTHONDONTWRITEBYTECODE=1, as on the project's CI
    machines) and in every fresh checkout. The workers start together: each rewrites its share
    and reads the others' (a file not written yet when it is imported is rewritten there, as
    before). pytest checks its cache against the file's contents and writes it by rename.
    pytest's private functions, called as its import hook calls them: with a pytest where they
    differ, nothing is written here and the workers rewrite as before."""
    share = _my_share(config)
    if share is None:
        return
    from _pytest.assertion import rewrite
    state = config.stash[rewrite.assertstate_key]
    for source in share:
        pyc = rewritten_pyc(source)
        try:
            if rewrite._read_pyc(source, pyc) is not None:
                continue
            if not rewrite.try_makedirs(pyc.parent):
                return  # a folder that cannot be written: the workers rewrite as before
            key, code = rewrite._rewrite_test(source, config)  # (source's hash or stat, code)
            rewrite._write_pyc(state, code, key, pyc)
        except (OSError, SyntaxError, AttributeError, TypeError):
            return  # the import reports a broken file; another pytest: as before


def _my_share(config) -> list[Path] | None:
    """This pytest-xdist worker's share of the session's test files (tests/test_*.py under the
    session's arguments, sorted): every n-th from the worker's number on. None outside a
    worker, without assertion rewriting, or with a pytest whose rewriting differs."""
    try:
        from _pytest.assertion import rewrite
        needed = ("_read_pyc", "_rewrite_test", "_write_pyc", "try_makedirs", "get_cache_dir",
                  "PYC_TAIL")
        if rewrite.assertstate_key not in config.stash or \
                not all(hasattr(rewrite, name) for name in needed):
            return None
        number = int(config.workerinput["workerid"].removeprefix("gw"))
        count = int(config.workerinput["workercount"])
    except (ImportError, AttributeError, KeyError, ValueError):
        return None
    if config.getoption("assertmode") != "rewrite":
        return None
    here = Path(config.invocation_params.dir)
    files: set[Path] = set()
    for arg in config.args:
        path = (here / arg.split("::")[0]).resolve()
        if path.is_dir():
            files.update(path.rglob("test_*.py"))
        elif path.name.startswith("test_") and path.suffix == ".py":
            files.add(path)
    return sorted(f for f in files if f.parent == ROOT / "tests")[number::count]


def rewritten_pyc(source: Path) -> Path:
    """Where pytest caches the rewritten module of the test file `source`."""
    from _pytest.assertion import rewrite
    return rewrite.get_cache_dir(source) / (source.name[:-3] + rewrite.PYC_TAIL)


def pytest_collection_finish(session) -> None:
    """The test processes collect cyclic garbage less often than Python's default: what exists
    once the tests are collected (numpy, scipy, fmpy, matplotlib, crankfmu, the test modules)
    lives to the session's end and is moved out of the collector's reach (gc.freeze), and a
    collection starts after 20,000 allocations instead of 700 (gc.set_threshold). Before, 3,000
    collections per worker, 19 to 30 of them full ones over some 250,000 objects, took 2.5 and
    4.9 s of CPU in the two workers (a gc.callbacks timer, 2026-11-26). Reference counting frees
    the rest as before; tests that need a collection make one (gc.collect)."""
    import gc
    gc.collect()
    gc.freeze()
    gc.set_threshold(20_000, 10, 10)


def pytest_unconfigure(config) -> None:
    import shutil
    for folder in (getattr(config, "_crankfmu_cache", None),
                   getattr(config, "_crankfmu_catalog", None)):
        if folder:
            shutil.rmtree(folder, ignore_errors=True)


def pytest_sessionstart(session) -> None:
    """With pytest-xdist (pyproject.toml's addopts: one worker process per core, whole test files
    per worker), the controller makes the session's catalog (fmu_dir, fmi3_dir) before the
    workers start, for all of them: each worker built its own (4 s of CPU each), then the
    controller built it in a thread while the workers started (1.6 s of CPU, and the first test
    to need it waited up to 1.4 s). Serially the fixtures make it. Either way it is the
    repository's fmus/ and fmus/fmi3/ brought up to date (_catalog)."""
    config = session.config
    if hasattr(config, "workerinput") or not getattr(config.option, "numprocesses", None):
        return
    catalog = config._tmp_path_factory.getbasetemp() / "crankfmu-catalog"  # as the cache
    config._crankfmu_catalog = str(catalog)  # (pytest_configure); removed at unconfigure
    # the controller runs one thread until xdist starts its workers, after this hook: the
    # builds a fresh checkout needs (18 FMUs, 2.7 s of CPU) may fork a process per core
    _catalog(catalog / "fmus", jobs=config.getoption("numprocesses"))


def _catalog(dest: Path, jobs: int = 1) -> Path:
    """Every catalog model's FMI 2.0 FMU in dest and FMI 3.0 FMU (default effects) in
    dest/fmi3/: copies of the repository's fmus/ and fmus/fmi3/ once those are current, each
    built there first if missing or stale, as a scene's run does (system/wiring.resolve_fmu),
    by `jobs` forked processes when more than one is stale (only from a process that runs no
    other thread). Scenes run without --fmus use those files; with the copies, no test can
    change what another reads. The builds are the same bytes wherever they are written (fmpy
    validate checks them in tests/test_fmu_build.py)."""
    import shutil

    from crankfmu.fmu import build_fmi3
    from crankfmu.models.catalog import FMU_MODELS

    stale = [(model, version) for model in FMU_MODELS for version in (2, 3)
             if _stale(model, version)]
    if jobs > 1 and len(stale) > 1:
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor
        with ProcessPoolExecutor(min(jobs, len(stale)),
                                 mp_context=multiprocessing.get_context("fork")) as pool:
            list(pool.map(_build_repository_fmu, stale))
    else:
        for model, version in stale:
            _build_repository_fmu((model, version))
    (dest / build_fmi3.FMI3_DIR).mkdir(parents=True, exist_ok=True)
    for model in FMU_MODELS:
        shutil.copyfile(_repository_fmu(model, 2), dest / f"{model}.fmu")
        fmi3 = _repository_fmu(model, 3)
        shutil.copyfile(fmi3, dest / build_fmi3.FMI3_DIR / fmi3.name)
    return dest


def _repository_fmu(model: str, version: int) -> Path:
    """The repository's FMU file of `model`, FMI `version` (FMI 3.0: default effects)."""
    from crankfmu.fmu import build_fmi3

    if version == 2:
        return ROOT / "fmus" / f"{model}.fmu"
    return build_fmi3.fmu_path(model, ROOT / "fmus", build_fmi3.variant(model, None))


def _stale(model: str, version: int) -> bool:
    """Is the repository's FMU missing or stale (build.rebuild_reason, as resolve_fmu asks), or
    built by another python than this session's (_built_elsewhere)?"""
    from crankfmu.fmu import build_fmi3
    from crankfmu.fmu.build import rebuild_reason

    path = _repository_fmu(model, version)
    if version == 2:
        reason = rebuild_reason(path, model)
    else:
        build_id = build_fmi3.current_build_id(model, build_fmi3.variant(model, None))
        reason = rebuild_reason(path, model, 3, build_id)
    return reason is not None or _built_elsewhere(path)


def _built_elsewhere(path: Path) -> bool:
    """Does the FMU record a builder's python other than this session's? A run uses such an
    FMU as it is (the host's interpreter runs it), but the tests check the session's builds:
    the python the launcher records, a rebuilt FMU's bytes against the catalog's. fmus/ built
    from another environment (or, before launcher.builder_python, by another name of this
    interpreter) are built again for the session, as a stale file would be."""
    import zipfile

    from crankfmu.fmu import launcher

    try:
        with zipfile.ZipFile(path) as zf:
            config = zf.read(f"resources/{launcher.CONFIG_NAME}").decode()
    except (OSError, KeyError, UnicodeDecodeError, zipfile.BadZipFile):
        return False  # no launcher (no C compiler), or damaged: rebuild_reason's to judge
    recorded = recorded_python(config)
    return recorded is not None and recorded != launcher.builder_python()


def recorded_python(config: str) -> str | None:
    """The builder's python a launcher config (resources/crankfmu_launcher.txt) names, None in
    a portable build's."""
    return next((v for k, _, v in (line.partition(" = ") for line in config.splitlines())
                 if k == "python"), None)


def _build_repository_fmu(item: tuple[str, int]) -> None:
    """Build the repository's FMU (model, FMI version) into fmus/ (or fmus/fmi3/)."""
    from crankfmu.fmu import build_fmi3
    from crankfmu.fmu.build import build_fmu

    model, version = item
    if version == 2:
        build_fmu(model, ROOT / "fmus")
    else:
        build_fmi3.build_fmu3(model, _repository_fmu(model, 3).parent,
                              build_fmi3.variant(model, None))


@pytest.hookimpl(optionalhook=True)
def pytest_configure_node(node) -> None:
    """pytest-xdist, in the controller: each worker gets the folder of the session's catalog."""
    node.workerinput["crankfmu_catalog"] = getattr(node.config, "_crankfmu_catalog", None)


@pytest.fixture(scope="session")
def catalog_dir(request, tmp_path_factory) -> Path:
    """The session's catalog (_catalog): the controller's with pytest-xdist, else made here."""
    made = getattr(request.config, "workerinput", {}).get("crankfmu_catalog")
    if made:  # complete: made before the workers started
        return Path(made) / "fmus"
    return _catalog(tmp_path_factory.mktemp("catalog") / "fmus")


@pytest.fixture(scope="session")
def fmu_dir(catalog_dir) -> Path:
    """Every FMI 2.0 FMU of the catalog, made once for the session (the test modules used to
    build their own, 17 builds of up to 9 FMUs). Tests only read these files: a test that needs
    other builds makes them in its own folder."""
    return catalog_dir


@pytest.fixture(scope="session")
def fmi3_dir(catalog_dir) -> Path:
    """Every catalog model's FMI 3.0 FMU (Co-Simulation and Model Exchange, default effects),
    made once for the session (as fmu_dir)."""
    from crankfmu.fmu.build_fmi3 import FMI3_DIR

    return catalog_dir / FMI3_DIR


# -- pytest-xdist: which worker runs what, and in which order ------------------------------------
# Files that share what a support module computes once run on one worker, one after the other.
SHARED = {"tests/test_papers_figures.py": "papers",   # tests/support/papers_data.py
          "tests/test_papers_claims.py": "papers",
          "tests/test_adaptive_edges.py": "clutch_hammer",  # tests/support/clutch_reference.py
          "tests/test_clutch_hammer.py": "clutch_hammer"}
# Seconds of wall time per unit (a file, named without tests/test_ and .py, or a SHARED name) in
# `python -m pytest`, from a per-test plugin (2026-11-27, a fresh clone): the units go out
# longest first, so that only short ones are left at the end and the two workers finish
# together. Units not listed (under 0.5 s, or new) come after, the most tests first. (With nine
# units listed and the rest by number of tests, files of 1-2 s ran last: the workers ended
# 0.4-1.0 s apart.) Stale figures cost balance only.
UNIT_SECONDS = {
    "fmi3": 12.1, "papers": 9.5, "sweep": 9.2, "large_steps": 8.8, "api": 5.1,
    "runtime_scenes": 5.1, "fmu_build": 5.1, "importer_ecos": 5.0, "importer_c": 4.4,
    "runtime": 3.9, "executor": 3.7, "press_physics": 3.4, "outputs": 3.0, "error_estimate": 2.8,
    "hostile_input": 2.6, "fmu_cache": 2.5, "planetary": 2.5, "accuracy_events": 2.5,
    "companions": 2.0, "launcher": 1.9, "mixing": 1.9, "ctrl_c": 1.9, "masters": 1.8, "cli": 1.7,
    "taylor_coupling": 1.6, "fuzz_quick": 1.5, "clutch_mill_stand": 1.5, "rocker_impact": 1.4,
    "mill_stand_scenes": 1.4, "clutch_hammer": 1.4, "hammer": 1.2, "exit_crash": 1.1,
    "adding_a_model": 1.0, "cli_options": 1.0, "planetary_scenes": 1.0, "effects_off": 1.0,
    "accuracy": 1.0, "fixed_step_edges": 0.9, "importer_fmpy": 0.8, "reference_hybrid": 0.8,
    "ssp": 0.8, "importer_libcosim": 0.8, "matrix_exponential": 0.8, "servo_press_scene": 0.8,
    "layers": 0.7, "speed_loop": 0.6, "dead_centre": 0.6, "reference": 0.6, "compare": 0.6,
    "master_contract": 0.5, "conventional_press": 0.5}


def unit_name(unit: str) -> str:
    """A unit's name in UNIT_SECONDS: a test file's path without tests/test_ and .py, or a
    SHARED name as it is."""
    return unit.removeprefix("tests/test_").removesuffix(".py")


def unit_seconds(unit: str) -> float:
    """UNIT_SECONDS of a unit (a test file's path or a SHARED name); 0 for one not listed."""
    return UNIT_SECONDS.get(unit_name(unit), 0.0)


@pytest.hookimpl(optionalhook=True)
def pytest_xdist_make_scheduler(config, log):
    """--dist loadfile (pyproject.toml) with the files of a SHARED name as one unit, and the
    units longest first (UNIT_SECONDS), then by number of tests (xdist's own order). (The
    xdist_group marks of --dist loadgroup are lost with pytest 9.2 and pytest-xdist 3.8: the
    worker renames item._nodeid, which pytest 9 no longer reads.)"""
    if config.getvalue("dist") != "loadfile":
        return None
    from xdist.scheduler import LoadFileScheduling

    class SharedFilesLongestFirst(LoadFileScheduling):
        ordered = False

        def _split_scope(self, nodeid: str) -> str:
            file = super()._split_scope(nodeid)
            return SHARED.get(file, file)

        def _assign_work_unit(self, node) -> None:
            if not self.ordered:  # the queue is complete before the first unit is assigned
                self.workqueue = type(self.workqueue)(sorted(
                    self.workqueue.items(),
                    key=lambda unit: (-unit_seconds(unit[0]), -len(unit[1]))))
                self.ordered = True
            super()._assign_work_unit(node)

    return SharedFilesLongestFirst(config, log)


@pytest.fixture(scope="session")
def catalog(fmu_dir) -> dict[str, Path]:
    """model name -> the session's FMU file (new models are picked up automatically)."""
    from crankfmu.models.catalog import FMU_MODELS

    return {model: fmu_dir / f"{model}.fmu" for model in FMU_MODELS}


@pytest.fixture(scope="module")
def jacobi_scene():
    """The servo press as the peers run it (tests/support/importer_support.py), for a module:
    the importer tests change its settings and put them back."""
    from tests.support.importer_support import servo_press_as_the_peers_run_it
    return servo_press_as_the_peers_run_it()


@pytest.fixture
def short_tmp():
    """An empty folder with a short path, for a process's temporary folder (TMPDIR) where its
    workers may come from a fork server: the server's socket lies there, and AF_UNIX takes 108
    bytes of path at most (pytest's tmp_path is too long: the workers were then spawned,
    cosim/workers.py). In a folder of its own under /tmp where that exists (what a test puts
    beside it goes there too), removed after the test."""
    import shutil
    import tempfile
    root = Path(tempfile.mkdtemp(prefix="ck-", dir="/tmp" if Path("/tmp").is_dir() else None))
    (root / "t").mkdir()
    yield root / "t"
    shutil.rmtree(root, ignore_errors=True)


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
