/* auvmpc's real-time nonlinear MPC (controller label `nmpc`), exported as a C99 library.
 *
 * One controller per program, in static memory: auvmpc_init once (it lays HPIPM's workspace
 * out in a static arena sized at export), then auvmpc_step every AUVMPC_SAMPLE_TIME seconds;
 * auvmpc_reset forgets the history (warm start, fallback plan) as after a restart.
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
} auvmpc_obstacle;

/* What one step did (the Python shell's ControlStatus). */
typedef enum {
    AUVMPC_OK = 0,
    AUVMPC_RELAXED = 1,   /* an obstacle constraint's slack was active */
    AUVMPC_FALLBACK = 2,  /* the solver failed: the previous plan's next move was applied */
    AUVMPC_SATURATED = 3, /* the command was projected into the thrust or rate limits */
    AUVMPC_RECOVERY = 4   /* the stabilising feedback was applied (plan used up, or a spin) */
} auvmpc_status;

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

#ifdef __cplusplus
}
#endif

#endif
