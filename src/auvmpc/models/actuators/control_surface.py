"""A control surface (a rudder, a pair of stern planes): lift and drag of the water passing
it at an angle, commanded in degrees.

Geometry: the fins one input turns sit at ``position`` r (their centre of pressure, m, body
axes, z down) and turn about the unit ``axis`` s (their stock, at right angles to the body's x
axis); at zero angle their chord lies along x. A positive angle is right-handed about s and
lifts along n = s x e_x: a rudder turning about +z lifts to starboard (+y), stern planes
turning about +y lift upwards (-z). These are Prestero's (2001) signs: positive rudder turns
the vehicle to port, positive planes pitch it nose down. (Fossen's MSS ``remus100.m`` turns
its rudder the other way: axis -z there.)

Flow: the water passes the fins at v_f = nu_r[0:3] + omega x r (the body's velocity through
the water and its turn), u_f = v_f . e_x along the chord and v_n = v_f . n across it. The
angle of attack is the fins' angle less the flow's, alpha = delta - v_n / u_f (small angles;
Prestero's effective fin angle delta_e = delta - beta_e). With q = rho A / 2 (A: the planform area
of all the fins the input turns), lift slope C_La and stall angle s:

    L = q C_La u_f^2 sat(alpha)                 along n
    D = q (C_D0 u_f |u_f| + K C_La^2 sign(u_f) (u_f sat(alpha))^2)    along -e_x

sat clips alpha to [-s, s] (past stall the lift stops growing; K C_L^2 is the induced drag).
Multiplied through by u_f, u_f sat(alpha) = clip(u_f delta - v_n, -s |u_f|, s |u_f|): no
division, defined at rest (no force there), so the wrench is CasADi-differentiable everywhere
except on the stall and zero-flow kinks (piecewise linear: fmin, fmax, fabs), where CasADi
takes one side's derivative. At small angles it is Prestero's linear fin model: with
q C_La = Y_uudr his fin derivatives Y_uvf = -Y_uudr, Y_urf = x_fin Y_uvf, N_uudr =
x_fin Y_uudr, ... all follow (tests/test_actuator_kinds.py checks his Table C.10).

Units: the command, its limits and rate in degrees and degrees per second; the lift slope
per radian and the stall angle in radians, like everything else physical here (SI).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property
from typing import Any

import numpy as np

from auvmpc.errors import FieldError
from auvmpc.models.actuators.base import check_fields, cross, described, elementwise, wrench_of

__all__ = ["ControlSurface"]

RADIANS_PER_DEGREE = math.pi / 180.0
_CHORD = (1.0, 0.0, 0.0)  # the fins' chord at zero angle: the body's x axis


@dataclass(frozen=True)
class ControlSurface:
    """Fins at ``position`` turning about the unit ``axis``; the command is their angle (deg)."""

    name: str = described("the input's name, e.g. rudder_deg")
    position: tuple[float, float, float] = described("the fins' centre of pressure (m)")
    axis: tuple[float, float, float] = described("unit stock axis, at right angles to x")
    area: float = described("planform area of all the fins the input turns (m2)")
    lift_slope: float = described("C_La, per rad")
    stall_angle: float = described("|alpha| beyond it gives no more lift (rad)")
    density: float = described("water density (kg/m3)")
    lower: float = described("deg")
    upper: float = described("deg")
    rate: float = described("deg/s")
    drag_coefficient: float = described("C_D0 at zero lift (0: in the hull's drag)", 0.0)
    induced_drag_factor: float = described("K in C_D = C_D0 + K C_L^2", 0.0)

    linear = False
    unit = "deg"  # its command's unit (plots, docs)
    jams = True  # a jammed fin holds its angle, and its lift still acts

    def __post_init__(self) -> None:
        check_fields(self, ("area", "lift_slope", "stall_angle", "density", "rate"), unit="axis")
        if abs(self.axis[0]) > 1e-9:
            raise FieldError(f"{self.name}.axis", self.axis,
                             f"{self.axis}, must be at right angles to x")  # fmt: skip

    @property
    def column(self) -> np.ndarray:
        raise ValueError(f"{self.name}: lift goes with the flow speed squared, no single column")

    @cached_property
    def lift_direction(self) -> tuple[float, float, float]:
        """n = s x e_x, the unit direction of lift for a positive angle."""
        return cross(self.axis, _CHORD)

    def lift_and_drag(self, nu_r: Any, command: Any) -> tuple[Any, Any]:
        """Lift L (N, along n) and drag D (N, along -e_x) at relative velocity ``nu_r`` (6,)
        for the fins' angle ``command`` (deg)."""
        maths = elementwise(nu_r, command)
        turn = cross((nu_r[3], nu_r[4], nu_r[5]), self.position)
        flow = [nu_r[i] + turn[i] for i in range(3)]
        along = flow[0]
        across = sum(flow[i] * self.lift_direction[i] for i in range(3) if self.lift_direction[i])
        bound = self.stall_angle * maths.fabs(along)
        # u_f sat(alpha): alpha = delta - v_n / u_f clipped to the stall angle, times u_f.
        lifting = maths.fmin(maths.fmax(along * command * RADIANS_PER_DEGREE - across, -bound),
                             bound)  # fmt: skip
        half_rho_area = 0.5 * self.density * self.area
        lift = half_rho_area * self.lift_slope * along * lifting
        drag = half_rho_area * (
            self.drag_coefficient * along * maths.fabs(along)
            + self.induced_drag_factor * self.lift_slope**2 * maths.sign(along) * lifting**2
        )
        return lift, drag

    def wrench(self, nu_r: Any, command: Any) -> Any:
        """(6,) ``[L n - D e_x; r x (L n - D e_x)]``; NumPy in, NumPy out; CasADi in, CasADi
        out."""
        maths = elementwise(nu_r, command)
        lift, drag = self.lift_and_drag(nu_r, command)
        force = tuple(lift * n - drag * e for n, e in zip(self.lift_direction, _CHORD, strict=True))
        return wrench_of(force, self.position, maths)
