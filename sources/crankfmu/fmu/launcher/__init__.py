"""The native launcher that makes crankfmu's FMUs run in any FMI host (launcher.c).

`package_binary` puts into an FMU's files: the launcher, compiled here with the system C compiler,
as binaries/linux64/<id>.so; pythonfmu's binary beside it as <id>_pythonfmu.so; and
resources/crankfmu_launcher.txt, the Python environment recorded at build time (this process's
python: the environment with numpy, scipy and pythonfmu). Where no C compiler is found the FMU
keeps pythonfmu's binary alone, which runs only in hosts that provide Python; the build says so
on stderr and the model card says what it means (`hosting_html`).

The compile is deterministic: the source is compiled from a fixed relative name in a temporary
folder, without debug information, and stripped (`-s`), so no path or time enters the binary;
the linker's build-id is a hash of the content. The same source, compiler and flags give the same
bytes, so two builds on one machine give byte-identical FMUs.
"""
from __future__ import annotations

import functools
import os
import sys
from pathlib import Path  # the others where used: a run reads SOURCE and CONFIG_NAME only

SOURCE = Path(__file__).resolve().parent / "launcher.c"
CONFIG_NAME = "crankfmu_launcher.txt"
REQUIRES = ("numpy", "scipy")  # what the bundled runtime imports beyond the standard library
OVERRIDE = "CRANKFMU_PYTHON"
LIB_OVERRIDE = "CRANKFMU_LIBPYTHON"
FLAGS = ["-O2", "-shared", "-fPIC", "-fvisibility=hidden", "-s", "-Wall", "-Wextra"]
_WARNED: list[bool] = []  # the warning once per process
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


@functools.lru_cache(maxsize=4)
def _compile(compiler: tuple[str, ...], source: bytes) -> bytes:
    import subprocess
    import tempfile
    with tempfile.TemporaryDirectory(prefix="crankfmu_launcher_") as tmp:
        (Path(tmp) / "launcher.c").write_bytes(source)
        cmd = [*compiler, *FLAGS, "-o", "launcher.so", "launcher.c", "-ldl", "-lpthread"]
        done = subprocess.run(cmd, cwd=tmp, capture_output=True, text=True)
        if done.returncode != 0:
            raise SystemExit(f"compiling the FMU launcher failed: {' '.join(cmd)}\n{done.stderr}")
        return (Path(tmp) / "launcher.so").read_bytes()


def compile_launcher() -> bytes | None:
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
    return _compile(tuple(compiler), SOURCE.read_bytes())


def libpython_path() -> str:
    """This Python's shared libpython, or '' (a static build: the launcher then searches the
    loader's path for libpython<version>.so.1.0)."""
    import sysconfig
    cfg = sysconfig.get_config_var
    for folder in dict.fromkeys(filter(None, [cfg("LIBDIR"), cfg("LIBPL")])):
        for name in filter(None, [cfg("INSTSONAME"), cfg("LDLIBRARY")]):
            if name.endswith(".so") or ".so." in name:
                path = Path(folder) / name
                if path.exists():
                    return str(path)
    return ""


def launcher_config(model_identifier: str) -> bytes:
    """resources/crankfmu_launcher.txt: what the launcher reads at fmi2Instantiate."""
    import sysconfig
    version = sysconfig.get_config_var("py_version_short") or \
        f"{sys.version_info[0]}.{sys.version_info[1]}"
    lines = [
        "# crankfmu FMU launcher: the Python environment recorded at build time.",
        f"# Override with {OVERRIDE}=<python executable or environment folder> "
        f"(and {LIB_OVERRIDE}=<libpython.so>).",
        f"model = {model_identifier}",
        f"python = {sys.executable}",
        f"libpython = {libpython_path()}",
        f"python_version = {version}",
        f"requires = {' '.join(REQUIRES)}",
    ]
    return ("\n".join(lines) + "\n").encode()


def package_binary(entries: dict[str, bytes], model_identifier: str,
                   launcher: bytes | None) -> None:
    """Put the launcher in front of pythonfmu's linux64 binary in an FMU's `entries`
    (zip name -> bytes), in place; nothing changes when `launcher` is None."""
    binary = f"binaries/linux64/{model_identifier}.so"
    if launcher is None or binary not in entries:
        return
    entries[f"binaries/linux64/{model_identifier}_pythonfmu.so"] = entries[binary]
    entries[binary] = launcher
    entries[f"resources/{CONFIG_NAME}"] = launcher_config(model_identifier)


def hosting_html(launcher: bool) -> str:
    """The model card's section "Using the FMUs in other tools"."""
    import html
    version = f"{sys.version_info[0]}.{sys.version_info[1]}"
    env = html.escape(sys.executable)
    req = ", ".join(REQUIRES)
    if launcher:
        how = (
            f"<p>The FMU's linux64 binary is crankfmu's launcher: it runs in any FMI 2.0 host, "
            f"also one that does not run Python. The host machine needs a Python {version} "
            f"(its shared library libpython{version}.so) and an environment with {req}. The "
            f"launcher uses the interpreter of the host process when there is one (fmpy, "
            f"libcosimpy, ecospy); otherwise it loads libpython and starts Python in the "
            f"environment recorded at build time: <code>{env}</code> (see "
            f"<code>resources/{CONFIG_NAME}</code>). To use another environment, set "
            f"<code>{OVERRIDE}</code> to its python executable or its folder (a venv or an "
            f"installation prefix); <code>{LIB_OVERRIDE}</code> names libpython when it is not "
            f"found beside that python. When Python or a package is missing, fmi2Instantiate "
            f"returns NULL and the log says what is missing and where it looked.</p>"
            f"<p>An impossible parameter ends fmi2ExitInitializationMode with fmi2Error and the "
            f"reason in the log; the instance can then be freed or reset. Messages of status "
            f"error and fatal are always logged, the others when logging is on.</p>"
            f"<p>Example: <code>env -i PATH=/usr/bin:/bin ecos simulate --path "
            f"DcServoMotor.fmu --stepSize 0.001</code> (the ecos binary is in the ecospy "
            f"wheel, <code>ecospy/binaries/ecos</code>; it needs Debian's libtbb12).</p>")
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
