"""The stage QP's step condensed: the states eliminated through the linearised dynamics and
the dense QP in the thrust steps solved by a dense solver (``qp_solver``).

The stage functions (ocp/stage_qp.py) are evaluated for all stages in one mapped call. The
variables V are, per stage that moves the thrust, its step dF_k = dp_k + w_k, and the
stage's slack where it has obstacle rows; a held stage's w is fixed by its bounds. With
z_0 known, every stage input and state is affine in V,

    v_k = c_k + M_k V,   z_k = phi_k + G_k V,
    phi_{k+1} = A_k phi_k + B_k c_k + b_k,   G_{k+1} = A_k G_k + B_k M_k,

and the stage costs and rows become a dense QP in V: the rate limits rows, the thrust limits
boxes on the steps. Thrust steps, not the w of the sparse form: their cumulative sums made
the condensed Hessian worse conditioned (bluerov2-figure-eight with 10 blocked moves left
the path by 0.081 m at most in w, 0.036 m in dF). Ill-conditioned for open-loop-unstable
vehicles all the same (solvers/real_time_iteration.py).
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from auvmpc.native import native_function
from auvmpc.ocp.multiple_shooting import NX
from auvmpc.ocp.stage_qp import StageQp
from auvmpc.solvers.dense_qp import QpProblem, QpSolverName, make_qp_solver
from auvmpc.solvers.hpipm import EVALUATION_FAILED, NOT_FINITE, SOLVED, hpipm_status

__all__ = ["CondensedQpStep"]

# A Levenberg-Marquardt term: at least the absolute value (keeps H definite when R = 0), else
# relative to the condensed Hessian's largest diagonal entry. Along a plan that spins the
# vehicle the sensitivities of late states grow without bound (measured: condition 1e21 when
# escaping an obstacle at rest) and DAQP fails; a damped step does not. It penalises the
# step, not the iterate, so the fixed point is unchanged; at 1e-8 the 10-step cold start
# converged 1000 times more slowly, at 1e-10 as without.
_HESSIAN_REGULARISATION = 1e-9
_RELATIVE_REGULARISATION = 1e-10
# The status code of a failed dense solve (hpipm.SOLVED and the data codes are the others).
_SOLVER_FAILED = 1


class CondensedQpStep:
    """One stage QP condensed and solved densely: the call of the sparse QP steps
    (CompiledQpStep), filling (dz, dv) in place and returning (status code, iterations)."""

    def __init__(self, qp: StageQp, horizon: int, slots: int, solver: QpSolverName,
                 iteration_limit: int | None, jit: bool) -> None:  # fmt: skip
        """``jit``: evaluate the stages compiled where a C compiler is present (as the sparse
        step does), else through CasADi's virtual machine."""
        # One evaluation for every stage; the disturbance, the obstacles and the thrusters'
        # effectiveness are the sample's.
        shared = [qp.stage.index_in(name) for name in ("d_world", "slots", "used", "e")]
        stages = qp.stage.map("condensed_stages", "serial", horizon, shared, [])
        self._stages = (native_function(stages) if jit else None) or _flat_outputs(stages)
        self._shapes = [qp.stage.size_out(i) for i in range(qp.stage.n_out())]
        self._terminal = qp.terminal
        self._solver = make_qp_solver(solver, iteration_limit)
        self._horizon = horizon
        # The slack input (the last) is one per stage for the stage's obstacle rows: a variable
        # only where the stage has a row.
        self._slack = qp.inputs - 1 if slots else None
        self._thrusters = qp.states - NX
        self._status = "not run"
        self.dz = np.zeros((horizon + 1, qp.states))
        self.dv = np.zeros((horizon, qp.inputs))

    def describe(self, code: int) -> str:
        """The log's words for a status code of this step: the dense solver's own."""
        return hpipm_status(code) if code == EVALUATION_FAILED else self._status

    def __call__(self, X, P, F, x_hat, previous, reference, weight, force, slots, used, movable,
                 effectiveness, hot_start=False):  # fmt: skip
        """The arguments of CompiledQpStep, in its (row-major) layout -> (status, iterations).
        ``hot_start`` changes nothing: the dense solver starts from zero."""
        N = self._horizon
        try:
            # Column-major inputs: a (stages, size) C array is the (size, stages) matrix.
            data = self._stages(
                X[:-1], X[1:], P[:-1], P[1:], F, reference[:-1], weight, force, slots, used,
                movable, np.arange(1.0, N + 1), effectiveness,
            )  # fmt: skip
            terminal = self._terminal(X[N], reference[N])
        except RuntimeError:
            return EVALUATION_FAILED, 0
        stacked = (_stacked(d, N, shape) for d, shape in zip(data, self._shapes, strict=True))
        A, B, b, Q, S, R, q, r, C, D, lg, ug, lbu, ubu, lbp, ubp = stacked
        Q_N, q_N = (np.asarray(t) for t in terminal)
        # A bound may be infinite (a slack's, a far obstacle's row); nothing may be NaN.
        if not all(np.isfinite(v).all() for v in (A, B, b, Q, S, R, q, r, Q_N, q_N)) or any(
            np.isnan(v).any() for v in (lg, ug, lbu, ubu, lbp, ubp)
        ):
            return NOT_FINITE, 0
        z0 = np.concatenate([x_hat - X[0], previous - P[0]])
        problem, (c, M, phi, G) = self._condense(
            (A, B, b, Q, S, R, q, r, C, D, lg, ug, lbu, ubu, lbp, ubp), Q_N, q_N, z0
        )
        result = self._solver.solve(problem, np.zeros(len(problem.f)))
        self._status = result.status
        if result.z is None:
            return _SOLVER_FAILED, result.iterations
        self.dv[:] = c + M @ result.z
        self.dz[:] = phi + G @ result.z
        return SOLVED, result.iterations

    def _condense(self, stages, Q_N, q_N, z0):
        """(the dense QP in V, (c, M, phi, G)) from the stacked stage data (module docstring)."""
        A, B, b, Q, S, R, q, r, C, D, lg, ug, lbu, ubu, lbp, ubp = stages
        N, n = self._horizon, self._thrusters
        # V: per stage that moves the thrust, its step dF_k = dp_k + w_k (n), then the slack
        # where the stage has obstacle rows. A held stage's w is fixed by its bounds.
        moving = (lbu[:, :n] < ubu[:, :n]).any(axis=1)
        active = np.isfinite(lg) | np.isfinite(ug)  # (N, rows)
        slacked = active.any(axis=1) if self._slack is not None else np.zeros(N, bool)
        columns = np.cumsum(n * moving + slacked)  # stage k's: columns[k - 1]..columns[k]
        nV = int(columns[-1]) if N else 0
        starts = np.concatenate([[0], columns[:-1]]).astype(int)

        nz, nv = A.shape[1], B.shape[2]
        phi = np.empty((N + 1, nz))
        G = np.zeros((N + 1, nz, nV))
        phi[0] = z0
        # v_k = c_k + M_k V: w_k = dF_k - dp_k where the stage moves, else its bound.
        c = np.where(lbu < ubu, 0.0, lbu)
        M = np.zeros((N, nv, nV))
        box_lower, box_upper = np.full(nV, -np.inf), np.full(nV, np.inf)
        rows, lower, upper = [], [], []
        for k in range(N):
            column = starts[k]
            if moving[k]:
                thrust = slice(column, column + n)
                c[k, :n] = -phi[k, NX:]
                M[k, :n] = -G[k, NX:]
                M[k, :n, thrust] += np.eye(n)
                column += n
                # The rate limit on w, a row; the thrust limit on dF_k, a box (the next
                # state's dp is dF_k plus its shooting gap).
                rows.append(M[k, :n])
                lower.append(lbu[k, :n] - c[k, :n])
                upper.append(ubu[k, :n] - c[k, :n])
                gap = b[k, NX:]
                box_lower[thrust], box_upper[thrust] = lbp[k] - gap, ubp[k] - gap
            if slacked[k]:
                M[k, self._slack, column] = 1.0
                box_lower[column], box_upper[column] = lbu[k, self._slack], ubu[k, self._slack]
            phi[k + 1] = A[k] @ phi[k] + B[k] @ c[k] + b[k]
            G[k + 1] = A[k] @ G[k] + B[k] @ M[k]

        # Cost sum_k 1/2 [v; z]' [R S; S' Q] [v; z] + r' v + q' z, then the terminal, in V.
        G_k, phi_k = G[:N], phi[:N]
        cross = np.einsum("kai,kab,kbj->ij", M, S, G_k, optimize=True)
        H = (
            np.einsum("kai,kab,kbj->ij", G_k, Q, G_k, optimize=True)
            + np.einsum("kai,kab,kbj->ij", M, R, M, optimize=True)
            + cross + cross.T + G[N].T @ Q_N @ G[N]
        )  # fmt: skip
        state_gradient = np.einsum("kab,kb->ka", Q, phi_k) + np.einsum("kba,kb->ka", S, c) + q
        input_gradient = np.einsum("kab,kb->ka", R, c) + np.einsum("kab,kb->ka", S, phi_k) + r
        g = (
            np.einsum("kai,ka->i", G_k, state_gradient)
            + np.einsum("kai,ka->i", M, input_gradient)
            + G[N].T @ (Q_N @ phi[N] + q_N.ravel())
        )
        if active.any():  # the obstacle rows kept
            offsets = np.einsum("kra,ka->kr", C, phi_k) + np.einsum("krb,kb->kr", D, c)
            obstacle_rows = np.einsum("kra,kai->kri", C, G_k) + np.einsum("krb,kbi->kri", D, M)
            rows.append(obstacle_rows[active])
            lower.append(lg[active] - offsets[active])
            upper.append(ug[active] - offsets[active])
        largest = float(np.abs(np.diag(H)).max(initial=0.0))
        H += max(_HESSIAN_REGULARISATION, _RELATIVE_REGULARISATION * largest) * np.eye(nV)

        problem = QpProblem(
            H, g,
            np.vstack(rows) if rows else np.zeros((0, nV)),
            np.concatenate(lower) if lower else np.zeros(0),
            np.concatenate(upper) if upper else np.zeros(0),
            box_lower, box_upper,
        )  # fmt: skip
        return problem, (c, M, phi, G)


def _flat_outputs(function: ca.Function):
    """``function`` called as a NativeFunction is: dense inputs in column-major order, every
    output flat in column-major order."""

    def evaluate(*inputs: np.ndarray) -> tuple[np.ndarray, ...]:
        arguments = [
            np.reshape(np.ravel(values), function.size_in(i), order="F")
            for i, values in enumerate(inputs)
        ]
        return tuple(np.asarray(out).ravel(order="F") for out in function(*arguments))

    return evaluate


def _stacked(flat: np.ndarray, stages: int, shape: tuple[int, int]) -> np.ndarray:
    """A mapped stage output, flat in column-major order, as (stages, rows, cols), or as
    (stages, rows) for a vector."""
    rows, columns = shape
    stacked = flat.reshape(stages, columns, rows).transpose(0, 2, 1)
    return stacked[:, :, 0] if columns == 1 else stacked
