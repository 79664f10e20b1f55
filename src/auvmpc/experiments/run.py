"""From a resolved scenario to a run folder: build, simulate, measure, write atomically."""

from __future__ import annotations

import contextlib
import json
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from threadpoolctl import threadpool_limits

from auvmpc import __version__, interrupts
from auvmpc.controllers.base import Controller
from auvmpc.controllers.channels import HorizontalAndDepth, WithDepth
from auvmpc.controllers.registry import build_controller
from auvmpc.environment.currents import WaterCurrent
from auvmpc.environment.depth_sensor import PressureSensor
from auvmpc.environment.disturbances import SensorNoise, WorldDisturbance
from auvmpc.environment.obstacle_sensor import ObstaclePerception
from auvmpc.environment.waves import WaveField
from auvmpc.errors import ConfigError, RunFailed
from auvmpc.experiments.outputs import OutputKind, atomic_write_text, staged_folder
from auvmpc.experiments.provenance import Stopwatch
from auvmpc.models.vehicle import VehicleParams
from auvmpc.references import DepthStep, make_reference
from auvmpc.scenario import (
    ControllerType,
    ResolvedDepthScenario,
    ResolvedScenario,
    ResolvedSixDofScenario,
    Scenario,
    SixDofScenario,
    scenario_to_dict,
)
from auvmpc.scenario.depth import DepthScenario
from auvmpc.sim.log import DepthLog, SimLog, SixDofLog
from auvmpc.sim.loop import Sensor, closed_loop, run_session
from auvmpc.sim.metrics import compute_depth_metrics, compute_metrics, compute_six_dof_metrics
from auvmpc.sim.plant import HeavePlant, HorizontalPlant, Plant, SixDofPlant, SixDofSensor
from auvmpc.sim.session import Session, StateReference

__all__ = [
    "DepthRunResult",
    "RunFailed",
    "RunResult",
    "RunSession",
    "SixDofRunResult",
    "atomic_write_text",
    "fill_run_folder",
    "make_controller",
    "read_run",
    "read_planar_run",
    "redraw",
    "run_plant",
    "simulate",
    "write_run",
]


@dataclass
class _Finished:
    """What both kinds of finished run share: the log, the metrics, and how to file them."""

    resolved: ResolvedScenario | ResolvedDepthScenario
    log: SimLog | DepthLog
    metrics: dict[str, Any]
    provenance: dict[str, Any] = field(default_factory=dict, kw_only=True)
    warnings: list[str] = field(default_factory=list, kw_only=True)

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
            "choices": getattr(self.resolved, "choices", {}),
            "warnings": list(self.warnings),
            "provenance": self.provenance,
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
class SixDofRunResult(RunResult):
    """A finished run on the 6-DOF plant (``kind: six-dof``)."""

    resolved: ResolvedSixDofScenario
    log: SixDofLog


@dataclass
class DepthRunResult(_Finished):
    """A finished depth experiment."""

    resolved: ResolvedDepthScenario
    log: DepthLog

    def simulated_plant(self) -> VehicleParams:
        return self.resolved.model.model_copy(update={"heave": self.resolved.heave_plant})

    def draw(self, folder: Path, fmt: str = "png", dpi: int = 120) -> None:
        draw_depth_figures(self.log, self.scenario, self.resolved.heave_plant, folder, fmt, dpi)


def make_controller(scenario: Scenario | DepthScenario, model: VehicleParams) -> Controller:
    """The scenario's controller, built on the nominal (controller-side) vehicle model."""
    if isinstance(scenario, DepthScenario):
        return build_controller(scenario.controller, model, water_depth_m=scenario.tank.depth_m)
    return build_controller(scenario.controller, model, obstacle_count=len(scenario.obstacles))


def simulate(
    resolved: ResolvedScenario | ResolvedDepthScenario,
    on_step: Callable[[int, int], None] | None = None,
) -> RunResult | DepthRunResult:
    """Run the scenario once. Randomness comes from children of the scenario seed.

    Checked first (:mod:`auvmpc.scenario.sanity`): the sizes fit in memory and the scenario is
    physically possible; what is doubtful but possible becomes ``warnings``. A SIGINT or
    SIGTERM stops the loop after the current step (:mod:`auvmpc.interrupts`), even one a
    compiled solver swallowed, so no result is ever built from an interrupted run.
    """
    from auvmpc.scenario.sanity import preflight

    stopwatch = Stopwatch()
    warnings = preflight(resolved)

    reached = [0]

    def step(k: int, n: int) -> None:
        reached[0] = k
        interrupts.check()
        if on_step is not None:
            on_step(k, n)

    with _failures_named(resolved.scenario, reached):
        return _simulate(resolved, step, stopwatch, warnings)


@contextlib.contextmanager
def _failures_named(scenario, reached: list[int]):
    try:
        yield
    except (ConfigError, RunFailed, KeyboardInterrupt):
        raise
    except Exception as error:
        k = reached[0]
        t = k * scenario.controller.sample_time
        text = str(error).strip().splitlines()
        what = f"{type(error).__name__}: {text[0]}" if text else type(error).__name__
        raise RunFailed(
            f"{scenario.name} with {scenario.controller.type} failed at t = {t:g} s "
            f"(step {k}): {what}"
        ) from error


def _simulate(resolved, step, stopwatch: Stopwatch, warnings: list[str]):
    if isinstance(resolved, ResolvedDepthScenario):
        libraries = _solver_libraries(resolved.scenario)
        return _simulate_depth(resolved, step, stopwatch, warnings, libraries)
    # One BLAS thread: a controller step works on small matrices, where a second thread only
    # adds hand-over latency (measured: p99 2 ms -> 16 ms for ltv-mpc at nc 30), and
    # campaigns run one process per core anyway.
    with threadpool_limits(limits=1, user_api="blas"):
        session = RunSession(resolved, warnings, stopwatch)
        plant, sensor = run_plant(resolved)
        run_session(session, plant, sensor, step)
    _check_finite(session.log.state, resolved.scenario)
    return session.result()


def _seeds(scenario: Scenario) -> dict[str, np.random.SeedSequence]:
    """The random streams of a run by what they drive. Horizontal: children 0, 1 and 2 of
    the scenario seed are the current's, the sensor's and the obstacle sensor's (2 came last,
    leaving 0 and 1 as they were before it). 6-DOF: 0 and 1 as in a horizontal scenario (so
    its planar twin sees the same draws), 2 the depth sensor's, 3 the obstacle sensor's."""
    if isinstance(scenario, SixDofScenario):
        current, sensor, depth, obstacles = np.random.SeedSequence(scenario.seed).spawn(4)
        return {"current": current, "sensor": sensor, "depth": depth, "obstacles": obstacles}
    current, sensor, obstacles = np.random.SeedSequence(scenario.seed).spawn(3)
    return {"current": current, "sensor": sensor, "obstacles": obstacles}


def run_plant(resolved: ResolvedScenario) -> tuple[Plant, Sensor]:
    """The simulated vehicle of a horizontal or 6-DOF scenario in its current, and its
    sensors: what ``auvmpc run`` steps a :class:`RunSession` against (tests step one by hand
    with them)."""
    scenario = resolved.scenario
    seeds = _seeds(scenario)
    sample_time = scenario.controller.sample_time
    navigation = SensorNoise(scenario.sensing, np.random.default_rng(seeds["sensor"]))
    if isinstance(resolved, ResolvedSixDofScenario):
        water = scenario.disturbance.water_current
        current = (
            None
            if water is None
            else WaterCurrent(water, sample_time, np.random.default_rng(seeds["current"]))
        )
        sensing = scenario.sensing
        sensor = SixDofSensor(
            navigation, sensing.depth_std_m, sensing.depth_rate_std_m_per_s,
            np.random.default_rng(seeds["depth"]),
        )  # fmt: skip
        return SixDofPlant(resolved.plant, current, sample_time, scenario.plant.max_step), sensor
    disturbance = WorldDisturbance(
        scenario.disturbance, sample_time, np.random.default_rng(seeds["current"])
    )
    plant = HorizontalPlant(resolved.plant, disturbance, sample_time, scenario.plant.max_step)
    return plant, navigation


class RunSession(Session):
    """A horizontal or 6-DOF scenario's controller, stepped sample by sample
    (``auvmpc.session``): its names, timing and start, and :meth:`close`, which files what
    was stepped as a run. A 6-DOF scenario's controller is its horizontal controller and
    depth MPC on the 6-DOF thrusters (controllers/channels.py).

    The batch run (:func:`simulate`) steps the same session against the scenario's plant.
    ``warnings``: the scenario's pre-run checks, when the caller has run them already.
    """

    def __init__(
        self,
        resolved: ResolvedScenario,
        warnings: list[str] | None = None,
        stopwatch: Stopwatch | None = None,
    ) -> None:
        from auvmpc.scenario.sanity import preflight

        self.resolved = resolved
        scenario = resolved.scenario
        self._stopwatch = stopwatch or Stopwatch()
        warnings = preflight(resolved) if warnings is None else warnings
        model = resolved.model
        controller = make_controller(scenario, model)
        # getattr: a controller need not derive from base.Controller (a user's own, a test's).
        self.warnings = [*warnings, *getattr(controller, "build_warnings", ())]
        sample_time = scenario.controller.sample_time
        steps = int(round(scenario.duration / sample_time))
        given = scenario.initial_thrust
        initial_thrust = None if given is None else np.array(given)
        if isinstance(resolved, ResolvedSixDofScenario):
            depth = build_controller(
                scenario.depth_controller, model, water_depth_m=scenario.water_depth_m
            )
            controller = HorizontalAndDepth(
                controller, depth, model, scenario.depth_controller.preview
            )
            reference: StateReference = WithDepth(resolved.reference)
            log: SimLog = SixDofLog.allocate(
                steps, model.six_dof.n_thrusters, sample_time, n_horizontal=model.n_thrusters
            )
            initial_thrust = _six_dof_thrust(model, given)
            x, y, psi, u, v, r = scenario.initial_state
            initial_state = [x, y, scenario.initial_depth_m, 0, 0, psi, u, v, 0, 0, 0, r]
        else:
            reference = make_reference(scenario.reference, resolved.base_dir)
            log = SimLog.allocate(steps, model.n_thrusters, sample_time)
            initial_state = scenario.initial_state
        super().__init__(
            controller,
            reference,
            log,
            initial_state=initial_state,
            initial_thrust=initial_thrust,
            obstacles=scenario.obstacles,
            perception=_perception(scenario, _seeds(scenario)["obstacles"]),
            vehicle_radius=scenario.controller.vehicle_radius,
        )
        self.duration = self.log.steps * sample_time

    def result(self) -> RunResult:
        """What was stepped, as a finished run: its log, metrics, warnings and provenance."""
        scenario = self.resolved.scenario
        log = self.stepped_log
        libraries = _solver_libraries(scenario)
        kind, measure = RunResult, compute_metrics
        if isinstance(log, SixDofLog):
            kind, measure = SixDofRunResult, compute_six_dof_metrics
        metrics = measure(
            log, self.resolved.model, scenario.transient_s, scenario.controller.obstacle_margin
        )
        return kind(
            self.resolved, log, metrics, provenance=self._stopwatch.record(libraries),
            warnings=self.warnings,
        )  # fmt: skip

    def close(
        self, out_dir: str | Path | None = None, figures: bool = True, *, overwrite: bool = False
    ) -> RunResult:
        """The run of the samples stepped so far, written as a run folder into ``out_dir``
        when given (as ``auvmpc run --out``: new or empty, or with ``overwrite`` an earlier
        run folder of auvmpc's). The session is closed then: nothing more may be stepped."""
        self._check_open("close")
        result = self.result()
        if out_dir is not None:
            write_run(result, Path(out_dir), figures=figures, overwrite=overwrite)
        self.closed = True
        return result


def _simulate_depth(
    resolved: ResolvedDepthScenario, step, stopwatch: Stopwatch, warnings, libraries
) -> DepthRunResult:
    """The depth MPC on the heave plant in the tank, in the same closed loop as a horizontal
    run. Random streams: child 0 of the scenario seed is the waves', child 1 the sensor's."""
    scenario = resolved.scenario
    wave_seed, sensor_seed = np.random.SeedSequence(scenario.seed).spawn(2)
    water_depth = scenario.tank.depth_m
    waves = (
        WaveField(scenario.waves, water_depth, np.random.default_rng(wave_seed))
        if scenario.waves is not None
        else None
    )
    config = scenario.controller
    plant = HeavePlant(
        resolved.model, resolved.heave_plant, waves, config.sample_time, scenario.plant.max_step
    )
    controller = make_controller(scenario, resolved.model)
    with threadpool_limits(limits=1, user_api="blas"):
        log = closed_loop(
            plant,
            controller,
            DepthStep(scenario.reference, config.preview),
            duration=scenario.duration,
            initial_state=scenario.start_state(),
            sensor=PressureSensor(scenario.sensor, np.random.default_rng(sensor_seed)),
            on_step=step,
        )
    return DepthRunResult(
        resolved,
        log,
        compute_depth_metrics(log, scenario.reference, resolved.heave_plant),
        provenance=stopwatch.record(libraries),
        warnings=warnings,
    )


def _check_finite(states: np.ndarray, scenario: Scenario) -> None:
    """A plant integration that diverged (e.g. from an initial speed far beyond what the
    vehicle's damping allows at the plant's step) is a failed run, not a result."""
    finite = np.isfinite(states).all(axis=1)
    if not finite.all():
        k = int(np.argmin(finite))
        raise RunFailed(
            f"{scenario.name} with {scenario.controller.type} failed at "
            f"t = {k * scenario.controller.sample_time:g} s (step {k}): the simulated state "
            "became non-finite (the plant integration diverged; check initial_state and "
            "plant.max_step)"
        )


def _solver_libraries(scenario: Scenario | DepthScenario) -> tuple[str, ...]:
    """Distributions beyond numpy, scipy and casadi that the scenario's controller uses."""
    config = scenario.controller
    if isinstance(scenario, DepthScenario):
        return (str(config.qp_solver),)
    libraries: tuple[str, ...] = ()  # baseline: NumPy only; nmpc: IPOPT inside casadi
    if config.type in (ControllerType.MPC, ControllerType.LTV_MPC):
        libraries = (str(config.qp_solver),)
    elif config.type is ControllerType.DO_MPC:
        libraries = ("do-mpc",)
    if isinstance(scenario, SixDofScenario):  # the depth MPC's QP solver beside them
        libraries = (*libraries, str(scenario.depth_controller.qp_solver))
    return libraries


def write_run(
    result: RunResult | DepthRunResult,
    out_dir: Path,
    figures: bool = True,
    figure_format: str = "png",
    dpi: int = 120,
    *,
    overwrite: bool = False,
) -> Path:
    """Write log.csv, run.json and figures into ``out_dir``, all or nothing.

    ``out_dir`` must be new, empty, or an earlier run folder of auvmpc's and then only
    with ``overwrite`` (:mod:`auvmpc.experiments.outputs`); it is written in a hidden staging folder
    renamed into place when complete, so an interrupted write leaves nothing that looks done.
    """
    with staged_folder(out_dir, OutputKind.RUN, overwrite=overwrite) as staging:
        fill_run_folder(result, staging, figures, figure_format, dpi)
    return Path(out_dir)


def fill_run_folder(
    result: RunResult | DepthRunResult,
    folder: Path,
    figures: bool,
    figure_format: str = "png",
    dpi: int = 120,
) -> None:
    """Write a run's files into ``folder`` (a staging folder the caller owns)."""
    folder.mkdir(parents=True, exist_ok=True)
    atomic_write_text(folder / "log.csv", result.csv_text())
    atomic_write_text(
        folder / "run.json", json.dumps(result.run_json(), indent=2, allow_nan=False) + "\n"
    )
    if figures:
        result.draw(folder, figure_format, dpi)


def draw_figures(
    log: SimLog,
    scenario: Scenario,
    limits: VehicleParams,
    folder: Path,
    fmt: str = "png",
    dpi: int = 120,
) -> None:
    """The run's figures; a 6-DOF run's add the 3-D, error and depth/attitude ones."""
    from auvmpc.plots import run_figures, run_title, save_figures, six_dof_figures

    title = run_title(scenario, limits.name)
    radius = scenario.controller.vehicle_radius
    six_dof = isinstance(log, SixDofLog)
    horizontal = log.horizontal() if six_dof else log
    figures = run_figures(horizontal, scenario.obstacles, radius, limits, title)
    if six_dof:
        figures.update(six_dof_figures(log, limits, title))
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
        log = DepthLog.read_csv(run_dir / "log.csv")
        heave = VehicleParams.model_validate(info["plant"]).heave
        draw_depth_figures(log, scenario, heave, run_dir, fmt, dpi)
        return
    if info["scenario"].get("kind") == "six-dof":
        scenario = SixDofScenario.model_validate(info["scenario"])
        model = VehicleParams.model_validate(info["model"])
        six_log = _read_six_dof_log(run_dir, info, model)
        draw_figures(six_log, scenario, model, run_dir, fmt, dpi)
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


def _read_six_dof_log(run_dir: Path, info: dict[str, Any], model: VehicleParams) -> SixDofLog:
    """A saved 6-DOF run's log, its thrusters' F(-1) from its scenario."""
    initial = _six_dof_thrust(model, info["scenario"].get("initial_thrust"))
    return SixDofLog.read_csv_six_dof(run_dir / "log.csv", model.n_thrusters, initial)


def _six_dof_thrust(model: VehicleParams, given) -> np.ndarray:
    """F(-1) of every 6-DOF thruster from a scenario's ``initial_thrust`` (the horizontal
    thrusters'; vertical ones start at 0)."""
    six = model.six_dof
    total = np.zeros(0 if six is None else six.n_thrusters)
    if given is not None:
        total[: len(given)] = given
    return total


def _perception(scenario: Scenario, seed) -> ObstaclePerception | None:
    """What the controller knows of the obstacles: through the scenario's obstacle sensor
    and trackers, or (no sensor) exactly."""
    if scenario.obstacle_sensor is None:
        return None
    return ObstaclePerception(
        scenario.obstacle_sensor, scenario.obstacles, np.random.default_rng(seed)
    )


def read_planar_run(
    run_dir: Path, command: str
) -> tuple[dict[str, Any], Scenario, VehicleParams, SimLog]:
    """A saved run as ``command`` (animate, compare) reads it: run.json, its scenario and
    nominal model, and the horizontal log (a 6-DOF run's horizontal view). A folder that is
    not a run, or a depth run, is refused with one line."""
    run_dir = Path(run_dir)
    if not (run_dir / "run.json").is_file() or not (run_dir / "log.csv").is_file():
        raise ConfigError("RUN_DIR", str(run_dir), "not a run folder (needs run.json and log.csv)")
    info = json.loads((run_dir / "run.json").read_text())
    kind = info["scenario"].get("kind")
    if kind == "depth":
        raise ConfigError(
            "RUN_DIR", str(run_dir), f"a depth run; {command} takes horizontal and 6-DOF runs"
        )
    model = VehicleParams.model_validate(info["model"])
    if kind == "six-dof":
        scenario: Scenario = SixDofScenario.model_validate(info["scenario"])
        six_log = _read_six_dof_log(run_dir, info, model)
        return info, scenario, model, six_log.horizontal()
    info, log = read_run(run_dir)
    return info, Scenario.model_validate(info["scenario"]), model, log


def read_run(run_dir: Path) -> tuple[dict[str, Any], SimLog]:
    """run.json contents and the log of a saved run folder."""
    run_dir = Path(run_dir)
    info = json.loads((run_dir / "run.json").read_text())
    log = SimLog.read_csv(run_dir / "log.csv")
    initial = info["scenario"].get("initial_thrust")
    if initial is not None:  # a 6-DOF run's vertical thrusters start at 0
        log.initial_thrust = np.zeros(log.n_thrusters)
        log.initial_thrust[: len(initial)] = initial
    return info, log
