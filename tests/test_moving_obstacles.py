"""Moving obstacles as the vehicle perceives them (issue 14): motion, sensor, tracker,
predicted keep-out discs, encounter scenarios and their metrics."""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.stats

from auvmpc.api import load_scenario
from auvmpc.controllers.base import Controller, ControlResult, Observation, ObstacleState
from auvmpc.environment.disturbances import (
    DisturbanceConfig,
    SensorNoise,
    SensorNoiseConfig,
    WorldDisturbance,
)
from auvmpc.environment.obstacle_sensor import (
    ObstaclePerception,
    ObstacleSensorConfig,
    confidence_gain,
)
from auvmpc.environment.obstacles import ObstacleConfig
from auvmpc.estimation import ConstantVelocityKalman
from auvmpc.experiments.run import simulate
from auvmpc.references import LineConfig, make_reference
from auvmpc.sim.loop import closed_loop
from auvmpc.sim.metrics import MARGIN_TOLERANCE_M, path_length

# A constant-velocity filter on 0.1 m noise at 2 Hz for 60 s at the default acceleration
# density (1e-4 m^2/s^3): its own steady-state velocity standard deviation is 1.9 cm/s
# (measured from its covariance); the tolerance is three of them.
TRACKER_VELOCITY_STD_M_PER_S = 0.019
TRACKER_VELOCITY_TOL_M_PER_S = 3 * TRACKER_VELOCITY_STD_M_PER_S
# Same filter, position: the measurement noise averaged over a few samples.
TRACKER_POSITION_TOL_M = 0.1

ENCOUNTERS = (
    "head-on",
    "crossing-port",
    "crossing-starboard",
    "overtaking",
    "slow-on-path",
    "two-obstacles",
    "pop-up",
)


# -- motion ------------------------------------------------------------------------------
def test_constant_turn_stays_on_its_circle_at_its_speed():
    v0, rate = np.array([0.3, 0.1]), 0.2
    obstacle = ObstacleConfig(center=(1.0, 2.0), radius=0.5, velocity=tuple(v0), turn_rate=rate)
    speed = float(np.hypot(*v0))
    # Circle centre: the start plus the turn radius to the left of the initial velocity.
    pivot = np.array([1.0, 2.0]) + np.array([-v0[1], v0[0]]) / rate
    for t in np.linspace(0.0, 40.0, 17):
        assert math.dist(obstacle.center_at(t), pivot) == pytest.approx(speed / rate)
        assert np.hypot(*obstacle.velocity_at(t)) == pytest.approx(speed)
    # Heading turned by rate * t.
    turned = obstacle.velocity_at(5.0)
    assert math.atan2(turned[1], turned[0]) - math.atan2(v0[1], v0[0]) == pytest.approx(1.0)


def test_waypoint_path_at_its_speed_then_held():
    obstacle = ObstacleConfig(
        center=(0.0, 0.0), radius=0.5, waypoints=((4.0, 0.0), (4.0, 3.0)), speed=0.5, at_time=2.0
    )
    np.testing.assert_allclose(obstacle.center_at(1.0), [0.0, 0.0])  # before at_time: held
    np.testing.assert_allclose(obstacle.center_at(2.0 + 4.0), [2.0, 0.0])
    np.testing.assert_allclose(obstacle.center_at(2.0 + 10.0), [4.0, 1.0])
    np.testing.assert_allclose(obstacle.velocity_at(2.0 + 10.0), [0.0, 0.5])
    np.testing.assert_allclose(obstacle.center_at(100.0), [4.0, 3.0])
    np.testing.assert_allclose(obstacle.velocity_at(100.0), [0.0, 0.0])


def test_constant_velocity_keeps_its_old_formula_bit_for_bit():
    obstacle = ObstacleConfig(center=(2.0, 8.0), radius=1.0, velocity=(0.1, -0.07))
    for t in (0.0, 0.5, 13.5, 99.5):
        old = np.array(obstacle.center) + np.array(obstacle.velocity) * t
        assert np.array_equal(obstacle.center_at(t), old)


@pytest.mark.parametrize(
    ("fields", "match"),
    [
        ({"waypoints": ((1.0, 1.0),)}, "waypoints need a speed"),
        ({"speed": 0.3}, "only meaningful with waypoints"),
        ({"waypoints": ((1.0, 1.0),), "speed": 0.3, "velocity": (0.1, 0.0)}, "either waypoints"),
    ],
)
def test_one_motion_per_obstacle(fields, match):
    with pytest.raises(ValueError, match=match):
        ObstacleConfig(center=(0.0, 0.0), radius=1.0, **fields)


# -- tracker -----------------------------------------------------------------------------
def test_tracker_converges_to_a_constant_velocity_obstacles_true_velocity():
    truth = ObstacleConfig(center=(20.0, -3.0), radius=1.0, velocity=(-0.35, 0.2))
    rng = np.random.default_rng(3)
    period, std = 0.5, 0.1
    kalman = ConstantVelocityKalman(
        truth.center_at(0.0) + std * rng.normal(size=2), 0.0, std, 0.5, 1e-4
    )
    for j in range(1, 121):
        t = j * period
        kalman.predict(t)
        kalman.correct(truth.center_at(t) + std * rng.normal(size=2))
    np.testing.assert_allclose(kalman.mean[2:], truth.velocity, atol=TRACKER_VELOCITY_TOL_M_PER_S)
    np.testing.assert_allclose(kalman.mean[:2], truth.center_at(60.0), atol=TRACKER_POSITION_TOL_M)
    # The filter's covariance says so too.
    assert np.sqrt(np.diag(kalman.covariance)[2:]).max() < TRACKER_VELOCITY_STD_M_PER_S


def test_tracks_start_at_detection_coast_through_dropouts_and_are_dropped():
    obstacle = ObstacleConfig(center=(30.0, 0.0), radius=1.0, velocity=(-0.5, 0.0), vanish_time=40)
    config = ObstacleSensorConfig(range_m=10.0, dropout_probability=0.5, drop_after_s=3.0)
    perception = ObstaclePerception(config, [obstacle], np.random.default_rng(0))
    vehicle = np.zeros(2)
    seen = {}
    for k in range(120):
        t = 0.5 * k
        seen[t] = perception.observe(t, vehicle)
    # In range (disc within 10 m) from t = 38 s: centre at 30 - 0.5 t <= 11.
    assert all(not seen[t] for t in seen if t < 38.0)
    assert all(len(seen[t]) == 1 for t in seen if 39.0 <= t < 40.0)
    # Vanished at 40 s: coasted for drop_after_s, then dropped.
    assert len(seen[42.5]) == 1
    assert all(not seen[t] for t in seen if t > 43.5)


def test_constant_position_prediction_holds_the_estimate():
    obstacle = ObstacleConfig(center=(5.0, 0.0), radius=1.0, velocity=(-0.4, 0.0))
    config = ObstacleSensorConfig(prediction="constant-position")
    perception = ObstaclePerception(config, [obstacle], np.random.default_rng(0))
    for k in range(20):
        (state,) = perception.observe(0.5 * k, np.zeros(2))
    centres, _ = state.predict(np.array([0.0, 5.0, 10.0]))
    assert np.array_equal(centres[0], centres[2])
    assert np.all(state.velocity == 0.0)


# -- predicted keep-out disc ---------------------------------------------------------------
def test_predicted_radius_grows_with_horizon_and_covariance():
    covariance = np.diag([0.01, 0.04, 0.002, 0.001])
    covariance[0, 2] = covariance[2, 0] = 0.003
    gain = confidence_gain(0.95)
    assert gain == pytest.approx(math.sqrt(-2.0 * math.log(0.05)))  # chi2(2) quantile, closed form
    state = ObstacleState(np.zeros(2), 1.0, np.array([0.2, 0.0]), covariance, 1e-4, gain)
    dts = np.linspace(0.0, 15.0, 31)
    centres, radii = state.predict(dts)
    np.testing.assert_allclose(centres[-1], [3.0, 0.0])
    assert np.all(np.diff(radii) > 0.0)
    # At dt = 0 the disc grows by gain * the largest standard deviation of the position.
    assert radii[0] == pytest.approx(
        1.0 + gain * math.sqrt(np.linalg.eigvalsh(covariance[:2, :2])[-1])
    )
    # Against the covariance propagated by the filter's own transition.
    kalman = ConstantVelocityKalman(np.zeros(2), 0.0, 0.1, 0.5, 1e-4)
    kalman.mean, kalman.covariance = np.array([0.0, 0.0, 0.2, 0.0]), covariance
    _, propagated = kalman.predicted(10.0)
    assert state.predict(np.array([10.0]))[1][0] == pytest.approx(
        1.0 + gain * math.sqrt(np.linalg.eigvalsh(propagated[:2, :2])[-1])
    )
    wider = ObstacleState(np.zeros(2), 1.0, np.array([0.2, 0.0]), 4 * covariance, 1e-4, gain)
    assert np.all(wider.predict(dts)[1] > radii)
    known = ObstacleState(np.zeros(2), 1.0, np.array([0.2, 0.0]))
    assert np.array_equal(known.predict(dts)[1], np.full(len(dts), 1.0))


def test_confidence_gain_is_the_chi_square_quantile():
    for confidence in (0.5, 0.9, 0.99):
        assert confidence_gain(confidence) ** 2 == pytest.approx(
            scipy.stats.chi2.ppf(confidence, 2)
        )


# -- the controller's inputs without a sensor ----------------------------------------------
class RecordingController(Controller):
    sample_time = 0.5
    preview_steps = 3

    def __init__(self):
        self.seen: list[Observation] = []

    def reset(self, initial_state, initial_thrust):
        pass

    def compute(self, observation: Observation) -> ControlResult:
        self.seen.append(observation)
        return ControlResult(thrust=np.zeros(4))


def test_without_a_sensor_the_controller_sees_what_it_saw_before(jmse):
    obstacles = [
        ObstacleConfig(center=(3.0, 1.0), radius=0.5, velocity=(0.1, -0.05), appear_time=1.0),
        ObstacleConfig(center=(8.0, -6.0), radius=1.0, vanish_time=2.5),
    ]
    rng = np.random.default_rng(0)
    controller = RecordingController()
    closed_loop(
        jmse,
        controller,
        make_reference(LineConfig(type="line", start=(0, 0), heading_deg=0, speed=0.5)),
        duration=4.0,
        initial_state=np.zeros(6),
        disturbance=WorldDisturbance(DisturbanceConfig(), 0.5, rng),
        sensor=SensorNoise(SensorNoiseConfig(), rng),
        obstacles=obstacles,
        vehicle_radius=0.5,
    )
    for observation in controller.seen:
        t = observation.t
        before = [  # visible_obstacles as it was written before the sensor existed
            (np.array(o.center) + np.array(o.velocity) * t, o.radius, np.array(o.velocity))
            for o in obstacles
            if o.appear_time <= t and (o.vanish_time is None or t < o.vanish_time)
        ]
        assert len(observation.obstacles) == len(before)
        for seen, (center, radius, velocity) in zip(observation.obstacles, before, strict=True):
            assert np.array_equal(seen.center, center)
            assert seen.radius == radius
            assert np.array_equal(seen.velocity, velocity)
            assert seen.covariance is None
            dts = 0.5 * np.arange(1, 31)
            old_centres = seen.center + np.outer(dts, seen.velocity)
            centres, radii = seen.predict(dts)
            assert np.array_equal(centres, old_centres)
            assert np.array_equal(radii, np.full(30, radius))


# -- encounters ----------------------------------------------------------------------------
@pytest.fixture(scope="module")
def encounter_runs():
    """Each encounter with constant-velocity prediction (its preset), ~1 s each."""
    return {name: simulate(load_scenario(f"encounter-{name}")) for name in ENCOUNTERS}


@pytest.mark.parametrize("name", ENCOUNTERS)
def test_encounter_with_prediction_never_touches(encounter_runs, name):
    metrics = encounter_runs[name].metrics
    assert metrics["min_obstacle_clearance_m"] >= 0.0
    assert metrics["thrust_limit_violations"] == 0
    assert metrics["thrust_rate_violations"] == 0
    assert metrics["time_inside_margin_s"] == 0.0
    assert metrics["detour_m"] > 0.0  # it went round


def test_constant_position_prediction_touches_a_crossing_obstacle(encounter_runs):
    """Measured (seed 0) with ltv-mpc: constant-velocity 0.27 m of clearance, constant-position
    -0.39 m. (The default nmpc, re-planning along the exact model, keeps 0.23 m even with the
    constant-position prediction: the campaigns' comparison pins ltv-mpc.)"""
    held = simulate(
        load_scenario(
            "encounter-crossing-port",
            {"obstacle_sensor.prediction": "constant-position"},
            controller="ltv-mpc",
        )
    ).metrics
    predicted = encounter_runs["crossing-port"].metrics
    margin = load_scenario("encounter-crossing-port").scenario.controller.obstacle_margin
    assert predicted["min_obstacle_clearance_m"] >= margin - MARGIN_TOLERANCE_M
    assert held["min_obstacle_clearance_m"] < 0.0
    assert held["time_inside_margin_s"] > 0.0


def test_encounter_same_seed_same_bits():
    first, second = (
        simulate(load_scenario("encounter-pop-up", {"duration": 35.0})) for _ in range(2)
    )
    assert np.array_equal(first.log.state, second.log.state)
    assert np.array_equal(first.log.thrust, second.log.thrust)


def test_path_length_of_a_polyline():
    assert path_length(np.array([[0.0, 0.0], [3.0, 4.0], [3.0, 0.0]])) == pytest.approx(9.0)


def test_encounter_campaigns_are_valid_and_draw_alike():
    from auvmpc.experiments.campaign import load_campaign, scenario_for_run, validate_campaign

    predicted, held = load_campaign("encounter"), load_campaign("encounter-constant-position")
    validate_campaign(predicted)
    validate_campaign(held)
    for index in (0, 7):
        a = scenario_for_run(predicted, index).scenario
        b = scenario_for_run(held, index).scenario
        assert a.obstacles == b.obstacles  # same draws
        assert a.disturbance == b.disturbance
        assert np.hypot(*a.obstacles[0].velocity) <= 0.5  # never faster than the vehicle
        assert a.obstacle_sensor.prediction == "constant-velocity"
        assert b.obstacle_sensor.prediction == "constant-position"
