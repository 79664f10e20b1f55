"""What every actuator kind has (:class:`Actuator`) and the hard limits of a set of them."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from types import SimpleNamespace
from typing import Any, Protocol

import casadi as ca
import numpy as np

from auvmpc.errors import FieldError
from auvmpc.models.layout import Layout

__all__ = [
    "WRENCH",
    "Actuator",
    "ActuatorLimits",
    "check_fields",
    "described",
    "cross",
    "elementwise",
    "wrench_of",
]

# The generalised force on the body, Fossen's tau: force X, Y, Z (N) and moment K, M, N (N m)
# about the body origin, body axes x forward, y starboard, z down.
WRENCH = Layout(names=("X", "Y", "Z", "K", "M", "N"))


# NumPy's element-wise functions under CasADi's names, so that a kind's physics reads the same
# for numbers and for symbols (``elementwise``).
_NUMPY = SimpleNamespace(fabs=np.abs, fmin=np.minimum, fmax=np.maximum, sign=np.sign)


def elementwise(*values: Any) -> Any:
    """CasADi (``ca``) if any value, or any entry of a tuple or list of them, is a CasADi
    expression, else NumPy's ``fabs``, ``fmin``, ``fmax`` and ``sign``: a kind's physics
    written once (the 3-DOF model hands a tuple of numbers and symbols as ``nu_r``)."""
    for value in values:
        entries = value if isinstance(value, tuple | list) else (value,)
        if any(isinstance(entry, ca.SX | ca.MX) for entry in entries):
            return ca
    return _NUMPY


def cross(a: Any, b: Any) -> tuple[Any, Any, Any]:
    """``a x b`` of two three-entry sequences of numbers, arrays or symbols."""
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def wrench_of(force: Any, position: Any, maths: Any, moment: Any = (0.0, 0.0, 0.0)) -> Any:
    """(6,) ``[F; r x F + moment]``: ``force`` (three entries) acting at ``position`` plus a
    free ``moment``; a CasADi column if ``maths`` is CasADi, else a NumPy array (``(6, k)``
    for entries of k states)."""
    arm = cross(position, force)
    entries = [*force, *(arm[i] + moment[i] for i in range(3))]
    if maths is ca:
        return ca.vertcat(*entries)
    return np.array(np.broadcast_arrays(*entries), dtype=float)


def described(meaning: str, default: Any = dataclasses.MISSING) -> Any:
    """A kind's dataclass field with its ``meaning`` and unit: what a vehicle file's
    ``actuators:`` entry says of it (models/actuators/entries.py, the scenario reference)."""
    return dataclasses.field(default=default, metadata={"description": meaning})


def check_fields(actuator: Any, positive: tuple[str, ...], unit: str) -> None:
    """Refuse an actuator, naming the field and its value, whose ``positive`` fields are not
    > 0, whose command box is upside down or whose ``unit`` direction is not of unit length."""
    for field in positive:
        value = getattr(actuator, field)
        if not value > 0.0:
            raise FieldError(f"{actuator.name}.{field}", value, f"{value}, must be > 0")
    if not actuator.lower <= actuator.upper:
        raise FieldError(f"{actuator.name}.lower", actuator.lower,
                         f"{actuator.lower}, above upper {actuator.upper}")  # fmt: skip
    direction = getattr(actuator, unit)
    if not math.isclose(math.hypot(*direction), 1.0, rel_tol=1e-9):
        raise FieldError(
            f"{actuator.name}.{unit}", direction, f"{direction}, must be a unit vector"
        )


class Actuator(Protocol):
    """One actuator: its input's name, its hard limits and the force it makes."""

    name: str  # the input's name (log.csv column, Session.input_names)
    lower: float  # command box, the actuator's own units
    upper: float
    rate: float  # largest command change per second
    unit: str  # the command's unit, e.g. "N", "rpm", "deg" (plot labels; optional: "")
    # Whether it can jam at a command and keep acting there, as a fin's lift does: the fault
    # detector's sequential stuck test watches it (optional: False).
    jams: bool

    @property
    def linear(self) -> bool:
        """Whether the wrench is ``column * command`` whatever ``nu_r`` (then the set has an
        allocation matrix, which linear-model controllers need)."""
        ...

    @property
    def column(self) -> np.ndarray:
        """(6,) wrench per unit command, for a linear actuator."""
        ...

    def wrench(self, nu_r: Any, command: Any) -> Any:
        """(6,) ``[X, Y, Z, K, M, N]`` at relative velocity ``nu_r`` (6,) for ``command``:
        NumPy in, NumPy out; CasADi in, CasADi out."""
        ...


@dataclass(frozen=True)
class ActuatorLimits:
    """Hard limits of a set of actuators: command box and rate, per actuator."""

    lower: float | np.ndarray  # in the actuators' own units (N for a thruster)
    upper: float | np.ndarray
    rate: float | np.ndarray  # per second

    def box(self, previous: np.ndarray, sample_time: float) -> tuple[np.ndarray, np.ndarray]:
        """Per-actuator [lower, upper] reachable in one sample under both hard limits."""
        max_step = self.rate * sample_time
        lower = np.maximum(self.lower, previous - max_step)
        upper = np.minimum(self.upper, previous + max_step)
        # A previous command outside the force limits (never ours) leaves an empty box:
        # the rate limit wins, moving towards the force box as fast as it allows.
        empty = lower > upper
        if np.any(empty):
            towards = np.clip(
                np.clip(previous, self.lower, self.upper), previous - max_step, previous + max_step
            )
            lower = np.where(empty, towards, lower)
            upper = np.where(empty, towards, upper)
        return lower, upper

    def project(
        self, command: np.ndarray, previous: np.ndarray, sample_time: float
    ) -> tuple[np.ndarray, bool]:
        """Clip a command into the hard-limit box; also say whether it had to move."""
        lower, upper = self.box(previous, sample_time)
        clipped = np.minimum(np.maximum(command, lower), upper)  # np.clip, at half the cost
        return clipped, bool(np.any(np.abs(clipped - command) > 1e-9))
