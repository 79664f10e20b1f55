"""6-DOF identification (issue 27, "6-DOF where the log has attitude and rates"): the roll
and pitch model's equations against the 6-DOF model's own, then the 6-DOF excite manoeuvre
simulated on the BlueROV2 Heavy with noisy attitude, rates and velocities, every model
identified from the one log from a start 30 % off in every parameter."""

from __future__ import annotations

import json

import numpy as np
import pytest
import yaml

from auvmpc.controllers.playback import read_thrust_table
from auvmpc.errors import ConfigError
from auvmpc.identification.estimation import (
    Identification,
    ParameterEstimate,
    _sandwich,
    correlated_lags,
    identify,
)
from auvmpc.identification.excitation import MAX_TILT_RAD
from auvmpc.identification.logs import LogOptions
from auvmpc.identification.report import (
    identification_json,
    markdown_report,
    vehicle_file_text,
)
from auvmpc.identification.roll_pitch import (
    OUTPUTS,
    PARAMETERS,
    RollPitchGreyBox,
    roll_pitch_log,
)
from auvmpc.identification.six_dof_log import (
    identify_six_dof,
    offset_vehicle,
    parameter_values,
    read_six_dof_samples,
)
from auvmpc.models.six_dof import SIX_DOF, six_dof_model
from auvmpc.models.six_dof_params import horizontal_equivalent
from auvmpc.models.vehicle import load_vehicle
from auvmpc.sim.log import read_log_table
from tests.conftest import (
    ROUND_OFF_TOL,
    SIX_DOF_EXCITE_VEHICLE,
    START_ERROR,
    WITHIN,
    assert_recovered,
    odometry_rewritten,
    with_sensor_noise,
)
from tests.test_cli import run_cli

VEHICLE = SIX_DOF_EXCITE_VEHICLE
SAMPLE_TIME_S = 0.1


def test_roll_pitch_rows_are_the_six_dof_model():
    """At a tilted, moving state under thrust, the grey box's [phi', theta', p', q'] at the
    vehicle's own values is the 6-DOF model's (the same C_RB, C_A, g and kinematics)."""
    truth = load_vehicle(VEHICLE)
    rng = np.random.default_rng(3)
    state = np.concatenate([[1.0, 2.0, 5.0, 0.2, -0.15, 0.7], rng.normal(0, 0.3, 6)])
    thrust = rng.uniform(-20, 20, truth.six_dof.n_thrusters)
    expected = six_dof_model(truth).evaluate(state, thrust)
    # A log holding this state and thrust: its inputs are theirs.
    log = roll_pitch_log(
        "one", SAMPLE_TIME_S, np.tile(state, (20, 1)), np.tile(thrust, (19, 1)), truth
    )
    greybox = RollPitchGreyBox(truth)
    x = state[[SIX_DOF.index(name) for name in ("phi", "theta", "p", "q")]]
    derivative = np.asarray(
        greybox.rhs()(x, log.force[0, : 2 + greybox.linear_inputs], greybox.start())
    ).ravel()
    rows = [SIX_DOF.index(name) for name in ("phi", "theta", "p", "q")]
    np.testing.assert_allclose(derivative, expected[rows], rtol=ROUND_OFF_TOL, atol=ROUND_OFF_TOL)


def test_a_log_too_slow_for_roll_and_pitch_is_refused():
    """A 6-DOF run's 0.5 s samples cannot follow the BlueROV2 Heavy's 1.5 s pitch period."""
    truth = load_vehicle(VEHICLE)
    state = np.zeros((121, SIX_DOF.size))
    thrust = np.ones((120, truth.six_dof.n_thrusters))
    log = roll_pitch_log("slow", 0.5, state, thrust, truth)
    with pytest.raises(ConfigError, match=r"sampled every 0.5 s: roll and pitch oscillate"):
        identify([log], truth, greybox=RollPitchGreyBox(truth))


def test_excite_run_identify_every_model_from_one_six_dof_log(six_dof_excite_run):
    """``excite --dof six-dof`` writes a 6-DOF scenario and the table of every six_dof
    thruster; ``run`` plays that table as it is (no depth channel splitting a heave force),
    so roll and pitch move; from that run's states with an AHRS's, gyro's and DVL's noise
    and a start 30 % off in all 20 parameters, the 3-DOF, heave and roll and pitch models
    come out of the one log, into one vehicle file whose six_dof section agrees."""
    truth = load_vehicle(VEHICLE)
    scenario = six_dof_excite_run / "excite.yaml"
    assert yaml.safe_load(scenario.read_text())["kind"] == "six-dof"
    names = truth.six_dof_actuators.layout.names
    table = read_thrust_table(six_dof_excite_run / "excite.csv", SAMPLE_TIME_S, names)
    run = six_dof_excite_run / "run"
    log = read_log_table(run / "log.csv", "RUN_DIR")
    played = np.column_stack([log.numbers(name, slice(0, len(table))) for name in names])
    np.testing.assert_array_equal(played, table)
    metrics = json.loads((run / "run.json").read_text())["metrics"]
    assert metrics["thrust_limit_violations"] == metrics["thrust_rate_violations"] == 0
    assert 0.1 < max(metrics["max_abs_roll_rad"], metrics["max_abs_pitch_rad"]) <= MAX_TILT_RAD
    name, sample_time, states, thrust = read_six_dof_samples(run, truth)
    measured = with_sensor_noise(states)
    start = offset_vehicle(truth, START_ERROR)
    found = identify_six_dof([(name, sample_time, measured, thrust)], start)
    true_values = parameter_values(truth)
    assert [p.name for p in found.parameters] == list(true_values)
    assert_recovered(found, true_values)
    assert found.outputs == ("u", "v", "r", "w", "phi", "theta", "p", "q")
    assert np.all(found.validation_rms < 0.5 * found.validation_rms_start)
    # One vehicle file: the 3-DOF fields, the heave section and the six_dof section agree.
    start_data = start.model_dump(mode="json")
    written = load_vehicle(yaml.safe_load(vehicle_file_text(start_data, found, "start")))
    reduced = horizontal_equivalent(written.mass, written.six_dof)
    for field in ("m11", "m22", "Iz_added", "Xu", "Xuu", "Yv", "Yvv", "Nr", "Nrr"):
        assert reduced[field] == pytest.approx(getattr(written, field), rel=1e-5, abs=1e-9)
    for field in ("m_heave", "Zw", "Zww", "net_buoyancy_N"):
        assert reduced[field] == pytest.approx(getattr(written.heave, field), rel=1e-4)
    assert RollPitchGreyBox(written).start() == pytest.approx(
        [true_values[name] for name in PARAMETERS], rel=WITHIN, abs=0.02
    )


def test_the_sandwich_widens_intervals_only_where_residuals_are_correlated():
    """A straight-line fit: with white residuals the sandwich variance is the Fisher one
    (to its sampling error); with residuals correlated over ~10 samples (a model error
    slower than the sampling) it is several times larger, as the true variance is."""
    rng = np.random.default_rng(1)
    n = 2000
    x = np.sin(np.linspace(0.0, 60.0, n))[:, None]  # the regressor, slowly varying
    inverse = np.linalg.inv(x.T @ x)
    white = rng.normal(0.0, 1.0, n)
    correlated = np.convolve(rng.normal(0.0, 1.0, n + 9), np.ones(10) / np.sqrt(10), "valid")
    ratios = []
    for residual in (white, correlated):
        fisher = residual @ residual / (n - 1) * inverse[0, 0]
        # rows as output_error stacks a segment: its samples 1..n-1, then its first
        rows = np.r_[1:n, 0]
        sandwich = _sandwich(x[rows], residual[rows], inverse, [n - 1], 1)[0, 0]
        ratios.append(sandwich / fisher)
    assert 0.7 < ratios[0] < 1.4
    assert ratios[1] > 4.0
    assert correlated_lags([white[:, None]]) < 9 <= correlated_lags([correlated[:, None]])


def test_a_model_error_warning_is_named_in_every_output():
    """A parameter identify flags (excited, the log's halves disagree) is named in
    identification.json, the report and the vehicle file's header."""
    flagged = ParameterEstimate("six_dof.K_pdot", -0.02, -0.1, -0.14, (-0.17, -0.11), True,
                                model_error=True)  # fmt: skip
    fine = ParameterEstimate("six_dof.M_qdot", -0.86, -0.8, -0.85, (-0.87, -0.83), True)
    found = Identification(
        parameters=[flagged, fine], logs=["x"], sample_time=0.1, fit_samples=320,
        validation_samples=80, noise_std=np.full(4, 0.005), equation_error_used=True,
        validation_rms=np.full(4, 0.006), validation_rms_start=np.full(4, 0.1), iterations=9,
        solver_status="Solve_Succeeded", substeps=2, outputs=OUTPUTS,
        units=RollPitchGreyBox.units, model=RollPitchGreyBox.title,
    )  # fmt: skip
    data = identification_json(found)
    assert data["model_error"] == ["six_dof.K_pdot"]
    assert data["parameters"]["six_dof.K_pdot"]["model_error"] is True
    assert data["parameters"]["six_dof.M_qdot"]["model_error"] is False
    assert "**Model error** dominates" in markdown_report(found, "start", None)
    text = vehicle_file_text(load_vehicle(VEHICLE).model_dump(mode="json"), found, "start")
    assert "six_dof.K_pdot: -0.14 [-0.17, -0.11]  MODEL ERROR" in text


# The exporter writes log.csv's float64 values into CDR float64 fields at round(t * 1e9) ns,
# where the reader's interpolation returns them; the attitude goes through a quaternion and
# back (scipy), which costs round-off of a few 1e-16 rad.
BAG_STATE_TOL = 1e-12
# Samples equal to 1e-12 through IPOPT's iterations (tol 1e-9, identification/estimation.py)
# reach the same optimum to well within 1e-6 relative.
SAME_FIT_REL = 1e-6


def _in_rep103_axes(message) -> None:
    """An odometry message in REP 103 axes (odometry frame and body y port, z up: the half
    turn about x)."""
    pose, twist = message.pose.pose, message.twist.twist
    for vector in (pose.position, twist.linear, twist.angular, pose.orientation):
        vector.y, vector.z = -vector.y, -vector.z  # a quaternion's too: D q D


def test_six_dof_identification_from_a_ros2_bag(six_dof_excite_run, tmp_path, monkeypatch,
                                                capsys):  # fmt: skip
    """The 6-DOF run exported as a ROS 2 bag (MCAP) reads back as the run folder's states and
    thrusts; the same bag rewritten in REP 103 axes (SQLite3) reads back the same with
    ``--body-frame flu``; and ``identify --dof six-dof`` from the bag finds the values the
    run folder gives, from a start 30 % off; a wrench topic is refused in one line."""
    pytest.importorskip("rosbags")
    truth = load_vehicle(VEHICLE)
    run = six_dof_excite_run / "run"
    code, _, err = run_cli(monkeypatch, capsys, "export", str(run), "--format", "rosbag2",
                           "--out", str(tmp_path / "bag"))  # fmt: skip
    assert code == 0, err
    _, sample_time, states, thrust = read_six_dof_samples(run, truth)
    mirrored = tmp_path / "rep103"
    odometry_rewritten(tmp_path / "bag", mirrored, _in_rep103_axes)
    for bag, frame in ((tmp_path / "bag", "frd"), (mirrored, "flu")):
        _, bag_time, bag_states, bag_thrust = read_six_dof_samples(
            bag, truth, LogOptions(body_frame=frame)
        )
        assert bag_time == pytest.approx(sample_time, rel=1e-12)
        np.testing.assert_allclose(bag_states, states, rtol=0, atol=BAG_STATE_TOL)
        np.testing.assert_array_equal(bag_thrust, thrust)
    start_file = tmp_path / "start.yaml"
    start = offset_vehicle(truth, START_ERROR)
    start_file.write_text(yaml.safe_dump(start.model_dump(mode="json")))
    out = tmp_path / "identified" / "vehicle.yaml"
    out.parent.mkdir()
    code, _, err = run_cli(monkeypatch, capsys, "identify", str(tmp_path / "bag"), "--dof",
                           "six-dof", "--vehicle", str(start_file), "--out", str(out))  # fmt: skip
    assert code == 0, err
    # The bag's samples are the run folder's (above) and identification is deterministic:
    # the same values as from the folder (the folder's accuracy against the truth is the
    # test above's, with noise).
    found = json.loads((out.parent / "identification.json").read_text())["parameters"]
    from_folder = identify_six_dof([(str(run), sample_time, states, thrust)], start)
    assert list(found) == [p.name for p in from_folder.parameters]
    for estimate in from_folder.parameters:
        entry = found[estimate.name]
        assert entry["value"] == pytest.approx(estimate.value, rel=SAME_FIT_REL, abs=1e-12)
        assert entry["excited"] == estimate.excited
    # A wrench has no roll and pitch moments: refused in one line.
    code, _, err = run_cli(monkeypatch, capsys, "identify", str(tmp_path / "bag"), "--dof",
                           "six-dof", "--vehicle", str(start_file), "--out", str(out),
                           "--wrench-topic", "/wrench", "--overwrite")  # fmt: skip
    assert code == 2 and len(err.strip().splitlines()) == 1 and "--wrench-topic" in err, err
