/* A QEMU TCG plugin (qemu-aarch64 -plugin FILE.so,out=PATH): the guest instructions executed
 * between the replay's clock readings, i.e. in each auvmpc_step, for `auvmpc verify-c
 * --instructions` on an emulated target (native targets use valgrind's callgrind).
 *
 * Debian's qemu-user is built with plugin support but ships neither plugins nor the plugin
 * header, so the few declarations of QEMU's stable plugin API (version 1, QEMU 7.2) this
 * uses are written out here. Each translated block adds its instruction count to a counter
 * when it runs (inline, no call); at every clock_gettime system call (the replay reads the
 * clock just before and just after each step; QEMU 7.2's linux-user has no vDSO, so each
 * reading is a system call) the counter is recorded. PATH gets one count per reading.
 */
#include <inttypes.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

typedef uint64_t qemu_plugin_id_t;
struct qemu_info_t;
struct qemu_plugin_tb;
enum qemu_plugin_op { QEMU_PLUGIN_INLINE_ADD_U64 };

void qemu_plugin_register_vcpu_tb_trans_cb(qemu_plugin_id_t id,
                                           void (*cb)(qemu_plugin_id_t, struct qemu_plugin_tb *));
size_t qemu_plugin_tb_n_insns(const struct qemu_plugin_tb *tb);
void qemu_plugin_register_vcpu_tb_exec_inline(struct qemu_plugin_tb *tb, enum qemu_plugin_op op,
                                              void *ptr, uint64_t imm);
void qemu_plugin_register_vcpu_syscall_cb(
    qemu_plugin_id_t id,
    void (*cb)(qemu_plugin_id_t, unsigned int, int64_t, uint64_t, uint64_t, uint64_t, uint64_t,
               uint64_t, uint64_t, uint64_t, uint64_t));
void qemu_plugin_register_atexit_cb(qemu_plugin_id_t id, void (*cb)(qemu_plugin_id_t, void *),
                                    void *userdata);

#define EXPORT __attribute__((visibility("default")))
EXPORT int qemu_plugin_version = 1;

#define CLOCK_GETTIME_AARCH64 113 /* asm-generic/unistd.h: __NR_clock_gettime */
#define MAX_READINGS (1 << 22)

static uint64_t executed; /* the replay is single-threaded: one vCPU */
static uint64_t *readings;
static size_t count;
static FILE *out;

static void translated(qemu_plugin_id_t id, struct qemu_plugin_tb *tb) {
    (void) id;
    qemu_plugin_register_vcpu_tb_exec_inline(tb, QEMU_PLUGIN_INLINE_ADD_U64, &executed,
                                             qemu_plugin_tb_n_insns(tb));
}

static void syscall_entered(qemu_plugin_id_t id, unsigned int vcpu, int64_t number, uint64_t a1,
                            uint64_t a2, uint64_t a3, uint64_t a4, uint64_t a5, uint64_t a6,
                            uint64_t a7, uint64_t a8) {
    (void) id, (void) vcpu, (void) a1, (void) a2, (void) a3, (void) a4;
    (void) a5, (void) a6, (void) a7, (void) a8;
    if (number == CLOCK_GETTIME_AARCH64 && count < MAX_READINGS) readings[count++] = executed;
}

static void finished(qemu_plugin_id_t id, void *user) {
    (void) id, (void) user;
    for (size_t i = 0; i < count; ++i) fprintf(out, "%" PRIu64 "\n", readings[i]);
    fclose(out);
    free(readings);
}

EXPORT int qemu_plugin_install(qemu_plugin_id_t id, const struct qemu_info_t *info, int argc,
                               char **argv) {
    (void) info;
    if (argc != 1 || strncmp(argv[0], "out=", 4) != 0) {
        fprintf(stderr, "qemu_step_counter: give out=PATH\n");
        return -1;
    }
    out = fopen(argv[0] + 4, "w");
    readings = malloc(MAX_READINGS * sizeof *readings);
    if (!out || !readings) return -1;
    qemu_plugin_register_vcpu_tb_trans_cb(id, translated);
    qemu_plugin_register_vcpu_syscall_cb(id, syscall_entered);
    qemu_plugin_register_atexit_cb(id, finished, NULL);
    return 0;
}
