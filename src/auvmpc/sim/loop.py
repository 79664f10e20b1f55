"""The closed loop: sample, control, hold, integrate, record.

One loop for every plant kind: a plain loop over a :class:`~auvmpc.sim.session.Session` (which
builds each observation, calls the controller and records the sample) with a built-in plant
(sim/plant.py: one held sample at a time, in its environment) and a sensor; the session's log
is the plant's kind (sim/log.py), whose columns the state layout names.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Protocol

import numpy as np

from auvmpc.controllers.base import Controller
from auvmpc.environment.disturbances import WorldDisturbance
from auvmpc.environment.obstacle_sensor import ObstaclePerception
from auvmpc.environment.obstacles import ObstacleConfig
from auvmpc.models.six_dof import PitchSingularity
from auvmpc.models.vehicle import VehicleParams
from auvmpc.sim.faults import FaultSchedule, FaultyPlant
from auvmpc.sim.log import SimLog
from auvmpc.sim.plant import HorizontalPlant, Plant, plant_step
from auvmpc.sim.session import Session, StateReference, Truth

__all__ = [
    "Sensor",
    "StateReference",
    "closed_loop",
    "plant_step",
    "run_session",
]


class Sensor(Protocol):
    """What the controller is shown of the true state."""

    def measure(self, true_state: np.ndarray, t: float) -> np.ndarray: ...


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
    """Run ``controller`` against ``plant`` for ``duration`` seconds; the log is in the
    plant's format (``plant.log_format``: a horizontal or a depth run's; a 6-DOF run's log
    needs its horizontal thruster count, so it goes through experiments/run.py's
    RunSession).

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
    session = Session(
        controller,
        reference,
        SimLog(plant.inputs.layout.names, sample_time, plant.log_format),
        int(round(duration / sample_time)),  # the run's commands
        initial_state=initial_state,
        initial_thrust=initial_thrust,
        obstacles=obstacles,
        perception=perception,
        vehicle_radius=vehicle_radius,
    )
    return run_session(session, plant, sensor, on_step)


# A state entry this large (m, m/s, rad, rad/s) is an integration that has blown up: no
# vehicle goes 1e9 m or m/s; stopping here, before it overflows to inf and NaN, keeps the
# controller from being handed it (it would fail on it and hide the cause).
DIVERGED_MAGNITUDE = 1e9


class PlantDiverged(ArithmeticError):
    """The plant's state after sample ``k - 1`` is not finite or beyond DIVERGED_MAGNITUDE,
    or the plant's step refused it (``what``: a 6-DOF pitch past its limit); the session
    holds samples ``0..k-1``."""

    def __init__(self, k: int, what: str = "its state became non-finite") -> None:
        super().__init__(f"the plant diverged at step {k}: {what}")
        self.k = k
        self.what = what


def run_session(
    session: Session,
    plant: Plant,
    sensor: Sensor,
    on_step: Callable[[int, int], None] | None = None,
    faults: FaultSchedule | None = None,
) -> SimLog:
    """Step ``session`` through its run against the built-in ``plant``: measure, step, hold
    the command over the sample; the session's log gets the plant's truth as well. A plant
    state that stops being finite raises :class:`PlantDiverged` before it reaches the
    controller or the log. ``faults``: the plant's actuators fail as they say (sim/faults.py),
    and the session is told of the declared ones from their time on (a stuck one's value
    too)."""
    if plant.sample_time != session.sample_time:
        raise ValueError(
            f"run_session: the plant steps {plant.sample_time} s, the controller samples "
            f"every {session.sample_time} s"
        )
    if faults:
        plant = FaultyPlant(plant, faults)
    steps, position, perception = session.steps, session.position, session.perception
    # The sample times k Te, each a product (never accumulated), as float64.
    times = session.sample_time * np.arange(steps + 1, dtype=float)
    state = session.initial_state.copy()
    for k in range(steps + 1):
        t = times[k]
        truth = Truth(state, plant.environment(t, state))
        # Measured on the last row too: what the controller would have seen (a depth log shows it).
        measured = sensor.measure(state, t)
        if k == steps:
            session.finish(t, measured, truth, trusted=True)
            break
        # The obstacle sensor looks from where the vehicle truly is.
        detections = None if perception is None else perception.observe(t, state[position])
        if faults:
            session.effectiveness = faults.declared(t)
            session.stuck_at = faults.stuck(t)
        result = session.step(t, measured, detections, truth, trusted=True)
        try:
            with np.errstate(over="ignore", invalid="ignore"):  # the state is judged below
                state = plant.step(state, result.u, t)
        except PitchSingularity as error:  # the plant's own guard: a 6-DOF pitch past 85 deg
            raise PlantDiverged(k + 1, str(error)) from error
        if not (np.abs(state) < DIVERGED_MAGNITUDE).all():  # also NaN
            raise PlantDiverged(k + 1)
        if on_step is not None:
            on_step(k + 1, steps)
    return session.log
