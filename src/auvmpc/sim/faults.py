"""A run's actuator faults in time (the scenario's ``faults``, scenario/faults.py): what the
actuators deliver of each command, what the controller is told, and a plant stepped with
what is delivered.

Effectiveness is each actuator's share of its wrench (force and moment) that acts, never a
share of its command: a propeller at 0.5 makes half its thrust at any rpm (scaling its rpm
by 0.5 would make a quarter, thrust going with rpm squared). The plant scales each wrench
(``ActuatorSet.force``), as every controller's prediction does.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from typing import Protocol

import numpy as np

from auvmpc.errors import ConfigError
from auvmpc.models.actuators import ActuatorSet
from auvmpc.sim.plant import Plant

__all__ = ["Fault", "FaultSchedule", "FaultyPlant", "acting_sample"]

# A fault "at" a sample time acts on that sample: sample times are k * Te in floating point,
# so a time within this much before it counts as reached.
_TIME_ROUND_OFF_S = 1e-9


class Fault(Protocol):
    """One actuator's failure (what scenario/faults.py's ``ActuatorFault`` holds)."""

    actuator: str
    at: float
    effectiveness: float | None
    stuck_at: float | None
    declared: bool


def acting_sample(times: np.ndarray, at: float) -> int:
    """The first of the sample ``times`` a fault at ``at`` acts on (``len(times)``: none)."""
    return int(np.searchsorted(times, at - _TIME_ROUND_OFF_S, side="left"))


class FaultSchedule:
    """The faults of a run on the plant's ``inputs``, lasting ``duration`` s; a fault naming
    no input or an input that fails twice, stuck outside its limits, or at or after the
    run's end, is one ConfigError line naming it."""

    def __init__(self, faults: Sequence[Fault], inputs: ActuatorSet, duration: float) -> None:
        names = list(inputs.layout.names)
        limits = inputs.limits
        self._index: list[int] = []
        for i, fault in enumerate(faults):
            if fault.actuator not in names:
                raise ConfigError(
                    f"faults.{i}.actuator", fault.actuator, f"one of {', '.join(names)}"
                )
            index = names.index(fault.actuator)
            if index in self._index:
                raise ConfigError(
                    f"faults.{i}.actuator", fault.actuator, "fails twice: one fault per actuator"
                )
            low, high = float(limits.lower[index]), float(limits.upper[index])
            if fault.stuck_at is not None and not low <= fault.stuck_at <= high:
                raise ConfigError(
                    f"faults.{i}.stuck_at", fault.stuck_at,
                    f"outside {fault.actuator}'s limits [{low:g}, {high:g}]",
                )  # fmt: skip
            if fault.at >= duration - _TIME_ROUND_OFF_S:
                raise ConfigError(
                    f"faults.{i}.at", fault.at, f"at or after the run's end ({duration:g} s)"
                )
            self._index.append(index)
        self.faults = tuple(faults)
        self.n_inputs = len(names)

    def __bool__(self) -> bool:
        return bool(self.faults)

    def _acting(self, t: float, declared_only: bool = False) -> Iterator[tuple[Fault, int]]:
        for fault, index in zip(self.faults, self._index, strict=True):
            if t + _TIME_ROUND_OFF_S >= fault.at and (fault.declared or not declared_only):
                yield fault, index

    def delivered(self, command: np.ndarray, t: float) -> tuple[np.ndarray, np.ndarray | None]:
        """What the actuators follow of ``command`` over the sample from ``t`` (a stuck one
        its value), and each one's share of its wrench that acts then (None: all healthy)."""
        delivered = np.array(command, dtype=float)
        effectiveness = None
        for fault, index in self._acting(t):
            if fault.stuck_at is not None:
                delivered[index] = fault.stuck_at
            else:
                if effectiveness is None:
                    effectiveness = np.ones(self.n_inputs)
                effectiveness[index] = fault.effectiveness
        return delivered, effectiveness

    def declared(self, t: float) -> np.ndarray | None:
        """Each input's effectiveness as the mission has declared it by ``t`` (None: nothing
        declared yet, all healthy to the controller). A stuck actuator is declared as not
        acting, and its value told by :meth:`stuck`: a controller that reads only this
        leaves its fixed force to its disturbance estimate."""
        acting = list(self._acting(t, declared_only=True))
        if not acting:
            return None
        effectiveness = np.ones(self.n_inputs)
        for fault, index in acting:
            effectiveness[index] = 0.0 if fault.stuck_at is not None else fault.effectiveness
        return effectiveness

    def stuck(self, t: float) -> np.ndarray | None:
        """The value each input is declared stuck at by ``t``, NaN where it is free (None:
        none declared stuck yet): ``Observation.stuck_at``."""
        acting = [(f, i) for f, i in self._acting(t, declared_only=True) if f.stuck_at is not None]
        if not acting:
            return None
        values = np.full(self.n_inputs, np.nan)
        for fault, index in acting:
            values[index] = fault.stuck_at
        return values


class FaultyPlant:
    """``plant`` whose actuators fail as ``schedule`` says: it is stepped with what they
    follow and the share of their wrench that acts (the log keeps the commanded thrust)."""

    def __init__(self, plant: Plant, schedule: FaultSchedule) -> None:
        self.plant = plant
        self.schedule = schedule
        self.sample_time = plant.sample_time
        self.log_format = plant.log_format
        self.inputs = plant.inputs

    def environment(self, t: float, state: np.ndarray) -> np.ndarray:
        return self.plant.environment(t, state)

    def step(self, state: np.ndarray, thrust: np.ndarray, t0: float) -> np.ndarray:
        delivered, effectiveness = self.schedule.delivered(thrust, t0)
        return self.plant.step(state, delivered, t0, effectiveness)
