"""A ROS 2 bag (rosbag2: SQLite3 or MCAP storage) as a :class:`VelocityLog`.

Read with the pure-Python ``rosbags`` library (``pip install 'auvmpc[ros]'``), no ROS
installation needed; the same library writes ``auvmpc export --format rosbag2``.

Topics (``auvmpc identify`` flags; the defaults are what ``auvmpc export`` writes):

- ``--odometry-topic`` (``/odom``), ``nav_msgs/msg/Odometry``: the body velocities. By the
  message's definition its twist is in ``child_frame_id``, the body: ``u = linear.x``,
  ``v = linear.y``, ``r = angular.z`` up to the body frame's signs (below). Of the pose only
  the yaw is read (z-y-x Euler angles of the orientation, with r's sign): the heading a
  constant current is estimated in (``identify --current``).
- ``--thrust-topic`` (``/thrust``), ``std_msgs/msg/Float64MultiArray``: every thruster's
  force (N), in the start vehicle's thruster order; or
- ``--wrench-topic``, ``geometry_msgs/msg/WrenchStamped``: the body force and moment
  (``force.x, force.y, torque.z``), used as the applied force directly (no allocation).

**Body frames.** auvmpc's body frame is x forward, y starboard, z down (Fossen;
``auvmpc.models.vehicle``): v positive to starboard, r positive turning right, and the
vehicle file's thruster positions are in it. ``auvmpc export`` writes the logged values
as they are into ``base_link`` (``export/rosbag2.py``), so its bags are read as they are:
``--body-frame frd``, the default. A vehicle that follows ROS's REP 103 has ``base_link``
x forward, y port, z up; ``--body-frame flu`` reads it: the mirror y -> -y, z -> -z, which
changes the sign of v and r and of a wrench's y force and z moment (:data:`PLANAR_SIGNS`,
the one conversion, applied to both). The 3-DOF model is symmetric under this mirror, so
a wrong choice with a wrench topic still fits; with a thrust topic it does not (the
thrusters' yaw moments then oppose the measured yaw rate).

**Time.** Every message is placed at the time the bag recorded it, one clock for all
topics (a header stamp may come from another computer's clock, and Float64MultiArray has
none); ``auvmpc export`` stamps both with the simulation time. The messages are put on a
uniform grid by :func:`auvmpc.identification.logs.resample`: the commands held, the
velocities interpolated.
"""

from __future__ import annotations

import math
from enum import StrEnum
from pathlib import Path

import numpy as np

from auvmpc.errors import ConfigError
from auvmpc.identification.logs import LogOptions, VelocityLog, resample
from auvmpc.models.layout import HORIZONTAL_VELOCITY, PLANAR_FORCE

__all__ = ["PLANAR_SIGNS", "BodyFrame", "read_rosbag"]

ODOMETRY = "nav_msgs/msg/Odometry"
THRUST = "std_msgs/msg/Float64MultiArray"
WRENCH = "geometry_msgs/msg/WrenchStamped"


class BodyFrame(StrEnum):
    """The body axes a bag's messages are written in."""

    FRD = "frd"  # x forward, y starboard, z down: auvmpc's own, what auvmpc export writes
    FLU = "flu"  # x forward, y port, z up: ROS REP 103's base_link


# The signs taking (x, y, yaw) components in a bag's body frame to auvmpc's: of a twist
# (linear.x, linear.y, angular.z) and of a wrench (force.x, force.y, torque.z) alike.
PLANAR_SIGNS = {
    BodyFrame.FRD: np.array([1.0, 1.0, 1.0]),
    BodyFrame.FLU: np.array([1.0, -1.0, -1.0]),
}


def body_frame(value: str) -> BodyFrame:
    try:
        return BodyFrame(value)
    except ValueError:
        raise ConfigError(
            "--body-frame", value, f"one of {', '.join(f.value for f in BodyFrame)}"
        ) from None


def _bag_folder(path: Path) -> Path:
    """The rosbag2 folder: ``path`` itself, or the folder of its .mcap / .db3 file."""
    folder = path if path.is_dir() else path.parent
    if not (folder / "metadata.yaml").is_file():
        raise ConfigError(
            "LOG",
            str(path),
            "has no metadata.yaml beside it: give the rosbag2 folder (`ros2 bag reindex` "
            "writes a missing metadata.yaml)",
        )
    return folder


def read_rosbag(path: str | Path, n_thrusters: int, options: LogOptions) -> VelocityLog:
    """The body velocities and the thrusts (or body wrench) in the bag at ``path`` (module
    docstring), resampled onto a uniform grid. A missing topic, a topic of another type,
    a thrust message of another length, or a log too short: one ConfigError line."""
    try:
        from rosbags.highlevel import AnyReader, AnyReaderError
        from rosbags.typesys import Stores, get_typestore
    except ImportError:
        raise ConfigError(
            "LOG", str(path), "a ROS 2 bag needs the rosbags package: pip install 'auvmpc[ros]'"
        ) from None
    frame = body_frame(options.body_frame)
    signs = PLANAR_SIGNS[frame]
    name = str(path)
    folder = _bag_folder(Path(path))
    command_topic = options.wrench_topic or options.thrust_topic
    command_type = WRENCH if options.wrench_topic else THRUST
    wanted = {options.odometry_topic: ODOMETRY, command_topic: command_type}
    try:
        with AnyReader([folder], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as reader:
            connections = []
            for topic, msgtype in wanted.items():
                found = [c for c in reader.connections if c.topic == topic]
                if not found:
                    topics = sorted({c.topic for c in reader.connections})
                    raise ConfigError(
                        "LOG",
                        name,
                        f"has no topic {topic} ({msgtype}); its topics: {', '.join(topics)}",
                    )
                wrong = [c.msgtype for c in found if c.msgtype != msgtype]
                if wrong:
                    raise ConfigError("LOG", name, f"topic {topic} is {wrong[0]}, not {msgtype}")
                connections += found
            stamps: dict[str, list[int]] = {topic: [] for topic in wanted}
            values: dict[str, list[np.ndarray]] = {topic: [] for topic in wanted}
            body = ""
            wrench_frame = ""
            for connection, stamp, raw in reader.messages(connections=connections):
                message = reader.deserialize(raw, connection.msgtype)
                topic = connection.topic
                if topic == options.odometry_topic:
                    twist = message.twist.twist
                    value = [twist.linear.x, twist.linear.y, twist.angular.z,
                             yaw_of(message.pose.pose.orientation)]  # fmt: skip
                    body = body or message.child_frame_id
                elif options.wrench_topic:
                    wrench = message.wrench
                    value = [wrench.force.x, wrench.force.y, wrench.torque.z]
                    wrench_frame = wrench_frame or message.header.frame_id
                else:
                    value = np.asarray(message.data, dtype=float)
                    if len(value) != n_thrusters:
                        raise ConfigError(
                            "LOG",
                            name,
                            f"{topic} carries {len(value)} thrusts at t = {stamp / 1e9:.6g} s, "
                            f"the start vehicle has {n_thrusters} thrusters",
                        )
                stamps[topic].append(stamp)
                values[topic].append(np.asarray(value, dtype=float))
    except AnyReaderError as error:
        raise ConfigError("LOG", name, f"is not a readable ROS 2 bag: {error}") from None
    if options.wrench_topic and body and wrench_frame and wrench_frame != body:
        raise ConfigError(
            "LOG",
            name,
            f"{command_topic} is in frame {wrench_frame!r}, not the body {body!r} of "
            f"{options.odometry_topic}: identify needs the body wrench",
        )

    def column(topic: str, width: int) -> np.ndarray:
        return np.array(values[topic]).reshape(-1, width)

    # An odometry row: the velocities [u, v, r], then the heading psi.
    heading_column = HORIZONTAL_VELOCITY.size
    odometry = column(options.odometry_topic, heading_column + 1)
    velocity = odometry[:, :heading_column] * signs
    command = column(command_topic, PLANAR_FORCE.size if options.wrench_topic else n_thrusters)
    if options.wrench_topic:
        command = command * signs
    return resample(
        name,
        options.sample_time,
        np.array(stamps[options.odometry_topic], dtype=np.int64),
        velocity,
        np.array(stamps[command_topic], dtype=np.int64),
        command,
        (options.odometry_topic, command_topic),
        as_force=bool(options.wrench_topic),
        # the yaw turns as r does
        heading=odometry[:, heading_column] * signs[HORIZONTAL_VELOCITY.index("r")],
    )


def yaw_of(orientation) -> float:
    """The yaw (rad) of a ``geometry_msgs/msg/Quaternion``: the z-y-x Euler angle psi, the
    inverse of ``auvmpc export``'s ``_quaternion`` for it."""
    x, y, z, w = orientation.x, orientation.y, orientation.z, orientation.w
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
