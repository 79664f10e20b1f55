"""Every bad input of issue 12 gives one line naming the field and the value, exit 2, and
touches nothing; a run that breaks down numerically gives one line too (exit 1)."""

from __future__ import annotations

import json
import math
import os

import numpy as np
import pytest
import yaml

from auvmpc.errors import ConfigError
from auvmpc.experiments.campaign import run_campaign
from auvmpc.references import MAX_TRACK_BYTES
from tests.test_cli import run_cli
from tests.test_safe_yaml import billion_laughs

SCENARIO = "name: s\nduration: 10\nreference: {type: circle}\n"


def _one_error_line(stderr: str) -> str:
    lines = stderr.strip().splitlines()
    assert len(lines) == 1, stderr
    assert lines[0].startswith("error: ")
    return lines[0]


@pytest.fixture
def files(tmp_path):
    (tmp_path / "binary.yaml").write_bytes(bytes(range(256)) * 4)
    (tmp_path / "latin1.yaml").write_bytes("name: caf\xe9\n".encode("latin-1"))
    (tmp_path / "folder.yaml").mkdir()
    (tmp_path / "duplicate.yaml").write_text(
        "name: dup\nduration: 10\nreference: {type: circle}\nreference: {type: line}\n"
        "initial_state: [0, 0, 0, 0, 0, 0]\n"
    )
    (tmp_path / "vehicle.yaml").write_text(
        "name: twice\nmass: 1\nmass: 2\n"
    )  # a duplicate key in a vehicle file
    bomb = "  " + billion_laughs().replace("\n", "\n  ")
    (tmp_path / "bomb1.yaml").write_text(
        f"{SCENARIO}initial_state: [0, 0, 0, 0, 0, 0]\ndescription:\n{bomb}"
    )
    (tmp_path / "bomb2.yaml").write_text(f"{SCENARIO}initial_state:\n{bomb}")
    (tmp_path / "bomb3.yaml").write_text(f"name: v\nmass:\n{bomb}")
    (tmp_path / "deep.yaml").write_text(f"{SCENARIO}description: {'[' * 100_000}")
    (tmp_path / "campaign.yaml").write_text("name: c\nruns: 2\nruns: 3\n")
    (tmp_path / "typo.yaml").write_text(
        "name: t\nduraton: 200\nreference: {type: circle}\ninitial_state: [0, 0, 0, 0, 0, 0]\n"
    )
    (tmp_path / "steps.csv").write_text("t,x,y\n0,0,0\n1e-300,1,0\n2e-300,2,1\n1,3,3\n")
    (tmp_path / "csv.yaml").write_text(
        "name: c\nduration: 10\nreference: {type: csv, path: steps.csv}\n"
        "initial_state: [0, 0, 0, 0, 0, 0]\n"
    )
    (tmp_path / "surrogate.yaml").write_text('name: s\n"\\ud800\\udc00": 1\n')
    (tmp_path / "newline.yaml").write_text('name: s\n"a\\nb": 1\n')
    (tmp_path / "nul.yaml").write_text(
        'name: n\nduration: 10\nreference: {type: csv, path: "a\\0b"}\n'
        "initial_state: [0, 0, 0, 0, 0, 0]\n"
    )
    os.mkfifo(tmp_path / "pipe.csv")  # a pipe as the track: opening it waited forever
    (tmp_path / "pipe.yaml").write_text(
        "name: p\nduration: 10\nreference: {type: csv, path: pipe.csv}\n"
        "initial_state: [0, 0, 0, 0, 0, 0]\n"
    )
    (tmp_path / "many.yaml").write_text(
        "name: m\nbase: paper-ideal\nruns: 100000000\nseed: 1\nparameters: {}\n"
    )
    with open(tmp_path / "big.csv", "wb") as track:  # sparse: refused by its size alone
        track.truncate(MAX_TRACK_BYTES + 1)
    (tmp_path / "big.yaml").write_text(
        "name: b\nduration: 10\nreference: {type: csv, path: big.csv}\n"
        "initial_state: [0, 0, 0, 0, 0, 0]\n"
    )
    (tmp_path / "quoted.yaml").write_text(
        'name: q\nduration: "100"\nreference: {type: circle}\ninitial_state: [0, 0, 0, 0, 0, 0]\n'
    )
    return tmp_path


CASES = [
    # (arguments, the line's field and reason, the value it names)
    (("run", "{d}/binary.yaml"), "scenario: is a binary file, not a scenario file", "binary.yaml"),
    (("run", "{d}/latin1.yaml"), "scenario: is not UTF-8 text (byte 9)", "latin1.yaml"),
    (("run", "{d}/folder.yaml"), "scenario: is a folder, not a scenario file", "folder.yaml"),
    (
        ("run", "{d}/duplicate.yaml"),
        "scenario: not valid YAML at line 4: duplicate key 'reference'",
        "duplicate.yaml",
    ),  # fmt: skip
    (
        ("run", "paper-ideal", "--set", "vehicle={d}/vehicle.yaml"),
        "vehicle: not valid YAML at line 3: duplicate key 'mass'",
        "vehicle.yaml",
    ),  # fmt: skip
    (
        ("run", "{d}/bomb1.yaml"),
        "scenario: refused at line 11: holds more than 100000 values with its aliases expanded",
        "bomb1.yaml",
    ),  # fmt: skip
    (
        ("run", "{d}/bomb2.yaml"),
        "scenario: refused at line 10: holds more than 100000 values with its aliases expanded",
        "bomb2.yaml",
    ),  # fmt: skip
    (
        ("run", "paper-ideal", "--set", "vehicle={d}/bomb3.yaml"),
        "vehicle: refused at line 8: holds more than 100000 values",
        "bomb3.yaml",
    ),  # fmt: skip
    (
        ("run", "{d}/deep.yaml"),
        "scenario: refused at line 4: nested more than 50 levels deep",
        "deep.yaml",
    ),  # fmt: skip
    (
        ("run", "paper-ideal", "--set", "description=" + "[" * 1000),
        "description: value is refused: nested more than 50 levels deep",
        "[[[",
    ),  # fmt: skip
    (
        ("run", "{d}/csv.yaml"),
        "reference.path:3: t must be at least 1e-06 s after the row before (previous t = 0.0)",
        "1e-300",
    ),  # fmt: skip
    (
        ("run", "{d}/surrogate.yaml"),  # a UnicodeEncodeError traceback before
        # (libyaml refuses the escape itself; without it, auvmpc's constructor does)
        "scenario: not valid YAML at line 2: found invalid Unicode character escape code"
        if yaml.__with_libyaml__
        else "scenario: not valid YAML at line 2: '\\ud800' is half of a UTF-16 surrogate pair",
        "surrogate.yaml",
    ),  # fmt: skip
    (
        ("run", "{d}/newline.yaml"),  # the key's newline split the line before
        "a\\nb: unknown key",
        "1",
    ),  # fmt: skip
    (
        ("run", "paper-ideal", "--set", "a\n.0=1"),  # the line was split before
        "--set: the field holds a control character",
        "a\\n.0=1",
    ),  # fmt: skip
    (
        ("run", "{d}/nul.yaml"),  # a ValueError traceback before
        "reference.path: holds a NUL character, which no file name can",
        "\\x00",
    ),  # fmt: skip
    (
        ("run", "{d}/pipe.yaml"),
        "reference.path: is a pipe or device, expected a CSV file",
        "pipe.csv",
    ),  # fmt: skip
    (
        ("run", "paper-ideal", "--set", "duration=1e308"),  # inf samples: an OverflowError
        "duration: is inf samples of 0.5 s",
        "1e+308",
    ),  # fmt: skip
    (
        ("run", "{d}/typo.yaml"),
        "duraton: unknown key, did you mean duration? (got 200)",
        "200",
    ),  # fmt: skip
    (
        ("run", "paper-ideal", "--set", "controller.sample_tim=0.5"),
        "controller.sample_tim: unknown key, did you mean sample_time? (got 0.5)",
        "0.5",
    ),  # fmt: skip
    (
        ("run", "paper-ideal", "--set", "reference.colour=1"),
        "reference.paper-oval.colour: unknown key (got 1)",  # nothing near: no guess
        "1",
    ),  # fmt: skip
    (
        ("run", "paper-ideal", "--set", "duration=1.0e+400"),
        "duration: input should be a finite number",
        "inf",
    ),  # fmt: skip
    (
        ("run", "paper-ideal", "--set", "duration=1e400"),  # YAML 1.1 reads it as text
        "duration: input should be a finite number",
        "1e400",
    ),  # fmt: skip
    (
        ("run", "paper-ideal", "--set", "seed=" + "9" * 5000),
        "seed: value is refused: an integer of 5000 digits (at most 400)",
        "999",
    ),  # fmt: skip
    (
        ("run", "paper-ideal", "--set", "controller={{type: mpc, type: baseline}}"),
        "controller: value is not valid YAML: duplicate key 'type'",
        "baseline",
    ),  # fmt: skip
    (
        (
            "run",
            "paper-ideal",
            "--set",
            "controller.prediction_horizon=100000",
            "--set",
            "controller.control_horizon=null",
        ),
        "controller.prediction_horizon: the condensed QP of mpc with ny=100000",
        "100000",
    ),  # fmt: skip
    (
        ("run", "paper-ideal", "--set", "duration=1e12"),
        "duration: 2e+12 samples",
        "1000000000000.0",
    ),  # fmt: skip
    (
        ("run", "paper-ideal", "--set", "reference={{type: line, speed: 20}}"),
        "reference.speed: the reference moves at 20 m/s (t = 0 s), faster than jmse2210's "
        "steady top speed 1.76 m/s",
        "20",
    ),  # fmt: skip
    (
        (
            "run",
            "paper-ideal",
            "--set",
            "vehicle=bluerov2-heavy",
            "--set",
            "reference={{type: circle, radius: 10, speed: 1.5}}",
        ),
        "reference.speed: the reference moves at 1.5 m/s (t = 0 s), faster than "
        "bluerov2-heavy's steady top speed",
        "1.5",
    ),  # fmt: skip
    (
        ("run", "paper-ideal", "--set", "plant.scale.mass=5"),
        "plant.scale.mass: the horizontal (3-DOF) model does not use mass: it uses m11, m22, "
        "Iz_rb, Iz_added, Xu",
        "5",
    ),  # fmt: skip
    (
        ("run", "paper-ideal", "--set", "plant.scale.thrust_limits=2"),
        "plant.scale.thrust_limits: thrust_limits is the controller's limit",
        "2",
    ),  # fmt: skip
    (
        ("run", "paper-depth-calm", "--set", "plant.scale.Iz_rb=2"),
        "plant.scale.Iz_rb: the depth (heave) model does not use Iz_rb: it uses",
        "2",
    ),  # fmt: skip
    (
        ("run", "paper-ideal", "--set", "obstacles.3.radius=1"),
        "obstacles.3: no such list index (obstacles is not given",
        "'3'",
    ),  # fmt: skip
    (
        ("run", "paper-obstacles", "--set", "obstacles.3.radius=1"),
        "obstacles.3: no such list index (length 2)",
        "'3'",
    ),  # fmt: skip
    (
        ("run", "paper-ideal", "--out", "{d}/binary.yaml"),
        "--out: is a file, not a folder",
        "binary.yaml",
    ),  # fmt: skip
    (
        ("run", "{d}/big.yaml"),  # read whole with no limit: minutes and gigabytes before
        f"reference.path: is {MAX_TRACK_BYTES + 1} bytes, more than a CSV track may be",
        "big.csv",
    ),  # fmt: skip
    (
        ("run", "{d}/quoted.yaml"),  # pydantic read it as 100: a number quoted is text
        "duration: a number is needed, not text: write it without quotes",
        "'100'",
    ),  # fmt: skip
    (
        ("run", "paper-ideal", "--set", 'controller.sample_time="0.1"'),
        "controller.sample_time: a number is needed, not text: write it without quotes",
        "'0.1'",
    ),  # fmt: skip
    (
        ("run", "paper-ideal", "--set", 'plant.scale.m11="2"'),  # a mapping's value
        "plant.scale.m11: a number is needed, not text: write it without quotes",
        "'2'",
    ),  # fmt: skip
]


@pytest.mark.parametrize(("args", "expected", "value"), CASES)
def test_each_bad_input_is_one_line_naming_field_and_value(
    monkeypatch, capsys, files, args, expected, value
):
    before = sorted(p.name for p in files.iterdir())
    arguments = [a.format(d=files) for a in args]
    code, _, stderr = run_cli(monkeypatch, capsys, *arguments, "--no-figures")
    line = _one_error_line(stderr)
    assert code == 2
    assert line.startswith(f"error: {expected}"), line
    assert value in line.rsplit("(got ", 1)[1], line
    assert sorted(p.name for p in files.iterdir()) == before  # nothing written


@pytest.mark.parametrize(
    ("vehicle", "expected"),
    [
        ("name: v\nmas: 16.5\n", "vehicle.mas: unknown key, did you mean mass? (vehicle file "),
        ("name: v\n", "vehicle.mass: field required (vehicle file "),
        (
            'name: v\nmass: "16.5"\n',
            "vehicle.mass: a number is needed, not text: write it without quotes (vehicle file ",
        ),
    ],
)
def test_a_vehicle_error_names_the_vehicle_file(monkeypatch, capsys, tmp_path, vehicle, expected):
    (tmp_path / "own.yaml").write_text(vehicle)
    (tmp_path / "s.yaml").write_text(
        "name: s\nduration: 10\nvehicle: own.yaml\nreference: {type: circle}\n"
        "initial_state: [0, 0, 0, 0, 0, 0]\n"
    )
    code, _, stderr = run_cli(monkeypatch, capsys, "run", str(tmp_path / "s.yaml"))
    assert code == 2
    assert _one_error_line(stderr).startswith(f"error: {expected}{tmp_path / 'own.yaml'})")


def test_a_campaign_file_goes_through_the_same_loader(monkeypatch, capsys, files):
    code, _, stderr = run_cli(
        monkeypatch, capsys, "campaign", str(files / "campaign.yaml"), "--out", str(files / "c")
    )
    assert code == 2
    assert _one_error_line(stderr).startswith(
        "error: campaign: not valid YAML at line 3: duplicate key 'runs'"
    )
    assert not (files / "c").exists()


@pytest.mark.parametrize(
    ("line", "expected"),
    [
        ('runs: "3"\nparameters: {}\n', "runs: a number is needed, not text"),
        (
            "runs: 3\nparameters:\n  plant.scale.Iz_rb: {type: uniform, low: '0.75', high: 1}\n",
            "parameters.plant.scale.Iz_rb.low: a number is needed, not text",
        ),
    ],
)
def test_a_campaign_number_in_quotes_is_refused(monkeypatch, capsys, tmp_path, line, expected):
    (tmp_path / "c.yaml").write_text(f"name: c\nbase: paper-ideal\nseed: 1\n{line}")
    code, _, stderr = run_cli(
        monkeypatch, capsys, "campaign", str(tmp_path / "c.yaml"), "--out", str(tmp_path / "c")
    )
    assert code == 2
    assert _one_error_line(stderr).startswith(f"error: {expected}")
    assert not (tmp_path / "c").exists()


def test_a_number_on_the_command_line_stays_a_number():
    """--set values are YAML scalars: 100 is a number there (and 1e-3, which YAML 1.1 reads
    as text, is still read as one)."""
    from auvmpc.scenario import load_scenario

    scenario = load_scenario("paper-ideal", ["duration=100", "plant.max_step=1e-3"]).scenario
    assert scenario.duration == 100.0 and scenario.plant.max_step == 1e-3


def test_absurdly_many_runs_are_refused(monkeypatch, capsys, files):
    """Each run is checked before the first starts (about 1 ms each): 10^8 runs were hours
    of silent checking (found by tests/test_fuzz_inputs.py)."""
    code, _, stderr = run_cli(
        monkeypatch, capsys, "campaign", str(files / "many.yaml"), "--out", str(files / "c")
    )
    assert code == 2
    assert _one_error_line(stderr) == (
        "error: runs: input should be less than or equal to 1000000 (got 100000000)"
    )
    assert not (files / "c").exists()


def test_index_beyond_the_campaign_is_refused(monkeypatch, capsys, tmp_path):
    run_campaign("paper-robustness", tmp_path / "camp", runs=1, workers=1)
    code, _, stderr = run_cli(
        monkeypatch, capsys, "run", "--from-campaign", str(tmp_path / "camp"), "--index", "5000"
    )
    assert code == 2
    assert _one_error_line(stderr) == (
        "error: --index: need a run index in 0..299 (300 runs) (got 5000)"
    )


def test_a_run_that_breaks_down_is_one_line_exit_1(monkeypatch, capsys, tmp_path):
    """The long-run estimator failure of issue 10 (LinAlgError in the EKF), reproduced by a
    controller that raises it at step 3: one line saying where, no traceback, no folder."""
    from auvmpc.controllers.baseline import BaselineController

    compute = BaselineController.compute

    def failing(self, observation):
        if observation.k == 3:
            raise np.linalg.LinAlgError("Singular matrix")
        return compute(self, observation)

    monkeypatch.setattr(BaselineController, "compute", failing)
    out = tmp_path / "run"
    code, _, stderr = run_cli(
        monkeypatch, capsys, "run", "paper-ideal", "--controller", "baseline", "--out", str(out)
    )
    assert code == 1
    assert _one_error_line(stderr).startswith(
        "error: paper-ideal with baseline failed at t = 1.5 s (step 3): "
        "LinAlgError: Singular matrix (nothing was written"
    )
    assert not out.exists()


def test_a_criterion_report_is_written_next_to_the_campaigns_own(monkeypatch, capsys, tmp_path):
    out = tmp_path / "camp"
    run_campaign("paper-robustness", out, runs=2, workers=1)
    assert run_cli(monkeypatch, capsys, "campaign-report", str(out), "--no-figures")[0] == 0
    own = (out / "report.md").read_text()
    code, stdout, _ = run_cli(
        monkeypatch, capsys, "campaign-report", str(out), "--criterion",
        "max_position_error_m < 0.5", "--no-figures",
    )  # fmt: skip
    assert code == 0
    assert (out / "report.md").read_text() == own
    extra = sorted(p.name for p in out.glob("report-*"))
    assert len(extra) == 2 and extra[0].startswith("report-max_position_error_m_0_5-")
    assert "max_position_error_m < 0.5" in (out / extra[1].replace(".json", ".md")).read_text()
    summary = json.loads((out / extra[0]).read_text())
    assert summary["sessions"][0]["command"]  # provenance of the session that ran the rows
    assert math.isfinite(summary["sessions"][0]["wall_s"])


def test_a_long_value_keeps_its_end_where_a_path_names_its_file():
    """A refused value longer than the line allows keeps its start and its end: a path deep
    in a user's folders still says which file it was (the test's own temporary folders are
    long enough to have cut it, under a parallel runner)."""
    path = "/home/user" + "/missions" * 20 + "/survey-2026.yaml"
    line = str(ConfigError("scenario", path, "no such file"))
    assert line.startswith("scenario: no such file (got '/home/user/")
    assert line.endswith("/survey-2026.yaml')")
    assert len(line) < 120  # one short line
