"""What identification reads from a log: body velocities and the force applied.

A log for identification is :class:`VelocityLog`: the body velocities ``u, v, r`` at
t_k = k Te and, held over [t_k, t_k+1), either each thruster's force or the body force
``[X, Y, N]`` itself (a log that recorded a wrench: no allocation is needed, or assumed).
:func:`read_log` picks the reader from what the path is:

- an auvmpc run folder (``log.csv``): :func:`read_run_folder` here (that file keeps the
  simulated truth, docs/identification.md; a real vehicle's log holds what its sensors
  measured);
- a ROS 2 bag (a rosbag2 folder, or its ``.mcap`` / ``.db3`` file):
  :mod:`~auvmpc.identification.rosbag`;
- an ArduSub DataFlash log (``.bin``, ``.log``): :mod:`~auvmpc.identification.dataflash`.

Real logs are not sampled on one grid: their messages come when they come. The model needs
t_k = k Te with the thrust held over a sample, so :func:`resample` puts them on one, the
same way for every reader (its docstring says how and why). Whatever is missing or too
short is one :class:`~auvmpc.errors.ConfigError` line naming it (exit 2 from the CLI).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import StrEnum
from pathlib import Path

import numpy as np

from auvmpc.errors import ConfigError
from auvmpc.models.layout import HORIZONTAL, HORIZONTAL_VELOCITY
from auvmpc.sim.log import read_log_table

__all__ = [
    "MIN_SAMPLES",
    "LogKind",
    "LogOptions",
    "VelocityLog",
    "log_kind",
    "read_log",
    "read_run_folder",
    "resample",
]

# Fewer samples than this cannot hold a fit, a held-out part and a filter window.
MIN_SAMPLES = 100
# The sample times of a log may wander by this share of a sample (written to 1 us).
_TIME_JITTER = 1e-3
VELOCITY_NAMES = HORIZONTAL_VELOCITY.names
HEADING = HORIZONTAL.names[HORIZONTAL.heading]  # the log's heading column, psi


@dataclass(frozen=True)
class VelocityLog:
    """Body velocities and the applied force of one log, sampled every ``sample_time``.

    Exactly one of ``thrust`` (per thruster, mapped to the body by the vehicle's allocation
    ``tau = T F``) and ``force`` (the body force itself) is given. ``heading``, where the log
    has it, is what a constant current is estimated in (``identify --current``): the
    current rotates in the body as the vehicle turns. A log of the heave model
    (identification/heave.py) holds in ``velocity`` what ``outputs`` names instead: the
    depth z (m, up) and, where logged, the heave rate w (m/s), and the vertical thrusts.
    """

    name: str  # where it came from (a path), for the provenance
    sample_time: float  # s
    velocity: np.ndarray  # (N+1, outputs) u, v (m/s), r (rad/s) at t_k (heave: z, w)
    thrust: np.ndarray | None  # (N, n) N, held over [t_k, t_k+1)
    force: np.ndarray | None = None  # (N, ni) X, Y (N), N (N m), held over [t_k, t_k+1)
    outputs: tuple[str, ...] = VELOCITY_NAMES  # what ``velocity``'s columns are
    heading: np.ndarray | None = None  # (N+1,) psi (rad, unwrapped) at t_k, if logged

    def __post_init__(self) -> None:
        given = [name for name in ("thrust", "force") if getattr(self, name) is not None]
        if len(given) != 1:
            raise ValueError(f"VelocityLog needs exactly one of thrust and force, got {given}")
        held = self.thrust if self.thrust is not None else self.force
        if len(held) != len(self.velocity) - 1:
            raise ValueError(
                f"VelocityLog: {len(self.velocity)} velocities need {len(self.velocity) - 1} "
                f"commands, got {len(held)}"
            )
        if self.heading is not None and len(self.heading) != len(self.velocity):
            raise ValueError(
                f"VelocityLog: {len(self.velocity)} velocities need as many headings, "
                f"got {len(self.heading)}"
            )

    @property
    def steps(self) -> int:
        return len(self.velocity) - 1

    def part(self, start: int, stop: int) -> VelocityLog:
        """Samples start..stop (commands start..stop-1)."""
        return VelocityLog(
            self.name,
            self.sample_time,
            self.velocity[start : stop + 1],
            None if self.thrust is None else self.thrust[start:stop],
            None if self.force is None else self.force[start:stop],
            self.outputs,
            None if self.heading is None else self.heading[start : stop + 1],
        )


@dataclass(frozen=True)
class LogOptions:
    """How to read the logs that are not run folders (``auvmpc identify``'s flags)."""

    sample_time: float | None = None  # s; None: the commands' median interval
    # ROS 2 bags (identification/rosbag.py)
    odometry_topic: str = "/odom"
    thrust_topic: str = "/thrust"
    wrench_topic: str | None = None  # given: the body wrench instead of the thrusts
    body_frame: str = "frd"  # the bag's body axes: frd (as auvmpc export) or flu (REP 103)
    # ArduSub DataFlash logs (identification/dataflash.py)
    thruster_curve: str = "t200-16v"
    channels: tuple[int, ...] = field(default_factory=tuple)  # RCOU channels; () 1..n
    reversed_channels: tuple[int, ...] = field(default_factory=tuple)


class LogKind(StrEnum):
    """What a log path is, and so which reader reads it."""

    RUN_FOLDER = "run folder"
    ROSBAG = "ROS 2 bag"
    DATAFLASH = "DataFlash log"


def log_kind(path: str | Path) -> LogKind:
    """Which reader reads ``path`` (module docstring): a missing file or one of no known
    format is one ConfigError line; a folder that is not a bag is a run folder (its reader
    says what is wrong with it)."""
    where = Path(path)
    suffix = where.suffix.lower()
    if where.is_dir() and not (where / "log.csv").exists() and (where / "metadata.yaml").exists():
        return LogKind.ROSBAG
    if where.is_file() and suffix in (".mcap", ".db3"):
        return LogKind.ROSBAG
    if where.is_file() and suffix in (".bin", ".log"):
        return LogKind.DATAFLASH
    if not where.exists() and suffix in (".mcap", ".db3", ".bin", ".log"):
        raise ConfigError("LOG", str(path), "no such file")
    if where.is_file():
        raise ConfigError(
            "LOG",
            str(path),
            "is not a log identify reads: give an auvmpc run folder, a ROS 2 bag (folder, "
            ".mcap or .db3) or an ArduSub DataFlash log (.bin, .log)",
        )
    return LogKind.RUN_FOLDER


def read_log(path: str | Path, n_thrusters: int, options: LogOptions | None = None) -> VelocityLog:
    """The :class:`VelocityLog` in ``path``, read by the reader for what it is (module
    docstring); ``n_thrusters`` is the start vehicle's."""
    options = options or LogOptions()
    kind = log_kind(path)
    if kind is LogKind.ROSBAG:
        from auvmpc.identification.rosbag import read_rosbag

        return read_rosbag(Path(path), n_thrusters, options)
    if kind is LogKind.DATAFLASH:
        from auvmpc.identification.dataflash import read_dataflash

        return read_dataflash(Path(path), n_thrusters, options)
    return read_run_folder(Path(path), n_thrusters)


# A gap in a measured signal longer than this many samples is refused: interpolating over it
# would invent the motion identification fits.
MAX_GAP_SAMPLES = 10


def resample(
    name: str,
    sample_time: float | None,
    measured_t: np.ndarray,
    velocity: np.ndarray,
    command_t: np.ndarray,
    command: np.ndarray,
    what: tuple[str, str],
    as_force: bool = False,
    heading: np.ndarray | None = None,
    outputs: tuple[str, ...] = VELOCITY_NAMES,
) -> VelocityLog:
    """Measured velocities and commands, each at its own times, on one grid t_k = t0 + k Te.
    ``velocity``'s columns are ``outputs`` (a 6-DOF log's: the whole state, angles unwrapped).

    How, and why:

    - **The grid** starts at the first command that has a velocity measurement at or before
      it and ends at the last velocity measurement; Te is ``sample_time`` or, if None, the
      median interval of the commands (the rate at which the thrust can change; a coarser
      grid would average commands the model holds constant, a finer one only adds samples
      of the same hold).
    - **Commands are held** (zero-order hold): the command over [t_k, t_k+1) is the last one
      issued at or before t_k. That is what an ESC does with a command until the next one
      and what the model assumes (thrust held over each sample).
    - **Velocities are interpolated linearly** between the two measurements around t_k. A
      velocity is a continuous signal sampled by the sensor; linear interpolation adds no
      overshoot and, where a measurement falls on the grid (``auvmpc export``'s bags), it
      returns that measurement exactly.
    - The ``heading`` (rad, at the velocities' times, if given) is unwrapped and
      interpolated like a velocity.
    - Times are integer nanoseconds throughout, so that a grid point equal to a stamp is
      equal, not within round-off of it.

    A gap in the measurements longer than :data:`MAX_GAP_SAMPLES` samples, fewer than
    :data:`MIN_SAMPLES` + 1 samples, or commands that never change: one ConfigError line.
    ``what`` names the velocity and the command source for those messages.
    """
    field_name = "LOG"
    measured_what, command_what = what
    measured_t = np.asarray(measured_t, dtype=np.int64)
    command_t = np.asarray(command_t, dtype=np.int64)
    for label, stamps, count in (
        (measured_what, measured_t, len(velocity)),
        (command_what, command_t, len(command)),
    ):
        if count < 2:
            raise ConfigError(field_name, name, f"has {count} {label} messages, need many more")
        if np.any(np.diff(stamps) < 0):
            raise ConfigError(field_name, name, f"{label}: time goes backwards")
    if sample_time is None:
        step_ns = int(np.median(np.diff(command_t)))
        if step_ns <= 0:
            raise ConfigError(field_name, name, f"{command_what}: no time between messages")
    else:
        if not sample_time > 0:
            raise ConfigError("--sample-time", sample_time, "must be positive")
        step_ns = round(sample_time * 1e9)
    if command_t[-1] < measured_t[0]:
        raise ConfigError(field_name, name, f"{command_what} ends before {measured_what} starts")
    start = command_t[np.searchsorted(command_t, measured_t[0], side="left")]
    steps = int((measured_t[-1] - start) // step_ns)
    if steps < MIN_SAMPLES:
        raise ConfigError(
            field_name,
            name,
            f"holds {steps * step_ns / 1e9:.3g} s of {measured_what} with {command_what} "
            f"({steps} samples of {step_ns / 1e9:g} s), too short: need at least "
            f"{MIN_SAMPLES} samples",
        )
    grid = start + step_ns * np.arange(steps + 1, dtype=np.int64)
    inside = measured_t[(measured_t >= grid[0]) & (measured_t <= grid[-1])]
    edges = np.concatenate([[grid[0]], inside, [grid[-1]]])
    widest = int(np.argmax(np.diff(edges)))
    if np.diff(edges)[widest] > MAX_GAP_SAMPLES * step_ns:
        raise ConfigError(
            field_name,
            name,
            f"{measured_what} has a gap of {np.diff(edges)[widest] / 1e9:.3g} s at "
            f"t = {(edges[widest] - grid[0]) / 1e9:.3g} s into the log (more than "
            f"{MAX_GAP_SAMPLES} samples): cut the log there",
        )
    origin = grid[0]  # interpolate in ns from the grid's start: float64 keeps them exact
    measured = np.asarray(velocity, dtype=float)
    width = measured.shape[1]
    if heading is not None:
        measured = np.column_stack([measured, np.unwrap(np.asarray(heading, dtype=float))])
    sampled = np.column_stack(
        [
            np.interp((grid - origin).astype(float), (measured_t - origin).astype(float), column)
            for column in measured.T
        ]
    )
    held = np.asarray(command, dtype=float)[np.searchsorted(command_t, grid[:-1], side="right") - 1]
    if not np.all(np.isfinite(sampled)) or not np.all(np.isfinite(held)):
        raise ConfigError(field_name, name, "holds values that are not numbers (NaN or inf)")
    if np.ptp(held, axis=0).max() == 0.0:
        raise ConfigError(field_name, name, f"{command_what} never changes: nothing to identify")
    sample_s = step_ns / 1e9
    velocities, psi = sampled[:, :width], (sampled[:, width] if heading is not None else None)
    if as_force:
        return VelocityLog(name, sample_s, velocities, None, held, outputs, psi)
    return VelocityLog(name, sample_s, velocities, held, None, outputs, psi)


def read_run_folder(folder: str | Path, n_thrusters: int) -> VelocityLog:
    """The velocities and thrusts in a run folder's log.csv (columns t, u, v, r, F1..Fn; the
    heading psi where the log has it), read by the log's own table reader (sim/log.py,
    :class:`~auvmpc.sim.log.LogTable`): a file that is not a log, a cut or edited row, a
    cell that is not a number, a NaN or t not increasing is one line naming the file and
    the line."""
    table, log_file = run_table(folder)
    return log_from_table(table, log_file, folder, VELOCITY_NAMES, "F", n_thrusters)


# The field a run folder's refusals name (as every command reading one).
RUN_FIELD = "RUN_DIR"


def run_table(folder: str | Path):
    """A run folder's log.csv as a :class:`~auvmpc.sim.log.LogTable`, and the file."""
    path = Path(folder)
    if not path.is_dir():
        raise ConfigError(RUN_FIELD, str(folder), "no such run folder")
    log_file = path / "log.csv"
    if not log_file.is_file():
        raise ConfigError(RUN_FIELD, str(folder), "has no log.csv (not an auvmpc run folder)")
    return read_log_table(log_file, RUN_FIELD), log_file


def log_from_table(
    table,
    log_file: Path,
    folder: str | Path,
    signals: tuple[str, ...],
    prefix: str,
    n_thrusters: int,
    outputs: tuple[str, ...] = VELOCITY_NAMES,
) -> VelocityLog:
    """The columns ``signals`` (the log's ``outputs``) and the thrusts ``prefix``1..n of a
    run folder's log ``table``, checked (:func:`read_run_folder`)."""
    field = RUN_FIELD
    inputs = tuple(f"{prefix}{i + 1}" for i in range(n_thrusters))
    missing = [name for name in ("t", *signals, *inputs) if name not in table.header]
    if missing:
        raise ConfigError(
            field,
            str(log_file),
            f"has no column {', '.join(missing)} (need {', '.join(('t', *signals, *inputs))}: "
            f"the start vehicle has {n_thrusters} thrusters)",
        )
    extra = f"{prefix}{n_thrusters + 1}"
    if extra in table.header:
        raise ConfigError(
            field,
            str(log_file),
            f"has a column {extra}: more thrusters than the start vehicle's {n_thrusters}",
        )
    rows = len(table.rows)
    if rows < MIN_SAMPLES + 1:
        raise ConfigError(
            field,
            str(log_file),
            f"has {rows} rows, too short: need at least {MIN_SAMPLES + 1} samples",
        )
    t = table.numbers("t")
    table.increasing("t", t)
    velocity = np.column_stack([table.numbers(name) for name in signals])
    heading = np.unwrap(table.numbers(HEADING)) if HEADING in table.header else None
    commands = slice(0, rows - 1)  # the last row has no command
    thrust = np.column_stack([table.numbers(name, commands) for name in inputs])
    steps = np.diff(t)
    sample_time = float(np.median(steps))
    if np.max(np.abs(steps - sample_time)) > _TIME_JITTER * sample_time:
        raise ConfigError(field, str(log_file), "t is not evenly sampled")
    if np.ptp(thrust, axis=0).max() == 0.0:
        raise ConfigError(field, str(log_file), "the thrust never changes: nothing to identify")
    return VelocityLog(str(folder), sample_time, velocity, thrust, outputs=outputs,
                       heading=heading)  # fmt: skip
