"""`auvmpc identify` from ROS 2 bags (issue 27 item 3): a short excite -> run -> export
--format rosbag2 (MCAP) read back equals the run folder's log, a SQLite3 bag with a body
wrench in REP 103 axes (written by rosbags' own writer) reads back to the same velocities
and the allocation's force, and identify from the bag recovers the vehicle.
The resampling against analytic truth; bad bags refused in one line."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest

from auvmpc.errors import ConfigError
from auvmpc.identification.logs import MIN_SAMPLES, LogOptions, read_log, read_run_folder, resample
from auvmpc.identification.rosbag import MIRROR, BodyFrame
from auvmpc.models.vehicle import load_vehicle
from tests.conftest import ROUND_OFF_TOL, cli, odometry_rewritten
from tests.test_cli import run_cli

rosbags = pytest.importorskip("rosbags")

VEHICLE = "jmse2210"
# The exporter writes log.csv's float64 values into CDR float64 fields and stamps each row
# with round(t * 1e9) ns; on that grid the reader's interpolation returns the stored values
# exactly. 1e-12 only allows for another summation order.
BAG_VELOCITY_TOL = 1e-12


@pytest.fixture(scope="module")
def run(tmp_path_factory) -> Path:
    """excite (40 s) -> run -> export --format rosbag2, once for the module (~5 s)."""
    folder = tmp_path_factory.mktemp("bag")
    cli("excite", VEHICLE, "--out", str(folder / "excite.yaml"), "--duration", "40")
    cli("run", str(folder / "excite.yaml"), "--out", str(folder / "run"), "--no-figures")
    cli("export", str(folder / "run"), "--format", "rosbag2")
    return folder / "run"


def _rewrite_as_sqlite3_rep103(run: Path, out: Path) -> None:
    """The exporter's /odom and the sum of its per-thruster wrenches (= T F) as /wrench, in
    REP 103 body axes (y port, z up), into a SQLite3 bag, by rosbags' own reader and writer."""
    from rosbags.highlevel import AnyReader
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_JAZZY)
    flip = MIRROR[BodyFrame.FLU]
    odometry, wrenches = [], {}
    with AnyReader([run / "rosbag2"]) as reader:
        for connection, stamp, raw in reader.messages():
            topic = connection.topic
            if topic == "/odom":
                odometry.append((stamp, reader.deserialize(raw, connection.msgtype)))
            elif topic.startswith("/thrusters/"):
                message = reader.deserialize(raw, connection.msgtype)
                wrenches.setdefault(stamp, []).append(message)
    with Writer(out, version=9, storage_plugin=StoragePlugin.SQLITE3) as writer:
        odom = writer.add_connection("/odom", "nav_msgs/msg/Odometry", typestore=store)
        wrench = writer.add_connection(
            "/wrench", "geometry_msgs/msg/WrenchStamped", typestore=store
        )
        for stamp, message in odometry:
            twist = message.twist.twist
            _, twist.linear.y, twist.angular.z = flip * [0.0, twist.linear.y, twist.angular.z]
            message.pose.pose.orientation.z *= flip[2]  # level: the mirror negates the yaw
            writer.write(odom, stamp, store.serialize_cdr(message, "nav_msgs/msg/Odometry"))
        for stamp, parts in sorted(wrenches.items()):
            total = parts[0]
            body = total.wrench
            body.force.x = sum(p.wrench.force.x for p in parts)
            body.force.y = flip[1] * sum(p.wrench.force.y for p in parts)
            body.torque.z = flip[2] * sum(p.wrench.torque.z for p in parts)
            writer.write(
                wrench, stamp, store.serialize_cdr(total, "geometry_msgs/msg/WrenchStamped")
            )


def test_the_exported_bag_reads_back_as_the_run_folder(run, tmp_path):
    vehicle = load_vehicle(VEHICLE)
    folder = read_run_folder(run, vehicle.n_thrusters)
    for path in (run / "rosbag2", run / "rosbag2" / "rosbag2.mcap"):
        bag = read_log(path, vehicle.n_thrusters)
        assert bag.sample_time == pytest.approx(folder.sample_time, rel=1e-12)
        assert bag.steps == folder.steps
        np.testing.assert_allclose(bag.velocity, folder.velocity, rtol=0, atol=BAG_VELOCITY_TOL)
        np.testing.assert_array_equal(bag.thrust, folder.thrust)
        np.testing.assert_allclose(bag.heading, folder.heading, rtol=0, atol=BAG_VELOCITY_TOL)
    # SQLite3 storage, a body wrench instead of thrusts, REP 103 axes.
    sqlite = tmp_path / "rep103"
    _rewrite_as_sqlite3_rep103(run, sqlite)
    assert list(sqlite.glob("*.db3"))
    options = LogOptions(wrench_topic="/wrench", body_frame="flu")
    bag = read_log(sqlite, vehicle.n_thrusters, options)
    assert bag.thrust is None
    np.testing.assert_allclose(bag.velocity, folder.velocity, rtol=0, atol=BAG_VELOCITY_TOL)
    np.testing.assert_allclose(bag.heading, folder.heading, rtol=0, atol=BAG_VELOCITY_TOL)
    np.testing.assert_allclose(bag.force, folder.thrust @ vehicle.T.T, rtol=0, atol=1e-9)
    # Read in the wrong axes, v and r come back mirrored.
    mirrored = read_log(sqlite, vehicle.n_thrusters, LogOptions(wrench_topic="/wrench"))
    np.testing.assert_allclose(mirrored.velocity * [1, -1, -1], bag.velocity, atol=1e-15)


def test_identify_from_the_bag_recovers_the_vehicle(run, tmp_path, monkeypatch, capsys):
    """The bag's log is the run folder's bit for bit (the test above), so identify finds the
    same values from either (identification is deterministic); test_identification.py's
    round trip checks the folder, this one the bag through the CLI."""
    out = tmp_path / "vehicle.yaml"
    code, _, err = run_cli(monkeypatch, capsys, "identify", str(run / "rosbag2"), "--vehicle",
                           VEHICLE, "--out", str(out))  # fmt: skip
    assert code == 0, err
    found = json.loads((out.parent / "identification.json").read_text())
    assert found["logs"] == [str(run / "rosbag2")]
    truth = load_vehicle(VEHICLE)
    assert not found["not_excited"]
    for name, entry in found["parameters"].items():
        low, high = entry["ci95"]
        true_value = getattr(truth, name)
        assert abs(entry["value"] - true_value) <= 0.1 * abs(true_value) or (
            low <= true_value <= high
        ), name


def test_resample_holds_commands_and_interpolates_velocities():
    """Against analytic truth: velocities linear in t (linear interpolation is exact at any
    time), measured at irregular times; commands issued at irregular times and held."""
    rng = np.random.default_rng(0)
    measured_t = np.cumsum(rng.integers(30, 70, size=400)) * 1_000_000  # ns, 30..70 ms
    slope = np.array([0.1, -0.05, 0.02])
    velocity = (measured_t[:, None] / 1e9) * slope + [0.3, 0.0, -0.1]
    command_t = np.arange(measured_t[0] - 20_000_000, measured_t[-1], 100_000_000)
    command_t = command_t + rng.integers(0, 5, size=len(command_t)) * 1_000_000
    command = rng.normal(size=(len(command_t), 2))
    log = resample("synthetic", None, measured_t, velocity, command_t, command, ("v", "F"))
    grid = command_t[1] + np.round(np.arange(log.steps + 1) * log.sample_time * 1e9)
    assert log.steps >= MIN_SAMPLES
    np.testing.assert_allclose(
        log.velocity, (grid[:, None] / 1e9) * slope + [0.3, 0.0, -0.1], atol=ROUND_OFF_TOL
    )
    for k in range(log.steps):
        last = np.searchsorted(command_t, grid[k], side="right") - 1
        np.testing.assert_array_equal(log.thrust[k], command[last])


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--odometry-topic", "/nope"], "has no topic /nope (nav_msgs/msg/Odometry); its topics:"),
        (["--wrench-topic", "/thrust"], "topic /thrust is std_msgs/msg/Float64MultiArray, not"),
        (["--body-frame", "enu"], "--body-frame: one of frd, flu"),
        (["--vehicle", "videoray-pro3"], "/thrust carries 4 thrusts at t = 0 s, the start"),
        (["--sample-time", "0.5"], "(80 samples of 0.5 s), too short: need at least 100"),
    ],
)
def test_a_bad_bag_or_flag_is_refused_in_one_line(run, tmp_path, monkeypatch, capsys, args,
                                                  message):  # fmt: skip
    vehicle = [] if "--vehicle" in args else ["--vehicle", VEHICLE]
    code, _, err = run_cli(monkeypatch, capsys, "identify", str(run / "rosbag2"), *vehicle,
                           *args, "--out", str(tmp_path / "v.yaml"))  # fmt: skip
    assert code == 2, err
    assert err.count("\n") == 1 and message in err


def test_a_gap_in_the_odometry_is_refused():
    measured_t = np.concatenate([np.arange(0, 100), np.arange(120, 300)]) * 100_000_000
    command_t = np.arange(0, 300) * 100_000_000
    command = np.sin(np.arange(300))[:, None]
    with pytest.raises(Exception, match=r"/odom has a gap of 2.1 s at t = 9.9 s into the log"):
        resample("bag", None, measured_t, np.zeros((280, 3)), command_t, command,
                 ("/odom", "/thrust"))  # fmt: skip


def test_without_rosbags_the_error_names_the_extra(run, monkeypatch):
    monkeypatch.setitem(sys.modules, "rosbags.highlevel", None)
    with pytest.raises(Exception, match=r"needs the rosbags package: pip install 'auvmpc\[ros\]'"):
        read_log(run / "rosbag2", 4)


def test_an_odometry_without_orientation_is_refused_in_one_line(run, tmp_path):
    """A driver that leaves the pose's quaternion all zeros (no orientation): one line naming
    the topic and the time, not a traceback from the rotation."""

    def unset(message) -> None:
        turn = message.pose.pose.orientation
        turn.x = turn.y = turn.z = turn.w = 0.0

    out = tmp_path / "no-orientation"
    odometry_rewritten(run / "rosbag2", out, unset)
    with pytest.raises(
        ConfigError, match=r"^LOG: .*/odom has no orientation \(a zero quaternion\)"
    ):
        read_log(out, load_vehicle(VEHICLE).n_thrusters)
