"""A scenario plus what its names point at: the nominal model, the simulated plant, the
settings chosen for the vehicle, and the checks that need the vehicle.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from auvmpc.controllers.config import ControllerType
from auvmpc.controllers.registry import DEFAULT_TYPE, REGISTRY, retyped, whole_vehicle
from auvmpc.errors import ConfigError, FieldError
from auvmpc.models.actuators import ActuatorSet
from auvmpc.models.heave import resolve_heave
from auvmpc.models.layout import DEPTH, DEPTH_PROFILE, HORIZONTAL, Layout
from auvmpc.models.six_dof import SIX_DOF, plant_step_length
from auvmpc.models.vehicle import (
    VehicleParams,
    check_plant_scale,
    load_vehicle,
    scaled,
    stable_plant_step,
)
from auvmpc.references import Reference, make_reference
from auvmpc.scenario.depth import DepthScenario
from auvmpc.scenario.model import (
    DEFAULT_PLANT_STEP_S,
    Scenario,
    SixDofScenario,
    check_one_sample_time,
    rounded_to_samples,
)
from auvmpc.sim.faults import FaultSchedule

__all__ = [
    "ResolvedDepthScenario",
    "ResolvedScenario",
    "ResolvedSixDofScenario",
    "load_vehicle_relative",
]


# Standard deviations of position noise added to an omitted obstacle margin: measured on a
# hard-survey case (11 kg, noise 0.02 m, 30 % model error, current), the default 0.1 m
# margin left -0.017 m of clearance, 0.13 m and 0.16 m left 0.058 and 0.032 m.
NOISE_MARGIN_SIGMAS = 3.0


class ResolvedScenario:
    """A scenario plus what its names point at: the nominal model and the simulated plant."""

    #: The state its (horizontal) controller predicts; a horizontal path to check.
    controlled_layout: Layout = HORIZONTAL
    has_horizontal_path = True
    follows_depth = False  # whether a reference's depth is followed (a 6-DOF run's is)
    plant_model = "horizontal"  # the simulated model, for what plant.scale may scale

    @property
    def controlled_inputs(self) -> ActuatorSet:
        """The inputs its ``controller`` commands (the nominal model's)."""
        return self.model.actuators

    @property
    def plant_inputs(self) -> ActuatorSet:
        """The inputs the simulated plant takes (the log's thrust columns)."""
        return self.plant.actuators

    @property
    def initial_inputs(self) -> ActuatorSet:
        """The inputs ``initial_thrust`` gives one value each, within their limits: the
        horizontal thrusters (a 6-DOF vehicle's vertical ones start at 0)."""
        return self.model.actuators

    @classmethod
    def default_controller_type(cls, vehicle: VehicleParams) -> str:
        """The type a ``controller`` mapping without one has on ``vehicle`` (what the
        scenario loader validates it as)."""
        return DEFAULT_TYPE

    def _check_vehicle(self, scenario: Scenario) -> None:
        """Refuse a vehicle the scenario's controller cannot command (one line)."""
        self.model.fixed_thrusters(f"a {scenario.kind} scenario's controller")

    def _default_plant_step(self) -> float:
        """The plant's longest RK4 step when the scenario gives none (``plant.max_step``)."""
        return stable_plant_step(self.plant, DEFAULT_PLANT_STEP_S)

    def __init__(self, scenario: Scenario, base_dir: Path) -> None:
        self.given = scenario  # as written: what overrides apply to
        self.scenario = scenario  # below: with what the vehicle decides filled in
        self.base_dir = base_dir
        self.model: VehicleParams = load_vehicle_relative(scenario.vehicle, base_dir)
        self._check_vehicle(scenario)
        check_plant_scale(scenario.plant.scale, self.plant_model)
        self.plant: VehicleParams = scaled(_plant_vehicle(self.model, scenario, base_dir),
                                           scenario.plant.scale)  # fmt: skip
        weights = getattr(scenario.controller, "R", None)  # the optimising controllers'
        if weights is not None:
            n = self.model.n_thrusters
            if len(weights) not in (1, n):
                raise ConfigError(
                    "controller.R", list(weights), f"need 1 or {n} weights (one per thruster)"
                )
        # What the scenario left out is filled in for its vehicle here, so the run's record
        # (run.json's scenario) holds every value the controller used. Overrides apply to
        # ``given``: a filled-in value must not outlive a change of vehicle or sample time.
        plant_step = scenario.plant.max_step or self._default_plant_step()
        # What was chosen for the vehicle, and why (run.json ``choices``, ``auvmpc explain``).
        self.choices = scenario.controller.choices(self.model)
        controller = with_table_found(scenario.controller.for_vehicle(self.model), base_dir)
        noise = max(scenario.sensing.std[HORIZONTAL.position])
        if (
            scenario.obstacles
            and noise > 0
            and "obstacle_margin" not in controller.model_fields_set
        ):
            # The controller steers the position it measures: the margin covers the noise.
            margin = controller.obstacle_margin + NOISE_MARGIN_SIGMAS * noise
            controller = controller.model_copy(update={"obstacle_margin": margin})
            self.choices["obstacle_margin"] = {
                "value": margin,
                "why": f"{scenario.controller.obstacle_margin:g} m plus {NOISE_MARGIN_SIGMAS:g}"
                f" x the position noise's {noise:g} m std (sensing.std): the controller "
                "steers the position it measures",
            }
        controller, sensed = controller.for_sensing(scenario.sensing)
        self.choices |= sensed
        self.scenario = scenario = scenario.model_copy(
            update={
                "controller": controller,
                "plant": scenario.plant.model_copy(update={"max_step": plant_step}),
            }
        )
        # What was decided for the user that they should hear of (run.json ``warnings``).
        scenario, self.notes = rounded_to_samples(scenario)
        self.scenario = scenario
        initial = scenario.initial_thrust
        if initial is not None:
            _check_initial_command(initial, self.initial_inputs)
        #: Its actuator faults on the plant's inputs (None: none).
        self.faults = (
            FaultSchedule(scenario.faults, self.plant_inputs, scenario.duration)
            if scenario.faults
            else None
        )


class ResolvedSixDofScenario(ResolvedScenario):
    """A 6-DOF scenario, its vehicle (which must have a ``six_dof`` section) and its 3-D
    reference. The horizontal controller and the depth MPC need fixed thrusters, a ``heave``
    section and vertical thrusters after the horizontal ones; a controller of the whole
    vehicle (``registry.whole_vehicle``) needs none of these and flies any actuators (a
    propeller and fins). Without a ``controller.type``, a vehicle with ``actuators:`` gets
    ``six-dof-nmpc``: the default controller must fly the vehicle."""

    scenario: SixDofScenario
    follows_depth = True
    plant_model = "six-dof"

    @property
    def plant_inputs(self) -> ActuatorSet:
        return self.plant.six_dof_actuators

    @property
    def controlled_inputs(self) -> ActuatorSet:
        """A controller of the whole vehicle's: every 6-DOF input; else the horizontal ones."""
        if whole_vehicle(self.scenario.controller):
            return self.model.six_dof_actuators
        return super().controlled_inputs

    @property
    def controlled_layout(self) -> Layout:  # type: ignore[override]
        return SIX_DOF if whole_vehicle(self.scenario.controller) else HORIZONTAL

    @property
    def initial_inputs(self) -> ActuatorSet:
        """A vehicle with ``actuators:``: every one (rpm, deg); else the horizontal thrusters."""
        if self.model.has_thrusters:
            return super().initial_inputs
        return self.model.six_dof_actuators

    @classmethod
    def default_controller_type(cls, vehicle: VehicleParams) -> str:
        """A vehicle with ``actuators:`` (a propeller and fins): six-dof-nmpc, the only
        controller that flies them; one with thrusters: the horizontal default."""
        return DEFAULT_TYPE if vehicle.has_thrusters else ControllerType.SIX_DOF_NMPC

    def _check_vehicle(self, scenario: Scenario) -> None:
        if not whole_vehicle(scenario.controller):  # the pair: fixed thrusters, checked below
            super()._check_vehicle(scenario)

    def _default_plant_step(self) -> float:
        return plant_step_length(self.plant, DEFAULT_PLANT_STEP_S)

    def __init__(self, scenario: SixDofScenario, base_dir: Path) -> None:
        if scenario.plant.vehicle is not None:
            raise ConfigError(
                "plant.vehicle",
                scenario.plant.vehicle if isinstance(scenario.plant.vehicle, str) else "mapping",
                "not supported on the 6-DOF plant yet (it simulates the vehicle's six_dof "
                "section); horizontal scenarios only",
            )
        # The vehicle's fitness for the 6-DOF plant first: it decides whether anything else
        # about the scenario (e.g. a weight per thruster) can matter.
        vehicle = load_vehicle_relative(scenario.vehicle, base_dir)
        if vehicle.six_dof is None:
            raise ConfigError(
                "vehicle.six_dof",
                vehicle.name,
                "missing: the 6-DOF plant needs the vehicle's six_dof section (docs/six-dof.md)",
            )
        given, typed = scenario, _typed_for(scenario, vehicle)
        whole = whole_vehicle(typed.controller)
        if not whole:
            _check_channel_pair(typed, vehicle)
        super().__init__(typed, base_dir)
        self.given = given  # as written (a default type is the vehicle's: not an override)
        if typed is not scenario:
            self.choices = {"type": _default_type_choice(vehicle), **self.choices}
        model = self.model
        if not whole:
            _check_depth_channel(model)
        if whole and scenario.obstacles:
            raise ConfigError(
                "obstacles", len(scenario.obstacles),
                f"{typed.controller.type} has no keep-out constraint yet: it would fly through "
                "them (the horizontal controllers keep clear, docs/moving-obstacles.md)",
            )  # fmt: skip
        if scenario.fault_detection and not (whole or model.has_thrusters):
            raise ConfigError(
                "fault_detection", True,
                f"with {typed.controller.type} it watches horizontal thrusters on the 3-DOF "
                f"model; {model.name} has a propeller and fins: fly a controller of the whole "
                "vehicle (six-dof-nmpc), whose detector watches every input",
            )  # fmt: skip
        self.reference: Reference = make_reference(scenario.reference, base_dir)
        if not self.reference.has_depth:
            raise ConfigError(
                "reference.depth",
                None,
                "the 6-DOF plant needs a depth reference: give reference.depth or a 3-D type "
                "(helix, lawnmower, waypoints-3d)",
            )
        given = self.given
        initial_depth = given.initial_depth_m
        if initial_depth is None:
            initial_depth = float(self.reference.depths([0.0])[0, DEPTH_PROFILE.index("z")])
        bottom = given.water_depth_m
        if not 0.0 < initial_depth < bottom:
            raise ConfigError(
                "initial_depth_m", initial_depth, f"not in the water (0 to {bottom} m below)"
            )
        # The reference over the run, at the controller's samples or finer: one out of the
        # water cannot be tracked and is no test of a controller.
        times = np.linspace(0.0, scenario.duration, max(2, int(scenario.duration / 0.1) + 1))
        path_depths = self.reference.depths(times)[:, DEPTH_PROFILE.index("z")]
        if path_depths.min() <= 0.0 or path_depths.max() >= bottom:
            raise ConfigError(
                "reference.depth",
                [round(float(path_depths.min()), 3), round(float(path_depths.max()), 3)],
                f"the reference leaves the water (0 to water_depth_m {bottom} m below)",
            )
        sample_time = self.scenario.controller.sample_time  # chosen for the vehicle if omitted
        depth_controller = given.depth_controller
        if "sample_time" not in depth_controller.model_fields_set:
            depth_controller = depth_controller.model_copy(update={"sample_time": sample_time})
        elif not whole:
            check_one_sample_time(depth_controller.sample_time, sample_time)
        # (the schema fills in ``preview`` itself: a field beyond it is the user's)
        if whole and given.depth_controller.model_fields_set - {"preview"}:
            # Said, not refused: a scenario written for the pair (bluerov2-helix) flies with
            # --controller six-dof-nmpc or another vehicle as it is.
            self.notes.append(
                f"depth_controller: unused: {self.scenario.controller.type} commands every "
                "input of the vehicle itself (no depth channel)"
            )
        self.scenario = self.scenario.model_copy(
            update={"depth_controller": depth_controller, "initial_depth_m": initial_depth}
        )


def _typed_for(scenario: SixDofScenario, vehicle: VehicleParams) -> SixDofScenario:
    """``scenario`` with ``controller.type: six-dof-nmpc`` if it names no type and its vehicle
    has ``actuators:`` (the default nmpc, a horizontal controller on thrusters, cannot fly a
    propeller and fins); else as it is. The loader validated a ``controller`` mapping as the
    vehicle's default already; this types the omitted one, and a scenario validated without
    the loader, whose knob that six-dof-nmpc has not is one line naming it."""
    config = scenario.controller
    default = ResolvedSixDofScenario.default_controller_type(vehicle)
    if default == DEFAULT_TYPE or "type" in config.model_fields_set:
        return scenario
    target = REGISTRY[default].config
    for knob in sorted(config.model_fields_set):
        if knob not in target.model_fields:
            raise ConfigError(
                f"controller.{knob}", getattr(config, knob),
                f"not a knob of {default}, the default controller of "
                f"{vehicle.name} (a vehicle with actuators:); name controller.type to use it",
            )  # fmt: skip
    typed = retyped(config, default)
    return scenario.model_copy(update={"controller": typed})


def _default_type_choice(vehicle: VehicleParams) -> dict[str, Any]:
    """run.json's ``choices`` entry for the type :func:`_typed_for` gave."""
    kinds = ", ".join(f"{e.name} ({e.kind})" for e in vehicle.actuator_entries or ())
    return {
        "value": str(ControllerType.SIX_DOF_NMPC),
        "why": f"the default for a vehicle with actuators: ({kinds}): it predicts through "
        "them on the 6-DOF model; the horizontal controllers and the depth MPC need fixed "
        "thrusters",
    }


def _check_channel_pair(scenario: SixDofScenario, vehicle: VehicleParams) -> None:
    """Refuse (one line) a vehicle the horizontal controller and the depth MPC cannot fly:
    one without fixed thrusters, or whose 6-DOF thrusters do not follow the layout."""
    if not vehicle.has_thrusters:
        raise ConfigError(
            "controller.type", str(scenario.controller.type),
            f"commands fixed thrusters (a horizontal controller with the depth MPC, or a "
            f"thrust table); {vehicle.name} has a propeller and fins: six-dof-nmpc flies it "
            "(its default without a controller.type)",
        )  # fmt: skip
    try:
        vehicle.check_six_dof_layout()
    except FieldError as error:
        raise ConfigError(f"vehicle.{error.field}", error.value, error.reason) from None


def _check_depth_channel(model: VehicleParams) -> None:
    """Refuse (one line) a vehicle without what the depth MPC commands: a ``heave`` section
    and thrusters with a heave component after the horizontal ones."""
    if model.heave is None:
        raise ConfigError(
            "vehicle.heave", model.name, "missing: the depth controller needs a heave section"
        )
    six, n = model.six_dof, model.n_thrusters
    vertical = np.asarray(six.T)[2, n:]
    if vertical.size == 0 or not np.any(np.abs(vertical) > 1e-9):
        raise ConfigError(
            "vehicle.six_dof.thrusters",
            six.n_thrusters,
            f"no vertical thrusters after the {n} horizontal ones: the depth reference "
            "needs thrusters with a heave (z) component",
        )


def _check_initial_command(initial: Sequence[float], inputs: ActuatorSet) -> None:
    """Refuse (one line) an ``initial_thrust`` without one value per input of ``inputs`` or
    with one outside that input's limits (in its own units: N, rpm, deg)."""
    n = inputs.size
    if len(initial) != n:
        raise ConfigError("initial_thrust", list(initial), f"need {n} values")
    limits = inputs.limits
    lower = np.broadcast_to(limits.lower, (n,))
    upper = np.broadcast_to(limits.upper, (n,))
    for name, unit, value, low, high in zip(
        inputs.layout.names, inputs.units, initial, lower, upper, strict=True
    ):
        if not low <= value <= high:
            raise ConfigError(
                "initial_thrust", list(initial),
                f"{name} {value:g} outside its limits [{low:g}, {high:g}] {unit}",
            )  # fmt: skip


def _plant_vehicle(model: VehicleParams, scenario: Scenario, base_dir: Path) -> VehicleParams:
    """The vehicle the plant simulates: ``plant.vehicle`` if given (as many horizontal
    thrusters as the model: the controller commands the plant's thrusters), else the model."""
    given = scenario.plant.vehicle
    if given is None:
        return model
    plant = load_vehicle_relative(given, base_dir, field="plant.vehicle")
    if plant.n_thrusters != model.n_thrusters:
        raise ConfigError(
            "plant.vehicle",
            plant.name,
            f"has {plant.n_thrusters} horizontal thrusters, the controller's model "
            f"({model.name}) {model.n_thrusters}: the plant takes the controller's commands",
        )
    return plant


def with_table_found(controller, base_dir: Path):
    """A thrust-playback ``controller``'s config with its table's path relative to the
    scenario's folder, as a vehicle file's (any other config as it is)."""
    if getattr(controller, "playback", None) is None:  # only thrust-playback has a table
        return controller
    table = relative_to(controller.playback.path, base_dir)
    return controller.model_copy(
        update={"playback": controller.playback.model_copy(update={"path": table})}
    )


def relative_to(path: str, base_dir: Path) -> str:
    """A file a scenario names: a relative path is relative to the scenario's folder."""
    return path if Path(path).is_absolute() else str(base_dir / path)


def load_vehicle_relative(
    vehicle: str | dict[str, Any], base_dir: Path, field: str = "vehicle"
) -> VehicleParams:
    """A vehicle named by a scenario; a file path is relative to the scenario's folder."""
    if isinstance(vehicle, str) and vehicle.endswith((".yaml", ".yml")):
        vehicle = relative_to(vehicle, base_dir)
    return load_vehicle(vehicle, field)


class ResolvedDepthScenario:
    """A depth scenario (``kind: depth``) and its vehicle."""

    controlled_layout: Layout = DEPTH
    faults = None  # a depth scenario has none yet
    has_horizontal_path = False

    @property
    def controlled_inputs(self) -> ActuatorSet:
        return self.heave_model.actuators

    def __init__(self, scenario: DepthScenario, base_dir: Path) -> None:
        self.scenario = scenario
        self.base_dir = base_dir
        self.model: VehicleParams = load_vehicle_relative(scenario.vehicle, base_dir)
        check_plant_scale(scenario.plant.scale, "depth")
        try:
            self.heave_model = resolve_heave(self.model, {})
            self.heave_plant = resolve_heave(self.model, scenario.plant.scale)
        except FieldError as error:
            raise ConfigError(error.field, error.value, error.reason) from None
        self.given = scenario  # as written: what overrides apply to
        scenario = scenario.model_copy(
            update={"controller": with_table_found(scenario.controller, base_dir)}
        )
        # What was decided for the user that they should hear of (run.json ``warnings``).
        self.scenario, self.notes = rounded_to_samples(scenario)
