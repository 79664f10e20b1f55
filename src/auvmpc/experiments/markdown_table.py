"""Markdown tables of result rows whose columns are described once: the table and its legend
(each column's unit and meaning) are written from the same :class:`Column` list, so the
legend cannot drift from the columns."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

__all__ = ["Column", "cell", "legend", "table"]


@dataclass(frozen=True)
class Column:
    """One column: the row's ``key``, its ``unit`` ("" for names and counts), what it means
    and, if the key is not to head the column, a ``title`` (the unit is appended to it)."""

    key: str
    meaning: str
    unit: str = ""
    title: str | None = None

    @property
    def header(self) -> str:
        if self.title is None:
            return self.key
        return f"{self.title} ({self.unit})" if self.unit else self.title


def table(rows: Sequence[Mapping], columns: Sequence[Column]) -> list[str]:
    """The rows as markdown table lines, one cell per column."""
    lines = [
        "| " + " | ".join(column.header for column in columns) + " |",
        "|" + "---|" * len(columns),
    ]
    lines += ["| " + " | ".join(cell(row[c.key]) for c in columns) + " |" for row in rows]
    return lines


def legend(columns: Sequence[Column], key_heading: str | None = None) -> list[str]:
    """One line per column: its header, unit and meaning; with ``key_heading`` also its key
    (where the same value is found under that name, e.g. in a CSV or JSON file)."""
    head = ["column", "unit", "meaning"]
    if key_heading is not None:
        head.insert(1, key_heading)
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for column in columns:
        cells = [column.header, column.unit, column.meaning]
        if key_heading is not None:
            cells.insert(1, f"`{column.key}`")
        lines.append("| " + " | ".join(cells) + " |")
    return lines


def cell(value) -> str:
    """``-`` for a missing value, 4 significant digits for a float, the rest as written."""
    if value is None:
        return "-"
    if isinstance(value, float):
        return f"{value:.4g}"
    return str(value)
