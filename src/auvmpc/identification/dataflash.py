"""An ArduSub DataFlash log (``.bin``, or its text form ``.log``) as a :class:`VelocityLog`.

Read with pymavlink's DFReader (``pip install 'auvmpc[ardupilot]'``), the reader ArduPilot's
own tools (MAVExplorer, mavlogdump) use. A DataFlash file describes its own messages: FMT
messages give each message type's name, binary layout and column names, the others follow.

What is read (ArduPilot's log message reference; frames NED world, FRD body, as auvmpc's):

- ``ATT``: ``Roll``, ``Pitch``, ``Yaw`` (degrees): the attitude, to rotate the velocity;
  the yaw is also the heading a constant current is estimated in (``identify --current``).
- ``XKF1`` (EKF3; ``NKF1``, EKF2, when there is no XKF1): ``VN``, ``VE``, ``VD`` (m/s), the
  EKF's velocity in the NED world, of its first core (``C`` = 0). The body velocity is
  ``R(phi, theta, psi)' [VN, VE, VD]`` (Fossen 2021, eq. 2.18, :func:`auvmpc.models.six_dof.Rzyx`)
  with the attitude interpolated to the EKF's times; ``u, v`` are its first two rows.
- ``IMU`` (first instance): ``GyrZ`` (rad/s), the body yaw rate r. A log without IMU gets
  r from the time derivative of the unwrapped ATT yaw (central differences), which equals
  r for a vehicle that stays level (Fossen 2021, eq. 2.28 with phi = theta = 0).
- ``RCOU``: ``C1..C14``, the PWM (us) each ESC was sent. ``--channels`` lists the channels of
  the start vehicle's thrusters in its order (default 1..n: ArduSub's motors 1..4 are the
  BlueROV2's horizontal ones); ``--reversed`` the channels whose thrust points against the
  vehicle file's thruster direction (a reversed propeller, ``MOT_n_DIRECTION = -1``). The
  force is the ``--thruster-curve`` at that PWM (:mod:`~auvmpc.identification.thruster_curve`:
  the Blue Robotics T200 at 16 V by default).

The messages are put on a uniform grid by :func:`auvmpc.identification.logs.resample` (the
RCOU commands held, the velocities interpolated); Te defaults to RCOU's median interval.
"""

from __future__ import annotations

from pathlib import Path

import casadi as ca
import numpy as np

from auvmpc.errors import ConfigError
from auvmpc.identification.logs import LogOptions, VelocityLog, resample
from auvmpc.identification.thruster_curve import thruster_curve
from auvmpc.models.layout import WORLD_VECTOR
from auvmpc.models.six_dof import BODY_VELOCITY, Rzyx

__all__ = ["body_velocity", "read_dataflash"]

MESSAGES = ("ATT", "XKF1", "NKF1", "IMU", "RCOU")
RCOU_CHANNELS = 14


def body_velocity(roll, pitch, yaw, ned: np.ndarray) -> np.ndarray:
    """R(phi, theta, psi)' v for each sample: (n,) angles (rad), world velocities ``ned`` (n, 3)
    -> body [u, v, w] (n, 3)."""
    phi, theta, psi = ca.SX.sym("phi"), ca.SX.sym("theta"), ca.SX.sym("psi")
    v = ca.SX.sym("v", WORLD_VECTOR.size)
    rotate = ca.Function("body", [phi, theta, psi, v], [Rzyx(phi, theta, psi).T @ v])
    n = len(ned)
    out = rotate.map(n)(np.asarray(roll)[None, :], np.asarray(pitch)[None, :],
                        np.asarray(yaw)[None, :], np.asarray(ned).T)  # fmt: skip
    return np.asarray(out).T


def _open(path: Path):
    try:
        from pymavlink import DFReader
    except ImportError:
        raise ConfigError(
            "LOG",
            str(path),
            "an ArduSub DataFlash log needs pymavlink: pip install 'auvmpc[ardupilot]'",
        ) from None
    try:
        if path.suffix.lower() == ".log":
            return DFReader.DFReader_text(str(path))
        return DFReader.DFReader_binary(str(path))
    except Exception as error:  # DFReader raises whatever its parse hits first
        raise ConfigError("LOG", str(path), f"is not a readable DataFlash log: {error}") from None


def _messages(path: Path) -> dict[str, list[dict]]:
    """Each wanted message type's messages as dicts, in log order."""
    reader = _open(path)
    found: dict[str, list[dict]] = {name: [] for name in MESSAGES}
    try:
        while (message := reader.recv_match(type=list(MESSAGES))) is not None:
            kind = message.get_type()
            if kind in found:
                found[kind].append(message.to_dict())
    except Exception as error:  # a cut or corrupt file
        raise ConfigError("LOG", str(path), f"is not a readable DataFlash log: {error}") from None
    return found


def _first_instance(messages: list[dict], key: str) -> list[dict]:
    """The messages of the first core / sensor (``key`` = 0), or all where there is no key."""
    return [m for m in messages if m.get(key, 0) == 0]


def _columns(name: str, messages: list[dict], fields: tuple[str, ...], path: Path):
    missing = [f for f in ("TimeUS", *fields) if messages and f not in messages[0]]
    if missing:
        raise ConfigError("LOG", str(path), f"{name} has no field {', '.join(missing)}")
    stamps = np.array([m["TimeUS"] for m in messages], dtype=np.int64) * 1000  # ns
    return stamps, np.array([[float(m[f]) for f in fields] for m in messages])


def read_dataflash(path: str | Path, n_thrusters: int, options: LogOptions) -> VelocityLog:
    """The body velocities and thrusts in an ArduSub DataFlash log (module docstring),
    resampled onto a uniform grid. A missing message type, field or channel, or a log too
    short: one ConfigError line."""
    path = Path(path)
    curve = thruster_curve(options.thruster_curve)
    channels = options.channels or tuple(range(1, n_thrusters + 1))
    if len(channels) != n_thrusters:
        raise ConfigError(
            "--channels", ",".join(map(str, channels)),
            f"lists {len(channels)} channels, the start vehicle has {n_thrusters} thrusters",
        )  # fmt: skip
    for flag, listed in (("--channels", channels), ("--reversed", options.reversed_channels)):
        for channel in listed:
            if not 1 <= channel <= RCOU_CHANNELS:
                raise ConfigError(flag, channel, f"RCOU channels are 1..{RCOU_CHANNELS}")
    found = _messages(path)
    ekf = "XKF1" if found["XKF1"] else "NKF1"
    for name, messages in (("ATT", found["ATT"]), ("XKF1 or NKF1", found[ekf]),
                           ("RCOU", found["RCOU"])):  # fmt: skip
        if not messages:
            raise ConfigError(
                "LOG", str(path), f"has no {name} messages (need ATT, XKF1 or NKF1, RCOU)"
            )
    att_t, attitude = _columns("ATT", found["ATT"], ("Roll", "Pitch", "Yaw"), path)
    ekf_t, ned = _columns(ekf, _first_instance(found[ekf], "C"), ("VN", "VE", "VD"), path)
    names = tuple(f"C{c}" for c in channels)
    rc_t, pwm = _columns("RCOU", found["RCOU"], names, path)

    roll, pitch, yaw = np.radians(attitude).T
    yaw = np.unwrap(yaw)
    # The attitude at the velocities' times.
    roll_v, pitch_v, yaw_v = (np.interp(ekf_t, att_t, angle) for angle in (roll, pitch, yaw))
    uv = body_velocity(roll_v, pitch_v, yaw_v, ned)[:, BODY_VELOCITY.span("u", "v")]
    imu = _first_instance(found["IMU"], "I")
    if imu:
        rate_t, gyro = _columns("IMU", imu, ("GyrZ",), path)
        rate = gyro[:, 0]
    else:
        rate_t, rate = att_t, np.gradient(yaw, att_t / 1e9)
    r = np.interp(ekf_t, rate_t, rate)

    thrust = np.column_stack([curve.force(column) for column in pwm.T])
    reversed_ = np.array([c in options.reversed_channels for c in channels])
    thrust[:, reversed_] *= -1.0
    return resample(
        str(path),
        options.sample_time,
        ekf_t,
        np.column_stack([uv, r]),
        rc_t,
        thrust,
        (f"{ekf} velocity", "RCOU"),
        heading=yaw_v,
    )
