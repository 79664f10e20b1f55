"""The remus100 preset flown open loop on the 6-DOF plant: steady speeds, turning circles,
a stern-plane step, and the level trim it would need with Prestero's measured buoyancy.

    python benchmarks/remus100_open_loop.py

Prints the numbers docs/remus100.md quotes ("Flown open loop"); tests/test_remus100.py
holds the preset to the published ones.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.optimize import fsolve

from auvmpc.models.six_dof import plant_step_length, six_dof_model
from auvmpc.models.vehicle import load_vehicle, vehicle_data
from auvmpc.sim.plant import SixDofPlant

SAMPLE_S = 0.5
PRESTERO_BUOYANCY_N = 308.0


def fly(plant: SixDofPlant, state: np.ndarray, command, seconds: float) -> np.ndarray:
    states = [state]
    for k in range(round(seconds / SAMPLE_S)):
        states.append(plant.step(states[-1], np.asarray(command, dtype=float), k * SAMPLE_S))
    return np.array(states)


def level_trim(data: dict, speed: float) -> tuple[float, float, float]:
    """Pitch (deg), stern planes (deg) and rpm for level straight flight at ``speed``."""
    model = six_dof_model(load_vehicle(data))

    def residual(unknowns):
        theta, w, planes, rpm = unknowns
        state = np.zeros(12)
        state[4], state[6], state[8] = theta, speed, w
        rates = np.asarray(model.derivative(state, [rpm, 0.0, planes], np.zeros(3), np.zeros(3)))
        rates = rates.ravel()
        return [rates[6], rates[8], rates[10], -math.sin(theta) * speed + math.cos(theta) * w]

    theta, _, planes, rpm = fsolve(residual, [0.0, 0.0, 0.0, 900.0])
    return math.degrees(theta), planes, rpm


def main() -> None:
    vehicle = load_vehicle("remus100")
    step = plant_step_length(vehicle, 0.05)
    plant = SixDofPlant(vehicle, None, SAMPLE_S, step)
    print(f"{'plant RK4 step (s)':50s} {step:.4f}")
    start = np.zeros(12)
    start[2], start[6] = 10.0, 1.5
    for rpm in (900.0, 1525.0):
        end = fly(plant, start, [rpm, 0.0, 0.0], 30.0)[-1]
        print(f"{f'steady surge at {rpm:.0f} rpm (m/s)':50s} {end[6]:.4f}")
    cruise = fly(plant, start, [900.0, 0.0, 0.0], 30.0)[-1]
    for rudder in (10.0, 20.0):
        end = fly(plant, cruise, [900.0, rudder, 0.0], 60.0)[-1]
        speed = math.hypot(end[6], end[7])
        diameter = 2.0 * speed / abs(end[11])
        print(f"{f'rudder +{rudder:.0f} deg at 900 rpm: yaw rate (rad/s), diameter (m)':50s} "
              f"{end[11]:.4f}, {diameter:.1f}")  # fmt: skip
    states = fly(plant, cruise, [900.0, 0.0, 5.0], 10.0)
    print(f"{'planes +5 deg: pitch after 2 s (deg), depth gain 10 s (m)':50s} "
          f"{math.degrees(states[4, 4]):.2f}, {states[-1, 2] - cruise[2]:.2f}")  # fmt: skip
    data, _ = vehicle_data("remus100")
    six = data["six_dof"]
    volume = PRESTERO_BUOYANCY_N / (six["water_density"] * six["gravity"])
    buoyant = {**data, "six_dof": {**six, "displaced_volume": volume}}
    for speed in (1.0, 1.5, 2.0):
        theta, planes, rpm = level_trim(buoyant, speed)
        print(f"{f'B = 308 N, level at {speed} m/s: pitch, planes (deg), rpm':50s} "
              f"{theta:.1f}, {planes:.1f}, {rpm:.0f}")  # fmt: skip


if __name__ == "__main__":
    main()
