"""Depth control: heave model, waves, the tank step experiment, bad input."""

from __future__ import annotations

import csv
import json
import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from auvmpc.controllers.base import Observation
from auvmpc.environment.waves import GRAVITY, WaveConfig, WaveField, wave_number
from auvmpc.errors import ConfigError
from auvmpc.experiments.run import simulate, write_run
from auvmpc.models.heave import heave_dynamics
from auvmpc.models.vehicle import load_vehicle
from auvmpc.scenario import load_scenario

# Issue 5: replaying the logged thrust reproduces the logged depth in calm water to 1 mm.
DEPTH_REPLAY_TOL_M = 1e-3
# JONSWAP significant height from 20 min of surface record: sampling error of 4 std(eta)
# is a few per cent for ~1000 wave periods.
HS_RELATIVE_TOL = 0.05


def test_dispersion_relation_and_its_limits():
    for omega in (0.5, 2.0, 6.0):
        for depth in (0.3, 1.25, 50.0):
            k = wave_number(omega, depth)
            assert omega**2 == pytest.approx(GRAVITY * k * math.tanh(k * depth), rel=1e-10)
    assert wave_number(6.0, 50.0) == pytest.approx(36.0 / GRAVITY, rel=1e-9)  # deep water
    shallow = wave_number(0.1, 0.5)  # shallow water: k = omega / sqrt(g h)
    assert shallow == pytest.approx(0.1 / math.sqrt(GRAVITY * 0.5), rel=1e-3)


def test_regular_wave_acceleration_decays_with_depth_as_linear_theory_says():
    field = WaveField(WaveConfig(height_m=0.1, period_s=1.0), 1.25, np.random.default_rng(0))
    omega, k = 2 * math.pi, field.wavenumbers[0]
    times = np.linspace(0.0, 1.0, 400)
    for z in (0.0, -0.3, -0.5, -1.0):
        peak = max(abs(field.vertical_acceleration(z, t)) for t in times)
        expected = 0.05 * omega**2 * math.sinh(k * (z + 1.25)) / math.sinh(k * 1.25)
        assert peak == pytest.approx(expected, rel=1e-3)
    assert field.vertical_acceleration(-1.25, 0.3) == pytest.approx(0.0, abs=1e-12)  # bottom


def test_jonswap_sea_has_its_significant_height_and_is_seeded():
    config = WaveConfig(type="jonswap", height_m=0.1, period_s=1.0)
    field = WaveField(config, 1.25, np.random.default_rng(3))
    elevation = np.array([field.elevation(t) for t in np.arange(0.0, 1200.0, 0.05)])
    assert 4.0 * elevation.std() == pytest.approx(0.1, rel=HS_RELATIVE_TOL)
    again = WaveField(config, 1.25, np.random.default_rng(3))
    assert again.elevation(12.3) == field.elevation(12.3)
    other = WaveField(config, 1.25, np.random.default_rng(4))
    assert other.elevation(12.3) != field.elevation(12.3)


def test_heave_model_hand_values_and_terminal_sink_speed():
    heave = load_vehicle("bluerov2-heavy").heave
    derivative = heave_dynamics(np.array([-1.0, -0.1]), np.array([1.0, 1.0, 1.0, 1.0]), heave)
    # m w' = Zw w + Zww |w| w + sum F + net buoyancy
    expected = (-33.0 * -0.1 + -190.0 * 0.1 * -0.1 + 4.0 - 0.98) / 32.18
    np.testing.assert_allclose(derivative, [-0.1, expected], atol=1e-12)
    # No thrust: it sinks at the speed where drag balances -0.98 N.
    w = -(-33.0 + math.sqrt(33.0**2 + 4 * 190.0 * 0.98)) / (2 * 190.0)
    assert heave_dynamics(np.array([-1.0, w]), np.zeros(4), heave)[1] == pytest.approx(
        0.0, abs=1e-12
    )
    assert w < 0


def replay_errors(run_dir) -> float:
    info = json.loads((run_dir / "run.json").read_text())
    heave = info["plant"]["heave"]
    with open(run_dir / "log.csv", newline="") as handle:
        rows = list(csv.DictReader(handle))
    names = [c for c in rows[0] if c.startswith("Fz")]

    def rhs(_t, s, total):  # section 8 written out again, independently of auvmpc.models.vehicle
        w = s[1]
        force = heave["Zw"] * w + heave["Zww"] * abs(w) * w + total + heave["net_buoyancy_N"]
        return [w, force / heave["m_heave"]]

    worst = 0.0
    for k in range(len(rows) - 1):
        start = [float(rows[k]["z"]), float(rows[k]["w"])]
        total = sum(float(rows[k][n]) for n in names)
        span = (float(rows[k]["t"]), float(rows[k + 1]["t"]))
        end = solve_ivp(rhs, span, start, args=(total,), rtol=1e-10, atol=1e-12).y[:, -1]
        worst = max(worst, abs(end[0] - float(rows[k + 1]["z"])))
    return worst


@pytest.mark.slow
def test_calm_water_step_meets_the_papers_figures_and_replays(tmp_path):
    result = simulate(load_scenario("paper-depth-calm"))
    m = result.metrics
    assert m["steady_state_error_max_abs_m"] <= 0.005  # issue 5: calm water
    assert m["settling_time_0p05m_s"] <= 5.0
    assert m["thrust_limit_violations"] == 0 and m["thrust_rate_violations"] == 0
    assert m["max_z_m"] < 0.0
    write_run(result, tmp_path / "calm", figures=False)
    assert replay_errors(tmp_path / "calm") < DEPTH_REPLAY_TOL_M


@pytest.mark.slow
def test_wave_step_meets_the_papers_figures_and_our_goal():
    m = simulate(load_scenario("paper-depth-waves")).metrics
    assert m["settling_time_0p05m_s"] <= 5.0  # paper: about 5 s
    assert m["steady_state_error_max_abs_m"] <= 0.05  # paper: below 0.05 m
    assert m["steady_state_error_mean_abs_m"] <= 0.01  # our goal
    assert m["thrust_limit_violations"] == 0 and m["thrust_rate_violations"] == 0
    assert m["max_z_m"] < 0.0  # never above the surface


def test_unknown_buoyancy_is_estimated_not_known():
    resolved = load_scenario("paper-depth-calm", ["duration=30", "reference.step_time_s=5"])
    assert resolved.heave_plant.net_buoyancy_N == 1.0
    m = simulate(resolved).metrics
    assert m["steady_state_error_mean_abs_m"] < 0.005
    without = simulate(
        load_scenario(
            "paper-depth-calm",
            ["duration=30", "reference.step_time_s=5", "controller.offset_free=false"],
        )
    ).metrics
    # Without the estimate, 1 N of unknown buoyancy leaves a steady offset.
    assert without["steady_state_error_mean_abs_m"] > m["steady_state_error_mean_abs_m"]


def test_the_surface_is_a_constraint():
    # Ask for a depth just below the surface: the controller keeps its 0.1 m margin.
    m = simulate(
        load_scenario("paper-depth-calm", ["reference.final_depth_m=-0.02", "duration=30"])
    ).metrics
    assert m["max_z_m"] < -0.05
    assert m["thrust_limit_violations"] == 0 and m["thrust_rate_violations"] == 0


@pytest.mark.parametrize(
    ("override", "field"),
    [
        ("waves.height_m=-0.1", "waves.height_m"),
        ("waves.period_s=0", "waves.period_s"),
        ("waves.height_m=0.6", "waves.height_m"),  # breaks: steeper than 1/7
        ("reference.final_depth_m=-1.5", "reference.final_depth_m"),  # below the bottom
        ("reference.initial_depth_m=0.2", "reference.initial_depth_m"),  # above the surface
        ("tank.depth_m=-1", "tank.depth_m"),
        ("sensor.rate_hz=0", "sensor.rate_hz"),
        ("waves.colour=blue", "waves.colour"),
    ],
)
def test_bad_wave_and_tank_parameters_name_the_field(override, field):
    with pytest.raises(ConfigError) as caught:
        load_scenario("paper-depth-waves", [override])
    assert str(caught.value).startswith(field)


def test_depth_runs_in_the_shared_loop_with_a_registered_controller(tmp_path):
    """kind: depth uses sim.loop.closed_loop, the registry's depth-mpc inside the shell (same
    ``info`` keys as the horizontal controllers) and the log named by the DEPTH layout."""
    from auvmpc.controllers.registry import DEPTH_REGISTRY
    from auvmpc.controllers.shell import INFO_KEYS
    from auvmpc.experiments.run import make_controller
    from auvmpc.sim.log import DEPTH_LOG, SimLog

    resolved = load_scenario("paper-depth-calm", ["duration=12", "reference.step_time_s=2"])
    assert "depth-mpc" in DEPTH_REGISTRY
    controller = make_controller(resolved.scenario, resolved.model)
    result = controller.compute(
        Observation(k=0, t=0.0, state=np.array([-0.3]), reference=np.tile([-0.3, 0.0], (31, 1)))
    )
    assert set(INFO_KEYS) <= set(result.info)
    run = simulate(resolved)
    assert run.log.format is DEPTH_LOG
    assert run.log.layout.names == ("z", "w")
    write_run(run, tmp_path / "run", figures=False)
    header = (tmp_path / "run" / "log.csv").read_text().splitlines()[0].split(",")
    assert header == ["t", "z", "w", "z_ref", "Fz1", "Fz2", "solve_ms", "status",
                      "z_measured", "wave_force_N"]  # fmt: skip
    again = SimLog.read_csv(tmp_path / "run" / "log.csv", format=DEPTH_LOG)
    np.testing.assert_array_equal(again.state, run.log.state)
    np.testing.assert_array_equal(again.column("z_measured"), run.log.column("z_measured"))
    np.testing.assert_array_equal(again.thrust, run.log.thrust)
    # The same actuation metrics as a horizontal run, computed the same way.
    assert run.metrics["fallback_steps"] == run.metrics["solver_failures"] == 0


def test_each_kind_refuses_the_others_controller_in_one_line():
    with pytest.raises(ConfigError, match="controller.type"):
        load_scenario("paper-depth-calm", ["controller.type=mpc"])
    with pytest.raises(ConfigError, match="controller.type"):
        load_scenario("paper-ideal", ["controller.type=depth-mpc"])


def test_a_knob_of_the_other_depth_controller_type_is_refused_unless_an_override_retyped(
    tmp_path,
):
    """Each depth controller type's configuration holds its own knobs (a discriminated union
    on ``type``, as the horizontal one): the other type's is refused in one line naming it; a
    type changed by an override drops the old type's knobs and says so."""
    from auvmpc.controllers.playback import DepthPlaybackConfig

    table = tmp_path / "heave.csv"
    table.write_text("t,Fz1,Fz2\n0.0,0.0,0.0\n")
    with pytest.raises(
        ConfigError,
        match=r"^controller\.playback: a knob of thrust-playback, not of "
        "controller type depth-mpc",
    ):
        load_scenario("paper-depth-calm", [f"controller.playback.path={table}"])
    scenario = tmp_path / "heave.yaml"  # as `auvmpc excite --dof heave` writes it, plus ny
    scenario.write_text(
        "kind: depth\nname: heave\nduration: 1\nreference: {step_time_s: 0.5}\n"
        "controller: {type: thrust-playback, sample_time: 0.1, playback: {path: heave.csv}, "
        "prediction_horizon: 20}\n"
    )
    with pytest.raises(
        ConfigError,
        match=r"^controller\.prediction_horizon: a knob of depth-mpc, not of "
        "controller type thrust-playback",
    ):
        load_scenario(scenario)
    retyped = load_scenario(
        "paper-depth-calm", ["controller.type=thrust-playback", f"controller.playback.path={table}"]
    )
    assert isinstance(retyped.scenario.controller, DepthPlaybackConfig)
    assert retyped.notes[0] == (
        "controller.type: depth-mpc changed to thrust-playback by an override; dropped what "
        "thrust-playback has no knob for: prediction_horizon"
    )
    assert retyped.scenario.controller.sample_time == 0.1  # a knob both have: kept
    with pytest.raises(
        ConfigError, match=r"^depth_controller\.type: the 6-DOF depth channel is depth-mpc"
    ):
        load_scenario(
            "paper-6dof",
            ["depth_controller.type=thrust-playback", f"depth_controller.playback.path={table}"],
        )
