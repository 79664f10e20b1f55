"""The whole vehicle's nonlinear MPC (controllers/six_dof_nmpc.py) and what it stands on:
the hull's lift, the prediction's RK4 steps, the current observer, the kind's wiring."""

from __future__ import annotations

import io

import numpy as np
import pytest

from auvmpc.controllers.base import Observation
from auvmpc.controllers.recovery import AutopilotFeedback, ChannelFeedback
from auvmpc.controllers.registry import build_controller
from auvmpc.controllers.shell import Proposal
from auvmpc.controllers.six_dof_nmpc import SixDofNmpc, SixDofNmpcConfig
from auvmpc.errors import ConfigError
from auvmpc.experiments.run import simulate
from auvmpc.models import six_dof
from auvmpc.models.actuators import ActuatorSet, ControlSurface, Propeller
from auvmpc.models.vehicle import RK4_STABLE_STEP, load_vehicle, scaled
from auvmpc.scenario import load_scenario
from tests.test_cli import run_cli

HEAVY = "bluerov2-heavy"
# A short helix on the BlueROV2 Heavy with a short horizon: enough samples to see the
# tracking settle, few enough for a unit test.
SHORT = [
    "duration=8",
    "controller.type=six-dof-nmpc",
    "controller.prediction_horizon=10",
    "controller.jit=false",  # the compile (minutes, once per configuration) is benchmarked
]


def test_hull_lift_adds_prestero_body_lift_to_the_model():
    """The derivative with hull lift minus without is M^-1 [0, Y_uv u v, Z_uw u w, 0, M_uw u w,
    N_uv u v] at any state: the terms enter as written (Prestero 2001, Table C.4's form)."""
    base = load_vehicle(HEAVY)
    lift = (-28.6, -20.0, -4.47, 4.47)
    data = base.model_dump()
    data["six_dof"]["hull_lift"] = lift
    lifted = type(base).model_validate(data)
    state = np.array([1.0, 2.0, 3.0, 0.05, -0.04, 0.3, 0.8, 0.2, -0.1, 0.01, 0.02, 0.03])
    thrust = np.zeros(base.six_dof_actuators.size)
    difference = six_dof.dynamics(state, thrust, lifted) - six_dof.dynamics(state, thrust, base)
    u, v, w = state[6:9]
    expected_force = np.array(
        [0, lift[0] * u * v, lift[1] * u * w, 0, lift[2] * u * w, lift[3] * u * v]
    )
    mass = base.six_dof.mass_matrix(base.mass)
    np.testing.assert_allclose(difference[6:], np.linalg.solve(mass, expected_force), atol=1e-12)
    np.testing.assert_array_equal(difference[:6], 0.0)


def test_prediction_substeps_keep_rk4_stable_on_the_fastest_mode():
    """h |lambda| <= RK4_STABLE_STEP for every vehicle with a 6-DOF section, at the default
    sample time and a longer one (the rule the prediction's substeps are chosen by)."""
    for name in (HEAVY, "jmse2210"):
        vehicle = load_vehicle(name)
        fastest = six_dof.ACCURATE_RATE_STEP / six_dof.plant_step_length(vehicle, 1.0)
        for sample_time in (0.2, 0.5):
            steps = six_dof.stable_substeps(vehicle, sample_time)
            assert sample_time / steps * fastest <= RK4_STABLE_STEP + 1e-12


def test_a_torpedo_cannot_push_sideways_a_thruster_vehicle_can():
    propeller = Propeller("propeller_rpm", (-0.8, 0, 0), (1, 0, 0), 0.14, 0.4566, 0.007, 1026.0,
                          0.0, 1525.0, 1525.0)  # fmt: skip
    rudder = ControlSurface("rudder_deg", (-0.64, 0, 0), (0, 0, 1), 0.0133, 1.41, 0.4, 1026.0,
                            -20.0, 20.0, 100.0)  # fmt: skip
    assert not ActuatorSet((propeller, rudder)).pushes_sideways
    assert load_vehicle(HEAVY).six_dof_actuators.pushes_sideways


@pytest.mark.parametrize("estimator", ["filters", "ekf"])
def test_the_observer_finds_a_steady_current(estimator):
    """Held still in a 0.2 m/s current by the controller on the nominal model, the estimate
    converges on the true current, with either estimator (the filters' current observer, or
    the EKF of estimation/six_dof_current.py on exact measurements): within 2 % after 10 s
    (the observer's gain 0.2 per sample
    leaves 0.8^50 of the first error; the rest is the model's own prediction error)."""
    vehicle = load_vehicle(HEAVY)
    config = SixDofNmpcConfig(prediction_horizon=5, jit=False, estimator=estimator)
    controller = SixDofNmpc(vehicle, config)
    model = six_dof.six_dof_model(vehicle)
    current = np.array([0.2, -0.1, 0.0])
    state = np.zeros(12)
    state[2] = 2.0
    thrust = np.zeros(vehicle.six_dof_actuators.size)
    controller.reset(state, thrust)
    hold = np.tile([0, 0, 0, 0, 0, 0, 2.0, 0], (6, 1))  # [x, y, psi, u, v, r, z, z']
    for k in range(50):
        result = controller.compute(Observation(k, 0.2 * k, state.copy(), hold))
        substeps = controller.config.model_substeps
        state = six_dof.integrate(model, state, result.thrust, 0.2, substeps, held_current=current)
    np.testing.assert_allclose(controller._current[:2], current[:2], rtol=0.02)


# REMUS 100 at 10 m and 1.5 m/s: on a straight line at rest in the water (rudder and planes
# at 0) and in a turn (sideslip 0.1 m/s, yaw rate 0.05 rad/s, the rudder at 5 deg).
def _remus_at(sway, yaw_rate):
    state = np.zeros(12)
    state[[2, 6, 7, 11]] = 10.0, 1.5, sway, yaw_rate
    return state


STRAIGHT = (_remus_at(0.0, 0.0), np.array([1000.0, 0.0, 0.0]))
TURN = (_remus_at(-0.1, 0.05), np.array([1000.0, 5.0, -2.0]))
_SWAY, _YAW_RATE = six_dof.SIX_DOF.index("v"), six_dof.SIX_DOF.index("r")


def test_the_model_spread_is_each_uncertain_part_off_and_grows_in_a_turn():
    """Each column of the EKF's model spread is model_error_gain times the difference of one
    sample of the plant's integrator (models/six_dof.integrate, the same RK4 steps) on the
    vehicle with that part scaled by 1 + model_uncertainty and on the nominal one (to 1e-12:
    round-off). On the straight line the sway and yaw-rate spread is at least 10 times
    smaller than in the turn (measured: 63 and 480 times): the model's error is in the turn."""
    vehicle = load_vehicle("remus100")
    config = SixDofNmpcConfig(prediction_horizon=2, jit=False)
    controller = SixDofNmpc(vehicle, config)
    substeps, water, healthy = controller.config.model_substeps, np.zeros(3), np.ones(3)
    spreads = []
    for state, command in (STRAIGHT, TURN):
        spread = np.asarray(controller._ekf._spread(state, command, water, healthy))
        nominal = six_dof.integrate(six_dof.six_dof_model(vehicle), state, command, 0.25, substeps)
        for column, part in zip(spread.T, ("added_mass", "linear_damping", "quadratic_damping"),
                                strict=True):  # fmt: skip
            off = scaled(vehicle, {part: 1.0 + config.model_uncertainty})
            moved = six_dof.integrate(six_dof.six_dof_model(off), state, command, 0.25, substeps)
            np.testing.assert_allclose(
                column, config.model_error_gain * (moved - nominal), rtol=0, atol=1e-12
            )
        spreads.append(np.linalg.norm(spread, axis=1))
    straight, turn = spreads
    assert turn[_SWAY] > 10 * straight[_SWAY] and turn[_YAW_RATE] > 10 * straight[_YAW_RATE]


# The presets' navigation noise (SixDofNmpcConfig.measurement_std's defaults).
NAVIGATION_STD = np.array(
    [0.1, 0.1, 0.02, 0.005, 0.005, 0.005, 0.01, 0.01, 0.01, 0.005, 0.005, 0.005]
)


@pytest.mark.parametrize("seed", [0, 1])
def test_in_a_turn_the_spread_keeps_the_sway_estimate_on_a_model_20_percent_off(seed):
    """The EKF alone, on a plant with 20 % more added mass and 20 % less quadratic damping
    than its model, the commands of TURN held for 2 minutes (a steady turn after 30 s),
    the presets' noise: with the model's spread its sway estimate errs by at most 0.7 of what
    it errs by with the fixed process noise alone (model_uncertainty 0) (measured: 0.0030
    against 0.0051 m/s, 0.0029 against 0.0046). A steady turn is where the model's error is
    a bias that the fixed noise, trusting the model on a straight line, lets stand."""
    vehicle = load_vehicle("remus100")
    plant = six_dof.six_dof_model(scaled(vehicle, {"added_mass": 1.2, "quadratic_damping": 0.8}))
    errors = {}
    for uncertainty in (0.2, 0.0):
        config = SixDofNmpcConfig(prediction_horizon=2, jit=False, model_uncertainty=uncertainty)
        ekf = SixDofNmpc(vehicle, config)._ekf
        state, command = STRAIGHT[0].copy(), TURN[1]
        ekf.reset(state)
        rng = np.random.default_rng(seed)
        sway = []
        for k in range(480):
            estimate, _ = ekf.correct(state + rng.normal(0.0, NAVIGATION_STD))
            if k >= 120:
                sway.append(estimate[_SWAY] - state[_SWAY])
            ekf.predict(command, np.ones(3))
            state = six_dof.integrate(plant, state, command, 0.25, 4)
        errors[uncertainty] = np.sqrt(np.mean(np.square(sway)))
    assert errors[0.2] < 0.7 * errors[0.0]


def test_the_ekf_assumes_the_noise_the_scenario_says_its_sensors_have():
    """Omitted, measurement_std is the scenario's sensing, entry by entry (the REMUS presets'
    gives the former fixed default exactly); a sensor without noise is followed to a tenth of
    that; one the user names is kept. run.json's choices say where it came from."""
    helix = load_scenario("bluerov2-helix", ["controller.type=six-dof-nmpc"])
    assert helix.scenario.controller.measurement_std == pytest.approx(
        (0.01, 0.01, 0.01, 0.005, 0.005, 0.005, 0.01, 0.01, 0.01, 0.005, 0.005, 0.005)
    )  # fmt: skip
    assert "sensing" in helix.choices["measurement_std"]["why"]
    survey = load_scenario("remus100-survey")
    default = SixDofNmpcConfig.model_fields["measurement_std"].default
    assert survey.scenario.controller.measurement_std == default
    still = load_scenario(
        "bluerov2-helix",
        ["controller.type=six-dof-nmpc", "sensing.std=[0,0,0,0,0,0]", "sensing.depth_std_m=0"],
    )
    assert still.scenario.controller.measurement_std == pytest.approx(0.1 * np.array(default))
    named = [0.2] * 12
    given = load_scenario("remus100-survey", [f"controller.measurement_std={named}"])
    assert given.scenario.controller.measurement_std == tuple(named)
    assert "measurement_std" not in given.choices


def test_it_flies_the_six_dof_helix_within_the_hard_limits():
    """BlueROV2 Heavy, 8 s of the helix: every sample solved, no input beyond its limits or
    rate, position within 5 cm and depth within 2 cm after 4 s (the helix starts on the
    vehicle; these bound the settling, the 60 s run measures 9 mm, CHANGELOG)."""
    result = simulate(load_scenario("bluerov2-helix", SHORT))
    metrics = result.metrics
    assert metrics["thrust_limit_violations"] == metrics["thrust_rate_violations"] == 0
    assert metrics["fallback_steps"] == 0
    log = result.log
    late = log.t >= 4.0
    horizontal = log.horizontal()
    error = np.hypot(*(horizontal.state[late, i] - horizontal.reference[late, i] for i in (0, 1)))
    assert error.max() < 0.05
    assert np.abs(log.column("z") - log.column("z_ref"))[late].max() < 0.02
    assert log.format.measured_names == six_dof.SIX_DOF.names


def test_a_horizontal_scenario_refuses_it_in_one_line(monkeypatch, capsys):
    code, out, err = run_cli(
        monkeypatch, capsys, "run", "paper-ideal", "--set", "controller.type=six-dof-nmpc",
        "--no-figures", "--out", "never",
    )  # fmt: skip
    assert code == 2
    assert "controller.type" in err and "six-dof" in err and "Traceback" not in err
    assert len(err.strip().splitlines()) == 1


def test_obstacles_are_refused_with_a_controller_that_cannot_keep_clear():
    """Neither whole-vehicle controller has a keep-out constraint: flying such a scenario
    would go through the disc, so it is refused naming the field."""
    for controller in ("six-dof-nmpc", "los-pid"):
        with pytest.raises(ConfigError, match="^obstacles: .*keep-out"):
            load_scenario(
                "remus100-survey",
                [f"controller.type={controller}", "obstacles=[{center: [60.0, 0.0], radius: 2.0}]"],
            )


def test_a_thruster_vehicles_dump_has_no_hull_lift_key():
    """run.json's vehicle and the compiled model's cache key are as before the field."""
    assert "hull_lift" not in load_vehicle(HEAVY).model_dump()["six_dof"]


TORPEDO_SHORT = "tests/scenarios/remus100-short.yaml"


@pytest.mark.parametrize(
    "starved",
    [
        "controller.max_iterations=2",  # IPOPT never converges from a warm start in 2
        "controller.solver_time_limit_ms=0.001",  # every solve is past its deadline
    ],
)
def test_a_torpedo_whose_optimiser_never_delivers_is_flown_by_its_autopilot(starved):
    """Every solve is refused by the safety shell, so from the first sample (no plan to fall
    back on) the recovery flies: the torpedo's los-pid, within the hard limits, on the path.
    The run says so: every step a recovery, the verdict not ok. Bounds: the autopilot alone
    measured 0.073 m cross-track and 0.004 m depth on this case; 0.2 m and 0.02 m catch a
    recovery that does nothing (the torpedo drifts metres in the 0.3 m/s current)."""
    result = simulate(load_scenario(TORPEDO_SHORT, ["controller.type=six-dof-nmpc", starved]))
    metrics = result.metrics
    commands = len(result.log.t) - 1  # the last row is the final state: no command
    assert metrics["recovery_steps"] == metrics["fallback_steps"] == commands
    assert metrics["actuator_limit_violations"] == metrics["actuator_rate_violations"] == 0
    assert metrics["cross_track_rms_after_transient_m"] < 0.2
    assert metrics["depth_rms_error_after_transient_m"] < 0.02
    assert metrics["verdict"] != "ok"


def test_the_recovery_is_chosen_by_what_the_vehicle_has():
    """los-pid needs a propeller, a rudder and stern planes: the torpedo's shell recovers with
    it; the BlueROV2 Heavy's with the channel pair's feedbacks (horizontal thrusters, a heave
    section, vertical thrusters after them)."""
    heavy = load_scenario("bluerov2-helix", SHORT)
    torpedo = load_scenario(TORPEDO_SHORT, [])
    assert isinstance(
        build_controller(heavy.scenario.controller, heavy.model).recovery, ChannelFeedback
    )
    recovery = build_controller(torpedo.scenario.controller, torpedo.model).recovery
    assert isinstance(recovery, AutopilotFeedback)
    assert recovery.autopilot.sample_time == torpedo.scenario.controller.sample_time


# What the channel feedback holds the starved BlueROV2 Heavy within (m; measured below):
# over the whole run, over its last 5 s (the current known by then), and in depth.
HELD_POSITION_M = 0.4
HELD_SETTLED_M = 0.05
HELD_DEPTH_M = 0.12


def _heavy_starved(monkeypatch, recovered: bool, estimator: str = "ekf"):
    """20 s of the BlueROV2 Heavy's helix (a 0.2 m/s current) flown by six-dof-nmpc with every
    solve refused (IPOPT capped at one iteration), with its shell's recovery or without one
    (the shell then holds the last command: zero thrust, no plan was ever made)."""
    from dataclasses import replace

    from auvmpc.controllers.registry import REGISTRY

    if not recovered:
        entry = REGISTRY["six-dof-nmpc"]
        monkeypatch.setitem(REGISTRY, "six-dof-nmpc", replace(entry, recovery=None))
    overrides = [*SHORT, "duration=20", "controller.max_iterations=1",
                 f"controller.estimator={estimator}"]  # fmt: skip
    return simulate(load_scenario("bluerov2-helix", overrides))


@pytest.mark.parametrize("estimator", ["ekf", "filters"])
def test_a_thruster_vehicle_whose_optimiser_never_delivers_is_held_by_the_channel_feedback(
    monkeypatch, estimator
):
    """Every solve refused from the first sample: the channel feedback flies every command,
    within the hard limits, and keeps the vehicle on its helix; without it the vehicle stays
    where it was, drifting with the current, while the reference moves on. Measured on this
    case: with it at most 0.286 m of position error with the EKF (its current estimate,
    which the feedback is fed, converges from its prior over the first seconds: 0.28 m at
    2 s, 0.04 m at 12 s, 0.025 m at the end) and 0.073 m with the filters' observer, 0.061 m
    of depth; without it 8.4 m and 0.18 m. The bounds, 0.4 m (0.05 m over the last 5 s) and
    0.12 m, leave the feedback room and catch one that does not steer."""
    run = _heavy_starved(monkeypatch, recovered=True, estimator=estimator)
    held = run.metrics
    commands = held["fallback_steps"]
    assert commands > 0 and held["recovery_steps"] == commands
    assert held["thrust_limit_violations"] == held["thrust_rate_violations"] == 0
    assert held["max_position_error_m"] < HELD_POSITION_M
    assert held["max_depth_error_m"] < HELD_DEPTH_M
    log = np.genfromtxt(io.StringIO(run.csv_text()), delimiter=",", names=True)
    last = log["t"] >= 15.0
    settled = np.hypot(log["x"] - log["x_ref"], log["y"] - log["y_ref"])[last]
    assert settled.max() < HELD_SETTLED_M
    drifted = _heavy_starved(monkeypatch, recovered=False).metrics
    assert drifted["recovery_steps"] == 0
    assert drifted["max_position_error_m"] > HELD_POSITION_M


# Round-off in the allocation's pseudo-inverse and damped least squares (N): far below a thrust.
ALLOCATION_ROUND_OFF_N = 1e-6


def test_the_channel_feedback_asks_a_dead_thruster_for_nothing():
    """On the BlueROV2 Heavy (4 horizontal, 4 vertical thrusters), against analytic truth:
    level and still on a still reference, it asks the verticals for the net weight (0.98 N
    up, the heave section's net buoyancy) and the horizontals for nothing; off the reference,
    with one horizontal and one vertical thruster dead, the dead ones get nothing and the
    others make the same surge, sway and yaw force and the same heave force as the healthy
    set (the minimum-norm allocations are exact while no limit cuts them)."""
    vehicle = load_vehicle(HEAVY)
    T = np.asarray(vehicle.six_dof.T)
    n = vehicle.n_thrusters
    feedback = ChannelFeedback(vehicle, 0.25, keep_out_extra=0.5)
    reference = np.zeros((3, 8))
    reference[:, 6] = 2.0  # [x y psi u v r z z'], NED: 2 m down
    still = np.zeros(12)
    still[2] = 2.0
    zeros = np.zeros(T.shape[1])
    held = feedback.command(Observation(0, 0.0, still, reference), zeros, Proposal(None))
    np.testing.assert_allclose(held[:n], 0.0, atol=ALLOCATION_ROUND_OFF_N)
    weight = -vehicle.heave.net_buoyancy_N  # N, down
    wrench = T @ held
    assert wrench[2] == pytest.approx(-weight, abs=ALLOCATION_ROUND_OFF_N)  # NED: up
    off = still.copy()
    off[[0, 1, 2, 5]] = 0.2, -0.1, 2.1, 0.05  # m, m, m, rad
    healthy = feedback.command(Observation(0, 0.0, off, reference), zeros, Proposal(None))
    share = np.ones(T.shape[1])
    share[[0, n + 1]] = 0.0
    crippled = feedback.command(
        Observation(0, 0.0, off, reference, effectiveness=share), zeros, Proposal(None)
    )
    assert crippled[0] == crippled[n + 1] == 0.0
    planar_and_heave = [0, 1, 2, 5]  # X, Y, Z, N
    np.testing.assert_allclose(
        (T @ (share * crippled))[planar_and_heave],
        (T @ healthy)[planar_and_heave],
        atol=ALLOCATION_ROUND_OFF_N,
    )


def _fixes(count: int, sigma: float, seed: int = 7) -> tuple[np.ndarray, np.ndarray]:
    """``count`` 6-DOF states of a straight run at 1.5 m/s, 0.2 m/s sideslip, heading 0.3
    rad, 10 deg nose down (truth), and the same with white noise ``sigma`` (m) on x and y."""
    truth = np.zeros((count, 12))
    truth[:, 4], truth[:, 5], truth[:, 6], truth[:, 7] = -0.17, 0.3, 1.5, 0.2
    R = np.asarray(six_dof.Rzyx(0.0, -0.17, 0.3), dtype=float)
    velocity = R[:2] @ truth[0, 6:9]
    truth[:, 0:2] = np.outer(0.25 * np.arange(count), velocity)
    noisy = truth.copy()
    noisy[:, 0:2] += np.random.default_rng(seed).normal(0.0, sigma, size=(count, 2))
    return truth, noisy


def test_the_position_fix_filter_leaves_what_a_complementary_filter_leaves():
    """Fixes with white noise sigma on a straight run, the velocities exact: dead reckoning
    is exact, so the filtered position errs by the fix noise through a first-order filter
    of gain K, variance K / (2 - K) sigma^2 (0.23 sigma at the default 0.1), unbiased by
    the motion. 20000 samples: the standard deviation within 3 % of it (sampling error
    0.5 %, a few times that from the filter's memory of 1 / K samples), the mean within
    3 standard errors of zero."""
    vehicle = load_vehicle("remus100")
    config = SixDofNmpcConfig(prediction_horizon=2, jit=False, estimator="filters")
    controller = SixDofNmpc(vehicle, config)
    gain, sigma = controller.config.position_fix_gain, 0.1
    truth, noisy = _fixes(20001, sigma)
    errors = []
    for k in range(len(noisy)):
        controller._filter_fix(noisy[k])
        errors.append(noisy[k, 0:2] + controller._fix_correction - truth[k, 0:2])
    errors = np.array(errors[200:])  # after 20 memories of the start
    expected = sigma * np.sqrt(gain / (2.0 - gain))
    np.testing.assert_allclose(np.std(errors, axis=0), expected, rtol=0.03)
    assert np.all(np.abs(errors.mean(axis=0)) < 3.0 * expected * np.sqrt(2.0 / gain / len(errors)))


def test_moved_targets_are_the_program_from_the_filtered_position():
    """The position targets moved back by the filter's correction give the command the
    program gives started from the filtered position with the targets in place: nothing in
    the 6-DOF model depends on x and y. Both solved cold by IPOPT to its 1e-6 tolerance;
    the commands agree to 1e-6 of each input's range."""
    vehicle = load_vehicle("remus100")
    config = SixDofNmpcConfig(prediction_horizon=6, jit=False, estimator="filters")
    raw, moved = SixDofNmpc(vehicle, config), SixDofNmpc(vehicle, config)
    state = np.zeros(12)
    state[[2, 6]] = 5.0, 1.5  # 5 m deep at 1.5 m/s, heading along x
    command = np.array([900.0, 0.0, 0.0])
    rows = np.array([[0.375 * k, 0.0, 0.0, 1.5, 0.0, 0.0, 5.0, 0.0] for k in range(7)])
    correction = np.array([0.04, -0.07])  # filtered less measured
    raw.reset(state, command)
    raw._fix_correction = correction.copy()
    shifted = state.copy()
    shifted[:2] += correction
    moved.reset(shifted, command)
    first = raw.compute(Observation(0, 0.0, state, rows)).thrust
    second = moved.compute(Observation(0, 0.0, shifted, rows)).thrust
    span = vehicle.six_dof_actuators.limits.upper - vehicle.six_dof_actuators.limits.lower
    np.testing.assert_allclose(first, second, atol=1e-6 * float(np.min(span)))


def test_a_position_fix_gain_of_one_steers_the_raw_fix():
    """position_fix_gain 1 keeps no correction: the targets are the reference's positions."""
    vehicle = load_vehicle("remus100")
    controller = SixDofNmpc(
        vehicle,
        SixDofNmpcConfig(
            prediction_horizon=3, jit=False, estimator="filters", position_fix_gain=1.0
        ),
    )
    for state in _fixes(5, 0.1)[1]:
        controller._filter_fix(state)
    assert not controller._fix_correction.any()
    rows = np.array([[1.0 * k, 2.0, 0.0, 1.5, 0.0, 0.0, 5.0, 0.0] for k in range(4)])
    nodes = controller._nodes(np.zeros(12), rows)
    np.testing.assert_array_equal(nodes[0:2], rows[1:, 0:2].T)
