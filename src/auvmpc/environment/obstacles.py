"""Circular keep-out zones that may appear, move, and vanish.

Motion, one of (the fields of the others left at their defaults):

* constant velocity: ``velocity`` (m/s), the centre at ``center + velocity t``;
* constant turn: ``velocity`` at t = 0 turned at ``turn_rate`` (rad/s, anticlockwise),
  the centre on a circle of radius |velocity| / turn_rate;
* waypoints: from ``center`` through ``waypoints`` at ``speed`` (m/s) along the straight
  legs, then held at the last waypoint.

Motion time counts from ``at_time`` (default 0), whatever ``appear_time`` is: ``center`` is
where the obstacle is at t = ``at_time`` (a campaign can so sample when an obstacle crosses a
point of the track without moving the point).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Annotated

import numpy as np
from pydantic import Field, model_validator

from auvmpc.config import StrictModel
from auvmpc.errors import FieldError
from auvmpc.models.layout import OBSTACLE_TRACK

__all__ = ["ObstacleConfig", "ObstacleState", "clearance", "visible_obstacles"]


@dataclass(frozen=True)
class ObstacleState:
    """A keep-out disc as the controller sees it at the current sample, and its prediction.

    Known exactly (no obstacle sensor): ``covariance`` is None and the disc keeps its radius.
    Tracked (environment/obstacle_sensor.py): ``center`` and ``velocity`` are the tracker's
    estimate, ``covariance`` its (4, 4) covariance of [x, y, vx, vy] now, and the predicted
    keep-out radius at ``dt`` ahead grows by ``confidence_gain`` times the largest standard
    deviation of the predicted position (constant-velocity model with white acceleration
    noise of spectral density ``acceleration_psd``; Bar-Shalom, Li, Kirubarajan 2001, sec. 6.2):

        P_pos(dt) = P_pp + dt (P_pv + P_vp) + dt^2 P_vv + acceleration_psd dt^3 / 3 I,
        radius(dt) = radius + confidence_gain sqrt(lambda_max(P_pos(dt))).
    """

    center: np.ndarray  # (2,) world position now (m)
    radius: float  # m
    velocity: np.ndarray  # (2,) world velocity (m/s); zero for a fixed obstacle
    covariance: np.ndarray | None = None  # (4, 4) of [x, y, vx, vy]; None: known exactly
    acceleration_psd: float = 0.0  # m^2/s^3, the prediction's white-acceleration noise
    confidence_gain: float = 0.0  # sqrt of the chi-square(2) quantile of the confidence

    def center_at(self, dt: float) -> np.ndarray:
        """Predicted centre ``dt`` seconds ahead (constant velocity)."""
        return self.center + self.velocity * dt

    def predict(self, dts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Predicted centres (n, 2) and keep-out radii (n,) at ``dts`` (n,) seconds ahead."""
        dts = np.asarray(dts, dtype=float)
        centres = self.center + np.outer(dts, self.velocity)
        if self.covariance is None:
            return centres, np.full(len(dts), self.radius)
        return centres, self.radius + self.confidence_gain * np.sqrt(
            self.largest_position_variance(dts)
        )

    def horizon_radius(self, dts: np.ndarray) -> float:
        """The one keep-out radius over predictions ``dts`` (s) ahead: the largest predicted
        one (a tracked obstacle's grows with its uncertainty), the radius if known exactly."""
        if self.covariance is None:
            return self.radius
        return float(self.predict(dts)[1].max())

    def largest_position_variance(self, dts: np.ndarray) -> np.ndarray:
        """Largest eigenvalue of the predicted position covariance (n,) (m^2); 0 if known."""
        dts = np.asarray(dts, dtype=float)
        if self.covariance is None:
            return np.zeros(len(dts))
        P = self.covariance
        position, velocity = OBSTACLE_TRACK.position, OBSTACLE_TRACK.span("vx", "vy")
        cross = P[position, velocity] + P[velocity, position]
        growth = self.acceleration_psd * dts**3 / 3.0
        pos = (
            P[position, position][None]
            + dts[:, None, None] * cross[None]
            + (dts**2)[:, None, None] * P[velocity, velocity][None]
            + growth[:, None, None] * np.eye(2)[None]
        )
        half_trace = 0.5 * (pos[:, 0, 0] + pos[:, 1, 1])
        spread = np.hypot(0.5 * (pos[:, 0, 0] - pos[:, 1, 1]), pos[:, 0, 1])
        return half_trace + spread


class ObstacleConfig(StrictModel):
    """A disc obstacle; ``center`` is where it is at t = 0."""

    center: tuple[float, float] = Field(description="world position at t = at_time (m)")
    radius: Annotated[float, Field(gt=0)] = Field(description="m")
    velocity: tuple[float, float] = Field(default=(0.0, 0.0), description="world velocity (m/s)")
    appear_time: Annotated[float, Field(ge=0)] = Field(
        default=0.0, description="first time it exists (s)"
    )
    vanish_time: float | None = Field(default=None, description="time it stops existing (s)")
    at_time: float = Field(
        default=0.0, description="time at which the obstacle is at ``center`` (s)"
    )
    turn_rate: float = Field(
        default=0.0,
        description="rate at which ``velocity`` turns (rad/s, anticlockwise): a constant turn",
    )
    waypoints: tuple[tuple[float, float], ...] = Field(
        default=(),
        description="world points visited after ``center`` at ``speed``, the last one held (m)",
    )
    speed: Annotated[float, Field(gt=0)] | None = Field(
        default=None, description="speed along ``waypoints`` (m/s); only with waypoints"
    )

    @model_validator(mode="after")
    def _ordered_times(self) -> ObstacleConfig:
        if self.vanish_time is not None and not self.vanish_time > self.appear_time:
            raise FieldError(
                "vanish_time", self.vanish_time, f"must be after appear_time {self.appear_time}"
            )
        return self

    @model_validator(mode="after")
    def _one_motion(self) -> ObstacleConfig:
        if self.waypoints and self.speed is None:
            raise FieldError("speed", None, "waypoints need a speed (m/s)")
        if self.speed is not None and not self.waypoints:
            raise FieldError("speed", self.speed, "only meaningful with waypoints")
        if self.waypoints and (self.velocity != (0.0, 0.0) or self.turn_rate != 0.0):
            raise FieldError(
                "waypoints", self.waypoints, "give either waypoints or velocity/turn_rate"
            )
        return self

    def exists_at(self, t: float) -> bool:
        return self.appear_time <= t and (self.vanish_time is None or t < self.vanish_time)

    def center_at(self, t: float) -> np.ndarray:
        """World centre at time t (m)."""
        t = t - self.at_time
        if self.waypoints:
            return self._along_waypoints(t)[0]
        if self.turn_rate == 0.0:
            return np.array(self.center) + np.array(self.velocity) * t
        w = self.turn_rate
        s, c = math.sin(w * t), math.cos(w * t)
        # Integral of R(w tau) v0 over [0, t] (R: rotation by w tau).
        travelled = np.array([[s, c - 1.0], [1.0 - c, s]]) / w @ np.array(self.velocity)
        return np.array(self.center) + travelled

    def velocity_at(self, t: float) -> np.ndarray:
        """World velocity at time t (m/s)."""
        t = t - self.at_time
        if self.waypoints:
            return self._along_waypoints(t)[1]
        if self.turn_rate == 0.0:
            return np.array(self.velocity)
        s, c = math.sin(self.turn_rate * t), math.cos(self.turn_rate * t)
        return np.array([[c, -s], [s, c]]) @ np.array(self.velocity)

    def _along_waypoints(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """Position and velocity ``t`` seconds after leaving ``center`` (held there before)."""
        points = np.array([self.center, *self.waypoints], dtype=float)
        remaining = max(t, 0.0) * self.speed
        for start, end in zip(points[:-1], points[1:], strict=True):
            leg = end - start
            length = float(np.hypot(*leg))
            if length == 0.0:
                continue
            if remaining < length:
                direction = leg / length
                return start + remaining * direction, self.speed * direction
            remaining -= length
        return points[-1], np.zeros(2)


def visible_obstacles(obstacles: Sequence[ObstacleConfig], t: float) -> tuple[ObstacleState, ...]:
    """The obstacles that exist at t, as the controller sees them."""
    return tuple(
        ObstacleState(center=o.center_at(t), radius=o.radius, velocity=o.velocity_at(t))
        for o in obstacles
        if o.exists_at(t)
    )


def clearance(
    position: np.ndarray, t: float, obstacles: Sequence[ObstacleConfig], vehicle_radius: float
) -> float:
    """Smallest gap between the vehicle disc and any existing obstacle disc (m); inf if none."""
    gaps = [
        math.dist(position, o.center_at(t)) - o.radius - vehicle_radius
        for o in obstacles
        if o.exists_at(t)
    ]
    return min(gaps, default=math.inf)
