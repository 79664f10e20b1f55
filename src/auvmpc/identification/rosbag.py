"""A ROS 2 bag (rosbag2: SQLite3 or MCAP storage) as a :class:`VelocityLog`, or as the 6-DOF
samples every model is identified from (``identify --dof six-dof``).

Read with the pure-Python ``rosbags`` library (``pip install 'auvmpc[ros]'``), no ROS
installation needed; the same library writes ``auvmpc export --format rosbag2``.

Topics (``auvmpc identify`` flags; the defaults are what ``auvmpc export`` writes):

- ``--odometry-topic`` (``/odom``), ``nav_msgs/msg/Odometry``: the body velocities. By the
  message's definition its twist is in ``child_frame_id``, the body: ``u = linear.x``,
  ``v = linear.y``, ``r = angular.z`` (6-DOF: also ``w``, ``p``, ``q``) up to the body
  frame's signs (below). Of the pose the 3-DOF model reads the yaw (z-y-x Euler angles of
  the orientation): the heading a constant current is estimated in (``identify
  --current``); the 6-DOF models read the whole pose, position and roll, pitch and yaw.
- ``--thrust-topic`` (``/thrust``), ``std_msgs/msg/Float64MultiArray``: every thruster's
  force (N), in the start vehicle's thruster order; or
- ``--wrench-topic``, ``geometry_msgs/msg/WrenchStamped``: the body force and moment
  (``force.x, force.y, torque.z``), used as the applied force directly (no allocation;
  3-DOF only: the 6-DOF models need each thruster's roll and pitch moments).

**Body frames.** auvmpc's body frame is x forward, y starboard, z down (Fossen;
``auvmpc.models.vehicle``): v positive to starboard, r positive turning right, and the
vehicle file's thruster positions are in it. ``auvmpc export`` writes the logged values
as they are into ``base_link`` (``export/rosbag2.py``), so its bags are read as they are:
``--body-frame frd``, the default. A vehicle that follows ROS's REP 103 has ``base_link``
x forward, y port, z up (and its odometry frame z up); ``--body-frame flu`` reads it: the
mirror y -> -y, z -> -z of both frames, which changes the sign of y and z components (v, w,
q, r, a wrench's y force and z moment, the position's y and z) and of the pitch and yaw
(:data:`MIRROR`, the one conversion, applied to all). The 3-DOF model is symmetric under
this mirror, so a wrong choice with a wrench topic still fits; with a thrust topic it does
not (the thrusters' yaw moments then oppose the measured yaw rate).

**Time.** Every message is placed at the time the bag recorded it, one clock for all
topics (a header stamp may come from another computer's clock, and Float64MultiArray has
none); ``auvmpc export`` stamps both with the simulation time. The messages are put on a
uniform grid by :func:`auvmpc.identification.logs.resample`: the commands held, the
velocities interpolated.
"""

from __future__ import annotations

from enum import StrEnum
from pathlib import Path
from typing import NamedTuple

import numpy as np

from auvmpc.errors import ConfigError
from auvmpc.identification.logs import VELOCITY_NAMES, LogOptions, VelocityLog, resample
from auvmpc.models.layout import PLANAR_FORCE, Layout
from auvmpc.models.six_dof import SIX_DOF

__all__ = [
    "MIRROR",
    "BodyFrame",
    "euler_angles",
    "read_rosbag",
    "read_six_dof_rosbag",
]

ODOMETRY = "nav_msgs/msg/Odometry"
THRUST = "std_msgs/msg/Float64MultiArray"
WRENCH = "geometry_msgs/msg/WrenchStamped"


class BodyFrame(StrEnum):
    """The body axes a bag's messages are written in."""

    FRD = "frd"  # x forward, y starboard, z down: auvmpc's own, what auvmpc export writes
    FLU = "flu"  # x forward, y port, z up: ROS REP 103's base_link


# The signs taking a vector's (x, y, z) components in a bag's axes to auvmpc's: the REP 103
# mirror y -> -y, z -> -z is the half turn about x, so it takes a position, a velocity, a
# rate and the z-y-x Euler angles (phi, theta, psi) alike (D R(phi, theta, psi) D =
# R(phi, -theta, -psi) with D = diag(1, -1, -1)).
MIRROR = {
    BodyFrame.FRD: np.array([1.0, 1.0, 1.0]),
    BodyFrame.FLU: np.array([1.0, -1.0, -1.0]),
}
# An odometry message as read: the pose's position and orientation quaternion, the twist.
_ODOMETRY_ROW = Layout(names=("x", "y", "z", "qx", "qy", "qz", "qw", "u", "v", "w", "p", "q", "r"))
_PLANAR_VELOCITY = [SIX_DOF.index(name) for name in VELOCITY_NAMES]
_HEADING = SIX_DOF.index("psi")


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


class _BagMessages(NamedTuple):
    """A bag's odometry and commands, each at the times the bag recorded them, in auvmpc's
    axes: ``odometry`` (n, 12) the SIX_DOF state (position, z-y-x Euler angles with the yaw
    unwrapped, body velocities and rates); ``command`` (m, n_thrusters) the thrusts or
    (m, 3) the planar wrench [X, Y, N]."""

    odometry_t: np.ndarray
    odometry: np.ndarray
    command_t: np.ndarray
    command: np.ndarray
    what: tuple[str, str]


def _read_bag(path: Path, n_thrusters: int, options: LogOptions) -> _BagMessages:
    """The odometry and command topics of the bag at ``path`` (module docstring). A missing
    topic, a topic of another type, a thrust message of another length: one ConfigError."""
    try:
        from rosbags.highlevel import AnyReader, AnyReaderError
        from rosbags.typesys import Stores, get_typestore
    except ImportError:
        raise ConfigError(
            "LOG", str(path), "a ROS 2 bag needs the rosbags package: pip install 'auvmpc[ros]'"
        ) from None
    mirror = MIRROR[body_frame(options.body_frame)]
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
                    pose, twist = message.pose.pose, message.twist.twist
                    turn = pose.orientation
                    value = [pose.position.x, pose.position.y, pose.position.z,
                             turn.x, turn.y, turn.z, turn.w,
                             twist.linear.x, twist.linear.y, twist.linear.z,
                             twist.angular.x, twist.angular.y, twist.angular.z]  # fmt: skip
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

    raw = column(options.odometry_topic, _ODOMETRY_ROW.size)
    position, quaternion, linear, angular = (
        raw[:, _ODOMETRY_ROW.span(first, last)]
        for first, last in (("x", "z"), ("qx", "qw"), ("u", "w"), ("p", "r"))
    )
    unset = np.flatnonzero(np.linalg.norm(quaternion, axis=1) == 0.0)
    if len(unset):
        stamp = stamps[options.odometry_topic][int(unset[0])]
        raise ConfigError(
            "LOG", name, f"{options.odometry_topic} has no orientation (a zero quaternion) at "
            f"t = {stamp / 1e9:.6g} s: identify reads the heading from it",
        )  # fmt: skip
    angles = euler_angles(quaternion) * mirror  # the mirror turns pitch and yaw over
    angles[:, 2] = np.unwrap(angles[:, 2])
    odometry = np.column_stack([position * mirror, angles, linear * mirror, angular * mirror])
    command = column(command_topic, PLANAR_FORCE.size if options.wrench_topic else n_thrusters)
    if options.wrench_topic:
        command = command * mirror  # (force.x, force.y, torque.z): a vector's (x, y, z)
    return _BagMessages(
        np.array(stamps[options.odometry_topic], dtype=np.int64),
        odometry,
        np.array(stamps[command_topic], dtype=np.int64),
        command,
        (options.odometry_topic, command_topic),
    )


def read_rosbag(path: str | Path, n_thrusters: int, options: LogOptions) -> VelocityLog:
    """The body velocities ``u, v, r``, the heading and the thrusts (or planar wrench) in the
    bag at ``path`` (module docstring), resampled onto a uniform grid; what is missing or
    wrong, or a log too short: one ConfigError line."""
    bag = _read_bag(Path(path), n_thrusters, options)
    return resample(
        str(path),
        options.sample_time,
        bag.odometry_t,
        bag.odometry[:, _PLANAR_VELOCITY],
        bag.command_t,
        bag.command,
        bag.what,
        as_force=bool(options.wrench_topic),
        heading=bag.odometry[:, _HEADING],
    )


def read_six_dof_rosbag(
    path: str | Path, n_thrusters: int, options: LogOptions
) -> tuple[str, float, np.ndarray, np.ndarray]:
    """(name, sample time, state (N+1, 12) in SIX_DOF order, thrust (N, n)) of the bag at
    ``path``: the odometry's whole pose and twist and every thruster's force, on one grid
    (identification/six_dof_log.py). A wrench topic is refused: the 6-DOF models need each
    thruster's force for the roll and pitch moments, which a planar wrench does not hold."""
    if options.wrench_topic:
        raise ConfigError(
            "--wrench-topic", options.wrench_topic, "6-DOF identification needs the thrusts "
            "(--thrust-topic): a planar wrench has no roll and pitch moments",
        )  # fmt: skip
    bag = _read_bag(Path(path), n_thrusters, options)
    log = resample(str(path), options.sample_time, bag.odometry_t, bag.odometry, bag.command_t,
                   bag.command, bag.what, outputs=SIX_DOF.names)  # fmt: skip
    return log.name, log.sample_time, log.velocity, log.thrust


def euler_angles(quaternions: np.ndarray) -> np.ndarray:
    """(n, 4) ``geometry_msgs/msg/Quaternion`` [x, y, z, w] -> (n, 3) z-y-x Euler angles
    [phi, theta, psi] (rad; Fossen 2021, eq. 2.18), the inverse of ``auvmpc export``'s
    ``_quaternion``."""
    from scipy.spatial.transform import Rotation

    return Rotation.from_quat(quaternions).as_euler("ZYX")[:, ::-1]
