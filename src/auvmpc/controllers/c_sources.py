"""The C controller's sources for one configuration: what ``export-c`` writes and what the
compiled ``nmpc`` builds and runs (controllers/compiled_nmpc.py), so that the two are one.

The C (``solvers/auvmpc_controller.c``, its header, and auvmpc's HPIPM driver
``solvers/hpipm_ocp_step.c``) is fixed; per configuration come CasADi's C code of the
functions the Python controller evaluates (``rti_qp_data.c``: the stage QP, the terminal
cost, the RK4 step, the shell's stabilising feedback; ``ekf_data.c``, offset-free: the EKF's
update and propagation) and the sizes and settings (``auvmpc_config.h``).
"""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

import casadi as ca
import numpy as np

from auvmpc.controllers.base import horizontal_limits
from auvmpc.controllers.nmpc import _COLD_START_ITERATIONS, NmpcConfig
from auvmpc.controllers.recovery import StabilisingFeedback
from auvmpc.controllers.shell import (
    PLAN_FALLBACK_STEPS,
    SPIN_ANGLE_PER_SAMPLE_RAD,
    SPIN_REFERENCE_FACTOR,
)
from auvmpc.controllers.tracking_law import LAW_OUTPUTS
from auvmpc.estimation.ekf import DisturbanceObserver
from auvmpc.models.layout import HORIZONTAL, PLANAR_FORCE, Layout
from auvmpc.ocp.multiple_shooting import (
    _PARKED_OBSTACLE_M,
    ND,
    SLOT,
    SLOT_FIELDS,
    MultipleShootingProgram,
)
from auvmpc.ocp.stage_qp import StageQp
from auvmpc.solvers.hpipm import hpipm_settings, slack_scale

__all__ = ["FIXED_SOURCES", "GENERATED_SOURCE", "generate_c", "write_sources"]

_SOLVERS = Path(__file__).parents[1] / "solvers"
# The C every configuration shares: the controller, its header, the HPIPM driver.
FIXED_SOURCES = tuple(
    _SOLVERS / name for name in ("auvmpc_controller.c", "auvmpc_controller.h", "hpipm_ocp_step.c")
)
GENERATED_SOURCE = "rti_qp_data.c"  # and its header, rti_qp_data.h
_OBSERVER_SOURCE = "ekf_data.c"  # the estimator's functions, with offset_free
_CONFIG_HEADER = "auvmpc_config.h"
_NX = HORIZONTAL.size


def write_sources(
    program: MultipleShootingProgram, qp: StageQp, config: NmpcConfig, folder: Path
) -> list[Path]:
    """The controller's C for ``program`` (built from the resolved ``config``) written into
    ``folder``; returns the C files to compile (the headers are beside them)."""
    # Each built once: its functions are generated and its sizes go into the header.
    law = _recovery_law(program)
    observer = _observer(program.model, config) if config.offset_free else None
    functions = {
        # the stage QP, the RK4 step (the cold-start rollout and the shift), the shell's
        # stabilising feedback
        GENERATED_SOURCE: [qp.stage, qp.terminal, program.step, law],
    }
    if observer is not None:  # the EKF's update and propagation (estimation/ekf.py)
        ekf = observer.filter
        # Its own file: the largest generated code, compiled beside the other in parallel.
        functions[_OBSERVER_SOURCE] = [ekf.update, ekf.propagation]
    for name, members in functions.items():
        generate_c(name, members, folder)
    (folder / _CONFIG_HEADER).write_text(_config_header(program, qp, config, law, observer))
    for source in FIXED_SOURCES:
        shutil.copyfile(source, folder / source.name)
    fixed = [source.name for source in FIXED_SOURCES if source.suffix == ".c"]
    return [folder / name for name in (*functions, *fixed)]


def generate_c(name: str, functions: list[ca.Function], folder: Path) -> None:
    """CasADi's C of ``functions`` as ``folder/name`` with its header, clean under -Wall
    -Wextra -Werror (a six-dof export's depth functions are generated the same way)."""
    generator = ca.CodeGenerator(name, {"with_header": True})
    for function in functions:
        generator.add(function)
    generator.generate(str(folder) + "/")
    generated = folder / name
    generated.write_text(_warning_clean(generated.read_text()))


_DEFINITION = re.compile(
    r"^(?:static |CASADI_SYMBOL_EXPORT )?[\w\s*]+?\b\w+\((?P<params>[^()]*)\) \{$"
)


def _warning_clean(source: str) -> str:
    """CasADi's generated C with every parameter marked used, ``(void) name;`` (the
    functions' shared signature leaves some unused), so that it compiles under -Wall -Wextra
    -Werror. Nothing it computes changes."""
    lines = []
    for line in source.splitlines():
        lines.append(line)
        match = _DEFINITION.match(line)
        if match and match["params"].strip() not in ("", "void"):
            names = [re.findall(r"\w+", p)[-1] for p in match["params"].split(",")]
            lines.append("  " + " ".join(f"(void) {name};" for name in names))
    return "\n".join(lines) + "\n"


def _array(values) -> str:
    return "{" + ", ".join(f"{float(v):.17g}" for v in np.ravel(values)) + "}"


def _names(layout: Layout) -> str:
    """A C initialiser of the layout's names as strings."""
    return "{" + ", ".join(json.dumps(name) for name in layout.names) + "}"


def _config_header(
    program: MultipleShootingProgram,
    qp,
    config: NmpcConfig,
    law: ca.Function,
    observer: DisturbanceObserver | None,
) -> str:
    model, ocp = program.model, program.ocp
    n = program.n_thrusters
    limits = horizontal_limits(model)
    step = program.step
    macros = {
        "AUVMPC_NX": _NX,
        "AUVMPC_HORIZON": program.horizon,
        "AUVMPC_THRUSTERS": n,
        "AUVMPC_OBSTACLE_SLOTS": program.n_slots,
        "AUVMPC_SLOTS_ALLOC": max(program.n_slots, 1),
        "AUVMPC_NZ": qp.states,
        "AUVMPC_NV": qp.inputs,
        "AUVMPC_NG": qp.rows,
        "AUVMPC_SAMPLE_TIME": f"{program.sample_time:.17g}",
        "AUVMPC_ITERATIONS": config.linearisation_iterations,
        "AUVMPC_COLD_ITERATIONS": _COLD_START_ITERATIONS,
        "AUVMPC_KEEP_OUT_EXTRA": f"{ocp.keep_out_extra:.17g}",
        "AUVMPC_SLACK_SCALE": f"{slack_scale(ocp.slack_penalty):.17g}",
        "AUVMPC_PARKED_M": f"{_PARKED_OBSTACLE_M:.17g}",
        "AUVMPC_STEP_SZ_ARG": step.sz_arg(),
        "AUVMPC_STEP_SZ_RES": step.sz_res(),
        "AUVMPC_STEP_SZ_IW": step.sz_iw(),
        "AUVMPC_STEP_SZ_W": step.sz_w(),
        "AUVMPC_THRUST_LOWER": _array(np.broadcast_to(limits.lower, n)),
        "AUVMPC_THRUST_UPPER": _array(np.broadcast_to(limits.upper, n)),
        "AUVMPC_THRUST_RATE": _array(np.broadcast_to(limits.rate, n)),
        "AUVMPC_STAGE_WEIGHT": _array(ocp.stage_weight),
        "AUVMPC_HPIPM_SETTINGS": _array(hpipm_settings(config.qp_iteration_limit)),
        "AUVMPC_OFFSET_FREE": int(config.offset_free),
    }
    macros.update(_layout_macros(program))
    macros.update(_recovery_macros(law))
    if observer is not None:
        macros.update(_observer_macros(observer))
    lines = [
        f"/* Generated by auvmpc for vehicle {model.name}: sizes and settings. */",
        "#ifndef AUVMPC_CONFIG_H",
        "#define AUVMPC_CONFIG_H",
        "",
        *(f"#define {name} {value}" for name, value in macros.items()),
        "",
        "#endif",
        "",
    ]
    return "\n".join(lines)


def _layout_macros(program: MultipleShootingProgram) -> dict[str, object]:
    """Where the C finds each quantity it reads by name (models/layout.py and the program's
    obstacle slot): the state's and inputs' names (replay's columns), the state entries, the
    disturbance's size and each slot field."""
    return {
        "AUVMPC_STATE_NAMES": _names(HORIZONTAL),
        "AUVMPC_INPUT_NAMES": _names(program.model.actuators.layout),
        "AUVMPC_X": HORIZONTAL.index("x"),
        "AUVMPC_Y": HORIZONTAL.index("y"),
        "AUVMPC_HEADING": HORIZONTAL.heading,
        "AUVMPC_YAW_RATE": HORIZONTAL.index("r"),
        "AUVMPC_ND": ND,
        "AUVMPC_SLOT_FIELDS": SLOT_FIELDS,
        **{f"AUVMPC_SLOT_{name.upper()}": SLOT.index(name) for name in SLOT.names},
    }


def _recovery_law(program: MultipleShootingProgram) -> ca.Function:
    """The stabilising feedback the registry gives the Python controller: its tracking law,
    generated to C as ``tracking_law``."""
    feedback = StabilisingFeedback(program.model, program.sample_time, program.ocp.keep_out_extra)
    return feedback.law


def _recovery_macros(law: ca.Function) -> dict:
    """The shell's recovery rules (controllers/shell.py) and the law's work sizes."""
    return {
        "AUVMPC_PLAN_FALLBACK_STEPS": PLAN_FALLBACK_STEPS,
        "AUVMPC_SPIN_ANGLE_PER_SAMPLE": f"{SPIN_ANGLE_PER_SAMPLE_RAD:.17g}",
        "AUVMPC_SPIN_REFERENCE_FACTOR": f"{SPIN_REFERENCE_FACTOR:.17g}",
        "AUVMPC_LAW_THRUST": LAW_OUTPUTS.index("thrust"),
        "AUVMPC_LAW_SZ_ARG": law.sz_arg(),
        "AUVMPC_LAW_SZ_RES": law.sz_res(),
        "AUVMPC_LAW_SZ_IW": law.sz_iw(),
        "AUVMPC_LAW_SZ_W": law.sz_w(),
    }


def _observer(model, config: NmpcConfig) -> DisturbanceObserver:
    """The estimator the Python controller builds: its filter's update and propagation
    functions are generated to C, its prior, bounds and plausible force are the C's
    constants."""
    return DisturbanceObserver(model, config.sample_time, config.observer, config.model_substeps)


def _observer_macros(observer: DisturbanceObserver) -> dict[str, object]:
    """The EKF's prior covariance, eigenvalue bounds and work sizes."""
    ekf = observer.filter
    floor, ceiling = ekf.bounds
    force, moment = observer.plausible
    functions = (ekf.update, ekf.propagation)
    return {
        "AUVMPC_PRIOR_COVARIANCE": _array(np.diag(ekf.prior)),
        "AUVMPC_COVARIANCE_FLOOR": f"{floor:.17g}",
        "AUVMPC_COVARIANCE_CEILING": f"{ceiling:.17g}",
        "AUVMPC_PLAUSIBLE_FORCE": f"{force:.17g}",
        "AUVMPC_PLAUSIBLE_MOMENT": f"{moment:.17g}",
        **{f"AUVMPC_DISTURBANCE_{name}": PLANAR_FORCE.index(name) for name in PLANAR_FORCE.names},
        "AUVMPC_OBSERVER_SZ_ARG": max(f.sz_arg() for f in functions),
        "AUVMPC_OBSERVER_SZ_RES": max(f.sz_res() for f in functions),
        "AUVMPC_OBSERVER_SZ_IW": max(f.sz_iw() for f in functions),
        "AUVMPC_OBSERVER_SZ_W": max(f.sz_w() for f in functions),
    }
