/* Replays recorded inputs through the drilling controller: one line per control period on stdin,
 * "t q_meas[0] ... q_meas[VGTD_NJ - 1] sensor_thrust" (numbers as strtod reads them, hexadecimal
 * floating point for exact values), one line per period on stdout: the efforts F[0] ...
 * F[VGTD_NJ - 1], the thrust fed back, the observer's thrust and the axial push in hexadecimal
 * floating point (%a: every bit), then the phase. Exit status 0; 1 on a malformed line (its number
 * on stderr) or a failed step; 2 on a line longer than the buffer. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "vgtd_controller.h"

#define VGTD_LINE (64 * (VGTD_NJ + 4))

static vgtd_context context;

int main(void)
{
    static char line[VGTD_LINE];
    double values[VGTD_NJ + 2], F[VGTD_NJ];
    long number = 0;
    vgtd_init(&context);
    while (fgets(line, sizeof line, stdin)) {
        ++number;
        if (!strchr(line, '\n') && !feof(stdin)) {
            fprintf(stderr, "line %ld: longer than %d characters\n", number, VGTD_LINE - 2);
            return 2;
        }
        char *cursor = line, *end = NULL;
        for (int i = 0; i < VGTD_NJ + 2; ++i) {
            values[i] = strtod(cursor, &end);
            if (end == cursor) {
                fprintf(stderr, "line %ld: expected %d numbers (t, %d readings, the sensor's thrust)\n", number,
                        VGTD_NJ + 2, VGTD_NJ);
                return 1;
            }
            cursor = end;
        }
        vgt_drill_output out;
        int status = vgtd_step(&context, values[0], values + 1, values[VGTD_NJ + 1], F, &out);
        if (status < 0) {
            fprintf(stderr, "line %ld: the controller failed\n", number);
            return 1;
        }
        for (int i = 0; i < VGTD_NJ; ++i) printf("%a ", F[i]);
        printf("%a %a %a %d\n", out.estimate, out.observed, out.push, context.state.phase);
    }
    return 0;
}
