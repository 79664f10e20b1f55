"""Actuators: what turns a vehicle's commands into forces, one kind per module.

An actuator turns its command (in its own units) into a generalised force on the body, given
the body's velocity relative to the water ``nu_r``: ``wrench(nu_r, command)`` in the 6-DOF
body frame ``[X, Y, Z, K, M, N]`` (:data:`WRENCH`; Fossen 2021, ch. 2: x forward, y starboard,
z down). It carries its own hard limits (command box and rate). An :class:`ActuatorSet` is a
vehicle's inputs in order: their names (the input layout), limits, and the force they make,
each scaled by a runtime ``effectiveness`` (1 healthy, 0 dead). The 3-DOF model reads the
wrench's ``X, Y, N`` rows, so it is a reduction of the same description.

Kinds: :class:`FixedThruster` (force along a fixed direction, linear in the command, N),
:class:`Propeller` (thrust and torque from the shaft speed, the n|n| law, rpm) and
:class:`ControlSurface` (a rudder or stern planes: lift and drag from the flow past them and
their angle, deg). A new kind is one module with a class that has the :class:`Actuator`
members (docs/extending.md).
"""

from auvmpc.models.actuators.base import WRENCH, Actuator, ActuatorLimits
from auvmpc.models.actuators.control_surface import ControlSurface
from auvmpc.models.actuators.propeller import Propeller
from auvmpc.models.actuators.set import ActuatorSet
from auvmpc.models.actuators.thruster import FixedThruster

__all__ = [
    "WRENCH",
    "Actuator",
    "ActuatorLimits",
    "ActuatorSet",
    "ControlSurface",
    "FixedThruster",
    "Propeller",
]
