"""The one safety shell around every optimising controller.

A back end (the paper's MPC, LTV-MPC, NMPC, the do-mpc yardstick, the depth MPC) only
*proposes* a thrust plan; :class:`ShelledController` decides what is applied:

* a proposal that failed, is not finite, or came later than ``solver_time_limit_ms`` is
  replaced by the previous plan's next move (FALLBACK);
* whatever is applied is projected into the hard thrust and thrust-rate box, so no back end
  can command thrust outside the limits;
* the status says what happened (OK, RELAXED when a soft constraint's slack is active,
  SATURATED when the projection moved the command, FALLBACK);
* ``info`` has the same keys for every back end (:data:`INFO_KEYS`).
"""

from __future__ import annotations

from abc import abstractmethod
from dataclasses import dataclass, field

import numpy as np

from auvmpc.controllers.base import (
    ActuatorLimits,
    Controller,
    ControlResult,
    ControlStatus,
    Observation,
    next_planned_move,
)

__all__ = ["INFO_KEYS", "Proposal", "ShelledController"]

# A slack below this is solver tolerance, not a relaxed constraint (m for obstacle rows).
SLACK_ACTIVE = 1e-6
# The projection moving the command by less than this (N) is round-off, not saturation.
_SATURATION_N = 1e-6

INFO_KEYS = (
    "solver_iterations",  # QP iterations (summed over SQP passes) or IPOPT iterations
    "max_slack",  # largest slack of the soft constraints (m for obstacles)
    "solve_ms",  # the back end's own solve time
    "relaxed",  # 1 if a soft constraint was relaxed
    "fallback",  # 1 if the previous plan's next move was applied
    "dist_X_hat",  # the world-frame force and moment the prediction used (N, N, N m);
    "dist_Y_hat",  # zero without an estimator
    "dist_N_hat",
)


@dataclass
class Proposal:
    """What a back end proposes at one sample."""

    plan: np.ndarray | None  # (steps, n) thrust from now on; None: the solver failed
    solve_time_s: float = 0.0
    iterations: int = 0
    max_slack: float = 0.0
    predicted_states: np.ndarray | None = None
    disturbance: np.ndarray | None = None  # (3,) world force and moment used, if any
    limited: bool = False  # the back end itself cut its demand to fit the limits
    details: dict[str, float] = field(default_factory=dict)  # back-end-specific, in ``info``


class ShelledController(Controller):
    """A controller whose back end proposes plans and whose shell applies them safely.

    Subclasses implement :meth:`propose` (and may override :meth:`restart` and
    :meth:`applied`); :meth:`reset` and :meth:`compute` are the shell's.
    """

    limits: ActuatorLimits
    solver_time_limit_ms: float | None = None

    @classmethod
    def from_config(cls, model, config, obstacle_count: int = 0) -> ShelledController:
        """Built from a vehicle and a ``ControllerConfig`` (controllers/registry.py)."""
        return cls(model, config)

    @abstractmethod
    def propose(self, observation: Observation, previous: np.ndarray) -> Proposal:
        """A plan from this sample on, given the last applied command ``previous``."""

    def restart(self, initial_state: np.ndarray, initial_thrust: np.ndarray) -> None:
        """Forget the back end's own history (estimators, warm starts)."""

    def applied(self, command: np.ndarray, fell_back: bool) -> None:
        """Told the command actually applied, and whether the proposal was discarded."""

    # -- the shell ---------------------------------------------------------------------
    def reset(self, initial_state: np.ndarray, initial_thrust: np.ndarray) -> None:
        self._previous = np.array(initial_thrust, dtype=float)
        self._plan: np.ndarray | None = None  # what a fallback follows
        self.restart(initial_state, initial_thrust)

    @property
    def plan(self) -> np.ndarray | None:
        """The thrust plan a fallback follows (last good proposal, shifted once per fallback)."""
        return None if self._plan is None else self._plan.copy()

    def compute(self, observation: Observation) -> ControlResult:
        previous = self._previous
        proposal = self.propose(observation, previous)
        limit = self.solver_time_limit_ms
        late = limit is not None and 1e3 * proposal.solve_time_s > limit
        usable = proposal.plan is not None and bool(np.all(np.isfinite(proposal.plan)))
        if usable and not late:
            wanted = proposal.plan[0]
            self._plan = np.array(proposal.plan, dtype=float)
            fell_back = False
        else:
            wanted, self._plan = next_planned_move(self._plan, previous)
            fell_back = True
        command, _ = self.limits.project(wanted, previous, self.sample_time)
        self._previous = command
        self.applied(command, fell_back)
        relaxed = not fell_back and proposal.max_slack > SLACK_ACTIVE
        if fell_back:
            status = ControlStatus.FALLBACK
        elif relaxed:
            status = ControlStatus.RELAXED
        elif proposal.limited or np.max(np.abs(command - wanted)) > _SATURATION_N:
            status = ControlStatus.SATURATED
        else:
            status = ControlStatus.OK
        disturbance = np.zeros(3)
        if proposal.disturbance is not None and np.size(proposal.disturbance) == 3:
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
                **dict(zip(INFO_KEYS[5:], map(float, disturbance), strict=True)),
                **proposal.details,
            },
        )
