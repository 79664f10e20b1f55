"""Base class for every validated, immutable configuration model."""

from __future__ import annotations

from importlib import resources
from typing import Any

import yaml
from pydantic import BaseModel, ConfigDict

from auvmpc.errors import ConfigError

__all__ = ["StrictModel", "builtin_descriptions", "read_yaml_mapping"]


class StrictModel(BaseModel):
    """Frozen, no unknown keys, no NaN/inf, no silent type coercion from strings."""

    model_config = ConfigDict(
        frozen=True,
        extra="forbid",
        allow_inf_nan=False,
        validate_default=True,
    )


def read_yaml_mapping(text: str, field: str, origin: str, what: str = "fields") -> dict[str, Any]:
    """Parse a YAML document that must be a mapping; errors name ``field`` and ``origin``."""
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as error:
        mark = getattr(error, "problem_mark", None)
        where = f" at line {mark.line + 1}" if mark is not None else ""
        raise ConfigError(field, origin, f"not valid YAML{where}") from None
    if not isinstance(data, dict):
        raise ConfigError(field, origin, f"expected a mapping of {what}")
    return data


def builtin_descriptions(kind: str) -> dict[str, str]:
    """Names and one-line descriptions of the YAML files in ``presets/<kind>``."""
    folder = resources.files("auvmpc.presets") / kind
    found = {}
    for item in sorted(folder.iterdir(), key=lambda p: p.name):
        if item.name.endswith(".yaml"):
            data = yaml.safe_load(item.read_text()) or {}
            found[item.name.removesuffix(".yaml")] = str(data.get("description", ""))
    return found
