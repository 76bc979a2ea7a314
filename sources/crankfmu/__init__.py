"""crankfmu: FMI 2.0 co-simulation components for crank-driven forming machines."""
__version__ = "0.1.0"
