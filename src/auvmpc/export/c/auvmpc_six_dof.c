/* The six-dof entry point (auvmpc_six_dof.h): the horizontal controller and the depth MPC on
 * one vehicle, their demands mapped onto every thruster (controllers/channels.py,
 * HorizontalAndDepth and ThrustMapping), step for step as the Python pair. The depth channel
 * works in z up, the vehicle in NED: z_up = -z, here and nowhere else. */
#include "auvmpc_six_dof.h"

#include <math.h>
#include <string.h>

#define NH AUVMPC_THRUSTERS        /* the horizontal thrusters, first */
#define NT AUVMPC_SIX_DOF_THRUSTERS
#define NV (NT - NH)               /* the vertical ones */
#define NU AUVMPC_DEPTH_THRUSTERS  /* the depth model's vertical thrusters */
#define NM AUVMPC_SIX_DOF_NM
#define P AUVMPC_SIX_DOF_PREVIEW
#define NHX AUVMPC_NX
#define NDX AUVMPC_DEPTH_NX

static const double heave_row[NV] = AUVMPC_SIX_DOF_HEAVE_ROW;     /* NED Z per unit thrust */
static const double healthy_split[NV] = AUVMPC_SIX_DOF_HEAVE_SPLIT; /* its least-norm inverse */
static const double thrust_lower[NT] = AUVMPC_SIX_DOF_THRUST_LOWER;
static const double thrust_upper[NT] = AUVMPC_SIX_DOF_THRUST_UPPER;
static const double thrust_rate[NT] = AUVMPC_SIX_DOF_THRUST_RATE;

static struct {
    double previous[NT];       /* the last mapped command */
    double effectiveness[NT];
    int told;                  /* an effectiveness was set (the Python pair's told is not None) */
    double split[NV];          /* the least-norm split over the verticals as they act */
    double horizontal_reference[(AUVMPC_HORIZON + 1) * NHX];
    double depth_reference[(AUVMPC_DEPTH_HORIZON + 1) * NDX];
} mapping;

/* [z, w] up of the depth channel from a measurement's NED depth and depth rate. */
static void depth_state(const double *measured, double state[NDX]) {
    state[AUVMPC_DEPTH_Z] = -measured[AUVMPC_SIX_DOF_DEPTH];
    state[AUVMPC_DEPTH_W] = -measured[AUVMPC_SIX_DOF_DEPTH_RATE];
}

int auvmpc_six_dof_init(const double measured[NM], const double initial_thrust[NT]) {
    double depth[NDX];
    depth_state(measured, depth);
    if (auvmpc_init(measured, initial_thrust) || auvmpc_depth_init(depth)) return -1;
    for (int i = 0; i < NT; ++i) mapping.effectiveness[i] = 1.0;
    mapping.told = 0;
    memcpy(mapping.split, healthy_split, sizeof mapping.split);
    memcpy(mapping.previous, initial_thrust, sizeof mapping.previous);
    return 0;
}

void auvmpc_six_dof_reset(const double measured[NM], const double initial_thrust[NT]) {
    double depth[NDX];
    depth_state(measured, depth);
    auvmpc_reset(measured, initial_thrust);
    auvmpc_depth_reset(depth);
    memcpy(mapping.previous, initial_thrust, sizeof mapping.previous);
}

int auvmpc_six_dof_set_effectiveness(const double effectiveness[NT]) {
    for (int i = 0; i < NT; ++i)
        if (!(effectiveness[i] >= 0.0 && effectiveness[i] <= 1.0)) return -1;
    if (auvmpc_set_effectiveness(effectiveness) || auvmpc_depth_set_effectiveness(effectiveness + NH))
        return -1;
    memcpy(mapping.effectiveness, effectiveness, sizeof mapping.effectiveness);
    mapping.told = 1;
    /* the verticals' least-norm split as they act (ThrustMapping.vertical); none to push: 0 */
    double acting[NV], strength = 0.0;
    for (int i = 0; i < NV; ++i) {
        acting[i] = heave_row[i] * effectiveness[NH + i];
        strength += acting[i] * acting[i];
    }
    for (int i = 0; i < NV; ++i) mapping.split[i] = strength > 0.0 ? acting[i] / strength : 0.0;
    return 0;
}

auvmpc_six_dof_status auvmpc_six_dof_step(const double measured[NM],
                                          const double reference[AUVMPC_SIX_DOF_ROWS],
                                          const auvmpc_obstacle *obstacles, int obstacle_count,
                                          double command[NT]) {
    auvmpc_six_dof_status status;
    double demand[NT], depth[NDX], heave[NU];
    /* the horizontal channel: [x, y, psi, u, v, r] and its preview */
    for (int k = 0; k <= AUVMPC_HORIZON; ++k)
        memcpy(mapping.horizontal_reference + k * NHX, reference + k * NM, sizeof(double) * NHX);
    status.horizontal = auvmpc_step(measured, mapping.horizontal_reference, obstacles,
                                    obstacle_count, demand);
    /* the depth channel: its preview (or today's reference held) in z up */
    for (int k = 0; k <= AUVMPC_DEPTH_HORIZON; ++k) {
        const double *row = reference + (AUVMPC_SIX_DOF_DEPTH_PREVIEW ? k : 0) * NM;
        mapping.depth_reference[k * NDX + AUVMPC_DEPTH_Z] = -row[AUVMPC_SIX_DOF_DEPTH];
        mapping.depth_reference[k * NDX + AUVMPC_DEPTH_W] = -row[AUVMPC_SIX_DOF_DEPTH_RATE];
    }
    depth_state(measured, depth);
    status.depth = auvmpc_depth_step(depth, mapping.depth_reference, heave);
    /* the heave force the depth MPC's thrusts make as they act, split over the verticals:
     * NED Z = -force */
    double force = 0.0;
    for (int i = 0; i < NU; ++i)
        force += mapping.told ? heave[i] * mapping.effectiveness[NH + i] : heave[i];
    for (int i = 0; i < NV; ++i) demand[NH + i] = mapping.split[i] * (-force);
    /* every thruster within its force and rate limits (ThrustMapping.apply) */
    status.saturated = 0;
    for (int i = 0; i < NT; ++i) {
        double step = AUVMPC_SAMPLE_TIME * thrust_rate[i];
        double low = fmax(thrust_lower[i], mapping.previous[i] - step);
        double high = fmin(thrust_upper[i], mapping.previous[i] + step);
        command[i] = fmin(fmax(demand[i], low), high);
        if (fabs(command[i] - demand[i]) > AUVMPC_SIX_DOF_CLIP_TOLERANCE) ++status.saturated;
    }
    memcpy(mapping.previous, command, sizeof mapping.previous);
    return status;
}

long auvmpc_six_dof_static_bytes(void) {
    return auvmpc_static_bytes() + auvmpc_depth_static_bytes() + (long) sizeof mapping;
}

long auvmpc_six_dof_workspace_bytes(void) { return auvmpc_workspace_bytes(); }
