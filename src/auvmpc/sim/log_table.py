"""log.csv read back as a checked table: the one reader's first half.

:func:`read_log_table` reads a log.csv's text into a :class:`LogTable` (a header with ``t``
and rows of as many fields), or refuses the file in one line naming what is damaged; the
table's methods read its columns with the same checks for every reader of a log
(``SimLog.from_table`` in sim/log.py, identification's readers).
"""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from auvmpc.errors import ConfigError

__all__ = ["MAX_LOG_BYTES", "LogTable", "read_log_table"]

# A log.csv read whole: an hour at 0.05 s with 8 thrusters is about 60 MB; four times that
# stays well inside memory (the rows are parsed once).
MAX_LOG_BYTES = 256 * 1024 * 1024


@dataclass(frozen=True)
class LogTable:
    """log.csv's text checked as a table: a header with ``t`` and rows of as many fields
    (:func:`read_log_table`). Its methods read columns with the same checks for every reader
    of a log (:meth:`SimLog.read_csv`, identification's): each damage is one line naming
    ``field``, the file, the line and the column."""

    path: Path
    field: str
    header: list[str]
    rows: list[list[str]]  # the data rows; row i is the file's line i + 2

    def damaged(self, reason: str) -> ConfigError:
        return ConfigError(self.field, str(self.path), f"{self.path.name} {reason}")

    def frame(self) -> pd.DataFrame:
        """The table as a DataFrame with its columns by name, every number exactly as
        written (Python's float parser); a text column (``status``) stays text, an empty
        cell is NaN."""
        columns: dict[str, Any] = {}
        for i, name in enumerate(self.header):
            cells = [row[i] for row in self.rows]
            try:
                columns[name] = np.array([float(c) if c else np.nan for c in cells])
            except ValueError:
                columns[name] = cells
        return pd.DataFrame(columns)

    def require(self, names: Sequence[str], what: str) -> None:
        """Every one of ``names`` must be a column (``what``: whose log has them)."""
        missing = [name for name in names if name not in self.header]
        if missing:
            raise self.damaged(f"has no column {', '.join(missing)}, which a {what} run's log has")

    def _cells(self, name: str, rows: slice) -> list[str]:
        i = self.header.index(name)
        return [row[i] for row in self.rows[rows]]

    def texts(self, name: str, rows: slice = slice(None)) -> list[str]:
        """Column ``name`` as text; an empty cell is damage (a status is never empty)."""
        cells = self._cells(name, rows)
        for k, cell in enumerate(cells):
            if not cell:
                raise self.damaged(f"line {k + 2}, column {name}: empty, where a value belongs")
        return cells

    def numbers(
        self,
        name: str,
        rows: slice = slice(None),
        finite: bool = True,
        empty_is_inf: bool = False,
    ) -> np.ndarray:
        """Column ``name`` as floats (exactly as written); ``finite``: NaN or inf is damage;
        ``empty_is_inf``: an empty cell is inf (no obstacle), the only non-finite value."""
        values = np.empty(len(self.rows[rows]))
        for k, cell in enumerate(self._cells(name, rows)):
            if empty_is_inf and not cell:
                values[k] = math.inf
                continue
            try:
                values[k] = float(cell)
            except ValueError:
                where = f"line {k + 2}, column {name}"
                raise self.damaged(
                    f"{where}: empty, where a number belongs"
                    if not cell
                    else f"{where}: {cell[:20]!r} is not a number"
                ) from None
            if (finite or empty_is_inf) and not math.isfinite(values[k]):
                raise self.damaged(
                    f"line {k + 2}, column {name}: {cell!r}, a value the log never holds there"
                )
        return values

    def increasing(self, name: str, values: np.ndarray) -> None:
        """Column ``name``'s ``values`` (read by :meth:`numbers`) must increase row by row."""
        later = np.diff(values) > 0
        if not later.all():
            k = int(np.argmin(later)) + 1
            raise self.damaged(
                f"line {k + 2}, column {name}: {float(values[k])!r} is not after the line "
                f"before's {float(values[k - 1])!r}"
            )

    def final_row_empty(self, names: Sequence[str]) -> None:
        """Per-command ``names`` are empty on the final row (the state after the last
        command); a final row with a command is a log cut at a row boundary."""
        last = self.rows[-1]
        if any(last[self.header.index(name)] for name in names):
            raise self.damaged(
                f"ends at line {len(self.rows) + 1} with a command: its final row (the state "
                "after the last command, no command) is missing, so the log was cut short"
            )


def read_log_table(path: str | Path, field: str = "log") -> LogTable:
    """A log.csv's header and rows, or one :class:`~auvmpc.errors.ConfigError` line naming
    ``field``, the file and what is damaged: no such file, a folder, a binary file or one not
    UTF-8, larger than :data:`MAX_LOG_BYTES`, not CSV, empty, a first line without ``t``
    (not a log's header), a row with another number of fields than the header, a last line
    without its end (a file cut mid-row: the writer ends every row)."""
    from auvmpc.safe_yaml import read_text_file

    path = Path(path)
    text = read_text_file(path, field, "log.csv", MAX_LOG_BYTES)
    table = LogTable(path, field, [], [])
    try:
        rows = list(csv.reader(io.StringIO(text, newline="")))
    except csv.Error as error:
        raise table.damaged(f"is not a CSV table ({error})") from None
    if not rows:
        raise table.damaged("is empty")
    header = rows[0]
    if "t" not in header:
        raise table.damaged(
            "does not start with a log's header (its first line has no column t): "
            "not a log auvmpc wrote"
        )
    if not text.endswith("\n"):
        raise table.damaged(
            f"ends in the middle of line {len(rows)} (no line end): the file was cut short"
        )
    for line, row in enumerate(rows[1:], start=2):
        if len(row) != len(header):
            raise table.damaged(
                f"line {line} has {len(row)} fields, its header {len(header)}: "
                "the file was cut short or edited"
            )
    return replace(table, header=header, rows=rows[1:])
