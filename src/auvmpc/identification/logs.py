"""What identification reads from a log: body velocities and the thrust applied.

A log for identification is :class:`VelocityLog`: the body velocities ``u, v, r`` at
t_k = k Te and the thrust held over [t_k, t_k+1). :func:`read_run_folder` reads one from an
auvmpc run folder's ``log.csv`` (docs/identification.md: that file keeps the simulated
truth; a real vehicle's log holds what its sensors measured). Whatever is missing or too
short is one :class:`~auvmpc.errors.ConfigError` line naming it (exit 2 from the CLI).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from auvmpc.errors import ConfigError
from auvmpc.sim.log import read_log_table

__all__ = ["MIN_SAMPLES", "VelocityLog", "read_run_folder"]

# Fewer samples than this cannot hold a fit, a held-out part and a filter window.
MIN_SAMPLES = 100
# The sample times of a log may wander by this share of a sample (written to 1 us).
_TIME_JITTER = 1e-3
VELOCITY_NAMES = ("u", "v", "r")


@dataclass(frozen=True)
class VelocityLog:
    """Body velocities and thrusts of one log, sampled every ``sample_time``."""

    name: str  # where it came from (a path), for the provenance
    sample_time: float  # s
    velocity: np.ndarray  # (N+1, 3) u, v (m/s), r (rad/s) at t_k
    thrust: np.ndarray  # (N, n) N, held over [t_k, t_k+1)

    @property
    def steps(self) -> int:
        return len(self.thrust)

    def part(self, start: int, stop: int) -> VelocityLog:
        """Samples start..stop (commands start..stop-1)."""
        return VelocityLog(
            self.name, self.sample_time, self.velocity[start : stop + 1], self.thrust[start:stop]
        )


def read_run_folder(folder: str | Path, n_thrusters: int) -> VelocityLog:
    """The velocities and thrusts in a run folder's log.csv (columns t, u, v, r, F1..Fn),
    read by the log's own table reader (sim/log.py, :class:`~auvmpc.sim.log.LogTable`): a
    file that is not a log, a cut or edited row, a cell that is not a number, a NaN or t
    not increasing is one line naming the file and the line."""
    path = Path(folder)
    field = "RUN_DIR"
    if not path.is_dir():
        raise ConfigError(field, str(folder), "no such run folder")
    log_file = path / "log.csv"
    if not log_file.is_file():
        raise ConfigError(field, str(folder), "has no log.csv (not an auvmpc run folder)")
    table = read_log_table(log_file, field)
    inputs = tuple(f"F{i + 1}" for i in range(n_thrusters))
    missing = [name for name in ("t", *VELOCITY_NAMES, *inputs) if name not in table.header]
    if missing:
        raise ConfigError(
            field,
            str(log_file),
            f"has no column {', '.join(missing)} (need t, u, v, r, "
            f"{', '.join(inputs)}: the start vehicle has {n_thrusters} thrusters)",
        )
    extra = f"F{n_thrusters + 1}"
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
    velocity = np.column_stack([table.numbers(name) for name in VELOCITY_NAMES])
    commands = slice(0, rows - 1)  # the last row has no command
    thrust = np.column_stack([table.numbers(name, commands) for name in inputs])
    steps = np.diff(t)
    sample_time = float(np.median(steps))
    if np.max(np.abs(steps - sample_time)) > _TIME_JITTER * sample_time:
        raise ConfigError(field, str(log_file), "t is not evenly sampled")
    if np.ptp(thrust, axis=0).max() == 0.0:
        raise ConfigError(field, str(log_file), "the thrust never changes: nothing to identify")
    return VelocityLog(str(folder), sample_time, velocity, thrust)
