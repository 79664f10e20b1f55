"""`run --controller` takes the bench's labels as well as controller types (issue 13)."""

from __future__ import annotations

import json

import pytest

from auvmpc.api import controller_overrides
from auvmpc.controllers.config import CONTROLLER_PRESETS
from auvmpc.errors import ConfigError
from tests.test_cli import run_cli


def test_a_type_name_sets_the_type_only():
    assert controller_overrides("ltv-mpc") == ("controller.type=ltv-mpc",)


def test_a_bench_label_applies_its_preset():
    assert controller_overrides("ltv-mpc-nc30") == CONTROLLER_PRESETS["ltv-mpc-nc30"]


def test_an_unknown_label_names_the_option_and_the_choices():
    with pytest.raises(ConfigError, match=r"--controller: .*ltv-mpc-nc30.*\(got 'fuzzy'\)"):
        controller_overrides("fuzzy")


@pytest.mark.parametrize("vehicle", ["jmse2210", "bluerov2-heavy"])
def test_run_with_a_bench_label_and_a_set_that_wins(monkeypatch, capsys, tmp_path, vehicle):
    out = tmp_path / "run"
    code, _, err = run_cli(
        monkeypatch, capsys, "run", "paper-ideal", "--controller", "ltv-mpc-nc30",
        "--set", "controller.control_horizon=10", "--set", f"vehicle={vehicle}",
        "--set", "duration=2", "--no-figures", "--out", str(out),
    )  # fmt: skip
    assert code == 0, err
    controller = json.loads((out / "run.json").read_text())["scenario"]["controller"]
    assert (controller["type"], controller["control_horizon"]) == ("ltv-mpc", 10)
