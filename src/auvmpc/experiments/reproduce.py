"""Reproduce the paper's section 4: every paper scenario x controller variant, the
inertia-uncertainty sweep, the depth step (4.3) and the 6-DOF validation (4.2: the same
controller on the 6-DOF plant and on the 3-DOF plant, side by side), into one folder of run
folders, tables and figures."""

from __future__ import annotations

import csv
import io
import json
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from auvmpc.controllers.config import CONTROLLER_PRESETS
from auvmpc.experiments.markdown_table import Column, legend, table
from auvmpc.experiments.outputs import OutputKind, atomic_write_text, mark_folder, staged_folder
from auvmpc.experiments.paper_claims import PAPER_CLAIMS, missed_claims
from auvmpc.experiments.run import fill_run_folder, simulate
from auvmpc.models.layout import HORIZONTAL
from auvmpc.scenario import ResolvedScenario, load_scenario, planar_twin
from auvmpc.sim.log import SimLog
from auvmpc.sim.metrics import STEADY_WINDOW_S

__all__ = ["PAPER_VARIANTS", "PAPER_SCENARIOS", "SWEEP_LEVELS", "reproduce", "sweep_scale"]


# Controller labels of CONTROLLER_PRESETS run on every paper scenario.
PAPER_VARIANTS = (
    "mpc", "mpc-nc30", "ltv-mpc", "ltv-mpc-nc30", "ltv-mpc-offset-free", "baseline",
)  # fmt: skip
PAPER_SCENARIOS = ("paper-ideal", "paper-disturbed", "paper-obstacles")
DEPTH_SCENARIOS = ("paper-depth-calm", "paper-depth-waves")  # section 4.3, the tank step
# Section 4.2: each on the 6-DOF plant and, as its planar twin, on the 3-DOF plant, with the
# scenario's own controller (the paper's) and the best horizontal one.
SIX_DOF_SCENARIOS = ("paper-6dof",)
SIX_DOF_VARIANTS = ("mpc", "ltv-mpc-offset-free")
# Uncertainty level -1..1 maps to rigid-body yaw inertia -25..+25 % and added -35..+35 %.
IZ_RB_SPAN = 0.25
IZ_ADDED_SPAN = 0.35
SWEEP_LEVELS = tuple(float(level) for level in np.linspace(-1.0, 1.0, 7))
SWEEP_VARIANTS = ("mpc", "ltv-mpc", "ltv-mpc-nc30", "ltv-mpc-offset-free", "baseline")
SUMMARY_KEYS = (
    "rms_position_error_m", "max_position_error_m", "final_position_error_m",
    "rms_position_error_after_transient_m", "max_position_error_after_transient_m",
    "min_obstacle_clearance_m", "thrust_limit_violations", "thrust_rate_violations",
    "solver_failures", "solve_ms_median", "solve_ms_p99", "solve_ms_max",
)  # fmt: skip


def sweep_scale(level: float) -> tuple[str, ...]:
    """Overrides for one uncertainty level (paper-model.md section 6)."""
    return (
        f"plant.scale.Iz_rb={1.0 + IZ_RB_SPAN * level:.6g}",
        f"plant.scale.Iz_added={1.0 + IZ_ADDED_SPAN * level:.6g}",
    )


@dataclass(frozen=True)
class Job:
    scenario: str
    controller: str  # a CONTROLLER_PRESETS label
    extra: tuple[str, ...] = ()
    level: float | None = None

    @property
    def folder_name(self) -> str:
        suffix = "" if self.level is None else f"--level{self.level:+.2f}"
        return f"{self.scenario}--{self.controller}{suffix}"

    @property
    def overrides(self) -> tuple[str, ...]:
        return (*CONTROLLER_PRESETS[self.controller], *self.extra)


def jobs(include_sweep: bool = True) -> list[Job]:
    planned = [Job(s, c) for s in PAPER_SCENARIOS for c in PAPER_VARIANTS]
    if include_sweep:
        planned += [
            Job("paper-disturbed", label, sweep_scale(level), level)
            for label in SWEEP_VARIANTS
            for level in SWEEP_LEVELS
        ]
    return planned


def reproduce(
    out_dir: Path,
    include_sweep: bool = True,
    figures: bool = True,
    on_run: Callable[[int, int, str], None] | None = None,
    *,
    overwrite: bool = False,
) -> list[dict]:
    """Run everything; write run folders, summary.csv/.md/.json and the sweep figure.

    ``out_dir`` must be new, empty, or an earlier reproduction (then only with
    ``overwrite``); it appears only when everything is written (:mod:`auvmpc.experiments.outputs`).
    """
    with staged_folder(out_dir, OutputKind.REPRODUCE, overwrite=overwrite) as staging:
        return _reproduce_into(staging, include_sweep, figures, on_run)


def _reproduce_into(
    out_dir: Path,
    include_sweep: bool,
    figures: bool,
    on_run: Callable[[int, int, str], None] | None,
) -> list[dict]:
    (out_dir / "runs").mkdir(parents=True, exist_ok=True)
    planned = jobs(include_sweep)
    rows = []
    transients = {}  # scenario -> its transient_s, for the legend
    for index, job in enumerate(planned):
        if on_run is not None:
            on_run(index, len(planned), job.folder_name)
        resolved = load_scenario(job.scenario, job.overrides)
        result = simulate(resolved)
        folder = out_dir / "runs" / job.folder_name
        fill_run_folder(result, folder, figures=figures and job.level is None)
        mark_folder(folder, OutputKind.RUN)
        row = {"scenario": job.scenario, "controller": job.controller, "level": job.level}
        row.update({key: result.metrics[key] for key in SUMMARY_KEYS})
        row.update(velocity_settling(result.log.horizontal()))
        rows.append(row)
        transients.setdefault(job.scenario, result.metrics["transient_s"])
    depth_rows = []
    for name in DEPTH_SCENARIOS:
        if on_run is not None:
            on_run(len(planned), len(planned), name)
        result = simulate(load_scenario(name))
        fill_run_folder(result, out_dir / "runs" / name, figures=figures)
        mark_folder(out_dir / "runs" / name, OutputKind.RUN)
        depth_rows.append({"scenario": name, **result.metrics})
    six_dof_rows = []
    for name in SIX_DOF_SCENARIOS:
        for label in SIX_DOF_VARIANTS:
            if on_run is not None:
                on_run(len(planned), len(planned), f"{name}--{label}")
            six_dof_rows += _six_dof_pair(name, label, out_dir, figures)
    if on_run is not None:
        on_run(len(planned), len(planned), "done")
    atomic_write_text(out_dir / "six_dof.json", json.dumps(six_dof_rows, indent=2))
    atomic_write_text(out_dir / "six_dof.md", six_dof_markdown(six_dof_rows))
    atomic_write_text(out_dir / "depth.json", json.dumps(depth_rows, indent=2))
    atomic_write_text(out_dir / "depth.md", depth_markdown(depth_rows))
    atomic_write_text(out_dir / "summary.json", json.dumps(rows, indent=2))
    atomic_write_text(out_dir / "summary.csv", _csv(rows))
    atomic_write_text(out_dir / "summary.md", summary_markdown(rows, transients))
    if include_sweep and figures:
        _sweep_figure(rows, out_dir)
    return rows


# Paper claim (ideal run): yaw-rate error converges first, sway last. Measured as the time
# after which each velocity error stays inside this band until the first straight ends.
SETTLING_BAND = 0.01  # m/s for u and v, rad/s for r
FIRST_STRAIGHT_END_S = 24.0


def velocity_settling(log: SimLog) -> dict[str, float | None]:
    """``settle_u_s``, ``settle_v_s``, ``settle_r_s``: last exit from the band, first straight."""
    window = log.t < FIRST_STRAIGHT_END_S
    settled = {}
    for name in ("u", "v", "r"):
        index = HORIZONTAL.index(name)
        error = np.abs(log.state[window, index] - log.reference[window, index])
        outside = np.flatnonzero(error > SETTLING_BAND)
        if len(outside) == 0:
            settled[f"settle_{name}_s"] = 0.0
        elif outside[-1] + 1 < len(error):
            settled[f"settle_{name}_s"] = float(log.t[outside[-1] + 1])
        else:
            settled[f"settle_{name}_s"] = None  # never settled on the first straight
    return settled


# The tables' columns, each described once: the markdown tables and their legends come from
# these. Units are in the metric keys too (docs/run-folder.md defines every metric).
_AFTER_TRANSIENT = "after the transient"
_SOLVE = "wall time of one controller call (varies with the machine and its load)"
_CLAIM_COLUMN = Column(
    "paper_claim",
    "the paper's claims for this scenario (below): `met` if the row meets them all, else the"
    " missed ones, each linked to its explanation; empty where the paper claims nothing."
    " Only in this file",
    title="paper's claim",
)
SUMMARY_COLUMNS = (
    Column("scenario", "the paper's scenario (`auvmpc scenarios`)"),
    Column(
        "controller",
        "the controller preset: `mpc` is the paper's (its model frozen at the current state,"
        " 2 moves), `ltv-` linearises along the plan, `-nc30` frees every move of the"
        " horizon, `-offset-free` estimates the current, `baseline` is PID with feedback"
        " linearisation, blind to obstacles"
        " (docs/paper-reproduction.md, `CONTROLLER_PRESETS`)",
    ),
    Column(
        "level",
        f"the plant's yaw-inertia error, -1..+1: rigid-body {-100 * IZ_RB_SPAN:+.0f}.."
        f"{100 * IZ_RB_SPAN:+.0f} %, added {-100 * IZ_ADDED_SPAN:+.0f}.."
        f"{100 * IZ_ADDED_SPAN:+.0f} %"
        " (the controller keeps the nominal); `-`: the scenario as written (paper-disturbed's"
        " plant is level -1's)",
        title="uncertainty",
    ),
    Column(
        "rms_position_error_after_transient_m",
        f"RMS distance from the reference position {_AFTER_TRANSIENT}",
        "m",
        "RMS err after transient",
    ),
    Column(
        "max_position_error_after_transient_m",
        f"largest distance from the reference position {_AFTER_TRANSIENT}",
        "m",
        "max err after transient",
    ),
    Column("final_position_error_m", "distance at the end of the run", "m", "final err"),
    Column(
        "min_obstacle_clearance_m",
        "smallest gap between the vehicle's disc and an obstacle's; negative is contact;"
        " `-`: no obstacles",
        "m",
        "min clearance",
    ),
    Column(
        "thrust_limit_violations",
        "samples whose applied thrust left the hard limits (the paper: none)",
        title="F viol.",
    ),
    Column(
        "thrust_rate_violations",
        "samples whose change of thrust exceeded the rate limit (the paper: none)",
        title="dF viol.",
    ),
    Column(
        "solver_failures",
        "samples whose command was not the optimiser's (fallback or recovery)",
        title="fails",
    ),
    Column("solve_ms_median", f"median {_SOLVE}", "ms", "median"),
    Column("solve_ms_p99", f"99th percentile {_SOLVE}", "ms", "p99"),
    *(
        Column(
            f"settle_{name}_s",
            f"time after which the {what} error stays within {SETTLING_BAND:g} {unit} until the"
            f" first straight ends at {FIRST_STRAIGHT_END_S:g} s; `-`: it does not",
            "s",
            f"{name} settles",
        )
        for name, what, unit in (
            ("r", "yaw-rate", "rad/s"),
            ("u", "surge", "m/s"),
            ("v", "sway", "m/s"),
        )
    ),  # fmt: skip
    _CLAIM_COLUMN,
)
DEPTH_COLUMNS = (
    Column("scenario", "the tank step in calm water, and in 0.1 m waves (docs/depth.md)"),
    Column("rise_time_s", "10 % to 90 % of the step", "s"),
    Column(
        "settling_time_0p05m_s",
        "from the step until the depth stays within 0.05 m of the target; `-`: it does not",
        "s",
    ),
    Column(
        "settling_time_2pct_s",
        "from the step until the depth stays within 2 % of the step; `-`: it does not",
        "s",
    ),
    Column("overshoot_m", "beyond the target, in the step's direction", "m"),
    Column(
        "steady_state_error_mean_abs_m",
        f"mean distance from the depth setpoint over the last {STEADY_WINDOW_S:g} s",
        "m",
    ),
    Column(
        "steady_state_error_max_abs_m",
        f"largest distance from the depth setpoint over the last {STEADY_WINDOW_S:g} s",
        "m",
    ),
    Column("max_z_m", "highest depth reached (z up: below 0 is below the still surface)", "m"),
    Column("thrust_limit_violations", "samples whose applied thrust left the hard limits"),
    Column("thrust_rate_violations", "samples whose change of thrust exceeded the rate limit"),
    Column("solve_ms_median", f"median {_SOLVE}", "ms"),
)
_VELOCITY_ERROR = "RMS of the true minus the reference {} " + _AFTER_TRANSIENT
SIX_DOF_COLUMNS = (
    Column("scenario", "the 6-DOF scenario (docs/six-dof.md)"),
    Column("controller", "the horizontal controller preset (docs/paper-reproduction.md)"),
    Column(
        "plant",
        "`6-DOF`: the scenario's plant; `3-DOF`: its planar twin (the same controller,"
        " reference, current and noise on the 3-DOF plant)",
    ),
    Column(
        "rms_position_error_after_transient_m",
        f"RMS horizontal distance from the reference {_AFTER_TRANSIENT}",
        "m",
    ),
    Column(
        "max_position_error_after_transient_m",
        f"largest horizontal distance from the reference {_AFTER_TRANSIENT}",
        "m",
    ),
    Column(
        "rms_heading_error_after_transient_rad",
        f"RMS heading error {_AFTER_TRANSIENT}",
        "rad",
    ),
    Column(
        "rms_yaw_rate_error_after_transient_rad_per_s",
        _VELOCITY_ERROR.format("yaw rate"),
        "rad/s",
    ),
    Column("rms_surge_error_after_transient_m_per_s", _VELOCITY_ERROR.format("surge"), "m/s"),
    Column("rms_sway_error_after_transient_m_per_s", _VELOCITY_ERROR.format("sway"), "m/s"),
    Column(
        "depth_rms_error_after_transient_m",
        f"RMS depth error {_AFTER_TRANSIENT}; `-` on the 3-DOF plant",
        "m",
    ),
    Column("max_abs_roll_rad", "largest true roll; `-` on the 3-DOF plant", "rad"),
    Column("max_abs_pitch_rad", "largest true pitch; `-` on the 3-DOF plant", "rad"),
    Column(
        "thrust_limit_violations",
        "samples whose applied thrust left the hard limits (every thruster)",
    ),
    Column(
        "thrust_rate_violations",
        "samples whose change of thrust exceeded the rate limit (every thruster)",
    ),
    Column("verdict", "`ok`, `degraded` or `lost` (docs/verdict.md)"),
)
# What a 6-DOF row takes from the run's metrics and the velocity errors.
SIX_DOF_KEYS = tuple(
    column.key
    for column in SIX_DOF_COLUMNS
    if column.key not in ("scenario", "controller", "plant")
)


def summary_markdown(rows: Sequence[dict], transients: Mapping[str, float]) -> str:
    """summary.md: the rows, each judged against the paper's claims for its scenario, the
    legend of the columns and the claims. ``transients``: scenario -> its ``transient_s``."""
    shown = [{**row, _CLAIM_COLUMN.key: _claim_cell(row)} for row in rows]
    after = ", ".join(f"{name} {seconds:g} s" for name, seconds in transients.items())
    claims = [
        f"| {claim.name} | {claim.scenario} | {claim.paper} | {claim.test} |"
        f" [{claim.link}]({claim.link}) |"
        for claim in PAPER_CLAIMS
    ]
    lines = [
        "# The paper's horizontal scenarios (section 4.1)",
        "",
        *table(shown, SUMMARY_COLUMNS),
        "",
        "## Columns",
        "",
        f'"After the transient" is from the scenario\'s `transient_s` on ({after}).'
        " summary.csv and summary.json hold the same rows under the keys below, and the errors"
        " over the whole run and the slowest solve; the run folder"
        " `runs/<scenario>--<controller>[--level<level>]` holds every metric in its run.json"
        " (docs/run-folder.md).",
        "",
        *legend(SUMMARY_COLUMNS, "key"),
        "",
        "## The paper's claims",
        "",
        "Each row is judged against what the paper claims for its scenario. A missed claim"
        " links to the section of docs/paper-reproduction.md that explains it; the links are"
        " relative to the repository's root, not to this folder. The claims about the sweep as"
        " a whole and those this table cannot show are compared on that page only.",
        "",
        "| claim | scenario | the paper | judged here as | why rows miss it |",
        "|---|---|---|---|---|",
        *claims,
    ]
    return "\n".join(lines) + "\n"


def _claim_cell(row: Mapping) -> str:
    missed = missed_claims(row)
    if missed is None:
        return ""
    if not missed:
        return "met"
    return "missed: " + ", ".join(f"[{claim.name}]({claim.link})" for claim in missed)


def depth_markdown(rows: Sequence[dict]) -> str:
    """depth.md: the tank step (section 4.3) and the legend of its columns."""
    lines = [
        "# The tank depth step (section 4.3)",
        "",
        *table(rows, DEPTH_COLUMNS),
        "",
        "## Columns",
        "",
        "Each run folder `runs/<scenario>` holds every metric in its run.json"
        " (docs/run-folder.md).",
        "",
        *legend(DEPTH_COLUMNS),
    ]
    return "\n".join(lines) + "\n"


def six_dof_markdown(rows: Sequence[dict]) -> str:
    """six_dof.md: the same controller on the 6-DOF plant and on the 3-DOF one (section 4.2),
    and the legend of its columns."""
    lines = [
        "# The 6-DOF validation (section 4.2)",
        "",
        *table(rows, SIX_DOF_COLUMNS),
        "",
        "## Columns",
        "",
        '"After the transient" is from the scenario\'s `transient_s` on. Each run folder'
        " `runs/<scenario>--<controller>--<plant>` holds every metric in its run.json"
        " (docs/run-folder.md).",
        "",
        *legend(SIX_DOF_COLUMNS),
    ]
    return "\n".join(lines) + "\n"


def _six_dof_pair(name: str, label: str, out_dir: Path, figures: bool) -> list[dict]:
    """One 6-DOF scenario with one controller on the 6-DOF plant and on its planar twin."""
    resolved = load_scenario(name, CONTROLLER_PRESETS[label])
    twin = ResolvedScenario(planar_twin(resolved.given), resolved.base_dir)
    rows = []
    for plant, run in (("6-DOF", resolved), ("3-DOF", twin)):
        result = simulate(run)
        folder = out_dir / "runs" / f"{name}--{label}--{plant}"
        fill_run_folder(result, folder, figures=figures)
        mark_folder(folder, OutputKind.RUN)
        row = {"scenario": name, "controller": label, "plant": plant}
        row.update(velocity_errors(result.log.horizontal(), run.scenario.transient_s))
        row.update({key: result.metrics.get(key) for key in SIX_DOF_KEYS if key not in row})
        rows.append(row)
    return rows


def velocity_errors(log: SimLog, transient_s: float) -> dict[str, float]:
    """RMS yaw-rate, surge and sway errors after the transient (the paper's Figure 6)."""
    steady = log.t >= transient_s - 1e-9
    velocities = HORIZONTAL.nu  # surge, sway, yaw rate
    error = log.state[steady, velocities] - log.reference[steady, velocities]
    rms = dict(zip(HORIZONTAL.names[velocities], np.sqrt(np.mean(error**2, axis=0)), strict=True))
    return {
        "rms_surge_error_after_transient_m_per_s": float(rms["u"]),
        "rms_sway_error_after_transient_m_per_s": float(rms["v"]),
        "rms_yaw_rate_error_after_transient_rad_per_s": float(rms["r"]),
    }


def _csv(rows: Sequence[dict]) -> str:
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=list(rows[0]), lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    return buffer.getvalue()


def _sweep_figure(rows: Sequence[dict], out_dir: Path) -> None:
    from auvmpc.plots import figure_error_vs_parameter, save_figures

    sweep = [row for row in rows if row["level"] is not None]
    levels = sorted({row["level"] for row in sweep})
    series = {}
    for label in SWEEP_VARIANTS:
        by_level = {row["level"]: row for row in sweep if row["controller"] == label}
        series[label] = [
            by_level[level]["max_position_error_after_transient_m"] for level in levels
        ]
    rb, added = 100 * IZ_RB_SPAN, 100 * IZ_ADDED_SPAN  # %
    percent = [f"{rb * level:+.0f}/{added * level:+.0f}" for level in levels]
    figure = figure_error_vs_parameter(
        levels,
        series,
        xlabel=f"uncertainty level (-1: Iz_rb {-rb:.0f} %, Iz_added {-added:.0f} %;"
        f" +1: {rb:+.0f} %, {added:+.0f} %)",
        ylabel="max position error, t >= 30 s (m)",
        title="paper-disturbed: error against yaw-inertia uncertainty ("
        + ", ".join(percent[::3])
        + ")",
    )
    figure.axes[0].set_yscale("log")  # the controllers differ by four orders of magnitude
    save_figures({"error_vs_uncertainty": figure}, out_dir)
