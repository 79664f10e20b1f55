/* One sparse QP step of auvmpc's real-time iteration, in one call from Python.
 *
 * The stage data come from CasADi-generated code (rti_stage, rti_terminal: see
 * ocp/stage_qp.py, StageQp, for the QP); HPIPM, linked from the casadi wheel, solves the
 * QP. Everything HPIPM needs is allocated once per controller (auvmpc_rti_create): through
 * CasADi's interface the QP's set-up and memory were allocated and freed on every call, about
 * five times the cost of the interior point itself.
 *
 * Memory layout of the arguments (row-major, one stage per row): X (N+1, nx) the iterate's
 * states, P (N+1, n) the thrust before each step, F (N, n) the thrust, ref (N+1, nx) the
 * reference, W (N, nx) the stage weights, d the world force and moment, slots (S, 5), used
 * (S), movable (N), e (n) the thrusters' effectiveness (1 healthy, 0 dead). nx, the model's
 * state size, is the rows of the stage function's first input, X_k: no size of the model is
 * written here.
 * Results: dz (N+1, nz), dv (N, nv), the step of [dX; dp] and [w; sigma s], w = dF - dp
 * (ocp/stage_qp.py, stage_qp).
 *
 * Stage 0's state z_0 = [x_hat - X_0; F_prev - P_0] is known, so it is not a QP variable:
 * it is folded into stage 0's dynamics offset, input gradient and row bounds (HPIPM sees
 * nx_0 = 0). As a bound lb = ub it was ten two-sided inequalities for the interior point
 * (measured: the most iterations of one step on paper-obstacles fell from 123 to 22).
 *
 * The QP is solved by up to three interior-point passes, each with its own settings (solvers/
 * hpipm.py, hpipm_settings, says which and why): a few hot-started iterations from this
 * controller's previous QP solution, primal and dual; if they do not solve it, a fast pass
 * from the previous primal solution; only if that fails, a robust one from a cold start.
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

/* Memory: calloc and free, or, where the build defines AUVMPC_ARENA_BYTES (auvmpc export-c,
 * which measures the size at export), a static arena handed out once in 64-byte aligned
 * pieces and never freed: no heap at all. */
#ifdef AUVMPC_ARENA_BYTES
#include <stdint.h>
static unsigned char arena[AUVMPC_ARENA_BYTES + 64];
static size_t arena_used;
static void *zeroed(size_t count, size_t size) {
    size_t bytes = (count * size + 63) / 64 * 64;
    size_t offset = (size_t) ((((uintptr_t) arena + 63) / 64 * 64) - (uintptr_t) arena);
    if (bytes == 0) bytes = 64;
    if (offset + arena_used + bytes > sizeof arena) return NULL;
    void *memory = arena + offset + arena_used;
    arena_used += bytes;
    memset(memory, 0, bytes);
    return memory;
}
static void release(void *memory) { (void) memory; }
#else
#define zeroed calloc
#define release free
#endif

#define N_STAGE_OUT 16
#define NOT_FINITE (-1)
#define EVALUATION_FAILED (-2)
#define MAX_PASSES 2
#define SETTINGS_PER_PASS 6
#define GENERAL_SETTINGS 2 /* infinity, passes */
#define MEMORY_SLOTS (4 + 2 * MAX_PASSES)
#define HOT_START 3 /* HPIPM's warm_start value: from the primal and dual solution it holds */

enum { OUT_A, OUT_B, OUT_b, OUT_Q, OUT_S, OUT_R, OUT_q, OUT_r, OUT_C, OUT_D, OUT_lg, OUT_ug,
       OUT_lbu, OUT_ubu, OUT_lbp_next, OUT_ubp_next };

typedef struct {
    int N, n, S, nz, nv, ng;
    int nx; /* the model's states: z_k = [dX_k; p_k] holds nx + n */
    double inf;
    struct d_ocp_qp_dim dim;
    struct d_ocp_qp qp;
    struct d_ocp_qp_sol sol;
    struct d_ocp_qp_sol start; /* the previous solution, kept while a hot-started pass runs */
    int passes; /* interior-point settings tried in turn until one solves */
    int hot_limit[MAX_PASSES]; /* iterations of a pass's hot-started try, 0: none */
    struct d_ocp_qp_ipm_arg arg[MAX_PASSES];
    struct d_ocp_qp_ipm_ws ws[MAX_PASSES];
    void *hpipm_memory[MEMORY_SLOTS];
    int memory_used;
    long bytes; /* allocated by auvmpc_rti_create, all of it (auvmpc_rti_memory_bytes) */
    double *out[N_STAGE_OUT]; /* one stage's data, reused for every stage */
    int out_size[N_STAGE_OUT];
    double *fixed; /* z_0 = [x_hat - X_0; F_prev - P_0] */
    int *index;   /* 0, 1, ..., nv - 1: every input is bounded */
    int *state_index; /* nx, ..., nz - 1: the thrust part of every state but z_0 is bounded */
    const casadi_real **arg_work;
    casadi_real **res_work;
    casadi_int *iw;
    casadi_real *w;
} Step;

/* Zeroed memory that auvmpc_rti_free releases; NULL when it runs out. */
static void *allocate(Step *s, hpipm_size_t size) {
    if (s->memory_used == MEMORY_SLOTS) return NULL;
    void *memory = zeroed(1, size > 0 ? size : 1);
    if (memory) {
        s->hpipm_memory[s->memory_used++] = memory;
        s->bytes += (long) size;
    }
    return memory;
}

/* The bytes auvmpc_rti_create allocated for this handle: its own and HPIPM's. */
long auvmpc_rti_memory_bytes(const void *handle) {
#ifdef AUVMPC_ARENA_BYTES
    return handle ? (long) sizeof arena : 0; /* all of it, static */
#else
    return handle ? ((const Step *) handle)->bytes : 0;
#endif
}

void auvmpc_rti_free(void *handle) {
    Step *s = (Step *) handle;
    if (!s) return;
    for (int i = 0; i < s->memory_used; ++i) release(s->hpipm_memory[i]);
    for (int i = 0; i < N_STAGE_OUT; ++i) release(s->out[i]);
    release(s->fixed);
    release(s->index);
    release(s->state_index);
    release(s->arg_work);
    release(s->res_work);
    release(s->iw);
    release(s->w);
    release(s);
}

/* Whether a generated output holds `size` values, all of them: CasADi's compressed sparsity
 * is [rows, columns, 1] for a dense matrix, else [rows, columns, column offsets, rows...]. */
static int dense_of_size(const casadi_int *sp, int size) {
    casadi_int nonzeros = sp[2] == 1 ? sp[0] * sp[1] : sp[2 + sp[1]];
    return sp[0] * sp[1] == size && nonzeros == size;
}

/* The model's state size: the rows of the stage function's first input, X_k. */
static int state_size(void) { return (int) rti_stage_sparsity_in(0)[0]; }

/* Whether the generated stage functions have the sizes the caller gave. */
static int sizes_agree(int nz, int nv, int ng) {
    const int nx = state_size();
    const int expected[N_STAGE_OUT] = {nz * nz, nz * nv, nz, nz * nz, nv * nz, nv * nv, nz, nv,
                                       ng * nz, ng * nv, ng, ng, nv, nv, nz - nx, nz - nx};
    for (int i = 0; i < N_STAGE_OUT; ++i)
        if (!dense_of_size(rti_stage_sparsity_out(i), expected[i])) return 0;
    return dense_of_size(rti_terminal_sparsity_out(0), nz * nz)
           && dense_of_size(rti_terminal_sparsity_out(1), nz);
}

/* Sizes: horizon N, thrusters n, obstacle slots S, and the stage QP's nz, nv, ng (checked
 * against the generated functions). settings (count values): the bound standing for
 * infinity, the number of passes, then per pass HPIPM's mode, iteration limit, mu0,
 * tolerance (stationarity, equality, inequality, complementarity), warm start (0: cold,
 * 1: from the primal solution HPIPM holds, the previous call's) and the iterations of a
 * hot-started try before it (from that solution's primal and dual parts; 0: none). NULL
 * when memory runs out or the sizes or settings disagree. */
void *auvmpc_rti_create(int N, int n, int S, int nz, int nv, int ng, const double *settings,
                        int count) {
    if (N < 1 || nz != state_size() + n || count < GENERAL_SETTINGS || !sizes_agree(nz, nv, ng))
        return NULL;
    int passes = (int) settings[1];
    if (passes < 1 || passes > MAX_PASSES
        || count < GENERAL_SETTINGS + SETTINGS_PER_PASS * passes)
        return NULL;
    Step *s = (Step *) zeroed(1, sizeof(Step));
    if (!s) return NULL;
    s->N = N;
    s->n = n;
    s->S = S;
    s->nz = nz;
    s->nx = nz - n;
    s->nv = nv;
    s->ng = ng;
    s->inf = settings[0];
    s->passes = passes;

    int *nx = zeroed(N + 1, sizeof(int)), *nu = zeroed(N + 1, sizeof(int));
    int *nbx = zeroed(N + 1, sizeof(int)), *nbu = zeroed(N + 1, sizeof(int));
    int *rows = zeroed(N + 1, sizeof(int)), *ns = zeroed(N + 1, sizeof(int));
    int ok = nx && nu && nbx && nbu && rows && ns;
    if (ok) {
        for (int k = 0; k <= N; ++k) {
            nx[k] = k > 0 ? s->nz : 0; /* z_0 is known: folded into stage 0 */
            nu[k] = k < N ? s->nv : 0;
            nbu[k] = nu[k];
            nbx[k] = k > 0 ? n : 0;
            rows[k] = k < N ? s->ng : 0;
        }
        ok = allocate(s, d_ocp_qp_dim_memsize(N)) != NULL;
    }
    if (ok) {
        d_ocp_qp_dim_create(N, &s->dim, s->hpipm_memory[s->memory_used - 1]);
        d_ocp_qp_dim_set_all(nx, nu, nbx, nbu, rows, ns, &s->dim);
    }
    release(nx); release(nu); release(nbx); release(nbu); release(rows); release(ns);
    void *qp_memory = ok ? allocate(s, d_ocp_qp_memsize(&s->dim)) : NULL;
    void *sol_memory = qp_memory ? allocate(s, d_ocp_qp_sol_memsize(&s->dim)) : NULL;
    void *start_memory = sol_memory ? allocate(s, d_ocp_qp_sol_memsize(&s->dim)) : NULL;
    if (!start_memory) {
        auvmpc_rti_free(s);
        return NULL;
    }
    d_ocp_qp_create(&s->dim, &s->qp, qp_memory);
    d_ocp_qp_sol_create(&s->dim, &s->sol, sol_memory);
    d_ocp_qp_sol_create(&s->dim, &s->start, start_memory);

    for (int p = 0; p < s->passes; ++p) {
        const double *pass = settings + GENERAL_SETTINGS + SETTINGS_PER_PASS * p;
        struct d_ocp_qp_ipm_arg *arg = &s->arg[p];
        void *arg_memory = allocate(s, d_ocp_qp_ipm_arg_memsize(&s->dim));
        if (!arg_memory) {
            auvmpc_rti_free(s);
            return NULL;
        }
        d_ocp_qp_ipm_arg_create(&s->dim, arg, arg_memory);
        d_ocp_qp_ipm_arg_set_default((enum hpipm_mode) (int) pass[0], arg);
        int iteration_limit = (int) pass[1], warm_start = (int) pass[4];
        double mu0 = pass[2], tolerance = pass[3];
        d_ocp_qp_ipm_arg_set_iter_max(&iteration_limit, arg);
        d_ocp_qp_ipm_arg_set_mu0(&mu0, arg);
        d_ocp_qp_ipm_arg_set_tol_stat(&tolerance, arg);
        d_ocp_qp_ipm_arg_set_tol_eq(&tolerance, arg);
        d_ocp_qp_ipm_arg_set_tol_ineq(&tolerance, arg);
        d_ocp_qp_ipm_arg_set_tol_comp(&tolerance, arg);
        d_ocp_qp_ipm_arg_set_warm_start(&warm_start, arg);
        s->hot_limit[p] = (int) pass[5];
        void *ws_memory = allocate(s, d_ocp_qp_ipm_ws_memsize(&s->dim, arg));
        if (!ws_memory) {
            auvmpc_rti_free(s);
            return NULL;
        }
        d_ocp_qp_ipm_ws_create(&s->dim, arg, &s->ws[p], ws_memory);
    }

    for (int i = 0; i < N_STAGE_OUT; ++i) {
        s->out_size[i] = (int) rti_stage_sparsity_out(i)[0] * (int) rti_stage_sparsity_out(i)[1];
        s->out[i] = zeroed(s->out_size[i] > 0 ? s->out_size[i] : 1, sizeof(double));
        if (!s->out[i]) ok = 0;
    }
    s->fixed = zeroed(s->nz, sizeof(double));
    s->index = zeroed(s->nv, sizeof(int));
    s->state_index = zeroed(n, sizeof(int));
    casadi_int sz_arg, sz_res, sz_iw, sz_w, t_arg, t_res, t_iw, t_w;
    rti_stage_work(&sz_arg, &sz_res, &sz_iw, &sz_w);
    rti_terminal_work(&t_arg, &t_res, &t_iw, &t_w);
    if (t_arg > sz_arg) sz_arg = t_arg;
    if (t_res > sz_res) sz_res = t_res;
    if (t_iw > sz_iw) sz_iw = t_iw;
    if (t_w > sz_w) sz_w = t_w;
    s->arg_work = zeroed(sz_arg + 1, sizeof(casadi_real *));
    s->res_work = zeroed(sz_res + 1, sizeof(casadi_real *));
    s->iw = zeroed(sz_iw + 1, sizeof(casadi_int));
    s->w = zeroed(sz_w + 1, sizeof(casadi_real));
    if (!ok || !s->fixed || !s->index || !s->state_index || !s->arg_work || !s->res_work || !s->iw || !s->w) {
        auvmpc_rti_free(s);
        return NULL;
    }
    s->bytes += (long) (sizeof(Step) + sizeof(double) * (s->nz + sz_w + 1)
                        + sizeof(int) * (s->nv + n) + sizeof(casadi_real *) * (sz_arg + sz_res + 2)
                        + sizeof(casadi_int) * (sz_iw + 1));
    for (int i = 0; i < N_STAGE_OUT; ++i)
        s->bytes += (long) sizeof(double) * (s->out_size[i] > 0 ? s->out_size[i] : 1);
    for (int i = 0; i < s->nv; ++i) s->index[i] = i;
    for (int i = 0; i < n; ++i) s->state_index[i] = s->nx + i;
    for (int k = 0; k < N; ++k) {
        d_ocp_qp_set_idxbu(k, s->index, &s->qp);
        d_ocp_qp_set_idxbx(k + 1, s->state_index, &s->qp);
    }
    return s;
}

/* Stage 0 with its known state z_0 folded in (nx_0 = 0): the dynamics offset b + A z_0,
 * the input gradient r + S z_0, the row bounds minus C z_0. */
static void fold_initial_state(Step *s) {
    const int nz = s->nz, nv = s->nv, ng = s->ng;
    const double *z = s->fixed;
    double *b = s->out[OUT_b], *r = s->out[OUT_r], *lg = s->out[OUT_lg], *ug = s->out[OUT_ug];
    const double *A = s->out[OUT_A], *S = s->out[OUT_S], *C = s->out[OUT_C];
    for (int j = 0; j < nz; ++j) { /* column-major: A[i + nz j], S[i + nv j], C[i + ng j] */
        for (int i = 0; i < nz; ++i) b[i] += A[i + nz * j] * z[j];
        for (int i = 0; i < nv; ++i) r[i] += S[i + nv * j] * z[j];
        for (int i = 0; i < ng; ++i) {
            lg[i] -= C[i + ng * j] * z[j]; /* -inf stays -inf */
            ug[i] -= C[i + ng * j] * z[j];
        }
    }
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

/* Pass p with its own settings, from where sol stands; HPIPM's status (0: solved). */
static int run_pass(Step *s, int p, int *iterations) {
    int status, pass_iterations;
    d_ocp_qp_ipm_solve(&s->qp, &s->sol, &s->arg[p], &s->ws[p]);
    d_ocp_qp_ipm_get_status(&s->ws[p], &status);
    d_ocp_qp_ipm_get_iter(&s->ws[p], &pass_iterations);
    *iterations += pass_iterations;
    return status;
}

/* Pass p hot-started from the solution sol holds, primal and dual, for at most its hot limit
 * of iterations: whether that solved the QP. If not, sol is put back as it was, so that the
 * pass itself starts where it would have without the try. Same settings and workspace as the
 * pass (its memory is sized for the pass's larger iteration limit). */
static int hot_try(Step *s, int p, int *iterations) {
    struct d_ocp_qp_ipm_arg *arg = &s->arg[p];
    int limit = arg->iter_max, warm_start = arg->warm_start, hot = HOT_START;
    d_ocp_qp_sol_copy_all(&s->sol, &s->start);
    d_ocp_qp_ipm_arg_set_iter_max(&s->hot_limit[p], arg);
    d_ocp_qp_ipm_arg_set_warm_start(&hot, arg);
    int status = run_pass(s, p, iterations);
    d_ocp_qp_ipm_arg_set_iter_max(&limit, arg);
    d_ocp_qp_ipm_arg_set_warm_start(&warm_start, arg);
    if (status != 0) d_ocp_qp_sol_copy_all(&s->start, &s->sol);
    return status == 0;
}

/* The HPIPM status (0: solved), NOT_FINITE when the QP data are not finite,
 * EVALUATION_FAILED when the generated functions report an error. hot_start: try each pass
 * hot-started first, where its settings give a hot limit (the first QP of a sample that
 * continues a previous solution: hpipm.py, hpipm_settings, says why not the others). */
int auvmpc_rti_step(void *handle, const double *X, const double *P, const double *F,
                    const double *x_hat, const double *F_prev, const double *ref,
                    const double *W, const double *d, const double *slots, const double *used,
                    const double *movable, const double *e, int hot_start, double *dz,
                    double *dv, int *iterations) {
    Step *s = (Step *) handle;
    const int N = s->N, n = s->n, nz = s->nz, nv = s->nv, nx = s->nx;
    *iterations = 0;
    for (int i = 0; i < nx; ++i) s->fixed[i] = x_hat[i] - X[i];
    for (int i = 0; i < n; ++i) s->fixed[nx + i] = F_prev[i] - P[i];
    if (!all_finite(s->fixed, nz)) return NOT_FINITE;
    for (int k = 0; k < N; ++k) {
        double step_index = k + 1;
        const casadi_real *in[13] = {X + nx * k, X + nx * (k + 1), P + n * k, P + n * (k + 1),
                                     F + n * k, ref + nx * k, W + nx * k, d, slots, used,
                                     movable + k, &step_index, e};
        memcpy(s->arg_work, in, sizeof(in));
        memcpy(s->res_work, s->out, sizeof(s->out));
        if (rti_stage(s->arg_work, s->res_work, s->iw, s->w, 0)) return EVALUATION_FAILED;
        /* The gaps and gradients go non-finite first on a diverged iterate. */
        if (!all_finite(s->out[OUT_b], s->out_size[OUT_b]) || !all_finite(s->out[OUT_q], nz)
            || !all_finite(s->out[OUT_r], nv))
            return NOT_FINITE;
        for (int i = 0; i < N_STAGE_OUT; ++i)
            if (has_nan(s->out[i], s->out_size[i])) return NOT_FINITE;
        if (k == 0) fold_initial_state(s);
        clip(s->out[OUT_lg], s->ng, s->inf);
        clip(s->out[OUT_ug], s->ng, s->inf);
        clip(s->out[OUT_lbu], nv, s->inf);
        clip(s->out[OUT_ubu], nv, s->inf);
        if (k > 0) { /* stage 0 has no state */
            d_ocp_qp_set_A(k, s->out[OUT_A], &s->qp);
            d_ocp_qp_set_Q(k, s->out[OUT_Q], &s->qp);
            d_ocp_qp_set_S(k, s->out[OUT_S], &s->qp);
            d_ocp_qp_set_q(k, s->out[OUT_q], &s->qp);
            d_ocp_qp_set_C(k, s->out[OUT_C], &s->qp);
        }
        d_ocp_qp_set_B(k, s->out[OUT_B], &s->qp);
        d_ocp_qp_set_b(k, s->out[OUT_b], &s->qp);
        d_ocp_qp_set_R(k, s->out[OUT_R], &s->qp);
        d_ocp_qp_set_r(k, s->out[OUT_r], &s->qp);
        d_ocp_qp_set_D(k, s->out[OUT_D], &s->qp);
        d_ocp_qp_set_lg(k, s->out[OUT_lg], &s->qp);
        d_ocp_qp_set_ug(k, s->out[OUT_ug], &s->qp);
        d_ocp_qp_set_lbu(k, s->out[OUT_lbu], &s->qp);
        d_ocp_qp_set_ubu(k, s->out[OUT_ubu], &s->qp);
        d_ocp_qp_set_lbx(k + 1, s->out[OUT_lbp_next], &s->qp);
        d_ocp_qp_set_ubx(k + 1, s->out[OUT_ubp_next], &s->qp);
    }
    const casadi_real *in[2] = {X + nx * N, ref + nx * N};
    memcpy(s->arg_work, in, sizeof(in));
    s->res_work[0] = s->out[OUT_Q];
    s->res_work[1] = s->out[OUT_q];
    if (rti_terminal(s->arg_work, s->res_work, s->iw, s->w, 0)) return EVALUATION_FAILED;
    if (!all_finite(s->out[OUT_q], nz)) return NOT_FINITE;
    d_ocp_qp_set_Q(N, s->out[OUT_Q], &s->qp);
    d_ocp_qp_set_q(N, s->out[OUT_q], &s->qp);

    int status = 0;
    for (int p = 0; p < s->passes; ++p) {
        if (hot_start && s->hot_limit[p] > 0 && hot_try(s, p, iterations)) {
            status = 0;
            break;
        }
        status = run_pass(s, p, iterations);
        if (status == 0) break;
    }
    memcpy(dz, s->fixed, nz * sizeof(double));
    for (int k = 1; k <= N; ++k) d_ocp_qp_sol_get_x(k, &s->sol, dz + nz * k);
    for (int k = 0; k < N; ++k) d_ocp_qp_sol_get_u(k, &s->sol, dv + nv * k);
    return status;
}
