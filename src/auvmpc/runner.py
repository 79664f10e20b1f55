"""From a resolved scenario to a run folder: build, simulate, measure, write atomically."""

from __future__ import annotations

import json
import os
import shutil
import tempfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from threadpoolctl import threadpool_limits

from auvmpc import __version__
from auvmpc.controllers.base import Controller
from auvmpc.depth import DepthLog, DepthScenario, depth_metrics, simulate_depth
from auvmpc.disturbances import SensorNoise, WorldDisturbance
from auvmpc.log import SimLog
from auvmpc.metrics import compute_metrics
from auvmpc.references import make_reference
from auvmpc.scenario import (
    ControllerType,
    ResolvedDepthScenario,
    ResolvedScenario,
    Scenario,
    scenario_to_dict,
)
from auvmpc.sim import closed_loop
from auvmpc.vehicle import VehicleParams

__all__ = [
    "DepthRunResult",
    "RunResult",
    "atomic_write_text",
    "make_controller",
    "read_run",
    "redraw",
    "simulate",
    "write_run",
]


@dataclass
class _Finished:
    """What both kinds of finished run share: the log, the metrics, and how to file them."""

    resolved: ResolvedScenario | ResolvedDepthScenario
    log: SimLog | DepthLog
    metrics: dict[str, Any]

    @property
    def scenario(self):
        return self.resolved.scenario

    def simulated_plant(self) -> VehicleParams:
        raise NotImplementedError

    def run_json(self) -> dict[str, Any]:
        return {
            "version": __version__,
            "scenario": scenario_to_dict(self.scenario),
            "plant": self.simulated_plant().model_dump(mode="json"),
            "model": self.resolved.model.model_dump(mode="json"),
            "metrics": self.metrics,
        }

    def csv_text(self) -> str:
        return self.log.to_csv_text()


@dataclass
class RunResult(_Finished):
    """A finished closed-loop run."""

    resolved: ResolvedScenario
    log: SimLog

    def simulated_plant(self) -> VehicleParams:
        return self.resolved.plant

    def draw(self, folder: Path, fmt: str = "png", dpi: int = 120) -> None:
        draw_figures(self.log, self.scenario, self.resolved.model, folder, fmt, dpi)


@dataclass
class DepthRunResult(_Finished):
    """A finished depth experiment."""

    resolved: ResolvedDepthScenario
    log: DepthLog

    def simulated_plant(self) -> VehicleParams:
        return self.resolved.model.model_copy(update={"heave": self.resolved.heave_plant})

    def draw(self, folder: Path, fmt: str = "png", dpi: int = 120) -> None:
        draw_depth_figures(self.log, self.scenario, self.resolved.heave_plant, folder, fmt, dpi)


def make_controller(scenario: Scenario, model: VehicleParams) -> Controller:
    """The scenario's controller, built on the nominal (controller-side) vehicle model."""
    config = scenario.controller.with_model_substeps(model)
    if config.type is ControllerType.BASELINE:
        from auvmpc.controllers.baseline import BaselineController

        return BaselineController(model, config.sample_time, config.baseline)
    if config.type is ControllerType.MPC:
        from auvmpc.controllers.mpc import PaperMpc

        return PaperMpc(model, config)
    if config.type is ControllerType.LTV_MPC:
        from auvmpc.controllers.ltv import LtvMpc

        return LtvMpc(model, config)
    if config.type is ControllerType.NMPC:
        from auvmpc.controllers.nmpc import NonlinearMpc

        return NonlinearMpc(model, config)
    if config.type is ControllerType.DO_MPC:
        from auvmpc.controllers.dompc import DoMpcController

        return DoMpcController(model, config, obstacle_slots=len(scenario.obstacles))
    raise NotImplementedError(config.type)  # unreachable: the enum lists only built controllers


def simulate(
    resolved: ResolvedScenario | ResolvedDepthScenario,
    on_step: Callable[[int, int], None] | None = None,
) -> RunResult | DepthRunResult:
    """Run the scenario once. Randomness comes from children of the scenario seed."""
    if isinstance(resolved, ResolvedDepthScenario):
        with threadpool_limits(limits=1, user_api="blas"):
            log, heave = simulate_depth(resolved.scenario, resolved.model, on_step)
        return DepthRunResult(resolved, log, depth_metrics(log, resolved.scenario, heave))
    scenario = resolved.scenario
    disturbance_seed, sensor_seed = np.random.SeedSequence(scenario.seed).spawn(2)
    sample_time = scenario.controller.sample_time
    initial_thrust = scenario.initial_thrust
    # One BLAS thread: a controller step works on small matrices, where a second thread only
    # adds hand-over latency (measured: p99 2 ms -> 16 ms for ltv-mpc at nc 30), and
    # campaigns run one process per core anyway.
    with threadpool_limits(limits=1, user_api="blas"):
        log = closed_loop(
            resolved.plant,
            make_controller(scenario, resolved.model),
            make_reference(scenario.reference, resolved.base_dir),
            duration=scenario.duration,
            initial_state=scenario.initial_state,
            disturbance=WorldDisturbance(
                scenario.disturbance, sample_time, np.random.default_rng(disturbance_seed)
            ),
            sensor=SensorNoise(scenario.sensing, np.random.default_rng(sensor_seed)),
            obstacles=scenario.obstacles,
            vehicle_radius=scenario.controller.vehicle_radius,
            max_plant_step=scenario.plant.max_step,
            initial_thrust=None if initial_thrust is None else np.array(initial_thrust),
            on_step=on_step,
        )
    metrics = compute_metrics(log, resolved.model, scenario.transient_s)
    return RunResult(resolved, log, metrics)


def write_run(
    result: RunResult | DepthRunResult,
    out_dir: Path,
    figures: bool = True,
    figure_format: str = "png",
    dpi: int = 120,
) -> Path:
    """Write log.csv, run.json and figures into ``out_dir``, all or nothing.

    Everything goes to a hidden sibling folder first, which is renamed into place
    only when complete: an interrupted write never leaves a folder that looks done.
    An existing ``out_dir`` is replaced.
    """
    out_dir = Path(out_dir)
    out_dir.parent.mkdir(parents=True, exist_ok=True)
    staging = Path(
        tempfile.mkdtemp(prefix=f".{out_dir.name}.", suffix=".partial", dir=out_dir.parent)
    )
    try:
        staging.chmod(0o755)  # mkdtemp makes it private; a run folder is for everyone
        (staging / "log.csv").write_text(result.csv_text())
        (staging / "run.json").write_text(json.dumps(result.run_json(), indent=2, allow_nan=False))
        if figures:
            result.draw(staging, figure_format, dpi)
        _replace_dir(staging, out_dir)
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise
    return out_dir


def draw_figures(
    log: SimLog,
    scenario: Scenario,
    limits: VehicleParams,
    folder: Path,
    fmt: str = "png",
    dpi: int = 120,
) -> None:
    from auvmpc.plots import run_figures, run_title, save_figures

    title = run_title(scenario, limits.name)
    radius = scenario.controller.vehicle_radius
    figures = run_figures(log, scenario.obstacles, radius, limits, title)
    save_figures(figures, folder, dpi=dpi, fmt=fmt)


def draw_depth_figures(
    log: DepthLog, scenario: DepthScenario, heave, folder: Path, fmt: str = "png", dpi: int = 120
) -> None:
    from auvmpc.plots import figure_depth, save_figures

    title = f"{scenario.name}: {scenario.controller.type}"
    save_figures({"depth": figure_depth(log, heave, title=title)}, folder, dpi=dpi, fmt=fmt)


def redraw(run_dir: Path, fmt: str = "png", dpi: int = 120) -> None:
    """Re-draw the figures of a saved run folder (horizontal or depth) as ``fmt`` files."""
    run_dir = Path(run_dir)
    info = json.loads((run_dir / "run.json").read_text())
    if info["scenario"].get("kind") == "depth":
        scenario = DepthScenario.model_validate(info["scenario"])
        log = DepthLog.read_csv(run_dir / "log.csv", scenario.controller.sample_time)
        heave = VehicleParams.model_validate(info["plant"]).heave
        draw_depth_figures(log, scenario, heave, run_dir, fmt, dpi)
        return
    info, log = read_run(run_dir)
    draw_figures(
        log,
        Scenario.model_validate(info["scenario"]),
        VehicleParams.model_validate(info["model"]),
        run_dir,
        fmt,
        dpi,
    )


def read_run(run_dir: Path) -> tuple[dict[str, Any], SimLog]:
    """run.json contents and the log of a saved run folder."""
    run_dir = Path(run_dir)
    info = json.loads((run_dir / "run.json").read_text())
    log = SimLog.read_csv(run_dir / "log.csv")
    initial = info["scenario"].get("initial_thrust")
    if initial is not None:
        log.initial_thrust = np.array(initial, dtype=float)
    return info, log


def _replace_dir(staging: Path, target: Path) -> None:
    if target.exists():
        retired = target.with_name(f".{target.name}.old-{os.getpid()}")
        os.replace(target, retired)
        os.replace(staging, target)
        shutil.rmtree(retired, ignore_errors=True)
    else:
        os.replace(staging, target)


def atomic_write_text(path: Path, text: str) -> None:
    """Write a file so that readers see the old content or the new, never a part."""
    path = Path(path)
    handle, temporary = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(handle, "w") as stream:
            stream.write(text)
            stream.flush()
            os.fsync(stream.fileno())
        os.replace(temporary, path)
    except BaseException:
        Path(temporary).unlink(missing_ok=True)
        raise
