"""A six-dof scenario exported to C (auvmpc export-c, issue 29): the horizontal nmpc and the
depth MPC as one controller of every thruster reproduce the Python pair's commands and both
channels' statuses; DAQP travels with the folder."""

from __future__ import annotations

import shutil

import numpy as np
import pytest

import auvmpc
from auvmpc.errors import ConfigError
from auvmpc.experiments.run import run_plant, simulate, write_run
from auvmpc.experiments.run_folder import read_run_folder
from auvmpc.export.c_library import COMMAND_TOLERANCE_N, export_c, verify_c
from auvmpc.scenario import load_scenario
from auvmpc.sim.loop import run_session
from tests.conftest import C_EXPORT_COMMAND_TOL_N
from tests.test_cli import run_cli
from tests.test_export_c import _AARCH64_LIBS, _paths_of_this_machine, _run, needs_aarch64, needs_cc

# The exported pair, as verify-c replays it: nmpc with every move free, no sensor noise (the
# replay reads the true states); a short run keeps the test quick.
_PAIR = [
    "controller.type=nmpc",
    "controller.control_horizon=null",
    "sensing.std=[0, 0, 0, 0, 0, 0]",
    "sensing.depth_std_m=0",
    "sensing.depth_rate_std_m_per_s=0",
    "duration=5",
]
# paper-6dof's depth MPC through its other branches: R on the thrust, moves held after 5
# samples, the reference held at today's
_OTHER_DEPTH = [
    "depth_controller.thrust_penalty=absolute",
    "depth_controller.control_horizon=5",
    "depth_controller.preview=false",
]
needs_aarch64_daqp = pytest.mark.skipif(
    not (_AARCH64_LIBS / "libdaqp.so").is_file(),
    reason="the aarch64 folder was fetched before it held DAQP (make hpipm-aarch64 again)",
)


@needs_cc
def test_a_six_dof_export_copied_alone_reproduces_both_channels(tmp_path):
    """bluerov2-helix: the folder names no path of this machine, carries DAQP with its licence,
    and, copied alone elsewhere, builds and replays the run: every thruster's command within
    the bound, both channels' statuses the run's, no heap call in a step. A run with depth
    noise or of another kind is refused in one line."""
    resolved, run_dir = _run(tmp_path, "bluerov2-helix", _PAIR)
    export = tmp_path / "export"
    export_c(resolved, export)
    forbidden = _paths_of_this_machine(export)
    for file in export.rglob("*"):
        if file.is_file():
            assert not [p for p in forbidden if p.encode() in file.read_bytes()], file
    assert (export / "lib" / "x86-64-generic" / "libdaqp.so").is_file()
    assert (export / "licenses" / "DAQP-LICENSE.txt").is_file()
    alone = tmp_path / "elsewhere" / "controller"
    shutil.copytree(export, alone)
    shutil.rmtree(export)
    result = verify_c(alone, run_dir)
    assert result.steps == 10 and result.max_difference_n <= C_EXPORT_COMMAND_TOL_N
    assert result.status_differences == 0 and result.depth_status_differences == 0
    assert result.fallbacks == result.depth_fallbacks == 0 and result.heap_calls == 0
    assert 0 < result.depth_max_iterations
    log = read_run_folder(run_dir).log()
    assert np.ptp(log.thrust[:, 4:], axis=0).min() > 0.1  # the depth channel moved every vertical

    noisy = load_scenario("bluerov2-helix", [*_PAIR, "duration=1", "sensing.depth_std_m=0.01"])
    write_run(simulate(noisy), tmp_path / "noisy", figures=False)
    with pytest.raises(ConfigError, match="sensor noise"):
        verify_c(alone, tmp_path / "noisy")
    planar = load_scenario("paper-ideal", ["duration=1", "controller.type=nmpc"])
    write_run(simulate(planar), tmp_path / "planar", figures=False)
    with pytest.raises(ConfigError, match="a horizontal run; the export is of a six-dof"):
        verify_c(alone, tmp_path / "planar")


@needs_cc
def test_a_dead_vertical_thruster_is_told_to_both_as_python_does(tmp_path):
    """paper-6dof (the jmse2210, two vertical thrusters), its depth MPC with R on the thrust,
    held moves and no preview, told from the first sample that the second vertical thruster
    is dead: the C commands what the Python pair did, nothing to the dead one."""
    dead = [1.0, 1.0, 1.0, 1.0, 1.0, 0.0]
    overrides = [*_PAIR, *_OTHER_DEPTH]
    session = auvmpc.session(load_scenario("paper-6dof", overrides))
    session.effectiveness = dead
    run_session(session, *run_plant(session.resolved))
    session.close(tmp_path / "run", figures=False)
    export_c(load_scenario("paper-6dof", overrides), tmp_path / "export")
    result = verify_c(tmp_path / "export", tmp_path / "run", effectiveness=dead)
    assert result.steps == 10 and result.max_difference_n <= C_EXPORT_COMMAND_TOL_N
    assert result.status_differences == result.depth_status_differences == 0
    log = read_run_folder(tmp_path / "run").log()
    assert not log.column(log.input_names[5]).any() and log.column(log.input_names[4]).any()


@pytest.mark.parametrize(
    ("scenario", "overrides", "message"),
    [
        ("paper-depth-calm", [], "horizontal and six-dof scenarios only"),
        ("remus100-helix", [], "not a controller of the whole"),
        ("bluerov2-helix", ["depth_controller.qp_solver=osqp"], "with DAQP"),
        ("bluerov2-helix", ["depth_controller.qp_iteration_limit=50"], "other iterations"),
        ("bluerov2-helix", ["depth_controller.solver_time_limit_ms=20"], "solve-time limit"),
        ("bluerov2-helix", ["depth_controller.prediction_horizon=60"], "static memory"),
    ],
)
def test_six_dof_configurations_it_cannot_export_are_refused_in_one_line(
    tmp_path, monkeypatch, capsys, scenario, overrides, message
):
    sets = [part for o in overrides for part in ("--set", o)]
    out = tmp_path / "export"
    code, _, err = run_cli(monkeypatch, capsys, "export-c", scenario, "--out", str(out), *sets)
    assert code == 2
    assert message in err
    assert len(err.strip().splitlines()) == 1
    assert not out.exists()


@needs_aarch64
def test_an_aarch64_folder_without_daqp_is_refused_for_a_six_dof_export(tmp_path):
    """A folder make hpipm-aarch64 fetched before the depth channel needed DAQP: one line."""
    older = tmp_path / "hpipm-aarch64"
    shutil.copytree(_AARCH64_LIBS, older, ignore=shutil.ignore_patterns("libdaqp.so"))
    with pytest.raises(ConfigError, match="no libdaqp.so there.*make hpipm-aarch64"):
        export_c(load_scenario("bluerov2-helix", _PAIR), tmp_path / "export", aarch64=older)
    assert not (tmp_path / "export").exists()


@needs_cc
@needs_aarch64
@needs_aarch64_daqp
def test_the_aarch64_six_dof_build_reproduces_python_under_qemu(tmp_path):
    """make TARGET=aarch64 with the aarch64 DAQP, the replay under qemu-aarch64: within
    verify-c's bound, both channels' statuses the run's, no heap call in a step."""
    resolved, run_dir = _run(tmp_path, "paper-6dof", [*_PAIR, "duration=2"])
    export_c(resolved, tmp_path / "export", aarch64=_AARCH64_LIBS)
    result = verify_c(tmp_path / "export", run_dir, target="aarch64")
    assert result.target == "aarch64" and result.steps == 4
    assert result.max_difference_n <= COMMAND_TOLERANCE_N
    assert result.status_differences == result.depth_status_differences == 0
    assert result.heap_calls == 0
