"""What a closed-loop run did, sample by sample, and its CSV form (log.csv).

Row k holds the TRUE plant state at t_k and the reference at t_k; the command on row k is
what was applied over [t_k, t_k+1), so the last row has none (``shared/spec/interfaces.md``).
Arrays are preallocated and time-major.

One log for every kind of run: a :class:`LogFormat` is what a kind logs, as data: the names
of its state (a layout), reference, environment and measurement, its inputs' prefix, the
diagnostics it keeps of each controller result, log.csv's columns and the fields they hold,
and where its horizontal part sits. :data:`HORIZONTAL_LOG` (``x, y, psi, u, v, r``),
:data:`DEPTH_LOG` (``z, w``) and :data:`SIX_DOF_LOG` (the 12 states, the horizontal part
first in log.csv) are the three; one writer and one reader serve them all.
"""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd

from auvmpc.controllers.shell import BACKOFF_KEYS, ESTIMATE_KEYS, LOGGED_INFO
from auvmpc.errors import ConfigError
from auvmpc.models.layout import DEPTH, HORIZONTAL, HORIZONTAL_COMPONENTS, Layout
from auvmpc.models.six_dof import HORIZONTAL_INDEX, SIX_DOF, SIX_DOF_MEASUREMENT

if TYPE_CHECKING:
    from auvmpc.controllers.base import ControlResult

__all__ = [
    "BACKOFF_NAMES",
    "CURRENT_NAMES",
    "DEPTH_LOG",
    "ESTIMATE_NAMES",
    "FINITE_FIELDS",
    "HORIZONTAL_LOG",
    "MAX_LOG_BYTES",
    "REFERENCE_NAMES",
    "SIX_DOF_LOG",
    "LiveLog",
    "LogFormat",
    "LogTable",
    "SimLog",
    "read_log_table",
]

STATE_NAMES = HORIZONTAL.names
REFERENCE_NAMES = tuple(f"{name}_ref" for name in STATE_NAMES)
DISTURBANCE_NAMES = ("dist_X", "dist_Y", "dist_N")
# What the controller's prediction assumed at sample k and what the robust tightening took:
# the shell's ``info`` keys (controllers/shell.py), logged under these names.
ESTIMATE_NAMES, BACKOFF_NAMES = ESTIMATE_KEYS, BACKOFF_KEYS
# The water velocity at the vehicle (world NED, m/s): a 6-DOF run's three components, a
# horizontal run's first two (world x north, y east); and a 6-DOF run's depth reference
# (NED, m and m/s).
CURRENT_NAMES = ("current_north", "current_east", "current_down")
HORIZONTAL_CURRENT_NAMES = CURRENT_NAMES[HORIZONTAL_COMPONENTS]
DEPTH_REFERENCE_NAMES = ("z_ref", "z_rate_ref")
# Stands for the log's input names in a format's columns (they depend on the vehicle).
INPUTS = ("<inputs>",)


@dataclass(frozen=True)
class Column:
    """A block of log.csv's columns (``names``) and the log field or diagnostic it holds; a
    per-command field has no value on the final row (empty cells there)."""

    names: tuple[str, ...]
    field: str | None  # None: written as 0 and not read (a column kept for the file's shape)
    part: slice | np.ndarray | list[int] | None = None  # the field's columns (None: all)
    text: bool = False  # strings (a status), as they are
    empty_is_inf: bool = False  # an empty cell is inf (no obstacle, no gap)
    optional: bool = False  # logs written before these columns have none (read as 0)


@dataclass(frozen=True)
class Diagnostic:
    """A value the log keeps of each controller result, per command: the result's ``info``
    entries ``names`` (0 where absent), or its attribute ``attribute``."""

    field: str
    names: tuple[str, ...]
    attribute: str | None = None
    text: bool = False  # a status, kept as a string
    dtype: type = float

    def allocate(self, steps: int) -> np.ndarray | list[str]:
        if self.text:
            return [""] * steps
        shape = (steps,) if self.attribute is not None else (steps, len(self.names))
        return np.zeros(shape, dtype=self.dtype)

    def record(self, values: np.ndarray | list[str], k: int, result: ControlResult) -> None:
        if self.attribute is None:
            values[k] = [result.info.get(name, 0.0) for name in self.names]
        else:
            value = getattr(result, self.attribute)
            values[k] = str(value) if self.text else value


@dataclass(frozen=True)
class HorizontalPart:
    """Where a log's horizontal run sits: state columns, reference and measurement columns,
    and the first ``horizontal_inputs`` inputs (the log's own)."""

    state: np.ndarray
    reference: slice
    measured: slice


@dataclass(frozen=True, eq=False)
class LogFormat:
    """What a kind of run logs (module docstring)."""

    name: str
    layout: Layout  # the plant state's names: the columns of ``state``
    reference_names: tuple[str, ...]  # what the controller is asked to follow, per row
    #: What the environment does at each row: a horizontal run's external force, a depth
    #: run's wave force, a 6-DOF run's water current.
    environment_names: tuple[str, ...]
    #: What the controller's sensors measure (the session's measurement, in this order).
    measured_names: tuple[str, ...]
    #: What a log read without its inputs' names calls them: this prefix and the input's
    #: number from 1 (the thrusters' names: models/actuators).
    input_prefix: str
    diagnostics: tuple[Diagnostic, ...]
    columns: tuple[Column, ...]  # log.csv's, in order; INPUTS stands for the input names
    #: Where the horizontal run sits; None: it has none (a depth run). A horizontal log is
    #: its own (``horizontal_part`` with every column in place).
    horizontal_part: HorizontalPart | None
    #: The result's attribute whose wall time the log keeps as ``solve_ms`` (a 6-DOF run's
    #: horizontal channel's); None: the whole controller call's.
    solve_ms_attribute: str | None = None

    def csv_columns(self, input_names: tuple[str, ...]) -> tuple[Column, ...]:
        return tuple(
            replace(column, names=input_names) if column.names == INPUTS else column
            for column in self.columns
        )


# The fields with a row per sample (N + 1) and those with a row per command (N); a
# diagnostic is per command. :meth:`SimLog.first` cuts by these lists, so a new field goes in
# one of them (tests/test_session.py checks that every one is).
PER_SAMPLE = ("t", "state", "reference", "environment", "clearance_m", "measured")
PER_COMMAND = ("thrust", "solve_ms", "status")


@dataclass
class SimLog:
    """Time-major record of one run (N samples, n inputs, the state of ``format.layout``)."""

    format: LogFormat
    t: np.ndarray  # (N+1,) s
    state: np.ndarray  # (N+1, nx) true plant state
    reference: np.ndarray  # (N+1, nr) reference_names
    thrust: np.ndarray  # (N, n) applied over [t_k, t_k+1)
    solve_ms: np.ndarray  # (N,) wall time of the controller call
    status: list[str]  # (N,) ControlStatus values
    environment: np.ndarray  # (N+1, nd) environment_names at t_k
    clearance_m: np.ndarray  # (N+1,) vehicle-to-obstacle gap, inf without obstacles
    sample_time: float
    initial_thrust: np.ndarray  # (n,) F(-1), what the first rate limit is measured from
    # (N+1, m) what the sensors gave at t_k (the controller's input on rows 0..N-1); in
    # memory only for horizontal and 6-DOF runs, whose log.csv keeps the truth.
    measured: np.ndarray
    # The format's diagnostics by field, (N, ...) each: e.g. ``disturbance_estimate`` (what
    # the controller assumed over [t_k, t_k+1)), ``backoff``, a 6-DOF run's depth channel.
    diagnostics: dict[str, Any] = field(default_factory=dict)
    horizontal_inputs: int = 0  # how many of the inputs, from the first, are horizontal
    input_names: tuple[str, ...] = ()  # the commands' names: the thrust columns of log.csv

    @classmethod
    def allocate(
        cls,
        steps: int,
        inputs: int | Sequence[str],
        sample_time: float,
        format: LogFormat | None = None,
        horizontal_inputs: int | None = None,
    ) -> SimLog:
        """A log for ``steps`` commands of the ``inputs`` (their names, in order: an
        ActuatorSet's; or their number, named by the format's prefix), a horizontal run's
        unless ``format`` says otherwise; ``horizontal_inputs``: all of them unless given."""
        format = HORIZONTAL_LOG if format is None else format
        if isinstance(inputs, int):
            inputs = [f"{format.input_prefix}{i + 1}" for i in range(inputs)]
        names = tuple(inputs)
        n_inputs = len(names)
        return cls(
            format=format,
            t=sample_time * np.arange(steps + 1, dtype=float),
            state=np.zeros((steps + 1, format.layout.size)),
            reference=np.zeros((steps + 1, len(format.reference_names))),
            thrust=np.zeros((steps, n_inputs)),
            solve_ms=np.zeros(steps),
            status=[""] * steps,
            environment=np.zeros((steps + 1, len(format.environment_names))),
            clearance_m=np.full(steps + 1, math.inf),
            sample_time=sample_time,
            initial_thrust=np.zeros(n_inputs),
            measured=np.zeros((steps + 1, len(format.measured_names))),
            diagnostics={d.field: d.allocate(steps) for d in format.diagnostics},
            horizontal_inputs=n_inputs if horizontal_inputs is None else horizontal_inputs,
            input_names=names,
        )

    @property
    def layout(self) -> Layout:
        return self.format.layout

    @property
    def steps(self) -> int:
        return len(self.thrust)

    def first(self, rows: int) -> SimLog:
        """A copy of the log's first ``rows`` samples (and so ``rows - 1`` commands)."""
        cut: dict[str, Any] = {name: getattr(self, name)[:rows].copy() for name in PER_SAMPLE}
        cut.update({name: getattr(self, name)[: rows - 1].copy() for name in PER_COMMAND})
        cut["diagnostics"] = {
            name: values[: rows - 1].copy() for name, values in self.diagnostics.items()
        }
        return replace(self, **cut)

    @property
    def n_thrusters(self) -> int:
        return self.thrust.shape[1]

    def horizontal(self) -> SimLog:
        """The horizontal view: ``[x, y, psi, u, v, r]``, their reference and the horizontal
        inputs (what 3-DOF metrics and figures read); a horizontal log is its own."""
        if self.format is HORIZONTAL_LOG:
            return self
        part = self.format.horizontal_part
        if part is None:
            raise TypeError(f"a {self.format.name} run has no horizontal path")
        n = self.horizontal_inputs
        return SimLog(
            format=HORIZONTAL_LOG,
            t=self.t,
            state=self.state[:, part.state],
            reference=self.reference[:, part.reference],
            thrust=self.thrust[:, :n],
            solve_ms=self.solve_ms,
            status=self.status,
            environment=self._horizontal_environment(),
            clearance_m=self.clearance_m,
            sample_time=self.sample_time,
            initial_thrust=self.initial_thrust[:n],
            measured=self.measured[:, part.measured],
            diagnostics={d.field: self.diagnostics[d.field] for d in HORIZONTAL_LOG.diagnostics},
            horizontal_inputs=n,
            input_names=self.input_names[:n],
        )

    def _horizontal_environment(self) -> np.ndarray:
        """The horizontal view's environment: no force, the water velocity's north and east
        components where this log has them (a 6-DOF run's current)."""
        environment = np.zeros((len(self.t), len(HORIZONTAL_LOG.environment_names)))
        names = self.format.environment_names
        if all(name in names for name in HORIZONTAL_CURRENT_NAMES):
            columns = [names.index(name) for name in HORIZONTAL_CURRENT_NAMES]
            environment[:, _WATER] = self.environment[:, columns]
        return environment

    def record_command(
        self, k: int, result: ControlResult, thrust: np.ndarray, solve_ms: float
    ) -> None:
        """Row k's command: the (checked) thrust, how it came, the controller call's wall
        time (or the format's channel's) and the diagnostics the format keeps."""
        self.thrust[k] = thrust
        attribute = self.format.solve_ms_attribute
        self.solve_ms[k] = solve_ms if attribute is None else getattr(result, attribute)
        self.status[k] = str(result.status)
        for diagnostic in self.format.diagnostics:
            diagnostic.record(self.diagnostics[diagnostic.field], k, result)

    def column(self, name: str) -> np.ndarray | list[str]:
        """log.csv's column ``name`` (all rows; a per-command one has N), e.g. a depth run's
        ``z_ref``; a KeyError naming the columns if there is none."""
        for block in self.csv_columns():
            if name in block.names and block.field is not None:
                values = self._values(block.field)
                if block.text:
                    return values
                if np.ndim(values) == 1:
                    return values
                held = np.arange(values.shape[1])  # the field's columns this block holds
                held = held if block.part is None else held[block.part]
                return values[:, held[block.names.index(name)]]
        raise KeyError(f"no column {name!r} in this log ({', '.join(self.columns())})")

    def _values(self, name: str) -> Any:
        return self.diagnostics[name] if name in self.diagnostics else getattr(self, name)

    def _per_command(self, name: str) -> bool:
        return name in PER_COMMAND or name in self.diagnostics

    def csv_columns(self) -> tuple[Column, ...]:
        """log.csv's columns, in order, and the fields they hold."""
        return self.format.csv_columns(self.input_names)

    def columns(self) -> list[str]:
        return [name for column in self.csv_columns() for name in column.names]

    def to_csv_text(self) -> str:
        return _csv_text(self.columns(), self._rows())

    def _rows(self) -> Iterator[list[str]]:
        """log.csv's rows as text, in order."""
        blocks = self.csv_columns()
        return (self.row(blocks, k) for k in range(self.steps + 1))

    def dataframe(self) -> pd.DataFrame:
        """The log as a DataFrame with log.csv's columns (:meth:`LogTable.frame` of its
        rows: a per-command column is NaN on the final row)."""
        return LogTable(Path("log.csv"), "log", self.columns(), list(self._rows())).frame()

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
        if final and self._per_command(column.field):
            return [""] * len(column.names)
        value = self._values(column.field)[k]
        if column.text:
            return [value]
        if np.ndim(value) == 0:
            finite = math.isfinite(value) or not column.empty_is_inf
            return [csv_number(value) if finite else ""]
        part = value if column.part is None else np.asarray(value)[column.part]
        return [csv_number(v) for v in part]

    @classmethod
    def read_csv(cls, path: Path, *options: Any, field: str = "log", **named: Any) -> SimLog:
        """Load a log written by ``to_csv_text`` (values round-trip exactly): the log of
        :func:`read_log_table` ``(path, field)`` with :meth:`from_table`'s options. What the
        writer cannot have written is one line naming ``field`` and the file."""
        return cls.from_table(read_log_table(path, field), *options, **named)

    @classmethod
    def from_table(
        cls,
        table: LogTable,
        initial_thrust: np.ndarray | None = None,
        format: LogFormat | None = None,
        horizontal_inputs: int | None = None,
        input_names: Sequence[str] | None = None,
    ) -> SimLog:
        """The log of a log.csv's ``table`` (:func:`read_log_table`), of a horizontal run
        unless ``format`` says otherwise; its inputs are ``input_names`` or, without them, the
        columns named by the format's prefix and a number.

        What the writer cannot have written is a one-line :class:`~auvmpc.errors.ConfigError`
        naming the file and the first damage: a column of the format missing, a cell that is
        not a number, a non-finite value where the log never holds one
        (:data:`FINITE_FIELDS`), t not increasing, an empty command before the final row,
        and a final row with a command (a log cut at a row boundary)."""
        format = HORIZONTAL_LOG if format is None else format
        if len(table.rows) < 2:
            raise table.damaged(
                f"has {len(table.rows)} rows after its header; a run logs at least two samples"
            )
        prefix = format.input_prefix
        inputs = input_names or [
            name
            for name in table.header
            if name.startswith(prefix) and name[len(prefix) :].isdigit()
        ]
        steps = len(table.rows) - 1
        log = cls.allocate(steps, inputs, 0.0, format, horizontal_inputs)
        blocks = [
            column
            for column in log.csv_columns()
            if column.field is not None
            and not (column.optional and column.names[0] not in table.header)
        ]
        table.require([name for column in blocks for name in column.names], format.name)
        for column in blocks:
            values = log._values(column.field)
            per_command = log._per_command(column.field)
            if column.field in PER_COMMAND:  # the command itself (a diagnostic's is not read)
                table.final_row_empty(column.names)
            rows = slice(0, steps) if per_command else slice(None)
            if column.text:
                values[:] = table.texts(column.names[0], rows)
                continue
            finite = column.field in FINITE_FIELDS
            read = np.column_stack(
                [table.numbers(name, rows, finite, column.empty_is_inf) for name in column.names]
            )
            if values.ndim == 1:
                values[:] = read[:, 0]
            elif column.part is None:
                values[:] = read
            else:
                values[:, column.part] = read
        table.increasing("t", log.t)
        log.sample_time = float(log.t[1] - log.t[0])
        if initial_thrust is not None:
            log.initial_thrust = np.asarray(initial_thrust, dtype=float)
        return log


# What the shell declares a log keeps of every result (controllers/shell.py, LOGGED_INFO).
_SHELL_DIAGNOSTICS = tuple(Diagnostic(field, keys) for field, keys in LOGGED_INFO.items())

# A horizontal run's environment: the world force and moment, then the water velocity.
_FORCE = slice(0, len(DISTURBANCE_NAMES))
_WATER = slice(len(DISTURBANCE_NAMES), len(DISTURBANCE_NAMES) + len(HORIZONTAL_CURRENT_NAMES))

HORIZONTAL_LOG = LogFormat(
    name="horizontal",
    layout=HORIZONTAL,
    reference_names=REFERENCE_NAMES,
    environment_names=(*DISTURBANCE_NAMES, *HORIZONTAL_CURRENT_NAMES),
    measured_names=HORIZONTAL.names,
    input_prefix="F",
    diagnostics=_SHELL_DIAGNOSTICS,
    columns=(
        Column(("t",), "t"),
        Column(STATE_NAMES, "state"),
        Column(REFERENCE_NAMES, "reference"),
        Column(INPUTS, "thrust"),
        Column(("solve_ms",), "solve_ms"),
        Column(("status",), "status", text=True),
        Column(DISTURBANCE_NAMES, "environment", part=_FORCE),
        Column(("clearance_m",), "clearance_m", empty_is_inf=True),
        Column(ESTIMATE_NAMES, "disturbance_estimate", optional=True),
        Column(BACKOFF_NAMES, "backoff", optional=True),
        Column(HORIZONTAL_CURRENT_NAMES, "environment", part=_WATER, optional=True),
    ),
    horizontal_part=HorizontalPart(
        np.arange(HORIZONTAL.size), slice(0, len(REFERENCE_NAMES)), slice(0, HORIZONTAL.size)
    ),
)

_DEPTH = DEPTH.index("z")

# A depth run (``kind: depth``, docs/depth.md): true ``[z, w]``, the depth setpoint, the
# vertical thrusts, the pressure sensor's reading and the wave force.
DEPTH_LOG = LogFormat(
    name="depth",
    layout=DEPTH,
    reference_names=("z_ref", "w_ref"),  # log.csv keeps z_ref
    environment_names=("wave_force_N",),
    measured_names=("z",),  # the pressure sensor's depth
    input_prefix="Fz",  # the vertical thrusters
    diagnostics=(),
    columns=(
        Column(("t",), "t"),
        Column(DEPTH.names, "state"),
        Column(("z_ref",), "reference", part=[_DEPTH]),
        Column(INPUTS, "thrust"),
        Column(("solve_ms",), "solve_ms"),
        Column(("status",), "status", text=True),
        Column(("z_measured",), "measured"),
        Column(("wave_force_N",), "environment"),
    ),
    horizontal_part=None,
)

# The 6-DOF state's columns beyond the horizontal ones, in log.csv's order.
_SIX_DOF_EXTRA = ("z", "phi", "theta", "w", "p", "q")
_SIX_DOF_EXTRA_INDEX = np.array([SIX_DOF.index(name) for name in _SIX_DOF_EXTRA])
# Where the horizontal reference and the depth's sit in a 6-DOF log's reference.
_HORIZONTAL_REFERENCE = slice(0, len(REFERENCE_NAMES))
_DEPTH_REFERENCE = slice(len(REFERENCE_NAMES), len(REFERENCE_NAMES) + len(DEPTH_REFERENCE_NAMES))

# A 6-DOF run (``kind: six-dof``): the true 12-state, the horizontal reference with the
# depth's, the water current at the vehicle, and both control channels' timing and status
# (controllers/channels.py, ChannelResult). Its inputs are every ``six_dof`` thruster, the
# horizontal ones first; ``solve_ms``, ``status`` and the shell's diagnostics are the
# horizontal controller's. log.csv: a horizontal log's columns (its ``dist_*`` are 0: the
# 6-DOF plant's environment is the current, logged as ``current_*``), then ``z, phi, theta,
# w, p, q``, ``z_ref, z_rate_ref``, ``current_north, current_east, current_down``,
# ``depth_solve_ms, depth_status``.
SIX_DOF_LOG = LogFormat(
    name="six-dof",
    layout=SIX_DOF,
    reference_names=(*REFERENCE_NAMES, *DEPTH_REFERENCE_NAMES),
    environment_names=CURRENT_NAMES,
    measured_names=SIX_DOF_MEASUREMENT.names,
    input_prefix="F",
    diagnostics=(
        *_SHELL_DIAGNOSTICS,
        Diagnostic("depth_solve_ms", ("depth_solve_ms",), "depth_solve_ms"),
        Diagnostic("depth_status", ("depth_status",), "depth_status", text=True),
        # how many thrusters' demand the mapping had to change (rate or force limit)
        Diagnostic("saturated", ("saturated",), "saturated", dtype=int),
    ),
    columns=(
        Column(("t",), "t"),
        Column(STATE_NAMES, "state", part=HORIZONTAL_INDEX),
        Column(REFERENCE_NAMES, "reference", part=_HORIZONTAL_REFERENCE),
        *HORIZONTAL_LOG.columns[3:6],  # the inputs, solve_ms, status
        Column(DISTURBANCE_NAMES, None),  # no force: the current, below
        *HORIZONTAL_LOG.columns[7:10],  # clearance, the shell's diagnostics
        Column(_SIX_DOF_EXTRA, "state", part=_SIX_DOF_EXTRA_INDEX),
        Column(DEPTH_REFERENCE_NAMES, "reference", part=_DEPTH_REFERENCE),
        Column(CURRENT_NAMES, "environment"),
        Column(("depth_solve_ms",), "depth_solve_ms"),
        Column(("depth_status",), "depth_status", text=True),
    ),
    horizontal_part=HorizontalPart(
        HORIZONTAL_INDEX, _HORIZONTAL_REFERENCE, SIX_DOF_MEASUREMENT.span("x", "r")
    ),
    solve_ms_attribute="horizontal_solve_ms",  # the channel's own time, not the mapping's
)


class LiveLog:
    """log.csv written as a run goes: the header, then each row as soon as it is complete,
    flushed, so that a run that dies (a crash, a live vehicle's computer switched off) keeps
    every sample stepped. It is the record, not the result: the run folder (``close``) is.
    Opened exclusively: an existing file is never replaced."""

    def __init__(self, path: str | Path, log: SimLog) -> None:
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


# A log.csv read whole: an hour at 0.05 s with 8 thrusters is about 60 MB; four times that
# stays well inside memory (the rows are parsed once).
MAX_LOG_BYTES = 256 * 1024 * 1024

#: The fields a log only ever holds finite numbers of: the session checks every time,
#: measurement and truth it is handed, a run whose plant diverged is not written, and the
#: shell checks every command. A controller's own diagnostics (the estimate, the back-off)
#: are written as they come; ``clearance_m`` is empty without obstacles (``empty_is_inf``).
FINITE_FIELDS = frozenset(
    {"t", "state", "reference", "thrust", "solve_ms", "environment", "measured", "clearance_m"}
)


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
