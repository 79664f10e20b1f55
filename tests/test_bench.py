"""Benchmark rows: shape, keys and internal consistency; never absolute timings."""

from __future__ import annotations

import importlib.util
import io
import json
import os

import numpy as np
import pytest
from rich.console import Console

import auvmpc.experiments.bench as bench
from auvmpc.errors import ConfigError
from auvmpc.experiments.bench import (
    CONTROLLER_PRESETS,
    DEFAULT_CONTROLLERS,
    add_speedups,
    format_table,
    machine_info,
    pinned_to_one_cpu,
    resolve_controller,
    rows_to_json,
    run_benchmark,
)
from auvmpc.scenario import ControllerType, load_scenario

# The run metrics interfaces.md promises (a contract: spelled out here, not imported).
INTERFACE_METRICS = (
    "rms_position_error_m", "max_position_error_m", "final_position_error_m",
    "rms_heading_error_rad", "max_abs_thrust_N", "max_abs_thrust_rate_N_per_s",
    "thrust_limit_violations", "thrust_rate_violations", "min_obstacle_clearance_m",
    "solve_ms_median", "solve_ms_p99", "solve_ms_max", "thrust_effort_N2s", "solver_failures",
)  # fmt: skip
REQUIRED_KEYS = (
    "controller", "scenario", "wall_s", "steps", "speedup_vs_do_mpc", *INTERFACE_METRICS,
)  # fmt: skip
TIMING_KEYS = ("solve_ms_median", "solve_ms_p99", "solve_ms_max", "wall_s")
SHORT = ("duration=5",)  # 10 samples of 0.5 s: enough to exercise every column
CONTROLLERS = ("baseline", "mpc")
SCENARIOS = ("paper-ideal",)


@pytest.fixture(scope="module")
def calls_and_rows():
    calls = []
    rows = run_benchmark(
        CONTROLLERS, SCENARIOS, on_run=lambda *args: calls.append(args), overrides=SHORT
    )
    return calls, rows


@pytest.fixture(scope="module")
def rows(calls_and_rows):
    return calls_and_rows[1]


def test_one_row_per_controller_and_scenario(rows):
    assert len(rows) == len(CONTROLLERS) * len(SCENARIOS)
    pairs = {(row["controller"], row["scenario"]) for row in rows}
    assert pairs == {(c, s) for c in CONTROLLERS for s in SCENARIOS}


def test_rows_have_every_contract_key(rows):
    for row in rows:
        missing = [key for key in REQUIRED_KEYS if key not in row]
        assert not missing, f"{row['controller']}: missing {missing}"


def test_per_step_statistics_are_ordered_and_wall_time_positive(rows):
    for row in rows:
        assert 0.0 <= row["solve_ms_median"] <= row["solve_ms_p99"] <= row["solve_ms_max"]
        assert row["wall_s"] > 0.0
        # the whole run includes every controller call
        assert row["wall_s"] * 1e3 >= row["solve_ms_max"]


def test_steps_cover_the_duration(rows):
    scenario = load_scenario("paper-ideal", SHORT).scenario
    expected = round(scenario.duration / scenario.controller.sample_time)
    assert expected == 10
    for row in rows:
        assert row["steps"] == expected
        assert row["repeats"] == 1


def test_progress_reports_every_run_then_done(calls_and_rows):
    calls, rows = calls_and_rows
    total = len(rows)
    assert [call[:2] for call in calls] == [(k, total) for k in range(total + 1)]
    assert calls[0][2] == "paper-ideal / baseline"
    assert calls[-1][2] == "done"


def test_json_round_trip_is_a_list_of_rows(rows):
    loaded = json.loads(rows_to_json(rows))
    assert isinstance(loaded, list)
    assert all(isinstance(row, dict) for row in loaded)
    assert loaded == rows


def _printed(table) -> str:
    stream = io.StringIO()
    Console(file=stream, width=250).print(table)
    return stream.getvalue()


def test_table_has_a_line_per_row(rows):
    table = format_table(rows, machine_info())
    assert table.row_count == len(rows)
    text = _printed(table)
    for row in rows:
        assert row["controller"] in text
    assert "CPU" in text
    assert "RMS>tr" in text


def test_without_do_mpc_the_ratio_is_null_and_not_shown(rows):
    assert all(row["speedup_vs_do_mpc"] is None for row in rows)
    assert "vs do-mpc" not in _printed(format_table(rows))


def _fake_row(controller: str, scenario: str, median_ms: float) -> dict:
    return {"controller": controller, "scenario": scenario, "solve_ms_median": median_ms,
            "speedup_vs_do_mpc": None, "rms_position_error_m": 0.1}  # fmt: skip


def test_speedup_is_do_mpc_median_over_own_median_per_scenario():
    rows = [
        _fake_row("mpc", "a", 0.5),
        _fake_row("do-mpc", "a", 40.0),
        _fake_row("ltv-mpc", "a", 2.0),
        _fake_row("mpc", "b", 0.5),  # no do-mpc row for scenario b
        _fake_row("do-mpc", "c", 10.0),
        _fake_row("baseline", "c", 0.0),  # a zero median has no finite ratio
    ]
    speedups = [row["speedup_vs_do_mpc"] for row in add_speedups(rows)]
    assert speedups == [80.0, 1.0, 20.0, None, 1.0, None]
    assert [row["speedup_vs_do_mpc"] for row in rows] == [None] * len(rows)  # inputs untouched
    # the key keeps its place, so table columns and JSON keys keep their order
    assert list(add_speedups(rows)[0]) == list(rows[0])


def test_table_shows_the_ratio_when_a_do_mpc_row_exists():
    rows = add_speedups([_fake_row("mpc", "a", 0.5), _fake_row("do-mpc", "a", 40.0)])
    full = {key: 0 for key in INTERFACE_METRICS} | {"wall_s": 1.0, "min_obstacle_clearance_m": None}
    text = _printed(format_table([full | row for row in rows]))
    assert "vs do-mpc" in text
    assert "80.0x" in text
    assert "1.0x" in text


def test_do_mpc_label_poses_the_ocp_with_every_move_free():
    case = resolve_controller("do-mpc")
    config = load_scenario("paper-obstacles", case.overrides).scenario.controller
    assert config.type == ControllerType.DO_MPC
    assert config.control_horizon == config.prediction_horizon == 30
    assert not config.offset_free  # as the paper scenarios state it, and do-mpc requires


def test_do_mpc_is_a_default_exactly_when_installed():
    installed = importlib.util.find_spec("do_mpc") is not None
    assert ("do-mpc" in DEFAULT_CONTROLLERS) == installed


def test_one_run_with_do_mpc_gives_every_row_its_ratio():
    pytest.importorskip("do_mpc")
    rows = run_benchmark(["mpc-nc30", "mpc", "do-mpc"], ["paper-ideal"], overrides=SHORT)
    same_ocp, other_ocp, do_mpc = rows
    assert do_mpc["controller"] == "do-mpc"
    assert do_mpc["speedup_vs_do_mpc"] == 1.0
    # Only a row with do-mpc's move schedule solves the same OCP and gets a ratio.
    assert same_ocp["speedup_vs_do_mpc"] == do_mpc["solve_ms_median"] / same_ocp["solve_ms_median"]
    assert other_ocp["speedup_vs_do_mpc"] is None
    assert do_mpc["solver_failures"] == 0
    assert json.loads(rows_to_json(rows)) == rows


def test_solve_statistics_pool_all_steps_of_all_repeats(monkeypatch):
    real_simulate = bench.simulate
    runs = []

    def known_solve_times(resolved):
        result = real_simulate(resolved)
        steps = result.log.steps
        result.log.solve_ms[:] = np.arange(1, steps + 1) + steps * len(runs)
        runs.append(result.log.solve_ms.copy())
        return result

    monkeypatch.setattr(bench, "simulate", known_solve_times)
    (row,) = run_benchmark(["baseline"], ["paper-ideal"], repeats=2, overrides=SHORT)
    pooled = np.concatenate(runs)  # 1 .. 2 * steps
    assert len(runs) == 2
    assert row["repeats"] == 2
    assert row["steps"] == len(runs[0])
    assert row["solve_ms_median"] == float(np.percentile(pooled, 50))
    assert row["solve_ms_p99"] == float(np.percentile(pooled, 99))
    assert row["solve_ms_max"] == float(pooled.max())


def test_repeats_do_not_change_the_run_metrics(rows):
    (again,) = run_benchmark(["mpc"], ["paper-ideal"], repeats=2, overrides=SHORT)
    (once,) = [row for row in rows if row["controller"] == "mpc"]
    timing_free = set(INTERFACE_METRICS) - set(TIMING_KEYS)
    assert {key: again[key] for key in timing_free} == {key: once[key] for key in timing_free}


@pytest.mark.parametrize(
    ("controllers", "scenarios", "repeats", "field", "value"),
    [
        (["mpc", "nmpc-turbo"], ["paper-ideal"], 1, "--controllers", "nmpc-turbo"),
        (["mpc"], ["paper-ideal", "no-such-track"], 1, "--scenarios", "no-such-track"),
        ([], ["paper-ideal"], 1, "--controllers", ""),
        (["mpc"], [], 1, "--scenarios", ""),
        (["mpc"], ["paper-ideal"], 0, "--repeats", "0"),
    ],
)
def test_bad_names_fail_before_any_run(controllers, scenarios, repeats, field, value):
    calls = []
    with pytest.raises(ConfigError, match=f"^{field}: .*{value}") as caught:
        run_benchmark(controllers, scenarios, repeats, on_run=lambda *args: calls.append(args))
    assert caught.value.field == field
    assert calls == []


def test_every_controller_type_is_a_valid_label():
    for kind in ControllerType:
        case = resolve_controller(kind.value)
        assert f"controller.type={kind.value}" in case.overrides
    for label, overrides in CONTROLLER_PRESETS.items():
        load_scenario("paper-ideal", overrides)  # every preset is a valid override set
        assert resolve_controller(label).overrides == overrides


def test_a_label_carries_its_own_overrides():
    label = "ltv-mpc-nc30@controller.disturbance_bound.force_N=10"
    case = resolve_controller(label)
    assert case.controller == label
    assert case.overrides == (
        *CONTROLLER_PRESETS["ltv-mpc-nc30"],
        "controller.disturbance_bound.force_N=10",
    )
    config = load_scenario("paper-ideal", case.overrides).scenario.controller
    assert config.disturbance_bound.force_N == 10.0
    with pytest.raises(ConfigError, match="not field=value"):
        resolve_controller("ltv-mpc@force")
    with pytest.raises(ConfigError, match="unknown controller"):
        resolve_controller("ltv@controller.jit=false")


def test_nc30_labels_set_the_control_horizon():
    for label in ("mpc-nc30", "ltv-mpc-nc30"):
        config = load_scenario("paper-ideal", CONTROLLER_PRESETS[label]).scenario.controller
        assert config.control_horizon == 30
        assert config.type == label.removesuffix("-nc30")


@pytest.mark.skipif(not hasattr(os, "sched_getaffinity"), reason="no CPU affinity on this OS")
def test_pinning_is_one_cpu_and_is_undone():
    before = os.sched_getaffinity(0)
    with pinned_to_one_cpu() as cpu:
        if cpu is not None:
            assert os.sched_getaffinity(0) == {cpu}
            assert cpu in before
    assert os.sched_getaffinity(0) == before


def test_machine_info_names_the_solver_stack():
    info = machine_info()
    assert info["cpu_count"] == os.cpu_count()
    assert info["packages"]["numpy"] == np.__version__
    assert set(info["packages"]) == {"numpy", "scipy", "casadi", "daqp", "osqp", "do-mpc"}
    assert info["python"]
    json.dumps(info)  # serialisable as it is
