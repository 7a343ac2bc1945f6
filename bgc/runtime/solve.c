/* ============================================================== solve === */
/* The solvers' common machinery (output times, failures, the run state, the first step
   size), the explicit Runge-Kutta family (fixed-step and embedded pairs, read from the
   tables of bgc/solvers.py above) and bgc_simulate, which picks a family's run function.
   The stiff families follow in bgc/runtime/stiff.c. */

#include <time.h> /* clock(): the processor time bgc_simulate reports in its stats */

/* Output times: t0 + k*dt for k < n, and t_end for k = n (see the top of the file). */
static long bgc_output_count(const bgc_settings *s)
{
    double n = ceil((s->t_end - s->t0) / s->dt - 1e-6);
    return n > 0.0 ? (long)n : 0;
}

static double bgc_output_time(const bgc_settings *s, long k, long n)
{
    return k >= n ? s->t_end : s->t0 + (double)k * s->dt;
}

/* Steps below this are too small for floating point to resolve at t (16 units in the last
   place of t; DBL_MIN at t = 0). */
static double bgc_hmin(double t)
{
    return bgc_max(16.0 * DBL_EPSILON * fabs(t), DBL_MIN);
}

static int bgc_fail(char *msg, size_t msg_size, double t, const char *what, const char *name)
{
    snprintf(msg, msg_size, "at t = %.17g: %s '%s' is not finite", t, what, name);
    return BGC_ERR_RUNTIME;
}

static int bgc_fail_step(char *msg, size_t msg_size, double t, double h, int worst)
{
    if (worst >= 0)
        snprintf(msg, msg_size, "at t = %.17g: step size too small (h = %.3g), limited by state '%s'",
                 t, h, bgc_state_names[worst]);
    else
        snprintf(msg, msg_size, "at t = %.17g: step size too small (h = %.3g)", t, h);
    return BGC_ERR_RUNTIME;
}

static volatile sig_atomic_t bgc_stop_signal = 0;

void bgc_request_stop(int sig)
{
    bgc_stop_signal = (sig_atomic_t)sig;
}

static int bgc_fail_block(char *msg, size_t msg_size, const bgc_work *w)
{
    bgc_work_message(w, msg, msg_size);
    return BGC_ERR_RUNTIME;
}

static int bgc_fail_memory(char *msg, size_t msg_size)
{
    snprintf(msg, msg_size, "out of memory");
    return BGC_ERR_RUNTIME;
}

/* A run in progress: what every family's run function shares.  A run function integrates
   from (r->t, y) to s->t_end, hands the output times k = r->kout .. r->nout to the sink as it
   passes them (k = 0, the start, has been handed over before), keeps r->t and y at its last
   accepted step, and returns 0, an error (message in r->msg), the sink's nonzero value, or
   BGC_STIFF (an auto run's explicit phase found the problem stiff; r->h is its last step). */
typedef struct bgc_run {
    const bgc_settings *s;
    const bgc_params *p;
    bgc_work *w;
    bgc_sink sink;
    void *ctx;
    bgc_stats *st;
    char *msg;
    size_t msg_size;
    long nout, kout;
    double t, h;
    int detect_stiffness;
    long steps_out;  /* st->steps at the last output, at t_out */
    double t_out;
} bgc_run;
#define BGC_STIFF (-1)

/* Evaluates the outputs at (t, x), checks them and hands them to the sink. */
static int bgc_emit(bgc_run *r, double t, const double *x)
{
    double *y = r->w->v + BGC_WORK_Y;
    int j;
    if (bgc_model_outputs(t, x, r->p, r->w, y))
        return bgc_fail_block(r->msg, r->msg_size, r->w);
    j = bgc_first_nonfinite(y, BGC_NUM_OUTPUTS);
    if (j >= 0)
        return bgc_fail(r->msg, r->msg_size, t, "output", bgc_output_names[j]);
    r->steps_out = r->st->steps;
    r->t_out = t;
    return r->sink ? r->sink(r->ctx, t, x, y) : 0;
}

/* Counts an accepted step ending at t; BGC_ERR_RUNTIME and a message if a stop was asked or
   the step budget since the last output is spent. */
static int bgc_accept(bgc_run *r, double t)
{
    r->st->steps++;
    if (bgc_stop_signal) {
        snprintf(r->msg, r->msg_size, "at t = %.17g: interrupted by signal %d", t,
                 (int)bgc_stop_signal);
        return BGC_ERR_RUNTIME;
    }
    if (r->s->max_steps > 0 && r->st->steps - r->steps_out > r->s->max_steps) {
        snprintf(r->msg, r->msg_size, "at t = %.17g: step budget spent: %ld steps since the "
                 "output at t = %.17g (the step size runs away; --max-steps raises the budget)",
                 t, r->s->max_steps, r->t_out);
        return BGC_ERR_RUNTIME;
    }
    return 0;
}

/* A method's continuous extension: the state at t + theta h of the step just accepted. */
typedef void (*bgc_dense_fn)(const void *dctx, double theta, double *yout);

/* After an accepted step from t to tph = t + h (exactly t_end on the last step): hands over
   the output times in (t, tph], tph itself from y1 and the others through dense (prepare, if
   not NULL, is called once before the first of them).  yout: N doubles of scratch. */
static int bgc_emit_step(bgc_run *r, double t, double h, double tph, const double *y1,
                         int (*prepare)(void *dctx), bgc_dense_fn dense, void *dctx,
                         double *yout)
{
    int rc, prepared = prepare == NULL;
    for (; r->kout <= r->nout; r->kout++) {
        const double tk = bgc_output_time(r->s, r->kout, r->nout);
        if (tk > tph)
            break;
        if (tk == tph) {
            rc = bgc_emit(r, tk, y1);
        } else {
            if (!prepared) {
                rc = prepare(dctx);
                if (rc)
                    return rc;
                prepared = 1;
            }
            dense(dctx, (tk - t) / h, yout);
            rc = bgc_emit(r, tk, yout);
        }
        if (rc)
            return rc;
    }
    return 0;
}

/* The error-norm weight of component i (Hairer's): atol + rtol * max(|y_i|, |y1_i|). */
static inline double bgc_weight(const bgc_settings *s, double y, double y1)
{
    return s->atol + s->rtol * bgc_max(fabs(y), fabs(y1));
}

/* Hairer's initial step size guess (HINIT) for a method of order q; f1, y1: scratch. */
static double bgc_initial_step(bgc_run *r, int q, const double *y, const double *f0,
                               double hmax, double *y1, double *f1)
{
    enum { N = BGC_NUM_STATES };
    const bgc_settings *s = r->s;
    double dnf = 0.0, dny = 0.0, der2 = 0.0, der12, h, h1;
    int i;
    for (i = 0; i < N; i++) {
        const double sk = s->atol + s->rtol * fabs(y[i]);
        const double qf = f0[i] / sk, qy = y[i] / sk;
        dnf += qf * qf;
        dny += qy * qy;
    }
    h = (dnf <= 1e-10 || dny <= 1e-10) ? 1e-6 : sqrt(dny / dnf) * 0.01;
    h = bgc_min(h, hmax);
    for (i = 0; i < N; i++)
        y1[i] = y[i] + h * f0[i];
    r->st->rhs++;
    if (bgc_model_rhs(r->t + h, y1, r->p, r->w, f1))
        return h; /* a block failed there: start small, the step control takes over */
    for (i = 0; i < N; i++) {
        const double d = (f1[i] - f0[i]) / (s->atol + s->rtol * fabs(y[i]));
        der2 += d * d;
    }
    der2 = sqrt(der2) / h;
    der12 = bgc_max(sqrt(dnf), fabs(der2)); /* a NaN der2 is ignored */
    h1 = der12 <= 1e-15 ? bgc_max(1e-6, h * 1e-3) : pow(0.01 / der12, 1.0 / (double)q);
    if (!(h1 > 0.0))
        h1 = h * 1e-3;
    return bgc_min(bgc_min(100.0 * h, h1), hmax);
}

/* ------------------------------------------------ explicit Runge-Kutta methods --- */

/* out = y + h * sum_j w[j * stride] k_j over the stages j < count with a nonzero weight
   (y NULL: out = h * sum); summed stage by stage, left to right, as the Python runtime does.
   out must not overlap y or k. */
static void bgc_combine(double *out, const double *y, double h, const double *w, int stride,
                        int count, const double *k)
{
    enum { N = BGC_NUM_STATES, D = BGC_DIM(BGC_NUM_STATES) };
    int j, l, first = 1;
    for (j = 0; j < count; j++) {
        const double a = w[(size_t)j * stride];
        const double *kj = k + (size_t)j * D;
        if (a == 0.0)
            continue;
        if (first)
            for (l = 0; l < N; l++)
                out[l] = a * kj[l];
        else
            for (l = 0; l < N; l++)
                out[l] += a * kj[l];
        first = 0;
    }
    if (first)
        for (l = 0; l < N; l++)
            out[l] = 0.0;
    if (y)
        for (l = 0; l < N; l++)
            out[l] = y[l] + h * out[l];
    else
        for (l = 0; l < N; l++)
            out[l] = h * out[l];
}

/* ys = y + h * sum_j a[j] k_j over the stages j < i. */
static void bgc_erk_argument(const bgc_erk *m, int i, double h, const double *y,
                             const double *k, double *ys)
{
    bgc_combine(ys, y, h, m->a + (size_t)i * m->all, 1, i, k);
}

/* One fixed step from (t, y) to t + h, in place; k: the stages, ys: scratch. */
static int bgc_fixed_step(bgc_run *r, const bgc_erk *m, double t, double h, double *y,
                          double *k, double *ys)
{
    enum { N = BGC_NUM_STATES, D = BGC_DIM(BGC_NUM_STATES) };
    int i, l;
    for (i = 0; i < m->stages; i++) {
        double *ki = k + (size_t)i * D;
        if (i == 0) {
            if (bgc_model_rhs(t, y, r->p, r->w, ki))
                return bgc_fail_block(r->msg, r->msg_size, r->w);
            l = bgc_first_nonfinite(ki, N);
            if (l >= 0)
                return bgc_fail(r->msg, r->msg_size, t, "derivative of state", bgc_state_names[l]);
        } else {
            bgc_erk_argument(m, i, h, y, k, ys);
            if (bgc_model_rhs(t + m->c[i] * h, ys, r->p, r->w, ki))
                return bgc_fail_block(r->msg, r->msg_size, r->w);
        }
    }
    r->st->rhs += m->stages;
    bgc_combine(ys, y, h, m->b, 1, m->stages, k);
    memcpy(y, ys, sizeof(double) * N);
    l = bgc_first_nonfinite(y, N);
    if (l >= 0)
        return bgc_fail(r->msg, r->msg_size, t + h, "state", bgc_state_names[l]);
    return bgc_accept(r, t + h);
}

/* Number of fixed steps of size about h in span: steps of h, the last one shorter. */
static long bgc_substeps(double span, double h)
{
    double q = span / h, m;
    if (!(q < 1e15))
        return -1;
    m = ceil(q - 1e-6);
    return m < 1.0 ? 1 : (long)m;
}

/* Fixed-step methods: steps of s->step (or dt) that land exactly on every output time. */
static int bgc_run_fixed(bgc_run *r, const bgc_method *method, double *y)
{
    enum { D = BGC_DIM(BGC_NUM_STATES) };
    const bgc_erk *m = method->erk;
    const double hstep = r->s->step > 0.0 ? r->s->step : r->s->dt;
    double *mem = malloc((size_t)(m->stages + 1) * D * sizeof *mem);
    double ta = r->t;
    long j;
    int rc = mem ? 0 : bgc_fail_memory(r->msg, r->msg_size);
    for (; r->kout <= r->nout && rc == 0; r->kout++) {
        const double tb = bgc_output_time(r->s, r->kout, r->nout);
        const long steps = bgc_substeps(tb - ta, hstep);
        if (steps < 0) {
            rc = bgc_fail_step(r->msg, r->msg_size, ta, hstep, -1);
            break;
        }
        for (j = 0; j < steps && rc == 0; j++) {
            const double t = ta + (double)j * hstep;
            const double t1 = j + 1 == steps ? tb : ta + (double)(j + 1) * hstep;
            if (!(t1 - t >= bgc_hmin(t)))
                rc = bgc_fail_step(r->msg, r->msg_size, t, t1 - t, -1);
            else
                rc = bgc_fixed_step(r, m, t, t1 - t, y, mem + D, mem);
            if (rc == 0)
                r->t = t1;
        }
        if (rc == 0)
            rc = bgc_emit(r, tb, y);
        ta = tb;
    }
    free(mem);
    return rc;
}

/* The dense output of an embedded pair: the extra stages, then q_d = h sum_i P[i][d] k_i,
   y(theta) = y + theta (q_0 + theta (q_1 + ...)). */
typedef struct bgc_erk_dense {
    bgc_run *r;
    const bgc_erk *m;
    double t, h;
    const double *y;
    double *k, *ys, *q;
    int failed;
} bgc_erk_dense;

static int bgc_erk_prepare(void *dctx)
{
    enum { N = BGC_NUM_STATES, D = BGC_DIM(BGC_NUM_STATES) };
    bgc_erk_dense *d = dctx;
    const bgc_erk *m = d->m;
    int i, j;
    for (i = m->stages; i < m->all; i++) {
        bgc_erk_argument(m, i, d->h, d->y, d->k, d->ys);
        if (bgc_model_rhs(d->t + m->c[i] * d->h, d->ys, d->r->p, d->r->w, d->k + (size_t)i * D))
            return bgc_fail_block(d->r->msg, d->r->msg_size, d->r->w);
        d->r->st->rhs++;
    }
    for (j = 0; j < m->degree; j++)
        bgc_combine(d->q + (size_t)j * D, NULL, d->h, m->P + j, m->degree, m->all, d->k);
    return 0;
}

static void bgc_erk_dense_at(const void *dctx, double theta, double *yout)
{
    enum { N = BGC_NUM_STATES, D = BGC_DIM(BGC_NUM_STATES) };
    const bgc_erk_dense *d = dctx;
    const int deg = d->m->degree;
    int j, l;
    for (l = 0; l < N; l++) {
        double acc = d->q[(size_t)(deg - 1) * D + l];
        for (j = deg - 2; j >= 0; j--)
            acc = d->q[(size_t)j * D + l] + theta * acc;
        yout[l] = d->y[l] + theta * acc;
    }
}

/* Embedded explicit pairs: adaptive steps (never shortened for output), Hairer's error norm
   and step-size controller, outputs by the dense output; with s->step > 0, steps of that size
   without error control (to measure a method's order, or its stability at a given step).
   With r->detect_stiffness, Hairer's stiffness test ends the run with BGC_STIFF once it has
   fired on 15 accepted steps. */
static int bgc_run_erk(bgc_run *r, const bgc_method *method, double *y)
{
    enum { N = BGC_NUM_STATES, D = BGC_DIM(BGC_NUM_STATES) };
    const bgc_erk *m = method->erk;
    const bgc_settings *s = r->s;
    const int last_stage = m->stages - 1;
    const int fsal_first = m->fsal && m->e[last_stage] != 0.0; /* evaluate f(y1) before the estimate */
    const double expo1 = 1.0 / (double)method->q - method->expo_beta * method->beta;
    const double hmax = s->t_end - s->t0;
    const int fixed = s->step > 0.0;
    double *mem = malloc((size_t)(m->all + 5 + m->degree) * D * sizeof *mem);
    double *k, *ys, *y1, *yout, *ystiff, *e2v, *q;
    double t = r->t, h, hnew, facold = 1e-4, wanted = 0.0;
    int i, l, rc, reject = 0, last = 0, worst = -1, bad = -1, bad_kind = 0, failed;
    int stiff_count = 0, nonstiff_count = 0;
    bgc_erk_dense dense;

    if (!mem)
        return bgc_fail_memory(r->msg, r->msg_size);
    k = mem;
    ys = k + (size_t)m->all * D;
    y1 = ys + D;
    yout = y1 + D;
    ystiff = yout + D;
    e2v = ystiff + D;
    q = e2v + D;
    dense.r = r;
    dense.m = m;
    dense.k = k;
    dense.ys = ys;
    dense.q = q;
    rc = 0;
    if (r->kout > r->nout)
        goto done;
    r->st->rhs++;
    if (bgc_model_rhs(t, y, r->p, r->w, k)) {
        rc = bgc_fail_block(r->msg, r->msg_size, r->w);
        goto done;
    }
    i = bgc_first_nonfinite(k, N);
    if (i >= 0) {
        rc = bgc_fail(r->msg, r->msg_size, t, "derivative of state", bgc_state_names[i]);
        goto done;
    }
    if (fixed)
        h = s->step;
    else if (r->h > 0.0)
        h = bgc_min(r->h, hmax);
    else
        h = bgc_initial_step(r, method->q, y, k, hmax, ys, k + D);

    for (;;) {
        double tph, err = 0.0, err2 = 0.0, worst_q = -1.0, fac11, fac;
        if (!(h >= bgc_hmin(t))) {
            if (bad == -2)
                rc = bgc_fail_block(r->msg, r->msg_size, r->w);
            else if (bad >= 0)
                rc = bgc_fail(r->msg, r->msg_size, t,
                              bad_kind == 1 ? "state" : "derivative of state", bgc_state_names[bad]);
            else
                rc = bgc_fail_step(r->msg, r->msg_size, t, h, worst);
            goto done;
        }
        wanted = h;
        if (t + 1.01 * h - s->t_end > 0.0) {
            h = s->t_end - t;
            last = 1;
        }
        tph = last ? s->t_end : t + h;
        failed = 0;
        for (i = 1; i < m->stages && !failed; i++) {
            if (m->fsal && i == last_stage)
                break; /* f(y1), below */
            bgc_erk_argument(m, i, h, y, k, ys);
            if (i == method->stiff_i)
                memcpy(ystiff, ys, sizeof(double) * N);
            failed = bgc_model_rhs(m->c[i] == 1.0 ? tph : t + m->c[i] * h, ys, r->p, r->w,
                                   k + (size_t)i * D);
            r->st->rhs++;
        }
        if (!failed) {
            bgc_combine(y1, y, h, m->b, 1, m->stages, k);
            if (fsal_first) {
                failed = bgc_model_rhs(tph, y1, r->p, r->w, k + (size_t)last_stage * D);
                r->st->rhs++;
            }
        }
        if (failed && fixed) {
            rc = bgc_fail_block(r->msg, r->msg_size, r->w);
            goto done;
        }
        if (failed) { /* an algebraic block failed in a stage: retry with a much smaller step */
            bad = -2;
            h = h * method->fac_min;
            reject = 1;
            last = 0;
            r->st->rejected++;
            continue;
        }

        /* Hairer's error norm: RMS of err_i / (atol + rtol * max(|y_i|, |y1_i|)); DOP853
           combines its two estimates. */
        bgc_combine(yout, NULL, m->e2 ? 1.0 : h, m->e, 1, m->stages, k);
        if (m->e2)
            bgc_combine(e2v, NULL, 1.0, m->e2, 1, m->stages, k);
        for (l = 0; l < N; l++) {
            const double sk = bgc_weight(s, y[l], y1[l]);
            const double qq = yout[l] / sk;
            err += qq * qq;
            if (qq * qq > worst_q) {
                worst_q = qq * qq;
                worst = l;
            }
            if (m->e2)
                err2 += (e2v[l] / sk) * (e2v[l] / sk);
        }
        if (N == 0 || (fixed && err == err)) {
            err = 0.0; /* fixed steps: accepted as they are (a non-finite stage fails below) */
        } else if (m->e2) {
            double deno = err + 0.01 * err2;
            if (!(deno > 0.0))
                deno = 1.0;
            err = fabs(h) * err * sqrt(1.0 / ((double)N * deno));
        } else {
            err = sqrt(err / (double)N);
        }
        if (err != err && fixed) {
            i = bgc_first_nonfinite(y1, N);
            rc = bgc_fail(r->msg, r->msg_size, tph, "state", bgc_state_names[i >= 0 ? i : 0]);
            goto done;
        }
        if (err != err) { /* a non-finite stage: retry with a much smaller step */
            bad = bgc_first_nonfinite(y1, N);
            bad_kind = 1;
            for (i = 1; i < m->stages && bad < 0; i++) {
                bad = bgc_first_nonfinite(k + (size_t)i * D, N);
                bad_kind = 2;
            }
            h = h * method->fac_min;
            reject = 1;
            last = 0;
            r->st->rejected++;
            continue;
        }

        fac11 = pow(err, expo1);
        fac = fac11 / pow(facold, method->beta);
        fac = bgc_max(1.0 / method->fac_max, bgc_min(1.0 / method->fac_min, fac / method->safe));
        hnew = fixed ? s->step : h / fac;
        if (err <= 1.0) {
            facold = bgc_max(err, 1e-4);
            i = bgc_first_nonfinite(y1, N);
            if (i >= 0) {
                rc = bgc_fail(r->msg, r->msg_size, tph, "state", bgc_state_names[i]);
                goto done;
            }
            rc = bgc_accept(r, tph);
            if (rc)
                goto done;
            if (m->fsal && !fsal_first) {
                r->st->rhs++;
                if (bgc_model_rhs(tph, y1, r->p, r->w, k + (size_t)last_stage * D)) {
                    rc = bgc_fail_block(r->msg, r->msg_size, r->w);
                    goto done;
                }
            }
            dense.t = t;
            dense.h = h;
            dense.y = y;
            rc = bgc_emit_step(r, t, h, tph, y1, bgc_erk_prepare, bgc_erk_dense_at, &dense, yout);
            if (rc)
                goto done;
            if (r->detect_stiffness && method->stiff_i >= 0) {
                /* h |f(Y_i) - f(Y_j)| / |Y_i - Y_j| for two stages at the same time */
                const double *ki = k + (size_t)method->stiff_i * D;
                const double *kj = k + (size_t)method->stiff_j * D;
                const double *yj = method->stiff_j == last_stage ? y1 : ys;
                double num = 0.0, den = 0.0;
                for (l = 0; l < N; l++) {
                    num += (kj[l] - ki[l]) * (kj[l] - ki[l]);
                    den += (yj[l] - ystiff[l]) * (yj[l] - ystiff[l]);
                }
                if (den > 0.0 && h * sqrt(num / den) > method->stiff_bound) {
                    nonstiff_count = 0;
                    if (++stiff_count == 15) {
                        memcpy(y, y1, sizeof(double) * N);
                        r->t = tph;
                        r->h = hnew;
                        rc = BGC_STIFF;
                        goto done;
                    }
                } else if (++nonstiff_count == 6) {
                    stiff_count = 0;
                }
            }
            if (m->fsal)
                memcpy(k, k + (size_t)last_stage * D, sizeof(double) * N);
            else if (!last) {
                r->st->rhs++;
                if (bgc_model_rhs(tph, y1, r->p, r->w, k)) {
                    rc = bgc_fail_block(r->msg, r->msg_size, r->w);
                    goto done;
                }
            }
            memcpy(y, y1, sizeof(double) * N);
            t = tph;
            r->t = t;
            if (last) {
                if (!fixed) /* the step to go on with: the controller's, or the one cut short */
                    r->st->h_next = bgc_max(hnew, wanted);
                goto done;
            }
            if (fabs(hnew) > hmax && !fixed)
                hnew = hmax;
            if (reject)
                hnew = bgc_min(hnew, h);
            reject = 0;
            bad = -1;
        } else {
            hnew = h / bgc_min(1.0 / method->fac_min, fac11 / method->safe);
            reject = 1;
            last = 0;
            r->st->rejected++;
        }
        h = hnew;
    }
done:
    free(mem);
    return rc;
}

/* ------------------------------------------------------------ bgc_simulate --- */

int bgc_solver_index(const char *name)
{
    int k;
    for (k = 0; k < BGC_NUM_SOLVERS; k++)
        if (strcmp(name, bgc_solver_names[k]) == 0)
            return k;
    return -1;
}

void bgc_print_stats(FILE *f, const bgc_stats *st)
{
    fprintf(f, "stats: steps=%ld rejected=%ld rhs=%ld jac=%ld lu=%ld solves=%ld", st->steps,
            st->rejected, st->rhs, st->jac, st->lu, st->solves);
    if (st->switched)
        fprintf(f, " stiff_from=%.17g", st->t_switch);
    fprintf(f, " cpu=%.6e\n", st->cpu);
}

static int bgc_run_rosenbrock(bgc_run *r, const bgc_method *method, double *y);
static int bgc_run_radau(bgc_run *r, const bgc_method *method, double *y);

static int bgc_run_family(bgc_run *r, int solver, double *y)
{
    const bgc_method *m = &bgc_methods[solver];
    switch (m->family) {
    case BGC_FAMILY_FIXED:
        return bgc_run_fixed(r, m, y);
    case BGC_FAMILY_ERK:
        return bgc_run_erk(r, m, y);
    case BGC_FAMILY_ROSENBROCK:
        return bgc_run_rosenbrock(r, m, y);
    case BGC_FAMILY_RADAU:
        return bgc_run_radau(r, m, y);
    default:
        snprintf(r->msg, r->msg_size, "solver '%s' cannot run by itself", m->name);
        return BGC_ERR_USAGE;
    }
}

/* Integrates y (the state at s->t0, in the workspace w) to s->t_end: bgc_simulate's run,
   in a workspace the caller keeps. */
static int bgc_integrate(const bgc_settings *s, const bgc_params *p, bgc_work *w, double *y,
                         bgc_sink sink, void *ctx, bgc_stats *stats, char *msg, size_t msg_size)
{
    bgc_params q = *p;
    bgc_run r;
    int i, rc = bgc_check_settings(s, msg, msg_size);
    if (rc)
        return rc;
    w->rtol = s->rtol;
    w->atol = s->atol;
    r.w = w;
    r.s = s;
    r.p = &q;
    r.sink = sink;
    r.ctx = ctx;
    r.st = stats;
    r.msg = msg;
    r.msg_size = msg_size;
    r.nout = bgc_output_count(s);
    r.kout = 1;
    r.t = s->t0;
    r.h = s->h0;
    stats->h_next = 0.0;
    stats->order_next = 0;
    r.detect_stiffness = 0;
    r.steps_out = stats->steps;
    r.t_out = s->t0;
    bgc_params_update(&q);
    i = bgc_first_nonfinite(y, BGC_NUM_STATES);
    if (i >= 0)
        return bgc_fail(msg, msg_size, s->t0, "state", bgc_state_names[i]);
    rc = bgc_emit(&r, s->t0, y);
    if (rc == 0 && bgc_methods[s->solver].family == BGC_FAMILY_AUTO) {
        const bgc_method *m = &bgc_methods[s->solver];
        r.detect_stiffness = 1;
        rc = bgc_run_family(&r, m->explicit_solver, y);
        if (rc == BGC_STIFF) {
            stats->switched = 1;
            stats->t_switch = r.t;
            r.detect_stiffness = 0;
            rc = bgc_run_family(&r, m->stiff_solver, y);
        }
    } else if (rc == 0) {
        rc = bgc_run_family(&r, s->solver, y);
    }
    return rc;
}

int bgc_simulate(const bgc_settings *s, const bgc_params *p, const double *x0, bgc_sink sink,
                 void *ctx, bgc_stats *stats, char *msg, size_t msg_size)
{
    const clock_t start = clock();
    bgc_work *w;
    int rc = bgc_check_settings(s, msg, msg_size);
    if (rc)
        return rc;
    w = bgc_work_new();
    if (!w)
        return bgc_fail_memory(msg, msg_size);
    memcpy(w->v + BGC_WORK_Y0, x0, sizeof(double) * BGC_NUM_STATES);
    rc = bgc_integrate(s, p, w, w->v + BGC_WORK_Y0, sink, ctx, stats, msg, msg_size);
    bgc_work_free(w);
    stats->cpu = (double)(clock() - start) / CLOCKS_PER_SEC;
    return rc;
}

int bgc_advance(const bgc_settings *s, const bgc_params *p, bgc_work *w, double *x,
                bgc_sink sink, void *ctx, bgc_stats *stats, char *msg, size_t msg_size)
{
    const clock_t start = clock();
    double *y = w->v + BGC_WORK_Y0;
    int rc;
    memcpy(y, x, sizeof(double) * BGC_NUM_STATES);
    rc = bgc_integrate(s, p, w, y, sink, ctx, stats, msg, msg_size);
    memcpy(x, y, sizeof(double) * BGC_NUM_STATES);
    stats->cpu += (double)(clock() - start) / CLOCKS_PER_SEC;
    return rc;
}
