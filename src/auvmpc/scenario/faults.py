"""Actuator faults as scenario data (``faults:``): which input fails, when, and how.

:class:`ActuatorFault` is one fault as written; :class:`FaultSchedule` the run's faults
resolved on the plant's inputs, in time (sim/faults.py steps the plant with them). A fault
acts in the plant: from its time on, the actuator delivers a share of its command
(``effectiveness``: 0 dead, 0.5 half force) or a fixed value whatever it is commanded
(``stuck_at``, in the actuator's own unit: N for a thruster). The controller learns of it
only if the mission ``declared`` it (it is then told at that time, as a vehicle's health
monitor would tell it); otherwise the fault is a disturbance to it, as at sea.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from typing import Annotated

import numpy as np
from pydantic import Field, model_validator

from auvmpc.config import NonNegative, StrictModel
from auvmpc.errors import ConfigError, FieldError
from auvmpc.models.actuators import ActuatorSet

__all__ = ["ActuatorFault", "FaultSchedule"]

# A fault "at" a sample time acts on that sample: sample times are k * Te in floating point,
# so a time within this much before it counts as reached.
_TIME_ROUND_OFF_S = 1e-9


class ActuatorFault(StrictModel):
    """One actuator's failure during a run (module docstring)."""

    actuator: str = Field(
        description="the input that fails, by its name (a log.csv thrust column, e.g. F3)"
    )
    at: NonNegative = Field(
        description="when it fails (s from the start; it acts from the first sample at or "
        "after this time, when the next command is applied)"
    )
    effectiveness: Annotated[float, Field(ge=0.0, le=1.0)] | None = Field(
        default=None, description="the share of its command it delivers from then on (0: dead)"
    )
    stuck_at: float | None = Field(
        default=None,
        description="what it delivers from then on whatever it is commanded, in its own unit "
        "(N for a thruster); within its limits",
    )
    declared: bool = Field(
        default=False,
        description="the mission tells the controller at `at` (its prediction and allocation "
        "then use the actuator as it acts); false: the controller is not told",
    )

    @model_validator(mode="after")
    def _one_failure(self) -> ActuatorFault:
        given = [name for name in ("effectiveness", "stuck_at") if getattr(self, name) is not None]
        if len(given) != 1:
            raise FieldError(
                "effectiveness" if not given else given[1],
                None if not given else getattr(self, given[1]),
                "give exactly one of effectiveness (a share of the command) and stuck_at "
                "(a fixed value)",
            )
        return self

    @property
    def assumed_effectiveness(self) -> float:
        """What a controller told of the fault assumes of the actuator's command: its share, or
        none of it for a stuck actuator (whose fixed value the controller's disturbance
        estimate takes up)."""
        return 0.0 if self.effectiveness is None else self.effectiveness


class FaultSchedule:
    """The faults of a run on the plant's ``inputs``, in time; a fault naming no input, or
    stuck outside its input's limits, is one ConfigError line naming it."""

    def __init__(self, faults: Sequence[ActuatorFault], inputs: ActuatorSet) -> None:
        names = list(inputs.layout.names)
        limits = inputs.limits
        self._index = []
        for i, fault in enumerate(faults):
            if fault.actuator not in names:
                raise ConfigError(
                    f"faults[{i}].actuator", fault.actuator, f"one of {', '.join(names)}"
                )
            index = names.index(fault.actuator)
            low, high = float(limits.lower[index]), float(limits.upper[index])
            if fault.stuck_at is not None and not low <= fault.stuck_at <= high:
                raise ConfigError(
                    f"faults[{i}].stuck_at", fault.stuck_at,
                    f"outside {fault.actuator}'s limits [{low:g}, {high:g}]",
                )  # fmt: skip
            self._index.append(index)
        self.faults = tuple(faults)
        self.n_inputs = len(names)

    def __bool__(self) -> bool:
        return bool(self.faults)

    def _acting(self, t: float, declared_only: bool = False) -> Iterator[tuple[ActuatorFault, int]]:
        for fault, index in zip(self.faults, self._index, strict=True):
            if t + _TIME_ROUND_OFF_S >= fault.at and (fault.declared or not declared_only):
                yield fault, index

    def delivered(self, command: np.ndarray, t: float) -> np.ndarray:
        """What the actuators deliver of ``command`` over the sample from ``t``."""
        delivered = np.array(command, dtype=float)
        for fault, index in self._acting(t):
            if fault.stuck_at is not None:
                delivered[index] = fault.stuck_at
            else:
                delivered[index] *= fault.effectiveness
        return delivered

    def declared(self, t: float) -> np.ndarray | None:
        """Each input's effectiveness as the mission has declared it by ``t`` (None: nothing
        declared yet, all healthy to the controller)."""
        acting = list(self._acting(t, declared_only=True))
        if not acting:
            return None
        effectiveness = np.ones(self.n_inputs)
        for fault, index in acting:
            effectiveness[index] *= fault.assumed_effectiveness
        return effectiveness
