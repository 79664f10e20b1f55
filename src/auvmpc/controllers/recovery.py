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

A torpedo flown by the whole vehicle's MPC (``six-dof-nmpc``) has no fixed thrusters for that
law: its recovery is :class:`AutopilotFeedback`, the torpedo's own classical autopilot
(``los-pid``: LOS guidance and PID loops designed on the same nominal model), engaged afresh
each time the optimiser hands over.

The depth MPC's recovery is :class:`DepthFeedback`: a critically damped PD on depth through
the nominal heave model (its damping, net buoyancy and the estimated force cancelled), on
the depth MPC's own estimate of depth and heave rate.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from auvmpc.controllers.base import Controller, Observation
from auvmpc.controllers.baseline import BaselineConfig
from auvmpc.controllers.tracking_law import (
    LAW_OUTPUTS,
    REFERENCE_ROWS,
    apply_law,
    tracking_law,
)
from auvmpc.models.heave import heave_damping_force
from auvmpc.models.layout import DEPTH, HORIZONTAL, PLANAR_FORCE
from auvmpc.models.six_dof import SIX_DOF
from auvmpc.models.vehicle import HeaveParams, VehicleParams

if TYPE_CHECKING:
    from auvmpc.controllers.shell import Proposal

__all__ = ["AutopilotFeedback", "DepthFeedback", "StabilisingFeedback"]

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
