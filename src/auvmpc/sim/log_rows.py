"""One field of a log, row by row, in blocks: what lets a log be appended to as a run goes.

A run's log (sim/log.py, SimLog) keeps each field (``t``, ``state``, ``thrust``, a diagnostic)
as a :class:`FieldRows`: rows are appended into blocks of :data:`BLOCK_ROWS`, so a log never
needs its run's length up front, and reading the field joins the blocks into one array once
(kept joined until the next append). A field whose rows a live log has written can forget them
(:meth:`FieldRows.forget_full_blocks`): it then holds at most one block, whatever the run's
length.
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["BLOCK_ROWS", "FieldRows", "RowsForgotten"]

# Rows per block: 1024 rows of a 12-state run's widest field are 96 kB; an hour at 0.05 s
# (72,000 rows) is 71 blocks, joined once when the log is read.
BLOCK_ROWS = 1024


class RowsForgotten(LookupError):
    """A field's first rows were forgotten (a live log has them): read the live log."""


class FieldRows:
    """The rows of one field: each ``shape`` of ``dtype``, or a string (``text``: a status).

    :meth:`values` is every row appended, as one array (a list for text); writing into it
    writes the field (it is the field's storage until the next append)."""

    def __init__(
        self, name: str, shape: tuple[int, ...] = (), dtype: type = float, text: bool = False
    ) -> None:
        self.name, self.shape, self.dtype, self.text = name, shape, dtype, text
        self._blocks: list[Any] = []  # arrays (lists for text); the last one is being filled
        self._filled = 0  # rows in the last block
        self.count = 0  # rows appended, forgotten ones included
        self.forgotten = 0  # rows no longer held (a live log has them)
        self._forgetting = False

    def __len__(self) -> int:
        return self.count

    def append(self, value: Any) -> None:
        """One more row (copied into the field's block)."""
        if not self._blocks or self._filled == len(self._blocks[-1]):
            if self._forgetting and self._blocks:
                # Its rows are written: the full block is reused for the next ones.
                self.forgotten = self.count
                self._blocks = self._blocks[-1:]
            else:
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
        if self.forgotten:
            raise RowsForgotten(
                f"the log's {self.name!r} holds only its last rows in memory: its first "
                f"{self.forgotten} are in its live log (read it with SimLog.read_csv)"
            )
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
        self.count, self.forgotten = len(values), 0

    def forget_full_blocks(self) -> None:
        """From now on a full block is forgotten rather than kept (a live log has its rows):
        the field holds at most one block; reading it is then refused (RowsForgotten)."""
        self._forgetting = True

    def held(self) -> int:
        """How many rows are in memory."""
        return self.count - self.forgotten

    def __getstate__(self) -> dict[str, Any]:
        if not self.forgotten:
            self.values()  # joined: a pickled log carries no unused block rows
        return self.__dict__
