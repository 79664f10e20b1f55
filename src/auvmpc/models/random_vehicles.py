"""Physically plausible random vehicles, for sweeps that test a controller beyond one preset.

Each vehicle is the BlueROV2 Heavy (von Benzon et al. 2022, the ``bluerov2-heavy`` preset)
scaled geometrically to a mass drawn log-uniformly from 10 kg to 2 t, with every
hydrodynamic ratio spread over the range real vehicles have:

* length scale ``s = (mass / 13.5 kg)^(1/3)``; thruster positions scale with ``s``;
* added mass 10-60 % of the mass in surge, 30-120 % in sway (m11 < m22 for a box-like ROV);
* yaw radius of gyration 0.08-0.25 s m (the BlueROV2's is 0.166 m): light yaw inertia is in;
  added yaw inertia 0-80 % of the rigid body's;
* quadratic damping 0.3-2x the BlueROV2's, scaled with area (s^2; yaw: s^5), linear damping
  0-2x (light damping is in: a lightly damped vehicle is the hard case for an RTI);
* four thrusters in the BlueROV2's 45 deg layout, each strong enough for about 1.5 m/s in surge
  against the vehicle's own damping, reverse thrust 70-100 % of forward;
* thrust rate 0.5-4 full ranges per second.
"""

from __future__ import annotations

import math

import numpy as np

from auvmpc.models.vehicle import VehicleParams

__all__ = ["MASS_RANGE_KG", "random_vehicle"]

MASS_RANGE_KG = (10.0, 2000.0)
_REFERENCE_MASS_KG = 13.5  # bluerov2-heavy
_TOP_SPEED_M_PER_S = 1.5
_SURGE_SHARE = math.cos(math.radians(45.0))  # each thruster's share of its force along surge


def random_vehicle(rng: np.random.Generator, name: str = "random") -> VehicleParams:
    """One random vehicle (module docstring for the ranges)."""
    mass = float(np.exp(rng.uniform(*np.log(MASS_RANGE_KG))))
    s = (mass / _REFERENCE_MASS_KG) ** (1.0 / 3.0)
    area = s**2
    gyration = rng.uniform(0.08, 0.25) * s
    Iz_rb = mass * gyration**2
    Xuu = -141.0 * area * rng.uniform(0.3, 2.0)
    Xu = -13.7 * area * rng.uniform(0.0, 2.0)
    forward = (abs(Xu) * _TOP_SPEED_M_PER_S + abs(Xuu) * _TOP_SPEED_M_PER_S**2) / (
        4.0 * _SURGE_SHARE
    )
    reverse = forward * rng.uniform(0.7, 1.0)
    x_arm, y_arm = 0.156 * s, 0.111 * s
    return VehicleParams(
        name=name,
        description=f"random vehicle, {mass:.1f} kg",
        source="auvmpc.models.random_vehicles (BlueROV2 Heavy scaled, ratios randomised)",
        mass=mass,
        m11=mass * (1.0 + rng.uniform(0.1, 0.6)),
        m22=mass * (1.0 + rng.uniform(0.3, 1.2)),
        Iz_rb=Iz_rb,
        Iz_added=Iz_rb * rng.uniform(0.0, 0.8),
        Xu=Xu,
        Xuu=Xuu,
        Yv=-13.7 * area * rng.uniform(0.0, 2.0),
        Yvv=-217.0 * area * rng.uniform(0.3, 2.0),
        Nr=-0.5 * s**4 * rng.uniform(0.0, 2.0),
        Nrr=-1.5 * s**5 * rng.uniform(0.3, 2.0),
        thrusters=(
            {"position": (x_arm, y_arm), "angle_deg": -45.0},
            {"position": (x_arm, -y_arm), "angle_deg": 45.0},
            {"position": (-x_arm, y_arm), "angle_deg": -135.0},
            {"position": (-x_arm, -y_arm), "angle_deg": 135.0},
        ),
        thrust_limits=(-reverse, forward),
        thrust_rate_limit=(forward + reverse) * rng.uniform(0.5, 4.0),
    )
