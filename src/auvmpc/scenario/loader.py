"""Loading a scenario: a built-in name or a YAML file, command-line overrides, its kind."""

from __future__ import annotations

from collections.abc import Sequence
from importlib import resources
from pathlib import Path
from typing import Any

import yaml
from pydantic import ValidationError

from auvmpc.config import builtin_descriptions
from auvmpc.controllers.registry import DEFAULT_TYPE_CONTEXT
from auvmpc.errors import ConfigError, format_validation_error
from auvmpc.models.layout import WORLD_VECTOR
from auvmpc.models.vehicle import VehicleParams
from auvmpc.safe_yaml import load_yaml, read_text_file, read_yaml_mapping, yaml_problem
from auvmpc.scenario.depth import DepthScenario
from auvmpc.scenario.model import Scenario, SixDofScenario
from auvmpc.scenario.resolved import (
    ResolvedDepthScenario,
    ResolvedScenario,
    ResolvedSixDofScenario,
    load_vehicle_relative,
)

__all__ = [
    "apply_override",
    "apply_overrides",
    "builtin_scenarios",
    "load_scenario",
    "planar_twin",
    "resolve_document",
    "scenario_to_dict",
    "validate_scenario",
]


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
        velocity = list(water.velocity_m_per_s)
        velocity[WORLD_VECTOR.index("z")] = 0.0  # the plane has no vertical velocity
        current = water.model_copy(update={"velocity_m_per_s": tuple(velocity)})
        data["disturbance"] = {"water_current": current.model_dump(mode="json")}
    data["name"] = f"{scenario.name}-planar"
    return validate_scenario(data)


def builtin_scenarios() -> dict[str, str]:
    """Built-in scenario names and their one-line descriptions."""
    return builtin_descriptions("scenarios")


def load_scenario(
    source: str | Path, overrides: Sequence[str] = ()
) -> ResolvedScenario | ResolvedDepthScenario:
    """Load a built-in scenario by name or a YAML file, apply ``field=value`` overrides.

    A file with ``kind: depth`` is a depth experiment (auvmpc.scenario.depth), one with
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
    return resolve_document(data, base_dir, apply_overrides(data, overrides))


# A scenario document's ``kind``: its schema and what it resolves to for its vehicle.
SCENARIO_KINDS = {
    "horizontal": (Scenario, ResolvedScenario),
    "six-dof": (SixDofScenario, ResolvedSixDofScenario),
    "depth": (DepthScenario, ResolvedDepthScenario),
}


def resolve_document(
    data: dict[str, Any], base_dir: Path, notes: Sequence[str] = ()
) -> ResolvedScenario | ResolvedDepthScenario:
    """A scenario document (a mapping as read from YAML) validated by the schema its
    ``kind`` names and resolved for its vehicle; a bad field is one line naming it. A
    document without a known ``kind`` is a horizontal one (which refuses a ``kind`` it is
    not: "kind: input should be 'horizontal'"). ``notes``: what the overrides decided that
    the user should hear of (run.json ``warnings``)."""
    document = validate_document(data, base_dir)
    scenario = SCENARIO_KINDS[document.kind][1](document, base_dir)
    scenario.notes = [*notes, *scenario.notes]
    return scenario


def validate_document(
    data: dict[str, Any], base_dir: Path | None = None
) -> Scenario | DepthScenario:
    """A scenario document validated by the schema its ``kind`` names (a horizontal one's
    without a known ``kind``), not yet resolved for its vehicle; a bad field is one line.

    A ``controller`` mapping without ``type`` is validated as the default type for the
    document's vehicle (a 6-DOF torpedo's is six-dof-nmpc), read from ``base_dir`` as the
    resolution reads it (None: the working directory)."""
    kind = data.get("kind")
    known = kind if isinstance(kind, str) and kind in SCENARIO_KINDS else "horizontal"
    schema, resolved = SCENARIO_KINDS[known]
    context = None
    if issubclass(resolved, ResolvedScenario):  # a depth scenario's controller is depth-mpc's
        vehicle = _vehicle_or_none(data.get("vehicle", schema.model_fields["vehicle"].default),
                                   base_dir or Path.cwd())  # fmt: skip
        if vehicle is not None:
            context = {DEFAULT_TYPE_CONTEXT: resolved.default_controller_type(vehicle)}
    return _validated(schema, data, context)


def _vehicle_or_none(source: Any, base_dir: Path) -> VehicleParams | None:
    """The vehicle a document names, or None where it names none that loads (the resolution
    says what is wrong with it, after the fields are checked)."""
    if not isinstance(source, str | dict):
        return None
    try:
        return load_vehicle_relative(source, base_dir)
    except ConfigError:
        return None


def validate_scenario(data: dict[str, Any]) -> Scenario:
    """A horizontal scenario document validated (:func:`validate_document` takes any kind)."""
    return _validated(Scenario, data)


def _validated(schema: type, data: dict[str, Any], context: dict[str, Any] | None = None) -> Any:
    try:
        return schema.model_validate(data, context=context)
    except ValidationError as error:
        raise format_validation_error(error) from None


def apply_override(data: dict[str, Any], override: str) -> list[str]:
    """Set ``a.b.0.c=value`` in a nested mapping; the value is read as YAML.

    Returns what the user should hear of: a ``controller.type`` (a 6-DOF scenario's
    ``depth_controller.type``) changed to another controller of its kind drops the knobs
    given so far that the new type has not (the previous type's, e.g. a file's nmpc_mode
    under ``--controller ltv-mpc``), saying which; a knob set after the change is checked
    against the new type."""
    path, separator, raw_value = override.partition("=")
    if not separator or not path:
        raise ConfigError("--set", override, "expected field=value")
    if not path.isprintable():  # a newline in it made the error several lines
        raise ConfigError("--set", override, "the field holds a control character")
    try:
        value = load_yaml(raw_value)
    except yaml.YAMLError as error:
        raise ConfigError(path, raw_value, f"value is {yaml_problem(error, line=False)}") from None
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
            old_types = _controller_types(data)
            retyping = len(keys) == 2 and keys[0] in old_types and keys[1] == "type"
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
    return _drop_foreign_knobs(data, old_types) if retyping else []


def apply_overrides(data: dict[str, Any], overrides: Sequence[str]) -> list[str]:
    """:func:`apply_override` each of ``overrides`` in order (``--controller`` and ``--set``);
    where they change the controller's type, also the knobs they set that the new type has
    not are dropped (``--set controller.R=[1] --controller baseline``: the R was for the
    file's type). Returns what the user should hear of."""
    old_types = _controller_types(data)
    notes = [note for override in overrides for note in apply_override(data, override)]
    return notes + _drop_foreign_knobs(data, old_types)


def _controller_types(data: dict[str, Any]) -> dict[str, tuple[Any, dict[str, Any]]]:
    """Scenario ``data``'s controller mappings by field (``controller``, and a 6-DOF
    scenario's ``depth_controller``), each with the type it names (omitted: its kind's
    default) and the registry table of its kind."""
    from auvmpc.controllers.config import DEPTH_MPC
    from auvmpc.controllers.registry import DEFAULT_TYPE, DEPTH_REGISTRY, REGISTRY

    kind = data.get("kind")
    fields = {
        "controller": (DEPTH_MPC, DEPTH_REGISTRY) if kind == "depth" else (DEFAULT_TYPE, REGISTRY)
    }
    if kind == "six-dof":
        fields["depth_controller"] = (DEPTH_MPC, DEPTH_REGISTRY)
    types = {}
    for field, (default, table) in fields.items():
        controller = data.get(field)  # omitted: the default type's defaults
        given = controller.get("type", default) if isinstance(controller, dict) else default
        types[field] = (given, table)
    return types


def _drop_foreign_knobs(data: dict[str, Any], old_types: dict[str, tuple[Any, Any]]) -> list[str]:
    """Where a controller mapping of scenario ``data`` no longer names the type it named
    (``old_types``, as :func:`_controller_types` gave them): drop the knobs it holds that the
    new type's configuration has not, and say so (a knob of the type it names is kept, and
    checked)."""
    notes = []
    for field, (new_type, table) in _controller_types(data).items():
        old_type = old_types.get(field, (new_type,))[0]
        if new_type == old_type or not isinstance(new_type, str) or new_type not in table:
            continue  # an unknown type is refused by the validation, naming it
        controller = data[field]
        knobs = table[new_type].config.model_fields
        dropped = [key for key in controller if key not in knobs]
        for key in dropped:
            del controller[key]
        if dropped:
            notes.append(
                f"{field}.type: {old_type} changed to {new_type} by an override; dropped what "
                f"{new_type} has no knob for: {', '.join(map(str, dropped))}"
            )
    return notes


def scenario_to_dict(scenario: Scenario | DepthScenario) -> dict[str, Any]:
    """JSON-ready, fully resolved form (defaults filled in)."""
    return scenario.model_dump(mode="json")
