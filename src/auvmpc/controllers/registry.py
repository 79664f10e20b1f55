"""Which class implements each controller type: adding a controller is its module plus a line
here (and its name in ``ControllerType``, or its scenario kind's config for a depth one)."""

from __future__ import annotations

import importlib

from auvmpc.controllers.config import (
    DEPTH_MPC,
    ControllerConfig,
    ControllerType,
    DepthControllerConfig,
)
from auvmpc.controllers.recovery import DepthFeedback, StabilisingFeedback
from auvmpc.controllers.shell import ShelledController
from auvmpc.models.vehicle import VehicleParams

__all__ = ["REGISTRY", "build_controller"]

# Imported only when used: do-mpc is an optional extra, and CasADi set-up is not free.
REGISTRY: dict[str, tuple[str, str]] = {
    ControllerType.BASELINE: ("auvmpc.controllers.baseline", "BaselineController"),
    ControllerType.MPC: ("auvmpc.controllers.mpc", "PaperMpc"),
    ControllerType.LTV_MPC: ("auvmpc.controllers.ltv", "LtvMpc"),
    ControllerType.NMPC: ("auvmpc.controllers.nmpc", "NonlinearMpc"),
    ControllerType.DO_MPC: ("auvmpc.controllers.dompc", "DoMpcController"),
    DEPTH_MPC: ("auvmpc.controllers.depth_mpc", "DepthMpc"),  # kind: depth, 6-DOF's depth
}

# The optimising horizontal controllers, whose shell recovers with the stabilising feedback
# (the baseline is that feedback); the depth MPC's shell recovers with the depth feedback.
RECOVERED_TYPES = (
    ControllerType.MPC,
    ControllerType.LTV_MPC,
    ControllerType.NMPC,
    ControllerType.DO_MPC,
)


def build_controller(
    config: ControllerConfig | DepthControllerConfig,
    model: VehicleParams,
    obstacle_count: int = 0,
    **surroundings: float,
) -> ShelledController:
    """The configured controller on the nominal (controller-side) vehicle model.

    ``surroundings``: what else the scenario says that the controller is built for, by
    name (a depth controller's ``water_depth_m``)."""
    module, name = REGISTRY[config.type]
    controller_class = getattr(importlib.import_module(module), name)
    controller = controller_class.from_config(
        model, config.for_vehicle(model), obstacle_count=obstacle_count, **surroundings
    )
    if config.type in RECOVERED_TYPES:
        controller.recovery = StabilisingFeedback(
            model, controller.sample_time, config.vehicle_radius + config.obstacle_margin
        )
    elif config.type == DEPTH_MPC:
        controller.recovery = DepthFeedback(controller.heave, controller.sample_time)
    return controller
