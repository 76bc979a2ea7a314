"""The native launcher that makes crankfmu's FMUs run in any FMI host (launcher.c for FMI 2.0,
launcher3.c for FMI 3.0, both on python_host.c).

`package_binary` puts into an FMU's files: the launcher, compiled here with the system C compiler,
as the platform binary (FMI 2.0 binaries/linux64/<id>.so, FMI 3.0 binaries/x86_64-linux/<id>.so);
pythonfmu's (pythonfmu3's) binary beside it as <id>_pythonfmu.so (<id>_pythonfmu3.so); and
resources/crankfmu_launcher.txt: the Python version and packages the FMU needs and, unless the
build is portable, the builder's python (this process's: the environment with numpy, scipy and
pythonfmu). Where no C compiler is found the FMU keeps pythonfmu's binary alone, which runs only
in hosts that provide Python; the build says so on stderr and the model card says what it means
(`hosting_html`).

The compile is deterministic: the sources are compiled from fixed relative names in a temporary
folder, without debug information, and stripped (`-s`), so no path or time enters the binary;
the linker's build-id is a hash of the content. The same sources, compiler and flags give the
same bytes. The one line of an FMU that depends on where it was built is `python =` in
resources/crankfmu_launcher.txt (the builder's interpreter, the launcher's first guess after
CRANKFMU_PYTHON); a portable build (`python build.py --portable`, `set_portable(True)`) leaves
it out, so its FMUs are byte-identical wherever the builder's environment lies.
"""
from __future__ import annotations

import functools
import os
import sys
from pathlib import Path  # the others where used: a run reads the sources and names only

HERE = Path(__file__).resolve().parent
SOURCE = HERE / "launcher.c"        # FMI 2.0
SOURCE3 = HERE / "launcher3.c"      # FMI 3.0
SHARED = HERE / "python_host.c"     # included by both
MAIN_SOURCE = {2: SOURCE, 3: SOURCE3}
PLATFORM_DIR = {2: "linux64", 3: "x86_64-linux"}
REAL_SUFFIX = {2: "pythonfmu", 3: "pythonfmu3"}  # <id>_<suffix>.so: the library's own binary
CONFIG_NAME = "crankfmu_launcher.txt"
REQUIRES = ("numpy", "scipy")  # what the bundled runtime imports beyond the standard library
OVERRIDE = "CRANKFMU_PYTHON"
LIB_OVERRIDE = "CRANKFMU_LIBPYTHON"
FLAGS = ["-O2", "-shared", "-fPIC", "-fvisibility=hidden", "-s", "-Wall", "-Wextra"]
_WARNED: list[bool] = []  # the warning once per process
_PORTABLE: list[bool] = [False]  # a portable build records no builder's python
TESTED_HOSTS = (
    "fmpy (simulate_fmu and crankfmu's runner), libcosim (libcosimpy), ecos (ecospy and the "
    "native `ecos` command-line simulator shipped in the ecospy wheel, run from an empty "
    "environment), and a plain C host (crankfmu's tests/c_host/host.c) built two ways: "
    "without libpython (dlopen and fmi2 calls only) and owning a Python interpreter")


def find_compiler() -> list[str] | None:
    """$CC (split like a shell), else the first of cc, gcc, clang on PATH; None if none runs."""
    import shlex
    import shutil
    if os.environ.get("CC"):
        cmd = shlex.split(os.environ["CC"])
        return cmd if shutil.which(cmd[0]) else None
    for name in ("cc", "gcc", "clang"):
        if shutil.which(name):
            return [name]
    return None


def set_portable(portable: bool) -> None:
    """Portable builds leave the builder's python out of resources/crankfmu_launcher.txt: the
    FMUs are then byte-identical wherever the builder's environment lies, and the launcher
    finds Python by CRANKFMU_PYTHON or on PATH only."""
    _PORTABLE[0] = bool(portable)


def sources(fmi_version: int = 2) -> tuple[tuple[str, bytes], ...]:
    """(file name, bytes) of the launcher of `fmi_version`: its main file first, then the shared
    part it includes."""
    main = MAIN_SOURCE[fmi_version]
    return ((main.name, main.read_bytes()), (SHARED.name, SHARED.read_bytes()))


def source_bytes(fmi_version: int = 2) -> bytes:
    """Everything the launcher is compiled from (a build id hashes it: a change rebuilds)."""
    return b"".join(name.encode() + b"\0" + data for name, data in sources(fmi_version))


@functools.lru_cache(maxsize=8)
def _compile(compiler: tuple[str, ...], files: tuple[tuple[str, bytes], ...]) -> bytes:
    """The shared object compiled from `files` (the first is the main file)."""
    import subprocess
    import tempfile
    with tempfile.TemporaryDirectory(prefix="crankfmu_launcher_") as tmp:
        for name, data in files:
            (Path(tmp) / name).write_bytes(data)
        cmd = [*compiler, *FLAGS, "-o", "launcher.so", files[0][0], "-ldl", "-lpthread"]
        done = subprocess.run(cmd, cwd=tmp, capture_output=True, text=True)
        if done.returncode != 0:
            raise SystemExit(f"compiling the FMU launcher failed: {' '.join(cmd)}\n{done.stderr}")
        return (Path(tmp) / "launcher.so").read_bytes()


def compile_launcher(fmi_version: int = 2) -> bytes | None:
    """The launcher's bytes, or None (with a warning on stderr) when no C compiler is found."""
    compiler = find_compiler()
    if compiler is None:
        if _WARNED:
            return None
        _WARNED.append(True)
        print("WARNING: crankfmu build: no C compiler found ($CC, cc, gcc, clang): the FMUs keep "
              "pythonfmu's binary, which runs only in hosts that already run Python 3.11 with "
              "numpy and scipy (fmpy, libcosimpy, ecospy) or that link libpython and start the "
              "interpreter themselves; native hosts (ecos CLI, OMSimulator, Dymola, cosim) "
              "crash on load. Install a C compiler and build again.", file=sys.stderr)
        return None
    return _compile_kept(tuple(compiler), sources(fmi_version))


def _compiler_identity(compiler: tuple[str, ...]) -> str | None:
    """What the compiler says it is (`--version`: name, version, target), or None if it says
    nothing (then its output is not kept)."""
    import subprocess
    try:
        done = subprocess.run([*compiler, "--version"], capture_output=True, text=True,
                              timeout=60)
    except (OSError, subprocess.SubprocessError):
        return None
    return done.stdout if done.returncode == 0 and done.stdout.strip() else None


@functools.lru_cache(maxsize=8)
def _compile_kept(compiler: tuple[str, ...], files: tuple[tuple[str, bytes], ...]) -> bytes:
    """_compile's bytes, kept in the per-user cache folder (crankfmu.fmu.archive.cache_dir) as
    launcher-<key>.so, key = a hash of the compiler's command and identity, FLAGS and the
    sources: a later process that builds an FMU (a stale FMU rebuilt by `crankfmu run`, each
    `python build.py`) reads it instead of compiling again (0.4 s of CPU a compile, 0.005 s
    asking the compiler its version; measured 2026-11-26). The compile is deterministic (the
    module's docstring), so the kept bytes are what a compile gives; they are written whole
    (a temporary file renamed) and only into a folder that is this user's alone."""
    import hashlib

    from ...outputs import OutputError, atomic_write
    from ..archive import cache_dir
    root, identity = cache_dir(), _compiler_identity(compiler)
    if root is None or identity is None:
        return _compile(compiler, files)
    key = hashlib.sha256(repr((compiler, identity, FLAGS, files)).encode()).hexdigest()[:32]
    kept = root / f"launcher-{key}.so"
    try:
        return kept.read_bytes()
    except OSError:  # not kept yet
        pass
    compiled = _compile(compiler, files)
    try:
        atomic_write(kept, lambda f: f.write(compiled))
    except (OSError, OutputError):  # not kept: the next process compiles again
        pass
    return compiled


def python_version() -> str:
    import sysconfig
    return sysconfig.get_config_var("py_version_short") or \
        f"{sys.version_info[0]}.{sys.version_info[1]}"


def builder_python() -> str:
    """The builder's python as a build records it: this interpreter by one name however it was
    started. `python`, `python3` and `python3.11` of an environment are one file, and a process
    knows the name it was started by (sys.executable): `crankfmu run` (a console script, which
    starts python3.11) and `python -m pytest` wrote FMUs that differed in this line alone, and
    the tests after the README's run command failed on them. The versioned name where it is
    this file, else sys.executable."""
    started = sys.executable
    versioned = os.path.join(os.path.dirname(started), f"python{python_version()}")
    try:
        if os.path.samefile(started, versioned):
            return versioned
    except OSError:  # no such name beside it (Windows' python.exe, an embedded interpreter)
        pass
    return started


def launcher_config(model_identifier: str) -> bytes:
    """resources/crankfmu_launcher.txt: what the launcher reads at instantiation."""
    lines = [
        "# crankfmu FMU launcher: the Python the FMU needs, and where the build found it.",
        f"# Search: the host's interpreter, {OVERRIDE}=<python executable or environment "
        f"folder>, the builder's python below, python<version>/python3/python on PATH "
        f"({LIB_OVERRIDE}=<libpython.so> overrides the library).",
        f"model = {model_identifier}",
    ]
    if not _PORTABLE[0]:
        lines.append(f"python = {builder_python()}")
    lines += [f"python_version = {python_version()}", f"requires = {' '.join(REQUIRES)}"]
    return ("\n".join(lines) + "\n").encode()


def package_binary(entries: dict[str, bytes], model_identifier: str,
                   launcher: bytes | None, fmi_version: int = 2) -> None:
    """Put the launcher in front of the library's own binary for Linux in an FMU's `entries`
    (zip name -> bytes), in place; nothing changes when `launcher` is None."""
    folder = f"binaries/{PLATFORM_DIR[fmi_version]}"
    binary = f"{folder}/{model_identifier}.so"
    if launcher is None or binary not in entries:
        return
    entries[f"{folder}/{model_identifier}_{REAL_SUFFIX[fmi_version]}.so"] = entries[binary]
    entries[binary] = launcher
    entries[f"resources/{CONFIG_NAME}"] = launcher_config(model_identifier)


def host_requirements() -> str:
    """One sentence: what a host machine needs to run the FMUs (the model card, the
    modelDescription's annotation)."""
    return (f"Python {python_version()} with {' and '.join(REQUIRES)} (shared library "
            f"libpython{python_version()}.so); Linux x86_64 (win64: pythonfmu's binary, in a "
            f"host that runs that Python)")


SEARCH_TEXT = (
    f"the host process's own interpreter if it runs Python (fmpy, libcosimpy, ecospy); else "
    f"{OVERRIDE} when set (a python executable, or an environment or installation folder); else "
    f"the builder's python recorded in resources/{CONFIG_NAME} if it is still there (a portable "
    f"build records none); else, directory by directory on PATH, python<version>, python3, "
    f"python. A candidate is used when it is that Python version, has a shared libpython and "
    f"imports the packages; each is asked by running it once. {LIB_OVERRIDE} names libpython "
    f"when the candidate's own is not the one to load.")


def hosting_html(launcher: bool, fmi_version: int = 2) -> str:
    """The model card's section "Using the FMUs in other tools"."""
    import html
    version = python_version()
    api = "fmi2Instantiate" if fmi_version == 2 else \
        "fmi3InstantiateCoSimulation/fmi3InstantiateModelExchange"
    error = "fmi2Error" if fmi_version == 2 else "fmi3Error"
    req = ", ".join(REQUIRES)
    if launcher:
        how = (
            f"<p>The FMU's Linux binary is crankfmu's launcher: it runs in any FMI "
            f"{fmi_version}.0 host, also one that does not run Python. <b>The host machine "
            f"needs</b> {html.escape(host_requirements())}.</p>"
            f"<p>Which Python the FMU uses (the search): {html.escape(SEARCH_TEXT)} When no "
            f"suitable Python is found, {api} returns NULL and the log lists every candidate "
            f"it tried and why it was not used.</p>"
            f"<p>An impossible parameter ends the exit from initialization mode with {error} "
            f"and the reason in the log; the instance can then be freed or reset. Messages of "
            f"status error and fatal are always logged, the others when logging is on.</p>"
            f"<p>Example: <code>env -i PATH=/usr/bin:/bin CRANKFMU_PYTHON=/path/to/venv ecos "
            f"simulate --path DcServoMotor.fmu --stepSize 0.001</code> (the ecos binary is in "
            f"the ecospy wheel, <code>ecospy/binaries/ecos</code>; it needs Debian's "
            f"libtbb12).</p>")
    else:
        how = (
            f"<p><b>This FMU was built without a C compiler and carries pythonfmu's binary "
            f"alone.</b> That binary does not link libpython and leaves the Python C API "
            f"undefined: it runs only in hosts that already run Python {version} with {req} "
            f"(fmpy, libcosimpy, ecospy) or that link libpython and start the interpreter "
            f"themselves, pointed at such an environment. Native hosts (the ecos command line, "
            f"OMSimulator, Dymola, libcosim's cosim) crash on load. Rebuild with a C compiler "
            f"to get the launcher.</p>")
    return (f"<h2>Using the FMUs in other tools</h2>{how}"
            f"<p>Hosts tested: {html.escape(TESTED_HOSTS)}.</p>")
