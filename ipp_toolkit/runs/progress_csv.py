"""A training run's ``progress.csv``: one row per update, one column per logged quantity.

The one reader of the file (:func:`read_progress_csv`), for a learner resuming its history
(:func:`coma.run_files.read_progress`, strict: a damaged file is an error) and for the report
that draws the curves (:func:`reports.training.read_progress`, lenient: a missing cell is
empty). Cells are parsed by :func:`parse_cell`: empty is None, an integer is an int, any
other number a float.
"""

from __future__ import annotations

import csv
import os
from collections.abc import Sequence
from typing import Any

__all__ = ["read_progress_csv", "parse_cell"]


def parse_cell(text: str) -> Any:
    """None for an empty cell, an int for an integer (no ``.`` or exponent), else a float.

    Raises:
        ValueError: the cell is not a number.
    """
    if text == "":
        return None
    number = float(text)
    return int(number) if number.is_integer() and "." not in text and "e" not in text \
        else number


def read_progress_csv(path: str | os.PathLike[str], columns: Sequence[str] | None = None,
                      strict: bool = True) -> list[dict[str, Any]]:
    """The rows of a ``progress.csv``, each a dict of column -> parsed cell (:func:`parse_cell`).

    Args:
        path: the file.
        columns: the header the file must have (any header when None).
        strict: a row with the wrong number of cells is an error; otherwise its missing
            cells are None and its extra cells are dropped.

    Raises:
        OSError, UnicodeDecodeError, csv.Error: the file cannot be read.
        ValueError: another header than ``columns``, a row with the wrong number of cells
            (``strict``), or a cell that is not a number.
    """
    with open(path, newline="", encoding="utf-8") as handle:
        reader = csv.DictReader(handle)
        if columns is not None and (reader.fieldnames is None
                                    or list(reader.fieldnames) != list(columns)):
            raise ValueError(f"its header is not {','.join(columns)}")
        rows = []
        for row in reader:
            if None in row or any(value is None for value in row.values()):
                if strict:
                    raise ValueError(f"line {reader.line_num} has the wrong number of cells")
                row.pop(None, None)  # type: ignore[call-overload]
            rows.append({k: None if v is None else parse_cell(v) for k, v in row.items()})
    return rows
