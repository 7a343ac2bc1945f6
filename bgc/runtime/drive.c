/* ============================================================== drive === */
/* The step driver: everything a run does between two steps, for every solver.  A method
   family (erk.c, stiff.c) supplies only its step and its own state (stages, Jacobian,
   factorisations, order, step-size controller); the driver owns the output times and the
   dense output, the last step's clamp onto t_end, the fixed-step grid, the smallest step, the
   step budget and the stop request, the non-finite checks of the accepted state, the retries
   after a failed attempt, the switch of `auto` to its stiff phase, and the statistics.
   Adding a method is an entry in bgc/solvers.py plus, for a new family, a bgc_family.

   The contract of a family, bgc_family below, is written once for both runtimes: the numbered
   list on the Python runtime's family type, _Family (bgc/runtime/drive.py), which erk.c and
   stiff.c cite as "contract item N".  bgc_family's members, in the order the driver calls
   them:
     start     items 1 and 2: the family's state at (r->t, y), NULL with *rc and the message
               set if that fails; *h, the first step of an adaptive run;
     step      item 3 (and 4, the error estimate; 9, the Jacobian): the attempt's outcome in
               a bgc_outcome, BGC_STEP_END with rc and the message for a failure that ends
               the run (item 11), the error estimate's worst component in o->worst;
     accepted  item 5;
     prepare, dense  item 6 (prepare once per step, before its first dense value);
     after     item 7 (BGC_STIFF: the stiffness test fired);
     next_h    item 8;
     finish    its state freed (item 1: after an event, finish then start);
     span_grid item 12.
   A NULL member does nothing (next_h: the controller's step is taken; dense: none).
   A located event (the hybrid models' hook) will end an accepted step early at t* in
   (t, tph]: the driver hands on the outputs up to t*, takes the dense output there as the new
   point, applies the event's resets and starts the family afresh (finish, then start), so
   each method restarts from a clean history as after a discontinuity. */

#include <time.h> /* clock(): the processor time bgc_simulate reports in its stats */

/* Output times: t0 + k*dt for k < n, and t_end for k = n (see the top of the file); n is at
   least 1 when t_end > t0, so that t0 and t_end are rows whatever dt (a dt beyond the span
   included); 0 when they are the same time (one row). */
static long bgc_output_count(const bgc_settings *s)
{
    double n = ceil((s->t_end - s->t0) / s->dt - 1e-6);
    return n > 1.0 ? (long)n : s->t_end > s->t0 ? 1 : 0;
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

/* A run in progress, as the driver and the families share it: the run's settings, model and
   sink, where the outputs are (k = kout .. nout still to hand over; k = 0, the start, has been
   handed over before), the last accepted point r->t, and the step to start with (r->h: 0 for a
   new estimate; after BGC_STIFF, the explicit phase's last step). */
typedef struct bgc_run {
    const bgc_settings *s;
    const bgc_method *method;
    const bgc_params *p;
    bgc_work *w;
    bgc_sink sink;
    void *ctx;
    bgc_stats *st;
    char *msg;
    size_t msg_size;
    long nout, kout;
    double t, h;
    int fixed;       /* steps on a grid, no error control (s->step > 0, or euler, rk4) */
    int detect_stiffness;
    long steps_out;  /* st->steps at the last output (or event), at t_out */
    double t_out;
    int from_event;  /* t_out is an event's (the step budget counts from either) */
    /* events (a model with BGC_NUM_DISCRETE > 0): */
    double *d;       /* the discrete values, in the run's parameter copy */
    double *band;    /* per state relation: its hysteresis band (0: none), and ... */
    double *gmax;    /* ... its indicator's largest magnitude so far (in the workspace) */
    double *g;       /* the indicators at r->t */
    double *ev;      /* scratch: indicators (2 x BGC_NUM_INDICATORS), update's input and
                        output, a state and two derivatives */
    double t_next;   /* the first time event after r->t (INFINITY: none) */
    double t_event;  /* the last event's time, and how many events in a row came ... */
    long chain;      /* ... closer to the one before than the solver resolves */
    long kout_ev;    /* the output row the event count below starts at (r->kout then) */
    long events_out; /* st->events at that row: the events since it are bounded as steps are */
    long sliding;    /* accepted steps in a row, each ended at a located (state) event */
    /* what keeps changing, for the chattering messages: the event iteration's passes so far,
       the pass that last changed each discrete value (-1: none yet), and the passes where
       the chains the driver bounds began (events in a row, steps cut short, events since an
       output row) */
    double passes, *last, chain_from, sliding_from, out_from;
} bgc_run;
/* What raises a budget, as the messages say it: the program's --max-steps, or in an FMU,
   whose settings are the defaults (BGC_MAX_STEPS), what the fixed budget is. */
#ifdef BGC_FMU
#define BGC_HINT_STEPS "the FMU's budget, 100000 steps per communication step, is fixed"
#define BGC_HINT_SLIDING "a sliding mode or a Zeno model? The FMU's limit, 1000, is fixed"
#define BGC_HINT_EVENTS "a Zeno model? The FMU's budget, 100000 events per communication " \
    "step, is fixed"
#else
#define BGC_HINT_STEPS "--max-steps raises the budget"
#define BGC_HINT_SLIDING "a sliding mode or a Zeno model? --max-steps raises the limit, a " \
    "hundredth of it"
#define BGC_HINT_EVENTS "a Zeno model? --max-steps raises the budget"
#endif
#define BGC_STIFF (-1) /* an auto run's explicit phase found the problem stiff */

/* An attempted step's outcome. */
enum {
    BGC_STEP_ACCEPT, /* y1 is the new point; hnew the controller's next step */
    BGC_STEP_REJECT, /* the error test failed: retry with hnew */
    BGC_STEP_RETRY,  /* the attempt failed (bad says how): retry with hnew */
    BGC_STEP_AGAIN,  /* the same step once more (a fresh Jacobian), not counted as rejected */
    BGC_STEP_END     /* the run ends: rc and the message are set */
};
/* Why an attempt failed, for the message if the step size then falls below the smallest:
   >= 0 a non-finite component (bad_kind 1 a state, else a derivative), -1 the error test,
   -2 an algebraic block, -3 a singular iteration matrix, -4 Newton's iteration. */
enum { BGC_BAD_NONE = -1, BGC_BAD_BLOCK = -2, BGC_BAD_SINGULAR = -3, BGC_BAD_NEWTON = -4 };
typedef struct bgc_outcome {
    int kind, rc;
    double hnew;
    int bad, bad_kind;
    int worst; /* the component with the largest share of the last error estimate (-1) */
} bgc_outcome;

typedef struct bgc_family {
    void *(*start)(bgc_run *r, const double *y, double *h, int *rc);
    void (*step)(void *ms, bgc_run *r, double t, double h, double tph, const double *y,
                 double *y1, bgc_outcome *o);
    int (*accepted)(void *ms, bgc_run *r, double tph, const double *y1);
    int (*prepare)(void *ms);
    void (*dense)(const void *ms, double theta, double *yout);
    int (*after)(void *ms, bgc_run *r, double tph, const double *y1, int last);
    void (*next_h)(void *ms, double h, double *hnew);
    void (*finish)(void *ms);
    int span_grid; /* fixed steps: 1 the grid t_start + k step over the run, outputs by the
                      dense output; 0 each output interval in steps of about `step` landing
                      on its end (methods without a dense output) */
} bgc_family;
/* The families, defined with their steps in erk.c and stiff.c. */
static const bgc_family bgc_family_fixed, bgc_family_erk, bgc_family_rosenbrock,
    bgc_family_radau;

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
    r->from_event = 0;
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
                 "%s at t = %.17g (the step size runs away; " BGC_HINT_STEPS ")",
                 t, r->s->max_steps, r->from_event ? "event" : "output", r->t_out);
        return BGC_ERR_RUNTIME;
    }
    return 0;
}

/* The run's event scratch (r->ev): the indicators at both ends of a bracket and inside it,
   update's input and output, and the Hermite interpolant's two derivatives. */
#define BGC_EV_GA(r) ((r)->ev)
#define BGC_EV_GB(r) ((r)->ev + BGC_NUM_INDICATORS)
#define BGC_EV_IN(r) ((r)->ev + 2 * BGC_NUM_INDICATORS)
#define BGC_EV_OUT(r) (BGC_EV_IN(r) + BGC_NUM_INDICATORS + 2 + BGC_NUM_JUMPS)
#define BGC_EV_GM(r) (BGC_EV_OUT(r) + BGC_NUM_STATES + BGC_NUM_DISCRETE + BGC_NUM_JUMPS)
#define BGC_EV_F0(r) (BGC_EV_GM(r) + BGC_NUM_INDICATORS)
#define BGC_EV_SIZE (4 * BGC_NUM_INDICATORS + 2 + 3 * BGC_NUM_STATES + BGC_NUM_DISCRETE \
                     + 2 * BGC_NUM_JUMPS)

/* The state inside the step just accepted, from t over h to tph (y at t, y1 at tph): the
   family's dense output (prepared once), or for a family without one (the fixed-step
   methods, for event location only) the cubic Hermite interpolant of y, y1 and the
   derivatives there. */
typedef struct bgc_dense {
    const bgc_family *f;
    void *ms;
    double t, h, tph;
    const double *y, *y1;
    int prepared;
    double *f0, *f1; /* the Hermite interpolant's derivatives (NULL until needed) */
} bgc_dense;

static int bgc_dense_at(bgc_run *r, bgc_dense *c, double tk, double *out)
{
    enum { N = BGC_NUM_STATES };
    int i, rc;
    if (tk == c->tph) {
        memcpy(out, c->y1, sizeof(double) * N);
        return 0;
    }
    if (c->f->dense) {
        if (!c->prepared && c->f->prepare) {
            rc = c->f->prepare(c->ms);
            if (rc)
                return rc;
        }
        c->prepared = 1;
        c->f->dense(c->ms, (tk - c->t) / c->h, out);
        return 0;
    }
    if (!c->f0) {
        c->f0 = BGC_EV_F0(r);
        c->f1 = c->f0 + N;
        r->st->rhs += 2;
        if (bgc_model_rhs(c->t, c->y, r->p, r->w, c->f0)
            || bgc_model_rhs(c->tph, c->y1, r->p, r->w, c->f1))
            return bgc_fail_block(r->msg, r->msg_size, r->w);
    }
    {
        const double th = (tk - c->t) / c->h, h = c->h;
        for (i = 0; i < N; i++) {
            const double dy = c->y1[i] - c->y[i];
            out[i] = (1.0 - th) * c->y[i] + th * c->y1[i]
                     + th * (th - 1.0) * ((1.0 - 2.0 * th) * dy + (th - 1.0) * h * c->f0[i]
                                          + th * h * c->f1[i]);
        }
    }
    return 0;
}

/* After an accepted step: hands over the output times in (c->t, until] (until itself
   excluded if !inclusive), tph from y1, the others through the dense output.  yout: N
   doubles of scratch. */
static int bgc_emit_step(bgc_run *r, bgc_dense *c, double until, int inclusive, double *yout)
{
    int rc;
    for (; r->kout <= r->nout; r->kout++) {
        const double tk = bgc_output_time(r->s, r->kout, r->nout);
        if (tk > until || (tk == until && !inclusive))
            break;
        if (tk == c->tph) {
            rc = bgc_emit(r, tk, c->y1);
        } else {
            rc = bgc_dense_at(r, c, tk, yout);
            if (rc == 0)
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

/* The states the error control weighs: the first s->error_states, or all (0). */
static inline int bgc_error_states(const bgc_settings *s)
{
    return s->error_states > 0 && s->error_states < BGC_NUM_STATES ? (int)s->error_states
                                                                   : BGC_NUM_STATES;
}

/* The largest step: the run's span, and --max-step if set. */
static double bgc_hmax(const bgc_settings *s)
{
    const double span = s->t_end - s->t0;
    return s->hmax > 0.0 ? bgc_min(span, s->hmax) : span;
}

/* Hairer's initial step size guess (HINIT) for a method of order q at (r->t, y) with
   f0 = f(r->t, y); y1, f1: scratch. */
static double bgc_initial_step(bgc_run *r, int q, const double *y, const double *f0,
                               double *y1, double *f1)
{
    enum { N = BGC_NUM_STATES };
    const bgc_settings *s = r->s;
    const double hmax = bgc_hmax(s);
    const int E = bgc_error_states(s);
    double dnf = 0.0, dny = 0.0, der2 = 0.0, der12, h, h1;
    int i;
    for (i = 0; i < E; i++) {
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
    for (i = 0; i < E; i++) {
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

/* The first step of an adaptive run: the earlier run's (bounded by the span), else HINIT. */
static double bgc_first_step(bgc_run *r, const double *y, const double *f0, double *y1,
                             double *f1)
{
    const double hmax = bgc_hmax(r->s);
    return r->h > 0.0 ? bgc_min(r->h, hmax)
                      : bgc_initial_step(r, r->method->q, y, f0, y1, f1);
}

/* f(t, y) at the start of a step sequence: a failed block or a non-finite derivative ends
   the run (nonzero, message set). */
static int bgc_start_rhs(bgc_run *r, double t, const double *y, double *f)
{
    int i;
    r->st->rhs++;
    if (bgc_model_rhs(t, y, r->p, r->w, f))
        return bgc_fail_block(r->msg, r->msg_size, r->w);
    i = bgc_first_nonfinite(f, BGC_NUM_STATES);
    return i >= 0 ? bgc_fail(r->msg, r->msg_size, t, "derivative of state", bgc_state_names[i])
                  : 0;
}

/* A step size below bgc_hmin: the message names what made the steps shrink. */
static int bgc_fail_small(bgc_run *r, double t, double h, int bad, int bad_kind, int worst)
{
    if (bad == BGC_BAD_BLOCK)
        return bgc_fail_block(r->msg, r->msg_size, r->w);
    if (bad == BGC_BAD_SINGULAR || bad == BGC_BAD_NEWTON) {
        snprintf(r->msg, r->msg_size, "at t = %.17g: %s: %s (step size down to h = %.3g)", t,
                 r->method->name, bad == BGC_BAD_SINGULAR ? "the iteration matrix is singular"
                 : "the Newton iteration does not converge", h);
        return BGC_ERR_RUNTIME;
    }
    if (bad >= 0)
        return bgc_fail(r->msg, r->msg_size, t, bad_kind == 1 ? "state" : "derivative of state",
                        bgc_state_names[bad]);
    return bgc_fail_step(r->msg, r->msg_size, t, h, worst);
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

/* Where the driver is on a fixed-step grid: the k-th of n steps from ta (span grid: over the
   run; else over the output interval ending at tb). */
typedef struct bgc_grid {
    double ta, tb, step;
    long k, n;
} bgc_grid;

/* The fixed grid's next step from t: its end *tph (or a time event inside it) and whether it
   is the run's last; nonzero (message set) when the grid cannot be laid or the step is too
   small. */
static int bgc_grid_next(bgc_run *r, const bgc_family *f, bgc_grid *g, double t, double *tph,
                         int *last)
{
    if (g->k >= g->n) { /* a new grid: the run's, or the next output interval's */
        g->ta = t;
        g->tb = f->span_grid ? r->s->t_end : bgc_output_time(r->s, r->kout, r->nout);
        g->k = 0;
        g->n = bgc_substeps(g->tb - g->ta, g->step);
        if (g->n < 0)
            return bgc_fail_step(r->msg, r->msg_size, t, g->step, -1);
    }
    *tph = g->k + 1 >= g->n ? g->tb : g->ta + (double)(g->k + 1) * g->step;
    *last = g->k + 1 >= g->n && (f->span_grid || r->kout >= r->nout);
    if (!f->span_grid) /* each step from its grid point (the same value as the last end) */
        t = g->ta + (double)g->k * g->step;
    if (!(*tph - t >= bgc_hmin(t)))
        return bgc_fail_step(r->msg, r->msg_size, t, *tph - t, -1);
    if (r->t_next < *tph) { /* a time event inside: the step ends on it */
        *tph = r->t_next;
        *last = 0;
    }
    return 0;
}

/* ------------------------------------------------------------------ events --- */
/* A model's events (docs/hybrid.md): the driver checks the state relations' indicators at
   the end of every accepted step, locates the first change of a relation's value on the
   step's dense output (Illinois' variant of the secant method, to 1e-12 relative in t), and
   ends the step there; it steps onto time events exactly; at an event it runs the event
   iteration (bgc_model_update until nothing changes) and starts the method afresh. */

/* Whether state relation k holds for indicator value g. */
static int bgc_holds(int k, double g)
{
    return bgc_indicator_strict[k] ? g > 0.0 : g >= 0.0;
}

/* Hysteresis (docs/hybrid.md, "Knees"): a state relation that changed its value at an event
   keeps it until its indicator goes back beyond zero by more than its band, the solver's
   resolution of the indicator after the event: the larger of
   - what the indicator changes by in the time's resolution (1e-12 relative, as events are
     located) along the state's derivative after the event (bgc_bands), and
   - BGC_BAND_REL times the largest magnitude the indicator has had in the run: its
     floating-point resolution (its rounding is a few ulps of the numbers it is computed
     from, with a margin of 10^4 for an algebraic solve's condition).
   At a knee where the law is continuous, the indicator after the event sits within rounding
   of zero, or of a crossing within the time's resolution (a steep branch hands over to a
   flat one: the rounding of a current through 1/Ron is seen through 1/Goff), and may come out
   on the old side; a Zeno model's conditions go back by a finite amount, far beyond it. */
#define BGC_BAND_REL 1e-12

/* Relation k's indicator g moved by its band: > 0 where the relation holds (>= 0 while it
   is held true; g itself without a band). */
static double bgc_level(const bgc_run *r, int k, double g)
{
    const double b = r->band[k];
    return b > 0.0 ? (r->d[k] != 0.0 ? g + b : g - b) : g;
}

/* The value state relation k takes at indicator value g: its condition, or within its band
   the value it has. */
static int bgc_relation(const bgc_run *r, int k, double g)
{
    if (r->band[k] > 0.0)
        return r->d[k] != 0.0 ? bgc_level(r, k, g) >= 0.0 : bgc_level(r, k, g) > 0.0;
    return bgc_holds(k, g);
}

/* The indicators g seen at an accepted point: each one's largest magnitude, and the end of
   the band of a relation whose indicator is beyond it on the relation's own side. */
static void bgc_seen(bgc_run *r, const double *g)
{
    int k;
    for (k = 0; k < BGC_NUM_INDICATORS; k++) {
        r->gmax[k] = bgc_max(r->gmax[k], fabs(g[k]));
        if (r->band[k] > 0.0 && (r->d[k] != 0.0 ? g[k] > r->band[k] : g[k] < -r->band[k]))
            r->band[k] = 0.0;
    }
}

/* The first state relation whose value at g differs from its frozen value d, or -1. */
static int bgc_changed(const bgc_run *r, const double *g)
{
    int k;
    for (k = 0; k < BGC_NUM_INDICATORS; k++)
        if (bgc_relation(r, k, g[k]) != (r->d[k] != 0.0))
            return k;
    return -1;
}

static int bgc_indicators(bgc_run *r, double t, const double *x, double *g)
{
    int k;
    if (bgc_model_events(t, x, r->p, r->w, g))
        return bgc_fail_block(r->msg, r->msg_size, r->w);
    for (k = 0; k < BGC_NUM_INDICATORS; k++)
        if (!isfinite(g[k]))
            return bgc_fail(r->msg, r->msg_size, t, "event condition", bgc_discrete_names[k]);
    return 0;
}

/* The first time event after t: the least result of next_time beyond t (INFINITY: none). */
static int bgc_next_time(bgc_run *r, double t, const double *x)
{
    enum { M = BGC_DIM(BGC_NUM_TIMERS) };
    double tau[M];
    int k;
    r->t_next = INFINITY;
    if (BGC_NUM_TIMERS == 0)
        return 0;
    if (bgc_model_next_time(t, x, r->p, r->w, tau))
        return bgc_fail_block(r->msg, r->msg_size, r->w);
    for (k = 0; k < BGC_NUM_TIMERS; k++)
        if (tau[k] > t && tau[k] < r->t_next)
            r->t_next = tau[k];
    return 0;
}

static int bgc_log(bgc_run *r, double t, const char *what, const char *change)
{
    return r->s->on_event ? r->s->on_event(r->s->event_ctx, t, what, change) : 0;
}

/* The event log's row of discrete value k changing from old to v: a table of t's piece as the
   table's values, an input's segment (three discrete values, consecutive) as one row of the
   input's values by its name, from its data; *shown: the input whose row this pass wrote
   last (-1: none). */
static int bgc_log_discrete(bgc_run *r, double t, int k, double old, double v, int *shown)
{
    const int kind = bgc_discrete_log[2 * k], j = bgc_discrete_log[2 * k + 1];
    char change[96];
    if (kind == BGC_LOG_INPUT) {
        if (j == *shown)
            return 0;
        *shown = j;
        snprintf(change, sizeof change, "%.17g -> %.17g", bgc_input_value(r->w, j, t, 0),
                 bgc_input_value(r->w, j, t, 1));
        return bgc_log(r, t, bgc_input_name(j), change);
    }
    *shown = -1;
    if (kind == BGC_LOG_TABLE)
        snprintf(change, sizeof change, "%.17g -> %.17g",
                 bgc_table_limit(&bgc_tables[j], t, old), bgc_table(&bgc_tables[j], t, v, 0));
    else
        snprintf(change, sizeof change, "%.17g -> %.17g", old, v);
    return bgc_log(r, t, bgc_discrete_names[k], change);
}

/* Appends a, b and c to the message (truncated to its size); returns the length it would
   have untruncated. */
static size_t bgc_cat(const bgc_run *r, size_t used, const char *a, const char *b, const char *c)
{
    const size_t at = used < r->msg_size ? used : r->msg_size - 1;
    const int n = snprintf(r->msg + at, r->msg_size - at, "%s%s%s", a, b, c);
    return used + (n > 0 ? (size_t)n : 0);
}

/* A chattering message: head, then what keeps changing, every discrete value a pass since
   the pass `from` changed, conditions first (their order; at most BGC_NAMED_CHANGES named,
   then how many more), then tail: "at t = 1: chattering: HEAD ('a < 0.5' and 'a' keep
   changing: TAIL)". */
static int bgc_chattering(bgc_run *r, double t, const char *head, double from, const char *tail)
{
    enum { ND = BGC_NUM_DISCRETE };
    char count[64];
    int k, total = 0, named = 0;
    size_t used;
    for (k = 0; k < ND; k++)
        total += r->last[k] >= from;
    used = (size_t)snprintf(r->msg, r->msg_size, "at t = %.17g: chattering: %s (", t, head);
    for (k = 0; k < ND && named < BGC_NAMED_CHANGES; k++) {
        if (r->last[k] < from)
            continue;
        named++;
        used = bgc_cat(r, used, named == 1 ? "'" : named == total ? " and '" : ", '",
                       bgc_discrete_names[k], "'");
    }
    if (total > named) {
        snprintf(count, sizeof count, " and %d more", total - named);
        used = bgc_cat(r, used, count, "", "");
    }
    used = bgc_cat(r, used, total == 0 ? "the state" : "", total > 1 ? " keep changing: "
                   : " keeps changing: ", tail);
    bgc_cat(r, used, ")", "", "");
    return BGC_ERR_RUNTIME;
}

/* The bands of the state relations that changed in the event iteration's last pass, at
   (t, x) after it: each at least what its indicator changes by over the time's resolution
   tau along the derivative there (one Euler step of tau: x + tau f). */
static int bgc_bands(bgc_run *r, double t, const double *x)
{
    enum { N = BGC_NUM_STATES, G = BGC_NUM_INDICATORS };
    double *g0 = BGC_EV_GA(r), *g1 = BGC_EV_GB(r), *f = BGC_EV_F0(r), *xt = f + N;
    const double tau = bgc_max(1e-12 * fabs(t), bgc_hmin(t));
    int i, k, rc;
    if (bgc_model_rhs(t, x, r->p, r->w, f))
        return bgc_fail_block(r->msg, r->msg_size, r->w);
    for (i = 0; i < N; i++)
        xt[i] = x[i] + tau * f[i];
    rc = bgc_indicators(r, t, x, g0);
    if (rc == 0)
        rc = bgc_indicators(r, t + tau, xt, g1);
    if (rc)
        return rc;
    for (k = 0; k < G; k++)
        if (r->last[k] == r->passes)
            r->band[k] = bgc_max(r->band[k], fabs(g1[k] - g0[k]));
    return 0;
}

/* The sensitivities' jumps after an event iteration (a program with BGC_NUM_JUMPS > 0, see
   api.h): S -= f+ dtau/dp for each parameter, f+ the right side at (t, x) after it; dtau the
   update's last results (out).  Nothing where the event's time moves with no parameter. */
static int bgc_jumps_after(bgc_run *r, double t, double *x, const double *dtau)
{
    enum { N = BGC_NUM_STATES, J = BGC_NUM_JUMPS };
    const int n = N / (1 + J);
    double *f = BGC_EV_F0(r);
    int i, j, moved = 0;
    for (j = 0; j < J; j++)
        moved |= dtau[j] != 0.0;
    if (!moved)
        return 0;
    if (bgc_model_rhs(t, x, r->p, r->w, f))
        return bgc_fail_block(r->msg, r->msg_size, r->w);
    for (j = 0; j < J; j++)
        for (i = 0; i < n; i++)
            x[n + j * n + i] = x[n + j * n + i] - f[i] * dtau[j];
    return 0;
}

/* The event iteration at (t, x): bgc_model_update until the state and the discrete values
   stop changing (start: the run's first, at t0, which sets every discrete value and logs
   nothing); r->g the indicators there after it.  A program with the sensitivities' jumps
   (BGC_NUM_JUMPS > 0): its S are states that change nothing else, not logged; the first
   pass's dtau/dp goes back into each later pass, then bgc_jumps_after. */
static int bgc_event_iteration(bgc_run *r, double t, double *x, int start)
{
    enum { N = BGC_NUM_STATES, G = BGC_NUM_INDICATORS, ND = BGC_NUM_DISCRETE, J = BGC_NUM_JUMPS };
    const int n = N / (1 + J); /* the model's own states, before S */
    double *g = r->g, *in = BGC_EV_IN(r), *out = BGC_EV_OUT(r);
    char change[96];
    int it, i, k, rc, shown, crossed, changed = 1;
    for (it = 0; changed; it++) {
        if (it > BGC_MAX_EVENT_ITERATIONS) { /* the last pass still changed something */
            snprintf(change, sizeof change, "more than %d events at one instant, the event "
                     "iteration does not settle", BGC_MAX_EVENT_ITERATIONS);
            return bgc_chattering(r, t, change, r->passes - 1, "a Zeno model?");
        }
        rc = bgc_indicators(r, t, x, g);
        if (rc)
            return rc;
        for (k = 0; k < G; k++) {
            r->gmax[k] = bgc_max(r->gmax[k], fabs(g[k]));
            in[k] = bgc_relation(r, k, g[k]) ? 1.0 : 0.0;
        }
        in[G] = start && it == 0 ? 1.0 : 0.0;
        if (J > 0) {
            in[G + 1] = !start && it == 0 ? 1.0 : 0.0;
            for (k = 0; k < J; k++)
                in[G + 2 + k] = it == 0 ? 0.0 : out[N + ND + k];
        }
        if (bgc_model_update(t, x, r->p, r->w, in, out))
            return bgc_fail_block(r->msg, r->msg_size, r->w);
        for (k = 0; k < J; k++)
            if (!isfinite(out[N + ND + k])) {
                snprintf(r->msg, r->msg_size, "at t = %.17g: the event's time has no "
                         "derivative (an event that grazes: its indicator's rate along the "
                         "motion is zero), so the sensitivities cannot pass it", t);
                return BGC_ERR_RUNTIME;
            }
        changed = 0;
        for (i = 0; i < N; i++) {
            if (!isfinite(out[i]))
                return bgc_fail(r->msg, r->msg_size, t, "state after the event",
                                bgc_state_names[i]);
            if (out[i] != x[i] && i >= n) {
                x[i] = out[i];
            } else if (out[i] != x[i]) {
                changed = 1;
                if (!start) {
                    snprintf(change, sizeof change, "%.17g -> %.17g", x[i], out[i]);
                    rc = bgc_log(r, t, bgc_state_names[i], change);
                    if (rc)
                        return rc;
                }
                x[i] = out[i];
            }
        }
        shown = -1;
        crossed = 0;
        for (k = 0; k < ND; k++) {
            const double v = out[N + k];
            if (!isfinite(v))
                return bgc_fail(r->msg, r->msg_size, t, "discrete value", bgc_discrete_names[k]);
            if (v != r->d[k]) {
                changed = 1;
                r->last[k] = r->passes;
                if (k < G) { /* a relation that changed: its band (none at the start) */
                    r->band[k] = start && it == 0 ? 0.0 : BGC_BAND_REL * r->gmax[k];
                    crossed |= !(start && it == 0);
                }
                if (!start && r->s->on_event) {
                    rc = bgc_log_discrete(r, t, k, r->d[k], v, &shown);
                    if (rc)
                        return rc;
                }
                r->d[k] = v;
            }
        }
        if (crossed) {
            rc = bgc_bands(r, t, x);
            if (rc)
                return rc;
        }
        r->passes++;
    }
    if (J > 0 && !start) {
        rc = bgc_jumps_after(r, t, x, out + N + ND);
        if (rc)
            return rc;
    }
    bgc_seen(r, g);
    return 0;
}

/* Whether the step just accepted, from c->t to c->tph, holds an event: 0 none; 1 at *te
   (<= tph), the state there in ye; else an error.  A time event is due when the step ends
   on it; a state relation whose value at tph differs from its frozen one is located. */
/* How far relation k's indicator g is from changing its value (negative: changed). */
static double bgc_margin(const bgc_run *r, int k, double g)
{
    const double level = bgc_level(r, k, g);
    return r->d[k] != 0.0 ? level : -level;
}

/* A relation that changes and changes back inside a step, unseen at its ends: the
   indicators at the step's middle, then, where the parabola through a relation's margins at
   the start, the middle and the end turns below zero inside the step, at the turn (the
   earliest).  1 with *tm and g there if one has changed, 0 if none, or -rc. */
static int bgc_hidden(bgc_run *r, bgc_dense *c, const double *gb, double *tm, double *ye,
                      double *g)
{
    enum { G = BGC_NUM_INDICATORS };
    const double ta = c->t, h = c->tph - c->t;
    double best = 2.0;
    int k, rc, probe;
    *tm = ta + 0.5 * h;
    for (probe = 0; probe < 2; probe++) {
        rc = bgc_dense_at(r, c, *tm, ye);
        if (rc == 0)
            rc = bgc_indicators(r, *tm, ye, g);
        r->st->locate_evals++;
        if (rc)
            return -rc;
        if (bgc_changed(r, g) >= 0)
            return 1;
        if (probe == 1)
            break;
        for (k = 0; k < G; k++) {
            const double s0 = bgc_margin(r, k, r->g[k]), sm = bgc_margin(r, k, g[k]);
            const double s1 = bgc_margin(r, k, gb[k]);
            const double a2 = 2.0 * (s0 - 2.0 * sm + s1), a1 = 4.0 * sm - 3.0 * s0 - s1;
            if (a2 > 0.0) {
                const double s = -a1 / (2.0 * a2);
                if (s > 0.0 && s < 1.0 && s0 + s * (a1 + s * a2) < 0.0 && s < best)
                    best = s;
            }
        }
        if (best >= 2.0)
            break;
        *tm = ta + best * h;
    }
    return 0;
}

static int bgc_find_event(bgc_run *r, bgc_dense *c, double *te, double *ye)
{
    enum { G = BGC_NUM_INDICATORS };
    double *ga = BGC_EV_GA(r), *gb = BGC_EV_GB(r), *gm = BGC_EV_GM(r);
    double ta = c->t, tb = c->tph, wa = 1.0, wb = 1.0;
    const double h = c->tph - c->t; /* the time's resolution is relative to the step too */
    int rc, it, moved = 0, probed = 0;
    const int due = c->tph >= r->t_next;
    if (G > 0) {
        rc = bgc_indicators(r, tb, c->y1, gb);
        if (rc)
            return -rc;
    }
    if (G == 0 || bgc_changed(r, gb) < 0) {
        int hidden = 0;
        if (G > 0) {
            hidden = bgc_hidden(r, c, gb, &tb, ye, gm);
            if (hidden < 0)
                return hidden;
        }
        if (!hidden) {
            if (!due)
                return 0;
            *te = c->tph;
            memcpy(ye, c->y1, sizeof(double) * BGC_NUM_STATES);
            return 1;
        }
        memcpy(gb, gm, sizeof(double) * G);
    }
    memcpy(ga, r->g, sizeof(double) * G);
    for (it = 0; it < 200; it++) {
        /* 1e-12 relative in t, the floating point's resolution relative to the step too (an
           event near t = 0): a switched element's flow is resolved to its rate times that
           (bgc/contact.py, LOCATED) */
        const double at = bgc_max(fabs(ta), fabs(tb)), scale = bgc_max(at, h);
        const double tol = bgc_max(1e-12 * at, bgc_max(4.0 * DBL_EPSILON * scale, DBL_MIN));
        double frac = 1.0, tm;
        int k, side;
        if (tb - ta <= tol)
            break;
        for (k = 0; k < G; k++) {
            if (bgc_relation(r, k, gb[k]) != (r->d[k] != 0.0)) {
                const double a = wa * bgc_level(r, k, ga[k]), b = wb * bgc_level(r, k, gb[k]);
                double q = a / (a - b);
                if (!(q >= 0.0 && q <= 1.0) || (q == 0.0 && probed))
                    q = 0.5;
                if (q < frac)
                    frac = q;
            }
        }
        if (it >= 100)
            frac = 0.5; /* bisection, should the secant stall */
        if (frac == 0.0) /* an indicator exactly 0 at ta: probed once at the time's */
            probed = 1;  /* resolution, then bisected (rounding may hold it at 0) */
        tm = ta + frac * (tb - ta);
        tm = bgc_max(tm, ta + 0.5 * tol);
        tm = bgc_min(tm, tb - 0.5 * tol);
        rc = bgc_dense_at(r, c, tm, ye);
        if (rc == 0)
            rc = bgc_indicators(r, tm, ye, gm);
        r->st->locate_evals++;
        if (rc)
            return -rc;
        side = bgc_changed(r, gm) >= 0 ? 1 : -1;
        if (side > 0) { /* the change is in (ta, tm]: Illinois halves the end that stays */
            tb = tm;
            memcpy(gb, gm, sizeof(double) * G);
            wb = 1.0;
            wa = moved > 0 ? 0.5 * wa : 1.0;
        } else {
            ta = tm;
            memcpy(ga, gm, sizeof(double) * G);
            wa = 1.0;
            wb = moved < 0 ? 0.5 * wb : 1.0;
        }
        moved = side;
    }
    *te = tb;
    rc = bgc_dense_at(r, c, tb, ye);
    return rc ? -rc : 2;
}

/* An event at (t, x): the left limit's row (--event-rows), the event iteration, the right
   limit's row; then the next time event.  Stops a run whose events come closer together
   than it can resolve, BGC_MAX_EVENT_ITERATIONS in a row. */
static int bgc_handle_event(bgc_run *r, double t, double *x)
{
    const double scale = bgc_max(fabs(t), fabs(r->t_event));
    char head[96];
    int rc = 0;
    r->st->events++;
    if (r->kout != r->kout_ev) { /* the first event since an output row */
        r->kout_ev = r->kout;
        r->events_out = r->st->events - 1;
        r->out_from = r->passes;
    }
    /* (the run's first event has none before it: t_event is -inf, and so is the scale) */
    if (isfinite(r->t_event) && t - r->t_event <= bgc_max(1e-12 * scale, bgc_hmin(t))) {
        r->chain++;
    } else {
        r->chain = 0;
        r->chain_from = r->passes;
    }
    r->t_event = t;
    r->steps_out = r->st->steps; /* the step budget starts again */
    r->t_out = t;
    r->from_event = 1;
    if (r->s->event_rows)
        rc = bgc_emit(r, t, x);
    if (rc == 0)
        rc = bgc_event_iteration(r, t, x, 0);
    if (rc == 0 && r->chain >= BGC_MAX_EVENT_ITERATIONS) {
        snprintf(head, sizeof head, "%ld events in a row, each within 1e-12 relative of the "
                 "one before", r->chain);
        return bgc_chattering(r, t, head, r->chain_from, "a Zeno model, the switching "
                              "outruns the time's resolution");
    }
    /* every step cut short by a state event: at most a hundredth of the step budget in a
       row, and at least 1000 */
    if (rc == 0 && r->s->max_steps > 0
        && r->sliding >= (r->s->max_steps > 100000 ? r->s->max_steps / 100 : 1000)) {
        snprintf(head, sizeof head, "%ld steps in a row, each cut short by an event",
                 r->sliding);
        return bgc_chattering(r, t, head, r->sliding_from, BGC_HINT_SLIDING);
    }
    /* the events since the last output row: as many as the step budget, and at least 1000
       (a small step budget is for a step size that runs away, not for events) */
    if (rc == 0 && r->s->max_steps > 0 && r->st->events - r->events_out
                                          > (r->s->max_steps > 1000 ? r->s->max_steps : 1000)) {
        snprintf(head, sizeof head, "%ld events since the last output row",
                 r->st->events - r->events_out - 1);
        return bgc_chattering(r, t, head, r->out_from, BGC_HINT_EVENTS);
    }
    if (rc == 0 && r->s->event_rows)
        rc = bgc_emit(r, t, x);
    if (rc == 0)
        rc = bgc_next_time(r, t, x);
    return rc;
}

/* After the step that ended at an event at (t, y): the event, the rows at t (its right limit;
   those within the time's resolution of t too), and the family started afresh at t (*ms
   NULL: the run is over, or failed). */
static int bgc_after_event(bgc_run *r, const bgc_family *f, double t, double *y, void **ms,
                           double *h)
{
    int rc = bgc_handle_event(r, t, y);
    for (; rc == 0 && r->kout <= r->nout; r->kout++) {
        const double tk = bgc_output_time(r->s, r->kout, r->nout);
        if (tk - t > bgc_hmin(t))
            break;
        rc = bgc_emit(r, tk, y);
    }
    r->t = t;
    if (rc || t >= r->s->t_end || r->kout > r->nout)
        return rc;
    r->h = 0.0;
    *ms = f->start(r, y, h, &rc);
    return rc;
}

/* The step just accepted, from t to tph (y1 the state there): its state checked, the step
   counted (bgc_accept) and the family told; nonzero (message set) to end the run. */
static int bgc_accepted(bgc_run *r, const bgc_family *f, void *ms, double tph,
                        const double *y1)
{
    const int i = bgc_first_nonfinite(y1, BGC_NUM_STATES);
    int rc;
    if (i >= 0)
        return bgc_fail(r->msg, r->msg_size, tph, "state", bgc_state_names[i]);
    rc = bgc_accept(r, tph);
    if (rc == 0 && f->accepted)
        rc = f->accepted(ms, r, tph, y1);
    return rc;
}

/* One family's run from (r->t, y) to s->t_end (the driver proper).  Keeps r->t and y at the
   last accepted step; returns 0, an error (message set), the sink's nonzero value, or
   BGC_STIFF (r->h then holds the explicit phase's next step). */
static int bgc_drive(bgc_run *r, const bgc_family *f, double *y)
{
    enum { N = BGC_NUM_STATES, D = BGC_DIM(BGC_NUM_STATES) };
    const bgc_settings *s = r->s;
    const double hmax = bgc_hmax(s);
    double *mem = malloc((size_t)3 * D * sizeof *mem), *y1, *yout, *ye;
    double t = r->t, h = 0.0, hnew, wanted = 0.0;
    int rc = 0, reject = 0, last = 0, bad = BGC_BAD_NONE, bad_kind = 0, at_event = 0;
    bgc_grid grid = {0.0, 0.0, 0.0, 0, 0};
    bgc_outcome o;
    void *ms = NULL;

    if (!mem)
        return bgc_fail_memory(r->msg, r->msg_size);
    y1 = mem;
    yout = mem + D;
    ye = mem + 2 * D;
    o.worst = -1;
    grid.step = s->step > 0.0 ? s->step : s->dt;
    if (s->hmax > 0.0 && s->hmax < grid.step) /* --max-step bounds a fixed step too */
        grid.step = s->hmax;
    if (r->kout > r->nout)
        goto done;
    ms = f->start(r, y, &h, &rc);
    if (!ms)
        goto done;
    for (;;) {
        double tph;
        bgc_dense c;
        if (r->t_next - t <= bgc_hmin(t)) { /* a time event closer than a step can be */
            t = r->t_next;
            at_event = 1;
        }
        if (at_event) { /* the event at (t, y); the method starts afresh after it */
            at_event = 0;
            f->finish(ms);
            ms = NULL;
            rc = bgc_after_event(r, f, t, y, &ms, &h);
            if (rc || !ms)
                goto done;
            grid.k = grid.n; /* a new grid from the event */
            reject = last = 0;
            bad = BGC_BAD_NONE;
            continue;
        }
        if (r->fixed) {
            rc = bgc_grid_next(r, f, &grid, t, &tph, &last);
            if (rc)
                goto done;
            h = tph - t;
        } else {
            if (!(h >= bgc_hmin(t))) {
                rc = bgc_fail_small(r, t, h, bad, bad_kind, o.worst);
                goto done;
            }
            wanted = h;
            if (r->t_next < s->t_end && t + 1.01 * h - r->t_next > 0.0) {
                h = r->t_next - t; /* onto the time event */
                tph = r->t_next;
            } else {
                if (t + 1.01 * h - s->t_end > 0.0) {
                    h = s->t_end - t;
                    last = 1;
                }
                tph = last ? s->t_end : t + h;
            }
        }
        f->step(ms, r, t, h, tph, y, y1, &o);
        if (o.kind == BGC_STEP_END) {
            rc = o.rc;
            goto done;
        }
        if (o.kind == BGC_STEP_AGAIN)
            continue;
        if (o.kind != BGC_STEP_ACCEPT) {
            if (o.kind == BGC_STEP_RETRY) {
                bad = o.bad;
                bad_kind = o.bad_kind;
            }
            reject = 1;
            last = 0;
            r->st->rejected++;
            h = o.hnew;
            continue;
        }

        /* accepted */
        hnew = o.hnew;
        rc = bgc_accepted(r, f, ms, tph, y1);
        if (rc)
            goto done;
        c = (bgc_dense){ .f = f, .ms = ms, .t = t, .h = h, .tph = tph, .y = y, .y1 = y1,
                         .prepared = f->prepare == NULL, .f0 = NULL, .f1 = NULL };
        if (BGC_NUM_DISCRETE > 0) {
            double te = tph;
            const int found = bgc_find_event(r, &c, &te, ye);
            if (found < 0) {
                rc = -found;
                goto done;
            }
            r->sliding = found == 2 ? r->sliding + 1 : 0;
            if (r->sliding == 1)
                r->sliding_from = r->passes;
            if (found) { /* the step ends at the event; the method starts afresh there */
                rc = bgc_emit_step(r, &c, te, 0, yout);
                if (rc)
                    goto done;
                memcpy(y, ye, sizeof(double) * N);
                t = te;
                at_event = 1;
                continue;
            }
            memcpy(r->g, BGC_EV_GB(r), sizeof(double) * BGC_NUM_INDICATORS);
            bgc_seen(r, r->g);
        }
        rc = bgc_emit_step(r, &c, tph, 1, yout);
        if (rc == 0 && f->after)
            rc = f->after(ms, r, tph, y1, last);
        if (rc && rc != BGC_STIFF)
            goto done;
        memcpy(y, y1, sizeof(double) * N);
        t = tph;
        r->t = t;
        grid.k++;
        if (rc == BGC_STIFF) {
            r->h = hnew;
            goto done;
        }
        if (last) {
            if (!r->fixed) /* the step to go on with: the controller's, or the one cut short */
                r->st->h_next = bgc_max(hnew, wanted);
            goto done;
        }
        if (!r->fixed)
            hnew = bgc_min(hnew, hmax);
        if (reject)
            hnew = bgc_min(hnew, h);
        reject = 0;
        bad = BGC_BAD_NONE;
        if (f->next_h)
            f->next_h(ms, h, &hnew);
        h = hnew;
    }
done:
    if (ms)
        f->finish(ms);
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
    if (BGC_NUM_DISCRETE > 0)
        fprintf(f, " events=%ld locate=%ld", st->events, st->locate_evals);
    fprintf(f, " cpu=%.6e\n", st->cpu);
}

/* Runs solver number `solver` from (r->t, y) with the driver. */
static int bgc_run_solver(bgc_run *r, int solver, double *y)
{
    const bgc_method *m = &bgc_methods[solver];
    r->method = m;
    r->fixed = r->s->step > 0.0 || m->family == BGC_FAMILY_FIXED;
    switch (m->family) {
    case BGC_FAMILY_FIXED:
        return bgc_drive(r, &bgc_family_fixed, y);
    case BGC_FAMILY_ERK:
        return bgc_drive(r, &bgc_family_erk, y);
    case BGC_FAMILY_ROSENBROCK:
        return bgc_drive(r, &bgc_family_rosenbrock, y);
    case BGC_FAMILY_RADAU:
        return bgc_drive(r, &bgc_family_radau, y);
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
    bgc_params q;
    bgc_run r;
    int i, rc = bgc_check_settings(s, msg, msg_size);
    if (rc)
        return rc;
    BGC_COPY_PARAMS(&q, p);
    w->rtol = s->rtol;
    w->atol = s->atol;
    w->inputs = s->inputs;
    r.w = w;
    r.s = s;
    r.method = &bgc_methods[s->solver];
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
    r.from_event = 0;
    r.t_next = INFINITY;
    r.t_event = -INFINITY;
    r.chain = 0;
    r.kout_ev = 0;
    r.events_out = 0;
    r.sliding = 0;
    r.passes = r.chain_from = r.sliding_from = r.out_from = 0.0;
    r.d = (double *)&q + BGC_DISCRETE_OFFSET;
    r.band = w->d + BGC_NUM_DISCRETE;
    r.gmax = r.band + BGC_NUM_INDICATORS;
    r.g = r.ev = r.last = NULL;
    bgc_params_update(&q);
    i = bgc_first_nonfinite(y, BGC_NUM_STATES);
    if (i >= 0)
        return bgc_fail(msg, msg_size, s->t0, "state", bgc_state_names[i]);
    if (BGC_NUM_DISCRETE > 0) {
        r.g = malloc(sizeof(double) * (size_t)(BGC_NUM_INDICATORS + BGC_EV_SIZE
                                               + BGC_NUM_DISCRETE));
        if (!r.g)
            return bgc_fail_memory(msg, msg_size);
        r.ev = r.g + BGC_NUM_INDICATORS;
        r.last = r.ev + BGC_EV_SIZE;
        for (i = 0; i < BGC_NUM_DISCRETE; i++)
            r.last[i] = -1.0;
        memcpy(r.d, w->d, sizeof(double) * BGC_NUM_DISCRETE);
        rc = bgc_event_iteration(&r, s->t0, y, !w->started);
        w->started = 1;
        if (rc == 0)
            rc = bgc_next_time(&r, s->t0, y);
        if (rc) {
            free(r.g);
            return rc;
        }
    }
    rc = bgc_emit(&r, s->t0, y);
    if (rc == 0 && r.method->family == BGC_FAMILY_AUTO) {
        const bgc_method *m = r.method;
        r.detect_stiffness = 1;
        rc = bgc_run_solver(&r, m->explicit_solver, y);
        if (rc == BGC_STIFF) {
            stats->switched = 1;
            stats->t_switch = r.t;
            r.detect_stiffness = 0;
            rc = bgc_run_solver(&r, m->stiff_solver, y);
        }
    } else if (rc == 0) {
        rc = bgc_run_solver(&r, s->solver, y);
    }
    if (BGC_NUM_DISCRETE > 0) {
        memcpy(w->d, r.d, sizeof(double) * BGC_NUM_DISCRETE);
        free(r.g);
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
