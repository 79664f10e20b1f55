"""The reference an underactuated vehicle can follow (ocp/underactuated_reference.py), the
sample time chosen for it, and the closed loop they give (issue 10, item 2)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from auvmpc.controllers.config import (
    DEFAULT_SAMPLE_TIME_S,
    HEADING_PER_SAMPLE_RAD,
    SAMPLE_TIME_GRID_S,
    TURN_UP_SAMPLES,
    ControllerConfig,
    default_sample_time,
)
from auvmpc.estimation import ObserverConfig
from auvmpc.experiments.run import simulate
from auvmpc.models.random_vehicles import random_vehicle
from auvmpc.models.vehicle import (
    body_from_world,
    dynamics,
    heading_turn_time,
    load_vehicle,
    thruster_preset_names,
    top_yaw_rate,
    turn_up_time,
)
from auvmpc.ocp.underactuated_reference import CRAB_TURN_FRACTION, crab_reference
from auvmpc.scenario import ResolvedScenario, validate_scenario

TE = 0.5
# The crab angle is a root bracketed on a 1-degree grid and interpolated linearly inside
# it; the sway balance it leaves is second order in that interpolation: well below 1 mN
# for these vehicles and speeds.
SWAY_BALANCE_TOL_N = 2e-3
# Round-off of the reference's own trigonometry.
EXACT_TOL = 1e-12


@pytest.fixture(scope="module")
def videoray():
    return load_vehicle("videoray-pro3")


def straight(speed: float, heading: float, nodes: int = 31) -> np.ndarray:
    """A straight reference at constant speed: rows [x, y, psi, u, v, r]."""
    t = TE * np.arange(nodes)
    rows = np.zeros((nodes, 6))
    rows[:, 0], rows[:, 1] = speed * t * math.cos(heading), speed * t * math.sin(heading)
    rows[:, 2], rows[:, 3] = heading, speed
    return rows


def circle(radius: float, speed: float, nodes: int = 31) -> np.ndarray:
    """Counter-clockwise circle about the origin, started at (radius, 0)."""
    rate = speed / radius
    angle = rate * TE * np.arange(nodes)
    rows = np.zeros((nodes, 6))
    rows[:, 0], rows[:, 1] = radius * np.cos(angle), radius * np.sin(angle)
    rows[:, 2], rows[:, 3], rows[:, 5] = angle + math.pi / 2, speed, rate
    return rows


def sway_force_left(model, row: np.ndarray, disturbance: np.ndarray) -> float:
    """m22 times the sway acceleration the model gives at a reference row (no thruster can
    push sideways, so thrust is irrelevant) minus what the row's motion needs: the force
    the vehicle would lack to follow it, from vehicle.dynamics (not the module under test)."""
    d_u, d_v = body_from_world(disturbance, row[2])
    derivative = dynamics(row, np.zeros(model.n_thrusters), model, [d_u, d_v, disturbance[2]])
    needed_v_dot = 0.0  # straight or steady circle: the body-frame sway speed is constant
    return model.m22 * (derivative[4] - needed_v_dot)


def test_a_fully_actuated_vehicle_keeps_its_reference():
    reference = straight(0.3, 0.4)
    for preset in ("jmse2210", "bluerov2-heavy", "rexrov"):
        shaped = crab_reference(load_vehicle(preset), reference, np.array([5.0, 3.0, 0.0]),
                                TE, 0.4)  # fmt: skip
        assert shaped is reference


def test_in_a_cross_current_the_vehicle_crabs_until_sway_drag_balances_it(videoray):
    """Straight north-east at 0.3 m/s, pushed by 0.3 N from the side: the sway force left at
    the crab heading vanishes (vehicle.dynamics), and the world path is untouched."""
    heading = 0.7
    reference = straight(0.3, heading)
    push = 0.3 * np.array([-math.sin(heading), math.cos(heading), 0.0])
    # Start from the tangent: the turn-rate bound then lets the crab grow node by node.
    shaped = crab_reference(videoray, reference, push, TE, heading)
    settled = shaped[-1]
    assert abs(settled[2] - heading) > 0.05  # it does crab
    assert abs(sway_force_left(videoray, settled, push)) < SWAY_BALANCE_TOL_N
    world = np.stack(
        [shaped[:, 3] * np.cos(shaped[:, 2]) - shaped[:, 4] * np.sin(shaped[:, 2]),
         shaped[:, 3] * np.sin(shaped[:, 2]) + shaped[:, 4] * np.cos(shaped[:, 2])], axis=1
    )  # fmt: skip
    np.testing.assert_allclose(world, [[0.3 * math.cos(heading), 0.3 * math.sin(heading)]] * 31,
                               atol=EXACT_TOL)  # fmt: skip
    np.testing.assert_array_equal(shaped[:, :2], reference[:, :2])


def test_on_a_circle_it_crabs_out_for_the_centripetal_force(videoray):
    """A steady 2 m circle at 0.3 m/s in still water needs a sideways force (m11 u r); with
    no sway thruster the vehicle slips outwards until sway drag supplies it."""
    reference = circle(2.0, 0.3)
    shaped = crab_reference(videoray, reference, np.zeros(3), TE, reference[0, 2])
    middle = shaped[15]
    assert abs(sway_force_left(videoray, middle, np.zeros(3))) < SWAY_BALANCE_TOL_N
    assert abs(middle[4]) > 1e-3


def test_at_rest_in_a_current_it_faces_the_current(videoray):
    """Holding a point against a world force, the heading must be along the force."""
    reference = straight(0.0, 0.0)
    force = np.array([0.2, 0.4, 0.0])
    along = math.atan2(force[1], force[0])
    shaped = crab_reference(videoray, reference, force, TE, along)
    np.testing.assert_allclose(np.sin(shaped[:, 2] - along), 0.0, atol=1e-3)


def test_at_rest_in_still_water_estimator_noise_does_not_steer(videoray):
    reference = straight(0.0, 1.0)
    shaped = crab_reference(videoray, reference, np.array([1e-6, -2e-6, 0.0]), TE, 1.0)
    np.testing.assert_allclose(shaped[:, 2], 1.0, atol=EXACT_TOL)


def test_the_crab_turns_no_faster_than_the_bound(videoray):
    """Stopped in a current from abeam, with the vehicle still on the old heading: the
    reference turns it round at CRAB_TURN_FRACTION of its top yaw rate, not at once."""
    reference = straight(0.0, 0.0)
    shaped = crab_reference(videoray, reference, np.array([0.0, 0.5, 0.0]), TE, 0.0)
    step = CRAB_TURN_FRACTION * top_yaw_rate(videoray) * TE
    assert np.max(np.abs(np.diff(shaped[:, 2]))) <= step + EXACT_TOL
    assert abs(shaped[-1, 2]) == pytest.approx(math.pi / 2, abs=1e-3)


# --------------------------------------------------------------------------------------------
# The sample time chosen for a vehicle
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("preset", thruster_preset_names())
def test_sample_time_resolves_an_underactuated_turn(preset):
    model = load_vehicle(preset)
    te = default_sample_time(model)
    if model.underactuated:
        assert te <= TURN_UP_SAMPLES * turn_up_time(model)
        assert te < DEFAULT_SAMPLE_TIME_S
    else:  # every fully actuated preset turns under half a turn per 0.5 s at full moment
        assert te == DEFAULT_SAMPLE_TIME_S
    assert te * top_yaw_rate(model) <= HEADING_PER_SAMPLE_RAD


def test_sample_time_keeps_a_full_yaw_moment_within_half_a_turn():
    # random plausible vehicles (their top yaw rate does not depend on the yaw inertia the
    # hard survey cuts): the sample is the grid's longest the rule allows, at most 0.5 s
    for seed in range(40):
        vehicle = random_vehicle(np.random.default_rng(seed), name="random")
        spin = heading_turn_time(vehicle, HEADING_PER_SAMPLE_RAD)
        te = default_sample_time(vehicle)
        assert te <= min(DEFAULT_SAMPLE_TIME_S, spin)  # within half a turn (the grid allows)
        assert te * top_yaw_rate(vehicle) <= HEADING_PER_SAMPLE_RAD
        longer = [grid for grid in SAMPLE_TIME_GRID_S if grid > te]
        assert not longer or min(longer) > min(DEFAULT_SAMPLE_TIME_S, spin)  # the longest


def test_turn_up_time_is_inertia_times_top_rate_over_moment(videoray):
    # VideoRay: Iz 0.0538, moment 0.09 m x (6.1 + 4.3) N, top rate from |Nr| r + |Nrr| r^2.
    moment = 0.09 * (6.1 + 4.3)
    rate = (-0.023 + math.sqrt(0.023**2 + 4 * 0.45 * moment)) / (2 * 0.45)
    assert turn_up_time(videoray) == pytest.approx(0.0538 * rate / moment, rel=1e-9)


def scenario_data(**changes) -> dict:
    data = {
        "name": "stern-thrusters",
        "duration": 60.0,
        "vehicle": "videoray-pro3",
        "reference": {"type": "circle", "radius": 3.0, "speed": 0.3},
        "initial_state": [3.0, 0.0, math.pi / 2, 0.3, 0.0, 0.1],
        "transient_s": 20.0,
    }
    data.update(changes)
    return data


def test_an_omitted_sample_time_is_chosen_and_recorded():
    resolved = ResolvedScenario(validate_scenario(scenario_data()), Path.cwd())
    assert resolved.given.controller.sample_time is None
    assert resolved.scenario.controller.sample_time == default_sample_time(resolved.model)
    given = ControllerConfig(sample_time=0.5)
    assert given.for_vehicle(resolved.model).sample_time == 0.5


def test_a_duration_the_chosen_sample_does_not_divide_is_rounded_up_with_a_note():
    resolved = ResolvedScenario(validate_scenario(scenario_data(duration=60.1)), Path.cwd())
    sample_time = resolved.scenario.controller.sample_time
    steps = resolved.scenario.duration / sample_time
    assert steps == round(steps) and 60.1 < resolved.scenario.duration < 60.1 + sample_time
    assert len(resolved.notes) == 1 and resolved.notes[0].startswith("duration: 60.1 s")


def test_the_force_estimate_of_an_underactuated_vehicle_is_slower(videoray):
    jmse = load_vehicle("jmse2210")
    fraction = [
        ObserverConfig().for_vehicle(m).disturbance_rate_std[0] / max(m.thrust_authority[:2])
        for m in (videoray, jmse)
    ]
    assert fraction[0] < fraction[1] / 5


# The floor for the underactuated preset (m), and a current of about 0.2 m/s.
UNDERACTUATED_RMS_M = 0.3


@pytest.mark.parametrize("controller", ["ltv-mpc", "nmpc"])
def test_the_underactuated_preset_holds_a_circle_in_a_current(controller):
    """Default settings, a cross current of the drag at 0.2 m/s and 30 % model error: the
    vehicle crabs round the circle (before the crab reference and the chosen sample time
    it lost every such run to a two-sample yaw oscillation)."""
    model = load_vehicle("videoray-pro3")
    drag = abs(model.Xu * 0.2 + model.Xuu * 0.04)
    data = scenario_data(
        disturbance={"current_force_world": [drag * math.cos(0.5), drag * math.sin(0.5)]},
        plant={"scale": {"m11": 1.3, "m22": 0.7, "Iz_rb": 0.7, "Xu": 1.3, "Yv": 0.7}},
        controller={"type": controller},
    )
    metrics = simulate(ResolvedScenario(validate_scenario(data), Path.cwd())).metrics
    assert metrics["fallback_steps"] == 0
    assert metrics["rms_position_error_after_transient_m"] <= UNDERACTUATED_RMS_M
    assert metrics["verdict"] == "ok", metrics["verdict_reason"]
    assert metrics["thrust_limit_violations"] == metrics["thrust_rate_violations"] == 0


def test_sqp_steps_follow_the_vehicle_not_its_sample():
    """2 SQP steps where full thrust changes the speed by 0.5 m/s in under 1/8 of 0.5 s, also
    where the yaw rule shortens the sample; every preset keeps one."""
    from auvmpc.controllers.config import (
        RTI_AGILE_SAMPLES,
        default_sqp_iterations,
        velocity_change_time,
    )

    for preset in thruster_preset_names():
        assert ControllerConfig().for_vehicle(load_vehicle(preset)).linearisation_iterations == 1
    agile = [
        vehicle
        for seed in range(40)
        if velocity_change_time(vehicle := random_vehicle(np.random.default_rng(seed), name="r"))
        < DEFAULT_SAMPLE_TIME_S / RTI_AGILE_SAMPLES
    ]
    assert agile  # the random vehicles include such ones
    for vehicle in agile:
        assert default_sqp_iterations(vehicle) == 2
        for sample_time in (0.5, 0.25, 0.2):
            filled = ControllerConfig(sample_time=sample_time).for_vehicle(vehicle)
            assert filled.linearisation_iterations == 2
