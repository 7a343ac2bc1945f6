/* ================================================================ erk === */
/* The explicit Runge-Kutta family, read from the tables of bgc/solvers.py above: the
   fixed-step methods (bgc_family_fixed) and the embedded pairs (bgc_family_erk), as steps
   for the driver (drive.c).  Each keeps the family contract, the numbered list on the Python
   runtime's _Family (bgc/runtime/drive.py; its twins there are _FixedSteps and _Erk in
   bgc/runtime/erk.py): the items cited below are that list's. */

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

/* An explicit method's state: its stages k (all of them, the dense output's included), the
   stage argument ys, the error estimates, the dense output's polynomials q, the step last
   accepted (t, h, from y) and the controller's memory. */
typedef struct bgc_erk_state {
    bgc_run *r;
    const bgc_method *method;
    const bgc_erk *m;
    int fixed, fsal_first, worst, stiff_count, nonstiff_count;
    double *k, *ys, *est, *ystiff, *e2v, *q;
    double t, h, facold;
    const double *y;
} bgc_erk_state;

static void bgc_erk_finish(void *state)
{
    bgc_erk_state *e = state;
    free(e->k);
    free(e);
}

/* The state, or NULL with *rc set (no memory). */
static bgc_erk_state *bgc_erk_new(bgc_run *r, int *rc)
{
    enum { D = BGC_DIM(BGC_NUM_STATES) };
    const bgc_erk *m = r->method->erk;
    bgc_erk_state *e = calloc(1, sizeof *e);
    double *mem = malloc((size_t)(m->all + 4 + m->degree) * D * sizeof *mem);
    if (!e || !mem) {
        free(e);
        free(mem);
        *rc = bgc_fail_memory(r->msg, r->msg_size);
        return NULL;
    }
    e->r = r;
    e->method = r->method;
    e->m = m;
    e->fixed = r->fixed;
    e->fsal_first = m->fsal && m->e && m->e[m->stages - 1] != 0.0;
    e->worst = -1;
    e->facold = 1e-4;
    e->k = mem;
    e->ys = e->k + (size_t)m->all * D;
    e->est = e->ys + D;
    e->ystiff = e->est + D;
    e->e2v = e->ystiff + D;
    e->q = e->e2v + D;
    return e;
}

/* ---------------------------------------------------------------- fixed step --- */

/* The fixed-step methods: each step from f(t, y) afresh (no error estimate, no dense output:
   the driver lands a step on every output time, span_grid 0, contract items 6 and 12; a
   failure ends the run, item 11). */
static void *bgc_fixed_start(bgc_run *r, const double *y, double *h, int *rc)
{
    (void)y;
    (void)h;
    return bgc_erk_new(r, rc);
}

static void bgc_fixed_step(void *state, bgc_run *r, double t, double h, double tph,
                           const double *y, double *y1, bgc_outcome *o)
{
    enum { N = BGC_NUM_STATES, D = BGC_DIM(BGC_NUM_STATES) };
    bgc_erk_state *e = state;
    const bgc_erk *m = e->m;
    int i, l;
    (void)tph;
    o->kind = BGC_STEP_END;
    for (i = 0; i < m->stages; i++) {
        double *ki = e->k + (size_t)i * D;
        if (i > 0)
            bgc_erk_argument(m, i, h, y, e->k, e->ys);
        if (bgc_model_rhs(i == 0 ? t : t + m->c[i] * h, i == 0 ? y : e->ys, r->p, r->w, ki)) {
            o->rc = bgc_fail_block(r->msg, r->msg_size, r->w);
            return;
        }
        l = i == 0 ? bgc_first_nonfinite(ki, N) : -1;
        if (l >= 0) {
            o->rc = bgc_fail(r->msg, r->msg_size, t, "derivative of state", bgc_state_names[l]);
            return;
        }
    }
    r->st->rhs += m->stages;
    bgc_combine(y1, y, h, m->b, 1, m->stages, e->k);
    o->kind = BGC_STEP_ACCEPT;
    o->hnew = h;
    o->worst = -1;
}

static const bgc_family bgc_family_fixed = {
    bgc_fixed_start, bgc_fixed_step, NULL, NULL, NULL, NULL, NULL, bgc_erk_finish, 0};

/* ------------------------------------------------------------ embedded pairs --- */

/* Embedded explicit pairs: Hairer's error norm and step-size controller (DOPRI5, DOP853),
   outputs by the dense output: the extra stages, then q_d = h sum_i P[i][d] k_i,
   y(theta) = y + theta (q_0 + theta (q_1 + ...)).  On fixed steps (s->step > 0) without
   error control, to measure a method's order or its stability at a given step.  With
   r->detect_stiffness, Hairer's stiffness test ends the phase with BGC_STIFF once it has
   fired on 15 accepted steps.  bgc_erk_start: the state, f at the first point and the first
   step (contract items 1 and 2). */
static void *bgc_erk_start(bgc_run *r, const double *y, double *h, int *rc)
{
    enum { D = BGC_DIM(BGC_NUM_STATES) };
    bgc_erk_state *e = bgc_erk_new(r, rc);
    if (!e)
        return NULL;
    *rc = bgc_start_rhs(r, r->t, y, e->k);
    if (*rc) {
        bgc_erk_finish(e);
        return NULL;
    }
    if (!e->fixed)
        *h = bgc_first_step(r, y, e->k, e->ys, e->k + D);
    return e;
}

/* Hairer's error norm: RMS of err_i / (atol + rtol * max(|y_i|, |y1_i|)); DOP853 combines
   its two estimates.  *worst: the component with the largest share (contract item 4). */
static double bgc_erk_error(bgc_erk_state *e, const bgc_settings *s, double h, const double *y,
                            const double *y1)
{
    const int N = bgc_error_states(s);
    const bgc_erk *m = e->m;
    double err = 0.0, err2 = 0.0, worst_q = -1.0;
    int l;
    bgc_combine(e->est, NULL, m->e2 ? 1.0 : h, m->e, 1, m->stages, e->k);
    if (m->e2)
        bgc_combine(e->e2v, NULL, 1.0, m->e2, 1, m->stages, e->k);
    for (l = 0; l < N; l++) {
        const double sk = bgc_weight(s, y[l], y1[l]);
        const double qq = e->est[l] / sk;
        err += qq * qq;
        if (qq * qq > worst_q) {
            worst_q = qq * qq;
            e->worst = l;
        }
        if (m->e2)
            err2 += (e->e2v[l] / sk) * (e->e2v[l] / sk);
    }
    if (N == 0 || (e->fixed && err == err))
        return 0.0; /* fixed steps: accepted as they are (a non-finite stage fails below) */
    if (m->e2) {
        double deno = err + 0.01 * err2;
        if (!(deno > 0.0))
            deno = 1.0;
        return fabs(h) * err * sqrt(1.0 / ((double)N * deno));
    }
    return sqrt(err / (double)N);
}

/* A failed attempt: a step much smaller (or, on fixed steps, the end of the run; contract
   items 3 and 11). */
static void bgc_erk_retry(bgc_erk_state *e, bgc_run *r, double h, double tph, const double *y1,
                          int block, bgc_outcome *o)
{
    enum { N = BGC_NUM_STATES, D = BGC_DIM(BGC_NUM_STATES) };
    int i;
    if (e->fixed) {
        i = block ? 0 : bgc_first_nonfinite(y1, N);
        o->kind = BGC_STEP_END;
        o->rc = block ? bgc_fail_block(r->msg, r->msg_size, r->w)
                      : bgc_fail(r->msg, r->msg_size, tph, "state", bgc_state_names[i >= 0 ? i : 0]);
        return;
    }
    o->kind = BGC_STEP_RETRY;
    o->hnew = h * e->method->fac_min;
    if (block) {
        o->bad = BGC_BAD_BLOCK;
        return;
    }
    o->bad = bgc_first_nonfinite(y1, N);
    o->bad_kind = 1;
    for (i = 1; i < e->m->stages && o->bad < 0; i++) {
        o->bad = bgc_first_nonfinite(e->k + (size_t)i * D, N);
        o->bad_kind = 2;
    }
}

/* One attempt (contract item 3): the stages, y1, the error estimate and Hairer's step-size
   controller with Lund's stabilisation (beta). */
static void bgc_erk_step(void *state, bgc_run *r, double t, double h, double tph,
                         const double *y, double *y1, bgc_outcome *o)
{
    enum { D = BGC_DIM(BGC_NUM_STATES) };
    bgc_erk_state *e = state;
    const bgc_erk *m = e->m;
    const bgc_method *method = e->method;
    const int last_stage = m->stages - 1;
    const double expo1 = 1.0 / (double)method->q - method->expo_beta * method->beta;
    double err, fac11, fac;
    int i, failed = 0;
    for (i = 1; i < m->stages && !failed; i++) {
        if (m->fsal && i == last_stage)
            break; /* f(y1), below */
        bgc_erk_argument(m, i, h, y, e->k, e->ys);
        if (i == method->stiff_i)
            memcpy(e->ystiff, e->ys, sizeof(double) * BGC_NUM_STATES);
        failed = bgc_model_rhs(m->c[i] == 1.0 ? tph : t + m->c[i] * h, e->ys, r->p, r->w,
                               e->k + (size_t)i * D);
        r->st->rhs++;
    }
    if (!failed) {
        bgc_combine(y1, y, h, m->b, 1, m->stages, e->k);
        if (e->fsal_first) {
            failed = bgc_model_rhs(tph, y1, r->p, r->w, e->k + (size_t)last_stage * D);
            r->st->rhs++;
        }
    }
    if (failed) { /* an algebraic block failed in a stage */
        bgc_erk_retry(e, r, h, tph, y1, 1, o);
        return;
    }
    err = bgc_erk_error(e, r->s, h, y, y1);
    o->worst = e->worst;
    if (err != err) { /* a non-finite stage */
        bgc_erk_retry(e, r, h, tph, y1, 0, o);
        return;
    }
    fac11 = pow(err, expo1);
    fac = fac11 / pow(e->facold, method->beta);
    fac = bgc_max(1.0 / method->fac_max, bgc_min(1.0 / method->fac_min, fac / method->safe));
    if (err <= 1.0) {
        e->facold = bgc_max(err, 1e-4);
        e->t = t;
        e->h = h;
        e->y = y;
        o->kind = BGC_STEP_ACCEPT;
        o->hnew = e->fixed ? r->s->step : h / fac;
    } else {
        o->kind = BGC_STEP_REJECT;
        o->hnew = h / bgc_min(1.0 / method->fac_min, fac11 / method->safe);
    }
}

/* The last stage f(t + h, y1) of an FSAL pair whose estimate does not use it (contract
   item 5). */
static int bgc_erk_accepted(void *state, bgc_run *r, double tph, const double *y1)
{
    enum { D = BGC_DIM(BGC_NUM_STATES) };
    bgc_erk_state *e = state;
    const bgc_erk *m = e->m;
    if (!m->fsal || e->fsal_first)
        return 0;
    r->st->rhs++;
    if (bgc_model_rhs(tph, y1, r->p, r->w, e->k + (size_t)(m->stages - 1) * D))
        return bgc_fail_block(r->msg, r->msg_size, r->w);
    return 0;
}

/* The dense output (contract item 6): the extra stages and the q_d once, then y(theta). */
static int bgc_erk_prepare(void *state)
{
    enum { D = BGC_DIM(BGC_NUM_STATES) };
    bgc_erk_state *e = state;
    const bgc_erk *m = e->m;
    bgc_run *r = e->r;
    int i, j;
    for (i = m->stages; i < m->all; i++) {
        bgc_erk_argument(m, i, e->h, e->y, e->k, e->ys);
        if (bgc_model_rhs(e->t + m->c[i] * e->h, e->ys, r->p, r->w, e->k + (size_t)i * D))
            return bgc_fail_block(r->msg, r->msg_size, r->w);
        r->st->rhs++;
    }
    for (j = 0; j < m->degree; j++)
        bgc_combine(e->q + (size_t)j * D, NULL, e->h, m->P + j, m->degree, m->all, e->k);
    return 0;
}

static void bgc_erk_dense(const void *state, double theta, double *yout)
{
    enum { N = BGC_NUM_STATES, D = BGC_DIM(BGC_NUM_STATES) };
    const bgc_erk_state *e = state;
    const int deg = e->m->degree;
    int j, l;
    for (l = 0; l < N; l++) {
        double acc = e->q[(size_t)(deg - 1) * D + l];
        for (j = deg - 2; j >= 0; j--)
            acc = e->q[(size_t)j * D + l] + theta * acc;
        yout[l] = e->y[l] + theta * acc;
    }
}

/* After the outputs (contract item 7): Hairer's stiffness test, h |f(Y_i) - f(Y_j)| /
   |Y_i - Y_j| for two stages at the same time, then f at the new point (the FSAL stage, or
   evaluated). */
static int bgc_erk_after(void *state, bgc_run *r, double tph, const double *y1, int last)
{
    enum { N = BGC_NUM_STATES, D = BGC_DIM(BGC_NUM_STATES) };
    bgc_erk_state *e = state;
    const bgc_erk *m = e->m;
    const bgc_method *method = e->method;
    const int last_stage = m->stages - 1;
    int l;
    if (r->detect_stiffness && method->stiff_i >= 0) {
        const double *ki = e->k + (size_t)method->stiff_i * D;
        const double *kj = e->k + (size_t)method->stiff_j * D;
        const double *yj = method->stiff_j == last_stage ? y1 : e->ys;
        double num = 0.0, den = 0.0;
        for (l = 0; l < N; l++) {
            num += (kj[l] - ki[l]) * (kj[l] - ki[l]);
            den += (yj[l] - e->ystiff[l]) * (yj[l] - e->ystiff[l]);
        }
        if (den > 0.0 && e->h * sqrt(num / den) > method->stiff_bound) {
            e->nonstiff_count = 0;
            if (++e->stiff_count == 15)
                return BGC_STIFF;
        } else if (++e->nonstiff_count == 6) {
            e->stiff_count = 0;
        }
    }
    if (m->fsal) {
        memcpy(e->k, e->k + (size_t)last_stage * D, sizeof(double) * N);
    } else if (!last) {
        r->st->rhs++;
        if (bgc_model_rhs(tph, y1, r->p, r->w, e->k))
            return bgc_fail_block(r->msg, r->msg_size, r->w);
    }
    return 0;
}

static const bgc_family bgc_family_erk = {
    bgc_erk_start, bgc_erk_step, bgc_erk_accepted, bgc_erk_prepare, bgc_erk_dense,
    bgc_erk_after, NULL, bgc_erk_finish, 1};
