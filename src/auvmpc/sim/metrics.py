"""Run metrics: pure functions of a SimLog (names and units per interfaces.md)."""

from __future__ import annotations

import math

import numpy as np

from auvmpc.controllers.base import ControlStatus
from auvmpc.sim.log import SimLog
from auvmpc.sim.verdict import RunFacts, judge, relative_heading_turns
from auvmpc.vehicle import VehicleParams

__all__ = [
    "compute_metrics",
    "compute_six_dof_metrics",
    "position_error",
    "heading_error",
    "path_length",
    "time_lost",
    "LIMIT_TOLERANCE_N",
    "MARGIN_TOLERANCE_M",
]

# Slack for float round-off when checking hard limits: far below any physical meaning.
LIMIT_TOLERANCE_N = 1e-9
# A vehicle riding on its obstacle margin is not inside it (m): the constraints hold at the
# samples, and the plant drifts ~1 mm past them in between (measured on the encounters).
MARGIN_TOLERANCE_M = 0.01
# The reference is "not moving" below this speed (m/s): no along-track direction to lag on.
_MIN_REFERENCE_SPEED_M_PER_S = 0.01


def position_error(log: SimLog) -> np.ndarray:
    """(N+1,) Euclidean distance to the reference position (m)."""
    return np.hypot(*(log.state[:, :2] - log.reference[:, :2]).T)


def heading_error(log: SimLog) -> np.ndarray:
    """(N+1,) heading error wrapped to (-pi, pi] (rad)."""
    return wrap_angle(log.state[:, 2] - log.reference[:, 2])


def wrap_angle(angle: np.ndarray) -> np.ndarray:
    """Wrap to (-pi, pi]."""
    return np.pi - np.mod(np.pi - angle, 2.0 * np.pi)


def thrust_increments(log: SimLog) -> np.ndarray:
    """(N, n) change of each thruster's force at every sample, from F(-1)."""
    return np.diff(np.vstack([log.initial_thrust, log.thrust]), axis=0)


def compute_metrics(
    log: SimLog,
    limits: VehicleParams,
    transient_s: float = 20.0,
    obstacle_margin_m: float = 0.0,
) -> dict[str, float | int | str | None]:
    """All interfaces.md metrics, plus steady-state errors after ``transient_s``.

    ``obstacle_margin_m`` is the clearance the controller was asked to keep beyond the
    vehicle disc (``controller.obstacle_margin``): ``time_inside_margin_s`` counts the
    samples closer than that to an obstacle.

    ``limits`` supplies the hard thrust and rate limits the log is checked against
    (the controller's nominal vehicle: the limits are the hardware's) and the vehicle
    size the verdict scales with (``auvmpc.sim.verdict``).
    """
    error = position_error(log)
    heading = heading_error(log)
    increments = thrust_increments(log)
    max_step = limits.thrust_rate_limit * log.sample_time
    lower, upper = limits.thrust_limits
    force_violations = (log.thrust < lower - LIMIT_TOLERANCE_N) | (
        log.thrust > upper + LIMIT_TOLERANCE_N
    )
    rate_violations = np.abs(increments) > max_step + LIMIT_TOLERANCE_N
    solve = log.solve_ms
    steady = log.t >= transient_s - 1e-9
    clearance = log.clearance_m
    fallback = np.array([status == ControlStatus.FALLBACK for status in log.status], dtype=bool)
    relaxed_steps = sum(status == ControlStatus.RELAXED for status in log.status)
    yaw_rate = np.abs(log.state[:, 5])
    heading_after = np.abs(heading[steady])
    metrics = {
        "rms_position_error_m": _rms(error),
        "max_position_error_m": float(error.max()),
        "final_position_error_m": float(error[-1]),
        "rms_heading_error_rad": _rms(heading),
        "max_abs_thrust_N": float(np.abs(log.thrust).max()) if log.steps else 0.0,
        "max_abs_thrust_rate_N_per_s": float(np.abs(increments).max() / log.sample_time)
        if log.steps
        else 0.0,
        "thrust_limit_violations": int(force_violations.sum()),
        "thrust_rate_violations": int(rate_violations.sum()),
        "min_obstacle_clearance_m": float(clearance.min())
        if np.isfinite(clearance).any()
        else None,
        "time_inside_margin_s": float(
            np.sum(clearance < obstacle_margin_m - MARGIN_TOLERANCE_M) * log.sample_time
        )
        if np.isfinite(clearance).any()
        else None,
        "detour_m": path_length(log.state[:, :2]) - path_length(log.reference[:, :2]),
        "time_lost_s": time_lost(log),
        "solve_ms_median": _percentile(solve, 50),
        "solve_ms_p99": _percentile(solve, 99),
        "solve_ms_max": float(solve.max()) if len(solve) else 0.0,
        "thrust_effort_N2s": float(np.sum(log.thrust**2) * log.sample_time),
        **tightening_metrics(log),
        "solver_failures": int(fallback.sum()),
        "fallback_steps": int(fallback.sum()),
        "relaxed_steps": int(relaxed_steps),
        "longest_fallback_streak": longest_run(fallback),
        "max_abs_yaw_rate_rad_per_s": float(yaw_rate.max()),
        "transient_s": float(transient_s),
        "rms_position_error_after_transient_m": _rms(error[steady]),
        "max_position_error_after_transient_m": float(error[steady].max())
        if steady.any()
        else None,
        "rms_heading_error_after_transient_rad": _rms(heading[steady]),
        "max_heading_error_after_transient_rad": float(heading_after.max())
        if steady.any()
        else None,
    }
    facts = RunFacts(
        sample_time=log.sample_time,
        max_error_after_transient_m=metrics["max_position_error_after_transient_m"],
        max_heading_error_after_transient_rad=metrics["max_heading_error_after_transient_rad"],
        max_abs_yaw_rate_after_transient=float(yaw_rate[steady].max()) if steady.any() else None,
        max_abs_reference_yaw_rate=float(np.abs(log.reference[:, 5]).max()),
        reference_extent_m=float(np.hypot(*np.ptp(log.reference[:, :2], axis=0))),
        heading_turns=relative_heading_turns(log.state[:, 2], log.reference[:, 2]),
        fallback_steps=metrics["fallback_steps"],
        longest_fallback_streak=metrics["longest_fallback_streak"],
        relaxed_steps=metrics["relaxed_steps"],
        limit_violations=metrics["thrust_limit_violations"],
        rate_violations=metrics["thrust_rate_violations"],
        min_obstacle_clearance_m=metrics["min_obstacle_clearance_m"],
    )
    metrics["verdict"], metrics["verdict_reason"] = judge(facts, limits)
    return metrics


def path_length(points: np.ndarray) -> float:
    """Length of the polyline through ``points`` (N+1, 2) (m)."""
    return float(np.sum(np.hypot(*np.diff(points, axis=0).T)))


def time_lost(log: SimLog) -> float:
    """Largest along-track lag behind the reference, in seconds of the reference's own
    speed (s); 0 when never behind or when the reference does not move.

    The lag at sample k is (p_ref - p) . t_ref, t_ref the reference's unit velocity; it is
    divided by the reference speed there (samples slower than 1 cm/s are left out).
    """
    reference = log.reference
    velocity = np.column_stack(
        [
            np.cos(reference[:, 2]) * reference[:, 3] - np.sin(reference[:, 2]) * reference[:, 4],
            np.sin(reference[:, 2]) * reference[:, 3] + np.cos(reference[:, 2]) * reference[:, 4],
        ]
    )
    speed = np.hypot(*velocity.T)
    moving = speed > _MIN_REFERENCE_SPEED_M_PER_S
    if not moving.any():
        return 0.0
    lag = np.einsum("nk,nk->n", reference[moving, :2] - log.state[moving, :2], velocity[moving])
    return float(max(0.0, np.max(lag / speed[moving] ** 2)))


def longest_run(flags: np.ndarray) -> int:
    """Length of the longest stretch of consecutive True values."""
    longest = current = 0
    for flag in flags:
        current = current + 1 if flag else 0
        longest = max(longest, current)
    return longest


def _rms(values: np.ndarray) -> float | None:
    return float(math.sqrt(np.mean(values**2))) if len(values) else None


def _percentile(values: np.ndarray, q: float) -> float:
    return float(np.percentile(values, q)) if len(values) else 0.0


# A 6-DOF run whose depth stays this far from the reference after the transient, or whose roll
# or pitch passes this angle, is at best degraded (the horizontal verdict cannot see either).
DEGRADED_DEPTH_ERROR_M = 0.5
DEGRADED_TILT_RAD = math.radians(30.0)


def compute_six_dof_metrics(
    log, limits: VehicleParams, transient_s: float = 20.0, obstacle_margin_m: float = 0.0
) -> dict[str, float | int | str | None]:
    """:func:`compute_metrics` of the horizontal part, then every thruster's limits (vertical
    ones against the ``heave`` section's), depth, roll and pitch.

    Parameters
    ----------
    log : auvmpc.sim.six_dof_loop.SixDofLog
    limits : VehicleParams
        The nominal vehicle, with ``six_dof`` and ``heave`` sections.
    """
    from auvmpc.sim.six_dof_loop import ThrustMapping

    metrics = compute_metrics(log.horizontal(), limits, transient_s, obstacle_margin_m)
    mapping = ThrustMapping(limits, log.sample_time)
    increments = thrust_increments(log)
    force = (log.thrust < mapping.lower - LIMIT_TOLERANCE_N) | (
        log.thrust > mapping.upper + LIMIT_TOLERANCE_N
    )
    rate = np.abs(increments) > mapping.max_step + LIMIT_TOLERANCE_N
    steady = log.t >= transient_s - 1e-9
    depth_error = log.full_state[:, 2] - log.depth_reference[:, 0]
    roll, pitch = np.abs(log.full_state[:, 3]), np.abs(log.full_state[:, 4])
    metrics.update(
        {
            "thrust_limit_violations": int(force.sum()),
            "thrust_rate_violations": int(rate.sum()),
            "max_abs_thrust_N": float(np.abs(log.thrust).max()) if log.steps else 0.0,
            "max_abs_thrust_rate_N_per_s": float(np.abs(increments).max() / log.sample_time)
            if log.steps
            else 0.0,
            "thrust_effort_N2s": float(np.sum(log.thrust**2) * log.sample_time),
            "saturated_thrust_commands": int(log.saturated.sum()),
            "rms_depth_error_m": _rms(depth_error),
            "max_depth_error_m": float(np.abs(depth_error).max()),
            "depth_rms_error_after_transient_m": _rms(depth_error[steady]),
            "max_depth_error_after_transient_m": float(np.abs(depth_error[steady]).max())
            if steady.any()
            else None,
            "max_abs_roll_rad": float(roll.max()),
            "max_abs_pitch_rad": float(pitch.max()),
            "depth_solve_ms_median": _percentile(log.depth_solve_ms, 50),
            "depth_solve_ms_max": float(log.depth_solve_ms.max()) if log.steps else 0.0,
            "depth_fallback_steps": sum(s == ControlStatus.FALLBACK for s in log.depth_status),
        }
    )
    trouble = []
    if metrics["thrust_limit_violations"] or metrics["thrust_rate_violations"]:
        trouble.append(
            f"thrust limits violated ({metrics['thrust_limit_violations']} force, "
            f"{metrics['thrust_rate_violations']} rate)"
        )
    depth_after = metrics["max_depth_error_after_transient_m"]
    if depth_after is not None and depth_after > DEGRADED_DEPTH_ERROR_M:
        trouble.append(f"depth error {depth_after:.3g} m after the transient")
    tilt = max(metrics["max_abs_roll_rad"], metrics["max_abs_pitch_rad"])
    if tilt > DEGRADED_TILT_RAD:
        trouble.append(f"tilted {math.degrees(tilt):.0f} deg")
    if trouble and metrics["verdict"] == "ok":
        metrics["verdict"], metrics["verdict_reason"] = "degraded", "; ".join(trouble)
    elif trouble:
        metrics["verdict_reason"] = "; ".join([str(metrics["verdict_reason"]), *trouble])
    return metrics


def tightening_metrics(log: SimLog) -> dict[str, float]:
    """What the robust tightening (ocp/tightening.py) took, all zero for a nominal controller:
    the largest and the mean (over the samples with obstacle rows) obstacle back-off, and the
    largest and mean fraction of a thruster's range given up."""
    obstacle, thrust = log.backoff[:, 0], log.backoff[:, 1]
    with_rows = obstacle[obstacle > 0.0]
    return {
        "max_obstacle_backoff_m": float(obstacle.max(initial=0.0)),
        "mean_obstacle_backoff_m": float(with_rows.mean()) if len(with_rows) else 0.0,
        "max_thrust_backoff_fraction": float(thrust.max(initial=0.0)),
        "mean_thrust_backoff_fraction": float(thrust.mean()) if len(thrust) else 0.0,
    }
