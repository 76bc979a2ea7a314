"""Progress of the studies on stderr: notes (the logger "crankfmu", -q hides them) and bars over
the items of a long step."""
from __future__ import annotations

import logging

progress = logging.getLogger("crankfmu").info   # a note on stderr (-q hides it)


def progress_over(items, label: str, unit: str):
    """`items`, with a progress bar on stderr while they are worked through: on a terminal
    only (tqdm's disable=None), and not with -q (which hides the notes too)."""
    if not logging.getLogger("crankfmu").isEnabledFor(logging.INFO):
        return items
    from tqdm import tqdm
    return tqdm(items, desc=label, unit=unit, disable=None, leave=False)
