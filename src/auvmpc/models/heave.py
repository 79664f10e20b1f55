"""The 1-DOF heave model of the depth experiment (paper-model.md section 8).

    m_heave w' = Zw w + Zww |w| w + sum(F_z) + net_buoyancy_N + d_z,    z' = w

State ``[z, w]`` (:data:`auvmpc.models.layout.DEPTH`): depth z (m), up, negative below the
still surface, and heave rate w (m/s, up). Input: one force per vertical thruster (N, up).
``d_z`` is an external vertical force (N), e.g. of surface waves. The parameters are a vehicle
file's ``heave`` section (:class:`auvmpc.models.vehicle.HeaveParams`).
"""

from __future__ import annotations

from collections.abc import Callable

import casadi as ca
import numpy as np

from auvmpc.errors import FieldError
from auvmpc.models.integrators import rk4_step_time_varying
from auvmpc.models.layout import DEPTH
from auvmpc.models.vehicle import HEAVE_MODEL_FIELDS, HeaveParams, VehicleParams

__all__ = [
    "heave_damping_force",
    "heave_dynamics",
    "heave_plant_step",
    "resolve_heave",
]

_Z = DEPTH.index("z")


def heave_dynamics(state, thrust, heave: HeaveParams, disturbance=0.0):
    """Derivative of [z, w] (m, m/s, z up) under vertical thrusts (N) and a force d_z (N).

    NumPy in, NumPy out; CasADi in, CasADi out (like :func:`auvmpc.models.vehicle.dynamics`).
    """
    symbolic = isinstance(state, ca.SX | ca.MX) or isinstance(thrust, ca.SX | ca.MX)
    w = state[1]
    if symbolic:
        total, absolute = ca.sum1(thrust), ca.fabs
    else:
        total, absolute = float(np.sum(thrust)), abs
    force = heave_damping_force(heave, w, absolute) + total + heave.net_buoyancy_N + disturbance
    derivative = (w, force / heave.m_heave)
    return ca.vertcat(*derivative) if symbolic else np.array(derivative, dtype=float)


def heave_damping_force(heave: HeaveParams, w, absolute=abs):
    """The heave damping force at heave rate ``w`` (N, opposing it): Zw w + Zww |w| w.
    ``absolute``: ``abs`` for numbers, ``ca.fabs`` for CasADi expressions."""
    return heave.Zw * w + heave.Zww * absolute(w) * w


def resolve_heave(vehicle: VehicleParams, scale: dict[str, float]) -> HeaveParams:
    """The heave parameters of a vehicle, with the plant's scale factors applied."""
    vehicle.fixed_thrusters("the depth (heave) model")
    if vehicle.heave is None:
        raise FieldError("vehicle", vehicle.name, "has no heave section (needed for depth control)")
    changes = {}
    for field, factor in scale.items():
        if field not in HEAVE_MODEL_FIELDS:
            raise FieldError(f"plant.scale.{field}", factor, "not a scalable heave field")
        changes[field] = getattr(vehicle.heave, field) * factor
    return vehicle.heave.model_copy(update=changes)


def heave_plant_step(
    heave: HeaveParams,
    state: np.ndarray,
    thrust: np.ndarray,
    t0: float,
    duration: float,
    substeps: int,
    force: Callable[[float, float], float],
) -> np.ndarray:
    """Integrate the heave model over one held-thrust sample with RK4 sub-steps, under the
    vertical force ``force(z, t)`` (N) evaluated where each sub-step asks."""

    def rhs(time_s: float, x: np.ndarray) -> np.ndarray:
        return heave_dynamics(x, thrust, heave, force(x[_Z], time_s))

    h = duration / substeps
    for i in range(substeps):
        state = rk4_step_time_varying(rhs, t0 + i * h, state, h)
    return state
