"""What identification reads from a log: body velocities and the thrust applied.

A log for identification is :class:`VelocityLog`: the body velocities ``u, v, r`` at
t_k = k Te and the thrust held over [t_k, t_k+1). :func:`read_run_folder` reads one from an
auvmpc run folder's ``log.csv`` (docs/identification.md: that file keeps the simulated
truth; a real vehicle's log holds what its sensors measured). Whatever is missing or too
short is one :class:`~auvmpc.errors.ConfigError` line naming it (exit 2 from the CLI).
"""

from __future__ import annotations

import csv
import io
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from auvmpc.errors import ConfigError
from auvmpc.safe_yaml import read_text_file

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


# A log.csv read whole: an hour at 0.05 s with 8 thrusters is about 60 MB; four times that
# stays well inside memory (the rows are parsed once).
MAX_LOG_BYTES = 256 * 1024 * 1024


def read_run_folder(folder: str | Path, n_thrusters: int) -> VelocityLog:
    """The velocities and thrusts in a run folder's log.csv (columns t, u, v, r, F1..Fn)."""
    path = Path(folder)
    field = "RUN_DIR"
    if not path.is_dir():
        raise ConfigError(field, str(folder), "no such run folder")
    log_file = path / "log.csv"
    if not log_file.is_file():
        raise ConfigError(field, str(folder), "has no log.csv (not an auvmpc run folder)")
    text = read_text_file(log_file, field, "log.csv", MAX_LOG_BYTES)
    rows = list(csv.reader(io.StringIO(text)))
    if not rows:
        raise ConfigError(field, str(log_file), "is empty")
    header = [name.strip() for name in rows[0]]
    inputs = tuple(f"F{i + 1}" for i in range(n_thrusters))
    missing = [name for name in ("t", *VELOCITY_NAMES, *inputs) if name not in header]
    if missing:
        raise ConfigError(
            field,
            str(log_file),
            f"has no column {', '.join(missing)} (need t, u, v, r, "
            f"{', '.join(inputs)}: the start vehicle has {n_thrusters} thrusters)",
        )
    extra = f"F{n_thrusters + 1}"
    if extra in header:
        raise ConfigError(
            field,
            str(log_file),
            f"has a column {extra}: more thrusters than the start vehicle's {n_thrusters}",
        )
    body = rows[1:]
    if len(body) < MIN_SAMPLES + 1:
        raise ConfigError(
            field,
            str(log_file),
            f"has {len(body)} rows, too short: need at least {MIN_SAMPLES + 1} samples",
        )
    columns = {name: header.index(name) for name in ("t", *VELOCITY_NAMES, *inputs)}

    def numbers(names, rows_):
        try:
            return np.array([[float(row[columns[n]]) for n in names] for row in rows_])
        except (ValueError, IndexError):
            raise ConfigError(
                field, str(log_file), f"a value in {', '.join(names)} is missing or not a number"
            ) from None

    t = numbers(("t",), body)[:, 0]
    velocity = numbers(VELOCITY_NAMES, body)
    thrust = numbers(inputs, body[:-1])  # the last row has no command
    if not (np.all(np.isfinite(velocity)) and np.all(np.isfinite(thrust))):
        raise ConfigError(field, str(log_file), "holds a velocity or thrust that is not finite")
    steps = np.diff(t)
    sample_time = float(np.median(steps))
    if sample_time <= 0 or np.max(np.abs(steps - sample_time)) > _TIME_JITTER * sample_time:
        raise ConfigError(field, str(log_file), "t is not evenly sampled")
    if np.ptp(thrust, axis=0).max() == 0.0:
        raise ConfigError(field, str(log_file), "the thrust never changes: nothing to identify")
    return VelocityLog(str(folder), sample_time, velocity, thrust)
