/* ======================================================================= API === */
/* Everything global is prefixed bgc_/BGC_.  The model part above defines the sizes
   (BGC_NUM_*) and the parameter struct; the functions below are defined further down. */

#define BGC_DIM(n) ((n) > 0 ? (n) : 1) /* array size for n elements, n may be 0 */
#define BGC_COUNT(a) ((int)(sizeof(a) / sizeof((a)[0]))) /* elements of an array */
/* The doubles of the parameter struct the model uses (the runtime built once holds the most
   any linked model may have, bgc/emit.py's LINK_PARAMS), and a copy of them: a run's own
   parameters cost their size, not the largest struct's. */
#ifndef BGC_PARAM_DOUBLES
#define BGC_PARAM_DOUBLES ((int)(sizeof(bgc_params) / sizeof(double)))
#endif
#define BGC_COPY_PARAMS(dst, src) \
    memcpy((dst), (src), sizeof(double) * (size_t)BGC_PARAM_DOUBLES)

enum { BGC_OK = 0, BGC_ERR_CONSTRAINT = 1, BGC_ERR_USAGE = 2, BGC_ERR_RUNTIME = 3 };
/* How an algebraic block failed (bgc_work.failure). */
enum { BGC_BLOCK_SINGULAR = 1, BGC_BLOCK_DIVERGED = 2, BGC_BLOCK_NONFINITE = 3,
       BGC_NO_JACOBIAN = 4 /* jvp of a program built without it (BGC_HAS_JACOBIAN 0) */ };

/* Display names, ordered as the arrays below use them. */
extern const char *const bgc_model_name;
extern const char *const bgc_state_names[BGC_DIM(BGC_NUM_STATES)];
extern const char *const bgc_param_names[BGC_DIM(BGC_NUM_PARAMS)];
extern const char *const bgc_output_names[BGC_DIM(BGC_NUM_OUTPUTS)];
extern const char *const bgc_constraint_names[BGC_DIM(BGC_NUM_CONSTRAINTS)]; /* junctions */
extern const char *const bgc_constraint_levels[BGC_DIM(BGC_NUM_CONSTRAINTS)]; /* position|velocity */

/* Sets every parameter j with !given[j] (all of them if given is NULL) from its default
   expression, in order, so that a derived parameter follows the parameters it uses; then
   updates the constants. */
void bgc_params_defaults(bgc_params *p, const int *given);
/* Recomputes the constants p->c from the parameter fields.  Call it after setting a field
   and before calling a model function (bgc_simulate, bgc_check_constraints and
   bgc_project_initial update a copy of p themselves). */
void bgc_params_update(bgc_params *p);
/* The field of parameter j (NULL if j is out of range); its index by name (-1 if unknown). */
double *bgc_param_ref(bgc_params *p, int j);
int bgc_param_index(const char *name);

/* An input's data (`input NAME`, docs/cli.md "--input"): n samples (t[k], u[k]), t
   non-decreasing, interpolated linearly and held beyond the first and the last; each t[k] is
   a time event.  A repeated t is a jump, as a table's repeated x: the sample before it is the
   value on the left, the one after it on the right (bgc_input reads the segment after the
   last sample at or before t).  n == 0: no data, the input keeps its default. */
typedef struct bgc_input_series {
    int n;
    const double *t, *u;
} bgc_input_series;

/* The workspace of the model functions: the values they share between their parts, the
   storage of the algebraic blocks solved numerically (factors, and each Newton block's last
   solution, its next starting value), and the tolerance of the Newton iterations.  One per
   thread; bgc_work_new returns NULL when out of memory. */
typedef struct bgc_work {
    double *v;          /* BGC_WORK_DOUBLES values */
    int *iv;            /* BGC_WORK_INTS values (pivots) */
    double rtol, atol;  /* Newton: |step| <= 0.01 * (atol + rtol * |z|) ends the iteration */
    int block;          /* after a failure: the block (1-based, as bgc_block_names) ... */
    int failure;        /* ... and how: BGC_BLOCK_SINGULAR, _DIVERGED or _NONFINITE */
    double t;           /* ... and when */
    double *d;          /* a model with events: the discrete values between two calls of
                           bgc_advance (BGC_NUM_DISCRETE), then per state relation its
                           hysteresis band and its indicator's largest magnitude ... */
    int started;        /* ... once set by the event iteration at the run's start */
    const bgc_input_series *inputs; /* a model with inputs: one per input (NULL: none has
                                       data), set from bgc_settings.inputs by each run */
} bgc_work;
bgc_work *bgc_work_new(void);
void bgc_work_free(bgc_work *w);
/* The unknowns of each algebraic block solved in the generated code (comma-separated). */
extern const char *const bgc_block_names[BGC_DIM(BGC_NUM_BLOCKS)];
/* "at t = ...: algebraic block k (...) is singular" after a model function returned nonzero. */
void bgc_work_message(const bgc_work *w, char *msg, size_t msg_size);

/* The model: x[BGC_NUM_STATES] ordered as bgc_state_names, y as bgc_output_names.  The
   functions that may solve algebraic blocks return 0, or nonzero when a block failed (see
   bgc_work_message).  bgc_jvp gives jv = J v for the Jacobian J = d rhs / d x, and
   bgc_jacobian J itself (row-major, BGC_NUM_STATES squared), both derived symbolically
   through the algebraic solves.  r and s per constraint row; the constraint Jacobians
   row-major (rows x BGC_NUM_STATES) for the position rows and for the velocity rows, and the
   velocity rows' Jacobian times the projection's metric (K = J M: the rows' derivatives by
   the velocities of the momenta they read, the mass matrix's inverse weighing).  Row k
   holds when |r[k]| <= 1e-9 * s[k]. */
void bgc_init(const bgc_params *p, double *x0);
int bgc_rhs(double t, const double *x, const bgc_params *p, bgc_work *w, double *dx);
int bgc_outputs(double t, const double *x, const bgc_params *p, bgc_work *w, double *y);
int bgc_jvp(double t, const double *x, const bgc_params *p, bgc_work *w, const double *v,
            double *jv);
int bgc_jacobian(double t, const double *x, const bgc_params *p, bgc_work *w, double *J);
/* J's structural entries only, column by column (bgc_jac_col_ptr, bgc_jac_col_rows). */
int bgc_jacobian_values(double t, const double *x, const bgc_params *p, bgc_work *w,
                        double *Jv);
void bgc_residual(double t, const double *x, const bgc_params *p, double *r);
void bgc_scale(double t, const double *x, const bgc_params *p, double *s);
void bgc_position_jac(double t, const double *x, const bgc_params *p, double *J);
void bgc_velocity_jac(double t, const double *x, const bgc_params *p, double *J);
void bgc_velocity_metric(double t, const double *x, const bgc_params *p, double *K);

/* Number of violated constraint rows at (t, x); each is reported on err if err != NULL. */
int bgc_check_constraints(double t, const double *x, const bgc_params *p, FILE *err);
/* The same for a run that starts off its constraints on purpose (--allow-inconsistent): only
   the rows whose residual is not finite (the model undefined there) count. */
int bgc_check_constraints_finite(double t, const double *x, const bgc_params *p, FILE *err);
/* Gauss-Newton minimum-norm projection of x onto the position rows, then onto the velocity
   rows (moving only velocity-movable states, the momenta, by the kinetic metric: the least
   change of kinetic energy).  0 on success, else BGC_ERR_CONSTRAINT
   with a message in msg. */
int bgc_project_initial(double t, double *x, const bgc_params *p, char *msg, size_t msg_size);

/* The solvers, numbered BGC_SOLVER_<NAME> as bgc_solver_names lists them (the table comes
   from bgc/solvers.py; `./model --help` lists them with a line each). */
extern const char *const bgc_solver_names[BGC_NUM_SOLVERS];
/* The solver's number by name, -1 if unknown. */
int bgc_solver_index(const char *name);

typedef struct bgc_settings {
    double t0, t_end, dt; /* output times t0 + k*dt, and t_end */
    int solver;           /* BGC_SOLVER_<NAME> */
    double rtol, atol;    /* error control of the adaptive solvers (and the Newton tolerance) */
    double step;          /* fixed step of the fixed-step solvers; 0: dt */
    long max_steps;       /* the most steps accepted between two output times (a run that
                             needs more fails: a runaway step size); 0: no limit */
    double h0;            /* adaptive solvers: the first step to try; 0: estimated */
    int order0;           /* radau: the order to start at (5, 9 or 13); 0: 5 */
    double hmax;          /* adaptive solvers: the largest step; 0: no bound but the span */
    int event_rows;       /* 1: two rows at each event, its left and right limits */
    long error_states;    /* adaptive solvers: the error control weighs the first error_states
                             states only (the others follow the steps chosen for them: a
                             shooting's sensitivities, CVODES's errconS = false); 0: all */
    /* Called for each change at an event (what: a condition as written, a state or a
       discrete variable; change: what it became); nonzero stops the run.  NULL: none. */
    int (*on_event)(void *ctx, double t, const char *what, const char *change);
    void *event_ctx;
    /* The inputs' data: NULL (every input keeps its default), or BGC_NUM_INPUTS series
       ordered as bgc_input_name numbers them (a series of n = 0: that input keeps its
       default).  The arrays are read during the run, not copied. */
    const bgc_input_series *inputs;
} bgc_settings;
#define BGC_MAX_STEPS 100000L /* max_steps unless set */
typedef struct bgc_stats {
    long steps, rejected, rhs; /* accepted steps, rejected steps, right-side calls */
    long jac, lu, solves;      /* stiff solvers: Jacobians, LU factorisations, linear solves */
    int switched;              /* auto: 1 once it has switched to its stiff method ... */
    double t_switch;           /* ... at this time */
    double cpu;                /* processor seconds bgc_simulate took (clock()) */
    double h_next;             /* adaptive solvers: the step they would take after the run's
                                  end (set, not added to; 0: none) ... */
    int order_next;            /* ... and radau the order (0: another solver) */
    long events;               /* events handled (the start's event iteration not counted) */
    long locate_evals;         /* evaluations of the event indicators within steps, to locate
                                  events */
} bgc_stats;
/* Called at every output time with the state and the outputs; nonzero stops the run. */
typedef int (*bgc_sink)(void *ctx, double t, const double *x, const double *y);

/* "stats: steps=.. rejected=.. rhs=.. jac=.. lu=.. solves=..[ stiff_from=T] cpu=S" and a
   newline. */
void bgc_print_stats(FILE *f, const bgc_stats *st);

/* The compiled scene's settings; 0 if s is valid, else BGC_ERR_USAGE and a message. */
void bgc_settings_default(bgc_settings *s);
int bgc_check_settings(const bgc_settings *s, char *msg, size_t msg_size);
/* Integrates from x0 at s->t0 to s->t_end.  Returns 0, BGC_ERR_USAGE (bad settings),
   BGC_ERR_RUNTIME (non-finite value, step size too small, a failed algebraic block or no
   memory: message in msg), or the sink's nonzero value.  stats are added to. */
int bgc_simulate(const bgc_settings *s, const bgc_params *p, const double *x0, bgc_sink sink,
                 void *ctx, bgc_stats *stats, char *msg, size_t msg_size);

/* bgc_simulate in steps: integrates x from s->t0 to s->t_end in the caller's workspace w
   (bgc_work_new), so that consecutive calls continue one run as far as the algebraic blocks
   go (each Newton block starts from its last solution); the solver itself starts afresh:
   with s->h0 and s->order0 set to the previous call's stats->h_next and ->order_next it goes
   on with its step size (and radau with its order), else with a new first step.  x is updated to the state at s->t_end (on failure, at the last
   accepted step).  Returns as bgc_simulate; stats are added to, its cpu included. */
int bgc_advance(const bgc_settings *s, const bgc_params *p, bgc_work *w, double *x,
                bgc_sink sink, void *ctx, bgc_stats *stats, char *msg, size_t msg_size);

/* Asks a run in progress to stop at its next accepted step, as a failure ("interrupted by
   signal sig"), keeping the rows written so far.  Async-signal-safe: a signal handler may call
   it (the program's main does, for SIGINT and SIGTERM).  0 clears the request. */
void bgc_request_stop(int sig);

/* Events (docs/hybrid.md).  A model with events defines, before this section, the sizes
   BGC_NUM_INDICATORS (its state relations: g = bgc_model_events, the relation holding when
   g > 0, or g >= 0 where bgc_indicator_strict is 0), BGC_NUM_TIMERS (the results of
   bgc_model_next_time: time events, of which the runtime steps onto the first after t) and
   BGC_NUM_DISCRETE (the discrete values d: the relations' frozen values, the state relations'
   first, then square waves and discrete variables, named by bgc_discrete_names, their
   changes shown in the event log as bgc_discrete_log says: two ints each, BGC_LOG_PLAIN
   (the values themselves), BGC_LOG_TABLE k (a table of t's piece: the table's values),
   BGC_LOG_INPUT j (a value of input j's segment: the input's values, one row)), and
   BGC_DISCRETE_OFFSET, where d is in its parameter struct (in doubles).  bgc_model_update
   gives the state and d after one pass of an event iteration from r (the state relations'
   values at the event, then 1 at the start of a run, else 0).  A model without events gets
   the neutral ones below. */
enum { BGC_LOG_PLAIN, BGC_LOG_INPUT, BGC_LOG_TABLE }; /* bgc_discrete_log (bgc/ir.py LOG_*) */
#ifndef BGC_NUM_DISCRETE
#define BGC_NUM_INDICATORS 0
#define BGC_NUM_TIMERS 0
#define BGC_NUM_DISCRETE 0
#define BGC_DISCRETE_OFFSET 0
static const int bgc_indicator_strict[1] = { 0 };
static const char *const bgc_discrete_names[1] = { "" };
static const int bgc_discrete_log[2] = { 0, 0 };
static inline int bgc_model_events(double t, const double *x, const bgc_params *p,
                                   bgc_work *w, double *out)
{
    (void)t, (void)x, (void)p, (void)w, (void)out;
    return 0;
}
static inline int bgc_model_next_time(double t, const double *x, const bgc_params *p,
                                      bgc_work *w, double *out)
{
    (void)t, (void)x, (void)p, (void)w, (void)out;
    return 0;
}
static inline int bgc_model_update(double t, const double *x, const bgc_params *p,
                                   bgc_work *w, const double *r, double *out)
{
    (void)t, (void)x, (void)p, (void)w, (void)r, (void)out;
    return 0;
}
#endif
/* The stiff solvers' iteration matrices c I - J on a large sparse model (bgc/sparse.py,
   IterationPlan): a static LU, row k and column k of the factored matrix being state
   perm[k]; L + U by rows (row k: positions rowptr[k] .. rowptr[k + 1] - 1, columns cols[]
   ascending, the diagonal at diag[k]); jpos[q]: the position of the Jacobian's q-th
   structural entry (bgc_jac_col_rows' order), dpos[i]: that of state i's diagonal.  A model
   part with such a plan defines BGC_JAC_SPARSE 1 and bgc_jac_lu before this section; the
   others get n = 0 (the dense factorisations). */
typedef struct bgc_splu {
    int n, nnz;
    const int *perm, *rowptr, *cols, *diag, *jpos, *dpos;
} bgc_splu;
#ifndef BGC_JAC_SPARSE
#define BGC_JAC_SPARSE 0
static const bgc_splu bgc_jac_lu[1] = { { 0, 0, NULL, NULL, NULL, NULL, NULL, NULL } };
#endif
/* A model part built for an explicit solver's run (bgc simulate) has no jvp: it defines
   BGC_HAS_JACOBIAN 0, and a run with a solver that needs the Jacobian is refused. */
#ifndef BGC_HAS_JACOBIAN
#define BGC_HAS_JACOBIAN 1
#endif
/* A program augmented with the sensitivities to BGC_NUM_JUMPS parameters whose update
   carries their jumps at events (bgc/codegen/sensitivity.py, "Through events"): its r holds,
   after the start's flag, 1 in the first pass of an event's iteration (else 0) and the
   event time's sensitivities dtau/dp that the first pass gave (0 in it), and its results
   end with them; after the iteration the driver subtracts f+ dtau/dp from each S (f+ the
   right side there).  The states are x, then S for each parameter.  Others: 0. */
#ifndef BGC_NUM_JUMPS
#define BGC_NUM_JUMPS 0
#endif
#define BGC_MAX_EVENT_ITERATIONS 100 /* events at one instant (passes of the event iteration
                                        that change something) a run allows (Zeno) */
#define BGC_NAMED_CHANGES 6 /* the discrete values a chattering message names, at most */

/* Inputs (`input NAME`): BGC_NUM_INPUTS of them, input j named bgc_input_name(j); the data
   of a run in bgc_settings.inputs.  A model without inputs gets the neutral ones below. */
#ifndef BGC_NUM_INPUTS
#define BGC_NUM_INPUTS 0
static inline const char *bgc_input_name(int j)
{
    (void)j;
    return "";
}
#endif

/* -------------------------------------------- between the model part and the runtime --- */
static inline double bgc_sq(double a) { return a * a; }
/* A number the compiler cannot see through: libm's functions of literal arguments are
   computed at run time, as the Python backend and the interpreter compute them (a compiler
   folds tanh(cos(9.0)) with exact rounding, libm may round otherwise: bgc/ir/printers.py). */
static inline double bgc_opaque(double a)
{
    volatile double v = a;
    return v;
}
static inline double bgc_min(double a, double b) { return b < a ? b : a; }
static inline double bgc_max(double a, double b) { return b > a ? b : a; }
static inline double bgc_sign(double a) { return a > 0.0 ? 1.0 : (a < 0.0 ? -1.0 : a); }
static inline double bgc_heaviside(double a, double at_zero)
{
    return a > 0.0 ? 1.0 : (a < 0.0 ? 0.0 : (a == 0.0 ? at_zero : a));
}
/* square(period, duty, t0): the period k >= 0 that holds t (its edges t0 + k period and
   t0 + (k + duty) period computed as written, so that the value at an edge is the value
   after it, and the next edge is the time the driver steps onto).  NaN where the edges
   near t are not apart (k beyond 2^53, or the next edge rounds onto this one): the wave is
   finer there than the time's resolution, and the run stops naming it. */
static inline double bgc_square_period(double t, double period, double t0)
{
    double k = floor((t - t0) / period);
    if (k < 0.0)
        k = 0.0;
    if (!(k + 1.0 > k))
        return NAN;
    while (k > 0.0 && t0 + k * period > t)
        k -= 1.0;
    while (t0 + (k + 1.0) * period <= t) {
        if (!(t0 + (k + 1.0) * period > t0 + k * period))
            return NAN;
        k += 1.0;
    }
    return k;
}
static inline double bgc_square(double t, double period, double duty, double t0)
{
    double k;
    if (!(period > 0.0) || !isfinite(t))
        return NAN;
    if (t < t0)
        return 0.0;
    k = bgc_square_period(t, period, t0);
    if (isnan(k))
        return NAN;
    return t < t0 + (k + duty) * period ? 1.0 : 0.0;
}
static inline double bgc_square_next(double t, double period, double duty, double t0)
{
    double k, down;
    if (!(period > 0.0) || !isfinite(t))
        return NAN;
    if (t < t0)
        return t0;
    k = bgc_square_period(t, period, t0);
    if (isnan(k))
        return NAN;
    down = t0 + (k + duty) * period;
    return t < down ? down : t0 + (k + 1.0) * period;
}

/* The first of the times c + period*n (n any integer) after t: a relation of t's next
   crossing (bgc/events.py, time_roots); NaN where period is 0 or a value is not finite. */
static inline double bgc_periodic_next(double t, double period, double c)
{
    double k;
    if (period < 0.0)
        period = -period;
    if (!(period > 0.0) || !isfinite(period) || !isfinite(c) || !isfinite(t))
        return NAN;
    k = floor((t - c) / period);
    if (!(k + 1.0 > k && k - 1.0 < k))  /* beyond 2^53 periods: the times are not apart */
        return NAN;
    while (c + k * period > t)
        k -= 1.0;
    while (c + (k + 1.0) * period <= t) {
        if (!(c + (k + 1.0) * period > c + k * period))
            return NAN;
        k += 1.0;
    }
    return c + (k + 1.0) * period;
}

/* How many of x[0..n-1] (non-decreasing) are at or below X (binary search); below X. */
static inline int bgc_count_upto(const double *x, int n, double X)
{
    int lo = 0, hi = n;
    while (lo < hi) {
        const int mid = (lo + hi) / 2;
        if (x[mid] <= X)
            lo = mid + 1;
        else
            hi = mid;
    }
    return lo;
}
static inline int bgc_count_below(const double *x, int n, double X)
{
    int lo = 0, hi = n;
    while (lo < hi) {
        const int mid = (lo + hi) / 2;
        if (x[mid] < X)
            lo = mid + 1;
        else
            hi = mid;
    }
    return lo;
}

/* Input j's data at t (bgc/events.py, InputSlot): the segment holding t, as its start
   (part 0), the value there (1) and its slope (2); before the first sample and after the
   last the value is held (start and slope 0); without data 0, dflt, 0. */
static inline double bgc_input(const bgc_work *w, int j, double t, int part, double dflt)
{
    const bgc_input_series *u = w->inputs ? &w->inputs[j] : NULL;
    int lo, k;
    if (!u || u->n <= 0)
        return part == 1 ? dflt : 0.0;
    if (t != t)
        return NAN;
    lo = bgc_count_upto(u->t, u->n, t); /* the samples at or before t */
    if (lo == 0 || lo == u->n)
        return part == 1 ? u->u[lo == 0 ? 0 : u->n - 1] : 0.0;
    k = lo - 1;
    if (part == 0)
        return u->t[k];
    if (part == 1)
        return u->u[k];
    return (u->u[k + 1] - u->u[k]) / (u->t[k + 1] - u->t[k]);
}
/* Input j's value at t from its data, as the event log shows it: the limit from the left
   (side 0) or from the right (1).  At a sample's time the sample itself (at a jump, the row
   before it from the left, the row after it from the right), between samples the line
   between them, held outside them; NaN without data. */
static inline double bgc_input_value(const bgc_work *w, int j, double t, int side)
{
    const bgc_input_series *u = w->inputs ? &w->inputs[j] : NULL;
    int lo, k;
    if (!u || u->n <= 0 || t != t)
        return NAN;
    lo = side ? bgc_count_upto(u->t, u->n, t) : bgc_count_below(u->t, u->n, t);
    if (side == 0 && lo < u->n && u->t[lo] == t)
        return u->u[lo];
    if (side != 0 && lo > 0 && u->t[lo - 1] == t)
        return u->u[lo - 1];
    if (lo == 0 || lo == u->n)
        return u->u[lo == 0 ? 0 : u->n - 1];
    k = lo - 1;
    return u->u[k] + (u->u[k + 1] - u->u[k]) / (u->t[k + 1] - u->t[k]) * (t - u->t[k]);
}
/* Input j's first sample after t (INFINITY: none). */
static inline double bgc_input_next(const bgc_work *w, int j, double t)
{
    const bgc_input_series *u = w->inputs ? &w->inputs[j] : NULL;
    int lo;
    if (!u || u->n <= 0)
        return INFINITY;
    if (t != t)
        return NAN;
    lo = bgc_count_upto(u->t, u->n, t);
    return lo < u->n ? u->t[lo] : INFINITY;
}

/* A lookup table (bgc/tables.py): n rows x[0..n-1] (non-decreasing), n + 1 pieces, piece s
   the cubic a + dx (b + dx (c + dx d)) in dx = X - origin[s], coef[4 s ..] = a, b, c, d;
   error: extrapolate = error (held outside [x[0], x[n-1]], where bgc_table_guard, an event
   indicator, is negative: the event there stops the run). */
typedef struct bgc_table_data {
    int n, error;
    const double *x, *origin, *coef;
} bgc_table_data;
/* The piece holding X: the number of rows with x <= X. */
static inline int bgc_table_find(const bgc_table_data *T, double X)
{
    return bgc_count_upto(T->x, T->n, X);
}
/* The table's value at X (order 0) or its derivative of order 1 to 3, in piece `piece` (a
   time table's, set at events), or in X's piece if piece < 0. */
static inline double bgc_table(const bgc_table_data *T, double X, double piece, int order)
{
    int s;
    const double *k;
    double dx;
    if (X != X)
        return NAN;
    s = piece >= 0.0 ? (int)piece : bgc_table_find(T, X);
    k = T->coef + 4 * s;
    dx = X - T->origin[s];
    switch (order) {
    case 0: return k[0] + dx * (k[1] + dx * (k[2] + dx * k[3]));
    case 1: return k[1] + dx * (2.0 * k[2] + dx * (3.0 * k[3]));
    case 2: return 2.0 * k[2] + dx * (6.0 * k[3]);
    case 3: return 6.0 * k[3];
    default: return 0.0;
    }
}
/* How far X is within the table's rows (negative outside). */
static inline double bgc_table_guard(const bgc_table_data *T, double X)
{
    const double lo = X - T->x[0], hi = T->x[T->n - 1] - X;
    return hi < lo ? hi : lo;
}
/* The table's value at t in piece `piece` as the event log shows it: at the right end of a
   piece that is not constant (linear, cubic), the row there, its limit from the left (at a
   jump, the row before it; piece s + 1 starts at row s: its a is y[s]). */
static inline double bgc_table_limit(const bgc_table_data *T, double t, double piece)
{
    const int s = (int)piece;
    if (s >= 0 && s < T->n && T->x[s] == t
        && (T->coef[4 * s + 1] != 0.0 || T->coef[4 * s + 2] != 0.0 || T->coef[4 * s + 3] != 0.0))
        return T->coef[4 * (s + 1)];
    return bgc_table(T, t, piece, 0);
}
/* The model's tables: BGC_NUM_TABLES of them in bgc_tables (a model part with tables defines
   both); a model without tables gets the neutral ones. */
#ifndef BGC_NUM_TABLES
#define BGC_NUM_TABLES 0
static const bgc_table_data bgc_tables[1] = { { 0, 0, NULL, NULL, NULL } };
#endif
/* The piece that holds t, and the table's first row after t (a time table's events). */
static inline double bgc_table_piece(const bgc_table_data *T, double t)
{
    return t != t ? NAN : (double)bgc_table_find(T, t);
}
static inline double bgc_table_next(const bgc_table_data *T, double t)
{
    int s;
    if (t != t)
        return NAN;
    s = bgc_table_find(T, t);
    return s < T->n ? T->x[s] : INFINITY;
}

/* A solver as bgc/solvers.py describes it (the tables are printed below this section).
   erk: an explicit Runge-Kutta tableau: c[all], a[all x all] (row-major, strictly lower),
   b and e (NULL: fixed step) and e2 (NULL: one estimate) over the first `stages`; the last of
   those is f(t + h, y1) if fsal; P[all x degree]: the dense output's polynomials.
   rosenbrock: Hairer's transformed coefficients (see bgc/solvers.py).
   radau: Radau IIA with s stages in RADAU's transformed form: nodes c (c[s-1] = 1); the
   eigenvalues gamma and alpha_k +- i beta_k (k < (s-1)/2) of A^-1; T and Ti = T^-1 (s x s,
   row-major) with Ti A^-1 T = diag(gamma, [alpha_k -beta_k; beta_k alpha_k], ...); e: the
   error estimate's weights.  A solver has one stage set (fixed order) or several (variable
   order, lowest first). */
typedef struct bgc_erk {
    int stages, all, fsal, degree;
    const double *c, *a, *b, *e, *e2, *P;
} bgc_erk;
typedef struct bgc_rosenbrock {
    int stages, dense_rows;
    double gamma;
    const double *c, *d, *a, *C, *m, *e, *H; /* a, C: stages x stages, H: dense_rows x stages */
} bgc_rosenbrock;
typedef struct bgc_radau {
    int s;
    double gamma;
    const double *c, *alpha, *beta, *T, *Ti, *e;
} bgc_radau;
#define BGC_RADAU_MAX_STAGES 7
enum { BGC_FAMILY_FIXED, BGC_FAMILY_ERK, BGC_FAMILY_ROSENBROCK, BGC_FAMILY_RADAU,
       BGC_FAMILY_AUTO };
typedef struct bgc_method {
    const char *name, *summary;
    int family, order;
    const bgc_erk *erk;
    const bgc_rosenbrock *ros;
    double safe, fac_min, fac_max, beta; /* step-size control: hnew/h in [fac_min, fac_max] */
    int q;                               /* the error estimate's order + 1 */
    double expo_beta;                    /* exponent err^(1/q - expo_beta * beta) */
    int stiff_i, stiff_j;                /* erk: the stiffness test's stages (-1: none) */
    double stiff_bound;
    int explicit_solver, stiff_solver;   /* auto: the two phases (-1: not auto) */
    const bgc_radau *radau;              /* radau: its stage sets (NULL: another family) */
    int radau_sets;                      /* ... and how many */
} bgc_method;

/* A block's factorization plan (bgc/sparse.py): static order, or dense (partial pivoting). */
typedef struct bgc_lu_plan {
    int m, dense, symmetric, nnz;
    const int *diag, *lptr, *lpos, *lrow, *uptr, *upos, *ucol, *upd, *prow, *pcol;
} bgc_lu_plan;
/* A block and where its values live: offsets into bgc_work.v (the matrix as assembled,
   its factors, the dense fallback, the right side / solution; for Newton blocks the unknowns,
   which persist as the next starting value, the residuals, a trial point and its residuals)
   and into bgc_work.iv (pivots, and which factorization was used). */
typedef struct bgc_block {
    bgc_lu_plan lu;
    int save, lu_off, dense, b, scale, z, r, zt, rt;
    int piv, how;
    /* A small static plan unrolled in the model part (else NULL): factor(w->v) does what
       bgc_lu_static does on the matrix at .save, 0 or 1; lsolve(w->v, b) the solve. */
    int (*factor)(double *v);
    void (*lsolve)(const double *v, double *b);
} bgc_block;
/* A Newton block's residuals r at z (and, if J is not NULL, its Jacobian at the positions of
   the block's plan); nonzero if a block inside failed. */
typedef int (*bgc_eval_fn)(double t, const double *x, const bgc_params *p, bgc_work *w,
                           const double *z, double *r, double *J);
/* Factor the matrix assembled at .save and solve for the right side at .b, in place. */
int bgc_block_solve(bgc_work *w, int k, double t);
/* Solve again for the right side at .b with the factors the last solve (or Newton's final
   factorization) left. */
int bgc_block_resolve(bgc_work *w, int k, double t);
/* Newton's method from the unknowns' last values, damped (Armijo); final_factor: factor the
   Jacobian at the solution for a later bgc_block_resolve. */
int bgc_newton(bgc_work *w, int k, bgc_eval_fn f, double t, const double *x,
               const bgc_params *p, int final_factor);
