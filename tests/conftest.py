"""Shared tolerances, each with the reason for its size, and small fixtures."""

from __future__ import annotations

import math

import numpy as np
import pytest

# Issue 2's one-step replay bound: 0.1 mm and 1e-4 rad per 0.5 s sample.
REPLAY_POSITION_TOL_M = 1e-4
REPLAY_ANGLE_TOL_RAD = 1e-4
# Velocity replay bound: same relative size as the position bound over a 0.5 s sample.
REPLAY_VELOCITY_TOL = 2e-4
# Plant RK4 at 0.05 s against solve_ivp at rtol 1e-11: RK4's local error is
# O(h^5) ~ 1e-7 relative per step for this model's time constants; 1e-6 keeps margin.
PLANT_VS_SOLVE_IVP_TOL = 1e-6
# Symbolic (CasADi) and numeric evaluation of the same formula: round-off only.
ROUND_OFF_TOL = 1e-12

# The 6-DOF model with w = p = q = 0 and neutral buoyancy against the 3-DOF model: the same
# equations in a different operation order, so round-off only (1e-15 per step), also over a
# 20 s trajectory of 400 RK4 steps; 1e-9 is the bound.
SIX_DOF_REDUCTION_TOL = 1e-9
# Small roll and pitch oscillations at 1 % of a radian: the pendulum's amplitude effect on the
# frequency is a^2 / 16 ~ 6e-6, RK4's phase error at h = 0.01 s is (omega h)^4 / 120 < 1e-8;
# 1e-4 relative also absorbs the zero crossings' linear interpolation.
NATURAL_FREQUENCY_REL_TOL = 1e-4
# An unpowered vehicle in a uniform current after 40 of its slowest linear time constants
# (jmse2210's surge: 6 s): exp(-40) ~ 4e-18 of its start; 1e-9 m/s is round-off with margin.
DRIFT_VELOCITY_TOL = 1e-9

PAPER_INITIAL_STATE = (7.5, -12.0, math.pi / 2, 0.4, 0.1, 0.02 * math.pi)


def run_and_export(base, overrides):
    """``base`` holding a healthy run folder (``healthy``) of paper-ideal with ``overrides``
    and an export-c folder (``export``) of the same scenario: what the damaged-folder tests
    damage copies of."""
    from auvmpc.experiments.run import simulate, write_run
    from auvmpc.export.c_library import export_c
    from auvmpc.scenario import load_scenario

    write_run(simulate(load_scenario("paper-ideal", overrides)), base / "healthy", figures=False)
    export_c(load_scenario("paper-ideal", overrides), base / "export")
    return base


def cli(*args: str) -> None:
    """``auvmpc ARGS`` in-process, for fixtures wider than a test (run_cli needs a test's
    own monkeypatch and capsys); a non-zero exit fails the fixture."""
    import sys

    from auvmpc.cli import main

    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(sys, "argv", ["auvmpc", *args])
        try:
            main()
        except SystemExit as stop:
            assert not stop.code, f"auvmpc {' '.join(args)} exited {stop.code}"


def odometry_rewritten(bag, out, change) -> None:
    """The exporter's /odom and /thrust copied into a SQLite3 bag ``out`` by rosbags' own
    reader and writer, each odometry message passed through ``change`` (it edits in place)."""
    from rosbags.highlevel import AnyReader
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_JAZZY)
    with (
        AnyReader([bag]) as reader,
        Writer(out, version=9, storage_plugin=StoragePlugin.SQLITE3) as writer,
    ):
        kept = [c for c in reader.connections if c.topic in ("/odom", "/thrust")]
        added = {c.topic: writer.add_connection(c.topic, c.msgtype, typestore=store) for c in kept}
        for connection, stamp, raw in reader.messages(connections=kept):
            message = reader.deserialize(raw, connection.msgtype)
            if connection.topic == "/odom":
                change(message)
            writer.write(added[connection.topic], stamp,
                         store.serialize_cdr(message, connection.msgtype))  # fmt: skip


# The 6-DOF identification manoeuvre every 6-DOF log-format test starts from: short, for the
# tests' time (the method's default is 40 s, of which 10 s fade in and out).
SIX_DOF_EXCITE_VEHICLE = "bluerov2-heavy"
SIX_DOF_EXCITE_DURATION_S = 25.0


# A 6-DOF log's sensors: an AHRS's attitude (rad) and a gyro's and DVL's rates (rad/s, m/s).
ATTITUDE_NOISE_RAD = 0.002
RATE_NOISE = 0.005
# Issue 27's bar: every parameter the report calls excited, identified from a start this far
# off, is within WITHIN of the truth or its 95 % interval covers the truth.
START_ERROR = 0.3
WITHIN = 0.1


def with_sensor_noise(states: np.ndarray, seed: int = 0) -> np.ndarray:
    """6-DOF states (SIX_DOF order) as an AHRS, a gyro and a DVL would measure them."""
    from auvmpc.models.six_dof import SIX_DOF

    rng = np.random.default_rng(seed)
    measured = states.copy()
    angles = [SIX_DOF.index(name) for name in ("phi", "theta", "psi")]
    rates = [SIX_DOF.index(name) for name in ("u", "v", "w", "p", "q", "r")]
    measured[:, angles] += rng.normal(0, ATTITUDE_NOISE_RAD, (len(states), len(angles)))
    measured[:, rates] += rng.normal(0, RATE_NOISE, (len(states), len(rates)))
    return measured


def assert_recovered(found, true_values: dict[str, float]) -> None:
    """Every parameter of ``found`` (an Identification) is excited and meets issue 27's bar."""
    for estimate in found.parameters:
        value, (low, high) = true_values[estimate.name], estimate.ci95
        assert estimate.excited, estimate.name
        close = abs(estimate.value - value) <= WITHIN * abs(value)
        assert close or low <= value <= high, (estimate, value)


@pytest.fixture(scope="session")
def six_dof_excite_run(tmp_path_factory):
    """``excite --dof six-dof`` (excite.yaml, excite.csv) and its ``run`` (run/), once per
    test process (about 5 s)."""
    folder = tmp_path_factory.mktemp("six-dof-excite")
    cli("excite", SIX_DOF_EXCITE_VEHICLE, "--dof", "six-dof", "--out",
        str(folder / "excite.yaml"), "--duration", str(SIX_DOF_EXCITE_DURATION_S),
        "--box", "5")  # fmt: skip
    cli("run", str(folder / "excite.yaml"), "--out", str(folder / "run"), "--no-figures")
    return folder


@pytest.fixture
def installed_interrupts():
    """auvmpc's SIGINT/SIGTERM handlers installed for the test, as the CLI installs them,
    with no signal pending before or after."""
    from auvmpc import interrupts

    interrupts.reset()
    previous = interrupts.install()
    yield
    interrupts.restore(previous)
    interrupts.reset()


@pytest.fixture
def jmse():
    from auvmpc.models.vehicle import load_vehicle

    return load_vehicle("jmse2210")


@pytest.fixture
def bluerov():
    from auvmpc.models.vehicle import load_vehicle

    return load_vehicle("bluerov2-heavy")


def random_limit_case(rng, params, reference, sample_time: float, horizon: int):
    """A state near a random reference point and a previous thrust inside or at the limits
    (the hard-limit tests of every MPC draw from this)."""
    t0 = rng.uniform(0.0, 90.0)
    preview = reference.states(t0 + sample_time * np.arange(horizon + 1))
    offset = rng.uniform(
        [-3.0, -3.0, -math.pi, -1.0, -0.5, -0.5], [3.0, 3.0, math.pi, 1.0, 0.5, 0.5]
    )
    state = preview[0] + offset
    state[3:] = offset[3:]  # velocities about zero, either sign
    low, high = params.thrust_limits
    kind = rng.integers(3)
    n = params.n_thrusters
    if kind == 0:
        previous = rng.uniform(low, high, size=n)
    elif kind == 1:  # every thruster at one of its limits
        previous = rng.choice([low, high], size=n)
    else:  # all at the upper limit, the asymmetric side for bluerov
        previous = np.full(n, high)
    return t0, state, preview, previous


# Issue 11's closed-loop bounds on the 6-DOF plant (paper section 4.2), after the transient:
# the horizontal error within this factor of the same controller's on the 3-DOF plant, the
# depth RMS error, roll and pitch, and the BlueROV2 helix's horizontal RMS error.
SIX_DOF_VS_PLANAR_ERROR_FACTOR = 2.0
SIX_DOF_DEPTH_RMS_TOL_M = 0.05
SIX_DOF_TILT_LIMIT_RAD = math.radians(10.0)
HELIX_RMS_TOL_M = 0.1
# The C export of the real-time nmpc against the Python controller, command by command: the
# same generated code (the stage QP, the RK4 step, the estimator's update and propagation)
# and the same HPIPM driver, so the commands agree to the bit (measured 0 N on every case
# here and on the estimator's BlueROV2 lawnmower, where the hand-written C estimator had
# differed by up to 8.9e-6 N); 1e-9 N is issue 25's bound.
C_EXPORT_COMMAND_TOL_N = 1e-9
