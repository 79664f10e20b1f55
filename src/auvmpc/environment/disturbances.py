"""External forces on the plant and noise on what the controller measures.

Every random quantity comes from an injected ``numpy.random.Generator``: same
seed, same bits. Forces are given in the world frame as ``[X, Y, N]`` (N, N,
N m) and rotated into the body frame by the plant (paper-model.md section 6).
A current may also be given as water velocity (``water_current``), which the plant
applies through the relative velocity (:mod:`auvmpc.environment.currents`).
"""

from __future__ import annotations

import math

import numpy as np
from pydantic import Field, field_validator

from auvmpc.config import NonNegative, Positive, StrictModel
from auvmpc.environment.currents import WaterCurrent, WaterCurrentConfig, gauss_markov_step
from auvmpc.models.layout import (
    HORIZONTAL,
    HORIZONTAL_COMPONENTS,
    PLANAR_FORCE,
    PLANAR_FORCE_XY,
    WORLD_VECTOR,
)

__all__ = [
    "DisturbanceConfig",
    "GaussMarkovConfig",
    "SensorNoiseConfig",
    "WaveForceConfig",
    "WorldDisturbance",
    "SensorNoise",
]


class GaussMarkovConfig(StrictModel):
    """A slowly varying current: first-order Gauss-Markov force on top of the mean."""

    std_N: NonNegative = Field(description="stationary standard deviation per axis (N)")
    time_constant_s: Positive = Field(description="correlation time (s)")


class WaveForceConfig(StrictModel):
    """A wave-like oscillating world-frame force along one direction."""

    amplitude_N: NonNegative = Field(description="force amplitude (N)")
    period_s: Positive = Field(description="oscillation period (s)")
    direction_deg: float = Field(default=0.0, description="direction of the force, deg from +x")


class DisturbanceConfig(StrictModel):
    """Everything pushing on the vehicle that the controller is not told about."""

    current_force_world: tuple[float, float] = Field(
        default=(0.0, 0.0), description="constant current force (X, Y) in the world frame (N)"
    )
    moment_N_m: float = Field(default=0.0, description="constant yaw moment (N m)")
    current_variation: GaussMarkovConfig | None = Field(
        default=None, description="slowly varying part of the current, if any"
    )
    waves: WaveForceConfig | None = Field(default=None, description="oscillating force, if any")
    water_current: WaterCurrentConfig | None = Field(
        default=None,
        description="current as water velocity (world frame), acting through the velocity "
        "relative to the water; adds to the force form above",
    )

    @field_validator("water_current")
    @classmethod
    def _horizontal(cls, current: WaterCurrentConfig | None) -> WaterCurrentConfig | None:
        # The horizontal plant has no depth to read a profile at, nor a vertical velocity.
        if current is not None and current.depth_profile:
            raise ValueError("a depth profile needs a depth; the horizontal plant has none")
        if current is not None and current.velocity_m_per_s[WORLD_VECTOR.index("z")] != 0:
            raise ValueError("the horizontal plant has no vertical velocity: give down = 0")
        return current


class SensorNoiseConfig(StrictModel):
    """Zero-mean Gaussian noise on the state the controller sees (the log keeps the truth)."""

    # One per horizontal state: tuple[NonNegative, ...] with HORIZONTAL.size entries.
    std: tuple[(NonNegative,) * HORIZONTAL.size] = Field(
        default=(0.0,) * HORIZONTAL.size,
        description="standard deviation of [x, y, psi, u, v, r] (m, m, rad, m/s, m/s, rad/s)",
    )


class WorldDisturbance:
    """Constant current + Gauss-Markov variation + waves, as a force in the world frame.

    The Gauss-Markov part is held over each control sample and advanced with its
    exact discretisation at sample boundaries; the wave part is a smooth function
    of time evaluated wherever the integrator asks.
    """

    def __init__(self, config: DisturbanceConfig, sample_time: float, rng: np.random.Generator):
        self.config = config
        self.sample_time = sample_time
        self._rng = rng
        self._mean = np.array([*config.current_force_world, config.moment_N_m], dtype=float)
        self._variation = np.zeros(PLANAR_FORCE.size)
        variation = config.current_variation
        if variation is not None and variation.std_N > 0:
            # Start from the stationary distribution so the statistics do not drift.
            planar = self._variation[PLANAR_FORCE_XY]  # a view
            planar[:] = rng.normal(0.0, variation.std_N, size=planar.shape)
        self._wave_phase = 0.0
        if config.waves is not None:
            self._wave_phase = float(rng.uniform(0.0, 2.0 * math.pi))
        # Drawn after the force parts' first draws, so that a scenario without a water current
        # keeps its bits. (With a varying water current the later force draws interleave with
        # the current's on this generator.)
        self._water = (
            None
            if config.water_current is None
            else WaterCurrent(config.water_current, sample_time, rng)
        )

    @property
    def is_constant(self) -> bool:
        water = self.config.water_current
        return (
            self.config.current_variation is None
            and self.config.waves is None
            and (water is None or water.variation is None)
        )

    def advance(self) -> None:
        """Move the Gauss-Markov states forward by one control sample."""
        if self._water is not None:
            self._water.advance()
        variation = self.config.current_variation
        if variation is None or variation.std_N == 0:
            return
        self._variation[PLANAR_FORCE_XY] = gauss_markov_step(
            self._variation[PLANAR_FORCE_XY], variation.std_N, variation.time_constant_s,
            self.sample_time, self._rng,
        )  # fmt: skip

    def water_velocity_world(self, t: float) -> np.ndarray | None:
        """Horizontal water velocity ``[V_x, V_y]`` (m/s) at time t, or None without one."""
        if self._water is None:
            return None
        return self._water.velocity_world(t)[HORIZONTAL_COMPONENTS]

    def force_world(self, t: float) -> np.ndarray:
        """World-frame ``[X, Y, N]`` at time t within the current sample."""
        return self.forces_world(np.array([t]))[0]

    def forces_world(self, times: np.ndarray) -> np.ndarray:
        """(len(times), PLANAR_FORCE.size): :meth:`force_world` at each time within the current
        sample."""
        times = np.asarray(times, dtype=float)
        forces = np.tile(self._mean + self._variation, (times.size, 1))
        waves = self.config.waves
        if waves is not None and waves.amplitude_N > 0:
            angle = math.radians(waves.direction_deg)
            magnitude = waves.amplitude_N * np.sin(
                2.0 * math.pi * times / waves.period_s + self._wave_phase
            )
            forces += magnitude[:, None] * np.array([math.cos(angle), math.sin(angle), 0.0])
        return forces


class SensorNoise:
    """Adds Gaussian noise to a true state; a no-op (and draws nothing) when all std are 0."""

    def __init__(self, config: SensorNoiseConfig, rng: np.random.Generator):
        self._std = np.array(config.std, dtype=float)
        self._rng = rng
        self._active = bool(np.any(self._std > 0))

    def measure(self, true_state: np.ndarray, t: float | None = None) -> np.ndarray:
        """The state with noise; ``t`` is unused (the noise does not depend on time)."""
        if not self._active:
            return true_state.copy()
        return true_state + self._std * self._rng.standard_normal(self._std.shape)
