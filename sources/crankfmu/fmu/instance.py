"""A thin, fast layer over fmpy's FMU2Slave: value references and ctypes buffers prepared once.

fmpy's getReal/setReal build ctypes arrays on every call; a master calls them every step, so
`reader` and `writer` prepare the arrays once and reuse them (see benchmarks/).
"""
from __future__ import annotations

import atexit
import ctypes
import os
import sys
import time
from dataclasses import dataclass
from pathlib import Path

from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import FMU2Slave, fmi2FMUstate, fmi2Real, fmi2ValueReference

from .archive import load_fmu

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
            lib.fmi2Instantiate  # noqa: B018 - a probe: a pythonfmu FMU binary, not some other library
        except (OSError, AttributeError):
            continue
        release.restype = None
        release()
        released += 1
    return released


_FAILED_CALLS = [0]  # FMI calls that failed in this process (note_failed_call)


def note_failed_call() -> None:
    """Record that an FMU call failed in this process: pythonfmu 0.7.0 can leave the interpreter
    that ran a Python exception inside an FMU corrupt (a later run segfaulted in the garbage
    collector), so a study's pool no longer forks its workers from it
    (crankfmu.cosim.workers.start_method)."""
    _FAILED_CALLS[0] += 1


def failed_calls() -> int:
    """How many FMU calls failed in this process (note_failed_call)."""
    return _FAILED_CALLS[0]


atexit.register(release_pythonfmu_states)

@dataclass
class StepStatistics:
    do_step_calls: int = 0
    do_step_seconds: float = 0.0
    rollbacks: int = 0
    state_saves: int = 0

    def as_dict(self) -> dict:
        return {"doStep_calls": self.do_step_calls, "doStep_seconds": self.do_step_seconds,
                "rollbacks": self.rollbacks, "state_saves": self.state_saves}


# fmpy's FMU2Slave objects of freed instances, per unpacked FMU (folder, GUID, model
# identifier): making one loads the library's FMI functions with their signatures, 0.7 ms per
# FMU and run, while the library itself stays loaded (FmuInstance.terminate). A slave holds one
# instance at a time (its `component`): each FmuInstance takes its own, and gives it back when
# its instance is freed.
_IDLE_SLAVES: dict[tuple, list] = {}


def _take_slave(key: tuple, instance_name: str) -> FMU2Slave:
    idle = _IDLE_SLAVES.get(key)
    if idle:
        slave = idle.pop()
        slave.instanceName = instance_name
        return slave
    unzip_dir, guid, model_identifier = key
    return FMU2Slave(guid=guid, unzipDirectory=unzip_dir, modelIdentifier=model_identifier,
                     instanceName=instance_name)


def drop_repeated_path_entries() -> None:
    """After a pythonfmu instance is made: pythonfmu's and pythonfmu3's binaries put the FMU's
    resources folder on sys.path (at its front) at every instantiation and never take it off,
    so runs repeated in one process (the Python API, a sweep's workers, the tests) grew
    sys.path by one entry per FMU per run (10,000 entries after a sweep of 5,000 runs of 2
    FMUs), and every import of a module not yet loaded walked them all. Each folder is kept at
    its first place only: what an import finds is unchanged (a later repeat is never reached)."""
    if len(set(sys.path)) < len(sys.path):
        sys.path[:] = dict.fromkeys(sys.path)


class FmuInstance:
    """One instantiated FMU in a scene."""

    _slave_key: tuple | None = None  # where terminate gives the fmpy slave back (_take_slave)

    def __init__(self, name: str, path: Path, log=None):
        self.name, self.path = name, Path(path)
        self._component = None
        self.unzip_dir, self.model_description = load_fmu(self.path)
        self.variables = {v.name: v for v in self.model_description.modelVariables}
        cs = self.model_description.coSimulation
        if cs is None:
            raise ValueError("not a co-simulation FMU (no <CoSimulation> element)")
        self.can_rollback = bool(cs.canGetAndSetFMUstate)
        self._slave_key = (self.unzip_dir, self.model_description.guid, cs.modelIdentifier)
        self.slave = _take_slave(self._slave_key, name)
        self.stats = StepStatistics()
        self._log = log
        self._component = None

    # -- life cycle ------------------------------------------------------------------------
    def instantiate(self, logging_on: bool = False) -> None:
        self.slave.instantiate(loggingOn=logging_on,
                               callbacks=None if self._log is None else self._log.callbacks)
        drop_repeated_path_entries()
        self._component = self.slave.component
        self._fmi2_do_step = self.slave._functions["fmi2DoStep"]  # raw ctypes, as in reader

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
            if self._slave_key is not None:  # an FMI 2.0 slave (not Fmu3Instance's calls)
                _IDLE_SLAVES.setdefault(self._slave_key, []).append(self.slave)

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
        """A function returning the current values of `names` as a new list of Python floats
        (a master keeps what it reads; the list costs less than a numpy array of a few
        values)."""
        n = len(names)
        if not n:
            return list  # nothing to read: a new empty list per call
        vrs = (fmi2ValueReference * n)(*[self.variable(v).valueReference for v in names])
        buf = (fmi2Real * n)()
        values = memoryview(buf).cast("B").cast("d")  # tolist() costs half of buf[:]
        get = self.slave._functions["fmi2GetReal"]  # raw ctypes: fmpy's wrapper costs ~2 us

        def read() -> list[float]:
            status = get(self._component, vrs, n, buf)
            if status > FMI2_WARNING:
                raise FMICallException(function="fmi2GetReal", status=status)
            return values.tolist()  # type: ignore[return-value]  # "d": floats (typeshed: int)
        return read

    def writer(self, names: list[str]):
        """A function setting `names` from a sequence of floats."""
        n = len(names)
        vrs = (fmi2ValueReference * n)(*[self.variable(v).valueReference for v in names])
        buf = (fmi2Real * n)()
        setter = self.slave._functions["fmi2SetReal"]

        def write(values) -> None:
            if n:
                buf[:] = values
                status = setter(self._component, vrs, n, buf)
                if status > FMI2_WARNING:
                    raise FMICallException(function="fmi2SetReal", status=status)
        return write

    def do_step(self, t: float, h: float) -> None:
        clock = time.perf_counter
        start = clock()
        status = self._fmi2_do_step(self._component, t, h, 1)
        stats = self.stats
        stats.do_step_seconds += clock() - start
        if status > FMI2_WARNING:
            raise FMICallException(function="fmi2DoStep", status=status)
        stats.do_step_calls += 1

    # -- state rollback (raw ctypes, as fmpy's getFMUstate, with its status check) ---------
    # the functions get, set, free (Fmu3Instance: FMI 3.0's, same arguments)
    state_functions = ("fmi2GetFMUstate", "fmi2SetFMUstate", "fmi2FreeFMUstate")

    def get_state(self):
        self.stats.state_saves += 1
        state = fmi2FMUstate()  # a void pointer, as fmi3FMUState
        self._state_call(self.state_functions[0], ctypes.byref(state))
        return state

    def set_state(self, state) -> None:
        self.stats.rollbacks += 1
        self._state_call(self.state_functions[1], state)

    def free_state(self, state) -> None:
        self._state_call(self.state_functions[2], ctypes.byref(state))

    def _state_call(self, function: str, state) -> None:
        status = self.slave._functions[function](self._component, state)
        if status > FMI2_WARNING:
            raise FMICallException(function=function, status=status)


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
