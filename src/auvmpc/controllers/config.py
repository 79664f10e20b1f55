"""Controller choice and tuning as a scenario states it (``controller:`` in the YAML)."""

from __future__ import annotations

import math
from collections.abc import Mapping
from enum import StrEnum
from typing import Annotated, Any, ClassVar

from pydantic import Field, ValidationInfo, field_validator, model_validator

from auvmpc.config import NonNegative, Positive, StrictModel
from auvmpc.errors import FieldError
from auvmpc.estimation import ObserverConfig
from auvmpc.models.layout import HORIZONTAL, PLANAR_FORCE_XY
from auvmpc.models.vehicle import (
    RK4_STABLE_STEP,
    VehicleParams,
    damping_rates,
    heading_turn_time,
    top_yaw_rate,
    turn_up_time,
)
from auvmpc.ocp.tracking import ThrustPenalty, TrackingOcp
from auvmpc.solvers.dense_qp import QpSolverName

__all__ = [
    "AGILITY_SPEED_M_PER_S",
    "CONTROLLER_PRESETS",
    "ControllerConfig",
    "ControllerType",
    "DEPTH_MPC",
    "DEPTH_TYPE",
    "DEFAULT_SAMPLE_TIME_S",
    "DEFAULT_VEHICLE_RADIUS_M",
    "HEADING_PER_SAMPLE_RAD",
    "DisturbanceBound",
    "DepthChannelConfig",
    "Horizon",
    "HorizonLengths",
    "HorizontalControllerConfig",
    "ObstacleSlack",
    "OffsetFree",
    "OptimisingControllerConfig",
    "PlanLinearisation",
    "PredictionModel",
    "QpSolverOptions",
    "SolverTimeLimit",
    "Relinearisation",
    "SolverOptions",
    "TightenedConstraints",
    "TrackingWeights",
    "TypedControllerConfig",
    "type_field",
    "NmpcMode",
    "PlaybackConfig",
    "QpStructure",
    "THRUST_MOVE_COST",
    "ThrustPenalty",
    "default_sample_time",
    "default_sqp_iterations",
    "default_vehicle_radius",
    "default_thrust_weights",
    "stable_model_substeps",
    "velocity_change_time",
]

# One weight per horizontal state (tuple[NonNegative, ...] of HORIZONTAL.size entries).
StateWeights = tuple[(NonNegative,) * HORIZONTAL.size]


class ControllerType(StrEnum):
    """Controllers a scenario can name."""

    BASELINE = "baseline"
    MPC = "mpc"  # the paper's: SDC model frozen at the current state (paper-model.md sec. 3-4)
    LTV_MPC = "ltv-mpc"  # linearised along the shifted previous solution, exact Jacobians
    NMPC = "nmpc"  # nonlinear multiple shooting (CasADi): full IPOPT solve or real-time SQP
    DO_MPC = "do-mpc"  # the same OCP solved by do-mpc (pip install auvmpc[compare]), a yardstick
    THRUST_PLAYBACK = "thrust-playback"  # open loop: a thrust table played sample by sample
    SIX_DOF_NMPC = "six-dof-nmpc"  # every 6-DOF input on the 6-DOF model (kind: six-dof only)
    LOS_PID = "los-pid"  # a torpedo's LOS guidance and PID autopilots, the yardstick (six-dof)


class NmpcMode(StrEnum):
    """How ``nmpc`` solves its nonlinear program each sample."""

    FULL = "full"  # IPOPT to convergence: the accuracy reference
    REAL_TIME = "real-time"  # one SQP iteration from the shifted previous solution


class QpStructure(StrEnum):
    """How ltv-mpc and the real-time nmpc pose their QP (docs/performance.md compares them)."""

    AUTO = "auto"  # ltv-mpc: condensed while well conditioned, else sparse; nmpc: sparse
    SPARSE = "sparse"  # states kept, Riccati IPM (HPIPM): well posed for unstable vehicles
    CONDENSED = "condensed"  # states eliminated, dense QP (qp_solver): ill-conditioned there


Bound = Annotated[float, Field(ge=0, allow_inf_nan=False)]


class DisturbanceBound(StrictModel):
    """What the controller's prediction does not know, bounded (docs/tightening.md): at every
    sample, in any sequence, a world-frame force of at most ``force_N + model_error_N`` in any
    horizontal direction and a yaw moment of at most ``moment_Nm``. All zero: the nominal
    controller, exactly."""

    force_N: Bound = Field(
        default=0.0,
        description="largest unknown force on the vehicle (N): the current, or with "
        "offset_free the part of it the estimator has not learnt",
    )
    model_error_N: Bound = Field(
        default=0.0,
        description="largest force-equivalent of the model's error (N): mass, damping, "
        "thrust mismatch at the speeds the mission flies; added to force_N",
    )
    moment_Nm: Bound = Field(default=0.0, description="largest unknown yaw moment (N m)")

    @property
    def total_force_N(self) -> float:
        return self.force_N + self.model_error_N

    @property
    def is_zero(self) -> bool:
        return self.total_force_N == 0.0 and self.moment_Nm == 0.0


class PlaybackConfig(StrictModel):
    """A thrust time series to play open loop (``thrust-playback``)."""

    path: str = Field(
        min_length=1,
        description="CSV with header t, F1..Fn (s, N): row k is the thrust over "
        "[k Te, (k+1) Te), t = k Te; after the last row the thrust ramps to zero within the "
        "rate limit. A relative path is relative to the scenario file's folder",
    )


# The validation context of a scenario read back from a run folder's run.json.
SAVED_RUN = "saved_run"

# controller.vehicle_radius for a vehicle file without ``size`` (m): the value every vehicle
# had before the radius came from the size, and the paper's r_auv (paper-model.md sec. 7).
DEFAULT_VEHICLE_RADIUS_M = 0.5


def default_vehicle_radius(model: VehicleParams) -> float:
    """``controller.vehicle_radius`` when the scenario gives none (m): half the diagonal of
    the vehicle's planform, hypot(length, width) / 2; DEFAULT_VEHICLE_RADIUS_M without size.

    Why the diagonal: the obstacle constraint (and the clearance measured) keeps a disc round
    the vehicle's reference point, its (x, y), out of every keep-out disc, whatever the
    heading. The disc therefore has to hold the hull at any heading, and the smallest disc
    round the centre of a length x width box that does is the one through its corners. Half
    the length alone (the hull's nose) would let a corner into the obstacle when the vehicle
    passes it sideways. It takes the reference point at the middle of the size box (the
    body origin of the presets is the hull's centre, near enough); the height does not
    enter, the constraint is in the horizontal plane.
    """
    if model.size is None:
        return DEFAULT_VEHICLE_RADIUS_M
    return math.hypot(model.size.length, model.size.width) / 2.0


def check_control_horizon(control_horizon: int | None, prediction_horizon: int) -> None:
    """The moves fit in the horizon (a control horizon longer than it means nothing)."""
    if control_horizon is not None and control_horizon > prediction_horizon:
        raise FieldError(
            "control_horizon", control_horizon, f"exceeds prediction_horizon {prediction_horizon}"
        )


# What the ``type`` field of a horizontal and of a depth controller's configuration says.
HORIZONTAL_TYPE = (
    "which controller: selects this configuration (default nmpc, the real-time nmpc that "
    "measured best on the hard-survey sweep, docs/recovery.md)"
)
DEPTH_TYPE = (
    "depth controller; thrust-playback plays a table of the vertical thrusts open loop (a "
    "depth scenario's, as `auvmpc excite --dof heave` writes)"
)


def type_field(name: str, description: str = HORIZONTAL_TYPE) -> Any:
    """The ``type`` field of controller type ``name``'s configuration (a depth one's says
    DEPTH_TYPE)."""
    return Field(default=name, description=description)


class TypedControllerConfig(StrictModel):
    """A controller configuration, one of its kind's chosen by ``type`` (pydantic's
    discriminated union, controllers/registry.py). A knob that only other types of its kind
    have is named with them ("a knob of nmpc, not of controller type baseline"); read back
    from a saved run (context ``saved_run``) it is dropped: run folders written before the
    per-type configurations hold every type's knobs."""

    @classmethod
    def _knob_owners(cls, knob: str) -> list[str]:
        """The types of this configuration's kind whose configuration has ``knob``."""
        raise NotImplementedError

    @model_validator(mode="before")
    @classmethod
    def _known_keys_only(cls, data: Any, info: ValidationInfo) -> Any:
        if isinstance(data, Mapping):
            foreign = [key for key in data if key not in cls.model_fields]
            if foreign and (info.context or {}).get(SAVED_RUN):
                return {key: value for key, value in data.items() if key in cls.model_fields}
            own_type = data.get("type", cls.model_fields["type"].default)
            # No type named: the default's knobs are read before the vehicle is known (a
            # torpedo's default, six-dof-nmpc, is chosen after), so say how to name one.
            unnamed = "" if "type" in data else " (the default; name controller.type to use it)"
            for key in foreign:
                owners = cls._knob_owners(str(key))
                if owners:
                    reason = (
                        f"a knob of {', '.join(owners)}, not of controller type {own_type}"
                        + unnamed
                    )
                    raise FieldError(str(key), data[key], reason)
        return super()._known_keys_only(data)


class HorizontalControllerConfig(TypedControllerConfig):
    """What every horizontal controller's configuration holds: its type, its sample time and
    the disc round the vehicle that obstacles are kept from (which the metrics measure
    clearance from, whatever the controller). Each controller type's configuration adds
    its own knobs (in its module, composed from the blocks below); a scenario's
    ``controller`` mapping is one of them, chosen by ``type`` (controllers/registry.py)."""

    type: str = Field(
        description="which controller (default: the real-time nmpc, the one that measured best "
        "on the hard-survey sweep, docs/recovery.md); or a name given to "
        "controllers.registry.register_controller (docs/extending.md)",
    )
    sample_time: Annotated[float, Field(gt=0)] | None = Field(
        default=None,
        description="Te (s); omitted: 0.5, or shorter where the largest yaw moment turns the "
        "vehicle over half a turn in 0.5 s or an underactuated vehicle's turn is faster than "
        "that (default_sample_time, docs/tuning.md)",
    )
    vehicle_radius: NonNegative | None = Field(
        default=None,
        description="radius of the disc round the vehicle's reference point that is kept out "
        "of every obstacle's disc and from which clearance is measured; omitted: half the "
        "diagonal of the vehicle's size, length x width, the disc that holds the hull at any "
        f"heading, or {DEFAULT_VEHICLE_RADIUS_M:g} for a vehicle file without size (m)",
    )
    obstacle_margin: NonNegative = Field(
        default=0.1,
        description="extra clearance added to every obstacle constraint (m), covers the "
        "gap between the prediction model and the plant between samples",
    )

    @classmethod
    def _knob_owners(cls, knob: str) -> list[str]:
        from auvmpc.controllers.registry import knob_owners

        return knob_owners(knob, cls)

    def _has(self, knob: str) -> bool:
        """Whether this controller type has ``knob``."""
        return knob in type(self).model_fields

    def for_sensing(self, sensing: Any) -> tuple[HorizontalControllerConfig, dict[str, Any]]:
        """This config with what it takes from the scenario's sensors (``sensing``) filled in
        where omitted, and those choices (run.json's ``choices``): none but a type's own."""
        return self, {}

    def for_vehicle(self, model: VehicleParams) -> HorizontalControllerConfig:
        """This config with every setting that was omitted filled in for ``model``: the
        sample time, the RK4 steps, the thrust weights and the estimator's disturbance statistics
        (docs/tuning.md says why each scales as it does). Filling a filled config returns it."""
        update: dict[str, Any] = {}
        sample_time = self.sample_time or default_sample_time(model)
        if self.sample_time is None:
            update["sample_time"] = sample_time
        if self._has("model_substeps") and self.model_substeps is None:
            update["model_substeps"] = stable_model_substeps(model, sample_time)
        if self._has("R") and self.R is None:
            update["R"] = default_thrust_weights(model)
        if self.vehicle_radius is None:
            update["vehicle_radius"] = default_vehicle_radius(model)
        if self._linearises_along_a_plan and self.trust_region_weight is None:
            update["trust_region_weight"] = TRUST_REGION_WEIGHTS[self.type]
        if (
            self.type is ControllerType.NMPC
            and "linearisation_iterations" not in self.model_fields_set
        ):
            iterations = default_sqp_iterations(model)
            if iterations != self.linearisation_iterations:
                update["linearisation_iterations"] = iterations
        if self._has("observer"):
            observer = self.observer.for_vehicle(model)
            if observer is not self.observer:
                update["observer"] = observer
        return self.model_copy(update=update) if update else self

    @property
    def _linearises_along_a_plan(self) -> bool:
        """ltv-mpc and the real-time nmpc: the controllers with a trust region."""
        return self._has("trust_region_weight") and (
            self.type != ControllerType.NMPC or self.nmpc_mode == NmpcMode.REAL_TIME
        )

    def choices(self, model: VehicleParams) -> dict[str, dict[str, Any]]:
        """What :meth:`for_vehicle` (and the schema's defaults) chose for ``model`` among the
        settings this config leaves out, each as ``{"value": ..., "why": "..."}``: run.json's
        ``choices`` and ``auvmpc explain`` (docs/tuning.md has the rules)."""
        filled = self.for_vehicle(model)
        given = self.model_fields_set
        chosen: dict[str, dict[str, Any]] = {}
        if "type" not in given:
            chosen["type"] = {
                "value": str(filled.type),
                "why": "the default: the real-time nmpc tracked the hard-survey cases where "
                "ltv-mpc spun and was lost, at a few times less cost (docs/recovery.md)",
            }
        if self.sample_time is None:
            spin = heading_turn_time(model, HEADING_PER_SAMPLE_RAD)
            why = (
                f"at most the paper's {DEFAULT_SAMPLE_TIME_S:g} s and the {spin:.3g} s its "
                f"largest yaw moment needs to turn it by half a turn (top yaw rate "
                f"{top_yaw_rate(model):.3g} rad/s)"
            )
            if model.underactuated:
                why += (
                    f", and underactuated: at most {TURN_UP_SAMPLES:g} x its yaw turn-up time "
                    f"{turn_up_time(model):.3g} s"
                )
            why += f"; rounded down to the grid {list(SAMPLE_TIME_GRID_S)}"
            chosen["sample_time"] = {"value": filled.sample_time, "why": why}
        if self._has("model_substeps") and self.model_substeps is None:
            rates = damping_rates(model, _STABILITY_SPEED, _STABILITY_SPEED, _STABILITY_YAW_RATE)
            chosen["model_substeps"] = {
                "value": filled.model_substeps,
                "why": f"fewest RK4 steps per sample stable for its damping up to "
                f"{_STABILITY_SPEED:g} m/s and {_STABILITY_YAW_RATE:g} rad/s (fastest rate "
                f"{max(rates):.3g} /s, RK4 stable below {RK4_STABLE_STEP:g} per step)",
            }
        if self._has("R") and self.R is None:
            chosen["R"] = {
                "value": list(filled.R),
                "why": f"{THRUST_MOVE_COST:g} / h^2, h half the thrust range "
                f"({(model.thrust_max - model.thrust_min) / 2.0:.4g} N): moving a thruster by h "
                "costs the same on any vehicle",
            }
        if self.vehicle_radius is None:
            if model.size is None:
                why = (
                    f"{model.name} has no size: the {DEFAULT_VEHICLE_RADIUS_M:g} m of a "
                    "vehicle without one (give size {length, width, height} in its file)"
                )
            else:
                why = (
                    f"half the diagonal of its {model.size.length:g} x {model.size.width:g} m "
                    "planform (size): the disc round its reference point that holds the hull "
                    "at any heading"
                )
            chosen["vehicle_radius"] = {"value": filled.vehicle_radius, "why": why}
        if self.type is ControllerType.NMPC and "linearisation_iterations" not in given:
            change = velocity_change_time(model)
            chosen["linearisation_iterations"] = {
                "value": filled.linearisation_iterations,
                "why": f"its full thrust changes its speed by {AGILITY_SPEED_M_PER_S:g} m/s in "
                f"{change:.3g} s; where {DEFAULT_SAMPLE_TIME_S:g} s holds over "
                f"{RTI_AGILE_SAMPLES:g} of that, 2 SQP steps per sample (one oscillated near "
                "discs on such vehicles, docs/recovery.md)",
            }
        if self._linearises_along_a_plan and self.trust_region_weight is None:
            chosen["trust_region_weight"] = {
                "value": filled.trust_region_weight,
                "why": TRUST_REGION_WHY[self.type],
            }
        if self._has("prediction_horizon") and "prediction_horizon" not in given:
            chosen["prediction_horizon"] = {
                "value": filled.prediction_horizon,
                "why": f"the default {filled.prediction_horizon} samples "
                f"({filled.prediction_horizon * filled.sample_time:g} s ahead)",
            }
        if self._has("observer") and (
            self.observer.initial_disturbance_std is None
            or self.observer.disturbance_rate_std is None
        ):
            chosen["observer"] = {
                "value": filled.observer.model_dump(mode="json"),
                "why": "disturbance statistics as fractions of its thrust authority "
                f"{[round(float(a), 4) for a in model.thrust_authority]} (N, N, N m)",
            }
        return chosen


# --- the blocks the controller types' configurations are composed of -------------------------


ControlHorizon = Annotated[int, Field(ge=1)] | None


class HorizonLengths(StrictModel):
    """How far a predictive controller looks ahead and for how many samples its moves are
    free (every predictive controller: the horizontal ones and the depth MPC)."""

    prediction_horizon: Annotated[int, Field(ge=1)] = Field(default=30, description="ny (steps)")
    control_horizon: ControlHorizon = Field(
        default=None, description="nc (steps); omitted = every move free"
    )

    @model_validator(mode="after")
    def _horizons(self) -> HorizonLengths:
        check_control_horizon(self.control_horizon, self.prediction_horizon)
        return self

    def move_schedule(self) -> tuple[int, ...]:
        """Samples of the horizon at which a move is allowed: 0..nc-1."""
        return tuple(range(self.control_horizon or self.prediction_horizon))


class Horizon(HorizonLengths):
    """The horizontal controllers' horizons: the lengths, and move blocking, where the moves
    are free."""

    control_horizon: ControlHorizon = Field(
        default=None,
        description="nc (steps): moves after nc are held; omitted = prediction_horizon "
        "(every move free, the better tracker; the paper uses 2)",
    )
    move_steps: tuple[Annotated[int, Field(ge=0)], ...] | None = Field(
        default=None,
        description="move blocking: the samples of the horizon at which the thrust may change, "
        "starting with 0 and increasing; overrides control_horizon (nc = len(move_steps))",
    )

    @model_validator(mode="after")
    def _blocked_moves(self) -> Horizon:
        steps = self.move_steps
        if steps is not None:
            if (
                not steps
                or steps[0] != 0
                or any(b <= a for a, b in zip(steps, steps[1:], strict=False))
            ):
                raise FieldError("move_steps", list(steps), "must start at 0 and increase")
            if steps[-1] >= self.prediction_horizon:
                raise FieldError(
                    "move_steps",
                    list(steps),
                    f"reach past prediction_horizon {self.prediction_horizon}",
                )
        return self

    def move_schedule(self) -> tuple[int, ...]:
        """Samples of the horizon at which a move is allowed (0..nc-1 without blocking)."""
        if self.move_steps is not None:
            return self.move_steps
        return super().move_schedule()


class TrackingWeights(StrictModel):
    """The tracking cost (paper-model.md section 4)."""

    Q: StateWeights = Field(
        default=(5, 5, 5, 1, 1, 1),
        description="stage weights on [x y psi u v r], as a list in that order or a mapping "
        "by state name (names left out weigh 0), e.g. {x: 5, y: 5, psi: 5}",
    )
    S: StateWeights = Field(
        default=(10, 10, 10, 2, 2, 2), description="terminal weights, as Q (list or mapping)"
    )

    @field_validator("Q", "S", mode="before")
    @classmethod
    def _weights_by_name(cls, value: Any) -> Any:
        return tuple(HORIZONTAL.vector(value)) if isinstance(value, dict) else value

    R: tuple[NonNegative, ...] | None = Field(
        default=None,
        description="thrust weights, one per thruster or one for all; omitted: 0.1 / h^2 with "
        "h half the thrust range, so that (with the increment penalty) a thruster's move by h "
        "costs the same on any vehicle, see docs/tuning.md",
    )
    thrust_penalty: ThrustPenalty = Field(
        default=ThrustPenalty.INCREMENT,
        description="R on dF (the default: the steady thrust that drag and currents need "
        "costs nothing; R also on the internal thrust, which makes no force or moment) or on F "
        "(the paper's: it trades tracking error for thrust)",
    )


class PredictionModel(StrictModel):
    """How the predictive controllers integrate their model over a sample."""

    model_substeps: Annotated[int, Field(ge=1, le=50)] | None = Field(
        default=None,
        description="RK4 steps per sample in the controllers' prediction models and estimator; "
        "omitted = the fewest that keep RK4 stable for the vehicle's damping (see "
        "stable_model_substeps)",
    )
    jit: bool = Field(
        default=True,
        description="compile the CasADi model functions (ltv-mpc) and the real-time "
        "iteration's QP step (nmpc) with the system C compiler; falls back to interpreted "
        "evaluation when there is none",
    )


class SolverTimeLimit(StrictModel):
    """The real-time budget of an optimiser's step (every optimising controller)."""

    solver_time_limit_ms: Annotated[float, Field(gt=0)] | None = Field(
        default=None,
        description="a step whose optimisation takes longer is treated as a failure "
        "(the previous plan's next move is applied), as on a real-time computer",
    )


class QpBackEnd(StrictModel):
    """The QP back end and its iteration cap."""

    qp_solver: QpSolverName = Field(
        default=QpSolverName.DAQP, description="dense QP backend of the condensed QPs"
    )
    qp_iteration_limit: Annotated[int, Field(ge=1)] | None = Field(
        default=None,
        description="cap on QP iterations per interior-point pass (IPOPT iterations for nmpc "
        "full: below ~20 every step falls back); hitting it counts as a solver failure",
    )


class QpSolverOptions(SolverTimeLimit, QpBackEnd):  # the bases in reverse, as below
    """The QP back end and its budget (every controller that solves a QP)."""


class ObstacleSlack(StrictModel):
    """The price of a soft obstacle constraint's slack."""

    obstacle_slack_penalty: Annotated[float, Field(gt=0)] = Field(
        default=1e5, description="exact-penalty weight on obstacle-constraint slack (per m)"
    )


class SolverOptions(QpSolverOptions, ObstacleSlack):  # the bases in reverse, as below
    """The optimiser's back end and budget, and the obstacle slack's price (the horizontal
    optimising controllers)."""


class OffsetFree(StrictModel):
    """The disturbance estimator that removes the steady offset of a current."""

    offset_free: bool = Field(
        default=True,
        description="estimate the unknown current and model error online (EKF on a world-frame "
        "force) and feed it to the prediction; MPC controllers only (the paper: false)",
    )
    observer: ObserverConfig = Field(
        default_factory=ObserverConfig, description="tuning of the offset-free estimator"
    )


class Relinearisation(StrictModel):
    """Linearise-and-solve passes per sample (the linear MPCs and the real-time nmpc)."""

    linearisation_iterations: Annotated[int, Field(ge=1, le=10)] = Field(
        default=1,
        description="linearise-and-solve passes per sample (ltv-mpc and nmpc real-time: SQP "
        "iterations; also refreshes the obstacle half-planes around the new plan)",
    )


class PlanLinearisation(StrictModel):
    """What the controllers that linearise along their previous plan add: the QP's form
    and the trust region round the plan."""

    qp_structure: QpStructure = Field(
        default=QpStructure.AUTO,
        description="nmpc real-time and ltv-mpc: sparse QP solved by HPIPM (stays well posed "
        "on open-loop-unstable vehicles) or condensed QP solved by qp_solver (faster when "
        "well posed); auto: ltv-mpc solves the condensed QP while its Hessian's condition "
        "number is below 1e10 and the sparse one otherwise or when the condensed one fails, "
        "nmpc the sparse one; nmpc with move blocking always uses the condensed QP",
    )
    trust_region_weight: NonNegative | None = Field(
        default=None,
        description="penalty on the predicted deviations from the trajectory the model is "
        "linearised on, per rad^2 (heading) and (m/s)^2 (velocities): ltv-mpc on heading and "
        "velocities, the real-time nmpc on heading (keeps each step where the linearisation "
        "holds); omitted: 10 for ltv-mpc, 5 for nmpc",
    )


class TightenedConstraints(StrictModel):
    """Constraints tightened for a bounded disturbance (ltv-mpc and mpc, ocp/tightening.py)."""

    disturbance_bound: DisturbanceBound = Field(
        default_factory=DisturbanceBound,
        description="bound on the disturbance the prediction does not know; non-zero: ltv-mpc "
        "and mpc tighten their obstacle and thrust constraints so that the true vehicle keeps "
        "them under any disturbance inside it (docs/tightening.md)",
    )


class OptimisingControllerConfig(  # the bases in reverse: the common fields come first
    OffsetFree, SolverOptions, PredictionModel, TrackingWeights, Horizon, HorizontalControllerConfig
):
    """What every optimising horizontal controller (mpc, ltv-mpc, nmpc, do-mpc) is tuned by:
    the horizon, the tracking weights, the prediction model, the solver and the offset-free
    estimator (MPC fields follow paper-model.md section 4)."""

    def ocp(self, model: VehicleParams) -> TrackingOcp:
        """The tracking problem this configuration poses for ``model``'s horizontal thrusters."""
        from auvmpc.controllers.base import horizontal_limits

        filled = self.for_vehicle(model)
        return TrackingOcp.from_config(
            filled,
            model.n_thrusters,
            horizontal_limits(model),
            allocation=model.T,
            slack_penalty=filled.obstacle_slack_penalty,
            keep_out_extra=filled.vehicle_radius + filled.obstacle_margin,
        )


class WholeVehicleConfig(HorizontalControllerConfig):
    """What a controller of the whole 6-DOF vehicle (``Controller.whole_vehicle``:
    ``six-dof-nmpc``, ``los-pid``) fills in for a vehicle, by its own rules: the horizontal
    controllers' rules read the 3-DOF model's thrusters, which a torpedo has not."""

    #: Te (s) when the scenario gives none.
    default_sample_time_s: ClassVar[float]

    def for_vehicle(self, model: VehicleParams) -> WholeVehicleConfig:
        """Filled: the sample time, the vehicle radius and what :meth:`_filled` adds."""
        update: dict[str, Any] = {}
        if self.sample_time is None:
            update["sample_time"] = self.default_sample_time_s
        if self.vehicle_radius is None:
            update["vehicle_radius"] = default_vehicle_radius(model)
        update |= self._filled(model, self.sample_time or self.default_sample_time_s)
        return self.model_copy(update=update) if update else self

    def _filled(self, model: VehicleParams, sample_time: float) -> dict[str, Any]:
        """A type's own omitted settings, filled for ``model`` at ``sample_time``."""
        return {}

    def choices(self, model: VehicleParams) -> dict[str, dict[str, Any]]:
        """What :meth:`for_vehicle` chose, and why (run.json's ``choices``)."""
        filled = self.for_vehicle(model)
        chosen: dict[str, dict[str, Any]] = {}
        if self.sample_time is None:
            chosen["sample_time"] = {
                "value": filled.sample_time,
                "why": f"{self.type}'s default {self.default_sample_time_s:g} s",
            }
        if self.vehicle_radius is None:
            chosen["vehicle_radius"] = {
                "value": filled.vehicle_radius,
                "why": "half the diagonal of its planform (size), or the default without one",
            }
        return chosen | self._chosen(filled)

    def _chosen(self, filled: WholeVehicleConfig) -> dict[str, dict[str, Any]]:
        """A type's own choices (``filled``: this configuration filled in)."""
        return {}


def ControllerConfig(**knobs: Any) -> HorizontalControllerConfig:  # noqa: N802 (reads as a class)
    """The configuration of controller ``type`` (default nmpc) from its knobs, as a scenario's
    ``controller`` mapping states them: ``ControllerConfig(type="mpc", control_horizon=2)``
    is a ``PaperMpcConfig``. A knob the type does not have is refused."""
    from auvmpc.controllers.registry import controller_config

    return controller_config(knobs)


# The sample time when none is given: the paper's, for every vehicle it suits.
DEFAULT_SAMPLE_TIME_S = 0.5
# Sample times a derived one is rounded down to: each divides whole seconds, so scenario
# durations in seconds stay whole numbers of samples.
SAMPLE_TIME_GRID_S = (0.5, 0.25, 0.2, 0.1, 0.05)
# Samples per turn-up time (turn_up_time) that an underactuated vehicle's sample may span.
TURN_UP_SAMPLES = 3.0
# The most heading (rad) the largest yaw moment may turn in one sample at the top yaw rate:
# half a turn. Beyond it a held thrust can spin the vehicle round within the sample and the
# one linearisation per sample says little about where the heading ends. Measured on the
# hard survey at 0.5 s (docs/recovery.md): the two vehicles the default nmpc lost there turn
# 7.5 and 3.9 rad per sample at full moment; at the 0.2 and 0.25 s this gives them both
# track as well as the converged OCP (0.18 and 0.11 m, the latter with the 2 SQP steps of
# default_sqp_iterations). Every preset stays below it (BlueROV2 Heavy 2.4 rad).
HEADING_PER_SAMPLE_RAD = math.pi


def default_sample_time(model: VehicleParams) -> float:
    """Te when the scenario gives none: DEFAULT_SAMPLE_TIME_S, but no longer than the
    largest yaw moment takes to turn the vehicle by HEADING_PER_SAMPLE_RAD at its top yaw
    rate, and for an underactuated vehicle no more than TURN_UP_SAMPLES of its turn-up time
    (vehicle.turn_up_time); rounded down to SAMPLE_TIME_GRID_S.

    An underactuated vehicle moves sideways only by turning, so its heading loop is inside
    its position loop and the sample has to resolve the turn. Measured with
    benchmarks/generality.py (docs/tuning.md): videoray-pro3 (turn-up 0.08 s) lost every
    disturbed run to a two-sample yaw oscillation at 0.5 s, and tracked all of them within
    0.21 m at 0.25 s and 0.2 s. A fully actuated vehicle pushes sideways directly; the
    BlueROV2 (also 0.08 s) meets every floor at 0.5 s and at 0.2 s paid 2.5 times the steps.
    What a fully actuated vehicle's sample must still resolve is how far a held yaw moment
    can spin it (HEADING_PER_SAMPLE_RAD).
    """
    longest = min(DEFAULT_SAMPLE_TIME_S, heading_turn_time(model, HEADING_PER_SAMPLE_RAD))
    if model.underactuated:
        longest = min(longest, TURN_UP_SAMPLES * turn_up_time(model))
    return next((te for te in SAMPLE_TIME_GRID_S if te <= longest), SAMPLE_TIME_GRID_S[-1])


# The speed change that measures how agile a vehicle is (m/s): the hard survey's fastest.
AGILITY_SPEED_M_PER_S = 0.5
# How many of that speed change a DEFAULT_SAMPLE_TIME_S sample may hold before one
# real-time iteration per sample is not enough. Measured on the hard survey at 0.5 s
# (docs/recovery.md): two vehicles that change their speed by 0.5 m/s in 0.015 s and 0.056 s
# (33 and 9 of them per sample) oscillated at full thrust beside a disc and touched it with
# one SQP step, and matched the converged OCP with two; the presets take 0.08-0.56 s
# (jmse2210 2.4, bluerov2-heavy 6.5 per 0.5 s). Counted against 0.5 s even where the yaw
# rule shortens the sample: one such vehicle (0.049 s) at its 0.25 s jumped to full opposite
# yaw moment beside a disc and touched it (-0.31 m) with one step, and matched the converged
# OCP with two (so did the 11 other vehicles whose count this changes).
RTI_AGILE_SAMPLES = 8.0


def velocity_change_time(model: VehicleParams) -> float:
    """How long the full thrust authority takes to change the surge or the sway speed (the
    quicker of the two) by AGILITY_SPEED_M_PER_S, drag aside (s): m v / F."""
    forces = model.thrust_authority[PLANAR_FORCE_XY]  # surge and sway
    times = [
        mass / force if force > 0 else math.inf  # an axis without thrust: not agile on it
        for mass, force in zip((model.m11, model.m22), forces, strict=True)
    ]
    return AGILITY_SPEED_M_PER_S * min(times)


def default_sqp_iterations(model: VehicleParams) -> int:
    """The real-time nmpc's SQP steps per sample when the scenario gives none: 2 on a vehicle
    whose speed changes by AGILITY_SPEED_M_PER_S in less than 1/RTI_AGILE_SAMPLES of
    DEFAULT_SAMPLE_TIME_S (whatever its own sample), else 1."""
    return 2 if DEFAULT_SAMPLE_TIME_S > RTI_AGILE_SAMPLES * velocity_change_time(model) else 1


# The trust region of the controllers that linearise along a trajectory (ltv-mpc, the
# real-time nmpc): a penalty per rad^2 and (m/s)^2 on each step's deviation from it, in the
# units of the stage weights Q (5 on heading by default). ltv-mpc weighs heading and
# velocities (controllers/mpc.py); the real-time nmpc the heading alone (solvers/
# real_time_iteration.py). Measured for nmpc (docs/recovery.md): on the hard survey
# the runs with fallbacks fell from 7 to 2 and its one miss (spun beside a disc at a corner,
# 1.03 x its bar) matched the converged OCP; on 102 cases from another seed every fallback
# (29 steps) and both contacts (-0.19, -0.075 m) went. 10 lost a vehicle that 5 keeps; 5 on
# the velocities as well left it 5 fallbacks in a row and made another touch its disc.
TRUST_REGION_WEIGHTS = {ControllerType.LTV_MPC: 10.0, ControllerType.NMPC: 5.0}
TRUST_REGION_WHY = {
    ControllerType.LTV_MPC: "keeps each step where the linearisation along the previous plan "
    "holds: leaving it costs 10 per rad^2 of heading and (m/s)^2 of velocity",
    ControllerType.NMPC: "each real-time SQP step's heading change costs 5 per rad^2, as much "
    "as a heading error under the default Q: a corner's turn is taken over several steps "
    "instead of one linearised jump (docs/recovery.md)",
}

# The cost of moving one thruster by half its range in one sample, in units of the stage cost
# (Q = 5 per m^2: as much as 0.14 m of position error for one sample). Measured with
# benchmarks/generality.py on the fully actuated presets: 1 left the BlueROV2 0.050 m off at
# the oval's curvature jumps (ideal), 0.1 0.035 m, with the disturbed runs unchanged (RMS
# 0.014-0.016 m); on 12 random vehicles, disturbed (vehicle_sweep.py --disturbed), 0.1, 1
# and 10 gave median RMS 0.022, 0.018, 0.021 m and lost the same one (docs/tuning.md).
THRUST_MOVE_COST = 0.1


def default_thrust_weights(model: VehicleParams) -> tuple[float, ...]:
    """R when the scenario gives none: THRUST_MOVE_COST / h^2 per thruster, h half the
    thrust range, so the weight means the same on a 15 N and an 800 N thruster."""
    half_range = (model.thrust_max - model.thrust_min) / 2.0
    return (THRUST_MOVE_COST / half_range**2,) * model.n_thrusters


# Speeds up to which an automatically chosen model step keeps RK4 stable (m/s, rad/s):
# above the operating range of the presets, below their extremes.
_STABILITY_SPEED = 1.5
_STABILITY_YAW_RATE = 1.0


def stable_model_substeps(model: VehicleParams, sample_time: float) -> int:
    """Fewest RK4 steps per sample that stay stable for the model's damping
    (vehicle.damping_rates) up to 1.5 m/s and 1 rad/s.

    One 0.5 s step suits the paper vehicle (rate 3.8 /s); the BlueROV2's strong
    quadratic damping (rate 32 /s in sway at 1.5 m/s) needs seven.
    """
    rates = damping_rates(model, _STABILITY_SPEED, _STABILITY_SPEED, _STABILITY_YAW_RATE)
    return max(1, math.ceil(sample_time * max(rates) / RK4_STABLE_STEP))


BLOCKED_MOVES = (0, 1, 2, 3, 5, 7, 10, 14, 19, 25)

# The controller type of depth scenarios (``kind: depth``); ``ControllerType`` names the
# horizontal ones, so each kind refuses the other's controllers at validation.
DEPTH_MPC = "depth-mpc"


class DepthChannelConfig(TypedControllerConfig):
    """What every depth controller's configuration holds (a depth scenario's ``controller``,
    a 6-DOF scenario's ``depth_controller``): its type and its sample time. The depth MPC's
    configuration (controllers/depth_mpc.py) and thrust-playback's (controllers/playback.py)
    add their own knobs; the mapping is one of them, chosen by ``type``
    (controllers/registry.py)."""

    type: str = Field(description="depth controller")
    sample_time: Positive = Field(default=0.1, description="Te (s)")

    @classmethod
    def _knob_owners(cls, knob: str) -> list[str]:
        from auvmpc.controllers.registry import knob_owners

        return knob_owners(knob, cls)

    def for_vehicle(self, model: VehicleParams) -> DepthChannelConfig:
        """Nothing is left to fill in for a vehicle (the registry asks every config)."""
        return self


CONTROLLER_PRESETS: dict[str, tuple[str, ...]] = {
    "baseline": ("controller.type=baseline",),
    "mpc": ("controller.type=mpc", "controller.control_horizon=2"),
    "mpc-nc30": ("controller.type=mpc", "controller.control_horizon=30"),  # = ny of paper-*
    "ltv-mpc": ("controller.type=ltv-mpc", "controller.control_horizon=2"),
    "ltv-mpc-nc30": ("controller.type=ltv-mpc", "controller.control_horizon=30"),
    "ltv-mpc-offset-free": (
        "controller.type=ltv-mpc",
        "controller.control_horizon=30",
        "controller.offset_free=true",
    ),
    # Move blocking: 10 moves spread over the 30-step horizon (finer early, where they act).
    "ltv-mpc-blocked": ("controller.type=ltv-mpc", f"controller.move_steps={list(BLOCKED_MOVES)}"),
    "nmpc": (
        "controller.type=nmpc",
        "controller.nmpc_mode=real-time",
        "controller.control_horizon=30",
    ),
    "nmpc-full": (
        "controller.type=nmpc",
        "controller.nmpc_mode=full",
        "controller.control_horizon=30",
    ),
    "do-mpc": ("controller.type=do-mpc", "controller.control_horizon=30"),
    "do-mpc-blocked": ("controller.type=do-mpc", f"controller.move_steps={list(BLOCKED_MOVES)}"),
}
"""Controller labels and the scenario overrides that select them. ``mpc`` is the paper's
controller (ny from the scenario, nc 2); ``-nc30`` frees every move of a 30-step horizon;
other settings come from the scenario."""


def __getattr__(name: str) -> Any:
    """``BaselineConfig``, the baseline's gains, as before they moved next to it (baseline.py
    imports this module, so it cannot be imported here)."""
    if name == "BaselineConfig":
        from auvmpc.controllers.baseline import BaselineConfig

        return BaselineConfig
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
