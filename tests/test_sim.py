"""The closed loop: seeded determinism, honest recording, and the metrics it feeds."""

from __future__ import annotations

import math

import numpy as np
import pytest

from auvmpc.controllers.base import Controller, ControlResult, Observation
from auvmpc.environment.disturbances import (
    DisturbanceConfig,
    GaussMarkovConfig,
    SensorNoise,
    SensorNoiseConfig,
    WaveForceConfig,
    WorldDisturbance,
)
from auvmpc.environment.obstacles import ObstacleConfig
from auvmpc.experiments.run import simulate
from auvmpc.references import LineConfig, make_reference
from auvmpc.scenario import load_scenario
from auvmpc.sim.log import SimLog
from auvmpc.sim.loop import closed_loop
from auvmpc.sim.metrics import compute_metrics

NOISY = [
    "sensing.std=[0.05, 0.05, 0.01, 0.02, 0.02, 0.005]",
    "disturbance.current_variation={std_N: 3.0, time_constant_s: 20.0}",
    "disturbance.waves={amplitude_N: 2.0, period_s: 5.0, direction_deg: 30}",
    "duration=20",
]


def test_same_seed_same_bits_other_seed_other_bits():
    first = simulate(load_scenario("paper-disturbed", [*NOISY, "controller.type=baseline"])).log
    again = simulate(load_scenario("paper-disturbed", [*NOISY, "controller.type=baseline"])).log
    other = simulate(
        load_scenario("paper-disturbed", [*NOISY, "controller.type=baseline", "seed=7"])
    ).log
    assert np.array_equal(first.state, again.state)
    assert np.array_equal(first.thrust, again.thrust)
    assert np.array_equal(first.environment, again.environment)
    assert not np.array_equal(first.state, other.state)
    assert not np.array_equal(first.environment, other.environment)


def test_gauss_markov_current_has_its_stationary_statistics():
    config = DisturbanceConfig(current_variation=GaussMarkovConfig(std_N=2.0, time_constant_s=5.0))
    disturbance = WorldDisturbance(config, 0.5, np.random.default_rng(3))
    samples = []
    for _ in range(40_000):
        samples.append(disturbance.force_world(0.0)[:2])
        disturbance.advance()
    samples = np.array(samples)
    # 40k samples with correlation time 10 samples: ~4k independent ones, std error ~1.1 %.
    assert samples.std(axis=0) == pytest.approx([2.0, 2.0], rel=0.06)
    lag = 10  # one time constant: autocorrelation exp(-1)
    x = samples[:, 0] - samples[:, 0].mean()
    assert np.dot(x[:-lag], x[lag:]) / np.dot(x, x) == pytest.approx(math.exp(-1), abs=0.05)


def test_wave_force_is_a_sinusoid_along_its_direction():
    config = DisturbanceConfig(
        waves=WaveForceConfig(amplitude_N=3.0, period_s=4.0, direction_deg=90)
    )
    disturbance = WorldDisturbance(config, 0.5, np.random.default_rng(0))
    forces = np.array([disturbance.force_world(t) for t in np.linspace(0, 4, 401)])
    np.testing.assert_allclose(forces[:, 0], 0.0, atol=1e-12)
    assert np.abs(forces[:, 1]).max() == pytest.approx(3.0, rel=1e-3)
    np.testing.assert_allclose(forces[0], forces[-1], atol=1e-12)  # one period


def test_sensor_noise_only_on_what_the_controller_sees():
    noise = SensorNoise(SensorNoiseConfig(std=(1, 1, 0, 0, 0, 0)), np.random.default_rng(0))
    truth = np.zeros(6)
    measured = noise.measure(truth)
    assert np.all(truth == 0) and np.any(measured[:2] != 0) and np.all(measured[2:] == 0)


class ReckLessController(Controller):
    """Commands 20 N on every thruster: beyond the 15 N limit and the 2.5 N step."""

    sample_time = 0.5
    preview_steps = 0

    def reset(self, initial_state, initial_thrust):
        pass

    def compute(self, observation: Observation) -> ControlResult:
        return ControlResult(thrust=np.full(4, 20.0))


def test_loop_records_the_mistakes_it_is_given(jmse):
    rng = np.random.default_rng(0)
    log = closed_loop(
        jmse,
        ReckLessController(),
        make_reference(LineConfig(type="line", start=(0, 0), heading_deg=0, speed=0.5)),
        duration=2.0,
        initial_state=np.zeros(6),
        disturbance=WorldDisturbance(DisturbanceConfig(), 0.5, rng),
        sensor=SensorNoise(SensorNoiseConfig(), rng),
    )
    assert np.all(log.thrust == 20.0)  # applied unaltered
    metrics = compute_metrics(log, jmse)
    assert metrics["thrust_limit_violations"] == 4 * 4  # every thruster, every sample
    assert metrics["thrust_rate_violations"] == 4  # only the first jump from 0 N
    assert metrics["max_abs_thrust_rate_N_per_s"] == pytest.approx(40.0)


def test_the_loop_refuses_a_plant_that_steps_another_sample_time(jmse):
    from auvmpc.sim.plant import HorizontalPlant

    rng = np.random.default_rng(0)
    plant = HorizontalPlant(jmse, WorldDisturbance(DisturbanceConfig(), 0.25, rng), 0.25, 0.05)
    with pytest.raises(ValueError, match="plant steps 0.25 s"):
        closed_loop(
            plant,
            ReckLessController(),
            make_reference(LineConfig(type="line", start=(0, 0), heading_deg=0, speed=0.5)),
            duration=2.0,
            initial_state=np.zeros(6),
            sensor=SensorNoise(SensorNoiseConfig(), rng),
        )


def test_clearance_only_while_an_obstacle_exists(jmse):
    rng = np.random.default_rng(0)
    obstacle = ObstacleConfig(center=(3.0, 0.0), radius=0.5, appear_time=1.0, vanish_time=2.0)
    log = closed_loop(
        jmse,
        ReckLessController(),
        make_reference(LineConfig(type="line", start=(0, 0), heading_deg=0, speed=0.5)),
        duration=3.0,
        initial_state=np.zeros(6),
        disturbance=WorldDisturbance(DisturbanceConfig(), 0.5, rng),
        sensor=SensorNoise(SensorNoiseConfig(), rng),
        obstacles=[obstacle],
        vehicle_radius=0.5,
    )
    exists = (log.t >= 1.0) & (log.t < 2.0)
    assert np.all(np.isinf(log.clearance_m[~exists]))
    expected = np.hypot(log.state[exists, 0] - 3.0, log.state[exists, 1]) - 1.0
    np.testing.assert_allclose(log.clearance_m[exists], expected)


def test_the_log_records_the_disturbance_the_controller_assumed(tmp_path):
    """Offset-free ltv-mpc under a constant 5 N / 3 N current: the logged estimate (what the
    prediction used) settles on the true world force, and survives the CSV round trip."""
    from auvmpc.experiments.run import simulate
    from auvmpc.scenario import load_scenario
    from auvmpc.sim.log import ESTIMATE_NAMES, SimLog

    resolved = load_scenario(
        "paper-ideal",
        [
            "duration=40",
            "controller.type=ltv-mpc",
            "controller.offset_free=true",
            "disturbance.current_force_world=[5.0, 3.0]",
        ],
    )
    log = simulate(resolved).log
    # The EKF's random walk settles within the first 20 s; 0.5 N is 10 % of the force.
    estimate = log.diagnostics["disturbance_estimate"]
    np.testing.assert_allclose(estimate[-10:, :2], [[5.0, 3.0]] * 10, atol=0.5)
    path = tmp_path / "log.csv"
    path.write_text(log.to_csv_text())
    np.testing.assert_array_equal(
        SimLog.read_csv(path).diagnostics["disturbance_estimate"], estimate
    )
    assert set(ESTIMATE_NAMES) <= set(log.columns())


@pytest.mark.parametrize(
    ("name", "seconds"),
    [("encounter-pop-up", 10), ("paper-depth-waves", 30), ("bluerov2-helix", 10)],
)
def test_every_kind_of_log_reads_back_to_the_same_file_and_fields(tmp_path, name, seconds):
    """One writer and one reader serve every kind of log (sim/log.py, csv_columns): what a
    run writes reads back to the same text, and every field log.csv holds to the bit."""
    log = simulate(load_scenario(name, [f"duration={seconds}"])).log
    path = tmp_path / "log.csv"
    path.write_text(log.to_csv_text())
    back = SimLog.read_csv(path, log.initial_thrust, log.format, log.horizontal_inputs)
    assert back.to_csv_text() == log.to_csv_text()
    for block in log.csv_columns():
        if block.field is None:
            continue  # written as 0 (a 6-DOF log's dist_* beside its current)
        written, read = log._values(block.field), back._values(block.field)
        if block.text:
            assert read == written, block.names
            continue
        part = slice(None) if block.part is None else block.part
        np.testing.assert_array_equal(
            np.asarray(read)[..., part] if np.ndim(read) > 1 else read,
            np.asarray(written)[..., part] if np.ndim(written) > 1 else written,
            err_msg=str(block.names),
        )


def test_a_horizontal_run_logs_its_water_current(tmp_path):
    """issue 30: a water current set in a horizontal scenario is in log.csv (current_north,
    current_east, world m/s) beside the current force, and reads back; the 6-DOF run's
    horizontal view carries its current's north and east parts the same way."""
    resolved = load_scenario(
        "paper-ideal",
        ["duration=3", "disturbance.water_current={velocity_m_per_s: [0.2, -0.1, 0.0]}"],
    )
    log = simulate(resolved).log
    np.testing.assert_array_equal(log.column("current_north"), 0.2)
    np.testing.assert_array_equal(log.column("current_east"), -0.1)
    path = tmp_path / "log.csv"
    path.write_text(log.to_csv_text())
    header = path.read_text().splitlines()[0].split(",")
    assert header[-2:] == ["current_north", "current_east"]
    np.testing.assert_array_equal(SimLog.read_csv(path).column("current_east"), -0.1)
    six_dof = simulate(load_scenario("bluerov2-helix", ["duration=2"])).log
    np.testing.assert_array_equal(six_dof.horizontal().column("current_north"), 0.2)
