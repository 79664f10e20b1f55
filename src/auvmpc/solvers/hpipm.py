"""HPIPM (Frison and Diehl 2020), the Riccati-based interior-point QP solver for stage-wise
(optimal-control) QPs, as shipped inside the casadi wheel: one place for its settings."""

from __future__ import annotations

from collections.abc import Sequence

import casadi as ca

__all__ = [
    "EVALUATION_FAILED",
    "ITERATION_LIMIT",
    "NOT_FINITE",
    "SOLVED",
    "hpipm_settings",
    "hpipm_solver",
    "hpipm_status",
    "slack_scale",
    "solved",
]

# CasADi hands HPIPM every unbounded variable as a box of +-_INFINITY; 1e8 (CasADi's default)
# ruins the interior point's scaling (50 iterations without convergence on paper-obstacles),
# 1e4 converges in ~9. No state delta or thrust bound of a real vehicle comes near it.
_INFINITY = 1e4
# "robust" from mu0 = 1: on a move-blocked QP with obstacle rows (ltv-mpc, 2 moves,
# paper-obstacles, first sample) "speed" failed from every mu0 (1, 1e2, 1e4) and "robust"
# converged in 13 iterations to qrqp's solution within 4e-12; residuals tight enough that the
# first move agrees with IPOPT's to 1e-5 N (tests/test_mpc.py).
_MU0 = 1.0
_TOLERANCE = 1e-8
# enum hpipm_mode (hpipm_common.h): SPEED_ABS, SPEED, BALANCE, ROBUST
_SPEED, _ROBUST = 1.0, 3.0
# HPIPM's warm start: 0 cold, 1 from the primal solution it holds (the previous QP's).
_COLD, _WARM = 0.0, 1.0
# The compiled step's fast pass (hpipm_settings): mode, mu0, tolerance, warm start. The
# tolerance is that of one real-time iteration, which the next sample's iteration corrects.
_FAST_PASS = (_SPEED, 1e2, 1e-4, _WARM)
# Iterations of the fast pass's hot-started try: where the active set barely moves between
# samples one iteration solves the QP; where it moves, a hot start can wander (up to 31
# iterations when uncapped, docs/performance.md), so the fast pass takes over after 3.
_HOT_PASS_LIMIT = 3.0
_OPTIONS = {
    "mode": "robust",
    "mu0": _MU0,
    "res_g_max": _TOLERANCE,
    "res_b_max": _TOLERANCE,
    "res_d_max": _TOLERANCE,
    "res_m_max": _TOLERANCE,
}
# Measured: at most 52 iterations on paper-obstacles (a sample where 30 obstacle rows appear);
# 50 made that sample fall back.
ITERATION_LIMIT = 100
# The status codes of a QP step (hpipm_ocp_step.c's, and every step's in
# solvers/real_time_iteration.py): solved, the QP's data not finite, their evaluation failed;
# any other is the solver's own failure code.
SOLVED, NOT_FINITE, EVALUATION_FAILED = 0, -1, -2


def hpipm_solver(
    name: str,
    h_pattern: ca.Sparsity,
    a_pattern: ca.Sparsity,
    stage_states: Sequence[int],
    stage_inputs: Sequence[int],
    stage_rows: Sequence[int],
    iteration_limit: int | None = None,
) -> ca.Function:
    """A CasADi conic for a QP whose variables are ordered [z_0 v_0 z_1 v_1 ... z_N] and
    whose rows are [gaps_0 rows_0 gaps_1 rows_1 ...] (CasADi's HPIPM interface)."""
    horizon = len(stage_states) - 1
    options = {
        "N": horizon,
        "nx": list(stage_states),
        "nu": list(stage_inputs),
        "ng": list(stage_rows),
        "inf": _INFINITY,
        "error_on_fail": False,
        "hpipm": {**_OPTIONS, "iter_max": iteration_limit or ITERATION_LIMIT},
    }
    return ca.conic(name, "hpipm", {"h": h_pattern, "a": a_pattern}, options)


def hpipm_settings(
    iteration_limit: int | None = None, robust_only: bool = False
) -> tuple[float, ...]:
    """Settings of the compiled HPIPM driver (solvers/hpipm_ocp_step.c): the bound standing
    for infinity, the number of passes, then per pass the mode, iteration limit, mu0,
    tolerance, warm start and the iterations of a hot-started try before the pass.

    The fast pass is HPIPM's ``speed`` mode from mu0 = 1e2 to residuals of 1e-4, started from
    the controller's previous QP solution (_FAST_PASS); the robust one, only on a failure of
    the first, ``robust`` from a cold start to 1e-8, as everywhere else. For the first QP of a
    sample (the caller's ``hot_start``) the fast pass first tries at most _HOT_PASS_LIMIT
    iterations hot-started from that solution's primal and dual parts, and, where they do not
    solve the QP, starts as it would have without them. Not for a sample's later SQP steps,
    whose QPs' solutions shrink towards zero: a held solution within the tolerance of the next
    one would be taken again (tried: with the try on every SQP step, the cold start's 10
    steps stopped 2.1e-6 N from the NLP's optimum, against 4.6e-8 N without;
    tests/test_nmpc.py).

    Measured on the exported step (docs/performance.md): the hot try takes the BlueROV2
    lawnmower's median step from 2 interior-point iterations to 1 (4.06 M -> 2.74 M
    instructions) and costs ``paper-obstacles`` 6 % (its median stays at 2). The fast pass
    alone was 1 iteration at the median on ``paper-ideal`` and 2 on ``paper-obstacles``,
    against 4 and 5 for ``speed`` from a cold start to 1e-8, its thrust step 2e-5 N from the
    1e-8 one at the median (at most 0.03 N, on a transient) and the runs' RMS errors within
    0.02 %. ``speed_abs``, which stops on the duality measure alone, was 20 % faster but up to
    10 % off the exact step on perturbed QPs (tests/test_compiled_qp_step.py), against 1.4 %
    for ``speed``. ``robust_only``: the robust pass alone (the QP solved to 1e-8 every time).
    """
    limit = float(iteration_limit or ITERATION_LIMIT)
    robust = (_ROBUST, limit, _MU0, _TOLERANCE, _COLD, 0.0)
    if robust_only:
        return (_INFINITY, 1.0, *robust)
    fast = (_FAST_PASS[0], limit, *_FAST_PASS[1:], min(_HOT_PASS_LIMIT, limit))
    return (_INFINITY, 2.0, *fast, *robust)


def slack_scale(penalty: float) -> float:
    """The factor sigma by which an exact-penalty slack enters the QP (the variable is sigma s).

    With s itself the multiplier of s >= 0 is ~penalty (1e5) while its rows are inactive and
    the interior point needed 40-100 iterations, failing with move blocking, once obstacle
    rows were present. With sigma = penalty every multiplier is O(1), but CasADi bounds every
    variable by +-1e4 (_INFINITY), which then caps the slack at 0.1 m: a start inside a
    keep-out disc became infeasible. sqrt(penalty) balances both: multipliers ~316 and room
    for 30 m of slack at the default penalty.
    """
    return penalty**0.5


def solved(stats: dict) -> bool:
    """Whether HPIPM's last solve converged (return status 0)."""
    return stats["return_status"] == SOLVED


def hpipm_status(code: int) -> str:
    """The log's words for a QP step's status code from HPIPM."""
    return "QP data evaluation failed" if code == EVALUATION_FAILED else f"hpipm {code}"
