"""The tracking problem's QP of one Gauss-Newton SQP step, stage by stage (the one statement
every real-time back end reads: solvers/real_time_iteration.py solves it sparse or condensed,
export-c generates its C from the same functions).

Around an iterate (X, F) of the multiple-shooting program (ocp/multiple_shooting.py), in
deltas, stage k = 0..N:

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
    obstacles    n . (p(X_{k+1}) + p(dX_{k+1}) - c_o) + s_k >= reach_o,  written at stage k
                 through the linearised dynamics (n: the unit normal from the obstacle)
    cost         the program's cost (Gauss-Newton: its Hessian is exact and constant) plus
                 rho s_k + s_k^2, a tiny Levenberg-Marquardt term on w, and the trust
                 region's on the heading steps dpsi_k, k = 1..N-1 (trust_region_weight)
"""

from __future__ import annotations

from typing import NamedTuple

import casadi as ca

from auvmpc.models.layout import HORIZONTAL
from auvmpc.ocp.multiple_shooting import (
    DISTANCE_SMOOTHING_M2,
    ND,
    NX,
    SLOT_CENTRE,
    SLOT_FIELDS,
    SLOT_REACH,
    SLOT_VELOCITY,
    MultipleShootingProgram,
)
from auvmpc.ocp.tracking import SLACK_QUADRATIC_WEIGHT, ThrustPenalty
from auvmpc.solvers.hpipm import slack_scale

__all__ = ["StageQp", "stage_qp"]

# Levenberg-Marquardt term on the thrust step w: keeps the stage Hessian definite when R = 0;
# it penalises the step, not the iterate, so the fixed point is unchanged.
_STEP_REGULARISATION = 1e-9
# Obstacle rows are kept for the predicted steps within this distance of the inflated disc
# (m): one SQP step cannot move the plan that far, and a far row would only perturb the
# interior point's solution (by ~1e-7 N).
_OBSTACLE_RANGE_M = 5.0
_HEADING = HORIZONTAL.index("psi")
_POSITION = HORIZONTAL.position


class StageQp(NamedTuple):
    """The sparse QP of one SQP step, stage by stage, in HPIPM's form (Frison and Diehl 2020):

        z_{k+1} = A_k z_k + B_k v_k + b_k
        cost_k  = 1/2 [v; z]' [R S; S' Q] [v; z] + r' v + q' z
        lbu <= v_k <= ubu,   lg <= C_k z_k + D_k v_k <= ug

        lbp <= dp_{k+1} <= ubp   (the thrust part of the next state)

    ``stage`` maps (X_k, X_{k+1}, P_k, P_{k+1}, F_k, r_k, W_k, d, slots, used, movable_k,
    k + 1, e) to (A, B, b, Q, S, R, q, r, C, D, lg, ug, lbu, ubu, lbp, ubp), every matrix dense
    and column-major; ``terminal`` maps (X_N, r_N) to (Q, q) of the last stage. Both are
    expanded SX, so the same functions are evaluated by CasADi or compiled to C. ``e`` is
    the thrusters' effectiveness (n,; 1 healthy, 0 dead), a runtime input like the others:
    the model's thrust acts as ``e * F`` (ActuatorSet.force), so B's thrust columns scale
    with it and a fault rebuilds nothing.
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
    effectiveness = ca.SX.sym("e", n)  # each thruster's share of its command that acts

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
        if ocp.weights_internal_thrust:  # and M(e) the internal thrust (ocp/tracking.py)
            M = ocp.internal_weight(effectiveness)
            Q[NX:, NX:] = 2.0 * M
            S_cross[:n, NX:] = 2.0 * M
            R[:n, :n] += 2.0 * M
            q[NX:] = 2.0 * M @ F
            r[:n] += 2.0 * M @ F

    # Dynamics: dX_{k+1} = A dX_k + B (dp_k + w_k) + gap, dp_{k+1} = dp_k + w_k + (F_k - P_{k+1}).
    # The model's thrust that acts is a = e * F: differentiated in a and evaluated there, B's
    # thrust columns times e (the chain rule; models/discrete.py says why not through e * F).
    acting = ca.SX.sym("a", n)
    successor = program.acting_step(X, acting, force)
    # Both Jacobians from one reverse sweep per successor component (NX), where ca.jacobian
    # takes forward mode, one sweep per input (NX + n): with 7 RK4 substeps (BlueROV2 Heavy)
    # the successor and its Jacobians take 16 331 SX operations against 19 425, and the whole
    # stage 15 521 against 19 935 with its common subexpressions merged (cse below).
    transposed = ca.jtimes(successor, ca.vertcat(X, acting), ca.SX.eye(NX), True)  # (NX + n, NX)
    linearised = ca.Function("rk4_step_transposed", [X, acting, force], [successor, transposed])
    successor, transposed = linearised.call([X, F * effectiveness, force])
    A_x, B_acting = transposed[:NX, :].T, transposed[NX:, :].T
    B_x = B_acting * ca.repmat(effectiveness.T, NX, 1)
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
    inputs = (X, X_next, P, P_next, F, reference, weight, force, slots, used, movable, step_index,
              effectiveness)  # fmt: skip
    stage = ca.Function(
        "rti_stage",
        list(inputs),
        [ca.densify(ca.SX(e)) for e in outputs],
        "X X_next P P_next F ref W d_world slots used movable step e".split(),
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
