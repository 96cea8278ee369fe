/* ga_timing: the time of switching control's GA activations (vgtc_ga.h), measured.
 *
 *   ga_timing [ACTIVATIONS]   (default 1000) activations back to back, each from a state 0.3 mm /
 *                             3 mrad off a reference that moves every joint along a sinusoid of
 *                             2 mm / 20 mrad at 1 Hz around the home pose, over the exported
 *                             horizon, each with its own seed; prints the activation times as
 *                             percentiles and how many exceeded the control period.
 *
 * It asks for SCHED_FIFO priority 80 and locks its memory as rt_loop does (and says whether it got
 * them). The GA's memory is one static vgtc_ga: nothing is allocated per activation.
 *
 * ACTIVATIONS is checked before anything runs: a whole number (digits only) from 1 to
 * GA_MAX_ACTIVATIONS, else one line on stderr and exit status 1.
 */
#define _POSIX_C_SOURCE 200809L

#include <errno.h>
#include <math.h>
#include <sched.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <time.h>

#include "vgtc_ga.h"
#include "vgtarm_controller.h"

/* The most activations a run takes: one double of time each (80 MB), and at a millisecond or so
 * an activation, hours of running. Below what size_t and long can count on 32-bit targets too. */
#define GA_MAX_ACTIVATIONS 10000000L

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

/* `text` for a message: every byte that is not printable ASCII escaped, cut after 60 bytes. */
static const char *shown(const char *text)
{
    static char buffer[4 * 60 + 8];
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

static double seconds_between(const struct timespec *a, const struct timespec *b)
{
    return (double)(b->tv_sec - a->tv_sec) + 1e-9 * (double)(b->tv_nsec - a->tv_nsec);
}

static int compare(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

/* A reproducible offset in [-1, 1) (splitmix64 of the index). */
static double offset(uint64_t i)
{
    uint64_t z = (i + 1) * 0x9E3779B97F4A7C15ULL;
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ULL;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBULL;
    z ^= z >> 31;
    return (double)(z >> 11) * 0x1.0p-52 - 1.0;
}

int main(int argc, char **argv)
{
    static vgtc_ga ga;
    static double ref[(VGTC_GA_HORIZON + 1) * 3 * VGTC_NJ];
    vgtc_ga_params params;
    double q0[VGTC_NJ], qd0[VGTC_NJ], gains[VGTC_GA_GENES];
    long n = 1000, over = 0, exact = 0;
    double *times;
    int rt, locked;
    if (argc > 2) {
        fprintf(stderr, "ga_timing: %d arguments; usage: ga_timing [ACTIVATIONS (a whole number from 1 to %ld)]\n",
                argc - 1, GA_MAX_ACTIVATIONS);
        return 1;
    }
    if (argc == 2 && !parse_count(argv[1], GA_MAX_ACTIVATIONS, &n)) {
        fprintf(stderr, "ga_timing: ACTIVATIONS %s: expected a whole number from 1 to %ld\n", shown(argv[1]),
                GA_MAX_ACTIVATIONS);
        return 1;
    }
    vgtc_ga_default_params(&params);
    if (vgtc_ga_init(&ga, &params) != VGTC_GA_OK) {
        fprintf(stderr, "ga_timing: the exported GA parameters are out of range\n");
        return 1;
    }
    times = malloc(sizeof(double) * (size_t)n); /* the program's record, not the GA's memory */
    if (!times) {
        fprintf(stderr, "ga_timing: no memory for %ld times\n", n);
        return 1;
    }
    {
        struct sched_param sp;
        memset(&sp, 0, sizeof sp);
        sp.sched_priority = 80;
        rt = sched_setscheduler(0, SCHED_FIFO, &sp) == 0;
        locked = mlockall(MCL_CURRENT | MCL_FUTURE) == 0;
    }
    for (long a = 0; a < n; ++a) {
        const double w = 2.0 * 3.14159265358979323846, dt = params.dt;
        struct timespec t0, t1;
        vgtc_ga_result out;
        for (long j = 0; j <= params.horizon; ++j) {
            const double t = (double)(a * 7 + j) * dt;
            for (int i = 0; i < VGTC_NJ; ++i) {
                const double amplitude = vgtc_joint_is_angle[i] ? 2e-2 : 2e-3;
                double *row = ref + j * 3 * VGTC_NJ;
                row[i] = vgtc_home[i] + amplitude * sin(w * t);
                row[VGTC_NJ + i] = amplitude * w * cos(w * t);
                row[2 * VGTC_NJ + i] = -amplitude * w * w * sin(w * t);
            }
        }
        for (int i = 0; i < VGTC_NJ; ++i) {
            const double scale = vgtc_joint_is_angle[i] ? 3e-3 : 3e-4;
            q0[i] = ref[i] + scale * offset((uint64_t)a * (2 * VGTC_NJ) + (uint64_t)i);
            qd0[i] = ref[VGTC_NJ + i] + 10.0 * scale * offset((uint64_t)a * (2 * VGTC_NJ) + (uint64_t)(VGTC_NJ + i));
        }
        clock_gettime(CLOCK_MONOTONIC, &t0);
        const int status = vgtc_ga_activate(&ga, params.horizon, q0, qd0, ref, NULL, (uint64_t)a + 1, gains, &out);
        clock_gettime(CLOCK_MONOTONIC, &t1);
        if (status != VGTC_GA_OK) {
            fprintf(stderr, "ga_timing: activation %ld failed (status %d)\n", a, status);
            free(times);
            return 1;
        }
        times[a] = seconds_between(&t0, &t1);
        over += times[a] > params.dt;
        exact += out.exact_steps > 0;
    }
    printf("GA of %d x %d generations, horizon %ld, %s prediction%s: %ld activations (%s, %s)\n", params.population,
           params.generations, params.horizon, params.quadratic ? "quadratic" : "linear",
           params.safe ? ", safe variant" : "", n, rt ? "SCHED_FIFO 80" : "no real-time priority",
           locked ? "memory locked" : "memory not locked");
    qsort(times, (size_t)n, sizeof *times, compare);
    {
        const double marks[4] = {0.5, 0.99, 0.999, 1.0};
        const char *names[4] = {"p50", "p99", "p99.9", "max"};
        printf("activation");
        for (int i = 0; i < 4; ++i) {
            long at = (long)ceil(marks[i] * (double)n) - 1;
            if (at < 0) at = 0;
            printf("  %s %8.1f us", names[i], 1e6 * times[at]);
        }
        printf("\nlonger than the period (%g ms): %ld of %ld; with exact steps: %ld\n", 1e3 * params.dt, over, n,
               exact);
    }
    free(times);
    return 0;
}
