"""The remus100 preset against published numbers, flown open loop on the 6-DOF plant, and
its vehicle file's actuators: entries refused in one line when wrong.

Sources (docs/remus100.md): MSS is calibrated to Allen et al. (2000), 2.5 m/s at 1525 rpm;
its formulas give 1.5 m/s at 900 rpm (benchmarks/remus100_parameters.py). Prestero (2001):
positive rudder turns the vehicle to port, positive stern planes pitch it nose down.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import yaml

from auvmpc.errors import ConfigError
from auvmpc.models.six_dof import plant_step_length, six_dof_model, top_surge_speed
from auvmpc.models.vehicle import (
    VehicleParams,
    check_plant_scale,
    load_vehicle,
    scaled,
    vehicle_data,
)
from auvmpc.sim.plant import SixDofPlant
from tests.test_cli import run_cli

SAMPLE_S = 0.5
# Allen et al.'s 2.5 m/s at 1525 rpm: MSS's own drag and propeller, which the preset takes,
# hold 2.54 m/s there (1.6 % above, benchmarks/remus100_parameters.py); 2 % allows it.
TOP_SPEED_REL_TOL = 0.02
# 1.5 m/s at 900 rpm is MSS's formulas' own number (900.5 rpm): only the preset's rounding of
# the coefficients to three figures separates them; 0.5 % allows it.
SURVEY_SPEED_REL_TOL = 0.005
# The surge time constant at 1.5 m/s is m11 / (2 |X_uu| u) = 1.7 s: 30 s is 18 of them.
SETTLE_S = 30.0
# A tilt of 5 deg at 1.5 m/s decays to below this share of itself in 30 s (the slowest
# pitch mode at cruise e-folds in about 8 s: exp(-30 / 8) = 2 %).
TILT_LEFT_SHARE = 0.05
# Turn rate over the last 10 s of a 60 s rudder step: a steady turn, up to round-off of
# the compiled RK4 (measured 2e-8 rad/s at 20 deg).
STEADY_TURN_RATE_TOL = 1e-6


@pytest.fixture(scope="module")
def remus():
    return load_vehicle("remus100")


@pytest.fixture(scope="module")
def plant(remus):
    return SixDofPlant(remus, None, SAMPLE_S, plant_step_length(remus, 0.05))


def fly(plant, state, command, seconds):
    """The states at every sample of ``seconds`` of a held ``command`` (rpm, deg, deg)."""
    states = [np.asarray(state, dtype=float)]
    for k in range(round(seconds / SAMPLE_S)):
        states.append(plant.step(states[-1], np.asarray(command, dtype=float), k * SAMPLE_S))
    return np.array(states)


def cruising(plant, rpm=900.0):
    """The steady straight run at 10 m depth under ``rpm``, fins at zero."""
    start = np.zeros(12)
    start[2], start[6] = 10.0, 1.5
    return fly(plant, start, [rpm, 0.0, 0.0], SETTLE_S)[-1]


def test_steady_surge_speed_is_mss_calibration(plant):
    """900 rpm holds 1.5 m/s, 1525 rpm Allen et al.'s 2.5 m/s (MSS's pair of axial drag and
    propeller law); the straight run stays straight and level."""
    survey, top = cruising(plant, 900.0), cruising(plant, 1525.0)
    assert survey[6] == pytest.approx(1.5, rel=SURVEY_SPEED_REL_TOL)
    assert top[6] == pytest.approx(2.5, rel=TOP_SPEED_REL_TOL)
    for state in (survey, top):
        # no sway, no heave (the propeller torque heels it 0.4 to 1.1 deg: 0.2 mm/s of heave)
        assert abs(state[7]) < 1e-6 and abs(state[8]) < 1e-3
        # Neutral: no climb nor sink; measured 0.31 m over the 75 m run at 1525 rpm, where
        # the heel of 1.1 deg tilts the fins' lift.
        assert abs(state[2] - 10.0) < 0.5


def test_a_small_tilt_decays_at_rest_and_at_cruise(plant):
    """Passive roll and pitch stability: the centre of gravity 2 cm below the buoyancy's
    and the damping bring a 5 deg tilt back, at rest and at 1.5 m/s (where the roll settles
    on the propeller torque's own heel, 0.37 deg)."""
    tilt = math.radians(5.0)
    at_rest = np.zeros(12)
    at_rest[2] = 10.0
    cruise = cruising(plant)
    for start, rpm in ((at_rest, 0.0), (cruise, 900.0)):
        tilted = start.copy()
        tilted[3:5] += tilt
        end = fly(plant, tilted, [rpm, 0.0, 0.0], SETTLE_S)[-1]
        assert np.all(np.abs(end[3:5] - start[3:5]) < TILT_LEFT_SHARE * tilt)


@pytest.mark.parametrize("rudder_deg", [10.0, 20.0])
def test_positive_rudder_turns_to_port_in_a_steady_circle(plant, rudder_deg):
    """Prestero's sign: positive rudder lifts to starboard at the tail, the nose turns to
    port (negative yaw rate), into a steady turn. No published turning circle was found to
    compare with (docs/remus100.md): measured 47.6 m across at 10 deg, 20.5 m at 20 deg."""
    states = fly(plant, cruising(plant), [900.0, rudder_deg, 0.0], 60.0)
    rates = states[-20:, 11]
    assert np.all(rates < 0.0)
    assert np.ptp(rates) < STEADY_TURN_RATE_TOL
    assert states[-1, 5] < -math.pi  # more than half a turn to port
    speed = math.hypot(states[-1, 6], states[-1, 7])
    diameter = 2.0 * speed / abs(rates[-1])
    assert 10.0 < diameter < 100.0  # m: between 8 and 75 hull lengths


def test_positive_stern_planes_pitch_the_nose_down_and_dive(plant):
    start = cruising(plant)
    states = fly(plant, start, [900.0, 0.0, 5.0], 10.0)
    assert states[4, 4] < math.radians(-1.0)  # nose down within 2 s
    assert states[-1, 2] > start[2] + 0.3  # deeper (NED z down)


def test_the_plant_step_keeps_rk4_accurate_at_full_rudder_and_rpm(remus):
    """plant_step_length from the actuators' wrench at their limits: a full-rudder turn at
    top rpm agrees with a four times finer step to 1e-6 of its speed (the 3-DOF plant's
    accuracy against solve_ivp, tests/conftest.py)."""
    step = plant_step_length(remus, 0.05)
    assert step < 0.05  # the fins and the top speed decide it, not the default
    assert top_surge_speed(remus) == pytest.approx(2.54, abs=0.01)
    start = np.zeros(12)
    start[2], start[6] = 10.0, 2.5
    coarse, fine = (
        fly(SixDofPlant(remus, None, SAMPLE_S, h), start, [1525.0, 20.0, 20.0], 5.0)[-1]
        for h in (step, step / 4.0)
    )
    np.testing.assert_allclose(coarse[6:], fine[6:], atol=1e-6 * 2.5)


# -- the vehicle file -----------------------------------------------------------------------


def test_the_preset_flies_its_actuators_in_their_own_units(remus):
    inputs = remus.six_dof_actuators
    assert inputs.layout.names == ("propeller_rpm", "rudder_deg", "stern_planes_deg")
    np.testing.assert_array_equal(inputs.limits.lower, [0.0, -20.0, -20.0])
    np.testing.assert_array_equal(inputs.limits.upper, [1525.0, 20.0, 20.0])
    assert six_dof_model(remus).n_thrusters == 3
    # The 3-DOF coefficients it omits are the six_dof section's (horizontal_equivalent).
    assert remus.m11 == pytest.approx(30.48 + 0.93)
    assert remus.Iz_added == pytest.approx(4.88)
    assert {"actuators.rudder_deg.stall_angle", "actuators.propeller_rpm.rate"} <= set(
        remus.estimated
    )


def test_its_dump_round_trips_and_a_thruster_vehicle_dumps_as_before(remus):
    dumped = remus.model_dump()
    assert [entry["kind"] for entry in dumped["actuators"]] == [
        "propeller", "control_surface", "control_surface"
    ]  # fmt: skip
    again = VehicleParams.model_validate_json(remus.model_dump_json())
    assert again.model_dump_json() == remus.model_dump_json()
    thrusters = load_vehicle("bluerov2-heavy").model_dump()
    assert "actuators" not in thrusters and "actuator_entries" not in thrusters
    assert "without_munk_moments" not in thrusters["six_dof"]


@pytest.mark.parametrize(
    "needs",
    [
        lambda v: v.n_thrusters,
        lambda v: v.T,
        lambda v: v.T_pinv,
        lambda v: v.thrust_authority,
        lambda v: v.actuators,
        lambda v: v.thrust_max,
        lambda v: v.check_six_dof_layout(),
    ],
)
def test_what_needs_fixed_thrusters_refuses_it_in_one_line(remus, needs):
    with pytest.raises(ConfigError, match="^vehicle: has a propeller and fins.*six-dof-nmpc"):
        needs(remus)


@pytest.mark.parametrize("scenario", ["paper-ideal", "paper-depth-calm"])
def test_a_scenario_of_fixed_thrusters_refuses_it_with_exit_2(monkeypatch, capsys, scenario):
    code, _, err = run_cli(monkeypatch, capsys, "run", scenario, "--set", "vehicle=remus100")
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "has a propeller and fins" in lines[0]
    assert "'remus100'" in lines[0] and "six-dof-nmpc" in lines[0]


def with_entry(index, **changes):
    data, _ = vehicle_data("remus100")
    data["actuators"] = [dict(entry) for entry in data["actuators"]]
    data["actuators"][index].update(changes)
    return data


BAD_ENTRIES = [
    (with_entry(0, diameter=-0.14), "vehicle.actuators.0.propeller.propeller_rpm.diameter: "
     "-0.14, must be > 0"),
    (with_entry(0, kind="jet"), "vehicle.actuators.0: input tag 'jet'"),
    (with_entry(1, axis=[1.0, 0.0, 0.0]), "vehicle.actuators.1.control_surface.rudder_deg.axis: "
     r"\(1.0, 0.0, 0.0\), must be at right angles to x"),
    (with_entry(2, lower=30.0), "vehicle.actuators.2.control_surface.stern_planes_deg.lower: "
     "30.0, above upper 20.0"),
    (with_entry(2, name="rudder_deg"), "vehicle.actuators: input names must differ"),
    (with_entry(0, rpm=1.0), "vehicle.actuators.0.propeller.rpm: unknown key"),
]  # fmt: skip


@pytest.mark.parametrize(("data", "message"), BAD_ENTRIES)
def test_a_bad_actuator_entry_is_refused_in_one_line(data, message):
    with pytest.raises(ConfigError, match=f"^{message}"):
        load_vehicle(data)


def test_the_cli_refuses_a_bad_entry_with_exit_2(monkeypatch, capsys, tmp_path):
    path = tmp_path / "bad-remus.yaml"
    path.write_text(yaml.safe_dump(with_entry(1, axis=[1.0, 0.0, 0.0])))
    code, _, err = run_cli(monkeypatch, capsys, "run", "bluerov2-helix", "--set", f"vehicle={path}")
    assert code == 2
    assert err.strip().count("\n") == 0 and "must be at right angles to x" in err


def test_actuators_need_a_six_dof_section_and_exclude_thrusters():
    data, _ = vehicle_data("remus100")
    with pytest.raises(ConfigError, match="^vehicle.six_dof: missing: a vehicle with actuators"):
        load_vehicle({key: value for key, value in data.items() if key != "six_dof"})
    with pytest.raises(ConfigError, match="^vehicle.thrust_limits: not used with actuators"):
        load_vehicle({**data, "thrust_limits": [-10.0, 10.0]})


# -- model error ----------------------------------------------------------------------------


def test_a_six_dof_plant_scales_its_hydrodynamics(remus):
    """+20 % added mass and damping, -20 % inertia: each entry of the section, the mass (and
    so the weight) as it was."""
    plant = scaled(remus, {"added_mass": 1.2, "quadratic_damping": 1.2, "inertia": 0.8})
    np.testing.assert_allclose(
        plant.six_dof.added_mass_matrix, 1.2 * remus.six_dof.added_mass_matrix
    )
    np.testing.assert_allclose(plant.six_dof.quadratic_damping,
                               np.multiply(1.2, remus.six_dof.quadratic_damping))  # fmt: skip
    np.testing.assert_allclose(plant.six_dof.inertia_matrix, 0.8 * remus.six_dof.inertia_matrix)
    assert (
        plant.mass == remus.mass
        and plant.six_dof_actuators.layout == remus.six_dof_actuators.layout
    )
    check_plant_scale({"added_mass": 1.2, "linear_damping": 0.8}, "six-dof")
    with pytest.raises(ConfigError, match="^plant.scale.mass: the 6-DOF plant simulates"):
        check_plant_scale({"mass": 1.2}, "six-dof")
    with pytest.raises(ConfigError, match="^plant.scale.added_mass: a six_dof section field"):
        check_plant_scale({"added_mass": 1.2}, "horizontal")


def test_a_six_dof_scenario_takes_a_model_error():
    from auvmpc.scenario import load_scenario

    resolved = load_scenario("bluerov2-helix", ["plant.scale.added_mass=1.2"])
    np.testing.assert_allclose(resolved.plant.six_dof.added_mass_matrix,
                               1.2 * resolved.model.six_dof.added_mass_matrix)  # fmt: skip
    with pytest.raises(ConfigError, match="^plant.scale.m11: the 6-DOF plant simulates"):
        load_scenario("bluerov2-helix", ["plant.scale.m11=1.2"])
