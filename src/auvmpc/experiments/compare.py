"""Several run folders side by side: overlay figures and a metrics table (``auvmpc compare``).

The way the paper compares conditions: one trajectory plot with every run over the
reference, the errors against time, each thruster's force, and a table of the
headline metrics. Runs are named by their controller (and vehicle or scenario where
those differ between the runs), or by explicit labels.
"""

from __future__ import annotations

import json
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from auvmpc.errors import ConfigError
from auvmpc.experiments.outputs import MARKER, OutputKind, check_output_folder, staged_folder
from auvmpc.models.vehicle import VehicleParams
from auvmpc.scenario import Scenario
from auvmpc.sim.log import SimLog

__all__ = [
    "COMPARED_METRICS",
    "ComparedRun",
    "compare_runs",
    "load_compared_runs",
    "metrics_markdown",
]

RECORD_FILE = "comparison.json"  # the runs compared

# A metric no compared run has (a 6-DOF run's path and depth errors in a planar comparison; a
# torpedo's thrust in N, which it has not) leaves no column.
COMPARED_METRICS = (
    "rms_position_error_m",
    "max_position_error_m",
    "rms_position_error_after_transient_m",
    "cross_track_rms_after_transient_m",
    "depth_rms_error_after_transient_m",
    "rms_heading_error_rad",
    "max_abs_thrust_N",
    "thrust_effort_N2s",
    "actuator_limit_violations",
    "actuator_rate_violations",
    "min_obstacle_clearance_m",
    "solve_ms_median",
    "solve_ms_p99",
    "solver_failures",
    "verdict",
)


@dataclass(frozen=True)
class ComparedRun:
    """One run folder as compared: its label, scenario, controller model and log."""

    label: str
    folder: Path
    scenario: Scenario
    model: VehicleParams
    log: SimLog
    metrics: dict[str, Any]


def load_compared_runs(
    run_dirs: Sequence[Path], labels: Sequence[str] | None = None
) -> list[ComparedRun]:
    """Read horizontal-plane run folders and name each run.

    Raises
    ------
    ConfigError
        Fewer than two folders, a folder that is not a horizontal run, or a label count
        that does not match.
    """
    from auvmpc.experiments.run import read_planar_run

    if len(run_dirs) < 2:
        raise ConfigError("RUN_DIR", [str(d) for d in run_dirs], "compare needs two or more runs")
    if labels and len(labels) != len(run_dirs):
        raise ConfigError("--label", list(labels), f"give one per run ({len(run_dirs)})")
    loaded = []
    for folder in map(Path, run_dirs):
        info, scenario, model, log = read_planar_run(folder, "compare")
        loaded.append(ComparedRun("", folder, scenario, model, log, info.get("metrics", {})))
    names = list(labels) if labels else _labels(loaded)
    return [replace(run, label=name) for run, name in zip(loaded, names, strict=True)]


def _labels(runs: Sequence[ComparedRun]) -> list[str]:
    """Controller labels, plus the vehicle and the scenario where those differ between runs,
    plus the folder name where two labels are still the same."""
    from auvmpc.plots import controller_label

    names = [controller_label(run.scenario.controller) for run in runs]
    if len({run.model.name for run in runs}) > 1:
        names = [f"{name}, {run.model.name}" for name, run in zip(names, runs, strict=True)]
    if len({run.scenario.name for run in runs}) > 1:
        names = [f"{name}, {run.scenario.name}" for name, run in zip(names, runs, strict=True)]
    counts = Counter(names)
    return [
        f"{name} [{run.folder.name}]" if counts[name] > 1 else name
        for name, run in zip(names, runs, strict=True)
    ]


def compare_runs(
    runs: Sequence[ComparedRun], out: Path, fmt: str = "png", dpi: int = 120
) -> list[Path]:
    """Write the overlay figures, ``metrics.md``, ``metrics.csv`` and ``comparison.json``.

    ``out`` is new, empty, or an earlier comparison of auvmpc's, replaced (without
    ``--overwrite``) only if it holds nothing but what auvmpc wrote there
    (:mod:`auvmpc.experiments.outputs`).
    """
    from auvmpc.plots import (
        figure_compare_errors,
        figure_compare_thrusts,
        figure_compare_trajectory,
        save_figures,
    )

    check_output_folder(out, OutputKind.COMPARE, overwrite=True)  # before drawing
    pairs = [(run.label, run.log) for run in runs]
    first = runs[0]
    scenarios = ", ".join(sorted({run.scenario.name for run in runs}))
    vehicles = ", ".join(sorted({run.model.name for run in runs}))
    title = f"{scenarios}, vehicle {vehicles}: {len(runs)} runs compared"
    figures = {
        "trajectory": figure_compare_trajectory(pairs, first.scenario.obstacles, title),
        "errors": figure_compare_errors(pairs, title),
        "thrusts": figure_compare_thrusts(pairs, first.model, title),
    }
    with staged_folder(out, OutputKind.COMPARE, overwrite=True) as staging:
        save_figures(figures, staging, dpi=dpi, fmt=fmt)
        (staging / "metrics.md").write_text(metrics_markdown(runs))
        _metrics_frame(runs).to_csv(staging / "metrics.csv", index=False)
        record = {"runs": [{"label": r.label, "folder": str(r.folder)} for r in runs]}
        (staging / RECORD_FILE).write_text(json.dumps(record, indent=2))
    return sorted(p for p in Path(out).iterdir() if p.name != MARKER)


def _metrics_frame(runs: Sequence[ComparedRun]):
    import pandas as pd

    rows = [
        {"run": run.label, **{key: run.metrics.get(key) for key in COMPARED_METRICS}}
        for run in runs
    ]
    frame = pd.DataFrame(rows)
    present = [key for key in COMPARED_METRICS if frame[key].notna().any()]
    return frame[["run", *present]]


def metrics_markdown(runs: Sequence[ComparedRun]) -> str:
    """The headline metrics of each run as a Markdown table (metric names from run.json)."""
    frame = _metrics_frame(runs)
    columns = list(frame.columns)
    lines = ["| " + " | ".join(columns) + " |", "|---" * len(columns) + "|"]
    for _, row in frame.iterrows():
        lines.append("| " + " | ".join(_cell(row[c]) for c in columns) + " |")
    return "\n".join(lines) + "\n"


def _cell(value: Any) -> str:
    if value is None or (isinstance(value, float) and value != value):
        return "-"
    if isinstance(value, float):
        return f"{value:.4g}"
    return str(value)
