"""The safety shell's recovery (controllers/shell.py, controllers/recovery.py): a forced
solver failure at a corner and an injected spin, on the default controller."""

from __future__ import annotations

import numpy as np
import pytest

import auvmpc
from auvmpc.controllers import compiled_nmpc
from auvmpc.controllers.base import ControlStatus
from auvmpc.controllers.nmpc import NonlinearMpc
from auvmpc.controllers.shell import PLAN_FALLBACK_STEPS
from auvmpc.experiments.kinds import kind_of
from auvmpc.sim.metrics import LIMIT_TOLERANCE_N

# A light-yaw 20 kg vehicle (the before-stop smoke's) turning a lawnmower corner.
LIGHT_VEHICLE = {
    "name": "light-yaw",
    "mass": 20.0, "m11": 26.0, "m22": 34.0, "Iz_rb": 0.12, "Iz_added": 0.06,
    "Xu": -5.0, "Xuu": -120.0, "Yv": -8.0, "Yvv": -60.0, "Nr": -0.1, "Nrr": -0.5,
    "thrusters": [
        {"position": [0.18, 0.12], "angle_deg": -45.0},
        {"position": [0.18, -0.12], "angle_deg": 45.0},
        {"position": [-0.18, 0.12], "angle_deg": -135.0},
        {"position": [-0.18, -0.12], "angle_deg": 135.0},
    ],
    "thrust_limits": [-150.0, 150.0], "thrust_rate_limit": 300.0,
}  # fmt: skip
CORNER_SCENARIO = {
    "name": "corner",
    "duration": 40.0,
    "vehicle": LIGHT_VEHICLE,
    "reference": {"type": "waypoints", "points": [[0, 0], [8, 0], [8, 6]], "speed": 0.4},
    "disturbance": {"current_force_world": [10.0, -6.0]},
    "initial_state": [0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
    "controller": {"vehicle_radius": 0.3},
    "transient_s": 10.0,
}
# The corner is reached at 20 s (8 m at 0.4 m/s): the solver fails over 18-24 s.
FAILURE_WINDOW_S = (18.0, 24.0)
# After the optimiser is back the vehicle must be on the path again: the default tracks this
# case within 0.02 m; 0.3 m (the vehicle's radius) is "not lost" with room for the upset.
BACK_ON_PATH_M = 0.3


def _scenario(**changes):
    data = {**CORNER_SCENARIO, **changes}
    return auvmpc.load_scenario(_write(data))


def _write(data) -> str:
    import tempfile

    import yaml

    handle = tempfile.NamedTemporaryFile("w", suffix=".yaml", delete=False)
    yaml.safe_dump(data, handle)
    handle.close()
    return handle.name


def _within_limits(run, vehicle) -> None:
    thrust = run.log.thrust[: run.log.steps]
    low, high = vehicle["thrust_limits"]
    assert thrust.min() >= low - LIMIT_TOLERANCE_N
    assert thrust.max() <= high + LIMIT_TOLERANCE_N
    steps = np.abs(np.diff(thrust, axis=0))
    assert steps.max() <= vehicle["thrust_rate_limit"] * run.log.sample_time + LIMIT_TOLERANCE_N


def _fail_within(monkeypatch, controller_class, window_s: tuple[float, float]) -> None:
    """Every proposal of ``controller_class`` over ``window_s`` (s) comes without a plan."""
    propose = controller_class.propose

    def failing(self, observation, previous):
        proposal = propose(self, observation, previous)
        if window_s[0] <= observation.t < window_s[1]:
            proposal.plan = None
        return proposal

    monkeypatch.setattr(controller_class, "propose", failing)


def _plan_then_feedback(run, window_s: tuple[float, float]) -> tuple[np.ndarray, np.ndarray]:
    """Over the failure window the shell applied the last plan for PLAN_FALLBACK_STEPS
    samples, then its feedback; returns the run's statuses and the window's mask."""
    status = np.array(run.log.status[: run.log.steps])
    t = run.log.t[: run.log.steps]
    window = (t >= window_s[0]) & (t < window_s[1])
    failed = status[window]
    assert list(failed[:PLAN_FALLBACK_STEPS]) == [ControlStatus.FALLBACK] * PLAN_FALLBACK_STEPS
    assert set(failed[PLAN_FALLBACK_STEPS:]) == {ControlStatus.RECOVERY}
    return status, window


def test_a_solver_failing_at_a_corner_is_covered_by_the_plan_then_the_feedback(monkeypatch):
    """Every solve fails for 6 s at the corner: the shell follows the last plan for
    PLAN_FALLBACK_STEPS samples, then applies its feedback (RECOVERY), inside the limits; once
    the solver works again the optimiser takes over at once and the vehicle is back on the
    path."""
    # The Python controller, whose proposals can be made to fail (the C controller's shell is
    # held to it sample for sample through a failure: tests/test_compiled_nmpc.py).
    monkeypatch.setattr(compiled_nmpc, "runs_in_c", lambda model, config: False)
    _fail_within(monkeypatch, NonlinearMpc, FAILURE_WINDOW_S)
    run = auvmpc.simulate(_scenario())
    status, window = _plan_then_feedback(run, FAILURE_WINDOW_S)
    assert ControlStatus.FALLBACK not in status[~window] and "recovery" not in status[~window]
    _within_limits(run, LIGHT_VEHICLE)
    metrics = run.metrics
    assert metrics["recovery_steps"] == window.sum() - PLAN_FALLBACK_STEPS
    assert metrics["fallback_steps"] == window.sum()  # no optimiser in control: both kinds
    error = np.hypot(*(run.log.state[:, :2] - run.log.reference[:, :2]).T)
    assert error[run.log.t >= FAILURE_WINDOW_S[1] + 5.0].max() < BACK_ON_PATH_M


# The depth step of paper-depth-calm is at 10 s; the depth MPC fails from just before it
# until 15 s after it, so the whole step is the depth feedback's.
DEPTH_FAILURE_WINDOW_S = (9.0, 25.0)
# The feedback's bandwidth (0.5 rad/s, critically damped) leaves (1 + 7.5) e^-7.5 = 0.5 % of
# the 0.2 m step after 15 s; 0.01 m (5 %) allows for the unknown buoyancy's estimate.
DEPTH_RECOVERED_M = 0.01


def test_a_failing_depth_mpc_is_recovered_by_the_depth_feedback(monkeypatch):
    """The depth MPC fails over the whole depth step: the shell follows the last plan for
    PLAN_FALLBACK_STEPS samples, then its depth feedback makes the step, inside the limits."""
    from auvmpc.controllers.depth_mpc import DepthMpc

    _fail_within(monkeypatch, DepthMpc, DEPTH_FAILURE_WINDOW_S)
    run = auvmpc.simulate(auvmpc.load_scenario("paper-depth-calm"))
    _plan_then_feedback(run, DEPTH_FAILURE_WINDOW_S)
    log, t = run.log, run.log.t[: run.log.steps]
    in_window = (t >= DEPTH_FAILURE_WINDOW_S[0]) & (t < DEPTH_FAILURE_WINDOW_S[1])
    assert run.metrics["thrust_limit_violations"] == 0
    assert run.metrics["thrust_rate_violations"] == 0
    end = int(np.argmax(t >= DEPTH_FAILURE_WINDOW_S[1])) - 1  # the last sample of the window
    assert abs(log.state[end, 0] - log.reference[end, 0]) < DEPTH_RECOVERED_M
    # critically damped: it never went deeper than the new depth by more than that either
    final = log.reference[end, 0]
    assert log.state[: log.steps][in_window, 0].min() > final - DEPTH_RECOVERED_M


def test_without_a_feedback_the_shell_keeps_following_the_plan():
    """A controller without a recovery feedback (the baseline): after a failure the shell
    applies the last plan's moves in turn, then holds the last command."""
    from auvmpc.controllers.base import ActuatorLimits, Observation
    from auvmpc.controllers.shell import Proposal, ShelledController

    plan = np.array([[1.0], [2.0], [3.0]])

    class FailsAfterTwo(ShelledController):
        sample_time, preview_steps = 0.5, 1
        limits = ActuatorLimits(-10.0, 10.0, 100.0)

        def propose(self, observation, previous):
            return Proposal(plan=plan if observation.k < 2 else None)

    controller = FailsAfterTwo()
    controller.reset(np.zeros(6), np.zeros(1))
    results = [
        controller.compute(Observation(k, 0.5 * k, np.zeros(6), np.zeros((2, 6)))) for k in range(6)
    ]
    assert [r.status for r in results] == ["ok"] * 2 + ["fallback"] * 4
    assert [float(r.thrust[0]) for r in results] == [1.0, 1.0, 2.0, 3.0, 3.0, 3.0]


@pytest.mark.parametrize("yaw_rate", [4.0, -6.0])
def test_an_injected_spin_is_detected_and_stopped(yaw_rate):
    """The vehicle starts spinning (4-6 rad/s, far above the 1.5 rad/s limit at 0.5 s): the
    shell applies its feedback at once, the spin is gone within two samples, the optimiser
    takes over and the run is not lost. At the paper's 0.5 s, given by the user: the light
    vehicle's own default sample (0.1 s, its yaw rule) resolves such a spin by itself."""
    controller = {**CORNER_SCENARIO["controller"], "sample_time": 0.5}
    run = auvmpc.simulate(
        _scenario(duration=30.0, initial_state=[0, 0, 0, 0, 0, yaw_rate], controller=controller)
    )
    status = run.log.status
    assert status[0] == ControlStatus.RECOVERY
    r = np.abs(run.log.state[:, 5])
    assert r[2:].max() < 1.5
    assert ControlStatus.OK in status[:4] or ControlStatus.SATURATED in status[:4]
    _within_limits(run, LIGHT_VEHICLE)
    assert run.metrics["verdict"] != "lost"
    assert run.metrics["longest_fallback_streak"] <= 3


# Hard-survey cases (survey_cases.make_case) where the default was lost before issue 24:
# (seed, index): what happened then.
FORMERLY_LOST = {
    (2, 22): "12 kg, yaw inertia 0.17 kg m2, 188 N: 432 fallbacks in a row, 72 m off",
    (2, 39): "22 kg, 0.38 kg m2: spun at 4 rad/s passing a disc, touched it by 0.22 m",
    (1, 2): "34 kg, 0.21 kg m2: ltv-mpc (the default then) spun and fell back 219 in a row",
}


# How much of hard-survey case (2, 22) is compared with the converged OCP (s).
COMPARED_DURATION_S = 100


def _case(seed: int, index: int, *overrides: str):
    """Hard-survey case (seed, index) with ``overrides``, resolved."""
    from pathlib import Path

    from auvmpc.experiments.survey_cases import make_case
    from auvmpc.scenario import ResolvedScenario, apply_override, validate_scenario

    data = make_case("hard-survey", seed, index)
    for override in overrides:
        apply_override(data, override)
    return ResolvedScenario(validate_scenario(data), Path.cwd())


@pytest.mark.slow
@pytest.mark.parametrize(("seed", "index"), sorted(FORMERLY_LOST))
def test_formerly_lost_hard_survey_cases_hold_the_bar(seed, index):
    """The issue's bar on a few hard cases: not lost, at most 3 samples in a row without an
    optimiser, no contact, no limit violation, and (for the first) an RMS error after the
    transient within max(0.1 m, 1.2 x) the converged OCP's on the same case (its first
    COMPARED_DURATION_S). At full yaw moment all three turn 6.4-8.4 rad/s, half a turn in
    0.37-0.49 s, so they fly at the 0.25 s the sample-time rule gives them ((2, 39) spun
    beside its disc at 0.5 s, longest streak 4)."""
    run = auvmpc.simulate(_case(seed, index))
    metrics = run.metrics
    assert metrics["verdict"] != "lost", metrics["verdict_reason"]
    assert metrics["longest_fallback_streak"] <= 3
    assert metrics["min_obstacle_clearance_m"] >= 0.0
    assert metrics["thrust_limit_violations"] == metrics["thrust_rate_violations"] == 0
    if (seed, index) == (2, 22):
        from auvmpc.experiments.survey_cases import YARDSTICK

        # Judged against the converged OCP over the mission's first 100 s (of 220): the
        # converged solve is most of this test's time (21 s for the whole mission).
        first = f"duration={COMPARED_DURATION_S}"
        converged = auvmpc.simulate(_case(seed, index, *YARDSTICK, first)).metrics
        # the same mission's first 100 s, from the whole run (a run stopped there logs the
        # same samples: the run is deterministic sample by sample)
        shorter = _case(seed, index, first)
        rows = round(COMPARED_DURATION_S / run.log.sample_time) + 1
        ours = kind_of(shorter.scenario).metrics(shorter, run.log.first(rows))
        bar = max(0.1, 1.2 * converged["rms_position_error_after_transient_m"])
        assert ours["rms_position_error_after_transient_m"] <= bar
