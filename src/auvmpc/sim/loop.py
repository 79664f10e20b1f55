"""The closed loop: sample, control, hold, integrate, record.

One loop for every plant kind: it is generic over a plant (sim/plant.py: one held sample at a
time, in its environment), a sensor, a reference in the plant's state layout and a controller,
and writes the plant's kind of log (sim/log.py), whose columns the state layout names.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from typing import Protocol

import numpy as np

from auvmpc.controllers.base import Controller, ControlResult, Observation
from auvmpc.environment.disturbances import WorldDisturbance
from auvmpc.environment.obstacle_sensor import ObstaclePerception
from auvmpc.environment.obstacles import ObstacleConfig, clearance, visible_obstacles
from auvmpc.models.vehicle import VehicleParams
from auvmpc.sim.log import BACKOFF_NAMES, ESTIMATE_NAMES, SimLog
from auvmpc.sim.plant import HorizontalPlant, Plant, plant_step

__all__ = ["Sensor", "StateReference", "closed_loop", "plant_step", "timed_command"]


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


class Sensor(Protocol):
    """What the controller is shown of the true state."""

    def measure(self, true_state: np.ndarray, t: float) -> np.ndarray: ...


class StateReference(Protocol):
    """The reference in the plant's state layout, vectorised over time."""

    def states(self, t: np.ndarray) -> np.ndarray: ...


def closed_loop(
    plant: Plant | VehicleParams,
    controller: Controller,
    reference: StateReference,
    *,
    duration: float,
    initial_state: Sequence[float],
    sensor: Sensor,
    disturbance: WorldDisturbance | None = None,
    obstacles: Sequence[ObstacleConfig] = (),
    perception: ObstaclePerception | None = None,
    vehicle_radius: float = 0.0,
    max_plant_step: float = 0.05,
    initial_thrust: np.ndarray | None = None,
    on_step: Callable[[int, int], None] | None = None,
) -> SimLog:
    """Run ``controller`` against ``plant`` for ``duration`` seconds; the log is the plant's
    kind (``plant.log_type``: a horizontal :class:`SimLog`, a depth :class:`DepthLog`).

    The controller sees the sensor's measurement every ``controller.sample_time``;
    its command is applied unaltered and held until the next sample, so the log
    shows the controller's mistakes rather than hiding them. ``plant`` integrates the sample
    (sim/plant.py); a ``VehicleParams`` is the horizontal plant under ``disturbance``,
    integrated with RK4 at steps no longer than ``max_plant_step``.
    The controller knows the existing ``obstacles`` exactly, unless ``perception`` (a
    sensor and its trackers over the same obstacles) says what it perceives of them.
    """
    sample_time = controller.sample_time
    if isinstance(plant, VehicleParams):
        if disturbance is None:
            raise ValueError("closed_loop: a VehicleParams plant needs its disturbance")
        plant = HorizontalPlant(plant, disturbance, sample_time, max_plant_step)
    if plant.sample_time != sample_time:
        raise ValueError(
            f"closed_loop: the plant steps {plant.sample_time} s, the controller samples "
            f"every {sample_time} s"
        )
    steps = int(round(duration / sample_time))
    n_thrusters = plant.n_thrusters
    log = plant.log_type.allocate(steps, n_thrusters, sample_time)
    position = log.layout.position if obstacles or perception is not None else None
    previous = (
        np.zeros(n_thrusters) if initial_thrust is None else np.asarray(initial_thrust, float)
    )
    log.initial_thrust = previous.copy()

    state = np.asarray(initial_state, dtype=float).copy()
    controller.reset(state.copy(), previous.copy())
    preview_offsets = sample_time * np.arange(controller.preview_steps + 1)
    for k in range(steps + 1):
        t = log.t[k]
        preview = reference.states(t + preview_offsets)  # its first row is the reference at t
        log.state[k] = state
        log.reference[k] = preview[0]
        log.disturbance_world[k] = plant.external_force(t, state)
        if position is not None:
            log.clearance_m[k] = clearance(state[position], t, obstacles, vehicle_radius)
        # Measured on the last row too: what the controller would have seen (a depth log shows it).
        log.measured[k] = measured = sensor.measure(state, t)
        if k == steps:
            break
        observation = Observation(
            k=k,
            t=t,
            state=measured,
            reference=preview,
            obstacles=visible_obstacles(obstacles, t)
            if perception is None
            else perception.observe(t, state[position]),
        )
        result, thrust, log.solve_ms[k] = timed_command(controller, observation, n_thrusters)
        log.thrust[k] = thrust
        log.status[k] = str(result.status)
        log.disturbance_estimate[k] = [result.info.get(name, 0.0) for name in ESTIMATE_NAMES]
        log.backoff[k] = [result.info.get(name, 0.0) for name in BACKOFF_NAMES]
        state = plant.step(state, thrust, t)
        if on_step is not None:
            on_step(k + 1, steps)
    return log
