"""The README's Python section runs as written (from the repository's folder, as a reader would
run it) and writes nothing there."""
from __future__ import annotations

import re

from tests.conftest import ROOT


def test_readme_python_section_runs(monkeypatch):
    text = (ROOT / "README.md").read_text()
    section = text.split("## Python API", 1)[1].split("\n## ", 1)[0]
    blocks = re.findall(r"```python\n(.*?)```", section, re.S)
    assert blocks and "crankfmu.simulate(" in blocks[0]
    monkeypatch.chdir(ROOT)
    before = {p for p in ROOT.iterdir() if p.name != "fmus"}
    results_before = set((ROOT / "results").rglob("*")) if (ROOT / "results").is_dir() else set()
    namespace: dict = {}
    for block in blocks:
        exec(compile(block, "README.md (Python API)", "exec"), namespace)
    assert namespace["result"].units["press.w_crank"] == "rad/s"
    assert type(namespace["fig"]).__name__ == "Figure"
    assert namespace["error"] < 0.5  # rad/s: jacobi at 2 ms against the reference
    assert {p for p in ROOT.iterdir() if p.name != "fmus"} == before
    after = set((ROOT / "results").rglob("*")) if (ROOT / "results").is_dir() else set()
    assert after == results_before
