/* The depth MPC of a six-dof export (controllers/depth_mpc.py, DepthMpc, in its safety shell):
 * the depth channel beside the horizontal controller, which auvmpc_six_dof.h wires together.
 * One controller in static memory; DAQP's workspace is allocated once, by auvmpc_depth_init.
 *
 * Depth state [z, w]: depth and heave rate, z UP (m, negative below the surface; m/s), as the
 * Python depth MPC works; the six-dof entry point converts from the vehicle's NED depth. The
 * command is one force per vertical thruster of the vehicle's heave model (N, up). Sizes and
 * settings are the scenario's (auvmpc_depth_config.h).
 */
#ifndef AUVMPC_DEPTH_H
#define AUVMPC_DEPTH_H

#include "auvmpc_controller.h" /* auvmpc_status */
#include "auvmpc_depth_config.h"

#ifdef __cplusplus
extern "C" {
#endif

/* Allocate DAQP's workspace (once) and reset; the vertical thrust starts from zero, as in
 * Python. 0 on success, -1 when out of memory or the generated functions disagree with
 * auvmpc_depth_config.h. Calling it again only resets. */
int auvmpc_depth_init(const double initial_state[AUVMPC_DEPTH_NX]);

/* Forget the plan and the filter's history; the vertical thrust starts from zero. */
void auvmpc_depth_reset(const double initial_state[AUVMPC_DEPTH_NX]);

/* Each vertical thruster's effectiveness from the next step on (1 healthy, 0 dead): what the
 * prediction, the filter and the recovery assume. -1 (nothing changed) outside [0, 1]. */
int auvmpc_depth_set_effectiveness(const double effectiveness[AUVMPC_DEPTH_THRUSTERS]);

/* One sample: the measured [z, w] (only z is read: the filter estimates w), the reference
 * [z, w] at t_k + i Te for i = 0..AUVMPC_DEPTH_HORIZON (row-major). Writes the vertical
 * thrusts and returns the shell's status; no allocation. */
auvmpc_status auvmpc_depth_step(const double measured[AUVMPC_DEPTH_NX],
                                const double reference[(AUVMPC_DEPTH_HORIZON + 1) * AUVMPC_DEPTH_NX],
                                double command[AUVMPC_DEPTH_THRUSTERS]);

/* DAQP's iterations in the last step (both tries); its static structure (bytes). */
int auvmpc_depth_last_iterations(void);
long auvmpc_depth_static_bytes(void);

#ifdef __cplusplus
}
#endif

#endif
