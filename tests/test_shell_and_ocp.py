"""The problem stated once (TrackingOcp) and the one safety shell around every controller."""

from __future__ import annotations

import numpy as np
import pytest

from auvmpc.controllers.base import ControlStatus, Observation
from auvmpc.controllers.config import ControllerConfig
from auvmpc.controllers.shell import INFO_KEYS, Proposal, ShelledController
from auvmpc.experiments.run import make_controller
from auvmpc.references import PaperOvalConfig, make_reference
from auvmpc.scenario import load_scenario

# The projection is one np.clip: exact up to the subtraction that checks it.
LIMIT_ROUND_OFF_N = 1e-12


# -- the problem stated once ------------------------------------------------------------------
def test_weights_by_state_name_equal_the_list_form():
    by_name = ControllerConfig(Q={"x": 5, "y": 5, "psi": 5, "u": 1, "v": 1, "r": 1}, S={"x": 3})
    assert by_name.Q == ControllerConfig().Q
    assert by_name.S == (3, 0, 0, 0, 0, 0)  # names left out weigh 0


def test_unknown_state_name_is_refused():
    with pytest.raises(ValueError, match=r"unknown state names \['z'\]"):
        ControllerConfig(Q={"x": 1, "z": 1})


@pytest.mark.parametrize("vehicle", ["jmse", "bluerov"])
def test_ocp_states_limits_and_schedule_once(vehicle, request):
    model = request.getfixturevalue(vehicle)
    config = ControllerConfig(sample_time=0.25, move_steps=(0, 1, 3), R=(0.5,))
    ocp = config.ocp(model)
    n = model.n_thrusters
    np.testing.assert_array_equal(ocp.input_lower, np.full(n, model.thrust_min))
    np.testing.assert_array_equal(ocp.input_upper, np.full(n, model.thrust_max))
    # The rate limit is in N/s: one sample's move scales with the sample time.
    np.testing.assert_allclose(ocp.max_move, np.full(n, model.thrust_rate_limit * 0.25))
    np.testing.assert_array_equal(ocp.held[:6], [0, 1, 1, 2, 2, 2])
    np.testing.assert_array_equal(ocp.input_weight, np.full(n, 0.5))
    weights = ocp.stage_weights()
    assert weights.shape == (config.prediction_horizon, 6)
    np.testing.assert_array_equal(weights[-1], config.S)
    np.testing.assert_array_equal(weights[0], config.Q)
    filled = config.for_vehicle(model)  # the radius from the vehicle's size
    assert ocp.keep_out_extra == filled.vehicle_radius + filled.obstacle_margin


# The internal thrust's projector is damped by 1e-9 of the largest eigenvalue of T T'
# (ocp/tracking.py), which leaves it off by ~1e-9 on the force directions and, with one R for
# all thrusters, its weight by that squared. Measured 2.8e-16 (healthy) and 4.2e-16 (a dead
# thruster) relative to R on BlueROV2 Heavy: round-off.
INTERNAL_WEIGHT_TOL = 1e-12


@pytest.mark.parametrize("dead", [None, 2])
def test_internal_thrust_weight_is_r_on_the_thrust_that_makes_no_force(bluerov, dead):
    """With the increment penalty R also weighs the internal thrust (ocp/tracking.py): the
    thrusts the acting allocation T diag(e) maps to no force or moment. Healthy BlueROV2
    Heavy: its four 45-degree thrusters pushing against each other, the null vector v of T,
    so M = R v v'. With thruster 3 dead (e = 0) the other three have no such thrust left and
    only the dead one's command makes none: M = R e_3 e_3'."""
    R = 0.3
    ocp = ControllerConfig(R=(R,)).ocp(bluerov)
    assert ocp.weights_internal_thrust
    effectiveness = np.ones(bluerov.n_thrusters)
    if dead is None:
        null = np.linalg.svd(bluerov.T)[2][-1]
    else:
        effectiveness[dead] = 0.0
        null = np.eye(bluerov.n_thrusters)[dead]
    weight = ocp.internal_weight(effectiveness)
    np.testing.assert_allclose(weight, R * np.outer(null, null), atol=INTERNAL_WEIGHT_TOL * R)
    # the paper's absolute penalty weighs all the thrust already: nothing added
    assert not ControllerConfig(thrust_penalty="absolute").ocp(bluerov).weights_internal_thrust


# -- the shell --------------------------------------------------------------------------------
class _Scripted(ShelledController):
    """A back end that proposes what the test tells it to."""

    def __init__(self, model, proposals):
        self.sample_time, self.preview_steps = 0.5, 1
        self.limits = ControllerConfig().ocp(model).limits
        self.proposals = list(proposals)
        self.told = []
        self.reset(np.zeros(6), np.zeros(model.n_thrusters))

    def propose(self, observation, previous):
        return self.proposals.pop(0)

    def applied(self, command, fell_back):
        self.told.append((command.copy(), fell_back))


def _observation():
    return Observation(0, 0.0, np.zeros(6), np.zeros((2, 6)))


@pytest.mark.parametrize("vehicle", ["jmse", "bluerov"])
def test_shell_projects_falls_back_and_says_so(vehicle, request):
    model = request.getfixturevalue(vehicle)
    n, step = model.n_thrusters, model.thrust_rate_limit * 0.5
    plan = np.tile(np.linspace(1.0, 3.0, 3)[:, None], (1, n)) * step / 4
    far = np.full((1, n), 10 * model.thrust_max)
    shell = _Scripted(
        model,
        [
            Proposal(plan=plan),  # inside the limits: applied as proposed
            Proposal(plan=None),  # failed: the plan's next move
            Proposal(plan=plan, solve_time_s=1.0),  # late: the move after that
            Proposal(plan=far, max_slack=0.5),  # outside: projected (and relaxed)
            Proposal(plan=np.full((1, n), np.nan)),  # not finite: fallback
        ],
    )
    shell.solver_time_limit_ms = 100.0
    results = [shell.compute(_observation()) for _ in range(5)]
    statuses = [r.status for r in results]
    assert statuses == [
        ControlStatus.OK,
        ControlStatus.FALLBACK,
        ControlStatus.FALLBACK,
        ControlStatus.RELAXED,
        ControlStatus.FALLBACK,
    ]
    np.testing.assert_allclose(results[0].thrust, plan[0])
    np.testing.assert_allclose(results[1].thrust, plan[1])
    np.testing.assert_allclose(results[2].thrust, plan[2])
    # Projected: one rate step up from the previous command, never past the force limit.
    expected = np.minimum(results[2].thrust + step, model.thrust_max)
    np.testing.assert_allclose(results[3].thrust, expected, rtol=0, atol=LIMIT_ROUND_OFF_N)
    assert [fell for _, fell in shell.told] == [False, True, True, False, True]
    for result in results:
        assert set(INFO_KEYS) <= set(result.info)
        assert result.info["fallback"] == float(result.status is ControlStatus.FALLBACK)


class _Recording:
    """A recovery that records the observation it is asked to fly."""

    watches_yaw, yaw_rate_index = False, 5

    def __init__(self):
        self.seen = []

    def release(self):
        pass

    def command(self, observation, previous, proposal):
        self.seen.append(observation.reference)
        return previous


def test_the_recovery_flies_the_reference_the_back_end_flew(jmse):
    """A back end on its own clock (a crippled vehicle's schedule) hands the shell its rows;
    the recovery, when it takes over, flies those rows, not the loop's; without them, the
    loop's."""
    own = np.full((2, 6), 7.0)
    shell = _Scripted(jmse, [Proposal(plan=None, reference=own), Proposal(plan=None)])
    shell.recovery = _Recording()
    shown = _observation()
    shell.compute(shown)
    shell.compute(shown)
    assert shell.recovery.seen[0] is own and shell.recovery.seen[1] is shown.reference


@pytest.mark.parametrize(
    "label", ["baseline", "mpc", "ltv-mpc-nc30", "nmpc", "nmpc-full", "do-mpc"]
)
def test_every_controller_reports_the_same_info_keys(label):
    from auvmpc.controllers.compiled_nmpc import CompiledNmpc
    from auvmpc.controllers.config import CONTROLLER_PRESETS

    overrides = [*CONTROLLER_PRESETS[label], "controller.offset_free=false"]
    resolved = load_scenario("paper-obstacles", overrides)
    controller = make_controller(resolved.scenario, resolved.model)
    reference = make_reference(PaperOvalConfig())
    state = np.array(resolved.scenario.initial_state)
    controller.reset(state, np.zeros(resolved.model.n_thrusters))
    preview = reference.states(0.5 * np.arange(controller.preview_steps + 1))
    result = controller.compute(Observation(0, 0.0, state, preview))
    # The shell's rules are in every optimising controller: Python's, or the C's
    assert isinstance(controller, ShelledController | CompiledNmpc)
    assert set(INFO_KEYS) <= set(result.info)
    assert result.status is not ControlStatus.FALLBACK
