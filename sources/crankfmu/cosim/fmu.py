"""A thin, fast layer over fmpy's FMU2Slave: value references and ctypes buffers prepared once.

fmpy's getReal/setReal build ctypes arrays on every call; a master calls them every step, so
`reader` and `writer` prepare the arrays once and reuse them (see benchmarks/).
"""
from __future__ import annotations

import ctypes
import shutil
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from fmpy import extract, read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import FMU2Slave, fmi2Real, fmi2ValueReference

FMI2_WARNING = 1  # fmi2Status: a call returning more than fmi2Warning failed


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
        self.model_description = read_model_description(str(path))
        self.variables = {v.name: v for v in self.model_description.modelVariables}
        self.unzip_dir = extract(str(path))
        cs = self.model_description.coSimulation
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
        Python FMU's library while the interpreter lives on crashes it at exit."""
        try:
            self.slave.terminate()
        finally:
            self.slave.fmi2FreeInstance(self._component)
            shutil.rmtree(self.unzip_dir, ignore_errors=True)

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
