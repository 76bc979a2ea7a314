"""Build-time FMI tooling: modelDescription writer, units, FMU build (not bundled in FMUs)."""
