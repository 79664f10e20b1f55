"""What the safety shell applies when no optimiser is in control: a stabilising feedback.

After a failed solve the shell (controllers/shell.py) follows the last good plan for at
most ``PLAN_FALLBACK_STEPS`` samples (it was feasible and rate-limited when it was made, and
the back end re-initialises meanwhile); after that, and whenever the vehicle spins, it applies
:class:`StabilisingFeedback`: the classical tracker of controllers/baseline.py (feedback
linearisation on the nominal model, PD, yaw first in the allocation; its one statement,
controllers/tracking_law.py, is what the exported C controller evaluates too) without its
integrators, fed the optimiser's own disturbance estimate instead, tracking the
reference or, where the way there crosses an obstacle, holding station. It damps the yaw
rate and any drift on any vehicle, since its gains are accelerations and the model supplies
the inertia. Never blind plan-following for long, never zero thrust.

The shell also applies it while the vehicle spins (``shell.spin_limit``), then starts the
optimiser again cold (docs/recovery.md).

The depth MPC's recovery is :class:`DepthFeedback`: a critically damped PD on depth through
the nominal heave model (its damping, net buoyancy and the estimated force cancelled), on
the depth MPC's own estimate of depth and heave rate.

The whole vehicle's MPC (``six-dof-nmpc``) recovers with what flies the vehicle without an
optimiser. A torpedo (no fixed thrusters for the law above) gets :class:`AutopilotFeedback`,
its own classical autopilot (``los-pid``: LOS guidance and PID loops designed on the same
nominal model), engaged afresh each time the optimiser hands over. A thruster vehicle the
channel pair can fly (the BlueROV2 Heavy: horizontal thrusters, a heave section and vertical
thrusters after them) gets :class:`ChannelFeedback`: the two feedbacks above on the 6-DOF
measurement, the stabilising one on the horizontal thrusters and the depth one on the
vertical, split over them as the pair's depth channel splits it (controllers/channels.py),
each allocation over the thrusters as they act, so a dead one is asked for nothing.

Which recovery a controller type's shell gets is its registry entry's (controllers/
registry.py): :func:`stabilising_recovery`, :func:`depth_recovery` or
:func:`whole_vehicle_recovery`.
"""

from __future__ import annotations

from dataclasses import replace
from typing import TYPE_CHECKING, Any

import numpy as np

from auvmpc.controllers.base import Controller, Observation
from auvmpc.controllers.baseline import BaselineConfig
from auvmpc.controllers.channels import ThrustMapping
from auvmpc.controllers.los_pid import LosPid, LosPidConfig, flies
from auvmpc.controllers.tracking_law import (
    LAW_OUTPUTS,
    REFERENCE_ROWS,
    apply_law,
    tracking_law,
)
from auvmpc.errors import FieldError
from auvmpc.models.heave import heave_damping_force, resolve_heave
from auvmpc.models.layout import DEPTH, HORIZONTAL, PLANAR_FORCE
from auvmpc.models.six_dof import SIX_DOF, depth_rate, horizontal_state
from auvmpc.models.vehicle import HeaveParams, VehicleParams
from auvmpc.models.vehicle import dynamics as planar_dynamics

if TYPE_CHECKING:
    from auvmpc.controllers.shell import Proposal, ShelledController

__all__ = [
    "AutopilotFeedback",
    "ChannelFeedback",
    "DepthFeedback",
    "Recovery",
    "StabilisingFeedback",
    "depth_recovery",
    "stabilising_recovery",
    "whole_vehicle_recovery",
]

_POSITION, _HEADING = HORIZONTAL.position, HORIZONTAL.heading
# The baseline's gains without integrators: the optimiser's estimate stands in for them.
_THRUST = LAW_OUTPUTS.index("thrust")
RECOVERY_GAINS = BaselineConfig(along_ki=0.0, cross_ki=0.0, heading_ki=0.0)


class StabilisingFeedback:
    """The shell's recovery law for horizontal vehicles (module docstring).

    It tracks the reference, where the optimiser's cold start converges best, unless the
    straight way there crosses an obstacle's keep-out disc (the feedback knows no
    obstacles): then it holds station where that was first found, at the reference's
    heading, until the optimiser is back or the way is clear."""

    watches_yaw = True  # the shell judges spins by the yaw rate of [x y psi u v r]
    yaw_rate_index = HORIZONTAL.index("r")

    def __init__(self, model: VehicleParams, sample_time: float, keep_out_extra: float) -> None:
        self.law = tracking_law(model, sample_time, RECOVERY_GAINS, settling_yaw=True)
        self._keep_out_extra = keep_out_extra  # vehicle radius + margin, m
        self._hold: np.ndarray | None = None  # (2,) world position held, m
        self._healthy = np.ones(model.n_thrusters)

    def release(self) -> None:
        """The optimiser is in control again: the next hold starts afresh."""
        self._hold = None

    def command(
        self, observation: Observation, previous: np.ndarray, proposal: Proposal
    ) -> np.ndarray:
        """Thrust for the coming sample within the force limits (the shell's projection
        applies the rate limit around ``previous``), allocated to the thrusters as the
        observation's effectiveness says they act."""
        state = np.asarray(observation.state, dtype=float)
        target = observation.reference[:REFERENCE_ROWS]  # now and one sample ahead
        if self._blocked(state[_POSITION], target[0, _POSITION], observation):
            if self._hold is None:
                self._hold = state[_POSITION].copy()
            target = np.zeros((REFERENCE_ROWS, HORIZONTAL.size))
            target[:, _POSITION] = self._hold
            target[:, _HEADING] = observation.reference[0, _HEADING]
        else:
            self._hold = None
        disturbance = proposal.disturbance
        if disturbance is None or np.size(disturbance) != PLANAR_FORCE.size:
            disturbance = np.zeros(PLANAR_FORCE.size)
        effectiveness = observation.effectiveness
        if effectiveness is None:
            effectiveness = self._healthy
        law = apply_law(self.law, state, target, np.ravel(disturbance), effectiveness)
        return law[_THRUST]

    def _blocked(self, start: np.ndarray, end: np.ndarray, observation: Observation) -> bool:
        """Whether the segment start-end passes inside any obstacle's keep-out disc."""
        way = end - start
        length2 = float(way @ way)
        for obstacle in observation.obstacles:
            along = (
                0.0
                if length2 == 0.0
                else float(np.clip((obstacle.center - start) @ way / length2, 0.0, 1.0))
            )
            gap = float(np.hypot(*(start + along * way - obstacle.center)))
            if gap < obstacle.radius + self._keep_out_extra:
                return True
        return False


# The depth feedback's bandwidth: at most this many rad/s, and at most this share of the
# sample rate (rad/s per 1/Te) so that the sampled PD stays well damped. 0.5 rad/s settles a
# depth error to 5 % in about 10 s: a recovery, not a tracker (tests/test_recovery.py).
DEPTH_BANDWIDTH_RAD_PER_S = 0.5
DEPTH_BANDWIDTH_PER_SAMPLE_RATE = 0.2
_Z, _W = DEPTH.index("z"), DEPTH.index("w")


class DepthFeedback:
    """The shell's recovery law for the depth MPC (module docstring): the heave force
    m (wn^2 (z_ref - z) + 2 wn (w_ref - w)) with the nominal damping, net buoyancy and the
    estimated force cancelled, shared equally by the vertical thrusters."""

    watches_yaw = False  # heave has no yaw to spin

    def __init__(self, heave: HeaveParams, sample_time: float) -> None:
        self._heave = heave
        self._bandwidth = min(
            DEPTH_BANDWIDTH_RAD_PER_S, DEPTH_BANDWIDTH_PER_SAMPLE_RATE / sample_time
        )

    def release(self) -> None:
        """Nothing held between recoveries."""

    def command(
        self, observation: Observation, previous: np.ndarray, proposal: Proposal
    ) -> np.ndarray:
        """Thrust for the coming sample (the shell projects it into the hard limits), shared
        by the vertical thrusters in proportion to their effectiveness (the minimum-norm
        share: equal when all are healthy, none to a dead one)."""
        heave = self._heave
        if proposal.estimated_state is not None:
            z, w = proposal.estimated_state[[_Z, _W]]
        else:  # no estimate this sample: the measured depth, at rest
            z, w = float(observation.state[_Z]), 0.0
        disturbance = (
            0.0 if proposal.disturbance is None else float(np.ravel(proposal.disturbance)[0])
        )
        target = observation.reference[0]
        wn = self._bandwidth
        acceleration = wn**2 * (target[_Z] - z) + 2.0 * wn * (target[_W] - w)
        drag = heave_damping_force(heave, w)
        force = heave.m_heave * acceleration - drag - heave.net_buoyancy_N - disturbance
        effectiveness = observation.effectiveness
        if effectiveness is None:
            return np.full(len(previous), force / len(previous))
        acting = float(effectiveness @ effectiveness)
        if acting == 0.0:  # none left to push: ask for nothing
            return np.zeros(len(previous))
        return (force / acting) * effectiveness


class AutopilotFeedback:
    """The shell's recovery law for a whole-vehicle controller of a torpedo (module
    docstring): ``autopilot``, a whole-vehicle controller at the shell's sample time
    (``los-pid``), reset to the vehicle's state and last command each time it takes over, so
    it starts without the wound-up integrals or stale path of an earlier engagement."""

    watches_yaw = True  # the shell judges spins by the yaw rate of the 6-DOF state
    yaw_rate_index = SIX_DOF.index("r")

    def __init__(self, autopilot: Controller) -> None:
        self.autopilot = autopilot
        self._engaged = False

    def release(self) -> None:
        """The optimiser is in control again: the next takeover starts afresh."""
        self._engaged = False

    def command(
        self, observation: Observation, previous: np.ndarray, proposal: Proposal
    ) -> np.ndarray:
        """The autopilot's command for the coming sample (within the hard limits)."""
        if not self._engaged:
            self.autopilot.reset(np.asarray(observation.state, dtype=float), previous)
            self._engaged = True
        return self.autopilot.compute(observation).thrust


_DEPTH_NED = SIX_DOF.index("z")  # the 6-DOF state's depth (m, down)


class ChannelFeedback:
    """The shell's recovery law for a thruster vehicle flown by a controller of the whole
    vehicle (module docstring): on the 6-DOF measurement ``[x y z phi theta psi u v w p q r]``
    and the 3-D reference rows ``[x y psi u v r z z']`` (NED), :class:`StabilisingFeedback`
    commands the horizontal thrusters and :class:`DepthFeedback` the heave force, which the
    depth channel's :class:`~auvmpc.controllers.channels.ThrustMapping` splits over the
    vertical thrusters. Roll and pitch are left to passive stability, as the pair leaves
    them. The stabilising law is fed the optimiser's estimate of the current
    (``Proposal.current``) as the force it makes on the nominal 3-DOF model; the depth law
    the measured depth and depth rate, with no force estimate (the nominal net buoyancy
    only)."""

    watches_yaw = True  # the shell judges spins by the yaw rate of the 6-DOF state
    yaw_rate_index = SIX_DOF.index("r")

    def __init__(self, model: VehicleParams, sample_time: float, keep_out_extra: float) -> None:
        self.horizontal = StabilisingFeedback(model, sample_time, keep_out_extra)
        self.depth = DepthFeedback(resolve_heave(model, {}), sample_time)
        self.mapping = ThrustMapping(model, sample_time)
        self._model = model

    def release(self) -> None:
        """The optimiser is in control again: the next hold starts afresh."""
        self.horizontal.release()
        self.depth.release()

    def _current_force(self, planar: np.ndarray, current: np.ndarray) -> np.ndarray:
        """The optimiser's current as the force estimate the stabilising law cancels: world
        [X, Y] and N that make the nominal 3-DOF model at ``planar`` ([x y psi u v r])
        accelerate as the water velocity ``current`` (world, m/s) makes it, i.e. its inertia
        times its accelerations with the current less those without (thrust enters both
        alike)."""
        model = self._model
        idle = np.zeros(model.n_thrusters)
        change = (
            planar_dynamics(planar, idle, model, current_world=current)
            - planar_dynamics(planar, idle, model)
        )[HORIZONTAL.span("u", "r")]
        body = np.array([model.m11, model.m22, model.Iz]) * change
        psi = planar[HORIZONTAL.heading]
        c, s = np.cos(psi), np.sin(psi)
        return np.array([c * body[0] - s * body[1], s * body[0] + c * body[1], body[2]])

    def command(
        self, observation: Observation, previous: np.ndarray, proposal: Proposal
    ) -> np.ndarray:
        """Every thruster's force for the coming sample (the shell projects it into the hard
        limits): the horizontal ones' first, then the vertical ones' (the 6-DOF layout)."""
        state = np.asarray(observation.state, dtype=float)
        reference = np.asarray(observation.reference, dtype=float)
        n = self.mapping.n_horizontal
        told = observation.effectiveness
        planar = horizontal_state(state)
        estimate = (
            None if proposal.current is None else self._current_force(planar, proposal.current)
        )
        horizontal_observation = replace(
            observation,
            state=planar,
            reference=reference[:, : HORIZONTAL.size],
            effectiveness=None if told is None else told[:n],
        )
        horizontal = self.horizontal.command(
            horizontal_observation, previous[:n], replace(proposal, disturbance=estimate)
        )
        # The depth channel's view: z and its rate up (DEPTH), as the pair gives its MPC.
        depth = np.array([-state[_DEPTH_NED], -depth_rate(state)])
        vertical_share = None if told is None else told[n:]
        depth_observation = replace(
            observation,
            state=depth,
            reference=-reference[:, HORIZONTAL.size :],
            effectiveness=vertical_share,
        )
        measured = replace(proposal, estimated_state=depth, disturbance=None)
        heave = self.depth.command(depth_observation, previous[n:], measured)
        if vertical_share is None:
            vertical = self.mapping.vertical(float(heave.sum()))
        else:  # the heave force those thrusts make as they act, split as the pair splits it
            vertical = self.mapping.vertical(float(heave @ vertical_share), vertical_share)
        return np.concatenate([horizontal, vertical])


# What a shell may apply when no optimiser is in control (ShelledController.recovery).
Recovery = StabilisingFeedback | DepthFeedback | AutopilotFeedback | ChannelFeedback

# Which recovery a controller type's shell gets (its registry entry's ``recovery``): built
# from the controller, its nominal vehicle and its configuration filled in for the vehicle.


def stabilising_recovery(
    controller: ShelledController, model: VehicleParams, config: Any
) -> StabilisingFeedback:
    """A horizontal MPC's: the stabilising feedback, keeping its obstacle clearance."""
    keep_out = config.vehicle_radius + config.obstacle_margin
    return StabilisingFeedback(model, controller.sample_time, keep_out)


def depth_recovery(
    controller: ShelledController, model: VehicleParams, config: Any
) -> DepthFeedback:
    """The depth MPC's: the depth feedback on its heave model."""
    return DepthFeedback(controller.heave, controller.sample_time)


def whole_vehicle_recovery(
    controller: ShelledController, model: VehicleParams, config: Any
) -> AutopilotFeedback | ChannelFeedback | None:
    """A controller of the whole vehicle's, by what ``model`` has: a torpedo its autopilot
    at the optimiser's sample time, a vehicle the channel pair can fly that pair's
    feedbacks; None for any other (the shell then holds the plan's last move)."""
    if flies(model):
        autopilot = LosPid(model, LosPidConfig(sample_time=controller.sample_time))
        return AutopilotFeedback(autopilot)
    if _pair_flies(model):
        keep_out = config.vehicle_radius + config.obstacle_margin
        return ChannelFeedback(model, controller.sample_time, keep_out)
    return None


def _pair_flies(model: VehicleParams) -> bool:
    """Whether the channel pair's feedbacks can fly ``model``: horizontal thrusters first in
    its ``six_dof`` thrusters, then the ``heave`` section's vertical ones (what a 6-DOF
    scenario checks before it flies the pair, scenario/resolved.py)."""
    if not model.has_thrusters or model.heave is None or model.six_dof is None:
        return False
    try:
        model.check_six_dof_layout()
    except FieldError:
        return False
    return model.six_dof.n_thrusters > model.n_thrusters
