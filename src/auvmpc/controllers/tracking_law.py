"""The baseline's tracking law, stated once as a CasADi function.

Feedback linearisation on the nominal model, a PD loop in the path frame with a capped
closing speed, the heading loop, and the allocation that keeps the yaw moment and scales the
planar force into the force limits (controllers/baseline.py's docstring has the law and its
reasons). Three users evaluate this one statement: the ``baseline`` controller, the safety
shell's recovery (controllers/recovery.py) and the exported C controller (export-c generates
its C), so the feedback a vehicle falls back on is the same in Python and on board.

The function :func:`tracking_law` builds takes the state ``[x y psi u v r]``, the reference
now and one sample ahead, the disturbance estimate (world force X, Y and yaw moment N) and
the thrusters' effectiveness (1 healthy, 0 dead: the allocation is the minimum-norm one of
the effective thrusters, so a dead one gets nothing) and returns the generalised force asked
for, the errors, what the integrators are to see, the thrust (within the force limits where
they allow zero thrust; before the rate limit, which the caller's projection applies) and
the unlimited allocation.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import casadi as ca
import numpy as np

from auvmpc.models.layout import (
    HORIZONTAL,
    PLANAR_FORCE,
    PLANAR_FORCE_XY,
    PLANAR_MOMENT,
    Layout,
)
from auvmpc.models.vehicle import VehicleParams, yaw_damping_moment

if TYPE_CHECKING:
    from auvmpc.controllers.baseline import BaselineConfig

__all__ = [
    "LAW_INPUTS", "LAW_OUTPUTS", "PATH_ERRORS", "REFERENCE_ROWS", "apply_law",
    "effective_allocation", "tracking_law",
]  # fmt: skip

LAW_INPUTS = ("state", "reference_now", "reference_ahead", "disturbance", "effectiveness")
LAW_OUTPUTS = ("tau", "errors", "integrated", "thrust", "requested")
# The reference rows the law reads: now and one sample ahead.
REFERENCE_ROWS = 2
# The damping of the faulted allocation's least squares, relative to the mean eigenvalue of
# T T': small enough to be the pseudo-inverse's allocation to ~1e-9, large enough that a set
# of effective thrusters that no longer spans the plane (or none at all) stays finite.
_ALLOCATION_DAMPING = 1e-9
# The law's ``errors`` and ``integrated``: the position error along and across the
# reference's heading (m, path frame) and the heading error (rad, wrapped).
PATH_ERRORS = Layout(names=("along", "cross", "heading"))

_X, _Y, _PSI, _U, _V, _R = (HORIZONTAL.index(name) for name in HORIZONTAL.names)
_FORCE_X, _FORCE_Y = (PLANAR_FORCE.index(name) for name in ("X", "Y"))


def apply_law(
    law: ca.Function,
    state: np.ndarray,
    reference: np.ndarray,
    disturbance: np.ndarray,
    effectiveness: np.ndarray,
) -> list[np.ndarray]:
    """``law``'s outputs (LAW_OUTPUTS, as NumPy vectors) for ``state``, the reference rows
    from now on (the second is one sample ahead; a single row is held), the disturbance
    estimate and the thrusters' effectiveness (n,)."""
    ahead = reference[1] if len(reference) > 1 else reference[0]
    values = law(state, reference[0], ahead, disturbance, effectiveness)
    return [value.full().ravel() for value in values]


def effective_allocation(model: VehicleParams, effectiveness):
    """The minimum-norm allocation (n, 3) of the thrusters as they act, ``F = A tau`` with
    ``T diag(e) F = tau``: the vehicle's ``T_pinv`` itself where every ``e`` is 1 (so a
    healthy vehicle's law is the one it always was, to the bit), else the damped least
    squares ``M' (M M' + eps I)^-1`` of ``M = T diag(e)``, whose row of a dead thruster is
    zero. ``effectiveness`` is CasADi (n,)."""
    T = np.asarray(model.T)
    n = T.shape[1]
    effective = ca.DM(T) @ ca.diag(effectiveness)
    damping = _ALLOCATION_DAMPING * float(np.trace(T @ T.T)) / T.shape[0]
    gram = effective @ effective.T + damping * ca.SX.eye(T.shape[0])
    damped = effective.T @ ca.inv(gram)
    healthy = ca.SX(1.0)
    for i in range(n):
        healthy = ca.logic_and(healthy, effectiveness[i] == 1.0)
    return ca.if_else(healthy, ca.DM(np.asarray(model.T_pinv)), damped)


def _rotate(angle, vector) -> list:
    """R(angle) vector: body (or path) frame to world frame in the plane."""
    c, s = ca.cos(angle), ca.sin(angle)
    return [c * vector[0] - s * vector[1], s * vector[0] + c * vector[1]]


def _unrotate(angle, vector) -> list:
    """R(angle)^T vector: world frame to body (or path) frame."""
    c, s = ca.cos(angle), ca.sin(angle)
    return [c * vector[0] + s * vector[1], -s * vector[0] + c * vector[1]]


def _wrap(angle):
    """The angle wrapped to (-pi, pi]: pi - ((pi - angle) mod 2 pi), the modulo taking the
    divisor's sign as Python's does."""
    remainder = ca.fmod(math.pi - angle, 2.0 * math.pi)
    return math.pi - ca.if_else(remainder < 0, remainder + 2.0 * math.pi, remainder)


def _in_order(layout: Layout, by_name: dict):
    """The column of ``by_name``'s entries in ``layout``'s order."""
    return ca.vertcat(*(by_name[name] for name in layout.names))


def _world_velocity(row) -> list:
    """World velocity (x', y') of a reference row [x, y, psi, u, v, r]."""
    return _rotate(row[_PSI], [row[_U], row[_V]])


def _largest_step(start, direction, lower: float, upper: float):
    """Largest s in [0, 1] with lower <= start + s * direction <= upper (start inside)."""
    ratios = [
        ca.if_else(d > 0, (upper - s) / d, ca.if_else(d < 0, (lower - s) / d, math.inf))
        for s, d in zip(ca.vertsplit(start), ca.vertsplit(direction), strict=True)
    ]
    return ca.fmin(ca.fmax(ca.mmin(ca.vertcat(*ratios)), 0.0), 1.0)


def tracking_law(
    model: VehicleParams, sample_time: float, gains: BaselineConfig, settling_yaw: bool = False
) -> ca.Function:
    """The law as ``tracking_law(state, reference_now, reference_ahead, disturbance, effectiveness)
    -> (tau, errors, integrated, thrust, requested)`` (module docstring) for ``model`` held
    over ``sample_time`` with ``gains``; ``settling_yaw``: the shell's recovery, whose yaw
    term holds the wanted rate against the damping where the yaw settles within the sample."""
    p, te, g = model, float(sample_time), gains
    state, now, ahead = (ca.SX.sym(name, HORIZONTAL.size) for name in LAW_INPUTS[:3])
    disturbance = ca.SX.sym("disturbance", PLANAR_FORCE.size)
    effectiveness = ca.SX.sym("effectiveness", p.n_thrusters)
    psi, u, v, r = state[_PSI], state[_U], state[_V], state[_R]
    psi_r, r_r = now[_PSI], now[_R]

    # Reference world velocity now and one sample ahead; their difference over Te is the
    # mean acceleration the held command must produce (centripetal part included).
    velocity_r = _world_velocity(now)
    velocity_ahead = _world_velocity(ahead)
    accel_r = [(velocity_ahead[i] - velocity_r[i]) / te for i in range(2)]
    yaw_accel_r = (ahead[_R] - r_r) / te

    # Position loop in the path frame, closing speed K_D^-1 K_P e capped in norm.
    error_path = _unrotate(psi_r, [state[_X] - now[_X], state[_Y] - now[_Y]])
    velocity = _rotate(psi, [u, v])
    velocity_error_path = _unrotate(psi_r, [velocity[i] - velocity_r[i] for i in range(2)])
    kp, kd = (g.along_kp, g.cross_kp), (g.along_kd, g.cross_kd)
    closing = [kp[i] * error_path[i] / kd[i] if kd[i] > 0 else ca.SX(0.0) for i in range(2)]
    speed = ca.hypot(closing[0], closing[1])
    cap = ca.if_else(speed > 0, ca.fmin(1.0, g.max_approach_speed / speed), 1.0)
    closing = [cap * c for c in closing]
    accel_path = [-kd[i] * (velocity_error_path[i] + closing[i]) for i in range(2)]
    turned = _rotate(psi_r, accel_path)
    accel_world = [accel_r[i] + turned[i] for i in range(2)]

    # Heading loop on the wrapped error to the (optionally line-of-sight) desired heading.
    psi_d = psi_r
    if g.los_lookahead_m is not None:
        psi_d = psi_r - ca.atan(error_path[1] / g.los_lookahead_m)
    heading_error = _wrap(psi - psi_d)
    yaw_accel = yaw_accel_r - g.heading_kp * heading_error - g.heading_kd * (r - r_r)
    if settling_yaw:
        # Where the yaw damping's time constant at r is below a third of the sample, the
        # moment that holds the wanted rate r_r - (K_P / K_D) e_psi against the damping (as
        # an acceleration past the reference's damping, which is subtracted below). On a
        # light, strongly damped yaw (0.38 kg m2: 0.02 s) the inertial term, held for 0.5 s,
        # overshoots the wanted rate by several rad/s each sample and keeps the vehicle
        # spinning.
        slope = ca.fabs(p.Nr + 2.0 * p.Nrr * ca.fabs(r))  # N m s: the damping's at r
        wanted = r_r - g.heading_kp / g.heading_kd * heading_error
        held = (yaw_damping_moment(p, r_r, ca.fabs) - yaw_damping_moment(p, wanted, ca.fabs)) / p.Iz
        yaw_accel = ca.if_else(slope * te < 3.0 * p.Iz, yaw_accel, held)

    # Feedback linearisation: p'' = R(psi) (nu' + r [-v, u]) gives the body accelerations.
    # Damping is fed forward at the reference velocity (in the body frame): at the measured
    # one a model that over-estimates damping turns it into positive feedback. Coriolis and
    # Munk terms use the measured velocity: they are not dissipative, and the Munk moment
    # (m11 - m22) u v is what upsets the heading while the vehicle crabs.
    # Each term by its generalised force's name (body frame); the estimated world force is
    # seen in the body frame, the moment as it is.
    body_accel = _unrotate(psi, accel_world)
    nu_dot = [body_accel[0] + r * v, body_accel[1] - r * u]
    u_d, v_d = _unrotate(psi, velocity_r)
    damping = {
        "X": p.Xu * u_d + p.Xuu * ca.fabs(u_d) * u_d,
        "Y": p.Yv * v_d + p.Yvv * ca.fabs(v_d) * v_d,
        "N": yaw_damping_moment(p, r_r, ca.fabs),
    }
    coriolis = {"X": p.m22 * v * r, "Y": -p.m11 * u * r, "N": (p.m11 - p.m22) * u * v}
    estimate_body = _unrotate(psi, [disturbance[_FORCE_X], disturbance[_FORCE_Y]])
    estimate = {"X": estimate_body[0], "Y": estimate_body[1], "N": disturbance[PLANAR_MOMENT]}
    inertial = {"X": p.m11 * nu_dot[0], "Y": p.m22 * nu_dot[1], "N": p.Iz * yaw_accel}
    tau = _in_order(
        PLANAR_FORCE,
        {
            name: inertial[name] - damping[name] - coriolis[name] - estimate[name]
            for name in PLANAR_FORCE.names
        },
    )
    errors = _in_order(
        PATH_ERRORS, {"along": error_path[0], "cross": error_path[1], "heading": heading_error}
    )
    # The integrators see the position error shrunk by the same cap: outside the range where
    # the loop is linear a large error must not pile up integral in a few samples.
    integrated = _in_order(
        PATH_ERRORS,
        {"along": cap * error_path[0], "cross": cap * error_path[1], "heading": heading_error},
    )

    # Allocation: the yaw moment kept whole if it fits and the planar force scaled along its
    # own direction into the force limits; if the moment alone does not fit, it is scaled
    # and the planar force dropped (a heading error rotates every other error). Scaling
    # towards zero keeps the direction only where zero thrust is allowed.
    allocation = effective_allocation(p, effectiveness)
    thrust_yaw = allocation[:, PLANAR_MOMENT] * tau[PLANAR_MOMENT]
    thrust_planar = ca.mtimes(allocation[:, PLANAR_FORCE_XY], tau[PLANAR_FORCE_XY])
    requested = thrust_yaw + thrust_planar
    lower, upper = p.thrust_min, p.thrust_max
    if lower <= 0.0 <= upper:
        fits = ca.SX(1.0)
        for f in ca.vertsplit(thrust_yaw):
            fits = ca.logic_and(fits, ca.logic_and(lower <= f, f <= upper))
        scaled_planar = thrust_yaw + _largest_step(thrust_yaw, thrust_planar, lower, upper) * (
            thrust_planar
        )
        zero = ca.SX.zeros(p.n_thrusters)
        scaled_yaw = _largest_step(zero, thrust_yaw, lower, upper) * thrust_yaw
        thrust = ca.if_else(fits, scaled_planar, scaled_yaw)
    else:  # limits that exclude zero thrust: nothing to scale towards
        thrust = requested
    return ca.Function(
        "tracking_law",
        [state, now, ahead, disturbance, effectiveness],
        [tau, errors, integrated, thrust, requested],
        list(LAW_INPUTS),
        list(LAW_OUTPUTS),
    )
