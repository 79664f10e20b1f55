"""An actuator kind of your own, in one file (docs/extending.md).

A thruster whose propeller pushes less in reverse than forward for the same command (a
T200 makes 51.5 N forward and 40.2 N in reverse at full command, Blue Robotics' published
curve): thrust = command for command >= 0, ``reverse_ratio * command`` below. Its force is
no longer linear in the command, so the set has no allocation matrix: controllers that
predict with the nonlinear model (``nmpc``) can use it, linear-model ones cannot.

    python examples/own_actuator.py     # prints the force of one command in NumPy and CasADi
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from auvmpc.models.actuators import ActuatorSet, FixedThruster


@dataclass(frozen=True)
class AsymmetricThruster:
    """A fixed thruster (``placement``: where it sits and which way it pushes) whose reverse
    thrust is ``reverse_ratio`` times the command."""

    placement: FixedThruster
    reverse_ratio: float  # reverse thrust per unit of negative command

    linear = False

    @property
    def name(self) -> str:
        return self.placement.name

    @property
    def lower(self) -> float:
        return self.placement.lower

    @property
    def upper(self) -> float:
        return self.placement.upper

    @property
    def rate(self) -> float:
        return self.placement.rate

    @property
    def column(self) -> np.ndarray:
        raise ValueError(f"{self.name}: reverse thrust differs, no single column")

    def wrench(self, nu_r, command):
        if isinstance(command, ca.SX | ca.MX):
            thrust = ca.fmax(command, 0) + self.reverse_ratio * ca.fmin(command, 0)
        else:
            thrust = max(command, 0.0) + self.reverse_ratio * min(command, 0.0)
        return self.placement.column * thrust


def asymmetric(actuators: ActuatorSet, reverse_ratio: float) -> ActuatorSet:
    """The same thrusters, each with this reverse ratio."""
    return ActuatorSet(tuple(AsymmetricThruster(a, reverse_ratio) for a in actuators.actuators))


if __name__ == "__main__":
    from auvmpc.models.vehicle import load_vehicle

    vehicle = load_vehicle("bluerov2-heavy")
    thrusters = asymmetric(vehicle.actuators, 40.2 / 51.5)
    command = np.array([10.0, -10.0, 10.0, -10.0])
    symbol = ca.SX.sym("F", thrusters.size)
    symbolic = ca.Function("tau", [symbol], [thrusters.force(None, symbol, ("X", "Y", "N"))])
    print("NumPy  [X, Y, N]:", thrusters.force(None, command, ("X", "Y", "N")))
    print("CasADi [X, Y, N]:", np.array(symbolic(command)).ravel())
