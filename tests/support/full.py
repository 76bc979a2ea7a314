"""Quick subsets and their full studies. A test that checks a property on a subset (fewer
cases, a shorter span, a seeded sample) to keep the suite under a minute takes the full set when
CRANKFMU_FULL_TESTS=1; `python scripts/full_checks.py` runs those tests so. Each such test's
docstring names its subset and the command of its full study."""
from __future__ import annotations

import os

FULL = os.environ.get("CRANKFMU_FULL_TESTS") == "1"


def quick_or_full(quick, full):
    """`full` under scripts/full_checks.py (CRANKFMU_FULL_TESTS=1), else `quick`."""
    return full if FULL else quick
