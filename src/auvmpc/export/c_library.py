"""The real-time controller ``nmpc`` exported as a standalone C99 library (``auvmpc export-c``).

What is written (docs/onboard.md): the controller's sources, exactly those the Python ``nmpc``
builds and runs where it is compiled (controllers/c_sources.py: the controller and its safety
shell ``auvmpc_controller.c`` with its header, auvmpc's HPIPM driver ``hpipm_ocp_step.c``,
CasADi's C code of the functions the Python evaluates, ``rti_qp_data.c`` and ``ekf_data.c``,
and the scenario's sizes and settings, ``auvmpc_config.h``), a replay harness (``replay.c``)
with the scenario's reference preview and obstacles per sample (``replay_data.txt``), an
example main (``example.c``), a Makefile and a README; and HPIPM's and BLASFEO's shared
libraries for each target, with their headers and licences (export/c_targets.py), so that
the folder builds anywhere with a C compiler alone.

:func:`verify_c` builds the export for a target in a temporary folder, replays a run
folder's states through it (under QEMU for an emulated target) and compares its commands
with the run's (``auvmpc verify-c``), with the step's real-time facts: heap calls inside the
step, iterations against their bound, and optionally the instructions per step.

Supported: a horizontal scenario, a fully actuated vehicle, the real-time iteration with every
move free (what the bench label ``nmpc`` runs), with or without the offset-free estimator, no
solve-time limit; and a six-dof scenario, that horizontal controller beside its depth MPC, one
C controller of every thruster (export/six_dof_c.py). Anything else is refused with one line.
"""

from __future__ import annotations

import csv
import json
import shutil
import statistics
import subprocess
import tempfile
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import casadi as ca
import numpy as np
from pydantic import ValidationError

from auvmpc.controllers.base import ControlStatus
from auvmpc.controllers.c_sources import write_sources
from auvmpc.controllers.compiled_nmpc import C_STATUS
from auvmpc.controllers.config import (
    SAVED_RUN,
    ControllerType,
    HorizontalControllerConfig,
    NmpcMode,
    QpStructure,
    TightenedConstraints,
)
from auvmpc.controllers.depth_mpc import DepthControllerConfig
from auvmpc.controllers.nmpc import _COLD_START_ITERATIONS, NmpcConfig
from auvmpc.errors import ConfigError, RunFailed, format_validation_error
from auvmpc.experiments.outputs import OutputKind, check_output_folder, staged_folder
from auvmpc.experiments.run_folder import RunFolder, read_run_folder
from auvmpc.export.c_targets import (
    Target,
    aarch64_target,
    generic_with,
    host_machine,
    hwcaps_level,
    makefile_table,
    tuned_target,
    wheel_target,
    write_solver_files,
)
from auvmpc.export.instruction_counts import emulator_command, step_instructions
from auvmpc.export.replay_data import replay_data
from auvmpc.export.six_dof_c import (
    check_six_dof,
    daqp_libraries,
    depth_static_bytes,
    six_dof_replay_data,
    write_six_dof_sources,
)
from auvmpc.models.layout import HORIZONTAL
from auvmpc.models.vehicle import VehicleParams
from auvmpc.native import compiler
from auvmpc.ocp.multiple_shooting import (
    MAX_OBSTACLES,
    ND,
    SLOT_FIELDS,
    MultipleShootingProgram,
)
from auvmpc.ocp.stage_qp import stage_qp
from auvmpc.references import make_reference
from auvmpc.safe_yaml import read_text_file
from auvmpc.solvers.blasfeo_target import blasfeo_folder, missing_features
from auvmpc.solvers.compiled_qp_step import _casadi_hpipm, compiled_qp_step
from auvmpc.solvers.hpipm import hpipm_settings

__all__ = [
    "COMMAND_TOLERANCE_N",
    "STATIC_MEMORY_LIMIT_BYTES",
    "VerifyResult",
    "export_c",
    "exported_config",
    "iteration_bound",
    "verify_c",
]

# The controller's own static arrays may take at most this much (bytes); HPIPM's workspace,
# allocated once at init, comes on top (docs/onboard.md). At 4 thrusters and 8 obstacle slots
# this allows a horizon of about 450 samples.
STATIC_MEMORY_LIMIT_BYTES = 256 * 1024
# verify-c's pass mark: the largest difference between a C and a Python command (N).
COMMAND_TOLERANCE_N = 1e-6

_TEMPLATES = Path(__file__).with_name("c")
_COPIED = ("replay.c", "replay_common.h", "example.c", "README.md")
_DATA = "replay_data.txt"
_RECORD = "export.json"
_NX = HORIZONTAL.size


def exported_config(config: HorizontalControllerConfig) -> NmpcConfig:
    """The controller a run must use to be reproduced by the export: ``nmpc`` real-time with
    every move free (control_horizon = prediction_horizon), with the settings ``config``
    gives that nmpc has."""
    from auvmpc.controllers.registry import retyped

    return retyped(
        config,
        ControllerType.NMPC,
        nmpc_mode=NmpcMode.REAL_TIME,
        control_horizon=None,
        move_steps=None,
    )


def static_bytes(horizon: int, thrusters: int, slots: int) -> int:
    """The controller's arrays that grow with the horizon (auvmpc_controller.c), bytes; the
    generated functions' work arrays come on top (measured sizeof: 17.1 kB on paper-obstacles,
    estimated 17.3 kB; 24.4 kB against 17.3 kB with the estimator's CasADi work)."""
    N, n, S = horizon, thrusters, max(slots, 1)
    nz, nv = _NX + n, n + (1 if slots else 0)
    iterates = 3 * ((N + 1) * _NX + N * n)  # guess, next guess, iterate
    # previous command, fallback plan, predicted yaw rate, hold, the thrusters' effectiveness
    shell = n * (2 + N) + 3
    # state, disturbance, reference, obstacle slots with their used flags, weights, movable
    sample = _NX + ND + (N + 1) * _NX + (SLOT_FIELDS + 1) * S + N * _NX + N
    step = (N + 1) * n + (N + 1) * nz + N * nv + N  # P, dz, dv, slack
    estimator = (_NX + ND) * (1 + _NX + ND)  # estimate, covariance
    doubles = iterates + shell + sample + step + estimator
    return 8 * doubles


def iteration_bound(config: NmpcConfig) -> int:
    """The most HPIPM interior-point iterations one exported step can take: the cold start's
    SQP steps and both retries from the reference (auvmpc_controller.c, auvmpc_step), each QP
    through every pass at its iteration limit after its hot-started try
    (hpipm_ocp_step.c)."""
    settings = hpipm_settings(config.qp_iteration_limit)
    passes = [settings[2 + 6 * p : 8 + 6 * p] for p in range(int(settings[1]))]
    per_qp = sum(int(limit) + int(hot) for _, limit, _, _, _, hot in passes)
    sqp_steps = max(config.linearisation_iterations, _COLD_START_ITERATIONS)
    return 3 * sqp_steps * per_qp


_KINDS = ("horizontal", "six-dof")  # the scenario kinds export-c takes
_SIX_DOF = "six-dof"


def _kind(resolved) -> str | None:
    return getattr(resolved.scenario, "kind", None)


def _check_supported(resolved) -> tuple[NmpcConfig, int]:
    scenario = resolved.scenario
    if _kind(resolved) not in _KINDS:
        raise ConfigError(
            "SCENARIO", scenario.name, "export-c takes horizontal and six-dof scenarios only"
        )
    if _kind(resolved) == _SIX_DOF:  # the depth channel first: it decides the controller type
        check_six_dof(resolved)
    model = resolved.model
    if model.unactuated_direction is not None:
        raise ConfigError(
            "vehicle", model.name, "underactuated: export-c supports fully actuated vehicles only"
        )
    given = scenario.controller
    if isinstance(given, TightenedConstraints) and not given.disturbance_bound.is_zero:
        raise ConfigError(
            "controller.disturbance_bound", given.disturbance_bound.model_dump(),
            "export-c exports the nominal nmpc; the robust tightening is not exported "
            "(leave the bound zero)",
        )  # fmt: skip
    config = exported_config(given)
    if config.solver_time_limit_ms is not None:
        raise ConfigError(
            "controller.solver_time_limit_ms", config.solver_time_limit_ms,
            "export-c has no solve-time limit (the caller owns the deadline); leave it unset",
        )  # fmt: skip
    if config.qp_structure is QpStructure.CONDENSED:
        raise ConfigError(
            "controller.qp_structure", "condensed", "export-c exports the sparse QP (HPIPM)"
        )
    slots = min(MAX_OBSTACLES, len(scenario.obstacles))
    needed = static_bytes(config.prediction_horizon, model.n_thrusters, slots)
    if needed > STATIC_MEMORY_LIMIT_BYTES:
        raise ConfigError(
            "controller.prediction_horizon", config.prediction_horizon,
            f"needs {needed} bytes of static memory, over export-c's limit of "
            f"{STATIC_MEMORY_LIMIT_BYTES}",
        )  # fmt: skip
    return config, slots


# The arena's room beyond what the driver counts: each of its at most 40 pieces rounded up to
# 64 bytes, the base aligned, and the six (N + 1)-int temporaries it sizes the QP with.
_ARENA_PIECES, _ARENA_ALIGN = 40, 64


def _arena_bytes(qp, program: MultipleShootingProgram, config: NmpcConfig) -> int | None:
    """The static arena for the HPIPM driver, measured on the Python controller's compiled
    step for the same QP; None where that cannot be built (then the export allocates at
    init)."""
    step = compiled_qp_step(
        qp, program.horizon, program.n_thrusters, program.n_slots,
        hpipm_settings(config.qp_iteration_limit),
    )  # fmt: skip
    if step is None:
        return None
    # auvmpc_rti_create's six int arrays per stage (nx, nu, nbx, nbu, rows, ns), 4 bytes each
    temporaries = 6 * (program.horizon + 1) * 4
    return step.memory_bytes + _ARENA_PIECES * _ARENA_ALIGN + temporaries + _ARENA_ALIGN


def _replay_data(resolved, horizon: int, sample_time: float) -> str:
    """The reference preview and the obstacles at every sample, as the closed loop computes
    them (sim/loop.py), and the initial thrust."""
    scenario = resolved.scenario
    steps = int(round(scenario.duration / sample_time))
    reference = make_reference(scenario.reference, resolved.base_dir)
    n = resolved.model.n_thrusters
    initial = np.zeros(n) if scenario.initial_thrust is None else scenario.initial_thrust
    header = f"auvmpc-replay 1 steps {steps} horizon {horizon} thrusters {n}"
    return replay_data(header, initial, reference, horizon, steps, sample_time, scenario.obstacles)


def export_c(
    resolved,
    out: Path | str,
    *,
    overwrite: bool = False,
    blasfeo: Path | str | Sequence[Path | str] = (),
    aarch64: Path | str | None = None,
    generic_blasfeo: Path | str | None = None,
) -> Path:
    """Write the export of ``resolved``'s controller into the folder ``out`` (auvmpc's output
    rules: a new or empty folder, or an earlier export with ``overwrite``). Returns it.

    It builds for this computer's instruction set from the installed casadi wheel's HPIPM
    and BLASFEO (``x86-64-generic`` on an x86-64), and also for: ``aarch64``, the aarch64
    HPIPM and BLASFEO in the folder ``aarch64`` (``make hpipm-aarch64``); ``x86-64-tuned`` or
    ``aarch64-tuned``, each folder in ``blasfeo`` (one per instruction set) with a
    ``libblasfeo.so`` built for one CPU, under the portable HPIPM of its instruction set
    (solvers/blasfeo_target.py). ``generic_blasfeo``: a folder with a ``libblasfeo.so`` that
    needs no CPU feature beyond the wheel's HPIPM's (AVX on x86-64: ``make blasfeo-avx``),
    carried by this computer's portable target instead of the wheel's GENERIC one. Their
    libraries, headers and licences are copied in (export/c_targets.py).
    """
    config, slots = _check_supported(resolved)
    six_dof = _kind(resolved) == _SIX_DOF
    hpipm = _casadi_hpipm()
    if hpipm is None:
        raise ConfigError("casadi", ca.__version__, "this casadi wheel has no HPIPM to link")
    include, libraries = hpipm
    targets = [wheel_target(libraries, include)]
    if generic_blasfeo is not None:
        folder = blasfeo_folder(generic_blasfeo, include, field="--generic-blasfeo")
        targets[0] = generic_with(targets[0], folder)
    if aarch64 is not None:
        targets.append(aarch64_target(aarch64, ca.__version__, include))
    portable = {t.machine: t for t in targets}
    for given in [blasfeo] if isinstance(blasfeo, str | Path) else blasfeo:
        tuned = tuned_target(blasfeo_folder(given, include), portable)
        if any(t.name == tuned.name for t in targets):
            raise ConfigError("--blasfeo", str(given), f"a second BLASFEO for {tuned.machine}")
        targets.append(tuned)
    daqp = daqp_libraries(targets, libraries, aarch64) if six_dof else {}
    check_output_folder(out, OutputKind.EXPORT_C, overwrite=overwrite)  # before the work
    model = resolved.model
    program = MultipleShootingProgram(model, config, slots)
    qp = stage_qp(program)
    with staged_folder(out, OutputKind.EXPORT_C, overwrite=overwrite) as folder:
        write_sources(program, qp, config, folder)
        for name in _COPIED:
            shutil.copyfile(_TEMPLATES / name, folder / name)
        write_solver_files(targets, include, folder)
        depth = None
        if six_dof:  # the depth channel and the mapping; the pair's replay and example main
            depth = write_six_dof_sources(resolved, folder, daqp, include, program.horizon)
        arena = _arena_bytes(qp, program, config)
        defaults = {machine: _default_target(targets, machine) for machine in _MACHINES}
        fills = {
            "@TARGET_TABLE@": makefile_table(targets),
            "@TARGETS@": " ".join(t.name for t in targets),
            "@X86_DEFAULT@": defaults["x86_64"] or "none",
            "@ARM_DEFAULT@": defaults["aarch64"] or "none",
            "@ARENA_DEFINE@": "" if arena is None else f"-DAUVMPC_ARENA_BYTES={arena}",
        }
        makefile = (_TEMPLATES / "Makefile.in").read_text()
        for key, value in fills.items():
            makefile = makefile.replace(key, value)
        (folder / "Makefile").write_text(makefile)
        replay_data = six_dof_replay_data if six_dof else _replay_data
        (folder / _DATA).write_text(replay_data(resolved, program.horizon, program.sample_time))
        record = {
            "scenario": resolved.scenario.name,
            "controller": json.loads(config.model_dump_json()),
            "model": json.loads(model.model_dump_json()),
            "casadi": ca.__version__,
            "targets": {t.name: t.record() for t in targets},
            # the tuned BLASFEO glibc's loader takes for the generic x86-64 build on a CPU of
            # that level (export/c_targets.py)
            "hwcaps": {level: t.blasfeo_target for t in targets if (level := hwcaps_level(t))},
            "default_targets": defaults,
            "static_bytes_estimate": static_bytes(program.horizon, program.n_thrusters, slots),
            "hpipm_arena_bytes": arena,
            "iteration_bound": iteration_bound(config),
            "kind": _kind(resolved),
        }
        if depth is not None:
            depth_config = resolved.scenario.depth_controller
            record["depth_controller"] = json.loads(depth_config.model_dump_json())
            moves = depth.qp.n_moves // depth.heave.thruster_count
            record["depth_static_bytes_estimate"] = depth_static_bytes(
                depth.horizon, moves, depth.heave.thruster_count
            )
        (folder / _RECORD).write_text(json.dumps(record, indent=2) + "\n")
    return Path(out)


_MACHINES = ("x86_64", "aarch64")


def _default_target(targets: list[Target], machine: str) -> str | None:
    """What ``make`` builds on a ``machine`` computer: the tuned target where there is one."""
    names = [t.name for t in targets if t.machine == machine]
    return next((n for n in names if n.endswith("-tuned")), names[0] if names else None)


@dataclass(frozen=True)
class VerifyResult:
    """What ``verify-c`` measured."""

    target: str  # the make TARGET that was built and replayed
    steps: int
    max_difference_n: float  # largest |F_C - F_Python| over every step and thruster (N)
    worst_step: int
    step_us_median: float  # on an emulated target: the emulator's time, not the target's
    step_us_max: float
    step_us_max_after_first: float  # the first step starts cold: 10 SQP steps
    static_bytes: int  # the controller's static structure
    workspace_bytes: int  # HPIPM's workspace and the driver's buffers: the static arena
    heap_calls: int  # malloc, calloc, realloc, free inside auvmpc_step (-1: not counted)
    max_iterations: int  # the most HPIPM iterations of one step
    iteration_bound: int  # the most one step can take (iteration_bound)
    fallbacks: int
    recoveries: int  # steps the shell's stabilising feedback commanded
    status_differences: int  # steps whose C status is not the Python run's
    instructions: tuple[int, ...] = ()  # per step, where counted (--instructions)
    # A six-dof export's depth channel (None for a horizontal one): the most DAQP iterations
    # of one step, the steps its shell fell back or recovered, and those whose depth status
    # is not the run's.
    depth_max_iterations: int | None = None
    depth_fallbacks: int = 0
    depth_recoveries: int = 0
    depth_status_differences: int = 0

    @property
    def failures(self) -> list[str]:
        """What the replay did not reproduce (none: it passed)."""
        found = []
        if self.max_difference_n > COMMAND_TOLERANCE_N:
            found.append(f"commands above the tolerance of {COMMAND_TOLERANCE_N:g} N")
        if self.status_differences:
            found.append(
                f"{self.status_differences} steps with another status than the run's (the C "
                "has neither the IPOPT rescue nor the estimator's restart: docs/onboard.md)"
            )
        if self.depth_status_differences:
            found.append(
                f"{self.depth_status_differences} steps with another depth status than the run's"
            )
        if self.heap_calls > 0:
            found.append(f"{self.heap_calls} heap calls inside the steps")
        if self.max_iterations > self.iteration_bound:
            found.append(
                f"{self.max_iterations} iterations in a step, over the bound {self.iteration_bound}"
            )
        return found

    @property
    def passed(self) -> bool:
        return not self.failures


@dataclass(frozen=True)
class _ExportRecord:
    """What an export's export.json says it exported (checked by :func:`_export_record`)."""

    model: VehicleParams
    model_data: dict  # as written: a run's run.json ``model`` is compared with it
    controller: NmpcConfig
    targets: dict[str, dict]  # name -> machine, flags, blasfeo_target, blasfeo_features
    default_targets: dict[str, str | None]  # machine -> what make builds there
    kind: str = "horizontal"  # the scenario kind exported
    depth_controller: DepthControllerConfig | None = None  # a six-dof export's depth MPC


def _export_record(export: Path) -> _ExportRecord:
    """export.json, checked: a JSON object whose model and controller validate; anything
    else is one line naming the file (an edited or damaged export)."""
    file = export / _RECORD
    text = read_text_file(file, "DIR", "export.json")
    try:
        record = json.loads(text)
    except json.JSONDecodeError as error:
        raise ConfigError(
            "DIR", str(file), f"export.json is not valid JSON (line {error.lineno}: {error.msg})"
        ) from None
    except RecursionError:
        raise ConfigError("DIR", str(file), "export.json nests too deep to be one") from None
    if not isinstance(record, dict):
        raise ConfigError("DIR", str(file), f"export.json holds a {type(record).__name__}")
    for key in ("model", "controller", "targets", "default_targets"):
        if key not in record:
            raise ConfigError("DIR", str(file), f"export.json has no {key!r}")
    targets, defaults = record["targets"], record["default_targets"]
    if not isinstance(targets, dict) or not all(
        isinstance(t, dict) and isinstance(t.get("machine"), str)
        and isinstance(t.get("blasfeo_features"), list)
        and all(isinstance(f, str) for f in t["blasfeo_features"])
        for t in targets.values()
    ):  # fmt: skip
        raise ConfigError("DIR", str(file), "export.json's targets are not the ones it writes")
    if not isinstance(defaults, dict) or not all(
        d is None or d in targets for d in defaults.values()
    ):
        raise ConfigError("DIR", str(file), "export.json's default_targets name no target")
    kind = record.get("kind", "horizontal")  # exports before six-dof ones say none
    if kind not in _KINDS or (kind == _SIX_DOF) != ("depth_controller" in record):
        raise ConfigError("DIR", str(file), f"export.json's kind {kind!r} is not one it writes")
    try:
        model = VehicleParams.model_validate(record["model"])
        controller = NmpcConfig.model_validate(record["controller"], context={SAVED_RUN: True})
        depth = record.get("depth_controller")
        if depth is not None:
            depth = DepthControllerConfig.model_validate(depth, context={SAVED_RUN: True})
    except ValidationError as error:
        raise format_validation_error(error, "export.json", str(file)) from None
    return _ExportRecord(model, record["model"], controller, targets, defaults, kind, depth)


def _check_run(record: _ExportRecord, run: RunFolder) -> None:
    """The run must be the exported controller's, on the same vehicle, without sensor noise."""
    scenario = run.scenario()
    kind = getattr(scenario, "kind", None)
    if kind != record.kind:
        raise ConfigError(
            "RUN_DIR", str(run.path), f"a {kind} run; the export is of a {record.kind} scenario"
        )
    sensing = scenario.sensing
    depth_noise = kind == _SIX_DOF and (sensing.depth_std_m or sensing.depth_rate_std_m_per_s)
    if any(sensing.std) or depth_noise:
        raise ConfigError(
            "RUN_DIR", str(run.path), "the run has sensor noise; log.csv holds the true states"
        )
    controller = scenario.controller
    # Both filled in for the vehicle: a run of the exported type has the defaults of that
    # type (nmpc's trust region) filled in, an export of a preset of another type does not.
    model, exported = record.model, record.controller
    ran = json.loads(exported_config(controller).for_vehicle(model).model_dump_json())
    if (
        controller.type is not ControllerType.NMPC
        or controller.nmpc_mode is not NmpcMode.REAL_TIME
        or controller.control_horizon not in (None, controller.prediction_horizon)
        or ran != json.loads(exported.for_vehicle(model).model_dump_json())
    ):
        raise ConfigError(
            "RUN_DIR", str(run.path),
            "its controller is not the exported one (run the exported scenario with --set "
            "controller.type=nmpc --set controller.control_horizon=null)",
        )  # fmt: skip
    if record.depth_controller is not None and scenario.depth_controller != record.depth_controller:
        raise ConfigError(
            "RUN_DIR", str(run.path),
            "its depth_controller is not the exported one (export the scenario the run was "
            "made of)",
        )  # fmt: skip
    if run.info["model"] != record.model_data:
        raise ConfigError("RUN_DIR", str(run.path), "its vehicle model is not the exported one")


def _chosen_target(export: Path, record: _ExportRecord, target: str | None) -> str:
    """``target``, or what ``make`` builds on this computer; one line where the export has
    no such target or this computer cannot run it."""
    names = sorted(record.targets)
    if target is None:
        target = record.default_targets.get(host_machine())
        if target is None:
            raise ConfigError("DIR", str(export), f"has no target for this computer: {names}")
    if target not in record.targets:
        raise ConfigError("--target", target, f"one of the export's targets {names}")
    described = record.targets[target]
    if described["machine"] == host_machine():
        missing = missing_features(tuple(described["blasfeo_features"]))
        if missing:
            raise ConfigError(
                "--target", target,
                f"its BLASFEO ({described.get('blasfeo_target')}) needs CPU features this "
                f"machine lacks ({', '.join(missing)}): its replay would stop on an illegal "
                "instruction",
            )  # fmt: skip
    return target


def verify_c(
    export: Path | str,
    run_dir: Path | str,
    effectiveness: Sequence[float] | None = None,
    *,
    target: str | None = None,
    instructions: bool = False,
) -> VerifyResult:
    """Build ``export`` for ``target`` (None: this computer's; a temporary copy, with the
    system C compiler or, for another machine, Debian's cross compiler), replay
    ``run_dir``'s log.csv through it (another machine's under QEMU's user-mode emulator) and
    compare its commands with the logged ones. ``effectiveness``: the thrusters'
    effectiveness the run's controller was told from its first sample
    (``Session.effectiveness``), which the replay sets by ``auvmpc_set_effectiveness``;
    None: all healthy. ``instructions``: also count each step's instructions
    (export/instruction_counts.py; valgrind natively, a QEMU plugin emulated).

    The run folder is read by the one reader (:mod:`auvmpc.experiments.run_folder`): a log
    that is not whole (cut mid-row or at a row boundary, edited) is refused in one line
    before anything is built, as is a damaged export.json."""
    export, run_dir = Path(export), Path(run_dir)
    if not own_export(export):
        raise ConfigError("DIR", str(export), "not a folder written by auvmpc export-c")
    record = _export_record(export)
    run = read_run_folder(run_dir, ("scenario", "model"))
    log = run.log()
    _check_run(record, run)
    target = _chosen_target(export, record, target)
    machine = record.targets[target]["machine"]
    emulated = None if machine == host_machine() else machine
    prefix = [] if emulated is None else emulator_command(machine)
    cc = compiler() if emulated is None else shutil.which(f"{machine}-linux-gnu-gcc")
    if cc is None or shutil.which("make") is None:
        raise ConfigError(
            "--target", target,
            "needs make and a C compiler for it on the PATH"
            + ("" if emulated is None else f" ({machine}-linux-gnu-gcc)"),
        )  # fmt: skip
    with tempfile.TemporaryDirectory(prefix="auvmpc-verify-c-") as scratch:
        build = Path(scratch) / "build"
        shutil.copytree(export, build)
        made = subprocess.run(
            ["make", "-s", "-C", str(build), f"TARGET={target}", f"CC={cc}"],
            capture_output=True, text=True,
        )  # fmt: skip
        if made.returncode:
            lines = made.stderr.strip().splitlines()
            first = next((line for line in lines if "error" in line), "make failed")
            raise RunFailed(f"the export did not build: {first}")
        told = [] if effectiveness is None else [",".join(f"{e:.17g}" for e in effectiveness)]
        program = [str(build / "build" / target / "replay"), str(run_dir / "log.csv"),
                   str(build / _DATA), str(log.steps), *told]  # fmt: skip
        replay = subprocess.run([*prefix, *program], capture_output=True, text=True)
        if replay.returncode:
            raise RunFailed(f"replay failed: {replay.stderr.strip()}")
        example = subprocess.run(  # the template for a vehicle's main (example.c) runs too
            [*prefix, str(build / "build" / target / "example")], capture_output=True, text=True
        )
        if example.returncode:
            raise RunFailed(f"the example main failed: {example.stderr.strip()}")
        counted = (
            step_instructions(program, emulated, Path(scratch), _STEP_FUNCTION[record.kind])
            if instructions
            else []
        )
    commands = list(csv.DictReader(replay.stdout.splitlines()))
    stats = dict(zip(*[iter(replay.stderr.split())] * 2, strict=True))
    inputs = log.input_names  # the replay's columns too: the export's AUVMPC_INPUT_NAMES
    c_thrust = np.array([[float(r[name]) for name in inputs] for r in commands])
    py_thrust = np.column_stack([log.column(name) for name in inputs])[: len(commands)]
    difference = np.abs(c_thrust - py_thrust).max(axis=1)
    if len(commands) != log.steps:  # the export's replay data ends before the run
        raise ConfigError(
            "RUN_DIR", str(run_dir),
            f"has {log.steps} steps, the export replays {len(commands)}: export the scenario "
            "with the run's duration",
        )  # fmt: skip
    codes = [int(r["status"]) for r in commands]
    if not all(0 <= code < len(C_STATUS) for code in codes):
        raise RunFailed(f"replay wrote a status auvmpc does not know: {sorted(set(codes))}")
    c_status = [C_STATUS[code] for code in codes]
    depth = _depth_comparison(commands, log) if record.kind == _SIX_DOF else {}
    return VerifyResult(
        target=target,
        steps=len(commands),
        max_difference_n=float(difference.max()),
        worst_step=int(difference.argmax()),
        step_us_median=float(stats["step_us_median"]),
        step_us_max=float(stats["step_us_max"]),
        step_us_max_after_first=float(stats["step_us_max_after_first"]),
        static_bytes=int(stats["static_bytes"]),
        workspace_bytes=int(stats["workspace_bytes"]),
        heap_calls=int(stats["heap_calls_in_steps"]),
        max_iterations=int(stats["max_iterations"]),
        iteration_bound=iteration_bound(record.controller),
        fallbacks=c_status.count(ControlStatus.FALLBACK),
        recoveries=c_status.count(ControlStatus.RECOVERY),
        status_differences=sum(
            mine != logged for mine, logged in zip(c_status, log.status, strict=True)
        ),
        instructions=tuple(counted),
        **depth,
    )


# The function one controller step is: what the instruction counter counts natively.
_STEP_FUNCTION = {"horizontal": "auvmpc_step", _SIX_DOF: "auvmpc_six_dof_step"}


def _depth_comparison(commands: list[dict], log) -> dict:
    """A six-dof replay's depth channel against the run's: VerifyResult's depth fields."""
    codes = [int(r["depth_status"]) for r in commands]
    if not all(0 <= code < len(C_STATUS) for code in codes):
        raise RunFailed(f"replay wrote a depth status auvmpc does not know: {sorted(set(codes))}")
    mine = [C_STATUS[code] for code in codes]
    logged = log.diagnostics["depth_status"]
    return {
        "depth_max_iterations": max(int(r["depth_iterations"]) for r in commands),
        "depth_fallbacks": mine.count(ControlStatus.FALLBACK),
        "depth_recoveries": mine.count(ControlStatus.RECOVERY),
        "depth_status_differences": sum(
            status != str(was) for status, was in zip(mine, logged, strict=True)
        ),
    }


def median_instructions(result: VerifyResult) -> float | None:
    """The median step's instructions, where they were counted."""
    return statistics.median(result.instructions) if result.instructions else None


def own_export(folder: Path) -> bool:
    """Whether ``folder`` is an export-c folder written by auvmpc."""
    from auvmpc.experiments.outputs import own_kind

    return own_kind(folder) is OutputKind.EXPORT_C and (folder / _RECORD).is_file()
