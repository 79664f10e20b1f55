"""The closed loop: sample, control, hold, integrate, record."""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence

import numpy as np

from auvmpc.controllers.base import Controller, ControlResult, Observation
from auvmpc.environment.disturbances import SensorNoise, WorldDisturbance
from auvmpc.environment.obstacle_sensor import ObstaclePerception
from auvmpc.environment.obstacles import ObstacleConfig, clearance, visible_obstacles
from auvmpc.references import Reference
from auvmpc.sim.log import BACKOFF_NAMES, ESTIMATE_NAMES, SimLog
from auvmpc.sim.plant import PlantStepper, plant_step
from auvmpc.vehicle import VehicleParams

__all__ = ["closed_loop", "plant_step", "timed_command"]


def timed_command(
    controller: Controller, observation: Observation, size: int, who: str = "controller"
) -> tuple[ControlResult, np.ndarray, float]:
    """``(result, thrust, solve ms)`` of one controller call; an invalid command (wrong size
    or not finite) raises RuntimeError naming ``who`` and the sample."""
    started = time.perf_counter()
    result = controller.compute(observation)
    solve_ms = 1e3 * (time.perf_counter() - started)
    thrust = np.asarray(result.thrust, dtype=float)
    if thrust.shape != (size,) or not np.all(np.isfinite(thrust)):
        raise RuntimeError(f"{who} returned an invalid command at k={observation.k}: {thrust!r}")
    return result, thrust, solve_ms


def closed_loop(
    plant: VehicleParams,
    controller: Controller,
    reference: Reference,
    *,
    duration: float,
    initial_state: Sequence[float],
    disturbance: WorldDisturbance,
    sensor: SensorNoise,
    obstacles: Sequence[ObstacleConfig] = (),
    perception: ObstaclePerception | None = None,
    vehicle_radius: float = 0.0,
    max_plant_step: float = 0.05,
    initial_thrust: np.ndarray | None = None,
    on_step: Callable[[int, int], None] | None = None,
) -> SimLog:
    """Run ``controller`` against ``plant`` for ``duration`` seconds.

    The controller sees the (noisy) measured state every ``controller.sample_time``;
    its command is applied unaltered and held until the next sample, so the log
    shows the controller's mistakes rather than hiding them. The plant is
    integrated with RK4 at steps no longer than ``max_plant_step`` (sim/plant.py).
    The controller knows the existing ``obstacles`` exactly, unless ``perception`` (a
    sensor and its trackers over the same obstacles) says what it perceives of them.
    """
    sample_time = controller.sample_time
    steps = int(round(duration / sample_time))
    substeps = max(1, math.ceil(sample_time / max_plant_step - 1e-9))
    plant_sample = PlantStepper(plant, sample_time, substeps)
    n_thrusters = plant.n_thrusters
    log = SimLog.allocate(steps, n_thrusters, sample_time)
    previous = (
        np.zeros(n_thrusters) if initial_thrust is None else np.asarray(initial_thrust, float)
    )
    log.initial_thrust = previous.copy()

    state = np.asarray(initial_state, dtype=float).copy()
    controller.reset(state.copy(), previous.copy())
    preview_offsets = sample_time * np.arange(controller.preview_steps + 1)
    for k in range(steps + 1):
        t = log.t[k]
        log.state[k] = state
        log.reference[k] = reference.state(t)
        log.disturbance_world[k] = disturbance.force_world(t)
        log.clearance_m[k] = clearance(state[:2], t, obstacles, vehicle_radius)
        if k == steps:
            break
        observation = Observation(
            k=k,
            t=t,
            state=sensor.measure(state),
            reference=reference.states(t + preview_offsets),
            obstacles=visible_obstacles(obstacles, t)
            if perception is None
            else perception.observe(t, state[:2]),
        )
        result, thrust, log.solve_ms[k] = timed_command(controller, observation, n_thrusters)
        log.thrust[k] = thrust
        log.status[k] = str(result.status)
        log.disturbance_estimate[k] = [result.info.get(name, 0.0) for name in ESTIMATE_NAMES]
        log.backoff[k] = [result.info.get(name, 0.0) for name in BACKOFF_NAMES]
        state = plant_sample(state, thrust, t, disturbance)
        disturbance.advance()
        if on_step is not None:
            on_step(k + 1, steps)
    return log
