"""What a closed-loop run did, sample by sample, and its CSV form (log.csv).

Row k holds the TRUE plant state at t_k and the reference at t_k; the thrust on
row k is what was applied over [t_k, t_k+1), so the last row has none
(``shared/spec/interfaces.md``). Arrays are preallocated and time-major. The state columns
are named by the log's state layout: :class:`SimLog` is a horizontal run's
(``x, y, psi, u, v, r``), :class:`DepthLog` a depth run's (``z, w``), :class:`SixDofLog` a
6-DOF run's (the 12 states, its horizontal part first in log.csv); same loop, same rows. Each
kind declares its log.csv columns and the fields they hold (:meth:`SimLog.csv_columns`); one
writer and one reader serve them all.
"""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from auvmpc.models.layout import DEPTH, HORIZONTAL, Layout
from auvmpc.models.six_dof import HORIZONTAL_INDEX, SIX_DOF, SIX_DOF_MEASUREMENT

if TYPE_CHECKING:
    from auvmpc.controllers.base import ControlResult

__all__ = [
    "BACKOFF_NAMES",
    "CURRENT_NAMES",
    "DepthLog",
    "ESTIMATE_NAMES",
    "LiveLog",
    "REFERENCE_NAMES",
    "SimLog",
    "SixDofLog",
]

STATE_NAMES = HORIZONTAL.names
REFERENCE_NAMES = tuple(f"{name}_ref" for name in STATE_NAMES)
DISTURBANCE_NAMES = ("dist_X", "dist_Y", "dist_N")
# The world force and moment the controller's prediction used at sample k (its estimate with
# offset-free tracking, zero without), the shell's ``info`` keys.
ESTIMATE_NAMES = ("dist_X_hat", "dist_Y_hat", "dist_N_hat")
# What the robust tightening took at sample k (ocp/tightening.py; zero for a nominal
# controller): the largest obstacle back-off (m) and the largest fraction of a thruster's
# range given up, the shell's ``info`` keys.
BACKOFF_NAMES = ("obstacle_backoff_m", "thrust_backoff_fraction")
# A 6-DOF run: the depth reference (NED, m and m/s) and the water velocity at the vehicle
# (world NED, m/s).
DEPTH_REFERENCE_NAMES = ("z_ref", "z_rate_ref")
CURRENT_NAMES = ("current_north", "current_east", "current_down")


@dataclass(frozen=True)
class Column:
    """A block of log.csv's columns (``names``) and the log field it holds; a field in the
    log's ``PER_COMMAND`` has no value on the final row (empty cells there)."""

    names: tuple[str, ...]
    field: str | None  # None: written as 0 and not read (a column kept for the file's shape)
    part: slice | np.ndarray | list[int] | None = None  # the field's columns (None: all)
    text: bool = False  # strings (a status), as they are
    empty_is_inf: bool = False  # an empty cell is inf (no obstacle, no gap)
    optional: bool = False  # logs written before these columns have none (read as 0)


@dataclass
class SimLog:
    """Time-major record of one run (N samples, n thrusters, nx states of ``layout``)."""

    #: The plant state's names: the columns of ``state``.
    layout: ClassVar[Layout] = HORIZONTAL
    #: The reference's columns (what the controller is asked to follow, logged per row).
    reference_names: ClassVar[tuple[str, ...]] = REFERENCE_NAMES
    #: What the environment does at each row (``environment``'s columns): a horizontal
    #: run's external force, a depth run's wave force, a 6-DOF run's water current.
    environment_names: ClassVar[tuple[str, ...]] = DISTURBANCE_NAMES
    #: What the controller's sensors measure (``measured``'s columns, the session's
    #: measurement, in this order).
    measured_names: ClassVar[tuple[str, ...]] = HORIZONTAL.names
    #: The commands' names in log.csv: this prefix and the thruster's number from 1.
    input_prefix: ClassVar[str] = "F"

    t: np.ndarray  # (N+1,) s
    state: np.ndarray  # (N+1, nx) true plant state
    reference: np.ndarray  # (N+1, nr) reference_names
    thrust: np.ndarray  # (N, n) applied over [t_k, t_k+1)
    solve_ms: np.ndarray  # (N,) wall time of the controller call
    disturbance_estimate: np.ndarray  # (N, 3) what the controller assumed over [t_k, t_k+1)
    status: list[str]  # (N,) ControlStatus values
    environment: np.ndarray  # (N+1, nd) environment_names at t_k
    clearance_m: np.ndarray  # (N+1,) vehicle-to-obstacle gap, inf without obstacles
    sample_time: float
    initial_thrust: np.ndarray  # (n,) F(-1), what the first rate limit is measured from
    # (N+1, m) what the sensors gave at t_k (the controller's input on rows 0..N-1); in
    # memory only for horizontal and 6-DOF runs, whose log.csv keeps the truth.
    measured: np.ndarray
    backoff: np.ndarray  # (N, 2) BACKOFF_NAMES over [t_k, t_k+1)

    # The fields with a row per sample (N + 1) and those with a row per command (N); the
    # others (sample_time, initial_thrust) are the run's. :meth:`first` cuts by these lists,
    # so a new field goes in one of them (tests/test_session.py checks that every one is).
    PER_SAMPLE: ClassVar[tuple[str, ...]] = (
        "t", "state", "reference", "environment", "clearance_m", "measured",
    )  # fmt: skip
    PER_COMMAND: ClassVar[tuple[str, ...]] = (
        "thrust", "solve_ms", "disturbance_estimate", "status", "backoff",
    )  # fmt: skip

    @classmethod
    def allocate(cls, steps: int, n_thrusters: int, sample_time: float) -> SimLog:
        nx = cls.layout.size
        return cls(
            t=sample_time * np.arange(steps + 1, dtype=float),
            state=np.zeros((steps + 1, nx)),
            reference=np.zeros((steps + 1, len(cls.reference_names))),
            thrust=np.zeros((steps, n_thrusters)),
            solve_ms=np.zeros(steps),
            disturbance_estimate=np.zeros((steps, len(ESTIMATE_NAMES))),
            status=[""] * steps,
            environment=np.zeros((steps + 1, len(cls.environment_names))),
            clearance_m=np.full(steps + 1, math.inf),
            sample_time=sample_time,
            initial_thrust=np.zeros(n_thrusters),
            measured=np.zeros((steps + 1, len(cls.measured_names))),
            backoff=np.zeros((steps, len(BACKOFF_NAMES))),
        )

    @property
    def steps(self) -> int:
        return len(self.thrust)

    def first(self, rows: int) -> SimLog:
        """A copy of the log's first ``rows`` samples (and so ``rows - 1`` commands)."""
        cut = {name: getattr(self, name)[:rows].copy() for name in self.PER_SAMPLE}
        cut.update({name: getattr(self, name)[: rows - 1].copy() for name in self.PER_COMMAND})
        return replace(self, **cut)

    @property
    def input_names(self) -> tuple[str, ...]:
        """The commands' names: the thrust columns of log.csv."""
        return tuple(f"{self.input_prefix}{i + 1}" for i in range(self.n_thrusters))

    @property
    def n_thrusters(self) -> int:
        return self.thrust.shape[1]

    def horizontal(self) -> SimLog:
        """The horizontal view: ``[x, y, psi, u, v, r]``, their reference and the horizontal
        thrusters (what 3-DOF metrics and figures read); a horizontal log is its own."""
        return self

    def record_command(
        self, k: int, result: ControlResult, thrust: np.ndarray, solve_ms: float
    ) -> None:
        """Row k's command: the (checked) thrust, how it came, the controller call's wall
        time and the diagnostics the log keeps of the controller's ``info``."""
        self.thrust[k] = thrust
        self.solve_ms[k] = solve_ms
        self.status[k] = str(result.status)
        self.disturbance_estimate[k] = [result.info.get(name, 0.0) for name in ESTIMATE_NAMES]
        self.backoff[k] = [result.info.get(name, 0.0) for name in BACKOFF_NAMES]

    def csv_columns(self) -> tuple[Column, ...]:
        """log.csv's columns, in order, and the fields they hold."""
        return (
            Column(("t",), "t"),
            Column(STATE_NAMES, "state"),
            Column(REFERENCE_NAMES, "reference"),
            Column(self.input_names, "thrust"),
            Column(("solve_ms",), "solve_ms"),
            Column(("status",), "status", text=True),
            Column(DISTURBANCE_NAMES, "environment"),
            Column(("clearance_m",), "clearance_m", empty_is_inf=True),
            Column(ESTIMATE_NAMES, "disturbance_estimate", optional=True),
            Column(BACKOFF_NAMES, "backoff", optional=True),
        )

    def columns(self) -> list[str]:
        return [name for column in self.csv_columns() for name in column.names]

    def to_csv_text(self) -> str:
        blocks = self.csv_columns()
        return _csv_text(self.columns(), (self.row(blocks, k) for k in range(self.steps + 1)))

    def row(self, blocks: tuple[Column, ...], k: int, final: bool = False) -> list[str]:
        """Row k of log.csv by ``blocks`` (:meth:`csv_columns`, made once per log);
        ``final``: the run's last row, which has no command (as every row past the last
        command)."""
        final = final or k >= self.steps
        return [cell for block in blocks for cell in self._cells(block, k, final)]

    def _cells(self, column: Column, k: int, final: bool) -> list[str]:
        """Row k's cells of one block of columns."""
        if column.field is None:
            return [csv_number(0.0)] * len(column.names)
        if final and column.field in self.PER_COMMAND:
            return [""] * len(column.names)
        value = getattr(self, column.field)[k]
        if column.text:
            return [value]
        if np.ndim(value) == 0:
            finite = math.isfinite(value) or not column.empty_is_inf
            return [csv_number(value) if finite else ""]
        part = value if column.part is None else np.asarray(value)[column.part]
        return [csv_number(v) for v in part]

    @classmethod
    def read_csv(
        cls, path: Path, initial_thrust: np.ndarray | None = None, **run_fields: Any
    ) -> SimLog:
        """Load a log written by ``to_csv_text`` (values round-trip exactly); ``run_fields``:
        what the kind's ``allocate`` takes beyond the sizes (a 6-DOF log's ``n_horizontal``)."""
        rows = _csv_rows(path)
        prefix = cls.input_prefix
        inputs = sum(name.startswith(prefix) and name[len(prefix) :].isdigit() for name in rows[0])
        steps = len(rows) - 1
        sample_time = float(rows[1]["t"]) - float(rows[0]["t"]) if steps else 0.0
        log = cls.allocate(steps, inputs, sample_time, **run_fields)
        for column in log.csv_columns():
            if column.field is None or (column.optional and column.names[0] not in rows[0]):
                continue
            values = getattr(log, column.field)
            for k, row in enumerate(rows[:steps] if column.field in cls.PER_COMMAND else rows):
                cells = [row[name] for name in column.names]
                if column.text:
                    values[k] = cells[0]
                elif values.ndim == 1:
                    empty = column.empty_is_inf and not cells[0]
                    values[k] = math.inf if empty else float(cells[0])
                elif column.part is None:
                    values[k] = [float(cell) for cell in cells]
                else:
                    values[k, column.part] = [float(cell) for cell in cells]
        if initial_thrust is not None:
            log.initial_thrust = np.asarray(initial_thrust, dtype=float)
        return log


@dataclass
class DepthLog(SimLog):
    """A depth run's log (``kind: depth``): true ``[z, w]``, the depth setpoint, the vertical
    thrusts, the pressure sensor's reading and the wave force (docs/depth.md). Its log.csv
    columns: ``t, z, w, z_ref, Fz1..Fzn, solve_ms, status, z_measured, wave_force_N``."""

    layout: ClassVar[Layout] = DEPTH
    reference_names: ClassVar[tuple[str, ...]] = ("z_ref", "w_ref")  # log.csv keeps z_ref
    environment_names: ClassVar[tuple[str, ...]] = ("wave_force_N",)
    measured_names: ClassVar[tuple[str, ...]] = ("z",)  # the pressure sensor's depth
    input_prefix: ClassVar[str] = "Fz"  # the vertical thrusters

    def horizontal(self) -> SimLog:
        raise TypeError("a depth run has no horizontal path")

    @property
    def z_ref(self) -> np.ndarray:
        """(N+1,) the depth setpoint (m, up)."""
        return self.reference[:, _DEPTH]

    @property
    def z_measured(self) -> np.ndarray:
        """(N+1,) the depth the controller saw (m, up)."""
        return self.measured[:, 0]

    @property
    def wave_force(self) -> np.ndarray:
        """(N+1,) the waves' vertical force on the vehicle at t_k (N, up)."""
        return self.environment[:, 0]

    def csv_columns(self) -> tuple[Column, ...]:
        return (
            Column(("t",), "t"),
            Column(self.layout.names, "state"),
            Column(("z_ref",), "reference", part=[_DEPTH]),
            Column(self.input_names, "thrust"),
            Column(("solve_ms",), "solve_ms"),
            Column(("status",), "status", text=True),
            Column(("z_measured",), "measured"),
            Column(self.environment_names, "environment"),
        )


@dataclass
class SixDofLog(SimLog):
    """A 6-DOF run's log (``kind: six-dof``): the true 12-state, the horizontal reference with
    the depth's, the water current at the vehicle, and both control channels' timing and
    status. ``thrust`` has one column per ``six_dof`` thruster (the horizontal ones first);
    ``solve_ms``, ``status`` and the diagnostics are the horizontal controller's.

    log.csv: a horizontal log's columns (its ``dist_*`` are 0: the 6-DOF plant's environment
    is the current, logged as ``current_*``), then ``z, phi, theta, w, p, q``, ``z_ref,
    z_rate_ref``, ``current_north, current_east, current_down``, ``depth_solve_ms,
    depth_status``.
    """

    layout: ClassVar[Layout] = SIX_DOF
    reference_names: ClassVar[tuple[str, ...]] = (*REFERENCE_NAMES, *DEPTH_REFERENCE_NAMES)
    environment_names: ClassVar[tuple[str, ...]] = CURRENT_NAMES
    measured_names: ClassVar[tuple[str, ...]] = SIX_DOF_MEASUREMENT.names
    PER_COMMAND: ClassVar[tuple[str, ...]] = (
        *SimLog.PER_COMMAND, "depth_solve_ms", "depth_status", "saturated",
    )  # fmt: skip

    n_horizontal: int = 0  # thrust's first columns, the horizontal controller's (allocate's)
    depth_solve_ms: np.ndarray = field(default_factory=lambda: np.zeros(0))  # (N,)
    depth_status: list[str] = field(default_factory=list)  # (N,) the depth controller's
    saturated: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))  # (N,)
    # (N,): how many thrusters' demand the mapping had to change (rate or force limit)

    @classmethod
    def allocate(
        cls, steps: int, n_thrusters: int, sample_time: float, *, n_horizontal: int
    ) -> SixDofLog:
        log = super().allocate(steps, n_thrusters, sample_time)
        log.n_horizontal = n_horizontal
        log.depth_solve_ms = np.zeros(steps)
        log.depth_status = [""] * steps
        log.saturated = np.zeros(steps, dtype=int)
        return log

    @property
    def depth(self) -> np.ndarray:
        """(N+1,) the true depth z (m, down)."""
        return self.state[:, SIX_DOF.index("z")]

    @property
    def depth_reference(self) -> np.ndarray:
        """(N+1, 2) [z_ref, z_ref'] (NED: m, m/s)."""
        return self.reference[:, _DEPTH_REFERENCE]

    @property
    def current_world(self) -> np.ndarray:
        """(N+1, 3) the water velocity at the vehicle over [t_k, t_k+1) (world NED, m/s)."""
        return self.environment

    def record_command(
        self, k: int, result: ControlResult, thrust: np.ndarray, solve_ms: float
    ) -> None:
        # The channels' own results (controllers/channels.py): each one's time, not the
        # whole call's (which adds the mapping's).
        super().record_command(k, result, thrust, result.horizontal_solve_ms)
        self.depth_solve_ms[k] = result.depth_solve_ms
        self.depth_status[k] = str(result.depth_status)
        self.saturated[k] = result.saturated

    def horizontal(self) -> SimLog:
        """The horizontal view: ``[x, y, psi, u, v, r]``, their reference and the horizontal
        thrusters (what the 3-DOF metrics and figures read, checked against the horizontal
        controller's limits)."""
        n = self.n_horizontal
        return SimLog(
            t=self.t,
            state=self.state[:, HORIZONTAL_INDEX],
            reference=self.reference[:, _HORIZONTAL_REFERENCE],
            thrust=self.thrust[:, :n],
            solve_ms=self.solve_ms,
            disturbance_estimate=self.disturbance_estimate,
            status=self.status,
            environment=np.zeros((len(self.t), len(DISTURBANCE_NAMES))),
            clearance_m=self.clearance_m,
            sample_time=self.sample_time,
            initial_thrust=self.initial_thrust[:n],
            measured=self.measured[:, SIX_DOF_MEASUREMENT.span("x", "r")],
            backoff=self.backoff,
        )

    def csv_columns(self) -> tuple[Column, ...]:
        # A horizontal log's columns (every thruster), then the 6-DOF rest.
        horizontal_part = {
            "state": Column(STATE_NAMES, "state", part=HORIZONTAL_INDEX),
            "reference": Column(REFERENCE_NAMES, "reference", part=_HORIZONTAL_REFERENCE),
            "environment": Column(DISTURBANCE_NAMES, None),  # no force: the current
        }
        return (
            *(horizontal_part.get(column.field, column) for column in super().csv_columns()),
            Column(_SIX_DOF_EXTRA, "state", part=_SIX_DOF_EXTRA_INDEX),
            Column(DEPTH_REFERENCE_NAMES, "reference", part=_DEPTH_REFERENCE),
            Column(CURRENT_NAMES, "environment"),
            Column(("depth_solve_ms",), "depth_solve_ms"),
            Column(("depth_status",), "depth_status", text=True),
        )


# The 6-DOF state's columns beyond the horizontal ones, in log.csv's order.
_SIX_DOF_EXTRA = ("z", "phi", "theta", "w", "p", "q")
_SIX_DOF_EXTRA_INDEX = np.array([SIX_DOF.index(name) for name in _SIX_DOF_EXTRA])
# Where the horizontal reference and the depth's sit in a 6-DOF log's reference.
_HORIZONTAL_REFERENCE = slice(0, len(REFERENCE_NAMES))
_DEPTH_REFERENCE = slice(len(REFERENCE_NAMES), len(REFERENCE_NAMES) + len(DEPTH_REFERENCE_NAMES))
_DEPTH = DEPTH.index("z")


class LiveLog:
    """log.csv written as a run goes: the header, then each row as soon as it is complete,
    flushed, so that a run that dies (a crash, a live vehicle's computer switched off) keeps
    every sample stepped. It is the record, not the result: the run folder (``close``) is.
    Opened exclusively: an existing file is never replaced."""

    def __init__(self, path: str | Path, log: SimLog) -> None:
        from auvmpc.errors import ConfigError

        try:
            self._file = open(path, "x", newline="")  # open until close()
        except FileExistsError:
            raise ConfigError(
                "live_log", str(path), "exists already; a live log never replaces a file"
            ) from None
        except OSError as error:
            raise ConfigError(
                "live_log", str(path), f"cannot be created: {error.strerror}"
            ) from None
        self.path, self._log, self._blocks = Path(path), log, log.csv_columns()
        self._writer = csv.writer(self._file, lineterminator="\n")
        self._writer.writerow(log.columns())
        self._file.flush()

    def append(self, k: int, final: bool = False) -> None:
        """Row k of the log, now complete (``final``: the state after the last command)."""
        self._writer.writerow(self._log.row(self._blocks, k, final))
        self._file.flush()

    def close(self) -> None:
        self._file.close()


def _csv_text(columns: Sequence[str], rows: Iterable[Sequence[str]]) -> str:
    """log.csv's text: the header, then the rows (the one writer of every kind of log)."""
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(columns)
    writer.writerows(rows)
    return buffer.getvalue()


def csv_number(value: float) -> str:
    """Shortest text that reads back to the same float."""
    return repr(float(value))


def _csv_rows(path: Path) -> list[dict[str, str]]:
    """The rows of a log.csv by column name; an empty log is an error naming the file."""
    with open(path, newline="") as handle:
        rows = list(csv.DictReader(handle))
    if not rows:
        raise ValueError(f"{path}: empty log")
    return rows
