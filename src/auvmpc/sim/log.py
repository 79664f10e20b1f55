"""What a closed-loop run did, sample by sample, and its CSV form (log.csv).

Row k holds the TRUE plant state at t_k and the reference at t_k; the command on row k is
what was applied over [t_k, t_k+1), so the last row has none (``shared/spec/interfaces.md``).
Arrays are time-major, appended a row at a time as the run goes (sim/log_rows.py: blocks,
so nothing needs the run's length up front); a live log (:class:`LiveLog`) also writes each
row to log.csv as it comes.

One log for every kind of run: a :class:`LogFormat` is what a kind logs, as data: the names
of its state (a layout), reference, environment and measurement, its inputs' prefix, the
diagnostics it keeps of each controller result, log.csv's columns and the fields they hold,
and where its horizontal part sits. :data:`HORIZONTAL_LOG` (``x, y, psi, u, v, r``),
:data:`DEPTH_LOG` (``z, w``) and :data:`SIX_DOF_LOG` (the 12 states, the horizontal part
first in log.csv) are the three; one writer (:func:`csv_row`) and one reader
(:meth:`SimLog.from_table` of sim/log_table.py's table) serve them all.
"""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd

from auvmpc.controllers.shell import BACKOFF_KEYS, ESTIMATE_KEYS, LOGGED_INFO
from auvmpc.errors import ConfigError
from auvmpc.models.layout import DEPTH, HORIZONTAL, HORIZONTAL_COMPONENTS, Layout
from auvmpc.models.six_dof import HORIZONTAL_INDEX, SIX_DOF, SIX_DOF_MEASUREMENT
from auvmpc.sim.log_rows import FieldRows
from auvmpc.sim.log_table import MAX_LOG_BYTES, LogTable, read_log_table

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
    "WHOLE_VEHICLE_LOG",
    "LiveLog",
    "LogFormat",
    "LogTable",
    "Row",
    "SimLog",
    "csv_row",
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

    @property
    def shape(self) -> tuple[int, ...]:
        """One row's shape: a value, or one per name."""
        return () if self.attribute is not None else (len(self.names),)

    def value(self, result: ControlResult) -> Any:
        """What the log keeps of ``result``."""
        if self.attribute is None:
            return [result.info.get(name, 0.0) for name in self.names]
        value = getattr(result, self.attribute)
        return str(value) if self.text else value


@dataclass(frozen=True)
class HorizontalPart:
    """Where a log's horizontal run sits: state columns, reference and measurement columns,
    and the first ``horizontal_inputs`` inputs (the log's own)."""

    state: np.ndarray
    reference: slice
    measured: slice | np.ndarray


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

    @property
    def diagnostic_fields(self) -> frozenset[str]:
        return frozenset(d.field for d in self.diagnostics)

    def command(self, result: ControlResult, thrust: np.ndarray, solve_ms: float) -> Row:
        """A row's command: the (checked) thrust, how it came, the controller call's wall
        time (or the format's channel's: ``solve_ms_attribute``) and the diagnostics the
        format keeps of ``result``."""
        attribute = self.solve_ms_attribute
        return {
            "thrust": thrust,
            "solve_ms": solve_ms if attribute is None else getattr(result, attribute),
            "status": str(result.status),
            **{d.field: d.value(result) for d in self.diagnostics},
        }


# The fields with a row per sample (N + 1) and those with a row per command (N); a
# diagnostic is per command. A row of the log (:meth:`SimLog.append`) holds these fields by
# name, and the final row only the per-sample ones; :meth:`SimLog.first` cuts by these lists,
# so a new field goes in one of them (tests/test_session.py checks that every one is).
PER_SAMPLE = ("t", "state", "reference", "environment", "clearance_m", "measured")
PER_COMMAND = ("thrust", "solve_ms", "status", "effectiveness")

#: One row of a log: its fields by name (``PER_SAMPLE``, then ``PER_COMMAND`` and the
#: format's diagnostics unless it is the final row, which has no command).
Row = dict[str, Any]


# What a whole log's fields hold before they are filled in, where not 0: no obstacle, every
# input healthy.
_ALLOCATED = {"clearance_m": math.inf, "effectiveness": 1.0}


def _rows_field(name: str, doc: str) -> property:
    """A log field as an attribute: its rows so far as one array (sim/log_rows.py)."""

    def read(log: SimLog) -> Any:
        return log._rows[name].values()

    def write(log: SimLog, values: Any) -> None:
        log._rows[name].replace(values)

    return property(read, write, doc=doc)


class SimLog:
    """Time-major record of one run (N commands, n inputs, the state of ``format.layout``),
    appended a row at a time as the run goes (:meth:`append`), so that nothing needs the
    run's length up front.

    Each field is an array of the rows appended so far (kept in blocks, sim/log_rows.py,
    joined when read and kept joined until the next append); writing into it writes the log.
    ``inputs``: the commands' names, in order (an ActuatorSet's), or their number, named by
    the format's prefix; ``format``: a horizontal run's unless given; ``horizontal_inputs``:
    how many of the inputs, from the first, are horizontal (all unless given).
    """

    t = _rows_field("t", "(N+1,) s")
    state = _rows_field("state", "(N+1, nx) true plant state")
    reference = _rows_field("reference", "(N+1, nr) the format's reference_names")
    thrust = _rows_field("thrust", "(N, n) the command applied over [t_k, t_k+1)")
    solve_ms = _rows_field("solve_ms", "(N,) wall time of the controller call")
    status = _rows_field("status", "(N,) ControlStatus values (a list of str)")
    environment = _rows_field("environment", "(N+1, nd) environment_names at t_k")
    clearance_m = _rows_field(
        "clearance_m", "(N+1,) vehicle-to-obstacle gap, inf without obstacles"
    )
    effectiveness = _rows_field(
        "effectiveness",
        "(N, n) each input's effectiveness the controller assumed for the command (1 healthy, "
        "0 dead: what it was told and what the fault detector found); in memory only, a log "
        "read from log.csv has 1",
    )
    measured = _rows_field(
        "measured",
        "(N+1, m) what the sensors gave at t_k (the controller's input on rows 0..N-1); in "
        "log.csv only for depth runs: horizontal and 6-DOF runs' keeps the truth",
    )

    def __init__(
        self,
        inputs: int | Sequence[str],
        sample_time: float,
        format: LogFormat | None = None,
        horizontal_inputs: int | None = None,
    ) -> None:
        self.format = HORIZONTAL_LOG if format is None else format
        if isinstance(inputs, int):
            inputs = [f"{self.format.input_prefix}{i + 1}" for i in range(inputs)]
        self.input_names = tuple(inputs)  # the commands' names: the thrust columns of log.csv
        n_inputs = len(self.input_names)
        self.horizontal_inputs = n_inputs if horizontal_inputs is None else horizontal_inputs
        self.sample_time = sample_time
        self.initial_thrust = np.zeros(n_inputs)  # F(-1): the first rate limit's start
        layout, format = self.format.layout, self.format
        self._rows: dict[str, FieldRows] = {
            "t": FieldRows(),
            "state": FieldRows((layout.size,)),
            "reference": FieldRows((len(format.reference_names),)),
            "environment": FieldRows((len(format.environment_names),)),
            "clearance_m": FieldRows(),
            "measured": FieldRows((len(format.measured_names),)),
            "thrust": FieldRows((n_inputs,)),
            "solve_ms": FieldRows(),
            "status": FieldRows(text=True),
            "effectiveness": FieldRows((n_inputs,)),
            **{d.field: FieldRows(d.shape, d.dtype, d.text) for d in format.diagnostics},
        }

    @classmethod
    def allocate(
        cls,
        steps: int,
        inputs: int | Sequence[str],
        sample_time: float,
        format: LogFormat | None = None,
        horizontal_inputs: int | None = None,
    ) -> SimLog:
        """A whole log of ``steps`` commands, every value 0 (no obstacle: clearance inf) and
        t on the sample grid, to fill in place (a log read from a file, a test's); a run's
        log is appended to instead."""
        log = cls(inputs, sample_time, format, horizontal_inputs)
        for name, rows in log._rows.items():
            count = steps if log._per_command(name) else steps + 1
            if rows.text:
                rows.replace([""] * count)
            else:
                fill = _ALLOCATED.get(name, 0.0)
                rows.replace(np.full((count, *rows.shape), fill, dtype=rows.dtype))
        log.t = sample_time * np.arange(steps + 1, dtype=float)
        return log

    def append(self, row: Row) -> None:
        """The next row: a sample's fields and, unless it is the final row, its command's
        (:meth:`LogFormat.command`); a field missing is a KeyError."""
        final = len(row) == len(PER_SAMPLE)
        for name, rows in self._rows.items():
            if not (final and self._per_command(name)):
                rows.append(row[name])

    @property
    def diagnostics(self) -> dict[str, Any]:
        """The format's diagnostics by field, (N, ...) each: e.g. ``disturbance_estimate``
        (what the controller assumed over [t_k, t_k+1)), ``backoff``, a 6-DOF run's depth
        channel."""
        return {d.field: self._rows[d.field].values() for d in self.format.diagnostics}

    @property
    def layout(self) -> Layout:
        return self.format.layout

    @property
    def steps(self) -> int:
        return len(self._rows["thrust"])

    @property
    def n_thrusters(self) -> int:
        return len(self.input_names)

    def first(self, rows: int) -> SimLog:
        """A copy of the log's first ``rows`` samples (and so ``rows - 1`` commands)."""
        cut = SimLog(self.input_names, self.sample_time, self.format, self.horizontal_inputs)
        cut.initial_thrust = self.initial_thrust
        for name, values in self._rows.items():
            count = rows - 1 if self._per_command(name) else rows
            cut._rows[name].replace(values.values()[:count].copy())
        return cut

    def horizontal(self) -> SimLog:
        """The horizontal view: ``[x, y, psi, u, v, r]``, their reference and the horizontal
        inputs (what 3-DOF metrics and figures read); a horizontal log is its own."""
        if self.format is HORIZONTAL_LOG:
            return self
        part = self.format.horizontal_part
        if part is None:
            raise TypeError(f"a {self.format.name} run has no horizontal path")
        n = self.horizontal_inputs
        view = SimLog(self.input_names[:n], self.sample_time, HORIZONTAL_LOG, n)
        view.initial_thrust = self.initial_thrust[:n]
        fields = {
            "t": self.t,
            "state": self.state[:, part.state],
            "reference": self.reference[:, part.reference],
            "thrust": self.thrust[:, :n],
            "effectiveness": self.effectiveness[:, :n],
            "solve_ms": self.solve_ms,
            "status": self.status,
            "environment": self._horizontal_environment(),
            "clearance_m": self.clearance_m,
            "measured": self.measured[:, part.measured],
        }
        fields |= {d.field: self._values(d.field) for d in HORIZONTAL_LOG.diagnostics}
        for name, values in fields.items():
            view._rows[name].replace(values)
        return view

    def _horizontal_environment(self) -> np.ndarray:
        """The horizontal view's environment: no force, the water velocity's north and east
        components where this log has them (a 6-DOF run's current)."""
        environment = np.zeros((len(self.t), len(HORIZONTAL_LOG.environment_names)))
        names = self.format.environment_names
        if all(name in names for name in HORIZONTAL_CURRENT_NAMES):
            columns = [names.index(name) for name in HORIZONTAL_CURRENT_NAMES]
            environment[:, _WATER] = self.environment[:, columns]
        return environment

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
        return self._rows[name].values()

    def _per_command(self, name: str) -> bool:
        return name in PER_COMMAND or name in self.format.diagnostic_fields

    def csv_columns(self) -> tuple[Column, ...]:
        """log.csv's columns, in order, and the fields they hold."""
        return self.format.csv_columns(self.input_names)

    def columns(self) -> list[str]:
        return [name for column in self.csv_columns() for name in column.names]

    def to_csv_text(self) -> str:
        return _csv_text(self.columns(), self._csv_rows())

    def _csv_rows(self) -> Iterator[list[str]]:
        """log.csv's rows as text, in order."""
        blocks = self.csv_columns()
        values = {name: rows.values() for name, rows in self._rows.items()}
        samples = {name: values[name] for name in PER_SAMPLE}
        steps = self.steps
        for k in range(steps + 1):
            row = {name: field[k] for name, field in (values if k < steps else samples).items()}
            yield csv_row(blocks, row)

    def dataframe(self) -> pd.DataFrame:
        """The log as a DataFrame with log.csv's columns (:meth:`LogTable.frame` of its
        rows: a per-command column is NaN on the final row)."""
        return LogTable(Path("log.csv"), "log", self.columns(), list(self._csv_rows())).frame()

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
        columns named by the format's prefix and a number, or without any, the columns where the
        format has its inputs (named ones: ``propeller_rpm, rudder_deg, ...``).

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
        numbered = [
            name
            for name in table.header
            if name.startswith(prefix) and name[len(prefix) :].isdigit()
        ]
        inputs = input_names or numbered or _named_inputs(table.header, format)
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


def _named_inputs(header: Sequence[str], format: LogFormat) -> list[str]:
    """The inputs of a log.csv whose inputs are named, not numbered (a propeller's and fins':
    ``propeller_rpm, rudder_deg, ...``): the header's columns where ``INPUTS`` stands in the
    format's, between the block before it and the block after (none if either is missing)."""
    slot = [column.names for column in format.columns].index(INPUTS)
    before, after = format.columns[slot - 1].names[-1], format.columns[slot + 1].names[0]
    if before not in header or after not in header:
        return []
    return list(header[header.index(before) + 1 : header.index(after)])


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
        # how far behind the mission's clock the controller flew the reference (s): a
        # vehicle too crippled to keep its pace follows the path later (controllers/schedule.py)
        Diagnostic("schedule_lag_s", ("schedule_lag_s",)),
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
        Column(("schedule_lag_s",), "schedule_lag_s", optional=True),
    ),
    horizontal_part=HorizontalPart(
        HORIZONTAL_INDEX, _HORIZONTAL_REFERENCE, SIX_DOF_MEASUREMENT.span("x", "r")
    ),
    solve_ms_attribute="horizontal_solve_ms",  # the channel's own time, not the mapping's
)
# The same log for a controller of the whole vehicle (Controller.whole_vehicle): it measures
# the whole 6-DOF state, in the state's order; log.csv's columns are the same.
WHOLE_VEHICLE_LOG = replace(
    SIX_DOF_LOG,
    measured_names=SIX_DOF.names,
    horizontal_part=replace(SIX_DOF_LOG.horizontal_part, measured=HORIZONTAL_INDEX),
)


class LiveLog:
    """log.csv written as a run goes: the header, then each row as soon as it is complete,
    flushed, so that a run that dies (a crash, a live vehicle's computer switched off) keeps
    every sample stepped. It is the record, not the result: the run folder (``close``) is.
    Opened exclusively: an existing file is never replaced.

    The session keeps its log in memory as well: the metrics and figures at its close need
    every row, and the log's arrays are smaller than the file read back (docs/session.md)."""

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

    def append(self, row: Row) -> None:
        """A complete row of the log (the final one has no command)."""
        self._writer.writerow(csv_row(self._blocks, row))
        self._file.flush()

    def close(self) -> None:
        self._file.close()


def csv_row(blocks: Sequence[Column], row: Row) -> list[str]:
    """One row of log.csv by ``blocks`` (:meth:`SimLog.csv_columns`, made once per log) from
    the fields of ``row`` (:meth:`SimLog.append`'s): the one writer's row. The final row has
    no command: its per-command cells are empty."""
    return [cell for block in blocks for cell in _cells(block, row)]


def _cells(column: Column, row: Row) -> list[str]:
    """A row's cells of one block of columns."""
    if column.field is None:
        return [csv_number(0.0)] * len(column.names)
    if column.field not in row:  # the final row's command
        return [""] * len(column.names)
    value = row[column.field]
    if column.text:
        return [value]
    if np.ndim(value) == 0:
        finite = math.isfinite(value) or not column.empty_is_inf
        return [csv_number(value) if finite else ""]
    part = value if column.part is None else np.asarray(value)[column.part]
    return [csv_number(v) for v in part]


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


#: The fields a log only ever holds finite numbers of: the session checks every time,
#: measurement and truth it is handed, a run whose plant diverged is not written, and the
#: shell checks every command. A controller's own diagnostics (the estimate, the back-off)
#: are written as they come; ``clearance_m`` is empty without obstacles (``empty_is_inf``).
FINITE_FIELDS = frozenset(
    {"t", "state", "reference", "thrust", "solve_ms", "environment", "measured", "clearance_m"}
)
