/* machine_noise: what this machine does to a computation that never changes, timed as rt_loop
 * times the controller's steps (the baseline of bench_export.py).
 *
 *   machine_noise MEDIAN_US N   calibrates a fixed chain of floating-point operations to take
 *                               MEDIAN_US at the median, then times N of them back to back with
 *                               rt_loop --steps's scheduling (SCHED_FIFO 80, memory locked, a 3 ms
 *                               rest every 5000) and prints the percentiles in rt_loop's format.
 *
 * The chain does the same work every time (no branch, no memory beyond a few registers), so every
 * microsecond above its median is the machine's: interrupts, the hypervisor, caches refilled after
 * a rest. A controller step's tails at or below these are not the controller's.
 */
#define _POSIX_C_SOURCE 200809L

#include <math.h>
#include <sched.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <time.h>

enum { REST_EVERY = 5000 };
static const long REST_NS = 3000000L;

static double now(void)
{
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return (double)t.tv_sec + 1e-9 * (double)t.tv_nsec;
}

static double chain(long k, double x)
{
    for (long i = 0; i < k; ++i) x = x * 0.999999 + 1e-6;
    return x;
}

static int compare(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

static double median_of(long k, int trials, double *work, volatile double *sink)
{
    for (int t = 0; t < trials; ++t) {
        const double start = now();
        *sink += chain(k, (double)t);
        work[t] = now() - start;
    }
    qsort(work, (size_t)trials, sizeof *work, compare);
    return work[trials / 2];
}

int main(int argc, char **argv)
{
    if (argc != 3) {
        fprintf(stderr, "usage: machine_noise MEDIAN_US N\n");
        return 1;
    }
    const double target = atof(argv[1]) * 1e-6;
    const long n = atol(argv[2]);
    double *times = malloc(sizeof(double) * (size_t)(n > 1001 ? n : 1001));
    volatile double sink = 0.0;
    if (!(target > 0.0) || n < 1 || !times) {
        fprintf(stderr, "machine_noise: expected a positive median (us) and count\n");
        return 1;
    }
    struct sched_param sp;
    memset(&sp, 0, sizeof sp);
    sp.sched_priority = 80;
    const int fifo = sched_setscheduler(0, SCHED_FIFO, &sp) == 0;
    const int locked = mlockall(MCL_CURRENT | MCL_FUTURE) == 0;
    long k = 64;
    for (int round = 0; round < 40; ++round) { /* scale k until the median is within 1 % */
        const double m = median_of(k, 1001, times, &sink);
        const double ratio = target / m;
        if (fabs(ratio - 1.0) < 0.01) break;
        k = (long)((double)k * ratio) + 1;
    }
    const struct timespec rest = {0, REST_NS};
    for (long i = 0; i < n; ++i) {
        if (i > 0 && i % REST_EVERY == 0) nanosleep(&rest, NULL);
        const double start = now();
        sink += chain(k, (double)i);
        times[i] = now() - start;
    }
    qsort(times, (size_t)n, sizeof *times, compare);
    printf("scheduling: %s; memory %s; chain of %ld operations\n", fifo ? "SCHED_FIFO priority 80" : "ordinary",
           locked ? "locked" : "not locked", k);
    const double marks[5] = {0.5, 0.99, 0.999, 0.9999, 1.0};
    printf("step time ");
    for (int i = 0; i < 5; ++i) {
        long at = (long)ceil(marks[i] * (double)n) - 1;
        printf("  %s %8.2f us", i == 0 ? "p50" : i == 1 ? "p99" : i == 2 ? "p99.9" : i == 3 ? "p99.99" : "max",
               1e6 * times[at < 0 ? 0 : at]);
    }
    printf("   (%ld samples)\n", n);
    free(times);
    return sink == 12345.0; /* keeps the chains */
}
