"""Vehicles whose thrusters cannot make every body-frame force (issue 10, item 2), and the
new presets (items 2 and 3)."""

from __future__ import annotations

import numpy as np
import pytest

from auvmpc.controllers.baseline import BaselineController
from auvmpc.controllers.config import BaselineConfig, ControllerConfig
from auvmpc.controllers.ltv import LtvMpc
from auvmpc.controllers.mpc import PaperMpc
from auvmpc.controllers.registry import retyped
from auvmpc.errors import ConfigError
from auvmpc.models.vehicle import (
    Thruster,
    VehicleParams,
    allocation_matrix,
    allocation_rank,
    load_vehicle,
)

# Round-off of 3x2 / 3x4 products of unit vectors and arms below 1 m.
ALLOCATION_TOL = 1e-12


def with_thrusters(base: VehicleParams, thrusters) -> VehicleParams:
    data = base.model_dump()
    data["thrusters"] = thrusters
    return VehicleParams.model_validate(data)


def test_two_stern_thrusters_make_surge_and_yaw_but_no_sway(jmse):
    # Thrusters at (-0.5, +-0.1) pointing forward: columns (1, 0, 0.1) and (1, 0, -0.1)
    # (moment px sin a - py cos a = -py); they span surge and yaw, sway is missing.
    stern = with_thrusters(
        jmse,
        [{"position": (-0.5, -0.1), "angle_deg": 0}, {"position": (-0.5, 0.1), "angle_deg": 0}],
    )
    np.testing.assert_allclose(stern.T, [[1, 1], [0, 0], [0.1, -0.1]], atol=ALLOCATION_TOL)
    assert allocation_rank(stern.T) == 2
    assert stern.underactuated
    np.testing.assert_allclose(stern.unactuated_direction, [0, 1, 0], atol=ALLOCATION_TOL)
    assert stern.describe_actuation() == "underactuated: no sway"


def test_a_tilted_pair_misses_a_mixed_direction_that_no_thrust_reaches(jmse):
    pair = with_thrusters(
        jmse,
        [{"position": (0.3, 0.2), "angle_deg": 30}, {"position": (-0.4, -0.1), "angle_deg": 100}],
    )
    missing = pair.unactuated_direction
    assert pair.underactuated and np.linalg.norm(missing) == pytest.approx(1.0)
    thrusts = np.random.default_rng(0).uniform(-15, 15, size=(50, 2))
    np.testing.assert_allclose((pair.T @ thrusts.T).T @ missing, 0.0, atol=ALLOCATION_TOL * 15)
    assert pair.describe_actuation().startswith("underactuated: no ")
    assert "sway" in pair.describe_actuation()  # a mix of all three axes, named


@pytest.mark.parametrize("preset", ["jmse2210", "bluerov2-heavy", "rexrov"])
def test_four_thruster_presets_are_fully_actuated(preset):
    vehicle = load_vehicle(preset)
    assert not vehicle.underactuated and vehicle.unactuated_direction is None
    assert vehicle.describe_actuation() == "fully actuated"


def test_a_layout_that_can_only_push_is_refused(jmse):
    data = jmse.model_dump()
    data["thrusters"] = [{"position": (-0.5, 0.0), "angle_deg": 0}] * 2  # no yaw, no sway
    with pytest.raises(ConfigError, match="vehicle.thrusters: the layout spans only 1"):
        load_vehicle(data)


def test_allocation_rank_ignores_round_off_but_not_geometry():
    stern = allocation_matrix([Thruster(position=(-0.5, y), angle_deg=0) for y in (0.1, -0.1)])
    # A third column that is the sum of the first two up to round-off adds no direction.
    noisy = np.column_stack([stern, stern.sum(axis=1) + 1e-15])
    assert allocation_rank(stern) == allocation_rank(noisy) == 2
    assert allocation_rank(np.zeros((3, 2))) == 0


def test_videoray_pro3_preset_is_the_published_two_thruster_vehicle():
    vehicle = load_vehicle("videoray-pro3")
    assert vehicle.n_thrusters == 2 and vehicle.describe_actuation() == "underactuated: no sway"
    # Wang 2006 added mass on top of the (estimated) rigid body; damping as published.
    assert vehicle.m11 - vehicle.mass == pytest.approx(1.94)
    assert vehicle.m22 - vehicle.mass == pytest.approx(6.05)
    assert vehicle.Iz_added == 0.0118
    assert (vehicle.Xu, vehicle.Xuu, vehicle.Yv, vehicle.Yvv, vehicle.Nr, vehicle.Nrr) == (
        -0.95, -6.04, -5.87, -30.73, -0.023, -0.45,
    )  # fmt: skip
    assert "Wang 2006" in vehicle.source and "mass" in vehicle.estimated


def test_rexrov_allocation_matches_uuv_simulator_tam():
    # uuv_thruster_manager/config/rexrov/TAM.yaml, thrusters 4-7, rows surge, sway (y to
    # port) and yaw (z up): our y is to starboard and our z down, so rows 2 and 3 flip.
    tam_surge = [0.7071068613706476, 0.7071068613706476, -0.7071065406341925, -0.7071065406341925]
    tam_sway_port = [
        0.7071067010024383,
        -0.7071067010024383,
        0.7071070217388206,
        -0.7071070217388206,
    ]
    tam_yaw_up = [-0.6487987634902757, 0.6487987634902757, 0.6487987335687417, -0.6487987335687417]
    rexrov = load_vehicle("rexrov")
    expected = np.array([tam_surge, np.negative(tam_sway_port), np.negative(tam_yaw_up)])
    # The TAM was computed from poses rounded to 1e-6 m and 1e-2 deg: 1e-6 covers it.
    np.testing.assert_allclose(rexrov.T, expected, atol=1e-6)
    assert rexrov.mass == 1862.87 and rexrov.m11 == pytest.approx(1862.87 + 779.79)
    assert rexrov.Iz == pytest.approx(691.23 + 224.32)


def test_controllers_that_need_full_actuation_refuse_an_underactuated_vehicle():
    vehicle = load_vehicle("videoray-pro3")
    config = ControllerConfig(type="mpc", sample_time=0.5)
    with pytest.raises(
        ConfigError, match=r"vehicle: underactuated: no sway; controller baseline needs full"
    ):
        BaselineController(vehicle, 0.5, BaselineConfig())
    with pytest.raises(
        ConfigError, match=r"vehicle: underactuated: no sway; controller mpc needs full .*'videoray"
    ):
        PaperMpc(vehicle, config)
    # ltv-mpc linearises along its plan, whose heading turns: it accepts the vehicle.
    assert LtvMpc(vehicle, retyped(config, "ltv-mpc", jit=False))


def test_the_frozen_heading_model_cannot_move_an_underactuated_vehicle_sideways():
    # Why the paper's mpc refuses: its SDC pair (A(x), B) on a straight (r = 0) has a
    # controllability matrix of rank 4 of 6 without sway thrust (sway and the lateral
    # position are out of reach), rank 6 with the fully actuated vehicle.
    from auvmpc.models.sdc import input_matrix, sdc_matrix

    state = np.array([0.0, 0.0, 0.3, 0.5, 0.0, 0.0])

    def rank(vehicle):
        A, B = sdc_matrix(state, vehicle), input_matrix(vehicle)
        blocks = [np.linalg.matrix_power(A, i) @ B for i in range(6)]
        return np.linalg.matrix_rank(np.hstack(blocks))

    assert rank(load_vehicle("videoray-pro3")) == 4
    assert rank(load_vehicle("jmse2210")) == rank(load_vehicle("bluerov2-heavy")) == 6
