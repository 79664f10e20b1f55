"""What the fuzz suites share (issue 28, item 5): the two hypothesis profiles, hostile values,
a YAML writer that can say what ``yaml.safe_dump`` never would (anchors, aliases, bombs,
duplicate keys, raw scalars such as ``.nan`` or a 400-digit integer), damage to text (cut,
flipped bytes), and the property every generated input is held to.

The property: the in-process command line ends in 0, or in exit 2 (1 only for the documented
run failures, ``... failed at t = ...`` or ``... lost: the plant diverged at t = ...``) with
1-3 lines on stderr besides warnings, the first ``error: ``, never a traceback; within
:data:`DEADLINE_S` (a hang is a finding) and with the process's peak memory grown by less
than :data:`MEMORY_LIMIT_BYTES`.

Profiles: ``short`` (derandomized, a few dozen inputs per strategy, part of ``make test``)
and ``long`` (``AUVMPC_FUZZ=long``, ``make fuzz``: >= 10,000 inputs in all). Neither keeps
an example database.
"""

from __future__ import annotations

import json
import math
import os
import resource
import signal
import sys
from collections import Counter
from dataclasses import dataclass
from typing import Any

from hypothesis import HealthCheck, Phase, settings
from hypothesis import strategies as st

from auvmpc.cli import main

PROFILE = os.environ.get("AUVMPC_FUZZ", "short")
# Examples per strategy in each profile; the long one's add up to >= 10,000 (make fuzz).
EXAMPLES = {
    "short": {
        "scenario": 30, "vehicle": 15, "campaign": 10, "csv": 20, "set": 30, "run folder": 8,
    },
    "long": {
        "scenario": 2000, "vehicle": 1600, "campaign": 600, "csv": 1800, "set": 3200,
        "run folder": 800,
    },
}[PROFILE]  # fmt: skip
_COMMON = dict(
    database=None,  # nothing lands in the repository
    deadline=None,  # the hard deadline below interrupts a hang; hypothesis' only measures
    print_blob=True,
    # no explain phase: its tracing makes an example many times slower, past the deadline
    phases=[Phase.explicit, Phase.reuse, Phase.generate, Phase.target, Phase.shrink],
    suppress_health_check=[
        HealthCheck.too_slow,
        HealthCheck.function_scoped_fixture,
        HealthCheck.data_too_large,
        HealthCheck.filter_too_much,
    ],
)
settings.register_profile("fuzz-short", derandomize=True, **_COMMON)
settings.register_profile("fuzz-long", derandomize=False, **_COMMON)
FUZZ = settings.get_profile(f"fuzz-{PROFILE}")

# The bounds: an answer within 10 s on this machine and under 1 GiB of memory.
DEADLINE_S = 10.0
MEMORY_LIMIT_BYTES = 1 << 30

GENERATED: Counter[str] = Counter()


class Hang(BaseException):
    """Raised by the alarm: a BaseException, so no ``except Exception`` in the code under
    test can turn it into an answer (:func:`run_cli` makes it a failed assertion, which
    hypothesis shrinks and reports)."""


_FIRED: list[float] = []


def _alarm(signum, frame):
    _FIRED.append(DEADLINE_S)
    raise Hang


def _peak_rss() -> int:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024  # kB on Linux


def run_cli(monkeypatch, capsys, *args: str, stop=()) -> tuple[int | None, str]:
    """The command line in-process, under the deadline: (exit code, stderr). An exception
    in ``stop`` (raised by a stub to end a command early) counts as exit ``None``; any other
    exception escapes, as it would from the console script."""
    monkeypatch.setattr(sys, "argv", ["auvmpc", *args])
    before = _peak_rss()
    previous = signal.signal(signal.SIGALRM, _alarm)
    signal.setitimer(signal.ITIMER_REAL, DEADLINE_S)
    try:
        main()
        code: int | None = 0
    except SystemExit as exit_:
        code = int(exit_.code or 0)
    except stop:
        code = None
    except Hang:
        code = None
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)
    fired, _FIRED[:] = bool(_FIRED), []
    assert not fired, f"no answer within {DEADLINE_S} s (a hang): {args}"
    grown = _peak_rss() - before
    assert grown < MEMORY_LIMIT_BYTES, f"peak memory grew by {grown / 2**20:.0f} MiB: {args}"
    return code, capsys.readouterr().err


def assert_clean(
    code: int | None, stderr: str, may_fail_run: bool = False, verdict: str | None = None
) -> None:
    """The property: success, or one clean refusal; ``verdict``, a command's documented
    exit-1 line (verify-c's ``not reproduced: ...``), is an answer too."""
    if verdict is not None and code == 1 and stderr.strip().startswith(verdict):
        assert len(stderr.strip().splitlines()) == 1, stderr
        return
    assert "Traceback" not in stderr, stderr
    if code in (0, None):
        return
    lines = [line for line in stderr.splitlines() if line.strip()]
    said = [line for line in lines if not line.startswith("warning: ")]
    assert code in (1, 2), (code, stderr)
    assert 1 <= len(said) <= 3, stderr
    assert said[0].startswith("error: "), stderr
    if code == 1:  # the documented run failures only (docs/safety.md): a failed run, and a
        # plant that diverged within the first sample (nothing to keep)
        failed = " failed at t = " in said[0] or " lost: the plant diverged at t = " in said[0]
        assert may_fail_run and failed, stderr


# --- hostile values --------------------------------------------------------------------------


class Raw(str):
    """YAML text written as is: ``.nan``, ``1.0e+400``, ``!!binary aGk=``, ``*a``."""


@dataclass(frozen=True)
class Anchored:
    name: str
    value: Any


@dataclass(frozen=True)
class Pairs:
    """A mapping that may hold a key twice (and merge keys ``<<``)."""

    items: tuple[tuple[Any, Any], ...]


RAW_SCALARS = [
    "1e308", "-1e308", "1.0e+308", "1.7976931348623157e+308", "1.0e+400", "-1.0e+400",
    "1e400", "-0.0", "0.0", ".nan", ".NaN", ".inf", "-.inf", "+.inf", "5e-324", "1.0e-320",
    "0x7fffffffffffffff", "-0x8000000000000001", "0o777", "0b1010", "1_000", "190:20:30",
    "9" * 19, "9" * 40, "9" * 399, "9" * 401, "-" + "9" * 300, "~", "null", "true", "yes",
    "off", "2024-01-01", "2024-13-45", "2001-12-14t21:59:43.10-05:00", "''", '""',
    "!!binary aGk=", "!!binary x", "!!set {a: null}", "!!omap [a: 1]", "!!str 1",
    "!!float x", "!!int 1.5", "!!python/object:os.system", "!!python/name:os.system",
    "!custom 1", '"\\ud800"', '"\\0"', '"\\e[31mred"', '"\\u202e"', '"\\x85"', '"\\L"',
    "[]", "{}", "[[[]]]", "{a: }", "*undefined", "&x 1", "? a", "- 1", "|", ">", "%YAML 1.1",
    "'''", '"\\', "!", "&", "*", "@", "`", "\t1",
]  # fmt: skip

floats = st.one_of(
    st.floats(width=64),  # nan, inf, -0.0, subnormals included
    st.sampled_from([1e308, -1e308, 5e-324, -0.0, 1e-12, 1e12, 2.0**53 + 1, 1e15]),
)
integers = st.one_of(
    st.integers(-(2**70), 2**70),
    st.sampled_from([0, -1, 2**31, 2**63, -(2**63) - 1, 10**100, 10**399, 10**400]),
)
strings = st.one_of(
    st.text(max_size=12),  # any unicode, control characters included
    st.text(st.characters(categories=["Cc", "Cf", "Zl", "Zp", "Zs"]), max_size=6),
    st.sampled_from(["", " ", "..", "../../x", "/", "\\", "\x00", "é", "\u202e", "名前"]),
    st.text(max_size=2).map(lambda s: s * 300),  # long
)
scalars = st.one_of(
    floats, integers, strings, st.booleans(), st.none(), st.sampled_from(RAW_SCALARS).map(Raw)
)


def _nested(levels: int, inner: Any) -> Any:
    for _ in range(levels):
        inner = [inner]
    return inner


def _bomb(name: str, width: int, links: int) -> list:
    """A chain of anchored lists, each of ``width`` aliases to the one before: width^links."""
    chain = [Anchored(f"{name}0", [1] * width)]
    for i in range(1, links):
        chain.append(Anchored(f"{name}{i}", [Raw(f"*{name}{i - 1}")] * width))
    return chain


values = st.recursive(
    scalars,
    lambda inner: st.one_of(
        st.lists(inner, max_size=6),
        st.dictionaries(st.one_of(strings, integers, st.none(), floats), inner, max_size=4),
        st.tuples(st.integers(1, 120), inner).map(lambda p: _nested(*p)),  # deep
        st.tuples(st.integers(1, 12), st.integers(1, 12)).map(lambda p: _bomb("b", *p)),
        st.tuples(st.sampled_from(["a", "b"]), inner).map(lambda p: Anchored(*p)),
        st.lists(st.tuples(st.sampled_from(["a", "<<", "type"]), inner), max_size=4).map(
            lambda items: Pairs(tuple(items))
        ),
        st.integers(0, 30_000).map(lambda n: [0.5] * n),  # big, within the value budget
    ),
    max_leaves=12,
)


# --- a YAML writer ---------------------------------------------------------------------------


def yaml_scalar(value: Any, ascii_only: bool = True) -> str:
    if isinstance(value, Raw):
        return str(value)
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if math.isnan(value):
            return ".nan"
        if math.isinf(value):
            return ".inf" if value > 0 else "-.inf"
        text = repr(value)
        if "e" in text and "." not in text.split("e")[0]:  # YAML 1.1 floats need the dot
            mantissa, exponent = text.split("e")
            text = f"{mantissa}.0e{exponent if exponent[0] in '+-' else '+' + exponent}"
        return text
    return json.dumps(str(value), ensure_ascii=ascii_only)


def yaml_flow(value: Any, ascii_only: bool = True) -> str:
    """``value`` as flow-style YAML, anchors, aliases and duplicate keys as given."""
    if isinstance(value, Anchored):
        return f"&{value.name} {yaml_flow(value.value, ascii_only)}"
    if isinstance(value, list | tuple):
        return "[" + ", ".join(yaml_flow(item, ascii_only) for item in value) + "]"
    if isinstance(value, dict | Pairs):
        items = value.items if isinstance(value, Pairs) else value.items()
        return (
            "{"
            + ", ".join(
                f"{_key(key, ascii_only)}: {yaml_flow(item, ascii_only)}" for key, item in items
            )
            + "}"
        )
    return yaml_scalar(value, ascii_only)


def _key(key: Any, ascii_only: bool) -> str:
    return key if isinstance(key, str) and key == "<<" else yaml_flow(key, ascii_only)


def yaml_document(document: dict | Pairs, ascii_only: bool = True) -> str:
    """A mapping as block-style YAML, one top-level key a line, values in flow style."""
    items = document.items if isinstance(document, Pairs) else document.items()
    return "".join(f"{_key(k, ascii_only)}: {yaml_flow(v, ascii_only)}\n" for k, v in items)


# --- mutations -------------------------------------------------------------------------------


def paths_of(document: Any, prefix: tuple = ()) -> list[tuple]:
    """Every path into a document of dicts and lists (inner nodes and leaves)."""
    found = [prefix] if prefix else []
    if isinstance(document, dict):
        for key, value in document.items():
            found += paths_of(value, (*prefix, key))
    elif isinstance(document, list):
        for index, value in enumerate(document):
            found += paths_of(value, (*prefix, index))
    return found


def set_path(document: Any, path: tuple, value: Any) -> None:
    node = document
    for key in path[:-1]:
        if isinstance(node, dict) and key not in node:
            node[key] = {}
        node = node[key]
    node[path[-1]] = value


def delete_path(document: Any, path: tuple) -> None:
    node = document
    for key in path[:-1]:
        node = node[key]
    if isinstance(node, dict):
        node.pop(path[-1], None)
    else:
        del node[path[-1]]


@st.composite
def mutated_document(draw, bases: list[dict], extra_paths: list[tuple] = ()) -> Pairs:
    """One of ``bases`` with up to four changes: a field set to a hostile value, removed, an
    unknown (hostile) key added, a value anchored and aliased elsewhere or merged, a key
    given twice."""
    import copy

    document = copy.deepcopy(draw(st.sampled_from(bases)))
    for _ in range(draw(st.integers(0, 4))):
        paths = paths_of(document)
        action = draw(st.sampled_from(["set", "set", "set", "delete", "unknown", "alias"]))
        if action == "set" or not paths:
            path = draw(st.sampled_from(paths + list(extra_paths)))
            try:
                set_path(document, path, draw(values))
            except (KeyError, IndexError, TypeError):
                set_path(document, path[:1], draw(values))
        elif action == "delete":
            delete_path(document, draw(st.sampled_from(paths)))
        elif action == "unknown":
            parents = [p for p in paths if isinstance(_get(document, p), dict)]
            parent = _get(document, draw(st.sampled_from([(), *parents])))
            parent[draw(st.one_of(strings, integers, floats))] = draw(values)
        else:  # the first path anchored, the second its alias (or an undefined one)
            first, second = draw(st.sampled_from(paths)), draw(st.sampled_from(paths))
            if first[: len(second)] != second and second[: len(first)] != first:
                set_path(document, first, Anchored("s", _get(document, first)))
                set_path(document, second, Raw("*s"))
    items = list(document.items())
    if items and draw(st.integers(0, 9)) == 0:  # a key twice
        items.append(draw(st.sampled_from(items)))
    return Pairs(tuple(items))


def _get(document: Any, path: tuple) -> Any:
    for key in path:
        document = document[key]
    return document


@st.composite
def damaged_text(draw, text: str, whole: int = 5) -> bytes:
    """``text`` as UTF-8, perhaps (``whole`` in ``whole`` + 5) left whole, else cut short,
    with flipped bytes or a stray character."""
    data = text.encode("utf-8", "surrogatepass")
    kind = draw(st.sampled_from(["whole"] * whole + ["cut", "flip", "insert", "bom", "crlf"]))
    if kind == "cut" and data:
        data = data[: draw(st.integers(0, len(data) - 1))]
    elif kind == "flip" and data:
        data = bytearray(data)
        for _ in range(draw(st.integers(1, 4))):
            data[draw(st.integers(0, len(data) - 1))] ^= draw(st.integers(1, 255))
        data = bytes(data)
    elif kind == "insert":
        at = draw(st.integers(0, len(data)))
        data = data[:at] + draw(st.text(min_size=1, max_size=3)).encode() + data[at:]
    elif kind == "bom":
        data = b"\xef\xbb\xbf" + data
    elif kind == "crlf":
        data = data.replace(b"\n", draw(st.sampled_from([b"\r\n", b"\r", b"\x85"])))
    return data
