"""Nonlinear MPC on the exact RK4 model: multiple shooting, IPOPT or real-time iterations.

The optimal control problem is the one :class:`~auvmpc.controllers.mpc.LinearMpc` poses
(paper-model.md section 4), with nothing linearised:

    min  sum_{n=1}^{ny-1} |X_n - r_n|_Q^2 + |X_ny - r_ny|_S^2 + sum_{n=0}^{ny-1} |F_n|_R^2
         + rho sum s + sum s^2
    s.t. X_0 = x_hat,   X_{n+1} = RK4(X_n, F_n, d_hat)        (model_substeps steps over Te)
         F_min <= F_n <= F_max,   |F_n - F_{n-1}| <= rate Te  (F_{-1}: last applied thrust)
         |p_n - c_o(t + n Te)| - (r_o + vehicle_radius + obstacle_margin) + s_{o,n} >= 0,
         s >= 0,   for every obstacle slot o and n = 1..ny

With ``thrust_penalty: increment`` R weights F_n - F_{n-1} instead. The decision variables
are the states X_0..X_ny and the thrusts at the move steps of ``config.move_schedule()``
(multiple shooting); the thrust is held between moves. The reference heading is shifted by
2 pi k to the turn the vehicle is on, as in LinearMpc. A keep-out disc is an exact
constraint in distance form, so its slack is in metres and ``obstacle_slack_penalty`` (per m)
means what it means for LinearMpc; its linearisation is the half-plane tangent to the
inflated disc facing the linearisation point. Obstacles fill ``MAX_OBSTACLES`` slots (the
nearest ones when there are more); an empty slot's rows have no lower bound. The program
is therefore built once, as expanded SX, with all that changes between samples passed as
parameters and bounds.

Two ways to solve it (``config.nmpc_mode``):

* ``full``: IPOPT to convergence, warm-started from the previous solution shifted one
  sample (primal and dual): the accuracy reference.
* ``real-time``: the real-time iteration (Diehl, Bock, Schloeder 2005, "A real-time
  iteration scheme for nonlinear optimization in optimal feedback control"): one SQP step
  per sample from the shifted previous solution. The cost is a linear least-squares cost,
  so the Gauss-Newton Hessian is exact for it and constant. The step's QP is built from
  the RK4 map's Jacobians at every shooting node. By default (``qp_structure: sparse``) it
  keeps the states and HPIPM solves it (solvers/sparse_rti.py: well posed for unstable
  vehicles); ``condensed`` (and move blocking) condenses it onto the thrusts (the shooting
  gaps enter as offsets) for the configured dense QP backend (``qp_solver``). Obstacle rows
  are kept where the linearisation point is within ``_OBSTACLE_RANGE_M`` of the disc.
  ``linearisation_iterations`` > 1 takes that many SQP steps per sample.

Without a previous solution (after a reset or a failed solve) both start from the states
on the reference and the last thrust held (multiple shooting need not start on a
trajectory; on 8 random states IPOPT took 160-500 iterations from the model's run under the
held thrust, failing twice, and 60-300 from the reference). The real-time scheme then takes
``_COLD_START_ITERATIONS`` SQP steps, each followed by re-simulating the states from the
new thrusts: from a crude guess the linear state update can run away (measured on random
states, 24 of 48 samples failed with it, 1 with re-simulated states). From a shifted
solution it keeps the multiple-shooting update, which tracks far better under model error
(paper-disturbed, offset-free, inertia level -1, RMS after 30 s: 0.045 m, against 0.46 m
with re-simulated states).

The safety rules are the shell's (controllers/shell.py), as for every MPC: the applied
command is projected into the hard-limit box; a failed or late solve applies the previous
plan's next move (FALLBACK); an active slack marks the step RELAXED. With ``offset_free``
the EKF of auvmpc.estimation supplies the state and the world-frame force the prediction
model uses.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import casadi as ca
import numpy as np

from auvmpc.controllers.base import (
    Observation,
    ObstacleState,
    align_heading,
    horizontal_limits,
)
from auvmpc.controllers.config import ControllerConfig, NmpcMode, QpStructure
from auvmpc.controllers.shell import Proposal, ShelledController
from auvmpc.estimation import DisturbanceObserver
from auvmpc.models.discrete import horizontal_model
from auvmpc.ocp.tracking import ThrustPenalty
from auvmpc.solvers.dense_qp import QpProblem, make_qp_solver
from auvmpc.solvers.sparse_rti import SparseRealTimeIteration
from auvmpc.vehicle import VehicleParams

__all__ = ["MAX_OBSTACLES", "Iterate", "MultipleShootingProgram", "NonlinearMpc", "Sample"]

NX, ND = 6, 3
# Obstacle slots in the program (built once): the nearest this many visible obstacles count.
MAX_OBSTACLES = 8
# Per slot: centre x, y now (m), velocity x, y (m/s), reach = radius + vehicle radius + margin.
_SLOT_FIELDS = 5
# Smooths the distance at an obstacle's centre, sqrt(d^2 + eps) (m^2): differentiable
# everywhere, and the constraint moves by at most sqrt(eps) = 1 mm (only at the centre).
_DISTANCE_SMOOTHING_M2 = 1e-6
# Quadratic part of the slack penalty (as in LinearMpc): definite in the slack; the linear
# part (config.obstacle_slack_penalty) is what makes the penalty exact.
_SLACK_QUADRATIC_WEIGHT = 1.0
# Where an unused obstacle slot is parked, from the vehicle (m); its rows are unbounded anyway.
_PARKED_OBSTACLE_M = 1e4
# IPOPT: tolerance of the accuracy reference, and its iteration cap unless
# config.qp_iteration_limit sets one.
_IPOPT_TOLERANCE = 1e-8
_IPOPT_MAX_ITERATIONS = 500
# IPOPT's initial barrier parameter when warm-started: the default 0.1 would push the shifted
# solution deep into the interior of the bounds and undo most of the warm start. Measured on
# paper-obstacles (60 samples): median 9 iterations at 1e-4, 6.5 at 1e-6, 16 cold.
_IPOPT_WARM_MU_INIT = 1e-6
# IPOPT return statuses of a solve cut short by its limits rather than failed.
_IPOPT_UNFINISHED = (
    "Maximum_Iterations_Exceeded",
    "Maximum_WallTime_Exceeded",
    "Maximum_CpuTime_Exceeded",
)
# Real-time iteration: obstacle rows are kept for the predicted steps whose linearisation
# point is within this distance of the inflated disc (m), as in LinearMpc; one SQP step
# cannot move the plan that far.
_OBSTACLE_RANGE_M = 5.0
# Levenberg-Marquardt term on the thrust step of the condensed QP: at least the absolute
# value (keeps H definite when R = 0, as in LinearMpc), else relative to H's largest diagonal
# entry. Along a plan that spins the vehicle the sensitivities of late states grow without
# bound (measured: condition 1e21 when escaping an obstacle at rest) and DAQP fails; a damped
# step does not. It penalises the step, not the iterate, so the fixed point is unchanged;
# at 1e-8 the 10-step cold start converged 1000 times more slowly, at 1e-10 as without.
_HESSIAN_REGULARISATION = 1e-9
_RELATIVE_REGULARISATION = 1e-10
# SQP steps on a sample without a solution to shift (first sample, after a failure): the
# real-time iteration then goes on from a (nearly) converged solution, as it assumes.
# Measured: 10 steps bring the first thrust within 5e-8 N of IPOPT's on the paper oval.
_COLD_START_ITERATIONS = 10


@dataclass
class Iterate:
    """A primal point of the program: the plan and its predicted states."""

    states: np.ndarray  # (ny + 1, 6): X_0..X_ny
    thrust: np.ndarray  # (nc, n): the thrust set at each move step
    slack: np.ndarray  # (ny, slots): s_{o,n} for n = 1..ny


@dataclass(frozen=True)
class Sample:
    """What one sample's program depends on besides the iterate."""

    state: np.ndarray  # (6,) X_0
    previous: np.ndarray  # (n,) F_{-1}
    reference: np.ndarray  # (ny + 1, 6) aligned
    disturbance: np.ndarray  # (3,) world force and moment
    slots: np.ndarray  # (slots, 5) obstacle data, parked where unused
    used: np.ndarray  # (slots,) bool


@dataclass
class _Solution:
    iterate: Iterate | None  # None: no usable solution
    iterations: int
    solve_time_s: float
    status: str
    resume: Iterate | None = None  # an unfinished solve's last point, worth continuing from


class MultipleShootingProgram:
    """The NLP ``min J(w, p) s.t. lbg <= g(w, p) <= ubg, lbw <= w <= ubw``, built once.

    ``w`` stacks the states X_0..X_ny (6 each), the thrusts at the move steps (n each) and one
    slack per predicted step and obstacle slot. ``p`` stacks the last applied thrust (n), the
    aligned reference rows 1..ny (6 each), the world-frame force and moment (3) and the
    obstacle slots (5 each). ``g`` stacks the shooting gaps X_{n+1} - RK4(X_n, F_n) (6 per
    step), the thrust changes at the move steps (n each) and, per step and slot, the distance
    to the obstacle minus its reach plus the slack.
    """

    def __init__(
        self, model: VehicleParams, config: ControllerConfig, n_slots: int = MAX_OBSTACLES
    ):
        config = config.with_model_substeps(model)
        n, ny = model.n_thrusters, config.prediction_horizon
        self.model, self.config = model, config
        self.n_thrusters, self.horizon, self.n_slots = n, ny, n_slots
        self.ocp = ocp = config.ocp(model)
        self.sample_time = ocp.sample_time
        self.move_steps = np.array(ocp.move_steps)
        self.n_moves = ocp.n_moves
        self.held = ocp.held  # held[i]: the move whose thrust acts at step i
        # Per stacked thrust change (move by move): the largest change in one sample (N).
        self.max_change = np.tile(ocp.max_move, self.n_moves)

        sampled = horizontal_model(model, config.sample_time, config.model_substeps, config.jit)
        self.step = sampled.step
        self.rollout = sampled.rollout(ny)
        # The step with its Jacobians, evaluated at every shooting node in one call.
        self.linearised_steps = sampled.linearised_nodes(ny)

        self.n_w = NX * (ny + 1) + n * self.n_moves + n_slots * ny
        w = ca.SX.sym("w", self.n_w)
        X = ca.reshape(w[: NX * (ny + 1)], NX, ny + 1)  # column i: X_i
        U = ca.reshape(w[NX * (ny + 1) : NX * (ny + 1) + n * self.n_moves], n, self.n_moves)
        # column i: the slacks of step i + 1
        slack = ca.reshape(w[NX * (ny + 1) + n * self.n_moves :], n_slots, ny)
        previous = ca.SX.sym("F_prev", n)
        reference = ca.SX.sym("ref", NX, ny)  # column i: r_{i+1}
        disturbance = ca.SX.sym("d_world", ND)
        slots = ca.SX.sym("obstacles", _SLOT_FIELDS, n_slots)
        p = ca.vertcat(previous, ca.vec(reference), disturbance, ca.vec(slots))

        thrust_at = [U[:, int(j)] for j in self.held]
        gaps = [X[:, i + 1] - self.step(X[:, i], thrust_at[i], disturbance) for i in range(ny)]
        changes = [U[:, 0] - previous] + [U[:, j] - U[:, j - 1] for j in range(1, self.n_moves)]
        clearances = []
        for i in range(1, ny + 1):
            for o in range(n_slots):
                centre = slots[0:2, o] + (i * config.sample_time) * slots[2:4, o]
                distance = ca.sqrt(ca.sumsqr(X[0:2, i] - centre) + _DISTANCE_SMOOTHING_M2)
                clearances.append(distance - slots[4, o] + slack[o, i - 1])
        self.n_gaps, self.n_changes = NX * ny, n * self.n_moves
        g = ca.vertcat(*gaps, *changes, *clearances)

        Q, S, R = np.diag(ocp.stage_weight), np.diag(ocp.terminal_weight), np.diag(ocp.input_weight)
        cost = 0
        for i in range(1, ny + 1):
            error = X[:, i] - reference[:, i - 1]
            cost += ca.bilin(S if i == ny else Q, error, error)
        if ocp.penalty is ThrustPenalty.ABSOLUTE:
            cost += sum(ca.bilin(R, F, F) for F in thrust_at)
        else:
            cost += sum(ca.bilin(R, dF, dF) for dF in changes)
        cost += ocp.slack_penalty * ca.sum1(ca.vec(slack))
        cost += _SLACK_QUADRATIC_WEIGHT * ca.sumsqr(slack)
        self.w, self.p, self.cost, self.g = w, p, cost, g

    # -- packing -------------------------------------------------------------------------
    def pack(self, iterate: Iterate) -> np.ndarray:
        """w from an iterate (the states column by column, as ``w`` stacks them)."""
        return np.concatenate(
            [iterate.states.ravel(), iterate.thrust.ravel(), iterate.slack.ravel()]
        )

    def unpack(self, w: np.ndarray) -> Iterate:
        n, ny = self.n_thrusters, self.horizon
        states_end = NX * (ny + 1)
        thrust_end = states_end + n * self.n_moves
        return Iterate(
            states=w[:states_end].reshape(ny + 1, NX),
            thrust=w[states_end:thrust_end].reshape(self.n_moves, n),
            slack=w[thrust_end:].reshape(ny, self.n_slots),
        )

    def parameters(self, sample: Sample) -> np.ndarray:
        return np.concatenate(
            [
                sample.previous,
                sample.reference[1:].ravel(),
                sample.disturbance,
                sample.slots.ravel(),
            ]
        )

    def bounds(self, sample: Sample) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """lbw, ubw, lbg, ubg: X_0 fixed, thrust box, rate box, obstacles of the used slots."""
        lbw, ubw = np.full(self.n_w, -np.inf), np.full(self.n_w, np.inf)
        lbw[:NX] = ubw[:NX] = sample.state
        thrust = slice(NX * (self.horizon + 1), NX * (self.horizon + 1) + self.n_changes)
        lbw[thrust] = np.tile(self.ocp.input_lower, self.n_moves)
        ubw[thrust] = np.tile(self.ocp.input_upper, self.n_moves)
        lbw[thrust.stop :] = 0.0
        lbg, ubg = np.zeros(self.n_gaps), np.zeros(self.n_gaps)
        obstacle_lower = np.where(np.tile(sample.used, self.horizon), 0.0, -np.inf)
        lbg = np.concatenate([lbg, -self.max_change, obstacle_lower])
        ubg = np.concatenate([ubg, self.max_change, np.full(obstacle_lower.size, np.inf)])
        return lbw, ubw, lbg, ubg

    # -- numeric pieces ------------------------------------------------------------------
    def sample(
        self,
        state: np.ndarray,
        previous: np.ndarray,
        reference: np.ndarray,
        disturbance: np.ndarray,
        obstacles: tuple[ObstacleState, ...],
    ) -> Sample:
        """The sample's data; the nearest obstacles fill the slots, the rest are parked."""
        slots = np.zeros((self.n_slots, _SLOT_FIELDS))
        slots[:, 0:2] = state[:2] + _PARKED_OBSTACLE_M
        used = np.zeros(self.n_slots, dtype=bool)
        nearest = sorted(obstacles, key=lambda o: float(np.linalg.norm(o.center - state[:2])))
        extra = self.ocp.keep_out_extra
        for o, obstacle in enumerate(nearest[: self.n_slots]):
            slots[o] = [*obstacle.center, *obstacle.velocity, obstacle.radius + extra]
            used[o] = True
        return Sample(state, previous, reference, disturbance, slots, used)

    def plan(self, iterate: Iterate) -> np.ndarray:
        """Thrust at every step of the horizon (ny, n)."""
        return iterate.thrust[self.held]

    def shifted(self, iterate: Iterate, disturbance: np.ndarray) -> Iterate:
        """The iterate one sample on: states, plan and slacks advanced by one step.

        The new terminal state is the model's step from the old one under the last thrust;
        the thrusts at the move steps are read from the plan shifted by one sample.
        """
        plan = self.plan(iterate)
        terminal = np.asarray(self.step(iterate.states[-1], plan[-1], disturbance)).ravel()
        return Iterate(
            states=np.vstack([iterate.states[1:], terminal]),
            thrust=np.vstack([plan[1:], plan[-1:]])[self.move_steps],
            slack=np.vstack([iterate.slack[1:], iterate.slack[-1:]]),
        )

    def reference_guess(self, sample: Sample) -> Iterate:
        """A guess without a previous solution: the states on the reference (multiple
        shooting need not start from a trajectory), the last thrust held, no slack."""
        return Iterate(
            states=np.vstack([sample.state, sample.reference[1:]]),
            thrust=np.tile(sample.previous, (self.n_moves, 1)),
            slack=np.zeros((self.horizon, self.n_slots)),
        )

    def clearances(self, states: np.ndarray, sample: Sample) -> tuple[np.ndarray, np.ndarray]:
        """Distance minus reach (ny, slots) at steps 1..ny, and its gradient in p (ny, slots, 2)."""
        steps = self.sample_time * np.arange(1, self.horizon + 1)
        centres = sample.slots[None, :, 0:2] + steps[:, None, None] * sample.slots[None, :, 2:4]
        offset = states[1:, None, :2] - centres
        distance = np.sqrt(np.einsum("nok,nok->no", offset, offset) + _DISTANCE_SMOOTHING_M2)
        return distance - sample.slots[None, :, 4], offset / distance[:, :, None]


class _IpoptSolver:
    """The full solve: IPOPT to convergence, warm-started in primal and dual variables.

    Two instances of IPOPT on the same program: one for a shifted solution (small initial
    barrier, multipliers kept), one with IPOPT's default initialisation for a cold guess.
    From a cold guess on 8 random states the warm settings took 60-300 iterations, the
    defaults 20-240; from a shifted solution the defaults take 2.5 times the warm settings'.
    """

    def __init__(self, program: MultipleShootingProgram, config: ControllerConfig) -> None:
        common = {
            "print_level": 0,
            "sb": "yes",
            "tol": _IPOPT_TOLERANCE,
            # IPOPT would scale the objective by 100 / max gradient, 1e-3 for the slack
            # penalty's 1e5, and loosen its tolerance as much (measured: first thrusts
            # 1.6e-5 N from the converged real-time iteration, 1.6e-8 N unscaled).
            "nlp_scaling_method": "none",
            "s_max": 1e6,
            "max_iter": config.qp_iteration_limit or _IPOPT_MAX_ITERATIONS,
        }
        if config.solver_time_limit_ms is not None:
            # Stop at the deadline rather than finish a solve whose result is discarded.
            common["max_wall_time"] = 1e-3 * config.solver_time_limit_ms
        warm = {
            "warm_start_init_point": "yes",
            "mu_init": _IPOPT_WARM_MU_INIT,
            "warm_start_bound_push": 1e-8,
            "warm_start_mult_bound_push": 1e-8,
        }
        nlp = {"x": program.w, "p": program.p, "f": program.cost, "g": program.g}
        self._warm = ca.nlpsol(
            "nmpc_ipopt", "ipopt", nlp, {"print_time": False, "ipopt": {**common, **warm}}
        )
        self._cold = ca.nlpsol(
            "nmpc_ipopt_cold", "ipopt", nlp, {"print_time": False, "ipopt": common}
        )
        self.program = program
        self.reset()

    def reset(self) -> None:
        self._lam_g = np.zeros(self.program.g.numel())
        self._lam_w = np.zeros(self.program.n_w)

    def solve(self, guess: Iterate, sample: Sample, iterations: int, cold: bool) -> _Solution:
        """``iterations`` is ignored: IPOPT runs to convergence (or its limits)."""
        program = self.program
        lbw, ubw, lbg, ubg = program.bounds(sample)
        solver = self._cold if cold else self._warm
        if cold:
            self.reset()
        started = time.perf_counter()
        try:
            result = solver(
                x0=program.pack(guess),
                p=program.parameters(sample),
                lbx=lbw,
                ubx=ubw,
                lbg=lbg,
                ubg=ubg,
                lam_g0=self._lam_g,
                lam_x0=self._lam_w,
            )
        except RuntimeError as error:  # CasADi rejects ill-posed data (e.g. NaN bounds)
            self.reset()
            return _Solution(None, 0, time.perf_counter() - started, f"RuntimeError: {error}")
        elapsed = time.perf_counter() - started
        stats = solver.stats()
        w = np.asarray(result["x"]).ravel()
        finite = bool(np.all(np.isfinite(w)))
        usable = bool(stats["success"]) and finite
        status = str(stats["return_status"])
        # Stopped at its iteration or time limit: not a solution, but a point to go on from.
        unfinished = finite and status in _IPOPT_UNFINISHED
        if usable or unfinished:
            self._lam_g = self._shifted_multipliers(np.asarray(result["lam_g"]).ravel())
            self._lam_w = np.asarray(result["lam_x"]).ravel()
        else:  # a failed solve's multipliers are no guide to the next
            self.reset()
        return _Solution(
            iterate=program.unpack(w) if usable else None,
            iterations=int(stats["iter_count"]),
            solve_time_s=elapsed,
            status=status,
            resume=program.unpack(w) if unfinished else None,
        )

    def _shifted_multipliers(self, lam_g: np.ndarray) -> np.ndarray:
        """Multipliers one sample on: gaps and obstacle rows by one step, rate rows reset."""
        program = self.program
        ny = program.horizon
        gaps = lam_g[: program.n_gaps].reshape(ny, NX)
        obstacles = lam_g[program.n_gaps + program.n_changes :].reshape(ny, program.n_slots)
        return np.concatenate(
            [
                np.vstack([gaps[1:], gaps[-1:]]).ravel(),
                np.zeros(program.n_changes),  # a move's meaning changes when shifted
                np.vstack([obstacles[1:], obstacles[-1:]]).ravel(),
            ]
        )


class _RealTimeIteration:
    """Gauss-Newton SQP steps on the multiple-shooting program, each one condensed QP.

    Around an iterate (X, U, S), with A_i, B_i the Jacobians of the RK4 map at (X_i, F_i)
    and c_i = RK4(X_i, F_i) - X_{i+1} the shooting gap, the step's prediction is
        dX_0 = x_hat - X_0,   dX_{i+1} = A_i dX_i + B_i dF_i + c_i,
    so dX_i = f_i + G_i dU: the QP's variables are the thrust steps dU at the move steps and
    one slack per obstacle row kept. The new iterate is (X + dX, U + dU, s), or on a cold
    start (X simulated from x_hat under U + dU, U + dU, s) (module docstring).
    """

    def __init__(self, program: MultipleShootingProgram, config: ControllerConfig) -> None:
        self.program = program
        n, ny, nc = program.n_thrusters, program.horizon, program.n_moves
        self._solver = make_qp_solver(config.qp_solver, config.qp_iteration_limit)
        # E_i: the thrust at step i as a selection from the stacked move thrusts (n, nc n).
        self._selection = np.zeros((ny, n, nc * n))
        for i, j in enumerate(program.held):
            self._selection[i, :, j * n : (j + 1) * n] = np.eye(n)
        ocp = program.ocp
        self._sqrt_weights = np.sqrt(ocp.stage_weights())  # rows n = 1..ny
        R = ocp.input_weight
        self._absolute = ocp.penalty is ThrustPenalty.ABSOLUTE
        if self._absolute:
            # sum_i |F_i|_R^2 with F_i = E_i U: each move's weight counts the steps it is held.
            counts = np.bincount(program.held, minlength=nc)
            self._thrust_hessian = 2.0 * np.diag(np.repeat(counts, n) * np.tile(R, nc))
        else:
            # sum_j |U_j - U_{j-1}|_R^2 = |D U - e_0 F_prev|_R^2 with D the block difference.
            self._difference = np.eye(nc * n) - np.eye(nc * n, k=-n)
            self._thrust_hessian = (
                2.0 * self._difference.T @ (np.tile(R, nc)[:, None] * self._difference)
            )
        self._R = np.tile(R, nc)

    def reset(self) -> None:
        """Nothing is carried between samples except the backend's active set."""

    def solve(self, guess: Iterate, sample: Sample, iterations: int, cold: bool) -> _Solution:
        started = time.perf_counter()
        iterate: Iterate | None = guess
        total = 0
        status = "not run"
        # A diverging iterate overflows to inf/NaN; the QP backend then reports a failure.
        with np.errstate(over="ignore", invalid="ignore"):
            for _ in range(iterations):
                iterate, count, status = self._step(iterate, sample, simulate_states=cold)
                total += count
                if iterate is None:
                    break
        return _Solution(iterate, total, time.perf_counter() - started, status)

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
        near = (clearance < _OBSTACLE_RANGE_M) & sample.used[None, :]
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
        H[:n_thrust, :n_thrust] += _regularisation(H[:n_thrust, :n_thrust]) * np.eye(n_thrust)
        f[:n_thrust] = 2.0 * weighted.T @ error + self._thrust_gradient(iterate, sample)
        thrust = iterate.thrust.ravel()
        lower_thrust = np.tile(program.ocp.input_lower, nc)
        upper_thrust = np.tile(program.ocp.input_upper, nc)
        bound_lower = np.concatenate([lower_thrust - thrust, np.zeros(n_slack)])
        bound_upper = np.concatenate([upper_thrust - thrust, np.full(n_slack, np.inf)])

        # Rate rows: U_0 - F_prev and U_j - U_{j-1} within +-max_move.
        change = np.concatenate([thrust[:n] - sample.previous, thrust[n:] - thrust[:-n]])
        rate_rows = np.zeros((n_thrust, nz))
        rate_rows[:, :n_thrust] = np.eye(n_thrust) - np.eye(n_thrust, k=-n)
        max_change = program.max_change
        rows, lower, upper = [rate_rows], [-max_change - change], [max_change - change]
        if n_slack:
            slack = np.arange(n_thrust, nz)
            H[slack, slack] = 2.0 * _SLACK_QUADRATIC_WEIGHT
            f[slack] = program.ocp.slack_penalty
            normals = normal[steps, slot_index]  # (rows, 2)
            block = np.zeros((n_slack, nz))
            block[:, :n_thrust] = np.einsum("rk,rkj->rj", normals, sensitivity[steps + 1, :2, :])
            block[:, slack] = np.eye(n_slack)
            rows.append(block)
            lower.append(
                -clearance[steps, slot_index] - np.einsum("rk,rk->r", normals, free[steps + 1, :2])
            )
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
        change = self._difference @ thrust
        change[:n] -= sample.previous
        return 2.0 * self._difference.T @ (self._R * change)


class NonlinearMpc(ShelledController):
    """Nonlinear multiple-shooting MPC (``nmpc``): full IPOPT solve or real-time iterations."""

    def __init__(
        self, model: VehicleParams, config: ControllerConfig, obstacle_slots: int = MAX_OBSTACLES
    ) -> None:
        config = config.with_model_substeps(model)
        self.model = model
        self.config = config
        self.sample_time = config.sample_time
        self.horizon = config.prediction_horizon
        self.preview_steps = self.horizon
        self.limits = horizontal_limits(model)
        self.solver_time_limit_ms = config.solver_time_limit_ms
        self.program = MultipleShootingProgram(model, config, obstacle_slots)
        if config.nmpc_mode is NmpcMode.FULL:
            self._solver: _IpoptSolver | _RealTimeIteration | SparseRealTimeIteration = (
                _IpoptSolver(self.program, config)
            )
        elif (
            config.qp_structure is not QpStructure.CONDENSED
            and self.program.n_moves == self.horizon
        ):
            # Held thrusts would be equality rows, which an interior point handles badly
            # (HPIPM took 50 iterations without converging); move blocking keeps the
            # condensed QP, whose variables are the moves themselves.
            self._solver = SparseRealTimeIteration(self.program)
        elif config.nmpc_mode is NmpcMode.REAL_TIME:
            self._solver = _RealTimeIteration(self.program, config)
        else:  # unreachable: NmpcMode has no other member
            raise NotImplementedError(config.nmpc_mode)
        self._observer = (
            DisturbanceObserver(model, config.sample_time, config.observer, config.model_substeps)
            if config.offset_free
            else None
        )
        self.reset(np.zeros(NX), np.zeros(model.n_thrusters))

    @classmethod
    def from_config(cls, model, config, obstacle_count: int = 0) -> NonlinearMpc:
        """Room for the scenario's obstacles (at least one slot, at most MAX_OBSTACLES): every
        unused slot is rows and variables each solve carries."""
        return cls(model, config, obstacle_slots=max(1, min(MAX_OBSTACLES, obstacle_count)))

    # -- the back end of the safety shell -------------------------------------------------
    def restart(self, initial_state: np.ndarray, initial_thrust: np.ndarray) -> None:
        self._guess: Iterate | None = None  # where the next solve starts (None: cold)
        self._next_guess: Iterate | None = None
        self._solver.reset()
        if self._observer is not None:
            self._observer.reset(initial_state)

    def propose(self, observation: Observation, previous: np.ndarray) -> Proposal:
        state = np.asarray(observation.state, dtype=float)
        disturbance = np.zeros(ND)
        if self._observer is not None:
            state, disturbance = self._observer.correct(state)
        reference = align_heading(state, observation.reference[: self.horizon + 1])
        self._next_guess = None
        if not all(np.all(np.isfinite(a)) for a in (state, disturbance, reference)):
            # Never hand NaN to a solver (IPOPT raises on it): a failed step, not an error.
            return Proposal(plan=None, disturbance=disturbance)
        sample = self.program.sample(state, previous, reference, disturbance, observation.obstacles)
        cold = self._guess is None
        if cold:
            guess = self.program.reference_guess(sample)
            iterations = max(_COLD_START_ITERATIONS, self.config.linearisation_iterations)
        else:
            guess = _aligned_guess(self._guess, state)
            iterations = self.config.linearisation_iterations
        solution = self._solver.solve(guess, sample, iterations, cold)
        if solution.iterate is None and not cold and self.config.nmpc_mode is NmpcMode.REAL_TIME:
            # The shifted iterate itself can be what failed (a prediction that left the
            # range where the model's RK4 step is stable, and went non-finite): start again
            # from the reference within the same sample, as after a reset. Measured on the
            # random-vehicle sweep: 1 fallback in 100 vehicles without it, none with it.
            retry = self._solver.solve(
                self.program.reference_guess(sample),
                sample,
                max(_COLD_START_ITERATIONS, self.config.linearisation_iterations),
                True,
            )
            retry.solve_time_s += solution.solve_time_s
            solution = retry
        # Where the next solve starts: this solution shifted, also when the shell finds it
        # late (a solve that needs more than one sample gets it over several), or the last
        # point of a solve stopped at its limits; after any other failure, cold (its
        # starting point may be what made it fail).
        resume = solution.iterate if solution.iterate is not None else solution.resume
        if resume is not None:
            self._next_guess = self.program.shifted(resume, disturbance)
        iterate = solution.iterate
        return Proposal(
            plan=None if iterate is None else self.program.plan(iterate),
            solve_time_s=solution.solve_time_s,
            iterations=solution.iterations,
            max_slack=0.0 if iterate is None else float(iterate.slack.max(initial=0.0)),
            predicted_states=None if iterate is None else iterate.states.copy(),
            disturbance=disturbance,
        )

    def applied(self, command: np.ndarray, fell_back: bool) -> None:
        """Propagate the estimator with the applied thrust; move the warm start on."""
        self._guess = self._next_guess
        if self._observer is not None:
            self._observer.predict(command)


def _regularisation(H: np.ndarray) -> float:
    """The Levenberg-Marquardt weight for a condensed Hessian (module constants)."""
    return max(_HESSIAN_REGULARISATION, _RELATIVE_REGULARISATION * float(np.abs(np.diag(H)).max()))


def _aligned_guess(guess: Iterate, state: np.ndarray) -> Iterate:
    """The guess with its headings shifted by 2 pi k to the turn of the measured heading."""
    turns = np.round((state[2] - guess.states[0, 2]) / (2.0 * math.pi))
    if not turns:
        return guess
    states = guess.states.copy()
    states[:, 2] += 2.0 * math.pi * turns
    return Iterate(states, guess.thrust, guess.slack)
