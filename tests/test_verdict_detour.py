"""The verdict on simulated runs round obstacles (issue 30, item 4): the planned detour of
paper-obstacles is not tracking error, a controller that tracks badly there still is.

Each run is the 100 s paper-obstacles scenario (0.5-0.7 s), simulated once per module.
"""

from __future__ import annotations

import functools

import pytest

from auvmpc.experiments.run import RunResult, simulate
from auvmpc.scenario import load_scenario
from auvmpc.sim.verdict import characteristic_length_m

# Weak controllers: thrust weighed 500 times the paper's R (max error outside detours
# measured 1.27 m), or the position weighed 0.02 instead of 5 (1.86 m); and the paper's
# controller, which does not estimate the current, in a fifth of paper-disturbed's current
# (measured 18 m off, spun 3 turns).
SLUGGISH = {
    "heavy thrust penalty": ("controller.R=[5, 5, 5, 5]",),
    "weak position weight": (
        "controller.Q=[0.02, 0.02, 5, 1, 1, 1]",
        "controller.S=[0.02, 0.02, 10, 2, 2, 2]",
    ),
}
CURRENT = ("disturbance.current_force_world=[2, 1]",)


@functools.cache
def _run(*overrides: str) -> RunResult:
    return simulate(load_scenario("paper-obstacles", list(overrides)))


def test_the_planned_detour_of_paper_obstacles_is_ok():
    run = _run()
    metrics = run.metrics
    length = characteristic_length_m(run.resolved.model)
    # Measured: 2.12 m off round the first disc, 0.47 m everywhere else, 0.10 m clearance.
    assert metrics["max_position_error_after_transient_m"] > 2.0 * length
    assert metrics["max_tracking_error_after_transient_m"] < length
    assert metrics["min_obstacle_clearance_m"] >= 0.0
    assert metrics["detour_m"] > 0.0
    assert metrics["verdict"] == "ok", metrics["verdict_reason"]
    assert "went round an obstacle" in metrics["verdict_reason"]


@pytest.mark.parametrize("overrides", SLUGGISH.values(), ids=SLUGGISH.keys())
def test_a_controller_that_tracks_badly_round_the_obstacles_is_still_degraded(overrides):
    metrics = _run(*overrides).metrics
    assert metrics["verdict"] == "degraded"
    assert metrics["verdict_reason"].startswith("position error")


def test_a_current_the_controller_does_not_estimate_still_loses_it():
    metrics = _run(*CURRENT).metrics
    assert metrics["verdict"] == "lost"
    assert metrics["verdict_reason"].startswith("left the path")
