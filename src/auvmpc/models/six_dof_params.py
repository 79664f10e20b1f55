"""The vehicle file's optional ``six_dof`` section: 3-D thruster poses and 6-DOF hydrodynamics.

Fossen's names and signs (``shared/spec/six-dof.md``; Fossen 2021, ch. 2-4 and 6): body
frame x forward, y starboard, z down, origin at the body origin CO; added-mass derivatives
and damping coefficients are negative. The rigid-body mass is the vehicle's ``mass``; the
section adds what the 3-DOF and heave models do not need:

- ``inertia`` about CO, ``center_of_gravity`` r_g and ``center_of_buoyancy`` r_b,
- ``displaced_volume``, ``water_density`` and ``gravity`` (W = m g, B = rho g V),
- ``added_mass`` [X_udot, Y_vdot, Z_wdot, K_pdot, M_qdot, N_rdot], or a full 6x6 matrix
  of derivatives (M_A = -added_mass),
- ``linear_damping`` [X_u, Y_v, Z_w, K_p, M_q, N_r] and ``quadratic_damping``
  [X_uu, Y_vv, Z_ww, K_pp, M_qq, N_rr],
- ``thrusters``: every thruster's position and direction; the 6-DOF plant's input is one
  force per entry, in this order (none for a vehicle whose ``actuators:`` list is its
  inputs: a propeller and fins).

The section stands alone: the 6-DOF plant reads only it (and ``mass``); the 3-DOF fields
stay the horizontal model's. :func:`horizontal_equivalent` says which 3-DOF values a
section implies, so a preset can be checked for agreement.
"""

from __future__ import annotations

import math
from functools import cached_property
from typing import Annotated

import numpy as np
from pydantic import (
    AfterValidator,
    Field,
    SerializerFunctionWrapHandler,
    model_serializer,
    model_validator,
)

from auvmpc.config import Positive, StrictModel
from auvmpc.errors import FieldError
from auvmpc.models.actuators.thruster import thrust_column

__all__ = [
    "SixDofParams",
    "Thruster3D",
    "allocation_matrix_6dof",
    "horizontal_equivalent",
    "rigid_body_mass_matrix",
    "skew",
]

Vector3 = tuple[float, float, float]
Vector6 = tuple[float, float, float, float, float, float]
Matrix3 = tuple[Vector3, Vector3, Vector3]
Matrix6 = tuple[Vector6, Vector6, Vector6, Vector6, Vector6, Vector6]
Damping6 = tuple[
    Annotated[float, Field(le=0)],
    Annotated[float, Field(le=0)],
    Annotated[float, Field(le=0)],
    Annotated[float, Field(le=0)],
    Annotated[float, Field(le=0)],
    Annotated[float, Field(le=0)],
]

# A matrix typed with a few decimals is symmetric when its transposed entries agree to this
# fraction of its largest entry; round-off in a computed one is far smaller.
SYMMETRY_TOL = 1e-9


def _unit_direction(direction: Vector3) -> Vector3:
    if math.hypot(*direction) < 1e-9:
        raise ValueError(f"thrust direction must not be zero, got {list(direction)}")
    return direction


class Thruster3D(StrictModel):
    """One thruster in 3-D: where it sits and which way positive thrust pushes (body frame)."""

    position: Vector3 = Field(description="(x forward, y starboard, z down) from CO in m")
    direction: Annotated[Vector3, AfterValidator(_unit_direction)] = Field(
        description="thrust direction (x, y, z down); normalised, so [0.7071, 0.7071, 0] is 45 deg"
    )

    @property
    def unit_direction(self) -> np.ndarray:
        direction = np.array(self.direction, dtype=float)
        return direction / np.linalg.norm(direction)


def skew(a) -> np.ndarray:
    """S(a) with S(a) b = a x b (Fossen 2021, eq. 2.9)."""
    return np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])


def allocation_matrix_6dof(thrusters) -> np.ndarray:
    """Columns [d_i; r_i x d_i] (6, n): tau = [X, Y, Z, K, M, N] = T @ F (six-dof.md)."""
    return np.array(
        [thrust_column(thruster.position, thruster.unit_direction) for thruster in thrusters],
        dtype=float,
    ).T


def rigid_body_mass_matrix(mass: float, inertia: np.ndarray, r_g: np.ndarray) -> np.ndarray:
    """M_RB = [[m I3, -m S(r_g)], [m S(r_g), I_b]], I_b about CO (Fossen 2021, eq. 3.44)."""
    S = skew(r_g)
    return np.block([[mass * np.eye(3), -mass * S], [mass * S, inertia]])


def _is_symmetric(matrix: np.ndarray) -> bool:
    scale = max(float(np.max(np.abs(matrix))), 1.0)
    return bool(np.all(np.abs(matrix - matrix.T) <= SYMMETRY_TOL * scale))


def _smallest_eigenvalue(matrix: np.ndarray) -> float:
    return float(np.min(np.linalg.eigvalsh(0.5 * (matrix + matrix.T))))


class SixDofParams(StrictModel):
    """A vehicle's 6-DOF model: 3-D thruster poses and hydrodynamics, Fossen's names and signs
    (body axes x forward, y starboard, z down; origin CO)."""

    inertia: Vector3 | Matrix3 = Field(
        description="rigid-body inertia about CO: [Ix, Iy, Iz] or the 3x3 tensor (kg m2)"
    )
    center_of_gravity: Vector3 = Field(description="r_g from CO, body axes, z down (m)")
    center_of_buoyancy: Vector3 = Field(
        description="r_b from CO, body axes, z down; above r_g, i.e. a smaller z (m)"
    )
    displaced_volume: Positive = Field(description="volume of water displaced (m3)")
    water_density: Positive = Field(description="rho: 1000 fresh, 1025 sea water (kg/m3)")
    gravity: Positive = Field(default=9.81, description="g (m/s2)")
    added_mass: Vector6 | Matrix6 = Field(
        description="added-mass derivatives [X_udot, Y_vdot, Z_wdot, K_pdot, M_qdot, N_rdot] "
        "(negative; kg, kg m2) or their 6x6 matrix; M_A = -added_mass"
    )
    linear_damping: Damping6 = Field(
        description="[X_u, Y_v, Z_w, K_p, M_q, N_r] (negative; N s/m, N m s)"
    )
    quadratic_damping: Damping6 = Field(
        description="[X_uu, Y_vv, Z_ww, K_pp, M_qq, N_rr] (negative; N s2/m2, N m s2)"
    )
    hull_lift: tuple[float, float, float, float] | None = Field(
        default=None,
        description="the hull's lift in a sideslip or an angle of attack, Prestero's body-lift "
        "derivatives [Y_uv, Z_uw, M_uw, N_uv] (kg/m, kg/m, kg, kg): Y = Y_uv u_r v_r, Z = "
        "Z_uw u_r w_r, M = M_uw u_r w_r, N = N_uv u_r v_r; omitted: none (a slender hull "
        "moving fast needs it, a box-shaped ROV does not)",
    )
    thrusters: tuple[Thruster3D, ...] = Field(
        default=(),
        description="every thruster (horizontal and vertical); the 6-DOF plant takes one "
        "force per entry, in this order; empty for a vehicle with ``actuators`` (a propeller "
        "and fins), whose inputs those are",
    )

    without_munk_moments: bool = Field(
        default=False,
        description="leave out C_A(nu_r)'s pitch and yaw terms in surge, heave and sway (the "
        "Munk moments; C_A stays skew-symmetric), as Fossen's MSS remus100.m does where a "
        "torpedo's small strip-theory rotational damping could not hold them",
    )

    @model_serializer(mode="wrap")
    def _dump(self, handler: SerializerFunctionWrapHandler) -> dict:
        """``without_munk_moments`` and ``hull_lift`` only when set: a section's dump
        (run.json, the compiled model's cache key) is as it was before the fields existed."""
        data = handler(self)
        if not data.get("without_munk_moments"):
            data.pop("without_munk_moments", None)
        if data.get("hull_lift") is None:
            data.pop("hull_lift", None)
        return data

    @model_validator(mode="after")
    def _physical(self) -> SixDofParams:
        inertia = self.inertia_matrix
        if not _is_symmetric(inertia):
            raise FieldError("inertia", self.inertia, "the inertia tensor must be symmetric")
        if _smallest_eigenvalue(inertia) <= 0:
            raise FieldError(
                "inertia", self.inertia, "the inertia tensor must be positive definite"
            )
        derivatives = np.array(self.added_mass, dtype=float)
        if derivatives.ndim == 1 and np.any(derivatives > 0):
            raise FieldError(
                "added_mass",
                self.added_mass,
                "added-mass derivatives are negative or zero (Fossen: M_A = -diag(X_udot, ...))",
            )
        added = self.added_mass_matrix
        if not _is_symmetric(added):
            raise FieldError(
                "added_mass", self.added_mass, "the added-mass matrix must be symmetric"
            )
        if _smallest_eigenvalue(added) < -SYMMETRY_TOL * max(float(np.max(np.abs(added))), 1.0):
            raise FieldError(
                "added_mass",
                self.added_mass,
                "M_A = -added_mass must be positive semi-definite (a body in water gains "
                "inertia, never loses it)",
            )
        z_g, z_b = self.center_of_gravity[2], self.center_of_buoyancy[2]
        if not z_b < z_g:
            raise FieldError(
                "center_of_buoyancy",
                self.center_of_buoyancy,
                f"the centre of buoyancy must be above the centre of gravity (z down: "
                f"z_b < z_g = {z_g}), else roll and pitch have no restoring moment",
            )
        return self

    @cached_property
    def inertia_matrix(self) -> np.ndarray:
        """I_b (3, 3) about CO (kg m2)."""
        inertia = np.array(self.inertia, dtype=float)
        matrix = np.diag(inertia) if inertia.ndim == 1 else inertia
        matrix.setflags(write=False)
        return matrix

    @cached_property
    def added_mass_matrix(self) -> np.ndarray:
        """M_A (6, 6) = -added_mass (positive semi-definite)."""
        derivatives = np.array(self.added_mass, dtype=float)
        matrix = -(np.diag(derivatives) if derivatives.ndim == 1 else derivatives)
        matrix.setflags(write=False)
        return matrix

    @cached_property
    def T(self) -> np.ndarray:
        """Allocation matrix (6, n): tau = [X, Y, Z, K, M, N] = T @ F."""
        matrix = allocation_matrix_6dof(self.thrusters)
        matrix.setflags(write=False)
        return matrix

    @property
    def n_thrusters(self) -> int:
        return len(self.thrusters)

    def weight(self, mass: float) -> float:
        """W = m g (N)."""
        return mass * self.gravity

    @property
    def buoyancy(self) -> float:
        """B = rho g V (N)."""
        return self.water_density * self.gravity * self.displaced_volume

    def mass_matrix(self, mass: float) -> np.ndarray:
        """M = M_RB + M_A (6, 6) for a rigid-body mass ``mass`` (kg)."""
        r_g = np.array(self.center_of_gravity, dtype=float)
        return rigid_body_mass_matrix(mass, self.inertia_matrix, r_g) + self.added_mass_matrix


def horizontal_equivalent(mass: float, six_dof: SixDofParams) -> dict[str, float]:
    """The 3-DOF and heave values a 6-DOF section implies (diagonal terms; six-dof.md's
    reduction: m11 = m - X_udot, m22 = m - Y_vdot, Iz = Iz_rb - N_rdot)."""
    added = np.diag(six_dof.added_mass_matrix)
    linear, quadratic = six_dof.linear_damping, six_dof.quadratic_damping
    return {
        "m11": mass + added[0],
        "m22": mass + added[1],
        "Iz_rb": float(six_dof.inertia_matrix[2, 2]),
        "Iz_added": float(added[5]),
        "Xu": linear[0], "Xuu": quadratic[0],
        "Yv": linear[1], "Yvv": quadratic[1],
        "Nr": linear[5], "Nrr": quadratic[5],
        "m_heave": mass + added[2],
        "Zw": linear[2], "Zww": quadratic[2],
        "net_buoyancy_N": six_dof.buoyancy - six_dof.weight(mass),
    }  # fmt: skip
