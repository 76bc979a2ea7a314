"""Master algorithms, one file each on the shared base `Master` (see base.py for the contract)."""
from .adaptive import Adaptive
from .base import DivergenceError, Master
from .gauss_seidel import GaussSeidel
from .iterative import Iterative
from .jacobi import Jacobi

MASTERS: dict[str, type[Master]] = {
    cls.name: cls for cls in (GaussSeidel, Jacobi, Iterative, Adaptive)}


def make_master(algorithm: str, system, settings) -> Master:
    try:
        cls = MASTERS[algorithm]
    except KeyError:
        raise ValueError(f"master algorithm {algorithm!r} is not available; available: "
                         f"{', '.join(MASTERS)}") from None
    return cls(system, settings)


__all__ = ["DivergenceError", "Master", "MASTERS", "make_master"]
