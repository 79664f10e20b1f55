/* The exported controller in a vehicle's control loop: the template for your own main
 * (auvmpc's docs/onboard.md explains each step). Built by `make` as build/TARGET/example;
 * it runs the loop for 5 s against a made-up vehicle (read_state below) and prints the
 * commands, so that it shows the calls, not a vehicle.
 *
 * Replace read_state, read_obstacles, reference_preview and send_thrust with your vehicle's
 * navigation, perception, mission and thruster interfaces, and the sleep with your timer.
 */
#include <stdio.h>

#include "auvmpc_controller.h"

#define ROWS ((AUVMPC_HORIZON + 1) * AUVMPC_NX)

/* The navigation's state estimate now, [x, y, psi, u, v, r] (m, m, rad, m/s, m/s, rad/s),
 * world x north, y east; here a vehicle that drifts slowly along x. */
static void read_state(int k, double state[AUVMPC_NX]) {
    for (int i = 0; i < AUVMPC_NX; ++i) state[i] = 0.0;
    state[0] = 0.05 * k * AUVMPC_SAMPLE_TIME;
}

/* The keep-out discs known now (world position and velocity, radius without the vehicle's:
 * the controller adds it); the nearest AUVMPC_OBSTACLE_SLOTS are used. Returns how many. */
static int read_obstacles(auvmpc_obstacle *obstacles, int capacity) {
    if (capacity < 1) return 0;
    obstacles[0] = (auvmpc_obstacle){{8.0, 0.5}, {0.0, 0.0}, 0.5, 0.0};
    return 1;
}

/* The mission's reference at t_k + i * AUVMPC_SAMPLE_TIME, i = 0..AUVMPC_HORIZON: one row
 * [x, y, psi, u, v, r] per sample; here a straight line north at 0.5 m/s. */
static void reference_preview(double t, double reference[ROWS]) {
    for (int i = 0; i <= AUVMPC_HORIZON; ++i) {
        double *row = reference + i * AUVMPC_NX;
        for (int j = 0; j < AUVMPC_NX; ++j) row[j] = 0.0;
        row[0] = 0.5 * (t + i * AUVMPC_SAMPLE_TIME);
        row[3] = 0.5;
    }
}

/* Hand each horizontal thruster its force (N) for the next AUVMPC_SAMPLE_TIME seconds. */
static void send_thrust(int k, const double thrust[AUVMPC_THRUSTERS], auvmpc_status status) {
    printf("%6.2f s  status %d  thrust", k * AUVMPC_SAMPLE_TIME, (int) status);
    for (int i = 0; i < AUVMPC_THRUSTERS; ++i) printf(" %8.3f", thrust[i]);
    printf(" N\n");
}

int main(void) {
    static const double stopped[AUVMPC_THRUSTERS] = {0};
    static double reference[ROWS];
    static auvmpc_obstacle obstacles[AUVMPC_SLOTS_ALLOC];
    double state[AUVMPC_NX], thrust[AUVMPC_THRUSTERS];

    /* Once, before the loop: lays HPIPM's workspace out in the static arena. Nothing is
     * allocated after this. */
    read_state(0, state);
    if (auvmpc_init(state, stopped)) {
        fprintf(stderr, "auvmpc_init failed: arena too small or a mismatched build\n");
        return 1;
    }
    const int steps = (int) (5.0 / AUVMPC_SAMPLE_TIME);
    for (int k = 0; k < steps; ++k) {
        read_state(k, state); /* sample at t_k */
        int count = read_obstacles(obstacles, (int) (sizeof obstacles / sizeof obstacles[0]));
        reference_preview(k * AUVMPC_SAMPLE_TIME, reference);
        auvmpc_status status = auvmpc_step(state, reference, obstacles, count, thrust);
        /* Every status comes with a command within the thrust and rate limits: FALLBACK and
         * RECOVERY are the safety shell's own (the previous plan's move, then the stabilising
         * feedback), so apply it; log the status, and stop the mission (surface, hold) when
         * FALLBACK or RECOVERY persist. A step past its deadline: apply the previous command
         * and treat it as a FALLBACK. */
        send_thrust(k, thrust, status);
        /* your timer: wait for t_k + AUVMPC_SAMPLE_TIME here */
    }
    return 0;
}
