"""A vehicle's actuators in input order: names, hard limits and the force they make."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from functools import cached_property
from typing import Any

import casadi as ca
import numpy as np

from auvmpc.models.actuators.base import WRENCH, Actuator, ActuatorLimits
from auvmpc.models.layout import Layout

__all__ = ["ActuatorSet"]

# A force below this (N) is none: round-off of a wrench that should vanish.
_NO_FORCE_N = 1e-9


@dataclass(frozen=True, eq=False)
class ActuatorSet:
    """The actuators whose commands are a model's input vector, in that order."""

    actuators: tuple[Actuator, ...]

    def __add__(self, other: ActuatorSet) -> ActuatorSet:
        """This set's inputs, then ``other``'s (a 6-DOF vehicle's horizontal and vertical
        thrusters)."""
        return ActuatorSet(self.actuators + other.actuators)

    @property
    def size(self) -> int:
        return len(self.actuators)

    @cached_property
    def layout(self) -> Layout:
        """The inputs' names, in order."""
        return Layout(names=tuple(actuator.name for actuator in self.actuators))

    @cached_property
    def units(self) -> tuple[str, ...]:
        """Each input's unit (``Actuator.unit``; "" for a kind that does not say)."""
        return tuple(getattr(actuator, "unit", "") for actuator in self.actuators)

    @cached_property
    def jams(self) -> np.ndarray:
        """(n,) bool: whether each input can jam at a command and keep acting there
        (``Actuator.jams``; False for a kind that does not say)."""
        jams = np.array([bool(getattr(actuator, "jams", False)) for actuator in self.actuators])
        jams.setflags(write=False)
        return jams

    @cached_property
    def limits(self) -> ActuatorLimits:
        """Per-input command box and rate."""
        return ActuatorLimits(*(self._per_input(part) for part in ("lower", "upper", "rate")))

    def _per_input(self, member: str) -> np.ndarray:
        values = np.array([getattr(actuator, member) for actuator in self.actuators], dtype=float)
        values.setflags(write=False)
        return values

    @property
    def linear(self) -> bool:
        return all(actuator.linear for actuator in self.actuators)

    def allocation(self, rows: Sequence[str] = WRENCH.names) -> np.ndarray:
        """(len(rows), n): the wrench rows ``rows`` per unit command, ``tau = A @ u``; only
        for a set of linear actuators. Made once per row set (read-only)."""
        matrix = self._allocations.get(tuple(rows))
        if matrix is None:
            matrix = self._allocations[tuple(rows)] = self._allocation(rows)
        return matrix

    def _allocation(self, rows: Sequence[str]) -> np.ndarray:
        if not self.linear:
            nonlinear = [a.name for a in self.actuators if not a.linear]
            raise ValueError(f"actuators {nonlinear} are not linear in their commands")
        index = [WRENCH.index(name) for name in rows]
        matrix = np.array([actuator.column[index] for actuator in self.actuators], dtype=float).T
        matrix.setflags(write=False)
        return matrix

    def force(self, nu_r: Any, commands: Any, rows: Sequence[str] = WRENCH.names,
              effectiveness: Any = None) -> Any:  # fmt: skip
        """The wrench rows ``rows`` the commands make at relative velocity ``nu_r`` (6,),
        each actuator's wrench scaled by its ``effectiveness`` (n,; None: all healthy). NumPy
        in, NumPy out; CasADi in, CasADi out."""
        symbolic = any(isinstance(v, ca.SX | ca.MX) for v in (nu_r, commands, effectiveness))
        if self.linear:  # A @ (e * u): the wrench is linear in the command
            matrix = self.allocation(rows)
            scaled = commands if effectiveness is None else commands * effectiveness
            if symbolic:
                return ca.mtimes(ca.DM(matrix), scaled)
            return matrix @ np.asarray(scaled, dtype=float)
        index = [WRENCH.index(name) for name in rows]
        shares = [a.wrench(nu_r, commands[i]) for i, a in enumerate(self.actuators)]
        if effectiveness is not None:
            shares = [share * effectiveness[i] for i, share in enumerate(shares)]
        if symbolic:
            total = sum(shares[1:], shares[0])
            return ca.vertcat(*(total[i] for i in index))
        return np.sum(shares, axis=0)[index]

    @cached_property
    def pushes_sideways(self) -> bool:
        """Whether some command makes a sway force with the vehicle at rest (a thruster set
        does; a propeller and fins, whose forces need the flow, do not): whether the vehicle
        can hold a heading off its track without crabbing."""
        at_rest = np.zeros(WRENCH.size)  # nu_r, in the wrench's order
        sway = WRENCH.index("Y")
        for command in (self.limits.lower, self.limits.upper):
            full = np.broadcast_to(command, (self.size,)).astype(float)
            for i in range(self.size):
                alone = np.where(np.arange(self.size) == i, full, 0.0)
                if abs(float(self.force(at_rest, alone)[sway])) > _NO_FORCE_N:
                    return True
        return False

    @cached_property
    def _allocations(self) -> dict[tuple[str, ...], np.ndarray]:
        """:meth:`allocation` per row set (a model asks at every evaluation)."""
        return {}
