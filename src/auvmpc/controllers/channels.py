"""The paper's control architecture on the 6-DOF vehicle (paper section 4.2): two control
channels, each on its own reduced model, on one set of thrusters.

Every sample the horizontal controller (any registered one, built on the 3-DOF model) sees
the measured ``[x, y, psi, u, v, r]``; the depth MPC (controllers/depth_mpc.py) sees the
measured depth and depth rate and the depth reference; :class:`ThrustMapping` puts both
demands on the vehicle's ``six_dof.thrusters`` within their hard force and rate limits. Roll
and pitch are left to passive stability. To the loop and the session the pair is one
controller (:class:`HorizontalAndDepth`) of the 6-DOF log's layouts (sim/log.py,
``SIX_DOF_LOG``).

Conventions: the plant, the log and the 3-D reference use NED (z down, the depth below the
surface); the depth controller works in z up (negative below the surface), as in the tank
experiment. The conversion happens here and nowhere else: z_up = -z, z_up' = -z'.

A controller that commands every thruster itself (a thrust table played open loop, the
6-DOF identification manoeuvre of ``auvmpc excite --dof six-dof``) takes the pair's place
as :class:`EveryThruster`: no depth channel, no mapping.

Thrusters: the first ``n`` entries of ``six_dof.thrusters`` are the horizontal ones, in the
order of the 3-DOF ``thrusters`` (the horizontal controller's), with that vehicle's thrust and
rate limits; the rest are the vertical set, with the ``heave`` section's limits. The depth
controller's total heave force is split over the vertical set by least squares on their heave
(Z) row: the least-norm split, which for a symmetric set is equal thrust and no roll moment.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from auvmpc.controllers.base import Controller, ControlResult, Observation, timed_command
from auvmpc.models.actuators import WRENCH
from auvmpc.models.layout import DEPTH_PROFILE, HORIZONTAL
from auvmpc.models.six_dof import SIX_DOF, SIX_DOF_MEASUREMENT, depth_rate, horizontal_state
from auvmpc.models.vehicle import VehicleParams

__all__ = [
    "ChannelResult",
    "EveryThruster",
    "HorizontalAndDepth",
    "ThrustMapping",
    "ReferenceWithDepth",
]

# Slack in a saturation check: far below any physical force.
CLIP_TOLERANCE_N = 1e-9
_DEPTH = SIX_DOF.index("z")  # NED, down (m)
# Where the navigation solution and the depth sensor's [z, z'] (NED) sit in the measurement.
_MEASURED_HORIZONTAL = SIX_DOF_MEASUREMENT.span("x", "r")
_MEASURED_DEPTH = SIX_DOF_MEASUREMENT.span("z", "z_rate")
_HEAVE = WRENCH.index("Z")  # the heave force's row of an allocation matrix (NED, down)


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
        heave_row = np.asarray(six.T)[_HEAVE, n:]  # NED Z force per unit thrust of each vertical
        self._heave_row = heave_row
        # Least-norm F_v with heave_row @ F_v = Z: F_v = pinv(heave_row) Z.
        self.heave_split = self._healthy_split = heave_row / float(heave_row @ heave_row)
        self._split_effectiveness = np.ones(heave_row.size)
        limits = vehicle.six_dof_actuators.limits
        self.lower, self.upper, self.rate_limit = limits.lower, limits.upper, limits.rate
        self.max_step = sample_time * self.rate_limit

    def vertical(
        self, heave_force_up: float, effectiveness: np.ndarray | None = None
    ) -> np.ndarray:
        """The vertical thrusters' forces for an upward heave force (N): NED Z = -force, the
        least-norm split over the verticals as they act (``effectiveness``, theirs only; None:
        all healthy), so a dead one gets nothing."""
        if effectiveness is None:
            return self._healthy_split * (-heave_force_up)
        if not np.array_equal(effectiveness, self._split_effectiveness):
            self._split_effectiveness = np.array(effectiveness, dtype=float)
            acting = self._heave_row * self._split_effectiveness
            strength = float(acting @ acting)
            self.heave_split = acting / strength if strength > 0.0 else np.zeros(acting.size)
        return self.heave_split * (-heave_force_up)

    def apply(self, demand: np.ndarray, previous: np.ndarray) -> tuple[np.ndarray, int]:
        """``demand`` (n_total,) saturated to the rate limits from ``previous`` and to the force
        limits; also the number of thrusters whose demand had to be changed."""
        low = np.maximum(self.lower, previous - self.max_step)
        high = np.minimum(self.upper, previous + self.max_step)
        applied = np.clip(demand, low, high)
        return applied, int(np.sum(np.abs(applied - demand) > CLIP_TOLERANCE_N))


@dataclass
class ChannelResult(ControlResult):
    """The horizontal controller's result (status, diagnostics), the mapped command of every
    thruster, and what the depth channel and the mapping did (SIX_DOF_LOG's columns)."""

    horizontal_solve_ms: float = 0.0
    depth_solve_ms: float = 0.0
    depth_status: str = "ok"  # a ControlStatus value
    saturated: int = 0  # thrusters whose demand the mapping had to change


class ReferenceWithDepth:
    """A 3-D reference as the pair sees it: rows ``[x, y, psi, u, v, r, z, z']`` (NED), the
    horizontal reference and the depth's (SIX_DOF_LOG's ``reference_names``)."""

    def __init__(self, reference) -> None:
        self.reference = reference  # a references.Reference with a depth profile

    def states(self, t: np.ndarray) -> np.ndarray:
        depth = self.reference.depths(t)[:, DEPTH_PROFILE.span("z", "z_rate")]
        return np.hstack([self.reference.states(t), depth])


class HorizontalAndDepth(Controller):
    """The horizontal controller and the depth MPC as one controller of the 6-DOF vehicle.

    It sees the 6-DOF measurement (``SIX_DOF_MEASUREMENT``) and a :class:`ReferenceWithDepth`
    preview; it returns every ``six_dof`` thruster's force (:class:`ChannelResult`).
    ``depth_preview``: the depth MPC sees the reference ahead (else today's, held).
    """

    def __init__(
        self,
        horizontal: Controller,
        depth,  # controllers.depth_mpc.DepthMpc
        vehicle: VehicleParams,
        depth_preview: bool,
    ) -> None:
        self.horizontal, self.depth, self.depth_preview = horizontal, depth, depth_preview
        self.sample_time = horizontal.sample_time
        self.preview_steps = max(horizontal.preview_steps, depth.preview_steps)
        self.mapping = ThrustMapping(vehicle, self.sample_time)
        self._heave_count = depth.heave.thruster_count

    def reset(self, initial_state: np.ndarray, initial_thrust: np.ndarray) -> None:
        """``initial_state``: the true 6-DOF start (SIX_DOF order); ``initial_thrust`` every
        thruster's F(-1) (the depth channel's total heave starts from 0)."""
        n = self.mapping.n_horizontal
        self._previous = np.asarray(initial_thrust, dtype=float).copy()
        self.horizontal.reset(horizontal_state(initial_state), self._previous[:n].copy())
        self.depth.reset(
            np.array([-initial_state[_DEPTH], -depth_rate(initial_state)]),
            np.zeros(self._heave_count),
        )

    def compute(self, observation: Observation) -> ChannelResult:
        mapping, measured, reference = self.mapping, observation.state, observation.reference
        # Every thruster's effectiveness: the horizontal ones' first, then the verticals'.
        told = observation.effectiveness
        n = mapping.n_horizontal
        horizontal_observation = Observation(
            k=observation.k,
            t=observation.t,
            state=measured[_MEASURED_HORIZONTAL],
            reference=reference[: self.horizontal.preview_steps + 1, : HORIZONTAL.size],
            obstacles=observation.obstacles,
            effectiveness=None if told is None else told[:n],
        )
        result, horizontal, horizontal_ms = timed_command(
            self.horizontal, horizontal_observation, mapping.n_horizontal
        )
        target = reference[: self.depth.preview_steps + 1, HORIZONTAL.size :]
        if not self.depth_preview:
            target = np.repeat(target[:1], len(target), axis=0)
        measured_depth, measured_rate = measured[_MEASURED_DEPTH]
        depth_observation = Observation(
            k=observation.k,
            t=observation.t,
            state=np.array([-measured_depth, -measured_rate]),
            reference=-target,  # [z_ref, z_rate_ref] down -> DEPTH's [z, w] up
            effectiveness=None if told is None else told[n:],
        )
        depth_result, heave, depth_ms = timed_command(
            self.depth, depth_observation, self._heave_count, "depth controller"
        )
        if told is None:
            vertical = mapping.vertical(float(heave.sum()))
        else:  # the heave force the depth MPC predicts its thrusts make, as they act
            vertical = mapping.vertical(float(heave @ told[n:]), told[n:])
        demand = np.concatenate([horizontal, vertical])
        thrust, saturated = mapping.apply(demand, self._previous)
        self._previous = thrust
        return ChannelResult(
            thrust, result.status, result.solve_time_s, info=result.info,
            horizontal_solve_ms=horizontal_ms, depth_solve_ms=depth_ms,
            depth_status=str(depth_result.status), saturated=saturated,
        )  # fmt: skip


class EveryThruster(Controller):
    """A controller of every ``six_dof`` input at once (``thrust-playback`` of a 6-DOF
    table: roll and pitch moments the depth channel's equal split cannot make; a controller of
    the whole vehicle, ``Controller.whole_vehicle``, e.g. ``six-dof-nmpc``), as the 6-DOF
    loop sees the pair: a :class:`ChannelResult` with the depth channel idle. It sees the
    6-DOF observation as it is; its command goes to the thrusters unmapped (it keeps its own
    limits)."""

    def __init__(self, controller: Controller) -> None:
        self.controller = controller
        self.sample_time = controller.sample_time
        self.preview_steps = controller.preview_steps

    def reset(self, initial_state: np.ndarray, initial_thrust: np.ndarray) -> None:
        """The true 6-DOF start for a controller of the whole vehicle, else its horizontal
        part (a thrust table reads neither)."""
        whole = self.controller.whole_vehicle
        self.controller.reset(initial_state if whole else horizontal_state(initial_state),
                              initial_thrust)  # fmt: skip

    def compute(self, observation: Observation) -> ChannelResult:
        result = self.controller.compute(observation)
        return ChannelResult(
            result.thrust, result.status, result.solve_time_s, info=result.info,
            horizontal_solve_ms=1000.0 * result.solve_time_s,
        )  # fmt: skip
