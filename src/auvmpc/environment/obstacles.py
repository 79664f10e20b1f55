"""Circular keep-out zones that may appear, move at constant velocity, and vanish."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Annotated

import numpy as np
from pydantic import Field, model_validator

from auvmpc.config import StrictModel
from auvmpc.controllers.base import ObstacleState
from auvmpc.errors import FieldError

__all__ = ["ObstacleConfig", "visible_obstacles", "clearance"]


class ObstacleConfig(StrictModel):
    """A disc obstacle; ``center`` is where it is at t = 0."""

    center: tuple[float, float] = Field(description="world position at t = 0 (m)")
    radius: Annotated[float, Field(gt=0)] = Field(description="m")
    velocity: tuple[float, float] = Field(default=(0.0, 0.0), description="world velocity (m/s)")
    appear_time: Annotated[float, Field(ge=0)] = Field(
        default=0.0, description="first time it exists (s)"
    )
    vanish_time: float | None = Field(default=None, description="time it stops existing (s)")

    @model_validator(mode="after")
    def _ordered_times(self) -> ObstacleConfig:
        if self.vanish_time is not None and not self.vanish_time > self.appear_time:
            raise FieldError(
                "vanish_time", self.vanish_time, f"must be after appear_time {self.appear_time}"
            )
        return self

    def exists_at(self, t: float) -> bool:
        return self.appear_time <= t and (self.vanish_time is None or t < self.vanish_time)

    def center_at(self, t: float) -> np.ndarray:
        return np.array(self.center) + np.array(self.velocity) * t


def visible_obstacles(obstacles: Sequence[ObstacleConfig], t: float) -> tuple[ObstacleState, ...]:
    """The obstacles that exist at t, as the controller sees them."""
    return tuple(
        ObstacleState(center=o.center_at(t), radius=o.radius, velocity=np.array(o.velocity))
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
