/* One sparse QP step of auvmpc's real-time iteration, in one call from Python.
 *
 * The stage data come from CasADi-generated code (rti_stage, rti_terminal: see
 * solvers/sparse_rti.py, StageQp, for the QP); HPIPM, linked from the casadi wheel, solves the
 * QP. Everything HPIPM needs is allocated once per controller (auvmpc_rti_create): through
 * CasADi's interface the QP's set-up and memory were allocated and freed on every call, about
 * five times the cost of the interior point itself.
 *
 * Memory layout of the arguments (row-major, one stage per row): X (N+1, 6) the iterate's
 * states, P (N+1, n) the thrust before each step, F (N, n) the thrust, ref (N+1, 6) the
 * reference, W (N, 6) the stage weights, d (3), slots (S, 5), used (S), movable (N).
 * Results: dz (N+1, nz), dv (N, nv), the step of [dX; dp] and [dF; sigma s].
 *
 * The QP is solved by up to two interior-point passes: HPIPM's fast "speed" mode, then, only
 * if that fails, its "robust" mode (solvers/hpipm.py, hpipm_settings, says why).
 */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include <hpipm_common.h>
#include <hpipm_d_ocp_qp.h>
#include <hpipm_d_ocp_qp_dim.h>
#include <hpipm_d_ocp_qp_ipm.h>
#include <hpipm_d_ocp_qp_sol.h>

#include "rti_qp_data.h"

#define NX 6
#define N_STAGE_OUT 14
#define NOT_FINITE (-1)
#define EVALUATION_FAILED (-2)
#define MAX_PASSES 2
#define SETTINGS_PER_PASS 4

enum { OUT_A, OUT_B, OUT_b, OUT_Q, OUT_S, OUT_R, OUT_q, OUT_r, OUT_C, OUT_D, OUT_lg, OUT_ug,
       OUT_lbu, OUT_ubu };

typedef struct {
    int N, n, S, nz, nv, ng;
    double inf;
    struct d_ocp_qp_dim dim;
    struct d_ocp_qp qp;
    struct d_ocp_qp_sol sol;
    int passes; /* interior-point settings tried in turn until one solves */
    struct d_ocp_qp_ipm_arg arg[MAX_PASSES];
    struct d_ocp_qp_ipm_ws ws[MAX_PASSES];
    void *hpipm_memory[3 + 2 * MAX_PASSES];
    double *out[N_STAGE_OUT]; /* one stage's data, reused for every stage */
    int out_size[N_STAGE_OUT];
    double *fixed; /* z_0 = [x_hat - X_0; F_prev - P_0] */
    int *index;   /* 0, 1, ..., max(nz, nv) - 1: every bound is on every variable */
    const casadi_real **arg_work;
    casadi_real **res_work;
    casadi_int *iw;
    casadi_real *w;
} Step;

static void *allocate(void **slot, hpipm_size_t size) {
    *slot = calloc(1, size);
    return *slot;
}

void auvmpc_rti_free(void *handle) {
    Step *s = (Step *) handle;
    if (!s) return;
    for (int i = 0; i < 3 + 2 * MAX_PASSES; ++i) free(s->hpipm_memory[i]);
    for (int i = 0; i < N_STAGE_OUT; ++i) free(s->out[i]);
    free(s->fixed);
    free(s->index);
    free(s->arg_work);
    free(s->res_work);
    free(s->iw);
    free(s->w);
    free(s);
}

/* Whether a generated output holds `size` values, all of them: CasADi's compressed sparsity
 * is [rows, columns, 1] for a dense matrix, else [rows, columns, column offsets, rows...]. */
static int dense_of_size(const casadi_int *sp, int size) {
    casadi_int nonzeros = sp[2] == 1 ? sp[0] * sp[1] : sp[2 + sp[1]];
    return sp[0] * sp[1] == size && nonzeros == size;
}

/* Whether the generated stage functions have the sizes the caller gave. */
static int sizes_agree(int nz, int nv, int ng) {
    const int expected[N_STAGE_OUT] = {nz * nz, nz * nv, nz, nz * nz, nv * nz, nv * nv, nz, nv,
                                       ng * nz, ng * nv, ng, ng, nv, nv};
    for (int i = 0; i < N_STAGE_OUT; ++i)
        if (!dense_of_size(rti_stage_sparsity_out(i), expected[i])) return 0;
    return dense_of_size(rti_terminal_sparsity_out(0), nz * nz)
           && dense_of_size(rti_terminal_sparsity_out(1), nz);
}

/* Sizes: horizon N, thrusters n, obstacle slots S, and the stage QP's nz, nv, ng (checked
 * against the generated functions). settings (count values): the bound standing for
 * infinity, the number of passes, then per pass HPIPM's mode, iteration limit, mu0 and
 * tolerance (stationarity, equality, inequality, complementarity). NULL when memory runs
 * out or the sizes or settings disagree. */
void *auvmpc_rti_create(int N, int n, int S, int nz, int nv, int ng, const double *settings,
                        int count) {
    if (nz != NX + n || count < 2 || !sizes_agree(nz, nv, ng)) return NULL;
    int passes = (int) settings[1];
    if (passes < 1 || passes > MAX_PASSES || count < 2 + SETTINGS_PER_PASS * passes) return NULL;
    Step *s = (Step *) calloc(1, sizeof(Step));
    if (!s) return NULL;
    s->N = N;
    s->n = n;
    s->S = S;
    s->nz = nz;
    s->nv = nv;
    s->ng = ng;
    s->inf = settings[0];
    s->passes = passes;

    int *nx = calloc(N + 1, sizeof(int)), *nu = calloc(N + 1, sizeof(int));
    int *nbx = calloc(N + 1, sizeof(int)), *nbu = calloc(N + 1, sizeof(int));
    int *rows = calloc(N + 1, sizeof(int)), *ns = calloc(N + 1, sizeof(int));
    int ok = nx && nu && nbx && nbu && rows && ns;
    if (ok) {
        for (int k = 0; k <= N; ++k) {
            nx[k] = s->nz;
            nu[k] = k < N ? s->nv : 0;
            nbu[k] = nu[k];
            rows[k] = k < N ? s->ng : 0;
        }
        nbx[0] = s->nz; /* z_0 fixed by its bounds */
        ok = allocate(&s->hpipm_memory[0], d_ocp_qp_dim_memsize(N)) != NULL;
    }
    if (ok) {
        d_ocp_qp_dim_create(N, &s->dim, s->hpipm_memory[0]);
        d_ocp_qp_dim_set_all(nx, nu, nbx, nbu, rows, ns, &s->dim);
        ok = allocate(&s->hpipm_memory[1], d_ocp_qp_memsize(&s->dim))
             && allocate(&s->hpipm_memory[2], d_ocp_qp_sol_memsize(&s->dim));
    }
    free(nx); free(nu); free(nbx); free(nbu); free(rows); free(ns);
    if (!ok) {
        auvmpc_rti_free(s);
        return NULL;
    }
    d_ocp_qp_create(&s->dim, &s->qp, s->hpipm_memory[1]);
    d_ocp_qp_sol_create(&s->dim, &s->sol, s->hpipm_memory[2]);
    for (int p = 0; p < s->passes; ++p) {
        const double *pass = settings + 2 + SETTINGS_PER_PASS * p;
        struct d_ocp_qp_ipm_arg *arg = &s->arg[p];
        if (!allocate(&s->hpipm_memory[3 + 2 * p], d_ocp_qp_ipm_arg_memsize(&s->dim))) {
            auvmpc_rti_free(s);
            return NULL;
        }
        d_ocp_qp_ipm_arg_create(&s->dim, arg, s->hpipm_memory[3 + 2 * p]);
        d_ocp_qp_ipm_arg_set_default((enum hpipm_mode) (int) pass[0], arg);
        int iteration_limit = (int) pass[1];
        double mu0 = pass[2], tolerance = pass[3];
        d_ocp_qp_ipm_arg_set_iter_max(&iteration_limit, arg);
        d_ocp_qp_ipm_arg_set_mu0(&mu0, arg);
        d_ocp_qp_ipm_arg_set_tol_stat(&tolerance, arg);
        d_ocp_qp_ipm_arg_set_tol_eq(&tolerance, arg);
        d_ocp_qp_ipm_arg_set_tol_ineq(&tolerance, arg);
        d_ocp_qp_ipm_arg_set_tol_comp(&tolerance, arg);
        if (!allocate(&s->hpipm_memory[4 + 2 * p], d_ocp_qp_ipm_ws_memsize(&s->dim, arg))) {
            auvmpc_rti_free(s);
            return NULL;
        }
        d_ocp_qp_ipm_ws_create(&s->dim, arg, &s->ws[p], s->hpipm_memory[4 + 2 * p]);
    }

    for (int i = 0; i < N_STAGE_OUT; ++i) {
        s->out_size[i] = (int) rti_stage_sparsity_out(i)[0] * (int) rti_stage_sparsity_out(i)[1];
        s->out[i] = calloc(s->out_size[i] > 0 ? s->out_size[i] : 1, sizeof(double));
        if (!s->out[i]) ok = 0;
    }
    int width = s->nz > s->nv ? s->nz : s->nv;
    s->fixed = calloc(s->nz, sizeof(double));
    s->index = calloc(width, sizeof(int));
    casadi_int sz_arg, sz_res, sz_iw, sz_w, t_arg, t_res, t_iw, t_w;
    rti_stage_work(&sz_arg, &sz_res, &sz_iw, &sz_w);
    rti_terminal_work(&t_arg, &t_res, &t_iw, &t_w);
    if (t_arg > sz_arg) sz_arg = t_arg;
    if (t_res > sz_res) sz_res = t_res;
    if (t_iw > sz_iw) sz_iw = t_iw;
    if (t_w > sz_w) sz_w = t_w;
    s->arg_work = calloc(sz_arg + 1, sizeof(casadi_real *));
    s->res_work = calloc(sz_res + 1, sizeof(casadi_real *));
    s->iw = calloc(sz_iw + 1, sizeof(casadi_int));
    s->w = calloc(sz_w + 1, sizeof(casadi_real));
    if (!ok || !s->fixed || !s->index || !s->arg_work || !s->res_work || !s->iw || !s->w) {
        auvmpc_rti_free(s);
        return NULL;
    }
    for (int i = 0; i < width; ++i) s->index[i] = i;
    d_ocp_qp_set_idxbx(0, s->index, &s->qp);
    for (int k = 0; k < N; ++k) d_ocp_qp_set_idxbu(k, s->index, &s->qp);
    return s;
}

static int all_finite(const double *v, int size) {
    for (int i = 0; i < size; ++i)
        if (!isfinite(v[i])) return 0;
    return 1;
}

/* Bounds of +-inf (no bound) become +-s->inf, as CasADi's HPIPM interface does; NaN is kept
 * (and refused by the caller). */
static void clip(double *v, int size, double inf) {
    for (int i = 0; i < size; ++i) {
        if (v[i] > inf) v[i] = inf;
        if (v[i] < -inf) v[i] = -inf;
    }
}

static int has_nan(const double *v, int size) {
    for (int i = 0; i < size; ++i)
        if (v[i] != v[i]) return 1;
    return 0;
}

/* The HPIPM status (0: solved), NOT_FINITE when the QP data are not finite,
 * EVALUATION_FAILED when the generated functions report an error. */
int auvmpc_rti_step(void *handle, const double *X, const double *P, const double *F,
                    const double *x_hat, const double *F_prev, const double *ref,
                    const double *W, const double *d, const double *slots, const double *used,
                    const double *movable, double *dz, double *dv, int *iterations) {
    Step *s = (Step *) handle;
    const int N = s->N, n = s->n, nz = s->nz, nv = s->nv;
    *iterations = 0;
    for (int k = 0; k < N; ++k) {
        double step_index = k + 1;
        const casadi_real *in[12] = {X + NX * k, X + NX * (k + 1), P + n * k, P + n * (k + 1),
                                     F + n * k, ref + NX * k, W + NX * k, d, slots, used,
                                     movable + k, &step_index};
        memcpy(s->arg_work, in, sizeof(in));
        memcpy(s->res_work, s->out, sizeof(s->out));
        if (rti_stage(s->arg_work, s->res_work, s->iw, s->w, 0)) return EVALUATION_FAILED;
        /* The gaps and gradients go non-finite first on a diverged iterate. */
        if (!all_finite(s->out[OUT_b], s->out_size[OUT_b]) || !all_finite(s->out[OUT_q], nz)
            || !all_finite(s->out[OUT_r], nv))
            return NOT_FINITE;
        for (int i = 0; i < N_STAGE_OUT; ++i)
            if (has_nan(s->out[i], s->out_size[i])) return NOT_FINITE;
        clip(s->out[OUT_lg], s->ng, s->inf);
        clip(s->out[OUT_ug], s->ng, s->inf);
        clip(s->out[OUT_lbu], nv, s->inf);
        clip(s->out[OUT_ubu], nv, s->inf);
        d_ocp_qp_set_A(k, s->out[OUT_A], &s->qp);
        d_ocp_qp_set_B(k, s->out[OUT_B], &s->qp);
        d_ocp_qp_set_b(k, s->out[OUT_b], &s->qp);
        d_ocp_qp_set_Q(k, s->out[OUT_Q], &s->qp);
        d_ocp_qp_set_S(k, s->out[OUT_S], &s->qp);
        d_ocp_qp_set_R(k, s->out[OUT_R], &s->qp);
        d_ocp_qp_set_q(k, s->out[OUT_q], &s->qp);
        d_ocp_qp_set_r(k, s->out[OUT_r], &s->qp);
        d_ocp_qp_set_C(k, s->out[OUT_C], &s->qp);
        d_ocp_qp_set_D(k, s->out[OUT_D], &s->qp);
        d_ocp_qp_set_lg(k, s->out[OUT_lg], &s->qp);
        d_ocp_qp_set_ug(k, s->out[OUT_ug], &s->qp);
        d_ocp_qp_set_lbu(k, s->out[OUT_lbu], &s->qp);
        d_ocp_qp_set_ubu(k, s->out[OUT_ubu], &s->qp);
    }
    const casadi_real *in[2] = {X + NX * N, ref + NX * N};
    memcpy(s->arg_work, in, sizeof(in));
    s->res_work[0] = s->out[OUT_Q];
    s->res_work[1] = s->out[OUT_q];
    if (rti_terminal(s->arg_work, s->res_work, s->iw, s->w, 0)) return EVALUATION_FAILED;
    if (!all_finite(s->out[OUT_q], nz)) return NOT_FINITE;
    d_ocp_qp_set_Q(N, s->out[OUT_Q], &s->qp);
    d_ocp_qp_set_q(N, s->out[OUT_q], &s->qp);

    for (int i = 0; i < NX; ++i) s->fixed[i] = x_hat[i] - X[i];
    for (int i = 0; i < n; ++i) s->fixed[NX + i] = F_prev[i] - P[i];
    if (!all_finite(s->fixed, nz)) return NOT_FINITE;
    d_ocp_qp_set_lbx(0, s->fixed, &s->qp);
    d_ocp_qp_set_ubx(0, s->fixed, &s->qp);

    int status = 0;
    for (int p = 0; p < s->passes; ++p) {
        int pass_iterations;
        d_ocp_qp_ipm_solve(&s->qp, &s->sol, &s->arg[p], &s->ws[p]);
        d_ocp_qp_ipm_get_status(&s->ws[p], &status);
        d_ocp_qp_ipm_get_iter(&s->ws[p], &pass_iterations);
        *iterations += pass_iterations;
        if (status == 0) break;
    }
    for (int k = 0; k <= N; ++k) d_ocp_qp_sol_get_x(k, &s->sol, dz + nz * k);
    for (int k = 0; k < N; ++k) d_ocp_qp_sol_get_u(k, &s->sol, dv + nv * k);
    return status;
}
