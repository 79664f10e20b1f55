"""Metrics that show trouble, and the verdict, on hand-made logs (issue 10, item 5)."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest

from auvmpc.controllers.base import ControlStatus
from auvmpc.models.vehicle import top_yaw_rate
from auvmpc.sim.log import SimLog
from auvmpc.sim.metrics import compute_metrics, longest_run
from auvmpc.sim.verdict import (
    DEGRADED_HEADING_RAD,
    LOST_FALLBACK_S,
    characteristic_length_m,
    relative_heading_turns,
)

SAMPLE_TIME = 0.5
TRANSIENT_S = 20.0
RADIUS, SPEED = 8.0, 0.5


def circle_log(params, duration_s: float = 100.0) -> SimLog:
    """A log whose vehicle sits exactly on a circle reference: no error of any kind."""
    steps = int(round(duration_s / SAMPLE_TIME))
    log = SimLog.allocate(steps, params.n_thrusters, SAMPLE_TIME)
    rate = SPEED / RADIUS
    angle = rate * log.t
    log.reference[:] = np.column_stack(
        [
            RADIUS * np.cos(angle),
            RADIUS * np.sin(angle),
            angle + math.pi / 2,
            np.full_like(angle, SPEED),
            np.zeros_like(angle),
            np.full_like(angle, rate),
        ]
    )
    log.state[:] = log.reference
    log.status = [str(ControlStatus.OK)] * steps
    return log


def metrics_of(log, params):
    return compute_metrics(log, params, TRANSIENT_S)


@pytest.fixture(params=["jmse2210", "bluerov2-heavy"])
def vehicle(request):
    from auvmpc.models.vehicle import load_vehicle

    return load_vehicle(request.param)


def test_perfect_tracking_is_ok_with_no_trouble_counted(vehicle):
    metrics = metrics_of(circle_log(vehicle), vehicle)
    assert metrics["verdict"] == "ok"
    assert "0 m" in metrics["verdict_reason"]
    assert metrics["fallback_steps"] == metrics["solver_failures"] == 0
    assert metrics["relaxed_steps"] == metrics["longest_fallback_streak"] == 0
    assert metrics["max_abs_yaw_rate_rad_per_s"] == pytest.approx(SPEED / RADIUS)
    assert metrics["max_heading_error_after_transient_rad"] == pytest.approx(0.0, abs=1e-12)


def test_fallbacks_and_their_longest_streak_are_counted(vehicle):
    log = circle_log(vehicle)
    for k in (3, 4, 50, 51, 52, 90):
        log.status[k] = str(ControlStatus.FALLBACK)
    metrics = metrics_of(log, vehicle)
    assert metrics["fallback_steps"] == metrics["solver_failures"] == 6
    assert metrics["longest_fallback_streak"] == 3
    assert metrics["verdict"] == "degraded"
    assert metrics["verdict_reason"] == "6 fallback steps (longest streak 3)"


def test_a_long_fallback_streak_means_nobody_was_steering(vehicle):
    log = circle_log(vehicle)
    streak = int(LOST_FALLBACK_S / SAMPLE_TIME)
    log.status[100 : 100 + streak] = [str(ControlStatus.FALLBACK)] * streak
    metrics = metrics_of(log, vehicle)
    assert metrics["longest_fallback_streak"] == streak
    assert metrics["verdict"] == "lost"
    assert metrics["verdict_reason"].startswith("no control for 10 s")


def test_relaxed_steps_are_counted_and_degrade(vehicle):
    log = circle_log(vehicle)
    log.status[10:14] = [str(ControlStatus.RELAXED)] * 4
    metrics = metrics_of(log, vehicle)
    assert metrics["relaxed_steps"] == 4
    assert metrics["fallback_steps"] == 0
    assert (metrics["verdict"], metrics["verdict_reason"]) == (
        "degraded",
        "4 steps with obstacle constraints relaxed",
    )


def test_a_vehicle_that_winds_its_heading_up_is_lost(vehicle):
    log = circle_log(vehicle)
    # Three full extra turns at 4 rad/s around t = 60 s, then back on the reference
    # heading modulo 2 pi: position fine, wrapped heading error back to zero.
    k0, turn = 120, 3 * 2 * math.pi
    steps = math.ceil(turn / (4.0 * SAMPLE_TIME))
    extra = np.minimum(np.arange(len(log.t)) - k0, steps).clip(0) * (turn / steps)
    log.state[:, 2] += extra
    log.state[k0 : k0 + steps, 5] = 4.0
    metrics = metrics_of(log, vehicle)
    assert metrics["max_abs_yaw_rate_rad_per_s"] == 4.0
    assert metrics["verdict"] == "lost"
    assert metrics["verdict_reason"].startswith("spun: heading wound 3.0 turns")


def test_relative_heading_turns_counts_full_revolutions_only():
    psi_ref = np.linspace(0.0, 20.0, 200)  # a reference that turns a lot by itself
    assert relative_heading_turns(psi_ref, psi_ref) == 0.0
    start_opposite = psi_ref + np.linspace(math.pi, 0.0, 200)  # aligning: half a turn
    assert relative_heading_turns(start_opposite, psi_ref) == pytest.approx(0.5)
    assert relative_heading_turns(psi_ref + np.linspace(0, 4 * math.pi, 200), psi_ref) == 2.0


def test_heading_error_after_the_transient_ignores_the_transient(vehicle):
    log = circle_log(vehicle)
    log.state[10, 2] += 2.0  # t = 5 s: inside the transient
    log.state[100, 2] -= 0.7  # t = 50 s
    log.state[101, 2] += 0.1
    metrics = metrics_of(log, vehicle)
    assert metrics["max_heading_error_after_transient_rad"] == pytest.approx(0.7)
    assert 0.7 > DEGRADED_HEADING_RAD
    assert metrics["verdict"] == "degraded"
    assert metrics["verdict_reason"] == "heading error 0.70 rad after the transient (limit 0.5)"


def _offset_after_transient(log, distance_m: float) -> None:
    """Push the vehicle radially outwards by ``distance_m`` for 10 s after the transient."""
    k = slice(int(60 / SAMPLE_TIME), int(70 / SAMPLE_TIME))
    radial = log.reference[k, :2] / RADIUS
    log.state[k, :2] = log.reference[k, :2] + distance_m * radial


@pytest.mark.parametrize(
    ("vehicle_name", "expected"), [("jmse2210", "ok"), ("bluerov2-heavy", "degraded")]
)
def test_the_same_error_is_judged_against_the_vehicle_size(vehicle_name, expected):
    from auvmpc.models.vehicle import load_vehicle

    params = load_vehicle(vehicle_name)
    log = circle_log(params)
    _offset_after_transient(log, 0.6)  # 0.6 jmse2210 lengths, 1.3 BlueROV2 lengths
    metrics = metrics_of(log, params)
    assert metrics["max_position_error_after_transient_m"] == pytest.approx(0.6)
    assert metrics["verdict"] == expected


def test_leaving_the_path_by_several_vehicle_lengths_is_lost(vehicle):
    log = circle_log(vehicle)
    length = characteristic_length_m(vehicle)
    _offset_after_transient(log, 5.5 * length)
    metrics = metrics_of(log, vehicle)
    assert metrics["verdict"] == "lost"
    assert metrics["verdict_reason"].startswith("left the path")


def test_a_vehicle_stopped_at_an_obstacle_while_the_reference_moves_on_is_called_blocked(jmse):
    """From 60 s the vehicle stands still at an obstacle's keep-out edge (clearance 0.05 m,
    within BLOCKED_BAND_M of a zero margin) while the reference goes on round the circle:
    lost, and the reason says it was blocked for the time it stood there. The same stop far
    from any obstacle is only lost (no blocked reason)."""
    from auvmpc.sim.verdict import BLOCKED_S

    log = circle_log(jmse)
    stop = slice(int(60 / SAMPLE_TIME), int(80 / SAMPLE_TIME))  # 20 s, 1/6 of the circle
    log.state[stop, :2] = log.state[stop.start, :2]
    log.state[stop, 3:] = 0.0
    log.clearance_m[:] = 5.0
    log.clearance_m[stop] = 0.05
    metrics = metrics_of(log, jmse)
    assert metrics["verdict"] == "lost"
    # the stop's ends are judged on the 5 s around them: blocked for all but about that
    match = re.search(
        r"blocked: stopped at an obstacle's keep-out edge for ([0-9.]+) s",
        metrics["verdict_reason"],
    )
    assert match and BLOCKED_S <= float(match.group(1)) <= 20.0
    log.clearance_m[:] = 5.0
    clear = metrics_of(log, jmse)
    assert clear["verdict"] == "lost" and "blocked" not in clear["verdict_reason"]


def test_a_small_path_lowers_the_distance_that_counts_as_lost(jmse):
    # A 1 m square of waypoints is smaller than five jmse2210 lengths (5 m): 2 m off it
    # is lost (a quarter of the 1.41 m diagonal is the limit), not merely degraded.
    log = circle_log(jmse)
    log.reference[:, :2] = np.clip(log.reference[:, :2] / RADIUS, 0.0, 1.0)
    log.state[:] = log.reference
    log.state[150, 0] += 2.0
    assert metrics_of(log, jmse)["verdict"] == "lost"


def test_a_yaw_rate_excursion_is_degraded(vehicle):
    log = circle_log(vehicle)
    top = top_yaw_rate(vehicle)
    log.state[100, 5] = 0.6 * top  # above half the vehicle's top rate, heading still fine
    metrics = metrics_of(log, vehicle)
    assert metrics["max_abs_yaw_rate_rad_per_s"] == pytest.approx(0.6 * top)
    assert metrics["verdict"] == "degraded"
    assert metrics["verdict_reason"].startswith(f"yaw rate {0.6 * top:.2f} rad/s")


@pytest.mark.parametrize(
    ("vehicle_name", "length_m", "without_size_m"),
    [("jmse2210", 1.0, 0.849), ("bluerov2-heavy", 0.457, 0.381), ("rexrov", 2.56, 1.30)],
)
def test_the_vehicle_length_is_the_size_blocks_else_the_thruster_span(
    vehicle_name, length_m, without_size_m
):
    from auvmpc.models.vehicle import load_vehicle

    params = load_vehicle(vehicle_name)
    assert characteristic_length_m(params) == length_m
    unsized = params.model_copy(update={"size": None})
    assert characteristic_length_m(unsized) == pytest.approx(without_size_m, abs=0.005)


def test_top_yaw_rate_balances_damping_against_the_largest_yaw_moment(jmse):
    # jmse2210: four thrusters with 0.30 m arms at 15 N -> 18 N m; Nr -1.5, Nrr -2.5.
    r = top_yaw_rate(jmse)
    assert 2.5 * r**2 + 1.5 * r == pytest.approx(4 * 0.4243 * math.sin(math.pi / 4) * 15.0)


def test_thrust_limit_violations_degrade(vehicle):
    log = circle_log(vehicle)
    log.thrust[30, 0] = vehicle.thrust_max + 1.0
    metrics = metrics_of(log, vehicle)
    assert metrics["thrust_limit_violations"] == 1
    assert metrics["verdict"] == "degraded"
    assert "thrust limits violated (1 force" in metrics["verdict_reason"]


def test_worst_problems_all_appear_in_one_line(vehicle):
    log = circle_log(vehicle)
    log.status[5] = str(ControlStatus.FALLBACK)
    log.status[6] = str(ControlStatus.RELAXED)
    _offset_after_transient(log, 6.0 * characteristic_length_m(vehicle))
    metrics = metrics_of(log, vehicle)
    reason = metrics["verdict_reason"]
    assert metrics["verdict"] == "lost"
    assert "\n" not in reason
    assert (
        reason.index("left the path") < reason.index("1 fallback steps") < reason.index("relaxed")
    )


def test_a_run_shorter_than_the_transient_is_judged_on_what_there_is(vehicle):
    metrics = metrics_of(circle_log(vehicle, duration_s=10.0), vehicle)
    assert metrics["max_heading_error_after_transient_rad"] is None
    assert metrics["verdict"] == "ok"


def test_longest_run():
    assert longest_run(np.array([], dtype=bool)) == 0
    assert longest_run(np.array([0, 1, 1, 0, 1, 1, 1, 0], dtype=bool)) == 3


# A detour round an obstacle on the circle: the reference at t = 60 s passes 0.1 m from the
# centre of a 1 m disc; keep-out radius 1 + 0.5 (vehicle) + 0.1 (margin) = 1.6 m.
OBSTACLE_RADIUS, VEHICLE_RADIUS, MARGIN = 1.0, 0.5, 0.1
KEEP_OUT = OBSTACLE_RADIUS + VEHICLE_RADIUS + MARGIN


def _obstacle_at(t_s: float, inward_m: float):
    from auvmpc.environment.obstacles import ObstacleConfig

    angle = SPEED / RADIUS * t_s
    centre = (RADIUS - inward_m) * np.array([math.cos(angle), math.sin(angle)])
    return ObstacleConfig(center=tuple(centre), radius=OBSTACLE_RADIUS)


def _round_the_disc(log, obstacle, distance_m: float) -> None:
    """Wherever the reference is closer than ``distance_m`` to the obstacle's centre, put
    the vehicle at that distance from it, straight out from the centre through the
    reference: the shortest way round the disc."""
    centre = np.array(obstacle.center)
    away = log.reference[:, :2] - centre
    reach = np.hypot(*away.T)
    inside = reach < distance_m
    log.state[inside, :2] = centre + distance_m * away[inside] / reach[inside, None]


def _judged(log, params, obstacles):
    log.clearance_m[:] = [
        min(math.dist(p, o.center) - o.radius - VEHICLE_RADIUS for o in obstacles)
        for p in log.state[:, :2]
    ]
    return compute_metrics(log, params, TRANSIENT_S, MARGIN, obstacles, VEHICLE_RADIUS)


def test_going_round_an_obstacle_on_the_path_is_a_detour_not_tracking_error(jmse):
    obstacle = _obstacle_at(60.0, inward_m=0.1)
    log = circle_log(jmse)
    _round_the_disc(log, obstacle, KEEP_OUT + 0.05)  # up to 1.55 m off the reference
    metrics = _judged(log, jmse, [obstacle])
    assert metrics["max_position_error_after_transient_m"] == pytest.approx(1.55, abs=0.01)
    assert metrics["max_position_error_after_transient_m"] > characteristic_length_m(jmse)
    assert metrics["max_tracking_error_after_transient_m"] == pytest.approx(0.0, abs=1e-9)
    assert metrics["verdict"] == "ok"
    detour = "went round an obstacle up to 1.55 m off the reference (clearance 0.15 m)"
    assert detour in metrics["verdict_reason"]


def test_touching_the_obstacle_on_a_detour_is_degraded(jmse):
    obstacle = _obstacle_at(60.0, inward_m=0.1)
    log = circle_log(jmse)
    _round_the_disc(log, obstacle, OBSTACLE_RADIUS + VEHICLE_RADIUS - 0.05)
    metrics = _judged(log, jmse, [obstacle])
    assert metrics["verdict"] == "degraded"
    assert metrics["verdict_reason"] == "touched an obstacle (clearance -0.05 m)"


def test_an_error_beside_an_obstacle_the_reference_passes_is_tracking_error(jmse):
    """The reference passes 0.3 m outside the keep-out disc: the obstacle does not stand in
    its way, so 1.5 m off next to it is tracking error."""
    obstacle = _obstacle_at(65.0, inward_m=-(KEEP_OUT + 0.3))
    log = circle_log(jmse)
    _offset_after_transient(log, -1.5)  # 60-70 s, inwards, away from the obstacle
    metrics = _judged(log, jmse, [obstacle])
    assert metrics["verdict"] == "degraded"
    assert metrics["verdict_reason"].startswith("position error 1.5 m after the transient (")


def test_more_than_the_discs_width_off_near_an_obstacle_is_tracking_error(jmse):
    obstacle = _obstacle_at(65.0, inward_m=0.1)
    log = circle_log(jmse)
    _offset_after_transient(log, -(2.0 * KEEP_OUT + 0.2))  # 3.4 m inwards over 60-70 s
    metrics = _judged(log, jmse, [obstacle])
    assert metrics["max_position_error_after_transient_m"] == pytest.approx(3.4)
    assert metrics["verdict"] == "degraded"
    assert metrics["verdict_reason"].startswith("position error 3.4 m after the transient (")
