/* auvmpc's depth MPC in C: the Python DepthMpc (controllers/depth_mpc.py) with the incremental
 * MPC loop it runs (controllers/incremental.py), its condensed QP (solvers/condensed_qp.py)
 * solved by DAQP as in Python (solvers/dense_qp.py), its filter (estimation/ekf.py,
 * AugmentedEkf) and its safety shell with the depth feedback (controllers/shell.py,
 * controllers/recovery.py), step for step, so that it reproduces the Python commands.
 *
 * Generated per scenario (auvmpc export-c): depth_data.c, CasADi's code of the functions the
 * Python evaluates (the model's rollout with its Jacobians, the filter's update and
 * propagation), and auvmpc_depth_config.h (sizes, weights, limits, the QP's constant blocks,
 * the soft rows). DAQP is casadi's build (lib/TARGET/libdaqp.so). Static memory, but for
 * DAQP's workspace, allocated once by auvmpc_depth_init.
 */
#include "auvmpc_depth.h"

#include <math.h>
#include <string.h>

#include "auvmpc_covariance.h"
#include "daqp/api.h"
#include "daqp/auxiliary.h"
#include "daqp/utils.h"
#include "depth_data.h"

#define DNX AUVMPC_DEPTH_NX /* [z, w]; DAQP has its own NX */
#define NA AUVMPC_DEPTH_NA /* the filter's [z, w, d_z] */
#define N AUVMPC_DEPTH_HORIZON
#define NU AUVMPC_DEPTH_THRUSTERS
#define NC AUVMPC_DEPTH_MOVE_COUNT
#define NM AUVMPC_DEPTH_MOVES /* NU * NC */
#define NS AUVMPC_DEPTH_SOFT_ROWS
#define NZ (NM + NS)          /* the QP's variables: the moves, one slack per soft row */
#define NR (NC * NU + NS)     /* its rows: the force limits at the move steps, the soft rows */
#define Z AUVMPC_DEPTH_Z
#define W AUVMPC_DEPTH_W

static const int move_steps[NC] = AUVMPC_DEPTH_MOVE_STEPS;
static const double thrust_lower[NU] = AUVMPC_DEPTH_THRUST_LOWER;
static const double thrust_upper[NU] = AUVMPC_DEPTH_THRUST_UPPER;
static const double thrust_rate[NU] = AUVMPC_DEPTH_THRUST_RATE;
static const double max_move[NU] = AUVMPC_DEPTH_MAX_MOVE;
static const double input_lower[NU] = AUVMPC_DEPTH_INPUT_LOWER;
static const double input_upper[NU] = AUVMPC_DEPTH_INPUT_UPPER;
static const double sqrt_weights[N][DNX] = AUVMPC_DEPTH_SQRT_WEIGHTS;
static const double input_hessian[NM][NM] = AUVMPC_DEPTH_INPUT_HESSIAN;
static const double input_gradient_map[NM][NU] = AUVMPC_DEPTH_INPUT_GRADIENT_MAP;
static const int soft_steps[NS] = AUVMPC_DEPTH_SOFT_STEPS;
static const double soft_coefficients[NS][DNX] = AUVMPC_DEPTH_SOFT_COEFFICIENTS;
static const double soft_lower[NS] = AUVMPC_DEPTH_SOFT_LOWER;
static const double prior_covariance[NA][NA] = AUVMPC_DEPTH_PRIOR_COVARIANCE;

typedef int (*casadi_function)(const casadi_real **, casadi_real **, casadi_int *, casadi_real *,
                               int);

/* Everything the depth controller holds (sizes from auvmpc_depth_config.h). */
typedef struct {
    int ready;                   /* DAQP's workspace is set up */
    int warm;                    /* the last solve succeeded: its working set starts the next */
    /* the shell (ShelledController) */
    double previous[NU];         /* the last applied command */
    double plan[N][NU];          /* what a fallback follows, and the next warm start */
    int has_plan;
    int unsolved;                /* samples in a row without an applied proposal */
    double effectiveness[NU];
    /* the back end (IncrementalMpc) */
    int has_predicted;           /* the last applied plan's states exist (a retry is worth it) */
    double proposed[N + 1][DNX];  /* this sample's predicted states */
    /* the filter (AugmentedEkf) */
    double estimate[NA], covariance[NA][NA];
    int initialised;
    /* one sample */
    double state[DNX], disturbance;
    double reference[N + 1][DNX];
    double moves[NM];
    double input[N][NU];         /* the plan the model is linearised along */
    double rollout[N][DNX], jac_x[N][DNX][DNX], jac_u[N][NU][DNX]; /* column-major blocks */
    double A[N][DNX][DNX], B[N][DNX][NU], c[N][DNX];
    double forcing[N][DNX][NM + 1];
    double stacked[N + 1][DNX][NM + 1];  /* [sensitivity | free response] */
    double predicted[N + 1][DNX];
    double weighted[N * DNX][NM], error[N * DNX];
    /* the QP as DAQP reads it: row-major, simple bounds first */
    double H[NZ][NZ], f[NZ], rows[NR][NZ], upper[NZ + NR], lower[NZ + NR];
    int sense[NZ + NR];
    double x[NZ], lam[NZ + NR];
    DAQPProblem qp;
    DAQPSettings settings;
    DAQPWorkspace work;
    int iterations;
    double max_slack;
    /* the generated functions' work */
    const casadi_real *arg[AUVMPC_DEPTH_SZ_ARG + 1];
    casadi_real *res[AUVMPC_DEPTH_SZ_RES + 1];
    casadi_int iw[AUVMPC_DEPTH_SZ_IW + 1];
    casadi_real w[AUVMPC_DEPTH_SZ_W + 1];
} Depth;

static Depth depth;

static int all_finite(const double *v, int size) {
    for (int i = 0; i < size; ++i)
        if (!isfinite(v[i])) return 0;
    return 1;
}

/* -- the filter on [z, w, d_z] (AugmentedEkf, depth measured) -- */

static void filter_reset(Depth *d, double z) {
    for (int i = 0; i < NA; ++i) {
        d->estimate[i] = i == Z ? z : 0.0;
        for (int j = 0; j < NA; ++j) d->covariance[i][j] = prior_covariance[i][j];
    }
    d->initialised = 0;
}

/* A generated filter function on (estimate, covariance, x[, effectiveness]) into z_out,
 * P_out (column-major; the covariance is symmetric, so its rows are its columns). */
static int filter_call(Depth *d, casadi_function function, const double *x, double *z_out,
                       double *P_out) {
    d->arg[0] = d->estimate;
    d->arg[1] = d->covariance[0];
    d->arg[2] = x;
    d->arg[3] = d->effectiveness;
    d->res[0] = z_out;
    d->res[1] = P_out;
    return function(d->arg, d->res, d->iw, d->w, 0);
}

static void filter_correct(Depth *d, double z) {
    double innovation, corrected[NA], joseph[NA * NA];
    if (!d->initialised) {
        d->estimate[Z] = z;
        d->initialised = 1;
    }
    innovation = z - d->estimate[Z];
    filter_call(d, depth_ekf_update, &innovation, corrected, joseph);
    memcpy(d->estimate, corrected, sizeof corrected);
    auvmpc_condition_covariance(NA, joseph, AUVMPC_DEPTH_COVARIANCE_FLOOR,
                                AUVMPC_DEPTH_COVARIANCE_CEILING, d->covariance[0]);
}

/* A non-finite prediction restarts the filter from its prior, keeping the finite unmeasured
 * estimate (AugmentedEkf.predict). */
static void filter_predict(Depth *d, const double *thrust) {
    double next[NA], propagated[NA * NA];
    int failed = filter_call(d, depth_ekf_propagation, thrust, next, propagated);
    if (failed || !all_finite(next, NA) || !all_finite(propagated, NA * NA)) {
        double kept[NA];
        for (int i = 0; i < NA; ++i)
            kept[i] = i == Z || !isfinite(d->estimate[i]) ? 0.0 : d->estimate[i];
        filter_reset(d, 0.0);
        memcpy(d->estimate, kept, sizeof kept);
        return;
    }
    memcpy(d->estimate, next, sizeof next);
    auvmpc_condition_covariance(NA, propagated, AUVMPC_DEPTH_COVARIANCE_FLOOR,
                                AUVMPC_DEPTH_COVARIANCE_CEILING, d->covariance[0]);
}

/* -- the condensed QP (CondensedQp) -- */

/* Whether move j acts at sample i (CondensedQp.move_to_input: the thrust is the last one
 * plus every move made at or before i). */
static int moved_by(int i, int j) { return move_steps[j] <= i; }

/* The inputs (N x NU) of a move vector (CondensedQp.plan). */
static void plan_of(const double *previous, const double *moves, double input[N][NU]) {
    for (int i = 0; i < N; ++i)
        for (int t = 0; t < NU; ++t) {
            double sum = 0.0;
            for (int j = 0; j < NC; ++j)
                if (moved_by(i, j)) sum += moves[j * NU + t];
            input[i][t] = previous[t] + sum;
        }
}

/* The moves that best reproduce a plan one sample on, each within the rate limit
 * (CondensedQp.shifted_moves); zeros without a plan. */
static void shifted_moves(const Depth *d, int has_plan, double *moves) {
    if (!has_plan) {
        for (int k = 0; k < NM; ++k) moves[k] = 0.0;
        return;
    }
    for (int j = 0; j < NC; ++j) {
        int at = move_steps[j] + 1 < N ? move_steps[j] + 1 : N - 1;
        for (int t = 0; t < NU; ++t) {
            double before = j == 0 ? d->previous[t]
                                   : d->plan[move_steps[j - 1] + 1 < N ? move_steps[j - 1] + 1 : N - 1][t];
            double move = d->plan[at][t] - before;
            moves[j * NU + t] = fmin(fmax(move, -max_move[t]), max_move[t]);
        }
    }
}

/* The affine model along the plan (DepthMpc.prediction_model): the generated rollout gives
 * the states and the one-step Jacobians; c closes the affine form. */
static int linearise(Depth *d) {
    d->arg[0] = d->state;
    d->arg[1] = d->input[0];
    d->arg[2] = &d->disturbance;
    d->arg[3] = d->effectiveness;
    d->res[0] = d->rollout[0];
    d->res[1] = d->jac_x[0][0];
    d->res[2] = d->jac_u[0][0];
    if (depth_rollout(d->arg, d->res, d->iw, d->w, 0)) return -1;
    for (int n = 0; n < N; ++n) {
        const double *from = n == 0 ? d->state : d->rollout[n - 1];
        for (int i = 0; i < DNX; ++i) {
            for (int j = 0; j < DNX; ++j) d->A[n][i][j] = d->jac_x[n][j][i];
            for (int t = 0; t < NU; ++t) d->B[n][i][t] = d->jac_u[n][t][i];
            double Ax = 0.0, Bu = 0.0;
            for (int j = 0; j < DNX; ++j) Ax += d->A[n][i][j] * from[j];
            for (int t = 0; t < NU; ++t) Bu += d->B[n][i][t] * d->input[n][t];
            d->c[n][i] = d->rollout[n][i] - Ax - Bu;
        }
    }
    return 0;
}

/* The free response and the sensitivity to the moves, stacked as [S_n | x_free_n] and
 * advanced through the A_n together (CondensedQp.condense). */
static void condense(Depth *d) {
    for (int n = 0; n < N; ++n)
        for (int i = 0; i < DNX; ++i) {
            for (int k = 0; k < NM; ++k) {
                int j = k / NU, t = k % NU;
                d->forcing[n][i][k] = moved_by(n, j) ? d->B[n][i][t] : 0.0;
            }
            double Bp = 0.0;
            for (int t = 0; t < NU; ++t) Bp += d->B[n][i][t] * d->previous[t];
            d->forcing[n][i][NM] = Bp + d->c[n][i];
        }
    memset(d->stacked[0], 0, sizeof d->stacked[0]);
    for (int i = 0; i < DNX; ++i) d->stacked[0][i][NM] = d->state[i];
    for (int n = 0; n < N; ++n)
        for (int i = 0; i < DNX; ++i)
            for (int k = 0; k <= NM; ++k) {
                double sum = 0.0;
                for (int j = 0; j < DNX; ++j) sum += d->A[n][i][j] * d->stacked[n][j][k];
                d->stacked[n + 1][i][k] = sum + d->forcing[n][i][k];
            }
}

/* The QP in [moves, slacks] (CondensedQp.problem, soft_constrained_qp), with DAQP's bounds
 * (DaqpSolver._bounds): its infinity for an unbounded side. 0 when it is well posed (no
 * non-finite data, no empty interval: DenseQp's _data_defect). */
static int fill_qp(Depth *d) {
    for (int n = 1; n <= N; ++n)
        for (int i = 0; i < DNX; ++i) {
            int r = (n - 1) * DNX + i;
            for (int k = 0; k < NM; ++k) d->weighted[r][k] = d->stacked[n][i][k] * sqrt_weights[n - 1][i];
            d->error[r] = (d->stacked[n][i][NM] - d->reference[n][i]) * sqrt_weights[n - 1][i];
        }
    memset(d->H, 0, sizeof d->H);
    memset(d->f, 0, sizeof d->f);
    for (int k = 0; k < NM; ++k) {
        for (int l = k; l < NM; ++l) { /* symmetric: the upper triangle, mirrored */
            double sum = 0.0;
            for (int r = 0; r < N * DNX; ++r) sum += 2.0 * d->weighted[r][k] * d->weighted[r][l];
            d->H[k][l] = sum + input_hessian[k][l];
            d->H[l][k] = sum + input_hessian[l][k];
        }
        d->H[k][k] += AUVMPC_DEPTH_HESSIAN_REGULARISATION;
        double gradient = 0.0, mapped = 0.0;
        for (int r = 0; r < N * DNX; ++r) gradient += 2.0 * d->weighted[r][k] * d->error[r];
        for (int t = 0; t < NU; ++t) mapped += input_gradient_map[k][t] * d->previous[t];
        d->f[k] = gradient + mapped;
    }
    for (int s = 0; s < NS; ++s) {
        d->H[NM + s][NM + s] = AUVMPC_DEPTH_SLACK_HESSIAN;
        d->f[NM + s] = AUVMPC_DEPTH_SLACK_PENALTY;
    }
    /* bounds: every move within the rate limit, every slack >= 0 */
    for (int k = 0; k < NM; ++k) {
        d->lower[k] = -max_move[k % NU];
        d->upper[k] = max_move[k % NU];
    }
    for (int s = 0; s < NS; ++s) {
        d->lower[NM + s] = 0.0;
        d->upper[NM + s] = AUVMPC_DEPTH_QP_INFINITY;
    }
    /* rows: the force limits where the thrust changes, then the soft rows with their slack */
    memset(d->rows, 0, sizeof d->rows);
    for (int j = 0; j < NC; ++j)
        for (int t = 0; t < NU; ++t) {
            int r = j * NU + t;
            for (int m = 0; m < NC; ++m)
                if (moved_by(move_steps[j], m)) d->rows[r][m * NU + t] = 1.0;
            d->lower[NZ + r] = input_lower[t] - d->previous[t];
            d->upper[NZ + r] = input_upper[t] - d->previous[t];
        }
    for (int s = 0; s < NS; ++s) {
        int r = NC * NU + s, n = soft_steps[s];
        double offset = 0.0;
        for (int k = 0; k < NM; ++k) {
            double sum = 0.0;
            for (int i = 0; i < DNX; ++i) sum += soft_coefficients[s][i] * d->stacked[n][i][k];
            d->rows[r][k] = sum;
        }
        for (int i = 0; i < DNX; ++i) offset += soft_coefficients[s][i] * d->stacked[n][i][NM];
        d->rows[r][NM + s] = 1.0;
        d->lower[NZ + r] = soft_lower[s] - offset;
        d->upper[NZ + r] = AUVMPC_DEPTH_QP_INFINITY;
    }
    if (!all_finite(d->H[0], NZ * NZ) || !all_finite(d->f, NZ) || !all_finite(d->rows[0], NR * NZ))
        return -1;
    for (int i = 0; i < NZ + NR; ++i) {
        if (isnan(d->lower[i]) || isnan(d->upper[i]) || d->lower[i] > d->upper[i]) return -1;
        d->upper[i] = fmin(d->upper[i], AUVMPC_DEPTH_QP_INFINITY);
        d->lower[i] = fmax(d->lower[i], -AUVMPC_DEPTH_QP_INFINITY);
    }
    return 0;
}

/* The working set the next solve starts from (DaqpSolver: the last solve's, as the Python
 * DAQP keeps it): marked active in the problem's sense, which update_ldp copies into DAQP's.
 * Cold (after a failure, and at the first solve): the slacks at zero, where the Python's first
 * setup starts them. */
static void mark_start(Depth *d) {
    memset(d->sense, 0, sizeof d->sense);
    if (d->warm) {
        for (int i = 0; i < d->work.n_active; ++i) {
            int c = d->work.WS[i];
            d->sense[c] = ACTIVE + (d->work.sense[c] & LOWER);
        }
    } else {
        for (int s = 0; s < NS; ++s) d->sense[NM + s] = ACTIVE + LOWER;
    }
}

/* DAQP on the QP filled in, from the last working set (the solution does not depend on it, the
 * optimum being unique; the iterations do). 0 when optimal. */
static int daqp_on_qp(Depth *d) {
    mark_start(d);
    d->warm = 0; /* until this solve succeeds */
    if (update_ldp(UPDATE_Rinv + UPDATE_M + UPDATE_v + UPDATE_d + UPDATE_sense, &d->work) < 0)
        return -1;
    reset_daqp_workspace(&d->work);
    if (activate_constraints(&d->work) < 0) { /* dependent rows: from an empty set instead */
        reset_daqp_workspace(&d->work);
        for (int i = 0; i < NZ + NR; ++i) d->work.sense[i] = 0;
    }
    /* daqp_solve without its timer: the algorithm it runs for a plain QP */
    int flag = daqp_ldp(&d->work);
    d->iterations += d->work.iterations;
    if (flag != EXIT_OPTIMAL) return -1;
    ldp2qp_solution(&d->work);
    memcpy(d->x, d->work.x, sizeof d->x);
    d->warm = all_finite(d->x, NZ);
    return d->warm ? 0 : -1;
}

/* The linearise-and-solve passes from the moves d->moves (IncrementalMpc._solve); the
 * solution's moves, predicted states and largest slack. 0 on success. */
static int solve(Depth *d) {
    d->max_slack = 0.0;
    for (int pass = 0; pass < AUVMPC_DEPTH_PASSES; ++pass) {
        plan_of(d->previous, d->moves, d->input);
        if (linearise(d)) return -1;
        condense(d);
        if (fill_qp(d) || daqp_on_qp(d)) return -1;
        memcpy(d->moves, d->x, sizeof d->moves);
        d->max_slack = 0.0;
        for (int s = 0; s < NS; ++s) d->max_slack = fmax(d->max_slack, d->x[NM + s]);
        for (int n = 0; n <= N; ++n)
            for (int i = 0; i < DNX; ++i) {
                double sum = 0.0;
                for (int k = 0; k < NM; ++k) sum += d->stacked[n][i][k] * d->moves[k];
                d->predicted[n][i] = d->stacked[n][i][NM] + sum;
            }
    }
    return 0;
}

/* The back end's proposal (IncrementalMpc.propose): the filter's estimate, then the solve
 * from the shifted plan and, where that fails after an applied plan, from rest. */
static int propose(Depth *d, const double *measured, const double *reference) {
    filter_correct(d, measured[Z]);
    memcpy(d->state, d->estimate, sizeof d->state);
    d->disturbance = d->estimate[DNX];
    memcpy(d->reference, reference, sizeof d->reference);
    shifted_moves(d, d->has_plan, d->moves);
    int failed = solve(d);
    if (failed && d->has_predicted) {
        d->has_predicted = 0;
        shifted_moves(d, 0, d->moves);
        failed = solve(d);
    }
    if (!failed) {
        memcpy(d->proposed, d->predicted, sizeof d->proposed);
        plan_of(d->previous, d->moves, d->input);
        failed = !all_finite(d->input[0], N * NU);
    }
    return failed ? -1 : 0;
}

/* The shell's recovery for depth (DepthFeedback.command): a critically damped PD through the
 * nominal heave model on the filter's estimate, shared in proportion to the effectiveness. */
static void recover(const Depth *d, double *thrust) {
    double z = d->state[Z], w = d->state[W];
    double wn = AUVMPC_DEPTH_FEEDBACK_BANDWIDTH;
    double acceleration = wn * wn * (d->reference[0][Z] - z) + 2.0 * wn * (d->reference[0][W] - w);
    double drag = AUVMPC_DEPTH_ZW * w + AUVMPC_DEPTH_ZWW * fabs(w) * w;
    double force = AUVMPC_DEPTH_MASS * acceleration - drag - AUVMPC_DEPTH_NET_BUOYANCY
                   - d->disturbance;
    double acting = 0.0;
    for (int t = 0; t < NU; ++t) acting += d->effectiveness[t] * d->effectiveness[t];
    for (int t = 0; t < NU; ++t)
        thrust[t] = acting == 0.0 ? 0.0 : (force / acting) * d->effectiveness[t];
}

int auvmpc_depth_init(const double initial_state[DNX]) {
    Depth *d = &depth;
    if (!d->ready) {
        if (AUVMPC_DEPTH_SZ_ARG < depth_rollout_n_in() || AUVMPC_DEPTH_SZ_RES < depth_rollout_n_out())
            return -1;
        d->qp = (DAQPProblem){NZ, NZ + NR, NZ, d->H[0], d->f, d->rows[0], d->upper, d->lower,
                              d->sense};
        daqp_default_settings(&d->settings);
        d->settings.primal_tol = AUVMPC_DEPTH_PRIMAL_TOL;
        d->settings.iter_limit = AUVMPC_DEPTH_ITERATION_LIMIT;
        /* a well-posed QP of the right size to set DAQP up on: the constant Hessian blocks,
         * all bounds open; every step replaces all of it */
        for (int k = 0; k < NZ; ++k) d->H[k][k] = 1.0;
        for (int i = 0; i < NZ + NR; ++i) {
            d->upper[i] = AUVMPC_DEPTH_QP_INFINITY;
            d->lower[i] = -AUVMPC_DEPTH_QP_INFINITY;
        }
        d->work.settings = &d->settings;
        if (setup_daqp(&d->qp, &d->work, NULL) < 0) return -1;
        d->ready = 1;
    }
    for (int t = 0; t < NU; ++t) d->effectiveness[t] = 1.0;
    auvmpc_depth_reset(initial_state);
    return 0;
}

void auvmpc_depth_reset(const double initial_state[DNX]) {
    Depth *d = &depth;
    for (int t = 0; t < NU; ++t) d->previous[t] = 0.0;
    d->has_plan = 0;
    d->unsolved = 0;
    d->has_predicted = 0;
    filter_reset(d, initial_state[Z]);
}

int auvmpc_depth_set_effectiveness(const double effectiveness[NU]) {
    for (int t = 0; t < NU; ++t)
        if (!(effectiveness[t] >= 0.0 && effectiveness[t] <= 1.0)) return -1;
    memcpy(depth.effectiveness, effectiveness, sizeof depth.effectiveness);
    return 0;
}

auvmpc_status auvmpc_depth_step(const double measured[DNX], const double reference[(N + 1) * DNX],
                                double command[NU]) {
    Depth *d = &depth;
    double wanted[NU];
    d->iterations = 0;
    int solved = d->ready && !propose(d, measured, reference);
    int fell_back = !solved, recovered = 0;
    if (solved) {
        memcpy(wanted, d->input[0], sizeof wanted);
        memcpy(d->plan, d->input, sizeof d->plan);
        d->has_plan = 1;
        d->unsolved = 0;
    } else {
        ++d->unsolved;
        /* the plan for at most AUVMPC_DEPTH_FALLBACK_STEPS samples, then the feedback */
        recovered = d->ready && (!d->has_plan || d->unsolved > AUVMPC_DEPTH_FALLBACK_STEPS);
        if (recovered) {
            recover(d, wanted);
            if (!all_finite(wanted, NU)) memcpy(wanted, d->previous, sizeof wanted);
            d->has_plan = 0;
        } else if (d->has_plan && N > 1) { /* the previous plan's next move, shifted on */
            memcpy(wanted, d->plan[1], sizeof wanted);
            memmove(d->plan[0], d->plan[1], sizeof(double) * (N - 1) * NU);
        } else {
            memcpy(wanted, d->previous, sizeof wanted);
        }
    }
    /* the projection into the force and rate box (ActuatorLimits.project) */
    int saturated = 0;
    for (int t = 0; t < NU; ++t) {
        double step = thrust_rate[t] * AUVMPC_DEPTH_SAMPLE_TIME;
        double lower = fmax(thrust_lower[t], d->previous[t] - step);
        double upper = fmin(thrust_upper[t], d->previous[t] + step);
        if (lower > upper) { /* a previous command outside the force box: the rate wins */
            double inside = fmin(fmax(d->previous[t], thrust_lower[t]), thrust_upper[t]);
            lower = upper = fmin(fmax(inside, d->previous[t] - step), d->previous[t] + step);
        }
        command[t] = fmin(fmax(wanted[t], lower), upper);
        if (fabs(command[t] - wanted[t]) > AUVMPC_DEPTH_SATURATION_N) saturated = 1;
    }
    memcpy(d->previous, command, sizeof d->previous);
    d->has_predicted = !fell_back; /* after a fallback the next sample linearises afresh */
    filter_predict(d, command);
    if (recovered) return AUVMPC_RECOVERY;
    if (fell_back) return AUVMPC_FALLBACK;
    if (d->max_slack > AUVMPC_DEPTH_SLACK_ACTIVE) return AUVMPC_RELAXED;
    return saturated ? AUVMPC_SATURATED : AUVMPC_OK;
}

int auvmpc_depth_last_iterations(void) { return depth.iterations; }

long auvmpc_depth_static_bytes(void) { return (long) sizeof depth; }
