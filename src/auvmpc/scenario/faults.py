"""Actuator faults as scenario data (``faults:``): which input fails, when, and how.

:class:`ActuatorFault` is one fault as written; sim/faults.py's ``FaultSchedule`` holds a
run's faults on the plant's inputs, in time, and steps the plant with them. A fault acts in
the plant: from its time on, the actuator makes a share of its force and moment
(``effectiveness``: 0 dead, 0.5 half force at whatever command: a propeller at 0.5 makes
half the thrust of its rpm, not the thrust of half the rpm) or follows a fixed value
whatever it is commanded
(``stuck_at``, in the actuator's own unit: N for a thruster). The controller learns of it
only if the mission ``declared`` it (it is then told at that time, as a vehicle's health
monitor would tell it); otherwise the fault is a disturbance to it, as at sea.
"""

from __future__ import annotations

from typing import Annotated

from pydantic import Field, model_validator

from auvmpc.config import NonNegative, StrictModel
from auvmpc.errors import FieldError

__all__ = ["ActuatorFault"]


class ActuatorFault(StrictModel):
    """One actuator's failure during a run (module docstring)."""

    actuator: str = Field(
        description="the input that fails, by its name (a log.csv thrust column, e.g. F3); "
        "one fault per actuator"
    )
    at: NonNegative = Field(
        description="when it fails (s from the start, before the run's end; it acts from the "
        "first sample at or after this time, when the next command is applied)"
    )
    effectiveness: Annotated[float, Field(ge=0.0, le=1.0)] | None = Field(
        default=None,
        description="the share of its force and moment it makes from then on, at whatever "
        "command (0: dead, 0.5: half the force of its command)",
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
                "give exactly one of effectiveness (a share of the force) and stuck_at "
                "(a fixed value)",
            )
        return self
