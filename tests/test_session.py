"""What tests/conftest.py sets up for a test session's processes."""
from __future__ import annotations

import pytest

from tests.conftest import ROOT, SHARED, UNIT_SECONDS, _my_share, rewritten_pyc, unit_name


def test_each_worker_finds_its_share_of_the_test_files_rewritten(request):
    """A pytest-xdist worker rewrote its share of the test files before collecting
    (conftest._rewrite_my_share): pytest's cache holds each, current for the file's contents.
    Before, where bytecode is not written (PYTHONDONTWRITEBYTECODE=1, the CI machines), no
    rewritten file was cached and each worker rewrote them all (1.3 s of CPU each)."""
    from _pytest.assertion import rewrite

    config = request.config
    if not hasattr(config, "workerinput") or config.getoption("assertmode") != "rewrite":
        pytest.skip("only in a pytest-xdist worker, with pytest's assertion rewriting")
    share = _my_share(config)
    assert share is not None, "pytest's rewriting functions differ: the workers rewrite all"
    if not share:
        pytest.skip("this worker's share of the session's test files is empty")
    stale = [source.name for source in share if rewrite._read_pyc(source, rewritten_pyc(source))
             is None]
    assert stale == [], f"not rewritten before collection: {stale}"


def test_every_unit_the_schedule_times_exists():
    """The workers take the units longest first by UNIT_SECONDS (conftest's scheduler): a name
    there that is no test file and no SHARED unit (a file renamed) would lose its place."""
    files = {f"tests/{p.name}" for p in (ROOT / "tests").glob("test_*.py")}
    names = {unit_name(SHARED.get(f, f)) for f in files}
    assert set(UNIT_SECONDS) <= names, sorted(set(UNIT_SECONDS) - names)
