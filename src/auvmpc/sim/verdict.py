"""Whether a run went well: ``ok``, ``degraded`` or ``lost``, with a one-line reason.

The rules (docs/verdict.md gives the reason for each number) scale with the vehicle and
the reference, so that a 15 kg vehicle and a 2 t ROV are judged alike:

lost, if any of
    * after the transient the vehicle was farther from the reference than
      ``LOST_LENGTHS`` vehicle lengths (at most ``LOST_EXTENT_FRACTION`` of the
      reference's size): it left the path;
    * its heading turned a full revolution or more relative to the reference's: it spun;
    * the controller fell back for ``LOST_FALLBACK_S`` seconds in a row: nobody was steering.
    A run that left the path after standing at an obstacle's keep-out edge for ``BLOCKED_S``
    seconds while the reference moved on says so too (blocked): it found no way past.

degraded, if not lost and any of
    * a solver fallback, or an obstacle constraint relaxed;
    * after the transient, a position error above ``DEGRADED_LENGTHS`` vehicle lengths (at
      most ``DEGRADED_EXTENT_FRACTION`` of the reference's size), leaving out the samples of
      a detour round an obstacle (``metrics.detour_samples``): those are judged by the
      clearance, below;
    * after the transient, a heading error above ``DEGRADED_HEADING_RAD`` (fully actuated
      vehicles only: an underactuated one steers sideways with its heading);
    * after the transient, a yaw rate above both ``YAW_RATE_REFERENCE_FACTOR`` times the
      reference's largest and ``YAW_RATE_CAPABILITY_FRACTION`` of the vehicle's own
      top yaw rate: a yaw-rate excursion (thruster vehicles only: a propeller and fins
      have no top yaw rate, their turn rate grows with the speed);
    * a thrust or thrust-rate limit violated (a vehicle with ``actuators:``: any input's
      limits, in its own units), or an obstacle touched.

ok otherwise.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from auvmpc.models.vehicle import VehicleParams, top_yaw_rate

__all__ = [
    "Verdict",
    "RunFacts",
    "characteristic_length_m",
    "judge",
    "relative_heading_turns",
]

# Sea water density (kg/m3), for the volume-equivalent size of a vehicle.
SEA_WATER_DENSITY = 1025.0

LOST_LENGTHS = 5.0
LOST_EXTENT_FRACTION = 0.25
LOST_FALLBACK_S = 10.0
BLOCKED_S = 5.0
DEGRADED_LENGTHS = 1.0
DEGRADED_EXTENT_FRACTION = 0.1
DEGRADED_HEADING_RAD = 0.5
YAW_RATE_REFERENCE_FACTOR = 2.0
YAW_RATE_CAPABILITY_FRACTION = 0.5


class Verdict:
    """The three verdicts (plain strings in run.json)."""

    OK = "ok"
    DEGRADED = "degraded"
    LOST = "lost"


def characteristic_length_m(params: VehicleParams) -> float:
    """A vehicle's length (m): ``size.length`` from its vehicle file, or without a ``size``
    the span of its thruster layout or the side of the cube of water it displaces,
    whichever is larger.

    The presets all have a size: jmse2210 1.0 m, bluerov2-heavy 0.457 m, rexrov 2.56 m,
    videoray-pro3 0.30 m. Without one, the layout span tracks the hull length of
    thruster-driven vehicles (0.85, 0.38, 1.30, 0.27 m for the same four) and the cube root
    keeps a vehicle with thrusters bunched at the centre from looking tiny.
    """
    if params.size is not None:
        return params.size.length
    if params.has_thrusters:
        span = 2.0 * max(math.hypot(*thruster.position) for thruster in params.thrusters)
    else:  # its propeller and fins (their 3-D positions: the fins sit at the tail)
        inputs = params.six_dof_actuators.actuators
        span = 2.0 * max(math.hypot(*actuator.position) for actuator in inputs)
    cube = (params.mass / SEA_WATER_DENSITY) ** (1.0 / 3.0)
    return max(span, cube)


def relative_heading_turns(psi: np.ndarray, psi_ref: np.ndarray) -> float:
    """How far the vehicle's heading wound relative to the reference's over the run, in
    revolutions: the range of their difference divided by 2 pi. Both are continuous
    (unwrapped) in the log, so the difference counts every turn. Aligning with the
    reference from any start needs less than one."""
    if len(psi) == 0:
        return 0.0
    relative = np.asarray(psi) - np.asarray(psi_ref)
    return float((relative.max() - relative.min()) / (2.0 * math.pi))


@dataclass(frozen=True)
class RunFacts:
    """What the verdict looks at, gathered from a log by ``metrics.compute_metrics``."""

    sample_time: float
    max_error_after_transient_m: float | None  # None: the run ended within the transient
    # The same, leaving out the samples of a detour round an obstacle (metrics.detour_samples;
    # 0 when every sample after the transient is one), and the largest error among those
    # (None: no detour after the transient).
    max_tracking_error_after_transient_m: float | None
    max_detour_error_m: float | None
    max_heading_error_after_transient_rad: float | None
    max_abs_yaw_rate_after_transient: float | None
    max_abs_reference_yaw_rate: float
    reference_extent_m: float  # diagonal of the reference path's bounding box
    heading_turns: float  # relative_heading_turns over the whole run
    fallback_steps: int
    longest_fallback_streak: int
    relaxed_steps: int
    limit_violations: int
    rate_violations: int
    min_obstacle_clearance_m: float | None
    blocked_s: float = 0.0  # longest stop at an obstacle's keep-out edge (metrics.blocked_time)


def judge(facts: RunFacts, params: VehicleParams) -> tuple[str, str]:
    """``(verdict, reason)`` for a run of ``params`` (the controller's nominal vehicle)."""
    length = characteristic_length_m(params)
    lost, degraded = [], []

    lost_distance = _capped(LOST_LENGTHS * length, LOST_EXTENT_FRACTION, facts.reference_extent_m)
    degraded_distance = _capped(
        DEGRADED_LENGTHS * length, DEGRADED_EXTENT_FRACTION, facts.reference_extent_m
    )
    error = facts.max_error_after_transient_m
    tracking, detour = facts.max_tracking_error_after_transient_m, facts.max_detour_error_m
    away = "" if detour is None else " outside detours"
    if error is not None and error > lost_distance:
        lost.append(
            f"left the path: {error:.3g} m off after the transient (limit {lost_distance:.3g} m)"
        )
        if facts.blocked_s >= BLOCKED_S:
            lost.append(
                f"blocked: stopped at an obstacle's keep-out edge for {facts.blocked_s:.3g} s "
                "while the reference moved on"
            )
    elif tracking is not None and tracking > degraded_distance:
        degraded.append(
            f"position error {tracking:.3g} m after the transient{away} "
            f"(limit {degraded_distance:.3g} m)"
        )
    if facts.heading_turns >= 1.0:
        lost.append(f"spun: heading wound {facts.heading_turns:.1f} turns against the reference")
    streak_s = facts.longest_fallback_streak * facts.sample_time
    if streak_s >= LOST_FALLBACK_S:
        lost.append(f"no control for {streak_s:.3g} s (solver fallbacks in a row)")
    elif facts.fallback_steps:
        streak = facts.longest_fallback_streak
        degraded.append(f"{facts.fallback_steps} fallback steps (longest streak {streak})")
    if facts.relaxed_steps:
        degraded.append(f"{facts.relaxed_steps} steps with obstacle constraints relaxed")
    heading = facts.max_heading_error_after_transient_rad
    if not _underactuated(params) and heading is not None and heading > DEGRADED_HEADING_RAD:
        degraded.append(
            f"heading error {heading:.2f} rad after the transient (limit {DEGRADED_HEADING_RAD})"
        )
    yaw_rate = facts.max_abs_yaw_rate_after_transient
    # A vehicle with actuators: (fins) turns faster the faster it goes: no top yaw rate to
    # scale by, and no excursion rule (a spin is still lost, above).
    yaw_limit = (
        max(
            YAW_RATE_REFERENCE_FACTOR * facts.max_abs_reference_yaw_rate,
            YAW_RATE_CAPABILITY_FRACTION * top_yaw_rate(params),
        )
        if params.has_thrusters
        else math.inf
    )
    if yaw_rate is not None and yaw_rate > yaw_limit:
        degraded.append(
            f"yaw rate {yaw_rate:.2f} rad/s after the transient (limit {yaw_limit:.2f})"
        )
    if facts.limit_violations or facts.rate_violations:
        degraded.append(
            f"thrust limits violated ({facts.limit_violations} force, {facts.rate_violations} rate)"
        )
    clearance = facts.min_obstacle_clearance_m
    if clearance is not None and clearance < 0.0:
        degraded.append(f"touched an obstacle (clearance {clearance:.3g} m)")

    if lost:
        return Verdict.LOST, "; ".join(lost + degraded)
    if degraded:
        return Verdict.DEGRADED, "; ".join(degraded)
    if error is None:
        return Verdict.OK, "no trouble found (the run ended within the transient)"
    reason = (
        f"tracked within {tracking:.3g} m ({tracking / length:.2g} vehicle lengths) "
        f"after the transient{away}"
    )
    if detour is not None:
        reason += (
            f"; went round an obstacle up to {detour:.3g} m off the reference "
            f"(clearance {facts.min_obstacle_clearance_m:.3g} m)"
        )
    return Verdict.OK, reason


def _underactuated(params: VehicleParams) -> bool:
    """Whether it cannot push sideways: thrusters of allocation rank < 3, or actuators that
    make no sway force at rest (a propeller and fins: a torpedo crabs into a current)."""
    if params.has_thrusters:
        return params.underactuated
    return not params.six_dof_actuators.pushes_sideways


def _capped(distance: float, fraction: float, extent: float) -> float:
    """``distance``, but no more than ``fraction`` of a reference path's size (a path that
    stays put, extent 0, is judged by the vehicle's size alone)."""
    return min(distance, fraction * extent) if extent > 0.0 else distance
