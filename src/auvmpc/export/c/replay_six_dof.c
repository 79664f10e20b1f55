/* Replays a six-dof run through the exported pair (auvmpc_six_dof.h) and prints its commands;
 * a six-dof export's replay.c.
 *
 *   ./replay RUN_DIR/log.csv replay_data.txt [STEPS [E1,E2,...]] > commands.csv
 *
 * log.csv (written by `auvmpc run`) gives the true 6-DOF state at every sample (the run must
 * be free of sensor noise), from which the measurement is formed as the Python sensor forms it
 * (sim/plant.py, SixDofSensor): [x, y, psi, u, v, r], the depth z and the depth rate (NED,
 * models/six_dof.py, depth_rate); replay_data.txt (written by `auvmpc export-c`) the initial
 * thrust, the 3-D reference preview and the obstacles at every sample. stdout: k, every
 * thruster's command (AUVMPC_SIX_DOF_INPUT_NAMES, %.17g), the horizontal status and HPIPM's
 * iterations, the depth status and DAQP's iterations, the thrusters the mapping saturated;
 * stderr: as replay.c's, and the depth channel's largest iterations.
 * E1,E2,...: every thruster's effectiveness, set by auvmpc_six_dof_set_effectiveness after
 * auvmpc_six_dof_init.
 */
#define _POSIX_C_SOURCE 199309L
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "auvmpc_six_dof.h"
#include "replay_common.h"

#define NT AUVMPC_SIX_DOF_THRUSTERS
#define NS AUVMPC_SIX_DOF_STATES

/* The measurement the Python sensor makes of a true 6-DOF state without noise. */
static void measure(const double state[NS], double measured[AUVMPC_SIX_DOF_NM]) {
    static const int horizontal[AUVMPC_NX] = AUVMPC_SIX_DOF_HORIZONTAL_STATES;
    for (int i = 0; i < AUVMPC_NX; ++i) measured[i] = state[horizontal[i]];
    double phi = state[AUVMPC_SIX_DOF_STATE_PHI], theta = state[AUVMPC_SIX_DOF_STATE_THETA];
    double u = state[AUVMPC_SIX_DOF_STATE_U], v = state[AUVMPC_SIX_DOF_STATE_V];
    double w = state[AUVMPC_SIX_DOF_STATE_W];
    measured[AUVMPC_SIX_DOF_DEPTH] = state[AUVMPC_SIX_DOF_STATE_Z];
    measured[AUVMPC_SIX_DOF_DEPTH_RATE] =
        -sin(theta) * u + cos(theta) * sin(phi) * v + cos(theta) * cos(phi) * w;
}

int main(int argc, char **argv) {
    if (argc < 3 || argc > 5) {
        fprintf(stderr, "usage: %s LOG_CSV REPLAY_DATA [STEPS [E1,E2,...]]\n", argv[0]);
        return 2;
    }
    double effectiveness[NT];
    if (parse_effectiveness(argc == 5 ? argv[4] : NULL, effectiveness, NT)) return 2;
    FILE *log = fopen(argv[1], "r"), *data = fopen(argv[2], "r");
    if (!log || !data) {
        fprintf(stderr, "replay: cannot open %s\n", !log ? argv[1] : argv[2]);
        return 2;
    }
    static char line[MAX_LINE];
    static const char *state_names[NS] = AUVMPC_SIX_DOF_STATE_NAMES;
    int columns[NS], steps, preview, thrusters;
    if (!fgets(line, MAX_LINE, log) || find_columns(line, state_names, NS, columns)) {
        fprintf(stderr, "replay: %s lacks a state column (AUVMPC_SIX_DOF_STATE_NAMES)\n", argv[1]);
        return 2;
    }
    if (fscanf(data, " auvmpc-replay-six-dof 1 steps %d preview %d thrusters %d", &steps,
               &preview, &thrusters) != 3
        || preview != AUVMPC_SIX_DOF_PREVIEW || thrusters != NT || steps < 1) {
        fprintf(stderr, "replay: %s was not written for this export\n", argv[2]);
        return 2;
    }
    if (argc >= 4 && atoi(argv[3]) < steps) steps = atoi(argv[3]); /* a shorter run */
    if (steps < 1) return 2;
    double initial_thrust[NT], state[NS], measured[AUVMPC_SIX_DOF_NM];
    static double reference[AUVMPC_SIX_DOF_ROWS];
    static auvmpc_obstacle obstacles[MAX_OBSTACLES];
    for (int i = 0; i < NT; ++i)
        if (fscanf(data, "%lf", &initial_thrust[i]) != 1) return 2;
    double *times = malloc(sizeof(double) * (size_t) steps);
    if (!times) return 2;
    static const char *inputs[NT] = AUVMPC_SIX_DOF_INPUT_NAMES;
    printf("k");
    for (int i = 0; i < NT; ++i) printf(",%s", inputs[i]);
    printf(",status,iterations,depth_status,depth_iterations,saturated\n");
    int max_iterations = 0, depth_max_iterations = 0;
    for (int k = 0; k < steps; ++k) {
        int count;
        if (!fgets(line, MAX_LINE, log) || read_columns(line, columns, NS, state)) {
            fprintf(stderr, "replay: %s ends before sample %d\n", argv[1], k);
            return 2;
        }
        measure(state, measured);
        for (int i = 0; i < AUVMPC_SIX_DOF_ROWS; ++i)
            if (fscanf(data, "%lf", &reference[i]) != 1) return 2;
        if (fscanf(data, "%d", &count) != 1 || count < 0 || count > MAX_OBSTACLES) return 2;
        for (int o = 0; o < count; ++o) {
            auvmpc_obstacle *ob = &obstacles[o];
            if (fscanf(data, "%lf %lf %lf %lf %lf", &ob->center[0], &ob->center[1],
                       &ob->velocity[0], &ob->velocity[1], &ob->radius) != 5)
                return 2;
        }
        if (k == 0 && auvmpc_six_dof_init(measured, initial_thrust)) {
            fprintf(stderr, "replay: auvmpc_six_dof_init failed\n");
            return 1;
        }
        if (k == 0 && argc == 5 && auvmpc_six_dof_set_effectiveness(effectiveness)) {
            fprintf(stderr, "replay: an effectiveness outside [0, 1]\n");
            return 2;
        }
        double command[NT];
        struct timespec start, stop;
        if (k == 0 && HEAP_COUNTED) heap_calls = 0;
        /* Only these two clock readings per step: verify-c's instruction counter on an
         * emulated target (qemu_step_counter.c) counts between them. */
        clock_gettime(CLOCK_MONOTONIC, &start);
        counting = 1;
        auvmpc_six_dof_status status =
            auvmpc_six_dof_step(measured, reference, obstacles, count, command);
        counting = 0;
        clock_gettime(CLOCK_MONOTONIC, &stop);
        times[k] = 1e6 * (double) (stop.tv_sec - start.tv_sec) + 1e-3 * (double) (stop.tv_nsec - start.tv_nsec);
        printf("%d", k);
        for (int i = 0; i < NT; ++i) printf(",%.17g", command[i]);
        int iterations = auvmpc_last_iterations(), depth_iterations = auvmpc_depth_last_iterations();
        if (iterations > max_iterations) max_iterations = iterations;
        if (depth_iterations > depth_max_iterations) depth_max_iterations = depth_iterations;
        printf(",%d,%d,%d,%d,%d\n", (int) status.horizontal, iterations, (int) status.depth,
               depth_iterations, status.saturated);
    }
    double median, largest, after_first;
    summarise(times, steps, &median, &largest, &after_first);
    fprintf(stderr,
            "steps %d step_us_median %.1f step_us_max %.1f step_us_max_after_first %.1f "
            "static_bytes %ld workspace_bytes %ld heap_calls_in_steps %ld max_iterations %d "
            "depth_max_iterations %d\n",
            steps, median, largest, after_first, auvmpc_six_dof_static_bytes(),
            auvmpc_six_dof_workspace_bytes(), heap_calls, max_iterations, depth_max_iterations);
    free(times);
    fclose(log);
    fclose(data);
    return 0;
}
