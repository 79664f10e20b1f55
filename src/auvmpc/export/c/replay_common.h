/* What the replay programs share (replay.c, and a six-dof export's replay.c): the heap calls
 * counted, log.csv's columns read by name, the step times summarised. Included once per
 * program: it defines the C library's allocator functions.
 *
 * The heap calls inside a step, counted: this program's malloc, calloc, realloc and free (and
 * the aligned posix_memalign, aligned_alloc, memalign) replace the C library's for the whole
 * process (HPIPM's, BLASFEO's and DAQP's shared libraries included: glibc's documented way to
 * replace malloc) and hand on to glibc's own allocator. On another C library nothing is
 * replaced and the count reads -1. */
#ifndef AUVMPC_REPLAY_COMMON_H
#define AUVMPC_REPLAY_COMMON_H

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static long heap_calls = -1;
static int counting;
#ifdef __GLIBC__
extern void *__libc_malloc(size_t size);
extern void *__libc_calloc(size_t count, size_t size);
extern void *__libc_realloc(void *pointer, size_t size);
extern void __libc_free(void *pointer);
extern void *__libc_memalign(size_t alignment, size_t size);

void *malloc(size_t size) {
    heap_calls += counting;
    return __libc_malloc(size);
}
void *calloc(size_t count, size_t size) {
    heap_calls += counting;
    return __libc_calloc(count, size);
}
void *realloc(void *pointer, size_t size) {
    heap_calls += counting;
    return __libc_realloc(pointer, size);
}
void free(void *pointer) {
    heap_calls += counting && pointer;
    __libc_free(pointer);
}
/* The aligned allocators too: BLASFEO's own allocation is aligned (posix_memalign). */
int posix_memalign(void **pointer, size_t alignment, size_t size) {
    heap_calls += counting;
    *pointer = __libc_memalign(alignment, size);
    return *pointer || !size ? 0 : 12; /* ENOMEM */
}
void *aligned_alloc(size_t alignment, size_t size) {
    heap_calls += counting;
    return __libc_memalign(alignment, size);
}
void *memalign(size_t alignment, size_t size) {
    heap_calls += counting;
    return __libc_memalign(alignment, size);
}
#define HEAP_COUNTED 1
#else
#define HEAP_COUNTED 0
#endif

#define MAX_LINE 65536
#define MAX_OBSTACLES 256

static int compare(const void *a, const void *b) {
    double x = *(const double *) a, y = *(const double *) b;
    return (x > y) - (x < y);
}

/* Column indices of `names` (count of them) in log.csv's header; 0 when all are there. */
/* The replay's optional effectiveness argument: ``count`` comma-separated numbers into
 * ``values`` (all 1 when ``text`` is NULL); 0 on success, else a line on stderr. */
static int parse_effectiveness(const char *text, double *values, int count) {
    for (int i = 0; i < count; ++i) values[i] = 1.0;
    if (text == NULL) return 0;
    const char *p = text;
    for (int i = 0; i < count; ++i) {
        char *end;
        values[i] = strtod(p, &end);
        if (end == p || (i + 1 < count && *end != ',')) {
            fprintf(stderr, "replay: %s is not %d comma-separated numbers\n", text, count);
            return 2;
        }
        p = end + 1;
    }
    return 0;
}

static int find_columns(const char *header, const char *const *names, int count, int *columns) {
    char line[MAX_LINE];
    strncpy(line, header, MAX_LINE - 1);
    line[MAX_LINE - 1] = '\0';
    for (int i = 0; i < count; ++i) columns[i] = -1;
    int column = 0;
    for (char *name = strtok(line, ",\r\n"); name; name = strtok(NULL, ",\r\n"), ++column)
        for (int i = 0; i < count; ++i)
            if (strcmp(name, names[i]) == 0) columns[i] = column;
    for (int i = 0; i < count; ++i)
        if (columns[i] < 0) return -1;
    return 0;
}

/* The values of those columns in a row of log.csv; 0 when all were read. */
static int read_columns(const char *row, const int *columns, int count, double *values) {
    int column = 0, found = 0;
    const char *p = row;
    while (*p && found < count) {
        for (int i = 0; i < count; ++i)
            if (columns[i] == column) {
                values[i] = strtod(p, NULL);
                ++found;
            }
        p = strchr(p, ',');
        if (!p) break;
        ++p;
        ++column;
    }
    return found == count ? 0 : -1;
}

/* The median and the largest of times[0..steps) (sorted in place) and the largest after the
 * first, cold-started step. */
static void summarise(double *times, int steps, double *median, double *largest,
                      double *after_first) {
    *after_first = 0.0;
    for (int k = 1; k < steps; ++k)
        if (times[k] > *after_first) *after_first = times[k];
    qsort(times, (size_t) steps, sizeof(double), compare);
    *median = steps % 2 ? times[steps / 2] : 0.5 * (times[steps / 2 - 1] + times[steps / 2]);
    *largest = times[steps - 1];
}

#endif
