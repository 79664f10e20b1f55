"""Reference trajectories: a planar path p(t) = (x(t), y(t)) and the full state it implies.

State order everywhere: ``[x, y, psi, u, v, r]`` (world x, y in m; heading psi in rad; body
surge u and sway v in m/s; yaw rate r in rad/s). From the path (paper-model.md section 5):

    psi_r = atan2(y', x')  unwrapped,   u_r = sqrt(x'^2 + y'^2),   v_r = 0,
    r_r   = dpsi_r/dt = (x' y'' - y' x'') / (x'^2 + y'^2).

Conventions shared by every reference type:

- At a joint between two pieces the derivatives are those of the piece that starts there
  (taken from the right), the paper's convention.
- ``psi_r`` is a function of ``t`` alone, never of the other times in a query: it comes from an
  analytic unwrapped formula where one exists, otherwise a dense unwrapped heading table fixed at
  construction picks the multiple of 2 pi to add to the exact ``atan2`` value. A controller's
  horizon and a plot's dense grid therefore see the same ``psi_r`` at the same ``t``.
- ``psi_r`` at the start of a path (t = 0, or the first CSV time) lies in (-pi, pi].
- Where the path stands still, ``psi_r`` holds the last heading and ``r_r = 0``.
- Analytic types (paper-oval, circle, figure-eight, line) extend their formulas to any t; paths
  built from data (waypoints, csv) hold their first point before they start and their last point
  after they end (u_r = 0, r_r = 0, psi_r = heading at that end).

3-D references (for 6-DOF scenarios) add a depth below the surface (NED z, down positive) with
exact derivatives, :meth:`Reference.depths` -> ``[z, z', z'']``; the state reference above stays
the horizontal path's, with u_r its horizontal speed. ``helix``, ``lawnmower`` and
``waypoints-3d`` are 3-D by nature; every planar type takes an optional ``depth`` schedule
(start depth plus smooth changes), and without one it is exactly the planar reference it was.
Depth changes are quintic smooth steps in time: z' and z'' continuous, zero at each end.
"""

from __future__ import annotations

import csv
import io
import math
from abc import ABC, abstractmethod
from pathlib import Path
from typing import Annotated, Literal, get_args

import numpy as np
from numpy.typing import ArrayLike
from pydantic import Field, field_validator, model_validator
from scipy.interpolate import CubicSpline

from auvmpc.angles import wrap_angle
from auvmpc.config import NonNegative, StrictModel
from auvmpc.errors import ConfigError, shortened
from auvmpc.models.layout import DEPTH, DEPTH_PROFILE, HORIZONTAL
from auvmpc.safe_yaml import read_text_file

__all__ = [
    "REFERENCE_TYPES",
    "CORNER_TURN_DEG",
    "MAX_TRACK_BYTES",
    "Circle",
    "CircleConfig",
    "CsvConfig",
    "DepthChangeConfig",
    "DepthProfile",
    "DepthSchedule",
    "DepthScheduleConfig",
    "DepthStep",
    "DepthStepConfig",
    "Helix",
    "HelixConfig",
    "Lawnmower",
    "LawnmowerConfig",
    "LinearDepth",
    "FigureEight",
    "FigureEightConfig",
    "Line",
    "LineConfig",
    "PaperOval",
    "PaperOvalConfig",
    "Reference",
    "ReferenceConfig",
    "SampledPath",
    "WaypointPath",
    "Waypoints3D",
    "Waypoints3DConfig",
    "WaypointsConfig",
    "load_track_csv",
    "make_reference",
]

_TWO_PI = 2.0 * math.pi

# Below this speed (m/s) a path counts as standing still: heading is undefined there, so it is
# held from the last moving instant and the yaw rate is 0 (avoids dividing by ~0).
_STATIONARY_SPEED = 1e-9

# Consecutive waypoints closer than this (m) count as equal: the leg between them has no heading.
_MIN_LEG_LENGTH = 1e-9

# A waypoint turn this close to 180 deg (rad) is a reversal: no arc is tangent to both legs.
_REVERSAL_TOLERANCE = 1e-9

# Heading-table samples per CSV knot interval. A cubic's velocity is a quadratic, whose direction
# turns by less than 2 pi per interval, so 16 samples keep table steps well under pi.
_TABLE_SAMPLES_PER_INTERVAL = 16

_CSV_FIELD = "reference.path"
_CSV_COLUMNS = ("t", "x", "y")
_CSV_MIN_ROWS = 4
# Beyond these the spline's speed and acceleration overflow float64 (a NaN reference or a
# traceback): |t| up to 30 years, |x|, |y| up to 1e7 m (UTM northings fit), rows at least
# 1 us apart (a 1 MHz track is no vehicle's).
_CSV_LIMITS = {"t": (1e9, "s"), "x": (1e7, "m"), "y": (1e7, "m")}
_CSV_MIN_STEP_S = 1e-6
# A track is read whole and its rows parsed in Python, about 0.5 s and 20 MB of memory a
# MiB: 8 MiB holds 300 000 rows, over 8 h at 10 Hz; a larger file took minutes and
# gigabytes with no word.
MAX_TRACK_BYTES = 8 * 1024 * 1024


# --------------------------------------------------------------------------------------------
# Configuration models
# --------------------------------------------------------------------------------------------

Point = tuple[float, float]
Point3 = tuple[float, float, float]


# A bend of a polyline path counts as a corner from this turn on (deg): the hard survey's
# 90-degree corners are what the linearised controllers were measured to lose on
# (docs/recovery.md), a gentle bend is not.
CORNER_TURN_DEG = 45.0


class DepthChangeConfig(StrictModel):
    """One change of the reference depth: a smooth (quintic) transition over a time window."""

    time_s: float = Field(..., ge=0.0, description="Time the change starts, s.")
    depth_m: float = Field(..., description="Depth below the surface after the change (NED), m.")
    duration_s: float = Field(..., gt=0.0, description="Time the change takes, s.")


class DepthStepConfig(StrictModel):
    """The reference: hold ``initial_depth_m``, then step to ``final_depth_m``."""

    initial_depth_m: float = Field(default=-0.3, description="z before the step (m, negative)")
    final_depth_m: float = Field(default=-0.5, description="z after the step (m, negative)")
    step_time_s: NonNegative = Field(default=10.0, description="time of the step (s)")

    def depth(self, t: np.ndarray) -> np.ndarray:
        return np.where(np.asarray(t) >= self.step_time_s, self.final_depth_m, self.initial_depth_m)


class DepthScheduleConfig(StrictModel):
    """Depth below the surface over time: a start depth and smooth changes (quintic in time,
    so depth rate and depth acceleration are continuous and zero at both ends of a change)."""

    start_m: float = Field(..., description="Depth below the surface at t = 0 (NED, down), m.")
    changes: tuple[DepthChangeConfig, ...] = Field(
        (), description="Depth changes in time order, none overlapping another."
    )

    @field_validator("changes")
    @classmethod
    def _in_order(cls, changes: tuple[DepthChangeConfig, ...]) -> tuple[DepthChangeConfig, ...]:
        for i in range(1, len(changes)):
            previous_end = changes[i - 1].time_s + changes[i - 1].duration_s
            if changes[i].time_s < previous_end:
                raise ValueError(
                    f"changes[{i}] starts at {changes[i].time_s} s, before changes[{i - 1}] "
                    f"ends ({previous_end} s)"
                )
        return changes


class HelixConfig(StrictModel):
    """A helix: a circle in the horizontal plane, descending a fixed depth per turn."""

    type: Literal["helix"] = Field("helix", description="Reference type: helix (3-D).")
    center: Point = Field((0.0, 0.0), description="Axis position [x, y] in the world frame, m.")
    radius: float = Field(3.0, gt=0.0, description="Horizontal radius, m.")
    speed: float = Field(
        0.3, gt=0.0, description="Horizontal speed (what the horizontal controller tracks), m/s."
    )
    descent_per_turn_m: float = Field(
        1.0, description="Depth gained per full turn, m (negative: climbs)."
    )
    start_depth_m: float = Field(1.0, description="Depth below the surface at t = 0, m.")
    direction: Literal["ccw", "cw"] = Field(
        "ccw",
        description="ccw: heading increasing (x towards y); seen from above in NED (x north, "
        "y east) that is clockwise.",
    )
    start_angle_deg: float = Field(
        0.0, description="Angle of the start point seen from the axis, deg from world +x."
    )


class LawnmowerConfig(StrictModel):
    """A survey pattern: parallel legs joined by half-circle turns, a depth per leg, the depth
    changing smoothly during each turn."""

    type: Literal["lawnmower"] = Field("lawnmower", description="Reference type: lawnmower (3-D).")
    start: Point = Field((0.0, 0.0), description="Start of the first leg [x, y], m.")
    heading_deg: float = Field(0.0, description="Direction of the first leg, deg from world +x.")
    leg_length: float = Field(
        20.0,
        gt=0.0,
        description="Distance between the two ends of each leg (its waypoints), m. The "
        "half-circle turns (radius spacing / 2) begin spacing / 2 before an end, so the "
        "straight part of a leg between two turns is leg_length - spacing. The pattern "
        "ends when the last leg does; a longer run holds its end point (a pre-run warning "
        "gives both times).",
    )
    spacing: float = Field(
        4.0, gt=0.0, description="Distance between legs (twice the turn radius), m."
    )
    legs: int = Field(4, ge=1, description="Number of legs.")
    first_turn: Literal["ccw", "cw"] = Field(
        "ccw",
        description="Direction of the first turn: 'ccw' heading increasing (as a 'ccw' circle).",
    )
    speed: float = Field(0.5, gt=0.0, description="Horizontal speed while moving, m/s.")
    depths_m: tuple[float, ...] = Field(
        (1.0,),
        min_length=1,
        description="Depth below the surface of each leg, m: one value for all, or one per leg.",
    )

    @model_validator(mode="after")
    def _fits(self) -> LawnmowerConfig:
        if len(self.depths_m) not in (1, self.legs):
            raise ValueError(f"depths_m: need 1 or {self.legs} values (one per leg)")
        if self.legs > 1 and self.leg_length <= self.spacing:
            raise ValueError(
                f"leg_length {self.leg_length} must exceed spacing {self.spacing} (the turns "
                "take spacing / 2 of each leg)"
            )
        return self


class Waypoints3DConfig(StrictModel):
    """Waypoints in 3-D: the horizontal path of ``waypoints`` (circular-arc corners), the depth
    moving smoothly (quintic in time) from each waypoint's depth to the next's."""

    type: Literal["waypoints-3d"] = Field(
        "waypoints-3d", description="Reference type: 3-D waypoints."
    )
    points: tuple[Point3, ...] = Field(
        ...,
        min_length=2,
        description=(
            "Waypoints [[x, y, depth], ...] in m (depth below the surface), at least 2, no two "
            "consecutive at the same [x, y] and no 180 deg reversal in the horizontal plane."
        ),
    )
    speed: float = Field(0.5, gt=0.0, description="Horizontal speed while moving, m/s.")
    corner_radius: float = Field(
        1.0, gt=0.0, description="Radius of the horizontal arc at each interior corner, m."
    )

    @field_validator("points")
    @classmethod
    def _horizontal_legs(cls, points: tuple[Point3, ...]) -> tuple[Point3, ...]:
        _check_legs(tuple((x, y) for x, y, _ in points))
        return points


class _PlanarPathConfig(StrictModel):
    """A path in the horizontal plane, which a depth schedule may take down for 6-DOF."""

    depth: DepthScheduleConfig | None = Field(
        None,
        description=(
            "Depth below the surface over time (NED, m), for 6-DOF scenarios; none: the "
            "reference is planar."
        ),
    )


class PaperOvalConfig(_PlanarPathConfig):
    """The paper's semi-oval track (paper-model.md section 5): 100 s, counter-clockwise."""

    type: Literal["paper-oval"] = Field(
        "paper-oval", description="Reference type: the paper's semi-oval track, fixed geometry."
    )


class CircleConfig(_PlanarPathConfig):
    """A circle traversed at constant speed."""

    type: Literal["circle"] = Field("circle", description="Reference type: circle.")
    center: Point = Field((0.0, 0.0), description="Circle center [x, y] in the world frame, m.")
    radius: float = Field(10.0, gt=0.0, description="Circle radius, m.")
    speed: float = Field(0.5, gt=0.0, description="Constant speed along the circle, m/s.")
    direction: Literal["ccw", "cw"] = Field(
        "ccw", description="Direction of travel: 'ccw' (counter-clockwise) or 'cw' (clockwise)."
    )
    start_angle_deg: float = Field(
        0.0, description="Angle of the start point seen from the center, deg from world +x."
    )


class FigureEightConfig(_PlanarPathConfig):
    """A lemniscate of Gerono: x = cx + a sin(w t), y = cy + (a/2) sin(2 w t), w = 2 pi/period."""

    type: Literal["figure-eight"] = Field("figure-eight", description="Reference type: eight.")
    center: Point = Field(
        (0.0, 0.0), description="Crossing point [x, y] of the eight (where it starts), m."
    )
    size: float = Field(
        10.0, gt=0.0, description="Half-width a of the eight along x, m (half-height is a/2)."
    )
    period: float = Field(200.0, gt=0.0, description="Time for one full eight (both loops), s.")


class LineConfig(_PlanarPathConfig):
    """A straight line at constant speed, defined for all t (also before t = 0)."""

    type: Literal["line"] = Field("line", description="Reference type: straight line.")
    start: Point = Field((0.0, 0.0), description="Position [x, y] at t = 0, m.")
    heading_deg: float = Field(0.0, description="Direction of travel, deg from world +x (CCW).")
    speed: float = Field(0.5, gt=0.0, description="Constant speed, m/s.")


class WaypointsConfig(_PlanarPathConfig):
    """A polyline through waypoints with circular-arc corners, at constant speed."""

    type: Literal["waypoints"] = Field("waypoints", description="Reference type: waypoints.")
    points: tuple[Point, ...] = Field(
        ...,
        min_length=2,
        description=(
            "Waypoints [[x, y], ...] in m, at least 2, no two consecutive equal and no 180 deg "
            "reversal. Starts at the first at t = 0, holds at the last after arriving."
        ),
    )
    speed: float = Field(0.5, gt=0.0, description="Constant speed while moving, m/s.")
    corner_radius: float = Field(
        1.0,
        gt=0.0,
        description=(
            "Radius of the arc rounding each interior corner, m. Reduced automatically at a "
            "corner whose legs are too short for it."
        ),
    )

    @field_validator("points")
    @classmethod
    def _legs_have_direction(cls, points: tuple[Point, ...]) -> tuple[Point, ...]:
        _check_legs(points)
        return points


def _check_legs(points) -> None:
    """Consecutive waypoints differ and no leg reverses the previous one (m, [x, y])."""
    pts = np.asarray(points, dtype=float)
    legs = np.diff(pts, axis=0)
    for i, length in enumerate(np.hypot(legs[:, 0], legs[:, 1])):
        if length <= _MIN_LEG_LENGTH:
            raise ValueError(
                f"points[{i + 1}] = {list(points[i + 1])} equals points[{i}]; "
                "consecutive waypoints must differ"
            )
    headings = np.arctan2(legs[:, 1], legs[:, 0])
    for i, turn in enumerate(wrap_angle(np.diff(headings))):
        if abs(turn) >= math.pi - _REVERSAL_TOLERANCE:
            raise ValueError(
                f"the path reverses (180 deg turn) at points[{i + 1}] = {list(points[i + 1])}"
                "; no arc can round it, add a waypoint to the side"
            )


class CsvConfig(_PlanarPathConfig):
    """A track sampled in a CSV file with columns t, x, y, interpolated by a cubic spline."""

    type: Literal["csv"] = Field("csv", description="Reference type: track from a CSV file.")
    path: str = Field(
        ...,
        min_length=1,
        description=(
            "CSV file with header columns t, x, y (s, m, m; other columns ignored), t strictly "
            "increasing (rows at least 1 us apart) and used as simulation time as is, at least "
            "4 rows, |t| <= 1e9 s, |x|, |y| <= 1e7 m. A relative path is relative to the "
            "scenario file's folder."
        ),
    )


ReferenceConfig = Annotated[
    PaperOvalConfig
    | CircleConfig
    | FigureEightConfig
    | LineConfig
    | WaypointsConfig
    | CsvConfig
    | HelixConfig
    | LawnmowerConfig
    | Waypoints3DConfig,
    Field(discriminator="type"),
]

_CONFIG_MODELS: tuple[type[StrictModel], ...] = get_args(get_args(ReferenceConfig)[0])

#: Names accepted in a scenario's ``reference.type``, in documentation order.
REFERENCE_TYPES: tuple[str, ...] = tuple(
    get_args(model.model_fields["type"].annotation)[0] for model in _CONFIG_MODELS
)


# --------------------------------------------------------------------------------------------
# Reference base class and helpers
# --------------------------------------------------------------------------------------------


class Reference(ABC):
    """A state reference ``[x, y, psi, u, v, r]`` as a function of time, vectorised over t.

    Subclasses implement ``_states`` on a validated 1-D float array; everything a caller uses
    goes through ``states`` so every type shares the checks and conventions.
    """

    @property
    def end_time(self) -> float | None:
        """Time (s) at which the defining path ends, or None for an endless path."""
        return None

    @property
    def breakpoints(self) -> np.ndarray:
        """Times (s) at which the reference's derivatives may jump (joints, start and end)."""
        return np.empty(0)

    @property
    def corners(self) -> int:
        """How many corners the path turns: arcs joining straight legs of a polyline that
        turn by CORNER_TURN_DEG or more (a sampled path has none)."""
        return 0

    #: The depth reference of a 3-D path, None for a planar one (see :meth:`depths`).
    depth_profile: DepthProfile | None = None

    @property
    def has_depth(self) -> bool:
        """Whether the reference includes a depth (a 3-D path for a 6-DOF scenario)."""
        return self.depth_profile is not None

    def depths(self, t: ArrayLike) -> np.ndarray:
        """Depth reference at the given times, with its exact derivatives.

        Returns
        -------
        numpy.ndarray, shape (n, DEPTH_PROFILE.size)
            Rows ``[depth, depth rate, depth acceleration]``: depth below the surface (NED z,
            down positive) in m, m/s, m/s2.
        """
        if self.depth_profile is None:
            raise ValueError(f"{type(self).__name__}: a planar reference has no depth")
        return self.depth_profile.evaluate(_as_times(t))

    def states(self, t: ArrayLike) -> np.ndarray:
        """Reference states at the given times.

        Parameters
        ----------
        t : array_like, shape (n,)
            Times in s, any order, finite.

        Returns
        -------
        numpy.ndarray, shape (n, HORIZONTAL.size)
            Rows ``[x, y, psi, u, v, r]``; psi is continuous in t and independent of the query.
        """
        return self._states(_as_times(t))

    def state(self, t: float) -> np.ndarray:
        """Reference state ``[x, y, psi, u, v, r]`` at one time ``t`` (s)."""
        return self.states(np.array([t], dtype=float))[0]

    def positions(self, t: ArrayLike) -> np.ndarray:
        """Path positions ``[x, y]`` (m) at times ``t`` (s), shape (n, 2)."""
        return self.states(t)[:, HORIZONTAL.position]

    def preview(self, t0: float, dt: float, n: int) -> np.ndarray:
        """States ``[x, y, psi, u, v, r]`` at ``t0 + i*dt`` for i = 0..n-1, shape (n,
        HORIZONTAL.size).

        Times come from the integer i, never from accumulating dt, so sample i of a horizon is
        the same float whatever n is.
        """
        if not (math.isfinite(t0) and math.isfinite(dt) and dt > 0.0):
            raise ValueError(f"preview: need finite t0 and dt > 0, got t0={t0!r}, dt={dt!r}")
        if n < 0:
            raise ValueError(f"preview: need n >= 0, got n={n!r}")
        return self.states(t0 + dt * np.arange(n))

    @abstractmethod
    def _states(self, t: np.ndarray) -> np.ndarray:
        """States for a validated 1-D float array of times, shape (n, HORIZONTAL.size)."""


def _as_times(t: ArrayLike) -> np.ndarray:
    times = np.asarray(t, dtype=float)
    if times.ndim != 1:
        raise ValueError(f"t must be a 1-D array of times, got shape {times.shape}")
    if not np.all(np.isfinite(times)):
        raise ValueError("t must be finite, got NaN or inf")
    return times


def _assemble(
    x: ArrayLike, y: ArrayLike, psi: ArrayLike, u: ArrayLike, r: ArrayLike, n: int
) -> np.ndarray:
    out = np.empty((n, HORIZONTAL.size))
    # v_r = 0: the reference vehicle moves along its own heading.
    for name, value in zip(HORIZONTAL.names, (x, y, psi, u, 0.0, r), strict=True):
        out[:, HORIZONTAL.index(name)] = value
    return out


# --------------------------------------------------------------------------------------------
# Analytic references
# --------------------------------------------------------------------------------------------


class PaperOval(Reference):
    """The paper's semi-oval (paper-model.md section 5), counter-clockwise, 100 s.

    Pieces: straight x = 8, y = 0.5 t - 12 on t < 24; arc of radius 8, x = 8 cos(2 pi (t-24)/100),
    y = 8 sin(2 pi (t-24)/100) on 24 <= t < 74; straight x = -8, y = -0.5 (t - 74) on t >= 74.
    The straights' formulas also hold before t = 0 and after t = 100. The arc speed is
    8 * 2 pi/100 = 0.16 pi m/s, not 0.5: the paper's formula, kept, so u_r jumps slightly at
    t = 24 and t = 74. Heading is pi/2, then pi/2 + arc angle, then 3 pi/2 (unwrapped).
    """

    _ARC_START = 24.0  # s
    _ARC_END = 74.0  # s
    _END = 100.0  # s
    _RADIUS = 8.0  # m
    _LINE_SPEED = 0.5  # m/s
    _ARC_RATE = _TWO_PI / 100.0  # rad/s, angular rate of the arc

    def __init__(self, config: PaperOvalConfig | None = None) -> None:
        self.config = config if config is not None else PaperOvalConfig()

    @property
    def end_time(self) -> float | None:
        return self._END

    @property
    def breakpoints(self) -> np.ndarray:
        return np.array([self._ARC_START, self._ARC_END])

    def _states(self, t: np.ndarray) -> np.ndarray:
        first = t < self._ARC_START
        last = t >= self._ARC_END  # from the right: t = 74 belongs to the last straight
        arc = ~(first | last)
        angle = self._ARC_RATE * (t - self._ARC_START)
        x = np.where(first, 8.0, np.where(last, -8.0, self._RADIUS * np.cos(angle)))
        y = np.where(
            first, 0.5 * t - 12.0, np.where(last, -0.5 * (t - 74.0), self._RADIUS * np.sin(angle))
        )
        psi = np.where(first, 0.5 * math.pi, np.where(last, 1.5 * math.pi, 0.5 * math.pi + angle))
        u = np.where(arc, self._RADIUS * self._ARC_RATE, self._LINE_SPEED)
        r = np.where(arc, self._ARC_RATE, 0.0)
        return _assemble(x, y, psi, u, r, t.size)


class Circle(Reference):
    """A circle at constant speed; psi = phase +/- pi/2 in closed form, shifted into (-pi, pi]."""

    def __init__(self, config: CircleConfig) -> None:
        self.config = config
        sign = 1.0 if config.direction == "ccw" else -1.0
        self._center = np.asarray(config.center, dtype=float)
        self._phase0 = math.radians(config.start_angle_deg)
        self._omega = sign * config.speed / config.radius  # rad/s, signed
        # Tangent direction is the radial angle +/- pi/2; start it in (-pi, pi] and let it run.
        self._psi0 = float(wrap_angle(self._phase0 + sign * 0.5 * math.pi))

    def _states(self, t: np.ndarray) -> np.ndarray:
        phase = self._phase0 + self._omega * t
        x = self._center[0] + self.config.radius * np.cos(phase)
        y = self._center[1] + self.config.radius * np.sin(phase)
        psi = self._psi0 + self._omega * t
        return _assemble(x, y, psi, self.config.speed, self._omega, t.size)


class FigureEight(Reference):
    """Lemniscate of Gerono: x = cx + a sin(w t), y = cy + (a/2) sin(2 w t), w = 2 pi/period.

    Starts at the center heading pi/4, runs the right loop clockwise and the left loop
    counter-clockwise. Speed a w sqrt(cos^2(w t) + cos^2(2 w t)) never vanishes (when
    cos(w t) = 0, cos(2 w t) = -1). The heading winds by zero per period, so the unwrapped
    heading is periodic and has the closed form used in ``_states``.
    """

    def __init__(self, config: FigureEightConfig) -> None:
        self.config = config
        self._w = _TWO_PI / config.period

    def _states(self, t: np.ndarray) -> np.ndarray:
        a, w = self.config.size, self._w
        phase = w * t
        s1, c1 = np.sin(phase), np.cos(phase)
        s2, c2 = np.sin(2.0 * phase), np.cos(2.0 * phase)
        vx, vy = a * w * c1, a * w * c2
        ax, ay = -a * w * w * s1, -2.0 * a * w * w * s2
        # Right half (cos >= 0): principal atan2 is continuous there, in (-pi/2, pi/2).
        # Left half: atan2 of the reversed vector minus pi stays in (-3 pi/2, -pi/2) and meets
        # the right half at -pi/2 where cos(w t) = 0, so psi is continuous and periodic.
        psi = np.where(c1 >= 0.0, np.arctan2(c2, c1), np.arctan2(-c2, -c1) - math.pi)
        speed_sq = vx * vx + vy * vy
        r = (vx * ay - vy * ax) / speed_sq
        x = self.config.center[0] + a * s1
        y = self.config.center[1] + 0.5 * a * s2
        return _assemble(x, y, psi, np.sqrt(speed_sq), r, t.size)


class Line(Reference):
    """A straight line through ``start`` at t = 0, constant heading and speed, for all t."""

    def __init__(self, config: LineConfig) -> None:
        self.config = config
        heading = math.radians(config.heading_deg)
        self._psi = float(wrap_angle(heading))
        self._velocity = config.speed * np.array([math.cos(heading), math.sin(heading)])

    def _states(self, t: np.ndarray) -> np.ndarray:
        x = self.config.start[0] + self._velocity[0] * t
        y = self.config.start[1] + self._velocity[1] * t
        return _assemble(x, y, self._psi, self.config.speed, 0.0, t.size)


# --------------------------------------------------------------------------------------------
# Waypoints
# --------------------------------------------------------------------------------------------


class WaypointPath(Reference):
    """Waypoints joined by straight legs with circular-arc corners, run at constant speed.

    Corner rounding: at each interior waypoint the two legs are joined by an arc of radius
    ``corner_radius`` tangent to both, which starts and ends ``d = R tan(|turn|/2)`` from the
    waypoint and passes ``R (1/cos(|turn|/2) - 1)`` from it. A corner may use at most half of a
    leg shared with another corner, and all of the first or last leg; where ``d`` would exceed
    that, the radius of that corner alone is reduced to fit. The path starts at the first
    waypoint at t = 0, holds there (u = 0, r = 0, first heading) before, and holds at the last
    waypoint with the final heading after arriving at ``end_time``. Heading is unwrapped by
    construction: each piece starts at the previous piece's end heading.
    """

    def __init__(self, config: WaypointsConfig) -> None:
        self.config = config
        pts = np.asarray(config.points, dtype=float)
        legs = np.diff(pts, axis=0)
        lengths = np.hypot(legs[:, 0], legs[:, 1])
        units = legs / lengths[:, None]
        turns = wrap_angle(np.diff(np.arctan2(legs[:, 1], legs[:, 0])))  # (m-2,), each in (-pi, pi)
        leg_heading = math.atan2(legs[0, 1], legs[0, 0]) + np.concatenate(([0.0], np.cumsum(turns)))

        n_legs = lengths.size
        share = np.full(n_legs, 0.5)  # a leg between two corners gives each half
        share[0] = share[-1] = 1.0  # first and last legs have a corner at one end only
        half_tan = np.tan(0.5 * np.abs(turns))
        tangent = np.minimum.reduce(
            [
                config.corner_radius * half_tan,
                share[:-1] * lengths[:-1],  # room on the incoming leg
                share[1:] * lengths[1:],  # room on the outgoing leg
            ]
        )
        radius = np.divide(tangent, half_tan, out=np.zeros_like(tangent), where=half_tan > 0.0)
        # Tangent length at each end of each leg (0 at the path's ends).
        cut_in = np.concatenate(([0.0], tangent))
        cut_out = np.concatenate((tangent, [0.0]))

        starts: list[np.ndarray] = []  # piece start points
        headings: list[float] = []  # piece start headings (unwrapped)
        curvatures: list[float] = []  # signed, 1/m
        piece_lengths: list[float] = []
        scale = max(1.0, float(np.max(lengths)))
        corner_times: list[tuple[float, float]] = []
        travelled = 0.0  # path length before the current piece, m
        for j in range(n_legs):
            line_length = max(lengths[j] - cut_in[j] - cut_out[j], 0.0)
            if line_length > 1e-12 * scale:  # a leg fully eaten by its corners has no line
                starts.append(pts[j] + cut_in[j] * units[j])
                headings.append(float(leg_heading[j]))
                curvatures.append(0.0)
                piece_lengths.append(line_length)
            travelled += line_length
            if j == n_legs - 1:
                break
            arc_length = radius[j] * abs(turns[j]) if radius[j] > 0.0 else 0.0
            corner_times.append((travelled / config.speed, (travelled + arc_length) / config.speed))
            travelled += arc_length
            if radius[j] > 0.0:
                starts.append(pts[j + 1] - cut_out[j] * units[j])
                headings.append(float(leg_heading[j]))
                curvatures.append(math.copysign(1.0 / radius[j], turns[j]))
                piece_lengths.append(arc_length)

        self._starts = np.asarray(starts)
        self._headings = np.asarray(headings)
        self._curvatures = np.asarray(curvatures)
        self._lengths = np.asarray(piece_lengths)
        # Pieces are looked up by start time, the same floats ``breakpoints`` reports, so a
        # query exactly at a joint gets the piece starting there (derivatives from the right).
        self._piece_t0 = np.concatenate(([0.0], np.cumsum(self._lengths)[:-1])) / config.speed
        self._end = float(np.sum(self._lengths)) / config.speed
        self._final = pts[-1]
        self._final_heading = float(leg_heading[-1])
        #: Radius actually used at each interior waypoint, m (0 where the legs are collinear).
        self.corner_radii = radius
        #: (m-2, 2) start and end time (s) of the arc at each interior waypoint (equal where
        #: the legs are collinear and the path passes the waypoint itself).
        self.corner_times = np.array(corner_times, dtype=float).reshape(-1, 2)
        #: (m-2,) signed turn (rad) at each interior waypoint, 0 where the legs are collinear.
        self.corner_turns = turns

    @property
    def end_time(self) -> float | None:
        return self._end

    @property
    def breakpoints(self) -> np.ndarray:
        return np.append(self._piece_t0, self._end)

    @property
    def corners(self) -> int:
        return int(np.sum(np.abs(self.corner_turns) >= math.radians(CORNER_TURN_DEG)))

    def _states(self, t: np.ndarray) -> np.ndarray:
        speed = self.config.speed
        tc = np.clip(t, 0.0, self._end)
        moving = (t >= 0.0) & (t < self._end)
        k = np.searchsorted(self._piece_t0, tc, side="right") - 1
        sigma = np.minimum(speed * (tc - self._piece_t0[k]), self._lengths[k])
        h0, kappa, p0 = self._headings[k], self._curvatures[k], self._starts[k]
        psi = h0 + kappa * sigma
        straight = kappa == 0.0
        safe = np.where(straight, 1.0, kappa)
        dx = np.where(straight, sigma * np.cos(h0), (np.sin(psi) - np.sin(h0)) / safe)
        dy = np.where(straight, sigma * np.sin(h0), (np.cos(h0) - np.cos(psi)) / safe)
        x, y = p0[:, 0] + dx, p0[:, 1] + dy
        arrived = t >= self._end
        x = np.where(arrived, self._final[0], x)  # exactly the last waypoint, no round-off
        y = np.where(arrived, self._final[1], y)
        psi = np.where(arrived, self._final_heading, psi)
        u = np.where(moving, speed, 0.0)
        r = np.where(moving, speed * kappa, 0.0)
        return _assemble(x, y, psi, u, r, t.size)


# --------------------------------------------------------------------------------------------
# Depth profiles (3-D references): depth below the surface, NED z, with exact derivatives
# --------------------------------------------------------------------------------------------


_Z, _Z_RATE, _Z_ACCELERATION = (DEPTH_PROFILE.index(name) for name in DEPTH_PROFILE.names)


class DepthProfile(ABC):
    """Depth below the surface as a function of time, vectorised: rows [z, z', z'']."""

    @abstractmethod
    def evaluate(self, t: np.ndarray) -> np.ndarray:
        """(n, DEPTH_PROFILE.size) depth (m), rate (m/s) and acceleration (m/s2) at a 1-D
        array of times."""


class LinearDepth(DepthProfile):
    """z = start + rate t for all t (a helix)."""

    def __init__(self, start: float, rate: float) -> None:
        self.start, self.rate = float(start), float(rate)

    def evaluate(self, t: np.ndarray) -> np.ndarray:
        out = np.zeros((t.size, DEPTH_PROFILE.size))
        out[:, _Z] = self.start + self.rate * t
        out[:, _Z_RATE] = self.rate
        return out


class DepthSchedule(DepthProfile):
    """A start depth and non-overlapping smooth changes, each a quintic smooth step in time:
    s(tau) = 10 tau^3 - 15 tau^4 + 6 tau^5, tau = (t - t0) / T in [0, 1], whose rate and
    acceleration vanish at both ends, so z, z' and z'' are continuous everywhere.

    Parameters
    ----------
    start : float
        Depth before the first change, m.
    changes : sequence of (t0, duration, depth)
        Start time (s), duration (s, > 0) and depth after the change (m), in time order.
    """

    def __init__(self, start: float, changes) -> None:
        self.start = float(start)
        self.changes = tuple((float(t0), float(T), float(z)) for t0, T, z in changes)

    @classmethod
    def from_config(cls, config: DepthScheduleConfig) -> DepthSchedule:
        return cls(config.start_m, [(c.time_s, c.duration_s, c.depth_m) for c in config.changes])

    def evaluate(self, t: np.ndarray) -> np.ndarray:
        out = np.zeros((t.size, DEPTH_PROFILE.size))
        out[:, _Z] = self.start
        level = self.start
        for t0, duration, depth in self.changes:
            step = depth - level
            tau = np.clip((t - t0) / duration, 0.0, 1.0)
            inside = (t > t0) & (t < t0 + duration)
            out[:, _Z] += step * tau**3 * (10.0 - 15.0 * tau + 6.0 * tau * tau)
            rate = np.where(inside, step * 30.0 * tau**2 * (1.0 - tau) ** 2 / duration, 0.0)
            out[:, _Z_RATE] += rate
            out[:, _Z_ACCELERATION] += np.where(
                inside,
                step * 60.0 * tau * (1.0 - tau) * (1.0 - 2.0 * tau) / (duration * duration),
                0.0,
            )
            level = depth
        return out


class DepthStep:
    """The depth experiment's reference ``[z, w]`` (:data:`auvmpc.models.layout.DEPTH`): the
    setpoint of :class:`DepthStepConfig` at rest. Without ``preview`` a horizon of times sees
    the setpoint of its first time throughout (a commanded step is unknown until it happens).
    """

    layout = DEPTH

    def __init__(self, config: DepthStepConfig, preview: bool) -> None:
        self.config = config
        self.preview = preview

    def states(self, t: ArrayLike) -> np.ndarray:
        """(n, DEPTH.size) rows ``[z_ref, 0]`` at the times ``t`` (s), the first first."""
        times = np.asarray(t, dtype=float)
        if not self.preview:
            times = np.full_like(times, times[0])
        rows = np.zeros((times.size, DEPTH.size))  # at rest
        rows[:, DEPTH.index("z")] = self.config.depth(times)
        return rows


# --------------------------------------------------------------------------------------------
# 3-D references: a horizontal path for the horizontal controller plus a depth profile
# --------------------------------------------------------------------------------------------


class Helix(Reference):
    """A circle at constant horizontal speed (:class:`Circle`), the depth changing by
    ``descent_per_turn_m`` per turn: z' = descent speed / (2 pi radius), constant."""

    def __init__(self, config: HelixConfig) -> None:
        self.config = config
        self._circle = Circle(
            CircleConfig(
                center=config.center,
                radius=config.radius,
                speed=config.speed,
                direction=config.direction,
                start_angle_deg=config.start_angle_deg,
            )
        )
        rate = config.descent_per_turn_m * config.speed / (_TWO_PI * config.radius)
        self.depth_profile = LinearDepth(config.start_depth_m, rate)

    def _states(self, t: np.ndarray) -> np.ndarray:
        return self._circle._states(t)


class _AlongWaypoints(Reference):
    """A 3-D reference whose horizontal part is a :class:`WaypointPath` (``_path``)."""

    _path: WaypointPath

    @property
    def end_time(self) -> float | None:
        return self._path.end_time

    @property
    def breakpoints(self) -> np.ndarray:
        return self._path.breakpoints

    @property
    def corners(self) -> int:
        return self._path.corners

    def _states(self, t: np.ndarray) -> np.ndarray:
        return self._path._states(t)


class Lawnmower(_AlongWaypoints):
    """Parallel legs joined by half-circle turns of radius spacing / 2 (a :class:`WaypointPath`
    with corner radius spacing / 2, so each turn is two quarter circles), a depth per leg; the
    depth changes during the turn between two legs (quintic in time)."""

    def __init__(self, config: LawnmowerConfig) -> None:
        self.config = config
        heading = math.radians(config.heading_deg)
        along = np.array([math.cos(heading), math.sin(heading)])
        side = 1.0 if config.first_turn == "ccw" else -1.0
        across = side * np.array([-math.sin(heading), math.cos(heading)])
        points = []
        begin = np.asarray(config.start, dtype=float)
        for leg in range(config.legs):
            end = begin + (1.0 if leg % 2 == 0 else -1.0) * config.leg_length * along
            points += [begin, end]
            begin = end + config.spacing * across
        self._path = WaypointPath(
            WaypointsConfig(
                points=tuple((float(x), float(y)) for x, y in points),
                speed=config.speed,
                corner_radius=0.5 * config.spacing,
            )
        )
        depths = config.depths_m * (config.legs if len(config.depths_m) == 1 else 1)
        corners = self._path.corner_times
        changes = [
            (corners[2 * i, 0], corners[2 * i + 1, 1] - corners[2 * i, 0], depths[i + 1])
            for i in range(config.legs - 1)
            if depths[i + 1] != depths[i]
        ]
        self.depth_profile = DepthSchedule(depths[0], changes)


class Waypoints3D(_AlongWaypoints):
    """The horizontal :class:`WaypointPath` through the waypoints' [x, y]; the depth moves from
    one waypoint's depth to the next's (quintic in time) between the times the path passes
    them (the middle of each corner arc; the start and the end)."""

    def __init__(self, config: Waypoints3DConfig) -> None:
        self.config = config
        self._path = WaypointPath(
            WaypointsConfig(
                points=tuple((x, y) for x, y, _ in config.points),
                speed=config.speed,
                corner_radius=config.corner_radius,
            )
        )
        passing = np.concatenate(
            ([0.0], self._path.corner_times.mean(axis=1), [self._path.end_time])
        )
        depths = [depth for _, _, depth in config.points]
        changes = [
            (passing[i], passing[i + 1] - passing[i], depths[i + 1])
            for i in range(len(depths) - 1)
            if depths[i + 1] != depths[i] and passing[i + 1] > passing[i]
        ]
        self.depth_profile = DepthSchedule(depths[0], changes)


# --------------------------------------------------------------------------------------------
# Sampled track (CSV)
# --------------------------------------------------------------------------------------------


class SampledPath(Reference):
    """A track given as samples (t_i, x_i, y_i), interpolated by a C2 cubic spline.

    The spline is scipy's ``CubicSpline`` with not-a-knot ends, so x', y', x'', y'' exist and are
    continuous. Before the first time the track holds the first point, from the last time on it
    holds the last point (u = 0, r = 0, psi = heading at that end). Heading: a table of the
    unwrapped heading on ``16`` samples per knot interval is built once; a query takes the exact
    ``atan2`` of the spline velocity and adds the multiple of 2 pi that puts it nearest the
    table. Where the spline speed is below 1e-9 m/s the heading of the last table sample is held.

    Parameters
    ----------
    times : array_like, shape (n,)
        Strictly increasing, finite times in s, n >= 4.
    points : array_like, shape (n, 2)
        Finite positions [x, y] in m.
    """

    def __init__(self, times: ArrayLike, points: ArrayLike) -> None:
        t = np.asarray(times, dtype=float)
        xy = np.asarray(points, dtype=float)
        if t.ndim != 1 or t.size < _CSV_MIN_ROWS or xy.shape != (t.size, 2):
            raise ValueError(
                f"SampledPath: need times (n,) and points (n, 2) with n >= {_CSV_MIN_ROWS}, "
                f"got {t.shape} and {xy.shape}"
            )
        if not (np.all(np.isfinite(t)) and np.all(np.isfinite(xy))):
            raise ValueError("SampledPath: times and points must be finite")
        if not np.all(np.diff(t) > 0.0):
            raise ValueError("SampledPath: times must be strictly increasing")
        self._t0, self._t1 = float(t[0]), float(t[-1])
        self._knots = t
        self._spline = CubicSpline(t, xy, axis=0)
        self._d1 = self._spline.derivative(1)
        self._d2 = self._spline.derivative(2)

        fractions = np.arange(_TABLE_SAMPLES_PER_INTERVAL) / _TABLE_SAMPLES_PER_INTERVAL
        grid = (t[:-1, None] + np.diff(t)[:, None] * fractions).ravel()
        self._table_t = np.append(grid, t[-1])
        velocity = self._d1(self._table_t)
        moving = np.hypot(velocity[:, 0], velocity[:, 1]) > _STATIONARY_SPEED
        moving_idx = np.flatnonzero(moving)
        if moving_idx.size == 0:  # the track never moves: any constant heading will do
            self._table_psi = np.zeros(self._table_t.size)
        else:
            # Unwrap over moving samples only (atan2(0, 0) is meaningless), then hold the last
            # moving heading across stationary samples (the first one before the first move).
            unwrapped = np.unwrap(np.arctan2(velocity[moving_idx, 1], velocity[moving_idx, 0]))
            last = np.searchsorted(moving_idx, np.arange(self._table_t.size), side="right") - 1
            self._table_psi = unwrapped[np.maximum(last, 0)]

    @property
    def end_time(self) -> float | None:
        return self._t1

    @property
    def breakpoints(self) -> np.ndarray:
        return np.array([self._t0, self._t1])

    def _states(self, t: np.ndarray) -> np.ndarray:
        tc = np.clip(t, self._t0, self._t1)
        xy = self._spline(tc)
        vel = self._d1(tc)
        acc = self._d2(tc)
        speed = np.hypot(vel[:, 0], vel[:, 1])
        moving = speed > _STATIONARY_SPEED
        wrapped = np.arctan2(vel[:, 1], vel[:, 0])
        guide = np.interp(tc, self._table_t, self._table_psi)
        psi = wrapped + _TWO_PI * np.round((guide - wrapped) / _TWO_PI)
        held = self._table_psi[np.searchsorted(self._table_t, tc, side="right") - 1]
        psi = np.where(moving, psi, held)
        speed_sq = np.where(moving, speed * speed, 1.0)
        r = np.where(moving, (vel[:, 0] * acc[:, 1] - vel[:, 1] * acc[:, 0]) / speed_sq, 0.0)
        on_track = (t >= self._t0) & (t < self._t1)  # from the right: at t1 it already holds
        u = np.where(on_track, speed, 0.0)
        r = np.where(on_track, r, 0.0)
        return _assemble(xy[:, 0], xy[:, 1], psi, u, r, t.size)


def load_track_csv(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """Read a track CSV (header with columns t, x, y; others ignored).

    Parameters
    ----------
    path : pathlib.Path
        The file to read.

    Returns
    -------
    times : numpy.ndarray, shape (n,)
        Strictly increasing times, s.
    points : numpy.ndarray, shape (n, 2)
        Positions [x, y], m.

    Raises
    ------
    ConfigError
        Field ``reference.path`` for file-level problems (missing, a pipe or device, a
        folder, binary, not UTF-8, over :data:`MAX_TRACK_BYTES`, unreadable, no header,
        missing column, too few rows), ``reference.path:<line>`` for
        a bad row (not a number,
        not finite, beyond the limits above, wrong field count, t not increasing or rows
        under 1 us apart), with the offending value.
    """
    where = str(path)
    if path.exists() and not (path.is_file() or path.is_dir()):  # open() would wait forever
        raise ConfigError(_CSV_FIELD, where, "is a pipe or device, expected a CSV file")
    if "\x00" in where:  # open() raises ValueError
        raise ConfigError(_CSV_FIELD, where, "holds a NUL character, which no file name can")
    text = read_text_file(path, _CSV_FIELD, "CSV track", MAX_TRACK_BYTES)
    try:
        reader = csv.reader(io.StringIO(text, newline=""))
        rows = [(reader.line_num, row) for row in reader]
    except csv.Error as exc:
        raise ConfigError(_CSV_FIELD, where, f"not a readable CSV file ({exc})") from None

    rows = [(line, row) for line, row in rows if any(cell.strip() for cell in row)]
    if not rows:
        raise ConfigError(_CSV_FIELD, where, "empty file, expected a header row t,x,y")
    header = [name.strip() for name in rows[0][1]]
    for name in _CSV_COLUMNS:
        if name not in header:
            shown = shortened(", ".join(header))
            raise ConfigError(_CSV_FIELD, where, f"missing column '{name}' (header: {shown})")
        if header.count(name) > 1:
            raise ConfigError(_CSV_FIELD, where, f"column '{name}' appears more than once")
    columns = [header.index(name) for name in _CSV_COLUMNS]

    values = np.empty((len(rows) - 1, 3))
    for i, (line, row) in enumerate(rows[1:]):
        field = f"{_CSV_FIELD}:{line}"
        if len(row) != len(header):
            raise ConfigError(field, row, f"expected {len(header)} fields like the header")
        for j, (name, col) in enumerate(zip(_CSV_COLUMNS, columns, strict=True)):
            text = row[col].strip()
            try:
                value = float(text)
            except ValueError:
                raise ConfigError(field, text, f"column '{name}' is not a number") from None
            if not math.isfinite(value):
                raise ConfigError(field, text, f"column '{name}' is not finite")
            limit, unit = _CSV_LIMITS[name]
            if abs(value) > limit:
                raise ConfigError(field, text, f"column '{name}' is beyond +-{limit:g} {unit}")
            values[i, j] = value
        if i > 0 and values[i, 0] - values[i - 1, 0] < _CSV_MIN_STEP_S:
            rule = (
                "t must be strictly increasing"
                if values[i, 0] <= values[i - 1, 0]
                else f"t must be at least {_CSV_MIN_STEP_S:g} s after the row before"
            )
            raise ConfigError(field, values[i, 0], f"{rule} (previous t = {values[i - 1, 0]})")
    if values.shape[0] < _CSV_MIN_ROWS:
        raise ConfigError(
            _CSV_FIELD, where, f"needs at least {_CSV_MIN_ROWS} data rows, found {values.shape[0]}"
        )
    return values[:, 0].copy(), values[:, 1:].copy()


# --------------------------------------------------------------------------------------------
# Factory
# --------------------------------------------------------------------------------------------


def make_reference(config: ReferenceConfig, base_dir: Path | None = None) -> Reference:
    """Build the reference a validated config describes.

    Parameters
    ----------
    config : ReferenceConfig
        One of the reference config models (discriminated by ``type``).
    base_dir : pathlib.Path, optional
        Folder a relative CSV path is taken from (the scenario file's folder); the current
        working directory when None.

    Returns
    -------
    Reference

    Raises
    ------
    ConfigError
        For a CSV track that cannot be read (see ``load_track_csv``).
    """
    reference = _make_planar_or_3d(config, base_dir)
    depth = getattr(config, "depth", None)  # a planar path's optional depth schedule
    if depth is not None:
        reference.depth_profile = DepthSchedule.from_config(depth)
    return reference


def _make_planar_or_3d(config: ReferenceConfig, base_dir: Path | None) -> Reference:
    match config:
        case PaperOvalConfig():
            return PaperOval(config)
        case CircleConfig():
            return Circle(config)
        case FigureEightConfig():
            return FigureEight(config)
        case LineConfig():
            return Line(config)
        case WaypointsConfig():
            return WaypointPath(config)
        case CsvConfig():
            path = Path(config.path)
            if not path.is_absolute() and base_dir is not None:
                path = Path(base_dir) / path
            times, points = load_track_csv(path)
            return SampledPath(times, points)
        case HelixConfig():
            return Helix(config)
        case LawnmowerConfig():
            return Lawnmower(config)
        case Waypoints3DConfig():
            return Waypoints3D(config)
    raise TypeError(f"make_reference: not a reference config: {type(config).__name__}")
