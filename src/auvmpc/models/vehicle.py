"""Vehicle parameters, thrust allocation and the 3-DOF horizontal-plane model.

This module is the single source of truth for the plant equations (Fossen 2021,
Ch. 6, restated in ``shared/spec/paper-model.md`` section 1):

    x'   = u cos(psi) - v sin(psi)
    y'   = u sin(psi) + v cos(psi)
    psi' = r
    m11 u' = Xu u + Xuu |u| u + m22 v r + f_u + d_u
    m22 v' = Yv v + Yvv |v| v - m11 u r + f_v + d_v
    Iz  r' = Nr r + Nrr |r| r + (m11 - m22) u v + M_r + d_r

State ``[x, y, psi, u, v, r]``: world position (m), heading (rad), body surge
and sway (m/s), yaw rate (rad/s). Body frame x forward, y starboard. Input: one
force per thruster (N); ``tau = [f_u, f_v, M_r] = T @ F``. ``d`` is the external
force in the body frame. The same function evaluates on NumPy arrays (plant
simulation) and on CasADi symbols (controller models).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from functools import cached_property
from importlib import resources
from pathlib import Path
from typing import Annotated, Any, Protocol

import casadi as ca
import numpy as np
from pydantic import (
    AfterValidator,
    ConfigDict,
    Field,
    SerializerFunctionWrapHandler,
    ValidationError,
    model_serializer,
    model_validator,
)

from auvmpc.config import StrictModel
from auvmpc.errors import ConfigError, FieldError, format_validation_error
from auvmpc.models.actuators import WRENCH, ActuatorSet, FixedThruster
from auvmpc.models.actuators.entries import ActuatorEntry
from auvmpc.models.actuators.thruster import planar_direction, thrust_column
from auvmpc.models.layout import HORIZONTAL, PLANAR_FORCE
from auvmpc.models.six_dof_params import SixDofParams, horizontal_equivalent
from auvmpc.safe_yaml import read_text_file, read_yaml_mapping

__all__ = [
    "STATE_NAMES",
    "Thruster",
    "VehicleParams",
    "VehicleSize",
    "allocation_matrix",
    "allocation_rank",
    "check_plant_scale",
    "body_from_world",
    "dynamics",
    "HeaveParams",
    "load_vehicle",
    "preset_names",
    "scaled",
    "steady_speed",
    "thruster_preset_names",
    "top_yaw_rate",
    "heading_turn_time",
    "turn_up_time",
    "HorizontalCoefficients",
    "validated_vehicle",
    "vehicle_data",
    "velocity_derivative",
    "yaw_damping_moment",
]

STATE_NAMES = HORIZONTAL.names  # the state order of the equations above
NX = HORIZONTAL.size
# The 3-DOF model's force [f_u, f_v, M_r] is the body wrench's X, Y and N rows.
PLANAR_ROWS = PLANAR_FORCE.names
_PLANAR_INDEX = [WRENCH.index(name) for name in PLANAR_ROWS]

PositiveFloat = Annotated[float, Field(gt=0)]
Damping = Annotated[
    float, Field(le=0, description="damping coefficient (Fossen: negative or zero)")
]


class Thruster(StrictModel):
    """A horizontal thruster: where it sits and which way it pushes (body frame)."""

    position: tuple[float, float] = Field(description="(x forward, y starboard) in m")
    angle_deg: float = Field(description="thrust direction, deg from +x towards +y")


def _ordered_limits(limits: tuple[float, float]) -> tuple[float, float]:
    if not limits[0] < limits[1]:
        raise ValueError(f"need min < max, got {list(limits)}")
    return limits


ThrustLimits = Annotated[tuple[float, float], AfterValidator(_ordered_limits)]


class HeaveParams(StrictModel):
    """1-DOF heave model (paper-model.md section 8); z up, negative below the surface.

    m_heave w' = Zw w + Zww |w| w + sum(F_z) + net_buoyancy_N + d_z,   z' = w
    """

    m_heave: PositiveFloat = Field(description="heave mass incl. added mass, m - Z_wdot (kg)")
    Zw: Damping = Field(description="linear heave damping (N s/m)")
    Zww: Damping = Field(description="quadratic heave damping (N s2/m2)")
    net_buoyancy_N: float = Field(
        description="buoyancy minus weight (N): positive floats up, negative sinks"
    )
    thruster_count: int = Field(ge=1, description="number of vertical thrusters")
    thrust_limits: ThrustLimits = Field(description="per vertical thruster [min, max] (N)")
    thrust_rate_limit: PositiveFloat = Field(description="per vertical thruster (N/s)")

    @cached_property
    def actuators(self) -> ActuatorSet:
        """The vertical thrusters ``Fz1..Fzn``, each pushing straight up (NED -z) through the
        body origin: the heave model's force is their sum."""
        lower, upper = self.thrust_limits
        return ActuatorSet(tuple(
            FixedThruster(f"Fz{i + 1}", (0.0, 0.0, 0.0), (0.0, 0.0, -1.0), lower, upper,
                          self.thrust_rate_limit)
            for i in range(self.thruster_count)
        ))  # fmt: skip


class VehicleSize(StrictModel):
    """The hull's outer envelope: the smallest box round the vehicle, body axes (m).

    Optional in a vehicle file and read by no model: it documents the vehicle, is what
    ``auvmpc vehicle new`` estimates a model from, sets ``controller.vehicle_radius`` when a
    scenario omits it (controllers/config.py, default_vehicle_radius), and its ``length`` is
    the vehicle length the run verdict scales with (``auvmpc.sim.verdict``)."""

    length: PositiveFloat = Field(description="along x, forward (m)")
    width: PositiveFloat = Field(description="along y, starboard (m)")
    height: PositiveFloat = Field(description="along z, down (m)")


class VehicleParams(StrictModel):
    """Everything the 3-DOF model needs, validated and immutable; with ``actuators`` (a
    propeller and fins) the 3-DOF coefficients m11 ... Nrr may be omitted: they are read off
    ``six_dof``.

    Field names follow ``shared/spec/interfaces.md`` (the vehicle file contract). A vehicle
    is driven either by fixed ``thrusters`` (with ``thrust_limits``, ``thrust_rate_limit`` and,
    for depth, ``heave``) or by an ``actuators:`` list of kinds (a propeller and fins: a
    torpedo AUV), which only the 6-DOF model flies: its 3-DOF coefficients may then be
    omitted, read off ``six_dof`` (:func:`horizontal_equivalent`), and everything made of
    fixed thrusters (``T``, ``actuators``, ``n_thrusters``, ...) refuses it in one line.
    """

    # The 3-DOF coefficients are required unless ``actuators`` is given (then read off
    # six_dof, _horizontal_from_six_dof): a JSON schema cannot say "unless", so it lists them
    # as optional and the loader says which is missing.
    model_config = ConfigDict(
        json_schema_extra=lambda schema: schema.update(
            required=[n for n in schema.get("required", []) if n not in HORIZONTAL_MODEL_FIELDS]
        )
    )

    name: str = Field(description="short identifier")
    description: str = Field(default="", description="one line for humans")
    source: str = Field(default="", description="where the numbers come from")
    estimated: tuple[str, ...] = Field(
        default=(), description="fields whose values are estimates, not published data"
    )
    mass: PositiveFloat = Field(description="rigid-body mass (kg)")
    size: VehicleSize | None = Field(
        default=None,
        description="outer envelope {length, width, height} (m), if known; no model reads "
        "it; an omitted controller.vehicle_radius is half its length x width diagonal, the "
        "run verdict scales with its length",
    )
    m11: PositiveFloat = Field(description="surge mass incl. added mass, m - X_udot (kg)")
    m22: PositiveFloat = Field(description="sway mass incl. added mass, m - Y_vdot (kg)")
    Iz_rb: PositiveFloat = Field(description="rigid-body yaw inertia (kg m2)")
    Iz_added: Annotated[float, Field(ge=0)] = Field(
        description="added yaw inertia, -N_rdot (kg m2)"
    )
    Xu: Damping = Field(description="linear surge damping (N s/m)")
    Xuu: Damping = Field(description="quadratic surge damping (N s2/m2)")
    Yv: Damping = Field(description="linear sway damping (N s/m)")
    Yvv: Damping = Field(description="quadratic sway damping (N s2/m2)")
    Nr: Damping = Field(description="linear yaw damping (N m s)")
    Nrr: Damping = Field(description="quadratic yaw damping (N m s2)")
    thrusters: tuple[Thruster, ...] | None = Field(
        default=None,
        min_length=2,
        description="horizontal thrusters; fewer than three independent directions make the "
        "vehicle underactuated (``underactuated``); required unless ``actuators`` is given",
    )
    thrust_limits: ThrustLimits | None = Field(
        default=None, description="per thruster [min, max], required with ``thrusters`` (N)"
    )
    thrust_rate_limit: PositiveFloat | None = Field(
        default=None, description="per thruster |dF/dt| bound, required with ``thrusters`` (N/s)"
    )
    heave: HeaveParams | None = Field(default=None, description="depth model, if any")
    six_dof: SixDofParams | None = Field(
        default=None,
        description="6-DOF model (3-D thruster poses, hydrodynamics), if any; not needed "
        "for 3-DOF and depth scenarios; required with ``actuators``",
    )
    # The file's key is ``actuators``; the attribute of that name is the 3-DOF input set.
    actuator_entries: tuple[ActuatorEntry, ...] | None = Field(
        default=None,
        alias="actuators",
        min_length=1,
        description="the 6-DOF inputs as actuators of several kinds (propeller, "
        "control_surface: auvmpc.models.actuators.entries), in input order, instead of "
        "thrusters; each input named by its ``name`` and in its own units (rpm, deg)",
    )

    @model_validator(mode="before")
    @classmethod
    def _horizontal_from_six_dof(cls, data: Any) -> Any:
        """A vehicle with ``actuators`` flies only the 6-DOF model: its omitted 3-DOF
        coefficients are those the six_dof section implies (they feed only what reads a
        vehicle's scale, e.g. the default sample time)."""
        if not isinstance(data, Mapping) or data.get("actuators") is None:
            return data
        if data.get("six_dof") is None:
            raise FieldError("six_dof", None,
                             "missing: a vehicle with actuators (a propeller, fins) is flown "
                             "by its 6-DOF model, which needs the six_dof section")  # fmt: skip
        mass = data.get("mass")
        if not isinstance(mass, int | float) or isinstance(mass, bool) or not mass > 0:
            return data  # the field's own check names it
        try:
            six = SixDofParams.model_validate(data["six_dof"])
        except ValidationError as error:
            problem = format_validation_error(error, "six_dof")
            raise FieldError(problem.field, problem.value, problem.reason) from None
        implied = horizontal_equivalent(float(mass), six)
        return {**{name: implied[name] for name in HORIZONTAL_MODEL_FIELDS}, **data}

    @model_serializer(mode="wrap")
    def _dump(self, handler: SerializerFunctionWrapHandler) -> dict[str, Any]:
        """The fields under the file's keys; ``actuators`` only when given, so a thruster
        vehicle's dump (run.json's ``model``, the compiled-model cache key) is as before."""
        data = handler(self)
        entries = data.pop("actuator_entries", None)
        if entries is not None:
            data["actuators"] = entries
        return data

    @model_validator(mode="after")
    def _driven(self) -> VehicleParams:
        """Thrusters or actuators, never both, and what each needs."""
        if self.actuator_entries is None:
            for field in ("thrusters", "thrust_limits", "thrust_rate_limit"):
                if getattr(self, field) is None:
                    raise FieldError(field, None, "field required (or give actuators: a "
                                     "propeller and fins)")  # fmt: skip
            if self.six_dof is not None and not self.six_dof.thrusters:
                raise FieldError("six_dof.thrusters", [], "need at least 1 thruster")
            return self
        for field in ("thrusters", "thrust_limits", "thrust_rate_limit", "heave"):
            if getattr(self, field) is not None:
                raise FieldError(field, "given", "not used with actuators: the vehicle's "
                                 "inputs are its actuators (remove one or the other)")  # fmt: skip
        if self.six_dof is not None and self.six_dof.thrusters:
            raise FieldError("six_dof.thrusters", len(self.six_dof.thrusters),
                             "not used with actuators: they are the 6-DOF inputs")  # fmt: skip
        names = [entry.name for entry in self.actuator_entries]
        if len(set(names)) != len(names):
            raise FieldError("actuators", names, "input names must differ")
        return self

    @model_validator(mode="after")
    def _rigid_body(self) -> VehicleParams:
        # M_RB is positive definite iff the inertia about the centre of gravity is; the
        # section alone cannot check this, it does not know the mass.
        if self.six_dof is not None:
            mass_matrix = self.six_dof.mass_matrix(self.mass)
            if np.min(np.linalg.eigvalsh(mass_matrix)) <= 0:
                raise FieldError(
                    "six_dof.inertia",
                    self.six_dof.inertia,
                    "the mass matrix M_RB + M_A is not positive definite: the inertia about "
                    "the centre of gravity (I_b + m S(r_g)^2) must be",
                )
        return self

    @model_validator(mode="after")
    def _steerable(self) -> VehicleParams:
        if self.thrusters is None:
            return self  # actuators instead (_driven)
        rank = allocation_rank(allocation_matrix(self.thrusters))
        if rank < 2:
            raise FieldError(
                "thrusters",
                [t.model_dump() for t in self.thrusters],
                f"the layout spans only {rank} of surge, sway and yaw (need at least 2: "
                "a vehicle must be able to push and turn)",
            )
        return self

    def check_six_dof_layout(self) -> None:
        """Raise FieldError unless the six_dof thrusters start with the horizontal ones, in
        order, and the rest are the heave section's. The 6-DOF loop sends the horizontal
        controller's command to the first and the depth controller's to the rest: otherwise
        every command goes to the wrong thruster (a review swapped two and the run still
        "worked", 1.6 m off). Checked where a 6-DOF plant is used, so a file whose 3-DOF
        thrusters were edited still serves 3-DOF and depth scenarios."""
        six = self.six_dof
        if six is None:
            return
        n = len(self.fixed_thrusters("the split into horizontal and depth controllers"))
        planar = six.T[np.ix_(_PLANAR_INDEX, range(min(n, six.n_thrusters)))]
        if six.n_thrusters < n or not np.allclose(
            planar, allocation_matrix(self.thrusters), atol=THRUSTER_LAYOUT_TOL
        ):
            raise FieldError(
                "six_dof.thrusters",
                six.n_thrusters,
                f"the first {n} must be the horizontal thrusters of 'thrusters', in that order "
                "(same surge, sway and yaw columns)",
            )
        vertical = six.n_thrusters - n
        if self.heave is not None and vertical != self.heave.thruster_count:
            raise FieldError(
                "six_dof.thrusters",
                six.n_thrusters,
                f"{vertical} after the {n} horizontal ones, but heave.thruster_count is "
                f"{self.heave.thruster_count}",
            )

    @cached_property  # asked by the controllers every step (ocp/underactuated_reference.py)
    def underactuated(self) -> bool:
        """True when the thrusters cannot make every body-frame force and moment
        (allocation rank < 3), e.g. two stern thrusters: no sway force."""
        return allocation_rank(self.T) < 3

    @cached_property
    def unactuated_direction(self) -> np.ndarray | None:
        """Unit [f_u, f_v, M_r] direction no thrust combination can produce (orthogonal to
        the allocation's range), or None for a fully actuated vehicle."""
        if not self.underactuated:
            return None
        left, _, _ = np.linalg.svd(self.T)
        direction = left[:, -1] * np.sign(left[np.argmax(np.abs(left[:, -1])), -1])
        direction.setflags(write=False)
        return direction

    def describe_actuation(self) -> str:
        """'fully actuated', or which direction is missing, e.g. 'underactuated: no sway'."""
        direction = self.unactuated_direction
        if direction is None:
            return "fully actuated"
        axis = int(np.argmax(np.abs(direction)))
        if abs(direction[axis]) > 1.0 - 1e-9:
            return f"underactuated: no {('surge', 'sway', 'yaw')[axis]}"
        names = ("surge", "sway", "yaw")
        mix = ", ".join(f"{v:+.2f} {n}" for v, n in zip(direction, names, strict=True))
        return f"underactuated: no {mix}"

    def require_full_actuation(self, controller: str, why: str) -> None:
        """Raise ConfigError (one line, exit 2 from the CLI) if this vehicle is
        underactuated; ``controller`` and ``why`` say who needs full actuation and why."""
        if self.underactuated:
            raise ConfigError(
                "vehicle",
                self.name,
                f"{self.describe_actuation()}; controller {controller} needs full actuation "
                f"({why}); use ltv-mpc or nmpc",
            )

    @property
    def Iz(self) -> float:
        """Total yaw inertia, rigid body plus added (kg m2)."""
        return self.Iz_rb + self.Iz_added

    @property
    def has_thrusters(self) -> bool:
        """Whether fixed thrusters drive it (else an ``actuators:`` list of kinds)."""
        return self.actuator_entries is None

    def fixed_thrusters(self, needed_by: str) -> tuple[Thruster, ...]:
        """The horizontal thrusters; ConfigError (one line, exit 2) naming the vehicle if
        it has actuators of other kinds instead, ``needed_by`` saying what needed them."""
        if self.thrusters is None or self.thrust_limits is None:
            kinds = ", ".join(f"{e.name} ({e.kind})" for e in self.actuator_entries or ())
            raise ConfigError(
                "vehicle",
                self.name,
                f"has a propeller and fins, not fixed thrusters (actuators: {kinds}); "
                f"{needed_by} needs thrusters; its controller is six-dof-nmpc on the 6-DOF "
                "model, in a kind: six-dof scenario (docs/remus100.md)",
            )
        return self.thrusters

    @property
    def n_thrusters(self) -> int:
        return len(self.fixed_thrusters("a thruster count"))

    @cached_property
    def actuators(self) -> ActuatorSet:
        """The horizontal thrusters ``F1..Fn`` (the 3-DOF model's inputs) with their limits."""
        thrusters = self.fixed_thrusters("the 3-DOF model (its inputs)")
        lower, upper = self.thrust_limits
        return ActuatorSet(tuple(
            FixedThruster.planar(f"F{i + 1}", t.position, t.angle_deg, lower=lower, upper=upper,
                                 rate=self.thrust_rate_limit)
            for i, t in enumerate(thrusters)
        ))  # fmt: skip

    def with_actuators(self, actuators: ActuatorSet) -> VehicleParams:
        """This vehicle with other horizontal actuators, one per ``thrusters`` entry (a kind
        of your own: docs/extending.md). The 3-DOF model reads them; ``T`` and what is
        derived from it exist only for a set that is linear in its commands."""
        if actuators.size != self.n_thrusters:
            raise FieldError("actuators", actuators.layout.names,
                             f"need one per thruster ({self.n_thrusters})")  # fmt: skip
        copied = self.model_copy()
        copied.__dict__["actuators"] = actuators  # where the cached property keeps its value
        return copied

    @cached_property
    def six_dof_actuators(self) -> ActuatorSet:
        """The 6-DOF model's inputs: the ``actuators`` entries as they are, or ``F1..Fn``, the
        ``six_dof`` thrusters, the horizontal ones first with the horizontal limits, then the
        vertical ones with the heave section's (check_six_dof_layout)."""
        six = self.six_dof
        if six is not None and self.actuator_entries is not None:
            return ActuatorSet(tuple(entry.build() for entry in self.actuator_entries))
        if six is None or self.heave is None:
            raise FieldError("vehicle", self.name, "needs six_dof and heave sections")
        limits = [self.actuators.actuators[0], self.heave.actuators.actuators[0]]
        return ActuatorSet(tuple(
            FixedThruster(f"F{i + 1}", thruster.position, tuple(thruster.unit_direction),
                          **_limits_of(limits[i >= self.n_thrusters]))
            for i, thruster in enumerate(six.thrusters)
        ))  # fmt: skip

    @property
    def T(self) -> np.ndarray:
        """Allocation matrix (3, n): tau = [f_u, f_v, M_r] = T @ F."""
        return self.actuators.allocation(PLANAR_ROWS)

    @cached_property
    def T_pinv(self) -> np.ndarray:
        """Minimum-norm allocation (n, 3): F = T_pinv @ tau."""
        matrix = np.linalg.pinv(self.T)
        matrix.setflags(write=False)
        return matrix

    @cached_property
    def thrust_authority(self) -> np.ndarray:
        """The largest f_u, f_v (N) and M_r (N m) each axis can get on its own within the
        thrust limits (3,), in the positive direction, each thruster at whichever limit
        helps: the vehicle's own force scale (with asymmetric limits the negative direction
        may be weaker)."""
        T = self.T
        authority = np.maximum(T * self.thrust_max, T * self.thrust_min).sum(axis=1)
        authority.setflags(write=False)
        return authority

    @property
    def thrust_min(self) -> float:
        self.fixed_thrusters("a thrust limit")
        return self.thrust_limits[0]

    @property
    def thrust_max(self) -> float:
        self.fixed_thrusters("a thrust limit")
        return self.thrust_limits[1]


# RK4 is stable for h * lambda up to 2.785 on the negative real axis; keep a margin.
RK4_STABLE_STEP = 2.5


def damping_rates(params: VehicleParams, surge: float, sway: float, yaw_rate: float) -> tuple:
    """How fast each axis's damping acts at the given speeds (m/s) and yaw rate (rad/s):
    |D + 2 D_q s| / M (1/s), the linearised quadratic damping over the inertia. An RK4 step
    of length h is stable while h times the largest is below 2.785."""
    return (
        abs(params.Xu + 2.0 * params.Xuu * surge) / params.m11,
        abs(params.Yv + 2.0 * params.Yvv * sway) / params.m22,
        abs(params.Nr + 2.0 * params.Nrr * yaw_rate) / params.Iz,
    )


def stable_plant_step(params: VehicleParams, longest: float) -> float:
    """The longest RK4 step (at most ``longest``) that stays stable over everything the
    thrusters can do: each axis at the steady speed its full thrust authority reaches.

    A light yaw inertia with strong thrusters (a 16 kg random vehicle: 0.28 kg m2, 200 N)
    spins at 8 rad/s, where a 0.05 s step diverged; every preset keeps 0.05 s.
    """
    tops = [
        steady_speed(linear, quadratic, force)
        for linear, quadratic, force in zip(
            (params.Xu, params.Yv, params.Nr),
            (params.Xuu, params.Yvv, params.Nrr),
            params.thrust_authority,
            strict=True,
        )
    ]
    return min(longest, RK4_STABLE_STEP / max(damping_rates(params, *tops)))


def steady_speed(linear: float, quadratic: float, force: float) -> float:
    """Where |linear| s + |quadratic| s^2 = force (damping coefficients are <= 0)."""
    a, b = -quadratic, -linear
    if a > 0:
        return (-b + math.sqrt(b * b + 4.0 * a * force)) / (2.0 * a)
    return force / b if b > 0 else math.inf


def top_yaw_rate(params: VehicleParams) -> float:
    """The steady yaw rate under the largest yaw moment the thrusters can make (rad/s):
    |Nrr| r^2 + |Nr| r = M_max. Infinite for a vehicle without yaw damping."""
    return steady_speed(params.Nr, params.Nrr, float(params.thrust_authority[2]))


class HorizontalCoefficients(Protocol):
    """What the 3-DOF velocity equations read: a VehicleParams, or the same names bound to
    other values (CasADi symbols while a vehicle is identified from its log)."""

    m11: Any
    m22: Any
    Iz: Any
    Xu: Any
    Xuu: Any
    Yv: Any
    Yvv: Any
    Nr: Any
    Nrr: Any


def yaw_damping_moment(params: HorizontalCoefficients, yaw_rate, absolute=abs):
    """The yaw damping moment at ``yaw_rate`` (N m, opposing it): Nr r + Nrr |r| r.
    ``absolute``: ``abs`` for numbers, ``ca.fabs`` for CasADi expressions."""
    return params.Nr * yaw_rate + params.Nrr * absolute(yaw_rate) * yaw_rate


def heading_turn_time(params: VehicleParams, angle_rad: float) -> float:
    """The least time the largest yaw moment needs to turn the vehicle by ``angle_rad`` (s):
    angle / r_top at its top yaw rate; without yaw damping (no top rate) from rest,
    sqrt(2 angle Iz / M_max); infinite for a vehicle that makes no yaw moment."""
    moment = float(params.thrust_authority[2])
    if moment <= 0.0:
        return math.inf
    rate = top_yaw_rate(params)
    if math.isinf(rate):
        return math.sqrt(2.0 * angle_rad * params.Iz / moment)
    return angle_rad / rate


def turn_up_time(params: VehicleParams) -> float:
    """How long the largest yaw moment takes to spin the vehicle up to its top yaw rate
    from rest, damping aside (s): Iz r_top / M_max. The fastest thing an underactuated
    vehicle steers with (0.08 s for the VideoRay and the BlueROV2, 0.27 s for jmse2210);
    infinite for a vehicle that makes no yaw moment."""
    moment = float(params.thrust_authority[2])
    return params.Iz * top_yaw_rate(params) / moment if moment > 0.0 else math.inf


# How closely a six_dof thruster must reproduce its 3-DOF allocation column (N per N, N m
# per N): positions in mm and directions to 4 decimals, far coarser than round-off.
THRUSTER_LAYOUT_TOL = 1e-3


# Singular values below this fraction of the largest count as zero in the allocation rank:
# thruster angles are given in degrees to a few decimals, far coarser than round-off.
ALLOCATION_RANK_TOL = 1e-9


def allocation_rank(matrix: np.ndarray) -> int:
    """Number of independent body-frame directions an allocation matrix (3, n) can make."""
    singular = np.linalg.svd(matrix, compute_uv=False)
    return int(np.sum(singular > ALLOCATION_RANK_TOL * singular[0])) if singular[0] > 0 else 0


def allocation_matrix(thrusters: tuple[Thruster, ...] | list[Thruster]) -> np.ndarray:
    """Columns [cos a, sin a, px sin a - py cos a] per thruster (interfaces.md): the X, Y, N
    rows of each one's wrench."""
    columns = [
        thrust_column((*thruster.position, 0.0), planar_direction(thruster.angle_deg))
        for thruster in thrusters
    ]
    return np.array(columns, dtype=float)[:, _PLANAR_INDEX].T


def _limits_of(actuator: FixedThruster) -> dict[str, float]:
    return {"lower": actuator.lower, "upper": actuator.upper, "rate": actuator.rate}


def body_from_world(force_world, psi):
    """Rotate a world-frame planar force (X, Y) into the body frame at heading psi.

    Returns ``(d_u, d_v)`` with d_u = X cos psi + Y sin psi, d_v = -X sin psi + Y cos psi.
    """
    fx, fy = force_world[0], force_world[1]
    cos_psi, sin_psi = _cos(psi), _sin(psi)
    return fx * cos_psi + fy * sin_psi, -fx * sin_psi + fy * cos_psi


def velocity_derivative(p: HorizontalCoefficients, u_r, v_r, r, tau, absolute=abs):
    """(u', v', r') of the 3-DOF model (module docstring) at the velocity (u_r, v_r) through
    the water and yaw rate r under the body force ``tau`` = (X, Y, N), without the current's
    turning terms: the one statement of the velocity equations, numbers, arrays or CasADi
    (``absolute``: ``abs``, ``np.abs`` or ``ca.fabs``)."""
    u_dot = (p.Xu * u_r + p.Xuu * absolute(u_r) * u_r + p.m22 * v_r * r + tau[0]) / p.m11
    v_dot = (p.Yv * v_r + p.Yvv * absolute(v_r) * v_r - p.m11 * u_r * r + tau[1]) / p.m22
    r_dot = (yaw_damping_moment(p, r, absolute) + (p.m11 - p.m22) * u_r * v_r + tau[2]) / p.Iz
    return u_dot, v_dot, r_dot


def dynamics(
    state, thrust, params: VehicleParams, disturbance_body=None, current_world=None,
    effectiveness=None,
):  # fmt: skip
    """State derivative of the 3-DOF model (module docstring).

    Parameters
    ----------
    state : (6,) array or CasADi column
    thrust : (n,) array or CasADi column, one force per thruster (N)
    params : VehicleParams
    disturbance_body : (3,) [d_u, d_v, d_r] or None
    current_world : (2,) water velocity (V_x, V_y) in the world frame (m/s), or None
    effectiveness : (n,) each thruster's share of its force that acts (1 healthy), or None

    Returns
    -------
    (6,) NumPy array for numeric input, CasADi column for symbolic input.

    Notes
    -----
    A current acts through the relative velocity u_r = u - u_c, v_r = v - v_c, with
    (u_c, v_c) the current in the body frame (Fossen 2021, sec. 6.5; six-dof.md): damping
    and the Coriolis-centripetal terms see (u_r, v_r), and since the body turns under a
    current fixed in the world, u_c' = r v_c and v_c' = -r u_c are added to u', v'. This is
    the 6-DOF model's horizontal rows (``auvmpc.models.six_dof``) with w = p = q = 0 and the
    current held constant (as over one plant step). Without one, the original equations.
    """
    symbolic = isinstance(state, ca.SX | ca.MX) or isinstance(thrust, ca.SX | ca.MX)
    _, _, psi, u, v, r = (state[i] for i in range(NX))
    if symbolic:
        cos_psi, sin_psi, absolute = ca.cos(psi), ca.sin(psi), ca.fabs
    else:
        # NumPy's functions: a state of arrays evaluates many states at once.
        cos_psi, sin_psi, absolute = np.cos(psi), np.sin(psi), np.abs
    if current_world is None:
        u_r, v_r = u, v
    else:
        u_c, v_c = body_from_world(current_world, psi)
        u_r, v_r = u - u_c, v - v_c
    nu_r = (u_r, v_r, 0.0, 0.0, 0.0, r)
    tau = params.actuators.force(nu_r, thrust, PLANAR_ROWS, effectiveness)
    tau_u, tau_v, tau_r = tau[0], tau[1], tau[2]
    if disturbance_body is not None:
        tau_u = tau_u + disturbance_body[0]
        tau_v = tau_v + disturbance_body[1]
        tau_r = tau_r + disturbance_body[2]
    u_dot, v_dot, r_dot = velocity_derivative(params, u_r, v_r, r, (tau_u, tau_v, tau_r), absolute)
    if current_world is not None:
        u_dot, v_dot = u_dot + r * v_c, v_dot - r * u_c
    derivative = (
        u * cos_psi - v * sin_psi,
        u * sin_psi + v * cos_psi,
        r,
        u_dot,
        v_dot,
        r_dot,
    )
    if symbolic:
        return ca.vertcat(*derivative)
    return np.array(np.broadcast_arrays(*derivative), dtype=float)


def _cos(angle):
    return ca.cos(angle) if isinstance(angle, ca.SX | ca.MX) else np.cos(angle)


def _sin(angle):
    return ca.sin(angle) if isinstance(angle, ca.SX | ca.MX) else np.sin(angle)


# What the simulated 6-DOF plant reads from a vehicle's six_dof section that a model error
# scales (each entry of the vector or matrix by the factor); ``mass`` also sets the weight
# (a 20 % heavier vehicle would sink), so the 6-DOF plant's mass is not scaled.
SIX_DOF_MODEL_FIELDS = ("inertia", "added_mass", "linear_damping", "quadratic_damping")

# Fields a scenario's ``plant.scale`` may multiply (scalars; thrust_limits scales both ends;
# the six_dof section's every entry).
SCALABLE_FIELDS = (
    "mass", "m11", "m22", "Iz_rb", "Iz_added", "Xu", "Xuu", "Yv", "Yvv", "Nr", "Nrr",
    "thrust_limits", "thrust_rate_limit", *SIX_DOF_MODEL_FIELDS,
)  # fmt: skip


# What the simulated 3-DOF plant reads from a vehicle (``dynamics``); the thrust limits are
# the controller's (the plant applies each command as given), ``mass`` only the depth model's.
HORIZONTAL_MODEL_FIELDS = ("m11", "m22", "Iz_rb", "Iz_added", "Xu", "Xuu", "Yv", "Yvv", "Nr", "Nrr")
HEAVE_MODEL_FIELDS = ("m_heave", "Zw", "Zww", "net_buoyancy_N", "thrust_rate_limit")


def check_plant_scale(scale: Mapping[str, float], kind: str = "horizontal") -> None:
    """A ``plant.scale`` factor on a field the simulated model does not use has no effect,
    so it is an error that says which model uses what (``kind``: the plant's, "horizontal",
    "depth" or "six-dof")."""
    used = {"horizontal": HORIZONTAL_MODEL_FIELDS, "six-dof": SIX_DOF_MODEL_FIELDS}.get(
        kind, HEAVE_MODEL_FIELDS
    )
    for field, factor in scale.items():
        if field in used:
            continue
        if kind == "six-dof":
            reason = (
                f"the 6-DOF plant simulates the vehicle's six_dof section: scale one of "
                f"{list(SIX_DOF_MODEL_FIELDS)} (each entry; mass also sets the weight, which "
                "would sink or float the vehicle)"
            )
        elif field in SIX_DOF_MODEL_FIELDS:
            reason = f"a six_dof section field: only the 6-DOF plant (kind: six-dof) uses {field}"
        elif kind == "horizontal" and field in ("thrust_limits", "thrust_rate_limit"):
            reason = (
                f"{field} is the controller's limit, not the plant's (the simulated thrusters "
                f"apply each command as given); change vehicle.{field} instead"
            )
        elif kind == "horizontal" and field in VehicleParams.model_fields:
            reason = (
                f"the horizontal (3-DOF) model does not use {field}: it uses "
                f"{', '.join(HORIZONTAL_MODEL_FIELDS)} (masses and inertias incl. added mass, "
                "damping); mass is used by depth scenarios only"
            )
        elif kind == "horizontal":
            reason = (
                "not a scalable field (not a vehicle field); the horizontal model uses "
                f"{list(HORIZONTAL_MODEL_FIELDS)}"
            )
        else:
            reason = (
                f"the depth (heave) model does not use {field}: it uses the vehicle's heave "
                f"section {list(HEAVE_MODEL_FIELDS)}"
            )
        raise ConfigError(f"plant.scale.{field}", factor, reason)


def scaled(params: VehicleParams, scale: Mapping[str, float]) -> VehicleParams:
    """A copy of ``params`` with named fields multiplied by the given factors."""
    changes: dict[str, Any] = {}
    for field, factor in scale.items():
        if field not in SCALABLE_FIELDS:
            raise ConfigError(
                f"plant.scale.{field}",
                factor,
                f"not a scalable field; one of {list(SCALABLE_FIELDS)}",
            )
        if not (math.isfinite(factor) and factor > 0):
            raise ConfigError(f"plant.scale.{field}", factor, "factor must be finite and > 0")
        if field in SIX_DOF_MODEL_FIELDS:
            continue  # inside the section, below
        value = getattr(params, field)
        changes[field] = (
            tuple(v * factor for v in value) if isinstance(value, tuple) else value * factor
        )
    section = {field: factor for field, factor in scale.items() if field in SIX_DOF_MODEL_FIELDS}
    if not changes and not section:
        return params
    data = params.model_dump()
    data.update(changes)
    if section:
        if params.six_dof is None:
            raise ConfigError(f"plant.scale.{next(iter(section))}", params.name,
                              "the vehicle has no six_dof section")  # fmt: skip
        data["six_dof"] = {
            **data["six_dof"],
            **{field: _times(data["six_dof"][field], factor) for field, factor in section.items()},
        }
    try:
        return VehicleParams.model_validate(data)
    except ValidationError as error:
        raise format_validation_error(error, "plant") from None


def _times(value: Any, factor: float) -> Any:
    """Every number of a vector or matrix (nested tuples) times ``factor``."""
    if isinstance(value, tuple | list):
        return tuple(_times(entry, factor) for entry in value)
    return value * factor


def preset_names() -> list[str]:
    """Names of the vehicle presets shipped with the package."""
    folder = resources.files("auvmpc.presets") / "vehicles"
    return sorted(
        p.name.removesuffix(".yaml") for p in folder.iterdir() if p.name.endswith(".yaml")
    )


def thruster_preset_names() -> list[str]:
    """The presets fixed thrusters drive: what the 3-DOF and depth models and their
    controllers fly (a preset with ``actuators:``, a propeller and fins, flies only the 6-DOF
    model)."""
    return [name for name in preset_names() if load_vehicle(name).has_thrusters]


def vehicle_data(
    spec: str | Path | Mapping[str, Any], field: str = "vehicle"
) -> tuple[dict[str, Any], str]:
    """A vehicle's fields as written (a preset name, a YAML file path, or an inline mapping)
    and, for a file the user wrote, its name for errors ("vehicle file PATH", else "")."""
    if isinstance(spec, Mapping):
        return dict(spec), ""
    name = str(spec)
    source = ""
    if name in preset_names():
        text = (resources.files("auvmpc.presets") / "vehicles" / f"{name}.yaml").read_text()
    elif name.endswith((".yaml", ".yml")) or Path(name).exists():
        if not Path(name).exists():
            raise ConfigError(field, name, "vehicle file not found")
        text = read_text_file(name, field, "vehicle file")
        source = f"vehicle file {name}"
    else:
        raise ConfigError(field, name, f"unknown preset; known: {preset_names()}")
    return read_yaml_mapping(text, field, name, "vehicle fields"), source


def load_vehicle(spec: str | Path | Mapping[str, Any], field: str = "vehicle") -> VehicleParams:
    """Vehicle from a preset name, a YAML file path, or an inline mapping."""
    return validated_vehicle(*vehicle_data(spec, field), field)


def validated_vehicle(data: Mapping[str, Any], source: str, field: str) -> VehicleParams:
    """A vehicle from its fields as :func:`vehicle_data` read them (errors name ``source``)."""
    try:
        return VehicleParams.model_validate(data)
    except ValidationError as error:
        raise format_validation_error(error, field, source) from None
