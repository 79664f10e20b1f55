"""Errors that reach a user as one line: the field, the value, what is wrong."""

from __future__ import annotations

import difflib
from collections.abc import Iterable

__all__ = [
    "ConfigError",
    "FieldError",
    "RunFailed",
    "format_validation_error",
    "shortened",
    "unknown_key",
]


class ConfigError(ValueError):
    """Bad user input (file, field or value). The CLI prints it as one line, exit code 2."""

    def __init__(self, field: str, value: object, reason: str) -> None:
        self.field = field
        self.value = value
        self.reason = reason
        # the reason may quote the user's text (a CSV header): one line whatever it holds
        super().__init__(f"{_printable(field)}: {_printable(reason)} (got {_short(value)})")


class RunFailed(RuntimeError):
    """The simulation itself broke down (a numerical failure in a controller or the plant).

    One line for the user: where (time and step) and what; the original exception is the
    ``__cause__``. The CLI prints it as one line, exit code 1."""


class FieldError(ValueError):
    """Raised by a model validator that checks several fields: names the one at fault."""

    def __init__(self, field: str, value: object, reason: str) -> None:
        self.field = field
        self.value = value
        self.reason = reason
        super().__init__(f"{field}: {reason}")


def _printable(text: str) -> str:
    """Text from the user (a key, a --set path, a quoted header) on one line: a newline,
    another control character or a lone surrogate escaped as repr() would (``\n``,
    ``\ud800``)."""
    return "".join(c if c.isprintable() else repr(c)[1:-1] for c in str(text))


def _short(value: object) -> str:
    return shortened(repr(value))


def shortened(text: str, limit: int = 80) -> str:
    """At most ``limit`` characters of ``text`` (a value quoted in a refusal): its start and
    its end with "..." between, since a long path's end is its file name, the part that
    says which file was refused."""
    if len(text) <= limit:
        return text
    head = (limit - 3) * 2 // 5
    return text[:head] + "..." + text[len(text) - (limit - 3 - head) :]


def unknown_key(key: object, known: Iterable[str]) -> str:
    """The reason for an unknown key, with the nearest known one if one is near:
    ``unknown key, did you mean duration?``."""
    near = difflib.get_close_matches(str(key), list(known), n=1)
    return f"unknown key, did you mean {near[0]}?" if near else "unknown key"


def format_validation_error(error, prefix: str = "", source: str = "") -> ConfigError:
    """Turn a pydantic ValidationError into a ConfigError naming the first bad field, and
    the file it comes from if ``source`` names one."""
    first = error.errors()[0]
    location = ".".join(str(part) for part in first["loc"] if part != "__root__")
    reason = first["msg"]
    value = first.get("input")
    cause = first.get("ctx", {}).get("error")
    if isinstance(cause, FieldError):
        location = ".".join(part for part in (location, cause.field) if part)
        reason, value = cause.reason, cause.value
    field = ".".join(part for part in (prefix, location) if part) or "<root>"
    if first["type"] == "extra_forbidden":
        reason = "unknown key"
    reason = reason[0].lower() + reason[1:] if reason else "invalid"
    return ConfigError(field, value, f"{reason} ({source})" if source else reason)
