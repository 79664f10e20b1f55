"""The torpedo's LOS + PID autopilot (controllers/los_pid.py): the LOS geometry against its
formula, the sign conventions on the remus100 preset (Prestero's: positive rudder turns to
port, positive planes pitch the nose down), the hard limits in a short closed loop, and the
refusal of a vehicle without a propeller and fins."""

from __future__ import annotations

import math

import numpy as np
import pytest

from auvmpc.controllers.base import Observation
from auvmpc.controllers.channels import ReferenceWithDepth
from auvmpc.controllers.los_pid import LosPid, LosPidConfig, los_heading, nearest_on_path
from auvmpc.controllers.registry import build_controller, controller_config
from auvmpc.errors import ConfigError
from auvmpc.models import six_dof
from auvmpc.models.vehicle import load_vehicle
from auvmpc.references import LawnmowerConfig, make_reference

TORPEDO = "remus100"
CRUISE_M_PER_S = 1.5
CRUISE_RPM = 900.0  # holds 1.5 m/s (docs/remus100.md)
# Rounding of the limits' own arithmetic: a command beyond its box or rate by more is a breach.
LIMIT_SLACK = 1e-9


def test_los_heading_on_a_straight_path_is_fossens_formula():
    """A path along +x: a vehicle 2 m starboard (+y) of it is 2 m of cross-track error and
    steered atan(2 / Delta) to port; along +y the starboard side is -x; a vehicle behind
    the path's first point still gets the path's line."""
    along_x = np.array([[0.0, 0.0], [5.0, 0.0], [10.0, 0.0]])
    point = nearest_on_path(along_x, np.zeros(3), np.array([4.0, 2.0]))
    assert point.tangent == 0.0 and point.cross_track == pytest.approx(2.0)
    assert los_heading(point, 4.0) == pytest.approx(-math.atan(0.5))
    along_y = along_x[:, ::-1]
    point = nearest_on_path(along_y, np.zeros(3), np.array([3.0, 6.0]))
    assert point.tangent == pytest.approx(math.pi / 2) and point.cross_track == pytest.approx(-3.0)
    assert los_heading(point, 4.0) == pytest.approx(math.pi / 2 + math.atan(0.75))
    behind = nearest_on_path(along_x, np.zeros(3), np.array([-7.0, -1.0]))
    assert behind.tangent == 0.0 and behind.cross_track == pytest.approx(-1.0)
    # a reference holding still: its heading and its point
    still = nearest_on_path(np.zeros((3, 2)), np.full(3, math.pi), np.array([1.0, 1.0]))
    assert still.tangent == math.pi and still.cross_track == pytest.approx(-1.0)


def _cruising(y: float = 0.0, z: float = 10.0) -> np.ndarray:
    state = np.zeros(six_dof.SIX_DOF.size)
    state[six_dof.SIX_DOF.index("y")] = y
    state[six_dof.SIX_DOF.index("z")] = z
    state[six_dof.SIX_DOF.index("u")] = CRUISE_M_PER_S
    return state


def _straight_rows(controller: LosPid, depth: float = 10.0) -> np.ndarray:
    """Preview rows [x, y, psi, u, v, r, z, z'] of a path along +x at cruise speed."""
    n = controller.preview_steps + 1
    rows = np.zeros((n, 8))
    rows[:, 0] = CRUISE_M_PER_S * controller.sample_time * np.arange(n)
    rows[:, 3], rows[:, 6] = CRUISE_M_PER_S, depth
    return rows


def test_a_vehicle_starboard_of_the_path_is_steered_to_port_and_one_too_shallow_dives():
    """5 m starboard of a path along north, 2 m above its depth: the heading setpoint is to
    port, the rudder positive (Prestero: positive turns to port) and the planes positive
    (nose down). Flown 8 s on the plant, it has turned to port and closed on the path."""
    vehicle = load_vehicle(TORPEDO)
    controller = LosPid(vehicle, LosPidConfig())
    state = _cruising(y=5.0, z=8.0)
    controller.reset(state, np.array([CRUISE_RPM, 0.0, 0.0]))
    result = controller.compute(Observation(0, 0.0, state, _straight_rows(controller)))
    rpm, rudder, planes = result.thrust
    assert result.info["heading_setpoint_rad"] < 0.0 and rudder > 0.0
    assert result.info["pitch_setpoint_rad"] < 0.0 and planes > 0.0
    model = six_dof.six_dof_model(vehicle)
    te = controller.sample_time
    for k in range(1, round(8.0 / te)):
        state = six_dof.integrate(model, state, result.thrust, te, 5)
        rows = _straight_rows(controller)
        rows[:, 0] += CRUISE_M_PER_S * k * te
        result = controller.compute(Observation(k, k * te, state, rows))
    assert state[six_dof.SIX_DOF.index("psi")] < 0.0
    assert abs(state[six_dof.SIX_DOF.index("y")]) < 4.0
    assert state[six_dof.SIX_DOF.index("z")] > 8.5


def test_an_mss_rudder_turning_the_other_way_is_commanded_the_other_way():
    """Signs come from the model: the remus100 with its rudder's axis flipped (MSS's
    convention, positive rudder to starboard) gets a negative rudder where the preset gets a
    positive one, and the same heading setpoint."""
    data = load_vehicle(TORPEDO).model_dump()
    data["actuators"][1]["axis"] = (0.0, 0.0, -1.0)
    flipped = type(load_vehicle(TORPEDO)).model_validate(data)
    commands = []
    for vehicle in (load_vehicle(TORPEDO), flipped):
        controller = LosPid(vehicle, LosPidConfig())
        state = _cruising(y=5.0)
        controller.reset(state, np.array([CRUISE_RPM, 0.0, 0.0]))
        result = controller.compute(Observation(0, 0.0, state, _straight_rows(controller)))
        commands.append(result.thrust[1])
    assert commands[0] > 0.0 and commands[1] == pytest.approx(-commands[0])


def test_commands_stay_within_each_inputs_box_and_rate():
    """10 s of a lawnmower at 10 m in a 0.3 m/s cross current, started 6 m off the path and
    3 m shallow with the propeller stopped: every command within its box, every change
    within its rate (rpm from 0 meets the rate limit, the fins their angle limit)."""
    vehicle = load_vehicle(TORPEDO)
    controller = LosPid(vehicle, LosPidConfig())
    limits = vehicle.six_dof_actuators.limits
    reference = ReferenceWithDepth(make_reference(
        LawnmowerConfig(leg_length=100.0, spacing=45.0, legs=2, speed=CRUISE_M_PER_S,
                        depths_m=(10.0,))
    ))  # fmt: skip
    model = six_dof.six_dof_model(vehicle)
    state = _cruising(y=-6.0, z=7.0)
    previous = np.zeros(3)
    controller.reset(state, previous)
    te = controller.sample_time
    moves = []
    for k in range(round(10.0 / te)):
        rows = reference.states(k * te + te * np.arange(controller.preview_steps + 1))
        command = controller.compute(Observation(k, k * te, state, rows)).thrust
        assert np.all(command >= limits.lower - LIMIT_SLACK)
        assert np.all(command <= limits.upper + LIMIT_SLACK)
        assert np.all(np.abs(command - previous) <= limits.rate * te + LIMIT_SLACK)
        moves.append(np.abs(command - previous))
        previous = command
        state = six_dof.integrate(model, state, command, te, 5,
                                  held_current=np.array([0.0, 0.3, 0.0]))  # fmt: skip
    moves = np.array(moves)
    assert moves[:, 0].max() == pytest.approx(limits.rate[0] * te)  # the rpm rate was met


def test_a_thruster_vehicle_is_refused_in_one_line():
    """Built as a scenario builds it (the registry's ``los-pid``): one line naming the field
    and what the vehicle lacks (the CLI prints it and exits 2)."""
    config = controller_config({"type": "los-pid"})
    with pytest.raises(ConfigError, match="^controller.type: .*fixed thrusters") as caught:
        build_controller(config, load_vehicle("bluerov2-heavy"))
    assert "\n" not in str(caught.value) and caught.value.value == "los-pid"
