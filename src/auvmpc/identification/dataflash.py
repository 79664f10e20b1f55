"""An ArduSub DataFlash log (``.bin``, or its text form ``.log``) as a :class:`VelocityLog`, or
as the 6-DOF samples every model is identified from (``identify --dof six-dof``).

Read with pymavlink's DFReader (``pip install 'auvmpc[ardupilot]'``), the reader ArduPilot's
own tools (MAVExplorer, mavlogdump) use. A DataFlash file describes its own messages: FMT
messages give each message type's name, binary layout and column names, the others follow.

What is read (ArduPilot's log message reference; frames NED world, FRD body, as auvmpc's):

- ``ATT``: ``Roll``, ``Pitch``, ``Yaw`` (degrees): the attitude, to rotate the velocity;
  the yaw is also the heading a constant current is estimated in (``identify --current``).
- ``XKF1`` (EKF3; ``NKF1``, EKF2, when there is no XKF1): ``VN``, ``VE``, ``VD`` (m/s), the
  EKF's velocity in the NED world, of its first core (``C`` = 0). The body velocity is
  ``R(phi, theta, psi)' [VN, VE, VD]`` (Fossen 2021, eq. 2.18, :func:`auvmpc.models.six_dof.Rzyx`)
  with the attitude interpolated to the EKF's times; ``u, v`` are its first two rows (6-DOF:
  all three, and the EKF's position ``PN``, ``PE``, ``PD``).
- ``IMU`` (first instance): ``GyrZ`` (rad/s), the body yaw rate r. A log without IMU gets
  r from the time derivative of the unwrapped ATT yaw (central differences), which equals
  r for a vehicle that stays level (Fossen 2021, eq. 2.28 with phi = theta = 0). 6-DOF
  identification needs IMU: ``GyrX``, ``GyrY``, ``GyrZ`` are p, q, r.
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
from typing import NamedTuple

import casadi as ca
import numpy as np

from auvmpc.errors import ConfigError
from auvmpc.identification.logs import LogOptions, VelocityLog, resample
from auvmpc.identification.thruster_curve import thruster_curve
from auvmpc.models.layout import WORLD_VECTOR
from auvmpc.models.six_dof import BODY_VELOCITY, SIX_DOF, Rzyx

__all__ = ["body_velocity", "read_dataflash", "read_six_dof_dataflash"]

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


class _Flight(NamedTuple):
    """A DataFlash log's signals, each at its own times (ns): ATT's attitude (rad, yaw
    unwrapped) and the same at the EKF's times, the EKF's NED velocity, and each thruster's
    force at RCOU's times; the messages, for what only some models read."""

    ekf: str  # the EKF's message: XKF1 or NKF1
    att_t: np.ndarray
    angles: np.ndarray  # (n_att, 3)
    ekf_t: np.ndarray
    attitude: np.ndarray  # (n_ekf, 3): the angles at the EKF's times
    ned_velocity: np.ndarray  # (n_ekf, 3)
    messages: dict[str, list[dict]]
    rc_t: np.ndarray
    thrust: np.ndarray


def _read_flight(path: Path, n_thrusters: int, options: LogOptions) -> _Flight:
    """Every signal identification reads from the log at ``path`` (module docstring); a
    missing message type, field or channel: one ConfigError line."""
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
    angles = np.radians(attitude)
    angles[:, 2] = np.unwrap(angles[:, 2])
    at_ekf = np.column_stack([np.interp(ekf_t, att_t, a) for a in angles.T])
    thrust = np.column_stack([curve.force(column) for column in pwm.T])
    reversed_ = np.array([c in options.reversed_channels for c in channels])
    thrust[:, reversed_] *= -1.0
    return _Flight(ekf, att_t, angles, ekf_t, at_ekf, ned, found, rc_t, thrust)


def _body_rates(flight: _Flight, path: Path, fields: tuple[str, ...]) -> np.ndarray | None:
    """IMU's ``fields`` (body rates, rad/s) at the EKF's times; None without IMU messages."""
    imu = _first_instance(flight.messages["IMU"], "I")
    if not imu:
        return None
    rate_t, gyro = _columns("IMU", imu, fields, path)
    return np.column_stack([np.interp(flight.ekf_t, rate_t, column) for column in gyro.T])


def read_dataflash(path: str | Path, n_thrusters: int, options: LogOptions) -> VelocityLog:
    """The body velocities and thrusts in an ArduSub DataFlash log (module docstring),
    resampled onto a uniform grid. A missing message type, field or channel, or a log too
    short: one ConfigError line."""
    path = Path(path)
    flight = _read_flight(path, n_thrusters, options)
    phi, theta, psi = flight.attitude.T
    uv = body_velocity(phi, theta, psi, flight.ned_velocity)[:, BODY_VELOCITY.span("u", "v")]
    rates = _body_rates(flight, path, ("GyrZ",))
    if rates is None:  # the yaw's time derivative: r for a vehicle that stays level
        yaw = flight.angles[:, 2]
        r = np.interp(flight.ekf_t, flight.att_t, np.gradient(yaw, flight.att_t / 1e9))
    else:
        r = rates[:, 0]
    return resample(
        str(path),
        options.sample_time,
        flight.ekf_t,
        np.column_stack([uv, r]),
        flight.rc_t,
        flight.thrust,
        (f"{flight.ekf} velocity", "RCOU"),
        heading=psi,
    )


def read_six_dof_dataflash(
    path: str | Path, n_thrusters: int, options: LogOptions
) -> tuple[str, float, np.ndarray, np.ndarray]:
    """(name, sample time, state (N+1, 12) in SIX_DOF order, thrust (N, n)) of an ArduSub
    DataFlash log: the EKF's NED position, ATT's attitude, the EKF's velocity rotated into
    the body and IMU's ``GyrX, GyrY, GyrZ`` (p, q, r; needed: the roll and pitch model is
    fitted to them), on one grid (identification/six_dof_log.py)."""
    path = Path(path)
    flight = _read_flight(path, n_thrusters, options)
    rates = _body_rates(flight, path, ("GyrX", "GyrY", "GyrZ"))
    if rates is None:
        raise ConfigError(
            "LOG", str(path), "has no IMU messages: 6-DOF identification needs the body rates "
            "p, q, r (IMU GyrX, GyrY, GyrZ)",
        )  # fmt: skip
    navigation = _first_instance(flight.messages[flight.ekf], "C")
    _, position = _columns(flight.ekf, navigation, ("PN", "PE", "PD"), path)
    phi, theta, psi = flight.attitude.T
    nu = body_velocity(phi, theta, psi, flight.ned_velocity)
    state = np.column_stack([position, flight.attitude, nu, rates])
    log = resample(str(path), options.sample_time, flight.ekf_t, state, flight.rc_t,
                   flight.thrust, (f"{flight.ekf} navigation", "RCOU"),
                   outputs=SIX_DOF.names)  # fmt: skip
    return log.name, log.sample_time, log.velocity, log.thrust
