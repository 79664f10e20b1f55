"""The vehicle file's ``actuators:`` entries: one validated model per actuator kind.

Each entry is the kind's dataclass written as YAML, with ``kind`` naming it::

    actuators:
      - {kind: propeller, name: propeller_rpm, position: [-0.7, 0, 0], direction: [1, 0, 0],
         diameter: 0.14, ...}
      - {kind: control_surface, name: rudder_deg, ...}

:data:`ACTUATOR_KINDS` is the registry: a kind's name and its dataclass. The entry's fields
are the dataclass's (same names, types and defaults), so a kind is written once; its own
``__post_init__`` checks the values, and a bad one is refused in one line naming the field
and the value (``actuators.0.propeller.propeller_rpm.diameter: -0.14, must be > 0``). A kind
of your own is one module with its dataclass and one line here (docs/extending.md).
"""

from __future__ import annotations

import dataclasses
from typing import Annotated, Any, Literal, Union, get_type_hints

from pydantic import Field, create_model, model_validator

from auvmpc.config import StrictModel
from auvmpc.models.actuators.base import Actuator
from auvmpc.models.actuators.control_surface import ControlSurface
from auvmpc.models.actuators.propeller import Propeller

__all__ = ["ACTUATOR_KINDS", "ActuatorEntry", "ActuatorEntryBase"]

# kind (the entry's ``kind``) -> the actuator dataclass its other fields build.
ACTUATOR_KINDS: dict[str, type] = {
    "propeller": Propeller,
    "control_surface": ControlSurface,
}


class ActuatorEntryBase(StrictModel):
    """What every entry has beyond its kind's fields: the actuator it describes."""

    kind: str

    @property
    def actuator_type(self) -> type:
        return ACTUATOR_KINDS[self.kind]

    def build(self) -> Actuator:
        """The actuator (its dataclass) with this entry's values."""
        return self.actuator_type(**{
            field.name: getattr(self, field.name)
            for field in dataclasses.fields(self.actuator_type)
        })  # fmt: skip

    @model_validator(mode="after")
    def _buildable(self) -> ActuatorEntryBase:
        self.build()  # the kind's own checks (FieldError naming the field and value)
        return self


def _entry_model(kind: str, actuator: type) -> type[ActuatorEntryBase]:
    """The entry of ``kind``: ``kind`` plus the fields of the ``actuator`` dataclass."""
    hints = get_type_hints(actuator)
    fields: dict[str, Any] = {
        field.name: (hints[field.name], Field(
            ... if field.default is dataclasses.MISSING else field.default,
            description=field.metadata.get("description", ""),
        ))
        for field in dataclasses.fields(actuator)
    }  # fmt: skip
    return create_model(
        f"{actuator.__name__}Entry",
        __base__=ActuatorEntryBase,
        __doc__=f"An actuators: entry of kind {kind} ({actuator.__name__}).",
        kind=(Literal[kind], Field(description="the actuator kind")),
        **fields,
    )


# One entry of a vehicle file's ``actuators:`` list, told apart by its ``kind``.
ActuatorEntry = Annotated[
    Union[tuple(_entry_model(kind, cls) for kind, cls in ACTUATOR_KINDS.items())],  # noqa: UP007
    Field(discriminator="kind"),
]
