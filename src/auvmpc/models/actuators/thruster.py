"""A fixed thruster: a force along a fixed body direction, proportional to its command.

Its wrench per newton of thrust is ``[d; r x d]`` (Fossen 2021, eq. 11.2; six-dof.md) for a
thruster at ``r`` pushing along the unit direction ``d``; in the horizontal plane that is the
3-DOF allocation column ``[cos a, sin a, x sin a - y cos a]`` (interfaces.md).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property
from typing import Any

import numpy as np

__all__ = ["FixedThruster", "planar_direction", "thrust_column"]


def thrust_column(position, direction) -> np.ndarray:
    """(6,) ``[d; r x d]``: the wrench of 1 N along the unit ``direction`` at ``position``."""
    direction = np.asarray(direction, dtype=float)
    return np.concatenate([direction, np.cross(np.asarray(position, dtype=float), direction)])


def planar_direction(angle_deg: float) -> tuple[float, float, float]:
    """The unit direction at ``angle_deg`` from +x towards +y in the horizontal plane."""
    angle = math.radians(angle_deg)
    return (math.cos(angle), math.sin(angle), 0.0)


@dataclass(frozen=True)
class FixedThruster:
    """A thruster at ``position`` (m, body axes, z down) pushing along the unit ``direction``;
    its command is the thrust (N)."""

    name: str
    position: tuple[float, float, float]
    direction: tuple[float, float, float]  # unit length (the caller normalises)
    lower: float  # N
    upper: float  # N
    rate: float  # N/s

    linear = True
    unit = "N"  # its command's unit (plots, docs)
    jams = False  # a failed thruster stops or weakens (a loss)

    @classmethod
    def planar(cls, name: str, position: tuple[float, float], angle_deg: float,
               **limits: float) -> FixedThruster:  # fmt: skip
        """A horizontal thruster at ``position`` (x forward, y starboard) pushing at
        ``angle_deg`` from +x towards +y (a vehicle file's ``thrusters`` entry)."""
        return cls(name, (*position, 0.0), planar_direction(angle_deg), **limits)

    @cached_property
    def column(self) -> np.ndarray:
        """(6,) ``[d; r x d]``, the wrench per newton."""
        column = thrust_column(self.position, self.direction)
        column.setflags(write=False)
        return column

    def wrench(self, nu_r: Any, command: Any) -> Any:
        return self.column * command
