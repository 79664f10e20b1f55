"""The command line end to end: run folders, replay against an independent integration,
re-plotting, listing, and one-line errors with exit code 2."""

from __future__ import annotations

import csv
import json
import math
import subprocess
import sys

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from auvmpc.cli import main
from tests.conftest import REPLAY_ANGLE_TOL_RAD, REPLAY_POSITION_TOL_M, REPLAY_VELOCITY_TOL

INTERFACE_COLUMNS = (
    "t x y psi u v r x_ref y_ref psi_ref u_ref v_ref r_ref F1 F2 F3 F4 solve_ms".split()
)
INTERFACE_METRICS = (
    "rms_position_error_m max_position_error_m final_position_error_m rms_heading_error_rad "
    "max_abs_thrust_N max_abs_thrust_rate_N_per_s thrust_limit_violations "
    "thrust_rate_violations min_obstacle_clearance_m solve_ms_median solve_ms_p99 solve_ms_max "
    "thrust_effort_N2s solver_failures"
).split()


def run_cli(monkeypatch, capsys, *args: str) -> tuple[int, str, str]:
    monkeypatch.setattr(sys, "argv", ["auvmpc", *args])
    try:
        main()
        code = 0
    except SystemExit as stop:
        code = int(stop.code or 0)
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def spec_rhs(plant: dict, thrust: np.ndarray, current: tuple[float, float]):
    """paper-model.md section 1 written out again, independently of auvmpc.models.vehicle."""
    allocation = np.array(
        [
            [math.cos(math.radians(t["angle_deg"])) for t in plant["thrusters"]],
            [math.sin(math.radians(t["angle_deg"])) for t in plant["thrusters"]],
            [
                t["position"][0] * math.sin(math.radians(t["angle_deg"]))
                - t["position"][1] * math.cos(math.radians(t["angle_deg"]))
                for t in plant["thrusters"]
            ],
        ]
    )
    f_u, f_v, m_r = allocation @ thrust
    m11, m22, iz = plant["m11"], plant["m22"], plant["Iz_rb"] + plant["Iz_added"]
    dx, dy = current

    def rhs(_t, s):
        _, _, psi, u, v, r = s
        d_u = dx * math.cos(psi) + dy * math.sin(psi)
        d_v = -dx * math.sin(psi) + dy * math.cos(psi)
        return [
            u * math.cos(psi) - v * math.sin(psi),
            u * math.sin(psi) + v * math.cos(psi),
            r,
            (plant["Xu"] * u + plant["Xuu"] * abs(u) * u + m22 * v * r + f_u + d_u) / m11,
            (plant["Yv"] * v + plant["Yvv"] * abs(v) * v - m11 * u * r + f_v + d_v) / m22,
            (plant["Nr"] * r + plant["Nrr"] * abs(r) * r + (m11 - m22) * u * v + m_r) / iz,
        ]

    return rhs


@pytest.mark.slow
@pytest.mark.parametrize("scenario", ["paper-ideal", "paper-disturbed"])
def test_run_folder_replays_against_independent_integration(
    tmp_path, monkeypatch, capsys, scenario
):
    out = tmp_path / "run"
    code, stdout, _ = run_cli(
        monkeypatch, capsys, "run", scenario, "--controller", "baseline", "--out", str(out)
    )
    assert code == 0
    assert "rms_position_error_m" in stdout
    info = json.loads((out / "run.json").read_text())
    assert set(INTERFACE_METRICS) <= set(info["metrics"])
    assert {"version", "scenario", "plant", "metrics"} <= set(info)
    assert info["scenario"]["controller"]["type"] == "baseline"
    assert sorted(p.name for p in out.glob("*.png")) == [
        "errors.png", "solve_times.png", "thrusts.png", "trajectory.png", "velocities.png",
    ]  # fmt: skip
    with open(out / "log.csv", newline="") as handle:
        rows = list(csv.DictReader(handle))
    assert set(INTERFACE_COLUMNS) <= set(rows[0])
    assert len(rows) == 201 and rows[-1]["F1"] == ""
    current = tuple(info["scenario"]["disturbance"]["current_force_world"])
    plant = info["plant"]
    names = ("x", "y", "psi", "u", "v", "r")
    worst = np.zeros(6)
    for k in range(len(rows) - 1):
        state = np.array([float(rows[k][n]) for n in names])
        thrust = np.array([float(rows[k][f"F{i}"]) for i in range(1, 5)])
        t0, t1 = float(rows[k]["t"]), float(rows[k + 1]["t"])
        solution = solve_ivp(
            spec_rhs(plant, thrust, current),
            (t0, t1),
            state,
            method="DOP853",
            rtol=1e-11,
            atol=1e-12,
        )
        logged_next = np.array([float(rows[k + 1][n]) for n in names])
        worst = np.maximum(worst, np.abs(solution.y[:, -1] - logged_next))
    assert worst[:2].max() < REPLAY_POSITION_TOL_M
    assert worst[2] < REPLAY_ANGLE_TOL_RAD
    assert worst[3:].max() < REPLAY_VELOCITY_TOL


def test_plot_redraws_from_saved_run(tmp_path, monkeypatch, capsys):
    out = tmp_path / "short"
    code, _, _ = run_cli(
        monkeypatch, capsys, "run", "paper-obstacles", "--controller", "baseline",
        "--set", "duration=10", "--out", str(out), "--no-figures",
    )  # fmt: skip
    assert code == 0 and not list(out.glob("*.png"))
    code, stdout, _ = run_cli(monkeypatch, capsys, "plot", str(out))
    assert code == 0 and "redrew" in stdout
    trajectory = out / "trajectory.png"
    assert trajectory.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no staging left


def test_lists(monkeypatch, capsys):
    code, stdout, _ = run_cli(monkeypatch, capsys, "scenarios")
    assert code == 0
    assert all(name in stdout for name in ("paper-ideal", "paper-disturbed", "paper-obstacles"))
    code, stdout, _ = run_cli(monkeypatch, capsys, "vehicles")
    assert code == 0 and "jmse2210" in stdout and "bluerov2-heavy" in stdout


@pytest.mark.parametrize(
    ("args", "expected"),
    [
        (["run", "no-such-scenario"], "scenario: no such file"),
        (["run", "paper-ideal", "--set", "duration=-5"], "duration"),
        (["run", "paper-ideal", "--set", "controller.gain=2"], "controller.gain: unknown key"),
        (["run", "paper-ideal", "--controller", "fuzzy"], "controller.type"),
        (["run", "paper-ideal", "--set", "vehicle=rov9000"], "vehicle: unknown preset"),
        (["plot", "/nonexistent/run"], "RUN_DIR: not a run folder"),
        (
            [
                "run",
                "paper-ideal",
                "--set",
                "vehicle=videoray-pro3",
                "--set",
                "controller.R=[0.01]",
            ],
            "vehicle: underactuated: no sway; controller mpc needs full actuation",
        ),
        (
            [
                "run",
                "paper-ideal",
                "--set",
                "vehicle=videoray-pro3",
                "--set",
                "controller.R=[0.01]",
                "--controller",
                "baseline",
            ],
            "controller baseline needs full actuation",
        ),
    ],
)
def test_bad_input_is_one_line_exit_2(monkeypatch, capsys, args, expected):
    code, _, stderr = run_cli(monkeypatch, capsys, *args)
    assert code == 2
    lines = stderr.strip().splitlines()
    assert len(lines) == 1, stderr
    assert lines[0].startswith("error: ") and expected in lines[0]
    assert "Traceback" not in stderr


def test_installed_entry_point_gives_no_traceback(tmp_path):
    # The real process: what a user sees in a terminal.
    bad = tmp_path / "bad.yaml"
    bad.write_text(
        "name: bad\nduration: 10\nreference: {type: circle, radius: -3}\n"
        "initial_state: [0, 0, 0, 0, 0, 0]\n"
    )
    process = subprocess.run(
        [sys.executable, "-m", "auvmpc.cli", "run", str(bad)], capture_output=True, text=True
    )
    assert process.returncode == 2
    assert process.stderr.count("\n") == 1 and "reference.circle.radius" in process.stderr
    assert "Traceback" not in process.stderr


def test_a_run_that_is_not_ok_ends_with_one_warning_line(tmp_path, monkeypatch, capsys):
    # A time limit no solver meets: every step falls back, nobody steers for the whole run.
    code, stdout, stderr = run_cli(
        monkeypatch, capsys, "run", "paper-ideal", "--set", "duration=15",
        "--set", "controller.solver_time_limit_ms=0.001", "--no-figures",
        "--out", str(tmp_path / "run"),
    )  # fmt: skip
    assert code == 0 and (tmp_path / "run" / "run.json").is_file()
    # (the pre-run check also says that 15 s cut the paper's 100 s path short)
    warnings = [line for line in stderr.splitlines() if line.startswith("warning: run")]
    assert warnings == ["warning: run lost: no control for 15 s (solver fallbacks in a row)"]
