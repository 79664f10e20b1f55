"""Ocean currents as water velocity: constant, slowly varying (Gauss-Markov), varying with depth.

The velocity is in the world frame NED (m/s) and acts on the vehicle through the relative
velocity nu_r = nu - nu_c (``auvmpc.models.six_dof``; the 3-DOF model's ``current_world``),
unlike :mod:`auvmpc.environment.disturbances`, whose current is a force.

    v_c(t, depth) = profile(depth) * (mean + variation(t))

``variation`` is a first-order Gauss-Markov process on each horizontal axis, held over each
control sample and advanced with its exact discretisation at sample boundaries (as the force
form's). ``profile`` is piecewise linear in depth (m below the surface, NED z), held beyond
its first and last points; without one it is 1 everywhere. Randomness only from the
injected ``numpy.random.Generator``.
"""

from __future__ import annotations

import math
from typing import Annotated

import numpy as np
from pydantic import Field, field_validator

from auvmpc.config import NonNegative, Positive, StrictModel
from auvmpc.models.layout import HORIZONTAL_COMPONENTS, WORLD_VECTOR

__all__ = ["CurrentVariationConfig", "WaterCurrent", "WaterCurrentConfig", "gauss_markov_step"]


class CurrentVariationConfig(StrictModel):
    """The slowly varying part of a current: first-order Gauss-Markov velocity per axis."""

    std_m_per_s: NonNegative = Field(description="stationary standard deviation per axis (m/s)")
    time_constant_s: Positive = Field(description="correlation time (s)")


ProfilePoint = tuple[float, Annotated[float, Field(ge=0)]]


class WaterCurrentConfig(StrictModel):
    """A current as water velocity in the world frame (NED: x north, y east, z down)."""

    velocity_m_per_s: tuple[(float,) * WORLD_VECTOR.size] = Field(
        default=(0.0,) * WORLD_VECTOR.size,
        description="mean water velocity (north, east, down) where the profile is 1 (m/s)",
    )
    variation: CurrentVariationConfig | None = Field(
        default=None, description="slowly varying horizontal part, if any"
    )
    depth_profile: tuple[ProfilePoint, ...] = Field(
        default=(),
        description="[depth below the surface (m), factor] pairs, depths increasing; the "
        "velocity is scaled by the factor, linear in between, held beyond the ends (not in "
        "horizontal scenarios: their plant has no depth)",
    )

    @field_validator("depth_profile")
    @classmethod
    def _increasing(cls, points: tuple[ProfilePoint, ...]) -> tuple[ProfilePoint, ...]:
        depths = [depth for depth, _ in points]
        if any(b <= a for a, b in zip(depths, depths[1:], strict=False)):
            raise ValueError(f"depths must increase strictly, got {depths}")
        return points


def gauss_markov_step(
    value: np.ndarray, std: float, time_constant: float, dt: float, rng: np.random.Generator
) -> np.ndarray:
    """A first-order Gauss-Markov process with stationary ``std`` moved on by ``dt``: its
    exact discretisation, so the statistics do not depend on the step."""
    decay = math.exp(-dt / time_constant)
    drive = std * math.sqrt(1.0 - decay * decay)
    return decay * value + drive * rng.normal(size=np.shape(value))


class WaterCurrent:
    """The current of a :class:`WaterCurrentConfig` as the plant sees it (module docstring)."""

    def __init__(self, config: WaterCurrentConfig, sample_time: float, rng: np.random.Generator):
        self.config = config
        self.sample_time = sample_time
        self._rng = rng
        self._mean = np.array(config.velocity_m_per_s, dtype=float)
        self._variation = np.zeros(WORLD_VECTOR.size)
        variation = config.variation
        if variation is not None and variation.std_m_per_s > 0:
            # Start from the stationary distribution so the statistics do not drift.
            horizontal = self._variation[HORIZONTAL_COMPONENTS]  # a view
            horizontal[:] = rng.normal(0.0, variation.std_m_per_s, size=horizontal.shape)
        self._depths = np.array([depth for depth, _ in config.depth_profile], dtype=float)
        self._factors = np.array([factor for _, factor in config.depth_profile], dtype=float)

    def advance(self) -> None:
        """Move the Gauss-Markov part forward by one control sample."""
        variation = self.config.variation
        if variation is None or variation.std_m_per_s == 0:
            return
        horizontal = HORIZONTAL_COMPONENTS
        self._variation[horizontal] = gauss_markov_step(
            self._variation[horizontal], variation.std_m_per_s, variation.time_constant_s,
            self.sample_time, self._rng,
        )  # fmt: skip

    def profile(self, depth_m: float) -> float:
        """The depth factor (1 without a profile)."""
        if self._depths.size == 0:
            return 1.0
        return float(np.interp(depth_m, self._depths, self._factors))

    def profile_slope(self, depth_m: float) -> float:
        """d profile / d depth (1/m): the segment's slope, 0 beyond the ends."""
        depths, factors = self._depths, self._factors
        if depths.size < 2 or not depths[0] < depth_m < depths[-1]:
            return 0.0
        i = int(np.searchsorted(depths, depth_m)) - 1
        return float((factors[i + 1] - factors[i]) / (depths[i + 1] - depths[i]))

    def velocity_world(self, t: float, depth_m: float = 0.0) -> np.ndarray:
        """Water velocity [x, y, z] (WORLD_VECTOR, m/s) at time t within the current sample
        and a depth."""
        return self.profile(depth_m) * (self._mean + self._variation)

    def at(self, t: float, depth_m: float, depth_rate: float) -> tuple[np.ndarray, np.ndarray]:
        """(v_c, v_c') at a vehicle at ``depth_m`` moving down at ``depth_rate`` (m/s): the
        velocity and its rate along the vehicle's path (held part: only the depth changes)."""
        base = self._mean + self._variation
        return self.profile(depth_m) * base, self.profile_slope(depth_m) * depth_rate * base
