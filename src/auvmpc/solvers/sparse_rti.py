"""The real-time iteration with a sparse (stage-wise) QP, solved by HPIPM's Riccati IPM.

Why sparse: the condensed QP of the real-time iteration eliminates the states, so its
Hessian carries the products A_{N-1} ... A_0 of the linearised dynamics. Along a plan of an
open-loop-unstable vehicle (light yaw inertia, where the Munk moment (m11 - m22) u v
destabilises sway-yaw) those products grow like e^{lambda t} over the 15 s horizon, the
condensed Hessian's condition number reaches 1e17 and the dense QP solvers fail on most
steps (measured: BlueROV2 literature parameters on a lawnmower in a current, 181 of 300
steps fell back, the vehicle left the path by 19 m RMS). The sparse QP keeps the states as
variables, so its data are the one-step Jacobians, bounded whatever the vehicle, and
HPIPM's Riccati recursion factorises it stably (same run: 0 fallbacks, 0.248 m RMS,
against 0.254 m for IPOPT on the same OCP). ``benchmarks/vehicle_sweep.py`` checks this on
random vehicles.

The QP of one Gauss-Newton SQP step around an iterate (X, F), in deltas, stage k = 0..N:

    stage state  z_k = [dX_k; dp_k]   (p_k = F_{k-1}: the previous thrust, so that the rate
                                       limit is a stage constraint)
    stage input  v_k = [w_k; sigma s_k] (w_k = dF_k - dp_k, the change of the thrust's
                                       increment; s_k >= 0: one exact-penalty slack for the
                                       obstacle rows of step k + 1, scaled: hpipm.slack_scale)
    dynamics     dX_{k+1} = A_k dX_k + B_k (dp_k + w_k) + (RK4(X_k, F_k) - X_{k+1}),
                 dp_{k+1} = dp_k + w_k + (F_k - p_{k+1})
    bounds       z_0 = [x_hat - X_0; F_prev - p_0] (known: folded into stage 0),
                 |(F_k - p_k) + w_k| <= rate Te at a move step, = 0 where the thrust is held
                 (the rate limit), F_min <= p_{k+1} + dp_{k+1} <= F_max (the thrust limit,
                 on F_k + dF_k): boxes, which cost the interior point less than rows
    obstacles    n . (p(X_{k+1}) + dX_{k+1}[:2] - c_o) + s_k >= reach_o,  written at stage k
                 through the linearised dynamics (n: the unit normal from the obstacle)
    cost         the program's cost (Gauss-Newton: its Hessian is exact and constant) plus
                 rho s_k + s_k^2, a tiny Levenberg-Marquardt term on w, and the trust
                 region's on the heading steps dpsi_k, k = 1..N-1 (trust_region_weight)

The stage data are two CasADi functions (:class:`StageQp`). By default they are compiled to
C together with a small HPIPM driver, so that one SQP step (linearisation, QP, solve) is one
call (solvers/compiled_qp_step.py); without a C compiler CasADi evaluates them and solves
the assembled QP through its HPIPM interface (:class:`CasadiQpStep`): the same QP, slower.
"""

from __future__ import annotations

import time
from typing import NamedTuple

import casadi as ca
import numpy as np

from auvmpc.models.layout import HORIZONTAL
from auvmpc.ocp.multiple_shooting import (
    DISTANCE_SMOOTHING_M2,
    ND,
    NX,
    SLOT_CENTRE,
    SLOT_FIELDS,
    SLOT_REACH,
    SLOT_VELOCITY,
    Iterate,
    MultipleShootingProgram,
    Solution,
)
from auvmpc.ocp.tracking import SLACK_QUADRATIC_WEIGHT, ThrustPenalty
from auvmpc.solvers.compiled_qp_step import compiled_qp_step
from auvmpc.solvers.hpipm import hpipm_settings, hpipm_solver, slack_scale

__all__ = ["CasadiQpStep", "SparseRealTimeIteration", "StageQp", "stage_qp"]

# Levenberg-Marquardt term on the thrust step w (as in the condensed real-time iteration): keeps
# the stage Hessian definite when R = 0; it penalises the step, not the iterate, so the fixed
# point is unchanged.
_STEP_REGULARISATION = 1e-9
# Obstacle rows are kept for the predicted steps within this distance of the inflated disc
# (m), as in the condensed real-time iteration: one SQP step cannot move the plan that far,
# and a far row would only perturb the interior point's solution (by ~1e-7 N).
_OBSTACLE_RANGE_M = 5.0
_SOLVED, _NOT_FINITE, _EVALUATION_FAILED = 0, -1, -2
_HEADING = HORIZONTAL.index("psi")
_POSITION = HORIZONTAL.position


class SparseRealTimeIteration:
    """Gauss-Newton SQP steps on a :class:`MultipleShootingProgram`, each one sparse QP."""

    def __init__(self, program: MultipleShootingProgram, compiled: bool | None = None) -> None:
        """``compiled``: None (default) compiles where a C compiler is present and the
        configuration's ``jit`` allows, False never (CasADi evaluates the same QP), True
        requires it (RuntimeError without)."""
        self.program = program
        N, n, slots = program.horizon, program.n_thrusters, program.n_slots
        qp = stage_qp(program)
        limit = program.config.qp_iteration_limit
        step = None
        if compiled or (compiled is None and program.config.jit):
            step = compiled_qp_step(qp, N, n, slots, hpipm_settings(limit))
            if step is None and compiled:
                raise RuntimeError("no C compiler, or no HPIPM in the casadi wheel")
        self.compiled = step is not None
        self._step = step if step is not None else CasadiQpStep(qp, N, n, slots, limit)
        movable = np.zeros(N)
        movable[program.move_steps] = 1.0
        weights = np.tile(program.ocp.stage_weight, (N, 1))
        weights[0] = 0.0  # X_0 is fixed: no cost
        self._movable, self._weights = movable, weights

    def reset(self) -> None:
        """Nothing to reset: the compiled step keeps HPIPM's last solution (its hot start),
        which the next sample's QP only starts from."""

    def solve(self, guess, sample, iterations: int, cold: bool, resimulate: bool | None = None):
        """``iterations`` SQP steps from ``guess``; on a cold start the states are re-simulated
        from x_hat under the new thrusts after each step (module docstring of nmpc), unless
        ``resimulate`` is False (the multiple-shooting update, as from a shifted solution)."""
        resimulate = cold if resimulate is None else resimulate
        program = self.program
        n, N = program.n_thrusters, program.horizon
        started = time.perf_counter()
        states = np.asarray(guess.states, dtype=float)  # (N + 1, 6)
        thrust = np.asarray(program.plan(guess), dtype=float)  # (N, n)
        used = sample.used.astype(float)
        fixed = (sample.state, sample.previous, sample.reference, self._weights,
                 sample.disturbance, sample.slots, used, self._movable)  # fmt: skip
        total, status, slack = 0, "not run", np.zeros(N)
        with np.errstate(over="ignore", invalid="ignore"):
            for sqp_step in range(iterations):
                previous = np.vstack([sample.previous, thrust])
                hot_start = sqp_step == 0 and not cold
                code, used_iterations = self._step(
                    states, previous, thrust, *fixed, hot_start=hot_start
                )
                total += used_iterations
                if code == _NOT_FINITE:
                    # A diverged iterate: never hand NaN to the solver.
                    return Solution(
                        None, total, time.perf_counter() - started, "non-finite QP data"
                    )
                status = (
                    "QP data evaluation failed" if code == _EVALUATION_FAILED else f"hpipm {code}"
                )
                dz, dv = self._step.dz, self._step.dv
                if code != _SOLVED or not (np.isfinite(dz).all() and np.isfinite(dv).all()):
                    return Solution(None, total, time.perf_counter() - started, status)
                thrust = thrust + dz[:N, NX:] + dv[:, :n]  # dF_k = dp_k + w_k (stage_qp)
                if program.n_slots:
                    slack = dv[:, n] / slack_scale(program.ocp.slack_penalty)
                if resimulate:
                    disturbance = np.tile(sample.disturbance[:, None], (1, N))
                    rolled = program.rollout(sample.state, thrust.T, disturbance)
                    states = np.vstack([sample.state, np.asarray(rolled).T])
                else:
                    states = states + dz[:, :NX]  # z_k = [dX_k; dp_k]
                if not np.all(np.isfinite(states)):
                    return Solution(None, total, time.perf_counter() - started, "non-finite states")
        slacks = np.zeros((N, program.n_slots))
        if program.n_slots:
            slacks[:, 0] = np.maximum(slack, 0.0)
        iterate = Iterate(states.copy(), thrust[program.move_steps].copy(), slacks)
        return Solution(iterate, total, time.perf_counter() - started, status)


class StageQp(NamedTuple):
    """The sparse QP of one SQP step, stage by stage, in HPIPM's form (Frison and Diehl 2020):

        z_{k+1} = A_k z_k + B_k v_k + b_k
        cost_k  = 1/2 [v; z]' [R S; S' Q] [v; z] + r' v + q' z
        lbu <= v_k <= ubu,   lg <= C_k z_k + D_k v_k <= ug

        lbp <= dp_{k+1} <= ubp   (the thrust part of the next state)

    ``stage`` maps (X_k, X_{k+1}, P_k, P_{k+1}, F_k, r_k, W_k, d, slots, used, movable_k,
    k + 1) to (A, B, b, Q, S, R, q, r, C, D, lg, ug, lbu, ubu, lbp, ubp), every matrix dense
    and column-major; ``terminal`` maps (X_N, r_N) to (Q, q) of the last stage. Both are
    expanded SX, so the same functions are evaluated by CasADi or compiled to C.
    """

    stage: ca.Function
    terminal: ca.Function
    states: int  # nz
    inputs: int  # nv
    rows: int  # ng of stages 0..N-1


# Stage QPs by (vehicle, configuration, slots): campaign runs of one vehicle reuse one; the
# oldest is dropped past _CACHE_SIZE.
_CACHE: dict[tuple[str, str, int], StageQp] = {}
_CACHE_SIZE = 16


def stage_qp(program: MultipleShootingProgram) -> StageQp:
    """The program's stage QP functions, built once per vehicle and configuration."""
    key = (program.model.model_dump_json(), program.config.model_dump_json(), program.n_slots)
    if key not in _CACHE:
        if len(_CACHE) >= _CACHE_SIZE:
            _CACHE.pop(next(iter(_CACHE)))
        _CACHE[key] = _build_stage_qp(program)
    return _CACHE[key]


def _build_stage_qp(program: MultipleShootingProgram) -> StageQp:
    n, S = program.n_thrusters, program.n_slots
    # One slack input per stage for its obstacle rows; none without obstacle slots.
    nz, nv, ng = NX + n, n + (1 if S else 0), S
    ocp = program.ocp
    R_weight = ocp.input_weight
    rho = ocp.slack_penalty
    sigma = slack_scale(rho)  # the slack variable is sigma s (hpipm.slack_scale says why)

    X, X_next = ca.SX.sym("X", NX), ca.SX.sym("X_next", NX)
    P, P_next = ca.SX.sym("P", n), ca.SX.sym("P_next", n)  # P_k = F_{k-1} of the iterate
    F = ca.SX.sym("F", n)
    reference, weight = ca.SX.sym("r", NX), ca.SX.sym("W", NX)
    force = ca.SX.sym("d_world", ND)
    slots = ca.SX.sym("slots", SLOT_FIELDS, S)
    used = ca.SX.sym("used", S)
    movable = ca.SX.sym("movable")
    step_index = ca.SX.sym("step")  # k + 1: the step whose obstacle rows this stage carries

    # The input is the change of the thrust's increment, w_k = dF_k - dp_k, so that the
    # rate limit is a bound on w and the thrust limit a bound on the next state's dp (box
    # constraints, where general rows cost the interior point more); dF_k = dp_k + w_k.
    # Cost of z_k = [dX_k; dp_k] and v_k = [w_k; sigma s_k].
    change = F - P
    Q = ca.SX(nz, nz)
    Q[:NX, :NX] = ca.diag(2.0 * weight)
    # The trust region on the heading (controllers/config.py, TRUST_REGION_WEIGHTS): a
    # penalty on the step dX, not the iterate, so the fixed point is unchanged.
    Q[_HEADING, _HEADING] += 2.0 * (program.config.trust_region_weight or 0.0)
    q = ca.vertcat(2.0 * weight * (X - reference), ca.SX.zeros(n))
    R = ca.SX(nv, nv)
    R[:n, :n] = ca.diag(2.0 * R_weight + _STEP_REGULARISATION)
    if S:
        R[n, n] = 2.0 * SLACK_QUADRATIC_WEIGHT / sigma**2
    slack_gradient = [rho / sigma] if S else []
    S_cross = ca.SX(nv, nz)
    if ocp.penalty is ThrustPenalty.ABSOLUTE:  # R weights F + dF = F + dp + w
        Q[NX:, NX:] = ca.diag(2.0 * R_weight)
        S_cross[:n, NX:] = ca.diag(2.0 * R_weight)
        q[NX:] = 2.0 * R_weight * F
        r = ca.vertcat(2.0 * R_weight * F, *slack_gradient)
    else:  # R weights the change (F + dF) - (P + dp) = change + w
        r = ca.vertcat(2.0 * R_weight * change, *slack_gradient)

    # Dynamics: dX_{k+1} = A dX_k + B (dp_k + w_k) + gap, dp_{k+1} = dp_k + w_k + (F_k - P_{k+1}).
    successor = program.step(X, F, force)
    # Both Jacobians from one reverse sweep per successor component (6), where ca.jacobian
    # takes forward mode, one sweep per input (6 + n): with 7 RK4 substeps (BlueROV2 Heavy)
    # the successor and its Jacobians take 16 331 SX operations against 19 425, and the whole
    # stage 15 521 against 19 935 with its common subexpressions merged (cse below).
    transposed = ca.jtimes(successor, ca.vertcat(X, F), ca.SX.eye(NX), True)  # (NX + n, NX)
    A_x, B_x = transposed[:NX, :].T, transposed[NX:, :].T
    A = ca.SX(nz, nz)
    A[:NX, :NX] = A_x
    A[:NX, NX:] = B_x
    A[NX:, NX:] = ca.SX.eye(n)
    B = ca.SX(nz, nv)
    B[:NX, :n] = B_x
    B[NX:, :n] = ca.SX.eye(n)
    gap = successor - X_next
    b = ca.vertcat(gap, F - P_next)

    # Bounds: the rate |change + w| <= movable * max_move on w; the thrust limit on the
    # next state's dp, F_min <= P_{k+1} + dp_{k+1} <= F_max.
    max_move = ca.DM(ocp.max_move)
    lbu = ca.vertcat(-movable * max_move - change, *([0.0] if S else []))
    ubu = ca.vertcat(movable * max_move - change, *([ca.inf] if S else []))
    lbp_next, ubp_next = ocp.input_lower - P_next, ocp.input_upper - P_next

    # Rows: per obstacle slot the half-plane tangent to its inflated disc at X_{k+1},
    # n . (p_{k+1} + dp_{k+1} - c) + s >= reach, through the linearised dynamics; kept for the
    # used slots within _OBSTACLE_RANGE_M of the disc.
    t = step_index * program.sample_time
    C_rows, D_rows, lower, upper = [], [], [], []
    for o in range(S):
        offset = X_next[_POSITION] - (slots[SLOT_CENTRE, o] + t * slots[SLOT_VELOCITY, o])
        distance = ca.sqrt(ca.sumsqr(offset) + DISTANCE_SMOOTHING_M2)
        normal = (offset / distance).T
        C_rows.append(normal @ A[_POSITION, :])
        D_rows.append(ca.horzcat(normal @ B[_POSITION, :n], ca.SX(1, 1) + 1.0 / sigma))
        reach = slots[SLOT_REACH, o]
        near = ca.logic_and(used[o] > 0.5, distance - reach < _OBSTACLE_RANGE_M)
        lower.append(ca.if_else(near, reach - distance - normal @ gap[_POSITION], -ca.inf))
        upper.append(ca.inf)
    C = ca.vertcat(*C_rows) if S else ca.SX(0, nz)
    D = ca.vertcat(*D_rows) if S else ca.SX(0, nv)
    lg = ca.vertcat(*lower) if S else ca.SX(0, 1)
    ug = ca.vertcat(*upper) if S else ca.SX(0, 1)

    outputs = (A, B, b, Q, S_cross, R, q, r, C, D, lg, ug, lbu, ubu, lbp_next, ubp_next)
    inputs = (X, X_next, P, P_next, F, reference, weight, force, slots, used, movable, step_index)
    stage = ca.Function(
        "rti_stage",
        list(inputs),
        [ca.densify(ca.SX(e)) for e in outputs],
        "X X_next P P_next F ref W d_world slots used movable step".split(),
        "A B b Q S R q r C D lg ug lbu ubu lbp_next ubp_next".split(),
        {"cse": True},
    )
    terminal_weight = ocp.terminal_weight
    Q_N = ca.SX(nz, nz)
    Q_N[:NX, :NX] = ca.diag(2.0 * terminal_weight)
    q_N = ca.vertcat(2.0 * terminal_weight * (X - reference), ca.SX.zeros(n))
    terminal = ca.Function(
        "rti_terminal", [X, reference], [ca.densify(Q_N), ca.densify(q_N)], ["X", "ref"], ["Q", "q"]
    )
    return StageQp(stage, terminal, nz, nv, ng)


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

        n_w = (N + 1) * nz + N * nv
        hessian, gradient, rows, lba, uba = [], [], [], [], []
        lbx = [x_hat - X[:, 0], previous - P[:, 0]]
        ubx = list(lbx)
        for k in range(N):
            A, B, b, Q, S, R, q, r, C, D, lg, ug, lbu, ubu, lbp, ubp = qp.stage(
                X[:, k], X[:, k + 1], P[:, k], P[:, k + 1], F[:, k], reference[:, k],
                weight[:, k], force, slot_data, used, movable[k], k + 1,
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
            [X, P, F, x_hat, previous, reference, weight, force, slot_data, used, movable],
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
                 hot_start=False):  # fmt: skip
        """The arguments of CompiledQpStep, in its (row-major) layout -> (status, iterations).
        Every QP is solved to 1e-8 from HPIPM's cold start: ``hot_start`` changes nothing."""
        N, nz, nv = self._sizes
        H, g, A, lba, uba, lbx, ubx = self._data(
            X.T, P.T, F.T, x_hat, previous, reference.T, weight.T, force, slots.T, used, movable
        )
        # The bounds carry the shooting gaps, the first to go non-finite (and the ones CasADi
        # refuses); a NaN elsewhere shows in HPIPM's status or its solution.
        if any(np.isnan(np.asarray(v)).any() for v in (g, lba, uba, lbx, ubx)):
            return _NOT_FINITE, 0
        result = self._qp(h=H, g=g, a=A, lba=lba, uba=uba, lbx=lbx, ubx=ubx)
        stats = self._qp.stats()
        w = np.asarray(result["x"]).ravel()
        stage = nz + nv
        self.dz[:] = np.stack([w[k * stage : k * stage + nz] for k in range(N + 1)])
        self.dv[:] = np.stack([w[k * stage + nz : (k + 1) * stage] for k in range(N)])
        return int(stats["return_status"]), int(stats["iter_count"])
