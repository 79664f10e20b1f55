/* auvmpc's real-time nonlinear MPC in C: the Python NonlinearMpc (controllers/nmpc.py) with
 * every move free, its sparse real-time iteration (solvers/real_time_iteration.py) and the safety
 * shell (controllers/shell.py), step for step, so that it reproduces the Python commands.
 *
 * Generated per scenario: rti_qp_data.c (CasADi's code of the stage QP, the terminal cost,
 * the RK4 step and the shell's stabilising feedback) and, with the estimator, ekf_data.c (its
 * update and propagation): the functions the Python evaluates and auvmpc_config.h (sizes, weights, limits,
 * settings). hpipm_ocp_step.c is auvmpc's HPIPM driver, the same file the
 * Python controller compiles, built here with a static arena for HPIPM's workspace (the
 * Makefile's ARENA). Static memory only (README.md).
 */
#include "auvmpc_controller.h"

#include <float.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "rti_qp_data.h"
#if AUVMPC_OFFSET_FREE
#include "ekf_data.h"
#endif

#define NX AUVMPC_NX
#define ND AUVMPC_ND /* the disturbance [X, Y, N] */
#define N AUVMPC_HORIZON
#define NT AUVMPC_THRUSTERS
#define S AUVMPC_OBSTACLE_SLOTS
#define SA AUVMPC_SLOTS_ALLOC
#define NZ AUVMPC_NZ
#define NV AUVMPC_NV
#define SLOT_FIELDS AUVMPC_SLOT_FIELDS
#define SOLVED 0
/* A slack below this is solver tolerance, not a relaxed constraint (m); the projection moving
 * the command by less than this (N) is round-off, not saturation (controllers/shell.py). */
#define SLACK_ACTIVE 1e-6
#define SATURATION_N 1e-6
#define TWO_PI (2.0 * 3.14159265358979323846)
/* Where x, y, psi and r sit in a state (auvmpc_config.h, from models/layout.py). */
#define PX AUVMPC_X
#define PY AUVMPC_Y
#define HEADING AUVMPC_HEADING
#define YAW_RATE AUVMPC_YAW_RATE

void *auvmpc_rti_create(int horizon, int n, int slots, int nz, int nv, int ng,
                        const double *settings, int count);
int auvmpc_rti_step(void *handle, const double *X, const double *P, const double *F,
                    const double *x_hat, const double *F_prev, const double *ref,
                    const double *W, const double *d, const double *slots, const double *used,
                    const double *movable, const double *e, int hot_start, double *dz,
                    double *dv, int *iterations);
long auvmpc_rti_memory_bytes(const void *handle);
void auvmpc_rti_free(void *handle);

static const double thrust_lower[NT] = AUVMPC_THRUST_LOWER;
static const double thrust_upper[NT] = AUVMPC_THRUST_UPPER;
static const double thrust_rate[NT] = AUVMPC_THRUST_RATE;
static const double stage_weight[NX] = AUVMPC_STAGE_WEIGHT;
static const double hpipm_settings[] = AUVMPC_HPIPM_SETTINGS;
#if AUVMPC_OFFSET_FREE
#define NA (NX + ND) /* the estimator's state [x; d]: the state, then the disturbance */
static const double prior_covariance[NA] = AUVMPC_PRIOR_COVARIANCE;
#endif

typedef struct auvmpc_controller Controller;

typedef struct {
    double states[N + 1][NX];
    double thrust[N][NT];
} Iterate;

/* Everything one controller holds, sized at export (auvmpc_controller.h). */
struct auvmpc_controller {
    void *qp; /* HPIPM's driver, allocated once */
    double previous[NT];          /* the last applied command, F(-1) */
    double plan[N][NT];           /* what a fallback follows */
    int has_plan;
    int unsolved;                 /* samples in a row without an applied proposal */
    double predicted_yaw_rate;    /* at this sample, by the last applied plan */
    int has_predicted_yaw_rate;
    double hold[2];               /* where the recovery holds station, while it does */
    double effectiveness[NT];     /* each thruster's share of its command that acts (1 healthy)*/
    int holding;
    Iterate guess, next_guess;    /* where the next solve starts (warm start) */
    int has_guess, has_next_guess;
    /* one sample's data */
    double state[NX], disturbance[ND], reference[N + 1][NX];
    double slots[SA][SLOT_FIELDS], used[SA];
    double weights[N][NX], movable[N];
    /* one solve's work */
    Iterate iterate;
    double P[N + 1][NT];
    double dz[N + 1][NZ], dv[N][NV];
    double slack[N];
    double max_slack;
    int iterations;
#if AUVMPC_OFFSET_FREE
    /* the offset-free EKF on [x; d_world] (estimation/ekf.py, AugmentedEkf) */
    double estimate[NA], covariance[NA][NA];
    int initialised;
    const casadi_real *observer_arg[AUVMPC_OBSERVER_SZ_ARG + 1];
    casadi_real *observer_res[AUVMPC_OBSERVER_SZ_RES + 1];
    casadi_int observer_iw[AUVMPC_OBSERVER_SZ_IW + 1];
    casadi_real observer_w[AUVMPC_OBSERVER_SZ_W + 1];
#endif
    /* the stabilising feedback's CasADi work */
    const casadi_real *law_arg[AUVMPC_LAW_SZ_ARG + 1];
    casadi_real *law_res[AUVMPC_LAW_SZ_RES + 1];
    casadi_int law_iw[AUVMPC_LAW_SZ_IW + 1];
    casadi_real law_w[AUVMPC_LAW_SZ_W + 1];
    /* the RK4 step's CasADi work */
    const casadi_real *step_arg[AUVMPC_STEP_SZ_ARG + 1];
    casadi_real *step_res[AUVMPC_STEP_SZ_RES + 1];
    casadi_int step_iw[AUVMPC_STEP_SZ_IW + 1];
    casadi_real step_w[AUVMPC_STEP_SZ_W + 1];
    /* the host's last resort after every real-time try failed (NULL onboard) */
    auvmpc_rescue rescue;
    void *rescue_user;
    int spinning; /* the last step judged the vehicle to spin */
};

/* x_next = RK4(x, F, d, e) over one sample (models/discrete.py), e the thrusters'
 * effectiveness. 0 on success. */
static int model_step(Controller *c, const double *x, const double *F, const double *d, double *x_next) {
    c->step_arg[0] = x;
    c->step_arg[1] = F;
    c->step_arg[2] = d;
    c->step_arg[3] = c->effectiveness;
    c->step_res[0] = x_next;
    return rk4_step(c->step_arg, c->step_res, c->step_iw, c->step_w, 0);
}

static int all_finite(const double *v, int size) {
    for (int i = 0; i < size; ++i)
        if (!isfinite(v[i])) return 0;
    return 1;
}

#if AUVMPC_OFFSET_FREE
/* -- the offset-free estimator: an EKF on [x; d_world], d a random walk (estimation/ekf.py) -- */

static void observer_reset(Controller *c, const double *initial_state) {
    for (int i = 0; i < NA; ++i) {
        c->estimate[i] = i < NX ? initial_state[i] : 0.0;
        for (int j = 0; j < NA; ++j) c->covariance[i][j] = i == j ? prior_covariance[i] : 0.0;
    }
    c->initialised = 0;
}

/* Eigenvalues of the symmetric a (NA x NA) by cyclic Jacobi rotations; with vectors (columns)
 * when v is not NULL. */
static void jacobi_eigen(double a[NA][NA], double *values, double v[NA][NA]) {
    if (v)
        for (int i = 0; i < NA; ++i)
            for (int j = 0; j < NA; ++j) v[i][j] = i == j;
    for (int sweep = 0; sweep < 100; ++sweep) {
        double off = 0.0, scale = 0.0;
        for (int i = 0; i < NA; ++i)
            for (int j = 0; j < NA; ++j) {
                if (i != j) off += a[i][j] * a[i][j];
                scale += a[i][j] * a[i][j];
            }
        if (off <= 1e-32 * scale) break;
        for (int p = 0; p < NA - 1; ++p)
            for (int q = p + 1; q < NA; ++q) {
                if (a[p][q] == 0.0) continue;
                double theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
                double t = (theta >= 0.0 ? 1.0 : -1.0) / (fabs(theta) + sqrt(theta * theta + 1.0));
                double cs = 1.0 / sqrt(t * t + 1.0), sn = t * cs;
                for (int k = 0; k < NA; ++k) { /* columns p, q */
                    double kp = a[k][p], kq = a[k][q];
                    a[k][p] = cs * kp - sn * kq;
                    a[k][q] = sn * kp + cs * kq;
                }
                for (int k = 0; k < NA; ++k) { /* rows p, q */
                    double pk = a[p][k], qk = a[q][k];
                    a[p][k] = cs * pk - sn * qk;
                    a[q][k] = sn * pk + cs * qk;
                }
                if (v)
                    for (int k = 0; k < NA; ++k) {
                        double kp = v[k][p], kq = v[k][q];
                        v[k][p] = cs * kp - sn * kq;
                        v[k][q] = sn * kp + cs * kq;
                    }
            }
    }
    for (int i = 0; i < NA; ++i) values[i] = a[i][i];
}

/* Whether every eigenvalue of the symmetric a lies in [floor, ceiling], proved without them:
 * Gershgorin's discs for the ceiling, and for the floor a Cholesky factorisation of
 * a - (floor + margin) I, margin = NA^3 eps max|a_ij| covering the factorisation's
 * round-off (its backward error, Higham 2002, Thm. 10.3). 0 when unproved, not when false:
 * the eigenvalues then decide (a few thousand instructions here against about 57 000 for
 * one Jacobi eigen-decomposition, callgrind). */
static int eigenvalues_inside(double a[NA][NA]) {
    double largest = 0.0, l[NA][NA];
    for (int i = 0; i < NA; ++i) {
        double radius = 0.0;
        for (int j = 0; j < NA; ++j) {
            radius += fabs(a[i][j]);
            largest = fmax(largest, fabs(a[i][j]));
        }
        if (!(radius <= AUVMPC_COVARIANCE_CEILING)) return 0; /* a[i][i] + off-diagonal sum */
    }
    double shift = AUVMPC_COVARIANCE_FLOOR + NA * NA * NA * DBL_EPSILON * largest;
    for (int j = 0; j < NA; ++j) {
        double d = a[j][j] - shift;
        for (int k = 0; k < j; ++k) d -= l[j][k] * l[j][k];
        if (!(d > 0.0)) return 0;
        l[j][j] = sqrt(d);
        for (int i = j + 1; i < NA; ++i) {
            double e = a[i][j];
            for (int k = 0; k < j; ++k) e -= l[i][k] * l[j][k];
            l[i][j] = e / l[j][j];
        }
    }
    return 1;
}

/* The symmetric part of m with its eigenvalues clipped to [floor, ceiling], rebuilt only
 * when a bound is crossed (estimation/ekf.py, condition_covariance); into c->covariance. */
static void condition_covariance(Controller *c, double m[NA][NA]) {
    double symmetric[NA][NA], work[NA][NA], vectors[NA][NA], values[NA];
    for (int i = 0; i < NA; ++i)
        for (int j = 0; j < NA; ++j) symmetric[i][j] = 0.5 * (m[i][j] + m[j][i]);
    if (eigenvalues_inside(symmetric)) { /* the usual case: the eigenvalues are not needed */
        memcpy(c->covariance, symmetric, sizeof symmetric);
        return;
    }
    memcpy(work, symmetric, sizeof work);
    jacobi_eigen(work, values, NULL);
    double low = values[0], high = values[0];
    for (int i = 1; i < NA; ++i) {
        low = fmin(low, values[i]);
        high = fmax(high, values[i]);
    }
    if (low >= AUVMPC_COVARIANCE_FLOOR && high <= AUVMPC_COVARIANCE_CEILING) {
        memcpy(c->covariance, symmetric, sizeof symmetric);
        return;
    }
    memcpy(work, symmetric, sizeof work);
    jacobi_eigen(work, values, vectors);
    for (int i = 0; i < NA; ++i)
        values[i] = fmin(fmax(values[i], AUVMPC_COVARIANCE_FLOOR), AUVMPC_COVARIANCE_CEILING);
    for (int i = 0; i < NA; ++i)
        for (int j = 0; j < NA; ++j) {
            double sum = 0.0;
            for (int k = 0; k < NA; ++k) sum += vectors[i][k] * values[k] * vectors[j][k];
            work[i][j] = sum;
        }
    for (int i = 0; i < NA; ++i)
        for (int j = 0; j < NA; ++j) c->covariance[i][j] = 0.5 * (work[i][j] + work[j][i]);
}

/* Evaluate a generated EKF function (ekf_update or ekf_propagation: estimation/ekf.py,
 * ekf_functions) on (z, P, x) (and the thrusters' effectiveness, which only the propagation
 * reads): into z_out and P_out (column-major). 0 on success. The covariance is symmetric
 * (condition_covariance), so its rows are its columns. */
static int observer_call(Controller *c, int (*function)(const casadi_real **, casadi_real **, casadi_int *,
                                         casadi_real *, int),
                         const double *x, double *z_out, double *P_out) {
    c->observer_arg[0] = c->estimate;
    c->observer_arg[1] = c->covariance[0];
    c->observer_arg[2] = x;
    c->observer_arg[3] = c->effectiveness;
    c->observer_res[0] = z_out;
    c->observer_res[1] = P_out;
    return function(c->observer_arg, c->observer_res, c->observer_iw, c->observer_w, 0);
}

/* m[i][j] = P[i + NA j]: a column-major result as rows. */
static void from_columns(const double *P, double m[NA][NA]) {
    for (int i = 0; i < NA; ++i)
        for (int j = 0; j < NA; ++j) m[i][j] = P[i + NA * j];
}

/* Fuse a measurement of [x, y, psi, u, v, r] (AugmentedEkf.correct, Joseph form). */
static void observer_correct(Controller *c, const double *measured) {
    double innovation[NX], corrected[NA], joseph[NA * NA], m[NA][NA];
    if (!c->initialised) {
        memcpy(c->estimate, measured, sizeof(double) * NX);
        c->initialised = 1;
    }
    for (int i = 0; i < NX; ++i) innovation[i] = measured[i] - c->estimate[i];
    innovation[HEADING] = remainder(innovation[HEADING], TWO_PI);
    observer_call(c, ekf_update, innovation, corrected, joseph);
    memcpy(c->estimate, corrected, sizeof corrected);
    from_columns(joseph, m);
    condition_covariance(c, m);
}

/* Propagate over one sample with the applied thrust (AugmentedEkf.predict); a non-finite
 * prediction restarts the filter from its prior, keeping the finite unmeasured estimate. */
static void observer_predict(Controller *c, const double *thrust) {
    double next[NA], propagated[NA * NA], m[NA][NA];
    int failed = observer_call(c, ekf_propagation, thrust, next, propagated);
    if (failed || !all_finite(next, NA) || !all_finite(propagated, NA * NA)) {
        double kept[NX];
        for (int i = 0; i < NX; ++i) kept[i] = 0.0;
        double disturbance[ND];
        for (int i = 0; i < ND; ++i)
            disturbance[i] = isfinite(c->estimate[NX + i]) ? c->estimate[NX + i] : 0.0;
        observer_reset(c, kept);
        for (int i = 0; i < ND; ++i) c->estimate[NX + i] = disturbance[i];
        return;
    }
    memcpy(c->estimate, next, sizeof next);
    from_columns(propagated, m);
    condition_covariance(c, m);
}
#endif

static Controller instance; /* the one controller of the static API */

auvmpc_controller *auvmpc_create(void) { return calloc(1, sizeof(Controller)); }

void auvmpc_destroy(auvmpc_controller *c) {
    if (!c) return;
    auvmpc_rti_free(c->qp);
    free(c);
}

int auvmpc_controller_init(Controller *c, const double initial_state[NX],
                           const double initial_thrust[NT]) {
    if (!c->qp) {
        int count = (int) (sizeof hpipm_settings / sizeof hpipm_settings[0]);
        c->qp = auvmpc_rti_create(N, NT, S, NZ, NV, AUVMPC_NG, hpipm_settings, count);
        if (!c->qp) return -1;
    }
    for (int k = 0; k < N; ++k) {
        for (int i = 0; i < NX; ++i) c->weights[k][i] = k == 0 ? 0.0 : stage_weight[i];
        c->movable[k] = 1.0; /* every move free */
    }
    for (int i = 0; i < NT; ++i) c->effectiveness[i] = 1.0; /* healthy until told otherwise */
    auvmpc_controller_reset(c, initial_state, initial_thrust);
    return 0;
}

int auvmpc_controller_set_effectiveness(Controller *c, const double effectiveness[NT]) {
    for (int i = 0; i < NT; ++i)
        if (!(effectiveness[i] >= 0.0 && effectiveness[i] <= 1.0)) return -1;
    memcpy(c->effectiveness, effectiveness, sizeof c->effectiveness);
    return 0;
}

void auvmpc_controller_reset(Controller *c, const double initial_state[NX],
                             const double initial_thrust[NT]) {
#if AUVMPC_OFFSET_FREE
    observer_reset(c, initial_state);
#else
    (void) initial_state; /* the estimator's, when there is one */
#endif
    memcpy(c->previous, initial_thrust, sizeof c->previous);
    c->has_plan = 0;
    c->unsolved = 0;
    c->has_predicted_yaw_rate = 0;
    c->holding = 0;
    c->has_guess = 0;
    c->has_next_guess = 0;
    /* HPIPM keeps its last solution as the next warm start, as in Python. */
}

void auvmpc_controller_set_rescue(Controller *c, auvmpc_rescue rescue, void *user) {
    c->rescue = rescue;
    c->rescue_user = user;
}

void auvmpc_controller_last(const Controller *c, auvmpc_report *report,
                            double predicted_states[(N + 1) * NX]) {
    report->iterations = c->iterations;
    report->spinning = c->spinning;
    report->max_slack = c->max_slack;
    memcpy(report->disturbance, c->disturbance, sizeof c->disturbance);
    if (predicted_states) memcpy(predicted_states, c->iterate.states, sizeof c->iterate.states);
}

int auvmpc_init(const double initial_state[NX], const double initial_thrust[NT]) {
    return auvmpc_controller_init(&instance, initial_state, initial_thrust);
}

void auvmpc_reset(const double initial_state[NX], const double initial_thrust[NT]) {
    auvmpc_controller_reset(&instance, initial_state, initial_thrust);
}

int auvmpc_set_effectiveness(const double effectiveness[NT]) {
    return auvmpc_controller_set_effectiveness(&instance, effectiveness);
}

auvmpc_status auvmpc_step(const double measured_state[NX], const double reference[(N + 1) * NX],
                          const auvmpc_obstacle *obstacles, int obstacle_count,
                          double command[NT]) {
    return auvmpc_controller_step(&instance, measured_state, reference, obstacles,
                                  obstacle_count, command);
}

long auvmpc_static_bytes(void) { return (long) sizeof instance; }

long auvmpc_workspace_bytes(void) { return instance.qp ? auvmpc_rti_memory_bytes(instance.qp) : 0; }

int auvmpc_last_iterations(void) { return instance.iterations; }

/* The reference with its heading shifted by 2 pi k to the turn the vehicle is on
 * (controllers/base.py, align_heading). nearbyint rounds half to even, as numpy. */
static void align_reference(Controller *c, const double *reference) {
    double turns = nearbyint((c->state[HEADING] - reference[HEADING]) / TWO_PI);
    for (int k = 0; k <= N; ++k) {
        for (int i = 0; i < NX; ++i) c->reference[k][i] = reference[NX * k + i];
        c->reference[k][HEADING] += TWO_PI * turns;
    }
}

/* The nearest obstacles fill the slots, the rest are parked far away, unused
 * (MultipleShootingProgram.sample). Picked in the order of Python's stable sort by distance:
 * nearest first, equal distances by their index. */
static void fill_slots(Controller *c, const auvmpc_obstacle *obstacles, int count) {
    double last_distance = -1.0;
    int last_index = -1;
    for (int o = 0; o < SA; ++o) {
        c->slots[o][AUVMPC_SLOT_X] = c->state[PX] + AUVMPC_PARKED_M;
        c->slots[o][AUVMPC_SLOT_Y] = c->state[PY] + AUVMPC_PARKED_M;
        c->slots[o][AUVMPC_SLOT_VX] = c->slots[o][AUVMPC_SLOT_VY] = 0.0;
        c->slots[o][AUVMPC_SLOT_REACH] = 0.0;
        c->used[o] = 0.0;
    }
    for (int o = 0; o < S; ++o) {
        int best = -1;
        double best_distance = 0.0;
        for (int j = 0; j < count; ++j) {
            double d = hypot(obstacles[j].center[0] - c->state[PX],
                             obstacles[j].center[1] - c->state[PY]);
            int after_last = d > last_distance || (d == last_distance && j > last_index);
            if (after_last && (best < 0 || d < best_distance)) {
                best = j;
                best_distance = d;
            }
        }
        if (best < 0) break;
        const auvmpc_obstacle *ob = &obstacles[best];
        c->slots[o][AUVMPC_SLOT_X] = ob->center[0];
        c->slots[o][AUVMPC_SLOT_Y] = ob->center[1];
        c->slots[o][AUVMPC_SLOT_VX] = ob->velocity[0];
        c->slots[o][AUVMPC_SLOT_VY] = ob->velocity[1];
        c->slots[o][AUVMPC_SLOT_REACH] = fmax(ob->radius, ob->horizon_radius) + AUVMPC_KEEP_OUT_EXTRA;
        c->used[o] = 1.0;
        last_distance = best_distance;
        last_index = best;
    }
}

/* The guess without a previous solution: the states on the reference, the last thrust
 * held (MultipleShootingProgram.reference_guess). */
static void reference_guess(Controller *c, Iterate *guess) {
    memcpy(guess->states[0], c->state, sizeof c->state);
    memcpy(guess->states[1], c->reference[1], sizeof(double) * N * NX);
    for (int k = 0; k < N; ++k) memcpy(guess->thrust[k], c->previous, sizeof c->previous);
}

/* `iterations` Gauss-Newton SQP steps from `guess` (RealTimeIteration.solve); 0 and
 * c->iterate on success. With `resimulate` (a cold start's first try) the states are
 * re-simulated after each step, else moved by the QP's step (multiple shooting). */
static int solve(Controller *c, const Iterate *guess, int iterations, int cold, int resimulate) {
    Iterate *it = &c->iterate;
    if (it != guess) *it = *guess;
    for (int k = 0; k < N; ++k) c->slack[k] = 0.0;
    for (int pass = 0; pass < iterations; ++pass) {
        int used_iterations = 0;
        memcpy(c->P[0], c->previous, sizeof c->previous);
        memcpy(c->P[1], it->thrust, sizeof it->thrust);
        int code = auvmpc_rti_step(c->qp, it->states[0], c->P[0], it->thrust[0], c->state,
                                   c->previous, c->reference[0], c->weights[0], c->disturbance,
                                   c->slots[0], c->used, c->movable, c->effectiveness,
                                   pass == 0 && !cold, c->dz[0], c->dv[0], &used_iterations);
        c->iterations += used_iterations;
        if (code != SOLVED) return -1; /* NOT_FINITE data, an evaluation error, HPIPM failed */
        if (!all_finite(c->dz[0], (N + 1) * NZ) || !all_finite(c->dv[0], N * NV)) return -1;
        for (int k = 0; k < N; ++k)
            for (int i = 0; i < NT; ++i)
                it->thrust[k][i] = it->thrust[k][i] + c->dz[k][NX + i] + c->dv[k][i];
        if (S > 0)
            for (int k = 0; k < N; ++k) c->slack[k] = c->dv[k][NV - 1] / AUVMPC_SLACK_SCALE;
        if (resimulate) {
            memcpy(it->states[0], c->state, sizeof c->state);
            for (int k = 0; k < N; ++k)
                if (model_step(c, it->states[k], it->thrust[k], c->disturbance, it->states[k + 1]))
                    return -1;
        } else {
            for (int k = 0; k <= N; ++k)
                for (int i = 0; i < NX; ++i) it->states[k][i] = it->states[k][i] + c->dz[k][i];
        }
        if (!all_finite(it->states[0], (N + 1) * NX)) return -1;
    }
    c->max_slack = 0.0;
    for (int k = 0; k < N; ++k)
        if (c->slack[k] > c->max_slack) c->max_slack = c->slack[k];
    return 0;
}

/* The iterate one sample on (MultipleShootingProgram.shifted, every move free). */
static int shift(Controller *c, const Iterate *from, Iterate *to) {
    double terminal[NX];
    if (model_step(c, from->states[N], from->thrust[N - 1], c->disturbance, terminal)) return -1;
    memmove(to->states[0], from->states[1], sizeof(double) * N * NX);
    memcpy(to->states[N], terminal, sizeof terminal);
    memmove(to->thrust[0], from->thrust[1], sizeof(double) * (N - 1) * NT);
    memcpy(to->thrust[N - 1], from->thrust[N - 1], sizeof(double) * NT);
    return 0;
}

/* The back end: a plan from now on in c->iterate, 0 on success (NonlinearMpc.propose). */
static int propose(Controller *c, const double *measured, const double *reference,
                   const auvmpc_obstacle *obstacles, int count) {
#if AUVMPC_OFFSET_FREE
    observer_correct(c, measured);
    double *d = c->estimate + NX;
    double force = hypot(d[AUVMPC_DISTURBANCE_X], d[AUVMPC_DISTURBANCE_Y]);
    double moment = fabs(d[AUVMPC_DISTURBANCE_N]);
    if (!(force <= AUVMPC_PLAUSIBLE_FORCE && moment <= AUVMPC_PLAUSIBLE_MOMENT))
        observer_reset(c, measured); /* no force the water could exert: diverged, start again */
    memcpy(c->state, c->estimate, sizeof c->state);
    memcpy(c->disturbance, c->estimate + NX, sizeof c->disturbance);
#else
    memcpy(c->state, measured, sizeof c->state);
    for (int i = 0; i < ND; ++i) c->disturbance[i] = 0.0;
#endif
    align_reference(c, reference);
    c->has_next_guess = 0;
    c->max_slack = 0.0;
    if (!all_finite(c->state, NX) || !all_finite(c->disturbance, ND)
        || !all_finite(c->reference[0], (N + 1) * NX))
        return -1;
    fill_slots(c, obstacles, count);
    int cold = !c->has_guess;
    int iterations = AUVMPC_ITERATIONS;
    if (cold) {
        reference_guess(c, &c->iterate);
        if (AUVMPC_COLD_ITERATIONS > iterations) iterations = AUVMPC_COLD_ITERATIONS;
    } else {
        c->iterate = c->guess;
        double turns = nearbyint((c->state[HEADING] - c->iterate.states[0][HEADING]) / TWO_PI);
        if (turns != 0.0)
            for (int k = 0; k <= N; ++k) c->iterate.states[k][HEADING] += TWO_PI * turns;
    }
    int retry = AUVMPC_ITERATIONS > AUVMPC_COLD_ITERATIONS ? AUVMPC_ITERATIONS
                                                          : AUVMPC_COLD_ITERATIONS;
    int failed = solve(c, &c->iterate, iterations, cold, cold);
    if (failed && !cold) { /* the shifted iterate can be what failed: again from the reference */
        reference_guess(c, &c->iterate);
        failed = solve(c, &c->iterate, retry, 1, 1);
    }
    if (failed) { /* the re-simulated cold start can diverge: multiple shooting (NonlinearMpc) */
        reference_guess(c, &c->iterate);
        failed = solve(c, &c->iterate, retry, 1, 0);
    }
    int resumable = !failed;
    if (failed && c->rescue) {
        /* The host's last resort (the Python controller's IPOPT on the same program): its
         * plan in c->iterate, or where it stopped to resume from (NonlinearMpc.propose). */
        int extra = 0;
        double slack = 0.0;
        int code = c->rescue(c->rescue_user, c->state, c->disturbance, c->previous,
                             c->iterate.states[0], c->iterate.thrust[0], &slack, &extra);
        c->iterations += extra;
        failed = code != AUVMPC_RESCUED;
        resumable = code == AUVMPC_RESCUED || code == AUVMPC_RESCUE_RESUMABLE;
        if (!failed) c->max_slack = slack;
    }
    if (resumable && !shift(c, &c->iterate, &c->next_guess)) c->has_next_guess = 1;
    if (!failed && !all_finite(c->iterate.thrust[0], N * NT)) failed = 1;
    return failed ? -1 : 0;
}

/* -- the safety shell's recovery (controllers/shell.py, controllers/recovery.py) -- */

/* The yaw rate above which the vehicle spins: more heading per sample than
 * AUVMPC_SPIN_ANGLE_PER_SAMPLE, and more than AUVMPC_SPIN_REFERENCE_FACTOR times the fastest
 * reference yaw rate in the preview (shell.spin_limit). */
static double spin_limit(const double *reference) {
    double turn = 0.0;
    for (int k = 0; k <= N; ++k) turn = fmax(turn, fabs(reference[NX * k + YAW_RATE]));
    return fmax(AUVMPC_SPIN_ANGLE_PER_SAMPLE / AUVMPC_SAMPLE_TIME,
                AUVMPC_SPIN_REFERENCE_FACTOR * turn);
}

/* Faster than the limit, and not as the last applied plan predicted (ShelledController._spin). */
static int spinning(Controller *c, const double *measured, const double *reference) {
    double yaw_rate = measured[YAW_RATE], limit = spin_limit(reference);
    if (fabs(yaw_rate) <= limit) return 0;
    return !c->has_predicted_yaw_rate || fabs(yaw_rate - c->predicted_yaw_rate) > 0.5 * limit;
}

/* Whether the segment between the positions of the states start and end passes inside an
 * obstacle's keep-out disc (StabilisingFeedback._blocked). */
static int blocked(const double *start_state, const double *end_state,
                   const auvmpc_obstacle *obstacles, int count) {
    double start[2] = {start_state[PX], start_state[PY]};
    double way[2] = {end_state[PX] - start[0], end_state[PY] - start[1]};
    double length2 = way[0] * way[0] + way[1] * way[1];
    for (int j = 0; j < count; ++j) {
        const double *center = obstacles[j].center;
        double along = 0.0;
        if (length2 != 0.0) {
            along = ((center[0] - start[0]) * way[0] + (center[1] - start[1]) * way[1]) / length2;
            along = fmin(fmax(along, 0.0), 1.0);
        }
        double gap = hypot(start[0] + along * way[0] - center[0],
                           start[1] + along * way[1] - center[1]);
        if (gap < obstacles[j].radius + AUVMPC_KEEP_OUT_EXTRA) return 1;
    }
    return 0;
}

/* The stabilising feedback's thrust within the force limits (StabilisingFeedback.command):
 * the generated tracking law towards the reference, or towards the station held where the
 * way to the reference crosses a keep-out disc; the shell's projection follows. */
static void recover(Controller *c, const double *measured, const double *reference,
                    const auvmpc_obstacle *obstacles, int count, double *thrust) {
    double target[2][NX];
    memcpy(target, reference, sizeof target);
    if (blocked(measured, reference, obstacles, count)) {
        if (!c->holding) {
            c->hold[0] = measured[PX];
            c->hold[1] = measured[PY];
            c->holding = 1;
        }
        for (int k = 0; k < 2; ++k) {
            for (int i = 0; i < NX; ++i) target[k][i] = 0.0;
            target[k][PX] = c->hold[0];
            target[k][PY] = c->hold[1];
            target[k][HEADING] = reference[HEADING];
        }
    } else {
        c->holding = 0;
    }
    c->law_arg[0] = measured;
    c->law_arg[1] = target[0];
    c->law_arg[2] = target[1]; /* the reference one sample ahead (N >= 1) */
    c->law_arg[3] = c->disturbance;
    c->law_arg[4] = c->effectiveness;
    for (int i = 0; i < AUVMPC_LAW_SZ_RES; ++i) c->law_res[i] = NULL; /* only the thrust */
    c->law_res[AUVMPC_LAW_THRUST] = thrust;
    tracking_law(c->law_arg, c->law_res, c->law_iw, c->law_w, 0);
}

auvmpc_status auvmpc_controller_step(Controller *c, const double measured_state[NX],
                                     const double reference[(N + 1) * NX],
                                     const auvmpc_obstacle *obstacles, int obstacle_count,
                                     double command[NT]) {
    double wanted[NT];
    c->iterations = 0;
    int solved = c->qp && !propose(c, measured_state, reference, obstacles, obstacle_count);
    int spin = spinning(c, measured_state, reference);
    c->spinning = spin;
    int fell_back = !solved || spin, recovered = 0;
    if (!fell_back) {
        memcpy(wanted, c->iterate.thrust[0], sizeof wanted);
        memcpy(c->plan, c->iterate.thrust, sizeof c->plan);
        c->has_plan = 1;
        c->unsolved = 0;
        c->holding = 0; /* the optimiser is back: a later hold starts afresh */
    } else {
        ++c->unsolved;
        /* The plan was feasible when made: followed for at most AUVMPC_PLAN_FALLBACK_STEPS
         * samples, then (and while the vehicle spins) the stabilising feedback, and the
         * back end starts again cold. */
        recovered = c->qp && (spin || !c->has_plan || c->unsolved > AUVMPC_PLAN_FALLBACK_STEPS);
        if (recovered) {
            recover(c, measured_state, reference, obstacles, obstacle_count, wanted);
            if (!all_finite(wanted, NT)) /* a non-finite state or estimate in it */
                memcpy(wanted, c->previous, sizeof wanted);
            c->has_plan = 0;
            c->has_next_guess = 0;
        } else if (c->has_plan && N > 1) { /* the previous plan's next move, shifted on */
            memcpy(wanted, c->plan[1], sizeof wanted);
            memmove(c->plan[0], c->plan[1], sizeof(double) * (N - 1) * NT);
        } else {
            memcpy(wanted, c->previous, sizeof wanted);
        }
    }
    /* The safety shell's projection into the thrust and thrust-rate box (ActuatorLimits). */
    int saturated = 0;
    for (int i = 0; i < NT; ++i) {
        double step = thrust_rate[i] * AUVMPC_SAMPLE_TIME;
        double lower = fmax(thrust_lower[i], c->previous[i] - step);
        double upper = fmin(thrust_upper[i], c->previous[i] + step);
        if (lower > upper) { /* a previous command outside the force box: the rate wins */
            double inside = fmin(fmax(c->previous[i], thrust_lower[i]), thrust_upper[i]);
            lower = upper = fmin(fmax(inside, c->previous[i] - step), c->previous[i] + step);
        }
        command[i] = fmin(fmax(wanted[i], lower), upper);
        if (fabs(command[i] - wanted[i]) > SATURATION_N) saturated = 1;
    }
    memcpy(c->previous, command, sizeof c->previous);
    c->has_predicted_yaw_rate = !fell_back;
    if (!fell_back) c->predicted_yaw_rate = c->iterate.states[1][YAW_RATE];
    /* applied: the warm start moves on (a failure restarts cold) */
    if (c->has_next_guess) c->guess = c->next_guess;
    c->has_guess = c->has_next_guess;
#if AUVMPC_OFFSET_FREE
    observer_predict(c, command);
#endif
    if (recovered) return AUVMPC_RECOVERY;
    if (fell_back) return AUVMPC_FALLBACK;
    if (c->max_slack > SLACK_ACTIVE) return AUVMPC_RELAXED;
    return saturated ? AUVMPC_SATURATED : AUVMPC_OK;
}
