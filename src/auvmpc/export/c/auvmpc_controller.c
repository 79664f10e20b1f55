/* auvmpc's real-time nonlinear MPC in C: the Python NonlinearMpc (controllers/nmpc.py) with
 * every move free, its sparse real-time iteration (solvers/sparse_rti.py) and the safety
 * shell (controllers/shell.py), step for step, so that it reproduces the Python commands.
 *
 * Generated per scenario: rti_qp_data.c (CasADi's code of the stage QP, the terminal cost
 * and the RK4 step, from the same expressions the Python uses) and auvmpc_config.h (sizes,
 * weights, limits, settings). hpipm_ocp_step.c is auvmpc's HPIPM driver, the same file the
 * Python controller compiles. Static memory only, but for HPIPM's workspace, allocated once
 * in auvmpc_init (README.md).
 */
#include "auvmpc_controller.h"

#include <math.h>
#include <string.h>

#include "rti_qp_data.h"

#define NX AUVMPC_NX
#define N AUVMPC_HORIZON
#define NT AUVMPC_THRUSTERS
#define S AUVMPC_OBSTACLE_SLOTS
#define SA AUVMPC_SLOTS_ALLOC
#define NZ AUVMPC_NZ
#define NV AUVMPC_NV
#define SLOT_FIELDS 5
#define SOLVED 0
#define NOT_FINITE (-1)
/* A slack below this is solver tolerance, not a relaxed constraint (m); the projection moving
 * the command by less than this (N) is round-off, not saturation (controllers/shell.py). */
#define SLACK_ACTIVE 1e-6
#define SATURATION_N 1e-6
#define TWO_PI (2.0 * 3.14159265358979323846)

void *auvmpc_rti_create(int horizon, int n, int slots, int nz, int nv, int ng,
                        const double *settings, int count);
int auvmpc_rti_step(void *handle, const double *X, const double *P, const double *F,
                    const double *x_hat, const double *F_prev, const double *ref,
                    const double *W, const double *d, const double *slots, const double *used,
                    const double *movable, double *dz, double *dv, int *iterations);
long auvmpc_rti_memory_bytes(const void *handle);

static const double thrust_lower[NT] = AUVMPC_THRUST_LOWER;
static const double thrust_upper[NT] = AUVMPC_THRUST_UPPER;
static const double thrust_rate[NT] = AUVMPC_THRUST_RATE;
static const double stage_weight[NX] = AUVMPC_STAGE_WEIGHT;
static const double hpipm_settings[] = AUVMPC_HPIPM_SETTINGS;

typedef struct {
    double states[N + 1][NX];
    double thrust[N][NT];
} Iterate;

/* Everything the controller holds: static, sized at export. */
static struct {
    void *qp; /* HPIPM's driver, allocated once */
    double previous[NT];          /* the last applied command, F(-1) */
    double plan[N][NT];           /* what a fallback follows */
    int has_plan;
    Iterate guess, next_guess;    /* where the next solve starts (warm start) */
    int has_guess, has_next_guess;
    /* one sample's data */
    double state[NX], disturbance[3], reference[N + 1][NX];
    double slots[SA][SLOT_FIELDS], used[SA];
    double weights[N][NX], movable[N];
    /* one solve's work */
    Iterate iterate;
    double P[N + 1][NT];
    double dz[N + 1][NZ], dv[N][NV];
    double slack[N];
    double max_slack;
    int iterations;
    /* the RK4 step's CasADi work */
    const casadi_real *step_arg[AUVMPC_STEP_SZ_ARG + 1];
    casadi_real *step_res[AUVMPC_STEP_SZ_RES + 1];
    casadi_int step_iw[AUVMPC_STEP_SZ_IW + 1];
    casadi_real step_w[AUVMPC_STEP_SZ_W + 1];
} c;

/* x_next = RK4(x, F, d) over one sample (models/discrete.py). 0 on success. */
static int model_step(const double *x, const double *F, const double *d, double *x_next) {
    c.step_arg[0] = x;
    c.step_arg[1] = F;
    c.step_arg[2] = d;
    c.step_res[0] = x_next;
    return rk4_step(c.step_arg, c.step_res, c.step_iw, c.step_w, 0);
}

static int all_finite(const double *v, int size) {
    for (int i = 0; i < size; ++i)
        if (!isfinite(v[i])) return 0;
    return 1;
}

int auvmpc_init(const double initial_state[NX], const double initial_thrust[NT]) {
    if (!c.qp) {
        int count = (int) (sizeof hpipm_settings / sizeof hpipm_settings[0]);
        c.qp = auvmpc_rti_create(N, NT, S, NZ, NV, AUVMPC_NG, hpipm_settings, count);
        if (!c.qp) return -1;
    }
    for (int k = 0; k < N; ++k) {
        for (int i = 0; i < NX; ++i) c.weights[k][i] = k == 0 ? 0.0 : stage_weight[i];
        c.movable[k] = 1.0; /* every move free */
    }
    auvmpc_reset(initial_state, initial_thrust);
    return 0;
}

void auvmpc_reset(const double initial_state[NX], const double initial_thrust[NT]) {
    (void) initial_state; /* the estimator's, when there is one */
    memcpy(c.previous, initial_thrust, sizeof c.previous);
    c.has_plan = 0;
    c.has_guess = 0;
    c.has_next_guess = 0;
    /* HPIPM keeps its last solution as the next warm start, as in Python. */
}

long auvmpc_memory_bytes(void) {
    return (long) sizeof c + (c.qp ? auvmpc_rti_memory_bytes(c.qp) : 0);
}

int auvmpc_last_iterations(void) { return c.iterations; }

/* The reference with its heading shifted by 2 pi k to the turn the vehicle is on
 * (controllers/base.py, align_heading). nearbyint rounds half to even, as numpy. */
static void align_reference(const double *reference) {
    double turns = nearbyint((c.state[2] - reference[2]) / TWO_PI);
    for (int k = 0; k <= N; ++k) {
        for (int i = 0; i < NX; ++i) c.reference[k][i] = reference[NX * k + i];
        c.reference[k][2] += TWO_PI * turns;
    }
}

/* The nearest obstacles fill the slots, the rest are parked far away, unused
 * (MultipleShootingProgram.sample). Picked in the order of Python's stable sort by distance:
 * nearest first, equal distances by their index. */
static void fill_slots(const auvmpc_obstacle *obstacles, int count) {
    double last_distance = -1.0;
    int last_index = -1;
    for (int o = 0; o < SA; ++o) {
        c.slots[o][0] = c.state[0] + AUVMPC_PARKED_M;
        c.slots[o][1] = c.state[1] + AUVMPC_PARKED_M;
        c.slots[o][2] = c.slots[o][3] = c.slots[o][4] = 0.0;
        c.used[o] = 0.0;
    }
    for (int o = 0; o < S; ++o) {
        int best = -1;
        double best_distance = 0.0;
        for (int j = 0; j < count; ++j) {
            double d = hypot(obstacles[j].center[0] - c.state[0],
                             obstacles[j].center[1] - c.state[1]);
            int after_last = d > last_distance || (d == last_distance && j > last_index);
            if (after_last && (best < 0 || d < best_distance)) {
                best = j;
                best_distance = d;
            }
        }
        if (best < 0) break;
        const auvmpc_obstacle *ob = &obstacles[best];
        c.slots[o][0] = ob->center[0];
        c.slots[o][1] = ob->center[1];
        c.slots[o][2] = ob->velocity[0];
        c.slots[o][3] = ob->velocity[1];
        c.slots[o][4] = ob->radius + AUVMPC_KEEP_OUT_EXTRA;
        c.used[o] = 1.0;
        last_distance = best_distance;
        last_index = best;
    }
}

/* The guess without a previous solution: the states on the reference, the last thrust
 * held (MultipleShootingProgram.reference_guess). */
static void reference_guess(Iterate *guess) {
    memcpy(guess->states[0], c.state, sizeof c.state);
    memcpy(guess->states[1], c.reference[1], sizeof(double) * N * NX);
    for (int k = 0; k < N; ++k) memcpy(guess->thrust[k], c.previous, sizeof c.previous);
}

/* `iterations` Gauss-Newton SQP steps from `guess` (SparseRealTimeIteration.solve); 0 and
 * c.iterate on success. On a cold start the states are re-simulated after each step. */
static int solve(const Iterate *guess, int iterations, int cold) {
    Iterate *it = &c.iterate;
    if (it != guess) *it = *guess;
    for (int k = 0; k < N; ++k) c.slack[k] = 0.0;
    for (int pass = 0; pass < iterations; ++pass) {
        int used_iterations = 0;
        memcpy(c.P[0], c.previous, sizeof c.previous);
        memcpy(c.P[1], it->thrust, sizeof it->thrust);
        int code = auvmpc_rti_step(c.qp, it->states[0], c.P[0], it->thrust[0], c.state,
                                   c.previous, c.reference[0], c.weights[0], c.disturbance,
                                   c.slots[0], c.used, c.movable, c.dz[0], c.dv[0],
                                   &used_iterations);
        c.iterations += used_iterations;
        if (code == NOT_FINITE || code != SOLVED) return -1;
        if (!all_finite(c.dz[0], (N + 1) * NZ) || !all_finite(c.dv[0], N * NV)) return -1;
        for (int k = 0; k < N; ++k)
            for (int i = 0; i < NT; ++i)
                it->thrust[k][i] = it->thrust[k][i] + c.dz[k][NX + i] + c.dv[k][i];
        if (S > 0)
            for (int k = 0; k < N; ++k) c.slack[k] = c.dv[k][NV - 1] / AUVMPC_SLACK_SCALE;
        if (cold) {
            memcpy(it->states[0], c.state, sizeof c.state);
            for (int k = 0; k < N; ++k)
                if (model_step(it->states[k], it->thrust[k], c.disturbance, it->states[k + 1]))
                    return -1;
        } else {
            for (int k = 0; k <= N; ++k)
                for (int i = 0; i < NX; ++i) it->states[k][i] = it->states[k][i] + c.dz[k][i];
        }
        if (!all_finite(it->states[0], (N + 1) * NX)) return -1;
    }
    c.max_slack = 0.0;
    for (int k = 0; k < N; ++k)
        if (c.slack[k] > c.max_slack) c.max_slack = c.slack[k];
    return 0;
}

/* The iterate one sample on (MultipleShootingProgram.shifted, every move free). */
static int shift(const Iterate *from, Iterate *to) {
    double terminal[NX];
    if (model_step(from->states[N], from->thrust[N - 1], c.disturbance, terminal)) return -1;
    memmove(to->states[0], from->states[1], sizeof(double) * N * NX);
    memcpy(to->states[N], terminal, sizeof terminal);
    memmove(to->thrust[0], from->thrust[1], sizeof(double) * (N - 1) * NT);
    memcpy(to->thrust[N - 1], from->thrust[N - 1], sizeof(double) * NT);
    return 0;
}

/* The back end: a plan from now on in c.iterate, 0 on success (NonlinearMpc.propose). */
static int propose(const double *measured, const double *reference,
                   const auvmpc_obstacle *obstacles, int count) {
    memcpy(c.state, measured, sizeof c.state);
    for (int i = 0; i < 3; ++i) c.disturbance[i] = 0.0;
    align_reference(reference);
    c.has_next_guess = 0;
    c.max_slack = 0.0;
    if (!all_finite(c.state, NX) || !all_finite(c.disturbance, 3)
        || !all_finite(c.reference[0], (N + 1) * NX))
        return -1;
    fill_slots(obstacles, count);
    int cold = !c.has_guess;
    int iterations = AUVMPC_ITERATIONS;
    if (cold) {
        reference_guess(&c.iterate);
        if (AUVMPC_COLD_ITERATIONS > iterations) iterations = AUVMPC_COLD_ITERATIONS;
    } else {
        c.iterate = c.guess;
        double turns = nearbyint((c.state[2] - c.iterate.states[0][2]) / TWO_PI);
        if (turns != 0.0)
            for (int k = 0; k <= N; ++k) c.iterate.states[k][2] += TWO_PI * turns;
    }
    int failed = solve(&c.iterate, iterations, cold);
    if (failed && !cold) { /* the shifted iterate can be what failed: again from the reference */
        int retry = AUVMPC_ITERATIONS > AUVMPC_COLD_ITERATIONS ? AUVMPC_ITERATIONS
                                                              : AUVMPC_COLD_ITERATIONS;
        reference_guess(&c.iterate);
        failed = solve(&c.iterate, retry, 1);
    }
    if (!failed && !shift(&c.iterate, &c.next_guess)) c.has_next_guess = 1;
    if (!failed && !all_finite(c.iterate.thrust[0], N * NT)) failed = 1;
    return failed ? -1 : 0;
}

auvmpc_status auvmpc_step(const double measured_state[NX],
                          const double reference[(N + 1) * NX],
                          const auvmpc_obstacle *obstacles, int obstacle_count,
                          double command[NT]) {
    double wanted[NT];
    int fell_back = 1;
    c.iterations = 0;
    if (c.qp && !propose(measured_state, reference, obstacles, obstacle_count)) {
        memcpy(wanted, c.iterate.thrust[0], sizeof wanted);
        memcpy(c.plan, c.iterate.thrust, sizeof c.plan);
        c.has_plan = 1;
        fell_back = 0;
    } else if (c.has_plan && N > 1) { /* the previous plan's next move, the plan shifted on */
        memcpy(wanted, c.plan[1], sizeof wanted);
        memmove(c.plan[0], c.plan[1], sizeof(double) * (N - 1) * NT);
    } else {
        memcpy(wanted, c.previous, sizeof wanted);
    }
    /* The safety shell's projection into the thrust and thrust-rate box (ActuatorLimits). */
    int saturated = 0;
    for (int i = 0; i < NT; ++i) {
        double step = thrust_rate[i] * AUVMPC_SAMPLE_TIME;
        double lower = fmax(thrust_lower[i], c.previous[i] - step);
        double upper = fmin(thrust_upper[i], c.previous[i] + step);
        if (lower > upper) { /* a previous command outside the force box: the rate wins */
            double inside = fmin(fmax(c.previous[i], thrust_lower[i]), thrust_upper[i]);
            lower = upper = fmin(fmax(inside, c.previous[i] - step), c.previous[i] + step);
        }
        command[i] = fmin(fmax(wanted[i], lower), upper);
        if (fabs(command[i] - wanted[i]) > SATURATION_N) saturated = 1;
    }
    memcpy(c.previous, command, sizeof c.previous);
    /* applied: the warm start moves on (a failure restarts cold) */
    if (c.has_next_guess) c.guess = c.next_guess;
    c.has_guess = c.has_next_guess;
    if (fell_back) return AUVMPC_FALLBACK;
    if (c.max_slack > SLACK_ACTIVE) return AUVMPC_RELAXED;
    return saturated ? AUVMPC_SATURATED : AUVMPC_OK;
}
