"""The nonlinear MPC (``nmpc``) against the package's model, an independent solver and the issue.

What is checked, and against what:

- the program: its shooting gaps are exactly the package's RK4 map of ``vehicle.dynamics``
  (``integrators.rk4``), its obstacle rows the distance to each disc, its cost LinearMpc's
  cost written out here;
- the two solution modes against each other: the real-time iteration, given enough SQP steps
  on one sample, converges to IPOPT's solution of the same program;
- the full solve against LtvMpc's condensed QP near a steady trajectory, where the
  linearisation is exact to first order: the first moves differ at second order only;
- the hard limits under random states and references, the fallback on failure and
  time-out, the RELAXED status when no plan can keep clear of an obstacle;
- the issue's acceptance bounds on the paper scenarios (marked slow).

Measured values behind each tolerance are stated next to it.
"""

from __future__ import annotations

import functools
from types import SimpleNamespace

import casadi as ca
import numpy as np
import pytest

from auvmpc.controllers.base import ControlStatus, Observation, ObstacleState
from auvmpc.controllers.config import ControllerConfig, NmpcMode, ThrustPenalty
from auvmpc.controllers.ltv import LtvMpc
from auvmpc.controllers.nmpc import (
    MAX_OBSTACLES,
    MultipleShootingProgram,
    NonlinearMpc,
    tracked_reference,
)
from auvmpc.experiments.run import RunResult, simulate
from auvmpc.models.integrators import rk4
from auvmpc.models.vehicle import body_from_world, dynamics, load_vehicle
from auvmpc.references import CircleConfig, LineConfig, PaperOvalConfig, make_reference
from auvmpc.scenario import load_scenario
from auvmpc.solvers.real_time_iteration import RealTimeIteration
from tests.conftest import random_limit_case

SAMPLE_TIME = 0.5  # s, the paper's Te
HORIZON = 30  # ny, the paper's
PRESETS = ("jmse2210", "bluerov2-heavy")  # bluerov2-heavy has asymmetric limits [-40.2, 51.5] N
# RK4 steps per sample in the prediction model. The BlueROV's quadratic surge damping has
# the eigenvalue 2 Xuu |u| / m11 = -14 1/s at 1 m/s: one RK4 step of 0.5 s (-7.1) is outside
# RK4's stability interval (-2.79), four (-1.8) are inside. With one, the prediction overflows
# and every step falls back (safe, but it would test nothing else).
SUBSTEPS = {"jmse2210": 1, "bluerov2-heavy": 4}
MODES = (NmpcMode.FULL, NmpcMode.REAL_TIME)

# The program's RK4 (CasADi SX) vs integrators.rk4 on NumPy: the same operations in a
# different order, so round-off only. Measured 2.1e-14 on states up to 9 m.
ROUND_OFF = 1e-12
# The obstacle rows use sqrt(d^2 + 1e-6): at d >= 0.1 m that is d + 5e-6 m at most.
# Measured 4.6e-7 m.
DISTANCE_SMOOTHING_TOL_M = 1e-5
# Real-time iteration after RTI_SQP_STEPS SQP steps on one sample vs IPOPT (tol 1e-8,
# unscaled): measured 4.5e-8 N (every move free) and 1.6e-8 N (nc 3, increment penalty) on the
# first thrust with the default trust region and without, 1.2e-9 m on the predicted states.
# 1e-6 leaves room for DAQP's tolerance. The trust region slows the steps: after 10 of them
# 2.2e-5 N (free) and 9.7e-3 N (nc 3) off, after 20 4.7e-8 and 1.9e-5 N, after 30 as above.
RTI_SQP_STEPS = 30
RTI_VS_FULL_THRUST_TOL_N = 1e-6
RTI_VS_FULL_STATE_TOL = 1e-6
# Full solve vs LtvMpc (one linearisation along the steady trajectory, no trust region) at
# state offsets delta: the first moves differ by O(delta^2). Measured 8.4e-4, 1.1e-5, 6.6e-8 N
# at delta = 1e-2, 1e-3, 1e-4: observed orders 1.89 and 2.21.
LTV_OFFSETS = (1e-2, 1e-3, 1e-4)
LTV_ORDER = 2.0
LTV_ORDER_TOL = 0.35
# Hard limits are exact: the applied command is projected into the box; only the round-off
# of one subtraction (|F - F_prev| computed here) is allowed.
LIMIT_ROUND_OFF_N = 1e-12
# Far obstacles (in slots or beyond the slot count) must not change the solution. Both
# interior-point solvers keep the far rows, inactive (the sparse real-time QP has a fixed
# structure; their lower bound is lifted), which moves their iterates within tolerance:
# measured 2.0e-11 N for HPIPM (real-time), 2.7e-11 N for IPOPT.
SAME_SOLUTION_TOL_N = {NmpcMode.REAL_TIME: 1e-9, NmpcMode.FULL: 1e-6}

# The first command's internal thrust against the scalar problem's optimum (3.06 N from 8 N
# held before): measured 1.1e-11 N (full, IPOPT's tolerance) and 0 N (real-time); without the
# internal-thrust term both held 8 N, 4.9 N off.
INTERNAL_THRUST_TOL_N = 1e-8

LINE_REFERENCE = "reference={type: line, start: [0, 0], heading_deg: 0, speed: 0.5}"


def _config(mode: NmpcMode, **fields) -> ControllerConfig:
    """nmpc with the paper's weights unless told otherwise (the tolerances here were
    measured with them)."""
    fields.setdefault("R", (0.01,))
    fields.setdefault("thrust_penalty", ThrustPenalty.ABSOLUTE)
    return ControllerConfig(type="nmpc", nmpc_mode=mode, offset_free=False, **fields)


def _observation(state, reference, t=0.0, obstacles=()) -> Observation:
    return Observation(
        k=0, t=t, state=np.asarray(state, float), reference=reference, obstacles=obstacles
    )


def _oval_preview(t0: float) -> np.ndarray:
    return make_reference(PaperOvalConfig()).states(t0 + SAMPLE_TIME * np.arange(HORIZON + 1))


def _world_rk4(params, state, thrust, disturbance_world, substeps):
    """One sample of the package's model under a world-frame force and moment (NumPy)."""

    def f(x, u):
        d_u, d_v = body_from_world(disturbance_world, x[2])
        return dynamics(x, u, params, (d_u, d_v, disturbance_world[2]))

    return rk4(f, state, thrust, SAMPLE_TIME, substeps)


# --------------------------------------------------------------------------------------------
# 1. The program is the package's model, LinearMpc's cost and the exact obstacle distance
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("preset", "substeps"), [("jmse2210", 1), ("jmse2210", 3), ("bluerov2-heavy", 2)]
)
def test_program_constraints_use_the_package_rk4_map_and_exact_distances(preset, substeps):
    params = load_vehicle(preset)
    config = _config(NmpcMode.FULL, model_substeps=substeps, move_steps=(0, 1, 4, 10))
    program = MultipleShootingProgram(params, config)
    n, ny = params.n_thrusters, HORIZON
    rng = np.random.default_rng(11)
    states = rng.uniform([-9, -9, -4, -1, -0.5, -0.5], [9, 9, 4, 1, 0.5, 0.5], size=(ny + 1, 6))
    thrust = rng.uniform(*params.thrust_limits, size=(4, n))
    slack = rng.uniform(0.0, 0.2, size=(ny, MAX_OBSTACLES))
    disturbance = np.array([6.0, -3.0, 0.4])
    previous = rng.uniform(*params.thrust_limits, size=n)
    obstacles = (
        ObstacleState(np.array([1.0, 2.0]), 0.5, np.array([0.1, -0.2])),
        ObstacleState(np.array([-3.0, 0.5]), 1.0, np.zeros(2)),
    )
    reference = _oval_preview(10.0)
    sample = program.sample(states[0], previous, reference, disturbance, obstacles)
    w = np.concatenate([states.ravel(), thrust.ravel(), slack.ravel()])
    g = np.asarray(
        ca.Function("g", [program.nlp.w, program.nlp.p], [program.nlp.g])(
            w, program.parameters(sample)
        )
    ).ravel()

    held = np.searchsorted(config.move_schedule(), np.arange(ny), side="right") - 1
    gaps = g[: 6 * ny].reshape(ny, 6)
    for i in range(ny):
        expected = states[i + 1] - _world_rk4(
            params, states[i], thrust[held[i]], disturbance, substeps
        )
        np.testing.assert_allclose(gaps[i], expected, rtol=0, atol=ROUND_OFF)

    changes = g[6 * ny : 6 * ny + 4 * n].reshape(4, n)
    np.testing.assert_allclose(
        changes, np.diff(np.vstack([previous, thrust]), axis=0), atol=ROUND_OFF
    )

    rows = g[6 * ny + 4 * n :].reshape(ny, MAX_OBSTACLES)
    # The nearest obstacle takes slot 0.
    order = sorted(obstacles, key=lambda o: np.linalg.norm(o.center - states[0, :2]))
    filled = config.for_vehicle(params)  # the radius from the vehicle's size
    for o, obstacle in enumerate(order):
        reach = obstacle.radius + filled.vehicle_radius + filled.obstacle_margin
        for i in range(1, ny + 1):
            centre = obstacle.center_at(i * SAMPLE_TIME)
            expected = np.linalg.norm(states[i, :2] - centre) - reach + slack[i - 1, o]
            assert abs(rows[i - 1, o] - expected) < DISTANCE_SMOOTHING_TOL_M


@pytest.mark.parametrize("penalty", list(ThrustPenalty))
def test_program_cost_is_linear_mpc_cost(penalty):
    """Q on steps 1..ny-1, S on ny, R on the thrust (or its change), exact slack penalty."""
    params = load_vehicle("jmse2210")
    config = _config(
        NmpcMode.FULL, thrust_penalty=penalty, R=(0.01, 0.02, 0.03, 0.04), control_horizon=5
    )
    program = MultipleShootingProgram(params, config)
    n, ny = params.n_thrusters, HORIZON
    rng = np.random.default_rng(12)
    states = rng.normal(size=(ny + 1, 6))
    thrust = rng.uniform(-15, 15, size=(5, n))
    slack = rng.uniform(0.0, 0.1, size=(ny, MAX_OBSTACLES))
    previous = rng.uniform(-15, 15, size=n)
    reference = rng.normal(size=(ny + 1, 6))
    sample = program.sample(states[0], previous, reference, np.zeros(3), ())
    w = np.concatenate([states.ravel(), thrust.ravel(), slack.ravel()])
    cost = float(
        ca.Function("J", [program.nlp.w, program.nlp.p], [program.nlp.cost])(
            w, program.parameters(sample)
        )
    )

    error = states[1:] - reference[1:]
    expected = np.sum(error[:-1] ** 2 * np.array(config.Q)) + np.sum(
        error[-1] ** 2 * np.array(config.S)
    )
    per_step = thrust[np.minimum(np.arange(ny), 4)]  # moves at 0..4, held after
    R = np.array(config.R)
    if penalty is ThrustPenalty.ABSOLUTE:
        expected += np.sum(per_step**2 * R)
    else:  # and R on the internal thrust, the part T maps to no force or moment
        expected += np.sum(np.diff(np.vstack([previous, per_step]), axis=0) ** 2 * R)
        internal = per_step @ _internal_projector(params).T
        expected += np.sum(internal**2 * R)
    expected += config.obstacle_slack_penalty * slack.sum() + np.sum(slack**2)
    assert cost == pytest.approx(expected, rel=ROUND_OFF)  # the same sums in another order


def _internal_projector(params) -> np.ndarray:
    """I - pinv(T) T: the orthogonal projector onto the thrusts that make no force or moment."""
    return np.eye(params.n_thrusters) - np.linalg.pinv(params.T) @ params.T


@pytest.mark.parametrize("mode", MODES)
def test_internal_thrust_decays_as_the_increment_penalty_says(mode):
    """At rest on a resting reference, a previous command that pushes BlueROV2 Heavy's four
    thrusters against each other (c times the allocation's null vector: no force, no moment)
    is the only thing to optimise. The increment penalty with its internal-thrust term makes
    that the scalar problem min sum_k (n_k - n_{k-1})^2 + n_k^2, n_{-1} = c, whose optimum is
    the tridiagonal solve below; without the term the plan would hold c for ever, a direction
    nothing in the problem decides (ocp/tracking.py)."""
    params = load_vehicle("bluerov2-heavy")
    null = np.linalg.svd(params.T)[2][-1]  # unit null vector of T (3, 4)
    assert np.allclose(params.T @ null, 0.0, atol=ROUND_OFF)
    # R = 1: the internal thrust's cost well above IPOPT's tolerance (the scalar problem
    # does not depend on R)
    config = _config(mode, thrust_penalty=ThrustPenalty.INCREMENT, R=(1.0,), model_substeps=2)
    c = 8.0  # N along the null vector: 4 N per thruster, inside every limit and rate
    nmpc = NonlinearMpc(params, config)
    state = np.zeros(6)
    nmpc.reset(state, c * null)
    plan = nmpc.compute(_observation(state, np.zeros((HORIZON + 1, 6))))

    # d/dn_k: 2 (n_k - n_{k-1}) - 2 (n_{k+1} - n_k) [k < N - 1] + 2 n_k = 0
    hessian = 3.0 * np.eye(HORIZON) - np.eye(HORIZON, k=1) - np.eye(HORIZON, k=-1)
    hessian[-1, -1] = 2.0
    expected = np.linalg.solve(hessian, np.r_[c, np.zeros(HORIZON - 1)])
    assert plan.thrust @ null == pytest.approx(expected[0], abs=INTERNAL_THRUST_TOL_N)
    assert np.linalg.norm(plan.thrust - (plan.thrust @ null) * null) < INTERNAL_THRUST_TOL_N


# --------------------------------------------------------------------------------------------
# 2. The two modes against each other, and the full solve against LtvMpc
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "fields",
    [{}, {"control_horizon": 3, "thrust_penalty": ThrustPenalty.INCREMENT}],
    ids=["free", "nc3-increment"],
)
@pytest.mark.parametrize("trust", [0.0, None], ids=["no-trust-region", "default-trust-region"])
def test_real_time_iterations_converge_to_the_full_solve(fields, trust):
    """One sample, SQP steps from the cold start: the real-time scheme's fixed point is the
    NLP's optimum (a first move of 0.87 N here, not a trivial one), also with the trust
    region on the heading steps, which damps the steps but not the fixed point. Both QP forms:
    sparse (every move free) and condensed (move blocking)."""
    model = load_vehicle("jmse2210")
    reference = _oval_preview(2.0)
    state = reference[0] + np.array([0.1, -0.05, 0.03, 0.0, 0.02, 0.0])
    previous = np.array([1.6, 1.5, 1.6, 1.7])
    full_mpc = NonlinearMpc(model, _config(NmpcMode.FULL, **fields))
    full_mpc.reset(state, previous)
    full = full_mpc.compute(_observation(state, reference, 2.0))
    assert full.status is ControlStatus.OK
    assert np.abs(full.thrust - previous).max() > 0.3, "a case with a substantial first move"

    config = _config(NmpcMode.REAL_TIME, trust_region_weight=trust, **fields)
    real_time = NonlinearMpc(model, config)
    program = real_time.program
    assert program.config.trust_region_weight == (5.0 if trust is None else trust)
    solver = RealTimeIteration(program, condensed="control_horizon" in fields)
    preview = tracked_reference(model, state, np.zeros(3), reference, SAMPLE_TIME)
    sample = program.sample(state, previous, preview, np.zeros(3), ())
    solution = solver.solve(program.reference_guess(sample), sample, RTI_SQP_STEPS, True)
    np.testing.assert_allclose(
        program.plan(solution.iterate)[0], full.thrust, rtol=0, atol=RTI_VS_FULL_THRUST_TOL_N
    )
    np.testing.assert_allclose(
        solution.iterate.states, full.predicted_states, rtol=0, atol=RTI_VS_FULL_STATE_TOL
    )


def test_full_solve_first_move_matches_ltv_mpc_to_second_order():
    """Near a steady straight run the LTV model is exact to first order: the first moves of
    the nonlinear optimum and of LtvMpc's QP differ by O(delta^2) in the state offset delta.

    Increment penalty, so the steady run (thrust balancing drag at 0.5 m/s) is the optimum at
    delta = 0; no trust region (it is not part of the OCP); every move free.
    """
    model = load_vehicle("jmse2210")
    reference = make_reference(LineConfig(start=(0.0, 0.0), heading_deg=30.0, speed=0.5)).states(
        SAMPLE_TIME * np.arange(HORIZON + 1)
    )
    speed = 0.5
    steady = model.T_pinv @ np.array([-(model.Xu * speed + model.Xuu * speed**2), 0.0, 0.0])
    direction = np.array([1.0, -1.0, 1.0, 0.5, -0.5, 0.5])
    differences = []
    for delta in LTV_OFFSETS:
        state = reference[0] + delta * direction
        nmpc = NonlinearMpc(model, _config(NmpcMode.FULL, thrust_penalty=ThrustPenalty.INCREMENT))
        ltv = LtvMpc(
            model,
            ControllerConfig(
                type="ltv-mpc",
                offset_free=False,
                thrust_penalty=ThrustPenalty.INCREMENT,
                R=(0.01,),  # as _config: the same problem as the nmpc's
                trust_region_weight=0.0,
            ),
        )
        thrusts = []
        for controller in (nmpc, ltv):
            controller.reset(state, steady)
            thrusts.append(controller.compute(_observation(state, reference)).thrust)
        assert np.abs(thrusts[0] - steady).max() > 10 * delta, "the offset does move the thrust"
        differences.append(np.abs(thrusts[0] - thrusts[1]).max())
    orders = np.log10(np.array(differences[:-1]) / np.array(differences[1:]))
    np.testing.assert_allclose(orders, LTV_ORDER, atol=LTV_ORDER_TOL)


# --------------------------------------------------------------------------------------------
# 3. Hard limits, fallback, time-out, relaxed obstacles, obstacle slots
# --------------------------------------------------------------------------------------------


def _random_case(rng, params, reference):
    return random_limit_case(rng, params, reference, SAMPLE_TIME, HORIZON)


@pytest.mark.parametrize("mode", MODES)
@pytest.mark.parametrize("preset", PRESETS)
def test_command_respects_force_and_rate_limits(preset, mode):
    params = load_vehicle(preset)
    reference = make_reference(
        PaperOvalConfig() if preset == "jmse2210" else CircleConfig(radius=5.0)
    )
    controller = NonlinearMpc(params, _config(mode, model_substeps=SUBSTEPS[preset]))
    max_step = params.thrust_rate_limit * SAMPLE_TIME
    rng = np.random.default_rng(6)
    for _ in range(6):
        t0, state, preview, previous = _random_case(rng, params, reference)
        obstacle = ObstacleState(preview[6, :2] + rng.normal(size=2), 0.5, np.zeros(2))
        controller.reset(state, previous)
        # Three samples: the later ones start from a shifted solution.
        for _ in range(3):
            result = controller.compute(_observation(state, preview, t0, (obstacle,)))
            thrust = result.thrust
            assert np.all(thrust >= params.thrust_min) and np.all(thrust <= params.thrust_max)
            assert np.all(np.abs(thrust - previous) <= max_step + LIMIT_ROUND_OFF_N)
            previous = thrust
            state = rk4(lambda s, u: dynamics(s, u, params), state, thrust, SAMPLE_TIME, 10)
            t0 += SAMPLE_TIME
            preview = reference.states(t0 + SAMPLE_TIME * np.arange(HORIZON + 1))


@pytest.mark.parametrize("mode", MODES)
def test_time_out_every_step_is_recovered_by_the_shell(mode):
    """Every solve late: the shell's feedback steers from the first sample (never a blind
    hold), inside the limits."""
    initial_thrust = [15.0, -15.0, 15.0, -15.0]  # at the limits
    result = simulate(
        load_scenario(
            "paper-ideal",
            [
                "controller.type=nmpc",
                f"controller.nmpc_mode={mode}",
                "duration=5",
                "controller.solver_time_limit_ms=1e-6",
                f"initial_thrust={initial_thrust}",
            ],
        )
    )
    steps = result.log.steps
    assert result.log.status == [ControlStatus.RECOVERY] * steps
    assert result.metrics["solver_failures"] == result.metrics["recovery_steps"] == steps
    assert np.ptp(result.log.thrust[:steps], axis=0).max() > 1.0  # steered, not held
    assert result.metrics["thrust_limit_violations"] == 0
    assert result.metrics["thrust_rate_violations"] == 0


@pytest.mark.parametrize("mode", MODES)
def test_solver_failure_after_a_good_step_applies_the_plan_clipped(mode, monkeypatch):
    """Failures injected after one good sample: the plan's next thrusts, clipped to the limits."""
    model = load_vehicle("jmse2210")
    controller = NonlinearMpc(model, _config(mode, control_horizon=3))
    reference = _oval_preview(40.0)
    state = reference[0] + np.array([0.1, 0.1, -0.05, 0.0, 0.0, 0.0])
    controller.reset(state, np.array([1.2, 1.0, 1.2, 1.0]))
    first = controller.compute(_observation(state, reference, 40.0))
    plan = controller.plan
    assert first.status is not ControlStatus.FALLBACK
    assert np.abs(plan[2] - plan[0]).max() > 0.1, "the plan changes within the horizon"

    failed = SimpleNamespace(
        iterate=None, resume=None, iterations=0, solve_time_s=0.0, status="injected failure"
    )
    monkeypatch.setattr(
        controller._solver, "solve", lambda guess, sample, iterations, cold, **_: failed
    )
    # ... and the real-time mode's last resort (IPOPT) with it
    monkeypatch.setattr(controller, "_rescue_solver", lambda: controller._solver)
    max_step = model.thrust_rate_limit * SAMPLE_TIME
    applied = first.thrust
    for k in (1, 2, 3):
        result = controller.compute(_observation(state, _oval_preview(40.0 + k * SAMPLE_TIME)))
        expected = np.clip(
            plan[k],
            np.maximum(model.thrust_min, applied - max_step),
            np.minimum(model.thrust_max, applied + max_step),
        )
        assert result.status is ControlStatus.FALLBACK
        np.testing.assert_array_equal(result.thrust, expected)
        applied = result.thrust


@pytest.mark.parametrize("mode", MODES)
@pytest.mark.parametrize("center", [(0.4, 0.3), (0.0, 0.0)])
def test_start_inside_an_obstacle_is_relaxed_and_left(mode, center):
    """At rest inside the inflated disc no plan is feasible: RELAXED, not a failure.

    Measured (both modes, both discs): RELAXED on the first 3 samples, clear of the disc
    from t = 1.5-2 s. The real-time scheme may lose one sample on the way out (measured: one
    FALLBACK at t = 4 s for the disc at (0.4, 0.3), where DAQP reports the condensed QP along
    a spinning plan non-convex; the next sample starts cold and succeeds).
    """
    radius = 0.3 if center == (0.0, 0.0) else 0.5
    result = simulate(
        load_scenario(
            "paper-ideal",
            [
                "controller.type=nmpc",
                f"controller.nmpc_mode={mode}",
                LINE_REFERENCE,
                "initial_state=[0, 0, 0, 0, 0, 0]",
                "duration=10",
                f"obstacles=[{{center: {list(center)}, radius: {radius}}}]",
            ],
        )
    )
    log = result.log
    clearance = log.clearance_m
    assert clearance[0] < 0
    assert log.status[0] == ControlStatus.RELAXED
    assert log.status.count(ControlStatus.FALLBACK) <= (1 if mode is NmpcMode.REAL_TIME else 0)
    first_clear = int(np.argmax(clearance >= 0))
    assert 0 < first_clear <= 8, "clear of the disc within 4 s"
    assert np.all(clearance[first_clear:] >= 0)
    _assert_no_violations(result.metrics)


@pytest.mark.parametrize("mode", MODES)
def test_far_and_surplus_obstacles_do_not_change_the_solution(mode):
    """Empty slots are disabled, far discs inactive, and with more discs than slots the
    nearest fill them: a plan near one disc is the same with 12 more discs 200 m away."""
    model = load_vehicle("jmse2210")
    reference = _oval_preview(4.0)
    state = reference[0] + np.array([0.1, 0.0, 0.0, 0.0, 0.0, 0.0])
    previous = np.full(4, 1.5)
    near = ObstacleState(np.array([8.3, -6.0]), 0.5, np.zeros(2))
    far = tuple(
        ObstacleState(np.array([200.0 + 3 * i, 200.0]), 1.0, np.zeros(2))
        for i in range(MAX_OBSTACLES + 4)
    )
    thrusts = []
    for obstacles in ((near,), far + (near,)):
        controller = NonlinearMpc(model, _config(mode))
        controller.reset(state, previous)
        result = controller.compute(_observation(state, reference, 4.0, obstacles))
        assert result.status is ControlStatus.OK
        thrusts.append(result.thrust)
    np.testing.assert_allclose(thrusts[1], thrusts[0], rtol=0, atol=SAME_SOLUTION_TOL_N[mode])


def _assert_no_violations(metrics):
    assert metrics["thrust_limit_violations"] == 0
    assert metrics["thrust_rate_violations"] == 0


# --------------------------------------------------------------------------------------------
# 4. The acceptance bounds (full 100 s runs, every move free)
# --------------------------------------------------------------------------------------------

# Issue bounds; measured values next to them.
IDEAL_FINAL_ERROR_M = 0.01  # full: 9.9e-9 m
OBSTACLES_FINAL_ERROR_M = 0.05  # full 9.9e-9 m, real-time 5.3e-9 m; clearance 0.0996 m both
REAL_TIME_RMS_RATIO = 1.2  # real-time / full RMS error on paper-obstacles: 0.3115 / 0.3115 m
# paper-disturbed, offset-free, real-time, after 30 s: measured RMS 0.045 / 0.0066 / 0.0066 m,
# final 0.024 / 2.3e-7 / 2.3e-7 m at levels -1 / 0 / +1. Level -1 is close to the bound: there
# the yaw settles into a period-2 oscillation at the thrust-rate limit, driven by the
# observer's yaw-moment estimate (gone with disturbance_rate_std N = 0.05: RMS 0.0066 m,
# final 1.9e-6 m; without offset-free there is none either). The full solve: 0.021 / 0.019 m.
DISTURBED_RMS_AFTER_TRANSIENT_M = 0.05
DISTURBED_FINAL_ERROR_M = 0.05
UNCERTAINTY_LEVELS = (-1, 0, 1)


@functools.cache
def _run(name: str, mode: str, *overrides: str) -> RunResult:
    return simulate(
        load_scenario(
            name,
            [
                "controller.type=nmpc",
                f"controller.nmpc_mode={mode}",
                "controller.control_horizon=30",
                *overrides,
            ],
        )
    )


@pytest.mark.slow
def test_full_solve_on_paper_ideal_converges():
    result = _run("paper-ideal", "full")
    assert result.metrics["final_position_error_m"] <= IDEAL_FINAL_ERROR_M
    assert result.metrics["solver_failures"] == 0
    _assert_no_violations(result.metrics)


@pytest.mark.slow
@pytest.mark.parametrize("mode", ["full", "real-time"])
def test_paper_obstacles_are_avoided(mode):
    metrics = _run("paper-obstacles", mode).metrics
    assert metrics["min_obstacle_clearance_m"] >= 0
    assert metrics["final_position_error_m"] <= OBSTACLES_FINAL_ERROR_M
    assert metrics["solver_failures"] == 0
    _assert_no_violations(metrics)


@pytest.mark.slow
def test_real_time_mode_tracks_as_well_as_the_full_solve():
    full = _run("paper-obstacles", "full").metrics["rms_position_error_m"]
    real_time = _run("paper-obstacles", "real-time").metrics["rms_position_error_m"]
    assert real_time <= REAL_TIME_RMS_RATIO * full


@pytest.mark.slow
@pytest.mark.parametrize("level", UNCERTAINTY_LEVELS)
def test_offset_free_tracking_under_current_and_inertia_uncertainty(level):
    scale = f"plant.scale={{Iz_rb: {1 + 0.25 * level}, Iz_added: {1 + 0.35 * level}}}"
    metrics = _run("paper-disturbed", "real-time", "controller.offset_free=true", scale).metrics
    assert metrics["transient_s"] == 30.0
    assert metrics["rms_position_error_after_transient_m"] < DISTURBED_RMS_AFTER_TRANSIENT_M
    assert metrics["final_position_error_m"] < DISTURBED_FINAL_ERROR_M
    _assert_no_violations(metrics)


# The longest run of fallbacks the condensed QP may have on the light BlueROV2 (above): a
# fallback streak of 3 is what the hard-survey bar allows (docs/recovery.md).
CONDENSED_FALLBACK_STREAK = 3


def _light_lawnmower_with_disc(*overrides: str) -> RunResult:
    """The light BlueROV2's lawnmower (benchmarks/scenarios), 20 s, a disc 10 m ahead."""
    from pathlib import Path

    scenario = Path(__file__).parents[1] / "benchmarks/scenarios/bluerov2-light-lawnmower.yaml"
    disc = "obstacles=[{center: [10.0, 0.2], radius: 0.6}]"
    return simulate(load_scenario(str(scenario), ["duration=20", disc, *overrides]))


def test_the_multiple_shooting_retry_runs_with_the_condensed_qp_too():
    """Move blocking takes the condensed QP, whose solve has the same re-simulation switch: the
    retry ran into a TypeError there (the run failed at step 0). It completes and keeps off
    the disc. The condensed QP is ill-conditioned on this open-loop-unstable vehicle
    (solvers/real_time_iteration.py), so a fallback or two is the QP solver's round-off:
    measured 0 in one environment and 1 in a fresh one (other library builds); the former
    condensed form, derived apart, fell back more."""
    run = _light_lawnmower_with_disc("controller.type=nmpc", "controller.control_horizon=3")
    assert run.metrics["longest_fallback_streak"] <= CONDENSED_FALLBACK_STREAK
    assert run.metrics["min_obstacle_clearance_m"] >= 0
    _assert_no_violations(run.metrics)


def test_a_cold_start_that_diverges_when_re_simulated_recovers_by_multiple_shooting():
    """The light BlueROV2 (yaw inertia 0.28 kg m2, yaw damping -0.07) with a disc 10 m ahead:
    every cold start's re-simulated rollout spun up and the real-time nmpc fell back on all
    40 samples of these 20 s (before the multiple-shooting retry); now it solves every one."""
    run = _light_lawnmower_with_disc("controller.type=nmpc", "controller.control_horizon=null")
    metrics = run.metrics
    assert metrics["fallback_steps"] == 0
    assert metrics["min_obstacle_clearance_m"] >= 0
    _assert_no_violations(metrics)
