"""The FMI 2.0 adapter: a pythonfmu Fmi2Slave around any `PhysicsModel` (the physics stays
apart).

Every FMI 2.0 FMU of crankfmu is this adapter with a different `physics_class`. The variable
table, the values, initialization, stepping and the FMU state are the version-free core
(`slave_core.SlaveCore`, shared with the FMI 3.0 adapter `slave3.py`); this module adds
pythonfmu's variable registration, setupExperiment and its log status. The value references are
the core's (`variable_table`); `crankfmu.fmu.model_description` writes the modelDescription.xml
from the same table, so the two cannot disagree.
"""
from __future__ import annotations

from pythonfmu import Boolean, Fmi2Causality, Fmi2Slave, Fmi2Variability, Real
from pythonfmu.enums import Fmi2Status
from pythonfmu.default_experiment import DefaultExperiment

from .slave_core import (DEFAULT_TOLERANCE, FmiVariable, SlaveCore, derivative_unit,
                         variable_table)

__all__ = ["DEFAULT_TOLERANCE", "FmiVariable", "ModelSlave", "derivative_unit",
           "variable_table"]


class ModelSlave(SlaveCore, Fmi2Slave):
    """Generic co-simulation slave; subclasses set `physics_class`."""

    def __init__(self, **kwargs):
        Fmi2Slave.__init__(self, **kwargs)
        self._init_core()
        self.default_experiment = DefaultExperiment(0.0, self.default_stop, self.default_step,
                                                    DEFAULT_TOLERANCE)
        for vr, var in enumerate(self._table):
            self._register(vr, var)

    def _register(self, vr: int, var: FmiVariable) -> None:
        getter = lambda: self._read(vr)  # noqa: E731 - one closure per value reference
        setter = lambda value: self._write([vr], [value])  # noqa: E731
        kind = Real if var.kind == "Real" else Boolean
        self.register_variable(kind(var.name, causality=Fmi2Causality[var.causality],
                                    variability=Fmi2Variability[var.variability],
                                    description=var.description, getter=getter,
                                    setter=setter), nested=False)

    def _log_error(self, message: str) -> None:
        self.log(message, Fmi2Status.error)

    def setup_experiment(self, start_time, stop_time=None, tolerance=None):
        self._set_experiment(start_time, tolerance)
