"""Currents as water velocity: the profile and its slope, the Gauss-Markov statistics and
determinism, and the rate the 6-DOF plant is given along a diving vehicle's path."""

from __future__ import annotations

import math

import numpy as np
import pytest
from pydantic import ValidationError

from auvmpc.environment.currents import WaterCurrent, WaterCurrentConfig
from auvmpc.models.six_dof import Rzyx, depth_rate, integrate, six_dof_model
from auvmpc.models.vehicle import VehicleParams, load_vehicle

SHEAR = WaterCurrentConfig(
    velocity_m_per_s=(0.4, -0.2, 0.0), depth_profile=((0.0, 1.0), (10.0, 0.5), (30.0, 0.0))
)


def test_the_depth_profile_interpolates_and_holds_beyond_its_ends():
    current = WaterCurrent(SHEAR, 0.5, np.random.default_rng(0))
    assert current.profile(-1.0) == 1.0 and current.profile(50.0) == 0.0
    assert current.profile(5.0) == pytest.approx(0.75)
    assert current.profile(20.0) == pytest.approx(0.25)
    np.testing.assert_allclose(current.velocity_world(0.0, 5.0), [0.3, -0.15, 0.0])
    assert current.profile_slope(5.0) == pytest.approx(-0.05)
    assert current.profile_slope(20.0) == pytest.approx(-0.025)
    assert current.profile_slope(40.0) == 0.0


def test_without_a_profile_the_current_is_the_same_at_every_depth():
    current = WaterCurrent(WaterCurrentConfig(velocity_m_per_s=(0.3, 0.1, 0.0)), 0.5, None)
    for depth in (0.0, 3.0, 100.0):
        velocity, rate = current.at(0.0, depth, 1.0)
        np.testing.assert_array_equal(velocity, [0.3, 0.1, 0.0])
        np.testing.assert_array_equal(rate, 0.0)


def test_profile_depths_must_increase():
    with pytest.raises(ValidationError, match="depths must increase"):
        WaterCurrentConfig(depth_profile=((10.0, 1.0), (5.0, 0.5)))
    with pytest.raises(ValidationError, match="greater than or equal to 0"):
        WaterCurrentConfig(depth_profile=((0.0, -1.0),))


def test_gauss_markov_part_has_its_stationary_std_and_correlation_and_repeats_by_seed():
    config = WaterCurrentConfig(
        velocity_m_per_s=(0.2, 0.0, 0.0),
        variation={"std_m_per_s": 0.05, "time_constant_s": 20.0},
    )
    sample_time, steps = 1.0, 40000

    def draw(seed):
        current = WaterCurrent(config, sample_time, np.random.default_rng(seed))
        values = np.empty((steps, 3))
        for k in range(steps):
            values[k] = current.velocity_world(k * sample_time)
            current.advance()
        return values

    values = draw(7)
    np.testing.assert_array_equal(values, draw(7))  # same seed, same bits
    horizontal = values[:, :2] - [0.2, 0.0]
    # 40000 samples of a process correlated over 20: ~1000 independent ones, so the
    # standard deviation is known to ~2 % (1/sqrt(2 * 1000)); 10 % is a safe bound.
    assert np.std(horizontal, axis=0) == pytest.approx([0.05, 0.05], rel=0.1)
    lag = 20
    correlation = np.mean(horizontal[lag:, 0] * horizontal[:-lag, 0]) / np.var(horizontal[:, 0])
    assert correlation == pytest.approx(math.exp(-lag / 20.0), abs=0.1)
    np.testing.assert_array_equal(values[:, 2], 0.0)  # the vertical part stays as given


def neutral(name: str) -> VehicleParams:
    data = load_vehicle(name).model_dump()
    data["six_dof"]["displaced_volume"] = data["mass"] / data["six_dof"]["water_density"]
    return VehicleParams.model_validate(data)


def test_the_rate_along_a_diving_path_is_the_derivative_of_the_current_it_meets():
    # v_c' = profile'(z) z' (mean): compare with a finite difference of v_c(z(t)) along a
    # simulated dive through the sheared current.
    params = neutral("bluerov2-heavy")
    model = six_dof_model(params)
    current = WaterCurrent(SHEAR, 0.5, np.random.default_rng(0))
    thrust = np.zeros(model.n_thrusters)
    thrust[4:] = -10.0  # positive thrust on the vertical thrusters lifts: this dives
    state = np.zeros(12)
    state[2] = 4.0

    def current_at(t, x):
        return current.at(t, x[2], depth_rate(x))

    h = 0.01
    for _ in range(100):
        state = integrate(model, state, thrust, h, 1, current_at)
    before = current.velocity_world(0.0, state[2])
    _, rate = current_at(0.0, state)
    after_state = integrate(model, state, thrust, h, 1, current_at)
    after = current.velocity_world(0.0, after_state[2])
    assert depth_rate(state) > 0.1  # diving
    # Central enough: the depth rate changes by < 1 % over one 0.01 s step here.
    np.testing.assert_allclose((after - before) / h, rate, rtol=0.02, atol=1e-9)


def test_a_vehicle_held_at_depth_drifts_with_the_current_at_that_depth():
    params = neutral("jmse2210")
    model = six_dof_model(params)
    current = WaterCurrent(SHEAR, 1.0, np.random.default_rng(0))
    state = np.zeros(12)
    state[2] = 20.0  # profile 0.25 there

    def current_at(t, x):
        return current.at(t, x[2], depth_rate(x))

    zero = np.zeros(model.n_thrusters)
    for _ in range(240):
        state = integrate(model, state, zero, 1.0, 20, current_at)
    world_velocity = np.asarray(Rzyx(*state[3:6])) @ state[6:9]  # it has turned meanwhile
    np.testing.assert_allclose(world_velocity, [0.1, -0.05, 0.0], atol=1e-9)
    assert state[2] == pytest.approx(20.0, abs=1e-9)


def test_a_horizontal_scenario_takes_a_water_current_and_its_plant_drifts_with_it(jmse):
    from auvmpc.environment.disturbances import DisturbanceConfig, WorldDisturbance
    from auvmpc.scenario import validate_scenario
    from auvmpc.sim.loop import plant_step

    data = {
        "name": "drift",
        "duration": 10.0,
        "reference": {"type": "circle"},
        "initial_state": [0, 0, 0, 0, 0, 0],
        "disturbance": {"water_current": {"velocity_m_per_s": [0.3, -0.2, 0.0]}},
    }
    scenario = validate_scenario(data)
    disturbance = WorldDisturbance(scenario.disturbance, 0.5, np.random.default_rng(0))
    state = np.array([0.0, 0.0, 0.5, 0.4, 0.2, 0.6])
    zero = np.zeros(jmse.n_thrusters)
    for k in range(240):
        state = plant_step(jmse, state, zero, 1.0 * k, 1.0, disturbance, 20)
        disturbance.advance()
    c, s = math.cos(state[2]), math.sin(state[2])
    world = [c * state[3] - s * state[4], s * state[3] + c * state[4]]
    np.testing.assert_allclose(world, [0.3, -0.2], atol=1e-9)
    # Without one, the force form alone, as before.
    assert WorldDisturbance(DisturbanceConfig(), 0.5, None).water_velocity_world(0.0) is None


@pytest.mark.parametrize(
    ("current", "reason"),
    [
        ({"depth_profile": [[0, 1], [10, 0.5]]}, "the horizontal plant has none"),
        ({"velocity_m_per_s": [0.1, 0.0, 0.05]}, "no vertical velocity"),
    ],
)
def test_a_horizontal_scenario_refuses_what_its_plant_cannot_apply(current, reason):
    from auvmpc.errors import ConfigError
    from auvmpc.scenario import validate_scenario

    data = {
        "name": "drift",
        "duration": 10.0,
        "reference": {"type": "circle"},
        "initial_state": [0, 0, 0, 0, 0, 0],
        "disturbance": {"water_current": current},
    }
    with pytest.raises(ConfigError, match=f"disturbance.water_current: .*{reason}"):
        validate_scenario(data)
