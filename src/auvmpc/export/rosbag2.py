"""A run folder as a ROS 2 bag (rosbag2: metadata.yaml + MCAP, CDR-encoded messages).

Written with the pure-Python ``rosbags`` library (``pip install 'auvmpc[ros]'``); no ROS
installation is needed to write or read it. The messages are Jazzy's definitions and the
metadata is rosbag2 version 9 (what ``ros2 bag`` on Jazzy writes); the MCAP file carries
every message definition, so Foxglove and PlotJuggler open it without ROS at all.

Frames: ``world`` is the plane auvmpc plots (x right, y up, heading psi counter-clockwise
from +x; z up in depth runs), ``base_link`` is the vehicle body (x forward, the thrusters'
y). The planar equations of ``auvmpc.models.vehicle`` read the same in a z-up or a NED world, so
positions, heading and velocities are written exactly as logged. Stamps are the
simulation time (t = 0 is the start, 1970-01-01 in tools that show dates).

Columns are read from ``log.csv`` by name, so horizontal, depth and future 6-DOF logs all
export: missing pose or velocity components are 0.
"""

from __future__ import annotations

import math
import os
import shutil
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from pydantic import ValidationError

from auvmpc.errors import ConfigError
from auvmpc.experiments.outputs import new_entry
from auvmpc.experiments.run_folder import RunTables, read_run_tables
from auvmpc.models.actuators import WRENCH
from auvmpc.models.vehicle import VehicleParams

__all__ = ["TOPICS", "export_rosbag2"]

_FORCE, _MOMENT = WRENCH.span("X", "Z"), WRENCH.span("K", "N")

WORLD_FRAME = "world"
BODY_FRAME = "base_link"
METADATA_VERSION = 9

# topic -> (message type, what it carries). Thruster topics are /thrusters/<column>.
TOPICS: dict[str, tuple[str, str]] = {
    "/odom": ("nav_msgs/msg/Odometry", "true vehicle state, one per log row"),
    "/reference/odom": ("nav_msgs/msg/Odometry", "reference state, one per log row"),
    "/reference/path": ("nav_msgs/msg/Path", "the whole reference path, once at t = 0"),
    "/reference/horizon": (
        "nav_msgs/msg/Path",
        "the reference over the controller's prediction horizon from each log row",
    ),
    "/thrust": (
        "std_msgs/msg/Float64MultiArray",
        "every thruster's force (N), one per applied command (rows 0..N-1)",
    ),
    "/thrusters/<name>": (
        "geometry_msgs/msg/WrenchStamped",
        "one thruster's force and moment on the body, one per applied command",
    ),
    "/disturbance/true": (
        "geometry_msgs/msg/WrenchStamped",
        "the simulated current / wave force in the world frame, one per log row",
    ),
    "/disturbance/estimate": (
        "geometry_msgs/msg/WrenchStamped",
        "the controller's estimate, when the log has dist_X_hat, dist_Y_hat, dist_N_hat",
    ),
    "/obstacles": (
        "visualization_msgs/msg/MarkerArray",
        "obstacle cylinders where they are at each log row (DELETE while absent)",
    ),
}

_OBSTACLE_HEIGHT_M = 1.0
# Written once: offered as transient-local, so that a subscriber started during
# `ros2 bag play` still receives it (as a latched topic in ROS 1).
_LATCHED = frozenset({"/reference/path"})


def export_rosbag2(run_dir: Path, out: Path | None = None) -> Path:
    """Write the run in ``run_dir`` as a rosbag2 folder (MCAP storage) at ``out``.

    Parameters
    ----------
    run_dir : Path
        A folder written by ``auvmpc run`` (or ``run --from-campaign``).
    out : Path, optional
        The bag folder to create; default ``run_dir/rosbag2``. It must not exist. Inside
        a folder auvmpc wrote it is listed in that folder's marker
        (:mod:`auvmpc.experiments.outputs`).

    Returns
    -------
    Path
        The bag folder (``metadata.yaml`` and one ``.mcap`` file).

    Raises
    ------
    ConfigError
        If ``run_dir`` is not a run folder, ``out`` exists, or ``rosbags`` is missing.
    """
    try:
        import rosbags  # noqa: F401  (checked first: the one line names the extra to install)
    except ImportError:
        raise ConfigError(
            "--format", "rosbag2", "needs the rosbags package: pip install 'auvmpc[ros]'"
        ) from None
    tables = read_run_tables(run_dir)
    out = Path(out) if out is not None else Path(run_dir) / "rosbag2"
    if out.exists() or out.is_symlink():  # a bag is written once, never over another
        raise ConfigError("--out", str(out), "exists; remove it or choose another folder")
    with new_entry(out, "--out") as target:
        _write_bag(tables, target)
    return out


def _write_bag(tables: RunTables, out: Path) -> None:
    """The bag, staged in a hidden sibling folder and renamed onto ``out`` when complete."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_JAZZY)
    staging = Path(tempfile.mkdtemp(prefix=f".{out.name}.", suffix=".partial", dir=out.parent))
    bag = staging / out.name  # rosbags names the .mcap after the folder
    try:
        messages = _Messages(store)
        with Writer(bag, version=METADATA_VERSION, storage_plugin=StoragePlugin.MCAP) as writer:
            connections: dict[str, Any] = {}
            for topic, msgtype, stamp_ns, message in _messages(tables, messages):
                if topic not in connections:
                    qos = (_latched(),) if topic in _LATCHED else ()
                    connections[topic] = writer.add_connection(
                        topic, msgtype, typestore=store, offered_qos_profiles=qos
                    )
                writer.write(connections[topic], stamp_ns, store.serialize_cdr(message, msgtype))
        os.replace(bag, out)
    finally:
        shutil.rmtree(staging, ignore_errors=True)


# --- messages ---------------------------------------------------------------------------------


def _messages(tables: RunTables, m: _Messages) -> Iterator[tuple[str, str, int, Any]]:
    """(topic, type, stamp in ns, message) in time order."""
    log = tables.log
    scenario = tables.info.get("scenario", {})
    obstacles = scenario.get("obstacles") or []
    thrusters = _thruster_geometry(tables)
    has_reference = any(f"{name}_ref" in log.columns for name in ("x", "y", "z"))
    has_estimate = all(f"dist_{a}_hat" in log.columns for a in "XYN")
    thrust_columns = tables.thrust_columns
    odometry = TOPICS["/odom"][0]
    wrench = TOPICS["/thrusters/<name>"][0]

    path_type = TOPICS["/reference/path"][0]
    horizon = int((scenario.get("controller") or {}).get("prediction_horizon") or 0)
    poses = m.reference_poses(log) if has_reference else []
    if has_reference:
        yield "/reference/path", path_type, 0, m.path(poses, 0.0)
    for k, (_, row) in enumerate(log.iterrows()):
        t = float(row["t"])
        ns = _nanoseconds(t)
        yield "/odom", odometry, ns, m.odometry(row, t, "")
        if has_reference:
            yield "/reference/odom", odometry, ns, m.odometry(row, t, "_ref")
            yield "/reference/horizon", path_type, ns, m.path(poses[k : k + horizon + 1], t)
        if thrust_columns and row[thrust_columns].notna().all():
            forces = row[thrust_columns].to_numpy(dtype=float)
            yield "/thrust", TOPICS["/thrust"][0], ns, m.float_array(forces, thrust_columns)
            for name, force in zip(thrust_columns, forces, strict=True):
                vector, moment = thrusters.get(name, ((0.0, 0.0, 1.0), (0.0, 0.0, 0.0)))
                message = m.wrench(
                    t, BODY_FRAME, [force * c for c in vector], [force * c for c in moment]
                )
                yield f"/thrusters/{name}", wrench, ns, message
        disturbance = _disturbance(row, "")
        if disturbance is not None:
            yield "/disturbance/true", wrench, ns, m.wrench(t, WORLD_FRAME, *disturbance)
        if has_estimate and row[[f"dist_{a}_hat" for a in "XYN"]].notna().all():
            # Like the commands: what the controller assumed over [t_k, t_k+1), none on the
            # last row.
            estimate = _disturbance(row, "_hat")
            yield "/disturbance/estimate", wrench, ns, m.wrench(t, WORLD_FRAME, *estimate)
        if obstacles:
            yield "/obstacles", TOPICS["/obstacles"][0], ns, m.obstacles(obstacles, t)


def _latched():
    from rosbags.interfaces import (
        Qos,
        QosDurability,
        QosHistory,
        QosLiveliness,
        QosReliability,
        QosTime,
    )

    never = QosTime(sec=0, nsec=0)
    return Qos(
        history=QosHistory.KEEP_LAST,
        depth=1,
        reliability=QosReliability.RELIABLE,
        durability=QosDurability.TRANSIENT_LOCAL,
        deadline=never,
        lifespan=never,
        liveliness=QosLiveliness.AUTOMATIC,
        liveliness_lease_duration=never,
        avoid_ros_namespace_conventions=False,
    )


def _nanoseconds(t: float) -> int:
    return round(t * 1e9)


def _disturbance(row: pd.Series, suffix: str) -> tuple[list[float], list[float]] | None:
    """World force [X, Y, Z] and moment [0, 0, N] from the dist_* (and wave) columns."""
    names = [f"dist_X{suffix}", f"dist_Y{suffix}", f"dist_N{suffix}"]
    if suffix == "" and "wave_force_N" in row.index and names[0] not in row.index:
        return [0.0, 0.0, float(row["wave_force_N"])], [0.0, 0.0, 0.0]
    if not all(name in row.index for name in names):
        return None
    x, y, n = (float(row[name]) for name in names)
    return [x, y, 0.0], [0.0, 0.0, n]


def _thruster_geometry(tables: RunTables) -> dict[str, tuple[tuple[float, ...], tuple[float, ...]]]:
    """Per horizontal thruster column: the force and the moment one newton makes in the body
    frame (its wrench, models/actuators); none where run.json holds no valid plant."""
    try:
        plant = VehicleParams.model_validate(tables.info.get("plant"))
    except ValidationError:
        return {}
    return {
        actuator.name: (tuple(actuator.column[_FORCE]), tuple(actuator.column[_MOMENT]))
        for actuator in plant.actuators.actuators
    }


def _value(row: pd.Series, name: str) -> float:
    return float(row[name]) if name in row.index and pd.notna(row[name]) else 0.0


def _quaternion(roll: float, pitch: float, yaw: float) -> tuple[float, float, float, float]:
    """(x, y, z, w) of the z-y-x (yaw, pitch, roll) Euler angles (Fossen 2021, eq. 2.74)."""
    cr, sr = math.cos(roll / 2), math.sin(roll / 2)
    cp, sp = math.cos(pitch / 2), math.sin(pitch / 2)
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    return (
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
        cr * cp * cy + sr * sp * sy,
    )


class _Messages:
    """Builders of the ROS 2 messages from one typestore."""

    def __init__(self, store) -> None:
        self.types = store.types

    def _type(self, name: str):
        return self.types[name]

    def header(self, t: float, frame: str):
        ns = _nanoseconds(t)
        stamp = self._type("builtin_interfaces/msg/Time")(sec=ns // 10**9, nanosec=ns % 10**9)
        return self._type("std_msgs/msg/Header")(stamp=stamp, frame_id=frame)

    def vector(self, values) -> Any:
        x, y, z = (float(v) for v in values)
        return self._type("geometry_msgs/msg/Vector3")(x=x, y=y, z=z)

    def pose(self, row: pd.Series, suffix: str):
        position = self._type("geometry_msgs/msg/Point")(
            x=_value(row, f"x{suffix}"), y=_value(row, f"y{suffix}"), z=_value(row, f"z{suffix}")
        )
        qx, qy, qz, qw = _quaternion(
            _value(row, f"phi{suffix}"), _value(row, f"theta{suffix}"), _value(row, f"psi{suffix}")
        )
        orientation = self._type("geometry_msgs/msg/Quaternion")(x=qx, y=qy, z=qz, w=qw)
        return self._type("geometry_msgs/msg/Pose")(position=position, orientation=orientation)

    def odometry(self, row: pd.Series, t: float, suffix: str):
        pose = self._type("geometry_msgs/msg/PoseWithCovariance")(
            pose=self.pose(row, suffix), covariance=np.zeros(36)
        )
        twist = self._type("geometry_msgs/msg/Twist")(
            linear=self.vector([_value(row, f"{n}{suffix}") for n in ("u", "v", "w")]),
            angular=self.vector([_value(row, f"{n}{suffix}") for n in ("p", "q", "r")]),
        )
        return self._type("nav_msgs/msg/Odometry")(
            header=self.header(t, WORLD_FRAME),
            child_frame_id=BODY_FRAME if not suffix else f"{BODY_FRAME}{suffix}",
            pose=pose,
            twist=self._type("geometry_msgs/msg/TwistWithCovariance")(
                twist=twist, covariance=np.zeros(36)
            ),
        )

    def reference_poses(self, log: pd.DataFrame) -> list:
        """The reference at every log row as stamped poses."""
        stamped = self._type("geometry_msgs/msg/PoseStamped")
        return [
            stamped(header=self.header(float(row["t"]), WORLD_FRAME), pose=self.pose(row, "_ref"))
            for _, row in log.iterrows()
        ]

    def path(self, poses: list, t: float):
        return self._type("nav_msgs/msg/Path")(header=self.header(t, WORLD_FRAME), poses=poses)

    def float_array(self, values: np.ndarray, labels: list[str]):
        dimension = self._type("std_msgs/msg/MultiArrayDimension")(
            label="thruster:" + ",".join(labels), size=len(values), stride=len(values)
        )
        layout = self._type("std_msgs/msg/MultiArrayLayout")(dim=[dimension], data_offset=0)
        return self._type("std_msgs/msg/Float64MultiArray")(
            layout=layout, data=np.asarray(values, dtype=np.float64)
        )

    def wrench(self, t: float, frame: str, force, torque):
        return self._type("geometry_msgs/msg/WrenchStamped")(
            header=self.header(t, frame),
            wrench=self._type("geometry_msgs/msg/Wrench")(
                force=self.vector(force), torque=self.vector(torque)
            ),
        )

    def obstacles(self, obstacles: list[dict[str, Any]], t: float):
        marker_type = self._type("visualization_msgs/msg/Marker")
        markers = []
        for i, obstacle in enumerate(obstacles):
            appear = obstacle.get("appear_time", 0.0)
            vanish = obstacle.get("vanish_time")
            exists = appear <= t and (vanish is None or t < vanish)
            velocity = obstacle.get("velocity", (0.0, 0.0))
            x, y = (c + v * t for c, v in zip(obstacle["center"], velocity, strict=True))
            diameter = 2.0 * obstacle["radius"]
            markers.append(
                self._marker(
                    marker_type,
                    t,
                    i,
                    action=marker_type.ADD if exists else marker_type.DELETE,
                    position=(x, y),
                    scale=(diameter, diameter, _OBSTACLE_HEIGHT_M),
                )
            )
        return self._type("visualization_msgs/msg/MarkerArray")(markers=markers)

    def _marker(self, marker_type, t, marker_id, action, position, scale):
        t_ = self._type
        return marker_type(
            header=self.header(t, WORLD_FRAME),
            ns="obstacles",
            id=marker_id,
            type=marker_type.CYLINDER,
            action=action,
            pose=t_("geometry_msgs/msg/Pose")(
                position=t_("geometry_msgs/msg/Point")(x=position[0], y=position[1], z=0.0),
                orientation=t_("geometry_msgs/msg/Quaternion")(x=0.0, y=0.0, z=0.0, w=1.0),
            ),
            scale=self.vector(scale),
            color=t_("std_msgs/msg/ColorRGBA")(r=1.0, g=0.5, b=0.05, a=0.6),
            lifetime=t_("builtin_interfaces/msg/Duration")(sec=0, nanosec=0),
            frame_locked=False,
            points=[],
            colors=[],
            texture_resource="",
            texture=t_("sensor_msgs/msg/CompressedImage")(
                header=self.header(t, ""), format="", data=np.zeros(0, dtype=np.uint8)
            ),
            uv_coordinates=[],
            text="",
            mesh_resource="",
            mesh_file=t_("visualization_msgs/msg/MeshFile")(
                filename="", data=np.zeros(0, dtype=np.uint8)
            ),
            mesh_use_embedded_materials=False,
        )
