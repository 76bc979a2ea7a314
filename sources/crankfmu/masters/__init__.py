"""Master algorithms, one file each on the shared base `Master` (see base.py for the contract).

A new master is one new file (a `Master` subclass with its `name` and `options`) and one line
in MASTERS below; the scene reader, the command line, the Python API, the SSP annotation and
the runner read its declaration from here, and everything outside masters/ learns what kind of
master it is through `traits(algorithm)` (variable step, the FMI interface, the knob its error
follows, its design order), read from the class's attributes here and nowhere else.
"""
from __future__ import annotations

from dataclasses import dataclass

from ..fmu.instance3 import CO_SIMULATION
from .adaptive import Adaptive
from .base import DivergenceError, Master
from .gauss_seidel import GaussSeidel
from .iterative import Iterative
from .jacobi import Jacobi
from .model_exchange import ModelExchange
from .options import Option, OptionError

MASTERS: dict[str, type[Master]] = {cls.name: cls for cls in (
    GaussSeidel,
    Jacobi,
    Iterative,
    Adaptive,
    ModelExchange,
)}


def register(cls: type[Master]) -> type[Master]:
    """Add a master class (a plug-in, or a test's example) to MASTERS; its options must not
    redefine a key another master declares differently."""
    _check_declaration(cls, MASTERS)
    MASTERS[cls.name] = cls
    return cls


def master_class(algorithm: str) -> type[Master]:
    try:
        return MASTERS[algorithm]
    except (KeyError, TypeError):
        raise OptionError(f"{_show(algorithm)} is not one of {', '.join(MASTERS)}") from None


@dataclass(frozen=True)
class Traits:
    """What a master is, for the runner, the error estimate, the studies and the command line
    (read from its class by `traits`)."""

    name: str
    variable_step: bool   # it chooses its steps (class attribute `variable_step`)
    interface: str        # the FMI interface it steps the FMUs through (class attribute
    #                       `interface`, default "CoSimulation")
    options: frozenset = frozenset()  # the names of the options it declares (`options`)

    @property
    def monolithic(self) -> bool:
        """It integrates the FMUs' Model Exchange interfaces as one ODE: no coupling error, no
        communication step or extrapolation to vary (its step is its record grid)."""
        return self.interface != CO_SIMULATION

    @property
    def knob(self) -> str | None:
        """What its coupling error follows: "step" (a fixed-step master), "tolerance" (a
        variable-step master: it chooses the steps), None (monolithic: no coupling error)."""
        if self.monolithic:
            return None
        return "tolerance" if self.variable_step else "step"

    def design_order(self, extrapolation: int, taylor: int = 0) -> float | None:
        """The order p of its global error in its knob, e ~ C knob^p, that the error estimate
        assumes: extrapolation + 1 for a fixed-step master (inputs extrapolated with order
        p - 1), taylor + 1 with a Taylor coupling of order q = taylor ([master].taylor,
        masters/taylor.py; measured on the two-mass oscillator: tests/test_taylor_coupling.py),
        1 for a variable-step one (the tolerance bounds each step's input error, so the global
        error follows it whatever the coupling), None without a coupling error."""
        if self.monolithic:
            return None
        if self.variable_step:
            return 1.0
        return float(taylor + 1 if taylor else extrapolation + 1)

    def describe_steps(self, step: float) -> str:
        """How it steps, for a summary line: "variable steps" or "steps of 0.001 s"."""
        return "variable steps" if self.variable_step else f"steps of {step:g} s"


def traits(algorithm: str) -> Traits:
    """The traits of the master named `algorithm` (a key of MASTERS; an unknown name reads as
    a fixed-step co-simulation master, so a caller can describe what a scene asks for before
    the scene reader has refused it)."""
    cls = MASTERS.get(algorithm)
    return Traits(algorithm, bool(getattr(cls, "variable_step", False)),
                  getattr(cls, "interface", CO_SIMULATION),
                  frozenset(o.name for o in getattr(cls, "options", ())))


def all_options() -> dict[str, Option]:
    """Every option some master declares, by key (the command line offers each once); kept
    until MASTERS changes (the scene's settings read options through it)."""
    key = tuple(MASTERS.values())
    if _ALL_OPTIONS[0] != key:
        out: dict[str, Option] = {}
        for cls in key:
            for option in cls.options:
                out.setdefault(option.name, option)
        _ALL_OPTIONS[:] = [key, out]
    return _ALL_OPTIONS[1]


_ALL_OPTIONS: list = [None, {}]  # [the MASTERS classes it was made from, the options]


def option_default(algorithm: str, option: Option):
    """The default of `option` for the master `algorithm` (its own where it declares one; the
    option's declared default for an unknown algorithm)."""
    cls = MASTERS.get(algorithm)
    return option.default if cls is None else cls.default(option)


def make_master(algorithm: str, system, settings) -> Master:
    try:
        cls = MASTERS[algorithm]
    except KeyError:
        raise ValueError(f"master algorithm {algorithm!r} is not available; available: "
                         f"{', '.join(MASTERS)}") from None
    return cls(system, settings)


def _check_declaration(cls, masters) -> None:
    if not isinstance(getattr(cls, "name", None), str) or cls.name in ("", "base"):
        raise ValueError(f"master class {cls.__name__} needs a name")
    for option in cls.options:
        for other in masters.values():
            theirs = {o.name: o for o in other.options}.get(option.name)
            if theirs is not None and theirs != option:
                raise ValueError(f"master {cls.name}: option {option.name} differs from "
                                 f"master {other.name}'s (a key means one thing)")
    own = {o.name: o for o in cls.options}
    for key, value in cls.defaults.items():
        if key not in own:
            raise ValueError(f"master {cls.name}: a default for {key}, which is not one of its "
                             f"options")
        try:
            own[key].check(value)
        except OptionError as err:
            raise ValueError(f"master {cls.name}: its default {key} = {value!r} is not "
                             f"allowed: {err}") from None


def _show(value) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:60] + "..."


for _cls in MASTERS.values():
    _check_declaration(_cls, MASTERS)

__all__ = ["DivergenceError", "Master", "MASTERS", "Option", "OptionError", "all_options",
           "make_master", "master_class", "option_default", "register", "Traits", "traits"]
