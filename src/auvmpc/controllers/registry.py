"""Which class implements each controller type. A built-in controller is its module plus a
line here (and its name in ``ControllerType``); a controller of your own is one file and one
:func:`register_controller` call, after which scenarios name it as ``controller.type``
(docs/extending.md)."""

from __future__ import annotations

import importlib
import re

from auvmpc.controllers.base import Controller
from auvmpc.controllers.config import (
    DEPTH_MPC,
    ControllerConfig,
    ControllerType,
    DepthControllerConfig,
)
from auvmpc.controllers.recovery import DepthFeedback, StabilisingFeedback
from auvmpc.controllers.shell import ShelledController
from auvmpc.models.vehicle import VehicleParams

__all__ = ["REGISTRY", "build_controller", "class_of", "register_controller"]

# Imported only when used: do-mpc is an optional extra, and CasADi set-up is not free.
REGISTRY: dict[str, tuple[str, str] | type] = {
    ControllerType.BASELINE: ("auvmpc.controllers.baseline", "BaselineController"),
    ControllerType.MPC: ("auvmpc.controllers.mpc", "PaperMpc"),
    ControllerType.LTV_MPC: ("auvmpc.controllers.ltv", "LtvMpc"),
    ControllerType.NMPC: ("auvmpc.controllers.nmpc", "NonlinearMpc"),
    ControllerType.DO_MPC: ("auvmpc.controllers.dompc", "DoMpcController"),
    ControllerType.THRUST_PLAYBACK: ("auvmpc.controllers.playback", "ThrustPlayback"),
    DEPTH_MPC: ("auvmpc.controllers.depth_mpc", "DepthMpc"),  # kind: depth, 6-DOF's depth
}

# The optimising horizontal controllers, whose shell recovers with the stabilising feedback
# (the baseline is that feedback); the depth MPC's shell recovers with the depth feedback.
RECOVERED_TYPES = {
    ControllerType.MPC,
    ControllerType.LTV_MPC,
    ControllerType.NMPC,
    ControllerType.DO_MPC,
}
# A registered name: lower-case words joined by hyphens, as the built-in ones.
_NAME = re.compile(r"[a-z][a-z0-9]*(-[a-z0-9]+)*")


def register_controller(name: str, controller: type, *, recovered: bool = False) -> None:
    """Make ``controller`` the class of ``controller.type: name`` in every scenario loaded
    afterwards in this process.

    ``controller`` is a ``controllers.base.Controller`` subclass built by
    ``controller.from_config(model, config, obstacle_count=..., **surroundings)`` if it has
    that class method, else by ``controller(model, config)``: ``model`` the nominal vehicle,
    ``config`` the scenario's ``ControllerConfig`` filled in for it (``sample_time``,
    ``prediction_horizon`` ... are yours to read). ``recovered``: a ``ShelledController``
    whose shell steers by the stabilising feedback after a failed solve, as the built-in
    MPCs' does. A name already taken raises ValueError.
    """
    if not isinstance(name, str) or not _NAME.fullmatch(name):
        raise ValueError(f"controller name {name!r}: lower-case words joined by hyphens")
    if name in REGISTRY:
        raise ValueError(f"controller name {name!r} is taken (taken: {', '.join(REGISTRY)})")
    if not isinstance(controller, type) or not issubclass(controller, Controller):
        raise ValueError(f"{controller!r} is not a controllers.base.Controller subclass")
    if recovered and not issubclass(controller, ShelledController):
        raise ValueError(f"{controller.__name__}: only a ShelledController has a shell to recover")
    REGISTRY[name] = controller
    if recovered:
        RECOVERED_TYPES.add(name)


def class_of(controller_type: str) -> type[Controller]:
    """The class of a controller type (a built-in one's module imported now)."""
    entry = REGISTRY[controller_type]
    if isinstance(entry, type):  # registered by register_controller
        return entry
    module, name = entry
    return getattr(importlib.import_module(module), name)


def build_controller(
    config: ControllerConfig | DepthControllerConfig,
    model: VehicleParams,
    obstacle_count: int = 0,
    **surroundings: float,
) -> Controller:
    """The configured controller on the nominal (controller-side) vehicle model.

    ``surroundings``: what else the scenario says that the controller is built for, by
    name (a depth controller's ``water_depth_m``)."""
    controller_class = class_of(config.type)
    filled = config.for_vehicle(model)
    if not hasattr(controller_class, "from_config"):
        return controller_class(model, filled)
    controller = controller_class.from_config(
        model, filled, obstacle_count=obstacle_count, **surroundings
    )
    if not isinstance(controller, ShelledController):
        return controller  # its own safety rules (the C controller's shell is in its C)
    if config.type in RECOVERED_TYPES:
        controller.recovery = StabilisingFeedback(
            model, controller.sample_time, filled.vehicle_radius + filled.obstacle_margin
        )
    elif config.type == DEPTH_MPC:
        controller.recovery = DepthFeedback(controller.heave, controller.sample_time)
    return controller
