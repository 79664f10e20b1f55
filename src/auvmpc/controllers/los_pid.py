"""The torpedo AUV's classical autopilot (``los-pid``): line-of-sight guidance, heading, depth
and speed PID loops on a propeller, a rudder and stern planes. The yardstick the whole
vehicle's MPC (``six-dof-nmpc``) is measured against (issue 26): what survey AUVs fly.

Guidance (Fossen 2021, sec. 12.4, lookahead-based LOS)::

    chi_d = pi_p - atan(y_e / Delta),    psi_d = chi_d - beta

pi_p is the path's tangent and y_e the cross-track error (positive starboard of the path,
NED) at the point of the path nearest the vehicle: the nearest segment of the polyline through
the reference rows the controller saw in the last ``path_window_s`` and those of its preview as
far ahead (the reference is a moving point; the vehicle follows its path, not the point).
Delta is ``lookahead_lengths`` hull lengths. beta, the angle from the heading to the measured
ground track (the crab a current or a turn makes), turns the course setpoint into a heading
one (Fossen's LOS with crab angle compensation; ``sideslip_compensation``). Optionally
(``integral_los``, for a vehicle that does not measure its ground track) the integral LOS of
Børhaug, Pavlov and Pettersen (CDC 2008, as in Fossen's MSS ``GNC/ILOSpsi.m``)::

    psi_d = pi_p - atan((y_e + kappa y_int) / Delta),
    y_int' = Delta y_e / (Delta^2 + (y_e + kappa y_int)^2)

with kappa = U / (4 zeta^2), which puts the linearised cross-track loop (an ideal heading
loop) at damping ``ilos_damping_ratio``. Its integral is kept as a world-frame vector, each
sample's part added along the path's normal and read back as its projection on the normal: a
current fixed in the world keeps its crab through a lawnmower's turn instead of being learnt
again, with the opposite sign, on every leg.

Control, each axis a PID by pole placement on the vehicle's own model (Fossen 2021, ch. 15;
his Python Vehicle Simulator's ``PIDpolePlacement``): the 6-DOF model linearised (CasADi
Jacobian) at the trimmed cruise, level, fins at zero, gives for the yaw and pitch rate rows
``x'' = a_rate x' + a_angle x + b delta`` with the sway and heave velocities held (their
modes are slow beside the loops'; what their coupling leaves goes to the integral), that is
``m x'' + d x' + k x = delta`` with m = 1 / b, d = -a_rate / b, k = -a_angle / b, and::

    K_p = m w^2 - k,   K_d = 2 zeta w m - d (at least 0),   K_i = w / 10 K_p
    delta = feedforward + K_p e + K_d (x'_d - x') + integral of K_i e

w: the bandwidth, omitted chosen so that the P term alone asks for the whole fin at an
error of ``saturating_error_deg``. Heading: the rudder; x'_d the path's turn rate where the
vehicle is, 1 / w ahead (the heading loop's lag); feedforward the rudder of that steady turn
on the nonlinear model (sway and yaw accelerations zero, solved once per schedule speed).
Depth, NED (z down: nose down to go deeper), at 1 / ``depth_separation`` of the pitch
bandwidth::

    gamma_d = clip(gamma_path - K_z (z_d - z) - integral of K_iz (z_d - z), +-max_pitch)
    theta_d = clip(gamma_d + alpha, +-max_pitch)

gamma the flight-path angle (gamma_path the reference's climb), alpha = atan(w / u) the
measured angle of attack (``attack_compensation``); then pitch: the stern planes,
feedforward k theta_d (the restoring moment at the setpoint). Speed: PI on the propeller of
the ground speed along the path, about the command that holds the reference's speed on the
model (the surge balance, solved once per speed), closed at ``surge_bandwidth_ratio`` times
the hull's own surge rate. Gains are scheduled on the reference's speed (the fins' authority
grows with its square) over a grid from a fifth of the top speed to the top.

Signs come from the model, not from a convention: an input whose positive command turns the
vehicle the other way (Prestero's rudder turns to port for a positive angle, his stern
planes pitch the nose down) is commanded with the opposite sign. Anti-windup: conditional
integration (no integrator step that would deepen a cut the limits just made); commands are
clipped to each input's box and rate (``ActuatorLimits.project``). Actuator effectiveness
(faults) is not used: a PID autopilot does not re-allocate.

Frames and units: NED, the 6-DOF state (models/six_dof.py, SIX_DOF); reference rows
``[x, y, psi, u, v, r, z, z']`` (controllers/channels.py, ReferenceWithDepth); commands in
each actuator's own units (rpm, deg).
"""

from __future__ import annotations

import functools
import math
import time
from collections import deque
from dataclasses import dataclass
from typing import Annotated, ClassVar, Literal

import casadi as ca
import numpy as np
from pydantic import Field
from scipy.optimize import fsolve

from auvmpc.angles import wrap_angle
from auvmpc.config import Positive
from auvmpc.controllers.base import Controller, ControlResult, ControlStatus, Observation
from auvmpc.controllers.config import (
    ControllerType,
    WholeVehicleConfig,
    type_field,
)
from auvmpc.errors import ConfigError
from auvmpc.models.actuators import ControlSurface, Propeller
from auvmpc.models.six_dof import SIX_DOF, ground_velocity, six_dof_model, top_surge_speed
from auvmpc.models.vehicle import VehicleParams

__all__ = [
    "LOS_PID",
    "AxisModel",
    "LosPid",
    "flies",
    "LosPidConfig",
    "PathPoint",
    "los_heading",
    "nearest_on_path",
]

LOS_PID = ControllerType.LOS_PID
NX = SIX_DOF.size
_X, _Y, _Z = (SIX_DOF.index(name) for name in ("x", "y", "z"))
_THETA, _PSI = SIX_DOF.index("theta"), SIX_DOF.index("psi")
_U, _Q, _R = (SIX_DOF.index(name) for name in ("u", "q", "r"))
_V, _W = SIX_DOF.index("v"), SIX_DOF.index("w")
# The reference rows a 6-DOF controller sees (controllers/channels.py, ReferenceWithDepth).
_REF_U, _REF_Z, _REF_Z_RATE = 3, 6, 7
# A unit vector's component beyond this along an axis: the actuator acts about that axis.
_ALIGNED = 0.9
# Path segments shorter than this (m) give no direction (a reference holding still).
_NO_LENGTH_M = 1e-6
# Below this speed (m/s) the guidance and the gains take it as this (the fins need flow).
_SLOWEST_M_PER_S = 0.05
# The gain schedule's speeds, as shares of the top speed (the trim table's too, and rest).
_SCHEDULE = np.linspace(0.2, 1.0, 9)
# The integral's update Fossen's pole placement uses: K_i = w / 10 K_p.
_INTEGRAL_SHARE = 0.1
# A command the limits moved by more than this (its own units) was cut.
_CUT = 1e-9
# The rudder commands, as shares of its range, whose steady turns the feedforward inverts.
_TURN_SHARES = np.array([0.0, 0.1, 0.25, 0.5, 0.75, 1.0])
# The reference columns of the path the guidance keeps: x, y, heading, turn rate.
_PATH_COLUMNS = [0, 1, 2, 5]
_PATH_TURN = 3


class LosPidConfig(WholeVehicleConfig):
    """``los-pid``: LOS guidance and PID autopilots of a torpedo AUV (module docstring)."""

    default_sample_time_s: ClassVar[float] = 0.1  # an autopilot's 10 Hz

    type: Literal[ControllerType.LOS_PID] = type_field(LOS_PID)
    sample_time: Annotated[float, Field(gt=0)] | None = Field(
        default=None, description="Te (s); omitted: 0.1, an autopilot's 10 Hz"
    )
    lookahead_lengths: Positive = Field(
        default=3.0, description="LOS lookahead distance Delta over the hull's size.length"
    )
    lookahead_m: Positive | None = Field(
        default=None, description="LOS lookahead distance Delta (m); omitted: lookahead_lengths "
        "x the hull's length (a vehicle without size: 2 x its vehicle_radius)",
    )  # fmt: skip
    sideslip_compensation: bool = Field(
        default=True, description="steer the course, not the heading: the heading setpoint "
        "less the measured angle between the heading and the ground track (the crab a "
        "current or a turn makes; Fossen 2021, sec. 12.4, LOS with crab angle compensation)",
    )  # fmt: skip
    damping_ratio: Positive = Field(
        default=1.0, description="zeta of the heading and pitch loops' pole placement"
    )
    path_window_s: Positive = Field(
        default=10.0, description="how much of the path behind and ahead of the reference's "
        "point the nearest-point search looks at (s of reference)",
    )  # fmt: skip
    depth_separation: Positive = Field(
        default=3.0, description="pitch bandwidth over the depth loop's (the outer loop slower)"
    )
    integral_los: bool = Field(
        default=False, description="integral LOS (Børhaug et al. 2008): the crab angle a "
        "current needs, learnt from the cross-track error (for a vehicle that does not "
        "measure its ground track: with sideslip_compensation it counts the crab twice)",
    )  # fmt: skip
    max_pitch_deg: Positive = Field(
        default=20.0, le=60.0, description="the depth loop's pitch setpoint is clipped to +-this"
    )
    ilos_damping_ratio: Positive = Field(
        default=1.0, description="damping of the linearised cross-track loop with the integral "
        "(kappa = U / (4 zeta^2))",
    )  # fmt: skip
    saturating_error_deg: Positive = Field(
        default=10.0, description="heading or pitch error at which the P term alone asks for "
        "the whole fin: sets each loop's bandwidth where heading_bandwidth or "
        "pitch_bandwidth is omitted (deg)",
    )  # fmt: skip
    heading_bandwidth: Positive | None = Field(
        default=None, description="w of the heading loop (rad/s), the same at every speed; "
        "omitted: from saturating_error_deg, scheduled on the speed",
    )  # fmt: skip
    attack_compensation: bool = Field(
        default=True, description="steer the flight path, not the pitch: the depth loop's "
        "pitch setpoint plus the measured angle of attack atan(w / u) (the vertical "
        "counterpart of sideslip_compensation)",
    )  # fmt: skip
    pitch_bandwidth: Positive | None = Field(
        default=None, description="w of the pitch loop (rad/s), the same at every speed; "
        "omitted: from saturating_error_deg, scheduled on the speed",
    )  # fmt: skip
    surge_bandwidth_ratio: Positive = Field(
        default=1.0, description="the surge PI's bandwidth over the hull's own surge rate "
        "(-du'/du at the trim)",
    )  # fmt: skip


# -- guidance -------------------------------------------------------------------------------


@dataclass(frozen=True)
class PathPoint:
    """The point of the path nearest the vehicle: the path's tangent there (rad) and the
    vehicle's cross-track error (m, positive starboard of the path, NED)."""

    tangent: float
    cross_track: float
    segment: int = 0  # the nearest segment's first point, an index of the path's points

    @property
    def normal(self) -> np.ndarray:
        """(2,) the unit vector from the path to its starboard side (world x, y)."""
        return np.array([-math.sin(self.tangent), math.cos(self.tangent)])


def nearest_on_path(points: np.ndarray, headings: np.ndarray, position: np.ndarray) -> PathPoint:
    """The nearest point of the polyline through ``points`` (n, 2) to ``position`` (2,).

    The tangent is the nearest segment's direction; the cross-track error is measured from
    that segment's line (so a vehicle behind the first point or past the last still gets
    the path's line). A path without length (a reference holding still) takes its first
    point and ``headings[0]`` (rad): the reference's own heading there."""
    starts, steps = points[:-1], np.diff(points, axis=0)
    lengths = np.hypot(steps[:, 0], steps[:, 1])
    moving = lengths > _NO_LENGTH_M
    if not np.any(moving):
        return _cross_track(points[0], float(headings[0]), position, 0)
    indices = np.flatnonzero(moving)
    starts, steps, lengths = starts[moving], steps[moving], lengths[moving]
    along = np.clip(np.einsum("ij,ij->i", position - starts, steps) / lengths**2, 0.0, 1.0)
    gaps = starts + along[:, None] * steps - position
    nearest = int(np.argmin(np.einsum("ij,ij->i", gaps, gaps)))
    tangent = math.atan2(steps[nearest, 1], steps[nearest, 0])
    return _cross_track(starts[nearest], tangent, position, int(indices[nearest]))


def _cross_track(origin: np.ndarray, tangent: float, position: np.ndarray,
                 segment: int) -> PathPoint:  # fmt: skip
    """y_e = -(x - x_k) sin(pi_p) + (y - y_k) cos(pi_p) (Fossen 2021, sec. 12.4)."""
    dx, dy = position - origin
    return PathPoint(tangent, -dx * math.sin(tangent) + dy * math.cos(tangent), segment)


def los_heading(point: PathPoint, lookahead: float, integral_offset: float = 0.0) -> float:
    """psi_d = pi_p - atan((y_e + kappa y_int) / Delta) (rad): towards the path, the
    closer the steeper; ``integral_offset`` is kappa y_int (m)."""
    return point.tangent - math.atan((point.cross_track + integral_offset) / lookahead)


# -- the vehicle's loops, from its model ------------------------------------------------------


@dataclass(frozen=True)
class AxisModel:
    """One axis as the pole placement sees it, ``m x'' + d x' + k x = delta``, per unit of
    the role's command (its positive one speeds the axis up)."""

    m: float
    d: float
    k: float

    def gains(self, bandwidth: float, damping: float) -> tuple[float, float, float]:
        """``(K_p, K_d, K_i)`` placing the poles at ``bandwidth`` with ``damping`` (Fossen's
        PIDpolePlacement); K_d at least 0 (a hull damped enough already keeps its own)."""
        k_p = self.m * bandwidth**2 - self.k
        k_d = max(0.0, 2.0 * damping * bandwidth * self.m - self.d)
        return k_p, k_d, _INTEGRAL_SHARE * bandwidth * k_p

    def bandwidth_saturating(self, command: float, error: float) -> float:
        """The w at which K_p error = command: the P term asks for the whole command."""
        return math.sqrt(max((command / error + self.k) / self.m, 0.0))


@dataclass(frozen=True)
class _Role:
    """The inputs one loop commands (several rudders move as one) and each one's sign:
    input i gets ``signs[i] * command``, so that a positive command speeds the axis up."""

    name: str
    inputs: np.ndarray
    signs: np.ndarray
    lower: float  # the role's command box (the inputs' boxes, signs applied)
    upper: float

    def of(self, command: np.ndarray) -> float:
        """The role's command read back from the inputs' (its first input's)."""
        return float(self.signs[0] * command[self.inputs[0]])


def flies(model: VehicleParams) -> bool:
    """Whether this autopilot can fly ``model``: it has a propeller, a rudder and stern
    planes."""
    return all(_actuators_by_role(model).values())


def _actuators_by_role(model: VehicleParams) -> dict[str, list[int]]:
    """The indices of ``model``'s 6-DOF inputs that push along the hull (propeller), turn it
    (rudder) and pitch it (stern planes)."""
    inputs = model.six_dof_actuators if model.six_dof is not None else None
    actuators = () if inputs is None else inputs.actuators
    return {
        "propeller": [i for i, a in enumerate(actuators)
                      if isinstance(a, Propeller) and abs(a.direction[0]) > _ALIGNED],
        "rudder": [i for i, a in enumerate(actuators)
                   if isinstance(a, ControlSurface) and abs(a.axis[2]) > _ALIGNED],
        "stern planes": [i for i, a in enumerate(actuators)
                         if isinstance(a, ControlSurface) and abs(a.axis[1]) > _ALIGNED],
    }  # fmt: skip


def _roles(model: VehicleParams) -> tuple[_Role, _Role, _Role]:
    """The propeller, rudder and stern-plane inputs of ``model`` (refused in one line if it
    has not all three), each input's sign from the model: which way its axis's rate (surge,
    yaw, pitch) moves as the input goes from its lower to its upper end, at half the top
    speed with the other inputs at zero."""
    kinds = _actuators_by_role(model)
    missing = [name for name, found in kinds.items() if not found]
    if missing:
        raise ConfigError("controller.type", str(LOS_PID), _refusal(model, missing))
    inputs = model.six_dof_actuators
    axes = {"propeller": _U, "rudder": _R, "stern planes": _Q}
    limits = inputs.limits
    lower = np.broadcast_to(limits.lower, (inputs.size,))
    upper = np.broadcast_to(limits.upper, (inputs.size,))
    cruise = np.zeros(NX)
    cruise[_U] = 0.5 * _top_speed(model)
    model_rates = six_dof_model(model).evaluate

    def rate_at(i: int, command: float, axis: int) -> float:
        moved = np.zeros(inputs.size)
        moved[i] = command
        return float(model_rates(cruise, moved)[axis])

    roles = []
    for name, found in kinds.items():
        index = np.array(found)
        axis = axes[name]
        signs = np.array(
            [1.0 if rate_at(i, upper[i], axis) >= rate_at(i, lower[i], axis) else -1.0
             for i in index]
        )  # fmt: skip
        low = np.where(signs > 0, lower[index], -upper[index]).max()
        high = np.where(signs > 0, upper[index], -lower[index]).min()
        roles.append(_Role(name, index, signs, float(low), float(high)))
    return tuple(roles)


def _refusal(model: VehicleParams, missing: list[str]) -> str:
    if model.six_dof is None:
        what = "no six_dof section"
    elif model.six_dof_actuators.linear:
        what = "fixed thrusters"
    else:
        what = ", ".join(type(a).__name__ for a in model.six_dof_actuators.actuators)
    return (f"a torpedo's autopilot: it needs a propeller, a rudder and stern planes; "
            f"vehicle {model.name} has {what} (no {', '.join(missing)}); "
            "six-dof-nmpc flies any actuators")  # fmt: skip


@dataclass(frozen=True)
class _Schedule:
    """Each loop's gains at the schedule's speeds (rows), interpolated at a speed."""

    speeds: np.ndarray
    heading: np.ndarray  # (n, 3) K_p, K_d, K_i
    pitch: np.ndarray
    turn_rates: np.ndarray  # (n, m) the steady yaw rate of each of TURN_SHARES' rudders
    turn_commands: np.ndarray  # (m,) those rudder commands
    heading_bandwidth: np.ndarray  # (n,) rad/s
    pitch_model: np.ndarray  # (n, 2) d, k of the pitch axis (the feedforward's)
    depth: np.ndarray  # (n, 2) K_z (rad/m), its K_i (rad/(m s))
    surge: np.ndarray  # (n, 3) K_p (per m/s), 0, K_i (per m): a PI
    trim_speeds: np.ndarray
    trim_commands: np.ndarray  # the propeller's command holding each trim speed

    def at(self, table: np.ndarray, speed: float) -> np.ndarray:
        return np.array([np.interp(speed, self.speeds, column) for column in table.T])

    def trim(self, speed: float) -> float:
        return float(np.interp(speed, self.trim_speeds, self.trim_commands))

    def turn(self, speed: float, rate: float) -> float:
        """The rudder command of a steady turn at ``rate`` (rad/s): the model's, interpolated
        in the rate at each schedule speed, then in the speed (the fullest rudder beyond)."""
        at_speeds = [np.interp(abs(rate), rates, self.turn_commands) for rates in self.turn_rates]
        return math.copysign(float(np.interp(speed, self.speeds, at_speeds)), rate)


class LosPid(Controller):
    """LOS guidance and PID autopilots of a torpedo AUV (module docstring)."""

    #: Commands every 6-DOF input itself on the whole measured state (kind: six-dof only).
    whole_vehicle = True

    def __init__(self, model: VehicleParams, config: LosPidConfig) -> None:
        self.propeller, self.rudder, self.planes = _roles(model)
        self._rates = six_dof_model(model).evaluate
        self._jacobians = _jacobians(model)
        config = config.for_vehicle(model)
        self.model, self.config = model, config
        self.sample_time = float(config.sample_time)
        inputs = model.six_dof_actuators
        self.limits = inputs.limits
        self.n_inputs = inputs.size
        self.lookahead = config.lookahead_m or (
            config.lookahead_lengths * model.size.length
            if model.size is not None
            else 2.0 * float(config.vehicle_radius)
        )
        window = max(1, math.ceil(config.path_window_s / self.sample_time))
        self.preview_steps = window
        self._window = window
        self.schedule = self._design(_top_speed(model))
        self.reset(np.zeros(NX), np.zeros(self.n_inputs))

    @classmethod
    def from_config(cls, model, config, obstacle_count: int = 0) -> Controller:
        return cls(model, config)

    # -- design ----------------------------------------------------------------------------
    def _trim_command(self, speed: float) -> float:
        """The propeller's command that holds ``speed`` level with the fins at zero (the
        surge balance on the 6-DOF model, by bisection; its top if the speed is beyond)."""
        role = self.propeller
        state = np.zeros(NX)
        state[_U] = speed

        def surge_rate(command: float) -> float:
            inputs = np.zeros(self.n_inputs)
            inputs[role.inputs] = role.signs * command
            return float(self._rates(state, inputs)[_U])

        low, high = max(role.lower, 0.0), role.upper
        if surge_rate(high) <= 0.0:
            return high
        for _ in range(24):  # the box over 2^24: far below an rpm
            middle = 0.5 * (low + high)
            low, high = (middle, high) if surge_rate(middle) < 0.0 else (low, middle)
        return 0.5 * (low + high)

    def _design(self, top: float) -> _Schedule:
        """Every loop's gains and feedforward tables at the schedule's speeds up to ``top``
        (m/s), each from the model trimmed there (module docstring)."""
        config = self.config
        speeds = _SCHEDULE * top
        rows: dict[str, list] = {key: [] for key in ("heading", "pitch", "turns", "w_yaw",
                                                     "pitch_dk", "depth", "surge")}  # fmt: skip
        turn_commands = _TURN_SHARES * _half_range(self.rudder)
        trims = [self._trim_command(speed) for speed in speeds]
        for speed, trim in zip(speeds, trims, strict=True):
            state = np.zeros(NX)
            state[_U] = speed
            inputs = np.zeros(self.n_inputs)
            inputs[self.propeller.inputs] = self.propeller.signs * trim
            a, b = (np.asarray(value, dtype=float) for value in self._jacobians(state, inputs))
            yaw = _axis(a, b, _R, _PSI, self.rudder)
            pitch = _axis(a, b, _Q, _THETA, self.planes)
            saturating = math.radians(config.saturating_error_deg)
            w_yaw = config.heading_bandwidth or yaw.bandwidth_saturating(
                _half_range(self.rudder), saturating
            )
            w_pitch = config.pitch_bandwidth or pitch.bandwidth_saturating(
                _half_range(self.planes), saturating
            )
            rows["heading"].append(yaw.gains(w_yaw, config.damping_ratio))
            rows["pitch"].append(pitch.gains(w_pitch, config.damping_ratio))
            rows["turns"].append(self._turn_rates(state, inputs, turn_commands))
            rows["w_yaw"].append(w_yaw)
            rows["pitch_dk"].append((pitch.d, pitch.k))
            w_depth = w_pitch / config.depth_separation
            k_z = w_depth / speed  # z' = -U theta: the depth loop's rate is U K_z
            rows["depth"].append((k_z, _INTEGRAL_SHARE * w_depth * k_z))
            # u' = a u + b n: the PI's poles both at w (zeta = 1)
            rate = a[_U, _U]
            effect = float(np.sum(b[_U, self.propeller.inputs] * self.propeller.signs))
            w_surge = config.surge_bandwidth_ratio * abs(rate)
            k_p = max(0.0, (2.0 * w_surge + rate) / effect)
            rows["surge"].append((k_p, 0.0, w_surge**2 / effect))
        return _Schedule(
            speeds,
            np.array(rows["heading"]), np.array(rows["pitch"]),
            np.array(rows["turns"]), turn_commands, np.array(rows["w_yaw"]),
            np.array(rows["pitch_dk"]),
            np.array(rows["depth"]), np.array(rows["surge"]),
            np.concatenate([[0.0], speeds]), np.array([self._trim_command(0.0), *trims]),
        )  # fmt: skip

    def _turn_rates(self, state: np.ndarray, inputs: np.ndarray,
                    commands: np.ndarray) -> np.ndarray:  # fmt: skip
        """The steady yaw rate (rad/s) of each rudder command at the trim ``state``,
        ``inputs``: sway and yaw accelerations zero, the rest held (never decreasing: the
        feedforward inverts it)."""
        rates = [0.0]
        for command in commands[1:]:
            turning = inputs.copy()
            turning[self.rudder.inputs] = self.rudder.signs * command

            sway_yaw, _, found, _ = fsolve(
                self._sway_and_yaw_accelerations, [0.0, rates[-1]], args=(state, turning),
                full_output=True,
            )  # fmt: skip
            rates.append(float(sway_yaw[1]) if found == 1 else rates[-1])
        return np.maximum.accumulate(np.abs(rates))

    def _sway_and_yaw_accelerations(self, sway_yaw: np.ndarray, state: np.ndarray,
                                    inputs: np.ndarray) -> np.ndarray:  # fmt: skip
        moving = state.copy()
        moving[[_V, _R]] = sway_yaw
        return self._rates(moving, inputs)[[_V, _R]]

    # -- the controller ----------------------------------------------------------------------
    def reset(self, initial_state: np.ndarray, initial_thrust: np.ndarray) -> None:
        self._previous = np.asarray(initial_thrust, dtype=float).copy()
        self._seen: deque[np.ndarray] = deque(maxlen=self._window)  # past rows, _PATH_COLUMNS
        self._crab = np.zeros(2)  # the ILOS integral as a world-frame vector (s)
        self._integrals = {"heading": 0.0, "pitch": 0.0, "depth": 0.0, "surge": 0.0}

    def compute(self, observation: Observation) -> ControlResult:
        started = time.perf_counter()
        state = np.asarray(observation.state, dtype=float)
        rows = np.asarray(observation.reference, dtype=float)
        schedule = self.schedule
        speed_d = float(rows[0, _REF_U])
        speed = max(abs(speed_d), _SLOWEST_M_PER_S)
        scheduled = min(max(speed, schedule.speeds[0]), schedule.speeds[-1])
        self._seen.append(rows[0, _PATH_COLUMNS])
        path = np.vstack([*self._seen, rows[1 : self._window + 1, _PATH_COLUMNS]])
        point = nearest_on_path(path[:, :2], path[:, 2], state[[_X, _Y]])
        ground = ground_velocity(state)
        psi_d = self._heading_setpoint(state, point, ground, speed)
        theta_d = self._pitch_setpoint(state, rows[0], speed, scheduled)
        # the path's turn rate where the vehicle is, as far ahead as the heading loop lags
        bandwidth = float(np.interp(scheduled, schedule.speeds, schedule.heading_bandwidth))
        lead = round(1.0 / (bandwidth * self.sample_time))
        r_d = float(path[min(point.segment + lead, len(path) - 1), _PATH_TURN])
        along = float(ground @ [math.cos(point.tangent), math.sin(point.tangent)])
        loops = (  # name, its inputs, gains, error, rate error, feedforward
            ("heading", self.rudder, schedule.at(schedule.heading, scheduled),
             float(wrap_angle(psi_d - float(state[_PSI]))), r_d - float(state[_R]),
             schedule.turn(scheduled, r_d)),
            ("pitch", self.planes, schedule.at(schedule.pitch, scheduled),
             theta_d - float(state[_THETA]), -float(state[_Q]),
             schedule.at(schedule.pitch_model, scheduled)[1] * theta_d),
            ("surge", self.propeller, schedule.at(schedule.surge, scheduled), speed_d - along,
             0.0, schedule.trim(speed)),
        )  # fmt: skip
        command = np.zeros(self.n_inputs)
        steps = {}
        for name, role, (k_p, k_d, k_i), error, rate_error, feedforward in loops:
            steps[name] = self.sample_time * k_i * error
            wanted = feedforward + k_p * error + k_d * rate_error + self._integrals[name]
            command[role.inputs] = role.signs * (wanted + steps[name])
        applied, moved = self.limits.project(command, self._previous, self.sample_time)
        # conditional integration: no integrator step deepening a cut the limits just made
        for name, role, *_ in loops:
            cut = role.of(command) - role.of(applied)
            if abs(cut) <= _CUT or np.sign(cut) != np.sign(steps[name]):
                self._integrals[name] += steps[name]
        self._previous = applied
        info = {
            "cross_track_m": point.cross_track,
            "heading_setpoint_rad": psi_d,
            "pitch_setpoint_rad": theta_d,
        }
        status = ControlStatus.SATURATED if moved else ControlStatus.OK
        return ControlResult(applied.copy(), status, time.perf_counter() - started, info=info)

    def _heading_setpoint(self, state: np.ndarray, point: PathPoint, ground: np.ndarray,
                          speed: float) -> float:  # fmt: skip
        """psi_d (rad): LOS towards the path, the crab compensated (module docstring)."""
        config = self.config
        kappa = speed / (4.0 * config.ilos_damping_ratio**2)
        offset = kappa * float(self._crab @ point.normal) if config.integral_los else 0.0
        psi_d = los_heading(point, self.lookahead, offset)
        if config.integral_los:
            shift = point.cross_track + offset
            grow = self.lookahead * point.cross_track / (self.lookahead**2 + shift**2)
            self._crab += self.sample_time * grow * point.normal
        if config.sideslip_compensation and math.hypot(*ground) > _SLOWEST_M_PER_S:
            # steer the course: the heading less the measured angle of the ground track
            psi_d -= float(wrap_angle(math.atan2(ground[1], ground[0]) - float(state[_PSI])))
        return psi_d

    def _pitch_setpoint(self, state: np.ndarray, row: np.ndarray, speed: float,
                        scheduled: float) -> float:  # fmt: skip
        """theta_d (rad): the depth loop's flight path plus the angle of attack, clipped
        (module docstring); NED, so a positive depth error (too shallow) asks nose down."""
        k_z, k_iz = self.schedule.at(self.schedule.depth, scheduled)
        error = float(row[_REF_Z] - state[_Z])
        climb = math.atan2(-float(row[_REF_Z_RATE]), speed)
        limit = math.radians(self.config.max_pitch_deg)
        wanted = climb - k_z * error - self._integrals["depth"]
        flight_path = min(max(wanted, -limit), limit)
        step = self.sample_time * k_iz * error  # the integral enters with a minus sign
        if flight_path == wanted or np.sign(wanted - flight_path) == np.sign(step):
            self._integrals["depth"] += step
        if not self.config.attack_compensation:
            return flight_path
        attack = math.atan2(float(state[_W]), max(float(state[_U]), _SLOWEST_M_PER_S))
        return min(max(flight_path + attack, -limit), limit)


def _jacobians(model: VehicleParams) -> ca.Function:
    """``(x, u) -> (df/dx, df/du)`` of the 6-DOF model in still water."""
    derivative = six_dof_model(model).derivative
    x, u = ca.SX.sym("x", NX), ca.SX.sym("u", model.six_dof_actuators.size)
    rate = derivative(x, u, ca.DM.zeros(3), ca.DM.zeros(3))
    return ca.Function("los_pid_linearisation", [x, u],
                       [ca.jacobian(rate, x), ca.jacobian(rate, u)])  # fmt: skip


@functools.lru_cache(maxsize=16)
def _cached_top_speed(params_json: str) -> float:
    return top_surge_speed(VehicleParams.model_validate_json(params_json))


def _top_speed(model: VehicleParams) -> float:
    """The vehicle's top surge speed (m/s; at least _SLOWEST_M_PER_S), found once."""
    return max(_cached_top_speed(model.model_dump_json()), _SLOWEST_M_PER_S)


def _axis(a: np.ndarray, b: np.ndarray, rate: int, angle: int, role: _Role) -> AxisModel:
    """The ``rate`` row of the linearisation (``angle`` its angle) as m x'' + d x' + k x =
    the role's command, the other velocities held."""
    effect = float(np.sum(b[rate, role.inputs] * role.signs))
    return AxisModel(1.0 / effect, -a[rate, rate] / effect, -a[rate, angle] / effect)


def _half_range(role: _Role) -> float:
    """The command either way from zero the role always has (its box's nearer end)."""
    return min(abs(role.lower), abs(role.upper))
