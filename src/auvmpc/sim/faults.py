"""A plant whose actuators fail as the scenario's faults say (scenario/faults.py)."""

from __future__ import annotations

import numpy as np

from auvmpc.scenario.faults import FaultSchedule
from auvmpc.sim.plant import Plant

__all__ = ["FaultyPlant"]


class FaultyPlant:
    """``plant`` whose actuators fail as ``schedule`` says: it is stepped with the delivered
    thrust (the log keeps the commanded one)."""

    def __init__(self, plant: Plant, schedule: FaultSchedule) -> None:
        self.plant = plant
        self.schedule = schedule
        self.sample_time = plant.sample_time
        self.log_format = plant.log_format
        self.inputs = plant.inputs

    def environment(self, t: float, state: np.ndarray) -> np.ndarray:
        return self.plant.environment(t, state)

    def step(self, state: np.ndarray, thrust: np.ndarray, t0: float) -> np.ndarray:
        return self.plant.step(state, self.schedule.delivered(thrust, t0), t0)
