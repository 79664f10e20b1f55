"""`auvmpc schema`: JSON Schema from the pydantic models that accepts every built-in file and
rejects what the loader rejects; docs/scenario-reference.md is current (issue 13)."""

from __future__ import annotations

import json
from importlib import resources
from pathlib import Path

import pytest
import yaml

from auvmpc.experiments.json_schema import json_schema, reference_markdown
from tests.test_cli import run_cli

jsonschema = pytest.importorskip("jsonschema")

REFERENCE_PAGE = Path(__file__).resolve().parents[1] / "docs" / "scenario-reference.md"


def _presets(kind: str) -> list[tuple[str, dict]]:
    folder = resources.files("auvmpc.presets") / kind
    return [
        (item.name, yaml.safe_load(item.read_text()))
        for item in sorted(folder.iterdir(), key=lambda p: p.name)
        if item.name.endswith(".yaml")
    ]


@pytest.mark.parametrize(
    ("kind", "folder"),
    [("scenario", "scenarios"), ("vehicle", "vehicles"), ("campaign", "campaigns")],
)
def test_the_printed_schema_is_valid_and_accepts_every_builtin(monkeypatch, capsys, kind, folder):
    code, out, err = run_cli(monkeypatch, capsys, "schema", kind)
    assert code == 0, err
    schema = json.loads(out)
    jsonschema.Draft202012Validator.check_schema(schema)
    validator = jsonschema.Draft202012Validator(schema)
    presets = _presets(folder)
    assert presets, folder
    for name, data in presets:
        errors = [error.message for error in validator.iter_errors(data)]
        assert errors == [], name


@pytest.mark.parametrize(
    ("change", "where"),
    [
        ({"controller": {"gain": 2}}, "gain"),  # unknown key, as the loader says
        ({"duration": -1.0}, "duration"),
        ({"controller": {"type": "fuzzy"}}, "type"),
    ],
)
def test_the_scenario_schema_rejects_what_the_loader_rejects(change, where):
    from auvmpc.errors import ConfigError
    from auvmpc.scenario import validate_scenario

    data = dict(dict(_presets("scenarios"))["paper-ideal.yaml"])  # a horizontal scenario
    data.update(change)
    with pytest.raises(ConfigError, match=where):
        validate_scenario(data)
    validator = jsonschema.Draft202012Validator(json_schema("scenario"))
    assert not validator.is_valid(data)


def test_the_reference_page_is_current():
    assert REFERENCE_PAGE.read_text() == reference_markdown(), (
        "regenerate: auvmpc schema --markdown > docs/scenario-reference.md"
    )


def test_the_reference_page_lists_every_scenario_field():
    from auvmpc.scenario import Scenario

    text = reference_markdown()
    for name in Scenario.model_fields:
        assert f"| `{name}` |" in text


def test_an_unknown_kind_is_one_line(monkeypatch, capsys):
    code, _, err = run_cli(monkeypatch, capsys, "schema", "boat")
    assert code == 2
    assert err.strip() == "error: KIND: one of ['scenario', 'vehicle', 'campaign'] (got 'boat')"
