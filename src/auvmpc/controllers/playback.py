"""Open-loop thrust playback: a thrust table applied sample by sample (``thrust-playback``).

The controller of an identification manoeuvre (``auvmpc excite``): it ignores the measured
state and the reference, and applies row k of its table over [t_k, t_k+1), clipped into the
thrust and rate limits (a table written by ``excite`` is already inside them). In a
horizontal scenario it plays the horizontal thrusters ``F1..Fn``; as a depth scenario's
controller the vertical ones ``Fz1..Fzn`` of the vehicle's heave section; in a 6-DOF
scenario every ``six_dof`` thruster ``F1..Fn`` (controllers/channels.py's
:class:`~auvmpc.controllers.channels.EveryThruster`). After the
last row the thrust ramps to zero within the rate limit. The vehicle stays in a box of
water because the table's forces are bounded and zero-mean, not by feedback
(docs/identification.md).

Thrust table (CSV): header ``t`` and the thrusters' names (``F1..Fn`` or ``Fz1..Fzn``; s, N),
row k at t = k Te.
"""

from __future__ import annotations

import csv
import io
import time
from pathlib import Path
from typing import Literal

import numpy as np
from pydantic import Field, model_validator

from auvmpc.config import StrictModel
from auvmpc.controllers.base import Controller, ControlResult, ControlStatus, Observation
from auvmpc.controllers.config import (
    DEPTH_TYPE,
    ControllerType,
    DepthChannelConfig,
    HorizontalControllerConfig,
    PlaybackConfig,
    type_field,
)
from auvmpc.errors import ConfigError, FieldError
from auvmpc.models.actuators import ActuatorSet
from auvmpc.models.layout import HORIZONTAL
from auvmpc.models.vehicle import VehicleParams
from auvmpc.safe_yaml import read_text_file

__all__ = [
    "DepthPlaybackConfig",
    "PlaybackTable",
    "ThrustPlayback",
    "ThrustPlaybackConfig",
    "read_thrust_table",
    "write_thrust_table",
]

# How far a table's times may sit from the sample grid k Te (s): written to 1 us.
_TIME_TOLERANCE_S = 1e-5
_FIELD = "controller.playback.path"
# A thrust table read whole: an hour at 0.05 s for 8 thrusters is about 10 MB.
MAX_TABLE_BYTES = 64 * 1024 * 1024


def write_thrust_table(
    path: Path, sample_time: float, thrust: np.ndarray, inputs: tuple[str, ...]
) -> None:
    """Write ``thrust`` (N, n) as a thrust table, row k at t = k ``sample_time``, its columns
    named by the vehicle's ``inputs`` (its actuators' names)."""
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(["t", *inputs])
    for k, row in enumerate(thrust):
        writer.writerow([f"{k * sample_time:.6f}", *(f"{value:.6f}" for value in row)])
    Path(path).write_text(buffer.getvalue())


def read_thrust_table(path: str | Path, sample_time: float, inputs: tuple[str, ...]) -> np.ndarray:
    """The thrusts (N, n) of a thrust table whose columns are t and the vehicle's ``inputs``;
    a bad table is a one-line ConfigError."""
    text = read_text_file(path, _FIELD, "thrust table (CSV)", MAX_TABLE_BYTES)
    rows = list(csv.reader(io.StringIO(text)))
    n_thrusters = len(inputs)
    expected = ["t", *inputs]
    if not rows or [name.strip() for name in rows[0]] != expected:
        raise ConfigError(_FIELD, str(path), f"the header must be {','.join(expected)}")
    try:
        table = np.array([[float(value) for value in row] for row in rows[1:]], dtype=float)
    except ValueError as error:
        raise ConfigError(_FIELD, str(path), f"a value is not a number ({error})") from None
    if table.ndim != 2 or table.shape[0] < 1 or table.shape[1] != n_thrusters + 1:
        raise ConfigError(_FIELD, str(path), f"needs rows of {n_thrusters + 1} numbers")
    if not np.all(np.isfinite(table)):
        raise ConfigError(_FIELD, str(path), "holds a value that is not finite")
    grid = sample_time * np.arange(table.shape[0])
    if np.max(np.abs(table[:, 0] - grid)) > _TIME_TOLERANCE_S:
        raise ConfigError(
            _FIELD, str(path), f"t must be 0, {sample_time:g}, ... (the controller's sample time)"
        )
    return table[:, 1:]


class PlaybackTable(StrictModel):
    """What ``thrust-playback`` plays, in any kind of scenario: its thrust table."""

    playback: PlaybackConfig | None = Field(
        default=None,
        description="the thrust table thrust-playback plays (required); `auvmpc excite` writes one",
    )

    @model_validator(mode="after")
    def _table_given(self) -> PlaybackTable:
        if self.playback is None:  # optional for pydantic, to say what is missing
            raise FieldError("playback", None, "thrust-playback needs playback.path (a CSV)")
        return self


class ThrustPlaybackConfig(PlaybackTable, HorizontalControllerConfig):
    """``thrust-playback`` in a horizontal scenario: its table (a depth scenario's is in
    its depth controller's configuration)."""

    type: Literal[ControllerType.THRUST_PLAYBACK] = type_field(ControllerType.THRUST_PLAYBACK)


class DepthPlaybackConfig(PlaybackTable, DepthChannelConfig):
    """``thrust-playback`` in a depth scenario: a table of the vertical thrusts, as
    `auvmpc excite --dof heave` writes."""

    type: Literal["thrust-playback"] = type_field(ControllerType.THRUST_PLAYBACK.value, DEPTH_TYPE)
    playback: PlaybackConfig | None = Field(
        default=None,
        description="the vertical thrusts' table thrust-playback plays (header t, Fz1..Fzn)",
    )


class ThrustPlayback(Controller):
    """Plays a thrust table open loop (module docstring)."""

    preview_steps = 0

    def __init__(
        self,
        model: VehicleParams,
        sample_time: float,
        thrust: np.ndarray,
        actuators: ActuatorSet | None = None,
    ) -> None:
        """``actuators``: the thrusters the table drives (default the horizontal ones)."""
        self.actuators = model.actuators if actuators is None else actuators
        count = len(self.actuators.layout.names)
        thrust = np.asarray(thrust, dtype=float)
        if thrust.ndim != 2 or thrust.shape[1] != count:
            raise ValueError(f"thrust must have shape (N, {count}), got {thrust.shape}")
        self.model = model
        self.sample_time = float(sample_time)
        self.table = thrust
        self.reset(np.zeros(HORIZONTAL.size), np.zeros(count))

    @classmethod
    def from_config(
        cls, model, config, obstacle_count: int = 0, **surroundings: float
    ) -> ThrustPlayback:
        """A depth scenario's (a :class:`DepthPlaybackConfig`) plays the heave section's
        vertical thrusters, a horizontal one's the horizontal thrusters (a 6-DOF one's every
        thruster: :meth:`playing` them, experiments/kinds.py)."""
        depth = isinstance(config, DepthChannelConfig)
        return cls.playing(model, config, model.heave.actuators if depth else model.actuators)

    @classmethod
    def playing(cls, model, config, actuators: ActuatorSet) -> ThrustPlayback:
        """The table of ``config`` (columns ``actuators``' names) on those thrusters."""
        table = read_thrust_table(config.playback.path, config.sample_time, actuators.layout.names)
        return cls(model, config.sample_time, table, actuators)

    def reset(self, initial_state: np.ndarray, initial_thrust: np.ndarray) -> None:
        self._previous = np.asarray(initial_thrust, dtype=float).copy()

    def compute(self, observation: Observation) -> ControlResult:
        started = time.perf_counter()
        k = observation.k
        wanted = self.table[k] if k < len(self.table) else np.zeros(self.table.shape[1])
        thrust, moved = self.actuators.limits.project(wanted, self._previous, self.sample_time)
        self._previous = thrust
        return ControlResult(
            thrust=thrust,
            status=ControlStatus.SATURATED if moved else ControlStatus.OK,
            solve_time_s=time.perf_counter() - started,
        )
