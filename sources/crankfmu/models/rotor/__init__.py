"""Rotor and ShaftRotor: the two-mass test system of the masters. See README.md."""
