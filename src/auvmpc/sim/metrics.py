"""Run metrics: pure functions of a SimLog (names and units per interfaces.md).

Every kind of run gets the same actuation and solver metrics (:func:`actuation_metrics`:
limit and rate violations, fallbacks, solve times), then its own: tracking errors and the
verdict of a horizontal run (:func:`compute_metrics`), depth, roll and pitch of a 6-DOF one
(:func:`compute_six_dof_metrics`), the step response of a depth one
(:func:`compute_depth_metrics`, docs/depth.md).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike
from scipy.spatial import cKDTree

from auvmpc.angles import wrap_angle
from auvmpc.controllers.base import ControlStatus
from auvmpc.controllers.schedule import rows_at
from auvmpc.environment.obstacles import ObstacleConfig
from auvmpc.models.layout import DEPTH, HORIZONTAL
from auvmpc.models.six_dof import SIX_DOF
from auvmpc.models.vehicle import HeaveParams, VehicleParams
from auvmpc.references import DepthStepConfig, Reference
from auvmpc.sim.faults import Fault, acting_sample
from auvmpc.sim.log import SimLog
from auvmpc.sim.verdict import RunFacts, judge, relative_heading_turns

__all__ = [
    "STEP_METRIC_KEYS",
    "actuation_metrics",
    "compute_depth_metrics",
    "compute_metrics",
    "compute_six_dof_metrics",
    "cross_track_error",
    "fault_metrics",
    "six_dof_fault_metrics",
    "reference_as_flown",
    "input_limits",
    "reference_path",
    "detour_samples",
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
# A vehicle "stopped at an obstacle" (the verdict's blocked time): within this of its keep-out
# margin (m; the controllers ride the margin, a detour passes it at speed) and making good
# under this share of the reference's speed over BLOCKED_WINDOW_S (its speed through the
# water can be high: a vehicle wedged between two discs pushes back and forth). Case 81 of
# the hard survey sat at 0.13-0.20 m clearance (margin 0.16 m) within 0.1 m of one point
# for about 40 s (33.5 s by this measure), at 0.1-0.8 m/s through the water.
BLOCKED_BAND_M = 0.1
BLOCKED_SPEED_FRACTION = 0.1
BLOCKED_WINDOW_S = 5.0
# A detour round an obstacle (detour_samples): the vehicle within this many keep-out radii of
# the keep-out disc's edge, and off the reference by at most this many keep-out diameters.
# Going round a disc that the reference crosses takes the vehicle up to a radius to the side
# and, on the longer way round, behind: on paper-obstacles (keep-out radius 1.6 m) at most
# 2.12 m off. The MPC starts turning away before it is a radius from the edge: with 1.0 the
# start of the turn (0.98 m off, 1.58 m from the edge, obstacle_margin 0) was counted as
# tracking error; with 1.5 the largest error left is 0.44-0.47 m, away from them, and
# sluggish controllers (R 5, Q 0.02 on x, y) stay degraded.
DETOUR_REACH_RADII = 1.5
DETOUR_MAX_DIAMETERS = 1.0
# How many points per control sample the cross-track metric's path has (reference_path).
PATH_SUBSAMPLES = 20
# Where a horizontal log's columns are (auvmpc.models.layout).
_POSITION, _HEADING, _YAW_RATE = HORIZONTAL.position, HORIZONTAL.heading, HORIZONTAL.index("r")


def position_error(log: SimLog) -> np.ndarray:
    """(N+1,) Euclidean distance to the reference position (m)."""
    return np.hypot(*(log.state[:, _POSITION] - log.reference[:, _POSITION]).T)


def heading_error(log: SimLog) -> np.ndarray:
    """(N+1,) heading error wrapped to (-pi, pi] (rad)."""
    return wrap_angle(log.state[:, _HEADING] - log.reference[:, _HEADING])


def thrust_increments(log: SimLog) -> np.ndarray:
    """(N, n) change of each thruster's force at every sample, from F(-1)."""
    return np.diff(np.vstack([log.initial_thrust, log.thrust]), axis=0)


def actuation_metrics(
    log: SimLog,
    thrust_limits: tuple[ArrayLike, ArrayLike],
    thrust_rate_limit: ArrayLike,
) -> dict[str, float | int]:
    """What every kind of run reports of its thrust and its controller: the largest thrust and
    rate, hard-limit and rate-limit violations (against ``thrust_limits`` (N) and
    ``thrust_rate_limit`` (N/s), one for all thrusters or one per thruster), effort, solve
    times, fallback and relaxed steps."""
    increments = thrust_increments(log)
    max_step = thrust_rate_limit * log.sample_time
    lower, upper = thrust_limits
    force_violations = (log.thrust < lower - LIMIT_TOLERANCE_N) | (
        log.thrust > upper + LIMIT_TOLERANCE_N
    )
    rate_violations = np.abs(increments) > max_step + LIMIT_TOLERANCE_N
    solve = log.solve_ms
    # No optimiser in control: the previous plan's move, or the shell's feedback.
    unsolved = (ControlStatus.FALLBACK, ControlStatus.RECOVERY)
    fallback = np.array([status in unsolved for status in log.status], dtype=bool)
    relaxed_steps = sum(status == ControlStatus.RELAXED for status in log.status)
    recovery_steps = sum(status == ControlStatus.RECOVERY for status in log.status)
    return {
        "max_abs_thrust_N": float(np.abs(log.thrust).max()) if log.steps else 0.0,
        "max_abs_thrust_rate_N_per_s": float(np.abs(increments).max() / log.sample_time)
        if log.steps
        else 0.0,
        "thrust_limit_violations": int(force_violations.sum()),
        "thrust_rate_violations": int(rate_violations.sum()),
        "solve_ms_median": _percentile(solve, 50),
        "solve_ms_p99": _percentile(solve, 99),
        "solve_ms_max": float(solve.max()) if len(solve) else 0.0,
        "thrust_effort_N2s": float(np.sum(log.thrust**2) * log.sample_time),
        "solver_failures": int(fallback.sum()),
        "fallback_steps": int(fallback.sum()),
        "relaxed_steps": int(relaxed_steps),
        "recovery_steps": int(recovery_steps),
        "longest_fallback_streak": longest_run(fallback),
    }


def input_limits(
    limits: VehicleParams, count: int
) -> tuple[tuple[ArrayLike, ArrayLike], ArrayLike]:
    """The hard limits of a log's first ``count`` inputs, as :func:`actuation_metrics` takes
    them: the thrusters' (N, N/s), or a vehicle with ``actuators:``'s, each input's own (rpm,
    deg and per second)."""
    if limits.has_thrusters:
        return limits.thrust_limits, limits.thrust_rate_limit
    bounds = limits.six_dof_actuators.limits
    return (bounds.lower[:count], bounds.upper[:count]), bounds.rate[:count]


def compute_metrics(
    log: SimLog,
    limits: VehicleParams,
    transient_s: float = 20.0,
    obstacle_margin_m: float = 0.0,
    obstacles: Sequence[ObstacleConfig] = (),
    vehicle_radius_m: float = 0.0,
) -> dict[str, float | int | str | None]:
    """All interfaces.md metrics, plus steady-state errors after ``transient_s``.

    ``obstacle_margin_m`` is the clearance the controller was asked to keep beyond the
    vehicle disc (``controller.obstacle_margin``): ``time_inside_margin_s`` counts the
    samples closer than that to an obstacle. ``obstacles`` (the scenario's) and
    ``vehicle_radius_m`` (``controller.vehicle_radius``) tell the verdict which position
    error is a detour round an obstacle (:func:`detour_samples`).

    ``limits`` supplies the hard thrust and rate limits the log is checked against
    (the controller's nominal vehicle: the limits are the hardware's) and the vehicle
    size the verdict scales with (``auvmpc.sim.verdict``).
    """
    error = position_error(log)
    heading = heading_error(log)
    common = actuation_metrics(log, *input_limits(limits, log.n_thrusters))
    steady = log.t >= transient_s - 1e-9
    detour = detour_samples(log, error, obstacles, vehicle_radius_m + obstacle_margin_m)
    tracking = steady & ~detour
    clearance = log.clearance_m
    yaw_rate = np.abs(log.state[:, _YAW_RATE])
    heading_after = np.abs(heading[steady])
    metrics = {
        "rms_position_error_m": _rms(error),
        "max_position_error_m": float(error.max()),
        "final_position_error_m": float(error[-1]),
        "rms_heading_error_rad": _rms(heading),
        **_pick(
            common,
            "max_abs_thrust_N",
            "max_abs_thrust_rate_N_per_s",
            "thrust_limit_violations",
            "thrust_rate_violations",
        ),
        "min_obstacle_clearance_m": float(clearance.min())
        if np.isfinite(clearance).any()
        else None,
        "time_inside_margin_s": float(
            np.sum(clearance < obstacle_margin_m - MARGIN_TOLERANCE_M) * log.sample_time
        )
        if np.isfinite(clearance).any()
        else None,
        "detour_m": path_length(log.state[:, _POSITION]) - path_length(log.reference[:, _POSITION]),
        "time_lost_s": time_lost(log),
        **_pick(common, "solve_ms_median", "solve_ms_p99", "solve_ms_max", "thrust_effort_N2s"),
        **tightening_metrics(log),
        **_pick(
            common,
            "solver_failures",
            "fallback_steps",
            "relaxed_steps",
            "recovery_steps",
            "longest_fallback_streak",
        ),
        "max_abs_yaw_rate_rad_per_s": float(yaw_rate.max()),
        "transient_s": float(transient_s),
        "rms_position_error_after_transient_m": _rms(error[steady]),
        "max_position_error_after_transient_m": float(error[steady].max())
        if steady.any()
        else None,
        "max_tracking_error_after_transient_m": float(error[tracking].max(initial=0.0))
        if steady.any()
        else None,
        "rms_heading_error_after_transient_rad": _rms(heading[steady]),
        "max_heading_error_after_transient_rad": float(heading_after.max())
        if steady.any()
        else None,
    }
    detour_error = error[steady & detour]
    facts = RunFacts(
        sample_time=log.sample_time,
        max_error_after_transient_m=metrics["max_position_error_after_transient_m"],
        max_tracking_error_after_transient_m=metrics["max_tracking_error_after_transient_m"],
        max_detour_error_m=float(detour_error.max()) if len(detour_error) else None,
        max_heading_error_after_transient_rad=metrics["max_heading_error_after_transient_rad"],
        max_abs_yaw_rate_after_transient=float(yaw_rate[steady].max()) if steady.any() else None,
        max_abs_reference_yaw_rate=float(np.abs(log.reference[:, _YAW_RATE]).max()),
        reference_extent_m=float(np.hypot(*np.ptp(log.reference[:, _POSITION], axis=0))),
        heading_turns=relative_heading_turns(log.state[:, _HEADING], log.reference[:, _HEADING]),
        fallback_steps=metrics["fallback_steps"],
        longest_fallback_streak=metrics["longest_fallback_streak"],
        relaxed_steps=metrics["relaxed_steps"],
        limit_violations=metrics["thrust_limit_violations"],
        rate_violations=metrics["thrust_rate_violations"],
        min_obstacle_clearance_m=metrics["min_obstacle_clearance_m"],
        blocked_s=blocked_time(log, obstacle_margin_m),
    )
    metrics["verdict"], metrics["verdict_reason"] = judge(facts, limits)
    return metrics


def detour_samples(
    log: SimLog, error: np.ndarray, obstacles: Sequence[ObstacleConfig], keep_out_beyond_m: float
) -> np.ndarray:
    """(N+1,) True at the samples of a detour round an obstacle: position error that going
    round the obstacle explains, judged by the clearance rather than as tracking error.

    A detour round obstacle o, whose keep-out disc has radius R = o's radius +
    ``keep_out_beyond_m`` (the vehicle's radius and the obstacle margin), is a stretch of
    consecutive samples at which o exists, the vehicle is within DETOUR_REACH_RADII x R of
    that disc's edge and at most DETOUR_MAX_DIAMETERS x 2 R from the reference, and at one of
    which the reference is inside the disc: the obstacle was on the path and the vehicle went
    round it. A vehicle off a reference that passes beside an obstacle, or off by more than
    the disc's width, or farther from the obstacle than that, is tracking badly. ``error``:
    the log's :func:`position_error`.
    """
    vehicle, reference = log.state[:, _POSITION], log.reference[:, _POSITION]
    detour = np.zeros(len(log.t), dtype=bool)
    for obstacle in obstacles:
        exists = np.array([obstacle.exists_at(t) for t in log.t], dtype=bool)
        centre = np.array([obstacle.center_at(t) for t in log.t]).reshape(-1, 2)
        keep_out = obstacle.radius + keep_out_beyond_m
        vehicle_gap = np.hypot(*(vehicle - centre).T) - keep_out
        reference_gap = np.hypot(*(reference - centre).T) - keep_out
        around = (
            exists
            & (vehicle_gap <= DETOUR_REACH_RADII * keep_out)
            & (error <= DETOUR_MAX_DIAMETERS * 2.0 * keep_out)
        )
        # Number the stretches of `around`; keep those with the reference inside the disc.
        stretch = np.cumsum(~around)
        crossed = np.unique(stretch[around & (reference_gap < 0.0)])
        detour |= around & np.isin(stretch, crossed)
    return detour


def blocked_time(log: SimLog, obstacle_margin_m: float) -> float:
    """Longest time (s) the vehicle stood at an obstacle's keep-out edge while the reference
    moved on: clearance within BLOCKED_BAND_M of the margin, and its position over the
    BLOCKED_WINDOW_S around the sample moving at under BLOCKED_SPEED_FRACTION of the
    reference's speed. 0 without obstacles."""
    clearance = log.clearance_m
    if not np.isfinite(clearance).any():
        return 0.0
    samples = len(clearance)
    half = max(1, round(0.5 * BLOCKED_WINDOW_S / log.sample_time))
    k = np.arange(samples)
    before, after = np.maximum(k - half, 0), np.minimum(k + half, samples - 1)
    position = log.state[:, _POSITION]
    span = np.maximum(after - before, 1) * log.sample_time
    made_good = np.hypot(*(position[after] - position[before]).T) / span
    reference_speed = np.hypot(*log.reference[:, HORIZONTAL.body_velocity].T)
    with np.errstate(invalid="ignore"):  # NaN clearance: no obstacle seen at that sample
        at_edge = clearance <= obstacle_margin_m + BLOCKED_BAND_M
    stopped = (reference_speed > _MIN_REFERENCE_SPEED_M_PER_S) & (
        made_good < BLOCKED_SPEED_FRACTION * reference_speed
    )
    return longest_run(at_edge & stopped) * log.sample_time


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
    psi = reference[:, _HEADING]
    u, v = reference[:, HORIZONTAL.body_velocity].T
    velocity = np.column_stack(
        [np.cos(psi) * u - np.sin(psi) * v, np.sin(psi) * u + np.cos(psi) * v]
    )
    speed = np.hypot(*velocity.T)
    moving = speed > _MIN_REFERENCE_SPEED_M_PER_S
    if not moving.any():
        return 0.0
    ahead = reference[moving, _POSITION] - log.state[moving, _POSITION]
    lag = np.einsum("nk,nk->n", ahead, velocity[moving])
    return float(max(0.0, np.max(lag / speed[moving] ** 2)))


def longest_run(flags: np.ndarray) -> int:
    """Length of the longest stretch of consecutive True values."""
    longest = current = 0
    for flag in flags:
        current = current + 1 if flag else 0
        longest = max(longest, current)
    return longest


def fault_metrics(
    log: SimLog, transient_s: float, faults: Sequence[Fault]
) -> dict[str, float | int | None]:
    """How the run fared across its first actuator fault (``faults``: the scenario's, one per
    actuator; ``log``: the whole run's, whose ``effectiveness`` is what the controller
    assumed), timed from the sample the fault first acts on.

    ``fault_time_s``: that sample's time. ``rms_before_fault_m``: the position error's RMS from
    the transient to that sample (None when the fault comes first); ``rms_after_fault_m``:
    from it to the end, its transient included (what the fault cost).
    ``fault_detection_delay_s``: from it until the controller first assumed less of that
    actuator (told by the mission, or found by the fault detector; 0 for a declared fault),
    None if it never did. ``false_fault_detections``: inputs the controller assumed weaker
    before a fault of theirs acted, or with none, each counted once.
    """
    first = min(faults, key=lambda fault: fault.at)
    error = position_error(log.horizontal())
    start, before, reached = _fault_windows(log, transient_s, faults)
    weaker = log.effectiveness < 1.0  # (N, n): what the controller assumed per command
    index = log.input_names.index(first.actuator)
    told = np.flatnonzero(weaker[start:, index])
    failed_from = {
        log.input_names.index(fault.actuator): acting_sample(log.t, fault.at) for fault in faults
    }
    commands = np.arange(log.steps)
    false = sum(
        bool(np.any(weaker[:, i] & (commands < failed_from.get(i, log.steps))))
        for i in range(log.n_thrusters)
    )
    fault_time = float(log.t[start])
    return {
        "fault_time_s": fault_time,
        "fault_detection_delay_s": float(log.t[start + told[0]] - fault_time)
        if len(told)
        else None,
        "false_fault_detections": int(false),
        "rms_before_fault_m": _rms(error[before]),
        "rms_after_fault_m": _rms(error[reached]),
    }


def six_dof_fault_metrics(
    log: SimLog, transient_s: float, faults: Sequence[Fault], path: np.ndarray
) -> dict[str, float | None]:
    """What a 6-DOF run's first fault cost in depth and off the path (a torpedo follows a
    path: its lag along it is not a tracking error), over :func:`fault_metrics`'s windows:
    ``depth_rms_before_fault_m``, ``depth_rms_after_fault_m``,
    ``cross_track_rms_before_fault_m``, ``cross_track_rms_after_fault_m`` (``path``: the
    reference's horizontal path, densely, :func:`reference_path`)."""
    _, before, reached = _fault_windows(log, transient_s, faults)
    depth_error = log.column("z") - log.column("z_ref")
    cross_track = cross_track_error(log.state[:, SIX_DOF.span("x", "y")], path)
    return {
        "depth_rms_before_fault_m": _rms(depth_error[before]),
        "depth_rms_after_fault_m": _rms(depth_error[reached]),
        "cross_track_rms_before_fault_m": _rms(cross_track[before]),
        "cross_track_rms_after_fault_m": _rms(cross_track[reached]),
    }


def _fault_windows(
    log: SimLog, transient_s: float, faults: Sequence[Fault]
) -> tuple[int, np.ndarray, np.ndarray]:
    """The sample the first of ``faults`` acts on, and the rows before it (from the
    transient on) and from it to the end."""
    start = acting_sample(log.t, min(fault.at for fault in faults))
    reached = np.arange(len(log.t)) >= start
    return start, (log.t >= transient_s - 1e-9) & ~reached, reached


def _pick(metrics: dict, *names: str) -> dict:
    """``names`` of ``metrics``, in that order (run.json keeps its key order)."""
    return {name: metrics[name] for name in names}


def _rms(values: np.ndarray) -> float | None:
    return float(math.sqrt(np.mean(values**2))) if len(values) else None


def _percentile(values: np.ndarray, q: float) -> float:
    return float(np.percentile(values, q)) if len(values) else 0.0


# A 6-DOF run whose depth stays this far from the reference after the transient, or whose roll
# or pitch passes this angle, is at best degraded (the horizontal verdict cannot see either).
DEGRADED_DEPTH_ERROR_M = 0.5
DEGRADED_TILT_RAD = math.radians(30.0)


def compute_six_dof_metrics(
    log,
    limits: VehicleParams,
    transient_s: float = 20.0,
    *surroundings: Any,
    path: np.ndarray | None = None,
) -> dict[str, float | int | str | None]:
    """:func:`compute_metrics` of the horizontal part, then every input's limits (vertical
    thrusters against the ``heave`` section's; a propeller's and fins' in rpm and deg), depth,
    roll, pitch and the distance to the path.

    Parameters
    ----------
    log : auvmpc.sim.log.SimLog
        A 6-DOF run's (``SIX_DOF_LOG``).
    limits : VehicleParams
        The nominal vehicle, with a ``six_dof`` section.
    surroundings
        :func:`compute_metrics`'s obstacle margin, obstacles and vehicle radius.
    path : numpy.ndarray, shape (M, 2), optional
        The reference's horizontal path, densely (:func:`reference_path`); None: the log's
        reference rows.

    A vehicle with ``actuators:`` has no thrust in N: its ``max_abs_thrust_N``,
    ``max_abs_thrust_rate_N_per_s`` and ``thrust_effort_N2s`` are None, and its
    ``thrust_limit_violations`` and ``thrust_rate_violations`` count its inputs against their
    own limits (the ``actuator_*`` ones, which every 6-DOF run has).
    """
    metrics = compute_metrics(log.horizontal(), limits, transient_s, *surroundings)
    bounds = limits.six_dof_actuators.limits
    every_thruster = actuation_metrics(log, (bounds.lower, bounds.upper), bounds.rate)
    if not limits.has_thrusters:
        for name in ("max_abs_thrust_N", "max_abs_thrust_rate_N_per_s", "thrust_effort_N2s"):
            every_thruster[name] = None
    steady = log.t >= transient_s - 1e-9
    horizontal = log.state[:, SIX_DOF.span("x", "y")]
    reference_rows = log.reference[:, _POSITION]
    cross_track = cross_track_error(horizontal, reference_rows if path is None else path)
    depth_error = log.column("z") - log.column("z_ref")
    roll, pitch = (np.abs(log.state[:, SIX_DOF.index(name)]) for name in ("phi", "theta"))
    depth_solve_ms = log.diagnostics["depth_solve_ms"]
    metrics.update(
        {
            **_pick(
                every_thruster,
                "thrust_limit_violations",
                "thrust_rate_violations",
                "max_abs_thrust_N",
                "max_abs_thrust_rate_N_per_s",
                "thrust_effort_N2s",
            ),
            "saturated_thrust_commands": int(log.diagnostics["saturated"].sum()),
            "rms_depth_error_m": _rms(depth_error),
            "max_depth_error_m": float(np.abs(depth_error).max()),
            "depth_rms_error_after_transient_m": _rms(depth_error[steady]),
            "max_depth_error_after_transient_m": float(np.abs(depth_error[steady]).max())
            if steady.any()
            else None,
            "max_abs_roll_rad": float(roll.max()),
            "max_abs_pitch_rad": float(pitch.max()),
            "depth_solve_ms_median": _percentile(depth_solve_ms, 50),
            "depth_solve_ms_max": float(depth_solve_ms.max()) if log.steps else 0.0,
            "depth_fallback_steps": sum(
                s == ControlStatus.FALLBACK for s in log.diagnostics["depth_status"]
            ),
            # every input against its own limits, in its own units (N, rpm, deg)
            "actuator_limit_violations": every_thruster["thrust_limit_violations"],
            "actuator_rate_violations": every_thruster["thrust_rate_violations"],
            "cross_track_rms_after_transient_m": _rms(cross_track[steady]),
            "max_schedule_lag_s": float(schedule_lag(log).max()),
        }
    )
    trouble = []
    if metrics["max_schedule_lag_s"] >= log.sample_time:
        trouble.append(
            f"flew {metrics['max_schedule_lag_s']:.3g} s behind the mission's schedule "
            "(slowed to hold its depth)"
        )
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


def schedule_lag(log: SimLog) -> np.ndarray:
    """(N+1,) how far behind the mission's clock the controller flew the reference at each
    sample (s; controllers/schedule.py): 0 throughout for a log without the column, and the
    final row's the last command's."""
    if "schedule_lag_s" not in log.format.diagnostic_fields or not log.steps:
        return np.zeros(len(log.t))
    lag = np.ravel(log.diagnostics["schedule_lag_s"])
    return np.append(lag, lag[-1])


def reference_as_flown(log: SimLog) -> SimLog:
    """``log`` with its reference rows as the controller flew them, each sample's taken at
    t - :func:`schedule_lag` (linear in between, the heading unwrapped): a vehicle that slowed
    for a fault is judged against the path it followed on its own, later, clock, and its lag
    is reported beside (``max_schedule_lag_s``); the log itself where it never slowed."""
    lag = schedule_lag(log)
    if not lag.any():
        return log
    flown = log.first(len(log.t))
    flown.reference = rows_at(log.reference, log.t, log.t - lag, _HEADING)
    return flown


def reference_path(reference: Reference, end_s: float, sample_time: float) -> np.ndarray:
    """(M, 2) the reference's horizontal path ``[x, y]`` (m) from t = 0 to ``end_s``,
    sampled ``PATH_SUBSAMPLES`` times per control sample: at 1.5 m/s and 0.2 s, 1.5 cm
    apart, whose chords stray 2 micrometres from a 15 m turn."""
    count = max(2, int(round(end_s / sample_time)) * PATH_SUBSAMPLES + 1)
    return reference.positions(np.linspace(0.0, end_s, count))


def cross_track_error(position: np.ndarray, path: np.ndarray) -> np.ndarray:
    """(N,) horizontal distance (m) from each ``position`` (N, 2) to the polyline ``path``
    (M, 2): to the nearest point on the segments either side of the path's nearest vertex
    (exact for a straight path; elsewhere off by at most half a segment, where the path
    turns within one). Unlike :func:`position_error` it does not count lag along the path."""
    position = np.asarray(position, dtype=float)
    path = np.asarray(path, dtype=float)
    if len(path) < 2:
        return np.hypot(*(position - path[0]).T)
    _, nearest = cKDTree(path).query(position)
    best = np.full(len(position), np.inf)
    for before in (1, 0):  # the segment that ends at the nearest vertex, the one that starts
        start = np.clip(nearest - before, 0, len(path) - 2)
        a, along = path[start], path[start + 1] - path[start]
        length2 = np.einsum("ij,ij->i", along, along)
        share = np.einsum("ij,ij->i", position - a, along) / np.where(length2 > 0, length2, 1)
        closest = a + np.clip(share, 0.0, 1.0)[:, None] * along
        best = np.minimum(best, np.hypot(*(position - closest).T))
    return best


def tightening_metrics(log: SimLog) -> dict[str, float]:
    """What the robust tightening (ocp/tightening.py) took, all zero for a nominal controller:
    the largest and the mean (over the samples with obstacle rows) obstacle back-off, and the
    largest and mean fraction of a thruster's range given up."""
    obstacle, thrust = log.diagnostics["backoff"].T
    with_rows = obstacle[obstacle > 0.0]
    return {
        "max_obstacle_backoff_m": float(obstacle.max(initial=0.0)),
        "mean_obstacle_backoff_m": float(with_rows.mean()) if len(with_rows) else 0.0,
        "max_thrust_backoff_fraction": float(thrust.max(initial=0.0)),
        "mean_thrust_backoff_fraction": float(thrust.mean()) if len(thrust) else 0.0,
    }


# --- depth runs (kind: depth): the tank step experiment ------------------------------------

STEADY_WINDOW_S = 10.0  # "over the last 10 s" (issue 5)

STEP_METRIC_KEYS = (
    "rise_time_s", "settling_time_0p05m_s", "settling_time_2pct_s", "overshoot_m",
    "steady_state_error_mean_abs_m", "steady_state_error_max_abs_m",
)  # fmt: skip


def compute_depth_metrics(
    log: SimLog, step: DepthStepConfig, limits: HeaveParams
) -> dict[str, float | int | None]:
    """Step-response metrics of the true depth (docs/depth.md), then the actuation and solver
    metrics every run has, against the vertical thrusters' limits in ``limits``."""
    z = log.state[:, DEPTH.index("z")]
    after = log.t >= step.step_time_s - 1e-9
    t_after, z_after = log.t[after] - step.step_time_s, z[after]
    change = step.final_depth_m - step.initial_depth_m
    # 0 before, 1 at the target; a depth held (no step, e.g. an excite manoeuvre) rises never
    progress = (z_after - step.initial_depth_m) / change if change else np.zeros_like(z_after)
    error = np.abs(z_after - step.final_depth_m)
    steady = log.t >= log.t[-1] - STEADY_WINDOW_S - 1e-9
    steady_error = np.abs(z[steady] - log.column("z_ref")[steady])
    common = actuation_metrics(log, limits.thrust_limits, limits.thrust_rate_limit)
    metrics = {
        "rise_time_s": _rise_time(t_after, progress),
        "settling_time_0p05m_s": _settling_time(t_after, error, 0.05),
        "settling_time_2pct_s": _settling_time(t_after, error, 0.02 * abs(change)),
        # None when the run ended before the step (a session closed early).
        "overshoot_m": float(max(0.0, np.max((z_after - step.final_depth_m) * np.sign(change))))
        if len(z_after)
        else None,
        "steady_state_error_mean_abs_m": float(np.mean(steady_error)),
        "steady_state_error_max_abs_m": float(np.max(steady_error)),
        "max_z_m": float(z.max()),
        "min_z_m": float(z.min()),
    }
    # The keys depth runs had first, in their order; then the rest of the common ones.
    metrics |= _pick(
        common,
        "thrust_limit_violations",
        "thrust_rate_violations",
        "max_abs_thrust_N",
        "solve_ms_median",
        "solve_ms_p99",
        "solve_ms_max",
        "solver_failures",
    )
    metrics |= {name: value for name, value in common.items() if name not in metrics}
    return metrics


def _rise_time(t: np.ndarray, progress: np.ndarray) -> float | None:
    """10 % to 90 % of the step, first crossings."""
    ten = np.flatnonzero(progress >= 0.1)
    ninety = np.flatnonzero(progress >= 0.9)
    if len(ten) == 0 or len(ninety) == 0:
        return None
    return float(t[ninety[0]] - t[ten[0]])


def _settling_time(t: np.ndarray, error: np.ndarray, band: float) -> float | None:
    """Time of the last entry into the band (None if it ends outside, or never got there)."""
    if len(error) == 0:
        return None
    outside = np.flatnonzero(error > band)
    if len(outside) == 0:
        return 0.0
    if outside[-1] == len(error) - 1:
        return None
    return float(t[outside[-1] + 1])
