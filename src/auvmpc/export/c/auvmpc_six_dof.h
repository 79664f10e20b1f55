/* The onboard entry point of a six-dof export: auvmpc's control architecture for the 6-DOF
 * vehicle (controllers/channels.py, HorizontalAndDepth) as one C controller. Every sample the
 * horizontal controller (auvmpc_controller.h) steers [x, y, psi, u, v, r] with the horizontal
 * thrusters, the depth MPC (auvmpc_depth.h) the depth with the vertical ones, and the thrust
 * mapping puts both on every thruster within its force and rate limits. Roll and pitch are
 * left to the vehicle's passive stability. Static memory but for DAQP's and (without the
 * arena) HPIPM's workspaces, allocated once by auvmpc_six_dof_init.
 *
 * Measurement (AUVMPC_SIX_DOF_MEASUREMENT_NAMES): [x, y, psi, u, v, r, z, z_rate]: the
 * navigation's position (m, world x north, y east), heading (rad, from north), body
 * velocities (m/s, m/s, rad/s), and the depth sensor's depth and depth rate (m and m/s, NED:
 * down positive). Reference rows: the same eight entries of the mission's 3-D path at
 * t_k + i Te, i = 0..AUVMPC_SIX_DOF_PREVIEW. Command: every thruster's force (N), in the
 * vehicle's six_dof.thrusters order (AUVMPC_SIX_DOF_INPUT_NAMES): the horizontal ones first.
 */
#ifndef AUVMPC_SIX_DOF_H
#define AUVMPC_SIX_DOF_H

#include "auvmpc_controller.h"
#include "auvmpc_depth.h"
#include "auvmpc_six_dof_config.h"

#ifdef __cplusplus
extern "C" {
#endif

#define AUVMPC_SIX_DOF_ROWS ((AUVMPC_SIX_DOF_PREVIEW + 1) * AUVMPC_SIX_DOF_NM)

/* What one step did: each channel's status (auvmpc_status) and how many thrusters' demand the
 * mapping had to change to keep their force and rate limits (0 in every run measured). */
typedef struct {
    auvmpc_status horizontal;
    auvmpc_status depth;
    int saturated;
} auvmpc_six_dof_status;

/* Set both controllers up (once) and reset, from the measurement and the thrust every
 * thruster holds now. 0 on success, -1 if a workspace cannot be had (arena too small, out of
 * memory) or the generated code disagrees with its configuration: do not start then. */
int auvmpc_six_dof_init(const double measured[AUVMPC_SIX_DOF_NM],
                        const double initial_thrust[AUVMPC_SIX_DOF_THRUSTERS]);

/* Forget both controllers' history (warm starts, plans, filters). */
void auvmpc_six_dof_reset(const double measured[AUVMPC_SIX_DOF_NM],
                          const double initial_thrust[AUVMPC_SIX_DOF_THRUSTERS]);

/* Each thruster's effectiveness from the next step on (1 healthy, 0 dead), every thruster in
 * the command's order: the horizontal controller, the depth MPC and the vertical split each
 * assume theirs. -1 (nothing changed) if a value is outside [0, 1]. */
int auvmpc_six_dof_set_effectiveness(const double effectiveness[AUVMPC_SIX_DOF_THRUSTERS]);

/* One sample: the measurement at t_k, the reference preview (row-major, AUVMPC_SIX_DOF_PREVIEW
 * + 1 rows of AUVMPC_SIX_DOF_NM), the keep-out discs known now (as auvmpc_step). Writes every
 * thruster's force for [t_k, t_k + Te) and returns both statuses; no allocation. */
auvmpc_six_dof_status auvmpc_six_dof_step(const double measured[AUVMPC_SIX_DOF_NM],
                                          const double reference[AUVMPC_SIX_DOF_ROWS],
                                          const auvmpc_obstacle *obstacles, int obstacle_count,
                                          double command[AUVMPC_SIX_DOF_THRUSTERS]);

/* Static memory (bytes): the three controllers' structures; and HPIPM's arena. */
long auvmpc_six_dof_static_bytes(void);
long auvmpc_six_dof_workspace_bytes(void);

#ifdef __cplusplus
}
#endif

#endif
