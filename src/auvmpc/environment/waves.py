"""Surface waves in a tank of finite depth and the vertical force they put on a submerged body.

Linear (Airy) wave theory, waves travelling along the tank's x axis. A component
of amplitude a, angular frequency w and wavenumber k (from the dispersion
relation w^2 = g k tanh(k h) in water of depth h) has the surface elevation
``eta = a cos(k x - w t + phi)`` and, at height z below the still surface
(-h <= z <= 0), the vertical water acceleration

    a_z(z, t) = -a w^2 sinh(k (z + h)) / sinh(k h) cos(k x - w t + phi),

which decays with depth. The body is small against the wavelength, so the force
is the Morison inertia term: Froude-Krylov plus added mass,
``F_z = (rho V + m_added) a_z`` (drag on the relative velocity is neglected; it
is second order for small waves). Irregular seas sum components of a JONSWAP
spectrum with random phases from the injected generator (same seed, same sea).
"""

from __future__ import annotations

import math
from enum import StrEnum
from typing import Annotated

import numpy as np
from pydantic import Field

from auvmpc.config import StrictModel
from auvmpc.models.vehicle import HeaveParams, VehicleParams

__all__ = [
    "GRAVITY",
    "WATER_DENSITY",
    "WaveConfig",
    "WaveField",
    "WaveType",
    "morison_inertia",
    "wave_number",
]

GRAVITY = 9.81  # m/s^2
WATER_DENSITY = 1025.0  # kg/m^3, sea water (a fresh-water tank: 1000; 2.5 % on the wave force)
# Stokes' limiting steepness: a wave higher than this fraction of its length breaks.
_BREAKING_STEEPNESS = 1.0 / 7.0


class WaveType(StrEnum):
    REGULAR = "regular"
    JONSWAP = "jonswap"


class WaveConfig(StrictModel):
    """Surface waves: ``height_m`` is the crest-to-trough height (regular) or the
    significant height Hs (JONSWAP); ``period_s`` the period or the peak period Tp."""

    type: WaveType = Field(default=WaveType.REGULAR, description="regular | jonswap")
    height_m: Annotated[float, Field(ge=0)] = Field(description="wave height (m)")
    period_s: Annotated[float, Field(gt=0)] = Field(description="wave or peak period (s)")
    gamma: Annotated[float, Field(ge=1, le=10)] = Field(
        default=3.3, description="JONSWAP peak enhancement factor"
    )
    components: Annotated[int, Field(ge=1, le=1000)] = Field(
        default=64, description="JONSWAP: number of frequency components"
    )
    position_x_m: float = Field(
        default=0.0, description="x of the vehicle along the direction of travel (m)"
    )


def wave_number(omega: float, depth: float) -> float:
    """k solving omega^2 = g k tanh(k h) (Newton from the deep-water guess)."""
    k = max(omega * omega / GRAVITY, omega / math.sqrt(GRAVITY * depth))
    for _ in range(50):
        tanh = math.tanh(k * depth)
        residual = GRAVITY * k * tanh - omega * omega
        slope = GRAVITY * (tanh + k * depth * (1.0 - tanh * tanh))
        step = residual / slope
        k -= step
        if abs(step) < 1e-12 * k:
            break
    return k


def jonswap_spectrum(omega: np.ndarray, hs: float, tp: float, gamma: float) -> np.ndarray:
    """JONSWAP variance density S(omega) (m^2 s), scaled so that 4 sqrt(m0) = Hs."""
    peak = 2.0 * math.pi / tp
    sigma = np.where(omega <= peak, 0.07, 0.09)
    shape = omega**-5.0 * np.exp(-1.25 * (peak / omega) ** 4)
    shape = shape * gamma ** np.exp(-((omega - peak) ** 2) / (2.0 * sigma**2 * peak**2))
    dense = np.linspace(0.3 * peak, 6.0 * peak, 4000)
    dense_sigma = np.where(dense <= peak, 0.07, 0.09)
    dense_shape = (
        dense**-5.0
        * np.exp(-1.25 * (peak / dense) ** 4)
        * gamma ** np.exp(-((dense - peak) ** 2) / (2.0 * dense_sigma**2 * peak**2))
    )
    m0 = np.trapezoid(dense_shape, dense)
    return shape * (hs / 4.0) ** 2 / m0


class WaveField:
    """The wave components at the vehicle's x, and the vertical force they cause."""

    def __init__(self, config: WaveConfig, water_depth: float, rng: np.random.Generator) -> None:
        self.config = config
        self.water_depth = water_depth
        if config.type is WaveType.REGULAR:
            omegas = np.array([2.0 * math.pi / config.period_s])
            amplitudes = np.array([config.height_m / 2.0])
            phases = np.array([rng.uniform(0.0, 2.0 * math.pi)])
        else:
            peak = 2.0 * math.pi / config.period_s
            edges = np.linspace(0.5 * peak, 3.0 * peak, config.components + 1)
            spacing = edges[1] - edges[0]
            # Random frequencies within each bin avoid a sea that repeats itself.
            omegas = edges[:-1] + spacing * rng.uniform(size=config.components)
            spectrum = jonswap_spectrum(omegas, config.height_m, config.period_s, config.gamma)
            amplitudes = np.sqrt(2.0 * spectrum * spacing)
            phases = rng.uniform(0.0, 2.0 * math.pi, size=config.components)
        self.omegas = omegas
        self.amplitudes = amplitudes
        self.wavenumbers = np.array([wave_number(w, water_depth) for w in omegas])
        self.phases = phases + self.wavenumbers * config.position_x_m

    def elevation(self, t: float) -> float:
        """Surface elevation at the vehicle's x (m)."""
        return float(np.sum(self.amplitudes * np.cos(self.phases - self.omegas * t)))

    def vertical_acceleration(self, z: float, t: float) -> float:
        """Vertical water acceleration at height z (m, negative below the surface)."""
        depth = self.water_depth
        z = min(max(z, -depth), 0.0)
        decay = np.sinh(self.wavenumbers * (z + depth)) / np.sinh(self.wavenumbers * depth)
        return float(
            np.sum(
                -self.amplitudes * self.omegas**2 * decay * np.cos(self.phases - self.omegas * t)
            )
        )

    def steepness(self) -> float:
        """Largest height/wavelength over the components (2a k / 2 pi)."""
        return float(np.max(2.0 * self.amplitudes * self.wavenumbers / (2.0 * math.pi)))

    def breaks(self) -> bool:
        return self.steepness() > _BREAKING_STEEPNESS


def morison_inertia(vehicle: VehicleParams, heave: HeaveParams) -> float:
    """The mass (kg) that turns the water's vertical acceleration into a force on the body,
    ``F_z = (rho V + m_added) a_z``: Froude-Krylov (the displaced water, from the vehicle's
    mass and net buoyancy) plus the heave added mass."""
    displaced_mass = vehicle.mass + heave.net_buoyancy_N / GRAVITY
    return displaced_mass * WATER_DENSITY / 1025.0 + (heave.m_heave - vehicle.mass)
