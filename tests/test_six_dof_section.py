"""The vehicle file's ``six_dof`` section: optional, validated for physics, errors name the
field (one line, exit 2 from the CLI, like every other vehicle field)."""

from __future__ import annotations

import copy

import numpy as np
import pytest
import yaml

from auvmpc.errors import ConfigError, FieldError
from auvmpc.models.vehicle import load_vehicle
from tests.test_cli import run_cli


def bluerov_data() -> dict:
    return copy.deepcopy(load_vehicle("bluerov2-heavy").model_dump())


def with_six_dof(**changes) -> dict:
    data = bluerov_data()
    data["six_dof"].update(changes)
    return data


SYMMETRIC_INERTIA = [[0.26, 0.01, 0.0], [0.01, 0.23, 0.0], [0.0, 0.0, 0.37]]
ADDED_MATRIX = np.diag([-6.36, -7.12, -18.68, -0.189, -0.135, -0.222])


def added_with(i: int, j: int, value: float) -> list:
    matrix = ADDED_MATRIX.copy()
    matrix[i, j] = value
    return matrix.tolist()


def coupled_sway_yaw(value: float) -> list:
    """The diagonal added mass plus a symmetric sway-yaw coupling Y_rdot = N_vdot (as RexROV's)."""
    matrix = ADDED_MATRIX.copy()
    matrix[1, 5] = matrix[5, 1] = value
    return matrix.tolist()


BAD = [
    # (section changes, field named, reason)
    (
        {"center_of_buoyancy": [0.0, 0.0, 0.02]},
        "vehicle.six_dof.center_of_buoyancy",
        "must be above the centre of gravity",
    ),
    (
        {"center_of_buoyancy": [0.0, 0.0, 0.0]},  # coincident: no restoring moment either
        "vehicle.six_dof.center_of_buoyancy",
        "must be above",
    ),
    (
        {"inertia": [[0.26, 0.01, 0.0], [0.0, 0.23, 0.0], [0.0, 0.0, 0.37]]},
        "vehicle.six_dof.inertia",
        "must be symmetric",
    ),
    (
        {"inertia": [[0.26, 0.5, 0.0], [0.5, 0.23, 0.0], [0.0, 0.0, 0.37]]},
        "vehicle.six_dof.inertia",
        "positive definite",
    ),
    ({"inertia": [0.26, -0.23, 0.37]}, "vehicle.six_dof.inertia", "positive definite"),
    (
        {"added_mass": [-6.36, 7.12, -18.68, -0.189, -0.135, -0.222]},
        "vehicle.six_dof.added_mass",
        "negative or zero",
    ),
    ({"added_mass": added_with(0, 5, -0.3)}, "vehicle.six_dof.added_mass", "must be symmetric"),
    (
        {"added_mass": added_with(2, 2, 4.0)},  # M_A with a negative eigenvalue
        "vehicle.six_dof.added_mass",
        "positive semi-definite",
    ),
    (
        {"center_of_gravity": [0.0, 0.0, 0.5], "center_of_buoyancy": [0.0, 0.0, 0.4]},
        "vehicle.six_dof.inertia",  # 13.5 kg at 0.5 m: I about the CG is negative
        "mass matrix M_RB \\+ M_A is not positive definite",
    ),
    (
        {"linear_damping": [-13.7, 0.0, 33.0, 0.0, -0.8, 0.0]},
        "vehicle.six_dof.linear_damping.2",
        "less than or equal to 0",
    ),
    ({"displaced_volume": 0.0}, "vehicle.six_dof.displaced_volume", "greater than 0"),
    (
        {"thrusters": [{"position": [0, 0, 0], "direction": [0, 0, 0]}]},
        "vehicle.six_dof.thrusters.0.direction",
        "must not be zero",
    ),
    ({"thrusters": []}, "vehicle.six_dof.thrusters", "at least 1"),
    ({"mass_matrix": [1.0]}, "vehicle.six_dof.mass_matrix", "unknown key"),
]


@pytest.mark.parametrize(("changes", "field", "reason"), BAD)
def test_a_bad_section_is_rejected_naming_the_field(changes, field, reason):
    with pytest.raises(ConfigError, match=f"^{field}: .*{reason}"):
        load_vehicle(with_six_dof(**changes))


def test_good_variants_are_accepted():
    # Full matrices where the diagonal form is allowed; CG below the body origin.
    params = load_vehicle(
        with_six_dof(
            inertia=SYMMETRIC_INERTIA,
            added_mass=coupled_sway_yaw(-0.05),
            center_of_gravity=[0.0, 0.0, 0.02],
            center_of_buoyancy=[0.0, 0.0, -0.01],
        )
    )
    np.testing.assert_allclose(params.six_dof.inertia_matrix, SYMMETRIC_INERTIA)
    assert params.six_dof.added_mass_matrix[1, 5] == pytest.approx(0.05)  # M_A = -derivatives
    matrix = params.six_dof.mass_matrix(params.mass)
    np.testing.assert_allclose(matrix, matrix.T)
    assert params.six_dof.T.shape == (6, 8)


def test_a_vehicle_without_the_section_still_works_for_3dof_and_depth():
    data = bluerov_data()
    del data["six_dof"]
    params = load_vehicle(data)
    assert params.six_dof is None and params.heave is not None
    assert params.T.shape == (3, 4)


def test_the_cli_reports_a_bad_section_in_one_line_with_exit_2(monkeypatch, capsys, tmp_path):
    data = with_six_dof(center_of_buoyancy=[0.0, 0.0, 0.05])
    path = tmp_path / "sinking-cb.yaml"
    path.write_text(yaml.safe_dump(data))
    code, _, err = run_cli(monkeypatch, capsys, "run", "paper-ideal", "--set", f"vehicle={path}")
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert "six_dof.center_of_buoyancy" in lines[0] and "above the centre of gravity" in lines[0]


def test_six_dof_thrusters_must_start_with_the_horizontal_ones_in_order():
    """The 6-DOF loop sends the horizontal command to the first six_dof thrusters: two of
    them swapped would send every command to the wrong one."""
    data = bluerov_data()
    thrusters = list(data["six_dof"]["thrusters"])
    thrusters[0], thrusters[1] = thrusters[1], thrusters[0]
    data["six_dof"]["thrusters"] = thrusters
    with pytest.raises(FieldError, match="six_dof.thrusters"):
        load_vehicle(data).check_six_dof_layout()


def test_six_dof_vertical_thrusters_must_be_the_heave_sections():
    data = bluerov_data()
    data["six_dof"]["thrusters"] = data["six_dof"]["thrusters"][:-1]
    with pytest.raises(FieldError, match="heave.thruster_count"):
        load_vehicle(data).check_six_dof_layout()


def test_a_six_dof_scenario_refuses_a_mismatched_layout_in_one_line(tmp_path):
    from auvmpc.scenario import load_scenario

    data = bluerov_data()
    thrusters = list(data["six_dof"]["thrusters"])
    thrusters[0], thrusters[1] = thrusters[1], thrusters[0]
    data["six_dof"]["thrusters"] = thrusters
    path = tmp_path / "swapped.yaml"
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(ConfigError, match="vehicle.six_dof.thrusters"):
        load_scenario("bluerov2-helix", [f"vehicle={path}"])
