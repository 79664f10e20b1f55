"""Base class for every validated, immutable configuration model."""

from __future__ import annotations

import functools
from collections.abc import Mapping
from importlib import resources
from pathlib import Path
from typing import Annotated, Any

import yaml
from pydantic import BaseModel, ConfigDict, Field

from auvmpc.errors import ConfigError

__all__ = [
    "NonNegative",
    "Positive",
    "StrictModel",
    "builtin_descriptions",
    "load_yaml",
    "read_text_file",
    "read_yaml_mapping",
]

# A scenario, vehicle or campaign file larger than this is not one (the largest preset is
# 3 kB); reading it whole would only waste memory before the parser refuses it.
MAX_TEXT_FILE_BYTES = 16 * 1024 * 1024


# The number constraints every configuration model uses.
NonNegative = Annotated[float, Field(ge=0)]
Positive = Annotated[float, Field(gt=0)]


class StrictModel(BaseModel):
    """Frozen, no unknown keys, no NaN/inf, no silent type coercion from strings."""

    model_config = ConfigDict(
        frozen=True,
        extra="forbid",
        allow_inf_nan=False,
        validate_default=True,
    )

    def model_copy(self, *, update: Mapping[str, Any] | None = None, deep: bool = False):
        """pydantic's copy, without the values derived from the old fields: a
        ``functools.cached_property`` keeps its value in the instance's ``__dict__``, which
        pydantic copies, so a copy with new thrust limits would keep the old actuators."""
        copied = super().model_copy(update=update, deep=deep)
        if update:
            for name in _cached_properties(type(self)):
                copied.__dict__.pop(name, None)
        return copied


@functools.cache
def _cached_properties(model: type) -> tuple[str, ...]:
    """The names of a class's ``functools.cached_property`` members, its bases' too."""
    return tuple(
        name
        for klass in model.__mro__
        for name, member in vars(klass).items()
        if isinstance(member, functools.cached_property)
    )


class _UniqueKeyLoader(yaml.SafeLoader):
    """YAML's safe loader, but a key given twice in one mapping is an error: silently
    keeping the last one hides a typo or a merge mistake."""


def _unique_mapping(loader: _UniqueKeyLoader, node: yaml.MappingNode, deep: bool = False):
    seen: set = set()
    for key_node, _ in node.value:
        if key_node.tag == "tag:yaml.org,2002:merge":
            continue
        key = loader.construct_object(key_node, deep=deep)
        try:
            duplicate = key in seen
        except TypeError:  # unhashable key: the base constructor reports it
            break
        if duplicate:
            raise yaml.constructor.ConstructorError(
                None, None, f"duplicate key {key!r}", key_node.start_mark
            )
        seen.add(key)
    return yaml.SafeLoader.construct_mapping(loader, node, deep=deep)


_UniqueKeyLoader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _unique_mapping)


def load_yaml(text: str) -> Any:
    """``yaml.safe_load`` that rejects duplicate keys (raises ``yaml.YAMLError``)."""
    return yaml.load(text, Loader=_UniqueKeyLoader)  # noqa: S506 (a SafeLoader subclass)


def read_text_file(path: str | Path, field: str, what: str) -> str:
    """The text of a user's file; a folder, a missing file, a binary or huge file is a
    one-line :class:`ConfigError` naming ``field``."""
    file = Path(path)
    if file.is_dir():
        raise ConfigError(field, str(path), f"is a folder, not a {what}")
    if not file.is_file():
        raise ConfigError(field, str(path), f"no such {what}")
    try:
        size = file.stat().st_size
        if size > MAX_TEXT_FILE_BYTES:
            raise ConfigError(
                field, str(path), f"is {size} bytes, too large for a {what} (binary?)"
            )
        data = file.read_bytes()
    except OSError as error:
        raise ConfigError(field, str(path), f"cannot be read ({error.strerror})") from None
    if b"\x00" in data:
        raise ConfigError(field, str(path), f"is a binary file, not a {what} (YAML text)")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as error:
        raise ConfigError(
            field, str(path), f"is not UTF-8 text (byte {error.start}); a {what} is YAML text"
        ) from None


def read_yaml_mapping(text: str, field: str, origin: str, what: str = "fields") -> dict[str, Any]:
    """Parse a YAML document that must be a mapping; errors name ``field`` and ``origin``.

    A key given twice in one mapping is an error."""
    try:
        data = load_yaml(text)
    except yaml.YAMLError as error:
        mark = getattr(error, "problem_mark", None)
        where = f" at line {mark.line + 1}" if mark is not None else ""
        problem = getattr(error, "problem", None)
        detail = f": {problem}" if problem and str(problem).startswith("duplicate key") else ""
        raise ConfigError(field, origin, f"not valid YAML{where}{detail}") from None
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
