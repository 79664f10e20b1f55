"""The kinds of run, one entry each in :data:`KINDS` (by the scenario's ``kind``).

A :class:`RunKind` says, for its scenarios, everything that differs between a horizontal, a
depth and a 6-DOF run: what a session steps (the controller as the loop sees it, the
reference, the log and the start: :meth:`~RunKind.start`), the plant and sensors ``auvmpc
run`` simulates (:meth:`~RunKind.plant`), the metrics and finished run it files
(:meth:`~RunKind.finished`), its figures, the solver libraries it records, and how a saved
run folder's log is read back (:meth:`~RunKind.read_log`). experiments/run.py is written
once over them; a new kind of plant is one entry here, with its schema in scenario/, its
Plant and its log's columns (docs/architecture.md).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Sequence
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from auvmpc import __version__
from auvmpc.controllers.base import Controller
from auvmpc.controllers.channels import EveryThruster, HorizontalAndDepth, ReferenceWithDepth
from auvmpc.controllers.config import ControllerType, stable_model_substeps
from auvmpc.controllers.depth_mpc import DepthControllerConfig
from auvmpc.controllers.playback import ThrustPlayback
from auvmpc.controllers.registry import build_controller, class_of, whole_vehicle
from auvmpc.environment.currents import WaterCurrent
from auvmpc.environment.depth_sensor import PressureSensor
from auvmpc.environment.disturbances import SensorNoise, WorldDisturbance
from auvmpc.environment.obstacle_sensor import ObstaclePerception
from auvmpc.environment.obstacles import ObstacleConfig
from auvmpc.environment.waves import WaveField
from auvmpc.errors import ConfigError
from auvmpc.estimation.fault_detection import FaultDetector, SixDofFaultDetector
from auvmpc.models.layout import HORIZONTAL
from auvmpc.models.six_dof import stable_substeps
from auvmpc.models.vehicle import VehicleParams
from auvmpc.references import DepthStep, make_reference
from auvmpc.scenario import (
    ResolvedDepthScenario,
    ResolvedScenario,
    ResolvedSixDofScenario,
    scenario_to_dict,
)
from auvmpc.scenario.loader import SCENARIO_KINDS
from auvmpc.sim.log import WHOLE_VEHICLE_LOG, LogFormat, LogTable, SimLog
from auvmpc.sim.loop import Sensor
from auvmpc.sim.metrics import (
    compute_depth_metrics,
    compute_metrics,
    compute_six_dof_metrics,
    fault_metrics,
    reference_as_flown,
    reference_path,
    six_dof_fault_metrics,
)
from auvmpc.sim.plant import (
    HeavePlant,
    HorizontalPlant,
    Plant,
    SixDofPlant,
    SixDofSensor,
    WholeStateSensor,
)
from auvmpc.sim.session import StateReference

if TYPE_CHECKING:
    from matplotlib.figure import Figure

__all__ = [
    "KINDS",
    "DepthRunResult",
    "Finished",
    "HorizontalKind",
    "RunKind",
    "RunResult",
    "SessionStart",
    "SixDofRunResult",
    "kind_of",
    "padded",
]

Resolved = ResolvedScenario | ResolvedDepthScenario


@dataclass
class SessionStart:
    """What a session of a scenario steps, and from where (sim/session.py's arguments)."""

    controller: Controller
    reference: StateReference
    log: SimLog  # empty: the session appends its rows
    steps: int  # the run's commands (its duration over the sample time)
    initial_state: Sequence[float]
    initial_thrust: np.ndarray | None = None
    obstacles: Sequence[ObstacleConfig] = ()
    perception: ObstaclePerception | None = None
    vehicle_radius: float = 0.0
    fault_detector: FaultDetector | None = None

    def arguments(self) -> dict[str, Any]:
        """As keyword arguments of ``Session`` (its fields are Session's parameters)."""
        return {item.name: getattr(self, item.name) for item in fields(self)}


@dataclass
class Finished:
    """A finished run of any kind: the log, the metrics, and how to file them."""

    resolved: Resolved
    log: SimLog
    metrics: dict[str, Any]
    provenance: dict[str, Any] = field(default_factory=dict, kw_only=True)
    warnings: list[str] = field(default_factory=list, kw_only=True)
    #: What the fault detector found, in order (run.json ``fault_detections``); None: the run
    #: had no detector.
    fault_detections: list[dict[str, Any]] | None = field(default=None, kw_only=True)

    @property
    def scenario(self):
        return self.resolved.scenario

    @property
    def kind(self) -> RunKind:
        return kind_of(self.scenario)

    def simulated_plant(self) -> VehicleParams:
        """The vehicle the plant simulated (run.json's ``plant``)."""
        return self.resolved.plant

    def run_json(self) -> dict[str, Any]:
        detections = self.fault_detections
        return {
            "version": __version__,
            "scenario": scenario_to_dict(self.scenario),
            "plant": self.simulated_plant().model_dump(mode="json"),
            "model": self.resolved.model.model_dump(mode="json"),
            "metrics": self.metrics,
            "choices": getattr(self.resolved, "choices", {}),
            "warnings": list(self.warnings),
            **({} if detections is None else {"fault_detections": detections}),
            "provenance": self.provenance,
        }

    def csv_text(self) -> str:
        return self.log.to_csv_text()

    def figures(self) -> dict[str, Figure]:
        """The run's figures by file stem, titled with the controller and vehicle."""
        model, plant = self.resolved.model, self.simulated_plant()
        return self.kind.figures(self.log, self.scenario, model, plant)

    def draw(self, folder: Path, fmt: str = "png", dpi: int = 120) -> None:
        from auvmpc.plots import save_figures

        save_figures(self.figures(), folder, dpi=dpi, fmt=fmt)


@dataclass
class RunResult(Finished):
    """A finished horizontal run (and the base of a 6-DOF one)."""

    resolved: ResolvedScenario


@dataclass
class SixDofRunResult(RunResult):
    """A finished run on the 6-DOF plant (``kind: six-dof``)."""

    resolved: ResolvedSixDofScenario
    log: SimLog  # in SIX_DOF_LOG


@dataclass
class DepthRunResult(Finished):
    """A finished depth experiment."""

    resolved: ResolvedDepthScenario
    log: SimLog  # in DEPTH_LOG

    def simulated_plant(self) -> VehicleParams:
        return self.resolved.model.model_copy(update={"heave": self.resolved.heave_plant})


class RunKind(ABC):
    """What one kind of run does its own way (module docstring); ``name`` is its scenarios'
    ``kind``, whose schema is ``scenario.loader.SCENARIO_KINDS[name]``."""

    name: ClassVar[str]
    result_type: ClassVar[type[Finished]]
    log_format: ClassVar[LogFormat]  # what its log holds (its plant's)
    #: Whether :meth:`read_log` needs run.json's ``model`` (its inputs are the model's).
    reads_model: ClassVar[bool] = False

    @property
    def has_horizontal(self) -> bool:
        """Whether its runs have a horizontal path, to animate and compare."""
        return self.log_format.horizontal_part is not None

    @property
    def scenario_type(self) -> type:
        """The schema of its scenarios (as written in a run folder's run.json)."""
        return SCENARIO_KINDS[self.name][0]

    @abstractmethod
    def seeds(self, scenario) -> dict[str, np.random.SeedSequence]:
        """The run's random streams by what they drive (children of the scenario seed)."""

    @abstractmethod
    def controller(self, scenario, model: VehicleParams) -> Controller:
        """The scenario's controller on the nominal vehicle model ``model``."""

    @abstractmethod
    def start(self, resolved, controller: Controller) -> SessionStart:
        """What the session steps: ``controller`` is the scenario's, built by the caller."""

    @abstractmethod
    def plant(self, resolved) -> tuple[Plant, Sensor]:
        """The simulated vehicle in its environment, and its sensors."""

    @abstractmethod
    def metrics(self, resolved, log: SimLog) -> dict[str, Any]:
        """The run's metrics (sim/metrics.py)."""

    def libraries(self, scenario) -> tuple[str, ...]:
        """Distributions beyond numpy, scipy and casadi that the scenario's controllers use
        (each controller class declares its own)."""
        config = scenario.controller
        return class_of(config).libraries(config)

    @abstractmethod
    def figures(self, log, scenario, model: VehicleParams, plant: VehicleParams) -> dict:
        """The figures of a run by file stem (``model``: the controller's vehicle, whose
        limits are drawn; ``plant``: the simulated one)."""

    @abstractmethod
    def read_log(self, table: LogTable, info: dict[str, Any]) -> SimLog:
        """The log of a saved run folder of this kind from its log.csv's ``table`` (read by
        ``experiments/run_folder.py``; ``info``: its run.json, checked there)."""

    def finished(
        self, resolved, log: SimLog, provenance: dict[str, Any], warnings: list[str]
    ) -> Finished:
        """The finished run of ``log``, with its metrics."""
        metrics = self.metrics(resolved, log)
        return self.result_type(resolved, log, metrics, provenance=provenance, warnings=warnings)


class HorizontalKind(RunKind):
    """A horizontal run (``kind: horizontal``): the 3-DOF plant under a world-frame force and
    current."""

    name = "horizontal"
    result_type = RunResult
    log_format = HorizontalPlant.log_format
    # (log, model, transient_s, obstacle_margin, obstacles, vehicle_radius)
    measure = staticmethod(compute_metrics)

    def seeds(self, scenario) -> dict[str, np.random.SeedSequence]:
        """The run's random streams by what they drive: children 0, 1 and 2 of the scenario
        seed are the current's, the sensor's and the obstacle sensor's (2 came last, leaving
        0 and 1 as they were before it)."""
        current, sensor, obstacles = np.random.SeedSequence(scenario.seed).spawn(3)
        return {"current": current, "sensor": sensor, "obstacles": obstacles}

    def controller(self, scenario, model: VehicleParams) -> Controller:
        config = scenario.controller
        if whole_vehicle(config):
            raise ConfigError(
                "controller.type", str(config.type),
                "commands every input of the 6-DOF vehicle: kind: six-dof scenarios only",
            )  # fmt: skip
        return build_controller(config, model, obstacle_count=len(scenario.obstacles))

    def start(self, resolved, controller: Controller) -> SessionStart:
        scenario = resolved.scenario
        given = scenario.initial_thrust
        return SessionStart(
            controller,
            make_reference(scenario.reference, resolved.base_dir),
            SimLog(resolved.model.actuators.layout.names, _sample_time(scenario), self.log_format),
            _steps(scenario),
            scenario.initial_state,
            None if given is None else np.array(given),
            fault_detector=self._fault_detector(resolved),
            **self._surroundings(scenario),
        )

    def _fault_detector(self, resolved) -> FaultDetector | None:
        """The scenario's fault detector on the horizontal thrusters of the nominal model, if
        it asks for one (``fault_detection``)."""
        scenario = resolved.scenario
        if not scenario.fault_detection:
            return None
        sample_time = _sample_time(scenario)
        substeps = stable_model_substeps(resolved.model, sample_time)
        noise = np.asarray(scenario.sensing.std)[HORIZONTAL.nu]
        return FaultDetector(resolved.model, sample_time, substeps, noise)

    def _surroundings(self, scenario) -> dict[str, Any]:
        """The obstacles, what the controller perceives of them (through the scenario's
        obstacle sensor and trackers, or exactly without one) and the vehicle's radius."""
        perception = None
        if scenario.obstacle_sensor is not None:
            rng = np.random.default_rng(self.seeds(scenario)["obstacles"])
            perception = ObstaclePerception(scenario.obstacle_sensor, scenario.obstacles, rng)
        return {
            "obstacles": scenario.obstacles,
            "perception": perception,
            "vehicle_radius": scenario.controller.vehicle_radius,
        }

    def plant(self, resolved) -> tuple[Plant, Sensor]:
        scenario, seeds = resolved.scenario, self.seeds(resolved.scenario)
        sample_time = _sample_time(scenario)
        disturbance = WorldDisturbance(
            scenario.disturbance, sample_time, np.random.default_rng(seeds["current"])
        )
        plant = HorizontalPlant(resolved.plant, disturbance, sample_time, scenario.plant.max_step)
        return plant, SensorNoise(scenario.sensing, np.random.default_rng(seeds["sensor"]))

    def metrics(self, resolved, log: SimLog) -> dict[str, Any]:
        scenario = resolved.scenario
        controller = scenario.controller
        metrics = self.measure(
            log,
            resolved.model,
            scenario.transient_s,
            controller.obstacle_margin,
            scenario.obstacles,
            controller.vehicle_radius,
            **self._path(resolved, log),
        )
        if scenario.faults:
            metrics |= fault_metrics(log, scenario.transient_s, scenario.faults)
        return metrics

    def _path(self, resolved, log: SimLog) -> dict[str, Any]:
        """What :attr:`measure` is told of the reference path beyond the log (none here)."""
        return {}

    def figures(self, log, scenario, model: VehicleParams, plant: VehicleParams) -> dict:
        from auvmpc.plots import run_figures, run_title

        title = run_title(scenario, model.name)
        radius = scenario.controller.vehicle_radius
        return run_figures(log, scenario.obstacles, radius, model, title)

    def read_log(self, table: LogTable, info: dict[str, Any]) -> SimLog:
        log = SimLog.from_table(table, format=self.log_format)
        # (a 6-DOF run's log.csv read as a horizontal one has its vertical thrusters too)
        log.initial_thrust = padded(info["scenario"].get("initial_thrust"), log.n_thrusters)
        return log


class SixDofKind(HorizontalKind):
    """A 6-DOF run (``kind: six-dof``): the horizontal controller and the depth MPC as one
    controller (controllers/channels.py) on the 6-DOF plant in the water current."""

    name = "six-dof"
    reads_model = True
    result_type = SixDofRunResult
    log_format = SixDofPlant.log_format
    measure = staticmethod(compute_six_dof_metrics)

    def seeds(self, scenario) -> dict[str, np.random.SeedSequence]:
        """Children 0 and 1 as in a horizontal scenario (so its planar twin sees the same
        draws), 2 the depth sensor's, 3 the obstacle sensor's."""
        current, sensor, depth, obstacles = np.random.SeedSequence(scenario.seed).spawn(4)
        return {"current": current, "sensor": sensor, "depth": depth, "obstacles": obstacles}

    def controller(self, scenario, model: VehicleParams) -> Controller:
        """The horizontal controller, or a thrust table of every thruster (a 6-DOF excite
        manoeuvre: :class:`EveryThruster`, no depth channel)."""
        config = scenario.controller
        if config.type == ControllerType.THRUST_PLAYBACK:
            filled = config.for_vehicle(model)
            return EveryThruster(ThrustPlayback.playing(model, filled, model.six_dof_actuators))
        if whole_vehicle(config):
            count = len(scenario.obstacles)
            return EveryThruster(build_controller(config, model, obstacle_count=count))
        return super().controller(scenario, model)

    def start(self, resolved, controller: Controller) -> SessionStart:
        scenario, model = resolved.scenario, resolved.model
        if not isinstance(controller, EveryThruster):  # paired with the depth MPC
            depth = build_controller(
                scenario.depth_controller, model, water_depth_m=scenario.water_depth_m
            )
            controller = HorizontalAndDepth(
                controller, depth, model, scenario.depth_controller.preview
            )
        x, y, psi, u, v, r = scenario.initial_state
        log_format = WHOLE_VEHICLE_LOG if whole_vehicle(scenario.controller) else self.log_format
        return SessionStart(
            controller,
            ReferenceWithDepth(resolved.reference),
            SimLog(
                model.six_dof_actuators.layout.names, _sample_time(scenario), log_format,
                horizontal_inputs=horizontal_input_count(model),
            ),
            _steps(scenario),
            [x, y, scenario.initial_depth_m, 0, 0, psi, u, v, 0, 0, 0, r],
            padded(scenario.initial_thrust, model.six_dof_actuators.size),
            fault_detector=self._fault_detector(resolved),
            **self._surroundings(scenario),
        )  # fmt: skip

    def plant(self, resolved) -> tuple[Plant, Sensor]:
        scenario, seeds = resolved.scenario, self.seeds(resolved.scenario)
        sample_time = _sample_time(scenario)
        water = scenario.disturbance.water_current
        current = (
            None
            if water is None
            else WaterCurrent(water, sample_time, np.random.default_rng(seeds["current"]))
        )
        sensing = scenario.sensing
        measures = WholeStateSensor if whole_vehicle(scenario.controller) else SixDofSensor
        sensor = measures(
            SensorNoise(sensing, np.random.default_rng(seeds["sensor"])),
            sensing.depth_std_m, sensing.depth_rate_std_m_per_s,
            np.random.default_rng(seeds["depth"]),
        )  # fmt: skip
        return SixDofPlant(resolved.plant, current, sample_time, scenario.plant.max_step), sensor

    def _fault_detector(self, resolved) -> FaultDetector | None:
        """Beside a controller of the whole vehicle, the detector of every 6-DOF input on
        the nominal model (its body velocities as measured); beside the channel pair, the
        horizontal thrusters' (:class:`HorizontalKind`)."""
        scenario = resolved.scenario
        if not (scenario.fault_detection and whole_vehicle(scenario.controller)):
            return super()._fault_detector(resolved)
        model, sample_time = resolved.model, _sample_time(scenario)
        substeps = stable_substeps(model, sample_time)
        std = scenario.sensing.std  # [x, y, psi, u, v, r]; w, p, q are measured noise-free
        u, v, r = np.asarray(std)[HORIZONTAL.nu]
        return SixDofFaultDetector(model, sample_time, substeps, np.array([u, v, v, r, r, r]))

    def metrics(self, resolved, log: SimLog) -> dict[str, Any]:
        """The horizontal kind's, and what a fault cost in depth and off the path, against
        the reference as the controller flew it (a vehicle that slowed for a fault follows
        the path later: sim/metrics.py, reference_as_flown)."""
        log = reference_as_flown(log)
        metrics = super().metrics(resolved, log)
        scenario = resolved.scenario
        if scenario.faults:
            path = self._path(resolved, log)["path"]
            metrics |= six_dof_fault_metrics(log, scenario.transient_s, scenario.faults, path)
        return metrics

    def _path(self, resolved, log: SimLog) -> dict[str, Any]:
        """The reference's horizontal path over the run, densely (the cross-track metric)."""
        return {"path": reference_path(resolved.reference, log.t[-1], log.sample_time)}

    def libraries(self, scenario) -> tuple[str, ...]:
        """The horizontal controller's, then the depth MPC's (none beside a controller of
        the whole vehicle)."""
        if whole_vehicle(scenario.controller):
            return super().libraries(scenario)
        depth = scenario.depth_controller
        return (*super().libraries(scenario), *class_of(depth).libraries(depth))

    def figures(self, log, scenario, model: VehicleParams, plant: VehicleParams) -> dict:
        """The horizontal figures of the horizontal view, then the 6-DOF ones."""
        from auvmpc.plots import run_title, six_dof_figures

        drawn = super().figures(log.horizontal(), scenario, model, plant)
        return {**drawn, **six_dof_figures(log, model, run_title(scenario, model.name))}

    def read_log(self, table: LogTable, info: dict[str, Any]) -> SimLog:
        model = VehicleParams.model_validate(info["model"])
        inputs = model.six_dof_actuators
        initial = padded(info["scenario"].get("initial_thrust"), inputs.size)
        return SimLog.from_table(
            table, initial, self.log_format, horizontal_input_count(model),
            input_names=inputs.layout.names,
        )  # fmt: skip


class DepthKind(RunKind):
    """A depth run (``kind: depth``): the depth MPC on the heave plant in the tank, in calm
    water or under waves."""

    name = "depth"
    result_type = DepthRunResult
    log_format = HeavePlant.log_format

    def seeds(self, scenario) -> dict[str, np.random.SeedSequence]:
        """Child 0 of the scenario seed is the waves', child 1 the sensor's."""
        waves, sensor = np.random.SeedSequence(scenario.seed).spawn(2)
        return {"waves": waves, "sensor": sensor}

    def controller(self, scenario, model: VehicleParams) -> Controller:
        """The depth MPC, kept clear of the tank's bottom."""
        return build_controller(scenario.controller, model, water_depth_m=scenario.tank.depth_m)

    def start(self, resolved, controller: Controller) -> SessionStart:
        scenario = resolved.scenario
        config = scenario.controller  # only the depth MPC looks ahead; a thrust table reads none
        preview = isinstance(config, DepthControllerConfig) and config.preview
        reference = DepthStep(scenario.reference, preview)
        inputs = resolved.heave_plant.actuators.layout.names
        log = SimLog(inputs, _sample_time(scenario), self.log_format)
        return SessionStart(controller, reference, log, _steps(scenario), scenario.start_state())

    def plant(self, resolved) -> tuple[Plant, Sensor]:
        scenario, seeds = resolved.scenario, self.seeds(resolved.scenario)
        water_depth = scenario.tank.depth_m
        waves = (
            WaveField(scenario.waves, water_depth, np.random.default_rng(seeds["waves"]))
            if scenario.waves is not None
            else None
        )
        plant = HeavePlant(
            resolved.model, resolved.heave_plant, waves, _sample_time(scenario),
            scenario.plant.max_step,
        )  # fmt: skip
        return plant, PressureSensor(scenario.sensor, np.random.default_rng(seeds["sensor"]))

    def metrics(self, resolved, log) -> dict[str, Any]:
        return compute_depth_metrics(log, resolved.scenario.reference, resolved.heave_plant)

    def figures(self, log, scenario, model: VehicleParams, plant: VehicleParams) -> dict:
        """The depth step (``plant``'s heave limits drawn)."""
        from auvmpc.plots import figure_depth

        title = f"{scenario.name}: {scenario.controller.type}"
        return {"depth": figure_depth(log, plant.heave, title=title)}

    def read_log(self, table: LogTable, info: dict[str, Any]) -> SimLog:
        return SimLog.from_table(table, format=self.log_format)


KINDS: dict[str, RunKind] = {
    kind.name: kind for kind in (HorizontalKind(), SixDofKind(), DepthKind())
}


def kind_of(scenario) -> RunKind:
    """The kind of run of a scenario (a ``Scenario``, ``SixDofScenario`` or
    ``DepthScenario``), or of a saved run's ``scenario`` mapping (a kind it does not know is
    one line naming it)."""
    name = scenario.get("kind", "horizontal") if isinstance(scenario, dict) else scenario.kind
    if not isinstance(name, str) or name not in KINDS:
        raise ConfigError("scenario.kind", name, f"one of {', '.join(KINDS)}")
    return KINDS[name]


def horizontal_input_count(model: VehicleParams) -> int:
    """How many of a 6-DOF log's inputs, from the first, its horizontal view keeps: the
    horizontal thrusters, or every input of a vehicle with ``actuators:`` (a propeller and
    fins act in the horizontal plane and the vertical one alike)."""
    return model.n_thrusters if model.has_thrusters else model.six_dof_actuators.size


def padded(given, count: int) -> np.ndarray:
    """The command before t = 0 of ``count`` inputs from a scenario's ``initial_thrust`` (the
    horizontal thrusters', or every actuator's; the others, a 6-DOF vehicle's vertical
    thrusters, start at 0)."""
    total = np.zeros(count)
    if given is not None:
        total[: len(given)] = given
    return total


def _sample_time(scenario) -> float:
    return scenario.controller.sample_time


def _steps(scenario) -> int:
    return int(round(scenario.duration / scenario.controller.sample_time))
