/* The exported six-dof controller in a vehicle's control loop: the template for your own main
 * (auvmpc's docs/onboard.md explains each step); a six-dof export's example.c. Built by `make`
 * as build/TARGET/example; it runs the loop for 5 s against a made-up vehicle (read_measurement
 * below) and prints the commands, so that it shows the calls, not a vehicle.
 *
 * Replace read_measurement, read_obstacles, reference_preview and send_thrust with your
 * vehicle's navigation and depth sensor, perception, mission and thruster interfaces, and the
 * sleep with your timer.
 */
#include <stdio.h>

#include "auvmpc_six_dof.h"

#define NT AUVMPC_SIX_DOF_THRUSTERS
#define NM AUVMPC_SIX_DOF_NM

/* The measurement now, [x, y, psi, u, v, r, z, z_rate] (m, m, rad, m/s, m/s, rad/s, m, m/s):
 * the navigation's estimate (world x north, y east, heading from north, body velocities) and
 * the depth sensor's depth and depth rate (down positive); here a vehicle at 1 m that drifts
 * slowly along x. */
static void read_measurement(int k, double measured[NM]) {
    for (int i = 0; i < NM; ++i) measured[i] = 0.0;
    measured[0] = 0.05 * k * AUVMPC_SAMPLE_TIME;
    measured[AUVMPC_SIX_DOF_DEPTH] = 1.0;
}

/* The keep-out discs known now (as for auvmpc_step); here none. Returns how many. */
static int read_obstacles(auvmpc_obstacle *obstacles, int capacity) {
    (void) obstacles, (void) capacity;
    return 0;
}

/* The mission's 3-D reference at t_k + i * AUVMPC_SAMPLE_TIME, i = 0..AUVMPC_SIX_DOF_PREVIEW:
 * one row [x, y, psi, u, v, r, z, z_rate] per sample; here a straight line north at 0.5 m/s,
 * diving from 1 m at 0.1 m/s to 1.5 m. */
static void reference_preview(double t, double reference[AUVMPC_SIX_DOF_ROWS]) {
    for (int i = 0; i <= AUVMPC_SIX_DOF_PREVIEW; ++i) {
        double *row = reference + i * NM, at = t + i * AUVMPC_SAMPLE_TIME;
        for (int j = 0; j < NM; ++j) row[j] = 0.0;
        row[0] = 0.5 * at;
        row[3] = 0.5;
        row[AUVMPC_SIX_DOF_DEPTH] = at < 5.0 ? 1.0 + 0.1 * at : 1.5;
        row[AUVMPC_SIX_DOF_DEPTH_RATE] = at < 5.0 ? 0.1 : 0.0;
    }
}

/* Hand every thruster its force (N) for the next AUVMPC_SAMPLE_TIME seconds. */
static void send_thrust(int k, const double thrust[NT], auvmpc_six_dof_status status) {
    printf("%6.2f s  status %d depth %d  thrust", k * AUVMPC_SAMPLE_TIME, (int) status.horizontal,
           (int) status.depth);
    for (int i = 0; i < NT; ++i) printf(" %8.3f", thrust[i]);
    printf(" N\n");
}

int main(void) {
    static const double stopped[NT] = {0};
    static double reference[AUVMPC_SIX_DOF_ROWS];
    static auvmpc_obstacle obstacles[AUVMPC_SLOTS_ALLOC];
    double measured[NM], thrust[NT];

    /* Once, before the loop: lays HPIPM's workspace out in the static arena and allocates
     * DAQP's. Nothing is allocated after this. */
    read_measurement(0, measured);
    if (auvmpc_six_dof_init(measured, stopped)) {
        fprintf(stderr, "auvmpc_six_dof_init failed: arena too small, out of memory or a "
                        "mismatched build\n");
        return 1;
    }
    const int steps = (int) (5.0 / AUVMPC_SAMPLE_TIME);
    for (int k = 0; k < steps; ++k) {
        read_measurement(k, measured); /* sample at t_k */
        int count = read_obstacles(obstacles, (int) (sizeof obstacles / sizeof obstacles[0]));
        reference_preview(k * AUVMPC_SAMPLE_TIME, reference);
        auvmpc_six_dof_status status =
            auvmpc_six_dof_step(measured, reference, obstacles, count, thrust);
        /* Every status comes with a command within every thruster's force and rate limits:
         * apply it. Each channel's FALLBACK and RECOVERY are its safety shell's own (the
         * previous plan's move, then its stabilising feedback): log them, and stop the mission
         * (surface, hold) when they persist in either channel. A step past its deadline: apply
         * the previous command and treat it as a FALLBACK. */
        send_thrust(k, thrust, status);
        /* your timer: wait for t_k + AUVMPC_SAMPLE_TIME here */
    }
    return 0;
}
