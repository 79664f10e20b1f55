"""Actuators (models/actuators/): the thruster's wrench against its formula, the 3-DOF,
heave and 6-DOF models' inputs as one description, the runtime effectiveness, and a kind
of one's own (examples/own_actuator.py) in NumPy and CasADi alike."""

from __future__ import annotations

import importlib.util
import math
import subprocess
import sys
from pathlib import Path

import casadi as ca
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from auvmpc.errors import FieldError
from auvmpc.models.actuators import WRENCH, ActuatorSet, FixedThruster
from auvmpc.models.vehicle import PLANAR_ROWS, dynamics, load_vehicle

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "own_actuator.py"
# Round-off of a handful of products and sums of O(1) numbers.
ROUND_OFF = 1e-12
LIMITS = {"lower": -10.0, "upper": 10.0, "rate": 5.0}
finite = st.floats(-2.0, 2.0, allow_nan=False)


@settings(max_examples=50, deadline=None)
@given(finite, finite, st.floats(-360.0, 360.0, allow_nan=False))
def test_a_planar_thruster_makes_the_allocation_column_of_the_vehicle_file(x, y, angle_deg):
    """interfaces.md: column [cos a, sin a, x sin a - y cos a]; no Z, K or M in the plane."""
    thruster = FixedThruster.planar("F1", (x, y), angle_deg, **LIMITS)
    a = math.radians(angle_deg)
    expected = [math.cos(a), math.sin(a), x * math.sin(a) - y * math.cos(a)]
    column = thruster.wrench(None, 1.0)
    np.testing.assert_allclose(column[[0, 1, 5]], expected, atol=ROUND_OFF)
    np.testing.assert_allclose(column[[2, 3, 4]], 0.0, atol=ROUND_OFF)


@pytest.mark.parametrize("name", ["jmse2210", "bluerov2-heavy"])
def test_the_models_inputs_are_one_description(name):
    """The 3-DOF allocation is the X, Y, N rows of the 6-DOF one's horizontal thrusters; the
    heave force is the vertical thrusters' -Z (z up); each input keeps its section's limits."""
    vehicle = load_vehicle(name)
    six = vehicle.six_dof_actuators
    n = vehicle.n_thrusters
    np.testing.assert_allclose(six.allocation(PLANAR_ROWS)[:, :n], vehicle.T, atol=1e-3)
    np.testing.assert_array_equal(-vehicle.heave.actuators.allocation(("Z",)), 1.0)
    assert six.layout.names == tuple(f"F{i + 1}" for i in range(six.size))
    assert vehicle.heave.actuators.layout.names[0] == "Fz1"
    heave = vehicle.heave
    np.testing.assert_array_equal(six.limits.lower[:n], vehicle.thrust_limits[0])
    np.testing.assert_array_equal(six.limits.lower[n:], heave.thrust_limits[0])
    np.testing.assert_array_equal(six.limits.rate[n:], heave.thrust_rate_limit)


def test_a_copy_with_new_limits_has_new_actuators():
    """A cached set must not outlive the fields it came from (config.StrictModel.model_copy)."""
    vehicle = load_vehicle("bluerov2-heavy")
    assert vehicle.actuators.limits.upper[0] == vehicle.thrust_limits[1]  # cached now
    copied = vehicle.model_copy(update={"thrust_limits": (-1.0, 2.0)})
    np.testing.assert_array_equal(copied.actuators.limits.upper, 2.0)
    np.testing.assert_array_equal(copied.six_dof_actuators.limits.upper[:4], 2.0)


def test_effectiveness_scales_each_thrusters_share_in_numpy_and_casadi():
    """A thruster at effectiveness e acts as its command times e; a dead one (0) not at all."""
    vehicle = load_vehicle("jmse2210")
    state = np.array([1.0, -2.0, 0.3, 0.4, -0.1, 0.05])
    command = np.array([8.0, -3.0, 5.0, 1.0])
    effectiveness = np.array([1.0, 0.0, 0.5, 1.0])
    degraded = dynamics(state, command, vehicle, effectiveness=effectiveness)
    np.testing.assert_array_equal(degraded, dynamics(state, command * effectiveness, vehicle))
    other = command.copy()
    other[1] = -15.0  # the dead thruster's command changes nothing
    np.testing.assert_array_equal(
        degraded, dynamics(state, other, vehicle, effectiveness=effectiveness)
    )
    x, f, e = ca.SX.sym("x", 6), ca.SX.sym("F", 4), ca.SX.sym("e", 4)
    symbolic = ca.Function("f", [x, f, e], [dynamics(x, f, vehicle, effectiveness=e)])
    np.testing.assert_allclose(
        np.array(symbolic(state, command, effectiveness)).ravel(), degraded, atol=ROUND_OFF
    )


@pytest.fixture(scope="module")
def own_kind():
    spec = importlib.util.spec_from_file_location("own_actuator", EXAMPLE)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up there
    spec.loader.exec_module(module)
    yield module
    sys.modules.pop(spec.name, None)


def test_a_kind_of_ones_own_is_one_file_and_flies_in_the_model(own_kind):
    """examples/own_actuator.py: reverse thrust at 0.78 of forward. Its force agrees in NumPy
    and CasADi, the vehicle's 3-DOF model takes it, and a set that is not linear refuses an
    allocation matrix by name rather than giving a wrong one."""
    vehicle = load_vehicle("bluerov2-heavy")
    ratio = 40.2 / 51.5
    thrusters = own_kind.asymmetric(vehicle.actuators, ratio)
    own = vehicle.with_actuators(thrusters)
    rng = np.random.default_rng(7)
    symbol, state_symbol = ca.SX.sym("F", 4), ca.SX.sym("x", 6)
    model = ca.Function("f", [state_symbol, symbol], [dynamics(state_symbol, symbol, own)])
    for _ in range(20):
        command = rng.uniform(-20.0, 20.0, 4)
        state = rng.uniform(-1.0, 1.0, 6)
        numeric = dynamics(state, command, own)
        np.testing.assert_allclose(np.array(model(state, command)).ravel(), numeric,
                                   atol=ROUND_OFF)  # fmt: skip
        # The same as the linear thrusters with the reverse commands scaled down.
        thrust = np.where(command >= 0.0, command, ratio * command)
        np.testing.assert_allclose(numeric, dynamics(state, thrust, vehicle), atol=ROUND_OFF)
    with pytest.raises(ValueError, match=r"actuators \['F1', 'F2', 'F3', 'F4'\] are not linear"):
        _ = own.T
    with pytest.raises(FieldError, match="need one per thruster"):
        vehicle.with_actuators(ActuatorSet(thrusters.actuators[:2]))
    assert WRENCH.names == ("X", "Y", "Z", "K", "M", "N")


def test_the_example_prints_the_same_force_from_numpy_and_casadi():
    run = subprocess.run([sys.executable, str(EXAMPLE)], capture_output=True, text=True, check=True)
    numpy_line, casadi_line = run.stdout.splitlines()
    numbers = [np.array(line.split(":")[1].strip(" []").split(), dtype=float)
               for line in (numpy_line, casadi_line)]  # fmt: skip
    np.testing.assert_allclose(numbers[0], numbers[1], atol=ROUND_OFF)
