"""One field of a log, row by row, in blocks: what lets a log be appended to as a run goes.

A run's log (sim/log.py, SimLog) keeps each field (``t``, ``state``, ``thrust``, a diagnostic)
as a :class:`FieldRows`: rows are appended into blocks of :data:`BLOCK_ROWS`, so a log never
needs its run's length up front, and reading the field joins the blocks into one array once
(kept joined until the next append).
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["BLOCK_ROWS", "FieldRows"]

# Rows per block: 1024 rows of a 12-state run's widest field are 96 kB; an hour at 0.05 s
# (72,000 rows) is 71 blocks, joined once when the log is read.
BLOCK_ROWS = 1024


class FieldRows:
    """The rows of one field: each ``shape`` of ``dtype``, or a string (``text``: a status).

    :meth:`values` is every row appended, as one array (a list for text); writing into it
    writes the field (it is the field's storage until the next append)."""

    def __init__(
        self, shape: tuple[int, ...] = (), dtype: type = float, text: bool = False
    ) -> None:
        self.shape, self.dtype, self.text = shape, dtype, text
        self._blocks: list[Any] = []  # arrays (lists for text); the last one is being filled
        self._filled = 0  # rows in the last block
        self.count = 0  # rows appended

    def __len__(self) -> int:
        return self.count

    def append(self, value: Any) -> None:
        """One more row (copied into the field's block)."""
        if not self._blocks or self._filled == len(self._blocks[-1]):
            self._blocks.append([""] * BLOCK_ROWS if self.text else self._new_block())
            self._filled = 0
        self._blocks[-1][self._filled] = value
        self._filled += 1
        self.count += 1

    def _new_block(self) -> np.ndarray:
        return np.empty((BLOCK_ROWS, *self.shape), dtype=self.dtype)

    def values(self) -> Any:
        """Every row appended: one array (a list for text), the blocks joined into one the
        first time it is read after an append."""
        if len(self._blocks) == 1 and self._filled == len(self._blocks[0]):
            return self._blocks[0]
        parts = [*self._blocks[:-1], self._blocks[-1][: self._filled]] if self._blocks else []
        if self.text:
            joined: Any = [text for part in parts for text in part]
        elif parts:
            joined = np.concatenate(parts)
        else:
            joined = np.empty((0, *self.shape), dtype=self.dtype)
        self.replace(joined)
        return joined

    def replace(self, values: Any) -> None:
        """The field's rows are ``values`` (held as given: a list for text, else an array)."""
        values = values if not self.text or isinstance(values, list) else list(values)
        values = values if self.text else np.asarray(values)
        self._blocks, self._filled = [values], len(values)
        self.count = len(values)

    def __getstate__(self) -> dict[str, Any]:
        self.values()  # joined: a pickled log carries no unused block rows
        return self.__dict__
