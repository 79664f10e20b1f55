"""`auvmpc vehicle new`: first estimates from size and mass against analytic values, the
written file loads as-is, refusals in one line, the `vehicles` listing, `plant.vehicle`, and
one short closed loop of an estimated model against the published plant. The full check on
three vehicles is benchmarks/vehicle_from_size.py."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from auvmpc.errors import ConfigError
from auvmpc.experiments.run import simulate
from auvmpc.models.from_size import (
    BOX_DRAG_COEFFICIENT,
    HullShape,
    ellipsoid_added_mass,
    estimate_vehicle,
    lamb_integrals,
)
from auvmpc.models.vehicle import VehicleSize, load_vehicle
from auvmpc.scenario import ResolvedScenario, validate_scenario
from tests.test_cli import run_cli

BLUEROV2_THRUSTERS = ["0.156,0.111,-45", "0.156,-0.111,45", "-0.156,0.111,-135",
                      "-0.156,-0.111,135"]  # fmt: skip
# Lamb (1918), table for a prolate spheroid of length / breadth 2: k1, k2, k'.
LAMB_2_TO_1 = (0.210, 0.704, 0.240)
LAMB_TABLE_TOL = 2e-3  # the table's three decimals


def _bluerov2_args(out: Path, *extra: str) -> list[str]:
    args = [
        "vehicle",
        "new",
        "my-rov",
        "--mass",
        "13.5",
        "--length",
        "0.457",
        "--width",
        "0.575",
        "--height",
        "0.254",
        "--thrust-limits=-40.2,51.5",
        "--out",
        str(out),
    ]
    return args + [f"--thruster={t}" for t in BLUEROV2_THRUSTERS] + list(extra)  # fmt: skip


def test_lamb_integrals_and_k_factors_match_the_sphere_and_lambs_table():
    assert sum(lamb_integrals(0.3, 0.7, 1.9)) == pytest.approx(2.0, rel=1e-12)
    sphere = ellipsoid_added_mass(0.2, 0.2, 0.2, displaced_mass=10.0)
    np.testing.assert_allclose(sphere, [5.0, 5.0, 5.0, 0.0, 0.0, 0.0], atol=1e-12)
    # Prolate spheroid a = 2 b: per displaced mass and per its I_y = m (a2 + b2) / 5.
    a, b = 2.0, 1.0
    added = ellipsoid_added_mass(a, b, b, displaced_mass=1.0)
    k1, k2, k_prime = added[0], added[1], added[5] / ((a * a + b * b) / 5.0)
    np.testing.assert_allclose((k1, k2, k_prime), LAMB_2_TO_1, atol=LAMB_TABLE_TOL)
    # Fossen 2021, sec. 8.4.2, written out independently: the closed form in e.
    e = math.sqrt(1.0 - (b / a) ** 2)
    log = math.log((1 + e) / (1 - e))
    alpha0 = 2 * (1 - e * e) / e**3 * (0.5 * log - e)
    beta0 = 1 / e**2 - (1 - e * e) / (2 * e**3) * log
    fossen = e**4 * (beta0 - alpha0) / ((2 - e * e) * (2 * e * e - (2 - e * e) * (beta0 - alpha0)))
    assert k1 == pytest.approx(alpha0 / (2 - alpha0), rel=1e-9)
    assert k_prime == pytest.approx(fossen, rel=1e-9)
    assert added[3] == pytest.approx(0.0, abs=1e-12)  # round about its axis


def test_a_cube_gets_half_its_displaced_mass_and_face_on_drag():
    side, mass, rho = 0.3, 27.0, 1000.0
    estimate = estimate_vehicle(
        "cube", mass, VehicleSize(length=side, width=side, height=side),
        [(0.1, 0.1, -45), (0.1, -0.1, 45), (-0.1, 0.1, -135), (-0.1, -0.1, 135)],
        (-10.0, 10.0), 20.0, shape=HullShape.BOX, top_speed=1.0,
    )  # fmt: skip
    params = estimate.params
    assert params.m11 == pytest.approx(1.5 * mass) and params.m22 == pytest.approx(1.5 * mass)
    assert params.Iz_added == pytest.approx(0.0, abs=1e-12)
    assert params.Iz_rb == pytest.approx(mass * 2 * side**2 / 12)
    assert params.Xuu == pytest.approx(-0.5 * rho * BOX_DRAG_COEFFICIENT * side**2)
    # Strips of the four side faces turning: -rho H (Cd L^4 + Cd W^4) / 64.
    assert params.Nrr == pytest.approx(-rho * side * BOX_DRAG_COEFFICIENT * 2 * side**4 / 64)
    assert params.Xu < 0 and params.Nr < 0 and "thrust_rate_limit" not in params.estimated


def test_the_written_file_loads_as_is_and_says_how_each_field_was_estimated(
    monkeypatch, capsys, tmp_path
):
    out = tmp_path / "my-rov.yaml"
    vertical = [f"--vertical-thruster={xy}" for xy in ("0.12,-0.218", "-0.12,-0.218",
                                                       "0.12,0.218", "-0.12,0.218")]  # fmt: skip
    code, stdout, stderr = run_cli(monkeypatch, capsys, *_bluerov2_args(out, *vertical,
                                                                          "--six-dof"))  # fmt: skip
    assert code == 0, stderr
    assert "auvmpc identify" in stdout
    vehicle = load_vehicle(out)
    assert vehicle.size.length == 0.457 and vehicle.heave.thruster_count == 4
    vehicle.check_six_dof_layout()
    text = out.read_text()
    data = yaml.safe_load(text)
    assert "auvmpc identify" in text
    estimated = set(data["estimated"])
    assert {"m11", "Iz_added", "Xuu", "Nrr", "thrust_rate_limit", "heave", "six_dof"} <= estimated
    commented = {line.split(":")[0] for line in text.splitlines() if "#" in line}
    assert estimated - {"heave", "six_dof"} <= commented  # each with a comment on how
    assert vehicle.thrust_rate_limit == pytest.approx(51.5 + 40.2)  # full range in 1 s


@pytest.mark.parametrize(
    ("extra", "expected"),
    [
        (["--thruster=1,2"], "--thruster: need X,Y,ANGLE_DEG"),
        (["--mass", "-3"], "--mass: must be a finite number > 0"),
        (["--height", "nan"], "--height: must be a finite number > 0"),
        (["--thrust-limits=5,1"], "--thrust-limits: need LOW < HIGH"),
        (["--top-speed", "0"], "--top-speed: must be a finite number > 0"),
        (["--six-dof"], "--six-dof: needs the vertical thrusters"),
        (["--shape", "torpedo"], "--shape: one of"),
    ],
)
def test_bad_input_is_refused_in_one_line_naming_the_option(
    monkeypatch, capsys, tmp_path, extra, expected
):
    code, _, stderr = run_cli(monkeypatch, capsys, *_bluerov2_args(tmp_path / "v.yaml", *extra))
    assert code == 2
    assert expected in stderr and "Traceback" not in stderr
    assert len(stderr.strip().splitlines()) == 1
    assert not (tmp_path / "v.yaml").exists()


def test_an_existing_file_is_never_replaced_without_overwrite(monkeypatch, capsys, tmp_path):
    out = tmp_path / "mine.yaml"
    out.write_text("my own notes\n")
    code, _, stderr = run_cli(monkeypatch, capsys, *_bluerov2_args(out))
    assert code == 2 and "--out: exists; add --overwrite" in stderr
    assert out.read_text() == "my own notes\n"
    code, _, stderr = run_cli(monkeypatch, capsys, *_bluerov2_args(tmp_path / "v.txt"))
    assert code == 2 and "--out: a vehicle file ends in .yaml" in stderr
    code, _, stderr = run_cli(monkeypatch, capsys, *_bluerov2_args(out, "--overwrite"))
    assert code == 0, stderr
    assert load_vehicle(out).name == "my-rov"


def test_vehicles_lists_mass_size_thrusters_and_models(monkeypatch, capsys):
    code, stdout, _ = run_cli(monkeypatch, capsys, "vehicles")
    assert code == 0
    row = next(line for line in stdout.splitlines() if "bluerov2-heavy" in line)
    assert "13.5" in row and "0.457 x 0.575 x 0.254" in row and "4 + 4 vertical" in row
    assert "3-DOF, depth, 6-DOF" in row
    row = next(line for line in stdout.splitlines() if "videoray-pro3" in line)
    assert "3.6" in row and "3-DOF" in row and "depth" not in row


def _figure_eight(model, plant, duration=60.0) -> dict:
    return {
        "name": "from-size", "duration": duration, "vehicle": model, "plant": {"vehicle": plant},
        "reference": {"type": "figure-eight", "center": [0, 0], "size": 8.0, "period": 160.0},
        "initial_state": [0.0, 0.0, 0.7853982, 0.0, 0.0, 0.0],
        "disturbance": {"water_current": {"velocity_m_per_s": [0.1, 0.05, 0.0]}},
        "transient_s": 30.0,
    }  # fmt: skip


def test_plant_vehicle_is_simulated_instead_of_the_model_and_must_fit_it(tmp_path):
    resolved = ResolvedScenario(
        validate_scenario(_figure_eight("jmse2210", "bluerov2-heavy")), tmp_path
    )
    assert resolved.model.name == "jmse2210" and resolved.plant.name == "bluerov2-heavy"
    with pytest.raises(ConfigError, match="plant.vehicle: has 2 horizontal thrusters"):
        ResolvedScenario(validate_scenario(_figure_eight("jmse2210", "videoray-pro3")), tmp_path)


def test_an_estimated_bluerov2_tracks_the_published_one(monkeypatch, capsys, tmp_path):
    """The one closed loop: the model from size on the published plant, 60 s with a current."""
    out = tmp_path / "bluerov2-from-size.yaml"
    code, _, stderr = run_cli(monkeypatch, capsys, *_bluerov2_args(out, "--thrust-rate-limit=60"))
    assert code == 0, stderr
    scenario = validate_scenario(_figure_eight(str(out), "bluerov2-heavy"))
    metrics = simulate(ResolvedScenario(scenario, tmp_path)).metrics
    assert metrics["verdict"] == "ok"
    assert metrics["rms_position_error_after_transient_m"] < 0.05
