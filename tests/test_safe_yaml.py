"""The one YAML loader (issue 28, item 1): what it refuses while composing, and what it
still reads as PyYAML's safe loader does."""

from __future__ import annotations

import pytest
import yaml

from auvmpc.safe_yaml import (
    MAX_YAML_BYTES,
    MAX_YAML_DEPTH,
    MAX_YAML_VALUES,
    YamlLimit,
    load_yaml,
    yaml_problem,
)


def billion_laughs(levels: int = 9) -> str:
    """Nine aliases of the level below on each level: 9^9 strings from under 1 kB."""
    lines = ["l0: &l0 [x, x, x, x, x, x, x, x, x]"]
    lines += [f"l{i}: &l{i} [{', '.join([f'*l{i - 1}'] * 9)}]" for i in range(1, levels)]
    return "\n".join(lines) + "\n"


def test_an_alias_bomb_is_refused_at_the_alias_that_passes_the_budget():
    text = billion_laughs()
    assert len(text) < 1024
    with pytest.raises(YamlLimit) as raised:
        load_yaml(text)
    # 9 + 1 values a level: level 5 is the first past 100000 (each alias counts its anchor's)
    assert yaml_problem(raised.value) == (
        f"refused at line 6: holds more than {MAX_YAML_VALUES} values with its aliases expanded"
        " at l5.0"
    )


def test_deep_nesting_is_refused_not_a_recursion_error():
    for text in ("[" * 100_000, "a:\n" + "".join("  " * i + f"k{i}:\n" for i in range(1, 80))):
        with pytest.raises(YamlLimit, match=f"nested more than {MAX_YAML_DEPTH} levels deep"):
            load_yaml(text)
    nested = "[" * MAX_YAML_DEPTH + "]" * MAX_YAML_DEPTH
    assert load_yaml(nested) is not None  # the limit itself is allowed


@pytest.mark.parametrize(
    ("text", "problem"),
    [
        ("a: &a [1, *a]", "refused at line 1: alias *a inside its own anchor (a cycle)"),
        ("a: &a {<<: *a}", "refused at line 1: alias *a inside its own anchor (a cycle)"),
        (f"a: {'9' * 500}", "refused at line 1: an integer of 500 digits (at most 400)"),
        ("a: 1\na: 2", "not valid YAML at line 2: duplicate key 'a'"),
        (
            "a: 2024-13-45",
            "not valid YAML at line 1: '2024-13-45' is not a valid timestamp "
            "(month must be in 1..12)",
        ),
        ("a: *b", "not valid YAML at line 1: found undefined alias 'b'"),
        ("a: !!python/name:os.system", "not valid YAML at line 1: could not determine a "),
        ("x" * (MAX_YAML_BYTES + 1), f"refused: {MAX_YAML_BYTES + 1} characters, more than"),
    ],
)
def test_each_refusal_says_what_and_where(text, problem):
    with pytest.raises(yaml.YAMLError) as raised:
        load_yaml(text)
    assert yaml_problem(raised.value).startswith(problem)


@pytest.mark.parametrize(
    ("text", "problem"),
    [
        (
            "controller:\n  Q: [1]\n  Q: [2]\n",
            "not valid YAML at line 3: duplicate key 'Q' at controller.Q",
        ),
        ("a: 1\na: 2", "not valid YAML at line 2: duplicate key 'a'"),  # the key says where
        (
            "a:\n  b: " + "[" * 60,
            f"refused at line 2: nested more than {MAX_YAML_DEPTH} levels deep at a.b.0.0.0.0...",
        ),
        (
            "a: [1, &x [2, *x]]",
            "refused at line 1: alias *x inside its own anchor (a cycle) at a.1.1",
        ),
        (
            "obstacles:\n  - {center: [1, 2], radius: 2024-13-45}\n",
            "not valid YAML at line 2: '2024-13-45' is not a valid timestamp (month must be in "
            "1..12) at obstacles.0.radius",
        ),
    ],
)
def test_a_refusal_names_its_key_path(text, problem):
    """The loader knows where it is while it reads a document; a line number alone left
    the key to be found by hand."""
    with pytest.raises(yaml.YAMLError) as raised:
        load_yaml(text)
    assert yaml_problem(raised.value) == problem


def test_a_value_on_the_command_line_is_refused_without_key_path():
    """A --set value's keys are relative to its field, which the line names already."""
    with pytest.raises(yaml.YAMLError) as raised:
        load_yaml("{Q: {x: 1, x: 2}}")
    assert yaml_problem(raised.value, line=False) == "not valid YAML: duplicate key 'x'"


def test_what_safe_load_reads_is_read_the_same():
    text = (
        "base: &base {x: 1, y: [1.5, -2, .inf]}\n"
        "merged: {<<: *base, z: 2024-01-01}\n"
        "shared: [*base, *base]\n"
        "big: 1.0e+400\n"
        f"long: {'9' * 400}\n"
    )
    assert load_yaml(text) == yaml.safe_load(text)
