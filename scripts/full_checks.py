"""The suite's full studies: every test that checks a property on a quick subset (tests/support/
full.py: fewer cases, shorter spans, a seeded sample) run on its full set instead, with pytest
(pytest-xdist's workers as `python -m pytest`).

    python scripts/full_checks.py [PYTEST ARGS]

It runs every test file that has such a subset, or the tests the arguments name (e.g.
`tests/test_fmi3.py -k model_exchange_matches`); arguments that name no test (`-q`, `-k x`)
go to pytest with the files. The whole suite on its full sets: `CRANKFMU_FULL_TESTS=1 python -m
pytest`. Times: docs/testing.md.
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


def names_tests(arg: str) -> bool:
    return arg.startswith("tests") or arg.endswith(".py") or "::" in arg


def main(argv: list[str]) -> int:
    args = argv if any(map(names_tests, argv)) else [*argv, *files_with_subsets()]
    env = {**os.environ, "CRANKFMU_FULL_TESTS": "1"}
    return subprocess.run([sys.executable, "-m", "pytest", *args], cwd=ROOT, env=env).returncode


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
