"""Campaigns of generated cases against a yardstick (issue 24): `cases` instead of `base`,
the yardstick twin of every run stored beside it, `--controller`, `--yardstick-from`, the
presets, and the report's paired section. Short runs (12 s, transient 4 s) keep the file
under a minute."""

from __future__ import annotations

import json
import math
from pathlib import Path
from unittest import mock

import pandas as pd
import pytest

from auvmpc.errors import ConfigError
from auvmpc.experiments import campaign
from auvmpc.experiments.campaign import (
    NONDETERMINISTIC_COLUMNS,
    load_campaign,
    load_results,
    run_campaign,
    run_overrides,
    scenario_for_run,
    validate_campaign,
)
from auvmpc.experiments.campaign import __main__ as campaign_main
from auvmpc.experiments.survey_cases import CASE_KINDS, YARDSTICK, make_case
from auvmpc.scenario import ResolvedScenario, apply_override, validate_scenario
from tests.test_campaign import campaign_folder, write_campaign
from tests.test_cli import run_cli

SHORT = ["duration=12", "transient_s=4"]
CASES = {
    "name": "cases-small",
    "cases": {"kind": "hard-survey"},
    "overrides": SHORT,
    "runs": 2,
    "seed": 3,
    "yardstick": list(YARDSTICK),
    "criterion": "min_obstacle_clearance_m >= 0 and (yardstick_lost == 1 or rms_over_bar <= 1)",
}
# Paired columns a campaign with a yardstick stores (docs/campaigns.md).
PAIRED = (
    "lost",
    "warnings",
    "warnings_text",
    "yardstick_rms_position_error_after_transient_m",
    "yardstick_verdict",
    "yardstick_lost",
    "yardstick_longest_fallback_streak",
    "yardstick_min_obstacle_clearance_m",
    "yardstick_fallback_steps",
    "yardstick_solve_ms_median",
    "rms_over_bar",
)


@pytest.fixture(scope="module")
def cases_file(tmp_path_factory) -> Path:
    return write_campaign(tmp_path_factory.mktemp("cases"), CASES)


@pytest.fixture(scope="module")
def finished(cases_file, tmp_path_factory) -> tuple[Path, pd.DataFrame]:
    out = tmp_path_factory.mktemp("cases-out") / "out"
    summary = run_campaign(cases_file, out, workers=2)
    assert (summary.ok, summary.failed) == (2, 0)
    return out, load_results(out)


# ----------------------------------------------------------------------------- the file


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"base": "paper-disturbed"}, r"^cases: give base or cases, not both"),
        ({"cases": None}, r"^base: give base \(a scenario\) or cases"),
        ({"cases": {"kind": "spirals"}}, r"^cases\.kind: "),
        ({"yardstick": []}, r"^yardstick: give at least one field=value"),
        ({"yardstick": ["controller.type"]}, r"^yardstick\.0: expected field=value"),
        ({"yardstick": ["controller.type=lqr"]}, r"^yardstick\.0: .*controller\.type"),
        ({"controller": "fuzzy"}, r"^controller: not a controller\.type or bench label"),
        (
            {"parameters": {"controller.Q.0": {"type": "uniform", "low": 1, "high": 2}}},
            r"^parameters\.controller\.Q\.0: generated cases leave controller\.Q at its default",
        ),
    ],
)
def test_a_bad_cases_or_yardstick_field_is_one_line_naming_it(tmp_path, changes, message):
    data = {key: value for key, value in {**CASES, **changes}.items() if value is not None}
    with pytest.raises(ConfigError, match=message) as caught:
        validate_campaign(load_campaign(write_campaign(tmp_path, data)))
    assert "\n" not in str(caught.value)


def test_the_file_accepts_exactly_the_kinds_survey_cases_generates():
    assert {kind.value for kind in campaign.spec.CaseKind} == set(CASE_KINDS)


# Hashes of the built-in campaigns and of a campaign on a scenario file, computed on main at
# 9f217f4 before cases / yardstick / controller existed: a campaign without them must keep
# its identity, so an existing folder still resumes. (A built-in's hash also covers its base
# scenario preset: editing that preset changes it, rightly. The three encounter campaigns
# gained `controller.type=ltv-mpc` when the default became nmpc, so their identity changed.)
HASHES_BEFORE = {
    "bluerov2-figure-eight": "bb30996904d86405dab4778d552190eb89838dd91afd09df86c7a102a1665af8",
    "paper-robustness-ltv": "ca930caf7c2e7a44e1e9c2479704e3e34209b213469994a30f924793ff8546fe",
    "paper-robustness": "a1ffe9a92f434fd091332c71843875e2770379920d658a80a3fe6910cbb37659",
}
FILE_HASH_BEFORE = "d6cbc7dde70b7b005d3f4b1e5ffd00a69afd01358bbea84f09703f590f0332fd"


@pytest.mark.parametrize("name", sorted(HASHES_BEFORE))
def test_campaigns_without_the_new_keys_keep_their_hash(name):
    assert load_campaign(name).hash == HASHES_BEFORE[name]


def test_a_campaign_on_a_scenario_file_keeps_its_hash(tmp_path):
    base = {
        "name": "hash-base",
        "duration": 30,
        "reference": {"type": "circle", "center": [0, 0], "radius": 5, "speed": 0.3},
        "initial_state": [5, 0, 1.5708, 0, 0, 0],
    }
    write_campaign(tmp_path, base, "base.yaml")
    polar = {
        "type": "polar",
        "magnitude": {"type": "uniform", "low": 0.0, "high": 5.0},
        "direction_deg": {"type": "uniform", "low": 0.0, "high": 360.0},
    }
    data = {
        "name": "hash-check",
        "base": "base.yaml",
        "overrides": ["controller.type=mpc"],
        "runs": 4,
        "seed": 11,
        "parameters": {
            "plant.scale.Iz_rb": {"type": "uniform", "low": 0.8, "high": 1.2},
            "disturbance.current_force_world": polar,
            "controller.Q.0": {"type": "grid", "values": [5, 10]},
        },
    }
    assert load_campaign(write_campaign(tmp_path, data)).hash == FILE_HASH_BEFORE


def test_run_k_is_generated_case_k_with_the_yardstick_applied_last(cases_file):
    camp = load_campaign(cases_file)
    assert camp.base_source is None and camp.base_label == "cases: hard-survey"
    for k in (0, 1):
        case = make_case("hard-survey", CASES["seed"], k)
        for text in (*SHORT, f"seed={campaign.sample_run(camp, k).seed}"):
            apply_override(case, text)
        tested = scenario_for_run(camp, k).scenario
        expected = ResolvedScenario(validate_scenario(case), Path(camp.base_dir)).scenario
        assert tested == expected and tested.duration == 12
        twin = scenario_for_run(camp, k, yardstick=True).scenario
        assert run_overrides(camp, k, yardstick=True)[-len(YARDSTICK) :] == list(YARDSTICK)
        assert (twin.controller.type, twin.controller.nmpc_mode) == ("nmpc", "full")
        assert twin.controller.control_horizon is None
        assert twin.model_copy(update={"controller": tested.controller}) == tested
    assert (
        camp.hash
        != load_campaign(write_campaign(cases_file.parent, {**CASES, "seed": 4}, "s.yaml")).hash
    )


def test_a_controller_label_is_another_campaign_for_the_tested_runs_only(cases_file, tmp_path):
    plain = load_campaign(cases_file)
    labelled = load_campaign(cases_file, controller="ltv-mpc-nc30")
    assert labelled.hash != plain.hash
    label = ["controller.type=ltv-mpc", "controller.control_horizon=30"]
    assert run_overrides(labelled, 1)[:4] == [*SHORT, *label]  # after the file's overrides
    assert run_overrides(labelled, 1, yardstick=True) == run_overrides(plain, 1, yardstick=True)
    tested = scenario_for_run(labelled, 1).scenario.controller
    assert (tested.type, tested.control_horizon) == ("ltv-mpc", 30)
    out = campaign_folder(tmp_path / "out")
    campaign.store._Store(out, plain).close()  # the folder of the campaign without a label
    with pytest.raises(ConfigError, match=r"^--out: holds another campaign"):
        run_campaign(labelled, out, workers=1)


@pytest.mark.parametrize(("name", "kind", "runs"), [("hard-survey", "hard-survey", 200),
                                                     ("loop-sweep", "loops", 100)])  # fmt: skip
def test_the_presets_judge_the_default_controller_against_the_converged_ocp(name, kind, runs):
    camp = load_campaign(name)
    validate_campaign(camp)
    assert (camp.spec.cases.kind, camp.spec.runs, camp.spec.yardstick) == (kind, runs, YARDSTICK)
    assert camp.spec.controller is None  # the scenario schema decides the tested controller
    assert not any(text.startswith("controller.") for text in run_overrides(camp, 0))
    names = set(campaign.parse_criterion(camp.spec.criterion).names)
    bar = {"lost", "yardstick_lost", "longest_fallback_streak", "rms_over_bar",
           "thrust_limit_violations", "thrust_rate_violations"}  # fmt: skip
    assert names == (bar | {"min_obstacle_clearance_m"} if kind == "hard-survey" else bar)


def test_the_reproduce_command_of_a_generated_case_needs_the_folder(cases_file):
    camp = load_campaign(cases_file)
    with pytest.raises(ConfigError, match=r"^out_dir: generated cases are rerun"):
        campaign.reproduce_command(camp, 1)
    assert campaign.reproduce_command(camp, 1, "d", yardstick=True) == (
        "auvmpc run --from-campaign d --index 1 --yardstick"
    )


# --------------------------------------------------------------------------- the runs


def test_the_yardstick_twin_is_stored_beside_every_run(finished):
    _, frame = finished
    assert set(PAIRED) <= set(frame.columns)
    for _, row in frame.iterrows():
        bar = max(0.1, 1.2 * row["yardstick_rms_position_error_after_transient_m"])
        assert row["rms_over_bar"] == row["rms_position_error_after_transient_m"] / bar
        assert row["lost"] == int(row["verdict"] == "lost")
        assert row["yardstick_lost"] == int(row["yardstick_verdict"] == "lost")
        assert row["warnings"] == len(json.loads(row["warnings_text"]))
        # Two different controllers fly the same case: the twin's errors are its own.
        assert row["yardstick_rms_position_error_m"] != row["rms_position_error_m"]
    assert "yardstick_error" not in frame  # only stored when a yardstick fails
    for name in ("yardstick_solve_ms_median", "yardstick_solve_ms_p99"):
        assert name in NONDETERMINISTIC_COLUMNS


def test_run_k_reruns_alone_from_the_folder(finished, monkeypatch, capsys, tmp_path):
    out, frame = finished
    row = frame.set_index("index").loc[1]
    for twin, prefix in ((False, ""), (True, "yardstick_")):
        folder = tmp_path / f"rerun-{twin}"
        args = ["run", "--from-campaign", str(out), "--index", "1", "--out", str(folder)]
        flags = ["--no-figures", *(["--yardstick"] if twin else [])]
        code, _, err = run_cli(monkeypatch, capsys, *args, *flags)
        assert code == 0, err
        metrics = json.loads((folder / "run.json").read_text())["metrics"]
        compared = [name for name in metrics if name not in NONDETERMINISTIC_COLUMNS]
        assert len(compared) > 20
        for name in compared:
            stored = row[f"{prefix}{name}"]
            assert (metrics[name] is None and pd.isna(stored)) or metrics[name] == stored, name


def test_the_report_pairs_controller_and_yardstick_and_draws_the_worst(finished):
    out, frame = finished
    report = campaign.campaign_report(out, paired_figures=1)
    paired = report.summary["paired"]
    rows = {row["row"]: row for row in paired["table"]}
    rms = "RMS error after transient, median (m)"
    assert rows[rms]["controller"] == pytest.approx(
        frame["rms_position_error_after_transient_m"].median()
    )
    assert rows[rms]["yardstick"] == pytest.approx(
        frame["yardstick_rms_position_error_after_transient_m"].median()
    )
    contacts = int((frame["min_obstacle_clearance_m"] < 0).sum())
    assert rows["obstacle contacts (runs)"]["controller"] == contacts
    assert paired["paired_runs"] == 2
    assert [row["index"] for row in paired["yardstick_lost"]] == list(
        frame.loc[frame["yardstick_lost"] == 1, "index"]
    )
    (worst,) = paired["worst"]
    assert worst["index"] == campaign.paired.worst_cases(frame, 1)[0]
    assert worst["reproduced"]  # the rerun gave the stored RMS errors: the same runs
    text = (out / "report.md").read_text()
    assert "## Controller against the yardstick" in text
    for who in ("controller", "yardstick"):
        assert (out / worst["figures"][who]).is_file()
        assert f"]({worst['figures'][who]})" in text
    assert f"auvmpc run --from-campaign {out} --index {worst['index']} --yardstick" in text
    assert math.isfinite(rows["solve time p99, worst run (ms)"]["yardstick"])


# ------------------------------------------------------------------ --yardstick-from

TWIN_SIMULATED = "a yardstick twin was simulated"


def execute_without_twins(payload: str, index: int, twin: dict | None) -> dict:
    """``execute_run`` in a worker where simulating a yardstick twin fails the run."""
    simulated = RuntimeError(TWIN_SIMULATED)
    with mock.patch.object(campaign.paired, "_simulate_twin", side_effect=simulated):
        return campaign.execute_run(payload, index, twin)


def test_another_controller_copies_the_twins_the_folder_has_and_simulates_the_rest(
    finished, tmp_path, monkeypatch
):
    first, expected = finished  # 2 runs of the scenario's own controller
    path = write_campaign(tmp_path, {**CASES, "runs": 3, "controller": "ltv-mpc"})
    monkeypatch.setattr(campaign.execute, "execute_run", execute_without_twins)
    out = tmp_path / "ltv"
    summary = run_campaign(path, out, workers=1, yardstick_from=first)
    frame = load_results(out).set_index("index")
    # Run 2 is not in the first folder: its twin was simulated (here made to fail the run).
    assert (summary.ok, summary.failed) == (2, 1)
    assert frame.loc[2, "error"] == f"RuntimeError: {TWIN_SIMULATED}"
    twins = [name for name in expected if name.startswith("yardstick_")]
    assert len(twins) > 20 and "yardstick_solve_ms_p99" in twins  # timings copied too
    pd.testing.assert_frame_equal(
        frame.loc[[0, 1], twins], expected.set_index("index")[twins], check_exact=True
    )
    for k in (0, 1):
        row = frame.loc[k]
        bar = max(0.1, 1.2 * row["yardstick_rms_position_error_after_transient_m"])
        assert row["rms_over_bar"] == row["rms_position_error_after_transient_m"] / bar
        assert row["rms_position_error_m"] != expected.loc[k, "rms_position_error_m"]
    source = {"folder": str(first.resolve()), "runs": [0, 1]}
    assert campaign.stored_sessions(out)[-1]["yardstick_from"] == source
    report = campaign.campaign_report(out, write=False, figures=False)
    assert report.summary["paired"]["copied_from"] == {source["folder"]: 2}
    assert f"copied from `{source['folder']}` (`--yardstick-from`)" in report.markdown
    # Not part of the campaign's identity: the folder resumes without the option.
    assert run_campaign(path, out, workers=1).new == 0


OTHER = "not this campaign with another controller: "


@pytest.mark.parametrize(
    ("here", "there", "reason"),
    [
        ({}, {"seed": 4}, f"{OTHER}seed 4 there, 3 here"),
        ({}, {"yardstick": None}, f"{OTHER}no yardstick there"),
        ({}, {"overrides": ["duration=10"]}, f"{OTHER}different overrides"),
        ({"yardstick": None}, {}, "this campaign has no yardstick"),
    ],
)
def test_a_yardstick_folder_of_another_campaign_is_refused_in_one_line(
    tmp_path, here, there, reason
):
    def campaign_of(changes: dict, name: str) -> campaign.Campaign:
        data = {key: value for key, value in {**CASES, **changes}.items() if value is not None}
        return load_campaign(write_campaign(tmp_path, data, name))

    folder = tmp_path / "there"
    folder.mkdir()
    campaign.store._Store(folder, campaign_of(there, "there.yaml")).close()  # as a run leaves it
    tested = campaign_of({**here, "controller": "ltv-mpc"}, "here.yaml")
    with pytest.raises(ConfigError, match=rf"^--yardstick-from: {reason} \(got ") as caught:
        run_campaign(tested, tmp_path / "out", workers=1, yardstick_from=folder)
    assert "\n" not in str(caught.value)
    assert not (tmp_path / "out").exists()  # refused before anything was written


def test_the_cli_and_the_module_refuse_a_folder_without_results_with_exit_2(
    cases_file, tmp_path, monkeypatch, capsys
):
    options = ["--out", str(tmp_path / "out"), "--yardstick-from", str(tmp_path)]
    message = "--yardstick-from: no campaign results here (results.sqlite missing)"
    code, _, err = run_cli(monkeypatch, capsys, "campaign", str(cases_file), *options)
    assert (code, err.strip()) == (2, f"error: {message} (got '{tmp_path}')")
    assert campaign_main.main([str(cases_file), *options]) == 2
    assert capsys.readouterr().err.strip() == f"error: {message} (got '{tmp_path}')"
