"""Monolithic references: a scene's physics models composed into one ODE, solved by scipy."""
from .composed import ComposedModel, CompositionError
from .solve import DEFAULT_RTOL, ReferenceResult, record_times, solve_reference, write_reference

__all__ = ["ComposedModel", "CompositionError", "DEFAULT_RTOL", "ReferenceResult",
           "record_times", "solve_reference", "write_reference"]
