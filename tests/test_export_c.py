"""The real-time nmpc exported to C (auvmpc export-c) reproduces the Python commands (issue 15)."""

from __future__ import annotations

import json
import os
import re
import shutil
import sys
from pathlib import Path

import numpy as np
import pytest

import auvmpc
from auvmpc.errors import ConfigError, RunFailed
from auvmpc.experiments.run import run_plant, simulate, write_run
from auvmpc.experiments.run_folder import read_run_folder
from auvmpc.export.c_library import COMMAND_TOLERANCE_N, export_c, verify_c
from auvmpc.native import compiler
from auvmpc.scenario import load_scenario
from auvmpc.sim.loop import run_session
from auvmpc.solvers.blasfeo_target import BLASFEO_ENV, missing_features, required_features
from auvmpc.solvers.compiled_qp_step import _casadi_hpipm
from tests.conftest import C_EXPORT_COMMAND_TOL_N
from tests.test_cli import run_cli

needs_cc = pytest.mark.skipif(
    compiler() is None or shutil.which("make") is None or _casadi_hpipm() is None,
    reason="no C compiler, make, or HPIPM in the casadi wheel",
)
# Every move free, as export-c exports it; a short run keeps the test quick.
_FREE = ["controller.type=nmpc", "controller.control_horizon=null", "duration=5"]


_LIGHT_LAWNMOWER = str(
    Path(__file__).parents[1] / "benchmarks" / "scenarios" / "bluerov2-light-lawnmower.yaml"
)
_DISC_AHEAD = "obstacles=[{center: [10.0, 0.2], radius: 0.6}]"


def _run(tmp_path, scenario: str, overrides: list[str]):
    resolved = load_scenario(scenario, overrides)
    run_dir = tmp_path / "run"
    write_run(simulate(resolved), run_dir, figures=False)
    return resolved, run_dir


def _paths_of_this_machine(export: Path) -> list[str]:
    """The folders of this machine an export must not name: the project, the Python
    environment and its casadi, the home folder, the export's own folder."""
    _, wheel = _casadi_hpipm()
    return [str(Path(auvmpc.__file__).parents[2]), sys.prefix, str(wheel), str(Path.home()),
            str(export.resolve())]  # fmt: skip


@needs_cc
def test_the_documented_flow_verifies(tmp_path):
    """docs/onboard.md: export the preset as it is (its controller is the paper's mpc), run
    it with the exported controller by overrides, verify. The run's configuration has nmpc's
    defaults filled in, the export's record not: compared filled in for the vehicle. The
    folder names no path of this machine and verifies, example main included, when copied
    alone elsewhere: HPIPM and BLASFEO travel with it."""
    export = tmp_path / "export"
    export_c(load_scenario("paper-obstacles", ["duration=5"]), export)
    forbidden = _paths_of_this_machine(export)
    for file in export.rglob("*"):
        if file.is_file():
            data = file.read_bytes()
            assert not [p for p in forbidden if p.encode() in data], file
    assert {"libhpipm.so", "libblasfeo.so.0"} <= {f.name for f in export.glob("lib/*/*")}
    assert (export / "licenses" / "HPIPM-LICENSE.txt").is_file()
    alone = tmp_path / "elsewhere" / "controller"
    shutil.copytree(export, alone)
    shutil.rmtree(export)
    _, run_dir = _run(tmp_path, "paper-obstacles", _FREE)
    result = verify_c(alone, run_dir)
    assert result.steps == 10 and result.max_difference_n <= C_EXPORT_COMMAND_TOL_N
    assert result.target == "x86-64-generic" and result.heap_calls == 0
    assert 0 < result.max_iterations <= result.iteration_bound


@needs_cc
@pytest.mark.parametrize(
    ("scenario", "overrides"),
    [
        ("paper-ideal", ["controller.offset_free=false"]),
        # spinning at the start, a disc on the way to the reference: the shell's recovery
        # (the generated feedback, holding station) with the estimator's force
        (
            "paper-obstacles",
            [
                "controller.offset_free=true",
                "initial_state=[0.0, -12.0, 1.57, 0.0, 0.0, 3.0]",
                "obstacles=[{center: [4.0, -12.0], radius: 0.5}]",
            ],
        ),
        # a moving disc, one appearing and vanishing within the run, one fixed
        (
            "paper-obstacles",
            [
                "obstacles=[{center: [7.0, -9.0], radius: 0.5, velocity: [0.1, -0.2]}, "
                "{center: [8.0, -6.0], radius: 0.5, appear_time: 1.0, vanish_time: 3.0}, "
                "{center: [7.0, 2.0], radius: 0.4}]"
            ],
        ),
        # every cold start diverges when re-simulated: the multiple-shooting retry in C too
        (_LIGHT_LAWNMOWER, [_DISC_AHEAD]),
    ],
)
def test_exported_controller_reproduces_python_commands(tmp_path, scenario, overrides):
    """Obstacle slots (moving, appearing), the offset-free EKF and the shell's recovery
    included: every command within the bound, every status the Python run's."""
    resolved, run_dir = _run(tmp_path, scenario, [*_FREE, *overrides])
    export_c(resolved, tmp_path / "export")
    result = verify_c(tmp_path / "export", run_dir)
    assert result.steps == 10
    assert result.fallbacks == 0 and result.status_differences == 0
    spinning_start = any(o.startswith("initial_state") for o in overrides)
    assert result.recoveries == (1 if spinning_start else 0)
    assert result.max_difference_n <= C_EXPORT_COMMAND_TOL_N
    assert 0 < result.static_bytes < result.workspace_bytes
    # HPIPM's workspace lives in the static arena measured at export (plus its alignment room)
    record = json.loads((tmp_path / "export" / "export.json").read_text())
    assert result.workspace_bytes == record["hpipm_arena_bytes"] + 64


@pytest.mark.parametrize(
    ("overrides", "message"),
    [
        (["vehicle=videoray-pro3", "controller.R=null"], "underactuated"),
        (["controller.prediction_horizon=1000"], "static memory"),
        (["controller.solver_time_limit_ms=50"], "solve-time limit"),
        (["controller.disturbance_bound.force_N=5"], "tightening is not exported"),
    ],
)
def test_unsupported_configurations_refused_in_one_line(
    tmp_path, monkeypatch, capsys, overrides, message
):
    sets = [part for o in overrides for part in ("--set", o)]
    out = tmp_path / "export"
    code, _, err = run_cli(monkeypatch, capsys, "export-c", "paper-ideal", "--out", str(out), *sets)
    assert code == 2
    assert message in err
    assert len(err.strip().splitlines()) == 1
    assert not out.exists()


def test_export_refuses_a_folder_it_did_not_write(tmp_path):
    (tmp_path / "notes.txt").write_text("mine")
    with pytest.raises(ConfigError, match="did not write"):
        export_c(load_scenario("paper-ideal", ["duration=5"]), tmp_path)
    assert (tmp_path / "notes.txt").read_text() == "mine"


def test_verify_refuses_a_run_of_another_controller(tmp_path):
    """A run with move blocking (the scenario's own nc = 2) is not the exported controller."""
    resolved = load_scenario("paper-ideal", ["duration=5", "controller.offset_free=false"])
    export_c(resolved, tmp_path / "export")
    blocked = load_scenario("paper-ideal", ["duration=1", "controller.type=nmpc"])
    write_run(simulate(blocked), tmp_path / "run", figures=False)
    with pytest.raises(ConfigError, match="not the exported one"):
        verify_c(tmp_path / "export", tmp_path / "run")
    record = json.loads((tmp_path / "export" / "export.json").read_text())
    assert record["controller"]["control_horizon"] is None


def _blasfeo_folder(tmp_path, features: tuple[str, ...], target: str = "GENERIC"):
    """A folder standing in for a BLASFEO built for some CPU: the casadi wheel's own library
    as libblasfeo.so, and a blasfeo_target.h naming ``target`` and needing ``features``."""
    folder = tmp_path / "blasfeo"
    folder.mkdir()
    _, wheel_libraries = _casadi_hpipm()
    shutil.copyfile(next(wheel_libraries.glob("libblasfeo.so*")), folder / "libblasfeo.so")
    (folder / "blasfeo_target.h").write_text(
        f"#ifndef TARGET_{target}\n#define TARGET_{target}\n#endif\n"
        + "".join(
            f"#ifndef TARGET_NEED_FEATURE_{f}\n#define TARGET_NEED_FEATURE_{f} 1\n#endif\n"
            for f in features
        )  # fmt: skip
    )
    return folder


@needs_cc
def test_export_links_the_blasfeo_it_is_given(tmp_path):
    """--blasfeo DIR: the export carries DIR's libblasfeo.so as the target x86-64-tuned under
    the wheel's HPIPM (here a copy of the wheel's own, so the commands are the same to the
    bound), which make builds by default; a file there that is no library makes the build
    fail, which shows it is the one linked."""
    resolved, run_dir = _run(tmp_path, "paper-obstacles", _FREE)
    folder = _blasfeo_folder(tmp_path, ())
    export = tmp_path / "export"
    export_c(resolved, export, blasfeo=folder)
    record = json.loads((export / "export.json").read_text())
    assert record["default_targets"]["x86_64"] == "x86-64-tuned"
    assert record["targets"]["x86-64-tuned"]["blasfeo_target"] == "GENERIC"
    carried = export / "lib" / "x86-64-tuned" / "libblasfeo.so.0"
    assert carried.read_bytes() == (folder / "libblasfeo.so").read_bytes()
    result = verify_c(export, run_dir)
    assert result.target == "x86-64-tuned"
    assert result.max_difference_n <= C_EXPORT_COMMAND_TOL_N
    carried.write_bytes(b"not a shared library")
    with pytest.raises(RunFailed, match="did not build"):
        verify_c(export, run_dir)


@needs_cc
def test_the_generic_build_carries_the_avx_blasfeo_it_is_given(tmp_path):
    """--generic-blasfeo DIR: the target x86-64-generic carries DIR's libblasfeo.so instead
    of the wheel's GENERIC one, still compiled for every x86-64, with no tuned target added;
    export.json names DIR's target and its AVX, which verify-c checks before a replay."""
    folder = _blasfeo_folder(tmp_path, ("AVX",), "X64_INTEL_SANDY_BRIDGE")
    export = tmp_path / "export"
    export_c(load_scenario("paper-ideal", _FREE), export, generic_blasfeo=folder)
    record = json.loads((export / "export.json").read_text())
    assert record["targets"] == {
        "x86-64-generic": {"machine": "x86_64", "flags": "-march=x86-64 -mtune=generic",
                           "blasfeo_target": "X64_INTEL_SANDY_BRIDGE",
                           "blasfeo_features": ["AVX"]},
    }  # fmt: skip
    carried = export / "lib" / "x86-64-generic" / "libblasfeo.so.0"
    assert carried.read_bytes() == (folder / "libblasfeo.so").read_bytes()


def test_a_generic_blasfeo_needing_more_than_avx_is_refused_in_one_line(tmp_path, monkeypatch,
                                                                         capsys):  # fmt: skip
    """AVX2 and FMA would narrow the CPUs the generic build runs on: that library is the
    tuned target's (--blasfeo)."""
    folder = _blasfeo_folder(tmp_path, ("AVX2", "FMA"), "X64_INTEL_HASWELL")
    out = tmp_path / "export"
    code, _, err = run_cli(monkeypatch, capsys, "export-c", "paper-ideal",
                           "--generic-blasfeo", str(folder), "--out", str(out))  # fmt: skip
    assert code == 2
    # one line; the folder named after it, which the printer shortens when it is long
    (line,) = err.strip().splitlines()
    assert line.startswith(
        "error: --generic-blasfeo: its BLASFEO needs AVX2, FMA, which x86-64-generic does not: "
        "give it as --blasfeo (the tuned target) (got '"
    )
    assert not out.exists()


# The BLASFEO for AVX that make blasfeo-avx builds into the environment.
_AVX_BLASFEO = Path(
    os.environ.get("AUVMPC_AVX_BLASFEO", Path(sys.prefix) / "blasfeo-x64-sandy-bridge")
)


@needs_cc
@pytest.mark.skipif(
    not (_AVX_BLASFEO / "libblasfeo.so").is_file() or missing_features(("AVX",)),
    reason="no AVX BLASFEO (make blasfeo-avx) or no AVX on this CPU",
)
def test_the_generic_build_with_the_avx_blasfeo_reproduces_python(tmp_path):
    """The real X64_INTEL_SANDY_BRIDGE build under the wheel's HPIPM: the commands within
    verify-c's bound (its AVX kernels sum in another order than the GENERIC C), the statuses
    the run's, no heap call in a step."""
    resolved, run_dir = _run(tmp_path, "paper-obstacles", _FREE)
    export_c(resolved, tmp_path / "export", generic_blasfeo=_AVX_BLASFEO)
    result = verify_c(tmp_path / "export", run_dir)
    assert result.target == "x86-64-generic"
    assert result.max_difference_n <= COMMAND_TOLERANCE_N
    assert result.status_differences == 0 and result.heap_calls == 0


@needs_cc
def test_verify_refuses_a_blasfeo_built_for_features_this_cpu_lacks(tmp_path):
    resolved, run_dir = _run(tmp_path, "paper-ideal", _FREE)
    folder = _blasfeo_folder(tmp_path, ("NO_SUCH_FEATURE",))
    export_c(resolved, tmp_path / "export", blasfeo=folder)
    with pytest.raises(ConfigError, match="lacks \\(NO_SUCH_FEATURE\\).*illegal instruction"):
        verify_c(tmp_path / "export", run_dir)


def test_a_blasfeo_folder_without_the_library_is_refused_in_one_line(tmp_path, monkeypatch,
                                                                      capsys):  # fmt: skip
    out = tmp_path / "export"
    code, _, err = run_cli(
        monkeypatch,
        capsys,
        "export-c",
        "paper-ideal",
        "--blasfeo",
        str(tmp_path),
        "--out",
        str(out),
    )
    assert code == 2
    assert err.strip() == f"error: --blasfeo: no libblasfeo.so in that folder (got '{tmp_path}')"
    assert not out.exists()


def test_cpu_features_are_read_from_cpuinfo(tmp_path):
    cpuinfo = tmp_path / "cpuinfo"
    cpuinfo.write_text("processor\t: 0\nflags\t\t: fpu sse2 pni avx avx2 fma\n")
    assert missing_features(("SSE3", "AVX", "AVX2", "FMA"), cpuinfo) == []
    assert missing_features(("AVX2", "AVX512F", "NEON"), cpuinfo) == ["AVX512F", "NEON"]
    arm = tmp_path / "arm"
    arm.write_text("Features\t: fp asimd evtstrm aes\n")
    assert missing_features(("NEON", "NEONv2", "FMA"), arm) == ["FMA"]
    assert missing_features(("AVX2",), tmp_path / "absent") == ["AVX2"]
    # BLASFEO's ARMv8 targets need VFPv4 and NEONv2; 64-bit Arm calls them fp and asimd
    assert missing_features(("VFPv4", "NEONv2"), arm) == []
    header = tmp_path / "blasfeo_target.h"
    header.write_text("#define TARGET_NEED_FEATURE_AVX2 1\n/* #undef TARGET_NEED_FEATURE_SSE3 */\n")
    assert required_features(tmp_path) == ("AVX2",)


@needs_cc
@pytest.mark.parametrize(
    ("target", "header", "message"),
    [
        ("X64_INTEL_SKYLAKE_X", True, "packs 8 doubles per panel.*built for 4 \\(GENERIC\\)"),
        ("GENERIC", False, "no blasfeo_target.h"),
    ],
)
def test_a_blasfeo_the_wheels_hpipm_cannot_use_is_refused(tmp_path, target, header, message):
    """Another panel size would change the matrix layout the wheel's HPIPM was compiled for
    (silently wrong commands); without its target header its CPU needs are unknown."""
    folder = _blasfeo_folder(tmp_path, (), target)
    if not header:
        (folder / "blasfeo_target.h").unlink()
    with pytest.raises(ConfigError, match=message):
        export_c(load_scenario("paper-ideal", _FREE), tmp_path / "export", blasfeo=folder)
    assert not (tmp_path / "export").exists()


@needs_cc
def test_the_python_step_takes_its_blasfeo_from_the_environment(tmp_path, monkeypatch):
    """AUVMPC_BLASFEO_DIR: the real-time nmpc's compiled QP step links that folder's BLASFEO
    (here a copy of the wheel's, so the commands agree to the C export's bound); a folder the
    wheel's HPIPM cannot use is refused in one line naming the variable."""
    scenario = load_scenario("paper-obstacles", _FREE)
    wheel = simulate(scenario).log.thrust
    folder = _blasfeo_folder(tmp_path, ())
    monkeypatch.setenv(BLASFEO_ENV, str(folder))
    linked = simulate(scenario).log.thrust
    assert np.abs(linked - wheel).max() <= C_EXPORT_COMMAND_TOL_N
    (folder / "blasfeo_target.h").write_text("#define TARGET_X64_INTEL_SKYLAKE_X\n")
    with pytest.raises(ConfigError, match=f"^{BLASFEO_ENV}: .*packs 8 doubles per panel"):
        simulate(scenario)


def test_the_status_numbers_are_the_headers():
    """verify-c reads the replay's statuses by number: its table is auvmpc_status's order."""
    from auvmpc.controllers.c_sources import FIXED_SOURCES
    from auvmpc.controllers.compiled_nmpc import C_STATUS

    header = next(s for s in FIXED_SOURCES if s.name == "auvmpc_controller.h").read_text()
    header = header[header.index("typedef enum {") : header.index("} auvmpc_status;")]
    numbers = {
        name.lower(): int(number) for name, number in re.findall(r"AUVMPC_([A-Z]+) = (\d+)", header)
    }
    assert numbers == {str(status): i for i, status in enumerate(C_STATUS)}


@needs_cc
def test_the_effectiveness_setter_changes_the_c_command_as_python_does(tmp_path):
    """A controller told from its first sample that the third thruster is dead: the C told
    the same by auvmpc_set_effectiveness commands what Python did, nothing to the dead
    thruster (paper-ideal as exported: no estimator, the quickest export to build)."""
    dead_third = [1.0, 1.0, 0.0, 1.0]
    overrides = _FREE
    session = auvmpc.session(load_scenario("paper-ideal", overrides))
    session.effectiveness = dead_third
    run_session(session, *run_plant(session.resolved))
    session.close(tmp_path / "run", figures=False)
    export_c(load_scenario("paper-ideal", overrides), tmp_path / "export")
    result = verify_c(tmp_path / "export", tmp_path / "run", effectiveness=dead_third)
    assert result.steps == 10 and result.max_difference_n <= C_EXPORT_COMMAND_TOL_N
    assert result.status_differences == 0
    log = read_run_folder(tmp_path / "run").log()
    assert not log.column(log.input_names[2]).any()
    assert log.column(log.input_names[0]).any()


# The aarch64 HPIPM and BLASFEO that make hpipm-aarch64 fetches into the environment.
_AARCH64_LIBS = Path(os.environ.get("AUVMPC_AARCH64_LIBS", Path(sys.prefix) / "hpipm-aarch64"))
needs_aarch64 = pytest.mark.skipif(
    shutil.which("aarch64-linux-gnu-gcc") is None or shutil.which("qemu-aarch64") is None
    or not (_AARCH64_LIBS / "libhpipm.so").is_file(),
    reason="no aarch64 cross compiler, qemu-aarch64, or aarch64 HPIPM (make hpipm-aarch64)",
)  # fmt: skip


@needs_cc
@needs_aarch64
def test_the_aarch64_build_reproduces_python_under_qemu(tmp_path):
    """make TARGET=aarch64 with Debian's cross compiler, the replay under qemu-aarch64: the
    commands within verify-c's bound (the aarch64 HPIPM's round-off), the statuses the
    run's, no heap call in a step. paper-ideal: the quickest to emulate."""
    overrides = [*_FREE, "controller.offset_free=false", "duration=2"]
    resolved, run_dir = _run(tmp_path, "paper-ideal", overrides)
    export_c(resolved, tmp_path / "export", aarch64=_AARCH64_LIBS)
    result = verify_c(tmp_path / "export", run_dir, target="aarch64")
    assert result.target == "aarch64" and result.steps == 4
    assert result.max_difference_n <= COMMAND_TOLERANCE_N
    assert result.status_differences == 0 and result.heap_calls == 0
