"""Errors that reach a user as one line: the field, the value, what is wrong."""

from __future__ import annotations

__all__ = ["ConfigError", "format_validation_error"]


class ConfigError(ValueError):
    """Bad user input (file, field or value). The CLI prints it as one line, exit code 2."""

    def __init__(self, field: str, value: object, reason: str) -> None:
        self.field = field
        self.value = value
        self.reason = reason
        super().__init__(f"{field}: {reason} (got {_short(value)})")


def _short(value: object, limit: int = 80) -> str:
    text = repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def format_validation_error(error, prefix: str = "") -> ConfigError:
    """Turn a pydantic ValidationError into a ConfigError naming the first bad field."""
    first = error.errors()[0]
    location = ".".join(str(part) for part in first["loc"] if part != "__root__")
    field = ".".join(part for part in (prefix, location) if part) or "<root>"
    reason = first["msg"]
    if first["type"] == "extra_forbidden":
        reason = "unknown key"
    value = first.get("input")
    return ConfigError(field, value, reason[0].lower() + reason[1:] if reason else "invalid")
