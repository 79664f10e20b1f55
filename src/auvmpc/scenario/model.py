"""Scenario files as a typed schema: the horizontal-plane and 6-DOF scenario models.

The key names are a contract (``shared/spec/interfaces.md``). Every field has a
default and a description; unknown keys, wrong types and non-finite numbers are
errors that name the field (:class:`auvmpc.errors.ConfigError`).
"""

from __future__ import annotations

import math
from typing import Annotated, Any, Literal

from pydantic import Field, model_validator

from auvmpc.config import (
    NonNegative,
    StrictModel,
)
from auvmpc.controllers.config import DEPTH_MPC
from auvmpc.controllers.depth_mpc import DepthControllerConfig
from auvmpc.controllers.nmpc import NmpcConfig
from auvmpc.controllers.registry import ControllerChoice, DepthControllerChoice
from auvmpc.environment.currents import WaterCurrentConfig
from auvmpc.environment.disturbances import DisturbanceConfig, SensorNoiseConfig
from auvmpc.environment.obstacle_sensor import ObstacleSensorConfig
from auvmpc.environment.obstacles import ObstacleConfig
from auvmpc.errors import ConfigError, FieldError
from auvmpc.models.layout import HORIZONTAL
from auvmpc.references import ReferenceConfig
from auvmpc.scenario.faults import ActuatorFault

__all__ = [
    "DEFAULT_PLANT_STEP_S",
    "PlantConfig",
    "Scenario",
    "SixDofDisturbanceConfig",
    "SixDofScenario",
    "SixDofSensingConfig",
    "check_one_sample_time",
    "rounded_to_samples",
    "whole_samples",
]


# The plant's longest RK4 step when the scenario gives none and the vehicle allows it (s):
# 10 steps per 0.5 s sample, far below the time constants of any preset.
DEFAULT_PLANT_STEP_S = 0.05


class PlantConfig(StrictModel):
    """How the simulated vehicle differs from the controller's model, and how it is integrated."""

    vehicle: str | dict[str, Any] | None = Field(
        default=None,
        description="the simulated vehicle when it is not the controller's model (preset "
        "name, vehicle file path or inline mapping, as the scenario's vehicle), e.g. a "
        "published file as the plant and your estimate as the model; it needs as many "
        "horizontal thrusters; omitted: the scenario's vehicle. Horizontal scenarios only",
    )
    scale: dict[str, Annotated[float, Field(gt=0)]] = Field(
        default_factory=dict,
        description="factor per vehicle field, e.g. {Iz_rb: 0.75}, on the plant's vehicle; "
        "six-dof scenarios scale the six_dof section's inertia, added_mass, linear_damping "
        "and quadratic_damping (each entry), e.g. {added_mass: 1.2}",
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
        description="horizontal-plane tracking ('depth': auvmpc.scenario.depth; 'six-dof': the "
        "6-DOF plant, auvmpc.controllers.channels)",
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
    initial_state: tuple[(float,) * HORIZONTAL.size] = Field(
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
    controller: ControllerChoice = Field(
        default_factory=NmpcConfig,
        description="controller choice and tuning: the knobs of the controller type it names",
    )
    seed: Annotated[int, Field(ge=0)] = Field(default=0, description="master random seed")
    transient_s: NonNegative = Field(
        default=20.0, description="start of the window for the steady-state metrics (s)"
    )
    faults: tuple[ActuatorFault, ...] = Field(
        default=(),
        description="actuators that fail during the run (scenario/faults.py): the plant "
        "delivers what they still can; run.json gets the RMS before and after the first",
    )
    fault_detection: bool = Field(
        default=False,
        description="watch the actuators for a fault from the model's prediction residual and "
        "tell the controller what is found (estimation/fault_detection.py): the horizontal "
        "thrusters, or beside a controller of the whole 6-DOF vehicle every input, dead or stuck",
    )


def whole_samples(duration: float, sample_time: float) -> tuple[float, str | None]:
    """``duration`` rounded up to a whole number of samples, and a note when it had to be
    (None when it already was one, to round-off)."""
    steps = duration / sample_time
    if not math.isfinite(steps):  # 1e308 s at 0.5 s: round() would raise OverflowError
        raise ConfigError("duration", duration, f"is {steps} samples of {sample_time:g} s")
    if abs(steps - round(steps)) <= 1e-9 * max(1.0, steps):
        return duration, None
    rounded = math.ceil(steps) * sample_time
    return rounded, (
        f"duration: {duration:g} s is not a whole number of samples of {sample_time:g} s "
        f"(controller.sample_time); the run lasts {rounded:g} s ({math.ceil(steps)} samples)"
    )


def rounded_to_samples(scenario):
    """``scenario`` (any kind with ``duration`` and ``controller.sample_time``) with its
    duration rounded up to whole samples, and the notes saying so (none if it was whole)."""
    duration, note = whole_samples(scenario.duration, scenario.controller.sample_time)
    if note is None:
        return scenario, []
    return scenario.model_copy(update={"duration": duration}), [note]


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
    the depth controller on depth and its rate, roll and pitch left to passive stability; or
    one controller of the whole vehicle (``six-dof-nmpc``) on the whole measured state, which
    flies any actuators (a torpedo's propeller and fins) and is a torpedo's default.
    Every field of a horizontal scenario means the same here, but ``plant.scale``, which scales
    the ``six_dof`` section's inertia, added mass and damping."""

    kind: Literal["six-dof"] = Field(  # type: ignore[assignment]
        description="selects this schema: the 6-DOF plant (auvmpc.controllers.channels)"
    )
    disturbance: SixDofDisturbanceConfig = Field(  # type: ignore[assignment]
        default_factory=SixDofDisturbanceConfig
    )
    sensing: SixDofSensingConfig = Field(default_factory=SixDofSensingConfig)  # type: ignore[assignment]
    initial_thrust: tuple[float, ...] | None = Field(
        default=None,
        description="the command before t = 0: per horizontal thruster (N; the vertical ones "
        "start at 0), or for a vehicle with actuators: per actuator in its own units (rpm, "
        "deg), each within its limits; zeros if omitted",
    )
    controller: ControllerChoice = Field(
        default_factory=NmpcConfig,
        description="controller choice and tuning: the knobs of the controller type it names. "
        "Without a type: nmpc with the depth MPC for a vehicle with thrusters, six-dof-nmpc "
        "(every input on the 6-DOF model) for a vehicle with actuators: (a propeller and "
        "fins), which only a controller of the whole vehicle flies",
    )
    depth_controller: DepthControllerChoice = Field(
        default_factory=DepthControllerConfig,
        description="the depth MPC (controllers/depth_mpc.py); sample_time is the horizontal "
        "controller's and preview true unless given; unused beside a controller of the whole "
        "vehicle (six-dof-nmpc: a note says so if given)",
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
        if not isinstance(depth, dict) or depth.get("type", DEPTH_MPC) != DEPTH_MPC:
            return data  # the field validation names what is wrong
        return {**data, "depth_controller": {"preview": True, **depth}}

    @model_validator(mode="after")
    def _one_sample_time(self) -> SixDofScenario:
        depth = self.depth_controller
        if depth.type != DEPTH_MPC:  # a table of vertical thrusts is a depth scenario's
            raise FieldError(
                "depth_controller.type", depth.type, f"the 6-DOF depth channel is {DEPTH_MPC}"
            )
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
