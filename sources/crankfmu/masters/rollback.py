"""Rollback: save every FMU's state at a step's start and go back to it (fmi2GetFMUstate,
fmi2SetFMUstate). A part the master base composes; testable alone."""
from __future__ import annotations


class Rollback:
    def __init__(self, system, master_name: str, required: bool):
        """`required`: the master cannot work without it; an FMU that cannot roll back is then
        named at once (not at the first rejected step)."""
        self.system = system
        if required:
            for name, fmu in system.fmus.items():
                if not fmu.can_rollback:
                    raise ValueError(f"master {master_name} rolls FMUs back, but {name} "
                                     f"({fmu.path.name}) has canGetAndSetFMUstate = false")
        self.available = all(f.can_rollback for f in system.fmus.values())

    def save(self) -> dict:
        return {c: f.get_state() for c, f in self.system.fmus.items()}

    def restore(self, states: dict, comps=None) -> None:
        for c in comps or states:
            self.system.fmus[c].set_state(states[c])

    def free(self, states: dict) -> None:
        for c, s in states.items():
            self.system.fmus[c].free_state(s)
