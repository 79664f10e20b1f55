"""The depth experiment's scenario schema (``kind: depth``): the paper's tank step
(paper-model.md section 8, docs/depth.md).

A depth scenario steps the depth reference in a tank, with calm water or surface waves, a
pressure sensor with noise and a sample rate, and the depth MPC. It runs in the same closed
loop as a horizontal scenario (auvmpc.sim.loop), on the heave model (auvmpc.models.heave).
Sign convention: z up, negative below the still surface; the bottom is at -depth.
"""

from __future__ import annotations

import math
from typing import Annotated, Any, Literal

import numpy as np
from pydantic import Field, model_validator

from auvmpc.config import Positive, StrictModel
from auvmpc.controllers.depth_mpc import DepthControllerConfig
from auvmpc.controllers.registry import DepthControllerChoice
from auvmpc.environment.depth_sensor import DepthSensorConfig
from auvmpc.environment.waves import WaveConfig, WaveType, wave_number
from auvmpc.errors import FieldError
from auvmpc.models.layout import DEPTH
from auvmpc.references import DepthStepConfig

__all__ = [
    "DepthPlantConfig",
    "DepthScenario",
    "DepthSensorConfig",
    "DepthStepConfig",
    "TankConfig",
]


class TankConfig(StrictModel):
    length_m: Positive = Field(default=4.2, description="tank length (m)")
    width_m: Positive = Field(default=2.0, description="tank width (m)")
    depth_m: Positive = Field(default=1.25, description="water depth (m)")


class DepthPlantConfig(StrictModel):
    scale: dict[str, Positive] = Field(
        default_factory=dict, description="factor per heave field, e.g. {net_buoyancy_N: 2}"
    )
    max_step: Annotated[float, Field(gt=0, le=0.1)] = Field(
        default=0.01, description="longest RK4 step of the plant (s)"
    )


class DepthScenario(StrictModel):
    """A depth-step experiment in a tank."""

    kind: Literal["depth"] = Field(description="selects this schema")
    name: str
    description: str = ""
    duration: Positive = Field(description="simulated time (s)")
    vehicle: str | dict[str, Any] = Field(default="jmse2210")
    plant: DepthPlantConfig = Field(default_factory=DepthPlantConfig)
    tank: TankConfig = Field(default_factory=TankConfig)
    waves: WaveConfig | None = Field(default=None, description="surface waves, or calm water")
    sensor: DepthSensorConfig = Field(default_factory=DepthSensorConfig)
    reference: DepthStepConfig = Field(default_factory=DepthStepConfig)
    initial_state: tuple[float, float] | None = Field(
        default=None, description="[z, w]; default: at the initial depth, at rest"
    )
    controller: DepthControllerChoice = Field(
        default_factory=DepthControllerConfig,
        description="depth controller choice and tuning: the knobs of the controller type it "
        "names (default depth-mpc, controllers/depth_mpc.py)",
    )
    seed: Annotated[int, Field(ge=0)] = 0

    @model_validator(mode="after")
    def _inside_the_tank(self) -> DepthScenario:
        bottom = -self.tank.depth_m
        for field in ("initial_depth_m", "final_depth_m"):
            value = getattr(self.reference, field)
            if not bottom < value < 0.0:
                where = "below the tank bottom" if value <= bottom else "above the surface"
                raise FieldError(f"reference.{field}", value, f"{where} (water depth {-bottom} m)")
        z = DEPTH.index("z")
        if self.initial_state is not None and not bottom < self.initial_state[z] <= 0.0:
            raise FieldError(f"initial_state.{z}", self.initial_state[z], "outside the water")
        if self.reference.step_time_s >= self.duration:
            raise FieldError("reference.step_time_s", self.reference.step_time_s, "after the end")
        waves = self.waves
        if waves is not None:
            if waves.height_m >= self.tank.depth_m:
                raise FieldError("waves.height_m", waves.height_m, "not below the water depth")
            if waves.type is WaveType.REGULAR and waves.height_m > 0:
                k = wave_number(2.0 * math.pi / waves.period_s, self.tank.depth_m)
                if waves.height_m * k / (2.0 * math.pi) > 1.0 / 7.0:
                    raise FieldError(
                        "waves.height_m",
                        waves.height_m,
                        f"breaks: steeper than 1/7 of its {2 * math.pi / k:.2f} m wavelength",
                    )
        return self

    def start_state(self) -> np.ndarray:
        if self.initial_state is not None:
            return np.array(self.initial_state, dtype=float)
        return np.array([self.reference.initial_depth_m, 0.0])
