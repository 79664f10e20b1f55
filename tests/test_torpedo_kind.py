"""A vehicle with actuators: (remus100: a propeller and fins) flown by a kind: six-dof scenario
with a controller of the whole vehicle, end to end; the cross-track metric against analytic
truth; the refusals in one line."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from auvmpc.experiments.run import read_run
from auvmpc.models.vehicle import load_vehicle, vehicle_data
from auvmpc.plots import figure_actuators
from auvmpc.references import LineConfig, make_reference
from auvmpc.scenario import load_scenario
from auvmpc.sim.metrics import cross_track_error, reference_path
from auvmpc.sim.verdict import characteristic_length_m
from tests.test_cli import run_cli

SHORT = Path(__file__).parent / "scenarios" / "remus100-short.yaml"
INPUTS = ["propeller_rpm", "rudder_deg", "stern_planes_deg"]
ADDED = (
    "actuator_limit_violations",
    "actuator_rate_violations",
    "cross_track_rms_after_transient_m",
    "depth_rms_error_after_transient_m",
)


def test_auvmpc_run_flies_remus100_with_its_default_controller(monkeypatch, capsys, tmp_path):
    """8 s of a straight leg in a 0.3 m/s cross current (tests/scenarios/remus100-short.yaml,
    no controller.type): six-dof-nmpc chosen, the run folder with the actuators' names (and
    their figure, in their units), the added metrics finite, every input within its limits
    and rate. The bounds are loose: they catch a wiring error (a torpedo off its path by
    metres), not tuning."""
    out = tmp_path / "run"
    code, _, err = run_cli(
        monkeypatch, capsys, "run", str(SHORT), "--out", str(out), "--no-figures"
    )
    assert code == 0, err
    info = json.loads((out / "run.json").read_text())
    assert info["scenario"]["controller"]["type"] == "six-dof-nmpc"
    assert info["choices"]["type"]["value"] == "six-dof-nmpc"
    assert not any("depth_controller" in note for note in info["warnings"])  # none given
    header = (out / "log.csv").read_text().splitlines()[0].split(",")
    assert header[header.index("r_ref") + 1 : header.index("solve_ms")] == INPUTS
    metrics = info["metrics"]
    for name in ADDED:
        assert math.isfinite(metrics[name]), name
    assert metrics["actuator_limit_violations"] == metrics["actuator_rate_violations"] == 0
    assert metrics["thrust_effort_N2s"] is None  # no input is a thrust in N
    assert metrics["cross_track_rms_after_transient_m"] < 0.5
    assert metrics["depth_rms_error_after_transient_m"] < 0.2
    assert metrics["verdict"] == "ok"
    _, log = read_run(out)  # read back by the actuators' names
    assert list(log.input_names) == INPUTS and log.thrust.shape[1] == 3
    figure = figure_actuators(log, load_vehicle("remus100").six_dof_actuators)
    labels = [ax.get_ylabel() for ax in figure.axes]
    assert labels[0].startswith("propeller_rpm (rpm)") and labels[1].startswith("rudder_deg (deg)")


def test_cross_track_is_the_distance_to_a_straight_path():
    """A line at 30 deg through (2, -1), sampled from the reference: a vehicle 2.5 m to its
    left, anywhere along it, is 2.5 m off, and one on the line but lagging is 0 m off (the
    position error would count the lag)."""
    heading = math.radians(30.0)
    reference = make_reference(LineConfig(start=(2.0, -1.0), heading_deg=30.0, speed=1.5))
    path = reference_path(reference, 20.0, 0.2)
    along = np.array([math.cos(heading), math.sin(heading)])
    left = np.array([-math.sin(heading), math.cos(heading)])
    distance = np.array([3.0, 11.7, 25.0])
    offset = np.array([2.0, -1.0]) + distance[:, None] * along + 2.5 * left
    np.testing.assert_allclose(cross_track_error(offset, path), 2.5, atol=1e-9)
    lagging = np.array([2.0, -1.0]) + distance[:, None] * along
    np.testing.assert_allclose(cross_track_error(lagging, path), 0.0, atol=1e-9)
    beyond = np.array([[2.0, -1.0]]) - 4.0 * along  # before the path starts: to its end
    np.testing.assert_allclose(cross_track_error(beyond, path), 4.0, atol=1e-9)


def test_a_torpedo_without_a_size_is_as_long_as_its_actuators_reach():
    data, _ = vehicle_data("remus100")
    data.pop("size")
    vehicle = load_vehicle(data)
    reach = max(math.hypot(*a.position) for a in vehicle.six_dof_actuators.actuators)
    assert characteristic_length_m(vehicle) == pytest.approx(2.0 * reach)


def test_a_depth_controller_given_beside_it_is_a_note_not_an_error():
    resolved = load_scenario(SHORT, ["depth_controller.prediction_horizon=20"])
    assert any(note.startswith("depth_controller: unused") for note in resolved.notes)


@pytest.mark.parametrize(
    ("overrides", "field"),
    [
        (["controller.type=nmpc"], "controller.type"),
        (["controller.linearisation_iterations=2"], "controller.linearisation_iterations"),
        (["initial_thrust=[2000, 0, 0]"], "initial_thrust"),
        (["initial_thrust=[900, 0]"], "initial_thrust"),
    ],
)
def test_what_cannot_fly_it_is_refused_in_one_line(monkeypatch, capsys, overrides, field):
    """The channel pair (fixed thrusters), a knob the default six-dof-nmpc has not, an
    initial command beyond the propeller's 1525 rpm or one short."""
    sets = [item for override in overrides for item in ("--set", override)]
    code, _, err = run_cli(monkeypatch, capsys, "run", str(SHORT), *sets, "--out", "never")
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in err
    assert lines[0].lower().startswith(f"error: {field}:"), lines[0]


def test_a_knob_of_the_vehicles_default_controller_is_taken_without_naming_its_type(
    monkeypatch, capsys, tmp_path
):
    """remus100's default controller is six-dof-nmpc: a knob of it set on a controller mapping
    without ``type`` is that controller's (validated as it before the resolution, where the
    vehicle is known), the same configuration as with the type named, and it takes effect:
    the run's record says so and the built controller runs the EKF."""
    from auvmpc.api import override
    from auvmpc.controllers.registry import build_controller

    unnamed = load_scenario(SHORT, ["controller.estimator=ekf"])
    named = load_scenario(SHORT, ["controller.type=six-dof-nmpc", "controller.estimator=ekf"])
    assert unnamed.scenario.controller == named.scenario.controller
    assert unnamed.scenario.controller.estimator == "ekf"
    assert "type" not in unnamed.given.controller.model_fields_set  # still the vehicle's
    assert unnamed.choices["type"]["value"] == "six-dof-nmpc"
    assert build_controller(unnamed.scenario.controller, unnamed.model)._ekf is not None
    # the library's override, from the scenario as written, the same
    again = override(load_scenario(SHORT), {"controller.estimator": "ekf"})
    assert again.scenario.controller == named.scenario.controller
    out = tmp_path / "run"
    code, _, err = run_cli(
        monkeypatch, capsys, "run", str(SHORT), "--set", "controller.estimator=ekf",
        "--set", "duration=1.0", "--out", str(out), "--no-figures",
    )  # fmt: skip
    assert code == 0, err
    controller = json.loads((out / "run.json").read_text())["scenario"]["controller"]
    assert (controller["type"], controller["estimator"]) == ("six-dof-nmpc", "ekf")


@pytest.mark.parametrize(
    ("override", "expected"),
    [
        ("controller.nmpc_mode=full", "a knob of nmpc, not of controller type six-dof-nmpc"),
        ("controller.estimatr=ekf", "unknown key"),
        ("controller.estimator=kalman", "input should be 'filters' or 'ekf'"),
    ],
)
def test_a_wrong_knob_of_the_vehicles_default_controller_is_one_line(
    monkeypatch, capsys, override, expected
):
    """Validated as six-dof-nmpc's: another type's knob, an unknown key and a bad value of
    its own knob each refused in one line naming the field and the value."""
    field, _, value = override.partition("=")
    code, _, err = run_cli(monkeypatch, capsys, "run", str(SHORT), "--set", override,
                           "--out", "never")  # fmt: skip
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in err
    assert lines[0].startswith(f"error: {field}: {expected}"), lines[0]
    assert value in lines[0]
