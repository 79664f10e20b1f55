"""Issue 28, item 4: a cost estimate before a run or campaign (absurd ones refused in one line
naming the field, unless confirmed), booleans refused where numbers are meant, a diverging
plant ending ``lost`` with the likely field, a signal never turned into a solver failure, and
a campaign whose every run is refused ending non-zero."""

from __future__ import annotations

import os
import resource
import signal
import subprocess
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import pytest

import auvmpc
from auvmpc import interrupts
from auvmpc.controllers.base import ControlResult
from auvmpc.errors import ConfigError, RunFailed
from auvmpc.experiments.run import simulate
from auvmpc.scenario import load_scenario
from auvmpc.scenario.cost import MAX_PLANT_STEPS, check_cost, estimate_cost


def _cli(*args: str, cwd, preexec_fn=None, timeout: float = 120) -> subprocess.CompletedProcess:
    # This auvmpc, whatever the working folder (a relative PYTHONPATH would not follow cwd).
    env = {**os.environ, "PYTHONPATH": str(Path(auvmpc.__file__).parents[1])}
    return subprocess.run(
        [sys.executable, "-c", "from auvmpc.cli import main; main()", *args],
        cwd=cwd, capture_output=True, text=True, timeout=timeout, preexec_fn=preexec_fn, env=env,
    )  # fmt: skip


@pytest.mark.parametrize(
    ("override", "field"),
    [
        ("duration=true", "duration"),
        ("controller.prediction_horizon=true", "controller.prediction_horizon"),
        ("controller.Q=[true,1,1,1,1,1]", "controller.Q.0"),
    ],
)
def test_a_boolean_is_not_a_number(override, field):
    with pytest.raises(ConfigError, match=rf"^{field}: a number is needed, not true/false"):
        load_scenario("paper-ideal", [override])


def test_a_duration_between_samples_is_rounded_up_and_noted():
    resolved = load_scenario("paper-ideal", ["duration=346.9", "controller.type=baseline"])
    assert resolved.scenario.duration == 347.0
    assert any("346.9 s is not a whole number of samples" in note for note in resolved.notes)


@pytest.mark.parametrize(
    ("override", "field"),
    [
        ("plant.max_step=1e-6", "plant.max_step"),  # 500 000 plant steps a sample
        ("controller.sample_time=1e-6", "controller.sample_time"),  # 1e8 samples
        ("duration=1e9", "duration"),
    ],
)
def test_absurd_step_counts_are_refused_naming_the_field_unless_confirmed(override, field):
    resolved = load_scenario("paper-ideal", [override, "controller.type=baseline"])
    with pytest.raises(ConfigError, match=rf"^{field}: .*plant steps, over the 1e\+07 limit"):
        check_cost(resolved)
    assert check_cost(resolved, confirmed=True).plant_steps > MAX_PLANT_STEPS


def test_a_long_horizon_is_refused_by_its_time_estimate():
    resolved = load_scenario(
        "paper-ideal",
        ["controller.type=nmpc", "controller.prediction_horizon=3000", "duration=400"],
    )
    with pytest.raises(ConfigError, match=r"^controller.prediction_horizon: the run would take"):
        check_cost(resolved)


def test_the_presets_cost_seconds():
    for name in ("paper-ideal", "paper-6dof", "paper-depth-calm"):
        estimate = check_cost(load_scenario(name))
        assert estimate.seconds < 60 and estimate.plant_steps < 10_000


def _address_space_limit(n_bytes: int):
    return lambda: resource.setrlimit(resource.RLIMIT_AS, (n_bytes, n_bytes))


def test_memory_precheck_counts_the_address_space_limit(tmp_path):
    """prediction_horizon 3000 passed the check on MemAvailable and died under ulimit -v."""
    done = _cli(
        "explain", "paper-ideal", "--set", "controller.type=nmpc",
        "--set", "controller.prediction_horizon=3000",
        cwd=tmp_path, preexec_fn=_address_space_limit(2 * 2**30),
    )  # fmt: skip
    assert done.returncode == 2, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: controller.prediction_horizon: ")
    assert "memory available" in lines[0]


def test_a_diverging_plant_ends_lost_naming_the_step():
    # bluerov2-heavy's stable plant step is about 0.1 s; 0.5 s blows up at t = 2 s.
    resolved = load_scenario(
        "paper-ideal", ["vehicle=bluerov2-heavy", "plant.max_step=0.5", "duration=20"]
    )
    result = simulate(resolved)
    assert result.metrics["verdict"] == "lost"
    reason = result.metrics["verdict_reason"]
    assert (
        reason.startswith("the plant diverged at t = ") and "likely cause: plant.max_step" in reason
    )
    assert np.isfinite(result.log.state).all()


@pytest.mark.parametrize(
    ("scenario", "override", "field"),
    [
        ("paper-ideal", "disturbance.water_current={velocity_m_per_s: [100, 0, 0]}",
         "disturbance.water_current"),
        ("paper-ideal", "initial_state=[7.5, -12, 1.57, 80, 0, 0]", "initial_state"),
        # the controller's first solve overflowed: numpy's warnings printed lines of source
        ("paper-ideal", "initial_state=[7.5, -12, 1.57, 1e6, 0, 0]", "initial_state"),
        ("paper-ideal", "disturbance.current_force_world=[1e6, 0]",
         "disturbance.current_force_world"),
        # the 6-DOF plant's pitch guard: a failed run naming the Euler angles, not the current
        ("paper-6dof", "disturbance.water_current={velocity_m_per_s: [1e4, 0, 0]}",
         "disturbance.water_current"),
    ],
)  # fmt: skip
def test_a_plant_that_blows_up_at_once_names_the_likely_field(scenario, override, field):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        with pytest.raises(
            RunFailed, match=rf"lost: the plant diverged .* likely cause: {field}: "
        ):
            simulate(load_scenario(scenario, [override, "duration=10"]))
    assert not [w for w in caught if issubclass(w.category, RuntimeWarning)], caught


class _SignalInsideNativeCode:
    """What CasADi's Python layer does with our handler's exception about 1 call in 10
    (measured): SWIG swallows it and raises another (NotImplementedError 'Function_call',
    SystemError from DM.__array__)."""

    sample_time = 0.5
    preview_steps = 1

    def reset(self, state, thrust) -> None:
        self.thrust = np.zeros(len(thrust))

    def compute(self, observation) -> ControlResult:
        if observation.k == 2:
            try:
                os.kill(os.getpid(), signal.SIGTERM)
                time.sleep(1.0)
            except KeyboardInterrupt:
                raise NotImplementedError(
                    "Wrong number or type of arguments for overloaded function 'Function_call'."
                ) from None
        return ControlResult(thrust=self.thrust)


def test_a_signal_turned_into_another_exception_is_still_an_interrupt(
    monkeypatch, installed_interrupts
):
    monkeypatch.setattr(
        "auvmpc.experiments.run.make_controller", lambda scenario, model: _SignalInsideNativeCode()
    )
    with pytest.raises(interrupts.Interrupted) as raised:
        simulate(load_scenario("paper-ideal"))
    assert raised.value.exit_code == 143


def _two_run_campaign(tmp_path, name: str, overrides: str):
    """``campaign`` of two baseline runs of paper-ideal with ``overrides`` (YAML list items),
    into ``out``."""
    (tmp_path / "c.yaml").write_text(
        f"name: {name}\nbase: paper-ideal\nruns: 2\nseed: 1\n"
        f"overrides: [controller.type=baseline, {overrides}]\n"
        "parameters:\n  initial_state.0: {type: uniform, low: -1.0, high: 1.0, apply: add}\n"
    )
    return _cli("campaign", "c.yaml", "--out", "out", "--workers", "1", "--no-report", cwd=tmp_path)


def test_a_campaign_whose_every_run_is_refused_ends_non_zero(tmp_path):
    too_fast = "'reference={type: circle, speed: 9}'"
    done = _two_run_campaign(tmp_path, "refused", f"duration=4, {too_fast}")
    assert done.returncode == 1, done.stdout + done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and "none of its 2 runs finished" in lines[0], done.stderr
    assert "reference.speed" in lines[0]


def test_a_campaign_beyond_the_cost_limits_is_refused_before_any_run(tmp_path):
    done = _two_run_campaign(tmp_path, "long", "plant.max_step=1e-6")
    assert done.returncode == 2, done.stdout + done.stderr
    assert "plant.max_step" in done.stderr and "--yes-long" in done.stderr
    assert not (tmp_path / "out" / "results.sqlite").exists()


def test_estimate_counts_plant_substeps():
    estimate = estimate_cost(load_scenario("paper-ideal"))
    assert (estimate.samples, estimate.substeps) == (200, 10)
