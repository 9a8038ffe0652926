"""Tidy tables: a benchmark's per-unit rows as CSV beside its JSON.

One row per observation, one column per variable, a header of plain snake_case names that say
their unit where they have one (``sim_s``, ``path_m``); booleans as ``true``/``false``, missing
values empty, floats in full (``repr``) precision. ``pandas.read_csv(path)`` and
``polars.read_csv(path)`` read the file with the right types and no options.
"""

from __future__ import annotations

import csv
import math
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path


def _cell(v: object) -> str:
    """One value as CSV text (see the module docstring)."""
    if v is None:
        return ""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return "" if not math.isfinite(v) else repr(v)
    return str(v)


def write_csv(
    path: Path | str, columns: Sequence[str], rows: Iterable[Mapping[str, object]]
) -> Path:
    """Write ``rows`` (mappings with exactly the keys ``columns``) to ``path`` as CSV with a
    header line; returns the path."""
    path = Path(path)
    cols = list(columns)
    with path.open("w", newline="") as f:
        w = csv.writer(f, lineterminator="\n")
        w.writerow(cols)
        for i, row in enumerate(rows):
            if set(row) != set(cols):
                missing = sorted(set(cols) - set(row))
                extra = sorted(set(row) - set(cols))
                raise ValueError(f"{path}: row {i}: missing {missing}, unexpected {extra}")
            w.writerow([_cell(row[c]) for c in cols])
    return path
