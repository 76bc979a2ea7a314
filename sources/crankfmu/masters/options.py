"""What a master takes: each master declares its own options, as scipy's ODE solvers own their
keyword arguments (solve_ivp(method="Radau", first_step=...)).

An `Option` is one [master] key: name, type, unit, default, allowed range, help. A master class
lists them in `options`; from that one declaration
  - the scene's [master] table accepts exactly the chosen master's keys (crankfmu.system.scene),
  - `--set master.KEY=V`, the Python API's `parameters={"master.KEY": V}` and the run command's
    options (`--tolerance`, `--min-step`, ...) are made and checked (crankfmu.cli),
  - the SSP annotation writes and reads them (crankfmu.system), the JSON sidecar lists them,
  - the master receives the checked values (`Master.option`).
Two masters that take the same key share one `Option` object (a key means one thing).

This module imports nothing of crankfmu but the error base: the scene reader uses it.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from ..errors import OptionError  # noqa: F401 - a master option's value or key is not allowed


@dataclass(frozen=True)
class Option:
    name: str                  # the [master] key
    kind: type                 # float or int
    unit: str                  # "s", "1"
    default: float | int
    help: str
    minimum: float | None = None
    maximum: float | None = None
    positive: bool = False     # > 0 (a minimum that is not itself allowed)
    choices: tuple | None = None

    def check(self, value):
        """The value as the master takes it (int or float), or OptionError saying what is
        allowed. Integers arrive as floats from `--set` (2.0): taken when whole."""
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise OptionError(f"must be {self._what()}, got {_show(value)}")
        if self.kind is int:
            return self._check_int(value)
        try:
            value = float(value)  # a TOML integer beyond a float's range
        except OverflowError:
            raise OptionError(f"must be a finite number, got {_show(value)}") from None
        if not math.isfinite(value):
            raise OptionError(f"must be a finite number, got {value!r}")
        if self.positive and value <= 0:
            raise OptionError(f"must be > 0, got {value!r}")
        if self.minimum is not None and value < self.minimum:
            raise OptionError(f"must be >= {self.minimum:g}, got {value!r}")
        if self.maximum is not None and value > self.maximum:
            raise OptionError(f"must be <= {self.maximum:g}, got {value!r}")
        return value

    def _check_int(self, value) -> int:
        if isinstance(value, float) and not value.is_integer():
            raise OptionError(f"must be {self._what()}, got {_show(value)}")
        if self.choices is not None and value not in self.choices:
            raise OptionError(f"must be {self._what()}, got {_show(value)}")
        if not (self.minimum is None or value >= self.minimum) or \
                not (self.maximum is None or value <= self.maximum):
            raise OptionError(f"must be {self._what()}, got {_show(value)}")
        return int(value)

    def _what(self) -> str:
        if self.choices is not None:
            return ", ".join(map(str, self.choices[:-1])) + f" or {self.choices[-1]}"
        if self.kind is int:
            return f"an integer from {self.minimum:g} to {self.maximum:g}"
        return "a finite number"

    def describe(self) -> str:
        """One line for help texts and error messages: what the key takes."""
        unit = "" if self.unit == "1" else f" [{self.unit}]"
        if self.choices is not None or self.kind is int:
            allowed = self._what()
        else:
            low = "> 0" if self.positive else (f">= {self.minimum:g}" if self.minimum is not None
                                               else "")
            high = f"<= {self.maximum:g}" if self.maximum is not None else ""
            allowed = "a number " + ", ".join(x for x in (low, high) if x) if low or high \
                else "a finite number"
        return f"{self.name}{unit}: {allowed}, default {self.default:g}; {self.help}"


def _show(value, limit: int = 60) -> str:
    text = repr(value)
    return text if len(text) <= limit else text[:limit] + f"... ({len(text)} characters)"


# -- options more than one master takes (one object each: a key means one thing) ------------
EXTRAPOLATION = Option(
    "extrapolation", int, "1", 0, "input extrapolation order: polynomial through the last 1, "
    "2, 3 communication points", minimum=0, maximum=2, choices=(0, 1, 2))
TOLERANCE = Option(
    "tolerance", float, "1", 1e-6, "the master's own relative tolerance (interface "
    "convergence, step error)", positive=True, maximum=1.0)
TAYLOR = Option(
    "taylor", int, "1", 0, "Taylor coupling order q: the inputs over a step follow the Taylor "
    "polynomial of degree q of their sources' outputs at its start, from the output "
    "derivatives the FMUs compute (<output>_d1 .. _dq, exchanged at each communication point); "
    "0: extrapolation from past points", minimum=0, maximum=4, choices=(0, 1, 2, 3, 4))


def check_coupling(values: dict) -> None:
    """Taylor coupling replaces extrapolation: not both."""
    if values.get("taylor", 0) and values.get("extrapolation", 0):
        raise OptionError(f"[master].extrapolation: must be 0 with taylor = {values['taylor']} "
                          f"(the inputs follow the sources' Taylor polynomial), got "
                          f"{values['extrapolation']}")
