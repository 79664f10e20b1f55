"""The reference an underactuated vehicle can follow: its heading turned to where its
thrusters can make the force the path needs.

A reference gives the path's heading (the tangent) and body velocities at that heading.
A vehicle with no sway force cannot follow the path at that heading whenever following it
needs a sideways force: in a current, or in a turn (centripetal force). It has to crab:
turn until the sway force the motion needs is zero, the sway drag of its sideslip
balancing the rest. Asked to hold the tangent heading, the MPC trades heading error
against position error and, on a light vehicle, the two fight sample by sample (measured
on ``videoray-pro3``: a growing two-sample yaw oscillation, docs/tuning.md).

:func:`crab_reference` replaces the heading of each reference node with the heading
closest to the tangent at which the force the path needs (the 3-DOF model solved for the
force, with the estimated disturbance) has no component in the vehicle's unactuated
direction, and re-expresses the velocities in that heading. The world-frame path (x, y and
its velocity) is unchanged; a fully actuated vehicle's reference is returned as it is.

The crab angle starts from the vehicle's own heading and turns towards that root at no
more than ``CRAB_TURN_FRACTION`` of the vehicle's top yaw rate beyond the path's own turn:
where the root jumps (the path stops in a current and the vehicle must face it; a
waypoint corner starts), the reference turns the vehicle round at a pace it can follow
instead of asking for the new heading at once (measured: a 1.6 rad/s snap round when a
path ended in a current, 0.6 rad/s with the bound).
"""

from __future__ import annotations

import numpy as np

from auvmpc.models.layout import HORIZONTAL, PLANAR_MOMENT
from auvmpc.models.vehicle import VehicleParams, body_from_world, dynamics, top_yaw_rate

__all__ = ["CRAB_TURN_FRACTION", "crab_reference"]

# How fast the crab angle may change, as a fraction of the vehicle's top yaw rate: half
# of what the run verdict allows a yaw-rate excursion (sim/verdict.py), so that tracking
# has room on top.
CRAB_TURN_FRACTION = 0.25

# Headings tried, relative to the tangent: within a quarter turn (beyond it the vehicle
# would back along the path; at rest one of the two roots, pi apart, always lies within).
_OFFSETS = np.linspace(-0.5 * np.pi, 0.5 * np.pi, 181)
# Where the missing force changes by less than this fraction of the thrust authority over
# every heading tried (a vehicle at rest in still or nearly still water), the heading does
# not matter and the reference keeps the tangent: otherwise the estimator's noise would
# choose it (measured: a vehicle stopped in still water turned a quarter turn after a
# 1e-6 N estimate). Elsewhere the root is exact: a dead band biased a slow circle by 2 cm.
_NEGLIGIBLE_FRACTION = 0.01


def crab_reference(
    model: VehicleParams,
    reference: np.ndarray,
    disturbance: np.ndarray,
    sample_time: float,
    heading: float,
) -> np.ndarray:
    """``reference`` (nodes, HORIZONTAL.size) with the heading an underactuated ``model`` at
    ``heading`` can turn to and hold under the world-frame ``disturbance`` [X, Y, N]; returned
    unchanged if fully actuated."""
    missing = model.unactuated_direction
    if missing is None or len(reference) < 2:
        return reference
    reference = np.asarray(reference, dtype=float)
    tangent = reference[:, HORIZONTAL.heading]
    cos_t, sin_t = np.cos(tangent), np.sin(tangent)
    u_ref, v_ref = reference[:, HORIZONTAL.body_velocity].T
    velocity = np.stack([u_ref * cos_t - v_ref * sin_t, u_ref * sin_t + v_ref * cos_t], axis=1)
    acceleration = np.gradient(velocity, sample_time, axis=0)
    r = reference[:, HORIZONTAL.index("r")]
    r_dot = np.gradient(r, sample_time)

    candidates = tangent[:, None] + _OFFSETS[None, :]  # (nodes, candidates)
    residual = _missing_force(model, missing, candidates, velocity, acceleration, r, r_dot,
                              np.asarray(disturbance, dtype=float))  # fmt: skip
    negligible = _NEGLIGIBLE_FRACTION * float(np.max(model.thrust_authority))
    indifferent = np.ptp(residual, axis=1) <= negligible
    crab = _root_nearest_tangent(np.where(indifferent[:, None], 0.0, residual))
    step = CRAB_TURN_FRACTION * top_yaw_rate(model) * sample_time
    crab[0] = np.clip(_wrapped(heading - tangent[0]), _OFFSETS[0], _OFFSETS[-1])
    for i in range(1, len(crab)):
        crab[i] = crab[i - 1] + np.clip(crab[i] - crab[i - 1], -step, step)
    psi = tangent + crab
    shaped = reference.copy()
    cos_p, sin_p = np.cos(psi), np.sin(psi)
    shaped[:, HORIZONTAL.heading] = psi
    shaped[:, HORIZONTAL.index("u")] = velocity[:, 0] * cos_p + velocity[:, 1] * sin_p
    shaped[:, HORIZONTAL.index("v")] = -velocity[:, 0] * sin_p + velocity[:, 1] * cos_p
    shaped[:, HORIZONTAL.index("r")] = np.gradient(np.unwrap(psi), sample_time)
    return shaped


def _wrapped(angle: float) -> float:
    return float((angle + np.pi) % (2.0 * np.pi) - np.pi)


def _missing_force(model, missing, heading, velocity, acceleration, r, r_dot, disturbance):
    """The component along ``missing`` of the body force and moment the motion needs at
    each candidate ``heading``: the model's inertia times the acceleration the path needs
    less the one auvmpc.models.vehicle.dynamics gives without thrust."""
    cos_h, sin_h = np.cos(heading), np.sin(heading)
    vx, vy = velocity[:, 0:1], velocity[:, 1:2]
    ax, ay = acceleration[:, 0:1], acceleration[:, 1:2]
    r = np.broadcast_to(r[:, None], heading.shape)
    u = vx * cos_h + vy * sin_h
    v = -vx * sin_h + vy * cos_h
    needed = (ax * cos_h + ay * sin_h + r * v, -ax * sin_h + ay * cos_h - r * u, r_dot[:, None])
    d_u, d_v = body_from_world(disturbance, heading)
    moment = disturbance[PLANAR_MOMENT]
    unforced = dynamics((0.0, 0.0, heading, u, v, r), np.zeros(model.n_thrusters), model,
                        (d_u, d_v, moment))[HORIZONTAL.span("u", "r")]  # fmt: skip
    inertia = (model.m11, model.m22, model.Iz)
    return sum(
        weight * mass * (want - have)
        for weight, mass, want, have in zip(missing, inertia, needed, unforced, strict=True)
    )


def _root_nearest_tangent(residual: np.ndarray) -> np.ndarray:
    """Per row, the offset (interpolated within its bracket) of the sign change of
    ``residual`` over ``_OFFSETS`` nearest the tangent; the offset of the smallest
    |residual| where there is none."""
    rows = np.arange(len(residual))
    left, right = residual[:, :-1], residual[:, 1:]
    crossing = left * right <= 0.0
    middle = 0.5 * (_OFFSETS[:-1] + _OFFSETS[1:])
    distance = np.where(crossing, np.abs(middle)[None, :], np.inf)
    pick = np.argmin(distance, axis=1)
    a, b = left[rows, pick], right[rows, pick]
    span = a - b
    # Where the residual is flat (zero across the bracket, e.g. at rest in still water)
    # any heading will do: keep the bracket's end nearer the tangent.
    fraction = np.divide(a, span, out=np.zeros_like(a), where=span != 0.0)
    root = _OFFSETS[pick] + fraction * (_OFFSETS[pick + 1] - _OFFSETS[pick])
    flat = (a == 0.0) & (b == 0.0)
    root = np.where(flat, np.where(np.abs(_OFFSETS[pick]) <= np.abs(_OFFSETS[pick + 1]),
                                   _OFFSETS[pick], _OFFSETS[pick + 1]), root)  # fmt: skip
    has_root = crossing[rows, pick]
    return np.where(has_root, root, _OFFSETS[np.argmin(np.abs(residual), axis=1)])
