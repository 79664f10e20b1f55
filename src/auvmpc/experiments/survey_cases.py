"""Random hard cases for judging a controller beyond the paper's vehicle and its circles.

A *case* is a whole scenario mapping (what ``auvmpc run`` reads) drawn from one
``np.random.Generator``: a random plausible vehicle (models/random_vehicles.py) flying a
random mission in a current, with model error, sensor noise and obstacles on its path.

* :func:`hard_survey_case`: a lawnmower survey, legs 12-30 m joined by 90-degree turns,
  0.25-0.5 m/s, in any orientation; yaw inertia from a quarter of the usual to the usual; a
  current force up to 30 % of the vehicle's largest surge thrust from any direction; +-30 %
  error on every added mass and damping coefficient of the simulated vehicle; sensor noise;
  one or two discs on the long legs.
* :func:`loop_case`: a circle or a figure-eight, same vehicles and disturbances, no obstacles
  (the older sweep's missions, kept beside the survey).

Each case is judged against the same scenario solved with the optimal control problem to
convergence (the ``nmpc`` controller with ``nmpc_mode: full``): see
:func:`yardstick_overrides` and docs/recovery.md.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from auvmpc.models.layout import HORIZONTAL_VELOCITY, PLANAR_FORCE
from auvmpc.models.random_vehicles import random_vehicle
from auvmpc.models.vehicle import VehicleParams

__all__ = [
    "CASE_KINDS",
    "YARDSTICK",
    "hard_survey_case",
    "loop_case",
    "make_case",
    "vehicle_radius",
    "yardstick_overrides",
]

# Ranges of the hard survey (the words, so that its numbers are checked as stated).
LEG_LENGTH_M = (12.0, 30.0)
SPEED_M_PER_S = (0.25, 0.5)
YAW_INERTIA_SCALE = (0.25, 1.0)  # times the random vehicle's usual yaw inertia
CURRENT_SHARE = 0.3  # largest current force, as a share of the largest surge thrust
MODEL_ERROR = 0.3  # +- relative error on added mass and damping
# Added-mass and damping fields of a vehicle file (the rigid-body mass and inertia are known).
_DAMPING_FIELDS = ("Xu", "Xuu", "Yv", "Yvv", "Nr", "Nrr")
# Sensor noise std on [x y psi u v r], m, rad, m/s, rad/s: a DVL-aided INS class of navigation.
SENSOR_STD = (0.02, 0.02, 0.005, 0.01, 0.01, 0.002)
_SETTLE_S = 15.0  # time after the reference stops, so a late vehicle can arrive
_REFERENCE_MASS_KG = 13.5  # the random vehicles scale the BlueROV2 Heavy (13.5 kg)
_REFERENCE_RADIUS_M = 0.35  # the BlueROV2 Heavy's footprint, half its 0.58 m width + margin

# The yardstick every case is also solved with: the same problem, IPOPT to convergence.
YARDSTICK = ("controller.type=nmpc", "controller.nmpc_mode=full", "controller.control_horizon=null")


def yardstick_overrides() -> tuple[str, ...]:
    """``--set`` overrides that turn a case's controller into the converged OCP."""
    return YARDSTICK


def _size_scale(vehicle: VehicleParams) -> float:
    return (vehicle.mass / _REFERENCE_MASS_KG) ** (1.0 / 3.0)


def vehicle_radius(vehicle: VehicleParams) -> float:
    """The disc a random vehicle fills (m): the BlueROV2's, scaled with its length."""
    return round(_REFERENCE_RADIUS_M * _size_scale(vehicle), 3)


def _light_yaw_vehicle(rng: np.random.Generator, name: str) -> VehicleParams:
    vehicle = random_vehicle(rng, name=name)
    scale = rng.uniform(*YAW_INERTIA_SCALE)
    return vehicle.model_copy(
        update={"Iz_rb": vehicle.Iz_rb * scale, "Iz_added": vehicle.Iz_added * scale}
    )


def _model_error(rng: np.random.Generator, vehicle: VehicleParams) -> dict[str, float]:
    """``plant.scale`` factors: each added mass and damping coefficient off by +-MODEL_ERROR.
    m11 and m22 hold the rigid mass too, so their factor scales only the added part."""
    scale: dict[str, float] = {}
    for name in ("m11", "m22"):
        total = getattr(vehicle, name)
        added = (total - vehicle.mass) * rng.uniform(1 - MODEL_ERROR, 1 + MODEL_ERROR)
        scale[name] = (vehicle.mass + added) / total
    scale["Iz_added"] = rng.uniform(1 - MODEL_ERROR, 1 + MODEL_ERROR)
    for name in _DAMPING_FIELDS:
        scale[name] = rng.uniform(1 - MODEL_ERROR, 1 + MODEL_ERROR)
    return {name: round(value, 6) for name, value in scale.items()}


def _current(rng: np.random.Generator, vehicle: VehicleParams) -> list[float]:
    from auvmpc.scenario.sanity import largest_surge_thrust

    surge = float(vehicle.T[PLANAR_FORCE.index("X")] @ largest_surge_thrust(vehicle))
    magnitude = CURRENT_SHARE * surge * rng.uniform(0.0, 1.0)
    direction = rng.uniform(0.0, 2.0 * math.pi)
    return [round(magnitude * math.cos(direction), 4), round(magnitude * math.sin(direction), 4)]


def _rotate(points: np.ndarray, angle: float, origin: np.ndarray) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    return origin + points @ np.array([[c, s], [-s, c]])


def _common(rng: np.random.Generator, index: int, kind: str) -> tuple[VehicleParams, dict]:
    vehicle = _light_yaw_vehicle(rng, name=f"{kind}-{index}")
    case: dict[str, Any] = {
        "name": f"{kind}-{index}",
        "vehicle": vehicle.model_dump(mode="json", exclude_none=True),
        "plant": {"scale": _model_error(rng, vehicle)},
        "disturbance": {"current_force_world": _current(rng, vehicle)},
        "sensing": {"std": list(SENSOR_STD)},
        "controller": {"vehicle_radius": vehicle_radius(vehicle)},
        "seed": int(rng.integers(0, 2**31)),
    }
    return vehicle, case


def hard_survey_case(rng: np.random.Generator, index: int = 0) -> dict[str, Any]:
    """A lawnmower survey with 90-degree corners and discs on the path (module docstring)."""
    vehicle, case = _common(rng, index, "hard-survey")
    leg = rng.uniform(*LEG_LENGTH_M)
    spacing = rng.uniform(0.25, 0.5) * leg
    legs = int(rng.integers(2, 4))  # long legs: 2 or 3, so 1 or 2 U-turns of two corners
    local = [[0.0, 0.0]]
    for i in range(legs):
        x_end = leg if i % 2 == 0 else 0.0
        local.append([x_end, i * spacing])
        if i < legs - 1:
            local.append([x_end, (i + 1) * spacing])
    heading = rng.uniform(-math.pi, math.pi)
    origin = np.zeros(2)
    points = _rotate(np.asarray(local), heading, origin)
    speed = rng.uniform(*SPEED_M_PER_S)
    length = float(np.sum(np.hypot(*np.diff(points, axis=0).T)))
    radius = vehicle_radius(vehicle)
    obstacles = []
    for i in range(int(rng.integers(1, 3))):
        # On long leg i (they alternate direction), between 35 % and 65 % of its length,
        # within a third of its radius of the line: the vehicle must go round it.
        start, end = np.asarray(local[2 * i]), np.asarray(local[2 * i + 1])
        along = start + rng.uniform(0.35, 0.65) * (end - start)
        disc = rng.uniform(0.3, 1.0) * max(1.0, radius / _REFERENCE_RADIUS_M) ** 0.5
        offset = rng.uniform(-1.0, 1.0) * disc / 3.0
        center = _rotate((along + [0.0, offset])[None, :], heading, origin)[0]
        obstacles.append({"center": [round(float(c), 4) for c in center], "radius": round(disc, 3)})
    case.update(
        duration=math.ceil(length / speed + _SETTLE_S),
        reference={
            "type": "waypoints",
            "points": [[round(float(x), 4), round(float(y), 4)] for x, y in points],
            "speed": round(speed, 4),
            # a turn the vehicle's size allows: 1 m for the small ones, 1.5 footprints above
            "corner_radius": round(max(1.0, 1.5 * radius), 3),
        },
        initial_state=[
            round(float(rng.uniform(-0.5, 0.5) * radius), 4),
            round(float(rng.uniform(-0.5, 0.5) * radius), 4),
            round(heading + float(rng.uniform(-0.3, 0.3)), 4),
            0.0,
            0.0,
            0.0,
        ],
        obstacles=obstacles,
    )
    return case


def loop_case(rng: np.random.Generator, index: int = 0) -> dict[str, Any]:
    """A circle or a figure-eight, same vehicles and disturbances, no obstacles."""
    vehicle, case = _common(rng, index, "loop")
    scale = max(1.0, _size_scale(vehicle))
    speed = rng.uniform(*SPEED_M_PER_S)
    size = rng.uniform(4.0, 8.0) * scale
    if rng.uniform() < 0.5:
        reference = {"type": "circle", "center": [0, 0], "radius": round(size, 4),
                     "speed": round(speed, 4)}  # fmt: skip
        initial = [size, 0.0, math.pi / 2]
        length = 2 * math.pi * size
    else:
        period = 4.0 * 2.0 * math.pi * size / 3.0 / speed  # about the lemniscate's length
        reference = {"type": "figure-eight", "center": [0, 0], "size": round(size, 4),
                     "period": round(period, 4)}  # fmt: skip
        initial = [0.0, 0.0, math.pi / 4]
        length = speed * period
    case.update(
        duration=math.ceil(length / speed),
        reference=reference,
        # [x, y, psi] on the path, at rest
        initial_state=[round(float(v), 4) for v in initial] + [0.0] * HORIZONTAL_VELOCITY.size,
    )
    return case


CASE_KINDS = {"hard-survey": hard_survey_case, "loops": loop_case}


def make_case(kind: str, seed: int, index: int) -> dict[str, Any]:
    """Case ``index`` of a sweep of ``kind`` with master ``seed``: its own generator, a child
    of ``SeedSequence(seed)`` (the same case whatever else is drawn, on any worker)."""
    rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(index,)))
    return CASE_KINDS[kind](rng, index)
