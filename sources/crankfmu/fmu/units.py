"""SI units as FMI 2.0 UnitDefinitions: base-unit exponents derived from the unit string.

A unit string is parsed, not looked up: `N.m/rad`, `kg.m2/s`, `rad/s3`, `V.s/rad`, `1/s2`,
`N/m1.5` or `N(2/3)/m` are products ('.') and quotients ('/') of symbols with optional
exponents (an integer, a decimal or a fraction in parentheses). Each symbol is defined once
below in SI base units (kg, m, s, A, K, mol, cd and rad, as FMI's BaseUnit knows them) with a
factor where it is not an SI unit (rpm, deg, min, h). The exponents of the whole string are the
sums; FMI's BaseUnit takes integer exponents only, so a unit whose exponents are not all
integral (e.g. `N(2/3)/m` of a Hertz contact) is declared by name only.
"""
from __future__ import annotations

import functools
import math
import re
from fractions import Fraction

BASE_SYMBOLS = ("kg", "m", "s", "A", "K", "mol", "cd", "rad")

# symbol -> (exponents of the base symbols, factor to SI). Derived SI units and the non-SI units
# in use; a new symbol is one line here, never a new composite unit.
SYMBOLS: dict[str, tuple[dict[str, int], float]] = {
    **{b: ({b: 1}, 1.0) for b in BASE_SYMBOLS},
    "1": ({}, 1.0),
    "g": ({"kg": 1}, 1e-3),
    "N": ({"kg": 1, "m": 1, "s": -2}, 1.0),
    "J": ({"kg": 1, "m": 2, "s": -2}, 1.0),
    "W": ({"kg": 1, "m": 2, "s": -3}, 1.0),
    "Pa": ({"kg": 1, "m": -1, "s": -2}, 1.0),
    "Hz": ({"s": -1}, 1.0),
    "C": ({"s": 1, "A": 1}, 1.0),
    "V": ({"kg": 1, "m": 2, "s": -3, "A": -1}, 1.0),
    "ohm": ({"kg": 1, "m": 2, "s": -3, "A": -2}, 1.0),
    "S": ({"kg": -1, "m": -2, "s": 3, "A": 2}, 1.0),
    "F": ({"kg": -1, "m": -2, "s": 4, "A": 2}, 1.0),
    "H": ({"kg": 1, "m": 2, "s": -2, "A": -2}, 1.0),
    "Wb": ({"kg": 1, "m": 2, "s": -2, "A": -1}, 1.0),
    "T": ({"kg": 1, "s": -2, "A": -1}, 1.0),
    "rpm": ({"rad": 1, "s": -1}, 2.0 * math.pi / 60.0),
    "deg": ({"rad": 1}, math.pi / 180.0),
    "min": ({"s": 1}, 60.0),
    "h": ({"s": 1}, 3600.0),
}

# one factor of a product: a symbol, then an optional exponent: 2, -1, 1.5 or (2/3)
_FACTOR = re.compile(r"([A-Za-z]+|1)(?:\((-?\d+/\d+)\)|(-?\d+(?:\.\d+)?))?")


class UnitError(ValueError):
    """A unit string that does not parse, or names an unknown symbol."""


def _product(text: str, unit: str) -> tuple[dict[str, Fraction], float]:
    text = text[1:-1] if text.startswith("(") and text.endswith(")") else text
    exps: dict[str, Fraction] = {}
    factor, pos = 1.0, 0
    while True:
        match = _FACTOR.match(text, pos)
        if not match:
            raise UnitError(f"unit {unit!r}: cannot read {text[pos:]!r}")
        symbol, frac, number = match.groups()
        if symbol not in SYMBOLS:
            raise UnitError(f"unit {unit!r}: unknown symbol {symbol!r} (known: "
                            f"{', '.join(SYMBOLS)})")
        power = Fraction(frac) if frac else Fraction(number) if number else Fraction(1)
        base, scale = SYMBOLS[symbol]
        for b, e in base.items():
            exps[b] = exps.get(b, Fraction(0)) + e * power
        factor *= scale ** float(power)
        pos = match.end()
        if pos == len(text):
            return exps, factor
        if text[pos] != ".":
            raise UnitError(f"unit {unit!r}: expected '.' or '/' at {text[pos:]!r}")
        pos += 1


@functools.lru_cache(maxsize=None)
def parse_unit(unit: str) -> tuple[dict[str, Fraction], float]:
    """(exponents of the base symbols, factor to SI) of a unit string; zero exponents dropped."""
    parts = re.split(r"/(?![^()]*\))", unit.strip())  # not the / of an exponent (2/3)
    if not all(parts):
        raise UnitError(f"unit {unit!r}: empty numerator or denominator")
    exps, factor = _product(parts[0], unit)
    for part in parts[1:]:  # a/b/c = a/(b.c)
        den, den_factor = _product(part, unit)
        for b, e in den.items():
            exps[b] = exps.get(b, Fraction(0)) - e
        factor /= den_factor
    return {b: exps[b] for b in BASE_SYMBOLS if exps.get(b)}, factor


def base_unit_attributes(unit: str) -> dict[str, str] | None:
    """Attributes of <BaseUnit> for a unit string, or None where the exponents are not all
    integral (FMI's BaseUnit takes integers): such a unit is declared by name only. Raises
    UnitError for a string that does not parse."""
    exps, factor = parse_unit(unit)
    if any(e.denominator != 1 for e in exps.values()):
        return None
    attrs = {b: str(int(e)) for b, e in exps.items()}
    if factor != 1.0:
        attrs["factor"] = repr(factor)
    return attrs
