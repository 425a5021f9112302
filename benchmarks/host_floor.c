/* The host's floor: a bare loop paced on clock_nanosleep to absolute deadlines, doing no work
 * (or, with --work-ns N, N ns of its own CPU time after each wake-up: a step's computation).
 *
 *   host_floor [--period-ns N] [--steps N] [--late-ns N] [--priority P] [--work-ns N]
 *              [--pair] [--peer-work-ns N]
 *
 * --pair: the floor of two processes that exchange a message every period, as a run and a rig in a
 * second process do. The probe forks a peer (same policy and priority) connected over TCP on the
 * loopback interface (TCP_NODELAY); after each wake-up the loop spends half its --work-ns, sends 8
 * bytes, waits for the peer's 8-byte answer and spends the other half. The peer answers each message
 * after --peer-work-ns of its own CPU time.
 *
 * Step n may start at t0 + n * period (CLOCK_MONOTONIC, integer nanoseconds: no drift, and a late
 * step does not shift the deadlines after it, as the master's pacer does). A step is late when it
 * starts --late-ns or more after its deadline. --priority P runs the loop under SCHED_FIFO at P
 * (0: not asked); a refusal is reported and the loop runs as it is. Prints one JSON object:
 * {"period_ns", "steps", "late_ns", "late", "late_fraction", "lateness_p99_ns", "lateness_max_ns",
 *  "sched_fifo", "work_ns", "pair", "peer_work_ns"}. Exit status 2 on a bad option, 1 when the
 * pair's link fails. */
#define _GNU_SOURCE
#include <errno.h>
#include <sched.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>
#include <arpa/inet.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <sys/socket.h>
#include <sys/wait.h>

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

static void spend(long long work) {
    long long until = cpu_ns() + work;
    while (cpu_ns() < until) {}
}

static int exact(int fd, char *buf, int n, int sending) {
    int done = 0;
    while (done < n) {
        ssize_t k = sending ? send(fd, buf + done, (size_t)(n - done), 0) : recv(fd, buf + done, (size_t)(n - done), 0);
        if (k > 0) done += (int)k;
        else if (k == 0 || errno != EINTR) return -1;
    }
    return 0;
}

/* The peer of --pair: answer every 8-byte message after `work` ns of CPU time, until the loop closes. */
static void peer(int fd, long long work) {
    char msg[8];
    while (exact(fd, msg, 8, 0) == 0) {
        if (work > 0) spend(work);
        if (exact(fd, msg, 8, 1)) break;
    }
    _exit(0);
}

/* A TCP connection on the loopback interface to a forked peer (-1 with a message when it fails). */
static int paired(long long peer_work, pid_t *child) {
    struct sockaddr_in at = {.sin_family = AF_INET, .sin_addr.s_addr = htonl(INADDR_LOOPBACK)};
    socklen_t len = sizeof at;
    int one = 1, lis = socket(AF_INET, SOCK_STREAM, 0), fd;
    if (lis < 0 || bind(lis, (struct sockaddr *)&at, sizeof at) || listen(lis, 1)
        || getsockname(lis, (struct sockaddr *)&at, &len)) {
        fprintf(stderr, "host_floor: --pair: no loopback listener: %s\n", strerror(errno));
        return -1;
    }
    *child = fork();
    if (*child < 0) { fprintf(stderr, "host_floor: --pair: fork: %s\n", strerror(errno)); return -1; }
    if (*child == 0) {
        close(lis);
        fd = socket(AF_INET, SOCK_STREAM, 0);
        if (fd < 0 || connect(fd, (struct sockaddr *)&at, sizeof at)) _exit(1);
        setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
        peer(fd, peer_work);
    }
    fd = accept(lis, NULL, NULL);
    close(lis);
    if (fd < 0) { fprintf(stderr, "host_floor: --pair: accept: %s\n", strerror(errno)); return -1; }
    setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
    return fd;
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
    long long peer_work = 0, *lateness;
    char fifo[160] = "not requested", msg[8] = {0};
    int i, pair = 0, fd = -1;
    pid_t child = 0;
    for (i = 1; i < argc; i++) {
        if (!strcmp(argv[i], "--pair")) { pair = 1; continue; }
        if (!(option(argc, argv, &i, "--period-ns", 10000, 1000000000, &period)
              || option(argc, argv, &i, "--steps", 1, 10000000, &steps)
              || option(argc, argv, &i, "--late-ns", 1, 1000000000, &late_ns)
              || option(argc, argv, &i, "--priority", 0, 99, &priority)
              || option(argc, argv, &i, "--work-ns", 0, 1000000000, &work)
              || option(argc, argv, &i, "--peer-work-ns", 0, 1000000000, &peer_work))) {
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
    if (pair && (fd = paired(peer_work, &child)) < 0) return 1;
    t0 = now_ns() + period;
    for (n = 0; n < steps; n++) {
        long long deadline = t0 + n * period;
        struct timespec ts = {.tv_sec = deadline / 1000000000LL, .tv_nsec = deadline % 1000000000LL};
        while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, NULL) == EINTR) {}
        lateness[n] = now_ns() - deadline;
        if (lateness[n] >= late_ns) late++;
        if (pair) {
            spend(work / 2);
            if (exact(fd, msg, 8, 1) || exact(fd, msg, 8, 0)) {
                fprintf(stderr, "host_floor: --pair: the peer stopped answering at step %lld\n", n);
                return 1;
            }
            spend(work - work / 2);
        } else if (work > 0) {
            spend(work);
        }
    }
    if (pair) {
        close(fd);
        waitpid(child, NULL, 0);
    }
    qsort(lateness, (size_t)steps, sizeof *lateness, by_value);
    printf("{\"period_ns\": %lld, \"steps\": %lld, \"late_ns\": %lld, \"late\": %lld, \"late_fraction\": %.9g, "
           "\"lateness_p99_ns\": %lld, \"lateness_max_ns\": %lld, \"sched_fifo\": \"%s\", \"work_ns\": %lld, \"pair\": %s, "
           "\"peer_work_ns\": %lld}\n",
           period, steps, late_ns, late, (double)late / (double)steps, lateness[(steps * 99) / 100],
           lateness[steps - 1], fifo, work, pair ? "true" : "false", peer_work);
    free(lateness);
    return 0;
}
