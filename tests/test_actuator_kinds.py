"""The propeller and the control surface (models/actuators/) against their formulas: thrust and
torque go with n|n| and fall with the advance ratio, fin lift is odd in the angle, zero at
zero and stops growing past stall, moments are arm x force, NumPy and CasADi agree, a mixed
set sums its members, and a fin with Prestero's lift reproduces his fin derivatives."""

from __future__ import annotations

import math
from dataclasses import replace

import casadi as ca
import numpy as np
import pytest

from auvmpc.errors import FieldError
from auvmpc.models.actuators import ActuatorSet, ControlSurface, FixedThruster, Propeller
from tests.conftest import ROUND_OFF_TOL

RHO = 1026.0  # kg/m3, Fossen's MSS remus100.m
# A REMUS 100-like propeller: MSS remus100.m's diameter, bollard K_T, K_Q and their slopes.
PROPELLER = Propeller("propeller_rpm", (-0.8, 0.0, 0.05), (1.0, 0.0, 0.0), 0.14, 0.4566, 0.0700,
                      RHO, -1525.0, 1525.0, 500.0)  # fmt: skip
ADVANCING = Propeller("propeller_rpm", (-0.8, 0.0, 0.0), (1.0, 0.0, 0.0), 0.14, 0.4566, 0.0700,
                      RHO, -1525.0, 1525.0, 500.0, thrust_slope=(0.1798 - 0.4566) / 0.6632,
                      torque_slope=(0.0312 - 0.0700) / 0.6632, wake_fraction=0.056,
                      thrust_deduction=0.1)  # fmt: skip
STALL = math.radians(15.0)
RUDDER = ControlSurface("rudder_deg", (-0.7, 0.0, 0.02), (0.0, 0.0, 1.0), 0.0133, 3.0, STALL, RHO,
                        -20.0, 20.0, 30.0, drag_coefficient=0.01,
                        induced_drag_factor=0.1)  # fmt: skip
PLANES = ControlSurface("stern_planes_deg", (-0.7, 0.0, 0.0), (0.0, 1.0, 0.0), 0.0133, 3.0, STALL,
                        RHO, -20.0, 20.0, 30.0)  # fmt: skip
AHEAD = np.array([1.5, 0.0, 0.0, 0.0, 0.0, 0.0])  # straight ahead through still water


def test_propeller_thrust_and_torque_follow_the_n_abs_n_law():
    """T = rho D^4 K_T n|n|, Q = rho D^5 K_Q n|n| (n in rev/s), along the shaft, at its place."""
    for rpm in (1200.0, -900.0):
        n = rpm / 60.0
        thrust = RHO * 0.14**4 * 0.4566 * n * abs(n)
        torque = RHO * 0.14**5 * 0.0700 * n * abs(n)
        wrench = PROPELLER.wrench(AHEAD, rpm)
        position = np.array(PROPELLER.position)
        expected_moment = np.cross(position, [thrust, 0.0, 0.0]) + [torque, 0.0, 0.0]
        np.testing.assert_allclose(wrench, [thrust, 0, 0, *expected_moment], rtol=ROUND_OFF_TOL)
    np.testing.assert_array_equal(PROPELLER.wrench(AHEAD, 0.0), 0.0)


def test_propeller_thrust_falls_with_the_advance_ratio_as_mss_writes_it():
    """Forward: K_T(J) = K_T0 + K_T' J, J = (1 - w) u / (n D), the hull feels (1 - t) T;
    reverse: the bollard K_T0 whatever the speed. At 2.5 m/s and 1525 rpm (REMUS 100's top
    speed in MSS remus100.m) that is 41.2 N."""
    n = 1525.0 / 60.0
    advance_ratio = 0.944 * 2.5 / (n * 0.14)
    k_t = 0.4566 + (0.1798 - 0.4566) / 0.6632 * advance_ratio
    moving = np.array([2.5, 0.0, 0.0, 0.0, 0.0, 0.0])
    thrust, _ = ADVANCING.thrust_and_torque(moving, 1525.0)
    assert thrust == pytest.approx(RHO * 0.14**4 * k_t * n**2, rel=ROUND_OFF_TOL)
    assert ADVANCING.wrench(moving, 1525.0)[0] == pytest.approx(0.9 * thrust, rel=ROUND_OFF_TOL)
    assert 0.9 * thrust == pytest.approx(41.2, abs=0.05)
    assert ADVANCING.thrust_and_torque(moving, -600.0) == pytest.approx(
        PROPELLER.thrust_and_torque(AHEAD, -600.0), rel=ROUND_OFF_TOL
    )


def test_fin_lift_is_zero_at_zero_odd_in_the_angle_and_stops_growing_past_stall():
    lift = [RUDDER.lift_and_drag(AHEAD, angle)[0] for angle in (-40.0, -15.0, -5.0, 0.0, 5.0,
                                                                15.0, 40.0)]  # fmt: skip
    assert lift[3] == 0.0
    np.testing.assert_allclose(lift[:3], -np.array(lift[:3:-1]), rtol=ROUND_OFF_TOL)
    slope = 0.5 * RHO * 0.0133 * 3.0 * 1.5**2  # q C_La u^2, per radian
    assert lift[4] == pytest.approx(slope * math.radians(5.0), rel=ROUND_OFF_TOL)
    assert lift[6] == pytest.approx(lift[5], rel=ROUND_OFF_TOL)  # 40 deg: held at 15 deg's
    assert lift[5] == pytest.approx(slope * STALL, rel=ROUND_OFF_TOL)
    drag = [RUDDER.lift_and_drag(AHEAD, angle)[1] for angle in (-10.0, 10.0)]
    assert drag[0] == pytest.approx(drag[1], rel=ROUND_OFF_TOL)  # even in the angle


def test_fin_force_turns_with_its_axis_and_its_moments_are_arm_cross_force():
    """A rudder about +z lifts to starboard, stern planes about +y lift up (NED: -Z)."""
    rudder, planes = RUDDER.wrench(AHEAD, 10.0), PLANES.wrench(AHEAD, 10.0)
    assert rudder[1] > 0.0 and rudder[2] == 0.0 and planes[2] < 0.0 and planes[1] == 0.0
    assert rudder[5] < 0.0 and planes[4] < 0.0  # aft fins: bow to port, nose down
    rng = np.random.default_rng(3)
    for _ in range(5):
        nu_r = np.concatenate([rng.uniform(0.5, 2.0, 1), rng.uniform(-0.3, 0.3, 5)])
        for fin in (RUDDER, PLANES):
            wrench = fin.wrench(nu_r, rng.uniform(-25.0, 25.0))
            moment = np.cross(fin.position, wrench[:3])
            np.testing.assert_allclose(wrench[3:], moment, atol=ROUND_OFF_TOL)


def test_numpy_and_casadi_agree_and_a_mixed_set_is_the_sum_of_its_members():
    thruster = FixedThruster("F1", (0.0, 0.2, 0.0), (0.0, 1.0, 0.0), -10.0, 10.0, 5.0)
    members = (ADVANCING, RUDDER, PLANES, thruster)
    actuators = ActuatorSet(members)
    assert not actuators.linear
    assert actuators.layout.names == ("propeller_rpm", "rudder_deg", "stern_planes_deg", "F1")
    np.testing.assert_array_equal(actuators.limits.rate, [500.0, 30.0, 30.0, 5.0])
    nu, u, e = ca.SX.sym("nu", 6), ca.SX.sym("u", 4), ca.SX.sym("e", 4)
    symbolic = ca.Function("tau", [nu, u, e], [actuators.force(nu, u, effectiveness=e)])
    rng = np.random.default_rng(5)
    for _ in range(10):
        nu_r = np.concatenate([rng.uniform(-0.5, 2.5, 1), rng.uniform(-0.5, 0.5, 5)])
        command = rng.uniform([-1525.0, -30.0, -30.0, -10.0], [1525.0, 30.0, 30.0, 10.0])
        effectiveness = rng.uniform(0.0, 1.0, 4)
        shares = zip(members, command, effectiveness, strict=True)
        total = sum(e_i * member.wrench(nu_r, c_i) for member, c_i, e_i in shares)
        numeric = actuators.force(nu_r, command, effectiveness=effectiveness)
        np.testing.assert_allclose(numeric, total, rtol=ROUND_OFF_TOL, atol=ROUND_OFF_TOL)
        np.testing.assert_allclose(np.array(symbolic(nu_r, command, effectiveness)).ravel(),
                                   numeric, rtol=ROUND_OFF_TOL, atol=ROUND_OFF_TOL)  # fmt: skip
    # The OCP differentiates the force: finite at rest too, where a fin has no flow.
    jacobian = ca.Function("J", [nu, u], [ca.jacobian(actuators.force(nu, u), ca.vertcat(nu, u))])
    assert np.all(np.isfinite(np.array(jacobian(np.zeros(6), np.zeros(4)))))


def test_a_fin_with_prestero_lift_gives_his_fin_derivatives():
    """Prestero (2001), Table C.10, REMUS: Y_uudr = 9.64 kg/(m rad) and N_uudr = -6.15 kg/rad
    give the lift q C_La and the arm x_fin = N_uudr / Y_uudr; the flow-angle derivatives
    Y_uvf, Y_urf, N_uvf, N_urf (and Z, M for the planes) must follow as he tabulates them."""
    y_uudr, arm = 9.64, -6.15 / 9.64
    area = 2.0 * y_uudr / (1030.0 * 1.0)  # q C_La = Y_uudr at rho 1030, C_La 1 per rad
    rudder = ControlSurface("rudder_deg", (arm, 0.0, 0.0), (0.0, 0.0, 1.0), area, 1.0, 0.5,
                            1030.0, -20.0, 20.0, 30.0)  # fmt: skip
    planes = ControlSurface("stern_planes_deg", (arm, 0.0, 0.0), (0.0, 1.0, 0.0), area, 1.0, 0.5,
                            1030.0, -20.0, 20.0, 30.0)  # fmt: skip
    u, small = 1.5, 0.01

    def per(fin, nu_r, angle_rad, rows):
        return fin.wrench(np.array(nu_r, dtype=float), math.degrees(angle_rad))[list(rows)]

    # Each derivative: the force over the product of the velocities (and angle) it multiplies.
    derived = {
        "Yuudr": per(rudder, [u, 0, 0, 0, 0, 0], small, [1])[0] / (u * u * small),
        "Nuudr": per(rudder, [u, 0, 0, 0, 0, 0], small, [5])[0] / (u * u * small),
        "Yuvf": per(rudder, [u, small, 0, 0, 0, 0], 0.0, [1])[0] / (u * small),
        "Yurf": per(rudder, [u, 0, 0, 0, 0, small], 0.0, [1])[0] / (u * small),
        "Nuvf": per(rudder, [u, small, 0, 0, 0, 0], 0.0, [5])[0] / (u * small),
        "Nurf": per(rudder, [u, 0, 0, 0, 0, small], 0.0, [5])[0] / (u * small),
        "Zuuds": per(planes, [u, 0, 0, 0, 0, 0], small, [2])[0] / (u * u * small),
        "Muuds": per(planes, [u, 0, 0, 0, 0, 0], small, [4])[0] / (u * u * small),
        "Zuwf": per(planes, [u, 0, small, 0, 0, 0], 0.0, [2])[0] / (u * small),
        "Zuqf": per(planes, [u, 0, 0, 0, small, 0], 0.0, [2])[0] / (u * small),
        "Muwf": per(planes, [u, 0, small, 0, 0, 0], 0.0, [4])[0] / (u * small),
        "Muqf": per(planes, [u, 0, 0, 0, small, 0], 0.0, [4])[0] / (u * small),
    }
    table_c10 = {"Yuudr": 9.64, "Nuudr": -6.15, "Yuvf": -9.64, "Yurf": 6.15, "Nuvf": 6.15,
                 "Nurf": -3.93, "Zuuds": -9.64, "Muuds": -6.15, "Zuwf": -9.64, "Zuqf": -6.15,
                 "Muwf": -6.15, "Muqf": -3.93}  # fmt: skip
    for name, value in table_c10.items():
        # His table has three figures: 0.5 % covers the last one (3.92 for -6.15^2 / 9.64).
        assert derived[name] == pytest.approx(value, rel=5e-3), name


@pytest.mark.parametrize(
    ("kind", "changes", "message"),
    [
        (PROPELLER, {"diameter": 0.0}, r"propeller_rpm\.diameter: 0\.0, must be > 0"),
        (PROPELLER, {"direction": (1.0, 1.0, 0.0)}, r"propeller_rpm\.direction: .*must be a unit"),
        (RUDDER, {"axis": (1.0, 0.0, 0.0)}, r"rudder_deg\.axis: \(1\.0, 0\.0, 0\.0\), must be at"),
        (RUDDER, {"lower": 30.0}, r"rudder_deg\.lower: 30\.0, above upper 20\.0"),
    ],
)
def test_a_kind_refuses_a_bad_field_by_name(kind, changes, message):
    with pytest.raises(FieldError, match=message):
        replace(kind, **changes)
