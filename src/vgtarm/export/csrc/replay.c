/* replay: run the exported controller over recorded measurements (see README.md for the formats).
 *
 *   replay REFERENCE.csv MEASUREMENTS.csv EFFORTS.csv
 *
 * Row k of REFERENCE.csv is period k's reference (t, q_d, qd_d, qdd_d, and optionally the tool
 * force the path's cutting model expects, f_exp_x, f_exp_y, f_exp_z, fed forward: the header says
 * which); row k of MEASUREMENTS.csv what was measured then (t, q, qd, f). Every period is one
 * vgtc_step_feedforward (f_exp NULL without those columns); EFFORTS.csv gets t, the
 * efforts, the estimate of the external efforts and the status, numbers written with 17
 * significant digits (they read back exactly). Exit status 0, or 1 with one line on stderr.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "vgtarm_controller.h"

#define REF_COLUMNS (1 + 3 * VGTC_NJ)
#define MEAS_COLUMNS (1 + 2 * VGTC_NJ + 3)
#define MAX_LINE 65536

/* Read one data row of `columns` numbers separated by commas; 1 on success, 0 at the end of the
 * file, -1 on a malformed row (the message in `why`). */
static int read_row(FILE *in, int columns, double *values, char *line, const char **why)
{
    if (!fgets(line, MAX_LINE, in)) return 0;
    if (!strchr(line, '\n') && !feof(in)) {
        *why = "a line is longer than 65536 characters";
        return -1;
    }
    char *cursor = line;
    for (int i = 0; i < columns; ++i) {
        char *end;
        values[i] = strtod(cursor, &end);
        if (end == cursor) {
            *why = "a field is not a number";
            return -1;
        }
        while (*end == ' ' || *end == '\t') ++end;
        if (i + 1 < columns) {
            if (*end != ',') {
                *why = "a row has too few columns";
                return -1;
            }
            cursor = end + 1;
        } else if (*end != '\n' && *end != '\r' && *end != '\0') {
            *why = "a row has too many columns";
            return -1;
        }
    }
    return 1;
}

static int skip_header(FILE *in, char *line) { return fgets(line, MAX_LINE, in) != NULL; }

/* The fields of a header line (commas + 1). */
static int header_fields(const char *line)
{
    int fields = 1;
    for (; *line; ++line) fields += *line == ',';
    return fields;
}

int main(int argc, char **argv)
{
    static char line[MAX_LINE];
    static vgtc_context ctx;
    vgtc_params params;
    if (argc != 4) {
        fprintf(stderr, "usage: replay REFERENCE.csv MEASUREMENTS.csv EFFORTS.csv\n");
        return 1;
    }
    FILE *ref = fopen(argv[1], "r"), *meas = fopen(argv[2], "r");
    if (!ref || !meas) {
        fprintf(stderr, "replay: cannot read %s\n", !ref ? argv[1] : argv[2]);
        return 1;
    }
    if (!skip_header(ref, line)) {
        fprintf(stderr, "replay: %s is empty; expected a header line and rows\n", argv[1]);
        return 1;
    }
    const int ref_columns = header_fields(line), expected = ref_columns == REF_COLUMNS + 3;
    if (ref_columns != REF_COLUMNS && !expected) {
        fprintf(stderr, "replay: %s has %d columns in its header; expected %d (t, q_d, qd_d, qdd_d) or %d (and the "
                "expected tool force f_exp_x, f_exp_y, f_exp_z)\n", argv[1], ref_columns, REF_COLUMNS, REF_COLUMNS + 3);
        return 1;
    }
    if (!skip_header(meas, line)) {
        fprintf(stderr, "replay: %s is empty; expected a header line and rows\n", argv[2]);
        return 1;
    }
    FILE *out = fopen(argv[3], "w");
    if (!out) {
        fprintf(stderr, "replay: cannot write %s\n", argv[3]);
        return 1;
    }
    vgtc_default_params(&params);
    int status = vgtc_init(&ctx, &params);
    if (status != VGTC_OK) {
        fprintf(stderr, "replay: vgtc_init: %s\n", vgtc_status_text(status));
        return 1;
    }
    fprintf(out, "t");
    for (int i = 0; i < VGTC_NJ; ++i) fprintf(out, ",F_%d", i + 1);
    for (int i = 0; i < VGTC_NJ; ++i) fprintf(out, ",tau_hat_%d", i + 1);
    fprintf(out, ",status\n");
    double r[REF_COLUMNS + 3], m[MEAS_COLUMNS], F[VGTC_NJ];
    long row = 0;
    for (;;) {
        const char *why = NULL;
        int got_ref = read_row(ref, ref_columns, r, line, &why);
        if (got_ref < 0) {
            fprintf(stderr, "replay: %s row %ld: %s (expected %d numbers)\n", argv[1], row + 1, why, ref_columns);
            return 1;
        }
        int got_meas = read_row(meas, MEAS_COLUMNS, m, line, &why);
        if (got_meas < 0) {
            fprintf(stderr, "replay: %s row %ld: %s (expected %d numbers)\n", argv[2], row + 1, why, MEAS_COLUMNS);
            return 1;
        }
        if (!got_ref || !got_meas) {
            if (got_ref != got_meas) {
                fprintf(stderr, "replay: %s ends at row %ld, the other file goes on\n", !got_ref ? argv[1] : argv[2], row);
                return 1;
            }
            break;
        }
        const double *q = m + 1, *qd = m + 1 + VGTC_NJ, *f = m + 1 + 2 * VGTC_NJ;
        const int have_qd = !isnan(qd[0]), have_f = !isnan(f[0]);
        status = vgtc_step_feedforward(&ctx, m[0], q, have_qd ? qd : NULL, r + 1, have_f ? f : NULL,
                                       expected ? r + REF_COLUMNS : NULL, NULL, NULL, F);
        if (status < 0) {
            fprintf(stderr, "replay: row %ld (t = %.17g s): %s\n", row + 1, m[0], vgtc_status_text(status));
            return 1;
        }
        const double *tau = vgtc_effort_estimate(&ctx);
        fprintf(out, "%.17g", m[0]);
        for (int i = 0; i < VGTC_NJ; ++i) fprintf(out, ",%.17g", F[i]);
        for (int i = 0; i < VGTC_NJ; ++i) fprintf(out, ",%.17g", tau[i]);
        fprintf(out, ",%d\n", status);
        ++row;
    }
    if (fclose(out) != 0) {
        fprintf(stderr, "replay: cannot write %s\n", argv[3]);
        return 1;
    }
    fclose(ref);
    fclose(meas);
    return 0;
}
