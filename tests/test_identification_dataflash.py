"""`auvmpc identify` from an ArduSub DataFlash log (issue 27 item 3). No public sample log
of clear licence is vendored: the test writes one itself, a binary DataFlash file in the
format's own terms (FMT messages defining ATT, XKF1, IMU and RCOU with ArduSub's layouts,
packed with pymavlink's table of format characters), from a simulated excitation of the
BlueROV2 Heavy whose thrusts went through the T200 curve as PWM; then reads it back and
identifies from it."""

from __future__ import annotations

import math
import struct
import sys

import numpy as np
import pytest

from auvmpc.errors import ConfigError
from auvmpc.identification.estimation import identify
from auvmpc.identification.excitation import design_excitation, simulate_open_loop
from auvmpc.identification.logs import LogOptions, read_log
from auvmpc.identification.six_dof_log import (
    identify_six_dof,
    offset_vehicle,
    parameter_values,
    read_six_dof_samples,
)
from auvmpc.identification.thruster_curve import STANDARD_GRAVITY, thruster_curve
from auvmpc.models.six_dof import SIX_DOF, Rzyx
from auvmpc.models.vehicle import load_vehicle
from tests.conftest import (
    SIX_DOF_EXCITE_VEHICLE,
    START_ERROR,
    assert_recovered,
    with_sensor_noise,
)
from tests.test_cli import run_cli

DFReader = pytest.importorskip("pymavlink.DFReader")

VEHICLE = "bluerov2-heavy"
# ArduSub's layouts (ArduPilot's LogStructure.h): (type id, format, columns).
FORMATS = {
    "ATT": (1, "QccccCCCCB", "TimeUS,DesRoll,Roll,DesPitch,Pitch,DesYaw,Yaw,ErrRP,ErrYaw,AEKF"),
    "XKF1": (2, "QBccCfffffffccce", "TimeUS,C,Roll,Pitch,Yaw,VN,VE,VD,dPD,PN,PE,PD,GX,GY,GZ,OH"),
    "IMU": (3, "QBffffffIIfBBHH", "TimeUS,I,GyrX,GyrY,GyrZ,AccX,AccY,AccZ,EG,EA,T,GH,AH,GHz,AHz"),
    "RCOU": (4, "QHHHHHHHHHHHHHH", "TimeUS," + ",".join(f"C{i}" for i in range(1, 15))),
}
HEAD = bytes([0xA3, 0x95])
ROLL_DEG, PITCH_DEG = 2.0, -3.0  # a constant small attitude, so the rotation is exercised
# ATT stores angles in centidegrees (half a centidegree, 8.7e-5 rad, at most off) and XKF1
# the velocity in float32: u, v off by at most 8.7e-5 rad x 1 m/s + 1e-7; 2e-4 m/s margin.
VELOCITY_TOL = 2e-4
# IMU's GyrZ is float32: 1e-7 relative.
RATE_TOL = 1e-6
# ATT's yaw in centidegrees: half of one, 8.7e-5 rad, at most off.
HEADING_TOL = 1e-4


def _struct(fmt: str) -> struct.Struct:
    return struct.Struct("<" + "".join(DFReader.FORMAT_TO_STRUCT[c][0] for c in fmt))


def _packed(name: str, values: dict[str, float]) -> bytes:
    type_id, fmt, columns = FORMATS[name]
    cells = []
    for char, column in zip(fmt, columns.split(","), strict=True):
        value = values.get(column, 0)
        _, multiplier, kind = DFReader.FORMAT_TO_STRUCT[char]
        if multiplier:
            cells.append(round(value / multiplier))
        elif kind is str:
            cells.append(str(value).encode())
        else:
            cells.append(kind(value))
    return HEAD + bytes([type_id]) + _struct(fmt).pack(*cells)


def _fmt_messages() -> bytes:
    out = b""
    for name, (type_id, fmt, columns) in FORMATS.items():
        length = 3 + _struct(fmt).size
        out += (
            HEAD
            + bytes([0x80])
            + struct.pack(
                "<BB4s16s64s", type_id, length, name.encode(), fmt.encode(), columns.encode()
            )
        )
    return out


def _pwm_for(force_n: np.ndarray) -> np.ndarray:
    """Integer PWM (us) the T200 16 V curve maps closest to each force: what an ArduSub
    would have sent for it."""
    curve = thruster_curve("t200-16v")
    pwm = curve.pwm_us
    candidates = np.arange(pwm[0], pwm[-1] + 1)
    table = curve.force(candidates)
    return candidates[np.abs(table[None, :] - np.ravel(force_n)[:, None]).argmin(axis=1)].reshape(
        np.shape(force_n)
    )


@pytest.fixture(scope="module")
def flight(tmp_path_factory):
    """A 40 s excitation of the BlueROV2 Heavy through the T200 curve, as a .bin."""
    from auvmpc.models.vehicle import load_vehicle

    vehicle = load_vehicle(VEHICLE)
    excitation = design_excitation(vehicle, 40.0)
    pwm = _pwm_for(excitation.thrust)
    thrust = thruster_curve("t200-16v").force(pwm)  # what the vehicle really got
    states = simulate_open_loop(vehicle, thrust, excitation.sample_time)
    step_us = round(excitation.sample_time * 1e6)
    roll, pitch = math.radians(ROLL_DEG), math.radians(PITCH_DEG)
    blob = bytearray(_fmt_messages())
    for k, state in enumerate(states):
        time_us = 1_000_000 + k * step_us  # a log starts at boot, not at 0
        psi = state[2]
        ned = np.asarray(Rzyx(roll, pitch, psi)).reshape(3, 3) @ [state[3], state[4], 0.0]
        yaw_deg = math.degrees(psi) % 360.0
        blob += _packed("ATT", {"TimeUS": time_us, "Roll": ROLL_DEG, "Pitch": PITCH_DEG,
                                "Yaw": yaw_deg})  # fmt: skip
        for core in (0, 1):  # EKF3 logs each core; the second's velocity is wrong on purpose
            velocity = ned if core == 0 else -ned
            blob += _packed("XKF1", {"TimeUS": time_us, "C": core, "VN": velocity[0],
                                     "VE": velocity[1], "VD": velocity[2]})  # fmt: skip
        blob += _packed("IMU", {"TimeUS": time_us, "I": 0, "GyrZ": state[5]})
        if k < len(pwm):
            channels = {f"C{i + 1}": p for i, p in enumerate(pwm[k])}
            channels.update({f"C{i}": 1500 for i in range(5, 9)})  # the vertical thrusters
            blob += _packed("RCOU", {"TimeUS": time_us, **channels})
    path = tmp_path_factory.mktemp("dataflash") / "00000042.BIN"
    path.write_bytes(bytes(blob))
    return vehicle, excitation.sample_time, states, thrust, path


def test_the_t200_preset_is_blue_robotics_published_curve():
    """The workbook's end points (16 V: 5.245 kgf at 1900 us, -4.069 kgf at 1100 us; dead
    band 1472..1528 us) and the vehicle file's limits taken from the same datasheet."""
    curve = thruster_curve("t200-16v")
    np.testing.assert_allclose(curve.force([1100, 1900]) / STANDARD_GRAVITY, [-4.069, 5.245])
    assert np.all(curve.force(np.arange(1472, 1529)) == 0.0)
    assert curve.force(0.0) == 0.0  # an output switched off
    assert thruster_curve("t200-12v").force(1900) / STANDARD_GRAVITY == pytest.approx(3.714)


def test_the_dataflash_log_reads_back_as_the_flight(flight):
    vehicle, sample_time, states, thrust, path = flight
    log = read_log(path, vehicle.n_thrusters)
    assert log.sample_time == pytest.approx(sample_time)
    assert log.steps == len(thrust)
    np.testing.assert_allclose(log.velocity[:, :2], states[:, 3:5], rtol=0, atol=VELOCITY_TOL)
    np.testing.assert_allclose(log.velocity[:, 2], states[:, 5], rtol=0, atol=RATE_TOL)
    np.testing.assert_array_equal(log.thrust, thrust)
    # The heading (ATT's yaw, logged in [0, 360) deg) up to whole turns.
    turned = np.angle(np.exp(1j * (log.heading - states[:, 2])))
    np.testing.assert_allclose(turned, 0.0, rtol=0, atol=HEADING_TOL)
    # Channels named and reversed: thruster 1 read from C2, reversed.
    options = LogOptions(channels=(2, 1, 3, 4), reversed_channels=(2,))
    swapped = read_log(path, vehicle.n_thrusters, options)
    np.testing.assert_array_equal(swapped.thrust[:, 0], -thrust[:, 1])


def test_identify_from_the_dataflash_log_recovers_the_vehicle(flight):
    vehicle, _, _, _, path = flight
    found = identify([read_log(path, vehicle.n_thrusters)], vehicle)
    assert not found.unexcited  # 40 s excite every parameter (measured: all within 0.1 %)
    for estimate in found.parameters:
        truth = getattr(vehicle, estimate.name)
        if estimate.excited:
            low, high = estimate.ci95
            assert abs(estimate.value - truth) <= 0.1 * abs(truth) or low <= truth <= high, (
                estimate.name
            )


@pytest.mark.parametrize(
    ("keep", "args", "message"),
    [
        (("ATT", "XKF1", "IMU"), [], "has no RCOU messages (need ATT, XKF1 or NKF1, RCOU)"),
        (("ATT", "RCOU"), [], "has no XKF1 or NKF1 messages"),
        (FORMATS, ["--channels", "1,2"], "--channels: lists 2 channels, the start vehicle has 4"),
        (FORMATS, ["--reversed", "15"], "--reversed: RCOU channels are 1..14"),
        (FORMATS, ["--thruster-curve", "t100"], "neither a preset (t200-12v, t200-16v) nor a"),
    ],
)
def test_a_bad_dataflash_log_is_refused_in_one_line(
    flight, tmp_path, monkeypatch, capsys, keep, args, message
):
    """A log without a message type identify needs, or a flag that does not fit it."""
    _, _, _, _, path = flight
    reader = DFReader.DFReader_binary(str(path))
    blob = bytearray(_fmt_messages())
    while (m := reader.recv_match(type=[n for n in keep if n in FORMATS])) is not None:
        if m.get_type() in keep:
            blob += _packed(m.get_type(), m.to_dict())
    cut = tmp_path / "cut.bin"
    cut.write_bytes(bytes(blob))
    code, _, err = run_cli(monkeypatch, capsys, "identify", str(cut), "--vehicle", VEHICLE,
                           *args, "--out", str(tmp_path / "v.yaml"))  # fmt: skip
    assert code == 2, err
    assert err.count("\n") == 1 and message in err


def test_without_pymavlink_the_error_names_the_extra(flight, monkeypatch):
    monkeypatch.setitem(sys.modules, "pymavlink", None)
    with pytest.raises(Exception, match=r"needs pymavlink: pip install 'auvmpc\[ardupilot\]'"):
        read_log(flight[-1], 4)


# XKF1's position is float32: 6e-8 relative of a few metres.
POSITION_TOL = 1e-6


def _six_dof_dataflash(states: np.ndarray, pwm: np.ndarray, sample_time: float) -> bytes:
    """An ArduSub log of a 6-DOF flight: ATT, XKF1 (position and NED velocity), IMU's body
    rates and RCOU's PWM on channels 1..n, each row at a sample."""
    index = {name: SIX_DOF.index(name) for name in SIX_DOF.names}
    step_us = round(sample_time * 1e6)
    blob = bytearray(_fmt_messages())
    for k, state in enumerate(states):
        time_us = 1_000_000 + k * step_us
        phi, theta, psi = (state[index[n]] for n in ("phi", "theta", "psi"))
        body = [state[index[n]] for n in ("u", "v", "w")]
        ned = np.asarray(Rzyx(phi, theta, psi)).reshape(3, 3) @ body
        blob += _packed("ATT", {"TimeUS": time_us, "Roll": math.degrees(phi),
                                "Pitch": math.degrees(theta),
                                "Yaw": math.degrees(psi) % 360.0})  # fmt: skip
        blob += _packed("XKF1", {"TimeUS": time_us, "C": 0, "PN": state[index["x"]],
                                 "PE": state[index["y"]], "PD": state[index["z"]],
                                 "VN": ned[0], "VE": ned[1], "VD": ned[2]})  # fmt: skip
        blob += _packed("IMU", {"TimeUS": time_us, "I": 0, "GyrX": state[index["p"]],
                                "GyrY": state[index["q"]], "GyrZ": state[index["r"]]})  # fmt: skip
        if k < len(pwm):
            blob += _packed("RCOU", {"TimeUS": time_us,
                                     **{f"C{i + 1}": p for i, p in enumerate(pwm[k])}})  # fmt: skip
    return bytes(blob)


def test_six_dof_identification_from_a_dataflash_log(six_dof_excite_run, tmp_path):
    """The 6-DOF excite run flown as an ArduSub would log it (the AHRS's, gyro's and DVL's
    noise; each of the 8 thrusters' force as the T200 PWM nearest to it) reads back as
    written, up to the format's resolution; identify --dof six-dof recovers every model from
    a start 30 % off; a log without IMU is refused in one line (no p, q)."""
    truth = load_vehicle(SIX_DOF_EXCITE_VEHICLE)
    _, sample_time, states, thrust = read_six_dof_samples(six_dof_excite_run / "run", truth)
    measured = with_sensor_noise(states)
    angles = [SIX_DOF.index(name) for name in ("phi", "theta", "psi")]
    pwm = _pwm_for(thrust)
    path = tmp_path / "00000043.BIN"
    path.write_bytes(_six_dof_dataflash(measured, pwm, sample_time))

    name, read_time, read_states, read_thrust = read_six_dof_samples(path, truth)
    assert read_time == pytest.approx(sample_time) and name == str(path)
    np.testing.assert_array_equal(read_thrust, thruster_curve("t200-16v").force(pwm))
    positions = [SIX_DOF.index(n) for n in ("x", "y", "z")]
    np.testing.assert_allclose(read_states[:, positions], measured[:, positions], rtol=0,
                               atol=POSITION_TOL)  # fmt: skip
    turned = np.angle(np.exp(1j * (read_states[:, angles] - measured[:, angles])))
    np.testing.assert_allclose(turned, 0.0, rtol=0, atol=HEADING_TOL)
    velocities = [SIX_DOF.index(n) for n in ("u", "v", "w")]
    np.testing.assert_allclose(read_states[:, velocities], measured[:, velocities], rtol=0,
                               atol=VELOCITY_TOL)  # fmt: skip
    body_rates = [SIX_DOF.index(n) for n in ("p", "q", "r")]
    np.testing.assert_allclose(read_states[:, body_rates], measured[:, body_rates], rtol=0,
                               atol=RATE_TOL)  # fmt: skip

    found = identify_six_dof([(name, read_time, read_states, read_thrust)],
                             offset_vehicle(truth, START_ERROR))  # fmt: skip
    assert_recovered(found, parameter_values(truth))

    without_imu = tmp_path / "no-imu.bin"
    reader = DFReader.DFReader_binary(str(path))
    blob = bytearray(_fmt_messages())
    while (m := reader.recv_match(type=["ATT", "XKF1", "RCOU"])) is not None:
        blob += _packed(m.get_type(), m.to_dict())
    without_imu.write_bytes(bytes(blob))
    with pytest.raises(ConfigError, match="has no IMU messages: 6-DOF identification needs"):
        read_six_dof_samples(without_imu, truth)
