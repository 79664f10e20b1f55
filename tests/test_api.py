"""The public Python API (auvmpc.api, re-exported by the package): what it promises."""

from __future__ import annotations

import numpy as np
import pytest

import auvmpc
from auvmpc.errors import ConfigError


def test_the_package_exports_the_api_lazily():
    from auvmpc import api

    assert set(auvmpc.__all__) == {"__version__", *api.__all__}
    for name in api.__all__:
        assert getattr(auvmpc, name) is getattr(api, name)
    with pytest.raises(AttributeError, match="no attribute 'nope'"):
        auvmpc.nope  # noqa: B018


def test_mapping_and_text_overrides_agree():
    a = auvmpc.load_scenario("paper-ideal", {"duration": 5, "controller.Q": (1, 2, 3, 4, 5, 6)})
    b = auvmpc.load_scenario("paper-ideal", ["duration=5", "controller.Q=[1, 2, 3, 4, 5, 6]"])
    assert a.scenario == b.scenario
    assert a.scenario.controller.Q == (1, 2, 3, 4, 5, 6)


def test_override_copies_and_validates():
    base = auvmpc.load_scenario("paper-ideal", {"duration": 5})
    changed = auvmpc.override(base, {"vehicle": "bluerov2-heavy", "duration": 3})
    assert (base.model.name, base.scenario.duration) == ("jmse2210", 5)
    assert (changed.model.name, changed.scenario.duration) == ("bluerov2-heavy", 3)
    with pytest.raises(ConfigError, match=r"controller\.horizon: unknown key"):
        auvmpc.override(base, {"controller.horizon": 3})


def test_a_bad_controller_label_is_a_config_error():
    with pytest.raises(ConfigError, match=r"--controller: not a controller.type or bench label"):
        auvmpc.load_scenario("paper-ideal", controller="fastest")


@pytest.mark.parametrize("vehicle", ["jmse2210", "bluerov2-heavy"])
def test_simulate_dataframe_and_saved_folder_agree(tmp_path, vehicle):
    run = auvmpc.simulate(auvmpc.load_scenario("paper-ideal", {"duration": 3, "vehicle": vehicle}))
    frame = auvmpc.log_dataframe(run)
    n = run.log.n_thrusters
    assert len(frame) == run.log.steps + 1
    np.testing.assert_array_equal(frame[["x", "y", "psi"]].to_numpy(), run.log.state[:, :3])
    np.testing.assert_array_equal(
        frame[[f"F{i + 1}" for i in range(n)]].to_numpy()[:-1], run.log.thrust
    )
    assert frame[f"F{n}"].isna().iloc[-1]  # no command on the last row
    folder = auvmpc.save_run(run, tmp_path / "run", figures=False)
    info, saved = auvmpc.load_run(folder)
    assert info["metrics"] == run.metrics
    np.testing.assert_array_equal(saved[["x", "y"]].to_numpy(), frame[["x", "y"]].to_numpy())
    assert set(auvmpc.figures(run)) == {
        "trajectory",
        "errors",
        "velocities",
        "thrusts",
        "solve_times",
    }


def test_depth_scenarios_go_through_the_same_calls():
    scenario = auvmpc.load_scenario("paper-depth-calm", {"duration": 2, "reference.step_time_s": 1})
    run = auvmpc.simulate(scenario)
    assert list(auvmpc.figures(run)) == ["depth"]
    assert {"z", "z_ref", "Fz1"} <= set(auvmpc.log_dataframe(run).columns)
    assert type(auvmpc.build_controller(scenario)).__name__ == "DepthMpc"  # the registry's


def test_build_controller_returns_the_scenarios_controller():
    scenario = auvmpc.load_scenario("paper-ideal", controller="baseline")
    controller = auvmpc.build_controller(scenario)
    assert controller.sample_time == scenario.scenario.controller.sample_time
    assert type(controller).__name__ == "BaselineController"
