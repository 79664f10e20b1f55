/* auvmpc's real-time nonlinear MPC (controller label `nmpc`) as a C99 library: what export-c
 * ships, and what the Python controller runs where it is compiled (controllers/compiled_nmpc.py).
 *
 * Onboard, one controller per program in static memory: auvmpc_init once (it lays HPIPM's
 * workspace out in a static arena sized at export), then auvmpc_step every AUVMPC_SAMPLE_TIME
 * seconds; auvmpc_reset forgets the history (warm start, fallback plan) as after a restart.
 * A host that runs several (the Python controller) creates each with auvmpc_create and calls
 * the auvmpc_controller_* functions on it (heap, and a build without the static arena).
 * Sizes and settings are those of the scenario it was exported from (auvmpc_config.h).
 *
 * State order [x, y, psi, u, v, r] (m, m, rad, m/s, m/s, rad/s), world x north, y east;
 * thrust per horizontal thruster (N), applied over [t_k, t_k + Te).
 */
#ifndef AUVMPC_CONTROLLER_H
#define AUVMPC_CONTROLLER_H

#include "auvmpc_config.h"

#ifdef __cplusplus
extern "C" {
#endif

/* A keep-out disc as the controller sees it now. */
typedef struct {
    double center[2];   /* world position now (m) */
    double velocity[2]; /* world velocity (m/s), zero for a fixed obstacle */
    double radius;      /* m, without the vehicle radius and margin (added inside) */
    /* The radius to keep out over the whole horizon where it is larger than radius: a tracked
     * obstacle's largest predicted one (its uncertainty grows); 0 for one known exactly. */
    double horizon_radius;
} auvmpc_obstacle;

/* What one step did (the Python shell's ControlStatus). */
typedef enum {
    AUVMPC_OK = 0,
    AUVMPC_RELAXED = 1,   /* an obstacle constraint's slack was active */
    AUVMPC_FALLBACK = 2,  /* the solver failed: the previous plan's next move was applied */
    AUVMPC_SATURATED = 3, /* the command was projected into the thrust or rate limits */
    AUVMPC_RECOVERY = 4   /* the stabilising feedback was applied (plan used up, or a spin) */
} auvmpc_status;

/* One controller's state (auvmpc_controller.c). */
typedef struct auvmpc_controller auvmpc_controller;

/* What auvmpc_controller_last reports of the last step. */
typedef struct {
    int iterations;   /* HPIPM's iterations, summed over SQP steps and tries (+ the rescue's) */
    int spinning;     /* the shell judged the vehicle to spin (its stabilising feedback took over) */
    double max_slack; /* the largest obstacle slack of the step's plan (m); 0 without one */
    double disturbance[AUVMPC_ND]; /* the world-frame force [X, Y, N] the prediction used */
} auvmpc_report;

/* A host's last resort after every real-time try failed (the Python controller's IPOPT on
 * the same program): given the estimated state, the disturbance and the last command, it
 * writes a plan's states ((AUVMPC_HORIZON + 1) x AUVMPC_NX) and thrusts (AUVMPC_HORIZON x
 * AUVMPC_THRUSTERS), its largest slack and the iterations it took, and returns
 * AUVMPC_RESCUED; AUVMPC_RESCUE_RESUMABLE when it failed but its last point is where the next
 * sample should start from; anything else when it failed. */
enum { AUVMPC_RESCUED = 0, AUVMPC_RESCUE_RESUMABLE = 1, AUVMPC_RESCUE_FAILED = -1 };
typedef int (*auvmpc_rescue)(void *user, const double *state, const double *disturbance,
                             const double *previous, double *states, double *thrust,
                             double *max_slack, int *iterations);

/* Set HPIPM's workspace up (once) and reset. 0 on success, -1 if its arena is too small or
 * the generated functions disagree with auvmpc_config.h. Calling it again only resets. */
int auvmpc_init(const double initial_state[AUVMPC_NX],
                const double initial_thrust[AUVMPC_THRUSTERS]);

/* Each thruster's effectiveness from the next step on (1 healthy, 0 dead, 0.5 half force;
 * all ones after auvmpc_init, kept by auvmpc_reset): what the prediction model, the
 * estimator and the stabilising feedback's allocation assume, as the Python controller's
 * Observation.effectiveness. 0 on success, -1 (nothing changed) if a value is outside
 * [0, 1] or not a number. */
int auvmpc_set_effectiveness(const double effectiveness[AUVMPC_THRUSTERS]);

/* Forget the warm start and the fallback plan; initial_thrust is F(-1) for the first rate
 * limit. */
void auvmpc_reset(const double initial_state[AUVMPC_NX],
                  const double initial_thrust[AUVMPC_THRUSTERS]);

/* One sample: the measured state, the reference at t_k + i Te for i = 0..AUVMPC_HORIZON
 * (row-major, (AUVMPC_HORIZON + 1) x AUVMPC_NX), the obstacles that exist now (the nearest
 * AUVMPC_OBSTACLE_SLOTS count). Writes the command and returns its auvmpc_status; no
 * allocation. Before auvmpc_init it holds the previous command and returns FALLBACK. */
auvmpc_status auvmpc_step(const double measured_state[AUVMPC_NX],
                          const double reference[(AUVMPC_HORIZON + 1) * AUVMPC_NX],
                          const auvmpc_obstacle *obstacles, int obstacle_count,
                          double command[AUVMPC_THRUSTERS]);

/* Memory (bytes): the controller's static structure, and HPIPM's static arena (its
 * workspace and the driver's buffers; 0 before auvmpc_init). */
long auvmpc_static_bytes(void);
long auvmpc_workspace_bytes(void);

/* HPIPM interior-point iterations of the last step (summed over SQP steps and passes). */
int auvmpc_last_iterations(void);

/* The same on a controller of a host's own: auvmpc_create (zeroed, from calloc; NULL when out
 * of memory), then auvmpc_controller_init as auvmpc_init ... and auvmpc_destroy. */
auvmpc_controller *auvmpc_create(void);
void auvmpc_destroy(auvmpc_controller *controller);
int auvmpc_controller_init(auvmpc_controller *controller,
                           const double initial_state[AUVMPC_NX],
                           const double initial_thrust[AUVMPC_THRUSTERS]);
void auvmpc_controller_reset(auvmpc_controller *controller,
                             const double initial_state[AUVMPC_NX],
                             const double initial_thrust[AUVMPC_THRUSTERS]);
auvmpc_status auvmpc_controller_step(auvmpc_controller *controller,
                                     const double measured_state[AUVMPC_NX],
                                     const double reference[(AUVMPC_HORIZON + 1) * AUVMPC_NX],
                                     const auvmpc_obstacle *obstacles, int obstacle_count,
                                     double command[AUVMPC_THRUSTERS]);
int auvmpc_controller_set_effectiveness(auvmpc_controller *controller,
                                        const double effectiveness[AUVMPC_THRUSTERS]);
void auvmpc_controller_set_rescue(auvmpc_controller *controller, auvmpc_rescue rescue,
                                  void *user);
/* The last step's report, and its plan's predicted states ((AUVMPC_HORIZON + 1) x AUVMPC_NX;
 * NULL: not wanted). */
void auvmpc_controller_last(const auvmpc_controller *controller, auvmpc_report *report,
                            double predicted_states[(AUVMPC_HORIZON + 1) * AUVMPC_NX]);

#ifdef __cplusplus
}
#endif

#endif
