"""Robustness campaigns: validation before any run, sampling as a pure function of
(master seed, index), the local pool and a real Dask LocalCluster giving identical rows,
resume after a real SIGKILL, worker deaths, failed runs recorded once, and the report."""

from __future__ import annotations

import json
import math
import os
import signal
import sqlite3
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml

import auvmpc
from auvmpc.errors import ConfigError
from auvmpc.experiments import campaign
from auvmpc.experiments.campaign import (
    NONDETERMINISTIC_COLUMNS,
    load_campaign,
    load_results,
    run_campaign,
    run_overrides,
    sample_run,
    scenario_for_run,
    validate_campaign,
)
from auvmpc.experiments.campaign.spec import LOCK_FILE, RESULTS_FILE
from auvmpc.experiments.outputs import prepare_campaign_folder
from auvmpc.experiments.run import simulate
from auvmpc.scenario import load_scenario

# A short campaign: 40 s of the paper's disturbed scenario with the paper's MPC (~0.1 s
# per run), varied in inertia, current, initial offset and one controller weight.
SMALL = {
    "name": "small",
    "description": "test campaign",
    "base": "paper-disturbed",
    "overrides": ["duration=40", "controller.type=mpc", "controller.control_horizon=2"],
    "runs": 32,
    "seed": 7,
    "parameters": {
        "plant.scale.Iz_rb": {"type": "uniform", "low": 0.75, "high": 1.25},
        "disturbance.current_force_world": {
            "type": "polar",
            "magnitude": {"type": "uniform", "low": 0.0, "high": 10.0},
            "direction_deg": {"type": "uniform", "low": 0.0, "high": 360.0},
        },
        "initial_state.0": {"type": "uniform", "low": -0.5, "high": 0.5, "apply": "add"},
        "controller.Q.0": {"type": "grid", "values": [5, 10]},
    },
    "criterion": "max_position_error_after_transient_m < 1.5",
}
POLL_S = 0.02
KILL_AFTER_ROWS = 3


def write_campaign(folder: Path, data: dict, name: str = "campaign.yaml") -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / name
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def with_changes(**changes) -> dict:
    data = yaml.safe_load(yaml.safe_dump(SMALL))
    data.update(changes)
    return data


def deterministic(frame: pd.DataFrame) -> pd.DataFrame:
    """The columns that must be bit-identical between two executions of a campaign."""
    return frame.drop(columns=[c for c in NONDETERMINISTIC_COLUMNS if c in frame]).reset_index(
        drop=True
    )


def row_count(out: Path) -> int:
    path = out / campaign.RESULTS_FILE
    if not path.is_file():
        return 0
    try:
        with sqlite3.connect(f"{path.as_uri()}?mode=ro", uri=True) as db:
            return db.execute("SELECT COUNT(*) FROM runs").fetchone()[0]
    except sqlite3.OperationalError:  # tables not created yet
        return 0


def wait_for_rows(out: Path, rows: int, timeout_s: float = 60.0) -> int:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        count = row_count(out)
        if count >= rows:
            return count
        time.sleep(POLL_S)
    raise AssertionError(f"fewer than {rows} rows in {out} after {timeout_s} s")


@pytest.fixture(scope="module")
def small_file(tmp_path_factory) -> Path:
    return write_campaign(tmp_path_factory.mktemp("small"), SMALL)


@pytest.fixture(scope="module")
def reference(small_file, tmp_path_factory) -> tuple[Path, pd.DataFrame]:
    """The small campaign, uninterrupted, on the local pool."""
    out = tmp_path_factory.mktemp("reference") / "out"
    summary = run_campaign(small_file, out, workers=2)
    assert (summary.total, summary.ok, summary.failed, summary.new) == (32, 32, 0, 32)
    return out, load_results(out)


# ---------------------------------------------------------------------------- validation


def uniform(low, high, **more) -> dict:
    return {"type": "uniform", "low": low, "high": high, **more}


IZ = "plant.scale.Iz_rb"
CURRENT = "disturbance.current_force_world"
BAD_PARAMETERS = [
    ({"plant.scale.Izz": uniform(0.9, 1.1)}, r"plant\.scale\.Izz: .*not a scalable field"),
    ({"controller.foo": uniform(0.9, 1.1)}, r"controller\.foo: .*unknown key"),
    ({"initial_state.7": uniform(0, 1)}, r"initial_state\.7: .*no such list index"),
    ({IZ: uniform(1.25, 0.75)}, r"plant\.scale\.Iz_rb\.high: must be >= low 1\.25"),
    ({IZ: {"type": "normal", "mean": 1.0, "std": -0.1}}, r"plant\.scale\.Iz_rb\.std: "),
    ({IZ: {"type": "log-uniform", "low": 0.0, "high": 2.0}}, r"plant\.scale\.Iz_rb\.low: "),
    ({"controller.type": {"type": "choice", "values": []}}, r"controller\.type\.values: "),
    (
        {"controller.type": {"type": "grid", "values": ["mpc", "lqr"]}},
        r"controller\.type: .*\(at values\[1\]\)",
    ),
    (
        {IZ: uniform(0.0, 1.0)},
        r"plant\.scale\.Iz_rb: input should be greater than 0 \(at low\) \(got 0\.0\)",
    ),
    (
        {IZ: {"type": "normal", "mean": 1.0, "std": 0.5}},
        r"plant\.scale\.Iz_rb: .*\(at mean - 3 std\)",
    ),
    ({IZ: {"type": "gaussian", "mean": 1.0}}, r"plant\.scale\.Iz_rb: unknown distribution type"),
    ({IZ: 0.9}, r"plant\.scale\.Iz_rb: expected a distribution mapping"),
    ({"seed": {"type": "integers", "low": 0, "high": 9}}, r"seed: the run seed derives"),
    ({"controller..Q": uniform(0, 1)}, r"controller\.\.Q: not a field path"),
    (
        {CURRENT: {"type": "polar", "magnitude": uniform(5, 1), "direction_deg": uniform(0, 360)}},
        r"disturbance\.current_force_world\.magnitude\.high: must be >= low",
    ),
    (
        {"len(obstacles)": {"type": "integers", "low": 0, "high": 1}},
        r"len\(obstacles\): .*not a list",
    ),
]


@pytest.mark.parametrize(("parameters", "message"), BAD_PARAMETERS)
def test_a_bad_parameter_is_one_line_naming_it(tmp_path, parameters, message):
    path = write_campaign(tmp_path, with_changes(parameters=parameters))
    with pytest.raises(ConfigError, match=rf"^parameters\.{message}") as caught:
        validate_campaign(load_campaign(path))
    assert "\n" not in str(caught.value)


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"runz": 3}, r"^runz: unknown key"),
        ({"runs": 0}, r"^runs: "),
        ({"overrides": ["controller.type=lqr"]}, r"^overrides\.0: controller\.type: "),
        ({"overrides": ["no-equals-sign"]}, r"^overrides\.0: expected field=value"),
        ({"base": "no-such-scenario"}, r"^base: no such scenario file or built-in"),
        ({"criterion": "rms_position_error_m <"}, r"^criterion: not a valid expression"),
        ({"criterion": "__import__('os').system('true') == 0"}, r"^criterion: .*operands are"),
        ({"criterion": "rms_position_error_m + 1 < 2"}, r"^criterion: .*operands are"),
    ],
)
def test_a_bad_campaign_field_is_one_line_naming_it(tmp_path, changes, message):
    path = write_campaign(tmp_path, with_changes(**changes))
    with pytest.raises(ConfigError, match=message):
        validate_campaign(load_campaign(path))


def test_a_bad_campaign_is_rejected_before_anything_is_written(tmp_path):
    bad = with_changes(parameters={"plant.scale.Iz_rb": {"type": "uniform", "low": 2, "high": 1}})
    out = tmp_path / "out"
    with pytest.raises(ConfigError, match=r"^parameters\.plant\.scale\.Iz_rb\.high"):
        run_campaign(write_campaign(tmp_path, bad), out)
    assert not out.exists()


def test_every_run_is_checked_before_the_first_starts(tmp_path):
    """Two parameters valid at every extreme (the other at its run-0 value) but not jointly
    in some later run: control_horizon must not exceed prediction_horizon."""
    data = with_changes(
        runs=40,
        parameters={
            "controller.prediction_horizon": {"type": "integers", "low": 4, "high": 30},
            "controller.control_horizon": {"type": "integers", "low": 1, "high": 8},
        },
    )
    camp = load_campaign(write_campaign(tmp_path, data))
    first = sample_run(camp, 0).columns
    assert first["controller.prediction_horizon"] >= 8 and first["controller.control_horizon"] <= 4
    with pytest.raises(
        ConfigError,
        match=r"^parameters\.controller\.control_horizon: .*exceeds .*\(run [1-9]\d*\)",
    ):
        validate_campaign(camp)
    validate_campaign(camp, runs=1)  # run 0 alone is fine


@pytest.mark.parametrize("name", ["paper-robustness", "paper-robustness-ltv"])
def test_builtin_campaigns_are_valid(name):
    assert name in campaign.builtin_campaigns()
    camp = load_campaign(name)
    validate_campaign(camp)
    assert camp.spec.runs == 300 and camp.base_source == "paper-disturbed"
    first = scenario_for_run(camp, 0).scenario
    assert (
        0.75 <= first.plant.scale["Iz_rb"] <= 1.25 and 0.65 <= first.plant.scale["Iz_added"] <= 1.35
    )
    assert math.hypot(*first.disturbance.current_force_world) <= 15.0
    assert abs(first.initial_state[0] - 7.5) <= 1.0 and abs(first.initial_state[1] + 12.0) <= 1.0


def test_a_six_dof_campaign_draws_its_fault_per_run():
    """thruster-loss (issue 26's fault campaign) has a 6-DOF base: every run is checked
    against the 6-DOF schema, and run k is the 6-DOF preset with run k's fault."""
    camp = load_campaign("thruster-loss")
    validate_campaign(camp, runs=20)
    actuators = set()
    for index in range(20):
        resolved = scenario_for_run(camp, index)
        (fault,) = resolved.scenario.faults
        assert resolved.scenario.kind == "six-dof" and resolved.scenario.fault_detection
        assert 30.0 <= fault.at <= 150.0 and 0.0 <= fault.effectiveness <= 0.6
        actuators.add(fault.actuator)
    assert actuators <= {f"F{i}" for i in range(1, 9)} and len(actuators) > 4


# ------------------------------------------------------------------------------ sampling


def test_sampling_is_a_pure_function_of_seed_and_index(small_file, tmp_path):
    first, again = load_campaign(small_file), load_campaign(small_file)
    samples = [sample_run(first, k) for k in range(32)]
    assert samples == [sample_run(again, k) for k in range(32)]
    assert sample_run(first, 20) == samples[20]  # alone, after others, in any order
    assert len({s.seed for s in samples}) == 32
    assert len({s.columns["plant.scale.Iz_rb"] for s in samples}) == 32
    other_seed = load_campaign(write_campaign(tmp_path, with_changes(seed=8)))
    assert sample_run(other_seed, 3).columns != samples[3].columns
    assert other_seed.hash != first.hash


def test_a_parameter_draws_the_same_values_whatever_the_others(small_file, tmp_path):
    parameters = dict(SMALL["parameters"])
    parameters["plant.scale.Iz_added"] = {"type": "uniform", "low": 0.65, "high": 1.35}
    wider = load_campaign(write_campaign(tmp_path, with_changes(parameters=parameters)))
    small = load_campaign(small_file)
    for k in range(10):
        assert sample_run(wider, k).seed == sample_run(small, k).seed
        for column, value in sample_run(small, k).columns.items():
            assert sample_run(wider, k).columns[column] == value


def test_distributions_stay_in_their_ranges(tmp_path):
    parameters = {
        "plant.scale.Iz_rb": {"type": "log-uniform", "low": 0.5, "high": 2.0},
        "plant.scale.Iz_added": {
            "type": "normal",
            "mean": 1.0,
            "std": 0.4,
            "low": 0.8,
            "high": 1.1,
        },
        "controller.prediction_horizon": {"type": "integers", "low": 20, "high": 22},
        "controller.control_horizon": {"type": "choice", "values": [1, 2, 3], "weights": [1, 0, 1]},
    }
    camp = load_campaign(write_campaign(tmp_path, with_changes(runs=400, parameters=parameters)))
    columns = pd.DataFrame([sample_run(camp, k).columns for k in range(400)])
    assert columns["plant.scale.Iz_rb"].between(0.5, 2.0).all()
    assert (columns["plant.scale.Iz_rb"] < 1.0).mean() == pytest.approx(
        0.5, abs=0.08
    )  # log-uniform
    assert columns["plant.scale.Iz_added"].between(0.8, 1.1).all()
    assert set(columns["controller.prediction_horizon"]) == {20, 21, 22}
    assert set(columns["controller.control_horizon"]) == {1, 3}  # weight 0 never drawn


def test_grid_parameters_span_a_product_last_fastest(tmp_path):
    parameters = {
        "controller.Q.0": {"type": "grid", "values": [1, 2]},
        "controller.type": {"type": "grid", "values": ["mpc", "ltv-mpc", "baseline"]},
    }
    camp = load_campaign(write_campaign(tmp_path, with_changes(runs=12, parameters=parameters)))
    combos = [tuple(sample_run(camp, k).columns.values()) for k in range(12)]
    expected = [(q, t) for q in (1, 2) for t in ("mpc", "ltv-mpc", "baseline")]
    assert combos == expected + expected


def test_the_notes_of_a_retyping_override_are_kept_per_run_and_reported_once(tmp_path):
    """A run whose controller.type a parameter changes drops the old type's knobs, as
    ``auvmpc run --set`` does: the note is kept in its row (and among its run warnings) and
    the report lists it once, with how many runs it was made for."""
    data = with_changes(
        overrides=["duration=2", "controller.type=mpc", "controller.control_horizon=2"],
        runs=4,
        parameters={"controller.type": {"type": "grid", "values": ["mpc", "baseline"]}},
        criterion=None,
    )
    camp = load_campaign(write_campaign(tmp_path, data))
    out = prepare_campaign_folder(tmp_path / "out", overwrite=False, files=(RESULTS_FILE,))
    store = campaign.store._Store(out, camp)
    rows = [campaign.execute_run(camp.payload(), k) for k in range(3)]
    for row in rows:
        store.record(row)
    store.close()
    assert [bool(row["metrics"].get("override_notes")) for row in rows] == [False, True, False]
    (note,) = json.loads(rows[1]["metrics"]["override_notes"])  # a failed run would keep it too
    said = "controller.type: mpc changed to baseline by an override; dropped what baseline has "

    def dropped(text: str) -> set[str]:  # the knobs in the payload's key order or the file's
        assert text.startswith(said)
        return set(text.removeprefix(f"{said}no knob for: ").split(", "))

    assert "control_horizon" in dropped(note)  # the override's, and the file's mpc knobs
    assert dropped(scenario_for_run(camp, 1).notes[0]) == dropped(note)  # run.json warns too
    report = campaign.campaign_report(out, write=False, figures=False)
    assert report.summary["override_notes"] == [{"note": note, "of": "run", "runs": 1}]
    assert report.markdown.count(note) == 1


@pytest.mark.parametrize(
    "value", [1e-5, 1e16, 1.5e300, -0.0, 0.1, 5e-324, 7, "yes", "1.0", [1e-7, {"a": None}], True]
)
def test_values_reach_the_scenario_exactly_through_yaml_text(value):
    assert yaml.safe_load(campaign.spec._yaml_text(value)) == value


def test_list_length_and_defaults_are_written_as_plain_overrides(tmp_path):
    data = with_changes(
        base="paper-obstacles",
        overrides=["duration=10"],
        runs=30,
        parameters={
            "obstacles.1.radius": {"type": "uniform", "low": 0.3, "high": 0.8},
            "len(obstacles)": {"type": "integers", "low": 0, "high": 2},
            "disturbance.current_force_world.0": {"type": "uniform", "low": -3, "high": 3},
            "controller.obstacle_margin": {
                "type": "uniform",
                "low": 1.0,
                "high": 2.0,
                "apply": "multiply",
            },
        },
    )
    camp = load_campaign(write_campaign(tmp_path, data))
    validate_campaign(camp)
    counts = set()
    for k in range(30):
        sample = sample_run(camp, k)
        # What `auvmpc run paper-obstacles --set ...` would build, string for string.
        scenario = load_scenario(camp.base_source, run_overrides(camp, k)).scenario
        assert scenario == scenario_for_run(camp, k).scenario
        assert len(scenario.obstacles) == sample.columns["len(obstacles)"]
        counts.add(len(scenario.obstacles))
        assert (
            scenario.disturbance.current_force_world[0]
            == sample.columns["disturbance.current_force_world.0"]
        )
        assert (
            scenario.controller.obstacle_margin
            == 0.1 * sample.columns["controller.obstacle_margin"]
        )
    assert counts == {0, 1, 2}


# ----------------------------------------------------------------------- running, storing


@pytest.mark.slow
def test_local_pool_stores_one_row_per_run(reference):
    out, frame = reference
    assert list(frame["index"]) == list(range(32))
    assert (frame["status"] == "ok").all() and frame["error"].isna().all()
    assert list(frame.columns[:4]) == ["index", "seed", "status", "error"]
    for column in (IZ, f"{CURRENT}.magnitude", f"{CURRENT}.direction_deg", "initial_state.0",
                   "controller.Q.0", "rms_position_error_m", "thrust_rate_violations",
                   "solve_ms_p99"):  # fmt: skip
        assert column in frame
    assert frame["thrust_rate_violations"].dtype == "Int64"
    assert set(frame["controller.Q.0"]) == {5, 10}
    # The SQL view has the same columns, for queries without Python.
    with sqlite3.connect(out / campaign.RESULTS_FILE) as db:
        worst = db.execute(
            'SELECT "index", rms_position_error_m FROM results ORDER BY rms_position_error_m DESC'
        ).fetchone()
    assert worst[0] == frame.loc[frame["rms_position_error_m"].idxmax(), "index"]


@pytest.mark.slow
def test_run_k_alone_equals_run_k_in_the_batch(reference, small_file):
    out, frame = reference
    camp = load_campaign(small_file)
    for k in (0, 13):
        alone = scenario_for_run(camp, k)
        assert scenario_for_run(out, k).scenario == alone.scenario  # from the results folder
        assert load_scenario(camp.base_source, run_overrides(camp, k)).scenario == alone.scenario
        metrics = simulate(alone).metrics
        row = frame.loc[frame["index"] == k].iloc[0]
        for name, value in metrics.items():
            if name not in NONDETERMINISTIC_COLUMNS:
                assert (pd.isna(row[name]) and value is None) or row[name] == value, name


@pytest.mark.slow
def test_rerunning_a_finished_campaign_runs_nothing(reference, small_file):
    out, frame = reference
    summary = run_campaign(small_file, out, workers=2)
    assert (summary.new, summary.ok) == (0, 32)
    pd.testing.assert_frame_equal(load_results(out), frame)


def campaign_folder(out: Path) -> Path:
    """A campaign folder as a first run starts it: auvmpc's marker, store and lock listed."""
    return prepare_campaign_folder(out, overwrite=False, files=(RESULTS_FILE, LOCK_FILE))


def test_a_folder_holding_another_campaign_is_refused(small_file, tmp_path):
    out = campaign_folder(tmp_path / "out")
    campaign.store._Store(out, load_campaign(small_file)).close()  # as a first run leaves it
    other = write_campaign(tmp_path, with_changes(seed=99))
    with pytest.raises(ConfigError, match=r"^--out: holds another campaign"):
        run_campaign(other, out, workers=1)


def test_one_coordinator_per_folder(tmp_path, small_file):
    out = campaign_folder(tmp_path / "out")
    with campaign.store._exclusive(out):
        with pytest.raises(ConfigError, match=r"^--out: another campaign process is writing here"):
            run_campaign(small_file, out, workers=1)


@pytest.mark.slow
def test_sigkill_at_any_moment_then_resume_gives_the_uninterrupted_rows(
    reference, small_file, tmp_path
):
    _, expected = reference
    out = tmp_path / "killed"
    command = [
        sys.executable,
        "-m",
        "auvmpc.experiments.campaign",
        str(small_file),
        "--out",
        str(out),
        "--workers",
        "2",
    ]
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(Path(auvmpc.__file__).parents[1]), *sys.path])
    process = subprocess.Popen(command, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        wait_for_rows(out, KILL_AFTER_ROWS)
        workers = _children(process.pid)
        os.kill(process.pid, signal.SIGKILL)
        process.wait(timeout=10)
    finally:
        if process.poll() is None:
            process.kill()
    stored = row_count(out)
    assert KILL_AFTER_ROWS <= stored < 32, "the kill must land mid-campaign"
    _assert_gone(workers)  # the orphaned workers notice and exit
    resumed = subprocess.run(command, env=env, capture_output=True, text=True, timeout=120)
    assert resumed.returncode == 0, resumed.stderr
    assert "32 runs: 32 ok, 0 failed" in resumed.stdout
    frame = load_results(out)
    assert list(frame["index"]) == list(range(32))  # 32 distinct rows, none twice
    assert (frame["worker_deaths"] == 0).all()  # a killed coordinator is no worker death
    pd.testing.assert_frame_equal(deterministic(frame), deterministic(expected))


def _children(pid: int) -> list[int]:
    try:
        import psutil
    except ImportError:
        return []
    return [child.pid for child in psutil.Process(pid).children(recursive=True)]


def _assert_gone(pids: list[int], timeout_s: float = 10.0) -> None:
    deadline = time.monotonic() + timeout_s
    alive = list(pids)
    while alive and time.monotonic() < deadline:
        alive = [pid for pid in alive if _alive(pid)]
        time.sleep(0.1)
    assert not alive, f"worker processes {alive} outlived their coordinator"


def _alive(pid: int) -> bool:
    try:
        import psutil

        return psutil.Process(pid).status() != psutil.STATUS_ZOMBIE
    except Exception:
        return False


MISSING_CSV = {"type": "csv", "path": "missing.csv"}


def dies_on_run_5(payload: str, index: int, twin: dict | None) -> dict:
    """A run that kills its worker process every time (as a segfaulting solver would)."""
    if index == 5:
        os._exit(3)
    return campaign.execute_run(payload, index, twin)


@pytest.mark.slow
def test_a_run_that_kills_its_worker_is_failed_after_two_deaths(
    reference, small_file, tmp_path, monkeypatch
):
    _, expected = reference
    monkeypatch.setattr(campaign.execute, "execute_run", dies_on_run_5)
    out = tmp_path / "deaths"
    summary = run_campaign(small_file, out, workers=2, runs=8)
    assert (summary.ok, summary.failed) == (7, 1)
    frame = load_results(out)
    dead = frame.loc[frame["index"] == 5].iloc[0]
    assert dead["status"] == "failed" and dead["worker_deaths"] == campaign.MAX_WORKER_DEATHS
    assert dead["error"].startswith("WorkerDied: the worker process died 2 times")
    assert math.isnan(dead["rms_position_error_m"])
    rest = frame[frame["index"] != 5]
    # A run that shared the pool with run 5 died once with it, then passed alone.
    assert (rest["worker_deaths"] <= 1).all()
    pd.testing.assert_frame_equal(
        deterministic(rest), deterministic(expected[expected["index"].isin(rest["index"])])
    )


@pytest.mark.slow
def test_a_run_that_raises_is_failed_once_and_not_retried(tmp_path):
    data = with_changes(
        base="paper-ideal",
        overrides=["duration=10", "controller.type=mpc"],
        runs=4,
        parameters={"reference": {"type": "grid", "values": [{"type": "paper-oval"}, MISSING_CSV]}},
        criterion=None,
    )
    path = write_campaign(tmp_path, data)
    out = tmp_path / "out"
    summary = run_campaign(path, out, workers=2)
    assert (summary.ok, summary.failed) == (2, 2)
    frame = load_results(out)
    failed = frame[frame["status"] == "failed"]
    assert list(failed["index"]) == [1, 3]
    assert failed["error"].str.contains("missing.csv").all()
    assert failed["error"].str.fullmatch(r"\w+: [^\n]+").all()  # type and one line
    again = run_campaign(path, out, workers=2)
    assert again.new == 0 and (again.ok, again.failed) == (2, 2)
    pd.testing.assert_frame_equal(load_results(out), frame)
    report = campaign.campaign_report(out, write=False, figures=False).summary
    assert (report["successes"], report["rows"], report["criterion"]) == (2, 4, "status == ok")
    assert [row["index"] for row in report["failed_runs"]] == [1, 3]
    strict = campaign.campaign_report(out, "rms_position_error_m < 0", write=False, figures=False)
    assert strict.summary["successes"] == 0


# ----------------------------------------------------------------------------------- Dask


@pytest.fixture(scope="module")
def dask_cluster():
    distributed = pytest.importorskip("distributed")
    cluster = distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None
    )
    try:
        yield cluster
    finally:
        cluster.close()


@pytest.mark.slow
def test_dask_cluster_gives_the_local_pool_rows(reference, small_file, dask_cluster, tmp_path):
    _, expected = reference
    out = tmp_path / "dask"
    summary = run_campaign(small_file, out, scheduler=dask_cluster.scheduler_address)
    assert (summary.ok, summary.new) == (32, 32)
    pd.testing.assert_frame_equal(deterministic(load_results(out)), deterministic(expected))


@pytest.mark.slow
def test_dask_reruns_the_runs_of_a_worker_that_died(reference, small_file, dask_cluster, tmp_path):
    from distributed import Client

    _, expected = reference
    out = tmp_path / "dask-kill"
    with Client(dask_cluster.scheduler_address) as client:
        pids = list(client.run(os.getpid).values())
    outcome: dict = {}

    def coordinate() -> None:
        try:
            outcome["summary"] = run_campaign(
                small_file, out, scheduler=dask_cluster.scheduler_address
            )
        except BaseException as error:  # reported by the assertion below
            outcome["error"] = error

    thread = threading.Thread(target=coordinate)
    thread.start()
    wait_for_rows(out, KILL_AFTER_ROWS)
    os.kill(pids[0], signal.SIGKILL)
    stored = row_count(out)
    thread.join(timeout=120)
    assert "error" not in outcome, outcome.get("error")
    assert stored < 32, "the kill must land mid-campaign"
    assert outcome["summary"].ok == 32
    pd.testing.assert_frame_equal(deterministic(load_results(out)), deterministic(expected))


# --------------------------------------------------------------------------------- report


def test_wilson_interval_matches_scipy():
    stats = pytest.importorskip("scipy.stats")
    for successes, trials in ((8, 10), (0, 20), (20, 20), (137, 300)):
        expected = stats.binomtest(successes, trials).proportion_ci(0.95, method="wilson")
        low, high = campaign.wilson_interval(successes, trials)
        assert low == pytest.approx(expected.low, abs=1e-9)
        assert high == pytest.approx(expected.high, abs=1e-9)


def test_criterion_evaluates_without_eval():
    frame = pd.DataFrame(
        {
            "status": ["ok", "ok", "ok", "failed"],
            "a_m": [0.5, 2.0, np.nan, np.nan],
            "n": pd.array([0, 0, 1, None], dtype="Int64"),
            "p.q": [1.0, -1.0, 1.0, 1.0],
        }
    )
    parse = campaign.parse_criterion
    assert list(parse("a_m < 1.0 and n == 0").evaluate(frame)) == [True, False, False, False]
    assert list(parse("not (a_m >= 1) or `p.q` < -0.5").evaluate(frame)) == [
        True,
        True,
        True,
        False,
    ]
    assert list(parse("0 <= a_m <= 2").evaluate(frame)) == [True, True, False, False]
    with pytest.raises(ConfigError, match=r"^criterion: unknown column"):
        parse("b_m < 1").evaluate(frame)
    for text in ("a_m.__class__ < 1", "len(a_m) < 1", "a_m < 'x'", "a_m", "a_m < 1 if n else 2"):
        with pytest.raises(ConfigError, match=r"^criterion: "):
            parse(text)


@pytest.mark.slow
def test_report_has_the_interval_percentiles_worst_runs_and_figures(reference):
    out, frame = reference
    report = campaign.campaign_report(out, worst=3)
    summary = report.summary
    passed = int((frame["max_position_error_after_transient_m"] < 1.5).sum())
    assert summary["criterion"] == SMALL["criterion"]  # the file's default
    assert (summary["successes"], summary["rows"]) == (passed, 32)
    assert summary["success_ci95"] == list(campaign.wilson_interval(passed, 32))
    stats = summary["metrics"]["rms_position_error_m"]
    assert stats["p50"] == pytest.approx(float(np.percentile(frame["rms_position_error_m"], 50)))
    assert stats["max"] == frame["rms_position_error_m"].max()
    worst = summary["worst"]
    assert (
        summary["worst_by"] == "max_position_error_after_transient_m"
        and summary["worst_order"] == "desc"
    )
    assert (
        worst[0]["index"]
        == frame.loc[frame["max_position_error_after_transient_m"].idxmax(), "index"]
    )
    assert worst[0]["command"].startswith("auvmpc run paper-disturbed --set duration=40")
    for name in ("report.md", "report.json", "figures/histograms.png",
                 "figures/max_position_error_after_transient_m-vs-parameters.png"):  # fmt: skip
        assert (out / name).is_file(), name
    text = (out / "report.md").read_text()
    assert (
        "95 % Wilson interval" in text
        and f"--from-campaign {out} --index {worst[0]['index']}" in text
    )
    custom = campaign.campaign_report(
        out, "min_obstacle_clearance_m > 0", write=False, figures=False
    )
    assert custom.summary["successes"] == 0  # no obstacles: clearance is null, never > 0
    assert custom.summary["worst_order"] == "asc"


def test_paired_difference_compares_run_by_run(reference):
    out, frame = reference
    same = campaign.paired_difference(out, out, "rms_position_error_m")
    assert same["runs"] == len(frame)
    assert same["max"] == same["min"] == 0.0
    with pytest.raises(ConfigError, match="not a metric"):
        campaign.paired_difference(out, out, "rms_error")
