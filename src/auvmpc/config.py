"""Base class for every validated, immutable configuration model."""

from __future__ import annotations

import functools
import types
from collections.abc import Mapping
from importlib import resources
from typing import Annotated, Any, Union, get_args, get_origin

from pydantic import BaseModel, ConfigDict, Field, model_validator

from auvmpc.errors import FieldError, unknown_key
from auvmpc.safe_yaml import load_yaml, plain_number

__all__ = [
    "NonNegative",
    "Positive",
    "StrictModel",
    "builtin_descriptions",
]

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

    @model_validator(mode="before")
    @classmethod
    def _known_keys_only(cls, data: Any) -> Any:
        """An unknown key is named before any field is checked, with the nearest known one:
        ``duraton: 200`` would otherwise read ``duration: field required`` and hide the
        typo (``extra="forbid"`` reports it after the fields)."""
        if isinstance(data, Mapping):
            fields = _fields_by_key(cls)
            for key, value in data.items():
                if key not in fields:
                    raise FieldError(str(key), value, unknown_key(key, fields))
                _numbers_as_numbers(str(key), value, fields[key].annotation)
        return data

    def model_copy(self, *, update: Mapping[str, Any] | None = None, deep: bool = False):
        """pydantic's copy, without the values derived from the old fields: a
        ``functools.cached_property`` keeps its value in the instance's ``__dict__``, which
        pydantic copies, so a copy with new thrust limits would keep the old actuators."""
        copied = super().model_copy(update=update, deep=deep)
        if update:
            for name in _cached_properties(type(self)):
                copied.__dict__.pop(name, None)
        return copied


@functools.cache  # asked at every validation of every model
def _fields_by_key(model: type[BaseModel]) -> dict[str, Any]:
    """A model's fields by the key a file writes: the field's alias where it has one (a
    vehicle's ``actuators:`` list, whose field name the actuator set already uses)."""
    return {field.alias or name: field for name, field in model.model_fields.items()}


def _numbers_as_numbers(field: str, value: Any, annotation: Any) -> None:
    """pydantic reads ``true`` as 1 and ``"100"`` as 100 for a number (``duration: true``
    was a 1 s run, ``duration: "100"`` a 100 s one, without a word): a bool, or a number
    quoted, where the field takes only numbers is refused, also as an item of a list or a
    value of a mapping of numbers. Text that is no number is left to pydantic's error."""
    if isinstance(value, bool | str):
        if not _numbers_only(annotation):
            return
        if isinstance(value, bool):
            raise FieldError(field, value, "a number is needed, not true/false")
        if plain_number(value):
            raise FieldError(field, value, "a number is needed, not text: write it without quotes")
    elif isinstance(value, list | tuple):
        items = _item_annotations(annotation)
        for index, item in enumerate(value if items else ()):
            _numbers_as_numbers(f"{field}.{index}", item, items[min(index, len(items) - 1)])
    elif isinstance(value, Mapping):
        values = _value_annotation(annotation)
        for key, item in value.items() if values is not None else ():
            _numbers_as_numbers(f"{field}.{key}", item, values)


def _arms(annotation: Any) -> list[Any]:
    """The types an annotation allows, Annotated and Optional taken apart."""
    origin = get_origin(annotation)
    if origin is Annotated:
        return _arms(get_args(annotation)[0])
    if origin in (Union, types.UnionType):
        return [arm for part in get_args(annotation) for arm in _arms(part)]
    return [annotation]


def _numbers_only(annotation: Any) -> bool:
    arms = [arm for arm in _arms(annotation) if arm is not type(None)]
    return bool(arms) and all(arm in (int, float) for arm in arms)


def _item_annotations(annotation: Any) -> list[Any]:
    """The item types of a tuple or list annotation (one per place, or one for all)."""
    for arm in _arms(annotation):
        if get_origin(arm) in (tuple, list):
            return [a for a in get_args(arm) if a is not Ellipsis]
    return []


def _value_annotation(annotation: Any) -> Any:
    """The value type of a mapping annotation (``dict[str, float]``), or None."""
    for arm in _arms(annotation):
        if get_origin(arm) is dict:
            return get_args(arm)[1]
    return None


@functools.cache
def _cached_properties(model: type) -> tuple[str, ...]:
    """The names of a class's ``functools.cached_property`` members, its bases' too."""
    return tuple(
        name
        for klass in model.__mro__
        for name, member in vars(klass).items()
        if isinstance(member, functools.cached_property)
    )


def builtin_descriptions(kind: str) -> dict[str, str]:
    """Names and one-line descriptions of the YAML files in ``presets/<kind>``."""
    return dict(_builtin_descriptions(kind))


@functools.cache  # package data: parsing every preset took 80 ms per scenario loaded
def _builtin_descriptions(kind: str) -> dict[str, str]:
    folder = resources.files("auvmpc.presets") / kind
    found = {}
    for item in sorted(folder.iterdir(), key=lambda p: p.name):
        if item.name.endswith(".yaml"):
            data = load_yaml(item.read_text()) or {}
            found[item.name.removesuffix(".yaml")] = str(data.get("description", ""))
    return found
