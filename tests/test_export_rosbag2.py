"""`auvmpc export --format rosbag2`: the bag read back by rosbags equals the run folder
(issue 13). Positions to 1e-9 m: the CSV holds the shortest repr of each float and CDR
stores float64, so the round trip is exact; 1e-9 only allows for a different reader."""

from __future__ import annotations

import math

import numpy as np
import pytest

from auvmpc.models.vehicle import load_vehicle
from auvmpc.sim.log import read_log_table
from tests.test_cli import run_cli

rosbags = pytest.importorskip("rosbags")
from rosbags.highlevel import AnyReader  # noqa: E402

POSITION_TOL_M = 1e-9
ANGLE_TOL_RAD = 1e-9


def _run_and_export(monkeypatch, capsys, tmp_path, scenario, *overrides):
    run_dir = tmp_path / "run"
    sets = [arg for item in overrides for arg in ("--set", item)]
    code, _, err = run_cli(
        monkeypatch, capsys, "run", scenario, *sets, "--no-figures", "--out", str(run_dir)
    )
    assert code == 0, err
    code, _, err = run_cli(monkeypatch, capsys, "export", str(run_dir), "--format", "rosbag2")
    assert code == 0, err
    return run_dir, read_log_table(run_dir / "log.csv").frame()


def _read(bag):
    with AnyReader([bag]) as reader:
        types = {c.topic: c.msgtype for c in reader.connections}
        messages: dict[str, list] = {}
        for connection, stamp, raw in reader.messages():
            message = reader.deserialize(raw, connection.msgtype)
            messages.setdefault(connection.topic, []).append((stamp, message))
    return types, messages


@pytest.mark.parametrize("vehicle", ["jmse2210", "bluerov2-heavy"])
def test_paper_obstacles_bag_reads_back_as_the_log(monkeypatch, capsys, tmp_path, vehicle):
    run_dir, log = _run_and_export(
        monkeypatch, capsys, tmp_path, "paper-obstacles", "duration=10", f"vehicle={vehicle}"
    )
    bag = run_dir / "rosbag2"
    assert (bag / "metadata.yaml").is_file() and list(bag.glob("*.mcap"))
    types, messages = _read(bag)
    n_thrusters = load_vehicle(vehicle).n_thrusters
    thrusters = [f"F{i + 1}" for i in range(n_thrusters)]
    assert types == {
        "/odom": "nav_msgs/msg/Odometry",
        "/reference/odom": "nav_msgs/msg/Odometry",
        "/reference/path": "nav_msgs/msg/Path",
        "/reference/horizon": "nav_msgs/msg/Path",
        "/thrust": "std_msgs/msg/Float64MultiArray",
        **{f"/thrusters/{name}": "geometry_msgs/msg/WrenchStamped" for name in thrusters},
        "/disturbance/true": "geometry_msgs/msg/WrenchStamped",
        "/disturbance/estimate": "geometry_msgs/msg/WrenchStamped",
        "/obstacles": "visualization_msgs/msg/MarkerArray",
    }
    rows = len(log)
    for topic in (
        "/odom",
        "/reference/odom",
        "/reference/horizon",
        "/disturbance/true",
        "/obstacles",
    ):
        assert len(messages[topic]) == rows, topic
    # Commands exist on rows 0..N-1 (the last row has none, interfaces.md).
    for topic in (
        "/thrust",
        *(f"/thrusters/{name}" for name in thrusters),
        "/disturbance/estimate",
    ):
        assert len(messages[topic]) == rows - 1, topic

    stamps = np.array([stamp for stamp, _ in messages["/odom"]]) * 1e-9
    np.testing.assert_allclose(stamps, log["t"], rtol=0, atol=1e-9)
    for suffix, topic in (("", "/odom"), ("_ref", "/reference/odom")):
        pose = np.array(
            [[m.pose.pose.position.x, m.pose.pose.position.y] for _, m in messages[topic]]
        )
        np.testing.assert_allclose(
            pose, log[[f"x{suffix}", f"y{suffix}"]], rtol=0, atol=POSITION_TOL_M
        )
        yaw = np.array(
            [
                2 * math.atan2(m.pose.pose.orientation.z, m.pose.pose.orientation.w)
                for _, m in messages[topic]
            ]
        )
        wrapped = np.angle(np.exp(1j * (yaw - log[f"psi{suffix}"].to_numpy())))
        np.testing.assert_allclose(wrapped, 0.0, atol=ANGLE_TOL_RAD)
        twist = np.array(
            [
                [m.twist.twist.linear.x, m.twist.twist.linear.y, m.twist.twist.angular.z]
                for _, m in messages[topic]
            ]
        )
        np.testing.assert_allclose(
            twist, log[[f"u{suffix}", f"v{suffix}", f"r{suffix}"]], atol=1e-12
        )
    ((_, path),) = messages["/reference/path"]
    assert len(path.poses) == rows
    # The horizon from row k: the reference rows k..k+ny, cut at the end of the log.
    ny = 30  # paper-obstacles' prediction_horizon
    for k in (0, rows - 5):
        poses = messages["/reference/horizon"][k][1].poses
        assert len(poses) == min(ny + 1, rows - k)
        assert poses[0].pose.position.x == log["x_ref"][k]

    # The thrusters' wrenches add up to the allocation T @ F of auvmpc.models.vehicle.
    model = load_vehicle(vehicle)
    applied = log[thrusters].to_numpy()[:-1]
    total = np.zeros((rows - 1, 3))
    for name in thrusters:
        wrench = np.array(
            [
                [m.wrench.force.x, m.wrench.force.y, m.wrench.torque.z]
                for _, m in messages[f"/thrusters/{name}"]
            ]
        )
        total += wrench
    np.testing.assert_allclose(total, applied @ model.T.T, atol=1e-9)
    array = np.array([m.data for _, m in messages["/thrust"]])
    np.testing.assert_array_equal(array, applied)

    # Obstacles at their logged place, one marker each.
    markers = messages["/obstacles"][0][1].markers
    assert [(m.pose.position.x, m.pose.position.y) for m in markers] == [(2.0, 8.0), (8.0, -6.0)]
    assert [m.scale.x for m in markers] == [2.0, 1.0]


def test_a_moving_obstacle_moves_and_vanishes_in_the_bag(monkeypatch, capsys, tmp_path):
    run_dir, log = _run_and_export(
        monkeypatch, capsys, tmp_path, "paper-ideal", "duration=4",
        "obstacles=[{center: [30, 0], radius: 0.5, velocity: [0.5, -0.25], vanish_time: 2}]",
    )  # fmt: skip
    _, messages = _read(run_dir / "rosbag2")
    for (_stamp, array), t in zip(messages["/obstacles"], log["t"], strict=True):
        (marker,) = array.markers
        assert (marker.pose.position.x, marker.pose.position.y) == pytest.approx(
            (30 + 0.5 * t, -0.25 * t)
        )
        assert marker.action == (0 if t < 2 else 2)  # ADD while it exists, then DELETE


def test_a_depth_run_exports_depth_and_vertical_thrust(monkeypatch, capsys, tmp_path):
    run_dir, log = _run_and_export(
        monkeypatch, capsys, tmp_path, "paper-depth-calm", "duration=3", "reference.step_time_s=1"
    )
    types, messages = _read(run_dir / "rosbag2")
    z = [m.pose.pose.position.z for _, m in messages["/odom"]]
    np.testing.assert_allclose(z, log["z"], atol=POSITION_TOL_M)
    assert types["/thrusters/Fz1"] == "geometry_msgs/msg/WrenchStamped"
    forces = [m.wrench.force.z for _, m in messages["/thrusters/Fz1"]]
    np.testing.assert_array_equal(forces, log["Fz1"].to_numpy()[:-1])


def test_an_existing_output_is_never_replaced(monkeypatch, capsys, tmp_path):
    run_dir, _ = _run_and_export(monkeypatch, capsys, tmp_path, "paper-ideal", "duration=1")
    before = sorted(p.name for p in (run_dir / "rosbag2").iterdir())
    code, _, err = run_cli(monkeypatch, capsys, "export", str(run_dir))
    assert code == 2
    assert "--out: exists; remove it or choose another folder" in err
    assert sorted(p.name for p in (run_dir / "rosbag2").iterdir()) == before


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["export", "no-such-dir"], "RUN_DIR: not a run folder"),
        (["export", ".", "--format", "bag1"], "--format: one of ['rosbag2'] (got 'bag1')"),
    ],
)
def test_bad_input_is_one_line(monkeypatch, capsys, args, message):
    code, _, err = run_cli(monkeypatch, capsys, *args)
    assert code == 2
    assert message in err and len(err.strip().splitlines()) == 1


def test_without_rosbags_the_error_says_how_to_install(monkeypatch, tmp_path):
    import builtins

    from auvmpc.errors import ConfigError
    from auvmpc.export import export_rosbag2

    real_import = builtins.__import__

    def no_rosbags(name, *args, **kwargs):
        if name.startswith("rosbags"):
            raise ImportError(name)
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_rosbags)
    with pytest.raises(ConfigError, match=r"pip install 'auvmpc\[ros\]'"):
        export_rosbag2(tmp_path)


def test_columns_added_later_are_exported_by_name(monkeypatch, capsys, tmp_path):
    """A log with an estimate of the current and 6-DOF attitude columns (as later logs may
    have): /disturbance/estimate appears, and the orientation is the z-y-x Euler rotation
    (checked against scipy's Rotation)."""
    from scipy.spatial.transform import Rotation

    run_dir, log = _run_and_export(monkeypatch, capsys, tmp_path, "paper-ideal", "duration=2")
    rows = len(log)
    log["dist_X_hat"] = np.linspace(0, 1, rows)
    log["dist_Y_hat"] = 2.0
    log["dist_N_hat"] = -0.5
    log["z"] = -np.linspace(1, 2, rows)
    log["phi"] = 0.1
    log["theta"] = -0.2
    log.to_csv(run_dir / "log.csv", index=False, float_format="%.17g")
    out = tmp_path / "bag6"
    code, _, err = run_cli(monkeypatch, capsys, "export", str(run_dir), "--out", str(out))
    assert code == 0, err
    types, messages = _read(out)
    assert types["/disturbance/estimate"] == "geometry_msgs/msg/WrenchStamped"
    estimate = np.array(
        [
            [m.wrench.force.x, m.wrench.force.y, m.wrench.torque.z]
            for _, m in messages["/disturbance/estimate"]
        ]
    )
    np.testing.assert_allclose(
        estimate, log[["dist_X_hat", "dist_Y_hat", "dist_N_hat"]], atol=1e-12
    )
    for (_, message), (_, row) in zip(messages["/odom"], log.iterrows(), strict=True):
        q = message.pose.pose.orientation
        expected = Rotation.from_euler("ZYX", [row["psi"], row["theta"], row["phi"]]).as_quat()
        assert np.allclose([q.x, q.y, q.z, q.w], expected, atol=1e-12) or np.allclose(
            [q.x, q.y, q.z, q.w], -expected, atol=1e-12
        )
        assert message.pose.pose.position.z == pytest.approx(row["z"], abs=1e-12)
