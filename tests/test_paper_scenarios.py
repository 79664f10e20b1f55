"""The issue's acceptance criteria on the built-in paper scenarios (full 100 s runs).

Every paper scenario x controller (mpc, ltv-mpc) x control horizon (2, 30) keeps the hard
limits and, with obstacles, never touches one. The best configuration (ltv-mpc, nc = 30)
meets the error bounds the issue states. Each run is simulated once per session (cached) and
takes 0.2-0.9 s; the whole module about 10 s on two cores.

Measured values (ltv-mpc, nc = 30, unless said otherwise) are next to each bound.
"""

from __future__ import annotations

import functools
import math

import numpy as np
import pytest

from auvmpc.controllers.base import ControlStatus
from auvmpc.experiments.run import RunResult, simulate
from auvmpc.scenario import load_scenario

pytestmark = pytest.mark.slow

SCENARIOS = ("paper-ideal", "paper-disturbed", "paper-obstacles")
CONTROLLERS = ("mpc", "ltv-mpc")
CONTROL_HORIZONS = (2, 30)
BEST = ("ltv-mpc", 30)

# Issue bounds. paper-ideal: final error measured 5.3e-9 m, RMS after 20 s 3.5 mm.
IDEAL_FINAL_ERROR_M = 0.02
IDEAL_RMS_AFTER_TRANSIENT_M = 0.01
# paper-obstacles: final error measured 5.3e-9 m (the obstacles are behind it by then).
OBSTACLES_FINAL_ERROR_M = 0.05
# paper-disturbed, max error after 30 s: measured 0.584 m at each of the levels -1 / 0 / +1.
DISTURBED_MAX_AFTER_TRANSIENT_M = 1.0
DISTURBED_TRANSIENT_S = 30.0
UNCERTAINTY_LEVELS = (-1, 0, 1)
# A pass is judged where the vehicle is within this distance of the obstacle's centre (m):
# far enough to see the whole manoeuvre, near enough to exclude the other side of the oval.
PASS_WINDOW_M = 5.0


@functools.cache
def _run(name: str, controller: str, control_horizon: int, *overrides: str) -> RunResult:
    return simulate(
        load_scenario(
            name,
            [
                f"controller.type={controller}",
                f"controller.control_horizon={control_horizon}",
                *overrides,
            ],
        )
    )


def _uncertainty(level: int) -> str:
    """The issue's level -> plant yaw-inertia scaling (the controller keeps the nominal)."""
    return f"plant.scale={{Iz_rb: {1 + 0.25 * level}, Iz_added: {1 + 0.35 * level}}}"


@pytest.mark.parametrize("control_horizon", CONTROL_HORIZONS)
@pytest.mark.parametrize("controller", CONTROLLERS)
@pytest.mark.parametrize("name", SCENARIOS)
def test_hard_limits_and_obstacles_are_respected(name, controller, control_horizon):
    metrics = _run(name, controller, control_horizon).metrics
    assert metrics["thrust_limit_violations"] == 0
    assert metrics["thrust_rate_violations"] == 0
    assert metrics["solver_failures"] == 0  # measured 0 in all 12 runs
    if name == "paper-obstacles":
        # Measured 0.100 m (mpc, nc 2; 0.051 without its rollout check), 0.104 (mpc, 30),
        # 0.100 (ltv-mpc, 2), 0.100 (ltv-mpc, 30).
        assert metrics["min_obstacle_clearance_m"] >= 0


def test_ideal_tracking_error_of_the_best_configuration():
    metrics = _run("paper-ideal", *BEST).metrics
    assert metrics["transient_s"] == 20.0
    assert metrics["final_position_error_m"] <= IDEAL_FINAL_ERROR_M
    assert metrics["rms_position_error_after_transient_m"] <= IDEAL_RMS_AFTER_TRANSIENT_M


@pytest.mark.parametrize("level", UNCERTAINTY_LEVELS)
def test_disturbed_error_stays_bounded_under_inertia_uncertainty(level):
    result = _run("paper-disturbed", *BEST, _uncertainty(level))
    scale = result.scenario.plant.scale
    assert scale == pytest.approx({"Iz_rb": 1 + 0.25 * level, "Iz_added": 1 + 0.35 * level})
    metrics = result.metrics
    assert metrics["transient_s"] == DISTURBED_TRANSIENT_S
    assert metrics["thrust_limit_violations"] == 0
    assert metrics["thrust_rate_violations"] == 0
    assert metrics["max_position_error_after_transient_m"] <= DISTURBED_MAX_AFTER_TRANSIENT_M


def _passes(result: RunResult, center, radius):
    """How the vehicle went by an obstacle, in the track frame at the obstacle.

    The along-track axis is the reference heading where the reference comes closest to the
    centre. Returns (closest approach of the reference to the centre, lateral offsets of the
    vehicle at each upstream -> downstream crossing of the line through the centre, number of
    downstream -> upstream crossings), both crossing kinds counted only within PASS_WINDOW_M.
    """
    log = result.log
    reference_gap = np.hypot(*(log.reference[:, :2] - center).T)
    nearest = int(np.argmin(reference_gap))
    psi = log.reference[nearest, 2]
    tangent = np.array([math.cos(psi), math.sin(psi)])
    left = np.array([-tangent[1], tangent[0]])
    relative = log.state[:, :2] - center
    along, across = relative @ tangent, relative @ left
    near = np.hypot(*relative.T) < PASS_WINDOW_M
    window = near[:-1] & near[1:]
    forward = np.flatnonzero(window & (along[:-1] < 0) & (along[1:] >= 0))
    backward = np.flatnonzero(window & (along[:-1] >= 0) & (along[1:] < 0))
    # Lateral offset where along = 0, interpolated between the two samples.
    share = -along[forward] / (along[forward + 1] - along[forward])
    lateral = across[forward] + share * (across[forward + 1] - across[forward])
    return reference_gap[nearest], lateral, len(backward)


@pytest.mark.parametrize("control_horizon", CONTROL_HORIZONS)
@pytest.mark.parametrize("controller", CONTROLLERS)
def test_both_obstacles_are_passed_not_hit(controller, control_horizon):
    """Each disc lies on the track; the vehicle goes around it once, beside it, and on.

    Measured |lateral offset| when level with the centre, over the four configurations:
    1.59-1.78 m at (2, 8) and 1.10-1.17 m at (8, -6), against keep-out reaches of 1.5 m and
    1.0 m (mpc with nc 2 goes round (2, 8) on the outside, the others on the inside).
    """
    result = _run("paper-obstacles", controller, control_horizon)
    vehicle_radius = result.scenario.controller.vehicle_radius
    assert len(result.scenario.obstacles) == 2
    for obstacle in result.scenario.obstacles:
        reach = obstacle.radius + vehicle_radius
        reference_gap, lateral, backward = _passes(
            result, np.array(obstacle.center), obstacle.radius
        )
        assert reference_gap < reach, f"the reference runs into {obstacle.center}"
        assert len(lateral) == 1 and backward == 0, f"passes {obstacle.center} exactly once"
        assert abs(lateral[0]) >= reach, f"beside {obstacle.center} when level with it"
    assert result.metrics["min_obstacle_clearance_m"] >= 0
    if (controller, control_horizon) == BEST:
        assert result.metrics["final_position_error_m"] <= OBSTACLES_FINAL_ERROR_M


# BlueROV2 Heavy on a 5 m circle at 0.5 m/s, started on it at speed. Its surge damping
# (Xu = -13.7 N s/m, Xuu = -141 N s2/m2, m11 = 19.9 kg) puts the surge eigenvalue of the
# linearised model at (Xu + 2 Xuu |u|) / m11 = -7.8/s at 0.5 m/s: one RK4 step of 0.5 s
# (|lambda h| = 3.9) is past RK4's stability limit of 2.79, so with model_substeps = 1 the
# nonlinear rollout of ltv-mpc diverges (measured 34 of 120 samples FALLBACK, overflow
# warnings). Omitted, model_substeps is chosen for the vehicle (7 here).
BLUEROV = (
    "vehicle=bluerov2-heavy",
    "reference={type: circle, center: [0, 0], radius: 5, speed: 0.5}",
    f"initial_state=[5, 0, {math.pi / 2}, 0.5, 0, 0.1]",
    "duration=60",
)
# Max error after 20 s with the chosen sub-steps: measured 0.51 m (mpc; R on the absolute
# thrust against the strong damping leaves a steady offset) and 0.61 m (ltv-mpc).
BLUEROV_MAX_AFTER_TRANSIENT_M = 1.0


@pytest.mark.filterwarnings("ignore::RuntimeWarning")  # the diverging rollout overflows
@pytest.mark.parametrize("substeps", ("model_substeps=1", "model_substeps chosen"))
@pytest.mark.parametrize("controller", CONTROLLERS)
def test_bluerov_on_a_circle_keeps_the_limits(controller, substeps):
    """Asymmetric limits [-40.2, 51.5] N, 30 N per step: kept even when steps fall back."""
    overrides = ("controller.model_substeps=1",) if substeps == "model_substeps=1" else ()
    result = _run("paper-ideal", controller, 2, *BLUEROV, *overrides)
    assert result.resolved.model.name == "bluerov2-heavy"
    assert result.metrics["thrust_limit_violations"] == 0
    assert result.metrics["thrust_rate_violations"] == 0


@pytest.mark.parametrize("controller", CONTROLLERS)
def test_bluerov_on_a_circle_tracks_without_solver_failures(controller):
    result = _run("paper-ideal", controller, 2, *BLUEROV)
    assert result.log.status.count(ControlStatus.FALLBACK) == 0
    assert result.metrics["max_position_error_after_transient_m"] <= BLUEROV_MAX_AFTER_TRANSIENT_M
