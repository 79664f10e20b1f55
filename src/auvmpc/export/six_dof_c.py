"""A six-dof export's depth channel and thrust mapping (``auvmpc export-c`` of a ``kind:
six-dof`` scenario; docs/onboard.md).

A 6-DOF scenario runs two controllers on one vehicle (controllers/channels.py): the horizontal
real-time nmpc, exported as for a horizontal scenario (controllers/c_sources.py), and the
depth MPC (controllers/depth_mpc.py), whose demands a thrust mapping puts on every thruster.
This module writes the rest, generated from the Python depth MPC the scenario builds, as the
horizontal part is from its program: CasADi's C of the functions that depth MPC evaluates
(its model rollout with the Jacobians, its filter's update and propagation: ``depth_data.c``),
the sizes, weights, limits, the condensed QP's constant blocks and soft rows it holds
(``auvmpc_depth_config.h``) and the mapping's numbers (``auvmpc_six_dof_config.h``); the fixed
C beside them (``export/c/``: the depth MPC with its shell, ``auvmpc_depth.c``, and the entry
point, ``auvmpc_six_dof.c``), the replay and the example main for the pair; and DAQP, the QP
solver the Python depth MPC runs, as casadi's shared library for each target with its header
and licence (the same package the HPIPM comes from).

The depth MPC's QP is solved by DAQP, as in Python, not by HPIPM: an active-set solution is
exact to round-off once the active set is found, where an interior point stops at its
tolerance, so only the same kind of solver reproduces the Python commands to 1e-6 N
(measured: 5e-12 N between casadi's DAQP and the Python package's on a 150 s helix's QPs).
The Python depth MPC is unchanged, and so is every preset's run.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import casadi as ca
import numpy as np

from auvmpc.controllers.c_sources import _array, _names, generate_c
from auvmpc.controllers.channels import CLIP_TOLERANCE_N, ReferenceWithDepth, ThrustMapping
from auvmpc.controllers.depth_mpc import DepthControllerConfig, DepthMpc
from auvmpc.controllers.registry import build_controller, whole_vehicle
from auvmpc.controllers.shell import _SATURATION_N, PLAN_FALLBACK_STEPS, SLACK_ACTIVE
from auvmpc.errors import ConfigError
from auvmpc.experiments.kinds import padded
from auvmpc.export.c_targets import Target
from auvmpc.export.replay_data import replay_data
from auvmpc.models.layout import DEPTH
from auvmpc.models.six_dof import HORIZONTAL_INDEX, SIX_DOF, SIX_DOF_MEASUREMENT
from auvmpc.ocp.tracking import SLACK_QUADRATIC_WEIGHT
from auvmpc.solvers import condensed_qp
from auvmpc.solvers.dense_qp import _DAQP_INFINITY, QpSolverName

__all__ = [
    "DEPTH_STATIC_MEMORY_LIMIT_BYTES",
    "check_six_dof",
    "daqp_libraries",
    "depth_static_bytes",
    "preview_steps",
    "six_dof_replay_data",
    "write_six_dof_sources",
]

# The depth MPC's own static arrays may take at most this much (bytes): its condensed QP grows
# as (moves + soft rows)^2, 334 kB at 4 vertical thrusters and 20 samples (bluerov2-helix), the
# limit at 36 samples (53 at 2 vertical thrusters). DAQP's workspace, allocated once at init,
# comes on top.
DEPTH_STATIC_MEMORY_LIMIT_BYTES = 1024 * 1024

_TEMPLATES = Path(__file__).with_name("c")
# The fixed C of the pair, copied as they are; the replay and example main under the names the
# Makefile builds.
_FIXED = ("auvmpc_depth.c", "auvmpc_depth.h", "auvmpc_covariance.c", "auvmpc_covariance.h",
          "auvmpc_six_dof.c", "auvmpc_six_dof.h")  # fmt: skip
_MAINS = {"replay_six_dof.c": "replay.c", "example_six_dof.c": "example.c"}
_GENERATED = "depth_data.c"
_DEPTH_CONFIG, _SIX_DOF_CONFIG = "auvmpc_depth_config.h", "auvmpc_six_dof_config.h"
_DAQP, _DAQP_LICENCE = "libdaqp.so", "DAQP-LICENSE.txt"
_NX, _NA = DEPTH.size, DEPTH.size + 1  # [z, w]; the filter's [z, w, d_z]
_REPLAY_HEADER = "auvmpc-replay-six-dof 1"


def check_six_dof(resolved) -> DepthControllerConfig:
    """The depth controller a six-dof scenario's export carries, or one line saying why it
    cannot (the horizontal controller is checked as in a horizontal scenario)."""
    scenario = resolved.scenario
    if whole_vehicle(scenario.controller):
        raise ConfigError(
            "controller.type", str(scenario.controller.type),
            "export-c exports the horizontal nmpc and the depth MPC of a six-dof scenario, "
            "not a controller of the whole vehicle",
        )  # fmt: skip
    depth = scenario.depth_controller
    if depth.qp_solver is not QpSolverName.DAQP:
        raise ConfigError(
            "depth_controller.qp_solver", str(depth.qp_solver),
            "export-c exports the depth MPC with DAQP (the default)",
        )  # fmt: skip
    if depth.qp_iteration_limit is not None:
        raise ConfigError(
            "depth_controller.qp_iteration_limit", depth.qp_iteration_limit,
            "export-c's DAQP (casadi's build) takes other iterations than the Python package's "
            "to the same solution, so a limit would fail at other samples; leave it unset",
        )  # fmt: skip
    if depth.solver_time_limit_ms is not None:
        raise ConfigError(
            "depth_controller.solver_time_limit_ms", depth.solver_time_limit_ms,
            "export-c has no solve-time limit (the caller owns the deadline); leave it unset",
        )  # fmt: skip
    model = resolved.model
    vertical = model.six_dof_actuators.size - model.n_thrusters
    if model.heave.thruster_count != vertical:
        raise ConfigError(
            "vehicle.heave.thruster_count", model.heave.thruster_count,
            f"export-c maps the depth MPC's thrusts one to one onto the {vertical} vertical "
            "six_dof thrusters",
        )  # fmt: skip
    moves = depth.prediction_horizon if depth.control_horizon is None else depth.control_horizon
    needed = depth_static_bytes(depth.prediction_horizon, moves, vertical)
    if needed > DEPTH_STATIC_MEMORY_LIMIT_BYTES:
        raise ConfigError(
            "depth_controller.prediction_horizon", depth.prediction_horizon,
            f"needs {needed} bytes of static memory for the depth MPC, over export-c's limit "
            f"of {DEPTH_STATIC_MEMORY_LIMIT_BYTES}",
        )  # fmt: skip
    return depth


def depth_static_bytes(horizon: int, moves: int, thrusters: int) -> int:
    """The depth MPC's arrays (auvmpc_depth.c), bytes: its condensed QP (the Hessian and the
    rows, (moves + soft rows)^2 each), the sensitivities, the stage data and the plans; the
    generated functions' work arrays and the filter come on top (on bluerov2-helix 325 504 B
    estimated, 333 808 B by sizeof)."""
    N, n, nm = horizon, thrusters, moves * thrusters
    nz = rows = nm + 2 * N  # the moves and a slack per soft row (surface, bottom)
    qp = nz * nz + rows * nz + 4 * (nz + rows) + nz  # H, rows, bounds, multipliers, sense, x
    condensed = (2 * N + 1) * _NX * (nm + 1) + 2 * N * (nm + 1)  # forcing, stacked, weighted
    stages = N * (12 + 4 * n)  # the rollout, its Jacobians, A, B, c
    plans = 2 * N * n + nm + 3 * _NX * (N + 1)  # plan, input, moves, states, reference
    return 8 * (qp + condensed + stages + plans)


def depth_controller(resolved) -> DepthMpc:
    """The scenario's depth MPC as the Python run builds it (experiments/kinds.py)."""
    scenario = resolved.scenario
    return build_controller(
        scenario.depth_controller, resolved.model, water_depth_m=scenario.water_depth_m
    )


def daqp_libraries(
    targets: list[Target], wheel_libraries: Path, aarch64: Path | str | None
) -> dict[str, Path]:
    """The DAQP shared library of each target's instruction set: the installed casadi wheel's
    for this computer's, the one ``make hpipm-aarch64`` fetched beside the aarch64 HPIPM for
    aarch64 (the same casadi version, checked there); one line where it is missing."""
    by_machine = {targets[0].machine: wheel_libraries / _DAQP}
    if aarch64 is not None:
        by_machine["aarch64"] = Path(aarch64).expanduser().resolve() / _DAQP
    for machine, library in by_machine.items():
        if not library.is_file():
            field = "--aarch64" if machine == "aarch64" else "casadi"
            raise ConfigError(
                field, str(library.parent),
                f"no {_DAQP} there, which a six-dof export's depth MPC needs"
                + (" (fetched before it was needed: make hpipm-aarch64 into an empty folder)"
                   if machine == "aarch64" else ""),
            )  # fmt: skip
    return {t.name: by_machine[t.machine] for t in targets}


def write_six_dof_sources(
    resolved, folder: Path, daqp: dict[str, Path], include: Path, horizontal_horizon: int
) -> DepthMpc:
    """The depth channel, the mapping, the pair's replay and example main, and DAQP for
    each target (``daqp``: by target name, from :func:`daqp_libraries`) into ``folder``; the
    horizontal part is written beside them as for a horizontal scenario. Returns the depth MPC
    it was generated from."""
    depth = depth_controller(resolved)
    rollout, update, propagation = _depth_functions(depth)
    generate_c(_GENERATED, [rollout, update, propagation], folder)
    vehicle = resolved.model.name
    macros = _depth_macros(depth, [rollout, update, propagation])
    (folder / _DEPTH_CONFIG).write_text(_header(macros, "AUVMPC_DEPTH_CONFIG_H", vehicle))
    macros = _six_dof_macros(resolved, depth, horizontal_horizon)
    (folder / _SIX_DOF_CONFIG).write_text(_header(macros, "AUVMPC_SIX_DOF_CONFIG_H", vehicle))
    for name in _FIXED:
        shutil.copyfile(_TEMPLATES / name, folder / name)
    for source, name in _MAINS.items():
        shutil.copyfile(_TEMPLATES / source, folder / name)
    for target, library in daqp.items():
        shutil.copyfile(library, folder / "lib" / target / _DAQP)
    headers = folder / "include" / "daqp"
    headers.mkdir(parents=True)
    for header in (include / "daqp").glob("*.h"):
        shutil.copyfile(header, headers / header.name)
    shutil.copyfile(include / "licenses" / "daqp-external" / "LICENSE",
                    folder / "licenses" / _DAQP_LICENCE)  # fmt: skip
    return depth


def preview_steps(resolved, horizontal_horizon: int) -> int:
    """The reference rows the pair reads beyond the first (the longer horizon)."""
    return max(horizontal_horizon, resolved.scenario.depth_controller.prediction_horizon)


def six_dof_replay_data(resolved, horizontal_horizon: int, sample_time: float) -> str:
    """The 3-D reference preview ([x, y, psi, u, v, r, z, z_rate], NED) and the obstacles at
    every sample, as the closed loop computes them (sim/session.py), and every thruster's
    initial thrust."""
    scenario, model = resolved.scenario, resolved.model
    steps = int(round(scenario.duration / sample_time))
    preview = preview_steps(resolved, horizontal_horizon)
    n = model.six_dof_actuators.size
    header = f"{_REPLAY_HEADER} steps {steps} preview {preview} thrusters {n}"
    return replay_data(
        header, padded(scenario.initial_thrust, n), ReferenceWithDepth(resolved.reference),
        preview, steps, sample_time, scenario.obstacles,
    )  # fmt: skip


def _depth_functions(depth: DepthMpc) -> tuple[ca.Function, ...]:
    """The functions the Python depth MPC evaluates, under the names the C calls: its model
    rollout (the thrust plan, the force and the effectiveness as the Python passes them, the
    Jacobians dense) and its filter's update and propagation (renamed: the horizontal
    estimator's have the same names)."""
    ny, nu = depth.horizon, depth.heave.thruster_count
    state, plan = ca.MX.sym("x", _NX), ca.MX.sym("F", nu, ny)
    force, effectiveness = ca.MX.sym("d"), ca.MX.sym("e", nu)
    outputs = depth.rollout(state, plan, ca.repmat(force, 1, ny), ca.repmat(effectiveness, 1, ny))
    rollout = ca.Function(
        "depth_rollout", [state, plan, force, effectiveness], [ca.densify(o) for o in outputs],
        ["x", "F", "d", "e"], ["states", "jac_x", "jac_u"],
    )  # fmt: skip
    return (
        rollout,
        _renamed(depth.filter.update, "depth_ekf_update"),
        _renamed(depth.filter.propagation, "depth_ekf_propagation"),
    )


def _renamed(function: ca.Function, name: str) -> ca.Function:
    """An SX function under another name: the same expression, its C symbols its own."""
    inputs = [
        ca.SX.sym(function.name_in(i), function.sparsity_in(i)) for i in range(function.n_in())
    ]
    return ca.Function(name, inputs, function.call(inputs), function.name_in(), function.name_out())


def _matrix(values) -> str:
    """A C initialiser of a 2-D array, every row braced (-Wmissing-braces)."""
    return "{" + ", ".join(_array(row) for row in np.atleast_2d(values)) + "}"


def _header(macros: dict[str, object], guard: str, vehicle: str) -> str:
    """A generated header of ``macros`` (as controllers/c_sources.py writes auvmpc_config.h)."""
    lines = [
        f"/* Generated by auvmpc for vehicle {vehicle}: sizes and settings. */",
        f"#ifndef {guard}",
        f"#define {guard}",
        "",
        *(f"#define {name} {value}" for name, value in macros.items()),
        "",
        "#endif",
        "",
    ]
    return "\n".join(lines)


def _depth_macros(depth: DepthMpc, functions: list[ca.Function]) -> dict[str, object]:
    """The depth MPC's sizes and numbers, as the Python one holds them."""
    qp, ocp, heave = depth.qp, depth.ocp, depth.heave
    nu = heave.thruster_count
    limits = depth.limits
    soft = depth.soft_rows(None, None, None)  # constant: the surface and the bottom
    floor, ceiling = depth.filter.bounds
    return {
        "AUVMPC_DEPTH_NX": _NX,
        "AUVMPC_DEPTH_NA": _NA,
        "AUVMPC_DEPTH_Z": DEPTH.index("z"),
        "AUVMPC_DEPTH_W": DEPTH.index("w"),
        "AUVMPC_DEPTH_HORIZON": depth.horizon,
        "AUVMPC_DEPTH_THRUSTERS": nu,
        "AUVMPC_DEPTH_MOVE_COUNT": len(qp.move_steps),
        "AUVMPC_DEPTH_MOVES": qp.n_moves,
        "AUVMPC_DEPTH_MOVE_STEPS": "{" + ", ".join(str(int(s)) for s in qp.move_steps) + "}",
        "AUVMPC_DEPTH_PASSES": depth.linearisation_iterations,
        "AUVMPC_DEPTH_SAMPLE_TIME": f"{depth.sample_time:.17g}",
        "AUVMPC_DEPTH_THRUST_LOWER": _array(np.broadcast_to(limits.lower, nu)),
        "AUVMPC_DEPTH_THRUST_UPPER": _array(np.broadcast_to(limits.upper, nu)),
        "AUVMPC_DEPTH_THRUST_RATE": _array(np.broadcast_to(limits.rate, nu)),
        "AUVMPC_DEPTH_INPUT_LOWER": _array(ocp.input_lower),
        "AUVMPC_DEPTH_INPUT_UPPER": _array(ocp.input_upper),
        "AUVMPC_DEPTH_MAX_MOVE": _array(qp.max_move),
        "AUVMPC_DEPTH_SQRT_WEIGHTS": _matrix(qp.sqrt_state_weights),
        # the condensed QP's input blocks (CondensedQp: R on the thrust or its moves)
        "AUVMPC_DEPTH_INPUT_HESSIAN": _matrix(qp._input_hessian),
        "AUVMPC_DEPTH_INPUT_GRADIENT_MAP": _matrix(qp._input_gradient_map),
        "AUVMPC_DEPTH_HESSIAN_REGULARISATION": f"{condensed_qp._HESSIAN_REGULARISATION:.17g}",
        "AUVMPC_DEPTH_SLACK_HESSIAN": f"{2.0 * SLACK_QUADRATIC_WEIGHT:.17g}",
        "AUVMPC_DEPTH_SLACK_PENALTY": f"{qp.slack_penalty:.17g}",
        "AUVMPC_DEPTH_SOFT_ROWS": len(soft),
        "AUVMPC_DEPTH_SOFT_STEPS": "{" + ", ".join(str(int(s)) for s in soft.steps) + "}",
        "AUVMPC_DEPTH_SOFT_COEFFICIENTS": _matrix(soft.coefficients),
        "AUVMPC_DEPTH_SOFT_LOWER": _array(soft.lower),
        # DAQP as the Python runs it (DaqpSolver): its tolerance, limit and infinity
        "AUVMPC_DEPTH_QP_INFINITY": f"{_DAQP_INFINITY:.17g}",
        "AUVMPC_DEPTH_PRIMAL_TOL": f"{qp.solver.tolerance:.17g}",
        "AUVMPC_DEPTH_ITERATION_LIMIT": qp.solver.iteration_limit,
        # the filter (AugmentedEkf)
        "AUVMPC_DEPTH_PRIOR_COVARIANCE": _matrix(depth.filter.prior),
        "AUVMPC_DEPTH_COVARIANCE_FLOOR": f"{floor:.17g}",
        "AUVMPC_DEPTH_COVARIANCE_CEILING": f"{ceiling:.17g}",
        # the shell and its depth feedback (ShelledController, DepthFeedback)
        "AUVMPC_DEPTH_FALLBACK_STEPS": PLAN_FALLBACK_STEPS,
        "AUVMPC_DEPTH_SLACK_ACTIVE": f"{SLACK_ACTIVE:.17g}",
        "AUVMPC_DEPTH_SATURATION_N": f"{_SATURATION_N:.17g}",
        "AUVMPC_DEPTH_FEEDBACK_BANDWIDTH": f"{depth.recovery._bandwidth:.17g}",
        "AUVMPC_DEPTH_MASS": f"{heave.m_heave:.17g}",
        "AUVMPC_DEPTH_ZW": f"{heave.Zw:.17g}",
        "AUVMPC_DEPTH_ZWW": f"{heave.Zww:.17g}",
        "AUVMPC_DEPTH_NET_BUOYANCY": f"{heave.net_buoyancy_N:.17g}",
        "AUVMPC_DEPTH_SZ_ARG": max(f.sz_arg() for f in functions),
        "AUVMPC_DEPTH_SZ_RES": max(f.sz_res() for f in functions),
        "AUVMPC_DEPTH_SZ_IW": max(f.sz_iw() for f in functions),
        "AUVMPC_DEPTH_SZ_W": max(f.sz_w() for f in functions),
    }


def _six_dof_macros(resolved, depth: DepthMpc, horizontal_horizon: int) -> dict[str, object]:
    """The thrust mapping's numbers (ThrustMapping, as the Python pair builds it) and where
    each entry of the measurement, the reference and the logged state sits."""
    model = resolved.model
    mapping = ThrustMapping(model, depth.sample_time)
    total = mapping.n_total
    return {
        "AUVMPC_SIX_DOF_THRUSTERS": total,
        "AUVMPC_SIX_DOF_NM": SIX_DOF_MEASUREMENT.size,
        "AUVMPC_SIX_DOF_PREVIEW": preview_steps(resolved, horizontal_horizon),
        "AUVMPC_SIX_DOF_DEPTH_PREVIEW": int(resolved.scenario.depth_controller.preview),
        "AUVMPC_SIX_DOF_DEPTH": SIX_DOF_MEASUREMENT.index("z"),
        "AUVMPC_SIX_DOF_DEPTH_RATE": SIX_DOF_MEASUREMENT.index("z_rate"),
        "AUVMPC_SIX_DOF_HEAVE_ROW": _array(mapping._heave_row),
        "AUVMPC_SIX_DOF_HEAVE_SPLIT": _array(mapping.heave_split),
        "AUVMPC_SIX_DOF_THRUST_LOWER": _array(np.broadcast_to(mapping.lower, total)),
        "AUVMPC_SIX_DOF_THRUST_UPPER": _array(np.broadcast_to(mapping.upper, total)),
        "AUVMPC_SIX_DOF_THRUST_RATE": _array(np.broadcast_to(mapping.rate_limit, total)),
        "AUVMPC_SIX_DOF_CLIP_TOLERANCE": f"{CLIP_TOLERANCE_N:.17g}",
        "AUVMPC_SIX_DOF_INPUT_NAMES": _names(model.six_dof_actuators.layout),
        "AUVMPC_SIX_DOF_MEASUREMENT_NAMES": _names(SIX_DOF_MEASUREMENT),
        # the replay's: the logged 6-DOF state, by name
        "AUVMPC_SIX_DOF_STATES": SIX_DOF.size,
        "AUVMPC_SIX_DOF_STATE_NAMES": _names(SIX_DOF),
        "AUVMPC_SIX_DOF_HORIZONTAL_STATES": "{" + ", ".join(map(str, HORIZONTAL_INDEX)) + "}",
        **{
            f"AUVMPC_SIX_DOF_STATE_{name.upper()}": SIX_DOF.index(name)
            for name in ("z", "phi", "theta", "u", "v", "w")
        },  # fmt: skip
    }
