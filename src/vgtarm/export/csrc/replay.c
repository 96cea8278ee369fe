/* replay: run the exported controller over recorded measurements (see README.md for the formats).
 *
 *   replay REFERENCE.csv MEASUREMENTS.csv EFFORTS.csv
 *
 * Row k of REFERENCE.csv is period k's reference (t, q_d, qd_d, qdd_d, and optionally the tool
 * force the path's cutting model expects, f_exp_x, f_exp_y, f_exp_z, fed forward: the header says
 * which; or the CSV `vgtarm ik` writes, t, x, y, z, the joints, their rates and accelerations, the
 * tip point ignored); row k of MEASUREMENTS.csv what was measured then (t, q, qd, f). Every period
 * is one vgtc_step_feedforward (f_exp NULL without those columns); EFFORTS.csv gets t, the
 * efforts, the estimate of the external efforts and the status, numbers written with 17
 * significant digits (they read back exactly). Exit status 0, or 1 with one line on stderr.
 *
 * Before anything is read: every argument must name a regular file (a FIFO, a device or a folder
 * is refused before it is opened; EFFORTS.csv may also be a new name), EFFORTS.csv must be neither
 * input (compared by device and inode, so a link or another path to an input is caught) nor a
 * symbolic link (never written through). Each input's header must be one of the layouts above,
 * column for column. EFFORTS.csv is written to a temporary file beside it and renamed into place
 * only when every row was replayed: a refusal (a malformed row, a value that is not finite or out
 * of the bounds below, time going back, one file ending before the other, a full disk, the
 * file-size limit of `ulimit -f`) or an interrupting signal leaves nothing.
 */
#define _POSIX_C_SOURCE 200809L

#include <errno.h>
#include <fcntl.h>
#include <math.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <sys/types.h>
#include <unistd.h>

#include "vgtarm_controller.h"

/* Physical bounds of the values read: a value beyond them is a unit mistake or a corrupt file,
 * never a robot's (no joint travels, turns or accelerates that far), and is refused naming its row
 * and column. Positions, rates and accelerations of the reference and of the measurements (m, rad,
 * m/s, rad/s, m/s^2, rad/s^2, and vgtarm ik's tip point, m): */
#define REPLAY_MOTION_BOUND 1e3
/* Tool forces, the expected f_exp and the measured f (N): */
#define REPLAY_FORCE_BOUND 1e5
/* Times, t of both files (s; 1e9 s is over 30 years): */
#define REPLAY_TIME_BOUND 1e9

#define MAX_LINE 65536                    /* longest line read, its end included */
#define NAME_SIZE 64                      /* longest column name + 1 */
#define MAX_FIELDS (4 + 3 * VGTC_NJ)      /* the widest layout: vgtarm ik's, or the reference with f_exp */
#define SHOWN 60                          /* longest rendering of a file's text in a message */

enum layout { REF_PLAIN, REF_FEEDFORWARD, REF_IK, MEASUREMENTS };
enum kind { TIME, MOTION, FORCE };

/* A file being read: its argument's name and path, its layout, the names and kinds of its columns. */
typedef struct {
    const char *role, *what, *path;
    FILE *in;
    enum layout layout;
    int columns;
    long line; /* lines read */
    char names[MAX_FIELDS][NAME_SIZE];
    enum kind kinds[MAX_FIELDS];
    const char *starts[MAX_FIELDS]; /* the text of each field of the last row */
} csv_file;

/* The temporary output, removed on a refusal and by the signals that end the program. */
static char temp_path[4096];
static volatile sig_atomic_t temp_live = 0;

static void drop_temporary(void)
{
    if (temp_live) {
        temp_live = 0;
        unlink(temp_path);
    }
}

static void on_signal(int sig)
{
    if (temp_live) unlink(temp_path); /* async-signal-safe */
    signal(sig, SIG_DFL);
    raise(sig);
}

/* `text` (`length` bytes) for a message: quotes, backslashes and every byte that is not printable
 * ASCII escaped (a file's or a path's bytes never drive the terminal), cut after `limit`. */
static const char *shown(const char *text, size_t length, size_t limit, char *buffer, size_t size)
{
    static const char hex[] = "0123456789abcdef";
    size_t at = 0, i;
    for (i = 0; i < length && at + 8 < size; ++i) {
        const unsigned char c = (unsigned char)text[i];
        if (i == limit) break;
        if (c == '"' || c == '\\') {
            buffer[at++] = '\\';
            buffer[at++] = (char)c;
        } else if (c < 0x20 || c >= 0x7f) {
            buffer[at++] = '\\';
            buffer[at++] = 'x';
            buffer[at++] = hex[c >> 4];
            buffer[at++] = hex[c & 15];
        } else {
            buffer[at++] = (char)c;
        }
    }
    if (i < length && at + 4 < size) {
        memcpy(buffer + at, "...", 3);
        at += 3;
    }
    buffer[at] = '\0';
    return buffer;
}

/* A path or an argument for a message. */
static const char *path_shown(const char *path, int which)
{
    static char buffers[4][4 * 200 + 16];
    return shown(path, strlen(path), 200, buffers[which & 3], sizeof buffers[0]);
}

static const char *file_kind(mode_t mode)
{
    if (S_ISDIR(mode)) return "a folder";
    if (S_ISFIFO(mode)) return "a FIFO (named pipe)";
    if (S_ISCHR(mode)) return "a character device";
    if (S_ISBLK(mode)) return "a block device";
#ifdef S_ISSOCK
    if (S_ISSOCK(mode)) return "a socket";
#endif
#ifdef S_ISLNK
    if (S_ISLNK(mode)) return "a symbolic link";
#endif
    return "not a regular file";
}

/* An input: checked to be a regular file before it is opened (without blocking, so that a FIFO put
 * in its place meanwhile cannot hang it) and again once open; NULL after one line on stderr. */
static FILE *open_input(const char *role, const char *path, struct stat *st)
{
    if (!*path) {
        fprintf(stderr, "replay: %s is an empty argument; expected the name of a CSV file\n", role);
        return NULL;
    }
    if (stat(path, st) != 0) {
        fprintf(stderr, "replay: cannot read %s %s: %s\n", role, path_shown(path, 0), strerror(errno));
        return NULL;
    }
    if (!S_ISREG(st->st_mode)) {
        fprintf(stderr, "replay: %s %s is %s; expected a regular file\n", role, path_shown(path, 0),
                file_kind(st->st_mode));
        return NULL;
    }
    const int fd = open(path, O_RDONLY | O_NONBLOCK);
    if (fd < 0) {
        fprintf(stderr, "replay: cannot read %s %s: %s\n", role, path_shown(path, 0), strerror(errno));
        return NULL;
    }
    if (fstat(fd, st) != 0 || !S_ISREG(st->st_mode)) {
        fprintf(stderr, "replay: %s %s is %s; expected a regular file\n", role, path_shown(path, 0),
                file_kind(st->st_mode));
        close(fd);
        return NULL;
    }
    const int flags = fcntl(fd, F_GETFL);
    if (flags != -1) fcntl(fd, F_SETFL, flags & ~O_NONBLOCK);
    FILE *in = fdopen(fd, "r");
    if (!in) {
        fprintf(stderr, "replay: cannot read %s %s: %s\n", role, path_shown(path, 0), strerror(errno));
        close(fd);
    }
    return in;
}

/* One line into `line` (its end removed): 1, 0 at the end of the file, -1 with the reason in `why`. */
static int read_line(csv_file *f, char *line, const char **why)
{
    size_t length = 0;
    int c = EOF;
    while ((c = getc(f->in)) != EOF && c != '\n') {
        if (c == '\0') {
            *why = "holds a zero byte (not a text file)";
            return -1;
        }
        if (length + 1 >= MAX_LINE) {
            *why = "is longer than 65535 characters";
            return -1;
        }
        line[length++] = (char)c;
    }
    if (ferror(f->in)) {
        *why = strerror(errno);
        return -1;
    }
    if (c == EOF && length == 0) return 0;
    if (length > 0 && line[length - 1] == '\r') --length;
    line[length] = '\0';
    ++f->line;
    return 1;
}

/* `text` appended to the string in `buffer` (`size` bytes), cut to fit. */
static void append(char *buffer, size_t size, const char *text)
{
    size_t at = strlen(buffer), length = strlen(text);
    if (at + 1 >= size) return;
    if (length > size - 1 - at) length = size - 1 - at;
    memcpy(buffer + at, text, length);
    buffer[at + length] = '\0';
}

static void set_column(csv_file *f, int i, const char *prefix, const char *name, enum kind kind)
{
    f->names[i][0] = '\0';
    append(f->names[i], NAME_SIZE, prefix);
    append(f->names[i], NAME_SIZE, name);
    f->kinds[i] = kind;
}

/* The joint names of this export (VGTC_JOINT_NAMES, ", " between them), for vgtarm ik's layout; 0
 * when they cannot be told apart (that layout is then not recognised). */
static int joint_names(char names[VGTC_NJ][NAME_SIZE])
{
    const char *cursor = VGTC_JOINT_NAMES;
    for (int i = 0; i < VGTC_NJ; ++i) {
        const char *end = strstr(cursor, ", ");
        const size_t length = end ? (size_t)(end - cursor) : strlen(cursor);
        if (length == 0 || length + 3 > NAME_SIZE || (i + 1 < VGTC_NJ) != (end != NULL)) return 0;
        memcpy(names[i], cursor, length);
        names[i][length] = '\0';
        cursor = end ? end + 2 : cursor + length;
    }
    return 1;
}

/* The columns of `layout` into `f`. */
static void set_layout(csv_file *f, enum layout layout, char joints[VGTC_NJ][NAME_SIZE])
{
    const int n = VGTC_NJ;
    char index[16];
    int at = 0;
    f->layout = layout;
    set_column(f, at++, "", "t", TIME);
    if (layout == REF_IK) {
        set_column(f, at++, "", "x", MOTION);
        set_column(f, at++, "", "y", MOTION);
        set_column(f, at++, "", "z", MOTION);
        for (int block = 0; block < 3; ++block)
            for (int i = 0; i < n; ++i) set_column(f, at++, block == 0 ? "" : block == 1 ? "d" : "dd", joints[i], MOTION);
    } else {
        const char *const *prefixes;
        static const char *const reference[3] = {"q_d_", "qd_d_", "qdd_d_"};
        static const char *const measured[2] = {"q_", "qd_"};
        const int blocks = layout == MEASUREMENTS ? 2 : 3;
        prefixes = layout == MEASUREMENTS ? measured : reference;
        for (int block = 0; block < blocks; ++block)
            for (int i = 0; i < n; ++i) {
                snprintf(index, sizeof index, "%d", i + 1);
                set_column(f, at++, prefixes[block], index, MOTION);
            }
        if (layout == REF_FEEDFORWARD || layout == MEASUREMENTS) {
            const char *prefix = layout == MEASUREMENTS ? "f_" : "f_exp_";
            set_column(f, at++, prefix, "x", FORCE);
            set_column(f, at++, prefix, "y", FORCE);
            set_column(f, at++, prefix, "z", FORCE);
        }
    }
    f->columns = at;
}

/* Whether the header `line` names exactly the columns of `f` (spaces around a name allowed). */
static int header_matches(const csv_file *f, const char *line)
{
    const char *cursor = line;
    for (int i = 0; i < f->columns; ++i) {
        while (*cursor == ' ' || *cursor == '\t') ++cursor;
        const size_t length = strlen(f->names[i]);
        if (strncmp(cursor, f->names[i], length) != 0) return 0;
        cursor += length;
        while (*cursor == ' ' || *cursor == '\t') ++cursor;
        if (i + 1 < f->columns ? *cursor != ',' : *cursor != '\0') return 0;
        ++cursor;
    }
    return 1;
}

/* Reads the header of `f` and recognises its layout among `layouts`; 0 after one line on stderr. */
static int read_header(csv_file *f, const enum layout *layouts, int count, char *line, const char *expected)
{
    static char joints[VGTC_NJ][NAME_SIZE];
    static char buffer[4 * SHOWN + 16];
    const int have_joints = joint_names(joints);
    const char *why = NULL;
    const int got = read_line(f, line, &why);
    if (got < 0) {
        fprintf(stderr, "replay: %s %s: its header line %s; expected %s\n", f->role, path_shown(f->path, 0), why,
                expected);
        return 0;
    }
    if (got == 0) {
        fprintf(stderr, "replay: %s %s is empty; expected a header line %s, then one row per period\n", f->role,
                path_shown(f->path, 0), expected);
        return 0;
    }
    const char *text = line;
    if (!strncmp(text, "\xef\xbb\xbf", 3)) text += 3; /* a byte-order mark, as some editors write */
    for (int k = 0; k < count; ++k) {
        if (layouts[k] == REF_IK && !have_joints) continue;
        set_layout(f, layouts[k], joints);
        if (header_matches(f, text)) return 1;
    }
    int fields = 1;
    for (const char *c = text; *c; ++c) fields += *c == ',';
    fprintf(stderr, "replay: %s %s: its header is not that of %s; expected %s; found \"%s\" (%d columns)\n", f->role,
            path_shown(f->path, 0), f->what, expected, shown(text, strlen(text), SHOWN, buffer, sizeof buffer), fields);
    return 0;
}

/* Row `row` of `f` into `values`: 1, 0 at the end of the file, -1 after one line on stderr. */
static int read_row(csv_file *f, long row, double *values, char *line)
{
    static char buffer[4 * SHOWN + 16];
    const char *why = NULL;
    const int got = read_line(f, line, &why);
    if (got <= 0) {
        if (got < 0)
            fprintf(stderr, "replay: %s %s: line %ld %s\n", f->role, path_shown(f->path, 0), f->line + 1, why);
        return got;
    }
    char *cursor = line;
    for (int i = 0; i < f->columns; ++i) {
        char *end;
        while (*cursor == ' ' || *cursor == '\t') ++cursor;
        f->starts[i] = cursor;
        errno = 0;
        values[i] = strtod(cursor, &end);
        while (*end == ' ' || *end == '\t') ++end;
        if (end == cursor || (*end != ',' && *end != '\0')) {
            size_t length = strcspn(cursor, ",");
            fprintf(stderr, "replay: %s %s row %ld (line %ld) column %s: \"%s\" is not a number\n", f->role,
                    path_shown(f->path, 0), row, f->line, f->names[i], shown(cursor, length, SHOWN, buffer, sizeof buffer));
            return -1;
        }
        if (i + 1 < f->columns) {
            if (*end != ',') {
                fprintf(stderr, "replay: %s %s row %ld (line %ld): %d columns; expected %d\n", f->role,
                        path_shown(f->path, 0), row, f->line, i + 1, f->columns);
                return -1;
            }
            cursor = end + 1;
        } else if (*end != '\0') {
            int fields = f->columns;
            for (const char *c = end; *c; ++c) fields += *c == ',';
            fprintf(stderr, "replay: %s %s row %ld (line %ld): %d columns; expected %d\n", f->role,
                    path_shown(f->path, 0), row, f->line, fields, f->columns);
            return -1;
        }
    }
    return 1;
}

/* Refuses a value that is not finite or beyond its bound: 0 after one line on stderr. `optional`:
 * `count` blocks of columns (first, number) that may each be nan throughout (not measured). */
static int check_values(const csv_file *f, long row, const double *values, const int (*optional)[2], int count)
{
    static char buffer[4 * SHOWN + 16];
    for (int i = 0; i < f->columns; ++i) {
        const double v = values[i];
        const char *text = shown(f->starts[i], strcspn(f->starts[i], ","), SHOWN, buffer, sizeof buffer);
        int block = -1;
        for (int k = 0; k < count; ++k)
            if (i >= optional[k][0] && i < optional[k][0] + optional[k][1]) block = k;
        if (block >= 0 && isnan(values[optional[block][0]])) {
            const int first = optional[block][0], last = first + optional[block][1] - 1;
            if (isnan(v)) continue;
            fprintf(stderr, "replay: %s %s row %ld (line %ld) column %s: %s while %s is nan; expected %s..%s all "
                    "numbers, or all nan (not measured)\n", f->role, path_shown(f->path, 0), row, f->line, f->names[i],
                    text, f->names[first], f->names[first], f->names[last]);
            return 0;
        }
        if (!isfinite(v)) {
            fprintf(stderr, "replay: %s %s row %ld (line %ld) column %s: %s; expected a finite number%s\n", f->role,
                    path_shown(f->path, 0), row, f->line, f->names[i], text,
                    block >= 0 ? " (or nan throughout the block: not measured)" : "");
            return 0;
        }
        const double bound = f->kinds[i] == TIME ? REPLAY_TIME_BOUND : f->kinds[i] == FORCE ? REPLAY_FORCE_BOUND
                                                                                              : REPLAY_MOTION_BOUND;
        if (fabs(v) > bound) {
            fprintf(stderr, "replay: %s %s row %ld (line %ld) column %s: %s is out of bounds; expected |value| <= %g "
                    "%s\n", f->role, path_shown(f->path, 0), row, f->line, f->names[i], text, bound,
                    f->kinds[i] == TIME ? "s" : f->kinds[i] == FORCE ? "N" : "(m, rad and their rates, SI)");
            return 0;
        }
    }
    return 1;
}

/* Why a write failed, for the message: the full disk and the file-size limit said in words. */
static void write_failed(const char *path, int error)
{
    if (error == EFBIG) {
        struct rlimit limit;
        if (getrlimit(RLIMIT_FSIZE, &limit) == 0 && limit.rlim_cur != RLIM_INFINITY)
            fprintf(stderr, "replay: cannot write %s: the file-size limit (ulimit -f) of %llu bytes is reached; "
                    "nothing written\n", path_shown(path, 0), (unsigned long long)limit.rlim_cur);
        else
            fprintf(stderr, "replay: cannot write %s: the file is too large (%s); nothing written\n", path_shown(path, 0),
                    strerror(error));
    } else if (error == ENOSPC) {
        fprintf(stderr, "replay: cannot write %s: the disk is full (%s); nothing written\n", path_shown(path, 0),
                strerror(error));
    } else {
        fprintf(stderr, "replay: cannot write %s: %s; nothing written\n", path_shown(path, 0),
                strerror(error ? error : EIO));
    }
}

/* The output's checks: a regular file or a new name, not a link, neither input. 0 after one line. */
static int check_output(const char *path, const struct stat *ref, const struct stat *meas, struct stat *st, int *exists)
{
    if (!*path) {
        fprintf(stderr, "replay: EFFORTS is an empty argument; expected the name of the CSV file to write\n");
        return 0;
    }
    *exists = 0;
    if (lstat(path, st) != 0) {
        if (errno == ENOENT) return 1;
        fprintf(stderr, "replay: cannot write EFFORTS %s: %s\n", path_shown(path, 0), strerror(errno));
        return 0;
    }
    const struct stat *inputs[2] = {ref, meas};
    struct stat target;
    if (stat(path, &target) == 0) /* the file itself, or what a link leads to */
        for (int k = 0; k < 2; ++k)
            if (target.st_dev == inputs[k]->st_dev && target.st_ino == inputs[k]->st_ino) {
                fprintf(stderr, "replay: EFFORTS %s is the %s file it would read%s; expected another file to write\n",
                        path_shown(path, 0), k == 0 ? "REFERENCE" : "MEASUREMENTS",
                        S_ISREG(st->st_mode) ? "" : " (through a link)");
                return 0;
            }
    if (!S_ISREG(st->st_mode)) {
        fprintf(stderr, "replay: EFFORTS %s is %s; expected a regular file or a new name%s\n", path_shown(path, 0),
                file_kind(st->st_mode),
#ifdef S_ISLNK
                S_ISLNK(st->st_mode) ? " (replay does not write through links)" :
#endif
                "");
        return 0;
    }
    *exists = 1;
    return 1;
}

/* The temporary output beside `path` (its mode the existing file's, else 0666 less the umask). */
static FILE *open_temporary(const char *path, const struct stat *old, int exists)
{
    const char *slash = strrchr(path, '/');
    const size_t folder = slash ? (size_t)(slash - path) + 1 : 0;
    const char *base = path + folder;
    const size_t base_length = strlen(base) < 100 ? strlen(base) : 100;
    if (folder + base_length + 20 > sizeof temp_path) {
        fprintf(stderr, "replay: cannot write %s: the path is too long\n", path_shown(path, 0));
        return NULL;
    }
    memcpy(temp_path, path, folder);
    temp_path[folder] = '.';
    memcpy(temp_path + folder + 1, base, base_length);
    strcpy(temp_path + folder + 1 + base_length, ".replay-XXXXXX");
    const int fd = mkstemp(temp_path);
    if (fd < 0) {
        fprintf(stderr, "replay: cannot write %s: %s\n", path_shown(path, 0), strerror(errno));
        return NULL;
    }
    temp_live = 1;
    mode_t mode = 0;
    if (exists) {
        mode = old->st_mode & 07777;
    } else {
        const mode_t mask = umask(0);
        umask(mask);
        mode = 0666 & ~mask;
    }
    if (fchmod(fd, mode) != 0) { /* the permissions are the file's, not the temporary's 0600 */
        fprintf(stderr, "replay: cannot write %s: %s\n", path_shown(path, 0), strerror(errno));
        close(fd);
        drop_temporary();
        return NULL;
    }
    FILE *out = fdopen(fd, "w");
    if (!out) {
        fprintf(stderr, "replay: cannot write %s: %s\n", path_shown(path, 0), strerror(errno));
        close(fd);
        drop_temporary();
    }
    return out;
}

int main(int argc, char **argv)
{
    static char line[MAX_LINE];
    static vgtc_context ctx;
    static csv_file ref, meas;
    static char expected_ref[1024], expected_meas[256];
    vgtc_params params;
    struct stat ref_stat, meas_stat, out_stat;
    int out_exists = 0;
    if (argc != 4) {
        fprintf(stderr, "usage: replay REFERENCE.csv MEASUREMENTS.csv EFFORTS.csv (%d argument%s given)\n", argc - 1,
                argc == 2 ? "" : "s");
        return 1;
    }
    signal(SIGXFSZ, SIG_IGN); /* past `ulimit -f` a write fails with EFBIG, which is reported */
    {
        char joints[VGTC_NJ][NAME_SIZE];
        const int n = VGTC_NJ, plain = 1 + 3 * VGTC_NJ, wide = 4 + 3 * VGTC_NJ;
        snprintf(expected_ref, sizeof expected_ref, "t,q_d_1..q_d_%d,qd_d_1..qd_d_%d,qdd_d_1..qdd_d_%d (%d columns; %d "
                 "with f_exp_x,f_exp_y,f_exp_z after them)", n, n, n, plain, wide);
        if (joint_names(joints)) {
            const char *parts[13] = {" or vgtarm ik's t,x,y,z,", joints[0], "..", joints[n - 1], ",d", joints[0], "..d",
                                     joints[n - 1], ",dd", joints[0], "..dd", joints[n - 1], " ("};
            char count[32];
            for (int k = 0; k < 13; ++k) append(expected_ref, sizeof expected_ref, parts[k]);
            snprintf(count, sizeof count, "%d columns)", wide);
            append(expected_ref, sizeof expected_ref, count);
        }
        snprintf(expected_meas, sizeof expected_meas, "t,q_1..q_%d,qd_1..qd_%d,f_x,f_y,f_z (%d columns)", n, n,
                 1 + 2 * n + 3);
    }
    ref.role = "REFERENCE";
    ref.what = "a reference";
    ref.path = argv[1];
    meas.role = "MEASUREMENTS";
    meas.what = "a measurements file";
    meas.path = argv[2];
    /* every argument checked before anything is read */
    if (!(ref.in = open_input(ref.role, ref.path, &ref_stat))) return 1;
    if (!(meas.in = open_input(meas.role, meas.path, &meas_stat))) return 1;
    if (!check_output(argv[3], &ref_stat, &meas_stat, &out_stat, &out_exists)) return 1;
    const enum layout reference_layouts[3] = {REF_PLAIN, REF_FEEDFORWARD, REF_IK};
    const enum layout measurement_layouts[1] = {MEASUREMENTS};
    if (!read_header(&ref, reference_layouts, 3, line, expected_ref)) return 1;
    if (!read_header(&meas, measurement_layouts, 1, line, expected_meas)) return 1;
    vgtc_default_params(&params);
    int status = vgtc_init(&ctx, &params);
    if (status != VGTC_OK) {
        fprintf(stderr, "replay: vgtc_init: %s\n", vgtc_status_text(status));
        return 1;
    }
    {
        struct sigaction action;
        const int ending[4] = {SIGINT, SIGTERM, SIGHUP, SIGQUIT};
        memset(&action, 0, sizeof action);
        action.sa_handler = on_signal;
        sigemptyset(&action.sa_mask);
        for (int k = 0; k < 4; ++k) sigaction(ending[k], &action, NULL);
    }
    FILE *out = open_temporary(argv[3], &out_stat, out_exists);
    if (!out) return 1;
    const int offset = ref.layout == REF_IK ? 4 : 1; /* where q_d starts in a reference row */
    const int feedforward = ref.layout == REF_FEEDFORWARD;
    const int not_measured[2][2] = {{1 + VGTC_NJ, VGTC_NJ}, {1 + 2 * VGTC_NJ, 3}};
    int failed = 0, error = 0;
#define EMIT(call)                              \
    do {                                        \
        if (!failed && (call) < 0) {            \
            failed = 1;                         \
            error = errno;                      \
        }                                       \
    } while (0)
    EMIT(fprintf(out, "t"));
    for (int i = 0; i < VGTC_NJ; ++i) EMIT(fprintf(out, ",F_%d", i + 1));
    for (int i = 0; i < VGTC_NJ; ++i) EMIT(fprintf(out, ",tau_hat_%d", i + 1));
    EMIT(fprintf(out, ",status\n"));
    double r[MAX_FIELDS], m[MAX_FIELDS], F[VGTC_NJ], t_ref_last = -INFINITY;
    long row = 0;
    int refused = 0;
    while (!failed) {
        const int got_ref = read_row(&ref, row + 1, r, line);
        if (got_ref < 0 || (got_ref > 0 && !check_values(&ref, row + 1, r, NULL, 0))) {
            refused = 1;
            break;
        }
        if (got_ref > 0 && r[0] < t_ref_last) {
            fprintf(stderr, "replay: REFERENCE %s row %ld (line %ld) column t: %.17g s after %.17g s; expected times "
                    "that never go back\n", path_shown(ref.path, 0), row + 1, ref.line, r[0], t_ref_last);
            refused = 1;
            break;
        }
        const int got_meas = read_row(&meas, row + 1, m, line);
        /* qd (from qd_1) and f (from f_x) may each be nan throughout: not measured */
        if (got_meas < 0 || (got_meas > 0 && !check_values(&meas, row + 1, m, not_measured, 2))) {
            refused = 1;
            break;
        }
        if (!got_ref || !got_meas) {
            if (got_ref != got_meas) {
                const csv_file *ended = !got_ref ? &ref : &meas, *other = !got_ref ? &meas : &ref;
                fprintf(stderr, "replay: %s %s ends after %ld rows, %s %s goes on; expected as many rows in both\n",
                        ended->role, path_shown(ended->path, 0), row, other->role, path_shown(other->path, 1));
                refused = 1;
            }
            break;
        }
        t_ref_last = r[0];
        const double *q = m + 1, *qd = m + 1 + VGTC_NJ, *f = m + 1 + 2 * VGTC_NJ;
        const int have_qd = !isnan(qd[0]), have_f = !isnan(f[0]);
        status = vgtc_step_feedforward(&ctx, m[0], q, have_qd ? qd : NULL, r + offset, have_f ? f : NULL,
                                       feedforward ? r + 1 + 3 * VGTC_NJ : NULL, NULL, NULL, F);
        if (status < 0) {
            fprintf(stderr, "replay: MEASUREMENTS %s row %ld (line %ld, t = %.17g s): the controller refused the step: "
                    "%s\n", path_shown(meas.path, 0), row + 1, meas.line, m[0], vgtc_status_text(status));
            refused = 1;
            break;
        }
        const double *tau = vgtc_effort_estimate(&ctx);
        EMIT(fprintf(out, "%.17g", m[0]));
        for (int i = 0; i < VGTC_NJ; ++i) EMIT(fprintf(out, ",%.17g", F[i]));
        for (int i = 0; i < VGTC_NJ; ++i) EMIT(fprintf(out, ",%.17g", tau[i]));
        EMIT(fprintf(out, ",%d\n", status));
        ++row;
    }
#undef EMIT
    fclose(ref.in);
    fclose(meas.in);
    if (!refused && !failed) {
        if (fflush(out) != 0) {
            failed = 1;
            error = errno;
        } else if (fsync(fileno(out)) != 0 && errno != EINVAL && errno != EROFS) {
            failed = 1;
            error = errno;
        }
    }
    if (fclose(out) != 0 && !refused && !failed) {
        failed = 1;
        error = errno;
    }
    if (failed && !refused) write_failed(argv[3], error);
    if (refused || failed) {
        drop_temporary();
        return 1;
    }
    if (rename(temp_path, argv[3]) != 0) {
        const int why = errno;
        drop_temporary();
        fprintf(stderr, "replay: cannot write %s: %s; nothing written\n", path_shown(argv[3], 0), strerror(why));
        return 1;
    }
    temp_live = 0;
    return 0;
}
