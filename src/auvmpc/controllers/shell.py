"""The one safety shell around every optimising controller.

A back end (the paper's MPC, LTV-MPC, NMPC, the do-mpc yardstick, the depth MPC) only
*proposes* a thrust plan; :class:`ShelledController` decides what is applied:

* a proposal that failed, is not finite, or came later than ``solver_time_limit_ms`` is
  replaced by the previous plan's next move (FALLBACK) for at most
  :data:`PLAN_FALLBACK_STEPS` samples in a row; after that, without a plan, and
  whenever the vehicle spins, by a stabilising feedback (RECOVERY, controllers/recovery.py)
  where the controller has one (the horizontal MPCs, the depth MPC, six-dof-nmpc on a torpedo
  or a thruster vehicle the channel pair flies), and the back end starts again cold;
* whatever is applied is projected into the hard thrust and thrust-rate box, so no back end
  can command thrust outside the limits;
* the status says what happened (OK, RELAXED when a soft constraint's slack is active,
  SATURATED when the projection moved the command, FALLBACK, RECOVERY);
* ``info`` has the same keys for every back end (:data:`INFO_KEYS`).
"""

from __future__ import annotations

from abc import abstractmethod
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING

import numpy as np

from auvmpc.controllers.base import (
    ActuatorLimits,
    Controller,
    ControlResult,
    ControlStatus,
    Observation,
    next_planned_move,
)
from auvmpc.models.layout import HORIZONTAL, PLANAR_FORCE

if TYPE_CHECKING:
    from auvmpc.controllers.recovery import Recovery

__all__ = [
    "BACKOFF_KEYS",
    "ESTIMATE_KEYS",
    "INFO_KEYS",
    "LOGGED_INFO",
    "PLAN_FALLBACK_STEPS",
    "Proposal",
    "SPIN_ANGLE_PER_SAMPLE_RAD",
    "SPIN_REFERENCE_FACTOR",
    "ShelledController",
    "spin_limit",
]

# A slack below this is solver tolerance, not a relaxed constraint (m for obstacle rows).
SLACK_ACTIVE = 1e-6
# The projection moving the command by less than this (N) is round-off, not saturation.
_SATURATION_N = 1e-6

# The world-frame force and moment the prediction used (N, N, N m); zero without an estimator.
ESTIMATE_KEYS = ("dist_X_hat", "dist_Y_hat", "dist_N_hat")
# What the robust tightening took (ocp/tightening.py), in a back end's ``details``: the largest
# obstacle back-off (m) and the largest fraction of a thruster's range given up; zero (absent)
# for a nominal controller.
BACKOFF_KEYS = ("obstacle_backoff_m", "thrust_backoff_fraction")
# What a run's log keeps of every shelled controller's ``info``, by log field (sim/log.py).
LOGGED_INFO = {"disturbance_estimate": ESTIMATE_KEYS, "backoff": BACKOFF_KEYS}

INFO_KEYS = (
    "solver_iterations",  # QP iterations (summed over SQP passes) or IPOPT iterations
    "max_slack",  # largest slack of the soft constraints (m for obstacles)
    "solve_ms",  # the back end's own solve time
    "relaxed",  # 1 if a soft constraint was relaxed
    "fallback",  # 1 if no optimiser's proposal was applied (the plan's move or the feedback)
    *ESTIMATE_KEYS,
    "recovery",  # 1 if the shell's stabilising feedback was applied
    "spinning",  # 1 when the shell judged the vehicle to spin (spin_limit) at this sample
)
# The yaw rate in a reference row (horizontal and 6-DOF rows alike: controllers/channels.py).
_YAW_RATE = HORIZONTAL.index("r")

# Samples a failed optimiser may be covered by its last plan before the feedback takes over:
# the plan was feasible and rate-limited when it was made, and the back end re-initialises
# in the meantime (the bar: never more than 3 samples in a row without an optimiser).
PLAN_FALLBACK_STEPS = 2
# A spin is a yaw rate the sampled controller cannot see: more heading per sample than this
# (rad; 1.5 rad/s at 0.5 s; on 50 hard-survey cases the real-time NMPC stayed below 1.0 rad/s
# except on the two it spun on, ltv-mpc's spins reached 2-7 rad/s, docs/recovery.md) ...
SPIN_ANGLE_PER_SAMPLE_RAD = 0.75
# ... and more than this times the fastest reference yaw rate in the preview (a tight turn
# is not a spin) ...
SPIN_REFERENCE_FACTOR = 3.0
# ... unless the last plan predicted it to within half the limit: a fast turn the optimiser
# planned is not a spin (the paper's mpc on paper-disturbed turns at 1.53 rad/s once).


def spin_limit(observation: Observation, sample_time: float) -> float:
    """The yaw rate above which the vehicle counts as spinning at this sample (rad/s)."""
    turn = float(np.max(np.abs(observation.reference[:, _YAW_RATE]), initial=0.0))
    return max(SPIN_ANGLE_PER_SAMPLE_RAD / sample_time, SPIN_REFERENCE_FACTOR * turn)


@dataclass
class Proposal:
    """What a back end proposes at one sample."""

    plan: np.ndarray | None  # (steps, n) thrust from now on; None: the solver failed
    solve_time_s: float = 0.0
    iterations: int = 0
    max_slack: float = 0.0
    predicted_states: np.ndarray | None = None
    disturbance: np.ndarray | None = None  # the force estimate used, if any: horizontal
    # world [X, Y, N] (PLANAR_FORCE); the depth MPC's heave force [Z]
    estimated_state: np.ndarray | None = None  # the state the back end estimated, if any
    # The water velocity the back end predicted with, if it estimates one (six-dof-nmpc):
    # world-frame horizontal [x', y'] (m/s); what the recovery of a thruster vehicle cancels.
    current: np.ndarray | None = None
    limited: bool = False  # the back end itself cut its demand to fit the limits
    details: dict[str, float] = field(default_factory=dict)  # back-end-specific, in ``info``
    # The reference rows the back end flies, where they are not the loop's (a crippled
    # vehicle's own, later, clock: controllers/schedule.py); the recovery flies them too.
    reference: np.ndarray | None = None


class ShelledController(Controller):
    """A controller whose back end proposes plans and whose shell applies them safely.

    Subclasses implement :meth:`propose` (and may override :meth:`restart` and
    :meth:`applied`); :meth:`reset` and :meth:`compute` are the shell's.
    """

    limits: ActuatorLimits
    solver_time_limit_ms: float | None = None
    # What the shell applies when no optimiser is in control (set by the registry: its
    # entry's recovery, controllers/recovery.py); None: the previous plan's moves, then the
    # last command held.
    recovery: Recovery | None = None

    @classmethod
    def from_config(cls, model, config, obstacle_count: int = 0) -> ShelledController:
        """Built from a vehicle and a ``ControllerConfig`` (controllers/registry.py)."""
        return cls(model, config)

    def take_config(self, config) -> None:
        """Keep the (resolved) configuration and what every shelled controller takes from it:
        the sample time, the horizon (also the preview it asks for) and the solver's time
        limit."""
        self.config = config
        self.sample_time = config.sample_time
        self.horizon = config.prediction_horizon
        self.preview_steps = self.horizon
        self.solver_time_limit_ms = config.solver_time_limit_ms

    @abstractmethod
    def propose(self, observation: Observation, previous: np.ndarray) -> Proposal:
        """A plan from this sample on, given the last applied command ``previous``."""

    def restart(self, initial_state: np.ndarray, initial_thrust: np.ndarray) -> None:
        """Forget the back end's own history (estimators, warm starts)."""

    def applied(self, command: np.ndarray, fell_back: bool) -> None:
        """Told the command actually applied, and whether the proposal was discarded."""

    def forget_plan(self) -> None:
        """The next proposal must start cold (not from this sample's solution): called
        before :meth:`applied` when the shell's feedback took over."""

    # -- the shell ---------------------------------------------------------------------
    def reset(self, initial_state: np.ndarray, initial_thrust: np.ndarray) -> None:
        self._previous = np.array(initial_thrust, dtype=float)
        self._healthy = np.ones(self._previous.size)
        self._healthy.setflags(write=False)
        # The actuators' effectiveness this sample (Observation.effectiveness), what the back
        # end predicts and allocates with; read-only, all ones until an observation says
        # otherwise.
        self.effectiveness = self._healthy
        self._plan: np.ndarray | None = None  # what a fallback follows
        self._unsolved = 0  # samples in a row without an applied proposal
        self._predicted_yaw_rate: float | None = None  # at this sample, by the applied plan
        if self.recovery is not None:
            self.recovery.release()
        self.restart(initial_state, initial_thrust)

    @property
    def plan(self) -> np.ndarray | None:
        """The thrust plan a fallback follows (last good proposal, shifted once per fallback)."""
        return None if self._plan is None else self._plan.copy()

    def compute(self, observation: Observation) -> ControlResult:
        previous = self._previous
        told = observation.effectiveness
        self.effectiveness = self._healthy if told is None else told
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
            # An overflow in a back end is judged below by its result (not finite: a
            # fallback); numpy's warnings were lines of source code before the run's line.
            proposal = self.propose(observation, previous)
        limit = self.solver_time_limit_ms
        late = limit is not None and 1e3 * proposal.solve_time_s > limit
        usable = proposal.plan is not None and bool(np.all(np.isfinite(proposal.plan)))
        spinning = self._spin(observation)
        recovered = False
        if usable and not late and not spinning:
            wanted = proposal.plan[0]
            self._plan = np.array(proposal.plan, dtype=float)
            self._unsolved = 0
            fell_back = False
            if self.recovery is not None:
                self.recovery.release()
        else:
            self._unsolved += 1
            fell_back = True
            recovered = self.recovery is not None and (
                spinning or self._plan is None or self._unsolved > PLAN_FALLBACK_STEPS
            )
            if recovered:
                flown = observation
                if proposal.reference is not None:
                    flown = replace(observation, reference=proposal.reference)
                wanted = self.recovery.command(flown, previous, proposal)
                if not np.all(np.isfinite(wanted)):  # a non-finite state or estimate in it
                    wanted = previous
                self._plan = None
                self.forget_plan()
            else:
                wanted, self._plan = next_planned_move(self._plan, previous)
        command, _ = self.limits.project(wanted, previous, self.sample_time)
        self._previous = command
        if self._watches_yaw:
            states = None if fell_back else proposal.predicted_states
            self._predicted_yaw_rate = (
                float(states[1, self.recovery.yaw_rate_index])
                if states is not None and len(states) > 1
                else None
            )
        self.applied(command, fell_back)
        relaxed = not fell_back and proposal.max_slack > SLACK_ACTIVE
        if recovered:
            status = ControlStatus.RECOVERY
        elif fell_back:
            status = ControlStatus.FALLBACK
        elif relaxed:
            status = ControlStatus.RELAXED
        elif proposal.limited or np.max(np.abs(command - wanted)) > _SATURATION_N:
            status = ControlStatus.SATURATED
        else:
            status = ControlStatus.OK
        disturbance = np.zeros(PLANAR_FORCE.size)
        if proposal.disturbance is not None and np.size(proposal.disturbance) == PLANAR_FORCE.size:
            disturbance = np.ravel(proposal.disturbance)  # horizontal: world X, Y, N
        return ControlResult(
            thrust=command,
            status=status,
            solve_time_s=proposal.solve_time_s,
            predicted_states=None if fell_back else proposal.predicted_states,
            info={
                "solver_iterations": float(proposal.iterations),
                "max_slack": float(proposal.max_slack),
                "solve_ms": 1e3 * proposal.solve_time_s,
                "relaxed": float(relaxed),
                "fallback": float(fell_back),
                **dict(zip(ESTIMATE_KEYS, map(float, disturbance), strict=True)),
                "recovery": float(recovered),
                "spinning": float(spinning),
                **proposal.details,
            },
        )

    @property
    def _watches_yaw(self) -> bool:
        return self.recovery is not None and self.recovery.watches_yaw

    def _spin(self, observation: Observation) -> bool:
        """Whether the vehicle spins at this sample: faster than :func:`spin_limit`, and not
        as the last applied plan predicted; only where there is a feedback that watches the
        yaw (its ``yaw_rate_index`` in the state) to stop it. No hysteresis: the optimiser
        gets each calm sample back."""
        if not self._watches_yaw:
            return False
        yaw_rate = float(observation.state[self.recovery.yaw_rate_index])
        limit = spin_limit(observation, self.sample_time)
        if abs(yaw_rate) <= limit:
            return False
        predicted = self._predicted_yaw_rate
        return predicted is None or abs(yaw_rate - predicted) > 0.5 * limit
