"""What a closed-loop run did, sample by sample, and its CSV form (log.csv).

Row k holds the TRUE plant state at t_k and the reference at t_k; the thrust on
row k is what was applied over [t_k, t_k+1), so the last row has none
(``shared/spec/interfaces.md``). Arrays are preallocated and time-major. The state columns
are named by the log's state layout: :class:`SimLog` is a horizontal run's
(``x, y, psi, u, v, r``), :class:`DepthLog` a depth run's (``z, w``), :class:`SixDofLog` a
6-DOF run's (the 12 states, its horizontal part first in log.csv); same loop, same rows, one
CSV writer (each kind says what cells a row has).
"""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, ClassVar

import numpy as np

from auvmpc.models.layout import DEPTH, HORIZONTAL, StateLayout
from auvmpc.models.six_dof import HORIZONTAL_INDEX, SIX_DOF

if TYPE_CHECKING:
    from auvmpc.controllers.base import ControlResult

__all__ = [
    "BACKOFF_NAMES",
    "CURRENT_NAMES",
    "DepthLog",
    "ESTIMATE_NAMES",
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


@dataclass
class SimLog:
    """Time-major record of one run (N samples, n thrusters, nx states of ``layout``)."""

    #: The plant state's names: the columns of ``state``.
    layout: ClassVar[StateLayout] = HORIZONTAL
    #: The reference's columns (what the controller is asked to follow, logged per row).
    reference_names: ClassVar[tuple[str, ...]] = REFERENCE_NAMES
    #: What the environment does at each row (``disturbance_world``'s columns): a horizontal
    #: run's external force, a depth run's wave force, a 6-DOF run's water current.
    disturbance_names: ClassVar[tuple[str, ...]] = DISTURBANCE_NAMES
    #: What the controller's sensors measure (``measured``'s columns, the session's
    #: measurement, in this order).
    measured_names: ClassVar[tuple[str, ...]] = HORIZONTAL.names

    t: np.ndarray  # (N+1,) s
    state: np.ndarray  # (N+1, nx) true plant state
    reference: np.ndarray  # (N+1, nr) reference_names
    thrust: np.ndarray  # (N, n) applied over [t_k, t_k+1)
    solve_ms: np.ndarray  # (N,) wall time of the controller call
    disturbance_estimate: np.ndarray  # (N, 3) what the controller assumed over [t_k, t_k+1)
    status: list[str]  # (N,) ControlStatus values
    disturbance_world: np.ndarray  # (N+1, nd) disturbance_names at t_k
    clearance_m: np.ndarray  # (N+1,) vehicle-to-obstacle gap, inf without obstacles
    sample_time: float
    initial_thrust: np.ndarray  # (n,) F(-1), what the first rate limit is measured from
    # (N+1, m) what the sensor gave at t_k (the controller's input on rows 0..N-1); in memory
    # only for a horizontal run, whose log.csv keeps the truth.
    measured: np.ndarray
    backoff: np.ndarray  # (N, 2) BACKOFF_NAMES over [t_k, t_k+1)

    # The fields with a row per sample (N + 1) and those with a row per command (N); the
    # others (sample_time, initial_thrust) are the run's. :meth:`first` cuts by these lists,
    # so a new field goes in one of them (tests/test_session.py checks that every one is).
    PER_SAMPLE: ClassVar[tuple[str, ...]] = (
        "t", "state", "reference", "disturbance_world", "clearance_m", "measured",
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
            disturbance_world=np.zeros((steps + 1, len(cls.disturbance_names))),
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
        return tuple(f"F{i + 1}" for i in range(self.n_thrusters))

    @property
    def n_thrusters(self) -> int:
        return self.thrust.shape[1]

    def columns(self) -> list[str]:
        return [
            "t", *STATE_NAMES, *REFERENCE_NAMES, *self.input_names, "solve_ms", "status",
            *DISTURBANCE_NAMES, "clearance_m", *ESTIMATE_NAMES, *BACKOFF_NAMES,
        ]  # fmt: skip

    def record_command(self, k: int, result: ControlResult, thrust: np.ndarray) -> None:
        """Row k's command: the (checked) thrust, how it came and the diagnostics the log
        keeps of the controller's ``info``."""
        self.thrust[k] = thrust
        self.status[k] = str(result.status)
        self.disturbance_estimate[k] = [result.info.get(name, 0.0) for name in ESTIMATE_NAMES]
        self.backoff[k] = [result.info.get(name, 0.0) for name in BACKOFF_NAMES]

    def to_csv_text(self) -> str:
        return _csv_text(self.columns(), map(self.row_cells, range(self.steps + 1)))

    def row_cells(self, k: int) -> list[str]:
        """Row k of log.csv, in :meth:`columns` order (a command's cells empty on the last)."""
        applied = k < self.steps
        return [
            csv_number(self.t[k]),
            *(csv_number(v) for v in self.state[k]),
            *(csv_number(v) for v in self.reference[k]),
            *_command_cells(self.thrust, k),
            csv_number(self.solve_ms[k]) if applied else "",
            self.status[k] if applied else "",
            *(csv_number(v) for v in self.disturbance_world[k]),
            csv_number(self.clearance_m[k]) if math.isfinite(self.clearance_m[k]) else "",
            *_command_cells(self.disturbance_estimate, k),
            *_command_cells(self.backoff, k),
        ]

    @classmethod
    def read_csv(cls, path: Path, initial_thrust: np.ndarray | None = None) -> SimLog:
        """Load a log written by ``to_csv_text`` (values round-trip exactly)."""
        rows = _csv_rows(path)
        thrust_names = sorted(
            (name for name in rows[0] if name[0] == "F" and name[1:].isdigit()),
            key=lambda name: int(name[1:]),
        )
        steps = len(rows) - 1
        sample_time = float(rows[1]["t"]) - float(rows[0]["t"]) if steps else 0.0
        log = cls.allocate(steps, len(thrust_names), sample_time)
        for k, row in enumerate(rows):
            log.t[k] = float(row["t"])
            log.state[k] = [float(row[name]) for name in STATE_NAMES]
            log.reference[k] = [float(row[name]) for name in REFERENCE_NAMES]
            log.disturbance_world[k] = [float(row[name]) for name in DISTURBANCE_NAMES]
            log.clearance_m[k] = float(row["clearance_m"]) if row["clearance_m"] else math.inf
            if k < steps:
                log.thrust[k] = [float(row[name]) for name in thrust_names]
                log.solve_ms[k] = float(row["solve_ms"])
                log.status[k] = row["status"]
                if ESTIMATE_NAMES[0] in row:  # logs written before these columns have none
                    log.disturbance_estimate[k] = [float(row[name]) for name in ESTIMATE_NAMES]
                if BACKOFF_NAMES[0] in row:
                    log.backoff[k] = [float(row[name]) for name in BACKOFF_NAMES]
        if initial_thrust is not None:
            log.initial_thrust = np.asarray(initial_thrust, dtype=float)
        return log


@dataclass
class DepthLog(SimLog):
    """A depth run's log (``kind: depth``): true ``[z, w]``, the depth setpoint, the vertical
    thrusts, the pressure sensor's reading and the wave force (docs/depth.md). Its log.csv
    columns: ``t, z, w, z_ref, Fz1..Fzn, solve_ms, status, z_measured, wave_force_N``."""

    layout: ClassVar[StateLayout] = DEPTH
    reference_names: ClassVar[tuple[str, ...]] = ("z_ref", "w_ref")  # log.csv keeps z_ref
    disturbance_names: ClassVar[tuple[str, ...]] = ("wave_force_N",)
    measured_names: ClassVar[tuple[str, ...]] = ("z",)  # the pressure sensor's depth

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
        return self.disturbance_world[:, 0]

    @property
    def input_names(self) -> tuple[str, ...]:
        """The vertical thrusters' names: the thrust columns of log.csv."""
        return tuple(f"Fz{i + 1}" for i in range(self.n_thrusters))

    def columns(self) -> list[str]:
        return [
            "t", *self.layout.names, "z_ref", *self.input_names, "solve_ms", "status",
            "z_measured", *self.disturbance_names,
        ]  # fmt: skip

    def row_cells(self, k: int) -> list[str]:
        applied = k < self.steps
        return [
            csv_number(self.t[k]), *(csv_number(v) for v in self.state[k]),
            csv_number(self.z_ref[k]), *_command_cells(self.thrust, k),
            csv_number(self.solve_ms[k]) if applied else "",
            self.status[k] if applied else "",
            csv_number(self.z_measured[k]), csv_number(self.wave_force[k]),
        ]  # fmt: skip

    @classmethod
    def read_csv(cls, path: Path, initial_thrust: np.ndarray | None = None) -> DepthLog:
        """Load a log written by ``to_csv_text`` (values round-trip exactly)."""
        rows = _csv_rows(path)
        thrusters = sorted((c for c in rows[0] if c.startswith("Fz")), key=lambda c: int(c[2:]))
        steps = len(rows) - 1
        sample_time = float(rows[1]["t"]) - float(rows[0]["t"]) if steps else 0.0
        log = cls.allocate(steps, len(thrusters), sample_time)
        for k, row in enumerate(rows):
            log.t[k] = float(row["t"])
            log.state[k] = [float(row[name]) for name in cls.layout.names]
            log.reference[k, _DEPTH] = float(row["z_ref"])
            log.measured[k] = float(row["z_measured"])
            log.disturbance_world[k] = [float(row[name]) for name in cls.disturbance_names]
            if k < steps:
                log.thrust[k] = [float(row[name]) for name in thrusters]
                log.solve_ms[k] = float(row["solve_ms"])
                log.status[k] = row["status"]
        if initial_thrust is not None:
            log.initial_thrust = np.asarray(initial_thrust, dtype=float)
        return log


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

    layout: ClassVar[StateLayout] = SIX_DOF
    reference_names: ClassVar[tuple[str, ...]] = (*REFERENCE_NAMES, *DEPTH_REFERENCE_NAMES)
    disturbance_names: ClassVar[tuple[str, ...]] = CURRENT_NAMES
    # The navigation sensor's [x, y, psi, u, v, r] and the depth sensor's depth and depth
    # rate (NED, down positive).
    measured_names: ClassVar[tuple[str, ...]] = (*HORIZONTAL.names, "z", "z_rate")
    PER_COMMAND: ClassVar[tuple[str, ...]] = (
        *SimLog.PER_COMMAND, "depth_solve_ms", "depth_status", "saturated",
    )  # fmt: skip

    n_horizontal: int = 0  # thrust's first columns, the horizontal controller's thrusters
    depth_solve_ms: np.ndarray = field(default_factory=lambda: np.zeros(0))  # (N,)
    depth_status: list[str] = field(default_factory=list)  # (N,) the depth controller's
    saturated: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))  # (N,)
    # (N,): how many thrusters' demand the mapping had to change (rate or force limit)

    @classmethod
    def allocate(
        cls, steps: int, n_thrusters: int, sample_time: float, *, n_horizontal: int = 0
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
        return self.reference[:, len(REFERENCE_NAMES) :]

    @property
    def current_world(self) -> np.ndarray:
        """(N+1, 3) the water velocity at the vehicle over [t_k, t_k+1) (world NED, m/s)."""
        return self.disturbance_world

    def record_command(self, k: int, result: ControlResult, thrust: np.ndarray) -> None:
        super().record_command(k, result, thrust)
        # The channels' own results (controllers/channels.py): their time, not the mapping's.
        self.solve_ms[k] = result.horizontal_solve_ms
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
            reference=self.reference[:, : len(REFERENCE_NAMES)],
            thrust=self.thrust[:, :n],
            solve_ms=self.solve_ms,
            disturbance_estimate=self.disturbance_estimate,
            status=self.status,
            disturbance_world=np.zeros((len(self.t), len(DISTURBANCE_NAMES))),
            clearance_m=self.clearance_m,
            sample_time=self.sample_time,
            initial_thrust=self.initial_thrust[:n],
            measured=self.measured[:, : HORIZONTAL.size],
            backoff=self.backoff,
        )

    def columns(self) -> list[str]:
        return [
            *super().columns(), *_SIX_DOF_EXTRA, *DEPTH_REFERENCE_NAMES, *CURRENT_NAMES,
            "depth_solve_ms", "depth_status",
        ]  # fmt: skip

    def to_csv_text(self) -> str:
        # The horizontal view's cells, with every thruster, then the 6-DOF rest.
        planar = replace(self.horizontal(), thrust=self.thrust, initial_thrust=self.initial_thrust)
        rows = (planar.row_cells(k) + self._rest_cells(k) for k in range(self.steps + 1))
        return _csv_text(self.columns(), rows)

    def _rest_cells(self, k: int) -> list[str]:
        applied = k < self.steps
        return [
            *(csv_number(v) for v in self.state[k, _SIX_DOF_EXTRA_INDEX]),
            *(csv_number(v) for v in self.depth_reference[k]),
            *(csv_number(v) for v in self.current_world[k]),
            csv_number(self.depth_solve_ms[k]) if applied else "",
            self.depth_status[k] if applied else "",
        ]

    @classmethod
    def read_csv_six_dof(
        cls, path: Path, n_horizontal: int, initial_thrust: np.ndarray | None = None
    ) -> SixDofLog:
        """Load a log written by ``to_csv_text`` (values round-trip exactly)."""
        planar = SimLog.read_csv(path, initial_thrust)
        rows = _csv_rows(path)
        steps = planar.steps
        log = cls.allocate(steps, planar.n_thrusters, planar.sample_time, n_horizontal=n_horizontal)
        for name in (*SimLog.PER_COMMAND, "t", "initial_thrust", "clearance_m"):
            setattr(log, name, getattr(planar, name))
        log.state[:, HORIZONTAL_INDEX] = planar.state
        log.reference[:, : len(REFERENCE_NAMES)] = planar.reference
        for k, row in enumerate(rows):
            log.state[k, _SIX_DOF_EXTRA_INDEX] = [float(row[name]) for name in _SIX_DOF_EXTRA]
            log.depth_reference[k] = [float(row[name]) for name in DEPTH_REFERENCE_NAMES]
            log.current_world[k] = [float(row[name]) for name in CURRENT_NAMES]
            if k < steps:
                log.depth_solve_ms[k] = float(row["depth_solve_ms"])
                log.depth_status[k] = row["depth_status"]
        return log


# The 6-DOF state's columns beyond the horizontal ones, in log.csv's order.
_SIX_DOF_EXTRA = ("z", "phi", "theta", "w", "p", "q")
_SIX_DOF_EXTRA_INDEX = np.array([SIX_DOF.index(name) for name in _SIX_DOF_EXTRA])
_DEPTH = DEPTH.index("z")


def _csv_text(columns: Sequence[str], rows: Iterable[Sequence[str]]) -> str:
    """log.csv's text: the header, then the rows (the one writer of every kind of log)."""
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(columns)
    writer.writerows(rows)
    return buffer.getvalue()


def _command_cells(values: np.ndarray, k: int) -> list[str]:
    """Row k's cells of a per-command array (N, m): empty on the final row, which has none."""
    if k < len(values):
        return [csv_number(v) for v in values[k]]
    return [""] * values.shape[1]


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
