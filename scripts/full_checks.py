"""The suite's full studies: every test that checks a property on a quick subset (tests/support/
full.py: fewer cases, shorter spans, a seeded sample) run on its full set instead, with pytest
(pytest-xdist's workers as `python -m pytest`).

    python scripts/full_checks.py [PYTEST ARGS]

Without arguments it runs every test file that has such a subset; with arguments, what they
name (e.g. `tests/test_fmi3.py -k model_exchange_matches`). Takes several minutes.
"""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def files_with_subsets() -> list[str]:
    return sorted(str(p.relative_to(ROOT)) for p in (ROOT / "tests").glob("test_*.py")
                  if "tests.support.full import" in p.read_text())


def main(argv: list[str]) -> int:
    args = argv or files_with_subsets()
    env = {**os.environ, "CRANKFMU_FULL_TESTS": "1"}
    return subprocess.run([sys.executable, "-m", "pytest", *args], cwd=ROOT, env=env).returncode


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
