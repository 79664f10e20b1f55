"""Constraint tightening for a bounded disturbance (issue 14, part 2; ocp/tightening.py).

The back-offs against analytic truth (the support of the reachable deviation is attained by
the extremal disturbance sequence and never exceeded by others), the zero bound against the
nominal controller, the worst-direction current beside a static obstacle, the thrust limits,
and the bad inputs."""

from __future__ import annotations

import numpy as np
import pytest

import auvmpc.experiments.run
from auvmpc.api import load_scenario
from auvmpc.controllers.config import DisturbanceBound
from auvmpc.errors import ConfigError
from auvmpc.experiments.run import simulate
from auvmpc.ocp.tightening import (
    OBSTACLE_BACKOFF_LIMIT_M,
    THRUST_BACKOFF_LIMIT,
    Tightening,
    error_responses,
    tightened_box,
)
from auvmpc.sim.metrics import MARGIN_TOLERANCE_M

# A zero bound must leave the commands as the nominal controller's up to round-off: the
# back-offs are exact zeros, so only the order of floating-point operations may differ (it
# does not today; 1e-9 N is the tolerance, a millionth of a thruster's noise floor).
ZERO_BOUND_COMMAND_TOL_N = 1e-9
# The support function is a sum of norms: the extremal sequence attains it up to round-off.
SUPPORT_ROUND_OFF_TOL = 1e-9

# The side pass (worst direction): the track along x at 0.4 m/s, a static disc of 0.5 m at
# (12, 1), so the vehicle (0.5 m disc, 0.1 m margin) passes on the -y side; a constant 10 N
# current along +y pushes it towards the disc; the prediction does not know the current
# (offset_free false) and the bound says 10 N.
# The tightening is ltv-mpc's and mpc's (the default nmpc refuses a bound).
LTV_MPC = "controller.type=ltv-mpc"
SIDE_PASS = [
    LTV_MPC,
    "obstacle_sensor=null",
    "obstacles=[{center: [12.0, 1.0], radius: 0.5}]",
    "disturbance.current_force_world=[0.0, 10.0]",
    "controller.offset_free=false",
    "duration=45",
]
BOUND_N = 10.0


# -- the back-offs against analytic truth ---------------------------------------------------
def _random_problem(rng, ny=8, nx=6, nu=4):
    A = np.eye(nx) + 0.1 * rng.standard_normal((ny, nx, nx))
    B = 0.1 * rng.standard_normal((ny, nx, nu))
    G = 0.1 * rng.standard_normal((ny, nx, 3))
    gain = 0.5 * rng.standard_normal((nu, nx))
    return A, B, G, gain


def _deviation(A, B, G, K, disturbances):
    """e_n of the linearised error dynamics under a disturbance sequence (ny, 3), n = 0..ny."""
    e = [np.zeros(A.shape[1])]
    for n in range(len(A)):
        e.append((A[n] + B[n] @ K[n]) @ e[-1] + G[n] @ disturbances[n])
    return np.array(e)


def test_backoff_is_attained_by_the_extremal_disturbance_and_bounds_every_other():
    rng = np.random.default_rng(14)
    A, B, G, gain = _random_problem(rng)
    ny, nx = A.shape[0], A.shape[1]
    nominal = np.zeros((ny, nx))
    nominal[:, 2] = rng.uniform(-np.pi, np.pi, ny)  # headings
    force, moment = 3.0, 0.5
    tightening = Tightening(force, moment, [0.0], gain[None], np.full(4, 1e6))  # no cap
    direction = 0.1 * rng.standard_normal(nx)  # inside the obstacle cap
    step = ny - 1
    backoffs = tightening.backoffs(A, B, G, nominal, np.array([step]), direction[None])
    assert backoffs.rows[0] < OBSTACLE_BACKOFF_LIMIT_M
    K = tightening.feedback(nominal)
    M = error_responses(A, B, G, K)
    # The extremal sequence: each w_j aligned with a' M[n, :, j] within W.
    weights = np.einsum("k,kjw->jw", direction, M[step])  # (ny, 3)
    extremal = np.zeros((ny, 3))
    norms = np.hypot(weights[:, 0], weights[:, 1])
    aligned = norms > 0.0  # w_j for j >= step does not reach e_step
    extremal[aligned, :2] = force * weights[aligned, :2] / norms[aligned, None]
    extremal[:, 2] = moment * np.sign(weights[:, 2])
    reached = direction @ _deviation(A, B, G, K, extremal)[step]
    assert reached == pytest.approx(backoffs.rows[0], abs=SUPPORT_ROUND_OFF_TOL)
    for _ in range(200):  # any other sequence inside W stays below it
        angle = rng.uniform(0, 2 * np.pi, ny)
        radius = force * np.sqrt(rng.uniform(0, 1, ny))
        w = np.column_stack([radius * np.cos(angle), radius * np.sin(angle)])
        w = np.column_stack([w, rng.uniform(-moment, moment, ny)])
        assert direction @ _deviation(A, B, G, K, w)[step] <= backoffs.rows[0] + 1e-12


def test_backoff_grows_linearly_without_feedback_on_a_pure_integrator():
    # e_{n+1} = e_n + g w_n on x only: the back-off at step n is n g w_F exactly.
    ny, g, force = 6, 0.05, 4.0  # 1.2 m at the last step: inside the cap
    A = np.repeat(np.eye(6)[None], ny, axis=0)
    B = np.zeros((ny, 6, 4))
    G = np.zeros((ny, 6, 3))
    G[:, 0, 0] = g
    tightening = Tightening(force, 0.0, [0.0], np.zeros((1, 4, 6)), np.full(4, 15.0))
    direction = np.zeros((ny, 6))
    direction[:, 0] = 1.0
    steps = np.arange(1, ny + 1)
    backoffs = tightening.backoffs(A, B, G, np.zeros((ny, 6)), steps, direction)
    np.testing.assert_allclose(backoffs.rows, steps * g * force, atol=SUPPORT_ROUND_OFF_TOL)
    np.testing.assert_array_equal(backoffs.thrust, 0.0)  # no feedback, no thrust taken


def test_thrust_backoff_is_capped_and_the_box_stays_feasible():
    rng = np.random.default_rng(3)
    A, B, G, gain = _random_problem(rng)
    half_range = np.full(4, 15.0)
    # Far beyond what the thrust can hold.
    tightening = Tightening(1e4, 1e3, [0.0], gain[None], half_range)
    backoffs = tightening.backoffs(
        A, B, G, np.zeros((len(A), 6)), np.zeros(0, dtype=int), np.zeros((0, 6))
    )
    assert np.all(backoffs.thrust <= THRUST_BACKOFF_LIMIT * half_range + 1e-12)
    np.testing.assert_array_equal(backoffs.thrust[0], 0.0)  # u_0 is applied before any error
    previous = np.array([15.0, -15.0, 0.0, 14.0])  # at the limits: the box must still hold it
    max_move = np.full(4, 2.5)
    lower, upper = tightened_box(
        -half_range, half_range, backoffs.thrust, np.arange(len(A)), previous, max_move
    )
    assert np.all(lower <= upper)
    assert np.all(lower >= -half_range) and np.all(upper <= half_range)
    # Reachable: moving at the rate limit from the previous command meets every step's box.
    for n in range(len(A)):
        reach = (n + 1) * max_move
        lowest, highest = previous - reach, previous + reach
        assert np.all(np.maximum(lower[n], lowest) <= np.minimum(upper[n], highest))


# -- the controller --------------------------------------------------------------------------
def _forced_zero_tightening(monkeypatch):
    """make_controller, with the full tightening path on a zero disturbance set (the
    Jacobians in d, the support sums, the per-step boxes) instead of none."""
    from auvmpc.controllers.mpc import robust_tightening

    original = auvmpc.experiments.run.make_controller

    def make(scenario, model):
        controller = original(scenario, model)
        bounded = scenario.controller.model_copy(
            update={"disturbance_bound": DisturbanceBound(force_N=1.0, moment_Nm=1.0)}
        )
        gains = robust_tightening(model, bounded.for_vehicle(model))
        controller.tightening = Tightening(0.0, 0.0, gains.speeds, gains.gains, gains.half_range)
        return controller

    monkeypatch.setattr(auvmpc.experiments.run, "make_controller", make)


@pytest.mark.parametrize(
    "overrides",
    [
        ["duration=40", LTV_MPC],
        ["duration=40", LTV_MPC, "vehicle=bluerov2-heavy", "controller.R=null"],
        ["duration=40", "controller.type=mpc"],
    ],
    ids=["ltv-mpc-jmse2210", "ltv-mpc-bluerov2-heavy", "mpc-jmse2210"],
)
def test_zero_bound_commands_equal_the_nominal_controllers(monkeypatch, overrides):
    nominal = simulate(load_scenario("encounter-head-on", overrides))
    stated_zero = simulate(
        load_scenario("encounter-head-on", [*overrides, "controller.disturbance_bound.force_N=0"])
    )
    _forced_zero_tightening(monkeypatch)
    machinery = simulate(load_scenario("encounter-head-on", overrides))
    assert np.isfinite(nominal.log.clearance_m).any()  # the obstacle rows were in play
    for other in (stated_zero, machinery):
        np.testing.assert_allclose(
            other.log.thrust, nominal.log.thrust, rtol=0.0, atol=ZERO_BOUND_COMMAND_TOL_N
        )
    assert machinery.metrics["max_obstacle_backoff_m"] == 0.0
    assert machinery.metrics["max_thrust_backoff_fraction"] == 0.0


def test_worst_direction_current_beside_an_obstacle_tightened_keeps_clear():
    nominal = simulate(load_scenario("encounter-head-on", SIDE_PASS))
    tightened = simulate(
        load_scenario(
            "encounter-head-on", [*SIDE_PASS, f"controller.disturbance_bound.force_N={BOUND_N}"]
        )
    )
    margin = nominal.resolved.scenario.controller.obstacle_margin
    # The nominal controller, not told about the current, is pushed inside its margin ...
    assert nominal.metrics["min_obstacle_clearance_m"] < margin - MARGIN_TOLERANCE_M
    assert nominal.metrics["time_inside_margin_s"] > 0.0
    # ... the tightened one keeps the true vehicle clear (and here outside the margin too).
    assert tightened.metrics["min_obstacle_clearance_m"] >= 0.0
    assert tightened.metrics["time_inside_margin_s"] == 0.0
    assert tightened.metrics["max_obstacle_backoff_m"] > 0.0
    for result in (nominal, tightened):
        assert result.metrics["thrust_limit_violations"] == 0
        assert result.metrics["thrust_rate_violations"] == 0
        assert result.metrics["fallback_steps"] == 0
    lower, upper = tightened.resolved.model.thrust_limits
    assert lower <= tightened.log.thrust.min() and tightened.log.thrust.max() <= upper


# -- bad inputs ------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("overrides", "message"),
    [
        (
            [LTV_MPC, "controller.disturbance_bound.force_N=-1"],
            r"controller\.disturbance_bound\.force_N",
        ),
        # the default nmpc does not tighten: it has no such knob
        (["controller.disturbance_bound.force_N=1"], "not of controller type nmpc"),
        ([LTV_MPC, "controller.disturbance_bound.moment_Nm=inf"], r"disturbance_bound\.moment_Nm"),
        ([LTV_MPC, "controller.disturbance_bound.forse_N=1"], "unknown key"),
        (
            ["controller.type=nmpc", "controller.disturbance_bound.force_N=1"],
            r"^controller\.disturbance_bound: a knob of mpc, ltv-mpc, not of controller type nmpc",
        ),
    ],
)
def test_bad_bounds_are_refused_in_one_line(overrides, message):
    with pytest.raises(ConfigError, match=message) as caught:
        load_scenario("encounter-head-on", overrides)
    assert len(str(caught.value).splitlines()) == 1


def test_underactuated_vehicle_refuses_a_bound_in_one_line():
    scenario = load_scenario(
        "encounter-head-on",
        [
            LTV_MPC,
            "vehicle=videoray-pro3",
            "controller.R=null",
            "controller.disturbance_bound.force_N=1",
        ],
    )
    with pytest.raises(ConfigError, match="disturbance_bound") as caught:
        simulate(scenario)
    assert len(str(caught.value).splitlines()) == 1
