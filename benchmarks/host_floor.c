/* The host's floor: a bare loop paced on clock_nanosleep to absolute deadlines, doing no work
 * (or, with --work-ns N, N ns of its own CPU time after each wake-up: a step's computation).
 *
 *   host_floor [--period-ns N] [--steps N] [--late-ns N] [--priority P] [--work-ns N]
 *
 * Step n may start at t0 + n * period (CLOCK_MONOTONIC, integer nanoseconds: no drift, and a late
 * step does not shift the deadlines after it, as the master's pacer does). A step is late when it
 * starts --late-ns or more after its deadline. --priority P runs the loop under SCHED_FIFO at P
 * (0: not asked); a refusal is reported and the loop runs as it is. Prints one JSON object:
 * {"period_ns", "steps", "late_ns", "late", "late_fraction", "lateness_p99_ns", "lateness_max_ns",
 *  "sched_fifo", "work_ns"}. Exit status 2 on a bad option. */
#define _GNU_SOURCE
#include <errno.h>
#include <sched.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

static long long now_ns(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (long long)ts.tv_sec * 1000000000LL + ts.tv_nsec;
}

static long long cpu_ns(void) {
    struct timespec ts;
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
    return (long long)ts.tv_sec * 1000000000LL + ts.tv_nsec;
}

static int by_value(const void *a, const void *b) {
    long long x = *(const long long *)a, y = *(const long long *)b;
    return (x > y) - (x < y);
}

static int option(int argc, char **argv, int *i, const char *name, long long lo, long long hi, long long *out) {
    char *end;
    if (strcmp(argv[*i], name)) return 0;
    if (*i + 1 >= argc) { fprintf(stderr, "host_floor: %s needs a value\n", name); exit(2); }
    errno = 0;
    *out = strtoll(argv[++*i], &end, 10);
    if (errno || *end || *out < lo || *out > hi) {
        fprintf(stderr, "host_floor: %s %s: expected an integer in [%lld, %lld]\n", name, argv[*i], lo, hi);
        exit(2);
    }
    return 1;
}

int main(int argc, char **argv) {
    long long period = 1000000, steps = 5000, late_ns = 500000, priority = 0, work = 0, n, late = 0, t0;
    long long *lateness;
    char fifo[160] = "not requested";
    int i;
    for (i = 1; i < argc; i++) {
        if (!(option(argc, argv, &i, "--period-ns", 10000, 1000000000, &period)
              || option(argc, argv, &i, "--steps", 1, 10000000, &steps)
              || option(argc, argv, &i, "--late-ns", 1, 1000000000, &late_ns)
              || option(argc, argv, &i, "--priority", 0, 99, &priority)
              || option(argc, argv, &i, "--work-ns", 0, 1000000000, &work))) {
            fprintf(stderr, "host_floor: unknown option %s\n", argv[i]);
            return 2;
        }
    }
    if (priority > 0) {
        struct sched_param sp = {.sched_priority = (int)priority};
        if (sched_setscheduler(0, SCHED_FIFO, &sp) == 0)
            snprintf(fifo, sizeof fifo, "applied: SCHED_FIFO priority %lld", priority);
        else
            snprintf(fifo, sizeof fifo, "not applied: SCHED_FIFO priority %lld: %s", priority, strerror(errno));
    }
    lateness = malloc((size_t)steps * sizeof *lateness);
    if (!lateness) { fprintf(stderr, "host_floor: out of memory\n"); return 1; }
    t0 = now_ns() + period;
    for (n = 0; n < steps; n++) {
        long long deadline = t0 + n * period;
        struct timespec ts = {.tv_sec = deadline / 1000000000LL, .tv_nsec = deadline % 1000000000LL};
        while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, NULL) == EINTR) {}
        lateness[n] = now_ns() - deadline;
        if (lateness[n] >= late_ns) late++;
        if (work > 0) {
            long long until = cpu_ns() + work;
            while (cpu_ns() < until) {}
        }
    }
    qsort(lateness, (size_t)steps, sizeof *lateness, by_value);
    printf("{\"period_ns\": %lld, \"steps\": %lld, \"late_ns\": %lld, \"late\": %lld, \"late_fraction\": %.9g, "
           "\"lateness_p99_ns\": %lld, \"lateness_max_ns\": %lld, \"sched_fifo\": \"%s\", \"work_ns\": %lld}\n",
           period, steps, late_ns, late, (double)late / (double)steps, lateness[(steps * 99) / 100],
           lateness[steps - 1], fifo, work);
    free(lateness);
    return 0;
}
