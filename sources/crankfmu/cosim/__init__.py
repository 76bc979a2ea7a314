"""Co-simulation over fmpy: FMU instances, wiring, master algorithms, recording, the runner."""
