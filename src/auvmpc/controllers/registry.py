"""Which configuration and which class each controller type has. A built-in controller is its
module (its configuration class next to it) plus a line here; a controller of your own is
one file and one :func:`register_controller` call, after which scenarios name it as
``controller.type`` and give it the knobs of its own configuration class
(docs/extending.md).

A scenario's ``controller`` mapping is validated as :data:`ControllerChoice`: pydantic's
discriminated union on ``type`` over the built-in configurations, plus one member for the
registered ones (whose classes are only known at run time). A depth scenario's
``controller`` and a 6-DOF scenario's ``depth_controller`` are :data:`DepthControllerChoice`,
the same over the depth kind's types (:data:`DEPTH_REGISTRY`)."""

from __future__ import annotations

import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Annotated, Any, Union

from pydantic import (
    BeforeValidator,
    Discriminator,
    SerializeAsAny,
    Tag,
    ValidationError,
    ValidationInfo,
    WithJsonSchema,
    WrapValidator,
)
from pydantic.json_schema import GetJsonSchemaHandler, JsonSchemaValue
from pydantic_core import CoreSchema

from auvmpc.config import StrictModel
from auvmpc.controllers.base import Controller
from auvmpc.controllers.baseline import BaselineController, BaselineControllerConfig
from auvmpc.controllers.config import (
    DEPTH_MPC,
    SAVED_RUN,
    ControllerType,
    DepthChannelConfig,
    HorizontalControllerConfig,
)
from auvmpc.controllers.depth_mpc import DepthControllerConfig, DepthMpc
from auvmpc.controllers.dompc import DoMpcConfig, DoMpcController
from auvmpc.controllers.los_pid import LosPid, LosPidConfig
from auvmpc.controllers.ltv import LtvMpc, LtvMpcConfig
from auvmpc.controllers.mpc import PaperMpc, PaperMpcConfig
from auvmpc.controllers.nmpc import NmpcConfig, NonlinearMpc
from auvmpc.controllers.playback import DepthPlaybackConfig, ThrustPlayback, ThrustPlaybackConfig
from auvmpc.controllers.recovery import (
    Recovery,
    depth_recovery,
    stabilising_recovery,
    whole_vehicle_recovery,
)
from auvmpc.controllers.shell import ShelledController
from auvmpc.controllers.six_dof_nmpc import SixDofNmpc, SixDofNmpcConfig
from auvmpc.errors import FieldError, format_validation_error
from auvmpc.models.vehicle import VehicleParams

__all__ = [
    "DEFAULT_TYPE",
    "DEFAULT_TYPE_CONTEXT",
    "DEPTH_REGISTRY",
    "REGISTRY",
    "ControllerChoice",
    "ControllerEntry",
    "DepthControllerChoice",
    "build_controller",
    "class_of",
    "controller_config",
    "knob_owners",
    "register_controller",
    "retyped",
    "whole_vehicle",
]


@dataclass(frozen=True)
class ControllerEntry:
    """A controller type: the configuration its ``controller`` mapping validates as, the
    class built from it, and what builds the recovery its safety shell applies when no
    optimiser is in control (controllers/recovery.py; None: none, the shell holds the plan's
    last move)."""

    config: type[StrictModel]
    controller: type[Controller]
    recovery: Callable[[ShelledController, VehicleParams, Any], Recovery | None] | None = None


# do-mpc itself is imported only when its controller is built (an optional extra).
# The optimising horizontal controllers' shells recover with the stabilising feedback (the
# baseline is that feedback), the whole vehicle's MPC's by the vehicle (a torpedo's autopilot,
# a thruster vehicle's channel feedbacks).
REGISTRY: dict[str, ControllerEntry] = {
    ControllerType.BASELINE: ControllerEntry(BaselineControllerConfig, BaselineController),
    ControllerType.MPC: ControllerEntry(PaperMpcConfig, PaperMpc, stabilising_recovery),
    ControllerType.LTV_MPC: ControllerEntry(LtvMpcConfig, LtvMpc, stabilising_recovery),
    ControllerType.NMPC: ControllerEntry(NmpcConfig, NonlinearMpc, stabilising_recovery),
    ControllerType.DO_MPC: ControllerEntry(DoMpcConfig, DoMpcController, stabilising_recovery),
    ControllerType.THRUST_PLAYBACK: ControllerEntry(ThrustPlaybackConfig, ThrustPlayback),
    ControllerType.SIX_DOF_NMPC: ControllerEntry(
        SixDofNmpcConfig, SixDofNmpc, whole_vehicle_recovery
    ),
    ControllerType.LOS_PID: ControllerEntry(LosPidConfig, LosPid),
}
# The depth kind's (a depth scenario's ``controller``, a 6-DOF scenario's
# ``depth_controller``, which takes only the depth MPC): thrust-playback's configuration
# there is the depth one, whose table holds the vertical thrusts. The depth MPC's shell
# recovers with the depth feedback.
DEPTH_REGISTRY: dict[str, ControllerEntry] = {
    DEPTH_MPC: ControllerEntry(DepthControllerConfig, DepthMpc, depth_recovery),
    ControllerType.THRUST_PLAYBACK: ControllerEntry(DepthPlaybackConfig, ThrustPlayback),
}
# A registered name: lower-case words joined by hyphens, as the built-in ones.
_NAME = re.compile(r"[a-z][a-z0-9]*(-[a-z0-9]+)*")
# The horizontal type a ``controller`` mapping without ``type`` has, unless the validation
# context names another under DEFAULT_TYPE_CONTEXT (a scenario's vehicle decides it: a 6-DOF
# scenario's torpedo flies six-dof-nmpc, scenario.loader.validate_document).
DEFAULT_TYPE = ControllerType.NMPC
DEFAULT_TYPE_CONTEXT = "default_controller_type"
# The union member of the controllers registered at run time.
_REGISTERED = "registered"
_BUILT_IN = {name: entry.config for name, entry in REGISTRY.items()}


def register_controller(
    name: str,
    controller: type,
    *,
    config: type[HorizontalControllerConfig] = HorizontalControllerConfig,
    recovered: bool = False,
) -> None:
    """Make ``controller`` the class of ``controller.type: name`` in every scenario loaded
    afterwards in this process.

    ``controller`` is a ``controllers.base.Controller`` subclass built by
    ``controller.from_config(model, config, obstacle_count=..., **surroundings)`` if it has
    that class method, else by ``controller(model, config)``: ``model`` the nominal vehicle,
    ``config`` the scenario's ``controller`` mapping validated as ``config`` (a subclass of
    ``controllers.config.HorizontalControllerConfig``: ``type``, ``sample_time``,
    ``vehicle_radius``, ``obstacle_margin`` and the knobs you add, e.g. the blocks of
    controllers/config.py) and filled in for the vehicle. ``recovered``: a
    ``ShelledController`` whose shell steers by the stabilising feedback after a failed
    solve, as the built-in MPCs' does. A name already taken raises ValueError.
    """
    if not isinstance(name, str) or not _NAME.fullmatch(name):
        raise ValueError(f"controller name {name!r}: lower-case words joined by hyphens")
    if name in REGISTRY or name in DEPTH_REGISTRY or name == _REGISTERED:
        taken = ", ".join(dict.fromkeys([*REGISTRY, *DEPTH_REGISTRY]))
        raise ValueError(f"controller name {name!r} is taken (taken: {taken})")
    if not isinstance(controller, type) or not issubclass(controller, Controller):
        raise ValueError(f"{controller!r} is not a controllers.base.Controller subclass")
    if not isinstance(config, type) or not issubclass(config, HorizontalControllerConfig):
        raise ValueError(f"{config!r} is not a controllers.config.HorizontalControllerConfig")
    if recovered and not issubclass(controller, ShelledController):
        raise ValueError(f"{controller.__name__}: only a ShelledController has a shell to recover")
    REGISTRY[name] = ControllerEntry(
        config, controller, stabilising_recovery if recovered else None
    )


def _entry(config: Any) -> ControllerEntry:
    """The registry entry of a controller configuration, of its kind's table."""
    table = DEPTH_REGISTRY if isinstance(config, DepthChannelConfig) else REGISTRY
    return table[config.type]


def class_of(config: Any) -> type[Controller]:
    """The class of a controller configuration (a horizontal or a depth one)."""
    return _entry(config).controller


def whole_vehicle(config: Any) -> bool:
    """Whether the configuration's controller commands every 6-DOF input itself on the 6-DOF
    state (``Controller.whole_vehicle``), rather than the horizontal thrusters."""
    return bool(getattr(class_of(config), "whole_vehicle", False))


def knob_owners(knob: str, kind: type = HorizontalControllerConfig) -> list[str]:
    """The controller types of ``kind``'s table (a horizontal or a depth configuration class)
    whose configuration has ``knob``."""
    table = DEPTH_REGISTRY if issubclass(kind, DepthChannelConfig) else REGISTRY
    return [str(name) for name, entry in table.items() if knob in entry.config.model_fields]


def horizontal_types() -> list[str]:
    """The names a horizontal scenario's ``controller.type`` may take now."""
    return [str(name) for name in REGISTRY]


def _type_tag(value: Any) -> str:
    """The union member a ``controller`` value is validated as: its built-in type, or the
    member of the registered ones."""
    if isinstance(value, Mapping):
        given = value.get("type", DEFAULT_TYPE)
    else:  # a configuration, or what is none (the registered member's validation says so)
        given = getattr(value, "type", None)
    return str(given) if isinstance(given, str) and given in _BUILT_IN else _REGISTERED


def _registered_config(value: Any, info: ValidationInfo) -> Any:
    """A registered type's mapping as its own configuration class; read back from a saved
    run (context ``saved_run``), a type not registered in this process as the common part
    (the figures of a run need no controller)."""
    if not isinstance(value, Mapping):
        return value
    entry = REGISTRY.get(value["type"])
    config = entry.config if entry is not None else HorizontalControllerConfig
    return config.model_validate(value, context=info.context)


def _checked_type(value: Any, handler: Any, info: ValidationInfo) -> Any:
    """The type named first (a known one, or any name in a saved run), then the mapping
    validated as that type's configuration; an error names the field without the union
    member pydantic puts in its location. A mapping without ``type`` is the default type's
    configuration: the context's (DEFAULT_TYPE_CONTEXT), else DEFAULT_TYPE."""
    if isinstance(value, Mapping):
        context = info.context or {}
        default = context.get(DEFAULT_TYPE_CONTEXT, DEFAULT_TYPE)
        given = value.get("type", default)
        if given == DEPTH_MPC:
            where = "kind: depth scenarios, six-dof depth_controller"
            raise FieldError("type", given, f"the depth controller ({where})")
        if not (isinstance(given, str) and (given in REGISTRY or context.get(SAVED_RUN))):
            known = ", ".join(repr(name) for name in horizontal_types())
            raise FieldError("type", given, f"input should be one of {known}")
        if "type" not in value:
            # The discriminator reads no context: the default's configuration is named here
            # (``type`` stays unset, as the user left it).
            return _validated_as(REGISTRY[given].config, value, info)
    return _validated_member(value, handler)


def _validated_as(config: type[StrictModel], value: Any, info: ValidationInfo) -> Any:
    """``value`` validated as ``config``; an error names the field within the mapping."""
    try:
        return config.model_validate(value, context=info.context)
    except ValidationError as error:
        problem = format_validation_error(error)
        field = "" if problem.field == "<root>" else problem.field
        raise FieldError(field, problem.value, problem.reason) from None


def _validated_member(value: Any, handler: Any) -> Any:
    """``value`` validated as its union member; an error names the field without the
    member's tag that pydantic puts in its location."""
    try:
        return handler(value)
    except ValidationError as error:
        problem = format_validation_error(error)
        field = problem.field.partition(".")[2]  # without the member's tag
        raise FieldError(field, problem.value, problem.reason) from None


class _AnyOfSchema:
    """A union on ``type`` whose members all default their ``type``, as a JSON Schema:
    ``anyOf`` them (a mapping without ``type`` is the default member's, and fits the others'
    schemas too, which ``oneOf`` would refuse)."""

    def __get_pydantic_json_schema__(
        self, core_schema: CoreSchema, handler: GetJsonSchemaHandler
    ) -> JsonSchemaValue:
        schema = handler(core_schema)
        return {**schema, "anyOf": schema.pop("oneOf")}


class _FileSchema:
    """The union's JSON Schema as a scenario file may be written now: ``anyOf`` (as
    :class:`_AnyOfSchema`) the built-in types and the types registered when it is written."""

    def __get_pydantic_json_schema__(
        self, core_schema: CoreSchema, handler: GetJsonSchemaHandler
    ) -> JsonSchemaValue:
        schema = handler(core_schema)
        members = [m for m in schema.pop("oneOf") if m.get("title") != _REGISTERED_TITLE]
        registered = [str(name) for name in horizontal_types() if name not in _BUILT_IN]
        if registered:
            members.append({
                "type": "object",
                "title": _REGISTERED_TITLE,
                "description": "a controller given to controllers.registry.register_controller "
                "(docs/extending.md): its own knobs",
                "properties": {"type": {"enum": registered}},
                "required": ["type"],
            })  # fmt: skip
        return {**schema, "anyOf": members}


_REGISTERED_TITLE = "RegisteredControllerConfig"

ControllerChoice = Annotated[
    Union[  # noqa: UP007 (a tuple of members built from the registry)
        tuple(Annotated[config, Tag(str(name))] for name, config in _BUILT_IN.items())
        + (
            Annotated[
                SerializeAsAny[HorizontalControllerConfig],
                BeforeValidator(_registered_config),
                WithJsonSchema({"title": _REGISTERED_TITLE}),  # _FileSchema writes it
                Tag(_REGISTERED),
            ],
        )
    ],
    Discriminator(_type_tag),
    WrapValidator(_checked_type),
    _FileSchema(),
]
"""A horizontal scenario's ``controller``: the configuration of the type it names."""


def _depth_type_tag(value: Any) -> str:
    """The depth union member a value is validated as: the type it names (checked by
    :func:`_checked_depth_type`), the depth MPC's for what names none."""
    if isinstance(value, Mapping):
        return str(value.get("type", DEPTH_MPC))
    return str(getattr(value, "type", DEPTH_MPC))  # a configuration, or what is none


def _checked_depth_type(value: Any, handler: Any) -> Any:
    """The depth type named first (a horizontal one in one line saying so), then the
    mapping validated as that type's configuration."""
    if isinstance(value, Mapping):
        given = value.get("type", DEPTH_MPC)
        if not (isinstance(given, str) and given in DEPTH_REGISTRY):
            if isinstance(given, str) and given in REGISTRY:
                raise FieldError(
                    "type", given, f"a horizontal controller; depth scenarios use {DEPTH_MPC}"
                )
            known = " or ".join(repr(str(name)) for name in DEPTH_REGISTRY)
            raise FieldError("type", given, f"input should be {known}")
    return _validated_member(value, handler)


DepthControllerChoice = Annotated[
    Union[  # noqa: UP007 (a tuple of members built from the registry)
        tuple(Annotated[entry.config, Tag(str(name))] for name, entry in DEPTH_REGISTRY.items())
    ],
    Discriminator(_depth_type_tag),
    WrapValidator(_checked_depth_type),
    _AnyOfSchema(),
]
"""A depth scenario's ``controller`` and a 6-DOF scenario's ``depth_controller``: the
configuration of the depth type it names (default depth-mpc)."""


def controller_config(knobs: Mapping[str, Any], context: dict | None = None) -> Any:
    """``knobs`` (a ``controller`` mapping) validated as its type's configuration."""
    from pydantic import TypeAdapter

    try:
        return TypeAdapter(ControllerChoice).validate_python(dict(knobs), context=context)
    except ValidationError as error:
        raise format_validation_error(error, "controller") from None


def retyped(config: HorizontalControllerConfig, new_type: str, **update: Any) -> Any:
    """The configuration of ``new_type`` with the knobs ``config`` was given that it has,
    and ``update`` (what ``model_copy(update={"type": ...})`` did with one flat class)."""
    target = REGISTRY[new_type].config
    given = {
        name: getattr(config, name)
        for name in config.model_fields_set
        if name in target.model_fields and name != "type"
    }
    return target.model_validate({**given, **update, "type": new_type})


def build_controller(
    config: HorizontalControllerConfig | DepthChannelConfig,
    model: VehicleParams,
    obstacle_count: int = 0,
    **surroundings: float,
) -> Controller:
    """The configured controller on the nominal (controller-side) vehicle model.

    ``surroundings``: what else the scenario says that the controller is built for, by
    name (a depth controller's ``water_depth_m``)."""
    entry = _entry(config)
    filled = config.for_vehicle(model)
    if not hasattr(entry.controller, "from_config"):
        return entry.controller(model, filled)
    controller = entry.controller.from_config(
        model, filled, obstacle_count=obstacle_count, **surroundings
    )
    if not isinstance(controller, ShelledController):
        return controller  # its own safety rules (the C controller's shell is in its C)
    if entry.recovery is not None:
        controller.recovery = entry.recovery(controller, model, filled)
    return controller
