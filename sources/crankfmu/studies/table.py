"""A study's table as the Python API returns it: named columns, one dict per row, the unit of
each column (FMI's spelling, "1" dimensionless, None for text), and `to_pandas()`; on disk the
same table is a CSV with plain column names and a JSON sidecar whose "units" maps each column
to its unit (docs/cli.md: units are never part of a column's name)."""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np


class Table:
    """Mixed into a study's result: `columns`, `rows` (dicts column -> value) and `units`
    (column -> unit) are the table."""

    if TYPE_CHECKING:  # fields of a dataclass (SweepTable) or properties (the others)
        @property
        def columns(self) -> list[str]: ...

        @property
        def rows(self) -> list[dict]: ...

        @property
        def units(self) -> dict: ...

    def column(self, name: str) -> np.ndarray:
        """One numeric column as an array (nan where a row has no number)."""
        return np.array([_number(r.get(name)) for r in self.rows], dtype=float)

    def to_pandas(self):
        """A pandas DataFrame of the table (needs pandas); the units in `df.attrs["units"]`."""
        return data_frame(self.rows, self.columns, self.units)

    def __len__(self) -> int:
        return len(self.rows)


def data_frame(rows, columns: list[str], units: dict, index: str | None = None):
    """A DataFrame of `rows` (dicts or sequences in `columns` order), `df.attrs["units"]` =
    `units`; ImportError saying how to get pandas without it."""
    try:
        import pandas as pd
    except ImportError:
        raise ImportError("to_pandas needs pandas: pip install pandas") from None
    df = pd.DataFrame(list(rows), columns=columns)
    if index is not None:
        df = df.set_index(index)
    df.attrs["units"] = dict(units)
    return df


def _number(value) -> float:
    return value if isinstance(value, (int, float)) and not isinstance(value, bool) \
        else float("nan")
