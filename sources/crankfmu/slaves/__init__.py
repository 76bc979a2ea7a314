"""FMI plumbing: one generic pythonfmu adapter serves every physics model."""
