"""The incremental MPC loop, for any plant, inside the safety shell.

The paper augments the state with the previous input and optimises the moves. Every
sample :class:`IncrementalMpc` estimates the state, linearises the plant's model (its
``prediction_model``) around the plan, adds the plant's soft constraints, and solves the
QP, condensed (solvers/condensed_qp.py) or sparse (solvers/sparse_qp.py); the horizontal
controllers (mpc.py, ltv.py) and the depth controller (depth_mpc.py) are such plants.
"""

from __future__ import annotations

import time
from abc import abstractmethod
from dataclasses import dataclass

import numpy as np

from auvmpc.controllers.base import FLOAT_BYTES, MemoryNeed, Observation
from auvmpc.controllers.shell import Proposal, ShelledController
from auvmpc.solvers.condensed_qp import AffinePrediction, CondensedQp, SoftRows
from auvmpc.solvers.sparse_qp import SparseIncrementalQp

__all__ = ["IncrementalMpc", "Tightened"]

# What :meth:`IncrementalMpc.tightened` gives: the soft rows, the per-step force limits
# (lower, upper) or None for the ocp's, and what the back-offs took (``info`` entries).
Tightened = tuple[SoftRows, tuple[np.ndarray, np.ndarray] | None, dict[str, float]]


class IncrementalMpc(ShelledController):
    """One sample of an incremental MPC, for any plant, inside the safety shell.

    Subclasses supply the plant-specific parts: the estimator, the reference
    alignment, the prediction model, the soft state constraints and, optionally, a check
    of the solved plan (:meth:`plan_check`) that corrects the soft constraints for one
    more solve. This class owns the solve loop (condensed or sparse QP); the shell owns
    the hard limits, the fallback and the plan.
    """

    qp: CondensedQp
    linearisation_iterations: int = 1

    @classmethod
    def libraries(cls, config) -> tuple[str, ...]:
        return (str(config.qp_solver),)

    @classmethod
    def memory_need(cls, config, n_inputs: int, n_states: int) -> MemoryNeed:
        """The condensed QP's arrays, which grow as ny x nc x n^2 (the sparse form, where it
        is chosen, needs less)."""
        ny, nc = config.prediction_horizon, len(config.move_schedule())
        moves = nc * n_inputs
        # move-to-input map (ny, n, moves), forcing and stacked predictions
        # (ny, nx, moves + 1), the Hessian and constraint rows (moves^2 each)
        n_bytes = FLOAT_BYTES * (
            (ny + 1) * (n_inputs + 2 * n_states) * (moves + 1) + 3 * moves * moves
        )
        field, value = "controller.prediction_horizon", ny
        if config.control_horizon is not None and config.control_horizon > 1000:
            field, value = "controller.control_horizon", config.control_horizon
        what = f"the condensed QP of {config.type} with ny={ny}, nc={nc} and {n_inputs} thrusters"
        return MemoryNeed(field, value, n_bytes, what)

    trust_region_weights: np.ndarray | None = None  # (nx,) for plants linearised on a plan
    sparse_qp: SparseIncrementalQp | None = None  # set: the sparse form is available
    sparse_only: bool = False  # True: always the sparse form; False: condensed when well posed
    # The plan's predicted states (ny + 1, nx), shifted to this sample and aligned to the
    # measured heading, or None: where a plant that linearises along the plan may do so.
    linearisation_nodes: np.ndarray | None = None

    # -- plant-specific hooks --------------------------------------------------------
    @abstractmethod
    def estimate(self, measured: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(state the prediction starts from, disturbance estimate) from a measurement."""

    @abstractmethod
    def prediction_model(
        self, state: np.ndarray, nominal_input: np.ndarray, disturbance: np.ndarray
    ) -> AffinePrediction:
        """Affine model over the horizon around ``nominal_input`` (ny, nu)."""

    def aligned_reference(self, state: np.ndarray, reference: np.ndarray) -> np.ndarray:
        """A preview of states (reference or plan) put in the frame of ``state``."""
        return np.asarray(reference, dtype=float)

    def tracked_reference(
        self, state: np.ndarray, disturbance: np.ndarray, reference: np.ndarray
    ) -> np.ndarray:
        """The reference preview the cost tracks (the plant may reshape what it cannot
        follow as given)."""
        return self.aligned_reference(state, reference)

    def soft_rows(
        self,
        nominal: np.ndarray,
        reference: np.ndarray,
        observation: Observation,
        correction: object | None = None,
    ) -> SoftRows:
        """Soft state constraints along the nominal (ny + 1, nx), corrected by what
        :meth:`plan_check` returned on a second solve (None on the first)."""
        return SoftRows.empty(nominal.shape[1])

    def after_command(self, command: np.ndarray) -> None:
        """Called with every applied command (estimators propagate here)."""

    def tightened(
        self,
        prediction: AffinePrediction,
        nominal: np.ndarray,
        soft: SoftRows,
        previous: np.ndarray,
    ) -> Tightened:
        """The soft rows and the per-step force limits (lower, upper) after the robust
        back-offs of a disturbance bound, with what they took (``info`` entries). Nominal
        plants: unchanged rows, the ocp's limits (None), nothing taken."""
        return soft, None, {}

    # -- the loop ----------------------------------------------------------------------
    def restart(self, initial_state: np.ndarray, initial_thrust: np.ndarray) -> None:
        self._predicted: np.ndarray | None = None  # (ny + 1, nx) states of the last plan
        self._proposed: np.ndarray | None = None  # the states of this sample's proposal

    def propose(self, observation: Observation, previous: np.ndarray) -> Proposal:
        qp = self.qp
        state, disturbance = self.estimate(np.asarray(observation.state, dtype=float))
        reference = self.tracked_reference(
            state, disturbance, observation.reference[: qp.horizon + 1]
        )
        moves = qp.shifted_moves(self._plan, previous)
        started = time.perf_counter()
        solution = self._solve(observation, state, disturbance, reference, previous, moves, None)
        if not solution.solved and self._predicted is not None:
            # Re-initialise within the same sample, as after a reset: linearised afresh along
            # the model's run under the held thrust (the shifted plan may be what failed).
            self._predicted = None
            cold = qp.shifted_moves(None, previous)
            retry = self._solve(observation, state, disturbance, reference, previous, cold, None)
            retry.iterations += solution.iterations
            solution, moves = retry, cold
        if solution.solved:
            correction = self.plan_check(
                observation, state, disturbance, qp.plan(solution.moves, previous), solution.states
            )
            if correction is not None:
                # The same QP again (same nominal, so the same rows), the rows corrected.
                corrected = self._solve(
                    observation, state, disturbance, reference, previous, moves, correction
                )
                corrected.iterations += solution.iterations
                if corrected.solved:
                    solution = corrected
                else:
                    solution.iterations = corrected.iterations
        self._proposed = solution.states if solution.solved else None
        return Proposal(
            plan=qp.plan(solution.moves, previous) if solution.solved else None,
            solve_time_s=time.perf_counter() - started,
            iterations=solution.iterations,
            max_slack=solution.max_slack,
            predicted_states=solution.states,
            disturbance=disturbance,
            estimated_state=state,
            details=solution.details,
        )

    def plan_check(
        self,
        observation: Observation,
        state: np.ndarray,
        disturbance: np.ndarray,
        plan: np.ndarray,
        predicted: np.ndarray,
    ) -> object | None:
        """After a solve: None if the plan (ny, nu) and its predicted states (ny + 1, nx)
        stand, else a correction for :meth:`soft_rows`, and the QP is solved once more."""
        return None

    def _solve(
        self,
        observation: Observation,
        state: np.ndarray,
        disturbance: np.ndarray,
        reference: np.ndarray,
        previous: np.ndarray,
        moves: np.ndarray,
        correction: object | None,
    ) -> _Solution:
        """The linearise-and-solve passes from the nominal moves ``moves``."""
        qp = self.qp
        qp.set_effectiveness(self.effectiveness)  # for the internal thrust's weight
        if self.sparse_qp is not None:
            self.sparse_qp.set_effectiveness(self.effectiveness)
        self.linearisation_nodes = (
            self.aligned_reference(state, _shifted(self._predicted))
            if self._predicted is not None
            else None
        )
        iterations, max_slack, predicted, details = 0, 0.0, None, {}
        solved = False
        for _ in range(self.linearisation_iterations):
            # Each pass re-linearises (model and soft rows) around the last plan.
            prediction = self.prediction_model(state, qp.plan(moves, previous), disturbance)
            nominal = prediction.nominal
            free = sensitivity = None
            if nominal is None or not self.sparse_only:
                free, sensitivity = qp.condense(state, previous, prediction)
            if nominal is None:
                nominal = free + sensitivity @ moves
            soft = self.soft_rows(nominal, reference, observation, correction)
            soft, input_box, details = self.tightened(prediction, nominal, soft, previous)
            trust = None
            if prediction.nominal is not None and self.trust_region_weights is not None:
                trust = (self.trust_region_weights, prediction.nominal)
            solved = False
            if not self.sparse_only:
                problem = qp.problem(free, sensitivity, reference, previous, soft, input_box)
                if trust is not None:
                    weights, nominal_states = trust
                    qp.add_trust_region(problem, free, sensitivity, nominal_states, weights)
                # With a sparse form at hand, an ill-conditioned condensed QP goes to it at
                # once; a well-conditioned one that fails anyway goes to it after the failure.
                if self.sparse_qp is None or well_conditioned(
                    problem.H[: qp.n_moves, : qp.n_moves]
                ):
                    result = qp.solver.solve(problem, np.concatenate([moves, np.zeros(len(soft))]))
                    iterations += int(result.iterations)
                    solved = result.z is not None
                    if solved:
                        new_moves = result.z[: qp.n_moves]
                        max_slack = float(result.z[qp.n_moves :].max(initial=0.0))
                        predicted = free + sensitivity @ new_moves
            if not solved and self.sparse_qp is not None:
                solution = self.sparse_qp.solve(
                    state, previous, prediction, reference, soft, trust, input_box
                )
                iterations += int(solution.iterations)
                solved, new_moves = solution.moves is not None, solution.moves
                if solved:
                    max_slack = float(solution.slack.max(initial=0.0))
                    predicted = solution.states
            if not solved:
                break
            moves = new_moves
            self.linearisation_nodes = predicted
        return _Solution(solved, moves, predicted, iterations, max_slack, details)

    def applied(self, command: np.ndarray, fell_back: bool) -> None:
        # After a fallback the next sample linearises afresh.
        self._predicted = None if fell_back else self._proposed
        self.after_command(command)


@dataclass
class _Solution:
    """What the linearise-and-solve passes of one sample found."""

    solved: bool
    moves: np.ndarray  # (n_moves,) the last pass's moves (the nominal ones if it failed)
    states: np.ndarray | None  # (ny + 1, nx) predicted by the last pass that solved
    iterations: int
    max_slack: float
    details: dict[str, float]  # what a robust tightening took (info entries), else empty


def _shifted(states: np.ndarray) -> np.ndarray:
    """A predicted trajectory one sample on (the last state repeated)."""
    return np.vstack([states[1:], states[-1:]])


# Condition number of the condensed Hessian above which the sparse form is used instead
# (solution error grows like condition x machine epsilon: 1e10 leaves ~1e-6 relative). Along
# an open-loop-unstable linearisation it reaches 1e17 and DAQP fails (docs/performance.md).
_CONDITION_LIMIT = 1e10


def well_conditioned(hessian: np.ndarray) -> bool:
    """Whether a positive definite matrix's condition number is below _CONDITION_LIMIT,
    estimated from its Cholesky factor (the square of its diagonal's spread)."""
    try:
        diagonal = np.abs(np.diag(np.linalg.cholesky(hessian)))
    except np.linalg.LinAlgError:
        return False
    return float((diagonal.max() / diagonal.min()) ** 2) < _CONDITION_LIMIT
