"""Every repository path and crankfmu module that the docs and the docstrings and comments name
exists: a contract that points to a file shows where to look, and a stale one misleads (before:
masters/base.py named tests/examples/masters/halving.py, masters/history.py and inputs.py a
missing tests/test_master_parts.py, runtime/model.py a crankfmu.studies.reference, the model
cards a MODELS.md that is not in the repository).

Checked in README.md, docs/*.md, the model cards, tests' .md files, the scene files' comments
(scenarios/**/*.toml) and every .py file of sources/, tests/, scripts/ and benchmarks/: paths under the repository's folders (tests/..., docs/..., scripts/...,
benchmarks/..., scenarios/..., sources/...), paths inside the package (cosim/runner.py,
models/dc_motor/README.md, ...), and dotted names crankfmu.x.y (a module, or an attribute of the
longest module prefix).

And README.md stays a README (at most README_MOST_LINES lines) that links every docs/*.md page.
"""
from __future__ import annotations

import importlib
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "sources" / "crankfmu"
TOP = ("tests", "docs", "scripts", "benchmarks", "scenarios", "sources")
INSIDE = tuple(p.name for p in PACKAGE.iterdir() if p.is_dir() and not p.name.startswith("_"))
SUFFIXES = r"(?:py|md|toml|c|png|ssp)"
REPO_PATH = re.compile(rf"(?<![\w/.-])((?:{'|'.join(TOP)})/[\w./-]*\.{SUFFIXES})\b")
PACKAGE_PATH = re.compile(rf"(?<![\w/.-])((?:{'|'.join(INSIDE)})/[\w./-]*\.{SUFFIXES})\b")
MODULE = re.compile(r"(?<![\w.])(?<!getLogger\(\")(crankfmu(?:\.[A-Za-z_]\w*)+)")
NOT_HERE = ("MODELS.md", "DESIGN.md")  # the project's planning notes, outside the repository


def texts() -> list[Path]:
    files = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md")),
             *sorted(PACKAGE.rglob("*.md")), *sorted((ROOT / "tests").rglob("*.md")),
             *sorted((ROOT / "scenarios").rglob("*.toml"))]
    for top in ("sources", "tests", "scripts", "benchmarks"):
        files += sorted((ROOT / top).rglob("*.py"))
    return [f for f in files if "__pycache__" not in f.parts and f != Path(__file__)]


def resolves(name: str) -> bool:
    """A crankfmu module, or an attribute chain on the longest importable prefix."""
    parts = name.split(".")
    for k in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:k]))
        except ImportError:
            continue
        for attr in parts[k:]:
            if not hasattr(obj, attr):
                return False
            obj = getattr(obj, attr)
        return True
    return False


def problems(path: Path) -> list[str]:
    text = path.read_text(errors="replace")
    where = path.relative_to(ROOT)
    found = [f"{where}: names {n}, which is not in the repository" for n in NOT_HERE
             if n in text and path != Path(__file__)]
    for m in REPO_PATH.finditer(text):
        if not (ROOT / m.group(1)).exists():
            found.append(f"{where}: {m.group(1)} does not exist")
    for m in PACKAGE_PATH.finditer(text):
        candidates = [PACKAGE / m.group(1), path.parent / m.group(1), ROOT / m.group(1)]
        if not any(c.exists() for c in candidates):
            found.append(f"{where}: {m.group(1)} does not exist under sources/crankfmu/")
    for m in MODULE.finditer(text):
        if not resolves(m.group(1)):
            found.append(f"{where}: {m.group(1)} is no module or attribute of crankfmu")
    return found


def test_every_named_path_and_module_exists():
    stale = [p for f in texts() for p in problems(f)]
    assert stale == [], "\n".join(stale)


def test_the_checker_finds_a_stale_name(tmp_path):
    """The check can fail: a made-up file naming a missing path, module and the notes."""
    fake = ROOT / "tests" / "_stale_example.py"
    fake.write_text('"""See tests/test_nothing_here.py, cosim/nothing.py, crankfmu.cosim.nothing '
                    'and crankfmu.cosim.runner.no_such_function; ' + NOT_HERE[0] + '."""\n')
    try:
        found = problems(fake)
    finally:
        fake.unlink()
    assert len(found) == 5, found


README_MOST_LINES = 250  # a README read in five minutes; the rest lives in docs/ (issue #28)


def test_the_readme_is_short_and_links_every_docs_page():
    """README.md fits its budget, and every docs/*.md page is reachable from it by a link."""
    readme = (ROOT / "README.md").read_text()
    lines = readme.count("\n") + (not readme.endswith("\n"))
    assert lines <= README_MOST_LINES, f"README.md has {lines} lines, at most {README_MOST_LINES}"
    linked = set(re.findall(r"\]\((docs/[\w.-]+\.md)(?:#[\w-]*)?\)", readme))
    pages = {f"docs/{p.name}" for p in (ROOT / "docs").glob("*.md")}
    assert pages - linked == set(), f"docs pages the README does not link: {sorted(pages - linked)}"
