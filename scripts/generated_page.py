"""Docs pages that a script writes in part (docs/accuracy_tables.md, docs/error_estimate.md): the
text above the mark is written by hand (what the tables are and how to read them) and kept; below
it the script writes its tables, stamped with the command, the date and the machine, so every
figure on the page says how and where it was measured."""
from __future__ import annotations

import datetime
import os
import platform
import shlex
import sys
from pathlib import Path


def mark(script: str) -> str:
    return (f"<!-- generated below this line by {script}: edit the script or the text above, "
            "not this -->")


def machine() -> str:
    """The machine as it was when the tables were written: a shared machine's load moves the
    wall times in them."""
    one, five, fifteen = os.getloadavg()
    return (f"{platform.system()} {platform.machine()}, {os.cpu_count()} cores, load average "
            f"{one:.1f} / {five:.1f} / {fifteen:.1f} over 1 / 5 / 15 min when written")


def write_generated(page: Path, tables: str, script: str) -> None:
    """Write `tables` below the mark of `page`, keeping the hand-written text above it."""
    line = mark(script)
    text = page.read_text() if page.exists() else ""
    head = text.partition(line)[0] if line in text else ""
    command = shlex.join(["python", script, *sys.argv[1:]])
    stamp = f"Written {datetime.date.today().isoformat()} by `{command}` on {machine()}."
    page.write_text(f"{head}{line}\n\n{stamp}\n\n{tables}")
