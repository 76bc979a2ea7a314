"""SI units as FMI 2.0 UnitDefinitions (base-unit exponents; factor for non-SI display units)."""
from __future__ import annotations

# unit string -> exponents of kg, m, s, A, rad (and a factor to SI where it is not 1)
BASE_UNITS: dict[str, dict[str, float]] = {
    "1": {},
    "s": {"s": 1}, "1/s": {"s": -1},
    "m": {"m": 1}, "m/s": {"m": 1, "s": -1}, "m/s2": {"m": 1, "s": -2}, "m2": {"m": 2},
    "kg": {"kg": 1}, "kg.m2": {"kg": 1, "m": 2}, "kg/m3": {"kg": 1, "m": -3},
    "rad": {"rad": 1}, "rad/s": {"rad": 1, "s": -1}, "rad/s2": {"rad": 1, "s": -2},
    "rpm": {"rad": 1, "s": -1, "factor": 0.10471975511965977},
    "N": {"kg": 1, "m": 1, "s": -2}, "N/m": {"kg": 1, "s": -2},
    "N.s": {"kg": 1, "m": 1, "s": -1}, "N.m": {"kg": 1, "m": 2, "s": -2},
    "N.m.s/rad": {"kg": 1, "m": 2, "s": -1, "rad": -1},
    "J": {"kg": 1, "m": 2, "s": -2}, "W": {"kg": 1, "m": 2, "s": -3},
    "Pa": {"kg": 1, "m": -1, "s": -2},
    "V": {"kg": 1, "m": 2, "s": -3, "A": -1}, "A": {"A": 1},
    "ohm": {"kg": 1, "m": 2, "s": -3, "A": -2}, "H": {"kg": 1, "m": 2, "s": -2, "A": -2},
    "V.s/rad": {"kg": 1, "m": 2, "s": -2, "A": -1, "rad": -1},
    "V/rad": {"kg": 1, "m": 2, "s": -3, "A": -1, "rad": -1},
}


def base_unit_attributes(unit: str) -> dict[str, str] | None:
    """Attributes of <BaseUnit> for a unit string, or None where exponents are not integral
    (e.g. N/m1.5 of a Hertz contact): such units are declared by name only."""
    spec = BASE_UNITS.get(unit)
    if spec is None:
        return None
    return {k: (repr(float(v)) if k == "factor" else str(int(v))) for k, v in spec.items()}
