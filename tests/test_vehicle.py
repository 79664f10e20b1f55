"""The 3-DOF model against hand-derived values and physical invariants."""

from __future__ import annotations

import math

import casadi as ca
import numpy as np
import pytest

from auvmpc.errors import ConfigError
from auvmpc.models.vehicle import (
    Thruster,
    VehicleParams,
    allocation_matrix,
    body_from_world,
    dynamics,
    load_vehicle,
    scaled,
)
from tests.conftest import ROUND_OFF_TOL

C = 1.0 / math.sqrt(2.0)


def test_paper_allocation_matrix_matches_spec(jmse):
    # paper-model.md section 1: rows [c c c c], [c -c -c c], [l -l l -l] with l = 0.30 m.
    length = 0.4243 * C
    expected = np.array([[C, C, C, C], [C, -C, -C, C], [length, -length, length, -length]])
    np.testing.assert_allclose(jmse.T, expected, atol=1e-12)


@pytest.mark.parametrize("preset", ["jmse2210", "bluerov2-heavy"])
def test_allocation_round_trip(preset):
    params = load_vehicle(preset)
    np.testing.assert_allclose(params.T @ params.T_pinv, np.eye(3), atol=1e-12)
    tau = np.array([12.0, -3.0, 0.7])
    np.testing.assert_allclose(params.T @ (params.T_pinv @ tau), tau, atol=1e-12)


def test_bluerov_yaw_arm_is_published_value(bluerov):
    # vehicles.md: each thruster gives a yaw arm of 0.1888 m.
    np.testing.assert_allclose(np.abs(bluerov.T[2]), 0.1888, atol=5e-5)


def test_three_thrusters_are_enough_two_are_underactuated_one_is_refused():
    three = (
        Thruster(position=(0.0, 0.0), angle_deg=0),
        Thruster(position=(0.5, 0.0), angle_deg=90),
        Thruster(position=(-0.5, 0.0), angle_deg=90),
    )
    assert np.linalg.matrix_rank(allocation_matrix(three)) == 3
    base = load_vehicle("jmse2210").model_dump()
    base["thrusters"] = [t.model_dump() for t in three]
    vehicle = VehicleParams.model_validate(base)
    assert vehicle.n_thrusters == 3 and not vehicle.underactuated
    base["thrusters"] = base["thrusters"][1:]  # two sideways thrusters: sway and yaw
    assert VehicleParams.model_validate(base).underactuated
    base["thrusters"] = base["thrusters"][:1]
    with pytest.raises(ValueError, match="thrusters"):
        VehicleParams.model_validate(base)


def test_collinear_layout_is_rejected(jmse):
    data = jmse.model_dump()
    data["thrusters"] = [{"position": (x, 0.0), "angle_deg": 0} for x in (0.3, 0.0, -0.3)]
    with pytest.raises(ValueError, match="spans only"):
        VehicleParams.model_validate(data)


def test_steady_surge_speed_where_thrust_equals_drag(jmse):
    # Equal forward thrust F0 on all four: surge force 4 c F0, no sway force, no moment.
    # Steady speed solves Xu u + Xuu u^2 + 4 c F0 = 0 (u > 0).
    f0 = 15.0
    force = 4 * C * f0
    speed = (-jmse.Xu - math.sqrt(jmse.Xu**2 - 4 * jmse.Xuu * force)) / (2 * jmse.Xuu)
    state = np.array([0.0, 0.0, 0.3, speed, 0.0, 0.0])
    derivative = dynamics(state, np.full(4, f0), jmse)
    np.testing.assert_allclose(derivative[3:], 0.0, atol=1e-12)
    np.testing.assert_allclose(derivative[:2], speed * np.array([math.cos(0.3), math.sin(0.3)]))
    assert speed == pytest.approx(1.75, abs=0.02)  # spec section 2: "a top speed near 1.75 m/s"


def test_kinetic_energy_only_dissipates_without_forces(jmse):
    # Coriolis/Munk terms do no work: d/dt(1/2 m11 u^2 + 1/2 m22 v^2 + 1/2 Iz r^2) equals the
    # damping power, which is <= 0.
    rng = np.random.default_rng(1)
    for _ in range(50):
        state = np.concatenate([rng.normal(size=3), rng.normal(scale=0.8, size=3)])
        u, v, r = state[3:]
        du, dv, dr = dynamics(state, np.zeros(4), jmse)[3:]
        power = jmse.m11 * u * du + jmse.m22 * v * dv + jmse.Iz * r * dr
        damping = (
            jmse.Xu * u**2 + jmse.Xuu * abs(u) * u**2 + jmse.Yv * v**2 + jmse.Yvv * abs(v) * v**2
            + jmse.Nr * r**2 + jmse.Nrr * abs(r) * r**2
        )  # fmt: skip
        assert power == pytest.approx(damping, abs=1e-12)
        assert power <= 0


def test_hand_computed_derivative(jmse):
    state = np.array([1.0, 2.0, 0.3, 1.0, 0.1, 0.2])
    derivative = dynamics(state, np.ones(4), jmse)
    # u' = (Xu + Xuu + m22 v r + 4c) / m11, v' = (Yv v + Yvv |v| v - m11 u r + 0) / m22,
    # r' = (Nr r + Nrr r^2 + (m11 - m22) u v + 0) / Iz
    expected_u = (-3.0 - 12.0 + 30.0 * 0.1 * 0.2 + 4 * C) / 18.0
    expected_v = (-8.0 * 0.1 - 35.0 * 0.01 - 18.0 * 0.2) / 30.0
    expected_r = (-1.5 * 0.2 - 2.5 * 0.04 + (18.0 - 30.0) * 0.1) / 2.0
    np.testing.assert_allclose(derivative[3:], [expected_u, expected_v, expected_r], atol=1e-12)


def test_current_rotation_into_body_frame():
    force = np.array([10.0, 5.0])
    np.testing.assert_allclose(body_from_world(force, 0.0), (10.0, 5.0))
    # Heading north (+y): the world +x force pushes the body to port (-y_body).
    np.testing.assert_allclose(body_from_world(force, math.pi / 2), (5.0, -10.0), atol=1e-12)
    for psi in np.linspace(-4, 4, 17):
        d_u, d_v = body_from_world(force, psi)
        assert math.hypot(d_u, d_v) == pytest.approx(math.hypot(*force))
        # Rotating the body force back by psi gives the world force.
        back = np.array(
            [d_u * math.cos(psi) - d_v * math.sin(psi), d_u * math.sin(psi) + d_v * math.cos(psi)]
        )
        np.testing.assert_allclose(back, force, atol=1e-12)


def test_symbolic_and_numeric_dynamics_agree(jmse):
    x, f, d = ca.SX.sym("x", 6), ca.SX.sym("f", 4), ca.SX.sym("d", 3)
    symbolic = ca.Function("f", [x, f, d], [dynamics(x, f, jmse, d)])
    rng = np.random.default_rng(2)
    for _ in range(20):
        state, thrust, dist = rng.normal(size=6), rng.uniform(-15, 15, 4), rng.normal(size=3)
        np.testing.assert_allclose(
            np.array(symbolic(state, thrust, dist)).ravel(),
            dynamics(state, thrust, jmse, dist),
            atol=ROUND_OFF_TOL,
        )


def test_scaling_separates_the_two_yaw_inertia_parts(jmse):
    plant = scaled(jmse, {"Iz_rb": 0.75, "Iz_added": 0.65})
    assert plant.Iz_rb == pytest.approx(0.975)
    assert plant.Iz_added == pytest.approx(0.455)
    assert plant.Iz == pytest.approx(0.975 + 0.455)
    assert plant.m11 == jmse.m11
    assert scaled(jmse, {"thrust_limits": 0.5}).thrust_limits == (-7.5, 7.5)


@pytest.mark.parametrize(
    ("scale", "match"),
    [({"thrusters": 2.0}, "plant.scale.thrusters"), ({"m11": -1.0}, "plant.scale.m11")],
)
def test_bad_scale_is_named(jmse, scale, match):
    with pytest.raises(ConfigError, match=match):
        scaled(jmse, scale)


def test_bad_vehicle_fields_name_the_field(jmse):
    data = jmse.model_dump()
    data["mass"] = -1.0
    with pytest.raises(ConfigError, match=r"vehicle\.mass.*-1\.0"):
        load_vehicle(data)
    data = jmse.model_dump()
    data["Xu"] = 3.0
    with pytest.raises(ConfigError, match=r"vehicle\.Xu"):
        load_vehicle(data)
    data = jmse.model_dump()
    data["thrust_limits"] = (15.0, -15.0)
    with pytest.raises(ConfigError, match="thrust_limits"):
        load_vehicle(data)
    with pytest.raises(ConfigError, match="unknown preset"):
        load_vehicle("no-such-vehicle")


def test_presets_state_source_and_estimates():
    for name in ("jmse2210", "bluerov2-heavy"):
        params = load_vehicle(name)
        assert params.source
        assert params.estimated
        assert set(params.estimated) <= set(VehicleParams.model_fields) | {"thrusters", "heave"}
