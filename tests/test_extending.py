"""A controller of your own is one file and one register_controller call (docs/extending.md,
examples/own_controller.py): scenarios then name it, auvmpc flies it on any vehicle and
files its runs like a built-in controller's."""

from __future__ import annotations

import importlib.util
import subprocess
import sys
from pathlib import Path

import pytest

import auvmpc
from auvmpc.controllers.base import Controller
from auvmpc.controllers.registry import REGISTRY, register_controller
from auvmpc.errors import ConfigError

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "own_controller.py"
NAME = "pid-tracker"


@pytest.fixture
def example():
    """The example module, imported (which registers its controller), and the registry as
    it was afterwards: registration lasts for the process, and other tests must not see it."""
    spec = importlib.util.spec_from_file_location("own_controller", EXAMPLE)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    yield module
    REGISTRY.pop(NAME, None)  # its entry holds its recovery too


def test_a_name_is_refused_until_it_is_registered():
    with pytest.raises(ConfigError, match="controller.type: input should be one of 'baseline'"):
        auvmpc.load_scenario("paper-ideal", [f"controller.type={NAME}"])


@pytest.mark.parametrize(
    # the paper's 122 kg vehicle, and the BlueROV2 Heavy in a current with sensor noise
    "scenario",
    ["paper-ideal", "bluerov2-figure-eight"],
)
def test_a_registered_controller_flies_any_vehicle_like_a_built_in(tmp_path, example, scenario):
    run = auvmpc.simulate(auvmpc.load_scenario(scenario, [f"controller.type={NAME}"]))
    metrics = run.metrics
    # A verdict of "ok" is the metrics' own bar (docs/verdict.md): on track after the
    # transient, within the hard limits (its own clipping, checked by the run's metrics).
    assert metrics["verdict"] == "ok", metrics["verdict_reason"]
    assert metrics["thrust_limit_violations"] == metrics["thrust_rate_violations"] == 0
    folder = auvmpc.save_run(run, tmp_path / "run", figures=False)
    # The run folder names it, and reads back in a process where it is not registered.
    assert f'"type": "{NAME}"' in (folder / "run.json").read_text()
    command = Path(sys.executable).parent / "auvmpc"  # a fresh process, nothing registered
    plotted = subprocess.run([str(command), "plot", str(folder)], capture_output=True, text=True)
    assert plotted.returncode == 0, plotted.stderr
    assert (folder / "trajectory.png").is_file()


def test_a_registered_controller_has_knobs_of_its_own(tmp_path, example):
    """Its configuration class is the scenario's schema for it: its own knob is read and
    checked, a built-in controller's knob is refused, the file's type's knobs are dropped."""
    scenario = auvmpc.load_scenario(
        "paper-ideal", [f"controller.type={NAME}", "controller.natural_frequency=0.8"]
    )
    assert isinstance(scenario.scenario.controller, example.PidTrackerConfig)
    assert auvmpc.build_controller(scenario).natural_frequency == 0.8
    assert scenario.notes[0].startswith(f"controller.type: mpc changed to {NAME} by an override")
    with pytest.raises(ConfigError, match="natural_frequency: input should be greater than 0"):
        auvmpc.load_scenario("paper-ideal", [f"controller.type={NAME}",
                                             "controller.natural_frequency=0"])  # fmt: skip
    # the knobs of paper-ideal's mpc in a file that names this type: refused, not ignored
    text = (Path(auvmpc.__file__).parent / "presets/scenarios/paper-ideal.yaml").read_text()
    (tmp_path / "own.yaml").write_text(text.replace("type: mpc", f"type: {NAME}"))
    owners = "mpc, ltv-mpc, nmpc, do-mpc, six-dof-nmpc"
    with pytest.raises(ConfigError, match=f"controller.prediction_horizon: a knob of {owners}, "
                       f"not of controller type {NAME}"):  # fmt: skip
        auvmpc.load_scenario(tmp_path / "own.yaml")


def test_registering_is_checked(example):
    with pytest.raises(ValueError, match="is taken"):
        register_controller(NAME, example.PidTracker)
    with pytest.raises(ValueError, match="is taken"):
        register_controller("nmpc", example.PidTracker)
    with pytest.raises(ValueError, match="lower-case words"):
        register_controller("My Controller", example.PidTracker)
    with pytest.raises(ValueError, match="not a controllers.base.Controller"):
        register_controller("not-a-controller", dict)
    with pytest.raises(ValueError, match="not a controllers.config.HorizontalControllerConfig"):
        register_controller("no-config", example.PidTracker, config=dict)
    with pytest.raises(ValueError, match="only a ShelledController"):
        register_controller("unshelled", example.PidTracker, recovered=True)
    assert issubclass(example.PidTracker, Controller)
