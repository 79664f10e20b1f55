"""Defaults that transfer (docs/tuning.md): what a scenario leaves out is tuned for its vehicle,
recorded, and means the same on a 4 kg and a 1.9 t vehicle; the paper scenarios keep the
paper's settings."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from auvmpc.controllers.config import (
    DEFAULT_VEHICLE_RADIUS_M,
    THRUST_MOVE_COST,
    ControllerConfig,
    ControllerType,
    ThrustPenalty,
)
from auvmpc.estimation import ObserverConfig
from auvmpc.experiments.run import simulate
from auvmpc.models.integrators import rk4_step
from auvmpc.models.random_vehicles import random_vehicle
from auvmpc.models.vehicle import (
    dynamics,
    load_vehicle,
    scaled,
    stable_plant_step,
    thruster_preset_names,
)
from auvmpc.scenario import (
    DEFAULT_PLANT_STEP_S,
    ResolvedDepthScenario,
    ResolvedScenario,
    builtin_scenarios,
    load_scenario,
    validate_scenario,
)

PAPER_R = (0.01, 0.01, 0.01, 0.01)
# The paper vehicle's former fixed estimator tuning, which the authority fractions stay near:
# prior X, Y 20 N and N 2 N m, random walk 1 N/sqrt(s) and 0.05 N m/sqrt(s).
FORMER_PRIOR = (20.0, 20.0, 2.0)
FORMER_RATE = (1.0, 1.0, 0.05)
FORMER_TUNING_RTOL = 0.11  # measured: 6 % (X, Y) and 10 % (N) away
PAPER_VEHICLE_RADIUS_M = 0.5  # r_auv, paper-model.md section 7


@pytest.mark.parametrize("preset", thruster_preset_names())
def test_default_thrust_weight_prices_a_half_range_move_the_same_on_every_vehicle(preset):
    model = load_vehicle(preset)
    config = ControllerConfig().for_vehicle(model)
    half_range = (model.thrust_max - model.thrust_min) / 2.0
    np.testing.assert_allclose(np.array(config.R) * half_range**2, THRUST_MOVE_COST, rtol=1e-12)
    assert len(config.R) == model.n_thrusters
    assert config.thrust_penalty is ThrustPenalty.INCREMENT


def test_estimator_statistics_scale_with_the_thrusters():
    """Ten times stronger thrusters, ten times larger prior and random walk: the force scale
    is the vehicle's, not a number of newtons."""
    model = load_vehicle("bluerov2-heavy")
    stronger = scaled(model, {"thrust_limits": 10.0})
    base, strong = (ObserverConfig().for_vehicle(m) for m in (model, stronger))
    np.testing.assert_allclose(
        strong.initial_disturbance_std, 10 * np.array(base.initial_disturbance_std)
    )
    np.testing.assert_allclose(
        strong.disturbance_rate_std, 10 * np.array(base.disturbance_rate_std)
    )


def test_paper_vehicle_keeps_about_its_former_estimator_tuning():
    tuned = ObserverConfig().for_vehicle(load_vehicle("jmse2210"))
    np.testing.assert_allclose(tuned.initial_disturbance_std, FORMER_PRIOR, rtol=FORMER_TUNING_RTOL)
    np.testing.assert_allclose(tuned.disturbance_rate_std, FORMER_RATE, rtol=FORMER_TUNING_RTOL)


def test_given_settings_are_kept():
    given = ControllerConfig(
        R=(0.5,), observer={"initial_disturbance_std": (1, 2, 3), "disturbance_rate_std": (4, 5, 6)}
    )
    tuned = given.for_vehicle(load_vehicle("rexrov"))
    assert tuned.R == (0.5,)
    assert tuned.observer.initial_disturbance_std == (1, 2, 3)
    assert tuned.observer.disturbance_rate_std == (4, 5, 6)


def test_underactuated_vehicle_gets_a_planar_force_scale():
    """Two stern thrusters push no sway force; the world-frame current still needs a prior."""
    model = load_vehicle("videoray-pro3")
    assert model.thrust_authority[1] == pytest.approx(0.0, abs=1e-9)
    tuned = ObserverConfig().for_vehicle(model)
    assert tuned.initial_disturbance_std[0] == tuned.initial_disturbance_std[1] > 0


def test_a_loaded_scenario_records_the_values_it_runs_with():
    data = {
        "name": "defaults",
        "duration": 10.0,
        "vehicle": "rexrov",
        "reference": {"type": "circle", "radius": 12.0, "speed": 0.3},
        "initial_state": [12.0, 0.0, 1.5707963, 0.0, 0.0, 0.0],
    }
    controller = ResolvedScenario(validate_scenario(data), Path.cwd()).scenario.controller
    assert controller.R is not None and controller.model_substeps is not None
    assert controller.observer.initial_disturbance_std is not None
    assert controller.observer.disturbance_rate_std is not None


@pytest.mark.parametrize("name", ["paper-ideal", "paper-disturbed", "paper-obstacles"])
def test_paper_scenarios_keep_the_papers_weights(name):
    resolved = load_scenario(name)
    controller = resolved.scenario.controller
    assert controller.R == PAPER_R
    assert controller.thrust_penalty is ThrustPenalty.ABSOLUTE
    # the paper's r_auv as written, not the one from the vehicle's size (0.51 m)
    assert controller.vehicle_radius == PAPER_VEHICLE_RADIUS_M
    assert "vehicle_radius" not in resolved.choices


# The floor for the default controller on an ideal circle, any vehicle (m).
IDEAL_CIRCLE_RMS_M = 0.05


@pytest.mark.parametrize("preset", ["jmse2210", "bluerov2-heavy", "rexrov"])
def test_default_controller_tracks_an_ideal_circle_on_any_preset(preset):
    """With no controller settings (the old defaults held 0.37 m off on the BlueROV2 and let a
    2 t vehicle drift): a 0.3 m/s circle scaled to the vehicle, started on it."""
    model = load_vehicle(preset)
    radius = 4.0 * max(1.0, (model.mass / 13.5) ** (1 / 3))
    data = {
        "name": "circle",
        "duration": 60.0,
        "vehicle": preset,
        "reference": {"type": "circle", "radius": radius, "speed": 0.3},
        "initial_state": [radius, 0.0, np.pi / 2, 0.0, 0.0, 0.0],
        "transient_s": 20.0,
    }
    metrics = simulate(ResolvedScenario(validate_scenario(data), Path.cwd())).metrics
    assert metrics["fallback_steps"] == 0
    assert metrics["rms_position_error_after_transient_m"] <= IDEAL_CIRCLE_RMS_M
    assert metrics["verdict"] == "ok"


# --------------------------------------------------------------------------------------------
# The plant's integration step
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("preset", thruster_preset_names())
def test_presets_keep_the_default_plant_step(preset):
    assert stable_plant_step(load_vehicle(preset), DEFAULT_PLANT_STEP_S) == DEFAULT_PLANT_STEP_S


def test_plant_step_holds_a_full_thrust_spin_of_a_light_vehicle():
    """A random 16 kg vehicle with 0.28 kg m2 of yaw inertia and 200 N thrusters, every
    thruster pushing the largest yaw moment: at the chosen step RK4 reaches the analytic
    steady yaw rate (where the damping moment equals the thrust moment); at 0.05 s it
    diverges, so the test exercises the limit."""
    params = random_vehicle(np.random.default_rng(3))
    moment = params.thrust_authority[2]
    thrust = np.where(params.T[2] > 0, params.thrust_max, params.thrust_min)
    assert params.T[2] @ thrust == pytest.approx(moment, rel=1e-9)
    a, b = -params.Nrr, -params.Nr
    steady = (-b + math.sqrt(b * b + 4 * a * moment)) / (2 * a)

    def spin(step: float) -> np.ndarray:
        state = np.zeros(6)
        with np.errstate(over="ignore", invalid="ignore"):
            for _ in range(round(10.0 / step)):
                state = rk4_step(lambda x, u: dynamics(x, u, params), state, thrust, step)
        return state

    step = stable_plant_step(params, DEFAULT_PLANT_STEP_S)
    assert step < DEFAULT_PLANT_STEP_S
    assert spin(step)[5] == pytest.approx(steady, rel=1e-6)
    assert not np.isfinite(spin(DEFAULT_PLANT_STEP_S)).all()


def test_an_override_gets_the_new_vehicles_own_defaults():
    """Filled-in values are the vehicle's, not the scenario's: after changing the vehicle,
    the RK4 substeps and the estimator prior are the new vehicle's (the paper vehicle's one
    0.5 s step is unstable for the BlueROV2)."""
    from auvmpc.api import override

    changed = override(load_scenario("paper-disturbed"), {"vehicle": "bluerov2-heavy"})
    fresh = ControllerConfig(
        **load_scenario("paper-disturbed").given.controller.model_dump(exclude_unset=True)
    ).for_vehicle(load_vehicle("bluerov2-heavy"))
    assert changed.scenario.controller.model_substeps == fresh.model_substeps > 1
    assert (
        changed.scenario.controller.observer.initial_disturbance_std
        == fresh.observer.initial_disturbance_std
    )


def test_a_campaign_may_scale_a_default_that_depends_on_the_vehicle(tmp_path):
    from auvmpc.experiments.campaign.sampling import scenario_for_run
    from auvmpc.experiments.campaign.spec import load_campaign

    spec = {
        "name": "scaled-weights",
        "base": "bluerov2-figure-eight",
        "runs": 2,
        "seed": 3,
        "parameters": {
            "controller.R.0": {"type": "uniform", "low": 2.0, "high": 3.0, "apply": "multiply"}
        },  # fmt: skip
        "criterion": "thrust_limit_violations == 0",
    }
    path = tmp_path / "campaign.yaml"
    path.write_text(yaml.safe_dump(spec))
    default = load_scenario("bluerov2-figure-eight").scenario.controller.R[0]
    scaled_weight = scenario_for_run(load_campaign(path), 0).scenario.controller.R[0]
    assert 2.0 * default <= scaled_weight <= 3.0 * default


# -- controller.vehicle_radius from the vehicle's size ----------------------------------------


@pytest.mark.parametrize("preset", thruster_preset_names())
def test_the_default_vehicle_radius_is_the_disc_through_the_planforms_corners(preset):
    """Omitted, the radius is half the length x width diagonal: the disc round the middle
    of the planform that its farthest corner touches, so it holds the hull at any heading;
    run.json's ``choices`` and ``auvmpc explain`` say so."""
    model = load_vehicle(preset)
    size = model.size
    assert size is not None, "every preset has a size"
    radius = ControllerConfig().for_vehicle(model).vehicle_radius
    corners = np.array([[size.length, size.width], [size.length, -size.width]]) / 2.0
    assert radius == pytest.approx(np.hypot(*corners.T).max(), rel=1e-12)
    assert radius == pytest.approx(math.hypot(size.length, size.width) / 2.0, rel=1e-12)
    chosen = ControllerConfig().choices(model)["vehicle_radius"]
    assert chosen["value"] == radius
    assert f"{size.length:g} x {size.width:g} m planform" in chosen["why"]


def test_the_bluerov2_heavy_gets_the_disc_of_its_published_frame():
    """457 x 575 mm (Blue Robotics): 0.367 m, where every vehicle had 0.5 m before."""
    radius = ControllerConfig().for_vehicle(load_vehicle("bluerov2-heavy")).vehicle_radius
    assert radius == pytest.approx(0.3672, abs=1e-4)


def test_a_vehicle_without_size_keeps_half_a_metre():
    model = load_vehicle("bluerov2-heavy").model_copy(update={"size": None})
    assert ControllerConfig().for_vehicle(model).vehicle_radius == DEFAULT_VEHICLE_RADIUS_M
    chosen = ControllerConfig().choices(model)["vehicle_radius"]
    assert chosen["value"] == DEFAULT_VEHICLE_RADIUS_M
    assert "has no size" in chosen["why"]


def test_a_given_vehicle_radius_wins_over_the_size():
    model = load_vehicle("rexrov")  # its size gives 1.48 m
    given = ControllerConfig(vehicle_radius=0.8)
    assert given.for_vehicle(model).vehicle_radius == 0.8
    assert "vehicle_radius" not in given.choices(model)
    assert given.ocp(model).keep_out_extra == 0.8 + given.obstacle_margin


@pytest.mark.parametrize("preset", thruster_preset_names())
@pytest.mark.parametrize(
    "controller", [kind for kind in ControllerType if kind is not ControllerType.THRUST_PLAYBACK]
)
def test_a_filled_config_always_has_a_vehicle_radius(preset, controller):
    model = load_vehicle(preset)
    filled = ControllerConfig(type=controller).for_vehicle(model)
    assert isinstance(filled.vehicle_radius, float) and filled.vehicle_radius > 0
    whole_vehicle = (ControllerType.SIX_DOF_NMPC, ControllerType.LOS_PID)
    if controller is ControllerType.BASELINE or controller in whole_vehicle:
        return  # no horizontal tracking problem (six-dof-nmpc poses the whole vehicle's)
    assert filled.ocp(model).keep_out_extra == filled.vehicle_radius + filled.obstacle_margin


@pytest.mark.parametrize("name", list(builtin_scenarios()))
def test_every_built_in_scenario_runs_with_a_vehicle_radius(name):
    """What the session, the clearance, the figures and run.json read: never None."""
    resolved = load_scenario(name)
    controller = resolved.scenario.controller
    if isinstance(resolved, ResolvedDepthScenario):  # no obstacles, no radius
        assert "vehicle_radius" not in type(controller).model_fields
        return
    radius = controller.vehicle_radius
    assert isinstance(radius, float) and radius > 0
