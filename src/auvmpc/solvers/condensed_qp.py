"""The incremental linear MPC's QP, condensed to a small dense QP, for any plant.

The paper augments the state with the previous input, ``X(k) = [x(k); u(k-1)]``,
and optimises the moves ``du``. We keep exactly that problem but eliminate the
states (condensing): with ``u(k-1)`` known, the input over the horizon is
``u_n = u(k-1) + E_n z`` where ``z`` stacks the moves made at the move steps (the
input is held in between and after the last one), and each predicted state is
affine in ``z``: ``x_n = x_free_n + S_n z``. The cost

    sum_{n=1}^{ny-1} |x_n - r_n|_Q^2 + |x_ny - r_ny|_S^2 + sum_{n=0}^{ny-1} |u_n|_R^2

(or R on the moves) becomes ``0.5 z'Hz + f'z``; every move is bounded by rate*Te,
every input by its force limits, and soft state constraints get one exact-penalty
slack each. :class:`~auvmpc.controllers.incremental.IncrementalMpc` runs this every sample
for a plant that supplies its prediction model.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from auvmpc.ocp.tracking import SLACK_QUADRATIC_WEIGHT, ThrustPenalty, TrackingOcp
from auvmpc.solvers.dense_qp import QpProblem, QpSolverName, make_qp_solver

__all__ = ["AffinePrediction", "CondensedQp", "SoftRows", "soft_constrained_qp"]

# Keeps H positive definite when R = 0 (DAQP needs it); far below every real weight.
_HESSIAN_REGULARISATION = 1e-9


@dataclass
class AffinePrediction:
    """x_{n+1} = A_n x_n + B_n u_n + c_n for n = 0..ny-1."""

    A: np.ndarray  # (ny, nx, nx)
    B: np.ndarray  # (ny, nx, nu)
    c: np.ndarray  # (ny, nx)
    nominal: np.ndarray | None = None  # (ny + 1, nx) trajectory the model was linearised on
    G: np.ndarray | None = None  # (ny, nx, nd) Jacobians in the world force and moment, if asked


@dataclass
class SoftRows:
    """Soft state constraints ``a_r . x_{n_r} >= b_r``, one exact-penalty slack each."""

    steps: np.ndarray  # (r,) predicted step n_r in 1..ny
    coefficients: np.ndarray  # (r, nx)
    lower: np.ndarray  # (r,)

    @classmethod
    def empty(cls, nx: int) -> SoftRows:
        return cls(np.zeros(0, dtype=int), np.zeros((0, nx)), np.zeros(0))

    def __len__(self) -> int:
        return len(self.steps)


def soft_constrained_qp(
    H: np.ndarray,
    f: np.ndarray,
    rows: tuple[np.ndarray, np.ndarray, np.ndarray],
    bounds: tuple[np.ndarray, np.ndarray],
    soft: tuple[np.ndarray, np.ndarray] | None,
    penalty: float,
) -> QpProblem:
    """The dense QP with hard ``rows`` (matrix over the free variables, lower, upper), the
    variable ``bounds`` and, if given, ``soft`` rows ``coefficients . z + s_r >= lower``
    with one slack each, the slacks being the last variables: their cost goes into ``H``
    and ``f`` (in place), their bounds are in ``bounds`` already.

    One slack per row: an exact L1 penalty relaxes only the rows that must be.
    """
    matrix, lower, upper = rows
    n_all = H.shape[0]
    hard = np.zeros((matrix.shape[0], n_all))
    hard[:, : matrix.shape[1]] = matrix
    blocks, lowers, uppers = [hard], [lower], [upper]
    if soft is not None:
        coefficients, soft_lower = soft
        n_rows, n_free = coefficients.shape
        slack = np.arange(n_free, n_free + n_rows)
        H[slack, slack] = 2.0 * SLACK_QUADRATIC_WEIGHT
        f[slack] = penalty
        block = np.zeros((n_rows, n_all))
        block[:, :n_free] = coefficients
        block[:, slack] = np.eye(n_rows)
        blocks.append(block)
        lowers.append(soft_lower)
        uppers.append(np.full(n_rows, np.inf))
    return QpProblem(
        H=H,
        f=f,
        A=np.vstack(blocks),
        lower=np.concatenate(lowers),
        upper=np.concatenate(uppers),
        bound_lower=bounds[0],
        bound_upper=bounds[1],
    )


class CondensedQp:
    """The condensed QP of one incremental MPC: built once, filled every sample."""

    def __init__(
        self, ocp: TrackingOcp, qp_solver: QpSolverName, iteration_limit: int | None = None
    ) -> None:
        nu, ny, move_steps = ocp.n_inputs, ocp.horizon, ocp.move_steps
        input_weight, limits = ocp.input_weight, ocp.limits
        self.horizon = ny
        self.nu = nu
        self.move_steps = np.array(move_steps)
        nc = len(self.move_steps)
        self.n_moves = nu * nc
        # E[i] maps the moves to u_i - u(k-1): the sum of the moves made at or before sample i.
        self.move_to_input = np.zeros((ny, nu, self.n_moves))
        for i in range(ny):
            for j in np.flatnonzero(self.move_steps <= i):
                self.move_to_input[i, :, j * nu : (j + 1) * nu] = np.eye(nu)
        self.sqrt_state_weights = np.sqrt(ocp.stage_weights())  # n = 1..ny
        if ocp.penalty is ThrustPenalty.ABSOLUTE:
            stacked = self.move_to_input.reshape(ny * nu, self.n_moves)
            weighted = stacked * np.tile(input_weight, ny)[:, None]
            self._input_hessian = 2.0 * stacked.T @ weighted
            self._input_gradient_map = 2.0 * weighted.T.reshape(self.n_moves, ny, nu).sum(axis=1)
        else:
            self._input_hessian = 2.0 * np.diag(np.tile(input_weight, nc))
            self._input_gradient_map = np.zeros((self.n_moves, nu))
        self._ocp = ocp
        self._increment_hessian = self._input_hessian  # without the internal thrust's part
        self._effectiveness: np.ndarray | None = None
        self.set_effectiveness(np.ones(nu))
        self.limits = limits
        self.max_move = ocp.max_move
        self._move_bound = np.tile(self.max_move, nc)  # every move, built once
        # Force bounds where the input changes (it is held in between and after the last move).
        self._input_rows = self.move_to_input[self.move_steps].reshape(nc * nu, self.n_moves)
        self._input_lower, self._input_upper = ocp.input_lower, ocp.input_upper
        self.slack_penalty = ocp.slack_penalty
        self.solver = make_qp_solver(qp_solver, iteration_limit)

    def set_effectiveness(self, effectiveness: np.ndarray) -> None:
        """The thrusters' effectiveness the internal thrust's weight is for (ocp/tracking.py,
        TrackingOcp.internal_weight): with the increment penalty, |u_i|_M^2 over the horizon,
        u_i = u(k-1) + E_i moves, in the input Hessian and gradient; remade when it changes."""
        if not self._ocp.weights_internal_thrust or np.array_equal(
            effectiveness, self._effectiveness
        ):
            return
        self._effectiveness = np.array(effectiveness, dtype=float)
        weight = self._ocp.internal_weight(self._effectiveness)
        weighted = np.einsum("ij,njm->nim", weight, self.move_to_input)  # M E_i
        internal = 2.0 * np.einsum("nim,nik->mk", self.move_to_input, weighted)
        self._input_hessian = self._increment_hessian + internal
        self._input_gradient_map = 2.0 * weighted.sum(axis=0).T

    def condense(
        self, state: np.ndarray, previous: np.ndarray, prediction: AffinePrediction
    ) -> tuple[np.ndarray, np.ndarray]:
        """Free response (ny+1, nx) and sensitivity to the moves (ny+1, nx, n_moves).

        Both propagate through the same A_n, so they are stacked as the columns of one
        matrix [S_n | x_free_n] and advanced with one product per step (the loop over
        the horizon is the hot path of every MPC step).
        """
        ny, nx, nm = self.horizon, len(state), self.n_moves
        forcing = np.empty((ny, nx, nm + 1))
        forcing[:, :, :nm] = np.einsum("nij,njk->nik", prediction.B, self.move_to_input)
        forcing[:, :, nm] = np.einsum("nij,j->ni", prediction.B, previous) + prediction.c
        stacked = np.zeros((ny + 1, nx, nm + 1))
        stacked[0, :, nm] = state
        A = prediction.A
        for i in range(ny):
            stacked[i + 1] = A[i] @ stacked[i] + forcing[i]
        return stacked[:, :, nm], stacked[:, :, :nm]

    def problem(
        self,
        free: np.ndarray,
        sensitivity: np.ndarray,
        reference: np.ndarray,
        previous: np.ndarray,
        soft: SoftRows,
        input_box: tuple[np.ndarray, np.ndarray] | None = None,
    ) -> QpProblem:
        """The QP in z = [moves, slacks]; ``input_box``: per-step force limits (ny, nu) in
        place of the ocp's (a tightened box, ocp/tightening.py)."""
        n_moves, n_slack = self.n_moves, len(soft)
        nz = n_moves + n_slack
        weighted = (sensitivity[1:] * self.sqrt_state_weights[:, :, None]).reshape(-1, n_moves)
        error = ((free[1:] - reference[1:]) * self.sqrt_state_weights).ravel()
        H = np.zeros((nz, nz))
        f = np.zeros(nz)
        H[:n_moves, :n_moves] = 2.0 * weighted.T @ weighted + self._input_hessian
        H[:n_moves, :n_moves] += _HESSIAN_REGULARISATION * np.eye(n_moves)
        f[:n_moves] = 2.0 * weighted.T @ error + self._input_gradient_map @ previous
        bound_lower = np.concatenate([-self._move_bound, np.zeros(n_slack)])
        bound_upper = np.concatenate([self._move_bound, np.full(n_slack, np.inf)])
        nc = len(self.move_steps)
        if input_box is None:
            input_rows = (
                self._input_rows,
                np.tile(self._input_lower - previous, nc),
                np.tile(self._input_upper - previous, nc),
            )
        else:
            lower, upper = input_box
            input_rows = (
                self._input_rows,
                (lower[self.move_steps] - previous).ravel(),
                (upper[self.move_steps] - previous).ravel(),
            )
        soft_rows = (
            (
                np.einsum("rk,rkj->rj", soft.coefficients, sensitivity[soft.steps]),
                soft.lower - np.einsum("rk,rk->r", soft.coefficients, free[soft.steps]),
            )
            if n_slack
            else None
        )
        return soft_constrained_qp(
            H, f, input_rows, (bound_lower, bound_upper), soft_rows, self.slack_penalty
        )

    def add_trust_region(
        self,
        problem: QpProblem,
        free: np.ndarray,
        sensitivity: np.ndarray,
        nominal: np.ndarray,
        weights: np.ndarray,
    ) -> None:
        """Penalise predicted states far from the trajectory the model was linearised on.

        A linearisation is only valid near its nominal: without this term the QP may
        exploit it (e.g. a large heading change whose cosine it sees as linear) and the
        plan, the next nominal, jumps. The penalty vanishes when the plan agrees with
        its nominal, so it does not bias a converged, steady solution.
        """
        root = np.sqrt(weights)
        n_moves = self.n_moves
        weighted = (sensitivity[1:] * root[None, :, None]).reshape(-1, n_moves)
        deviation = ((free[1:] - nominal[1:]) * root).ravel()
        problem.H[:n_moves, :n_moves] += 2.0 * weighted.T @ weighted
        problem.f[:n_moves] += 2.0 * weighted.T @ deviation

    def plan(self, moves: np.ndarray, previous: np.ndarray) -> np.ndarray:
        """(ny, nu) inputs of a move vector."""
        return previous + self.move_to_input @ moves

    def shifted_moves(self, plan: np.ndarray | None, previous: np.ndarray) -> np.ndarray:
        """Moves that best reproduce ``plan`` one sample on (zeros without a plan).

        Without blocking this is the plan's moves shifted by one; with blocking the
        shifted plan is sampled at the move steps, and each move is clipped to the
        rate limit so that the warm start is feasible.
        """
        if plan is None:
            return np.zeros(self.n_moves)
        shifted = np.vstack([plan[1:], plan[-1:]])[self.move_steps]  # (nc, nu)
        moves = np.diff(np.vstack([previous, shifted]), axis=0)
        return np.clip(moves, -self.max_move, self.max_move).ravel()
