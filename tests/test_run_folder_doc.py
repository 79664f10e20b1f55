"""docs/run-folder.md names every column of every kind of log.csv and every run.json key a run
writes (issue 30: the run folder was undocumented)."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

import auvmpc
from auvmpc.experiments.run import write_run

DOC = (Path(__file__).resolve().parents[1] / "docs" / "run-folder.md").read_text()
# Inputs are listed as a range (`F1`..`Fn`, `Fz1`..`Fzn`), not one by one.
INPUT = re.compile(r"(Fz?)\d+")


def _documented(name: str) -> bool:
    is_input = INPUT.fullmatch(name)
    if is_input:
        prefix = is_input.group(1)
        return f"`{prefix}1`..`{prefix}n`" in DOC
    return f"`{name}`" in DOC


@pytest.mark.parametrize(
    ("name", "overrides"),
    [
        (
            "paper-obstacles",
            ["duration=4", "disturbance.water_current={velocity_m_per_s: [0.1, 0, 0]}"],
        ),
        ("bluerov2-helix", ["duration=2"]),
        ("paper-depth-calm", ["duration=12"]),
    ],
)
def test_every_column_and_key_a_run_writes_is_documented(tmp_path, name, overrides):
    run = auvmpc.simulate(auvmpc.load_scenario(name, overrides))
    folder = tmp_path / "run"
    write_run(run, folder, figures=False)
    columns = (folder / "log.csv").read_text().splitlines()[0].split(",")
    info = json.loads((folder / "run.json").read_text())
    names = [*columns, *info, *info["metrics"], *info["provenance"]]
    missing = [name for name in names if not _documented(name)]
    assert not missing, f"docs/run-folder.md lacks {missing}"
    assert all(f"`{path.name}`" in DOC for path in folder.iterdir() if path.suffix != ".png")
