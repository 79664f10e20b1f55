"""Actuator effectiveness as a runtime input of the controllers (issue 25 item 1, the seam of
issue 26's faults): told through ``Session.effectiveness`` (Observation.effectiveness), a
dead thruster is neither predicted to push nor allocated to, and nothing is rebuilt."""

from __future__ import annotations

import numpy as np
import pytest

import auvmpc
from auvmpc.controllers.baseline import BaselineConfig
from auvmpc.controllers.channels import ThrustMapping
from auvmpc.controllers.tracking_law import LAW_OUTPUTS, tracking_law
from auvmpc.errors import ConfigError
from auvmpc.models.integrators import rk4
from auvmpc.models.vehicle import dynamics, load_vehicle

# paper-ideal's vehicle (jmse2210) without its third thruster: the other three still span
# surge, sway and yaw.
DEAD_THIRD = np.array([1.0, 1.0, 0.0, 1.0])
# 20 s of paper-ideal against a plant whose third thruster is dead (RK4, 10 substeps):
# position RMS measured 0.221 m (nmpc), 0.239 m (mpc), 0.233 m (ltv-mpc) with the
# controller told, 0.395, 0.286, 0.360 m without; the bar is above the told runs.
TOLD_RMS_M = 0.3
# What the damped least squares of the faulted allocation leaves of the asked force
# (tracking_law._ALLOCATION_DAMPING ~1e-9 relative), N.
ALLOCATION_TOL_N = 1e-6


def _run(controller: str, told: bool) -> tuple[np.ndarray, float]:
    """Commands (steps, 4) and position RMS (m) of 20 s against the faulted plant."""
    resolved = auvmpc.load_scenario("paper-ideal", ["duration=20"], controller=controller)
    session = auvmpc.session(resolved)
    if told:
        session.effectiveness = DEAD_THIRD
    model, state, commands, errors = resolved.model, session.initial_state, [], []
    for k in range(round(session.duration / session.sample_time)):
        t = k * session.sample_time
        u = session.step(t, state).u
        commands.append(u)
        state = rk4(
            lambda x, f: dynamics(x, f, model, effectiveness=DEAD_THIRD),
            state, u, session.sample_time, 10,
        )  # fmt: skip
        reference = session.reference.states(np.array([t + session.sample_time]))[0]
        errors.append(np.hypot(*(state[:2] - reference[:2])))
    return np.array(commands), float(np.sqrt(np.mean(np.square(errors))))


@pytest.mark.parametrize("controller", ["mpc", "ltv-mpc"])
def test_a_dead_thruster_told_is_not_commanded_and_tracking_holds(controller):
    """The thrust penalty is on the absolute thrust: a thruster the prediction says moves
    nothing costs without helping, so the optimiser leaves it at zero. (nmpc: the same in
    tests/test_export_c.py, whose run the exported C replays; its build takes 2 s.)"""
    commands, rms = _run(controller, told=True)
    assert np.abs(commands[:, 2]).max() == 0.0
    assert rms < TOLD_RMS_M
    untold, untold_rms = _run(controller, told=False)
    assert np.abs(untold[:, 2]).max() > 1.0, "without being told it pushes a dead thruster"
    assert rms < untold_rms


def test_the_tracking_law_allocates_nothing_to_a_dead_thruster():
    vehicle = load_vehicle("jmse2210")
    law = tracking_law(vehicle, 0.5, BaselineConfig())
    state = np.array([0.5, -0.4, 0.2, 0.1, 0.05, -0.02])
    now, ahead = np.zeros(6), np.array([0.1, 0.0, 0.0, 0.2, 0.0, 0.0])
    outputs = {
        e: dict(zip(LAW_OUTPUTS, law(state, now, ahead, np.zeros(3), np.array(e)), strict=True))
        for e in ((1.0, 1.0, 1.0, 1.0), tuple(DEAD_THIRD), (1.0, 0.5, 1.0, 1.0))
    }
    healthy = outputs[(1.0, 1.0, 1.0, 1.0)]
    tau = np.asarray(healthy["tau"]).ravel()
    np.testing.assert_allclose(
        np.asarray(healthy["requested"]).ravel(), vehicle.T_pinv @ tau, rtol=1e-12
    )
    for e, out in outputs.items():
        requested = np.asarray(out["requested"]).ravel()
        acting = vehicle.T @ (np.array(e) * requested)
        np.testing.assert_allclose(acting, tau, rtol=0, atol=ALLOCATION_TOL_N)
    assert float(outputs[tuple(DEAD_THIRD)]["requested"][2]) == 0.0
    assert float(outputs[tuple(DEAD_THIRD)]["thrust"][2]) == 0.0


def test_a_dead_vertical_thruster_gets_no_heave_share():
    vehicle = load_vehicle("bluerov2-heavy")
    mapping = ThrustMapping(vehicle, 0.1)
    vertical = vehicle.six_dof.n_thrusters - vehicle.n_thrusters
    effectiveness = np.ones(vertical)
    effectiveness[0] = 0.0
    healthy, faulted = mapping.vertical(20.0), mapping.vertical(20.0, effectiveness)
    heave_row = np.asarray(vehicle.six_dof.T)[2, vehicle.n_thrusters :]
    assert faulted[0] == 0.0
    assert heave_row @ (effectiveness * faulted) == pytest.approx(heave_row @ healthy)


@pytest.mark.parametrize(
    ("values", "reason"),
    [([1.0, 1.0], "one value per input"), ([1.0, 1.0, 1.5, 1.0], "between 0 and 1"),
     ([1.0, 1.0, float("nan"), 1.0], "between 0 and 1"), (["dead"] * 4, "numbers")],
)  # fmt: skip
def test_a_bad_effectiveness_is_one_line_naming_the_field(values, reason):
    session = auvmpc.session(auvmpc.load_scenario("paper-ideal", ["duration=2"]))
    with pytest.raises(ConfigError, match=f"^effectiveness: .*{reason}"):
        session.effectiveness = values
    assert session.effectiveness is None, "a refused value changes nothing"
    session.effectiveness = DEAD_THIRD
    np.testing.assert_array_equal(session.effectiveness, DEAD_THIRD)
