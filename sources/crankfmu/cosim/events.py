"""Event-aware errors: what a hybrid scene is judged by when a shifted event makes a trajectory
difference meaningless (a lock 0.1 ms late puts a 100 % speed error into the samples between).

A scene names its event quantities in `[analysis].events`, each either
    "comp.var"                                   the value at the run's end: an event time the
                                                 model reports (drive.t_lock_b, the last lock), a
                                                 cumulative quantity (drive.E_brake_b: the brake
                                                 energy, complete once the member has locked)
    { variable = "comp.var", per = "comp.n" }    one value per event: `n` is a counter output
                                                 (hammer.n_impacts); the value of event k is the
                                                 variable at the last record with n == k (the
                                                 model's frozen figures of blow k: P_peak,
                                                 T_peak, V_impact, impact_duration)
and `[analysis].metric = "events"` makes them the default accuracy metric of the scene.

The error of one entry (dimensionless): end value |y - y_ref| / |y_ref| (absolute where
y_ref = 0); per event, max_k |y_k - y_ref,k| / mean_k |y_ref,k|, and infinite with a reason
when the run and the reference count different events (a missed or extra blow). The functions
take plain arrays on one time grid, so any run and any reference (crankfmu's, or a CSV from
elsewhere) can be compared, and an error estimate can evaluate the same figure.
"""
from __future__ import annotations

from ..errors import CrankfmuError

import math
from dataclasses import dataclass

import numpy as np


class EventSpecError(CrankfmuError, ValueError):
    """An [analysis].events entry that is not one of the allowed forms; names key and value."""


@dataclass(frozen=True)
class EventSpec:
    variable: str
    per: str | None = None  # counter variable: one value per event

    @property
    def label(self) -> str:
        return f"{self.variable} per {self.per}" if self.per else f"{self.variable} at end"

    @property
    def needs(self) -> list[str]:
        return [self.variable] + ([self.per] if self.per else [])


def parse_event_specs(raw, where: str = "[analysis].events") -> list[EventSpec]:
    """The [analysis].events list as EventSpecs (see the module docstring for the forms)."""
    if raw is None:
        return []
    if not isinstance(raw, list):
        raise EventSpecError(f"{where}: must be a list of \"component.variable\" or "
                             "{ variable = \"component.variable\", per = \"component.counter\" }")
    specs = []
    for k, entry in enumerate(raw):
        if isinstance(entry, str):
            specs.append(EventSpec(_ref(entry, f"{where}[{k}]")))
        elif isinstance(entry, dict) and set(entry) <= {"variable", "per"} and "variable" in entry:
            per = entry.get("per")
            specs.append(EventSpec(_ref(entry["variable"], f"{where}[{k}].variable"),
                                   _ref(per, f"{where}[{k}].per") if per is not None else None))
        else:
            raise EventSpecError(f"{where}[{k}]: {entry!r} is not \"component.variable\" or a "
                                 "table with the keys variable (required) and per")
    return specs


def _ref(value, where: str) -> str:
    if not isinstance(value, str) or "." not in value:
        raise EventSpecError(f"{where}: must be \"component.variable\", got {value!r}")
    return value


def event_values(spec: EventSpec, columns: dict[str, np.ndarray]) -> np.ndarray:
    """The entry's values: [end value], or one value per counted event (see module docstring)."""
    y = np.asarray(columns[spec.variable], dtype=float)
    if spec.per is None:
        return y[-1:]
    n = np.rint(np.asarray(columns[spec.per], dtype=float)).astype(int)
    counts = sorted(set(n[n >= 1].tolist()))
    return np.array([y[np.nonzero(n == k)[0][-1]] for k in counts])


@dataclass
class EventError:
    spec: EventSpec
    error: float          # relative, see module docstring; inf when the counts differ
    run: np.ndarray
    reference: np.ndarray
    reason: str = ""


def event_error(spec: EventSpec, run: dict, reference: dict) -> EventError:
    """One entry's error of `run` against `reference` (dicts of columns)."""
    mine, theirs = event_values(spec, run), event_values(spec, reference)
    if len(mine) != len(theirs):
        return EventError(spec, math.inf, mine, theirs,
                          f"{spec.per}: {len(mine)} events in the run, {len(theirs)} in the "
                          f"reference")
    if len(theirs) == 0:
        return EventError(spec, 0.0, mine, theirs)
    scale = float(np.mean(np.abs(theirs))) or 1.0
    return EventError(spec, float(np.max(np.abs(mine - theirs))) / scale, mine, theirs)


def event_errors(specs: list[EventSpec], run: dict, reference: dict) -> list[EventError]:
    return [event_error(s, run, reference) for s in specs]
