"""A thin, fast layer over fmpy's FMU2Slave: value references and ctypes buffers prepared once.

fmpy's getReal/setReal build ctypes arrays on every call; a master calls them every step, so
`reader` and `writer` prepare the arrays once and reuse them (see benchmarks/).
"""
from __future__ import annotations

import atexit
import ctypes
import errno
import hashlib
import io
import os
import shutil
import sys
import tempfile
import time
import zipfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from fmpy import platform as fmpy_platform, read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import FMU2Slave, fmi2Real, fmi2ValueReference

FMI2_WARNING = 1  # fmi2Status: a call returning more than fmi2Warning failed


class _DlPhdrInfo(ctypes.Structure):  # the leading fields of glibc's struct dl_phdr_info
    _fields_ = [("dlpi_addr", ctypes.c_void_p), ("dlpi_name", ctypes.c_char_p)]


def _loaded_libraries() -> list[bytes]:
    """Names of the shared objects loaded in this process, as the dynamic loader knows them."""
    names: list[bytes] = []
    callback_type = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.POINTER(_DlPhdrInfo), ctypes.c_size_t,
                                     ctypes.c_void_p)

    def collect(info, size, data) -> int:
        if info.contents.dlpi_name:
            names.append(info.contents.dlpi_name)
        return 0
    ctypes.CDLL(None).dl_iterate_phdr(callback_type(collect), None)
    return names


def release_pythonfmu_states() -> int:
    """Release the interpreter state of every pythonfmu binary still loaded; returns how many.

    pythonfmu 0.7.0's binary keeps a static std::shared_ptr<PyState> and resets it in a library
    destructor (__attribute__((destructor))). At process exit, glibc runs the static destructors
    (exit handlers) before the library destructors (_dl_fini), so for every binary still loaded
    at exit the reset acts on an already destroyed shared_ptr: it decrements a counter in a freed
    (possibly reused) heap block, which sporadically aborts the process after all work is done
    ("corrupted double-linked list", SIGABRT; valgrind: invalid read in
    finalizePythonInterpreter during _dl_fini). Calling the binary's exported
    finalizePythonInterpreter while the process is still alive empties the shared_ptr, so both
    destructors find nothing to do. In a Python host that is all it does: the PyState only
    starts an interpreter when none runs. Registered with atexit below; safe to call twice.
    """
    if not sys.platform.startswith("linux"):
        return 0  # measured on Linux only (glibc exit order); the Windows DllMain path differs
    released = 0
    for name in _loaded_libraries():
        try:  # RTLD_NOLOAD: only a handle to the already loaded copy, never a new load
            lib = ctypes.CDLL(os.fsdecode(name), mode=os.RTLD_NOLOAD | os.RTLD_LAZY)
            release = lib.finalizePythonInterpreter
            lib.fmi2Instantiate  # a pythonfmu FMU binary, not some other library
        except (OSError, AttributeError):
            continue
        release.restype = None
        release()
        released += 1
    return released


atexit.register(release_pythonfmu_states)

MAX_FMU_UNPACKED_BYTES = 1 << 30  # an FMU's files together, as its zip directory declares them
MAX_MEMBER_NAME_BYTES = 1024      # a member's name in the zip; a part of it at most NAME_MAX
NAME_MAX = 255                    # bytes in one file or folder name (Linux, most file systems)
_loaded: dict[str, tuple[str, object]] = {}  # sha256 of an FMU file -> (folder, description)


class FmuRefused(ValueError):
    """An FMU file that is not loaded: its names, its size or its bundled code are not allowed
    (the message says which and what is allowed; the caller names the file)."""


def _remove_extracted() -> None:
    for folder, _ in _loaded.values():
        shutil.rmtree(folder, ignore_errors=True)
    _loaded.clear()


atexit.register(_remove_extracted)


def _shortened(text: str, keep: int = 60) -> str:
    return text if len(text) <= keep else f"{text[:keep // 2]}...{text[-keep // 2:]}"


def fmu_file_problem(path: Path) -> str | None:
    """Why `path` names no FMU file that can be read (a sentence naming it), or None."""
    try:
        return None if Path(path).is_file() else f"no FMU file at {path}"
    except OSError as err:
        if err.errno != errno.ENAMETOOLONG:
            return f"cannot read the FMU file {_shortened(str(path))}: {err.strerror}"
    longest = max(Path(path).parts, key=lambda part: len(os.fsencode(part)))
    return (f"the FMU file name {_shortened(str(path))} is too long for the file system: a "
            f"file or folder name may have at most {NAME_MAX} bytes and a path "
            f"{os.pathconf('/', 'PC_PATH_MAX')}; this one has a name of "
            f"{len(os.fsencode(longest))} bytes in a path of {len(os.fsencode(str(path)))}")


def _member_problem(name: str) -> str | None:
    """What is wrong with a zip member's name, or None: a relative path with forward slashes,
    each part a plain name (not '', '.' or '..'), no drive, short enough to unpack anywhere."""
    parts = name.rstrip("/").split("/")
    if name.startswith("/") or "\\" in name or ":" in name or "\0" in name:
        return "an absolute name, a backslash, a drive or device colon or a NUL"
    if any(part in ("", ".", "..") for part in parts):
        return "an empty, '.' or '..' part"
    if len(name.encode()) > MAX_MEMBER_NAME_BYTES or \
            max(len(part.encode()) for part in parts) > NAME_MAX:
        return (f"a name longer than {MAX_MEMBER_NAME_BYTES} bytes or with a part longer than "
                f"{NAME_MAX} bytes")
    return None


def check_members(zf: zipfile.ZipFile) -> None:
    """Refuse an FMU whose zip has a member that could be unpacked outside its folder, or could
    not be unpacked, or that declares more than MAX_FMU_UNPACKED_BYTES in all."""
    for info in zf.infolist():
        problem = _member_problem(info.filename)
        if problem is not None:
            raise FmuRefused(f"zip member {_shortened(info.filename)!r} has {problem}; allowed "
                             "are relative paths of plain names joined by '/' (FMI 2.0, 2.1)")
    size = sum(i.file_size for i in zf.infolist())
    if size > MAX_FMU_UNPACKED_BYTES:
        raise FmuRefused(f"its files unpack to {size} bytes, more than the limit of "
                         f"{MAX_FMU_UNPACKED_BYTES} bytes")


def _needed(name: str) -> bool:
    """The members a co-simulation here uses: the description, this platform's binaries, the
    resources (not the documentation, the sources, other platforms' binaries)."""
    return name == "modelDescription.xml" or name.startswith(
        ("resources/", f"binaries/{fmpy_platform}/"))


def _unpack(zf: zipfile.ZipFile) -> str:
    folder = tempfile.mkdtemp(prefix="crankfmu-fmu-")
    try:
        for info in zf.infolist():
            if info.is_dir() or not _needed(info.filename):
                continue
            target = os.path.join(folder, *info.filename.split("/"))
            os.makedirs(os.path.dirname(target), exist_ok=True)
            with zf.open(info) as src, open(target, "wb") as dst:
                shutil.copyfileobj(src, dst, 1 << 20)
    except BaseException:
        shutil.rmtree(folder, ignore_errors=True)
        raise
    return folder


def load_fmu(path: Path) -> tuple[str, object]:
    """(unpacked folder, model description) of the FMU file at `path`, checked, once per FMU
    content for the life of the process (the folder is private, mkdtemp: mode 0700, and removed
    at exit). Refused (FmuRefused, a ValueError) before anything is unpacked: member names that
    are not plain relative paths, a DOCTYPE in modelDescription.xml, more than the size limits,
    bundled crankfmu code that is not what its digest stands for, a GUID that is not its
    build's (fmu/bundle.py). Unpacking an FMU once per process (not once per run) means its
    binary is loaded once: a shared library is never unloaded here (see
    FmuInstance.terminate), so a new copy per run would grow the process by the library's size
    on every run."""
    from .bundle import BundleError, check_description, read_bundle

    if Path(path).stat().st_size > MAX_FMU_UNPACKED_BYTES:
        raise FmuRefused(f"larger than the limit of {MAX_FMU_UNPACKED_BYTES} bytes")
    data = Path(path).read_bytes()
    key = hashlib.sha256(data).hexdigest()
    if key in _loaded and os.path.isdir(_loaded[key][0]):
        return _loaded[key]
    with zipfile.ZipFile(io.BytesIO(data)) as zf:
        check_members(zf)
        check_model_description_xml(zf)
        try:
            bundle = read_bundle(zf)
        except BundleError as err:
            raise FmuRefused(str(err)) from None
        folder = _unpack(zf)
    try:
        description = read_model_description(os.path.join(folder, "modelDescription.xml"))
        if bundle is not None:
            check_description(bundle, description.modelName, description.version,
                              description.guid)
    except BaseException as err:
        shutil.rmtree(folder, ignore_errors=True)
        if isinstance(err, BundleError):
            raise FmuRefused(str(err)) from None
        raise
    _loaded[key] = folder, description
    return _loaded[key]


@dataclass
class StepStatistics:
    do_step_calls: int = 0
    do_step_seconds: float = 0.0
    rollbacks: int = 0
    state_saves: int = 0

    def as_dict(self) -> dict:
        return {"doStep_calls": self.do_step_calls, "doStep_seconds": self.do_step_seconds,
                "rollbacks": self.rollbacks, "state_saves": self.state_saves}


class FmuInstance:
    """One instantiated FMU in a scene."""

    def __init__(self, name: str, path: Path, log=None):
        self.name, self.path = name, Path(path)
        self._component = None
        self.unzip_dir, self.model_description = load_fmu(self.path)
        self.variables = {v.name: v for v in self.model_description.modelVariables}
        cs = self.model_description.coSimulation
        if cs is None:
            raise ValueError("not a co-simulation FMU (no <CoSimulation> element)")
        self.can_rollback = bool(cs.canGetAndSetFMUstate)
        self.slave = FMU2Slave(guid=self.model_description.guid, unzipDirectory=self.unzip_dir,
                               modelIdentifier=cs.modelIdentifier, instanceName=name)
        self.stats = StepStatistics()
        self._log = log
        self._component = None

    # -- life cycle ------------------------------------------------------------------------
    def instantiate(self, logging_on: bool = False) -> None:
        self.slave.instantiate(loggingOn=logging_on,
                               callbacks=None if self._log is None else self._log.callbacks)
        self._component = self.slave.component

    def setup(self, start_time: float, stop_time: float, tolerance: float) -> None:
        self.slave.setupExperiment(tolerance=tolerance, startTime=start_time, stopTime=stop_time)

    def terminate(self) -> None:
        """Terminate and free the instance, but keep the shared library loaded: unloading a
        Python FMU's library while the interpreter lives on crashes it at exit. The unpacked
        folder stays for the process's other runs (load_fmu); safe to call twice."""
        if self._component is None:
            return
        component, self._component = self._component, None
        try:
            self.slave.terminate()
        finally:
            self.slave.fmi2FreeInstance(component)

    # -- values ----------------------------------------------------------------------------
    def variable(self, name: str):
        try:
            return self.variables[name]
        except KeyError:
            raise KeyError(f"{self.name}: no variable {name!r} in {self.path.name}") from None

    def set_start_values(self, values: dict) -> None:
        for name, value in values.items():
            var = self.variable(name)
            if var.type == "Boolean":
                self.slave.setBoolean([var.valueReference], [bool(value)])
            else:
                self.slave.setReal([var.valueReference], [float(value)])

    def reader(self, names: list[str]):
        """A function returning the current values of `names` as a numpy array (a view of one
        reused buffer: copy it to keep it)."""
        n = len(names)
        vrs = (fmi2ValueReference * n)(*[self.variable(v).valueReference for v in names])
        buf = (fmi2Real * n)()
        out = np.ctypeslib.as_array(buf)
        get = self.slave._functions["fmi2GetReal"]  # raw ctypes: fmpy's wrapper costs ~2 us

        def read() -> np.ndarray:
            status = get(self._component, vrs, n, buf) if n else 0
            if status > FMI2_WARNING:
                raise FMICallException(function="fmi2GetReal", status=status)
            return out
        return read

    def writer(self, names: list[str]):
        """A function setting `names` from a sequence of floats."""
        n = len(names)
        vrs = (fmi2ValueReference * n)(*[self.variable(v).valueReference for v in names])
        buf = (fmi2Real * n)()
        view = np.ctypeslib.as_array(buf)
        setter = self.slave._functions["fmi2SetReal"]

        def write(values) -> None:
            if n:
                view[:] = values
                status = setter(self._component, vrs, n, buf)
                if status > FMI2_WARNING:
                    raise FMICallException(function="fmi2SetReal", status=status)
        return write

    def do_step(self, t: float, h: float) -> None:
        start = time.perf_counter()
        status = self.slave._functions["fmi2DoStep"](self._component, t, h, 1)
        self.stats.do_step_seconds += time.perf_counter() - start
        if status > FMI2_WARNING:
            raise FMICallException(function="fmi2DoStep", status=status)
        self.stats.do_step_calls += 1

    # -- state rollback --------------------------------------------------------------------
    def get_state(self):
        self.stats.state_saves += 1
        return self.slave.getFMUState()

    def set_state(self, state) -> None:
        self.stats.rollbacks += 1
        self.slave.setFMUState(state)

    def free_state(self, state) -> None:
        self.slave.freeFMUState(state)


def check_model_description_xml(fmu) -> None:
    """Refuse a modelDescription.xml that a safe parser would not read (fmpy parses it with
    lxml's defaults, which resolve entities): no DTD, no entities, well-formed, < 64 MiB.
    `fmu`: the FMU's path or its open zip."""
    if not isinstance(fmu, zipfile.ZipFile):
        with zipfile.ZipFile(fmu) as zf:
            return check_model_description_xml(zf)
    try:
        info = fmu.getinfo("modelDescription.xml")
    except KeyError:
        raise ValueError("no modelDescription.xml in the FMU") from None
    if info.file_size > 64 << 20:
        raise ValueError(f"modelDescription.xml declares {info.file_size} bytes")
    with fmu.open(info) as f:
        parse_safe_xml(f.read(64 << 20), "modelDescription.xml")


def parse_safe_xml(data: bytes, what: str):
    """An XML document parsed without DTD, entities or network access; a document that holds
    a DOCTYPE is refused (ValueError naming `what`)."""
    from lxml import etree
    parser = etree.XMLParser(resolve_entities=False, no_network=True, load_dtd=False,
                             dtd_validation=False, huge_tree=False, remove_comments=False)
    try:
        root = etree.fromstring(data, parser)
    except etree.XMLSyntaxError as err:
        raise UnsafeXml(f"{what} line {err.lineno}", f"not well-formed XML: {err.msg}") from None
    tree = root.getroottree()
    if tree.docinfo.doctype or tree.docinfo.internalDTD is not None:
        raise UnsafeXml(what, "a DOCTYPE (DTD, entities) is not allowed")
    return root


class UnsafeXml(ValueError):
    def __init__(self, where: str, message: str):
        self.where, self.message = where, message
        super().__init__(f"{where}: {message}")


class LogCollector:
    """fmi2 logger callback that keeps the FMU's messages, so errors can quote the reason."""

    def __init__(self, echo: bool = False):
        from fmpy import calloc, free
        from fmpy.fmi2 import fmi2CallbackFunctions, fmi2CallbackLoggerTYPE
        from fmpy.fmi2 import fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE
        self.messages: list[tuple[str, int, str]] = []
        self.echo = echo
        self.callbacks = fmi2CallbackFunctions()
        self.callbacks.logger = fmi2CallbackLoggerTYPE(self._log)
        self.callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
        self.callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
        try:
            from fmpy.logging import addLoggerProxy
            addLoggerProxy(ctypes.byref(self.callbacks))
        except Exception:  # without the proxy, printf-style arguments stay unexpanded
            pass

    def _log(self, env, instance, status, category, message):
        text = message.decode("utf-8", "replace") if isinstance(message, bytes) else str(message)
        name = instance.decode() if isinstance(instance, bytes) else str(instance)
        self.messages.append((name, int(status), text))
        if self.echo:
            print(f"[{name}] {text}")

    def errors_of(self, instance: str) -> list[str]:
        return [m for n, s, m in self.messages if n == instance and s >= 3]
