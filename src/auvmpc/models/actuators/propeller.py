"""A propeller: thrust and shaft torque from the shaft speed, commanded in rpm.

Open-water law (as in Fossen's MSS ``remus100.m``), with n the shaft speed
(rev/s, the command / 60), D the diameter and rho the water's density:

    T = rho D^4 K_T(J) n|n|,    Q = rho D^5 K_Q(J) n|n|,    J = V_a / (n D),  V_a = (1 - w) u_r

K_T and K_Q fall linearly with the advance ratio J while the shaft turns forward and keep their
bollard values K_T0, K_Q0 in reverse (MSS ``remus100.m``'s "linear approximations for positive
Ja values"). Multiplied out, the 1/n of J cancels and the law has no division:

    T = rho D^4 (K_T0 n|n| + K_T' (V_a / D) max(n, 0)),    likewise Q with K_Q0, K_Q'

(K_T' = dK_T/dJ; zero gives the pure n|n| law). u_r is the surge of the body through the
water and w the wake fraction. The hull feels (1 - t) T along the shaft direction d at the
propeller's position r (t: thrust deduction) and the reaction torque Q about d; the sign of
K_Q says which way the hull rolls for forward thrust (the propeller's handedness).

Units: the command, its limits and rate in rpm and rpm/s; everything else SI. A first-order
motor lag (the shaft speed as a state) is not a wrench of the command and is left to the
plant's actuator state (docs/remus100.md, "What the actuator protocol cannot say yet").
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from auvmpc.models.actuators.base import check_fields, described, elementwise, wrench_of

__all__ = ["Propeller"]

SECONDS_PER_MINUTE = 60.0


@dataclass(frozen=True)
class Propeller:
    """A propeller at ``position`` (m, body axes, z down) whose shaft points along the unit
    ``direction``; its command is the shaft speed (rpm)."""

    name: str = described("the input's name, e.g. propeller_rpm")
    position: tuple[float, float, float] = described("body axes, z down (m)")
    direction: tuple[float, float, float] = described("the shaft's unit direction")
    diameter: float = described("m")
    thrust_coefficient: float = described("K_T0, K_T at J = 0")
    torque_coefficient: float = described("K_Q0, signed: the hull's roll moment about d is Q")
    density: float = described("water density (kg/m3)")
    lower: float = described("rpm")
    upper: float = described("rpm")
    rate: float = described("rpm/s")
    thrust_slope: float = described("dK_T/dJ for forward shaft speed (0: the pure n|n| law)", 0.0)
    torque_slope: float = described("dK_Q/dJ for forward shaft speed", 0.0)
    wake_fraction: float = described("w: V_a = (1 - w) u_r", 0.0)
    thrust_deduction: float = described("t: the hull feels (1 - t) T", 0.0)

    linear = False
    unit = "rpm"  # its command's unit (plots, docs)
    jams = False  # a failed propeller stops or weakens (a loss)

    def __post_init__(self) -> None:
        check_fields(self, ("diameter", "density", "rate"), unit="direction")

    @property
    def column(self) -> np.ndarray:
        raise ValueError(f"{self.name}: thrust goes with rpm squared, no single column")

    def thrust_and_torque(self, nu_r: Any, command: Any) -> tuple[Any, Any]:
        """Open-water thrust T (N) and shaft torque Q (N m) at relative velocity ``nu_r`` (its
        surge ``nu_r[0]``) for the shaft speed ``command`` (rpm)."""
        maths = elementwise(nu_r, command)
        n = command / SECONDS_PER_MINUTE
        square = n * maths.fabs(n)
        advance = (1.0 - self.wake_fraction) * nu_r[0] / self.diameter * maths.fmax(n, 0.0)
        rho_d4 = self.density * self.diameter**4
        thrust = rho_d4 * (self.thrust_coefficient * square + self.thrust_slope * advance)
        rho_d5 = rho_d4 * self.diameter
        torque = rho_d5 * (self.torque_coefficient * square + self.torque_slope * advance)
        return thrust, torque

    def wrench(self, nu_r: Any, command: Any) -> Any:
        """(6,) ``[(1 - t) T d; r x (1 - t) T d + Q d]``; NumPy in, NumPy out; CasADi in,
        CasADi out."""
        maths = elementwise(nu_r, command)
        thrust, torque = self.thrust_and_torque(nu_r, command)
        pushed = (1.0 - self.thrust_deduction) * thrust
        force = tuple(pushed * component for component in self.direction)
        moment = tuple(torque * component for component in self.direction)
        return wrench_of(force, self.position, maths, moment)
