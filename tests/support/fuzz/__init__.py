"""The project's seeded fuzzer (issue #16): hostile scene files, SSP archives and `--set` values.

`scenes.py`, `ssp.py` and `overrides.py` generate cases from a seed (the same seed gives the same
cases); `tests/test_fuzz_quick.py` runs a small subset in-process, `scripts/fuzz.py` the full
campaign, each case with a time limit, and prints the tally.
"""
