"""SimLog: what a closed-loop run did, sample by sample, and its CSV form.

Row k holds the TRUE plant state at t_k and the reference at t_k; the thrust on
row k is what was applied over [t_k, t_k+1), so the last row has none
(``shared/spec/interfaces.md``). Arrays are preallocated and time-major. The state columns
are named by the log's state layout: :class:`SimLog` is a horizontal run's
(``x, y, psi, u, v, r``), :class:`DepthLog` a depth run's (``z, w``), same loop, same rows.
"""

from __future__ import annotations

import csv
import io
import math
from dataclasses import dataclass, replace
from pathlib import Path
from typing import ClassVar

import numpy as np

from auvmpc.models.layout import DEPTH, HORIZONTAL, StateLayout

__all__ = ["BACKOFF_NAMES", "DepthLog", "ESTIMATE_NAMES", "REFERENCE_NAMES", "SimLog"]

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


@dataclass
class SimLog:
    """Time-major record of one run (N samples, n thrusters, nx states of ``layout``)."""

    #: The plant state's names: the columns of ``state`` and ``reference``.
    layout: ClassVar[StateLayout] = HORIZONTAL
    #: The external force logged at each row (``disturbance_world``'s columns).
    disturbance_names: ClassVar[tuple[str, ...]] = DISTURBANCE_NAMES
    #: Entries of what the controller's sensor measures (``measured``'s columns).
    measured_size: ClassVar[int] = HORIZONTAL.size

    t: np.ndarray  # (N+1,) s
    state: np.ndarray  # (N+1, nx) true plant state
    reference: np.ndarray  # (N+1, nx)
    thrust: np.ndarray  # (N, n) applied over [t_k, t_k+1)
    solve_ms: np.ndarray  # (N,) wall time of the controller call
    disturbance_estimate: np.ndarray  # (N, 3) what the controller assumed over [t_k, t_k+1)
    status: list[str]  # (N,) ControlStatus values
    disturbance_world: np.ndarray  # (N+1, nd) external force at t_k (horizontal: world X, Y, N)
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
            reference=np.zeros((steps + 1, nx)),
            thrust=np.zeros((steps, n_thrusters)),
            solve_ms=np.zeros(steps),
            disturbance_estimate=np.zeros((steps, len(ESTIMATE_NAMES))),
            status=[""] * steps,
            disturbance_world=np.zeros((steps + 1, len(cls.disturbance_names))),
            clearance_m=np.full(steps + 1, math.inf),
            sample_time=sample_time,
            initial_thrust=np.zeros(n_thrusters),
            measured=np.zeros((steps + 1, cls.measured_size)),
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

    def to_csv_text(self) -> str:
        buffer = io.StringIO()
        writer = csv.writer(buffer, lineterminator="\n")
        writer.writerow(self.columns())
        for k in range(self.steps + 1):
            applied = k < self.steps
            thrust = [csv_number(f) for f in self.thrust[k]] if applied else [""] * self.n_thrusters
            writer.writerow(
                [
                    csv_number(self.t[k]),
                    *(csv_number(v) for v in self.state[k]),
                    *(csv_number(v) for v in self.reference[k]),
                    *thrust,
                    csv_number(self.solve_ms[k]) if applied else "",
                    self.status[k] if applied else "",
                    *(csv_number(v) for v in self.disturbance_world[k]),
                    csv_number(self.clearance_m[k]) if math.isfinite(self.clearance_m[k]) else "",
                    *(
                        (csv_number(v) for v in self.disturbance_estimate[k])
                        if applied
                        else [""] * len(ESTIMATE_NAMES)
                    ),
                    *(
                        (csv_number(v) for v in self.backoff[k])
                        if applied
                        else [""] * len(BACKOFF_NAMES)
                    ),
                ]
            )
        return buffer.getvalue()

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
    disturbance_names: ClassVar[tuple[str, ...]] = ("wave_force_N",)
    measured_size: ClassVar[int] = 1  # the pressure sensor's depth

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

    def to_csv_text(self) -> str:
        buffer = io.StringIO()
        writer = csv.writer(buffer, lineterminator="\n")
        writer.writerow(self.columns())
        nv = self.n_thrusters
        for k in range(self.steps + 1):
            applied = k < self.steps
            writer.writerow(
                [
                    csv_number(self.t[k]), *(csv_number(v) for v in self.state[k]),
                    csv_number(self.z_ref[k]),
                    *([csv_number(f) for f in self.thrust[k]] if applied else [""] * nv),
                    csv_number(self.solve_ms[k]) if applied else "",
                    self.status[k] if applied else "",
                    csv_number(self.z_measured[k]), csv_number(self.wave_force[k]),
                ]
            )  # fmt: skip
        return buffer.getvalue()

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


_DEPTH = DEPTH.index("z")


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
