"""The depth experiment's pressure sensor: Gaussian noise and a sample rate, the sample held
between updates (docs/depth.md, Sensor)."""

from __future__ import annotations

import math

import numpy as np
from pydantic import Field

from auvmpc.config import NonNegative, Positive, StrictModel
from auvmpc.models.layout import DEPTH

__all__ = ["DepthSensorConfig", "PressureSensor"]

_DEPTH = DEPTH.index("z")


class DepthSensorConfig(StrictModel):
    noise_std_m: NonNegative = Field(default=0.002, description="pressure-sensor noise (m)")
    rate_hz: Positive = Field(default=10.0, description="new samples per second (held between)")


class PressureSensor:
    """Measures ``[z]`` of a ``[z, w]`` state: a new noisy sample when one is due, else the
    last one held. Call it at every control sample, in time order."""

    def __init__(self, config: DepthSensorConfig, rng: np.random.Generator) -> None:
        self.noise_std = config.noise_std_m
        self.period = 1.0 / config.rate_hz
        self._rng = rng
        self._next_time = 0.0
        self._held = math.nan

    def measure(self, true_state: np.ndarray, t: float) -> np.ndarray:
        """(1,) the depth (m) the controller sees at ``t``."""
        if t >= self._next_time - 1e-9:  # a new pressure sample; held until the next
            self._held = true_state[_DEPTH] + self.noise_std * self._rng.standard_normal()
            self._next_time += self.period * max(
                1, math.floor((t - self._next_time) / self.period) + 1
            )
        return np.array([self._held])
