"""The paper's control architecture on the 6-DOF plant (paper section 4.2).

Every sample: the horizontal controller (any registered one, built on the 3-DOF model) sees
``[x, y, psi, u, v, r]`` of the measured 6-DOF state; the depth MPC
(:mod:`auvmpc.controllers.depth_mpc`) sees the measured depth and depth rate and the depth
reference; :class:`ThrustMapping` puts both demands on the vehicle's ``six_dof.thrusters``
within their hard force and rate limits; the 6-DOF plant (:mod:`auvmpc.models.six_dof`)
integrates the held thrust with RK4 sub-steps in the water current. Roll and pitch are left
to passive stability.

Conventions: the plant, the log and the 3-D reference use NED (z down, the depth below the
surface); the depth controller works in z up (negative below the surface), as in the tank
experiment. The conversion happens here and nowhere else: z_up = -z, z_up' = -z'.

Thrusters: the first ``n`` entries of ``six_dof.thrusters`` are the horizontal ones, in the
order of the 3-DOF ``thrusters`` (the horizontal controller's), with that vehicle's thrust and
rate limits; the rest are the vertical set, with the ``heave`` section's limits. The depth
controller's total heave force is split over the vertical set by least squares on their heave
(Z) row: the least-norm split, which for a symmetric set is equal thrust and no roll moment.
"""

from __future__ import annotations

import csv
import dataclasses
import io
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from auvmpc.controllers.base import Controller, Observation
from auvmpc.environment.currents import WaterCurrent
from auvmpc.environment.disturbances import SensorNoise
from auvmpc.environment.obstacle_sensor import ObstaclePerception
from auvmpc.environment.obstacles import clearance, visible_obstacles
from auvmpc.models.layout import HORIZONTAL
from auvmpc.models.six_dof import SIX_DOF, check_pitch, depth_rate, integrate, six_dof_model
from auvmpc.models.vehicle import VehicleParams
from auvmpc.references import Reference
from auvmpc.sim.log import BACKOFF_NAMES, ESTIMATE_NAMES, SimLog, csv_number
from auvmpc.sim.loop import timed_command
from auvmpc.sim.plant import substeps_for

__all__ = [
    "EXTRA_STATE_NAMES",
    "SixDofLog",
    "ThrustMapping",
    "closed_loop_six_dof",
    "horizontal_state",
]

# The 6-DOF state's columns beyond the horizontal ones (x, y, psi, u, v, r).
EXTRA_STATE_NAMES = ("z", "phi", "theta", "w", "p", "q")
# Where [x, y, psi, u, v, r] and the rest sit in [x, y, z, phi, theta, psi, u, v, w, p, q, r].
HORIZONTAL_INDEX = np.array([SIX_DOF.index(name) for name in HORIZONTAL.names])
EXTRA_INDEX = np.array([SIX_DOF.index(name) for name in EXTRA_STATE_NAMES])
_DEPTH = SIX_DOF.index("z")  # NED, down (m)
_POSITION = SIX_DOF.position
DEPTH_REFERENCE_NAMES = ("z_ref", "z_rate_ref")
CURRENT_NAMES = ("current_north", "current_east", "current_down")
# Slack in a saturation check: far below any physical force.
CLIP_TOLERANCE_N = 1e-9


def horizontal_state(state: np.ndarray) -> np.ndarray:
    """``[x, y, psi, u, v, r]`` (6,) of a 6-DOF state (12,) (or rows of them)."""
    return np.asarray(state)[..., HORIZONTAL_INDEX]


class ThrustMapping:
    """Horizontal and heave demands onto the 6-DOF thrusters, within the hard limits.

    Parameters
    ----------
    vehicle : VehicleParams
        With ``six_dof`` and ``heave`` sections; its first ``n_thrusters`` six_dof entries
        are the horizontal ones.
    sample_time : float
        s; the rate limits allow ``rate * sample_time`` per sample.
    """

    def __init__(self, vehicle: VehicleParams, sample_time: float) -> None:
        six, heave = vehicle.six_dof, vehicle.heave
        if six is None or heave is None:
            raise ValueError(f"vehicle {vehicle.name!r} needs six_dof and heave sections")
        self.n_horizontal = n = vehicle.n_thrusters
        self.n_total = six.n_thrusters
        heave_row = np.asarray(six.T)[2, n:]  # NED Z force per unit thrust of each vertical
        # Least-norm F_v with heave_row @ F_v = Z: F_v = pinv(heave_row) Z.
        self.heave_split = heave_row / float(heave_row @ heave_row)
        count = self.n_total - n
        self.lower = np.concatenate(
            [np.full(n, vehicle.thrust_limits[0]), np.full(count, heave.thrust_limits[0])]
        )
        self.upper = np.concatenate(
            [np.full(n, vehicle.thrust_limits[1]), np.full(count, heave.thrust_limits[1])]
        )
        self.rate_limit = np.concatenate(  # N/s
            [np.full(n, vehicle.thrust_rate_limit), np.full(count, heave.thrust_rate_limit)]
        )
        self.max_step = sample_time * self.rate_limit

    def vertical(self, heave_force_up: float) -> np.ndarray:
        """The vertical thrusters' forces for an upward heave force (N): NED Z = -force."""
        return self.heave_split * (-heave_force_up)

    def apply(self, demand: np.ndarray, previous: np.ndarray) -> tuple[np.ndarray, int]:
        """``demand`` (n_total,) saturated to the rate limits from ``previous`` and to the force
        limits; also the number of thrusters whose demand had to be changed."""
        low = np.maximum(self.lower, previous - self.max_step)
        high = np.minimum(self.upper, previous + self.max_step)
        applied = np.clip(demand, low, high)
        return applied, int(np.sum(np.abs(applied - demand) > CLIP_TOLERANCE_N))


@dataclass
class SixDofLog(SimLog):
    """A :class:`SimLog` whose ``state``, ``reference`` hold the horizontal part, plus the 6-DOF
    rest. ``thrust`` has one column per ``six_dof`` thruster (horizontal ones first)."""

    full_state: np.ndarray  # (N+1, 12) true [x, y, z, phi, theta, psi, u, v, w, p, q, r]
    depth_reference: np.ndarray  # (N+1, 2) [z_ref, z_ref'] NED (m, m/s)
    current_world: np.ndarray  # (N+1, 3) water velocity at the vehicle over [t_k, t_k+1) (m/s)
    depth_solve_ms: np.ndarray  # (N,) wall time of the depth controller call
    depth_status: list[str]  # (N,)
    saturated: np.ndarray  # (N,) thrusters whose demand the mapping had to change
    n_horizontal: int

    @classmethod
    def allocate_six_dof(
        cls, steps: int, n_horizontal: int, n_total: int, sample_time: float
    ) -> SixDofLog:
        base = SimLog.allocate(steps, n_total, sample_time)
        return cls(
            **base.__dict__,
            full_state=np.zeros((steps + 1, 12)),
            depth_reference=np.zeros((steps + 1, 2)),
            current_world=np.zeros((steps + 1, 3)),
            depth_solve_ms=np.zeros(steps),
            depth_status=[""] * steps,
            saturated=np.zeros(steps, dtype=int),
            n_horizontal=n_horizontal,
        )

    def horizontal(self) -> SimLog:
        """The horizontal view: the horizontal thrusters only (what the 3-DOF metrics and
        figures read, checked against the horizontal controller's limits)."""
        n = self.n_horizontal
        fields = {f.name: getattr(self, f.name) for f in dataclasses.fields(SimLog)}
        fields["thrust"] = self.thrust[:, :n]
        fields["initial_thrust"] = self.initial_thrust[:n]
        return SimLog(**fields)

    def columns(self) -> list[str]:
        return [
            *super().columns(),
            *EXTRA_STATE_NAMES,
            *DEPTH_REFERENCE_NAMES,
            *CURRENT_NAMES,
            "depth_solve_ms",
            "depth_status",
        ]

    def to_csv_text(self) -> str:
        base = super().to_csv_text().splitlines()
        buffer = io.StringIO()
        writer = csv.writer(buffer, lineterminator="\n")
        writer.writerow(self.columns())
        for k, line in enumerate(base[1:]):
            applied = k < self.steps
            row = next(csv.reader([line]))
            writer.writerow(
                [
                    *row,
                    *(csv_number(v) for v in self.full_state[k, EXTRA_INDEX]),
                    *(csv_number(v) for v in self.depth_reference[k]),
                    *(csv_number(v) for v in self.current_world[k]),
                    csv_number(self.depth_solve_ms[k]) if applied else "",
                    self.depth_status[k] if applied else "",
                ]
            )
        return buffer.getvalue()

    @classmethod
    def read_csv_six_dof(
        cls, path: Path, n_horizontal: int, initial_thrust: np.ndarray | None = None
    ) -> SixDofLog:
        """Load a log written by ``to_csv_text`` (values round-trip exactly)."""
        base = SimLog.read_csv(path, initial_thrust)
        with open(path, newline="") as handle:
            rows = list(csv.DictReader(handle))
        steps = base.steps
        log = cls.allocate_six_dof(steps, n_horizontal, base.n_thrusters, base.sample_time)
        for simlog_field in dataclasses.fields(SimLog):
            setattr(log, simlog_field.name, getattr(base, simlog_field.name))
        number = lambda row, name: float(row[name])  # noqa: E731
        for k, row in enumerate(rows):
            full = np.zeros(12)
            full[HORIZONTAL_INDEX] = base.state[k]
            full[EXTRA_INDEX] = [number(row, name) for name in EXTRA_STATE_NAMES]
            log.full_state[k] = full
            log.depth_reference[k] = [number(row, name) for name in DEPTH_REFERENCE_NAMES]
            log.current_world[k] = [number(row, name) for name in CURRENT_NAMES]
            if k < steps:
                log.depth_solve_ms[k] = number(row, "depth_solve_ms")
                log.depth_status[k] = row["depth_status"]
        return log


def closed_loop_six_dof(
    plant: VehicleParams,
    controller: Controller,
    depth_controller,
    reference: Reference,
    *,
    duration: float,
    initial_state: np.ndarray,
    current: WaterCurrent | None,
    sensor: SensorNoise,
    depth_noise: tuple[float, float],
    depth_rng: np.random.Generator,
    depth_preview: bool,
    max_plant_step: float,
    initial_thrust: np.ndarray | None = None,
    obstacles=(),
    perception: ObstaclePerception | None = None,
    vehicle_radius: float = 0.0,
    on_step: Callable[[int, int], None] | None = None,
) -> SixDofLog:
    """Run both controllers against the 6-DOF ``plant`` for ``duration`` seconds.

    Parameters
    ----------
    plant : VehicleParams
        The simulated vehicle (``six_dof`` and ``heave`` sections).
    controller : Controller
        The horizontal controller; sees ``[x, y, psi, u, v, r]`` measured.
    depth_controller : auvmpc.controllers.depth_mpc.DepthMpc
        Sees ``[z_up, z_up']`` measured and ``[z_up_ref, z_up_ref']`` (z up).
    initial_state : (12,) [x, y, z, phi, theta, psi, u, v, w, p, q, r]
    current : the water current, or None for still water
    depth_noise : (depth std m, depth-rate std m/s)
    initial_thrust : (n,) F(-1) of the horizontal thrusters; vertical ones start at 0.
    """
    sample_time = controller.sample_time
    steps = int(round(duration / sample_time))
    substeps = substeps_for(sample_time, max_plant_step)
    mapping = ThrustMapping(plant, sample_time)
    n = mapping.n_horizontal
    model = six_dof_model(plant)
    log = SixDofLog.allocate_six_dof(steps, n, mapping.n_total, sample_time)
    previous = np.zeros(mapping.n_total)
    if initial_thrust is not None:
        previous[:n] = initial_thrust
    log.initial_thrust = previous.copy()
    heave_count = depth_controller.heave.thruster_count

    state = np.asarray(initial_state, dtype=float).copy()
    check_pitch(state)
    controller.reset(horizontal_state(state), previous[:n].copy())
    depth_controller.reset(np.array([-state[_DEPTH], -depth_rate(state)]), np.zeros(heave_count))
    preview = sample_time * np.arange(controller.preview_steps + 1)
    depth_preview_times = sample_time * np.arange(depth_controller.preview_steps + 1)
    depth_std, rate_std = depth_noise
    profile = current is not None and bool(current.config.depth_profile)
    for k in range(steps + 1):
        t = log.t[k]
        previewed = reference.states(t + preview)  # its first row is the reference at t
        log.full_state[k] = state
        log.state[k] = horizontal_state(state)
        log.reference[k] = previewed[0]
        log.depth_reference[k] = reference.depths([t])[0, :2]
        log.clearance_m[k] = clearance(state[_POSITION], t, obstacles, vehicle_radius)
        velocity = np.zeros(3)
        if current is not None:
            velocity = current.at(t, state[_DEPTH], depth_rate(state))[0]
        log.current_world[k] = velocity
        if k == steps:
            break
        observation = Observation(
            k=k,
            t=t,
            state=sensor.measure(horizontal_state(state)),
            reference=previewed,
            obstacles=visible_obstacles(obstacles, t)
            if perception is None
            else perception.observe(t, state[_POSITION]),
        )
        result, horizontal, log.solve_ms[k] = timed_command(controller, observation, n)

        measured_depth = state[_DEPTH] + depth_std * depth_rng.standard_normal()
        measured_rate = depth_rate(state) + rate_std * depth_rng.standard_normal()
        times = t + depth_preview_times if depth_preview else np.full_like(depth_preview_times, t)
        target = reference.depths(times)
        depth_observation = Observation(
            k=k,
            t=t,
            state=np.array([-measured_depth, -measured_rate]),
            reference=np.column_stack([-target[:, 0], -target[:, 1]]),
        )
        depth_result, heave, log.depth_solve_ms[k] = timed_command(
            depth_controller, depth_observation, heave_count, "depth controller"
        )

        demand = np.concatenate([horizontal, mapping.vertical(float(heave.sum()))])
        thrust, log.saturated[k] = mapping.apply(demand, previous)
        log.thrust[k] = thrust
        log.status[k] = str(result.status)
        log.depth_status[k] = str(depth_result.status)
        log.disturbance_estimate[k] = [result.info.get(name, 0.0) for name in ESTIMATE_NAMES]
        log.backoff[k] = [result.info.get(name, 0.0) for name in BACKOFF_NAMES]
        if profile:
            state = integrate(
                model,
                state,
                thrust,
                sample_time,
                substeps,
                lambda time_s, x: current.at(time_s, x[_DEPTH], depth_rate(x)),
                t0=t,
            )
        else:  # uniform in space, held over the sample: the compiled RK4 step
            h = sample_time / substeps
            for _ in range(substeps):
                state = np.asarray(model.step(state, thrust, velocity, h), dtype=float).ravel()
                check_pitch(state)
        previous = thrust
        if current is not None:
            current.advance()
        if on_step is not None:
            on_step(k + 1, steps)
    return log
