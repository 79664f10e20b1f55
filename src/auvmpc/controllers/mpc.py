"""Linear MPC on the incremental model, condensed to a small dense QP (paper-model.md 3-4).

The paper augments the state with the previous thrust, ``X(k) = [x(k); F(k-1)]``,
and optimises the moves ``dF``. We keep exactly that problem but eliminate the
states (condensing): with ``F(k-1)`` known, the thrust over the horizon is
``F_n = F(k-1) + E_n z`` where ``z = [dF_0 .. dF_{nc-1}]`` (moves after nc are
zero, so ``F`` is held), and each predicted state is affine in ``z``:
``x_n = x_free_n + S_n z``. Subclasses only say how the prediction model is
obtained each sample:

* :class:`PaperMpc` (``mpc``): the paper's state-dependent-coefficient (SDC)
  model ``x' = A_c(x) x + B_c F`` frozen at the current state, RK4-discretised;
* ``LtvMpc`` (``ltv-mpc``, ltv.py): the RK4 model linearised along the shifted
  previous solution with exact CasADi Jacobians.

Hard limits: every move within +-rate*Te, every thrust within [F_min, F_max]
(simple bounds and rows of the QP), and the applied command is projected into
the same box once more so that no solver tolerance can leak past a limit.
Obstacles: each keep-out disc becomes one half-plane per predicted step,
tangent to the inflated disc, softened by one exact-penalty slack per obstacle.
"""

from __future__ import annotations

import math
import time
from abc import abstractmethod
from dataclasses import dataclass

import numpy as np

from auvmpc.controllers.base import (
    ControlResult,
    ControlStatus,
    Controller,
    Observation,
    ObstacleState,
    project_to_limits,
)
from auvmpc.controllers.config import ControllerConfig, ThrustPenalty
from auvmpc.controllers.qp import QpProblem, make_qp_solver
from auvmpc.estimation import DisturbanceObserver
from auvmpc.vehicle import VehicleParams, body_from_world

__all__ = ["AffinePrediction", "LinearMpc", "PaperMpc", "sdc_matrix", "rk4_discretize"]

NX = 6
# Keeps H positive definite when R = 0 (DAQP needs it); far below every real weight.
_HESSIAN_REGULARISATION = 1e-9
# Quadratic part of the slack penalty: makes H definite in the slack; the linear
# part (config.obstacle_slack_penalty) is what makes the penalty exact.
_SLACK_QUADRATIC_WEIGHT = 1.0
# A slack below this (m) is solver tolerance, not a relaxed constraint.
_SLACK_ACTIVE_M = 1e-6
# Relative trust-region weights on [x, y, psi, u, v, r] deviations from the nominal: the
# heading and velocities carry the nonlinearity (rotation, Coriolis), positions follow them.
_TRUST_REGION_SCALE = (0.0, 0.0, 1.0, 1.0, 1.0, 1.0)
# Obstacle rows are kept for predicted steps whose nominal position is within this distance
# of the half-plane (m): 15 s at the vehicle's top speed is far more than one re-plan moves.
_OBSTACLE_RANGE_M = 5.0
# Half-plane normals are kept at least this far from the along-track direction, so a
# disc sitting on the path is passed on one side instead of blocking the prediction.
_MAX_NORMAL_ANGLE_FROM_SIDE = math.radians(60.0)


@dataclass
class AffinePrediction:
    """x_{n+1} = A_n x_n + B_n F_n + c_n for n = 0..ny-1."""

    A: np.ndarray  # (ny, 6, 6)
    B: np.ndarray  # (ny, 6, n)
    c: np.ndarray  # (ny, 6)
    nominal: np.ndarray | None = None  # (ny + 1, 6) trajectory the model was linearised on


class LinearMpc(Controller):
    """Condensed linear MPC; subclasses provide :meth:`prediction_model`."""

    def __init__(self, model: VehicleParams, config: ControllerConfig) -> None:
        self.model = model
        self.config = config
        self.sample_time = config.sample_time
        self.horizon = config.prediction_horizon
        self.preview_steps = self.horizon
        move_steps = np.array(config.move_schedule())
        n, ny, nc = model.n_thrusters, self.horizon, len(move_steps)
        self.n_moves = n * nc
        # E[i] maps the moves to F_i - F(k-1): the sum of the moves made at or before sample i.
        self._move_to_thrust = np.zeros((ny, n, self.n_moves))
        for i in range(ny):
            for j in np.flatnonzero(move_steps <= i):
                self._move_to_thrust[i, :, j * n : (j + 1) * n] = np.eye(n)
        self._move_steps = move_steps
        weights = np.vstack([np.tile(config.Q, (ny - 1, 1)), config.S])  # rows n = 1..ny
        self._sqrt_state_weights = np.sqrt(weights)
        thrust_weights = np.array(config.thrust_weights(n), dtype=float)
        if config.thrust_penalty is ThrustPenalty.ABSOLUTE:
            stacked = self._move_to_thrust.reshape(ny * n, self.n_moves)
            weighted = stacked * np.tile(thrust_weights, ny)[:, None]
            self._thrust_hessian = 2.0 * stacked.T @ weighted  # constant: the moves' R term
            self._thrust_gradient_map = 2.0 * weighted.T.reshape(self.n_moves, ny, n).sum(axis=1)
        else:
            self._thrust_hessian = 2.0 * np.diag(np.tile(thrust_weights, nc))
            self._thrust_gradient_map = np.zeros((self.n_moves, n))
        self._thrust_weights = thrust_weights
        self._max_move = model.thrust_rate_limit * config.sample_time
        # F bounds where the thrust changes (it is held in between and after the last move).
        self._thrust_rows = self._move_to_thrust[move_steps].reshape(nc * n, self.n_moves)
        self._solver = make_qp_solver(config.qp_solver, config.qp_iteration_limit)
        self._observer = (
            DisturbanceObserver(model, config.sample_time, config.observer, config.model_substeps)
            if config.offset_free
            else None
        )
        self.reset(np.zeros(NX), np.zeros(n))

    # -- the one thing subclasses decide ------------------------------------------------
    @abstractmethod
    def prediction_model(
        self, state: np.ndarray, nominal_thrust: np.ndarray, disturbance_world: np.ndarray
    ) -> AffinePrediction:
        """Affine model over the horizon around ``nominal_thrust`` (ny, n), with the
        estimated world-frame force and moment ``disturbance_world`` (3,) acting throughout."""

    # -- Controller interface ------------------------------------------------------------
    def reset(self, initial_state: np.ndarray, initial_thrust: np.ndarray) -> None:
        self._previous_thrust = np.array(initial_thrust, dtype=float)
        self._plan: np.ndarray | None = None  # (ny, n) thrusts of the last good solution
        if self._observer is not None:
            self._observer.reset(initial_state)

    def compute(self, observation: Observation) -> ControlResult:
        started = time.perf_counter()
        n, ny = self.model.n_thrusters, self.horizon
        previous = self._previous_thrust
        state = np.asarray(observation.state, dtype=float)
        disturbance = np.zeros(3)
        if self._observer is not None:
            state, disturbance = self._observer.correct(state)
        reference = self._aligned_reference(state, observation.reference[: ny + 1])
        moves = self._shifted_moves()
        solve_time = 0.0
        for _ in range(self.config.linearisation_iterations):
            # Each pass re-linearises (model and obstacle half-planes) around the last plan.
            nominal_thrust = previous + self._move_to_thrust @ moves
            prediction = self.prediction_model(state, nominal_thrust, disturbance)
            free, sensitivity = self._condense(state, previous, prediction)
            nominal = prediction.nominal
            if nominal is None:
                nominal = free + sensitivity @ moves
            problem, n_slack = self._build_qp(
                free, sensitivity, reference, previous, nominal, observation
            )
            if prediction.nominal is not None:
                self._add_trust_region(problem, free, sensitivity, prediction.nominal)
            result = self._solver.solve(problem, np.concatenate([moves, np.zeros(n_slack)]))
            solve_time += result.solve_time_s
            if result.z is None:
                break
            moves = result.z[: self.n_moves]
        time_limit = self.config.solver_time_limit_ms
        timed_out = time_limit is not None and 1e3 * solve_time > time_limit
        if result.z is None or timed_out:
            return self._fallback(started, solve_time)

        moves = result.z[: self.n_moves]
        slack = result.z[self.n_moves :]
        thrust, clipped = project_to_limits(previous + moves[:n], previous, self.model, self.sample_time)
        self._plan = previous + self._move_to_thrust @ moves
        self._commit(thrust)
        status = ControlStatus.OK
        if n_slack and slack.max() > _SLACK_ACTIVE_M:
            status = ControlStatus.RELAXED
        elif clipped and np.max(np.abs(thrust - previous - moves[:n])) > 1e-6:
            status = ControlStatus.SATURATED
        return ControlResult(
            thrust=thrust,
            status=status,
            solve_time_s=solve_time,
            predicted_states=free + sensitivity @ moves,
            info={
                "qp_iterations": float(result.iterations),
                "max_slack_m": float(slack.max(initial=0.0)),
                **dict(zip(("dist_X_hat", "dist_Y_hat", "dist_N_hat"), disturbance.tolist())),
            },
        )

    def _commit(self, thrust: np.ndarray) -> None:
        """Remember the applied thrust (next rate limit) and propagate the estimator with it."""
        self._previous_thrust = thrust
        if self._observer is not None:
            self._observer.predict(thrust)

    # -- pieces --------------------------------------------------------------------------
    def _aligned_reference(self, state: np.ndarray, reference: np.ndarray) -> np.ndarray:
        """Shift the (continuous) reference heading by 2 pi k to the turn the vehicle is on."""
        aligned = np.array(reference, dtype=float)
        turns = np.round((state[2] - aligned[0, 2]) / (2.0 * math.pi))
        aligned[:, 2] += 2.0 * math.pi * turns
        return aligned

    def _shifted_moves(self) -> np.ndarray:
        """Moves that best reproduce the previous plan one sample on (zeros at the start).

        Without blocking this is the plan's moves shifted by one; with blocking the
        shifted plan is sampled at the move steps, and each move is clipped to the
        rate limit so that the warm start is feasible.
        """
        if self._plan is None:
            return np.zeros(self.n_moves)
        shifted = np.vstack([self._plan[1:], self._plan[-1:]])[self._move_steps]  # (nc, n)
        moves = np.diff(np.vstack([self._previous_thrust, shifted]), axis=0)
        return np.clip(moves, -self._max_move, self._max_move).ravel()

    def _condense(
        self, state: np.ndarray, previous: np.ndarray, prediction: AffinePrediction
    ) -> tuple[np.ndarray, np.ndarray]:
        """Free response (ny+1, 6) and sensitivity to the moves (ny+1, 6, n_moves)."""
        ny = self.horizon
        free = np.empty((ny + 1, NX))
        sensitivity = np.zeros((ny + 1, NX, self.n_moves))
        free[0] = state
        for i in range(ny):
            A, B = prediction.A[i], prediction.B[i]
            free[i + 1] = A @ free[i] + B @ previous + prediction.c[i]
            sensitivity[i + 1] = A @ sensitivity[i] + B @ self._move_to_thrust[i]
        return free, sensitivity

    def _build_qp(self, free, sensitivity, reference, previous, nominal, observation):
        n_moves = self.n_moves
        normals, offsets, steps = self._obstacle_rows(observation.obstacles, nominal, reference)
        n_slack = len(steps)
        nz = n_moves + n_slack
        weighted = (sensitivity[1:] * self._sqrt_state_weights[:, :, None]).reshape(-1, n_moves)
        error = ((free[1:] - reference[1:]) * self._sqrt_state_weights).ravel()
        H = np.zeros((nz, nz))
        f = np.zeros(nz)
        H[:n_moves, :n_moves] = 2.0 * weighted.T @ weighted + self._thrust_hessian
        H[:n_moves, :n_moves] += _HESSIAN_REGULARISATION * np.eye(n_moves)
        f[:n_moves] = 2.0 * weighted.T @ error + self._thrust_gradient_map @ previous
        bound_lower = np.concatenate([np.full(n_moves, -self._max_move), np.zeros(n_slack)])
        bound_upper = np.concatenate([np.full(n_moves, self._max_move), np.full(n_slack, np.inf)])

        nc = len(self._move_steps)
        thrust_rows = np.zeros((self._thrust_rows.shape[0], nz))
        thrust_rows[:, :n_moves] = self._thrust_rows
        rows = [thrust_rows]
        lower = [np.tile(self.model.thrust_min - previous, nc)]
        upper = [np.tile(self.model.thrust_max - previous, nc)]
        if n_slack:
            # One slack per half-plane: an exact L1 penalty relaxes only the rows that must be.
            slack = np.arange(n_moves, nz)
            H[slack, slack] = 2.0 * _SLACK_QUADRATIC_WEIGHT
            f[slack] = self.config.obstacle_slack_penalty
            block = np.zeros((n_slack, nz))
            block[:, :n_moves] = np.einsum("rk,rkj->rj", normals, sensitivity[steps, :2, :])
            block[:, slack] = np.eye(n_slack)
            rows.append(block)
            lower.append(offsets - np.einsum("rk,rk->r", normals, free[steps, :2]))
            upper.append(np.full(n_slack, np.inf))
        problem = QpProblem(
            H=H,
            f=f,
            A=np.vstack(rows),
            lower=np.concatenate(lower),
            upper=np.concatenate(upper),
            bound_lower=bound_lower,
            bound_upper=bound_upper,
        )
        return problem, n_slack

    def _add_trust_region(self, problem, free, sensitivity, nominal) -> None:
        """Penalise predicted states far from the trajectory the model was linearised on.

        A linearisation is only valid near its nominal: without this term the QP may
        exploit it (e.g. a large heading change whose cosine it sees as linear) and the
        plan, the next nominal, jumps. The penalty vanishes when the plan agrees with
        its nominal, so it does not bias a converged, steady solution.
        """
        weight = np.sqrt(self.config.trust_region_weight * np.asarray(_TRUST_REGION_SCALE))
        n_moves = self.n_moves
        weighted = (sensitivity[1:] * weight[None, :, None]).reshape(-1, n_moves)
        deviation = ((free[1:] - nominal[1:]) * weight).ravel()
        problem.H[:n_moves, :n_moves] += 2.0 * weighted.T @ weighted
        problem.f[:n_moves] += 2.0 * weighted.T @ deviation

    def _obstacle_rows(self, obstacles, nominal, reference):
        """Half-planes a . p_n >= b for the predicted steps n near any obstacle.

        Steps whose nominal position is farther than ``_OBSTACLE_RANGE_M`` beyond the
        inflated disc are left out: the plan cannot move that far from its nominal in
        one re-plan, and every row saved keeps the QP small.
        """
        all_normals, all_offsets, all_steps = [], [], []
        for obstacle in obstacles:
            normals, offsets = self._half_planes(obstacle, nominal, reference)
            gaps = np.einsum("nk,nk->n", normals, nominal[1:, :2]) - offsets
            near = np.flatnonzero(gaps < _OBSTACLE_RANGE_M)
            all_normals.append(normals[near])
            all_offsets.append(offsets[near])
            all_steps.append(near + 1)
        if not all_steps:
            return np.zeros((0, 2)), np.zeros(0), np.zeros(0, dtype=int)
        return np.vstack(all_normals), np.concatenate(all_offsets), np.concatenate(all_steps)

    def _half_planes(
        self, obstacle: ObstacleState, nominal: np.ndarray, reference: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Unit normals a_n (ny, 2) and offsets b_n: the constraint is a_n . p_n >= b_n.

        Each half-plane is tangent to the disc inflated by the vehicle radius and margin, so
        any point satisfying it is clear of the obstacle whatever the normal. The normal
        points from the obstacle's predicted centre to the nominal predicted position,
        turned towards the pass side when that direction is nearly along the track (a
        disc on the path would otherwise stop the vehicle in front of it).
        """
        steps = np.arange(1, self.horizon + 1)
        centres = obstacle.center + np.outer(steps * self.sample_time, obstacle.velocity)
        radial = nominal[1:, :2] - centres
        heading = reference[1:, 2]
        tangent = np.column_stack([np.cos(heading), np.sin(heading)])
        left = np.column_stack([-tangent[:, 1], tangent[:, 0]])
        closest = int(np.argmin(np.einsum("nk,nk->n", radial, radial)))
        side_sign = np.sign(left[closest] @ radial[closest]) or 1.0
        side = side_sign * left
        normals = _clamp_towards(radial, side, _MAX_NORMAL_ANGLE_FROM_SIDE)
        reach = obstacle.radius + self.config.vehicle_radius + self.config.obstacle_margin
        offsets = np.einsum("nk,nk->n", normals, centres) + reach
        return normals, offsets

    def _fallback(self, started: float, solve_time_s: float) -> ControlResult:
        """Solver failed or was too slow: apply the previous plan's next move, clipped."""
        previous = self._previous_thrust
        if self._plan is not None and len(self._plan) > 1:
            wanted = self._plan[1]
            self._plan = np.vstack([self._plan[1:], self._plan[-1:]])
        else:
            wanted = previous
        thrust, _ = project_to_limits(wanted, previous, self.model, self.sample_time)
        self._commit(thrust)
        return ControlResult(thrust=thrust, status=ControlStatus.FALLBACK, solve_time_s=solve_time_s)


def _clamp_towards(vectors: np.ndarray, side: np.ndarray, max_angle: float) -> np.ndarray:
    """Unit vectors from ``vectors``, rotated towards ``side`` where further than max_angle."""
    norms = np.linalg.norm(vectors, axis=1)
    safe = np.where(norms[:, None] > 1e-9, vectors / np.maximum(norms, 1e-12)[:, None], side)
    cos_angle = np.clip(np.einsum("nk,nk->n", safe, side), -1.0, 1.0)
    too_far = np.arccos(cos_angle) > max_angle
    if not np.any(too_far):
        return safe
    # Component of the direction across ``side`` keeps its sign; the angle becomes max_angle.
    across = safe - cos_angle[:, None] * side
    across_norm = np.linalg.norm(across, axis=1)
    across_unit = np.where(
        across_norm[:, None] > 1e-9, across / np.maximum(across_norm, 1e-12)[:, None], 0.0
    )
    clamped = math.cos(max_angle) * side + math.sin(max_angle) * across_unit
    return np.where(too_far[:, None], clamped, safe)


def sdc_matrix(state: np.ndarray, params: VehicleParams) -> np.ndarray:
    """A_c(x) with A_c(x) x = f(x, 0): the paper's state-dependent-coefficient form.

    Rows 1-2 hold the rotation, row 3 psi' = r, rows 4-6 the damping and Coriolis
    terms with the coupling velocities frozen (one factorisation among many; this
    one makes A_c(x) x exact).
    """
    _, _, psi, u, v, r = state
    p = params
    A = np.zeros((NX, NX))
    A[0, 3], A[0, 4] = math.cos(psi), -math.sin(psi)
    A[1, 3], A[1, 4] = math.sin(psi), math.cos(psi)
    A[2, 5] = 1.0
    A[3, 3] = (p.Xu + p.Xuu * abs(u)) / p.m11
    A[3, 4] = p.m22 * r / p.m11
    A[4, 3] = -p.m11 * r / p.m22
    A[4, 4] = (p.Yv + p.Yvv * abs(v)) / p.m22
    A[5, 3] = (p.m11 - p.m22) * v / p.Iz
    A[5, 5] = (p.Nr + p.Nrr * abs(r)) / p.Iz
    return A


def input_matrix(params: VehicleParams) -> np.ndarray:
    """B_c (6, n): thrust enters the velocity rows through M^-1 T."""
    B = np.zeros((NX, params.n_thrusters))
    B[3:] = np.diag([1.0 / params.m11, 1.0 / params.m22, 1.0 / params.Iz]) @ params.T
    return B


def disturbance_matrix(params: VehicleParams) -> np.ndarray:
    """G_c (6, 3): a body-frame force [d_u, d_v, d_r] enters the velocity rows through M^-1."""
    G = np.zeros((NX, 3))
    G[3:] = np.diag([1.0 / params.m11, 1.0 / params.m22, 1.0 / params.Iz])
    return G


def rk4_discretize(A: np.ndarray, B: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Exact result of one RK4 step on x' = A x + B u with u held (Ad, Bd).

    RK4 applied to a linear system equals the 4th-order Taylor polynomial of the
    matrix exponential: Ad = sum_{k<=4} (A dt)^k / k!, Bd = sum_{k<=3} A^k dt^(k+1)/(k+1)! B.
    """
    identity = np.eye(A.shape[0])
    Ah = A * dt
    Ah2 = Ah @ Ah
    Ah3 = Ah2 @ Ah
    Ad = identity + Ah + Ah2 / 2.0 + Ah3 / 6.0 + Ah3 @ Ah / 24.0
    Bd = dt * (identity + Ah / 2.0 + Ah2 / 6.0 + Ah3 / 24.0) @ B
    return Ad, Bd


class PaperMpc(LinearMpc):
    """The paper's controller: SDC matrices refreshed at the current state every sample."""

    def __init__(self, model: VehicleParams, config: ControllerConfig) -> None:
        super().__init__(model, config)
        # Thrust and body-frame disturbance enter the same velocity rows: [B_c, G_c].
        self._input_matrix = np.hstack([input_matrix(model), disturbance_matrix(model)])

    def prediction_model(
        self, state: np.ndarray, nominal_thrust: np.ndarray, disturbance_world: np.ndarray
    ) -> AffinePrediction:
        h = self.sample_time / self.config.model_substeps
        step_A, step_B = rk4_discretize(sdc_matrix(state, self.model), self._input_matrix, h)
        Ad, Bd = step_A, step_B
        for _ in range(self.config.model_substeps - 1):  # compose the sub-steps, inputs held
            Ad, Bd = step_A @ Ad, step_A @ Bd + step_B
        n, ny = self.model.n_thrusters, self.horizon
        # The paper's g_c w_b term: the disturbance rotated at the frozen heading.
        d_u, d_v = body_from_world(disturbance_world, state[2])
        offset = Bd[:, n:] @ np.array([d_u, d_v, disturbance_world[2]])
        return AffinePrediction(
            A=np.broadcast_to(Ad, (ny, NX, NX)),
            B=np.broadcast_to(Bd[:, :n], (ny, NX, n)),
            c=np.broadcast_to(offset, (ny, NX)),
        )
