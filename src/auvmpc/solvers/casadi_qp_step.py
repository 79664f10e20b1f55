"""The stage QP's step without a C compiler: CasADi evaluates the stage functions and HPIPM
solves the assembled sparse QP through CasADi's interface (same QP as the compiled step)."""

from __future__ import annotations

import casadi as ca
import numpy as np

from auvmpc.ocp.multiple_shooting import ND, NX, SLOT_FIELDS
from auvmpc.ocp.stage_qp import StageQp
from auvmpc.solvers.hpipm import NOT_FINITE, hpipm_solver, hpipm_status

__all__ = ["CasadiQpStep"]


class CasadiQpStep:
    """The same QP step as :class:`~auvmpc.solvers.compiled_qp_step.CompiledQpStep`, without a
    C compiler: the stage functions assembled into one sparse QP (variables [z_0 v_0 z_1 ...
    z_N], rows [gaps_0 rows_0 gaps_1 ...]), evaluated by CasADi's virtual machine and solved
    by HPIPM through CasADi's interface."""

    def __init__(self, qp: StageQp, horizon: int, thrusters: int, slots: int,
                 iteration_limit: int | None) -> None:  # fmt: skip
        N, n = horizon, thrusters
        nz, nv = qp.states, qp.inputs
        X, P = ca.SX.sym("X", NX, N + 1), ca.SX.sym("P", n, N + 1)
        F, reference = ca.SX.sym("F", n, N), ca.SX.sym("ref", NX, N + 1)
        weight = ca.SX.sym("W", NX, N)
        x_hat, previous = ca.SX.sym("x_hat", NX), ca.SX.sym("F_prev", n)
        force = ca.SX.sym("d_world", ND)
        slot_data = ca.SX.sym("slots", SLOT_FIELDS, slots)
        used, movable = ca.SX.sym("used", slots), ca.SX.sym("movable", N)
        effectiveness = ca.SX.sym("e", n)

        n_w = (N + 1) * nz + N * nv
        hessian, gradient, rows, lba, uba = [], [], [], [], []
        lbx = [x_hat - X[:, 0], previous - P[:, 0]]
        ubx = list(lbx)
        for k in range(N):
            A, B, b, Q, S, R, q, r, C, D, lg, ug, lbu, ubu, lbp, ubp = qp.stage(
                X[:, k], X[:, k + 1], P[:, k], P[:, k + 1], F[:, k], reference[:, k],
                weight[:, k], force, slot_data, used, movable[k], k + 1, effectiveness,
            )  # fmt: skip
            hessian.append(ca.blockcat([[Q, S.T], [S, R]]))
            gradient += [q, r]
            lbx += [lbu, -np.inf * np.ones(NX), lbp]  # v_k, then z_{k+1}
            ubx += [ubu, np.inf * np.ones(NX), ubp]
            left, right = k * (nz + nv), n_w - (k + 1) * (nz + nv) - nz
            block = ca.vertcat(
                ca.horzcat(A, B, -ca.SX.eye(nz)), ca.horzcat(C, D, ca.SX(C.size1(), nz))
            )
            rows.append(ca.horzcat(ca.SX(block.size1(), left), block, ca.SX(block.size1(), right)))
            lba += [-b, lg]
            uba += [-b, ug]
        Q_N, q_N = qp.terminal(X[:, N], reference[:, N])
        hessian.append(Q_N)
        gradient.append(q_N)
        self._data = ca.Function(
            "rti_sparse_qp_data",
            [X, P, F, x_hat, previous, reference, weight, force, slot_data, used, movable,
             effectiveness],
            [ca.diagcat(*hessian), ca.vertcat(*gradient), ca.vertcat(*rows),
             ca.vertcat(*lba), ca.vertcat(*uba), ca.vertcat(*lbx), ca.vertcat(*ubx)],
        )  # fmt: skip
        self._qp = hpipm_solver(
            "rti_sparse_qp",
            self._data.sparsity_out(0),
            self._data.sparsity_out(2),
            [nz] * (N + 1),
            [nv] * N + [0],
            [qp.rows] * N + [0],
            iteration_limit,
        )
        self._sizes = (N, nz, nv)
        self.dz = np.zeros((N + 1, nz))
        self.dv = np.zeros((N, nv))

    def __call__(self, X, P, F, x_hat, previous, reference, weight, force, slots, used, movable,
                 effectiveness, hot_start=False):  # fmt: skip
        """The arguments of CompiledQpStep, in its (row-major) layout -> (status, iterations).
        Every QP is solved to 1e-8 from HPIPM's cold start: ``hot_start`` changes nothing."""
        N, nz, nv = self._sizes
        H, g, A, lba, uba, lbx, ubx = self._data(
            X.T, P.T, F.T, x_hat, previous, reference.T, weight.T, force, slots.T, used, movable,
            effectiveness,
        )  # fmt: skip
        # The bounds carry the shooting gaps, the first to go non-finite (and the ones CasADi
        # refuses); a NaN elsewhere shows in HPIPM's status or its solution.
        if any(np.isnan(np.asarray(v)).any() for v in (g, lba, uba, lbx, ubx)):
            return NOT_FINITE, 0
        result = self._qp(h=H, g=g, a=A, lba=lba, uba=uba, lbx=lbx, ubx=ubx)
        stats = self._qp.stats()
        w = np.asarray(result["x"]).ravel()
        stage = nz + nv
        self.dz[:] = np.stack([w[k * stage : k * stage + nz] for k in range(N + 1)])
        self.dv[:] = np.stack([w[k * stage + nz : (k + 1) * stage] for k in range(N)])
        return int(stats["return_status"]), int(stats["iter_count"])

    describe = staticmethod(hpipm_status)
