"""`auvmpc bench --yardstick`: a scenario's own controller and the yardstick in one command,
on the same seed, one table with the ratios, the run folders beside it (issue 26: the
torpedo's default controller "better than the LOS + PID yardstick in the same run").

On tests/scenarios/remus100-short.yaml (8 s, six-dof-nmpc interpreted with a short
horizon): the rows are the runs `auvmpc run` makes, the ratios are the rows' own metrics
divided, and `auvmpc compare` reads the folders with the torpedo's metrics."""

from __future__ import annotations

import io
import json
from pathlib import Path

import pytest
from rich.console import Console

from auvmpc.errors import ConfigError
from auvmpc.experiments.bench import (
    YARDSTICK_METRICS,
    add_yardstick_ratios,
    bench_markdown,
    format_table,
    rows_to_json,
    run_benchmark,
)
from auvmpc.experiments.compare import load_compared_runs, metrics_markdown
from auvmpc.experiments.outputs import MARKER
from auvmpc.experiments.run import simulate
from auvmpc.scenario import load_scenario
from tests.test_cli import run_cli

SHORT = Path(__file__).parent / "scenarios" / "remus100-short.yaml"
YARDSTICK = "los-pid"
TORPEDO_METRICS = (
    "cross_track_rms_after_transient_m",
    "depth_rms_error_after_transient_m",
    "actuator_limit_violations",
    "actuator_rate_violations",
)
# What a run's timing changes (everything else is seeded and repeats to the bit).
TIMED = {"solve_ms_median", "solve_ms_p99", "solve_ms_max"}


@pytest.fixture(scope="module")
def bench_folder(tmp_path_factory):
    out = tmp_path_factory.mktemp("bench") / "short"
    rows = run_benchmark(["default"], [str(SHORT)], yardstick=YARDSTICK, out=out, figures=False)
    return out, rows


def _printed(table) -> str:
    stream = io.StringIO()
    Console(file=stream, width=250).print(table)
    return stream.getvalue()


def test_the_scenarios_own_controller_then_the_yardstick(bench_folder):
    _, rows = bench_folder
    assert [row["controller"] for row in rows] == ["six-dof-nmpc", YARDSTICK]
    assert [row["controller_type"] for row in rows] == ["six-dof-nmpc", YARDSTICK]
    assert all(row["yardstick"] == YARDSTICK for row in rows)


def test_the_default_row_is_the_run_auvmpc_run_makes(bench_folder):
    """Same scenario, same seed: the bench row's metrics are `auvmpc run`'s, to the bit."""
    _, rows = bench_folder
    alone = simulate(load_scenario(str(SHORT))).metrics
    assert {key: rows[0][key] for key in alone if key not in TIMED} == {
        key: value for key, value in alone.items() if key not in TIMED
    }


def test_ratios_are_the_rows_metrics_over_the_yardsticks(bench_folder):
    _, (own, yardstick) = bench_folder
    for key in YARDSTICK_METRICS:
        assert own["vs_yardstick"][key] == own[key] / yardstick[key], key
        assert yardstick["vs_yardstick"][key] == 1.0, key


def test_the_folder_holds_both_runs_and_the_table(bench_folder):
    out, rows = bench_folder
    assert sorted(p.name for p in out.iterdir()) == sorted(
        [MARKER, "bench.md", "bench.json", "remus100-short"]
    )
    for row in rows:
        run = out / "remus100-short" / row["controller"]
        info = json.loads((run / "run.json").read_text())
        assert info["scenario"]["controller"]["type"] == row["controller_type"]
        assert info["scenario"]["seed"] == load_scenario(str(SHORT)).scenario.seed
        timing_free = {k: v for k, v in info["metrics"].items() if k not in TIMED}
        assert timing_free == {k: row[k] for k in timing_free}
        assert (run / "log.csv").is_file()
    assert json.loads((out / "bench.json").read_text()) == json.loads(rows_to_json(rows))
    table = bench_markdown(rows).splitlines()[: len(rows) + 2]  # the caption's machine aside
    assert (out / "bench.md").read_text().splitlines()[: len(rows) + 2] == table


def test_table_shows_the_torpedo_columns_and_the_ratios(bench_folder):
    _, (own, yardstick) = bench_folder
    text = _printed(format_table([own, yardstick]))
    for title in ("x-track>tr m", "depth>tr m", "viol. lim/rate", "fallb./streak", "verdict"):
        assert title in text
    assert "RMS err m" not in text  # the planar view's columns are not a torpedo's
    ratio = own["vs_yardstick"]["cross_track_rms_after_transient_m"]
    assert f"{own['cross_track_rms_after_transient_m']:.4f} ({ratio:.3g}x)" in text
    assert f"{yardstick['cross_track_rms_after_transient_m']:.4f} " in text
    assert "over the yardstick's (los-pid)" in text
    markdown = bench_markdown([own, yardstick])
    assert markdown.splitlines()[0].startswith("| controller | scenario | median ms")
    assert f"({ratio:.3g}x)" in markdown


def test_compare_reads_the_runs_with_the_torpedo_metrics(bench_folder, tmp_path):
    out, _ = bench_folder
    runs = load_compared_runs([out / "remus100-short" / name for name in ("six-dof-nmpc",
                                                                           YARDSTICK)])  # fmt: skip
    assert [run.label for run in runs] == ["six-dof-nmpc", YARDSTICK]
    header = metrics_markdown(runs).splitlines()[0]
    for name in TORPEDO_METRICS:
        assert name in header
    assert "max_abs_thrust_N" not in header  # a torpedo has no thrust in N
    assert list(runs[0].log.input_names) == ["propeller_rpm", "rudder_deg", "stern_planes_deg"]


def _fake(controller: str, scenario: str, **metrics) -> dict:
    return {"controller": controller, "scenario": scenario, **metrics}


def test_ratios_per_scenario_and_none_where_undefined():
    rows = [
        _fake("a", "s1", solve_ms_median=2.0, cross_track_rms_after_transient_m=0.02),
        _fake("y", "s1", solve_ms_median=0.5, cross_track_rms_after_transient_m=0.04),
        _fake("a", "s2", solve_ms_median=1.0),  # no yardstick row on s2
        _fake("a", "s3", solve_ms_median=1.0, cross_track_rms_after_transient_m=0.1),
        _fake("y", "s3", solve_ms_median=0.0, cross_track_rms_after_transient_m=None),
    ]
    result = add_yardstick_ratios(rows, "y")
    assert result[0]["vs_yardstick"]["solve_ms_median"] == 4.0
    assert result[0]["vs_yardstick"]["cross_track_rms_after_transient_m"] == 0.5
    assert result[0]["vs_yardstick"]["depth_rms_error_after_transient_m"] is None
    assert result[1]["vs_yardstick"]["solve_ms_median"] == 1.0
    assert result[2]["yardstick"] is None and result[2]["vs_yardstick"] is None
    assert set(result[3]["vs_yardstick"].values()) == {None}  # zero or missing on the yardstick
    assert all("vs_yardstick" not in row for row in rows)  # inputs untouched
    assert add_yardstick_ratios(rows, None)[0]["vs_yardstick"] is None


@pytest.mark.parametrize(
    ("controllers", "yardstick", "field", "message"),
    [
        (["default"], "default", "--yardstick", "name the controller to measure against"),
        (["default"], "lospid", "--yardstick", "unknown controller"),
        (["los-pid", "los-pid"], None, "--controllers", "runs twice"),
    ],
)
def test_bad_yardsticks_and_clashing_folders_fail_before_any_run(
    tmp_path, controllers, yardstick, field, message
):
    calls = []
    with pytest.raises(ConfigError, match=message) as caught:
        run_benchmark(
            controllers, [str(SHORT)], yardstick=yardstick, out=tmp_path / "o",
            on_run=lambda *args: calls.append(args),
        )  # fmt: skip
    assert caught.value.field == field
    assert calls == [] and not (tmp_path / "o").exists()


def test_cli_bench_with_a_yardstick(monkeypatch, capsys, tmp_path):
    (tmp_path / "mine").mkdir()
    (tmp_path / "mine" / "notes.txt").write_text("a user's file")
    args = ["bench", "--scenarios", str(SHORT), "--yardstick", YARDSTICK, "--no-figures"]
    code, _, err = run_cli(monkeypatch, capsys, *args, "--out", str(tmp_path / "mine"))
    assert code == 2 and "--out" in err and len(err.strip().splitlines()) == 1
    code, printed, err = run_cli(
        monkeypatch, capsys, *args, "--out", str(tmp_path / "b"), "--set", "duration=5"
    )
    assert code == 0, err
    assert "x-track>tr m" in printed and "six-dof-nmpc" in printed and "los-pid" in printed
    assert (tmp_path / "b" / "remus100-short" / "six-dof-nmpc" / "run.json").is_file()
    code, _, err = run_cli(monkeypatch, capsys, *args, "--out", str(tmp_path / "b"))
    assert code == 2 and "--overwrite" in err
