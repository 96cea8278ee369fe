/* rt_loop: the exported controller in a periodic real-time loop, measuring itself.
 *
 *   rt_loop [--seconds S]   a loop at the exported period (1 kHz by default) for S seconds (10):
 *                           wakes on clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME), runs one
 *                           vgtc_step per period; prints the wake-up jitter (how late each period
 *                           started) and the step times as percentiles.
 *   rt_loop ... --feedforward   each step feeds an expected tool force of 20 N forward
 *                           (vgtc_step_feedforward: one more model function, the tip Jacobian).
 *   rt_loop --steps N       N steps back to back: the distribution of the step time. Every
 *                           REST_EVERY steps it rests REST_NS (outside any step's time): a
 *                           SCHED_FIFO thread that never sleeps exceeds the kernel's real-time
 *                           budget (sched_rt_runtime_us, 95 % of each second by default) and is
 *                           stopped for the rest of the second, 50 ms, inside whichever step is
 *                           running. A controller at 1 kHz uses well under 1 % of it.
 *
 * It asks for SCHED_FIFO priority 80 and locks its memory (mlockall) and says whether it got them
 * (both need CAP_SYS_NICE / CAP_IPC_LOCK or an rtprio limit; without them it runs as an ordinary
 * thread, and the jitter shows it). The joints it feeds the controller are the home pose plus a
 * slow sinusoid of 1 mm / 10 mrad, the reference the home pose: no hardware needed.
 *
 * Every argument is checked before anything runs (one line on stderr, exit status 1): --steps a
 * whole number from 1 to RT_MAX_STEPS, --seconds a finite number of seconds making from 1 to
 * RT_MAX_STEPS periods, each option at most once and not both, a value after each.
 */
#define _POSIX_C_SOURCE 200809L

#include <errno.h>
#include <limits.h>
#include <math.h>
#include <sched.h>
#include <stdio.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <time.h>

#include "vgtarm_controller.h"

enum { REST_EVERY = 5000 };            /* steps between two rests of --steps (15 to 25 ms)  */
static const long REST_NS = 3000000L; /* a rest: 3 ms, so the steps take under 95 % of any second */
/* The most steps a run takes (--steps, or --seconds over the period): the times are kept, one
 * double a step (800 MB at most; 1.6 GB with the jitter of --seconds), and at a few microseconds a
 * step it runs for minutes. Also kept below what size_t and long can count (32-bit targets). */
#define RT_MAX_STEPS 100000000L

/* `text` for a message: every byte that is not printable ASCII escaped, cut after 60 bytes (`slot`:
 * one of two buffers, for two values in one message). */
static const char *shown(const char *text, int slot)
{
    static char buffers[2][4 * 60 + 8];
    char *buffer = buffers[slot & 1];
    static const char hex[] = "0123456789abcdef";
    size_t at = 0, i;
    if (!*text) return "\"\" (empty)";
    for (i = 0; text[i] && i < 60; ++i) {
        const unsigned char c = (unsigned char)text[i];
        if (c < 0x20 || c >= 0x7f || c == '\\') {
            buffer[at++] = '\\';
            buffer[at++] = 'x';
            buffer[at++] = hex[c >> 4];
            buffer[at++] = hex[c & 15];
        } else {
            buffer[at++] = (char)c;
        }
    }
    if (text[i]) {
        memcpy(buffer + at, "...", 3);
        at += 3;
    }
    buffer[at] = '\0';
    return buffer;
}

/* A whole number from 1 to `most`: digits only (no sign, space, exponent or fraction). */
static int parse_count(const char *text, long most, long *value)
{
    if (!*text || strspn(text, "0123456789") != strlen(text)) return 0;
    errno = 0;
    char *end;
    const long long n = strtoll(text, &end, 10);
    if (errno == ERANGE || *end || n < 1 || n > most) return 0;
    *value = (long)n;
    return 1;
}

/* A finite number (the whole text, no leading space), not out of double's range. */
static int parse_number(const char *text, double *value)
{
    if (!*text || *text == ' ' || (*text >= '\t' && *text <= '\r')) return 0;
    char *end;
    const double x = strtod(text, &end);
    if (*end || !isfinite(x)) return 0; /* past double's range strtod gives infinity */
    *value = x;
    return 1;
}

static double seconds_between(const struct timespec *a, const struct timespec *b)
{
    return (double)(b->tv_sec - a->tv_sec) + 1e-9 * (double)(b->tv_nsec - a->tv_nsec);
}

static int compare(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

static void report(const char *what, double *values, long n)
{
    qsort(values, (size_t)n, sizeof *values, compare);
    const double marks[5] = {0.5, 0.99, 0.999, 0.9999, 1.0};
    printf("%-10s", what);
    for (int i = 0; i < 5; ++i) {
        long at = (long)ceil(marks[i] * (double)n) - 1;
        if (at < 0) at = 0;
        printf("  %s %8.2f us", i == 0 ? "p50" : i == 1 ? "p99" : i == 2 ? "p99.9" : i == 3 ? "p99.99" : "max",
               1e6 * values[at]);
    }
    printf("   (%ld samples)\n", n);
}

static void inputs(long k, double dt, double *q, double *qd, double *ref)
{
    const double w = 2.0 * 3.14159265358979323846 * 0.5, s = sin(w * (double)k * dt), c = cos(w * (double)k * dt);
    for (int i = 0; i < VGTC_NJ; ++i) {
        const double amplitude = vgtc_joint_is_angle[i] ? 1e-2 : 1e-3;
        q[i] = vgtc_home[i] + amplitude * s;
        qd[i] = amplitude * w * c;
        ref[i] = vgtc_home[i];
        ref[VGTC_NJ + i] = 0.0;
        ref[2 * VGTC_NJ + i] = 0.0;
    }
}

int main(int argc, char **argv)
{
    static vgtc_context ctx;
    vgtc_params params;
    double seconds = 10.0;
    long steps = 0;
    int feedforward = 0;
    const char *seconds_text = NULL, *steps_text = NULL;
    const double f_exp[3] = {0.0, 0.0, -20.0}; /* --feedforward: a 20 N cutting force expected */
    const long most = (uint64_t)RT_MAX_STEPS <= SIZE_MAX / sizeof(double) ? RT_MAX_STEPS
                                                                           : (long)(SIZE_MAX / sizeof(double));
    vgtc_default_params(&params);
    const double dt = params.dt;
    for (int a = 1; a < argc; ++a) {
        const char **value = !strcmp(argv[a], "--seconds") ? &seconds_text : !strcmp(argv[a], "--steps") ? &steps_text
                                                                                                            : NULL;
        if (value) {
            if (a + 1 >= argc) {
                fprintf(stderr, "rt_loop: %s: its value is missing; expected %s\n", argv[a],
                        value == &steps_text ? "a whole number of steps" : "a duration in seconds");
                return 1;
            }
            if (*value) {
                fprintf(stderr, "rt_loop: %s %s, then %s %s: expected the option once\n", argv[a], shown(*value, 0),
                        argv[a], shown(argv[a + 1], 1));
                return 1;
            }
            *value = argv[++a];
        } else if (!strcmp(argv[a], "--feedforward")) {
            feedforward = 1;
        } else {
            fprintf(stderr, "rt_loop: unknown argument %s; expected --seconds S or --steps N, and --feedforward "
                    "(usage: rt_loop [--seconds S | --steps N] [--feedforward])\n", shown(argv[a], 0));
            return 1;
        }
    }
    if (seconds_text && steps_text) {
        fprintf(stderr, "rt_loop: --seconds %s and --steps %s: expected one of them\n", shown(seconds_text, 0),
                shown(steps_text, 1));
        return 1;
    }
    if (steps_text && !parse_count(steps_text, most, &steps)) {
        fprintf(stderr, "rt_loop: --steps %s: expected a whole number of steps from 1 to %ld\n", shown(steps_text, 0),
                most);
        return 1;
    }
    /* periods of --seconds (rounded), from 1 to `most`: seconds / dt fits a long */
    if (seconds_text && (!parse_number(seconds_text, &seconds) || !(seconds / dt + 0.5 >= 1.0)
                         || !(seconds / dt + 0.5 < (double)most + 1.0))) {
        fprintf(stderr, "rt_loop: --seconds %s: expected a duration in seconds from %g to %g (1 to %ld periods of %g "
                "s)\n", shown(seconds_text, 0), 0.5 * dt, (double)most * dt, most, dt);
        return 1;
    }
    int status = vgtc_init(&ctx, &params);
    if (status != VGTC_OK) {
        fprintf(stderr, "rt_loop: vgtc_init: %s\n", vgtc_status_text(status));
        return 1;
    }
    const long n = steps > 0 ? steps : (long)(seconds / dt + 0.5);
    /* the jitter only for the periodic loop (--steps runs back to back) */
    double *step_time = malloc(sizeof(double) * (size_t)n), *jitter = steps == 0 ? malloc(sizeof(double) * (size_t)n)
                                                                                  : NULL;
    if (!step_time || (steps == 0 && !jitter)) {
        fprintf(stderr, "rt_loop: out of memory for %ld samples\n", n);
        return 1;
    }
    struct sched_param sp;
    memset(&sp, 0, sizeof sp);
    sp.sched_priority = 80;
    const int fifo = sched_setscheduler(0, SCHED_FIFO, &sp) == 0;
    const int fifo_errno = errno;
    const int locked = mlockall(MCL_CURRENT | MCL_FUTURE) == 0;
    printf("vgtarm controller for %s: %d joints, %s, dt = %g s\n", VGTC_ROBOT, VGTC_NJ, VGTC_DESCRIPTION, dt);
    printf("scheduling: %s; memory %s\n", fifo ? "SCHED_FIFO priority 80" : strerror(fifo_errno),
           locked ? "locked" : "not locked (mlockall refused)");
    double q[VGTC_NJ], qd[VGTC_NJ], ref[3 * VGTC_NJ], F[VGTC_NJ], sink = 0.0;
    struct timespec next, woke, done;
    clock_gettime(CLOCK_MONOTONIC, &next);
    const long period_ns = (long)(dt * 1e9 + 0.5);
    for (long k = 0; k < n; ++k) {
        inputs(k, dt, q, qd, ref);
        if (steps == 0) {
            next.tv_nsec += period_ns;
            while (next.tv_nsec >= 1000000000L) {
                next.tv_nsec -= 1000000000L;
                ++next.tv_sec;
            }
            while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &next, NULL) == EINTR) {}
        } else if (k > 0 && k % REST_EVERY == 0) {
            const struct timespec rest = {0, REST_NS};
            while (clock_nanosleep(CLOCK_MONOTONIC, 0, &rest, NULL) == EINTR) {}
        }
        clock_gettime(CLOCK_MONOTONIC, &woke);
        status = vgtc_step_feedforward(&ctx, (double)k * dt, q, qd, ref, NULL, feedforward ? f_exp : NULL, NULL, NULL, F);
        clock_gettime(CLOCK_MONOTONIC, &done);
        if (status < 0) {
            fprintf(stderr, "rt_loop: step %ld: %s\n", k, vgtc_status_text(status));
            return 1;
        }
        sink += F[0];
        step_time[k] = seconds_between(&woke, &done);
        if (jitter) jitter[k] = seconds_between(&next, &woke);
    }
    if (steps == 0) report("jitter", jitter, n);
    report("step time", step_time, n);
    if (!isfinite(sink)) printf("(efforts not finite)\n");
    free(step_time);
    free(jitter);
    return 0;
}
