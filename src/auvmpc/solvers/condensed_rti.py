"""Real-time iterations on the multiple-shooting program with a condensed QP (dense backend).

Kept for move blocking, where the sparse form (solvers/sparse_rti.py) would need equality
rows, and as ``qp_structure: condensed``; ill-conditioned for open-loop-unstable vehicles.
"""

from __future__ import annotations

import time

import numpy as np

from auvmpc.models.layout import HORIZONTAL
from auvmpc.ocp.multiple_shooting import (
    NX,
    Iterate,
    MultipleShootingProgram,
    Sample,
    Solution,
)
from auvmpc.ocp.tracking import ThrustPenalty
from auvmpc.solvers.condensed_qp import soft_constrained_qp
from auvmpc.solvers.dense_qp import make_qp_solver

__all__ = ["CondensedRealTimeIteration"]

# Obstacle rows are kept for the predicted steps whose linearisation point is within this
# distance of the inflated disc (m), as in LinearMpc; one SQP step cannot move the plan that far.
OBSTACLE_RANGE_M = 5.0
_HEADING = HORIZONTAL.index("psi")
# Levenberg-Marquardt term on the thrust step of the condensed QP: at least the absolute
# value (keeps H definite when R = 0, as in LinearMpc), else relative to H's largest diagonal
# entry. Along a plan that spins the vehicle the sensitivities of late states grow without
# bound (measured: condition 1e21 when escaping an obstacle at rest) and DAQP fails; a damped
# step does not. It penalises the step, not the iterate, so the fixed point is unchanged;
# at 1e-8 the 10-step cold start converged 1000 times more slowly, at 1e-10 as without.
_HESSIAN_REGULARISATION = 1e-9
_RELATIVE_REGULARISATION = 1e-10


class CondensedRealTimeIteration:
    """Gauss-Newton SQP steps on the multiple-shooting program, each one condensed QP.

    Around an iterate (X, U, S), with A_i, B_i the Jacobians of the RK4 map at (X_i, F_i)
    and c_i = RK4(X_i, F_i) - X_{i+1} the shooting gap, the step's prediction is
        dX_0 = x_hat - X_0,   dX_{i+1} = A_i dX_i + B_i dF_i + c_i,
    so dX_i = f_i + G_i dU: the QP's variables are the thrust steps dU at the move steps and
    one slack per obstacle row kept. The new iterate is (X + dX, U + dU, s), or on a cold
    start (X simulated from x_hat under U + dU, U + dU, s) (module docstring).
    """

    def __init__(self, program: MultipleShootingProgram, config) -> None:
        self.program = program
        n, ny, nc = program.n_thrusters, program.horizon, program.n_moves
        self._solver = make_qp_solver(config.qp_solver, config.qp_iteration_limit)
        # E_i: the thrust at step i as a selection from the stacked move thrusts (n, nc n).
        self._selection = np.zeros((ny, n, nc * n))
        for i, j in enumerate(program.held):
            self._selection[i, :, j * n : (j + 1) * n] = np.eye(n)
        ocp = program.ocp
        self._trust = program.config.trust_region_weight or 0.0
        self._sqrt_weights = np.sqrt(ocp.stage_weights())  # rows n = 1..ny
        R = ocp.input_weight
        # D: the block difference U_j - U_{j-1} (U_{-1} = 0), the rate rows' matrix.
        self._rate_matrix = np.eye(nc * n) - np.eye(nc * n, k=-n)
        self._absolute = ocp.penalty is ThrustPenalty.ABSOLUTE
        if self._absolute:
            # sum_i |F_i|_R^2 with F_i = E_i U: each move's weight counts the steps it is held.
            counts = np.bincount(program.held, minlength=nc)
            self._thrust_hessian = 2.0 * np.diag(np.repeat(counts, n) * np.tile(R, nc))
        else:
            # sum_j |U_j - U_{j-1}|_R^2 = |D U - e_0 F_prev|_R^2.
            D = self._rate_matrix
            self._thrust_hessian = 2.0 * D.T @ (np.tile(R, nc)[:, None] * D)
        self._R = np.tile(R, nc)

    def reset(self) -> None:
        """Nothing is carried between samples except the backend's active set."""

    def solve(
        self,
        guess: Iterate,
        sample: Sample,
        iterations: int,
        cold: bool,
        resimulate: bool | None = None,
    ) -> Solution:
        """As SparseRealTimeIteration.solve: on a cold start the states are re-simulated after
        each step unless ``resimulate`` is False."""
        simulate_states = cold if resimulate is None else resimulate
        started = time.perf_counter()
        iterate: Iterate | None = guess
        total = 0
        status = "not run"
        # A diverging iterate overflows to inf/NaN; the QP backend then reports a failure.
        with np.errstate(over="ignore", invalid="ignore"):
            for _ in range(iterations):
                iterate, count, status = self._step(iterate, sample, simulate_states)
                total += count
                if iterate is None:
                    break
        return Solution(iterate, total, time.perf_counter() - started, status)

    def _step(
        self, iterate: Iterate, sample: Sample, simulate_states: bool
    ) -> tuple[Iterate | None, int, str]:
        program = self.program
        n, ny, nc = program.n_thrusters, program.horizon, program.n_moves
        n_thrust = nc * n
        plan = program.plan(iterate)
        disturbance = np.tile(sample.disturbance[:, None], (1, ny))
        next_states, jac_x, jac_u = self._linearise(iterate.states, plan, disturbance)

        # Condensing: dX_i = f_i + G_i dU.
        free = np.empty((ny + 1, NX))
        sensitivity = np.zeros((ny + 1, NX, n_thrust))
        free[0] = sample.state - iterate.states[0]
        gaps = next_states - iterate.states[1:]
        for i in range(ny):
            free[i + 1] = jac_x[i] @ free[i] + gaps[i]
            sensitivity[i + 1] = jac_x[i] @ sensitivity[i] + jac_u[i] @ self._selection[i]

        # Obstacle rows: d + n . dp - reach + s >= 0 where the point is near the disc.
        clearance, normal = program.clearances(iterate.states, sample)
        near = (clearance < OBSTACLE_RANGE_M) & sample.used[None, :]
        steps, slot_index = np.nonzero(near)  # step i - 1, slot o
        n_slack = len(steps)
        nz = n_thrust + n_slack

        weighted = (sensitivity[1:] * self._sqrt_weights[:, :, None]).reshape(-1, n_thrust)
        error = (
            (iterate.states[1:] + free[1:] - sample.reference[1:]) * self._sqrt_weights
        ).ravel()
        H = np.zeros((nz, nz))
        f = np.zeros(nz)
        H[:n_thrust, :n_thrust] = 2.0 * weighted.T @ weighted + self._thrust_hessian
        f[:n_thrust] = 2.0 * weighted.T @ error + self._thrust_gradient(iterate, sample)
        # The trust region on the heading steps dpsi_i, i = 1..ny-1, as in the sparse QP
        # (solvers/sparse_rti.py): trust |f_i + G_i dU|^2 on the heading rows.
        if self._trust:
            heading_step = sensitivity[1:ny, _HEADING]  # (ny - 1, nc n)
            H[:n_thrust, :n_thrust] += 2.0 * self._trust * heading_step.T @ heading_step
            f[:n_thrust] += 2.0 * self._trust * heading_step.T @ free[1:ny, _HEADING]
        H[:n_thrust, :n_thrust] += _regularisation(H[:n_thrust, :n_thrust]) * np.eye(n_thrust)
        thrust = iterate.thrust.ravel()
        lower_thrust = np.tile(program.ocp.input_lower, nc)
        upper_thrust = np.tile(program.ocp.input_upper, nc)
        bound_lower = np.concatenate([lower_thrust - thrust, np.zeros(n_slack)])
        bound_upper = np.concatenate([upper_thrust - thrust, np.full(n_slack, np.inf)])

        # Rate rows: U_0 - F_prev and U_j - U_{j-1} within +-max_move.
        change = np.concatenate([thrust[:n] - sample.previous, thrust[n:] - thrust[:-n]])
        max_change = program.max_change
        rate_rows = (self._rate_matrix, -max_change - change, max_change - change)
        soft_rows = None
        if n_slack:
            normals = normal[steps, slot_index]  # (rows, 2)
            soft_rows = (
                np.einsum("rk,rkj->rj", normals, sensitivity[steps + 1, :2, :]),
                -clearance[steps, slot_index] - np.einsum("rk,rk->r", normals, free[steps + 1, :2]),
            )
        problem = soft_constrained_qp(
            H, f, rate_rows, (bound_lower, bound_upper), soft_rows, program.ocp.slack_penalty
        )
        result = self._solver.solve(problem, np.zeros(nz))
        if result.z is None:
            return None, result.iterations, result.status
        step = result.z[:n_thrust]
        thrust = iterate.thrust + step.reshape(nc, n)
        if simulate_states:
            rolled = program.rollout(sample.state, thrust[program.held].T, disturbance)
            states = np.vstack([sample.state, np.asarray(rolled).T])
        else:
            states = iterate.states + free + sensitivity @ step
        if not np.all(np.isfinite(states)):
            return None, result.iterations, "non-finite predicted states"
        new_slack = np.zeros_like(iterate.slack)
        new_slack[steps, slot_index] = result.z[n_thrust:]
        updated = Iterate(
            states=states,
            thrust=thrust,
            slack=new_slack,
        )
        return updated, result.iterations, result.status

    def _linearise(self, states, plan, disturbance):
        """RK4 steps from every node and their Jacobians: (ny, 6), (ny, 6, 6), (ny, 6, n)."""
        ny, n = self.program.horizon, self.program.n_thrusters
        next_states, jac_x, jac_u = self.program.linearised_steps(
            states[:-1].T, plan.T, disturbance
        )
        return (
            np.asarray(next_states).T,
            np.asarray(jac_x).reshape(NX, ny, NX).transpose(1, 0, 2),
            np.asarray(jac_u).reshape(NX, ny, n).transpose(1, 0, 2),
        )

    def _thrust_gradient(self, iterate: Iterate, sample: Sample) -> np.ndarray:
        """Gradient of the thrust term at the iterate, in the stacked move thrusts."""
        thrust = iterate.thrust.ravel()
        if self._absolute:
            return self._thrust_hessian @ thrust
        n = self.program.n_thrusters
        change = self._rate_matrix @ thrust
        change[:n] -= sample.previous
        return 2.0 * self._rate_matrix.T @ (self._R * change)


def _regularisation(H: np.ndarray) -> float:
    """The Levenberg-Marquardt weight for a condensed Hessian (module constants)."""
    return max(_HESSIAN_REGULARISATION, _RELATIVE_REGULARISATION * float(np.abs(np.diag(H)).max()))
