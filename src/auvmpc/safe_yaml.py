"""The one YAML loader for everything auvmpc reads: scenario, vehicle and campaign files,
the presets and ``--set`` values.

PyYAML's safe loader with limits checked while the document is composed, before any of it
is built: a 1 kB "billion laughs" alias bomb expands to 10^9 values and a file of ten
thousand ``[`` ends in a RecursionError, so both are refused from the node graph alone. A
key given twice is refused too (keeping the last one hides a typo or a merge mistake).
Every refusal is a ``yaml.YAMLError`` that :func:`yaml_problem` says in a few words.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import yaml
from yaml.composer import Composer
from yaml.constructor import ConstructorError, SafeConstructor
from yaml.events import AliasEvent
from yaml.resolver import Resolver

from auvmpc.errors import ConfigError

__all__ = [
    "MAX_YAML_BYTES",
    "MAX_YAML_DEPTH",
    "MAX_YAML_VALUES",
    "YamlLimit",
    "load_yaml",
    "plain_number",
    "read_text_file",
    "read_yaml_mapping",
    "yaml_problem",
]

# The largest preset is 3 kB; the loader reads over 1 MB/s (libyaml's events), 200 kB/s
# without libyaml, so 512 kB is under 3 s of parsing either way. A long track belongs in a
# CSV file (reference type csv).
MAX_YAML_BYTES = 512 * 1024
# Values in a document with its aliases expanded: about what 512 kB of YAML holds at 5
# bytes a value; a bomb's billions are refused at the first alias that passes it.
MAX_YAML_VALUES = 100_000
# Settings nest about 6 deep; Python's recursion limit ends near 330 in PyYAML's composer.
MAX_YAML_DEPTH = 50
# More digits than any float holds (1.8e308): no setting needs such an integer, and past
# 4300 Python refuses to read it at all.
MAX_INT_DIGITS = 400


class YamlLimit(yaml.MarkedYAMLError):
    """A document refused for its size, nesting or aliases, not for its syntax."""


Part = str | int | None  # a key, a list index, or None for a mapping's key itself


def _refusal(kind: type[yaml.MarkedYAMLError], problem: str, mark, path: list[Part]):
    """An error of ``kind`` at ``mark``, with the key path it is at (``key_path``, which
    :func:`yaml_problem` names): known to the loader while it reads, lost after."""
    error = kind(None, None, problem, mark)
    error.key_path = list(path)
    return error


if yaml.__with_libyaml__:
    from yaml.cyaml import CParser

    class _EventsInC(Composer, CParser, SafeConstructor, Resolver):
        """The safe loader with libyaml scanning and parsing into events (C) and PyYAML's
        composer building the nodes from them (Python, where the checks below hook in):
        a 235 kB document loads in 0.19 s against 1.26 s all in Python."""

        def __init__(self, stream: str) -> None:
            CParser.__init__(self, stream)
            Composer.__init__(self)
            SafeConstructor.__init__(self)
            Resolver.__init__(self)

    _Loader: type = _EventsInC
else:  # a PyYAML built without libyaml: all in Python
    _Loader = yaml.SafeLoader


class _SafeLoader(_Loader):
    """The safe loader counting, while composing, the nesting depth and the values the
    document holds with each alias expanded (an alias counts as its anchor's values), and
    keeping where each node is (its parent and key), for the key path of a refusal."""

    def __init__(self, stream: str) -> None:
        super().__init__(stream)
        self._depth = 0
        self._values = 0
        self._anchor_values: dict[yaml.Node, int] = {}  # finished anchored nodes only
        self._path: list[Part] = []  # down to the node being composed
        self._parents: dict[yaml.Node, tuple[yaml.Node | None, Part]] = {}

    def compose_node(self, parent, index):
        event = self.peek_event()
        if isinstance(parent, yaml.SequenceNode):
            self._path.append(index)
        else:  # a mapping's value is under its key; the key itself, or the root, under none
            self._path.append(index.value if isinstance(index, yaml.ScalarNode) else None)
        if isinstance(event, AliasEvent):
            node = self.anchors.get(event.anchor)
            if node is not None:  # an undefined alias: PyYAML's own error
                if node not in self._anchor_values:
                    problem = f"alias *{event.anchor} inside its own anchor (a cycle)"
                    raise _refusal(YamlLimit, problem, event.start_mark, self._path)
                self._count(self._anchor_values[node], event)
            node = super().compose_node(parent, index)
        else:
            if self._depth >= MAX_YAML_DEPTH:
                problem = f"nested more than {MAX_YAML_DEPTH} levels deep"
                raise _refusal(YamlLimit, problem, event.start_mark, self._path)
            before = self._values
            self._count(1, event)
            self._depth += 1
            node = super().compose_node(parent, index)
            self._depth -= 1
            self._parents[node] = (parent, self._path[-1])
            if event.anchor is not None:
                self._anchor_values[node] = self._values - before
        self._path.pop()
        return node

    def _count(self, values: int, event) -> None:
        self._values += values
        if self._values > MAX_YAML_VALUES:
            problem = f"holds more than {MAX_YAML_VALUES} values with its aliases expanded"
            raise _refusal(YamlLimit, problem, event.start_mark, self._path)

    def path_of(self, node: yaml.Node) -> list[Part]:
        """The keys and indices from the document's root down to ``node`` (a key: down to
        its mapping)."""
        path: list[Part] = []
        while node in self._parents:
            node, part = self._parents[node]
            if part is not None:
                path.append(part)
        return path[::-1]

    def construct_object(self, node, deep=False):
        # A scalar PyYAML resolves but Python cannot build (a timestamp 2024-13-45).
        try:
            return super().construct_object(node, deep=deep)
        except (ValueError, OverflowError) as error:
            kind = node.tag.rsplit(":", 1)[-1]
            problem = f"{node.value!r} is not a valid {kind} ({error})"
            raise _refusal(ConstructorError, problem, node.start_mark, self.path_of(node)) from None


def _unique_mapping(loader: _SafeLoader, node: yaml.MappingNode, deep: bool = False):
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
            where = loader.path_of(node)  # at the top level, the key alone says where
            raise _refusal(
                ConstructorError, f"duplicate key {key!r}", key_node.start_mark,
                [*where, key_node.value] if where else [],
            )  # fmt: skip
        seen.add(key)
    return SafeConstructor.construct_mapping(loader, node, deep=deep)


def _bounded_int(loader: _SafeLoader, node: yaml.ScalarNode) -> int:
    digits = sum(character.isdigit() for character in node.value)
    if digits > MAX_INT_DIGITS:
        problem = f"an integer of {digits} digits (at most {MAX_INT_DIGITS})"
        raise _refusal(YamlLimit, problem, node.start_mark, loader.path_of(node))
    return SafeConstructor.construct_yaml_int(loader, node)


# "\ud800" in a double-quoted string is a lone UTF-16 surrogate, not a character: no UTF-8
# file, terminal or pydantic can take one (a UnicodeEncodeError traceback before, issue 28).
_SURROGATE = re.compile("[\ud800-\udfff]")


def _text(loader: _SafeLoader, node: yaml.ScalarNode) -> str:
    value = SafeConstructor.construct_yaml_str(loader, node)
    found = _SURROGATE.search(value)
    if found:
        problem = (
            f"{found.group()!r} is half of a UTF-16 surrogate pair, not a character (write a "
            "character beyond U+FFFF as \\U0001F600)"
        )
        raise _refusal(ConstructorError, problem, node.start_mark, loader.path_of(node))
    return value


_SafeLoader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _unique_mapping)
_SafeLoader.add_constructor("tag:yaml.org,2002:str", _text)
_SafeLoader.add_constructor("tag:yaml.org,2002:int", _bounded_int)


def load_yaml(text: str) -> Any:
    """``yaml.safe_load`` within the limits above, refusing duplicate keys; raises
    ``yaml.YAMLError`` (a :class:`YamlLimit` for a limit)."""
    if len(text) > MAX_YAML_BYTES:
        raise YamlLimit(None, None, f"{len(text)} characters, more than {MAX_YAML_BYTES}")
    try:
        return yaml.load(text, Loader=_SafeLoader)  # noqa: S506 (a SafeLoader subclass)
    except yaml.scanner.ScannerError as error:
        # libyaml reads a flow collection ahead and stops at its own depth limit (1000)
        # before the composer reaches ours: the same refusal
        if "maximum nesting depth" not in str(error.problem):
            raise
        problem = f"nested more than {MAX_YAML_DEPTH} levels deep"
        raise YamlLimit(None, None, problem, error.problem_mark) from None


_RESOLVER = yaml.resolver.Resolver()  # the safe loader's: it adds no implicit types
_NUMBER_TAGS = ("tag:yaml.org,2002:int", "tag:yaml.org,2002:float")


def plain_number(text: str) -> bool:
    """Whether YAML reads ``text``, written without quotes, as a number: ``"100"`` in a
    file is a number quoted. (``1e3`` is not: YAML 1.1 reads it as text, quoted or not.)"""
    return _RESOLVER.resolve(yaml.ScalarNode, text.strip(), (True, False)) in _NUMBER_TAGS


def yaml_problem(error: yaml.YAMLError, line: bool = True) -> str:
    """What is wrong in a few words, and where in a file (``line``; a value on the command
    line has no lines, and its keys are relative to its field): ``not valid YAML at line 4:
    duplicate key 'Q' at controller.Q``, ``refused at line 2: nested more than 50 levels
    deep at description.0.0.0.0.0...``."""
    mark = getattr(error, "problem_mark", None)
    where = f" at line {mark.line + 1}" if line and mark is not None else ""
    problem = getattr(error, "problem", None)
    path = getattr(error, "key_path", None) if line else None
    detail = f": {problem}{_key_path(path)}" if problem else ""
    lead = "refused" if isinstance(error, YamlLimit) else "not valid YAML"
    return f"{lead}{where}{detail}"


def _key_path(path: list[Part] | None) -> str:
    """`` at controller.Q`` (the first 6 parts), or nothing at the document's root."""
    parts = [str(part) for part in path or () if part is not None]
    if not parts:
        return ""
    shown = ".".join(p if p.isprintable() and len(p) <= 40 else repr(p[:40]) for p in parts[:6])
    return f" at {shown}{'...' if len(parts) > 6 else ''}"


def read_text_file(path: str | Path, field: str, what: str, limit: int = MAX_YAML_BYTES) -> str:
    """The text of a user's file; a folder, a missing file, a binary file or one larger than
    ``limit`` bytes (a YAML file's by default) is a one-line :class:`ConfigError` naming
    ``field``."""
    file = Path(path)
    if file.is_dir():
        raise ConfigError(field, str(path), f"is a folder, not a {what}")
    if not file.is_file():
        raise ConfigError(field, str(path), f"no such {what}")
    try:
        size = file.stat().st_size
        if size > limit:
            raise ConfigError(
                field, str(path), f"is {size} bytes, more than a {what} may be ({limit})"
            )
        data = file.read_bytes()
    except OSError as error:
        raise ConfigError(field, str(path), f"cannot be read ({error.strerror})") from None
    if b"\x00" in data:
        raise ConfigError(field, str(path), f"is a binary file, not a {what}")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as error:
        raise ConfigError(
            field, str(path), f"is not UTF-8 text (byte {error.start}); a {what} is text"
        ) from None


def read_yaml_mapping(text: str, field: str, origin: str, what: str = "fields") -> dict[str, Any]:
    """Parse a YAML document that must be a mapping; errors name ``field`` and ``origin``."""
    try:
        data = load_yaml(text)
    except yaml.YAMLError as error:
        raise ConfigError(field, origin, yaml_problem(error)) from None
    if not isinstance(data, dict):
        raise ConfigError(field, origin, f"expected a mapping of {what}")
    return data
