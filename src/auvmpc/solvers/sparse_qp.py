"""The incremental MPC's QP in sparse (stage-wise) form, solved by HPIPM's Riccati IPM.

:class:`~auvmpc.solvers.condensed_qp.CondensedQp` eliminates the states; along an
open-loop-unstable linearisation the condensed Hessian carries the growing products of the
A_n and becomes numerically indefinite (condition ~1e17, tests/test_mpc.py). This form
keeps the states: its data are the one-step matrices A_n, B_n, bounded for any vehicle, and
HPIPM's Riccati recursion factorises it stably. The problem is the same (paper-model.md
section 4), stage k = 0..ny with

    z_k = [x_k; u_{k-1}]           v_k = [du_k (only at a move step); s_k]
    x_{k+1} = A_k x_k + B_k (u_{k-1} + du_k) + c_k,   u_k = u_{k-1} + du_k
    z_0 = [x(k); u(k-1)],   |du_k| <= rate Te,   s_k >= 0
    lower <= u_{k-1} + du_k <= upper                              (at move steps)
    a_r . x_{k+1} + s_k >= b_r   for the soft rows of step k + 1  (one slack per step)

The slack enters scaled (the variable is sigma s, :func:`~auvmpc.solvers.hpipm.slack_scale`
says why). A held input has no variable at all (the stage has fewer inputs), so
move blocking adds no equality rows, which an interior point handles badly. The cost is the
condensed QP's term for term; the exact L1 penalty is on one slack per step instead of one
per row (still exact: a feasible problem leaves every slack at zero).
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from auvmpc.ocp.tracking import SLACK_QUADRATIC_WEIGHT, ThrustPenalty, TrackingOcp
from auvmpc.solvers.hpipm import hpipm_solver, slack_scale, solved

__all__ = ["SparseIncrementalQp", "SparseSolution"]

# As in CondensedQp: keeps the move Hessian definite when R = 0; far below every real weight.
_HESSIAN_REGULARISATION = 1e-9


class SparseSolution:
    """Moves in the condensed QP's order (move step by move step), the per-step slacks, and
    the predicted states; ``moves`` is None when HPIPM failed."""

    def __init__(self, moves, slack, states, iterations, status):
        self.moves = moves
        self.slack = slack
        self.states = states
        self.iterations = iterations
        self.status = status


class SparseIncrementalQp:
    """Builds and solves the sparse QP of one incremental MPC sample (module docstring)."""

    def __init__(self, ocp: TrackingOcp, iteration_limit: int | None = None) -> None:
        self.horizon = ocp.horizon
        self.move_steps = np.asarray(ocp.move_steps)
        self.is_move = np.zeros(ocp.horizon, dtype=bool)
        self.is_move[self.move_steps] = True
        self.weights = ocp.stage_weights()
        self.R = ocp.input_weight
        self.nu = ocp.n_inputs
        self.absolute = ocp.penalty is ThrustPenalty.ABSOLUTE
        self._ocp = ocp
        self.internal: np.ndarray | None = None  # M(e), the internal thrust's weight
        self._effectiveness: np.ndarray | None = None
        self.set_effectiveness(np.ones(ocp.n_inputs))
        self.lower, self.upper = ocp.input_lower, ocp.input_upper
        self.max_move = ocp.max_move
        self.slack_penalty = ocp.slack_penalty
        self.iteration_limit = iteration_limit
        self._solvers: dict[tuple, ca.Function] = {}  # by stage-row structure
        self._row_capacity = 1  # soft rows per step the structure has room for

    def set_effectiveness(self, effectiveness: np.ndarray) -> None:
        """The thrusters' effectiveness the internal thrust's weight is for (ocp/tracking.py,
        TrackingOcp.internal_weight); remade when it changes."""
        if self._ocp.weights_internal_thrust and not np.array_equal(
            effectiveness, self._effectiveness
        ):
            self._effectiveness = np.array(effectiveness, dtype=float)
            self.internal = self._ocp.internal_weight(self._effectiveness)

    # -- one sample ------------------------------------------------------------------------
    def solve(
        self, state, previous, prediction, reference, soft, trust=None, input_box=None
    ) -> SparseSolution:
        """``prediction``: A (ny, nx, nx), B (ny, nx, nu), c (ny, nx); ``reference``
        (ny + 1, nx); ``soft``: SoftRows; ``trust``: (weights (nx,), nominal (ny + 1, nx));
        ``input_box``: per-step force limits (lower, upper), each (ny, nu), in place of the
        ocp's (a tightened box, ocp/tightening.py)."""
        ny, nu = self.horizon, self.nu
        nx = len(state)
        nz = nx + nu
        soft_at = [np.flatnonzero(soft.steps == k + 1) for k in range(ny)]
        # A fixed number of soft rows per step (unused ones unbounded), so that the QP's
        # structure, and HPIPM's set-up, stay the same while obstacles come and go (a new
        # structure cost 10-40 ms of set-up whenever an obstacle row appeared).
        self._row_capacity = max(self._row_capacity, *(len(rows) for rows in soft_at))
        capacity = self._row_capacity
        n_inputs = [(nu if self.is_move[k] else 0) + 1 for k in range(ny)]
        n_rows = [(nu if self.is_move[k] else 0) + capacity for k in range(ny)]
        columns = np.cumsum([0] + [nz + n_inputs[k] for k in range(ny)])  # z_k starts
        n_w = columns[-1] + nz
        H = np.zeros((n_w, n_w))
        # Structural patterns: what the stage blocks can hold, whatever the values (each
        # nonzero passed costs conversion time, so the diagonal blocks are marked diagonal).
        H_mask = np.eye(n_w, dtype=bool)
        g = np.zeros(n_w)
        lbx, ubx = np.full(n_w, -np.inf), np.full(n_w, np.inf)
        rows = sum(nz + n_rows[k] for k in range(ny))
        A = np.zeros((rows, n_w))
        A_mask = np.zeros((rows, n_w), dtype=bool)
        lba, uba = np.zeros(rows), np.zeros(rows)

        sigma = slack_scale(self.slack_penalty)
        state_weights = self.weights.copy()
        state_targets = self.weights * reference[1:]
        if trust is not None:
            trust_weights, nominal = trust
            state_weights = state_weights + trust_weights
            state_targets = state_targets + trust_weights * nominal[1:]
        lbx[:nx] = ubx[:nx] = state
        lbx[nx:nz] = ubx[nx:nz] = previous
        row = 0
        for k in range(ny):
            z, v = columns[k], columns[k] + nz
            x_cols, p_cols = slice(z, z + nx), slice(z + nx, z + nz)
            moving = self.is_move[k]
            du = slice(v, v + nu) if moving else slice(v, v)
            s = v + (nu if moving else 0)
            # Cost: the next state's (stage k + 1's z block), the input's, the slack's.
            nxt = columns[k + 1]
            H[nxt : nxt + nx, nxt : nxt + nx] += np.diag(2.0 * state_weights[k])
            g[nxt : nxt + nx] -= 2.0 * state_targets[k]
            if self.absolute:  # |u_k|_R^2 with u_k = p_k + du_k
                H[p_cols, p_cols] += np.diag(2.0 * self.R)
                if moving:
                    H[du, du] += np.diag(2.0 * self.R)
                    H[p_cols, du] += np.diag(2.0 * self.R)
                    H[du, p_cols] += np.diag(2.0 * self.R)
                    H_mask[p_cols, du] = H_mask[du, p_cols] = np.eye(nu, dtype=bool)
            else:
                if moving:
                    H[du, du] += np.diag(2.0 * self.R)
                if self.internal is not None:  # |u_k|_M^2, the internal thrust
                    self._add_input_weight(H, H_mask, p_cols, du if moving else None)
            if moving:
                H[du, du] += _HESSIAN_REGULARISATION * np.eye(nu)
                lbx[du], ubx[du] = -self.max_move, self.max_move
            # The QP's variable is sigma times the slack (module docstring).
            H[s, s] = 2.0 * SLACK_QUADRATIC_WEIGHT / sigma**2
            g[s] = self.slack_penalty / sigma
            lbx[s] = 0.0

            # Gap rows: A_k x_k + B_k p_k + B_k du_k - x_{k+1} = -c_k;  p_k + du_k - p_{k+1} = 0.
            Ak, Bk, ck = prediction.A[k], prediction.B[k], prediction.c[k]
            A[row : row + nx, x_cols] = Ak
            A[row : row + nx, p_cols] = Bk
            A[row + nx : row + nz, p_cols] = np.eye(nu)
            if moving:
                A[row : row + nx, du] = Bk
                A[row + nx : row + nz, du] = np.eye(nu)
            A[row : row + nz, nxt : nxt + nz] = -np.eye(nz)
            lba[row : row + nx] = uba[row : row + nx] = -ck
            identity = np.eye(nu, dtype=bool)
            A_mask[row : row + nx, z:nxt] = True  # A_k, B_k (twice), slack column unused
            A_mask[row : row + nx, s] = False
            A_mask[row + nx : row + nz, p_cols] = identity
            A_mask[row + nx : row + nz, du] = identity if moving else False
            A_mask[row : row + nz, nxt : nxt + nz] = np.eye(nz, dtype=bool)
            row += nz
            if moving:  # force limits on the new input
                A[row : row + nu, p_cols] = np.eye(nu)
                A[row : row + nu, du] = np.eye(nu)
                if input_box is None:
                    lba[row : row + nu], uba[row : row + nu] = self.lower, self.upper
                else:
                    lba[row : row + nu], uba[row : row + nu] = input_box[0][k], input_box[1][k]
                A_mask[row : row + nu, p_cols] = A_mask[row : row + nu, du] = identity
                row += nu
            for r in soft_at[k]:  # a . (A_k x_k + B_k u_k + c_k) + s_k >= b
                a = soft.coefficients[r]
                A[row, x_cols] = a @ Ak
                A[row, p_cols] = a @ Bk
                if moving:
                    A[row, du] = a @ Bk
                A[row, s] = 1.0 / sigma
                lba[row], uba[row] = soft.lower[r] - a @ ck, np.inf
                row += 1
            unused = capacity - len(soft_at[k])
            lba[row : row + unused], uba[row : row + unused] = -np.inf, np.inf
            A_mask[row - len(soft_at[k]) : row + unused, z:nxt] = True
            row += unused

        if any(np.isnan(a).any() for a in (H, g, A, lba, uba)):
            # A diverged linearisation: never hand NaN to the solver (CasADi raises on it).
            return SparseSolution(None, None, None, 0, "non-finite QP data")
        end = columns[-1]
        H_mask[end:, end:] = True  # the last stage's z block
        solver, h_pattern, a_pattern = self._solver(
            H_mask, A_mask, tuple(n_inputs), tuple(n_rows), nz
        )
        result = solver(
            h=ca.DM(h_pattern, H.T[H_mask.T]),
            g=g,
            a=ca.DM(a_pattern, A.T[A_mask.T]),
            lba=lba,
            uba=uba,
            lbx=lbx,
            ubx=ubx,
        )
        stats = solver.stats()
        w = np.asarray(result["x"]).ravel()
        if not solved(stats) or not np.all(np.isfinite(w)):
            return SparseSolution(None, None, None, stats["iter_count"], stats["return_status"])
        states = np.array([w[columns[k] : columns[k] + nx] for k in range(ny + 1)])
        moves, slack = [], np.zeros(ny)
        for k in range(ny):
            v = columns[k] + nz
            if self.is_move[k]:
                moves.append(w[v : v + nu])
            slack[k] = w[v + n_inputs[k] - 1] / sigma
        return SparseSolution(
            np.concatenate(moves), slack, states, stats["iter_count"], stats["return_status"]
        )

    def _add_input_weight(self, H, H_mask, p_cols, du) -> None:
        """|p_k + du_k|_M^2 (M the internal thrust's weight) into H and its pattern; ``du``
        None where the thrust is held."""
        M, pattern = 2.0 * self.internal, self.internal != 0.0
        blocks = [(p_cols, p_cols)] + ([] if du is None else [(du, du), (p_cols, du), (du, p_cols)])
        for rows, columns in blocks:
            H[rows, columns] += M
            H_mask[rows, columns] |= pattern

    def _solver(self, H_mask, A_mask, n_inputs, n_rows, nz):
        """HPIPM for this stage structure (it changes only when soft rows come or go), with
        the structural patterns of H and A (block positions, not values)."""
        key = (n_inputs, n_rows)
        if key not in self._solvers:
            h_pattern = ca.sparsify(ca.DM(H_mask.astype(float))).sparsity()
            a_pattern = ca.sparsify(ca.DM(A_mask.astype(float))).sparsity()
            solver = hpipm_solver(
                "incremental_sparse_qp",
                h_pattern,
                a_pattern,
                [nz] * (self.horizon + 1),
                [*n_inputs, 0],
                [*n_rows, 0],
                self.iteration_limit,
            )
            self._solvers[key] = (solver, h_pattern, a_pattern)
        return self._solvers[key]
