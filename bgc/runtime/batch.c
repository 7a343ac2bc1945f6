#ifndef BGC_NO_MAIN
/* ============================================================== batch === */

/* Batch mode (--batch FILE, "-" for stdin): many runs in one process.  Each line of FILE is
   one run: NAME=VALUE words separated by blanks, set on top of the defaults and the -p values
   (derived parameters follow); a blank line is a run with those alone; a line that starts with
   '#' is no run.  Runs are numbered from 0 in line order.  Each run starts from the same state
   as a new process would (fresh parameters, workspace, Newton starting values and counters),
   so its numbers equal a separate run's bit for bit.  stdout gets one CSV row per run:
     run,status,<metrics>,steps,rejected,rhs,cpu,message
   status: ok | failed (the run stopped: non-finite value, step size too small, a failed
   algebraic block) | constraint (the initial conditions violate a constraint) | invalid (the
   line is not NAME=VALUE words with known names and finite decimal values); message: why
   (empty when ok), quoted.  --metric KIND:OUTPUT (any number, in order) adds the column
   KIND:OUTPUT, over the run's output rows y_0..y_{N-1} (t0, every dt, t_end):
     final  y_{N-1}    max, min  the largest, smallest y_k    maxabs  the largest |y_k|
     rms    sqrt((y_0^2 + ... + y_{N-1}^2) / N), summed in row order (per row, not time-weighted)
   (nan when the run did not complete).  --trajectories DIR also writes each run's CSV, as
   the program writes it without --batch, to DIR/run-NNNNNN.csv (its number, 6 digits or
   more).  The exit status is 0 when every line was run (whatever the runs' statuses), 2 for
   a usage error, 3 if the output cannot be written or a signal stopped the batch.  Read from
   stdin, each result is written out as soon as its run ends, so that a caller can give the
   next line from it (bgc periodic's Newton iterations, each run's start from the last). */

#define BGC_MAX_METRICS 256
#define BGC_LINE_MAX 65536

enum { BGC_M_FINAL, BGC_M_MAX, BGC_M_MIN, BGC_M_MAXABS, BGC_M_RMS, BGC_NUM_METRIC_KINDS };
static const char *const bgc_metric_kinds[BGC_NUM_METRIC_KINDS] = { "final", "max", "min",
                                                                    "maxabs", "rms" };

typedef struct bgc_batch {
    int nmetrics;
    int kind[BGC_MAX_METRICS], output[BGC_MAX_METRICS];
    const char *spec[BGC_MAX_METRICS];
    double acc[BGC_MAX_METRICS]; /* final, max, min, maxabs: the value; rms: the sum of squares */
    long rows;
    int traj; /* writing this run's trajectory to bgc_traj */
} bgc_batch;

static bgc_writer bgc_traj;
static volatile sig_atomic_t bgc_batch_signal = 0;
static char bgc_line[BGC_LINE_MAX];

static void bgc_batch_on_signal(int sig)
{
    bgc_batch_signal = (sig_atomic_t)sig;
    bgc_request_stop(sig);
}

static int bgc_batch_row(void *ctx, double t, const double *x, const double *y)
{
    bgc_batch *b = (bgc_batch *)ctx;
    int k;
    for (k = 0; k < b->nmetrics; k++) {
        const double v = y[b->output[k]];
        double *a = &b->acc[k];
        switch (b->kind[k]) {
        case BGC_M_FINAL:
            *a = v;
            break;
        case BGC_M_MAX:
            if (b->rows == 0 || v > *a)
                *a = v;
            break;
        case BGC_M_MIN:
            if (b->rows == 0 || v < *a)
                *a = v;
            break;
        case BGC_M_MAXABS:
            if (b->rows == 0 || fabs(v) > *a)
                *a = fabs(v);
            break;
        default:
            *a = b->rows == 0 ? v * v : *a + v * v;
        }
    }
    b->rows++;
    return b->traj ? bgc_csv_row(&bgc_traj, t, x, y) : 0;
}

/* --metric KIND:OUTPUT into b; -1 (and a message) if it is not one. */
static int bgc_batch_metric(bgc_batch *b, const char *spec)
{
    const char *colon = strchr(spec, ':');
    size_t len = colon ? (size_t)(colon - spec) : 0;
    int k, j;
    if (b->nmetrics == BGC_MAX_METRICS) {
        fprintf(stderr, "error: more than %d metrics\n", BGC_MAX_METRICS);
        return -1;
    }
    for (k = 0; colon && k < BGC_NUM_METRIC_KINDS; k++)
        if (strlen(bgc_metric_kinds[k]) == len && strncmp(spec, bgc_metric_kinds[k], len) == 0)
            break;
    if (!colon || k == BGC_NUM_METRIC_KINDS) {
        fprintf(stderr, "error: --metric expects KIND:OUTPUT with KIND one of final, max, min, "
                        "maxabs, rms; got '%s'\n", spec);
        return -1;
    }
    for (j = 0; j < BGC_NUM_OUTPUTS; j++)
        if (strcmp(colon + 1, bgc_output_names[j]) == 0)
            break;
    if (j == BGC_NUM_OUTPUTS) {
        fprintf(stderr, "error: --metric %s: '%s' is not an output\n", spec, colon + 1);
        return -1;
    }
    b->kind[b->nmetrics] = k;
    b->output[b->nmetrics] = j;
    b->spec[b->nmetrics++] = spec;
    return 0;
}

static void bgc_put_text(bgc_writer *w, const char *text)
{
    for (; *text; text++) {
        if (w->len + 2 > sizeof w->buf)
            bgc_flush(w);
        w->buf[w->len++] = *text;
    }
}

/* The message as one CSV field: quoted, quotes doubled, line breaks as blanks. */
static void bgc_put_quoted(bgc_writer *w, const char *text)
{
    bgc_put_text(w, "\"");
    for (; *text; text++) {
        if (w->len + 3 > sizeof w->buf)
            bgc_flush(w);
        if (*text == '"')
            w->buf[w->len++] = '"';
        w->buf[w->len++] = (*text == '\n' || *text == '\r') ? ' ' : *text;
    }
    bgc_put_text(w, "\"");
}

static void bgc_put_long(bgc_writer *w, long v)
{
    char buf[32];
    snprintf(buf, sizeof buf, "%ld", v);
    bgc_put_text(w, buf);
}

/* A decimal number, finite (as bgc_parse_number, without a message). */
static int bgc_batch_number(const char *text, double *out)
{
    char *end;
    if (*text == '\0' || strspn(text, "0123456789+-.eE") != strlen(text))
        return -1;
    *out = strtod(text, &end);
    return *end == '\0' && isfinite(*out) ? 0 : -1;
}

/* The line's NAME=VALUE words into p, given; -1 and a message if it has a bad word. */
static int bgc_batch_line(char *line, bgc_params *p, int *given, char *msg, size_t msg_size)
{
    char *word = strtok(line, " \t\r\n");
    for (; word; word = strtok(NULL, " \t\r\n")) {
        char *eq = strchr(word, '=');
        int j;
        double v;
        if (!eq || eq == word) {
            snprintf(msg, msg_size, "expected NAME=VALUE, got '%.200s'", word);
            return -1;
        }
        *eq = '\0';
        j = bgc_param_index(word);
        if (j < 0) {
            snprintf(msg, msg_size, "unknown parameter '%.200s'", word);
            return -1;
        }
        if (bgc_batch_number(eq + 1, &v)) {
            snprintf(msg, msg_size, "invalid value for %s: '%.200s'", word, eq + 1);
            return -1;
        }
        *bgc_param_ref(p, j) = v;
        given[j] = 1;
    }
    return 0;
}

/* The violated constraint rows at (t, x) as one message (with allow, as for
   --allow-inconsistent, only those not finite); their number. */
static int bgc_batch_constraints(double t, const double *x, const bgc_params *p, int allow,
                                 char *msg, size_t msg_size)
{
    double r[BGC_DIM(BGC_NUM_CONSTRAINTS)] = { 0.0 }, s[BGC_DIM(BGC_NUM_CONSTRAINTS)] = { 0.0 };
    bgc_params q;
    size_t used = 0;
    int k, bad = 0;
    BGC_COPY_PARAMS(&q, p);
    bgc_params_update(&q);
    bgc_residual(t, x, &q, r);
    bgc_scale(t, x, &q, s);
    msg[0] = '\0';
    for (k = 0; k < BGC_NUM_CONSTRAINTS; k++) {
        if (fabs(r[k]) <= 1e-9 * s[k] || (allow && isfinite(r[k])))
            continue;
        if (used < msg_size)
            used += (size_t)snprintf(msg + used, msg_size - used,
                                     "%sinitial conditions violate constraint '%s' (%s): "
                                     "residual = %.17g", bad ? "; " : "",
                                     bgc_constraint_names[k], bgc_constraint_levels[k], r[k]);
        bad++;
    }
    return bad;
}

/* One run: its status ("ok", ...) and msg; b's accumulators and st filled. */
static const char *bgc_batch_run(const bgc_settings *s, const bgc_params *base, int *given,
                                 int project, char *line, bgc_batch *b, bgc_stats *st, char *msg,
                                 size_t msg_size)
{
    double x0[BGC_DIM(BGC_NUM_STATES)] = { 0.0 };
    bgc_params p;
    int i;
    BGC_COPY_PARAMS(&p, base);
    msg[0] = '\0';
    if (bgc_batch_line(line, &p, given, msg, msg_size))
        return "invalid";
    bgc_params_defaults(&p, given);
    for (i = 0; i < BGC_NUM_PARAMS; i++)
        if (!isfinite(*bgc_param_ref(&p, i))) {
            snprintf(msg, msg_size, "parameter '%s' is not finite", bgc_param_names[i]);
            return "failed";
        }
    bgc_init(&p, x0);
    i = bgc_first_nonfinite(x0, BGC_NUM_STATES);
    if (i >= 0) {
        snprintf(msg, msg_size, "at t = %.17g: state '%s' is not finite", s->t0,
                 bgc_state_names[i]);
        return "failed";
    }
    if (project == 1 && bgc_project_initial(s->t0, x0, &p, msg, msg_size))
        return "constraint";
    if (bgc_batch_constraints(s->t0, x0, &p, project == 2, msg, msg_size))
        return "constraint";
    if (bgc_simulate(s, &p, x0, bgc_batch_row, b, st, msg, msg_size))
        return "failed";
    return "ok";
}

static void bgc_batch_result(bgc_writer *w, long run, const char *status, const bgc_batch *b,
                             const bgc_stats *st, const char *msg)
{
    const int ok = strcmp(status, "ok") == 0;
    int k;
    bgc_put_long(w, run);
    bgc_put_text(w, ",");
    bgc_put_text(w, status);
    for (k = 0; k < b->nmetrics; k++) {
        double v = b->acc[k];
        if (!ok || b->rows == 0)
            v = NAN;
        else if (b->kind[k] == BGC_M_RMS)
            v = sqrt(v / (double)b->rows);
        bgc_put_text(w, ",");
        bgc_put_number(w, v);
    }
    bgc_put_text(w, ",");
    bgc_put_long(w, st->steps);
    bgc_put_text(w, ",");
    bgc_put_long(w, st->rejected);
    bgc_put_text(w, ",");
    bgc_put_long(w, st->rhs);
    bgc_put_text(w, ",");
    bgc_put_number(w, st->cpu);
    bgc_put_text(w, ",");
    bgc_put_quoted(w, msg);
    bgc_put_text(w, "\n");
}

static int bgc_batch_open_trajectory(const char *dir, long run)
{
    char path[4096];
    if ((size_t)snprintf(path, sizeof path, "%s/run-%06ld.csv", dir, run) >= sizeof path) {
        fprintf(stderr, "error: --trajectories: the directory name is too long\n");
        return -1;
    }
    bgc_traj.file = fopen(path, "w");
    bgc_traj.len = 0;
    bgc_traj.failed = 0;
    if (!bgc_traj.file) {
        fprintf(stderr, "error: cannot write '%s'\n", path);
        return -1;
    }
    bgc_csv_header(bgc_traj.file);
    return 0;
}

static int bgc_batch_close_trajectory(void)
{
    int failed;
    bgc_flush(&bgc_traj);
    failed = bgc_traj.failed;
    if (fclose(bgc_traj.file) != 0)
        failed = 1;
    bgc_traj.file = NULL;
    return failed ? -1 : 0;
}

/* Runs the lines of in; the exit status. */
static int bgc_batch_loop(FILE *in, const bgc_settings *s, const bgc_params *base,
                          const int *base_given, int project, bgc_batch *b, const char *dir)
{
    int given[BGC_DIM(BGC_NUM_PARAMS)];
    char msg[1024];
    long run = 0;
    int k;
    bgc_put_text(&bgc_out, "run,status");
    for (k = 0; k < b->nmetrics; k++) {
        bgc_put_text(&bgc_out, ",");
        bgc_put_text(&bgc_out, b->spec[k]);
    }
    bgc_put_text(&bgc_out, ",steps,rejected,rhs,cpu,message\n");
    if (in == stdin) {
        bgc_flush(&bgc_out);
        fflush(stdout);
    }
    while (fgets(bgc_line, sizeof bgc_line, in)) {
        const size_t len = strlen(bgc_line);
        bgc_stats st = { 0, 0, 0, 0, 0, 0, 0, 0.0, 0.0, 0.0, 0, 0, 0 };
        const char *status;
        int c, too_long = len + 1 == sizeof bgc_line && bgc_line[len - 1] != '\n';
        if (too_long)
            while ((c = getc(in)) != EOF && c != '\n')
                ;
        if (bgc_line[0] == '#')
            continue;
        memcpy(given, base_given, sizeof given);
        b->rows = 0;
        b->traj = 0;
        if (too_long) {
            snprintf(msg, sizeof msg, "the line is longer than %d bytes", BGC_LINE_MAX - 2);
            status = "invalid";
        } else {
            if (dir) {
                if (bgc_batch_open_trajectory(dir, run))
                    return BGC_ERR_RUNTIME;
                b->traj = 1;
            }
            status = bgc_batch_run(s, base, given, project, bgc_line, b, &st, msg, sizeof msg);
            if (dir && bgc_batch_close_trajectory()) {
                fprintf(stderr, "error: cannot write the trajectory of run %ld\n", run);
                return BGC_ERR_RUNTIME;
            }
        }
        bgc_batch_result(&bgc_out, run++, status, b, &st, msg);
        if (in == stdin) { /* each result as it is known: a caller may wait for it */
            bgc_flush(&bgc_out);
            fflush(stdout);
        }
        if (bgc_out.failed)
            break;
        if (bgc_batch_signal) {
            bgc_flush(&bgc_out);
            fflush(stdout);
            fprintf(stderr, "error: interrupted by signal %d after %ld runs\n",
                    (int)bgc_batch_signal, run);
            return BGC_ERR_RUNTIME;
        }
    }
    bgc_flush(&bgc_out);
    if (fflush(stdout) != 0 || bgc_out.failed) {
        fprintf(stderr, "error: cannot write the output\n");
        return BGC_ERR_RUNTIME;
    }
    if (ferror(in)) {
        fprintf(stderr, "error: cannot read the batch\n");
        return BGC_ERR_RUNTIME;
    }
    return 0;
}

/* The batch options out of argv (the others are the usual ones, for every run); -1 if there
   is no --batch, else the exit status. */
static int bgc_batch_main(int argc, char **argv)
{
    static bgc_batch b;
    const char *file = NULL, *dir = NULL;
    char **rest;
    bgc_settings s;
    bgc_params p;
    int given[BGC_DIM(BGC_NUM_PARAMS)] = { 0 };
    int i, n = 1, rc, project = 0, stats = 0;
    FILE *in;
    for (i = 1; i < argc; i++)
        if (strcmp(argv[i], "--batch") == 0 || strncmp(argv[i], "--batch=", 8) == 0)
            break;
    if (i == argc)
        return -1;
    rest = (char **)malloc((size_t)argc * sizeof *rest);
    if (!rest) {
        fprintf(stderr, "error: out of memory\n");
        return BGC_ERR_RUNTIME;
    }
    rest[0] = argv[0];
    b.nmetrics = 0;
    for (i = 1; i < argc; i++) {
        static const char *const own[] = { "--batch", "--metric", "--trajectories" };
        const char *arg = argv[i], *value = NULL;
        int k;
        for (k = 0; k < 3; k++) {
            const size_t len = strlen(own[k]);
            if (strncmp(arg, own[k], len) == 0 && (arg[len] == '\0' || arg[len] == '='))
                break;
        }
        if (k == 3) {
            rest[n++] = argv[i];
            continue;
        }
        value = strchr(arg, '=') ? strchr(arg, '=') + 1 : (i + 1 < argc ? argv[++i] : NULL);
        if (!value) {
            fprintf(stderr, "error: option '%s' needs a value\n", arg);
            free(rest);
            return BGC_ERR_USAGE;
        }
        if (k == 0)
            file = value;
        else if (k == 2)
            dir = value;
        else if (bgc_batch_metric(&b, value)) {
            free(rest);
            return BGC_ERR_USAGE;
        }
    }
    memset(&p, 0, sizeof p); /* every field, a placeholder of a model without parameters too */
    bgc_params_defaults(&p, NULL);
    rc = bgc_settings_from_args(n, rest, &s, &p, given, &project, &stats);
    free(rest);
    if (rc >= 0)
        return rc;
    in = strcmp(file, "-") == 0 ? stdin : fopen(file, "r");
    if (!in) {
        fprintf(stderr, "error: cannot read '%s'\n", file);
        return BGC_ERR_USAGE;
    }
    signal(SIGINT, bgc_batch_on_signal);
    signal(SIGTERM, bgc_batch_on_signal);
    bgc_out.file = stdout;
    rc = bgc_batch_loop(in, &s, &p, given, project, &b, dir);
    if (in != stdin)
        fclose(in);
    return rc;
}
#endif /* BGC_NO_MAIN */
