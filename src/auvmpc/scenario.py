"""Scenario files: a typed, validated schema and the loader with command-line overrides.

The key names are a contract (``shared/spec/interfaces.md``). Every field has a
default and a description; unknown keys, wrong types and non-finite numbers are
errors that name the field (:class:`auvmpc.errors.ConfigError`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from importlib import resources
from pathlib import Path
from typing import Annotated, Any, Literal

import numpy as np
import yaml
from pydantic import Field, ValidationError, model_validator

from auvmpc.config import (
    NonNegative,
    StrictModel,
    builtin_descriptions,
    load_yaml,
    read_text_file,
    read_yaml_mapping,
)
from auvmpc.controllers.config import ControllerConfig, ControllerType
from auvmpc.depth import DepthControllerConfig, DepthScenario, resolve_heave
from auvmpc.environment.currents import WaterCurrentConfig
from auvmpc.environment.disturbances import DisturbanceConfig, SensorNoiseConfig
from auvmpc.environment.obstacle_sensor import ObstacleSensorConfig
from auvmpc.environment.obstacles import ObstacleConfig
from auvmpc.errors import ConfigError, FieldError, format_validation_error
from auvmpc.models.six_dof import plant_step_length
from auvmpc.references import Reference, ReferenceConfig, make_reference
from auvmpc.vehicle import (
    VehicleParams,
    check_plant_scale,
    load_vehicle,
    scaled,
    stable_plant_step,
)

__all__ = [
    "ControllerConfig",
    "ControllerType",
    "PlantConfig",
    "ResolvedSixDofScenario",
    "Scenario",
    "SixDofDisturbanceConfig",
    "SixDofScenario",
    "SixDofSensingConfig",
    "builtin_scenarios",
    "load_scenario",
    "apply_override",
    "planar_twin",
]


# The plant's longest RK4 step when the scenario gives none and the vehicle allows it (s):
# 10 steps per 0.5 s sample, far below the time constants of any preset.
DEFAULT_PLANT_STEP_S = 0.05


class PlantConfig(StrictModel):
    """How the simulated vehicle differs from the controller's model, and how it is integrated."""

    scale: dict[str, Annotated[float, Field(gt=0)]] = Field(
        default_factory=dict, description="factor per vehicle field, e.g. {Iz_rb: 0.75}"
    )
    max_step: Annotated[float, Field(gt=0, le=0.5)] | None = Field(
        default=None,
        description="longest RK4 step of the plant integration (s); omitted: 0.05 s, or "
        "shorter where the plant's damping at the speeds its thrusters can reach needs it "
        "for RK4 stability",
    )


class Scenario(StrictModel):
    """One closed-loop experiment, fully specified."""

    kind: Literal["horizontal"] = Field(
        default="horizontal",
        description="horizontal-plane tracking ('depth': auvmpc.depth; 'six-dof': the 6-DOF "
        "plant, auvmpc.sim.six_dof_loop)",
    )
    name: str = Field(description="identifier")
    description: str = Field(default="", description="one line for humans")
    duration: Annotated[float, Field(gt=0)] = Field(description="simulated time (s)")
    vehicle: str | dict[str, Any] = Field(
        default="jmse2210", description="preset name, vehicle file path, or inline mapping"
    )
    plant: PlantConfig = Field(default_factory=PlantConfig)
    disturbance: DisturbanceConfig = Field(default_factory=DisturbanceConfig)
    sensing: SensorNoiseConfig = Field(default_factory=SensorNoiseConfig)
    reference: ReferenceConfig
    initial_state: tuple[float, float, float, float, float, float] = Field(
        description="[x, y, psi, u, v, r] at t = 0"
    )
    initial_thrust: tuple[float, ...] | None = Field(
        default=None, description="F(-1) per thruster (N); zeros if omitted"
    )
    obstacles: tuple[ObstacleConfig, ...] = Field(default=())
    obstacle_sensor: ObstacleSensorConfig | None = Field(
        default=None,
        description="how the controller perceives the obstacles (range sensor and a "
        "constant-velocity tracker each); omitted: it knows their position and velocity",
    )
    controller: ControllerConfig = Field(default_factory=ControllerConfig)
    seed: Annotated[int, Field(ge=0)] = Field(default=0, description="master random seed")
    transient_s: NonNegative = Field(
        default=20.0, description="start of the window for the steady-state metrics (s)"
    )

    @model_validator(mode="after")
    def _whole_samples(self) -> Scenario:
        # An omitted sample time is checked once the vehicle has chosen it (ResolvedScenario).
        if self.controller.sample_time is not None:
            check_whole_samples(self.duration, self.controller.sample_time, FieldError)
        return self


def check_whole_samples(duration: float, sample_time: float, error=ConfigError) -> None:
    """Raise ``error`` on ``duration`` unless it is a whole number of samples."""
    steps = duration / sample_time
    if abs(steps - round(steps)) > 1e-9 * max(1.0, steps):
        raise error(
            "duration",
            duration,
            f"not a whole number of samples of {sample_time} s (controller.sample_time; "
            "chosen for the vehicle when omitted)",
        )


class SixDofDisturbanceConfig(StrictModel):
    """What moves the 6-DOF vehicle that no controller is told about."""

    water_current: WaterCurrentConfig | None = Field(
        default=None,
        description="current as water velocity (world NED), acting through the velocity "
        "relative to the water; a depth profile and a vertical part are allowed here",
    )


class SixDofSensingConfig(SensorNoiseConfig):
    """Zero-mean Gaussian noise on what the controllers see (the log keeps the truth): the
    horizontal state as in horizontal scenarios, plus the depth and its rate."""

    depth_std_m: NonNegative = Field(default=0.0, description="depth noise (m)")
    depth_rate_std_m_per_s: NonNegative = Field(
        default=0.0,
        description="depth-rate noise (m/s); the depth MPC's filter estimates the rate from "
        "the measured depth and does not read this measurement yet",
    )


class SixDofScenario(Scenario):
    """The paper's architecture on the 6-DOF plant (paper section 4.2): the horizontal
    controller (any ``controller.type``) on [x, y, psi, u, v, r] of the measured 6-DOF state,
    the depth controller on depth and its rate, roll and pitch left to passive stability.
    Every field of a horizontal scenario means the same here; ``plant.scale`` is refused (the
    plant is the vehicle's ``six_dof`` section as given)."""

    kind: Literal["six-dof"] = Field(  # type: ignore[assignment]
        description="selects this schema: the 6-DOF plant (auvmpc.sim.six_dof_loop)"
    )
    disturbance: SixDofDisturbanceConfig = Field(  # type: ignore[assignment]
        default_factory=SixDofDisturbanceConfig
    )
    sensing: SixDofSensingConfig = Field(default_factory=SixDofSensingConfig)  # type: ignore[assignment]
    depth_controller: DepthControllerConfig = Field(
        default_factory=DepthControllerConfig,
        description="the depth MPC (auvmpc.depth); sample_time is the horizontal controller's "
        "and preview true unless given",
    )
    water_depth_m: Annotated[float, Field(gt=0)] = Field(
        default=100.0, description="depth of the bottom below the surface (m)"
    )
    initial_depth_m: float | None = Field(
        default=None,
        description="depth below the surface at t = 0 (m); omitted: the reference's; the "
        "vehicle starts level (phi = theta = 0) with w = p = q = 0",
    )

    @model_validator(mode="before")
    @classmethod
    def _depth_controller_defaults(cls, data: Any) -> Any:
        """What a depth_controller mapping leaves out: preview (a planned 3-D path is known
        ahead, as the horizontal reference is). Its sample time, left out, is the horizontal
        controller's, given once the vehicle has chosen that (ResolvedSixDofScenario)."""
        if not isinstance(data, dict):
            return data
        depth = data.get("depth_controller", {})
        if not isinstance(depth, dict):
            return data  # the field validation names what is wrong
        return {**data, "depth_controller": {"preview": True, **depth}}

    @model_validator(mode="after")
    def _one_sample_time(self) -> SixDofScenario:
        depth = self.depth_controller
        if self.controller.sample_time is not None and "sample_time" in depth.model_fields_set:
            check_one_sample_time(depth.sample_time, self.controller.sample_time, FieldError)
        return self


def check_one_sample_time(depth: float, horizontal: float, error=ConfigError) -> None:
    """Raise ``error`` unless the depth controller samples with the horizontal one."""
    if not math.isclose(depth, horizontal):
        raise error(
            "depth_controller.sample_time",
            depth,
            f"must equal controller.sample_time ({horizontal} s): the log holds one command "
            "per thruster per sample",
        )


class ResolvedScenario:
    """A scenario plus what its names point at: the nominal model and the simulated plant."""

    def __init__(self, scenario: Scenario, base_dir: Path) -> None:
        self.given = scenario  # as written: what overrides apply to
        self.scenario = scenario  # below: with what the vehicle decides filled in
        self.base_dir = base_dir
        self.model: VehicleParams = _load_vehicle_relative(scenario.vehicle, base_dir)
        check_plant_scale(scenario.plant.scale)
        self.plant: VehicleParams = scaled(self.model, scenario.plant.scale)
        n = self.model.n_thrusters
        weights = scenario.controller.R
        if weights is not None and len(weights) not in (1, n):
            raise ConfigError(
                "controller.R", list(weights), f"need 1 or {n} weights (one per thruster)"
            )
        # What the scenario left out is filled in for its vehicle here, so the run's record
        # (run.json's scenario) holds every value the controller used. Overrides apply to
        # ``given``: a filled-in value must not outlive a change of vehicle or sample time.
        plant_step = scenario.plant.max_step or stable_plant_step(self.plant, DEFAULT_PLANT_STEP_S)
        self.scenario = scenario = scenario.model_copy(
            update={
                "controller": scenario.controller.for_vehicle(self.model),
                "plant": scenario.plant.model_copy(update={"max_step": plant_step}),
            }
        )
        check_whole_samples(scenario.duration, scenario.controller.sample_time)
        initial = scenario.initial_thrust
        if initial is not None:
            if len(initial) != n:
                raise ConfigError("initial_thrust", list(initial), f"need {n} values")
            low, high = self.model.thrust_limits
            if not all(low <= value <= high for value in initial):
                raise ConfigError(
                    "initial_thrust", list(initial), f"outside the thrust limits [{low}, {high}]"
                )


class ResolvedSixDofScenario(ResolvedScenario):
    """A 6-DOF scenario, its vehicle (which must have ``six_dof`` and ``heave`` sections and
    vertical thrusters after the horizontal ones) and its 3-D reference."""

    scenario: SixDofScenario

    def __init__(self, scenario: SixDofScenario, base_dir: Path) -> None:
        if scenario.plant.scale:
            raise ConfigError(
                "plant.scale",
                dict(scenario.plant.scale),
                "not supported on the 6-DOF plant (it simulates the vehicle's six_dof section "
                "as given; give a vehicle file with other values instead)",
            )
        # The vehicle's fitness for the 6-DOF plant first: it decides whether anything else
        # about the scenario (e.g. a weight per thruster) can matter.
        vehicle = _load_vehicle_relative(scenario.vehicle, base_dir)
        if vehicle.six_dof is None:
            raise ConfigError(
                "vehicle.six_dof",
                vehicle.name,
                "missing: the 6-DOF plant needs the vehicle's six_dof section (docs/six-dof.md)",
            )
        try:
            vehicle.check_six_dof_layout()
        except FieldError as error:
            raise ConfigError(f"vehicle.{error.field}", error.value, error.reason) from None
        super().__init__(scenario, base_dir)
        model = self.model
        six = model.six_dof
        if model.heave is None:
            raise ConfigError(
                "vehicle.heave", model.name, "missing: the depth controller needs a heave section"
            )
        n = model.n_thrusters
        vertical = np.asarray(six.T)[2, n:]
        if vertical.size == 0 or not np.any(np.abs(vertical) > 1e-9):
            raise ConfigError(
                "vehicle.six_dof.thrusters",
                six.n_thrusters,
                f"no vertical thrusters after the {n} horizontal ones: the depth reference "
                "needs thrusters with a heave (z) component",
            )
        self.reference: Reference = make_reference(scenario.reference, base_dir)
        if not self.reference.has_depth:
            raise ConfigError(
                "reference.depth",
                None,
                "the 6-DOF plant needs a depth reference: give reference.depth or a 3-D type "
                "(helix, lawnmower, waypoints-3d)",
            )
        given = self.given
        initial_depth = given.initial_depth_m
        if initial_depth is None:
            initial_depth = float(self.reference.depths([0.0])[0, 0])
        bottom = given.water_depth_m
        if not 0.0 < initial_depth < bottom:
            raise ConfigError(
                "initial_depth_m", initial_depth, f"not in the water (0 to {bottom} m below)"
            )
        # The reference over the run, at the controller's samples or finer: one out of the
        # water cannot be tracked and is no test of a controller.
        times = np.linspace(0.0, scenario.duration, max(2, int(scenario.duration / 0.1) + 1))
        path_depths = self.reference.depths(times)[:, 0]
        if path_depths.min() <= 0.0 or path_depths.max() >= bottom:
            raise ConfigError(
                "reference.depth",
                [round(float(path_depths.min()), 3), round(float(path_depths.max()), 3)],
                f"the reference leaves the water (0 to water_depth_m {bottom} m below)",
            )
        plant_step = given.plant.max_step or plant_step_length(self.plant, DEFAULT_PLANT_STEP_S)
        sample_time = self.scenario.controller.sample_time  # chosen for the vehicle if omitted
        depth_controller = given.depth_controller
        if "sample_time" in depth_controller.model_fields_set:
            check_one_sample_time(depth_controller.sample_time, sample_time)
        else:
            depth_controller = depth_controller.model_copy(update={"sample_time": sample_time})
        self.scenario = self.scenario.model_copy(
            update={
                "depth_controller": depth_controller,
                "initial_depth_m": initial_depth,
                "plant": self.scenario.plant.model_copy(update={"max_step": plant_step}),
            }
        )


def planar_twin(scenario: SixDofScenario) -> Scenario:
    """The same experiment on the 3-DOF plant: same vehicle, horizontal reference, controller,
    horizontal noise, seed and current (its horizontal part; the random streams line up, so
    both plants see the same current and the same horizontal noise draws). What only the
    6-DOF plant has (depth, its controller and sensor) is left out. A current with a depth
    profile has no planar twin."""
    water = scenario.disturbance.water_current
    if water is not None and water.depth_profile:
        raise ConfigError(
            "disturbance.water_current.depth_profile",
            [list(point) for point in water.depth_profile],
            "a current varying with depth has no planar (3-DOF) twin",
        )
    data = scenario.model_dump(
        mode="json",
        exclude={"kind", "depth_controller", "water_depth_m", "initial_depth_m", "disturbance"},
    )
    data["sensing"] = {"std": list(scenario.sensing.std)}
    data["plant"] = {"scale": {}}
    if water is not None:
        velocity = [*water.velocity_m_per_s[:2], 0.0]
        current = water.model_copy(update={"velocity_m_per_s": tuple(velocity)})
        data["disturbance"] = {"water_current": current.model_dump(mode="json")}
    data["name"] = f"{scenario.name}-planar"
    return validate_scenario(data)


def _load_vehicle_relative(vehicle: str | dict[str, Any], base_dir: Path) -> VehicleParams:
    """A vehicle named by a scenario; a file path is relative to the scenario's folder."""
    if isinstance(vehicle, str) and vehicle.endswith((".yaml", ".yml")):
        vehicle = str(base_dir / vehicle) if not Path(vehicle).is_absolute() else vehicle
    return load_vehicle(vehicle)


def builtin_scenarios() -> dict[str, str]:
    """Built-in scenario names and their one-line descriptions."""
    return builtin_descriptions("scenarios")


class ResolvedDepthScenario:
    """A depth scenario (``kind: depth``) and its vehicle."""

    def __init__(self, scenario: DepthScenario, base_dir: Path) -> None:
        self.scenario = scenario
        self.base_dir = base_dir
        self.model: VehicleParams = _load_vehicle_relative(scenario.vehicle, base_dir)
        check_plant_scale(scenario.plant.scale, "depth")
        try:
            self.heave_model = resolve_heave(self.model, {})
            self.heave_plant = resolve_heave(self.model, scenario.plant.scale)
        except FieldError as error:
            raise ConfigError(error.field, error.value, error.reason) from None


def load_scenario(
    source: str | Path, overrides: Sequence[str] = ()
) -> ResolvedScenario | ResolvedDepthScenario:
    """Load a built-in scenario by name or a YAML file, apply ``field=value`` overrides.

    A file with ``kind: depth`` is a depth experiment (auvmpc.depth), one with
    ``kind: six-dof`` runs on the 6-DOF plant (:class:`ResolvedSixDofScenario`, a
    :class:`ResolvedScenario`); any other is a horizontal-plane scenario."""
    text_source = str(source)
    if text_source in builtin_scenarios():
        text = (resources.files("auvmpc.presets") / "scenarios" / f"{text_source}.yaml").read_text()
        base_dir = Path.cwd()
    else:
        path = Path(text_source)
        if not path.exists():
            raise ConfigError(
                "scenario",
                text_source,
                f"no such file or built-in; built-ins: {list(builtin_scenarios())}",
            )
        text, base_dir = read_text_file(path, "scenario", "scenario file"), path.resolve().parent
    data = read_yaml_mapping(text, "scenario", text_source, "scenario fields")
    for override in overrides:
        apply_override(data, override)
    if data.get("kind") == "depth":
        try:
            return ResolvedDepthScenario(DepthScenario.model_validate(data), base_dir)
        except ValidationError as error:
            raise format_validation_error(error) from None
    if data.get("kind") == "six-dof":
        try:
            return ResolvedSixDofScenario(SixDofScenario.model_validate(data), base_dir)
        except ValidationError as error:
            raise format_validation_error(error) from None
    return ResolvedScenario(validate_scenario(data), base_dir)


def validate_scenario(data: dict[str, Any]) -> Scenario:
    try:
        return Scenario.model_validate(data)
    except ValidationError as error:
        raise format_validation_error(error) from None


def apply_override(data: dict[str, Any], override: str) -> None:
    """Set ``a.b.0.c=value`` in a nested mapping; the value is read as YAML."""
    path, separator, raw_value = override.partition("=")
    if not separator or not path:
        raise ConfigError("--set", override, "expected field=value")
    try:
        value = load_yaml(raw_value)
    except yaml.YAMLError as error:
        problem = str(getattr(error, "problem", "") or "")
        detail = f": {problem}" if problem.startswith("duplicate key") else ""
        raise ConfigError(path, raw_value, f"value is not valid YAML{detail}") from None
    keys = path.split(".")
    node: Any = data
    for depth, key in enumerate(keys):
        last = depth == len(keys) - 1
        if isinstance(node, list):
            if not key.isdigit() or int(key) >= len(node):
                raise ConfigError(
                    ".".join(keys[: depth + 1]), key, f"no such list index (length {len(node)})"
                )
            index: Any = int(key)
        elif isinstance(node, dict):
            index = key
        else:
            raise ConfigError(".".join(keys[:depth]), node, "is not a mapping or list")
        if last:
            node[index] = value
        else:
            if isinstance(node, dict) and (index not in node or node[index] is None):
                if keys[depth + 1].isdigit():  # a list the document leaves at its default
                    raise ConfigError(
                        ".".join(keys[: depth + 2]),
                        keys[depth + 1],
                        f"no such list index ({'.'.join(keys[: depth + 1])} is not given, "
                        "so it has no items to set; give the whole list)",
                    )
                node[index] = {}
            node = node[index]


def scenario_to_dict(scenario: Scenario | DepthScenario) -> dict[str, Any]:
    """JSON-ready, fully resolved form (defaults filled in)."""
    return scenario.model_dump(mode="json")
