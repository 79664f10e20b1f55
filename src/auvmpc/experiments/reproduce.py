"""Reproduce the paper's section 4: every paper scenario x controller variant, the
inertia-uncertainty sweep, the depth step (4.3) and the 6-DOF validation (4.2: the same
controller on the 6-DOF plant and on the 3-DOF plant, side by side), into one folder of run
folders, tables and figures."""

from __future__ import annotations

import csv
import io
import json
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from auvmpc.controllers.config import CONTROLLER_PRESETS
from auvmpc.experiments.outputs import OutputKind, atomic_write_text, mark_folder, staged_folder
from auvmpc.experiments.run import fill_run_folder, simulate
from auvmpc.models.layout import HORIZONTAL
from auvmpc.scenario import ResolvedScenario, load_scenario, planar_twin
from auvmpc.sim.log import SimLog
from auvmpc.sim.metrics import STEP_METRIC_KEYS

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
        f"plant.scale.Iz_rb={1.0 + 0.25 * level:.6g}",
        f"plant.scale.Iz_added={1.0 + 0.35 * level:.6g}",
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
    atomic_write_text(out_dir / "summary.md", summary_markdown(rows))
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


def summary_markdown(rows: Sequence[dict]) -> str:
    columns = (
        ("scenario", "scenario"), ("controller", "controller"), ("level", "uncertainty"),
        ("rms_position_error_after_transient_m", "RMS err after transient (m)"),
        ("max_position_error_after_transient_m", "max err after transient (m)"),
        ("final_position_error_m", "final err (m)"),
        ("min_obstacle_clearance_m", "min clearance (m)"),
        ("thrust_limit_violations", "F viol."), ("thrust_rate_violations", "dF viol."),
        ("solver_failures", "fails"), ("solve_ms_median", "median ms"), ("solve_ms_p99", "p99 ms"),
        ("settle_r_s", "r settles (s)"), ("settle_u_s", "u settles (s)"),
        ("settle_v_s", "v settles (s)"),
    )  # fmt: skip
    lines = [
        "| " + " | ".join(title for _, title in columns) + " |",
        "|" + "---|" * len(columns),
    ]
    for row in rows:
        lines.append("| " + " | ".join(_cell(row[key]) for key, _ in columns) + " |")
    return "\n".join(lines) + "\n"


def depth_markdown(rows: Sequence[dict]) -> str:
    keys = ("scenario", *STEP_METRIC_KEYS, "max_z_m", "thrust_limit_violations",
            "thrust_rate_violations", "solve_ms_median")  # fmt: skip
    lines = ["| " + " | ".join(keys) + " |", "|" + "---|" * len(keys)]
    lines += ["| " + " | ".join(_cell(row[key]) for key in keys) + " |" for row in rows]
    return "\n".join(lines) + "\n"


SIX_DOF_KEYS = (
    "rms_position_error_after_transient_m", "max_position_error_after_transient_m",
    "rms_heading_error_after_transient_rad", "rms_yaw_rate_error_after_transient_rad_per_s",
    "rms_surge_error_after_transient_m_per_s", "rms_sway_error_after_transient_m_per_s",
    "depth_rms_error_after_transient_m", "max_abs_roll_rad", "max_abs_pitch_rad",
    "thrust_limit_violations", "thrust_rate_violations", "verdict",
)  # fmt: skip


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
    velocities = HORIZONTAL.span("u", "r")  # surge, sway, yaw rate
    error = log.state[steady, velocities] - log.reference[steady, velocities]
    rms = np.sqrt(np.mean(error**2, axis=0))
    return {
        "rms_surge_error_after_transient_m_per_s": float(rms[0]),
        "rms_sway_error_after_transient_m_per_s": float(rms[1]),
        "rms_yaw_rate_error_after_transient_rad_per_s": float(rms[2]),
    }


def six_dof_markdown(rows: Sequence[dict]) -> str:
    keys = ("scenario", "controller", "plant", *SIX_DOF_KEYS)
    lines = ["| " + " | ".join(keys) + " |", "|" + "---|" * len(keys)]
    lines += ["| " + " | ".join(_cell(row[key]) for key in keys) + " |" for row in rows]
    return "\n".join(lines) + "\n"


def _cell(value) -> str:
    if value is None:
        return "-"
    if isinstance(value, float):
        return f"{value:.4g}"
    return str(value)


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
    percent = [f"{25 * level:+.0f}/{35 * level:+.0f}" for level in levels]
    figure = figure_error_vs_parameter(
        levels,
        series,
        xlabel="uncertainty level (-1: Iz_rb -25 %, Iz_added -35 %; +1: +25 %, +35 %)",
        ylabel="max position error, t >= 30 s (m)",
        title="paper-disturbed: error against yaw-inertia uncertainty ("
        + ", ".join(percent[::3])
        + ")",
    )
    figure.axes[0].set_yscale("log")  # the controllers differ by four orders of magnitude
    save_figures({"error_vs_uncertainty": figure}, out_dir)
