"""Heave identification (issue 27, the depth model): the model and its regression against
analytic truth, then excite -> simulate -> identify from a start file 30 % off on two
vehicles of very different size: the BlueROV2 Heavy (32 kg in heave) through the CLI and a
depth run folder (its noisy pressure sensor alone), the RexROV (5.5 t) through the library
from a noisy depth and heave rate."""

from __future__ import annotations

import json

import numpy as np
import pytest
import yaml

from auvmpc.controllers.playback import read_thrust_table
from auvmpc.identification.estimation import identify
from auvmpc.identification.excitation import Dof, design_excitation, simulate_heave_open_loop
from auvmpc.identification.heave import FIELDS, PARAMETERS, HeaveGreyBox
from auvmpc.identification.logs import VelocityLog
from auvmpc.models.heave import heave_dynamics
from auvmpc.models.vehicle import load_vehicle
from tests.conftest import ROUND_OFF_TOL
from tests.test_cli import run_cli

# Short manoeuvres in a small box of depth: the test's time, not the method's limit.
DURATION_S = 30.0
BOX_M = 3.0
# Every parameter of the start file this far off the truth, alternately up and down.
START_ERROR = 0.3
# The bar: an excited parameter within 10 % of the truth, or its interval covers it.
WITHIN = 0.1
# lstsq on exact derivatives: round-off in a four-column regression.
EXACT_REGRESSION_REL_TOL = 1e-9
# Thrust rate per sample within round-off of the limit.
LIMIT_TOL_N = 1e-6  # the table is written to 1e-6 N
# A DVL's heave rate (m/s) and a pressure sensor's depth (m): the library round trip's noise.
RATE_NOISE_M_PER_S = 0.005
DEPTH_NOISE_M = 0.002


def _start_file(truth, tmp_path=None):
    """The truth with each heave parameter START_ERROR off (up, down, up, down)."""
    heave = {
        name: getattr(truth.heave, name) * (1 + START_ERROR if i % 2 == 0 else 1 - START_ERROR)
        for i, name in enumerate(FIELDS)
    }
    start = truth.model_copy(update={"heave": truth.heave.model_copy(update=heave)})
    if tmp_path is None:
        return start
    data = truth.model_dump(mode="json")
    data["heave"] |= heave
    path = tmp_path / "start.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def _assert_found(parameters: dict, truth) -> None:
    """Every parameter excited, and within WITHIN of the truth or inside its interval."""
    assert set(parameters) == set(PARAMETERS)
    for name, entry in parameters.items():
        true_value = getattr(truth.heave, name.removeprefix("heave."))
        low, high = entry["ci95"]
        assert entry["excited"], name
        assert abs(entry["value"] - true_value) <= WITHIN * abs(true_value) or (
            low <= true_value <= high
        ), (name, entry, true_value)


def test_the_heave_model_is_the_depth_model_and_its_regression_is_exact():
    """The identified model is models/heave.py's, and with exact derivatives (analytic
    truth) the regression returns the vehicle's parameters to round-off."""
    truth = load_vehicle("bluerov2-heavy")
    greybox = HeaveGreyBox(truth)
    rng = np.random.default_rng(0)
    states = rng.normal(scale=[1.0, 0.3], size=(50, 2))
    thrust = rng.normal(scale=20.0, size=(50, truth.heave.thruster_count))
    pairs = list(zip(states, thrust, strict=True))
    expected = np.array([heave_dynamics(x, f, truth.heave) for x, f in pairs])
    rhs = greybox.rhs()
    got = np.array([np.asarray(rhs(x, f.sum(), greybox.start())).ravel() for x, f in pairs])
    np.testing.assert_allclose(got, expected, rtol=0, atol=ROUND_OFF_TOL)
    A, b = greybox.regression(states, expected, thrust.sum(axis=1, keepdims=True))
    theta, *_ = np.linalg.lstsq(A.reshape(-1, 4), b.ravel(), rcond=None)
    np.testing.assert_allclose(theta, greybox.start(), rtol=EXACT_REGRESSION_REL_TOL)


def test_excite_run_identify_heave_from_the_depth_sensor(tmp_path, monkeypatch, capsys):
    """BlueROV2 Heavy through the CLI: ``excite --dof heave`` writes a depth scenario whose
    table stays inside the vertical thrusters' limits and the box; ``run`` plays it on the
    depth plant with its pressure sensor; ``identify`` sees a depth run's log.csv, reads
    the sensor's depth alone and writes the heave section."""
    truth = load_vehicle("bluerov2-heavy")
    heave = truth.heave
    scenario = tmp_path / "excite.yaml"
    code, _, err = run_cli(monkeypatch, capsys, "excite", "bluerov2-heavy", "--dof", "heave",
                           "--out", str(scenario), "--duration", str(DURATION_S),
                           "--box", str(BOX_M))  # fmt: skip
    assert code == 0, err
    assert yaml.safe_load(scenario.read_text())["kind"] == "depth"
    names = heave.actuators.layout.names
    thrust = read_thrust_table(tmp_path / "excite.csv", 0.1, names)
    low, high = heave.thrust_limits
    assert thrust.min() >= low - LIMIT_TOL_N and thrust.max() <= high + LIMIT_TOL_N
    steps = np.diff(np.vstack([np.zeros(len(names)), thrust]), axis=0)
    assert np.abs(steps).max() <= heave.thrust_rate_limit * 0.1 + LIMIT_TOL_N
    assert np.abs(thrust[-1]).max() <= LIMIT_TOL_N  # faded out: it ends at rest
    assert np.abs(thrust).max() > 0.2 * min(-low, high)  # and it does excite
    run = tmp_path / "run"
    code, _, err = run_cli(monkeypatch, capsys, "run", str(scenario), "--out", str(run),
                           "--no-figures")  # fmt: skip
    assert code == 0, err
    metrics = json.loads((run / "run.json").read_text())["metrics"]
    start_depth = -(BOX_M + 1.0)  # DEPTH_MARGIN_M below the box's top
    assert start_depth - BOX_M <= metrics["min_z_m"] and metrics["max_z_m"] <= start_depth + BOX_M
    assert metrics["thrust_limit_violations"] == metrics["thrust_rate_violations"] == 0
    out = tmp_path / "identified" / "vehicle.yaml"
    code, text, err = run_cli(monkeypatch, capsys, "identify", str(run), "--vehicle",
                              str(_start_file(truth, tmp_path)), "--out", str(out))  # fmt: skip
    assert code == 0, err
    found = json.loads((out.parent / "identification.json").read_text())
    _assert_found(found["parameters"], truth)
    assert set(found["validation_rms"]) == {"z"}  # the sensor's depth, not the true w
    assert found["validation_rms"]["z"] < found["validation_rms_start"]["z"]
    identified = load_vehicle(str(out))  # loads as-is, the identified values in its heave
    for name, entry in found["parameters"].items():
        field = name.removeprefix("heave.")
        assert getattr(identified.heave, field) == pytest.approx(entry["value"], rel=1e-5)
        assert name in identified.estimated
    assert "held-out RMS z" in text
    # What identify cannot do with a heave log: one line each.
    for args, message in (
        (["--vehicle", "videoray-pro3"], "has no heave section"),
        (["--vehicle", "bluerov2-heavy", "--then-run", "paper-ideal"], "--then-run"),
        (["--vehicle", "bluerov2-heavy", "--dof", "sideways"], "--dof: one of auto"),
        (["--vehicle", "bluerov2-heavy", "--current"], "--current: the heave model has no"),
        (["--vehicle", "bluerov2-heavy", "--thrust-gain", "--fix", "heave.Zw"], "no current or"),
        (["--vehicle", "bluerov2-heavy", "--fix", "m11"], "--fix: not a parameter identify"),
    ):
        code, _, err = run_cli(monkeypatch, capsys, "identify", str(run), *args, "--out",
                               str(tmp_path / "refused.yaml"))  # fmt: skip
        assert code == 2 and err.count("\n") == 1 and message in err, err
    assert not (tmp_path / "refused.yaml").exists()


def test_identify_heave_of_a_work_class_rov_from_depth_and_heave_rate():
    """RexROV (5.5 t in heave, 170 times the BlueROV2's) through the library: the manoeuvre
    simulated as the depth plant steps it, a noisy depth and heave rate, a start 30 % off."""
    truth = load_vehicle("rexrov")
    excitation = design_excitation(truth, DURATION_S, box_m=BOX_M, dof=Dof.HEAVE)
    assert excitation.excursion_m <= BOX_M
    states = simulate_heave_open_loop(truth, excitation.thrust, excitation.sample_time)
    rng = np.random.default_rng(1)
    measured = states + rng.normal(size=states.shape) * [DEPTH_NOISE_M, RATE_NOISE_M_PER_S]
    outputs = ("z", "w")
    log = VelocityLog("rexrov", excitation.sample_time, measured, excitation.thrust,
                      outputs=outputs)  # fmt: skip
    start = _start_file(truth)
    found = identify([log], start, greybox=HeaveGreyBox(start, outputs))
    _assert_found({p.name: {"value": p.value, "ci95": p.ci95, "excited": p.excited}
                   for p in found.parameters}, truth)  # fmt: skip
    np.testing.assert_array_less(found.validation_rms, found.validation_rms_start)
