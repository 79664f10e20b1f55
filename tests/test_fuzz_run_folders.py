"""Fuzzing run folders (issue 28, item 5): copies of one short real run with log.csv, run.json
or the marker cut short, with flipped bytes, cells or values replaced by hostile ones, lines
dropped or doubled, through the commands that read a run folder (``export``, ``verify-c``,
``compare``, ``plot``, ``animate``), in-process. Each is held to
:func:`tests.fuzzing.assert_clean`: it works (the damage changed nothing that matters) or is
one clean refusal, within 10 s, no traceback. The last test says how many inputs the fuzz
suites generated (``make fuzz`` asks for >= 10,000).
"""

from __future__ import annotations

import json
import shutil

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.conftest import run_and_export
from tests.fuzzing import (
    EXAMPLES,
    FUZZ,
    GENERATED,
    PROFILE,
    assert_clean,
    damaged_text,
    floats,
    integers,
    run_cli,
    strings,
)

# The exported controller (nmpc, every move free) for 2 s: a run verify-c replays.
_SHORT = [
    "duration=2",
    "controller.type=nmpc",
    "controller.control_horizon=null",
    "controller.prediction_horizon=10",
]


@pytest.fixture(scope="module")
def made(tmp_path_factory):
    return run_and_export(tmp_path_factory.mktemp("fuzz-run-folders"), _SHORT)


LOG_CELLS = st.one_of(
    st.sampled_from(
        ["nan", "inf", "-inf", "1e308", "1e400", "-0.0", "", " ", "x", "ok", "9" * 400, "\x00",
         "é", '"', "1,2", "NaN", "saturated", "failed"]
    ),
    floats.map(repr),
    strings,
)  # fmt: skip
JSON_VALUES = st.recursive(
    st.one_of(
        floats, integers, strings, st.booleans(), st.none(),
        st.integers(1, 200).map(lambda n: json.loads("[" * n + "]" * n)),
    ),
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(strings, inner, max_size=3),
    max_leaves=8,
)  # fmt: skip


def _json_paths(value, prefix=()):
    found = [prefix] if prefix else []
    if isinstance(value, dict):
        for key, item in value.items():
            found += _json_paths(item, (*prefix, key))
    elif isinstance(value, list):
        for index, item in enumerate(value[:8]):
            found += _json_paths(item, (*prefix, index))
    return found


@st.composite
def log_damage(draw, text: str) -> bytes:
    lines = text.splitlines(keepends=True)
    kind = draw(st.sampled_from(["bytes", "cell", "cell", "drop line", "double line", "header"]))
    if kind == "cell":
        row = draw(st.integers(1, len(lines) - 1))
        cells = lines[row].rstrip("\n").split(",")
        cells[draw(st.integers(0, len(cells) - 1))] = draw(LOG_CELLS)
        lines[row] = ",".join(cells) + "\n"
    elif kind == "drop line":
        del lines[draw(st.integers(0, len(lines) - 1))]
    elif kind == "double line":
        at = draw(st.integers(0, len(lines) - 1))
        lines.insert(at, lines[at])
    elif kind == "header":
        names = lines[0].rstrip("\n").split(",")
        names[draw(st.integers(0, len(names) - 1))] = draw(st.sampled_from(["t", "x", "", "é"]))
        lines[0] = ",".join(names) + "\n"
    return draw(damaged_text("".join(lines)))


@st.composite
def run_json_damage(draw, text: str) -> bytes:
    info = json.loads(text)
    changed = draw(st.booleans())
    if changed:
        path = draw(st.sampled_from(_json_paths(info)))
        node = info
        for key in path[:-1]:
            node = node[key]
        if draw(st.integers(0, 3)) == 0:
            del node[path[-1]]
        else:
            node[path[-1]] = draw(JSON_VALUES)
        text = json.dumps(info)  # NaN and Infinity as JavaScript writes them
    if draw(st.integers(0, 9)) == 0:  # nested past Python's recursion limit
        levels = draw(st.integers(500, 200_000))
        text = text.replace(
            '"scenario": ', '"scenario": ' + "[" * levels + "]" * levels + ', "s": ', 1
        )
    return draw(damaged_text(text, whole=5 if changed else 0))


@settings(FUZZ, max_examples=EXAMPLES["run folder"])
@given(
    file=st.sampled_from(["log.csv"] * 4 + ["run.json"] * 3 + [".auvmpc-output.json"]),
    command=st.sampled_from(["export"] * 6 + ["verify-c"] * 2 + ["compare", "plot", "animate"]),
    damage=st.data(),
)
def test_fuzz_run_folders(made, tmp_path_factory, monkeypatch, capsys, file, command, damage):
    GENERATED["run folder"] += 1
    work = tmp_path_factory.mktemp("damaged")
    monkeypatch.chdir(work)
    folder = work / "run"
    shutil.copytree(made / "healthy", folder)
    text = (folder / file).read_text()
    if file == "log.csv":
        data = damage.draw(log_damage(text))
    elif file == "run.json":
        data = damage.draw(run_json_damage(text))
    else:
        data = damage.draw(damaged_text(text, whole=0))
    (folder / file).write_bytes(data)
    args = {
        "export": ["export", str(folder), "--out", str(work / "bag")],
        "verify-c": ["verify-c", str(made / "export"), str(folder)],
        "compare": ["compare", str(made / "healthy"), str(folder), "--out", str(work / "c")],
        "plot": ["plot", str(folder)],
        "animate": ["animate", str(folder), "--out", str(work / "a.gif")],
    }[command]
    code, stderr = run_cli(monkeypatch, capsys, *args)
    # an edited state or command is replayed, and differs: verify-c's documented verdict
    assert_clean(code, stderr, verdict="not reproduced: " if command == "verify-c" else None)
    shutil.rmtree(work)


def test_fuzz_counts():
    """Runs after every fuzz strategy (the files in this order): how many inputs they made;
    the long profile, run whole (``make fuzz``), must make >= 10,000."""
    total = sum(GENERATED.values())
    print(f"\nfuzz ({PROFILE} profile): {total} generated inputs {dict(GENERATED)}")
    assert all(count > 0 for count in GENERATED.values())
    if PROFILE == "long" and set(GENERATED) == set(EXAMPLES):
        assert total >= 10_000, GENERATED
