"""Obstacles as the vehicle perceives them: a range sensor and one tracker per obstacle.

Without an ``obstacle_sensor`` in the scenario the controllers know every existing obstacle
exactly, position and velocity (``visible_obstacles``). With one:

* the sensor samples every ``1 / update_rate_hz`` seconds (instants j / rate, j = 0, 1, ..)
  and detects each existing obstacle whose disc comes within ``range_m`` of the vehicle's
  centre, missing it with probability ``dropout_probability``; a detection is the true
  centre plus Gaussian noise of ``position_std_m`` per axis. The vehicle position used for
  the range test is the true one at the latest control sample. Which obstacle a detection
  belongs to is known (no data association problem);
* a constant-velocity Kalman filter per obstacle (estimation/ekf.py) starts at its first
  detection, coasts (predicts only) through missed detections, and is dropped
  ``drop_after_s`` seconds after its last detection;
* at every control sample each live track is handed to the controller as an
  ``ObstacleState`` predicted to that instant, with its covariance, so the controller can
  predict the centre and a keep-out radius grown at ``confidence`` over its horizon
  (controllers/base.py). ``prediction: constant-position`` hands the same track with its
  velocity (and velocity covariance) zeroed: the obstacle assumed to stay where it is.

All randomness comes from the injected Generator.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from enum import StrEnum
from typing import Annotated

import numpy as np
import scipy.stats
from pydantic import Field

from auvmpc.config import NonNegative, StrictModel
from auvmpc.environment.obstacles import ObstacleConfig, ObstacleState
from auvmpc.estimation import ConstantVelocityKalman
from auvmpc.models.layout import OBSTACLE_TRACK

__all__ = ["ObstacleSensorConfig", "ObstaclePerception", "Prediction", "confidence_gain"]

# Sensor instants closer than this to a control sample count as at it (s): float round-off.
_TIME_TOLERANCE_S = 1e-9


class Prediction(StrEnum):
    """How a tracked obstacle is extrapolated over the controller's horizon."""

    CONSTANT_POSITION = "constant-position"
    CONSTANT_VELOCITY = "constant-velocity"


class ObstacleSensorConfig(StrictModel):
    """A range sensor that detects obstacles, with one tracker per obstacle."""

    range_m: Annotated[float, Field(gt=0)] = Field(
        default=15.0, description="detection range from the vehicle centre to the disc (m)"
    )
    update_rate_hz: Annotated[float, Field(gt=0)] = Field(
        default=2.0, description="detections per second"
    )
    position_std_m: NonNegative = Field(
        default=0.1, description="Gaussian noise on a detected centre, per axis (m)"
    )
    dropout_probability: Annotated[float, Field(ge=0, lt=1)] = Field(
        default=0.0, description="probability that an obstacle in range is missed"
    )
    acceleration_psd: NonNegative = Field(
        # 1e-4: the keep-out radius of a tracked still obstacle grows ~1 m over 15 s at 95 %
        # (0.1 m noise, 2 Hz); 1e-2 grew it 9 m and the vehicle left the track to avoid it.
        default=1e-4,
        description="tracker's white-acceleration noise density (m^2/s^3); also used "
        "in the prediction",
    )
    initial_speed_std: Annotated[float, Field(gt=0)] = Field(
        # 0.25: per axis, a speed uniform up to the vehicles' 0.5 m/s in any direction has a
        # standard deviation of 0.2 m/s. 0.5 made the first predictions' discs so wide that
        # ltv-mpc's linearisation overflowed at detection (a fallback step in 14 of 200
        # encounter runs, 3 of 200 at 0.25, same clearances).
        default=0.25,
        description="tracker's velocity uncertainty per axis at the first detection (m/s)",
    )
    drop_after_s: Annotated[float, Field(gt=0)] = Field(
        default=3.0, description="a track without a detection for this long is dropped (s)"
    )
    confidence: Annotated[float, Field(gt=0, lt=1)] = Field(
        default=0.95,
        description="probability that the keep-out disc holds the predicted position "
        "(chi-square quantile of the 2-D covariance)",
    )
    prediction: Prediction = Field(
        default=Prediction.CONSTANT_VELOCITY,
        description="constant-velocity | constant-position extrapolation over the horizon",
    )


def confidence_gain(confidence: float) -> float:
    """sqrt of the chi-square quantile with 2 degrees of freedom: the 2-D covariance
    ellipse holding ``confidence`` of the probability has semi-axes gain * sigma."""
    return math.sqrt(float(scipy.stats.chi2.ppf(confidence, df=2)))


class ObstaclePerception:
    """The sensor and its trackers, advanced to each control sample by ``observe``."""

    def __init__(
        self,
        config: ObstacleSensorConfig,
        obstacles: Sequence[ObstacleConfig],
        rng: np.random.Generator,
    ) -> None:
        self.config = config
        self.obstacles = tuple(obstacles)
        self.rng = rng
        self._gain = confidence_gain(config.confidence)
        self._period = 1.0 / config.update_rate_hz
        self._next_instant = 0  # index j of the next sensor instant j * period
        self.tracks: dict[int, ConstantVelocityKalman] = {}
        self._last_seen: dict[int, float] = {}

    def observe(self, t: float, vehicle_position: np.ndarray) -> tuple[ObstacleState, ...]:
        """Process the sensor instants up to t; the live tracks predicted to t."""
        cfg = self.config
        while self._next_instant * self._period <= t + _TIME_TOLERANCE_S:
            instant = self._next_instant * self._period
            self._next_instant += 1
            for index, obstacle in enumerate(self.obstacles):
                if not self._detected(obstacle, instant, vehicle_position):
                    continue
                measured = obstacle.center_at(instant) + cfg.position_std_m * self.rng.normal(
                    size=2
                )
                track = self.tracks.get(index)
                if track is None:
                    track = ConstantVelocityKalman(
                        measured,
                        instant,
                        cfg.position_std_m,
                        cfg.initial_speed_std,
                        cfg.acceleration_psd,
                    )
                    self.tracks[index] = track
                else:
                    track.predict(instant)
                    track.correct(measured)
                self._last_seen[index] = instant
        for index in [i for i, seen in self._last_seen.items() if t - seen > cfg.drop_after_s]:
            del self.tracks[index], self._last_seen[index]
        return tuple(self._state(index, track.predicted(t)) for index, track in self.tracks.items())

    def _detected(self, obstacle: ObstacleConfig, t: float, vehicle: np.ndarray) -> bool:
        if not obstacle.exists_at(t):
            return False
        gap = math.dist(obstacle.center_at(t), vehicle) - obstacle.radius
        if gap > self.config.range_m:
            return False
        # Drawn only for obstacles in range, so a dropout-free sensor draws only the noise.
        return not (
            self.config.dropout_probability > 0.0
            and self.rng.random() < self.config.dropout_probability
        )

    def _state(self, index: int, estimate: tuple[np.ndarray, np.ndarray]) -> ObstacleState:
        mean, covariance = estimate
        position, velocities = OBSTACLE_TRACK.position, OBSTACLE_TRACK.span("vx", "vy")
        velocity = mean[velocities].copy()
        if self.config.prediction is Prediction.CONSTANT_POSITION:
            velocity = np.zeros_like(velocity)
            covariance = covariance.copy()
            covariance[velocities, :] = 0.0
            covariance[:, velocities] = 0.0
        return ObstacleState(
            center=mean[position].copy(),
            radius=self.obstacles[index].radius,
            velocity=velocity,
            covariance=covariance,
            acceleration_psd=self.config.acceleration_psd,
            confidence_gain=self._gain,
        )
