"""6-DOF identification's roll and pitch model (issue 27, "6-DOF where the log has attitude
and rates"): its equations against the 6-DOF model's own, then the 6-DOF excite manoeuvre
simulated on the BlueROV2 Heavy with noisy attitude and rates, identified from a start 30 %
off in every roll and pitch parameter."""

from __future__ import annotations

import numpy as np
import pytest

from auvmpc.errors import ConfigError
from auvmpc.identification.estimation import identify
from auvmpc.identification.excitation import MAX_TILT_RAD, Dof, design_excitation
from auvmpc.identification.roll_pitch import (
    PARAMETERS,
    RollPitchGreyBox,
    roll_pitch_log,
    six_dof_fields,
)
from auvmpc.models.six_dof import SIX_DOF, integrate, plant_step_length, six_dof_model
from auvmpc.models.vehicle import load_vehicle
from auvmpc.sim.plant import substeps_for
from tests.conftest import ROUND_OFF_TOL

VEHICLE = "bluerov2-heavy"
# Short: the test's time, not the method's limit (40 s, of which 10 s fade in and out).
DURATION_S = 40.0
SAMPLE_TIME_S = 0.1
START_ERROR = 0.3
WITHIN = 0.1
# An AHRS's attitude (rad) and a gyro's and DVL's rates (rad/s, m/s).
ATTITUDE_NOISE_RAD = 0.002
RATE_NOISE = 0.005


def _start(truth):
    """The truth with each roll and pitch parameter START_ERROR off, alternately up and down."""
    values = RollPitchGreyBox(truth).start()
    signs = np.where(np.arange(len(values)) % 2 == 0, 1.0, -1.0)
    data = truth.model_dump(mode="json")
    wrong = dict(zip(PARAMETERS, values * (1 + START_ERROR * signs), strict=True))
    data["six_dof"] |= six_dof_fields(truth, wrong)
    return load_vehicle(data)


def test_roll_pitch_rows_are_the_six_dof_model():
    """At a tilted, moving state under thrust, the grey box's [phi', theta', p', q'] at the
    vehicle's own values is the 6-DOF model's (the same C_RB, C_A, g and kinematics)."""
    truth = load_vehicle(VEHICLE)
    rng = np.random.default_rng(3)
    state = np.concatenate([[1.0, 2.0, 5.0, 0.2, -0.15, 0.7], rng.normal(0, 0.3, 6)])
    thrust = rng.uniform(-20, 20, truth.six_dof.n_thrusters)
    expected = six_dof_model(truth).evaluate(state, thrust)
    # A log holding this state and thrust: its inputs are theirs.
    log = roll_pitch_log(
        "one", SAMPLE_TIME_S, np.tile(state, (20, 1)), np.tile(thrust, (19, 1)), truth
    )
    greybox = RollPitchGreyBox(truth)
    x = state[[SIX_DOF.index(name) for name in ("phi", "theta", "p", "q")]]
    derivative = np.asarray(greybox.rhs()(x, log.force[0], greybox.start())).ravel()
    rows = [SIX_DOF.index(name) for name in ("phi", "theta", "p", "q")]
    np.testing.assert_allclose(derivative, expected[rows], rtol=ROUND_OFF_TOL, atol=ROUND_OFF_TOL)


def test_six_dof_excite_identifies_roll_and_pitch():
    truth = load_vehicle(VEHICLE)
    excitation = design_excitation(truth, DURATION_S, SAMPLE_TIME_S, seed=0, box_m=5.0,
                                   dof=Dof.SIX_DOF)  # fmt: skip
    assert excitation.thrust.shape[1] == truth.six_dof.n_thrusters
    model = six_dof_model(truth)
    substeps = substeps_for(SAMPLE_TIME_S, plant_step_length(truth, SAMPLE_TIME_S))
    states = np.zeros((len(excitation.thrust) + 1, SIX_DOF.size))
    states[0, SIX_DOF.index("z")] = 5.0
    for k, row in enumerate(excitation.thrust):
        states[k + 1] = integrate(model, states[k], row, SAMPLE_TIME_S, substeps)
    tilt = np.abs(states[:, [SIX_DOF.index("phi"), SIX_DOF.index("theta")]])
    assert 0.1 < tilt.max() <= MAX_TILT_RAD  # roll and pitch moved, within the design's limit
    rng = np.random.default_rng(0)
    measured = states.copy()
    angles = [SIX_DOF.index(name) for name in ("phi", "theta")]
    rates = [SIX_DOF.index(name) for name in ("u", "v", "w", "p", "q", "r")]
    measured[:, angles] += rng.normal(0, ATTITUDE_NOISE_RAD, (len(states), 2))
    measured[:, rates] += rng.normal(0, RATE_NOISE, (len(states), 6))
    start = _start(truth)
    log = roll_pitch_log("sim", SAMPLE_TIME_S, measured, excitation.thrust, start)
    found = identify([log], start, greybox=RollPitchGreyBox(start))
    true_values = dict(zip(PARAMETERS, RollPitchGreyBox(truth).start(), strict=True))
    assert [p.name for p in found.parameters] == list(PARAMETERS)
    for estimate in found.parameters:
        value, (low, high) = true_values[estimate.name], estimate.ci95
        assert estimate.excited, estimate.name
        close = abs(estimate.value - value) <= WITHIN * abs(value)
        assert close or low <= value <= high, (estimate, value)
    assert np.all(found.validation_rms < 0.5 * found.validation_rms_start)


def test_a_log_too_slow_for_roll_and_pitch_is_refused():
    """A 6-DOF run's 0.5 s samples cannot follow the BlueROV2 Heavy's 1.5 s pitch period."""
    truth = load_vehicle(VEHICLE)
    state = np.zeros((121, SIX_DOF.size))
    thrust = np.ones((120, truth.six_dof.n_thrusters))
    log = roll_pitch_log("slow", 0.5, state, thrust, truth)
    with pytest.raises(ConfigError, match=r"sampled every 0.5 s: roll and pitch oscillate"):
        identify([log], truth, greybox=RollPitchGreyBox(truth))
