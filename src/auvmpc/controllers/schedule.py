"""The reference as a controller flies it when the vehicle cannot keep the mission's pace.

A path with a speed profile is a point moving along the path on the mission's clock. A
vehicle that can no longer fly that fast (a jammed stern plane holds depth only at one
speed: models/level_flight.py) has to follow the same path later: it keeps its own place
on the path, a reference time ``tau`` that runs at the share ``rho`` of the clock the
slower speed allows, and is asked for the path's rows at ``tau + n rho Te`` instead of
``t + n Te``. The loop's reference stays the mission's; the controller reports how far
behind it flies (``schedule_lag_s`` = t - tau), and the metrics judge its tracking against
the reference it flew (sim/metrics.py, docs/verdict.md).

The rows it needs are behind the mission's point, where the loop no longer shows them, so
the schedule keeps every row it has been shown from its place on (rows are the reference
at whole samples; in between they are interpolated, the heading unwrapped). Until it is
first slowed it hands the loop's rows on untouched (bit for bit: a healthy run is the run
it was).
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["ReferenceSchedule", "pace_share", "rows_at"]

# A reference moving slower than this over ground (m/s) has no pace to slow.
_STILL_M_PER_S = 1e-6


def pace_share(ground: np.ndarray, current: np.ndarray, speed: float) -> float:
    """The share rho in [0, 1] of the reference's ground velocity ``ground`` (2,) that the
    vehicle flies at ``speed`` (m/s) through the water in the ``current`` (2,): the root of
    |rho g - c| = speed (1 if the whole of it is within ``speed``; 0 if the current alone is
    faster than ``speed`` along the path)."""
    g2 = float(ground @ ground)
    if g2 <= _STILL_M_PER_S**2 or float(np.hypot(*(ground - current))) <= speed:
        return 1.0
    along = float(ground @ current)
    discriminant = along**2 - g2 * (float(current @ current) - speed**2)
    if discriminant < 0.0:
        return 0.0
    return min(1.0, max(0.0, (along + math.sqrt(discriminant)) / g2))


class ReferenceSchedule:
    """The controller's own place on the reference (module docstring): rows whose first two
    columns are the horizontal position (m), one sample apart; ``heading_column``: their
    heading (unwrapped when interpolated); ``rate_columns``: their rates along the mission's
    clock (speeds, the turn rate, the climb rate), which the slower clock scales by rho."""

    def __init__(
        self, sample_time: float, heading_column: int, rate_columns: tuple[int, ...] = ()
    ) -> None:
        self.sample_time = sample_time
        self.heading_column = heading_column
        self.rate_columns = list(rate_columns)
        self.progress: float | None = None  # tau / Te now; None: on the mission's clock
        self._next = 0.0  # tau / Te at the next sample
        self._rows = np.empty((0, 0))  # the rows shown, from sample self._first on
        self._first = 0

    def lag(self, k: int) -> float:
        """How many samples behind the mission's clock the schedule is at sample ``k``."""
        return 0.0 if self.progress is None else k - self.progress

    def rows(
        self, k: int, reference: np.ndarray, count: int, speed: float | None, current: np.ndarray
    ) -> np.ndarray:
        """The ``count + 1`` rows to fly from sample ``k``, the loop's ``reference`` rows
        (samples k, k + 1, ...) shown: those rows themselves while on the mission's clock and
        the mission's pace is within ``speed`` (m/s through the water, in the horizontal
        ``current``; None: any pace); else the rows at tau + n rho (:func:`pace_share` of the
        path's ground velocity at tau), and tau moves on by rho."""
        reference = np.asarray(reference, dtype=float)
        if self.progress is None:
            if speed is None or pace_share(self._ground(reference, 0.0), current, speed) >= 1.0:
                return reference
            self._next = float(k)
        self.progress = self._next
        self._keep(k, reference)
        place = self.progress - self._first
        share = 1.0 if speed is None else pace_share(self._ground(self._rows, place), current,
                                                     speed)  # fmt: skip
        self._next = self.progress + share
        rows = self._at(self.progress + share * np.arange(count + 1))
        rows[:, self.rate_columns] *= share
        return rows

    def _ground(self, rows: np.ndarray, place: float) -> np.ndarray:
        """The path's ground velocity (m/s) at the fractional row ``place`` of ``rows``: that
        of the segment it is on (the last one, at the end)."""
        start = min(int(math.floor(place)), len(rows) - 2)
        return (rows[start + 1, :2] - rows[start, :2]) / self.sample_time

    def _keep(self, k: int, reference: np.ndarray) -> None:
        """Add the rows shown at sample ``k`` (samples k, k + 1, ...), and forget those
        before the schedule's place (set)."""
        if self._rows.size == 0:
            self._rows, self._first = reference.copy(), k
            return
        known = self._first + len(self._rows)
        if k + len(reference) > known:
            self._rows = np.vstack([self._rows, reference[known - k :]])
        behind = max(0, int(math.floor(self.progress)) - self._first)
        self._rows, self._first = self._rows[behind:], self._first + behind

    def _at(self, samples: np.ndarray) -> np.ndarray:
        """The rows at fractional ``samples``."""
        grid = np.arange(len(self._rows), dtype=float)
        return rows_at(self._rows, grid, samples - self._first, self.heading_column)


def rows_at(rows: np.ndarray, grid: np.ndarray, at: np.ndarray, heading_column: int) -> np.ndarray:
    """Reference ``rows`` (M, nr) given at ``grid`` (M,), at ``at`` instead: linear in
    between, the heading (column ``heading_column``) unwrapped first."""
    rows = np.array(rows, dtype=float)
    rows[:, heading_column] = np.unwrap(rows[:, heading_column])
    return np.column_stack([np.interp(at, grid, column) for column in rows.T])
