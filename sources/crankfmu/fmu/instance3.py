"""FMI 3.0 FMUs in a scene: the interface of `instance.FmuInstance` over fmpy's FMU3Slave
(Co-Simulation) and FMU3Model (Model Exchange), so masters, the runner and the recorder treat an
FMI 2.0 and an FMI 3.0 component alike.

Value references and ctypes buffers are prepared once per connection group (`reader`, `writer`),
as for FMI 2.0. The FMI 2.0 call sequence the runner makes (setup before the start values, then
`slave.enterInitializationMode()`) maps onto FMI 3.0's, where the start time and tolerance are
arguments of fmi3EnterInitializationMode: `setup` keeps them and `slave` passes them.
"""
from __future__ import annotations

import ctypes
import functools
import os
import time
from pathlib import Path

from fmpy.fmi1 import FMICallException
from fmpy.fmi3 import FMU3Model, FMU3Slave, fmi3Boolean, fmi3Float64, fmi3ValueReference

from .archive import load_fmu
from .instance import FmuInstance, StepStatistics, drop_repeated_path_entries

FMI3_WARNING = 1  # fmi3Status: a call returning more than fmi3Warning failed
CO_SIMULATION, MODEL_EXCHANGE = "CoSimulation", "ModelExchange"


def is_fmi3(path: Path) -> bool:
    """Does the FMU file declare fmiVersion 3.x? Read once per version of the file (its inode,
    size and modification time): a run asks for each FMU when it checks the scene and again when
    it opens it, a sweep or study for every run (1,289 calls, 111 reads over the test suite's
    workers). A build renames a new file over the old (a new inode); only a rewrite in place to
    the same size within one tick of the file system's clock would go unseen."""
    status = os.stat(path)
    return _declares_fmi3(os.fspath(path), (status.st_ino, status.st_size, status.st_mtime_ns))


@functools.lru_cache(maxsize=256)
def _declares_fmi3(path: str, identity: tuple[int, int, int]) -> bool:
    import zipfile
    with zipfile.ZipFile(path) as zf:
        head = zf.open("modelDescription.xml").read(4096)
    return b'fmiVersion="3.' in head


class _Fmi3Calls:
    """fmpy's FMI 3.0 object under the names FmuInstance and the runner call (the FMI 2.0
    ones): enter/exitInitializationMode (the experiment kept by `setup`), setReal,
    fmi2FreeInstance; anything else is fmpy's own."""

    def __init__(self, owner: "Fmu3Instance"):
        self._owner = owner

    def enterInitializationMode(self):
        start, stop, tolerance = self._owner.experiment
        self._owner.fmu.enterInitializationMode(tolerance=tolerance, startTime=start,
                                                stopTime=stop)

    def setReal(self, vrs, values):
        self._owner.fmu.setFloat64(vrs, values)

    def fmi2FreeInstance(self, component):
        self._owner.fmu.fmi3FreeInstance(component)

    def __getattr__(self, name):
        return getattr(self._owner.fmu, name)


class Fmu3Instance(FmuInstance):
    """One instantiated FMI 3.0 FMU in a scene, as Co-Simulation or as Model Exchange: an
    FmuInstance (variables, start values, terminate, FMU state as there) whose calls go to
    fmpy's FMU3Slave or FMU3Model."""

    fmi_version = 3
    state_functions = ("fmi3GetFMUState", "fmi3SetFMUState", "fmi3FreeFMUState")

    def __init__(self, name: str, path: Path, log=None, interface: str = CO_SIMULATION):
        self.name, self.path, self.interface = name, Path(path), interface
        self._component = None
        self.unzip_dir, self.model_description = load_fmu(self.path)  # checked as FMI 2.0 FMUs
        md = self.model_description
        self.variables = {v.name: v for v in md.modelVariables}
        kind = md.coSimulation if interface == CO_SIMULATION else md.modelExchange
        if kind is None:
            raise ValueError(f"not an FMI 3.0 {interface} FMU (no <{interface}> element)")
        self.can_rollback = bool(kind.canGetAndSetFMUstate)
        cls = FMU3Slave if interface == CO_SIMULATION else FMU3Model
        self.fmu = cls(guid=md.guid, unzipDirectory=self.unzip_dir,
                       modelIdentifier=kind.modelIdentifier, instanceName=name)
        self.slave = _Fmi3Calls(self)
        self.experiment: tuple[float, float | None, float | None] = (0.0, None, None)
        self.stats = StepStatistics()
        self._log = log
        self._functions = self.fmu._functions

    # -- life cycle ------------------------------------------------------------------------
    def instantiate(self, logging_on: bool = False) -> None:
        callback = None if self._log is None else self._log_message
        self.fmu.instantiate(loggingOn=logging_on, logMessage=callback)
        drop_repeated_path_entries()
        self._component = self.fmu.component

    def _log_message(self, env, status, category, message) -> None:
        text = message.decode("utf-8", "replace") if isinstance(message, bytes) else str(message)
        self._log.messages.append((self.name, int(status), text))
        if self._log.echo:
            print(f"[{self.name}] {text}")

    def setup(self, start_time: float, stop_time: float, tolerance: float) -> None:
        self.experiment = (start_time, stop_time, tolerance)

    # -- values ----------------------------------------------------------------------------
    def value_references(self, names: list[str]):
        return (fmi3ValueReference * len(names))(*[self.variable(v).valueReference
                                                   for v in names])

    def reader(self, names: list[str]):
        """A function returning the current values of `names` as a new list of Python floats
        (as FmuInstance.reader: a master keeps what it reads)."""
        n = len(names)
        if not n:
            return list  # nothing to read: a new empty list per call
        vrs = self.value_references(names)
        buf = (fmi3Float64 * n)()
        values = memoryview(buf).cast("B").cast("d")
        get = self._functions["fmi3GetFloat64"]

        def read() -> list[float]:
            status = get(self._component, vrs, n, buf, n)
            if status > FMI3_WARNING:
                raise FMICallException(function="fmi3GetFloat64", status=status)
            return values.tolist()  # type: ignore[return-value]  # "d": floats (typeshed: int)
        return read

    def writer(self, names: list[str]):
        """A function setting `names` from a sequence of floats."""
        n = len(names)
        vrs = self.value_references(names)
        buf = (fmi3Float64 * n)()
        setter = self._functions["fmi3SetFloat64"]

        def write(values) -> None:
            if n:
                buf[:] = values
                status = setter(self._component, vrs, n, buf, n)
                if status > FMI3_WARNING:
                    raise FMICallException(function="fmi3SetFloat64", status=status)
        return write

    def do_step(self, t: float, h: float) -> None:
        flags = [fmi3Boolean() for _ in range(3)]
        last = fmi3Float64()
        start = time.perf_counter()
        status = self._functions["fmi3DoStep"](self._component, t, h, fmi3Boolean(True),
                                               *map(ctypes.byref, flags), ctypes.byref(last))
        self.stats.do_step_seconds += time.perf_counter() - start
        if status > FMI3_WARNING:
            raise FMICallException(function="fmi3DoStep", status=status)
        self.stats.do_step_calls += 1


FMI3_REAL_TYPES = ("Float64", "Float32")


def value_type(var) -> str:
    """A variable's type in FMI 2.0's words: FMI 3.0's Float64 (Float32) is a Real, so FMI 2.0
    and FMI 3.0 components connect and are checked alike."""
    return "Real" if var.type in FMI3_REAL_TYPES else var.type


def feedthrough(fmu) -> dict[str, set[str]]:
    """output -> the inputs it depends on directly, from the modelDescription's
    ModelStructure/Outputs. An output listed without a `dependencies` attribute, or not listed,
    depends on every input (FMI 2.0, section 2.2.8)."""
    md = fmu.model_description
    inputs = {v.name for v in md.modelVariables if v.causality == "input"}
    out: dict[str, set[str]] = {v.name: set(inputs) for v in md.modelVariables
                                if v.causality == "output"}
    for unknown in md.outputs or []:
        name = unknown.variable.name
        if unknown.dependencies is not None:
            out[name] = {d.name for d in unknown.dependencies if d.name in inputs}
    return out


def open_fmu(name: str, path: Path, log=None, interface: str = CO_SIMULATION):
    """The FMU file loaded for `interface`: an FMI 3.0 file as Fmu3Instance, an FMI 2.0 file as
    instance.FmuInstance (Co-Simulation only: pythonfmu's FMUs have no Model Exchange)."""
    if is_fmi3(path):
        return Fmu3Instance(name, path, log, interface)
    if interface != CO_SIMULATION:
        raise ValueError(f"an FMI 2.0 FMU; {interface} needs an FMI 3.0 FMU with a "
                         f"<{interface}> interface")
    return FmuInstance(name, path, log)


__all__ = ["CO_SIMULATION", "MODEL_EXCHANGE", "Fmu3Instance", "feedthrough", "is_fmi3",
           "open_fmu", "value_type"]
