/* Replays a run through the exported controller and prints its commands.
 *
 *   ./replay RUN_DIR/log.csv replay_data.txt [STEPS [E1,E2,...]] > commands.csv
 *
 * log.csv (written by `auvmpc run`) gives the state the controller saw at every sample
 * (the columns AUVMPC_STATE_NAMES: the true state, so the run must be free of sensor noise);
 * replay_data.txt (written by `auvmpc export-c`) the initial thrust, the reference preview and
 * the obstacles at every sample, computed as the Python closed loop computes them. stdout:
 * k, the command per input (AUVMPC_INPUT_NAMES, %.17g), the status and HPIPM's iterations
 * per sample; stderr: the step time (median, max, max after the cold-started first step, in
 * microseconds), the controller's memory (static, and HPIPM's workspace allocated at init)
 * and the heap calls made inside auvmpc_step (-1: not counted on this C library).
 * E1,E2,...: each thruster's effectiveness, set by auvmpc_set_effectiveness after auvmpc_init
 * (a run whose controller was told it from its first sample: Session.effectiveness).
 */
#define _POSIX_C_SOURCE 199309L
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "auvmpc_controller.h"
#include "replay_common.h"

#define ROWS ((AUVMPC_HORIZON + 1) * AUVMPC_NX)

/* Column indices of the state's entries (AUVMPC_STATE_NAMES) in log.csv's header; 0 on
 * success. */
static int state_columns(const char *header, int columns[AUVMPC_NX]) {
    static const char *names[AUVMPC_NX] = AUVMPC_STATE_NAMES;
    return find_columns(header, names, AUVMPC_NX, columns);
}

int main(int argc, char **argv) {
    if (argc < 3 || argc > 5) {
        fprintf(stderr, "usage: %s LOG_CSV REPLAY_DATA [STEPS [E1,E2,...]]\n", argv[0]);
        return 2;
    }
    double effectiveness[AUVMPC_THRUSTERS];
    if (parse_effectiveness(argc == 5 ? argv[4] : NULL, effectiveness, AUVMPC_THRUSTERS)) return 2;
    FILE *log = fopen(argv[1], "r"), *data = fopen(argv[2], "r");
    if (!log || !data) {
        fprintf(stderr, "replay: cannot open %s\n", !log ? argv[1] : argv[2]);
        return 2;
    }
    static char line[MAX_LINE];
    int columns[AUVMPC_NX], steps, horizon, thrusters;
    if (!fgets(line, MAX_LINE, log) || state_columns(line, columns)) {
        fprintf(stderr, "replay: %s lacks a state column (AUVMPC_STATE_NAMES)\n", argv[1]);
        return 2;
    }
    if (fscanf(data, " auvmpc-replay 1 steps %d horizon %d thrusters %d", &steps, &horizon,
               &thrusters) != 3
        || horizon != AUVMPC_HORIZON || thrusters != AUVMPC_THRUSTERS || steps < 1) {
        fprintf(stderr, "replay: %s was not written for this export\n", argv[2]);
        return 2;
    }
    if (argc >= 4 && atoi(argv[3]) < steps) steps = atoi(argv[3]); /* a shorter run */
    if (steps < 1) return 2;
    double initial_thrust[AUVMPC_THRUSTERS], state[AUVMPC_NX];
    static double reference[ROWS];
    static auvmpc_obstacle obstacles[MAX_OBSTACLES];
    for (int i = 0; i < AUVMPC_THRUSTERS; ++i)
        if (fscanf(data, "%lf", &initial_thrust[i]) != 1) return 2;
    double *times = malloc(sizeof(double) * (size_t) steps);
    if (!times) return 2;
    static const char *inputs[AUVMPC_THRUSTERS] = AUVMPC_INPUT_NAMES;
    printf("k");
    for (int i = 0; i < AUVMPC_THRUSTERS; ++i) printf(",%s", inputs[i]);
    printf(",status,iterations\n");
    int max_iterations = 0;
    for (int k = 0; k < steps; ++k) {
        int count;
        if (!fgets(line, MAX_LINE, log) || read_columns(line, columns, AUVMPC_NX, state)) {
            fprintf(stderr, "replay: %s ends before sample %d\n", argv[1], k);
            return 2;
        }
        for (int i = 0; i < ROWS; ++i)
            if (fscanf(data, "%lf", &reference[i]) != 1) return 2;
        if (fscanf(data, "%d", &count) != 1 || count < 0 || count > MAX_OBSTACLES) return 2;
        for (int o = 0; o < count; ++o) {
            auvmpc_obstacle *ob = &obstacles[o];
            if (fscanf(data, "%lf %lf %lf %lf %lf", &ob->center[0], &ob->center[1],
                       &ob->velocity[0], &ob->velocity[1], &ob->radius) != 5)
                return 2;
        }
        if (k == 0 && auvmpc_init(state, initial_thrust)) {
            fprintf(stderr, "replay: auvmpc_init failed\n");
            return 1;
        }
        if (k == 0 && auvmpc_set_effectiveness(effectiveness)) {
            fprintf(stderr, "replay: an effectiveness outside [0, 1]\n");
            return 2;
        }
        double command[AUVMPC_THRUSTERS];
        struct timespec start, stop;
        if (k == 0 && HEAP_COUNTED) heap_calls = 0;
        /* Only these two clock readings per step: verify-c's instruction counter on an
         * emulated target (qemu_step_counter.c) counts between them. */
        clock_gettime(CLOCK_MONOTONIC, &start);
        counting = 1;
        auvmpc_status status = auvmpc_step(state, reference, obstacles, count, command);
        counting = 0;
        clock_gettime(CLOCK_MONOTONIC, &stop);
        times[k] = 1e6 * (double) (stop.tv_sec - start.tv_sec) + 1e-3 * (double) (stop.tv_nsec - start.tv_nsec);
        printf("%d", k);
        for (int i = 0; i < AUVMPC_THRUSTERS; ++i) printf(",%.17g", command[i]);
        int iterations = auvmpc_last_iterations();
        if (iterations > max_iterations) max_iterations = iterations;
        printf(",%d,%d\n", (int) status, iterations);
    }
    double median, largest, warm_max; /* warm: after the first step, which starts cold */
    summarise(times, steps, &median, &largest, &warm_max);
    fprintf(stderr,
            "steps %d step_us_median %.1f step_us_max %.1f step_us_max_after_first %.1f "
            "static_bytes %ld workspace_bytes %ld heap_calls_in_steps %ld max_iterations %d\n",
            steps, median, largest, warm_max, auvmpc_static_bytes(),
            auvmpc_workspace_bytes(), heap_calls, max_iterations);
    free(times);
    fclose(log);
    fclose(data);
    return 0;
}
