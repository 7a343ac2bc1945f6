/* ============================================================ solvers === */
/* The solvers (bgc/solvers.py); their tables follow the API section. */
#define BGC_NUM_SOLVERS 13
#define BGC_SOLVER_LIST "euler, rk4, dopri5, vern7, dop853, ros2, rodas4, radau5, rodas5p, radau9, radau13, radau or auto"
enum {
    BGC_SOLVER_EULER = 0,
    BGC_SOLVER_RK4 = 1,
    BGC_SOLVER_DOPRI5 = 2,
    BGC_SOLVER_VERN7 = 3,
    BGC_SOLVER_DOP853 = 4,
    BGC_SOLVER_ROS2 = 5,
    BGC_SOLVER_RODAS4 = 6,
    BGC_SOLVER_RADAU5 = 7,
    BGC_SOLVER_RODAS5P = 8,
    BGC_SOLVER_RADAU9 = 9,
    BGC_SOLVER_RADAU13 = 10,
    BGC_SOLVER_RADAU = 11,
    BGC_SOLVER_AUTO = 12,
};

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

/* ====================================================== solver tables === */
/* Printed from bgc/solvers.py. */
static const double bgc_euler_c[1] = { 0.0 };
static const double bgc_euler_a[1] = { 0.0 };
static const double bgc_euler_b[1] = { 1.0 };

static const bgc_erk bgc_euler_erk = { 1, 1, 0, 0, bgc_euler_c, bgc_euler_a, bgc_euler_b, NULL, NULL, NULL };
static const double bgc_rk4_c[4] = { 0.0, 0.5, 0.5, 1.0 };
static const double bgc_rk4_a[16] = { 0.0, 0.0, 0.0, 0.0, 0.5, 0.0, 0.0, 0.0, 0.0, 0.5, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0 };
static const double bgc_rk4_b[4] = { 0.16666666666666666, 0.3333333333333333, 0.3333333333333333, 0.16666666666666666 };

static const bgc_erk bgc_rk4_erk = { 4, 4, 0, 0, bgc_rk4_c, bgc_rk4_a, bgc_rk4_b, NULL, NULL, NULL };
static const double bgc_dopri5_c[7] = { 0.0, 0.2, 0.3, 0.8, 0.8888888888888888, 1.0, 1.0 };
static const double bgc_dopri5_a[49] = { 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.2, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.075, 0.225, 0.0, 0.0, 0.0, 0.0, 0.0, 0.9777777777777777, -3.7333333333333334, 3.5555555555555554, 0.0, 0.0, 0.0, 0.0, 2.9525986892242035, -11.595793324188385, 9.822892851699436, -0.2908093278463649, 0.0, 0.0, 0.0, 2.8462752525252526, -10.757575757575758, 8.906422717743473, 0.2784090909090909, -0.2735313036020583, 0.0, 0.0, 0.09114583333333333, 0.0, 0.44923629829290207, 0.6510416666666666, -0.322376179245283, 0.13095238095238096, 0.0 };
static const double bgc_dopri5_b[7] = { 0.09114583333333333, 0.0, 0.44923629829290207, 0.6510416666666666, -0.322376179245283, 0.13095238095238096, 0.0 };
static const double bgc_dopri5_e[7] = { 0.0012326388888888888, 0.0, -0.0042527702905061394, 0.03697916666666667, -0.05086379716981132, 0.0419047619047619, -0.025 };
static const double bgc_dopri5_P[28] = { 1.0, -2.8535800653862835, 3.0717434641059005, -1.1270175653862835, 0.0, 0.0, 0.0, 0.0, 0.0, 4.023133379230305, -6.249321565289, 2.675424484351598, 0.0, -3.7324019615885042, 10.068970589843675, -5.685526961588504, 0.0, 2.5548038301849423, -6.399112377351017, 3.5219323679207912, 0.0, -1.3744241142186024, 3.272657752246729, -1.7672812570757455, 0.0, 1.3824689317781436, -3.764937863556287, 2.382468931778144 };

static const bgc_erk bgc_dopri5_erk = { 7, 7, 1, 4, bgc_dopri5_c, bgc_dopri5_a, bgc_dopri5_b, bgc_dopri5_e, NULL, bgc_dopri5_P };
static const double bgc_vern7_c[16] = { 0.0, 0.005, 0.10888888888888888, 0.16333333333333333, 0.4555, 0.6095094489978381, 0.884, 0.925, 1.0, 1.0, 1.0, 0.6716626365038747, 0.125, 0.25, 0.53, 0.79 };
static const double bgc_vern7_a[256] = { 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.005, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, -1.07679012345679, 1.185679012345679, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.04083333333333333, 0.0, 0.1225, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.6389139236255726, 0.0, -2.455672638223657, 2.272258714598084, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, -2.6615773750187572, 0.0, 10.804513886456137, -8.3539146573962, 0.820487594956657, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 6.067741434696771, 0.0, -24.711273635911084, 20.427517930788895, -1.9061579788166472, 1.006172249242068, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 12.054670076253203, 0.0, -49.75478495046899, 41.142888638604674, -4.461760149974004, 2.042334822239175, -0.09834843665406108, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 10.138146522881808, 0.0, -42.6411360317175, 35.76384003992257, -4.3480228403929075, 2.0098622683770357, 0.3487490460338272, -0.27143900510483127, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, -45.030072034298676, 0.0, 187.3272437654589, -154.02882369350186, 18.56465306347536, -7.141809679295079, 1.3088085781613785, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.04715561848627222, 0.0, 0.0, 0.25750564298434153, 0.2621665397741262, 0.15216092656738558, 0.49399691700324844, -0.29430311714032503, 0.0813174723249511, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.04608828480030098, 0.0, 0.0, 0.26095211559122217, 0.2593539886572149, 0.10712848532313586, -0.07335737007803501, 0.09516817597231149, -0.05557470923733998, 0.0, 0.03190366547506434, 0.0, 0.0, 0.0, 0.0, 0.0, 0.05837333975598387, 0.0, 0.0, 0.08577524236694001, -0.03429204581002123, -0.02818259731103036, -0.02078116148802372, -0.0036707401444410195, 0.011406452584364688, 0.0, -0.002750153913374408, 0.05912166395960217, 0.0, 0.0, 0.0, 0.0, 0.037816201678944845, 0.0, 0.0, 0.031346785326310744, 0.02225110077526238, 0.009958131955421001, 0.015223096043899926, -0.007547047454118317, 0.0013158882065466297, 0.0, -0.002347519033359897, -0.024269839327928092, 0.16625320182902079, 0.0, 0.0, 0.0, 0.05345075085525607, 0.0, 0.0, 0.34301733821384506, 0.20767427262033986, 0.07722675619395836, 0.00013272687985611353, 0.022219958202462402, -0.017410228868402326, 0.0, 0.0071975937699150306, -0.08645504868462665, -0.07705411918260392, 0.0, 0.0, 0.0, 0.05681087911635884, 0.0, 0.0, 0.36852219016184323, 0.22940605301030753, 0.08854425014313802, 0.02937879283098644, 0.005463456745004648, -0.01311750049635595, 0.0, 0.005109093689745297, 0.12419640895877533, -0.1043136241598034, 0.0, 0.0, 0.0 };
static const double bgc_vern7_b[11] = { 0.04715561848627222, 0.0, 0.0, 0.25750564298434153, 0.2621665397741262, 0.15216092656738558, 0.49399691700324844, -0.29430311714032503, 0.0813174723249511, 0.0, 0.0 };
static const double bgc_vern7_e[11] = { 0.0025470118799310456, 0.0, 0.0, -0.00965839487279575, 0.0420647097563969, -0.0666822437469301, 0.26500974646212816, -0.29430311714032503, 0.0813174723249511, -0.020295184663356284, 0.0 };
static const double bgc_vern7_P[112] = { 1.0, -8.366136708817907, 33.45564674491339, -70.50417466572665, 80.67397907967836, -47.49724826833688, 11.28508943677596, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 13.822881552117133, -112.04150066933103, 378.80182330392614, -626.3590532637976, 497.1667710334457, -151.13341631337596, 0.0, 14.07307810511366, -114.06947125956815, 385.6582019903894, -637.6962607392367, 506.1655757984283, -153.86895735535242, 0.0, 8.16798591450387, -66.20568915797485, 223.8352361965341, -370.11761297318577, 293.7774709021209, -89.3052299554309, 0.0, 26.517713521571906, -214.93958449070786, 726.6906103441299, -1201.602565533699, 953.7610488090023, -289.9332257332943, 0.0, -15.798166912004106, 128.05219533798348, -432.93248289538707, 715.865561966764, -568.2117438592624, 172.7303332447658, 0.0, 4.36511516811192, -35.38148338938862, 119.62148256700969, -197.79735460926827, 156.99984154077703, -47.72628380491679, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, -3.274137494621028, 27.15609115402443, -93.85378772108284, 158.59209585933854, -128.87650569842114, 40.25624390076204, 0.0, 5.921404526401594, -27.552998537066152, 37.272033018740885, 3.387133200887934, -37.98539394174189, 18.957821732777628, 0.0, 8.487477767791544, -39.493242097657294, 53.42407366300933, 4.8549660153948455, -54.44657346814621, 27.17329811960779, 0.0, -19.186819751360847, 167.14983136102234, -537.8357359160404, 827.7451797910091, -614.6483785211819, 176.77592303655177, 0.0, -15.883752349342663, 109.64035230222805, -328.15049709039147, 514.4013813786597, -403.4939189483438, 123.4864347071902, 0.0, -18.84664333946508, 144.22985270152228, -462.026782795111, 728.0525498274546, -552.71094537834, 161.3019689839392 };

static const bgc_erk bgc_vern7_erk = { 11, 16, 1, 7, bgc_vern7_c, bgc_vern7_a, bgc_vern7_b, bgc_vern7_e, NULL, bgc_vern7_P };
static const double bgc_dop853_c[16] = { 0.0, 0.05260015195876773, 0.0789002279381516, 0.1183503419072274, 0.2816496580927726, 0.3333333333333333, 0.25, 0.3076923076923077, 0.6512820512820513, 0.6, 0.8571428571428571, 1.0, 1.0, 0.1, 0.2, 0.7777777777777778 };
static const double bgc_dop853_a[256] = { 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.05260015195876773, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0197250569845379, 0.0591751709536137, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.02958758547680685, 0.0, 0.08876275643042054, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.2413651341592667, 0.0, -0.8845494793282861, 0.924834003261792, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.037037037037037035, 0.0, 0.0, 0.17082860872947386, 0.12546768756682242, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.037109375, 0.0, 0.0, 0.17025221101954405, 0.06021653898045596, -0.017578125, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.03709200011850479, 0.0, 0.0, 0.17038392571223998, 0.10726203044637328, -0.015319437748624402, 0.008273789163814023, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.6241109587160757, 0.0, 0.0, -3.3608926294469414, -0.868219346841726, 27.59209969944671, 20.154067550477894, -43.48988418106996, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.47766253643826434, 0.0, 0.0, -2.4881146199716677, -0.590290826836843, 21.230051448181193, 15.279233632882423, -33.28821096898486, -0.020331201708508627, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, -0.9371424300859873, 0.0, 0.0, 5.186372428844064, 1.0914373489967295, -8.149787010746927, -18.52006565999696, 22.739487099350505, 2.4936055526796523, -3.0467644718982196, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 2.273310147516538, 0.0, 0.0, -10.53449546673725, -2.0008720582248625, -17.9589318631188, 27.94888452941996, -2.8589982771350235, -8.87285693353063, 12.360567175794303, 0.6433927460157636, 0.0, 0.0, 0.0, 0.0, 0.0, 0.054293734116568765, 0.0, 0.0, 0.0, 0.0, 4.450312892752409, 1.8915178993145003, -5.801203960010585, 0.3111643669578199, -0.1521609496625161, 0.20136540080403034, 0.04471061572777259, 0.0, 0.0, 0.0, 0.0, 0.056167502283047954, 0.0, 0.0, 0.0, 0.0, 0.0, 0.25350021021662483, -0.2462390374708025, -0.12419142326381637, 0.15329179827876568, 0.00820105229563469, 0.007567897660545699, -0.008298, 0.0, 0.0, 0.0, 0.03183464816350214, 0.0, 0.0, 0.0, 0.0, 0.028300909672366776, 0.053541988307438566, -0.05492374857139099, 0.0, 0.0, -0.00010834732869724932, 0.0003825710908356584, -0.00034046500868740456, 0.1413124436746325, 0.0, 0.0, -0.42889630158379194, 0.0, 0.0, 0.0, 0.0, -4.697621415361164, 7.683421196062599, 4.06898981839711, 0.3567271874552811, 0.0, 0.0, 0.0, -0.0013990241651590145, 2.9475147891527724, -9.15095847217987, 0.0 };
static const double bgc_dop853_b[13] = { 0.054293734116568765, 0.0, 0.0, 0.0, 0.0, 4.450312892752409, 1.8915178993145003, -5.801203960010585, 0.3111643669578199, -0.1521609496625161, 0.20136540080403034, 0.04471061572777259, 0.0 };
static const double bgc_dop853_e[13] = { 0.01312004499419488, 0.0, 0.0, 0.0, 0.0, -1.2251564463762044, -0.4957589496572502, 1.6643771824549864, -0.35032884874997366, 0.3341791187130175, 0.08192320648511571, -0.022355307863886294, 0.0 };
static const double bgc_dop853_e2[13] = { -0.18980075407240762, 0.0, 0.0, 0.0, 0.0, 4.450312892752409, 1.8915178993145003, -5.801203960010585, -0.42268232132379197, -0.1521609496625161, 0.20136540080403034, 0.022651792198360825, 0.0 };
static const double bgc_dop853_P[112] = { 1.0, -10.266057073759306, 48.161850968566455, -114.93304874997833, 147.46446875669767, -97.06685363011368, 25.69393346270375, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 13.917653631776604, -154.78787266663716, 522.9219089608218, -456.25918840208783, -75.53193732135753, 154.18974869023643, 0.0, 2.6056037519936095, -21.622822384626506, 2.535182028966755, 292.25417465990404, -505.40999933296894, 231.5293791760455, 0.0, -15.018944223519684, 160.09447708973047, -474.3071826037644, 135.96036916173838, 545.1091945264187, -357.6391179106141, 0.0, 3.050527683318488, -38.54396729189063, 174.47140009219885, -337.0513470238771, 291.78987509083254, -93.40532418362432, 0.0, -1.3278744327655212, 16.661770430049543, -74.44027814126304, 140.75210016191608, -119.2562021040512, 37.45832313645163, 0.0, 2.844533632672879, -36.55829548991012, 170.69007169147514, -345.9748485480496, 313.299553623578, -104.0996495089623, 0.0, 0.7657106259527866, -9.906995535619366, 46.8029919188744, -96.5198694669957, 88.74316650017616, -29.8402934266605, 0.0, -1.0889903364513334, 14.097013042320002, -66.68230591294363, 137.96299063474376, -127.82216401767992, 43.53345659001114, 0.0, 18.148505520854727, -127.63310949253875, 357.3419516129657, -500.7031507909224, 349.17035710882897, -96.32455395918828, 0.0, -9.194632392478356, 93.3567459327894, -282.6272618704363, 361.14007718803333, -201.85219053352347, 39.17726167561544, 0.0, -4.436036387594894, 56.68120539776666, -261.77342902691703, 520.9742236688993, -461.17279991013964, 149.72683625798564 };

static const bgc_erk bgc_dop853_erk = { 13, 16, 1, 7, bgc_dop853_c, bgc_dop853_a, bgc_dop853_b, bgc_dop853_e, bgc_dop853_e2, bgc_dop853_P };
static const double bgc_ros2_c[2] = { 0.0, 1.0 };
static const double bgc_ros2_d[2] = { 1.7071067811865475, -1.7071067811865475 };
static const double bgc_ros2_a[4] = { 0.0, 0.0, 0.585786437626905, 0.0 };
static const double bgc_ros2_C[4] = { 0.0, 0.0, -1.17157287525381, 0.0 };
static const double bgc_ros2_m[2] = { 0.8786796564403574, 0.2928932188134525 };
static const double bgc_ros2_e[2] = { 0.2928932188134525, 0.2928932188134525 };
static const double bgc_ros2_H[4] = { 0.12132034355964258, 0.12132034355964258, 0.0, 0.0 };

static const bgc_rosenbrock bgc_ros2_ros = { 2, 2, 1.7071067811865475, bgc_ros2_c, bgc_ros2_d, bgc_ros2_a, bgc_ros2_C, bgc_ros2_m, bgc_ros2_e, bgc_ros2_H };
static const double bgc_rodas4_c[6] = { 0.0, 0.386, 0.21, 0.63, 1.0, 1.0 };
static const double bgc_rodas4_d[6] = { 0.25, -0.1043, 0.1035, -0.03620000000000023, 0.0, 0.0 };
static const double bgc_rodas4_a[36] = { 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.544, 0.0, 0.0, 0.0, 0.0, 0.0, 0.9466785280815826, 0.2557011698983284, 0.0, 0.0, 0.0, 0.0, 3.314825187068521, 2.896124015972201, 0.9986419139977817, 0.0, 0.0, 0.0, 1.221224509226641, 6.019134481288629, 12.53708332932087, -0.687886036105895, 0.0, 0.0, 1.221224509226641, 6.019134481288629, 12.53708332932087, -0.687886036105895, 1.0, 0.0 };
static const double bgc_rodas4_C[36] = { 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, -5.6688, 0.0, 0.0, 0.0, 0.0, 0.0, -2.430093356833875, -0.2063599157091915, 0.0, 0.0, 0.0, 0.0, -0.1073529058151375, -9.594562251023355, -20.47028614809616, 0.0, 0.0, 0.0, 7.496443313967647, -10.24680431464352, -33.99990352819905, 11.7089089320616, 0.0, 0.0, 8.083246795921522, -7.981132988064893, -31.52159432874371, 16.31930543123136, -6.058818238834054, 0.0 };
static const double bgc_rodas4_m[6] = { 1.221224509226641, 6.019134481288629, 12.53708332932087, -0.687886036105895, 1.0, 1.0 };
static const double bgc_rodas4_e[6] = { 0.0, 0.0, 0.0, 0.0, 0.0, 1.0 };
static const double bgc_rodas4_H[12] = { 10.12623508344586, -7.487995877610167, -34.80091861555747, -7.992771707568823, 1.025137723295662, 0.0, -0.6762803392801253, 6.087714651680015, 16.43084320892478, 24.76722511418386, -6.594389125716872, 0.0 };

static const bgc_rosenbrock bgc_rodas4_ros = { 6, 2, 0.25, bgc_rodas4_c, bgc_rodas4_d, bgc_rodas4_a, bgc_rodas4_C, bgc_rodas4_m, bgc_rodas4_e, bgc_rodas4_H };
static const double bgc_radau_s3_c[3] = { 0.1550510257216822, 0.6449489742783178, 1.0 };
static const double bgc_radau_s3_alpha[1] = { 2.6810828736277523 };
static const double bgc_radau_s3_beta[1] = { 3.0504301992474105 };
static const double bgc_radau_s3_T[9] = { 0.09123239487089295, -0.1412552950209542, -0.030029194105147424, 0.241717932707107, 0.20412935229379994, 0.3829421127572619, 0.966048182615093, 1.0, 0.0 };
static const double bgc_radau_s3_Ti[9] = { 4.325579890063155, 0.33919925181580984, 0.5417705399358749, -4.178718591551905, -0.32768282076106237, 0.47662355450055044, -0.5028726349457868, 2.571926949855605, -0.5960392048282249 };
static const double bgc_radau_s3_e[3] = { -10.048809399827416, 1.382142733160749, -0.3333333333333333 };

static const bgc_radau bgc_radau5_radau[1] = {
    { 3, 3.637834252744496, bgc_radau_s3_c, bgc_radau_s3_alpha, bgc_radau_s3_beta, bgc_radau_s3_T, bgc_radau_s3_Ti, bgc_radau_s3_e },
};
static const double bgc_rodas5p_c[8] = { 0.0, 0.6358126895828704, 0.4095798393397535, 0.9769306725060716, 0.4288403609558664, 1.0, 1.0, 1.0 };
static const double bgc_rodas5p_d[8] = { 0.21193756319429014, -0.42387512638858027, -0.3384627126235924, 1.8046452872882734, 2.325825639765069, 0.0, 0.0, 0.0 };
static const double bgc_rodas5p_a[64] = { 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 3.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 2.849394379747939, 0.45842242204463923, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, -6.954028509809101, 2.489845061869568, -10.358996098473584, 0.0, 0.0, 0.0, 0.0, 0.0, 2.8029986275628964, 0.5072464736228206, -0.3988312541770524, -0.04721187230404641, 0.0, 0.0, 0.0, 0.0, -7.502846399306121, 2.561846144803919, -11.627539656261098, -0.18268767659942256, 0.030198172008377946, 0.0, 0.0, 0.0, -7.502846399306121, 2.561846144803919, -11.627539656261098, -0.18268767659942256, 0.030198172008377946, 1.0, 0.0, 0.0, -7.502846399306121, 2.561846144803919, -11.627539656261098, -0.18268767659942256, 0.030198172008377946, 1.0, 1.0, 0.0 };
static const double bgc_rodas5p_C[64] = { 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, -14.155112264123755, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, -17.97296035885952, -2.859693295451294, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 147.12150275711716, -1.41221402718213, 71.68940251302358, 0.0, 0.0, 0.0, 0.0, 0.0, 165.43517024871676, -0.4592823456491126, 42.90938336958603, -5.961986721573306, 0.0, 0.0, 0.0, 0.0, 24.854864614690072, -3.0009227002832186, 47.4931110020768, 5.5814197821558125, -0.6610691825249471, 0.0, 0.0, 0.0, 30.91273214028599, -3.1208243349937974, 77.79954646070892, 34.28646028294783, -19.097331116725623, -28.087943162872662, 0.0, 0.0, 37.80277123390563, -3.2571969029072276, 112.26918849496327, 66.9347231244047, -40.06618937091002, -54.66780262877968, -9.48861652309627, 0.0 };
static const double bgc_rodas5p_m[8] = { -7.502846399306121, 2.561846144803919, -11.627539656261098, -0.18268767659942256, 0.030198172008377946, 1.0, 1.0, 1.0 };
static const double bgc_rodas5p_e[8] = { 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0 };
static const double bgc_rodas5p_H[24] = { 25.948786856663858, -2.5579724845846235, 10.433815404888879, -2.3679251022685204, 0.524948541321073, 1.1241088310450404, 0.4272876194431874, -0.17202221070155493, -9.91568850695171, -0.9689944594115154, 3.0438037242978453, -24.495224566215796, 20.176138334709044, 15.98066361424651, -6.789040303419874, -6.710236069923372, 11.419903575922262, 2.8879645146136994, 72.92137995996029, 80.12511834622643, -52.072871366152654, -59.78993625266729, -0.15582684282751913, 4.883087185713722 };

static const bgc_rosenbrock bgc_rodas5p_ros = { 8, 3, 0.21193756319429014, bgc_rodas5p_c, bgc_rodas5p_d, bgc_rodas5p_a, bgc_rodas5p_C, bgc_rodas5p_m, bgc_rodas5p_e, bgc_rodas5p_H };
static const double bgc_radau_s5_c[5] = { 0.05710419611451768, 0.2768430136381238, 0.5835904323689168, 0.8602401356562195, 1.0 };
static const double bgc_radau_s5_alpha[2] = { 3.655694325463572, 5.70095329867179 };
static const double bgc_radau_s5_beta[2] = { 6.543736899360077, 3.2102656003085497 };
static const double bgc_radau_s5_T[25] = { 0.012517586220501045, -0.010242047817908826, 0.04767387729029572, -0.011478515255229515, -0.01401985889287541, 0.0014916701518953824, 0.05017286451737106, -0.09433181918161143, -0.007668830749180163, 0.024708578426518527, 0.07298187638808715, -0.23053953404341795, 0.1027030453801259, 0.01939846399882895, 0.08180035370375117, 0.3800914400035681, 0.37789390224886127, 0.46674413033249434, 0.40760117128019907, 0.19968242788680252, 0.9219789736812105, 1.0, 0.0, 1.0, 0.0 };
static const double bgc_radau_s5_Ti[25] = { 30.0415677215444, 13.865107856271413, 3.4800027747951856, -1.0320087978252634, 0.8043030450739899, 5.344186437834912, 4.593615567759161, -3.0363603234594243, 1.050660190231459, -0.27277861186429625, 3.748059807439805, -3.984965736343885, -1.0444156416080188, 1.1840985681379486, -0.44991777015678036, -33.041880213519, -17.376953479063566, -0.17212906325400557, -0.09916977798254265, 0.5312281158383066, -8.611443979875292, 9.699991409528808, 1.9147286396968743, 2.41869200608494, -1.0474634879353375 };
static const double bgc_radau_s5_e[5] = { -27.78093394406464, 3.641478498049213, -1.2525477211691187, 0.5920031671845428, -0.2 };

static const bgc_radau bgc_radau9_radau[1] = {
    { 5, 6.2867047517292765, bgc_radau_s5_c, bgc_radau_s5_alpha, bgc_radau_s5_beta, bgc_radau_s5_T, bgc_radau_s5_Ti, bgc_radau_s5_e },
};
static const double bgc_radau_s7_c[7] = { 0.029316427159784893, 0.1480785996684843, 0.3369846902811543, 0.5586715187715501, 0.7692338620300545, 0.9269456713197411, 1.0 };
static const double bgc_radau_s7_alpha[3] = { 4.378693561506806, 7.14105521918764, 8.511834825102946 };
static const double bgc_radau_s7_beta[3] = { 10.169693283795011, 6.623045922639276, 3.281013624325059 };
static const double bgc_radau_s7_T[49] = { 0.0021537546273105264, 0.021567551351320772, 0.008783567925144144, -0.004055161452331024, 0.004427232753268285, -0.0012386461879528741, -0.0027606174805438525, -0.0016000250778804286, -0.03813164813441155, -0.021525560594006874, 0.00841556827655959, -0.00403194957022455, -6.666635339396339e-05, 0.00318547482516621, 0.004059107301947683, 0.05739650893938172, 0.05885052920842679, -0.008560431061603433, -0.006923212665023909, -0.0023521809829433384, 0.00041690777252975626, 0.015750488079376845, -0.03821469359696835, -0.16573681127294385, -0.03737124230238446, 0.00823900729850772, 0.0031150711523461752, 0.025116604913438822, 0.11297766102422081, -0.2491742124652637, 0.27356330579866234, 0.0053667613791817705, 0.19321111610126201, 0.10171773248171515, 0.09504502035604623, 0.4583810431839315, 0.5315846490836285, 0.4863228366175729, 0.5265742264584493, 0.27553439498962584, 0.5217519452747653, 0.1280719446355439, 0.8813915783538184, 1.0, 0.0, 1.0, 0.0, 1.0, 0.0 };
static const double bgc_radau_s7_Ti[49] = { 258.13192631998226, 189.0737630813985, 49.08731481793013, 4.110647469661428, 4.053447889315564, -3.112755366607346, 1.6467749135584446, -3.007390169451292, -11.015866078765772, 1.4877994561316563, 2.1303881595592826, -1.8161410868175656, 1.134325587895161, -0.41469904594330353, -8.441963188321084, -0.650525274057515, 6.9406707303698765, -3.2050475255978985, 1.0712809435464785, -0.3548507491216222, 0.09198549132786554, 74.6783322350227, 87.40858897990081, 4.024158737379998, -3.714806315158364, -3.4300939859823174, 2.6966048097653124, -0.9386927436075462, 58.356528851906575, -10.06877395780018, -30.36638884256667, -1.020020865184866, -0.11241750037842496, 1.8906408310003777, -0.9716486393831483, -299.1862480282521, -243.04074536874478, -48.77710407803787, -2.0386719057419342, 1.673560239861085, -1.0873740320571061, 0.9019382492960993, -93.0765028974353, 23.881631056281144, 39.278880730813846, 14.38891568549108, -3.5104383993993613, 4.8632848855661805, -2.2464827295912397 };
static const double bgc_radau_s7_e[7] = { -54.374436894128614, 7.000024004259187, -2.355661091987557, 1.1322890661061344, -0.6468913267673587, 0.38753338537535237, -0.14285714285714285 };

static const bgc_radau bgc_radau13_radau[1] = {
    { 7, 8.936832788405216, bgc_radau_s7_c, bgc_radau_s7_alpha, bgc_radau_s7_beta, bgc_radau_s7_T, bgc_radau_s7_Ti, bgc_radau_s7_e },
};
static const bgc_radau bgc_radau_radau[3] = {
    { 3, 3.637834252744496, bgc_radau_s3_c, bgc_radau_s3_alpha, bgc_radau_s3_beta, bgc_radau_s3_T, bgc_radau_s3_Ti, bgc_radau_s3_e },
    { 5, 6.2867047517292765, bgc_radau_s5_c, bgc_radau_s5_alpha, bgc_radau_s5_beta, bgc_radau_s5_T, bgc_radau_s5_Ti, bgc_radau_s5_e },
    { 7, 8.936832788405216, bgc_radau_s7_c, bgc_radau_s7_alpha, bgc_radau_s7_beta, bgc_radau_s7_T, bgc_radau_s7_Ti, bgc_radau_s7_e },
};
const char *const bgc_solver_names[BGC_NUM_SOLVERS] = {
    "euler",
    "rk4",
    "dopri5",
    "vern7",
    "dop853",
    "ros2",
    "rodas4",
    "radau5",
    "rodas5p",
    "radau9",
    "radau13",
    "radau",
    "auto",
};
static const bgc_method bgc_methods[BGC_NUM_SOLVERS] = {
    { "euler", "explicit Euler, fixed step", BGC_FAMILY_FIXED, 1, &bgc_euler_erk, NULL, 0.9, 0.2, 10.0, 0.0, 1, 0.75, -1, -1, 0.0, -1, -1, NULL, 0 },
    { "rk4", "classical Runge-Kutta, fixed step", BGC_FAMILY_FIXED, 4, &bgc_rk4_erk, NULL, 0.9, 0.2, 10.0, 0.0, 4, 0.75, -1, -1, 0.0, -1, -1, NULL, 0 },
    { "dopri5", "Dormand-Prince 5(4), adaptive, dense output of order 4", BGC_FAMILY_ERK, 5, &bgc_dopri5_erk, NULL, 0.9, 0.2, 10.0, 0.04, 5, 0.75, 5, 6, 3.25, -1, -1, NULL, 0 },
    { "vern7", "Verner 7(6), adaptive, dense output of order 7: moderate to tight tolerances", BGC_FAMILY_ERK, 7, &bgc_vern7_erk, NULL, 0.9, 0.333, 6.0, 0.04, 7, 0.75, -1, -1, 0.0, -1, -1, NULL, 0 },
    { "dop853", "Dormand-Prince 8(5,3), adaptive, dense output of order 7: tight tolerances", BGC_FAMILY_ERK, 8, &bgc_dop853_erk, NULL, 0.9, 0.333, 6.0, 0.04, 8, 0.2, -1, -1, 0.0, -1, -1, NULL, 0 },
    { "ros2", "Rosenbrock 2(1), L-stable, two stages: stiff plants at a fixed step (--step, the embedded target); the Jacobian every step", BGC_FAMILY_ROSENBROCK, 2, NULL, &bgc_ros2_ros, 0.9, 0.2, 6.0, 0.0, 2, 0.75, -1, -1, 0.0, -1, -1, NULL, 0 },
    { "rodas4", "Rosenbrock 4(3), L-stable, stiff; the Jacobian every step", BGC_FAMILY_ROSENBROCK, 4, NULL, &bgc_rodas4_ros, 0.9, 0.2, 6.0, 0.0, 4, 0.75, -1, -1, 0.0, -1, -1, NULL, 0 },
    { "radau5", "Radau IIA of order 5, implicit, L-stable, stiff; Jacobian and factorisations reused", BGC_FAMILY_RADAU, 5, NULL, NULL, 0.9, 0.2, 8.0, 0.0, 4, 0.75, -1, -1, 0.0, -1, -1, bgc_radau5_radau, 1 },
    { "rodas5p", "Rosenbrock 5(4), L-stable, stiff; the Jacobian every step", BGC_FAMILY_ROSENBROCK, 5, NULL, &bgc_rodas5p_ros, 0.9, 0.2, 6.0, 0.0, 5, 0.75, -1, -1, 0.0, -1, -1, NULL, 0 },
    { "radau9", "Radau IIA of order 9 (5 stages), implicit, L-stable, stiff: tight tolerances", BGC_FAMILY_RADAU, 9, NULL, NULL, 0.9, 0.2, 8.0, 0.0, 4, 0.75, -1, -1, 0.0, -1, -1, bgc_radau9_radau, 1 },
    { "radau13", "Radau IIA of order 13 (7 stages), implicit, L-stable, stiff: very tight tolerances", BGC_FAMILY_RADAU, 13, NULL, NULL, 0.9, 0.2, 8.0, 0.0, 4, 0.75, -1, -1, 0.0, -1, -1, bgc_radau13_radau, 1 },
    { "radau", "Radau IIA of variable order 5, 9, 13 (Hairer's RADAU): the order follows the Newton iteration's convergence; stiff, any tolerance", BGC_FAMILY_RADAU, 13, NULL, NULL, 0.9, 0.2, 8.0, 0.0, 4, 0.75, -1, -1, 0.0, -1, -1, bgc_radau_radau, 3 },
    { "auto", "dopri5 until its stiffness test fires, then radau (variable order) for the rest of the run", BGC_FAMILY_AUTO, 5, NULL, NULL, 0.9, 0.2, 10.0, 0.0, 5, 0.75, -1, -1, 0.0, 2, 11, NULL, 0 },
};

/* ====================================================================== runtime === */
/* bgc's runtime: model-independent, the same in every generated program (bgc/runtime/runtime.c,
   inlined verbatim).  It uses the model part above: the sizes, bgc_model_rhs, _outputs and
   _jvp, the blocks' plans and the Jacobian's colouring. */

#ifndef BGC_SCENE_HMAX
#define BGC_SCENE_HMAX 0.0 /* the scene bounds no step */
#endif

/* ========================================================== parameters === */

int bgc_param_index(const char *name)
{
    int j;
    for (j = 0; j < BGC_NUM_PARAMS; j++)
        if (strcmp(name, bgc_param_names[j]) == 0)
            return j;
    return -1;
}

/* ========================================================== workspace === */

bgc_work *bgc_work_new(void)
{
    bgc_work *w = (bgc_work *)calloc(1, sizeof *w);
    if (!w)
        return NULL;
    w->v = (double *)calloc(BGC_DIM(BGC_WORK_DOUBLES), sizeof *w->v);
    w->iv = (int *)calloc(BGC_DIM(BGC_WORK_INTS), sizeof *w->iv);
    w->d = (double *)calloc(BGC_DIM(BGC_NUM_DISCRETE + 2 * BGC_NUM_INDICATORS), sizeof *w->d);
    if (!w->v || !w->iv || !w->d) {
        bgc_work_free(w);
        return NULL;
    }
    w->rtol = BGC_SCENE_RTOL;
    w->atol = BGC_SCENE_ATOL;
    return w;
}

void bgc_work_free(bgc_work *w)
{
    if (!w)
        return;
    free(w->v);
    free(w->iv);
    free(w->d);
    free(w);
}

void bgc_work_message(const bgc_work *w, char *msg, size_t msg_size)
{
    static const char *const how[] = { "failed", "is singular", "did not converge",
                                       "has a non-finite residual" };
    const int k = w->block - 1;
    if (w->failure == BGC_NO_JACOBIAN) {
        snprintf(msg, msg_size, "this program was built without its Jacobian");
        return;
    }
    snprintf(msg, msg_size, "at t = %.17g: algebraic block %d (%s) %s", w->t, w->block,
             k >= 0 && k < BGC_NUM_BLOCKS ? bgc_block_names[k] : "?",
             how[w->failure >= 1 && w->failure <= 3 ? w->failure : 0]);
}

static int bgc_block_fail(bgc_work *w, int k, int failure, double t)
{
    w->block = k + 1;
    w->failure = failure;
    w->t = t;
    return 1;
}

/* ======================================================= linear solves === */

/* Row scales of the assembled matrix: the largest magnitude in each row (of the plan's
   positions); a pivot below 1e-14 of its row's scale counts as zero. */
static void bgc_row_scales(const bgc_lu_plan *pl, const double *a, double *scale)
{
    int i, q;
    for (i = 0; i < pl->m; i++)
        scale[i] = 0.0;
    for (q = 0; q < pl->nnz; q++) {
        const int i2 = pl->dense ? q / pl->m : pl->prow[q];
        scale[i2] = bgc_max(scale[i2], fabs(a[q]));
    }
}

/* LU of the dense m x m matrix a (row-major) with partial pivoting, in place; scale: the
   rows' scales, permuted along.  0, or -1 if singular. */
static int bgc_lu_dense(int m, double *a, int *piv, double *scale)
{
    int i, j, k;
    for (k = 0; k < m; k++) {
        int r = k;
        for (i = k + 1; i < m; i++)
            if (fabs(a[i * m + k]) > fabs(a[r * m + k]))
                r = i;
        piv[k] = r;
        if (!(fabs(a[r * m + k]) > 1e-14 * scale[r]) || !isfinite(a[r * m + k]))
            return -1;
        if (r != k) {
            double tmp = scale[k];
            scale[k] = scale[r];
            scale[r] = tmp;
            for (j = 0; j < m; j++) {
                tmp = a[k * m + j];
                a[k * m + j] = a[r * m + j];
                a[r * m + j] = tmp;
            }
        }
        for (i = k + 1; i < m; i++) {
            const double f = a[i * m + k] / a[k * m + k];
            a[i * m + k] = f;
            for (j = k + 1; j < m; j++)
                a[i * m + j] -= f * a[k * m + j];
        }
    }
    return 0;
}

static void bgc_lu_dense_solve(int m, const double *a, const int *piv, double *b)
{
    int i, j, k;
    /* bgc_lu_dense swapped whole rows (multipliers included): all the swaps first */
    for (k = 0; k < m; k++)
        if (piv[k] != k) {
            const double tmp = b[k];
            b[k] = b[piv[k]];
            b[piv[k]] = tmp;
        }
    for (k = 0; k < m; k++)
        for (i = k + 1; i < m; i++)
            b[i] -= a[i * m + k] * b[k];
    for (i = m - 1; i >= 0; i--) {
        double sum = b[i];
        for (j = i + 1; j < m; j++)
            sum -= a[i * m + j] * b[j];
        b[i] = sum / a[i * m + i];
    }
}

/* LU in the plan's static order, in place.  0, or 1 if a pivot fails its test: for a
   symmetric matrix one sign for all pivots (definite: elimination is LDL^T, stable without
   pivoting), otherwise |pivot| >= 0.1 * the largest entry below it; and clearly nonzero for
   its row. */
static int bgc_lu_static(const bgc_lu_plan *pl, double *lu, const double *scale)
{
    int k, l, u, q = 0;
    const double sign = pl->m > 0 && lu[pl->diag[0]] < 0.0 ? -1.0 : 1.0;
    for (k = 0; k < pl->m; k++) {
        const double pivot = lu[pl->diag[k]];
        double largest = fabs(pivot);
        if (pl->symmetric) {
            if (!(sign * pivot > 1e-14 * scale[k]) || !isfinite(pivot))
                return 1;
        } else {
            for (l = pl->lptr[k]; l < pl->lptr[k + 1]; l++)
                largest = bgc_max(largest, fabs(lu[pl->lpos[l]]));
            if (!(fabs(pivot) >= 0.1 * largest && fabs(pivot) > 1e-14 * scale[k]) ||
                !isfinite(pivot))
                return 1;
        }
        for (l = pl->lptr[k]; l < pl->lptr[k + 1]; l++) {
            const double f = lu[pl->lpos[l]] / pivot;
            lu[pl->lpos[l]] = f;
            for (u = pl->uptr[k]; u < pl->uptr[k + 1]; u++)
                lu[pl->upd[q++]] -= f * lu[pl->upos[u]];
        }
    }
    return 0;
}

static void bgc_lu_static_solve(const bgc_lu_plan *pl, const double *lu, double *b)
{
    int k, l, u;
    for (k = 0; k < pl->m; k++)
        for (l = pl->lptr[k]; l < pl->lptr[k + 1]; l++)
            b[pl->lrow[l]] -= lu[pl->lpos[l]] * b[k];
    for (k = pl->m - 1; k >= 0; k--) {
        double sum = b[k];
        for (u = pl->uptr[k]; u < pl->uptr[k + 1]; u++)
            sum -= lu[pl->upos[u]] * b[pl->ucol[u]];
        b[k] = sum / lu[pl->diag[k]];
    }
}

/* Factors block k's matrix (assembled at .save): the static order (unrolled in the model
   part when the plan is small), else densely with partial pivoting.  Records which in .how;
   -1 if the matrix is singular. */
static int bgc_block_factor(bgc_work *w, const bgc_block *b)
{
    const bgc_lu_plan *pl = &b->lu;
    double *save = w->v + b->save, *lu = w->v + b->lu_off, *dense = w->v + b->dense;
    double *scale = w->v + b->scale;
    int *piv = w->iv + b->piv, q, how = 0;
    if (b->factor && b->factor(w->v) == 0) {
        w->iv[b->how] = 0;
        return 0;
    }
    bgc_row_scales(pl, save, scale);
    if (!pl->dense) {
        if (!b->factor) {
            memcpy(lu, save, (size_t)pl->nnz * sizeof *lu);
            if (bgc_lu_static(pl, lu, scale) == 0) {
                w->iv[b->how] = 0;
                return 0;
            }
        }
        for (q = 0; q < pl->m * pl->m; q++)
            dense[q] = 0.0;
        for (q = 0; q < pl->nnz; q++)
            dense[pl->prow[q] * pl->m + pl->pcol[q]] = save[q];
        how = 1;
    } else {
        memcpy(dense, save, (size_t)pl->nnz * sizeof *dense);
        how = 1;
    }
    w->iv[b->how] = how;
    return bgc_lu_dense(pl->m, dense, piv, scale);
}

static void bgc_block_lsolve(bgc_work *w, const bgc_block *b, double *rhs)
{
    if (w->iv[b->how] == 0 && b->lsolve)
        b->lsolve(w->v, rhs);
    else if (w->iv[b->how] == 0)
        bgc_lu_static_solve(&b->lu, w->v + b->lu_off, rhs);
    else
        bgc_lu_dense_solve(b->lu.m, w->v + b->dense, w->iv + b->piv, rhs);
}

static int bgc_first_nonfinite(const double *v, int n)
{
    int i;
    for (i = 0; i < n; i++)
        if (!isfinite(v[i]))
            return i;
    return -1;
}

int bgc_block_solve(bgc_work *w, int k, double t)
{
    const bgc_block *b = &bgc_blocks[k];
    if (bgc_block_factor(w, b))
        return bgc_block_fail(w, k, BGC_BLOCK_SINGULAR, t);
    bgc_block_lsolve(w, b, w->v + b->b);
    return 0;
}

int bgc_block_resolve(bgc_work *w, int k, double t)
{
    (void)t;
    bgc_block_lsolve(w, &bgc_blocks[k], w->v + bgc_blocks[k].b);
    return 0;
}

static double bgc_norm2(const double *r, int m)
{
    double s = 0.0;
    int i;
    for (i = 0; i < m; i++)
        s += r[i] * r[i];
    return sqrt(s);
}

#define BGC_NEWTON_MAXIT 50

int bgc_newton(bgc_work *w, int k, bgc_eval_fn f, double t, const double *x,
               const bgc_params *p, int final_factor)
{
    const bgc_block *b = &bgc_blocks[k];
    const int m = b->lu.m;
    double *z = w->v + b->z, *r = w->v + b->r, *dz = w->v + b->b, *zt = w->v + b->zt;
    double *rt = w->v + b->rt, *J = w->v + b->save, norm, trial, lambda;
    int it, i, small, near;
    if (f(t, x, p, w, z, r, J))
        return 1;
    norm = bgc_norm2(r, m);
    if (!isfinite(norm) || bgc_first_nonfinite(z, m) >= 0) {
        for (i = 0; i < m; i++) /* from a stale or bad start: try again from zero */
            z[i] = 0.0;
        if (f(t, x, p, w, z, r, J))
            return 1;
        norm = bgc_norm2(r, m);
        if (!isfinite(norm))
            return bgc_block_fail(w, k, BGC_BLOCK_NONFINITE, t);
    }
    for (it = 0; norm > 0.0; it++) {
        if (it == BGC_NEWTON_MAXIT)
            return bgc_block_fail(w, k, BGC_BLOCK_DIVERGED, t);
        if (bgc_block_factor(w, b))
            return bgc_block_fail(w, k, BGC_BLOCK_SINGULAR, t);
        for (i = 0; i < m; i++)
            dz[i] = -r[i];
        bgc_block_lsolve(w, b, dz);
        small = 1; /* a full step this small ends the iteration (quadratic convergence) */
        near = 1;  /* one within the tolerance ends it where the residual cannot decrease */
        for (i = 0; i < m; i++) {
            if (fabs(dz[i]) > 0.01 * (w->atol + w->rtol * fabs(z[i])) &&
                fabs(dz[i]) > 4.0 * DBL_EPSILON * fabs(z[i]))
                small = 0;
            if (fabs(dz[i]) > w->atol + w->rtol * fabs(z[i]))
                near = 0;
        }
        for (lambda = 1.0;; lambda *= 0.5) {
            for (i = 0; i < m; i++)
                zt[i] = z[i] + lambda * dz[i];
            if (f(t, x, p, w, zt, rt, NULL))
                return 1;
            trial = bgc_norm2(rt, m);
            if (small || trial <= (1.0 - 1e-4 * lambda) * norm || lambda < 1e-3)
                break;
        }
        for (i = 0; i < m; i++) {
            z[i] = zt[i];
            r[i] = rt[i];
        }
        /* no decrease even at the shortest step: the residual is at its rounding's floor (a
           flat branch of a kinked law sees it magnified: a current's rounding through
           1/Goff), and z is as good as it gets when the step left is within the tolerance */
        near = near && !small && !(trial <= (1.0 - 1e-4 * lambda) * norm);
        norm = trial;
        if (!isfinite(norm))
            return bgc_block_fail(w, k, BGC_BLOCK_NONFINITE, t);
        if (small || near)
            break;
        if (f(t, x, p, w, z, r, J))
            return 1;
    }
    /* the last evaluation was at z: the block's other variables hold their values there */
    if (final_factor) {
        if (f(t, x, p, w, z, r, J))
            return 1;
        if (bgc_block_factor(w, b))
            return bgc_block_fail(w, k, BGC_BLOCK_SINGULAR, t);
    }
    return 0;
}

/* ============================================================ Jacobian === */

/* J's structural entries, one J v per colour of columns: dense, into the n x n row-major J
   (the other entries left as they are), else into Jv, column by column as bgc_jac_col_ptr
   and bgc_jac_col_rows list them. */
static inline int bgc_jacobian_into(double t, const double *x, const bgc_params *p, bgc_work *w,
                                    double *out, int dense)
{
    enum { N = BGC_NUM_STATES };
    double *v = w->v + BGC_WORK_JAC, *jv = w->v + BGC_WORK_JAC + BGC_DIM(N);
    int c, k, i, q;
    for (i = 0; i < N; i++)
        v[i] = 0.0;
    for (c = 0; c < BGC_JAC_COLORS; c++) {
        for (k = bgc_jac_color_ptr[c]; k < bgc_jac_color_ptr[c + 1]; k++)
            v[bgc_jac_color_cols[k]] = 1.0;
        if (bgc_model_jvp(t, x, p, w, v, jv))
            return 1;
        for (k = bgc_jac_color_ptr[c]; k < bgc_jac_color_ptr[c + 1]; k++) {
            const int j = bgc_jac_color_cols[k];
            v[j] = 0.0;
            for (q = bgc_jac_col_ptr[j]; q < bgc_jac_col_ptr[j + 1]; q++)
                out[dense ? bgc_jac_col_rows[q] * N + j : q] = jv[bgc_jac_col_rows[q]];
        }
    }
    return 0;
}

int bgc_jacobian(double t, const double *x, const bgc_params *p, bgc_work *w, double *J)
{
    int q;
    for (q = 0; q < BGC_NUM_STATES * BGC_NUM_STATES; q++)
        J[q] = 0.0;
    return bgc_jacobian_into(t, x, p, w, J, 1);
}

int bgc_jacobian_values(double t, const double *x, const bgc_params *p, bgc_work *w,
                        double *Jv)
{
    return bgc_jacobian_into(t, x, p, w, Jv, 0);
}

int bgc_rhs(double t, const double *x, const bgc_params *p, bgc_work *w, double *dx)
{
    return bgc_model_rhs(t, x, p, w, dx);
}

int bgc_outputs(double t, const double *x, const bgc_params *p, bgc_work *w, double *y)
{
    return bgc_model_outputs(t, x, p, w, y);
}

int bgc_jvp(double t, const double *x, const bgc_params *p, bgc_work *w, const double *v,
            double *jv)
{
    return bgc_model_jvp(t, x, p, w, v, jv);
}

/* ========================================================= constraints === */

/* The rows that fail at (t, x): violated or not finite, or with allow only not finite. */
static int bgc_check_rows(double t, const double *x, const bgc_params *p, int allow, FILE *err)
{
    double r[BGC_DIM(BGC_NUM_CONSTRAINTS)] = { 0.0 }, s[BGC_DIM(BGC_NUM_CONSTRAINTS)] = { 0.0 };
    bgc_params q;
    int k, bad = 0;
    BGC_COPY_PARAMS(&q, p);
    bgc_params_update(&q);
    bgc_residual(t, x, &q, r);
    bgc_scale(t, x, &q, s);
    for (k = 0; k < BGC_NUM_CONSTRAINTS; k++) {
        if (fabs(r[k]) <= 1e-9 * s[k] || (allow && isfinite(r[k])))
            continue;
        bad++;
        if (err && !isfinite(r[k]))
            fprintf(err, "error: at t = %.17g: the %s residual of constraint '%s' is not finite: "
                    "the model is undefined at the initial state with these parameters (a zero "
                    "mass, say)\n", t, bgc_constraint_levels[k], bgc_constraint_names[k]);
        else if (err)
            fprintf(err, "error: initial conditions violate constraint '%s' (%s): residual = %.17g\n",
                    bgc_constraint_names[k], bgc_constraint_levels[k], r[k]);
    }
    return bad;
}

int bgc_check_constraints(double t, const double *x, const bgc_params *p, FILE *err)
{
    return bgc_check_rows(t, x, p, 0, err);
}

int bgc_check_constraints_finite(double t, const double *x, const bgc_params *p, FILE *err)
{
    return bgc_check_rows(t, x, p, 1, err);
}

/* Solves A z = b (A m x m row-major, both overwritten, z in b) by Gaussian elimination with
   partial pivoting.  -1 if A is singular to working precision. */
static int bgc_solve(int m, double *A, double *b)
{
    double scale = 0.0;
    int i, j, k;
    for (i = 0; i < m * m; i++)
        scale = bgc_max(scale, fabs(A[i]));
    for (k = 0; k < m; k++) {
        int piv = k;
        for (i = k + 1; i < m; i++)
            if (fabs(A[i * m + k]) > fabs(A[piv * m + k]))
                piv = i;
        if (!(fabs(A[piv * m + k]) > 1e-14 * scale))
            return -1;
        for (j = 0; j < m && piv != k; j++) {
            double tmp = A[k * m + j];
            A[k * m + j] = A[piv * m + j];
            A[piv * m + j] = tmp;
        }
        if (piv != k) {
            double tmp = b[k];
            b[k] = b[piv];
            b[piv] = tmp;
        }
        for (i = k + 1; i < m; i++) {
            double f = A[i * m + k] / A[k * m + k];
            for (j = k; j < m; j++)
                A[i * m + j] -= f * A[k * m + j];
            b[i] -= f * b[k];
        }
    }
    for (i = m - 1; i >= 0; i--) {
        double sum = b[i];
        for (j = i + 1; j < m; j++)
            sum -= A[i * m + j] * b[j];
        b[i] = sum / A[i * m + i];
    }
    return 0;
}

/* Projects x onto the m rows (indices rows[]) whose Jacobian jac() gives; only the states
   with movable[i] (all if movable is NULL) change.  With a metric W (metric() gives K = J W^-1,
   NULL for the identity) the step is the least change of x^T W x: dx = -K^T (K J^T)^-1 r.
   0, or -1 singular, -2 no convergence. */
typedef void (*bgc_rows_fn)(double, const double *, const bgc_params *, double *);

static int bgc_project_rows(double t, double *x, const bgc_params *p, const int *rows, int m,
                            bgc_rows_fn jac, bgc_rows_fn metric, const int *movable)
{
    enum { N = BGC_NUM_STATES, M = BGC_DIM(BGC_NUM_CONSTRAINTS) };
    double r[M] = { 0.0 }, s[M] = { 0.0 }, z[M] = { 0.0 }, A[M * M] = { 0.0 }, J[M * BGC_DIM(N)] = { 0.0 };
    double Kw[M * BGC_DIM(N)] = { 0.0 };
    const double *K = metric ? Kw : J;
    int it, i, j, k;
    for (it = 0;; it++) {
        int holds = 1;
        bgc_residual(t, x, p, r);
        bgc_scale(t, x, p, s);
        for (i = 0; i < m; i++) {
            z[i] = r[rows[i]];
            if (!(fabs(z[i]) <= 1e-9 * s[rows[i]]))
                holds = 0;
        }
        if (holds)
            return 0;
        if (it == 50)
            return -2;
        jac(t, x, p, J);
        if (metric)
            metric(t, x, p, Kw);
        for (i = 0; i < m; i++)
            for (k = 0; k < N; k++)
                if (movable && !movable[k])
                    J[i * N + k] = Kw[i * N + k] = 0.0;
        for (i = 0; i < m; i++)
            for (j = 0; j < m; j++) {
                double sum = 0.0;
                for (k = 0; k < N; k++)
                    sum += K[i * N + k] * J[j * N + k];
                A[i * m + j] = sum;
            }
        if (bgc_solve(m, A, z))
            return -1;
        for (k = 0; k < N; k++) {
            double dx = 0.0;
            for (i = 0; i < m; i++)
                dx += K[i * N + k] * z[i];
            x[k] -= dx;
        }
    }
}

int bgc_project_initial(double t, double *x, const bgc_params *p, char *msg, size_t msg_size)
{
    static const char *const why[] = { "", "the constraint Jacobian is singular",
                                       "no convergence after 50 iterations" };
    bgc_params q;
    const char *level = "position";
    int rc;
    BGC_COPY_PARAMS(&q, p);
    bgc_params_update(&q);
    rc = bgc_project_rows(t, x, &q, bgc_position_rows, BGC_NUM_POSITION_ROWS, bgc_position_jac,
                          NULL, NULL);
    if (rc == 0) {
        rc = bgc_project_rows(t, x, &q, bgc_velocity_rows, BGC_NUM_VELOCITY_ROWS,
                              bgc_velocity_jac, bgc_velocity_metric, bgc_velocity_movable);
        level = "velocity";
    }
    if (rc == 0)
        return 0;
    snprintf(msg, msg_size, "cannot project the initial conditions onto the %s constraints: %s",
             level, why[-rc]);
    return BGC_ERR_CONSTRAINT;
}

/* ============================================================ settings === */

void bgc_settings_default(bgc_settings *s)
{
    s->t0 = BGC_SCENE_T0;
    s->t_end = BGC_SCENE_T_END;
    s->dt = BGC_SCENE_DT;
    s->solver = BGC_SCENE_SOLVER;
    s->rtol = BGC_SCENE_RTOL;
    s->atol = BGC_SCENE_ATOL;
    s->step = BGC_SCENE_STEP;
    s->max_steps = BGC_MAX_STEPS;
    s->h0 = 0.0;
    s->order0 = 0;
    s->hmax = BGC_SCENE_HMAX;
    s->event_rows = 0;
    s->error_states = 0;
    s->on_event = NULL;
    s->event_ctx = NULL;
    s->inputs = NULL;
}

int bgc_check_settings(const bgc_settings *s, char *msg, size_t msg_size)
{
    const char *bad = NULL;
    if (!(isfinite(s->t0) && isfinite(s->t_end) && isfinite(s->dt) && isfinite(s->rtol)
          && isfinite(s->atol) && isfinite(s->step) && isfinite(s->h0) && isfinite(s->hmax)))
        bad = "settings must be finite numbers";
    else if (s->hmax < 0.0)
        bad = "--max-step must be positive (0: no bound)";
    else if (!(s->dt > 0.0))
        bad = "--dt must be positive";
    else if (s->t_end < s->t0)
        bad = "--t-end must not be before the start time";
    else if (!(s->rtol > 0.0 && s->atol > 0.0))
        bad = "--rtol and --atol must be positive";
    else if (s->step < 0.0)
        bad = "--step must be positive";
    else if (s->h0 < 0.0)
        bad = "the first step must not be negative";
    else if (s->max_steps < 0)
        bad = "--max-steps must not be negative";
    else if (s->solver < 0 || s->solver >= BGC_NUM_SOLVERS)
        bad = "unknown solver";
    else if (!BGC_HAS_JACOBIAN && bgc_methods[s->solver].family != BGC_FAMILY_FIXED
             && bgc_methods[s->solver].family != BGC_FAMILY_ERK)
        bad = "this program was built without the Jacobian that an implicit solver needs "
              "(bgc simulate builds one with it for such a solver)";
    else if (!((s->t_end - s->t0) / s->dt <= 1e9))
        bad = "too many output rows (more than 1e9): increase --dt";
    if (!bad)
        return 0;
    snprintf(msg, msg_size, "%s", bad);
    return BGC_ERR_USAGE;
}


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

/* ============================================================== stiff === */
/* The stiff families: Rosenbrock methods in Hairer's transformed form (RODAS's design, any
   tableau of the family) and Radau IIA with 3, 5 or 7 stages, of fixed or variable order
   (RADAU5's and RADAU's design), both with the Jacobian
   that bgc_jacobian derives symbolically and dense LU factorisations of their own (below); on
   a large sparse model (bgc_jac_lu->n > 0) with J's structural values and the sparse LU the
   compiler planned (bgc_splu_*, bgc_smat_*).  Each keeps the family contract, the numbered
   list on the Python runtime's _Family (bgc/runtime/drive.py; its twins there are _Rosenbrock
   and _Radau in bgc/runtime/stiff.py): the items cited below are that list's (item 9 is the
   Jacobian's use). */
#include <complex.h>
#undef I /* C99 7.3.1: the program may undefine it */
#undef complex

typedef double _Complex bgc_cplx;

/* ------------------------------------------------------ complex arithmetic --- */
/* Products and quotients written out, so that the results do not depend on the compiler's
   runtime library (clang's compiler-rt rounds quotients differently from libgcc): the product
   as gcc compiles it, (ac - bd) + i(ad + bc) with Annex G's recovery of infinities that came
   out as NaN + iNaN (libgcc's __muldc3), the quotient as libgcc's __divdc3 of GCC 12 and later
   (Smith's method, scaled).  With gcc these are the bits of its own `*` and `/`; the Python
   runtime does the same operations (_muldc3, _divdc3 in stiff.py). */

/* re + i im, exactly (C99 has no CMPLX; a complex is an array of its two parts, 6.2.5). */
static bgc_cplx bgc_cmake(double re, double im)
{
    union {
        bgc_cplx z;
        double part[2];
    } u;
    u.part[0] = re;
    u.part[1] = im;
    return u.z;
}

/* Annex G's boxing of a part: +-1 if it is infinite, else +-0. */
static double bgc_box(double v)
{
    return copysign(isinf(v) ? 1.0 : 0.0, v);
}

static double bgc_unnan(double v)
{
    return isnan(v) ? copysign(0.0, v) : v;
}

/* __muldc3's recovery of the infinities that came out as NaN + iNaN (rare: apart, so that the
   common product stays inline as gcc's does). */
static bgc_cplx bgc_cmul_nan(double a, double b, double c, double d)
{
    const double ac = a * c, bd = b * d, ad = a * d, bc = b * c;
    int recalc = 0;
    if (isinf(a) || isinf(b)) {
        a = bgc_box(a);
        b = bgc_box(b);
        c = bgc_unnan(c);
        d = bgc_unnan(d);
        recalc = 1;
    }
    if (isinf(c) || isinf(d)) {
        c = bgc_box(c);
        d = bgc_box(d);
        a = bgc_unnan(a);
        b = bgc_unnan(b);
        recalc = 1;
    }
    if (!recalc && (isinf(ac) || isinf(bd) || isinf(ad) || isinf(bc))) {
        a = bgc_unnan(a);
        b = bgc_unnan(b);
        c = bgc_unnan(c);
        d = bgc_unnan(d);
        recalc = 1;
    }
    if (recalc)
        return bgc_cmake(INFINITY * (a * c - b * d), INFINITY * (a * d + b * c));
    return bgc_cmake(ac - bd, ad + bc);
}

static inline bgc_cplx bgc_cmul(bgc_cplx z, bgc_cplx w)
{
    const double a = creal(z), b = cimag(z), c = creal(w), d = cimag(w);
    const double x = a * c - b * d, y = a * d + b * c;
    return isnan(x) && isnan(y) ? bgc_cmul_nan(a, b, c, d) : bgc_cmake(x, y);
}

/* __divdc3's scaling of a small numerator (big: the divisor's larger part). */
static int bgc_ctiny(double a, double b, double big)
{
    const double rmax2 = DBL_MAX / 2 * DBL_EPSILON;
    return (fabs(a) < DBL_MIN && fabs(b) < rmax2 && fabs(big) < rmax2)
           || (fabs(b) < DBL_MIN && fabs(a) < rmax2 && fabs(big) < rmax2);
}

static bgc_cplx bgc_cdiv(bgc_cplx z, bgc_cplx w)
{
    const double rbig = DBL_MAX / 2, rminscal = 1.0 / DBL_EPSILON;
    double a = creal(z), b = cimag(z), c = creal(w), d = cimag(w), ratio, denom, x, y;
    const int by_d = fabs(c) < fabs(d);
    const double big = by_d ? fabs(d) : fabs(c);
    if (big >= rbig) {
        a = a / 2;
        b = b / 2;
        c = c / 2;
        d = d / 2;
    }
    if ((by_d ? fabs(d) : fabs(c)) < DBL_EPSILON || bgc_ctiny(a, b, by_d ? d : c)) {
        a = a * rminscal;
        b = b * rminscal;
        c = c * rminscal;
        d = d * rminscal;
    }
    if (by_d) {
        ratio = c / d;
        denom = (c * ratio) + d;
        if (fabs(ratio) > DBL_MIN) {
            x = ((a * ratio) + b) / denom;
            y = ((b * ratio) - a) / denom;
        } else {
            x = ((c * (a / d)) + b) / denom;
            y = ((c * (b / d)) - a) / denom;
        }
    } else {
        ratio = d / c;
        denom = (d * ratio) + c;
        if (fabs(ratio) > DBL_MIN) {
            x = ((b * ratio) + a) / denom;
            y = (b - (a * ratio)) / denom;
        } else {
            x = (a + (d * (b / c))) / denom;
            y = (b - (d * (a / c))) / denom;
        }
    }
    if (isnan(x) && isnan(y)) { /* infinities and zeros that came out as NaN + iNaN */
        if (c == 0.0 && d == 0.0 && (!isnan(a) || !isnan(b))) {
            x = copysign(INFINITY, c) * a;
            y = copysign(INFINITY, c) * b;
        } else if ((isinf(a) || isinf(b)) && isfinite(c) && isfinite(d)) {
            a = bgc_box(a);
            b = bgc_box(b);
            x = INFINITY * (a * c + b * d);
            y = INFINITY * (b * c - a * d);
        } else if ((isinf(c) || isinf(d)) && isfinite(a) && isfinite(b)) {
            c = bgc_box(c);
            d = bgc_box(d);
            x = 0.0 * (a * c + b * d);
            y = 0.0 * (b * c - a * d);
        }
    }
    return bgc_cmake(x, y);
}

/* ------------------------------------------------------ dense linear algebra --- */
/* The real and the complex linear algebra below are one text each, written for an element
   type T by a macro: BGC_R and BGC_Z are the elements' operations, ABS1 the size a pivot is
   chosen and tested by (|re| + |im| for a complex), MUL and DIV the product and the quotient
   (for a complex bgc_cmul and bgc_cdiv, as the Python runtime computes them). */
#define BGC_RMUL(a, b) ((a) * (b))
#define BGC_RDIV(a, b) ((a) / (b))

static double bgc_cabs1(bgc_cplx z)
{
    return fabs(creal(z)) + fabs(cimag(z));
}

/* LU (LU_SOLVE) for T: LU factorisation with partial pivoting of the n x n row-major matrix
   a, in place (L below the diagonal with a unit diagonal, U on and above it); piv[k]: the
   row swapped with row k.  Returns 0, or k + 1 when column k has no nonzero pivot (a
   singular matrix; NaNs go through, as in LAPACK, and show as non-finite stages).  LU_SOLVE
   solves with its factors: b is overwritten by the solution; the factorisation swapped whole
   rows (multipliers included): all the swaps first, then L y = P b and U x = y. */
#define BGC_DENSE_LU(LU, LU_SOLVE, T, ABS1, MUL, DIV)                                       \
    static int LU(int n, T *a, int *piv)                                                     \
    {                                                                                        \
        int i, j, k;                                                                         \
        for (k = 0; k < n; k++) {                                                            \
            T *ak = a + (size_t)k * n;                                                       \
            double big = ABS1(ak[k]);                                                        \
            int p = k;                                                                       \
            for (i = k + 1; i < n; i++)                                                      \
                if (ABS1(a[(size_t)i * n + k]) > big) {                                      \
                    big = ABS1(a[(size_t)i * n + k]);                                        \
                    p = i;                                                                   \
                }                                                                            \
            piv[k] = p;                                                                      \
            if (big == 0.0)                                                                  \
                return k + 1;                                                                \
            if (p != k) {                                                                    \
                T *ap = a + (size_t)p * n;                                                   \
                for (j = 0; j < n; j++) {                                                    \
                    const T tmp = ak[j];                                                     \
                    ak[j] = ap[j];                                                           \
                    ap[j] = tmp;                                                             \
                }                                                                            \
            }                                                                                \
            for (i = k + 1; i < n; i++) {                                                    \
                T *ai = a + (size_t)i * n;                                                   \
                const T l = DIV(ai[k], ak[k]);                                               \
                ai[k] = l;                                                                   \
                if (l != 0.0)                                                                \
                    for (j = k + 1; j < n; j++)                                              \
                        ai[j] -= MUL(l, ak[j]);                                              \
            }                                                                                \
        }                                                                                    \
        return 0;                                                                            \
    }                                                                                        \
                                                                                             \
    static void LU_SOLVE(int n, const T *lu, const int *piv, T *b)                           \
    {                                                                                        \
        int i, k;                                                                            \
        for (k = 0; k < n; k++) {                                                            \
            const T bk = b[piv[k]];                                                          \
            b[piv[k]] = b[k];                                                                \
            b[k] = bk;                                                                       \
        }                                                                                    \
        for (k = 0; k < n; k++) {                                                            \
            const T bk = b[k];                                                               \
            if (bk != 0.0)                                                                   \
                for (i = k + 1; i < n; i++)                                                  \
                    b[i] -= MUL(lu[(size_t)i * n + k], bk);                                  \
        }                                                                                    \
        for (k = n - 1; k >= 0; k--) {                                                       \
            const T *row = lu + (size_t)k * n;                                               \
            T acc = b[k];                                                                    \
            for (i = k + 1; i < n; i++)                                                      \
                acc -= MUL(row[i], b[i]);                                                    \
            b[k] = DIV(acc, row[k]);                                                         \
        }                                                                                    \
    }

BGC_DENSE_LU(bgc_stiff_lu, bgc_stiff_lu_solve, double, fabs, BGC_RMUL, BGC_RDIV)
BGC_DENSE_LU(bgc_stiff_zlu, bgc_stiff_zlu_solve, bgc_cplx, bgc_cabs1, bgc_cmul, bgc_cdiv)

/* ----------------------------------------------------- sparse linear algebra --- */
/* On a large sparse model (bgc_jac_lu->n > 0) the iteration matrices c I - J are kept as the
   values of L + U in the plan's positions, and factored row by row in the plan's order with
   no search: row i is scattered into a work vector w (by column), each of its L entries, in
   ascending column k, becomes the multiplier l = w[k] / u_kk and subtracts l times row k of U,
   and the row is gathered back.  No pivot is chosen, so each is tested: every multiplier at
   most 10 in magnitude (|u_kk| >= 0.1 times the entry it eliminates, threshold partial
   pivoting's test) and each pivot clearly nonzero for its row (above 1e-14 of the row's
   largest entry) and finite.  If a test fails, the caller factors the same matrix densely
   with partial pivoting (bgc_stiff_lu). */

/* An iteration matrix on the sparse path: its factors, sparse (v or z), or dense (d or dz,
   with piv, allocated when first needed) after a pivot failed its test. */
typedef struct bgc_smat {
    double *v, *d;
    bgc_cplx *z, *dz;
    int *piv, dense;
} bgc_smat;

static void bgc_smat_free(bgc_smat *m)
{
    free(m->v);
    free(m->d);
    free(m->z);
    free(m->dz);
    free(m->piv);
}

/* Allocates the sparse values (complex: z); 0, or nonzero when out of memory. */
static int bgc_smat_new(bgc_smat *m, int complex_values)
{
    const size_t nnz = (size_t)(bgc_jac_lu->nnz > 0 ? bgc_jac_lu->nnz : 1);
    memset(m, 0, sizeof *m);
    if (complex_values)
        m->z = malloc(nnz * sizeof *m->z);
    else
        m->v = malloc(nnz * sizeof *m->v);
    return complex_values ? m->z == NULL : m->v == NULL;
}

/* The dense fallback's storage; nonzero when out of memory. */
static int bgc_smat_dense(bgc_smat *m, int complex_values)
{
    const size_t n = (size_t)bgc_jac_lu->n;
    if (!m->piv)
        m->piv = malloc(n * sizeof *m->piv);
    if (complex_values && !m->dz)
        m->dz = malloc(n * n * sizeof *m->dz);
    if (!complex_values && !m->d)
        m->d = malloc(n * n * sizeof *m->d);
    return !m->piv || (complex_values ? !m->dz : !m->d);
}

/* For T (COMPLEX 0 or 1; its values VALUES and DENSE in a bgc_smat; LU, LU_SOLVE dense):
   FORM: a = c I - J from J's structural values (c: diag).
   FACTOR: a factored in place; 0, or 1 if a pivot fails its test.  w: n elements.
   SOLVE: b (in the states' order) overwritten by the solution; w: n elements.
   SMAT_FACTOR: c I - J factored, sparse or else dense: 0, or nonzero if singular (or out of
   memory for the dense fallback).  SMAT_SOLVE: the solve with its factors. */
#define BGC_SPARSE_LU(FORM, FACTOR, SOLVE, SMAT_FACTOR, SMAT_SOLVE, T, COMPLEX, ABS1, MUL,    \
                      DIV, VALUES, DENSE, LU, LU_SOLVE)                                      \
    static void FORM(const bgc_splu *pl, const double *Jv, T diag, T *a)                     \
    {                                                                                        \
        int q;                                                                               \
        for (q = 0; q < pl->nnz; q++)                                                        \
            a[q] = 0.0;                                                                      \
        for (q = 0; q < bgc_jac_col_ptr[pl->n]; q++)                                         \
            a[pl->jpos[q]] = -Jv[q];                                                         \
        for (q = 0; q < pl->n; q++)                                                          \
            a[pl->dpos[q]] += diag;                                                          \
    }                                                                                        \
                                                                                             \
    static int FACTOR(const bgc_splu *pl, T *a, T *w)                                        \
    {                                                                                        \
        int i, q, r;                                                                         \
        for (i = 0; i < pl->n; i++) {                                                        \
            const int end = pl->rowptr[i + 1], d = pl->diag[i];                              \
            double scale = 0.0;                                                              \
            for (q = pl->rowptr[i]; q < end; q++) {                                          \
                w[pl->cols[q]] = a[q];                                                       \
                scale = bgc_max(scale, ABS1(a[q]));                                          \
            }                                                                                \
            for (q = pl->rowptr[i]; q < d; q++) {                                            \
                const int k = pl->cols[q];                                                   \
                const T l = DIV(w[k], a[pl->diag[k]]);                                       \
                if (!(ABS1(l) <= 10.0))                                                      \
                    return 1;                                                                \
                w[k] = l;                                                                    \
                for (r = pl->diag[k] + 1; r < pl->rowptr[k + 1]; r++)                        \
                    w[pl->cols[r]] -= MUL(l, a[r]);                                          \
            }                                                                                \
            for (q = pl->rowptr[i]; q < end; q++)                                            \
                a[q] = w[pl->cols[q]];                                                       \
            if (!(ABS1(a[d]) > 1e-14 * scale) || !isfinite(ABS1(a[d])))                      \
                return 1;                                                                    \
        }                                                                                    \
        return 0;                                                                            \
    }                                                                                        \
                                                                                             \
    static void SOLVE(const bgc_splu *pl, const T *a, T *b, T *w)                            \
    {                                                                                        \
        int i, q;                                                                            \
        for (i = 0; i < pl->n; i++) {                                                        \
            T acc = b[pl->perm[i]];                                                          \
            for (q = pl->rowptr[i]; q < pl->diag[i]; q++)                                    \
                acc -= MUL(a[q], w[pl->cols[q]]);                                            \
            w[i] = acc;                                                                      \
        }                                                                                    \
        for (i = pl->n - 1; i >= 0; i--) {                                                   \
            T acc = w[i];                                                                    \
            for (q = pl->diag[i] + 1; q < pl->rowptr[i + 1]; q++)                            \
                acc -= MUL(a[q], w[pl->cols[q]]);                                            \
            w[i] = DIV(acc, a[pl->diag[i]]);                                                 \
        }                                                                                    \
        for (i = 0; i < pl->n; i++)                                                          \
            b[pl->perm[i]] = w[i];                                                           \
    }                                                                                        \
                                                                                             \
    static int SMAT_FACTOR(bgc_smat *m, const double *Jv, T diag, T *w)                      \
    {                                                                                        \
        const bgc_splu *pl = bgc_jac_lu;                                                     \
        const int n = pl->n;                                                                 \
        int j, q;                                                                            \
        FORM(pl, Jv, diag, m->VALUES);                                                       \
        m->dense = 0;                                                                        \
        if (FACTOR(pl, m->VALUES, w) == 0)                                                   \
            return 0;                                                                        \
        if (bgc_smat_dense(m, COMPLEX))                                                      \
            return 1;                                                                        \
        m->dense = 1;                                                                        \
        for (q = 0; q < n * n; q++)                                                          \
            m->DENSE[q] = 0.0;                                                               \
        for (j = 0; j < n; j++)                                                              \
            for (q = bgc_jac_col_ptr[j]; q < bgc_jac_col_ptr[j + 1]; q++)                    \
                m->DENSE[(size_t)bgc_jac_col_rows[q] * n + j] = -Jv[q];                      \
        for (j = 0; j < n; j++)                                                              \
            m->DENSE[(size_t)j * n + j] += diag;                                             \
        return LU(n, m->DENSE, m->piv);                                                      \
    }                                                                                        \
                                                                                             \
    static void SMAT_SOLVE(const bgc_smat *m, T *b, T *w)                                    \
    {                                                                                        \
        if (m->dense)                                                                        \
            LU_SOLVE(bgc_jac_lu->n, m->DENSE, m->piv, b);                                    \
        else                                                                                 \
            SOLVE(bgc_jac_lu, m->VALUES, b, w);                                              \
    }

BGC_SPARSE_LU(bgc_splu_form, bgc_splu_factor, bgc_splu_solve, bgc_smat_factor, bgc_smat_solve,
              double, 0, fabs, BGC_RMUL, BGC_RDIV, v, d, bgc_stiff_lu, bgc_stiff_lu_solve)
BGC_SPARSE_LU(bgc_splu_zform, bgc_splu_zfactor, bgc_splu_zsolve, bgc_smat_zfactor,
              bgc_smat_zsolve, bgc_cplx, 1, bgc_cabs1, bgc_cmul, bgc_cdiv, z, dz, bgc_stiff_zlu,
              bgc_stiff_zlu_solve)

/* The error norm of the stiff families: sqrt(mean((v_i / w_i)^2)) over the states the error
   control weighs (s->error_states), 0 without states; *worst: the component with the largest
   share. */
static double bgc_stiff_norm(const bgc_settings *s, const double *v, const double *w,
                             int *worst)
{
    const int N = bgc_error_states(s);
    double sum = 0.0, big = -1.0;
    int l;
    for (l = 0; l < N; l++) {
        const double q = (v[l] / w[l]) * (v[l] / w[l]);
        sum += q;
        if (q > big) {
            big = q;
            *worst = l;
        }
    }
    return N > 0 ? sqrt(sum / (double)N) : 0.0;
}

static int bgc_stiff_fail_singular(bgc_run *r, double t, double h)
{
    snprintf(r->msg, r->msg_size, "at t = %.17g: %s: the iteration matrix is singular (h = %.3g)",
             t, r->method->name, h);
    return BGC_ERR_RUNTIME;
}

/* An attempt that failed (bad: how, bad_kind: what was not finite): half the step. */
static void bgc_stiff_retry(bgc_outcome *o, double hnew, int bad, int bad_kind)
{
    o->kind = BGC_STEP_RETRY;
    o->hnew = hnew;
    o->bad = bad;
    o->bad_kind = bad_kind;
}

static void bgc_stiff_end(bgc_outcome *o, int rc)
{
    o->kind = BGC_STEP_END;
    o->rc = rc;
}

/* ------------------------------------------------------- Rosenbrock methods --- */

/* Rosenbrock methods as Hairer's RODAS: at every new point f(t, y), df/dt (a forward
   difference, unless the model is autonomous) and the Jacobian J; per step attempt one
   factorisation of E = I/(gamma h) - J and one solve per stage,
   E k_i = f(t + c_i h, y + sum_j a_ij k_j) + sum_j C_ij k_j / h + h d_i df/dt;
   y1 = y + sum m_j k_j, the error sum e_j k_j in Hairer's norm, Gustafsson's predictive step
   control, outputs by the dense output y(theta) = (1 - theta) y0 + theta (y1 + (1 - theta)
   (q_1 + theta (q_2 + ... + theta q_R))), q_r = sum_j H_rj k_j (formed when first needed).
   A singular E, a failed block or a non-finite stage halve the step.  On fixed steps: no
   error control, and those failures end the run.  J at every new point (contract items 2, 7
   and 9). */
typedef struct bgc_ros_state {
    bgc_run *r;
    const bgc_rosenbrock *m;
    int fixed, accepted, nsing, worst;
    double hacc, erracc;
    double *J, *E, *k, *f0, *ft, *ys, *q; /* q: R rows (the first two also the error's) */
    int *piv;
    double *sw;  /* the sparse path: J's structural values in J, E in sm, a work vector */
    bgc_smat sm;
    const double *y, *y1; /* the step last accepted, for the dense output */
} bgc_ros_state;

/* f, df/dt and J at a new point (t, y); nonzero (message set) if that fails. */
static int bgc_ros_point(bgc_ros_state *ms, bgc_run *r, double t, const double *y)
{
    enum { N = BGC_NUM_STATES };
    int l, rc = bgc_start_rhs(r, t, y, ms->f0);
    if (rc)
        return rc;
    if (!BGC_AUTONOMOUS) {
        const double delta = sqrt(DBL_EPSILON * bgc_max(1e-5, fabs(t)));
        r->st->rhs++;
        if (bgc_model_rhs(t + delta, y, r->p, r->w, ms->ft))
            return bgc_fail_block(r->msg, r->msg_size, r->w);
        for (l = 0; l < N; l++)
            ms->ft[l] = (ms->ft[l] - ms->f0[l]) / delta;
    }
    r->st->jac++;
    if (bgc_jac_lu->n ? bgc_jacobian_values(t, y, r->p, r->w, ms->J)
                      : bgc_jacobian(t, y, r->p, r->w, ms->J))
        return bgc_fail_block(r->msg, r->msg_size, r->w);
    return 0;
}

static void bgc_ros_finish(void *state)
{
    bgc_ros_state *ms = state;
    free(ms->piv);
    free(ms->J);
    bgc_smat_free(&ms->sm);
    free(ms);
}

static void *bgc_ros_start(bgc_run *r, const double *y, double *h, int *rc)
{
    enum { N = BGC_NUM_STATES, D = BGC_DIM(BGC_NUM_STATES) };
    const bgc_rosenbrock *m = r->method->ros;
    const int S = m->stages, R = m->dense_rows > 2 ? m->dense_rows : 2;
    const size_t matrices = bgc_jac_lu->n ? (size_t)bgc_jac_col_ptr[N] + D : (size_t)2 * D * D;
    bgc_ros_state *ms = calloc(1, sizeof *ms);
    double *mem = malloc((matrices + (size_t)(S + 3 + R) * D) * sizeof *mem);
    int l, *piv = malloc((size_t)D * sizeof *piv);
    if (!ms || !mem || !piv || (bgc_jac_lu->n && bgc_smat_new(&ms->sm, 0))) {
        if (ms)
            bgc_smat_free(&ms->sm);
        free(ms);
        free(mem);
        free(piv);
        *rc = bgc_fail_memory(r->msg, r->msg_size);
        return NULL;
    }
    ms->r = r;
    ms->m = m;
    ms->fixed = r->fixed;
    ms->worst = -1;
    ms->erracc = 1.0;
    ms->piv = piv;
    ms->J = mem;
    ms->E = ms->J + (bgc_jac_lu->n ? (size_t)bgc_jac_col_ptr[N] : (size_t)D * D);
    ms->sw = ms->E; /* the sparse path: the work vector in E's place */
    ms->k = bgc_jac_lu->n ? ms->sw + D : ms->E + (size_t)D * D;
    ms->f0 = ms->k + (size_t)S * D;
    ms->ft = ms->f0 + D;
    ms->ys = ms->ft + D;
    ms->q = ms->ys + D;
    for (l = 0; l < N; l++)
        ms->ft[l] = 0.0;
    *rc = bgc_ros_point(ms, r, r->t, y);
    if (*rc) {
        bgc_ros_finish(ms);
        return NULL;
    }
    if (!ms->fixed)
        *h = bgc_first_step(r, y, ms->f0, ms->ys, ms->q);
    return ms;
}

/* The stages into k; nonzero if a block failed in one. */
static int bgc_ros_stages(bgc_ros_state *ms, bgc_run *r, double t, double h, double tph,
                          const double *y)
{
    enum { N = BGC_NUM_STATES, D = BGC_DIM(BGC_NUM_STATES) };
    const bgc_rosenbrock *m = ms->m;
    const int S = m->stages;
    double *k = ms->k;
    int i, j, l;
    for (i = 0; i < S; i++) {
        const double *a = m->a + (size_t)i * S, *C = m->C + (size_t)i * S;
        double *ki = k + (size_t)i * D;
        if (i == 0) {
            for (l = 0; l < N; l++)
                ki[l] = ms->f0[l];
        } else {
            for (l = 0; l < N; l++) {
                double acc = 0.0;
                for (j = 0; j < i; j++)
                    if (a[j] != 0.0)
                        acc += a[j] * k[(size_t)j * D + l];
                ms->ys[l] = y[l] + acc;
            }
            r->st->rhs++;
            if (bgc_model_rhs(m->c[i] == 1.0 ? tph : t + m->c[i] * h, ms->ys, r->p, r->w, ki))
                return 1;
        }
        for (l = 0; l < N; l++) {
            double acc = 0.0;
            for (j = 0; j < i; j++)
                if (C[j] != 0.0)
                    acc += C[j] * k[(size_t)j * D + l];
            ki[l] += acc / h;
            if (!BGC_AUTONOMOUS && m->d[i] != 0.0)
                ki[l] += h * m->d[i] * ms->ft[l];
        }
        if (bgc_jac_lu->n)
            bgc_smat_solve(&ms->sm, ki, ms->sw);
        else
            bgc_stiff_lu_solve(N, ms->E, ms->piv, ki);
        r->st->solves++;
    }
    return 0;
}

/* y1, and the error estimate's norm (the estimate in q's first row, the weights in its
   second). */
static double bgc_ros_solution(bgc_ros_state *ms, const bgc_settings *s, const double *y,
                               double *y1)
{
    enum { N = BGC_NUM_STATES, D = BGC_DIM(BGC_NUM_STATES) };
    const bgc_rosenbrock *m = ms->m;
    double *q2 = ms->q, *q3 = ms->q + D;
    int j, l;
    for (l = 0; l < N; l++) {
        double acc = 0.0, e = 0.0;
        for (j = 0; j < m->stages; j++) {
            const double kj = ms->k[(size_t)j * D + l];
            if (m->m[j] != 0.0)
                acc += m->m[j] * kj;
            if (m->e[j] != 0.0)
                e += m->e[j] * kj;
        }
        y1[l] = y[l] + acc;
        q2[l] = e;
        q3[l] = bgc_weight(s, y[l], y1[l]);
    }
    return bgc_stiff_norm(s, q2, q3, &ms->worst);
}

/* One attempt (contract item 3): E factored, the stages, y1 and the error, Gustafsson's
   controller. */
static void bgc_ros_step(void *state, bgc_run *r, double t, double h, double tph,
                         const double *y, double *y1, bgc_outcome *o)
{
    enum { N = BGC_NUM_STATES, D = BGC_DIM(BGC_NUM_STATES) };
    bgc_ros_state *ms = state;
    const bgc_method *method = r->method;
    const double expo = 1.0 / (double)method->q;
    double err, fac;
    int i, j, l;

    /* E = I/(gamma h) - J, factored */
    r->st->lu++;
    if (bgc_jac_lu->n) {
        l = bgc_smat_factor(&ms->sm, ms->J, 1.0 / (ms->m->gamma * h), ms->sw);
    } else {
        for (l = 0; l < N * N; l++)
            ms->E[l] = -ms->J[l];
        for (l = 0; l < N; l++)
            ms->E[(size_t)l * N + l] += 1.0 / (ms->m->gamma * h);
        l = bgc_stiff_lu(N, ms->E, ms->piv);
    }
    if (l) {
        if (ms->fixed || ++ms->nsing == 5)
            bgc_stiff_end(o, bgc_stiff_fail_singular(r, t, h));
        else
            bgc_stiff_retry(o, h * 0.5, BGC_BAD_SINGULAR, 0);
        return;
    }
    if (bgc_ros_stages(ms, r, t, h, tph, y)) { /* an algebraic block failed in a stage */
        if (ms->fixed)
            bgc_stiff_end(o, bgc_fail_block(r->msg, r->msg_size, r->w));
        else
            bgc_stiff_retry(o, h * 0.5, BGC_BAD_BLOCK, 0);
        return;
    }
    err = bgc_ros_solution(ms, r->s, y, y1);
    o->worst = ms->worst;
    i = bgc_first_nonfinite(y1, N);
    if (err != err || err > DBL_MAX || i >= 0) {
        int bad = i, bad_kind = 1;
        if (ms->fixed) {
            bgc_stiff_end(o, bgc_fail(r->msg, r->msg_size, tph, "state",
                                      bgc_state_names[i >= 0 ? i : 0]));
            return;
        }
        for (j = 1; j < ms->m->stages && bad < 0; j++) {
            bad = bgc_first_nonfinite(ms->k + (size_t)j * D, N);
            bad_kind = 2;
        }
        bgc_stiff_retry(o, h * 0.5, bad, bad_kind);
        return;
    }
    if (ms->fixed)
        err = 0.0;

    /* Gustafsson's predictive controller (rodas.f) */
    fac = bgc_max(1.0 / method->fac_max,
                  bgc_min(1.0 / method->fac_min, pow(err, expo) / method->safe));
    o->hnew = h / fac;
    if (err <= 1.0) {
        if (ms->accepted > 0) {
            double facgus = (ms->hacc / h) * pow(err * err / ms->erracc, expo) / method->safe;
            facgus = bgc_max(1.0 / method->fac_max, bgc_min(1.0 / method->fac_min, facgus));
            fac = bgc_max(fac, facgus);
            o->hnew = h / fac;
        }
        ms->hacc = h;
        ms->erracc = bgc_max(1e-2, err);
        ms->accepted++;
        ms->nsing = 0;
        ms->y = y;
        ms->y1 = y1;
        o->kind = BGC_STEP_ACCEPT;
    } else {
        o->kind = BGC_STEP_REJECT;
    }
}

/* The dense output (contract item 6): the q_r once, then y(theta). */
static int bgc_ros_prepare(void *state)
{
    enum { N = BGC_NUM_STATES, D = BGC_DIM(BGC_NUM_STATES) };
    bgc_ros_state *ms = state;
    const int S = ms->m->stages, R = ms->m->dense_rows;
    int j, l, r;
    for (r = 0; r < R; r++) {
        const double *H = ms->m->H + (size_t)r * S;
        double *q = ms->q + (size_t)r * D;
        for (l = 0; l < N; l++) {
            double acc = 0.0;
            for (j = 0; j < S; j++)
                acc += H[j] * ms->k[(size_t)j * D + l];
            q[l] = acc;
        }
    }
    return 0;
}

static void bgc_ros_dense(const void *state, double theta, double *yout)
{
    enum { N = BGC_NUM_STATES, D = BGC_DIM(BGC_NUM_STATES) };
    const bgc_ros_state *ms = state;
    const int R = ms->m->dense_rows;
    const double s1 = 1.0 - theta;
    int l, r;
    for (l = 0; l < N; l++) {
        double acc = ms->q[(size_t)(R - 1) * D + l];
        for (r = R - 2; r >= 0; r--)
            acc = ms->q[(size_t)r * D + l] + theta * acc;
        yout[l] = s1 * ms->y[l] + theta * (ms->y1[l] + s1 * acc);
    }
}

/* The new point's evaluations (none after the run's last step; contract item 7). */
static int bgc_ros_after(void *state, bgc_run *r, double tph, const double *y1, int last)
{
    return last ? 0 : bgc_ros_point(state, r, tph, y1);
}

static const bgc_family bgc_family_rosenbrock = {
    bgc_ros_start, bgc_ros_step, NULL, bgc_ros_prepare, bgc_ros_dense, bgc_ros_after, NULL,
    bgc_ros_finish, 1};

/* ------------------------------------------------------- Radau IIA (RADAU) --- */

/* The collocation polynomial of an accepted step through (0, 0) and (c_i, Z_i) in Newton's
   form: u(theta) = theta (b1 + (theta - c1) (b2 + ... + (theta - c_{s-1}) b_s)); the state is
   y0 + u(theta).  z, b: s x D. */
static void bgc_radau_poly(const bgc_radau *m, const double *z, double *b)
{
    enum { N = BGC_NUM_STATES, D = BGC_DIM(BGC_NUM_STATES) };
    const int ns = m->s;
    int l, j, k;
    for (l = 0; l < N; l++) {
        double d[BGC_RADAU_MAX_STAGES + 1], x[BGC_RADAU_MAX_STAGES + 1];
        d[0] = 0.0;
        x[0] = 0.0;
        for (k = 0; k < ns; k++) {
            d[k + 1] = z[(size_t)k * D + l];
            x[k + 1] = m->c[k];
        }
        for (j = 1; j <= ns; j++) /* divided differences, in place */
            for (k = ns; k >= j; k--)
                d[k] = (d[k] - d[k - 1]) / (x[k] - x[k - j]);
        for (k = 0; k < ns; k++)
            b[(size_t)k * D + l] = d[k + 1];
    }
}

static double bgc_radau_u(const bgc_radau *m, const double *b, int l, double theta)
{
    enum { D = BGC_DIM(BGC_NUM_STATES) };
    int k = m->s - 1;
    double acc = b[(size_t)k * D + l];
    while (k-- > 0)
        acc = b[(size_t)k * D + l] + (theta - m->c[k]) * acc;
    return theta * acc;
}

/* out[i so] = sum_j M[i ns + j] v[j sv] for i < ns (M: ns x ns, row-major), summed in the
   order of j: the stage transformations T and T^-1 applied to one component. */
static void bgc_radau_mul(const double *M, int ns, const double *v, size_t sv, double *out,
                          size_t so)
{
    int i, j;
    for (i = 0; i < ns; i++) {
        double acc = M[(size_t)i * ns] * v[0];
        for (j = 1; j < ns; j++)
            acc += M[(size_t)i * ns + j] * v[(size_t)j * sv];
        out[(size_t)i * so] = acc;
    }
}

/* What follows from a stage set: its Newton budget, RADAU's tolerances for it and its
   exponents. */
typedef struct bgc_radau_use {
    const bgc_radau *m;
    int ns, pairs, nit;
    double rtol, atol, fnewt, cfac, expo;
} bgc_radau_use;

static void bgc_radau_configure(bgc_radau_use *u, const bgc_method *method,
                                const bgc_settings *s, int set)
{
    const bgc_radau *m = &method->radau[set];
    const double expm = (double)(m->s + 1) / (2.0 * (double)m->s), en = 1.0 / expm - 1.0;
    u->m = m;
    u->ns = m->s;
    u->pairs = (m->s - 1) / 2;
    u->nit = 7 + 5 * ((m->s - 3) / 2);
    u->rtol = 0.1 * pow(s->rtol, expm);
    u->atol = u->rtol * (s->atol / s->rtol);
    u->fnewt = bgc_max(10.0 * DBL_EPSILON / u->rtol,
                       bgc_min(0.03, en == 0.5 ? sqrt(u->rtol) : pow(u->rtol, en)));
    u->cfac = method->safe * (double)(1 + 2 * u->nit);
    u->expo = 1.0 / (double)(m->s + 1);
}

/* Radau IIA after Hairer's RADAU5 and RADAU, with s = 3, 5 or 7 stages (order 2s - 1).  The
   stage increments Z_i = Y_i - y solve Z = h (A x I) F(Z); with W = (T^-1 x I) Z the simplified
   Newton iteration decouples into (gamma/h I - J) dW_1 = (T^-1 F)_1 - gamma/h W_1 and, for each
   complex pair k, dW_2k + i dW_2k+1 from ((alpha_k + i beta_k)/h I - J) with the right side
   (T^-1 F)_2k + i (T^-1 F)_2k+1 - (alpha_k + i beta_k)/h (W_2k + i W_2k+1): one real and
   (s - 1)/2 complex factorisations per h and J.
   Tolerances as RADAU transforms them: rtol' = 0.1 rtol^((s+1)/(2s)), atol' = rtol' atol / rtol;
   Newton's weights atol' + rtol' |y| at the step's start.  Newton: at most 7, 12 or 17
   iterations (s = 3, 5, 7) from the previous step's collocation polynomial (zero on the first
   step and after an order change), convergence rate theta, stop when
   theta/(1 - theta) |dW| <= fnewt = max(10 eps/rtol', min(0.03, rtol'^(1/e - 1))),
   e = (s+1)/(2s); never after one iteration (RADAU5 allows it with the previous step's theta:
   after a change of h the old rate does not hold, and the stages' Newton error of up to fnewt
   times the tolerance can exceed the method's far smaller local error; across a kink of a law
   under noevent, J is the other branch's, and a first increment damped by a matrix far
   stiffer than the branch's looked converged while the stages were not, the error estimate
   as blind: the run did not converge as the tolerance tightened); theta >= 0.99 or no
   convergence: h / 2; a predicted miss
   of fnewt within the budget: h shrunk accordingly.  Error estimate:
   (gamma/h I - J) err = f(t, y) + sum_j e_j Z_j / h, refined once with f(t, y + err) on the
   first step and after a rejection, in Hairer's norm with the weights
   atol' + rtol' max(|y|, |y1|) of the other solvers.  Step control: Gustafsson's, both the
   standard and the predictive factor (not on the first step of a new order) with the safety
   min(safe, safe (1 + 2 nit) / (newton + 2 nit)), err^(1/(s+1)), hnew/h in
   [fac_min, fac_max].  J is recomputed when the contraction was poorer than 0.001, the
   matrices are refactored unless hnew/h stays in [1, 1.2] (h is then kept).
   Variable order (several stage sets, adaptive steps): RADAU's strategy, looked at whenever
   the matrices are to be factored (and every 10 steps at a kept h): thetat = min(10,
   max(theta, thetat / 2)) smooths the last Newton contraction; the order goes up one set when
   thetat <= 0.002 after more than one iteration, h changes by less than 20 % and 10 steps
   have passed since the last change; down when thetat >= 0.8, after a Newton failure or a
   singular matrix, or after a Newton-predicted cut of h by half or more.
   Outputs by the collocation polynomial.  Counts: each real or complex factorisation and
   each real or complex solve.  With s->step > 0: steps of that size at the first stage set,
   no error estimate, and Newton's failure (after a fresh Jacobian) ends the run. */
typedef struct bgc_radau_state {
    bgc_run *r;
    const bgc_method *method;
    int fixed, variable, smax, set, since, change, unexp, unexn, recheck;
    int reject, first, needjac, caljac, accepted, nsing, worst, newt;
    double hfact, hold, hacc, erracc, faccon, theta, thetat, thqold, dynold, hhfac;
    double *J, *E1, *Z, *W, *b, *zlast, *dw, *f0, *scal, *ys, *tmp, *cont, *f2, *ew;
    bgc_cplx *Ec, *zc;
    int *piv;
    bgc_smat sm[(BGC_RADAU_MAX_STAGES + 1) / 2]; /* the sparse path: the real matrix, then
                                                    the complex ones (J: J's structural values,
                                                    E1 and Ec: work vectors) */
    bgc_radau_use u;
    const bgc_radau *dm; /* the stage set ... */
    const double *y;     /* ... and the start of the step last accepted (dense output) */
} bgc_radau_state;
#define BGC_RADAU_THET 0.001 /* recompute J when Newton contracted more slowly than this */

static void bgc_radau_finish(void *state)
{
    bgc_radau_state *ms = state;
    int k;
    for (k = 0; k < (BGC_RADAU_MAX_STAGES + 1) / 2; k++)
        bgc_smat_free(&ms->sm[k]);
    free(ms->piv);
    free(ms->Ec);
    free(ms->J);
    free(ms);
}

/* The state with its storage, or NULL (no memory). */
static bgc_radau_state *bgc_radau_new(bgc_run *r)
{
    enum { D = BGC_DIM(BGC_NUM_STATES) };
    const bgc_method *method = r->method;
    bgc_radau_state *ms = calloc(1, sizeof *ms);
    const int sparse = bgc_jac_lu->n > 0;
    int k, l, pmax, smax = 0;
    for (k = 0; k < method->radau_sets; k++)
        smax = method->radau[k].s > smax ? method->radau[k].s : smax;
    pmax = (smax - 1) / 2;
    if (!ms)
        return NULL;
    const size_t nj = sparse ? (size_t)bgc_jac_col_ptr[BGC_NUM_STATES] : (size_t)D * D;
    const size_t ne = sparse ? (size_t)D : (size_t)D * D;
    ms->J = malloc((nj + ne + (size_t)(3 * smax + 11) * D) * sizeof *ms->J);
    ms->Ec = malloc(((size_t)(sparse ? 1 : pmax) * ne + (size_t)pmax * D + 1) * sizeof *ms->Ec);
    ms->piv = malloc((size_t)(1 + pmax) * D * sizeof *ms->piv + sizeof *ms->piv);
    for (k = 0; k < 1 + pmax && sparse; k++)
        if (bgc_smat_new(&ms->sm[k], k > 0)) {
            bgc_radau_finish(ms);
            return NULL;
        }
    if (!ms->J || !ms->Ec || !ms->piv) {
        bgc_radau_finish(ms);
        return NULL;
    }
    ms->smax = smax;
    ms->E1 = ms->J + nj;
    ms->Z = ms->E1 + ne; /* smax x D */
    ms->W = ms->Z + (size_t)smax * D; /* smax x D */
    ms->b = ms->W + (size_t)smax * D; /* smax x D */
    ms->zlast = ms->b + (size_t)smax * D;
    ms->dw = ms->zlast + D;
    ms->f0 = ms->dw + D;
    ms->scal = ms->f0 + D;
    ms->ys = ms->scal + D;
    ms->tmp = ms->ys + D;
    ms->cont = ms->tmp + D;
    ms->f2 = ms->cont + D;
    ms->ew = ms->f2 + D;
    ms->zc = ms->Ec + (size_t)(sparse ? 1 : pmax) * ne; /* pmax x D */
    for (l = 0; l < smax * D; l++)
        ms->b[l] = 0.0;
    for (l = 0; l < D; l++)
        ms->zlast[l] = 0.0;
    return ms;
}

static void bgc_radau_scale(bgc_radau_state *ms, const double *y)
{
    int l;
    for (l = 0; l < BGC_NUM_STATES; l++)
        ms->scal[l] = ms->u.atol + ms->u.rtol * fabs(y[l]);
}

/* The state, f and Newton's weights at the first point and the first step (contract items 1
   and 2; J comes with the first attempt, item 9). */
static void *bgc_radau_start(bgc_run *r, const double *y, double *h, int *rc)
{
    const bgc_method *method = r->method;
    bgc_radau_state *ms = bgc_radau_new(r);
    int k;
    if (!ms) {
        *rc = bgc_fail_memory(r->msg, r->msg_size);
        return NULL;
    }
    ms->r = r;
    ms->method = method;
    ms->fixed = r->fixed;
    ms->variable = method->radau_sets > 1 && !ms->fixed;
    for (k = 0; k < method->radau_sets; k++)
        if (ms->variable && 2 * method->radau[k].s - 1 == r->s->order0) {
            ms->set = k; /* going on from an earlier run: at its order, free to change it */
            ms->since = 10;
        }
    ms->first = ms->needjac = 1;
    ms->worst = -1;
    ms->erracc = ms->thqold = ms->dynold = ms->faccon = 1.0;
    ms->theta = BGC_RADAU_THET;
    ms->hhfac = 0.5;
    bgc_radau_configure(&ms->u, method, r->s, ms->set);
    ms->dm = ms->u.m;
    *rc = bgc_start_rhs(r, r->t, y, ms->f0);
    if (*rc) {
        bgc_radau_finish(ms);
        return NULL;
    }
    bgc_radau_scale(ms, y);
    if (!ms->fixed)
        *h = bgc_first_step(r, y, ms->f0, ms->ys, ms->tmp);
    return ms;
}

/* The order, whenever the matrices are to be factored (variable order only). */
static void bgc_radau_order(bgc_radau_state *ms, double h, const double *y)
{
    const double hquot = ms->hold > 0.0 ? h / ms->hold : 0.0;
    int next = ms->set;
    ms->since++;
    ms->thetat = bgc_min(10.0, bgc_max(ms->theta, 0.5 * ms->thetat));
    if (ms->newt > 1 && ms->thetat <= 0.002 && hquot > 0.8 && hquot < 1.2 && ms->since > 10
        && ms->set + 1 < ms->method->radau_sets)
        next = ms->set + 1;
    if ((ms->thetat >= 0.8 || ms->unexp || ms->unexn) && ms->set > 0)
        next = ms->set - 1;
    ms->unexp = ms->unexn = ms->recheck = 0;
    if (next != ms->set) {
        ms->set = next;
        bgc_radau_configure(&ms->u, ms->method, ms->r->s, ms->set);
        ms->since = 1;
        ms->change = 1;
        ms->hfact = 0.0;
        bgc_radau_scale(ms, y);
    }
}

/* gamma/h I - J and (alpha_k + i beta_k)/h I - J, factored; nonzero if one is singular. */
static int bgc_radau_factor(bgc_radau_state *ms, bgc_run *r, const double *alphn,
                            const double *betan, double fac1)
{
    enum { N = BGC_NUM_STATES, D = BGC_DIM(BGC_NUM_STATES) };
    int k, l, singular;
    if (bgc_jac_lu->n) {
        r->st->lu++;
        singular = bgc_smat_factor(&ms->sm[0], ms->J, fac1, ms->E1);
        for (k = 0; k < ms->u.pairs && !singular; k++) {
            const bgc_cplx diag = bgc_cmake(alphn[k] + betan[k] * 0.0, betan[k]);
            r->st->lu++;
            singular = bgc_smat_zfactor(&ms->sm[1 + k], ms->J, diag, ms->Ec);
        }
        return singular;
    }
    for (l = 0; l < N * N; l++)
        ms->E1[l] = -ms->J[l];
    for (l = 0; l < N; l++)
        ms->E1[(size_t)l * N + l] += fac1;
    r->st->lu++;
    singular = bgc_stiff_lu(N, ms->E1, ms->piv);
    for (k = 0; k < ms->u.pairs && !singular; k++) {
        bgc_cplx *E = ms->Ec + (size_t)k * D * D;
        for (l = 0; l < N * N; l++)
            E[l] = -ms->J[l];
        for (l = 0; l < N; l++)
            E[(size_t)l * N + l] += bgc_cmake(alphn[k] + betan[k] * 0.0, betan[k]);
        r->st->lu++;
        singular = bgc_stiff_zlu(N, E, ms->piv + (size_t)(1 + k) * D);
    }
    return singular;
}

/* The simplified Newton iteration for the stage increments Z (W = T^-1 Z), from the last
   step's collocation polynomial: 0 converged, 1 a stage failed (block or non-finite: *bad,
   *bad_kind), 2 no convergence, 3 too slow (ms->hhfac: the step that would converge). */
static int bgc_radau_newton(bgc_radau_state *ms, bgc_run *r, double t, double h, double tph,
                            const double *y, const double *alphn, const double *betan,
                            double fac1, int *bad, int *bad_kind)
{
    enum { N = BGC_NUM_STATES, D = BGC_DIM(BGC_NUM_STATES), SMAX = BGC_RADAU_MAX_STAGES };
    const bgc_radau_use *u = &ms->u;
    const bgc_radau *m = u->m;
    double *Z = ms->Z, *W = ms->W;
    double dyno = 0.0;
    int i, k, l;
    if (ms->first || ms->change) {
        for (l = 0; l < u->ns * D; l++)
            Z[l] = W[l] = 0.0;
    } else {
        const double q = h / ms->hold;
        for (l = 0; l < N; l++) {
            for (i = 0; i < u->ns; i++)
                Z[(size_t)i * D + l] = bgc_radau_u(m, ms->b, l, 1.0 + m->c[i] * q) - ms->zlast[l];
            bgc_radau_mul(m->Ti, u->ns, Z + l, D, W + l, D);
        }
    }
    ms->newt = 0;
    ms->faccon = pow(bgc_max(ms->faccon, DBL_EPSILON), 0.8);
    ms->theta = BGC_RADAU_THET;
    for (;;) {
        double sum = 0.0;
        if (ms->newt >= u->nit)
            return 2;
        /* Z_i <- f(t + c_i h, y + Z_i) */
        for (i = 0; i < u->ns; i++) {
            double *zi = Z + (size_t)i * D;
            const double ti = i == u->ns - 1 ? tph : t + m->c[i] * h;
            for (l = 0; l < N; l++)
                ms->ys[l] = y[l] + zi[l];
            r->st->rhs++;
            if (bgc_model_rhs(ti, ms->ys, r->p, r->w, zi)) {
                *bad = BGC_BAD_BLOCK;
                return 1;
            }
            if ((l = bgc_first_nonfinite(zi, N)) >= 0) {
                *bad = l;
                *bad_kind = 2;
                return 1;
            }
        }
        for (l = 0; l < N; l++) {
            double g[SMAX];
            bgc_radau_mul(m->Ti, u->ns, Z + l, D, g, 1);
            ms->dw[l] = g[0] - fac1 * W[l];
            for (k = 0; k < u->pairs; k++) {
                const double w2 = W[(size_t)(2 * k + 1) * D + l];
                const double w3 = W[(size_t)(2 * k + 2) * D + l];
                const double re = g[2 * k + 1] - (alphn[k] * w2 - betan[k] * w3);
                const double im = g[2 * k + 2] - (betan[k] * w2 + alphn[k] * w3);
                ms->zc[(size_t)k * D + l] = bgc_cmake(re + im * 0.0, im); /* re + im I */
            }
        }
        if (bgc_jac_lu->n) {
            bgc_smat_solve(&ms->sm[0], ms->dw, ms->E1);
            for (k = 0; k < u->pairs; k++)
                bgc_smat_zsolve(&ms->sm[1 + k], ms->zc + (size_t)k * D, ms->Ec);
        } else {
            bgc_stiff_lu_solve(N, ms->E1, ms->piv, ms->dw);
            for (k = 0; k < u->pairs; k++)
                bgc_stiff_zlu_solve(N, ms->Ec + (size_t)k * D * D,
                                    ms->piv + (size_t)(1 + k) * D, ms->zc + (size_t)k * D);
        }
        r->st->solves += 1 + u->pairs;
        ms->newt++;
        for (l = 0; l < N; l++) {
            const double q1 = ms->dw[l] / ms->scal[l];
            double part = q1 * q1;
            for (k = 0; k < u->pairs; k++) {
                const double qr = creal(ms->zc[(size_t)k * D + l]) / ms->scal[l];
                const double qi = cimag(ms->zc[(size_t)k * D + l]) / ms->scal[l];
                part += qr * qr;
                part += qi * qi;
            }
            sum += part;
        }
        dyno = N > 0 ? sqrt(sum / (double)(u->ns * N)) : 0.0;
        if (dyno != dyno || dyno > DBL_MAX)
            return 2;
        if (ms->newt > 1 && ms->newt < u->nit) {
            const double thq = dyno / ms->dynold;
            ms->theta = ms->newt == 2 ? thq : sqrt(thq * ms->thqold);
            ms->thqold = thq;
            if (ms->theta < 0.99) {
                const double dyth = ms->theta / (1.0 - ms->theta) * dyno
                                    * pow(ms->theta, (double)(u->nit - 1 - ms->newt)) / u->fnewt;
                ms->faccon = ms->theta / (1.0 - ms->theta);
                if (dyth >= 1.0 && !ms->fixed) { /* too slow: a smaller step converges sooner */
                    const double qnewt = bgc_max(1e-4, bgc_min(20.0, dyth));
                    ms->hhfac = 0.8 * pow(qnewt, -1.0 / (4.0 + (double)(u->nit - 1 - ms->newt)));
                    return 3;
                }
            } else {
                return 2;
            }
        }
        ms->dynold = bgc_max(dyno, DBL_EPSILON);
        for (l = 0; l < N; l++) {
            double a[SMAX];
            a[0] = W[l] + ms->dw[l];
            for (k = 0; k < u->pairs; k++) {
                a[2 * k + 1] = W[(size_t)(2 * k + 1) * D + l] + creal(ms->zc[(size_t)k * D + l]);
                a[2 * k + 2] = W[(size_t)(2 * k + 2) * D + l] + cimag(ms->zc[(size_t)k * D + l]);
            }
            for (i = 0; i < u->ns; i++)
                W[(size_t)i * D + l] = a[i];
            bgc_radau_mul(m->T, u->ns, a, 1, Z + l, D);
        }
        /* converged, the contraction measured in this step (never after one iteration) */
        if (ms->newt > 1 && ms->faccon * dyno <= u->fnewt)
            return 0;
    }
}

/* b <- (gamma/h I - J)^-1 b with the real matrix's factors. */
static void bgc_radau_lsolve(const bgc_radau_state *ms, double *b)
{
    if (bgc_jac_lu->n)
        bgc_smat_solve(&ms->sm[0], b, ms->E1);
    else
        bgc_stiff_lu_solve(BGC_NUM_STATES, ms->E1, ms->piv, b);
}

/* The error estimate: (gamma/h I - J) err = f(t, y) + sum_j e_j Z_j / h, refined once with
   f(t, y + err) on the first step and after a rejection. */
static double bgc_radau_error(bgc_radau_state *ms, bgc_run *r, double t, double h,
                              const double *y)
{
    enum { N = BGC_NUM_STATES, D = BGC_DIM(BGC_NUM_STATES) };
    const bgc_radau_use *u = &ms->u;
    const bgc_radau *m = u->m;
    const double *zs = ms->Z + (size_t)(u->ns - 1) * D;
    double err;
    int j, l;
    for (l = 0; l < N; l++) {
        double acc = m->e[0] * ms->Z[l];
        for (j = 1; j < u->ns; j++)
            acc += m->e[j] * ms->Z[(size_t)j * D + l];
        ms->f2[l] = acc / h;
        ms->cont[l] = ms->f2[l] + ms->f0[l];
        ms->ew[l] = u->atol + u->rtol * bgc_max(fabs(y[l]), fabs(y[l] + zs[l]));
    }
    bgc_radau_lsolve(ms, ms->cont);
    r->st->solves++;
    err = bgc_max(bgc_stiff_norm(r->s, ms->cont, ms->ew, &ms->worst), 1e-10);
    if (err >= 1.0 && (ms->first || ms->reject)) { /* refined: f at y + err */
        for (l = 0; l < N; l++)
            ms->ys[l] = y[l] + ms->cont[l];
        r->st->rhs++;
        if (bgc_model_rhs(t, ms->ys, r->p, r->w, ms->tmp) == 0) {
            for (l = 0; l < N; l++)
                ms->cont[l] = ms->tmp[l] + ms->f2[l];
            bgc_radau_lsolve(ms, ms->cont);
            r->st->solves++;
            err = bgc_max(bgc_stiff_norm(r->s, ms->cont, ms->ew, &ms->worst), 1e-10);
        }
    }
    return err;
}

/* A failed attempt at an adaptive step: retried smaller, with a fresh Jacobian unless this
   one is. */
static void bgc_radau_retry(bgc_radau_state *ms, bgc_outcome *o, double hnew, int bad,
                            int bad_kind)
{
    bgc_stiff_retry(o, hnew, bad, bad_kind);
    ms->reject = 1;
    ms->needjac = !ms->caljac;
}

/* Newton's failure on a fixed step: once more with a fresh Jacobian, else the end. */
static void bgc_radau_fixed_failure(bgc_radau_state *ms, bgc_run *r, double t, double h,
                                    int failed, int bad, bgc_outcome *o)
{
    if (failed == 1) {
        bgc_stiff_end(o, bad == BGC_BAD_BLOCK ? bgc_fail_block(r->msg, r->msg_size, r->w)
                         : bgc_fail(r->msg, r->msg_size, t, "derivative of state",
                                    bgc_state_names[bad]));
    } else if (!ms->caljac) {
        ms->needjac = 1;
        o->kind = BGC_STEP_AGAIN;
    } else {
        snprintf(r->msg, r->msg_size, "at t = %.17g: %s: the Newton iteration does not "
                 "converge with the fixed step h = %.3g", t, ms->method->name, h);
        bgc_stiff_end(o, BGC_ERR_RUNTIME);
    }
}

/* Step control: Gustafsson's, the safety factor scaled by the Newton iterations. */
static void bgc_radau_control(bgc_radau_state *ms, double h, double err, const double *y,
                              double *y1, bgc_outcome *o)
{
    enum { N = BGC_NUM_STATES, D = BGC_DIM(BGC_NUM_STATES) };
    const bgc_method *method = ms->method;
    const bgc_radau_use *u = &ms->u;
    const double fac = bgc_min(method->safe, u->cfac / (double)(ms->newt + 2 * u->nit));
    double quot = bgc_max(1.0 / method->fac_max,
                          bgc_min(1.0 / method->fac_min, pow(err, u->expo) / fac));
    const double *zs = ms->Z + (size_t)(u->ns - 1) * D;
    int l;
    o->hnew = h / quot;
    if (!(err < 1.0)) {
        o->kind = BGC_STEP_REJECT;
        o->hnew = ms->first ? 0.1 * h : o->hnew;
        ms->reject = 1;
        ms->needjac = !ms->caljac;
        return;
    }
    ms->first = 0;
    ms->accepted++;
    if (ms->accepted > 1 && !ms->change) {
        double facgus = (ms->hacc / h) * pow(err * err / ms->erracc, u->expo) / fac;
        facgus = bgc_max(1.0 / method->fac_max, bgc_min(1.0 / method->fac_min, facgus));
        quot = bgc_max(quot, facgus);
        o->hnew = h / quot;
    }
    ms->change = 0;
    ms->hacc = h;
    ms->erracc = bgc_max(1e-2, err);
    for (l = 0; l < N; l++)
        y1[l] = y[l] + zs[l];
    bgc_radau_poly(u->m, ms->Z, ms->b);
    ms->dm = u->m;
    ms->y = y;
    memcpy(ms->zlast, zs, sizeof(double) * N);
    ms->hold = h;
    ms->reject = 0;
    ms->nsing = 0;
    ms->caljac = 0;
    o->kind = BGC_STEP_ACCEPT;
}

/* One attempt (contract item 3): J if it is due (item 9), the order, the factorisations when
   h or J changed, Newton's iteration, the error estimate and the step control. */
static void bgc_radau_step(void *state, bgc_run *r, double t, double h, double tph,
                           const double *y, double *y1, bgc_outcome *o)
{
    enum { SMAX = BGC_RADAU_MAX_STAGES };
    bgc_radau_state *ms = state;
    double err = 0.0, fac1, alphn[SMAX], betan[SMAX];
    int k, failed, bad = BGC_BAD_NONE, bad_kind = 0;
    if (ms->needjac) {
        r->st->jac++;
        if (bgc_jac_lu->n ? bgc_jacobian_values(t, y, r->p, r->w, ms->J)
                          : bgc_jacobian(t, y, r->p, r->w, ms->J)) {
            bgc_stiff_end(o, bgc_fail_block(r->msg, r->msg_size, r->w));
            return;
        }
        ms->needjac = 0;
        ms->caljac = 1;
        ms->hfact = 0.0;
    }
    if (ms->variable && (h != ms->hfact || ms->recheck))
        bgc_radau_order(ms, h, y);
    fac1 = ms->u.m->gamma / h;
    for (k = 0; k < ms->u.pairs; k++) {
        alphn[k] = ms->u.m->alpha[k] / h;
        betan[k] = ms->u.m->beta[k] / h;
    }
    if (h != ms->hfact) {
        if (bgc_radau_factor(ms, r, alphn, betan, fac1)) {
            ms->hfact = 0.0;
            if (ms->fixed || ++ms->nsing == 5) {
                bgc_stiff_end(o, bgc_stiff_fail_singular(r, t, h));
                return;
            }
            ms->unexp = 1;
            bgc_radau_retry(ms, o, h * 0.5, BGC_BAD_SINGULAR, 0);
            return;
        }
        ms->hfact = h;
    }
    failed = bgc_radau_newton(ms, r, t, h, tph, y, alphn, betan, fac1, &bad, &bad_kind);
    o->worst = ms->worst;
    if (failed && ms->fixed) {
        bgc_radau_fixed_failure(ms, r, t, h, failed, bad, o);
        return;
    }
    if (failed) {
        if (failed == 3)
            ms->unexn = ms->hhfac <= 0.5;
        else
            ms->unexp = 1;
        bgc_radau_retry(ms, o, h * (failed == 3 ? ms->hhfac : 0.5),
                        failed != 1 ? BGC_BAD_NEWTON : bad, bad_kind);
        return;
    }
    if (!ms->fixed) {
        err = bgc_radau_error(ms, r, t, h, y);
        o->worst = ms->worst;
        if (err != err || err > DBL_MAX) {
            ms->unexp = 1;
            bgc_radau_retry(ms, o, h * 0.5, BGC_BAD_NONE, 0);
            return;
        }
    }
    bgc_radau_control(ms, h, err, y, y1, o);
}

/* The dense output (contract item 6): y0 plus the collocation polynomial. */
static void bgc_radau_dense(const void *state, double theta, double *yout)
{
    const bgc_radau_state *ms = state;
    int l;
    for (l = 0; l < BGC_NUM_STATES; l++)
        yout[l] = ms->y[l] + bgc_radau_u(ms->dm, ms->b, l, theta);
}

/* The new point: its weights and f (after the run's last step, the order to go on with;
   contract items 7 and 10). */
static int bgc_radau_after(void *state, bgc_run *r, double tph, const double *y1, int last)
{
    bgc_radau_state *ms = state;
    if (last) {
        if (!ms->fixed)
            r->st->order_next = 2 * ms->u.ns - 1;
        return 0;
    }
    bgc_radau_scale(ms, y1);
    r->st->rhs++;
    if (bgc_model_rhs(tph, y1, r->p, r->w, ms->f0))
        return bgc_fail_block(r->msg, r->msg_size, r->w);
    return 0;
}

/* h is kept (and the factorisations with it) while the controller asks for at most 20 %
   more and Newton converged fast; J is recomputed when it converged slowly (contract items 8
   and 9). */
static void bgc_radau_next_h(void *state, double h, double *hnew)
{
    bgc_radau_state *ms = state;
    if (ms->theta <= BGC_RADAU_THET && *hnew / h >= 1.0 && *hnew / h <= 1.2) {
        *hnew = h;
        if (ms->variable && ++ms->since >= 10 && ms->set + 1 < ms->method->radau_sets)
            ms->recheck = 1; /* ... but look at the order now and then */
    }
    ms->needjac = ms->theta > BGC_RADAU_THET;
}

static const bgc_family bgc_family_radau = {
    bgc_radau_start, bgc_radau_step, NULL, NULL, bgc_radau_dense, bgc_radau_after,
    bgc_radau_next_h, bgc_radau_finish, 1};

#ifndef BGC_NO_MAIN
#include <errno.h>
#if defined(__linux__)
#include <sys/prctl.h> /* PR_SET_PDEATHSIG: bgc_die_with_parent */
#include <unistd.h>    /* getppid */
#endif
/* ================================================================ CSV === */

/* Numbers are written exactly as printf("%.17g") writes them (NaN as "nan"), in integer
   arithmetic: |v| = M 2^q (M < 2^53) times 10^m, a 128-bit mantissa from bgc_pow10 rounded
   down, is one 192-bit product whose integer part is v's 17 significant digits and whose
   next 64 bits, the fraction, are off by less than 1/8 of their last place.  That decides
   the rounding to nearest unless the fraction lies within that error of one half (exact
   ties, about one value in 2^63 otherwise): snprintf writes those, and subnormals,
   infinities and |v| outside 1e-40..1e40 (the range of the table).  Compile with
   -DBGC_PLAIN_PRINTF to always use snprintf. */
#define BGC_FMT_SIZE 32 /* bgc_fmt17 writes at most 26 bytes (it stores whole words) */
static unsigned long bgc_fmt_slow_count; /* snprintf fallbacks, for tests */

static int bgc_fmt_printf(char *buf, double v)
{
    bgc_fmt_slow_count++;
    if (v != v) {
        memcpy(buf, "nan", 4);
        return 3;
    }
    return snprintf(buf, BGC_FMT_SIZE, "%.17g", v);
}

#if !defined(BGC_PLAIN_PRINTF) && FLT_RADIX == 2 && DBL_MANT_DIG == 53 && DBL_MAX_EXP == 1024 \
    && ULLONG_MAX == 0xffffffffffffffffULL
typedef unsigned long long bgc_u64;

#if defined(__SIZEOF_INT128__) && !defined(BGC_NO_INT128)
__extension__ typedef unsigned __int128 bgc_u128;
/* a * b = (returned) 2^64 + *lo. */
static inline bgc_u64 bgc_mul64(bgc_u64 a, bgc_u64 b, bgc_u64 *lo)
{
    const bgc_u128 prod = (bgc_u128)a * b;
    *lo = (bgc_u64)prod;
    return (bgc_u64)(prod >> 64);
}
#else
/* a * b = (returned) 2^64 + *lo, from 32-bit halves (C99 has no 128-bit integer). */
static inline bgc_u64 bgc_mul64(bgc_u64 a, bgc_u64 b, bgc_u64 *lo)
{
    const bgc_u64 mask = 0xffffffffULL, a0 = a & mask, a1 = a >> 32, b0 = b & mask, b1 = b >> 32;
    const bgc_u64 p00 = a0 * b0, p01 = a0 * b1, p10 = a1 * b0;
    const bgc_u64 mid = (p00 >> 32) + (p01 & mask) + (p10 & mask);
    *lo = (mid << 32) | (p00 & mask);
    return a1 * b1 + (p01 >> 32) + (p10 >> 32) + (mid >> 32);
}
#endif

/* 10^m = (hi 2^64 + lo) 2^e2 rounded down, 2^127 <= hi 2^64 + lo < 2^128, for m in
   BGC_POW10_MIN..BGC_POW10_MAX. */
#define BGC_POW10_MIN (-24)
#define BGC_POW10_MAX 56
static const struct bgc_pow10_entry {
    bgc_u64 hi, lo;
    int e2;
} bgc_pow10[] = {
    { 0x9abe14cd44753b52ULL, 0xc4926a9672793542ULL, -207 }, /* 1e-24 */
    { 0xc16d9a0095928a27ULL, 0x75b7053c0f178293ULL, -204 }, /* 1e-23 */
    { 0xf1c90080baf72cb1ULL, 0x5324c68b12dd6338ULL, -201 }, /* 1e-22 */
    { 0x971da05074da7beeULL, 0xd3f6fc16ebca5e03ULL, -197 }, /* 1e-21 */
    { 0xbce5086492111aeaULL, 0x88f4bb1ca6bcf584ULL, -194 }, /* 1e-20 */
    { 0xec1e4a7db69561a5ULL, 0x2b31e9e3d06c32e5ULL, -191 }, /* 1e-19 */
    { 0x9392ee8e921d5d07ULL, 0x3aff322e62439fcfULL, -187 }, /* 1e-18 */
    { 0xb877aa3236a4b449ULL, 0x09befeb9fad487c2ULL, -184 }, /* 1e-17 */
    { 0xe69594bec44de15bULL, 0x4c2ebe687989a9b3ULL, -181 }, /* 1e-16 */
    { 0x901d7cf73ab0acd9ULL, 0x0f9d37014bf60a10ULL, -177 }, /* 1e-15 */
    { 0xb424dc35095cd80fULL, 0x538484c19ef38c94ULL, -174 }, /* 1e-14 */
    { 0xe12e13424bb40e13ULL, 0x2865a5f206b06fb9ULL, -171 }, /* 1e-13 */
    { 0x8cbccc096f5088cbULL, 0xf93f87b7442e45d3ULL, -167 }, /* 1e-12 */
    { 0xafebff0bcb24aafeULL, 0xf78f69a51539d748ULL, -164 }, /* 1e-11 */
    { 0xdbe6fecebdedd5beULL, 0xb573440e5a884d1bULL, -161 }, /* 1e-10 */
    { 0x89705f4136b4a597ULL, 0x31680a88f8953030ULL, -157 }, /* 1e-9 */
    { 0xabcc77118461cefcULL, 0xfdc20d2b36ba7c3dULL, -154 }, /* 1e-8 */
    { 0xd6bf94d5e57a42bcULL, 0x3d32907604691b4cULL, -151 }, /* 1e-7 */
    { 0x8637bd05af6c69b5ULL, 0xa63f9a49c2c1b10fULL, -147 }, /* 1e-6 */
    { 0xa7c5ac471b478423ULL, 0x0fcf80dc33721d53ULL, -144 }, /* 1e-5 */
    { 0xd1b71758e219652bULL, 0xd3c36113404ea4a8ULL, -141 }, /* 1e-4 */
    { 0x83126e978d4fdf3bULL, 0x645a1cac083126e9ULL, -137 }, /* 1e-3 */
    { 0xa3d70a3d70a3d70aULL, 0x3d70a3d70a3d70a3ULL, -134 }, /* 1e-2 */
    { 0xccccccccccccccccULL, 0xccccccccccccccccULL, -131 }, /* 1e-1 */
    { 0x8000000000000000ULL, 0x0000000000000000ULL, -127 }, /* 1e0 */
    { 0xa000000000000000ULL, 0x0000000000000000ULL, -124 }, /* 1e1 */
    { 0xc800000000000000ULL, 0x0000000000000000ULL, -121 }, /* 1e2 */
    { 0xfa00000000000000ULL, 0x0000000000000000ULL, -118 }, /* 1e3 */
    { 0x9c40000000000000ULL, 0x0000000000000000ULL, -114 }, /* 1e4 */
    { 0xc350000000000000ULL, 0x0000000000000000ULL, -111 }, /* 1e5 */
    { 0xf424000000000000ULL, 0x0000000000000000ULL, -108 }, /* 1e6 */
    { 0x9896800000000000ULL, 0x0000000000000000ULL, -104 }, /* 1e7 */
    { 0xbebc200000000000ULL, 0x0000000000000000ULL, -101 }, /* 1e8 */
    { 0xee6b280000000000ULL, 0x0000000000000000ULL, -98 }, /* 1e9 */
    { 0x9502f90000000000ULL, 0x0000000000000000ULL, -94 }, /* 1e10 */
    { 0xba43b74000000000ULL, 0x0000000000000000ULL, -91 }, /* 1e11 */
    { 0xe8d4a51000000000ULL, 0x0000000000000000ULL, -88 }, /* 1e12 */
    { 0x9184e72a00000000ULL, 0x0000000000000000ULL, -84 }, /* 1e13 */
    { 0xb5e620f480000000ULL, 0x0000000000000000ULL, -81 }, /* 1e14 */
    { 0xe35fa931a0000000ULL, 0x0000000000000000ULL, -78 }, /* 1e15 */
    { 0x8e1bc9bf04000000ULL, 0x0000000000000000ULL, -74 }, /* 1e16 */
    { 0xb1a2bc2ec5000000ULL, 0x0000000000000000ULL, -71 }, /* 1e17 */
    { 0xde0b6b3a76400000ULL, 0x0000000000000000ULL, -68 }, /* 1e18 */
    { 0x8ac7230489e80000ULL, 0x0000000000000000ULL, -64 }, /* 1e19 */
    { 0xad78ebc5ac620000ULL, 0x0000000000000000ULL, -61 }, /* 1e20 */
    { 0xd8d726b7177a8000ULL, 0x0000000000000000ULL, -58 }, /* 1e21 */
    { 0x878678326eac9000ULL, 0x0000000000000000ULL, -54 }, /* 1e22 */
    { 0xa968163f0a57b400ULL, 0x0000000000000000ULL, -51 }, /* 1e23 */
    { 0xd3c21bcecceda100ULL, 0x0000000000000000ULL, -48 }, /* 1e24 */
    { 0x84595161401484a0ULL, 0x0000000000000000ULL, -44 }, /* 1e25 */
    { 0xa56fa5b99019a5c8ULL, 0x0000000000000000ULL, -41 }, /* 1e26 */
    { 0xcecb8f27f4200f3aULL, 0x0000000000000000ULL, -38 }, /* 1e27 */
    { 0x813f3978f8940984ULL, 0x4000000000000000ULL, -34 }, /* 1e28 */
    { 0xa18f07d736b90be5ULL, 0x5000000000000000ULL, -31 }, /* 1e29 */
    { 0xc9f2c9cd04674edeULL, 0xa400000000000000ULL, -28 }, /* 1e30 */
    { 0xfc6f7c4045812296ULL, 0x4d00000000000000ULL, -25 }, /* 1e31 */
    { 0x9dc5ada82b70b59dULL, 0xf020000000000000ULL, -21 }, /* 1e32 */
    { 0xc5371912364ce305ULL, 0x6c28000000000000ULL, -18 }, /* 1e33 */
    { 0xf684df56c3e01bc6ULL, 0xc732000000000000ULL, -15 }, /* 1e34 */
    { 0x9a130b963a6c115cULL, 0x3c7f400000000000ULL, -11 }, /* 1e35 */
    { 0xc097ce7bc90715b3ULL, 0x4b9f100000000000ULL, -8 }, /* 1e36 */
    { 0xf0bdc21abb48db20ULL, 0x1e86d40000000000ULL, -5 }, /* 1e37 */
    { 0x96769950b50d88f4ULL, 0x1314448000000000ULL, -1 }, /* 1e38 */
    { 0xbc143fa4e250eb31ULL, 0x17d955a000000000ULL, 2 }, /* 1e39 */
    { 0xeb194f8e1ae525fdULL, 0x5dcfab0800000000ULL, 5 }, /* 1e40 */
    { 0x92efd1b8d0cf37beULL, 0x5aa1cae500000000ULL, 9 }, /* 1e41 */
    { 0xb7abc627050305adULL, 0xf14a3d9e40000000ULL, 12 }, /* 1e42 */
    { 0xe596b7b0c643c719ULL, 0x6d9ccd05d0000000ULL, 15 }, /* 1e43 */
    { 0x8f7e32ce7bea5c6fULL, 0xe4820023a2000000ULL, 19 }, /* 1e44 */
    { 0xb35dbf821ae4f38bULL, 0xdda2802c8a800000ULL, 22 }, /* 1e45 */
    { 0xe0352f62a19e306eULL, 0xd50b2037ad200000ULL, 25 }, /* 1e46 */
    { 0x8c213d9da502de45ULL, 0x4526f422cc340000ULL, 29 }, /* 1e47 */
    { 0xaf298d050e4395d6ULL, 0x9670b12b7f410000ULL, 32 }, /* 1e48 */
    { 0xdaf3f04651d47b4cULL, 0x3c0cdd765f114000ULL, 35 }, /* 1e49 */
    { 0x88d8762bf324cd0fULL, 0xa5880a69fb6ac800ULL, 39 }, /* 1e50 */
    { 0xab0e93b6efee0053ULL, 0x8eea0d047a457a00ULL, 42 }, /* 1e51 */
    { 0xd5d238a4abe98068ULL, 0x72a4904598d6d880ULL, 45 }, /* 1e52 */
    { 0x85a36366eb71f041ULL, 0x47a6da2b7f864750ULL, 49 }, /* 1e53 */
    { 0xa70c3c40a64e6c51ULL, 0x999090b65f67d924ULL, 52 }, /* 1e54 */
    { 0xd0cf4b50cfe20765ULL, 0xfff4b4e3f741cf6dULL, 55 }, /* 1e55 */
    { 0x82818f1281ed449fULL, 0xbff8f10e7a8921a4ULL, 59 }, /* 1e56 */
};

/* floor(log10(2^e)) for |e| <= 1650 (the constant is Ryu's). */
static int bgc_floor_log10_pow2(int e)
{
    return e >= 0 ? (int)(((unsigned long)e * 78913UL) >> 18)
                  : -(int)((((unsigned long)-e * 78913UL) >> 18) + 1);
}

/* floor(mant 2^q 10^m) and (in *frac) the next 64 bits, for mant < 2^53 and a result in
   [2^53, 2^60); the fraction is short by less than 1/8 of its last place. */
static inline bgc_u64 bgc_scaled(bgc_u64 mant, int q, int m, bgc_u64 *frac)
{
    const struct bgc_pow10_entry *p = &bgc_pow10[m - BGC_POW10_MIN];
    bgc_u64 w0, w1, w2, mid_lo;
    const bgc_u64 mid = bgc_mul64(mant, p->lo, &w0);
    int shift;
    w2 = bgc_mul64(mant, p->hi, &mid_lo);
    w1 = mid + mid_lo;
    w2 += w1 < mid; /* the product is w2 2^128 + w1 2^64 + w0 */
    shift = -(q + p->e2) - 64; /* 56..63: the binary point lies that far into w1 */
    *frac = (w1 << (64 - shift)) | (w0 >> shift);
    return (w2 << (64 - shift)) | (w1 >> shift);
}

/* The 8 digits of v < 10^8, all at once, as the word whose byte i (bits 8i..8i+7) is the
   character of digit i: v splits into two 4-digit lanes, each into two 2-digit lanes, each
   of those into two digits (the multiply-shifts divide exactly in these ranges). */
static inline bgc_u64 bgc_digits8(bgc_u64 v)
{
    const bgc_u64 high4 = (v * 109951163U) >> 40; /* v / 10000 */
    const bgc_u64 quads = high4 | (v - 10000U * high4) << 32;
    const bgc_u64 top2 = ((quads * 10486U) >> 20) & 0x0000007f0000007fULL; /* quads / 100 */
    const bgc_u64 pairs = (quads - 100U * top2) << 16 | top2;
    const bgc_u64 top1 = ((pairs * 103U) >> 10) & 0x000f000f000f000fULL; /* pairs / 10 */
    return ((pairs - 10U * top1) << 8 | top1) | 0x3030303030303030ULL;
}

/* Byte i of w into o[i], i < 8: one store where the bytes of a word are in that order
   (the test is a constant that compilers fold). */
static inline void bgc_store8(char *o, bgc_u64 w)
{
    const bgc_u64 one = 1;
    char first;
    int i;
    memcpy(&first, &one, 1);
    if (first == 1) {
        memcpy(o, &w, 8);
        return;
    }
    for (i = 0; i < 8; i++)
        o[i] = (char)(w >> (8 * i));
}

/* The %g layout of the 17 digits of d (10^16 <= d < 10^17) with decimal exponent x: fixed
   for -4 <= x < 17, else e-style.  The digits stay in registers (never stored and read
   back); whole words are stored, so it writes up to o[24]. */
static inline char *bgc_layout(char *o, bgc_u64 d, int x)
{
    const bgc_u64 high9 = d / 100000000U, low8 = d - 100000000U * high9;
    const bgc_u64 lead = high9 / 100000000U;
    const bgc_u64 w1 = bgc_digits8(high9 - 100000000U * lead), w2 = bgc_digits8(low8);
    int nd = 17, ax; /* significant digits without the trailing zeros */
    if ((w2 >> 56) == '0') /* the last digit */
        for (d /= 10U, nd--; d % 10U == 0; d /= 10U)
            nd--;
    o[0] = (char)('0' + lead);
    if (x >= 0 && x < 17) { /* digits 0..x, and '.' and digits x+1..nd-1 if nd > x + 1 */
        bgc_store8(o + 1, w1);
        bgc_store8(o + 9, w2);
        if (nd <= x + 1)
            return o + x + 1;
        if (x == 0) {
            bgc_store8(o + 2, w1);
            bgc_store8(o + 10, w2);
        } else if (x < 8) { /* digits x+1.. are w1:w2 shifted down by x bytes */
            bgc_store8(o + x + 2, w1 >> (8 * x) | w2 << (64 - 8 * x));
            bgc_store8(o + x + 10, w2 >> (8 * x));
        } else {
            bgc_store8(o + x + 2, w2 >> (8 * x - 64));
        }
        o[x + 1] = '.';
        return o + nd + 1;
    }
    if (x < 0 && x >= -4) { /* "0.", -x - 1 zeros, the digits */
        const char lead_char = o[0];
        memcpy(o, "0.000", 5);
        o += 1 - x;
        o[0] = lead_char;
        bgc_store8(o + 1, w1);
        bgc_store8(o + 9, w2);
        return o + nd;
    }
    o[1] = '.';
    bgc_store8(o + 2, w1);
    bgc_store8(o + 10, w2);
    o += nd > 1 ? nd + 1 : 1;
    ax = x < 0 ? -x : x;
    *o++ = 'e';
    *o++ = x < 0 ? '-' : '+';
    if (ax >= 100) {
        *o++ = (char)('0' + ax / 100);
        ax %= 100;
    }
    o[0] = (char)('0' + ax / 10);
    o[1] = (char)('0' + ax % 10);
    return o + 2;
}

/* Writes v into buf (>= BGC_FMT_SIZE bytes) as printf("%.17g", v); returns the length. */
static int bgc_fmt17(char *buf, double v)
{
    const bgc_u64 half = 1ULL << 63, ten17 = 100000000000000000ULL;
    bgc_u64 bits, mant, d, frac;
    char *o = buf;
    int e2, x, m;
    memcpy(&bits, &v, sizeof bits);
    e2 = (int)((bits >> 52) & 0x7ff); /* biased binary exponent */
    if (e2 == 0 || e2 == 0x7ff) {
        if (v != 0.0)
            return bgc_fmt_printf(buf, v); /* subnormal, inf or nan */
        if (signbit(v))
            *o++ = '-';
        *o++ = '0';
        *o = '\0';
        return (int)(o - buf);
    }
    mant = (bits & 0xfffffffffffffULL) | (1ULL << 52);
    x = bgc_floor_log10_pow2(e2 - 1023); /* floor(log10|v|) or one less */
    m = 16 - x;
    if (m - 1 < BGC_POW10_MIN || m > BGC_POW10_MAX)
        return bgc_fmt_printf(buf, v);
    d = bgc_scaled(mant, e2 - 1075, m, &frac);
    if (d >= ten17) {
        x++;
        d = bgc_scaled(mant, e2 - 1075, --m, &frac);
    }
    if (frac - (half - 1) <= 1)
        return bgc_fmt_printf(buf, v); /* too close to a tie to decide */
    d += frac >> 63; /* rounded to nearest */
    if (d == ten17) {
        d /= 10;
        x++;
    }
    *o = '-';
    o = bgc_layout(o + (bits >> 63), d, x);
    *o = '\0';
    return (int)(o - buf);
}
#else
static int bgc_fmt17(char *buf, double v)
{
    return bgc_fmt_printf(buf, v);
}
#endif

typedef struct bgc_writer {
    FILE *file;
    size_t len;
    int failed; /* a write failed: the errno it gave (-1 if none was set) */
    char buf[1 << 16];
} bgc_writer;

static bgc_writer bgc_out;

static void bgc_flush(bgc_writer *w)
{
    errno = 0;
    if (w->len && fwrite(w->buf, 1, w->len, w->file) != w->len && !w->failed)
        w->failed = errno ? errno : -1;
    w->len = 0;
}

static void bgc_put_number(bgc_writer *w, double v)
{
    if (sizeof w->buf - w->len < BGC_FMT_SIZE + 2)
        bgc_flush(w);
    w->len += (size_t)bgc_fmt17(w->buf + w->len, v);
}

/* --progress: a line "bgc-progress T T0 T_END" on stderr at the first row, then as the rows
   pass at most ten a second of processor time (bgc simulate draws them as a bar); off by
   default.  The clock is read once per thousandth of the time span at most. */
static struct bgc_progress {
    int on, lines;
    double t0, t_end, next;
    clock_t last;
} bgc_progress;

static void bgc_progress_row(double t)
{
    clock_t now;
    if (t < bgc_progress.next)
        return;
    bgc_progress.next = t + (bgc_progress.t_end - bgc_progress.t0) / 1000.0;
    now = clock();
    if (bgc_progress.lines && (double)(now - bgc_progress.last) < 0.1 * CLOCKS_PER_SEC)
        return;
    bgc_progress.lines++;
    bgc_progress.last = now;
    fprintf(stderr, "bgc-progress %.17g %.17g %.17g\n", t, bgc_progress.t0, bgc_progress.t_end);
}

static int bgc_csv_row(void *ctx, double t, const double *x, const double *y)
{
    bgc_writer *w = (bgc_writer *)ctx;
    int j;
    (void)x;
    if (bgc_progress.on)
        bgc_progress_row(t);
    bgc_put_number(w, t);
    for (j = 0; j < BGC_NUM_OUTPUTS; j++) {
        w->buf[w->len++] = ',';
        bgc_put_number(w, y[j]);
    }
    w->buf[w->len++] = '\n';
    return w->failed ? BGC_ERR_RUNTIME : 0;
}

static void bgc_csv_header(FILE *f)
{
    int j;
    fputs("t", f);
    for (j = 0; j < BGC_NUM_OUTPUTS; j++) {
        fputc(',', f);
        fputs(bgc_output_names[j], f);
    }
    fputc('\n', f);
}

/* ======================================================== command line === */

/* The event log (--events FILE): a header t,event,change, then a row per change at an event
   (a field with a comma, a quote or a line break quoted as CSV quotes it). */
static struct {
    const char *path;
    FILE *file;
    int failed;
} bgc_event_log = { NULL, NULL, 0 };

static void bgc_csv_field(FILE *f, const char *text)
{
    const char *c;
    if (strpbrk(text, ",\"\r\n") == NULL) {
        fputs(text, f);
        return;
    }
    fputc('"', f);
    for (c = text; *c; c++) {
        if (*c == '"')
            fputc('"', f);
        fputc(*c, f);
    }
    fputc('"', f);
}

static int bgc_log_event(void *ctx, double t, const char *what, const char *change)
{
    FILE *f = (FILE *)ctx;
    fprintf(f, "%.17g,", t);
    bgc_csv_field(f, what);
    fputc(',', f);
    bgc_csv_field(f, change);
    if (fputc('\n', f) == EOF) {
        bgc_event_log.failed = errno ? errno : -1;
        return BGC_ERR_RUNTIME;
    }
    return 0;
}



/* The inputs' data (--input FILE): a CSV file with a header row, a column t (non-decreasing:
   a repeated t is a jump, never three in a row) and a column per input given (named as
   bgc_input_name gives), a number in every field. */
static struct {
    const char *path;
    bgc_input_series *series; /* one per input */
    double *values; /* the file's numbers, column by column */
} bgc_input_file = { NULL, NULL, NULL };

/* The next comma-separated field of *line, its spaces trimmed ('\0'-terminated in place). */
static char *bgc_next_field(char **line)
{
    char *start = *line, *end, *comma = strchr(start, ',');
    if (comma) {
        *comma = '\0';
        *line = comma + 1;
    } else {
        *line = NULL;
    }
    while (*start == ' ' || *start == '\t')
        start++;
    end = start + strlen(start);
    while (end > start && (end[-1] == ' ' || end[-1] == '\t' || end[-1] == '\r'))
        *--end = '\0';
    return start;
}

/* The whole of the open file f as one '\0'-terminated string (its length in *size); NULL
   (message written) when out of memory.  Closes f. */
static char *bgc_read_text(const char *path, FILE *f, size_t *size)
{
    char *text = NULL;
    size_t cap = 0, got;
    *size = 0;
    do {
        if (*size + 4096 + 1 > cap) {
            char *more = (char *)realloc(text, cap = 2 * cap + 4096 + 1);
            if (!more) {
                free(text);
                fclose(f);
                fprintf(stderr, "error: out of memory reading '%s'\n", path);
                return NULL;
            }
            text = more;
        }
        got = fread(text + *size, 1, 4096, f);
        *size += got;
    } while (got > 0);
    fclose(f);
    text[*size] = '\0';
    return text;
}

/* The header line of --input's file: column[k] the input that column k gives (-2: none, the
   column t), *tcol the column t.  The number of columns, or -1 (message written). */
static int bgc_input_header(const char *path, char *line, int *column, int *tcol)
{
    int ncol = 0, k, j;
    *tcol = -1;
    while (line && ncol < 256) {
        const char *field = bgc_next_field(&line);
        column[ncol] = -2;
        if (strcmp(field, "t") == 0) {
            if (*tcol >= 0)
                goto twice;
            *tcol = ncol;
        } else {
            for (j = 0; j < BGC_NUM_INPUTS; j++)
                if (strcmp(field, bgc_input_name(j)) == 0)
                    break;
            if (j == BGC_NUM_INPUTS) {
                fprintf(stderr, "error: %s: '%s' is not an input of the model (its inputs:", path,
                        field);
                for (j = 0; j < BGC_NUM_INPUTS; j++)
                    fprintf(stderr, "%s %s", j ? "," : "", bgc_input_name(j));
                fprintf(stderr, "%s)\n", BGC_NUM_INPUTS ? "" : " none");
                return -1;
            }
            for (k = 0; k < ncol; k++)
                if (column[k] == j)
                    goto twice;
            if (bgc_input_file.series[j].n > 0) {
                fprintf(stderr, "error: %s: input '%s' is given twice\n", path, field);
                return -1;
            }
            column[ncol] = j;
        }
        ncol++;
    }
    if (*tcol < 0) {
        fprintf(stderr, "error: %s: the header has no column 't'\n", path);
        return -1;
    }
    if (line) {
        fprintf(stderr, "error: %s: more than 256 columns\n", path);
        return -1;
    }
    return ncol;
twice:
    fprintf(stderr, "error: %s: a column is named twice in the header\n", path);
    return -1;
}

/* The rows of data after the header (body: its lines, each '\0'-terminated, up to end) into
   v, row by row, cols numbers each, t in column tcol; the number of rows, or -1 (message
   written). */
static int bgc_input_rows(const char *path, char *body, const char *end, int cols, int tcol,
                          double *v)
{
    char *line, *next;
    long line_no = 1;
    int rows = 0, k;
    for (line = body; line && line < end; line = next) {
        char *rest = line;
        next = line + strlen(line) + 1;
        line_no++;
        if (strspn(line, " \t\r") == strlen(line))
            continue;
        for (k = 0; k < cols; k++) {
            char *field, *stop;
            double x;
            if (!rest) {
                fprintf(stderr, "error: %s:%ld: this row has %d fields, the header %d\n", path,
                        line_no, k, cols);
                return -1;
            }
            field = bgc_next_field(&rest);
            x = strtod(field, &stop);
            if (stop == field || *stop != '\0' || !isfinite(x)) {
                fprintf(stderr, "error: %s:%ld: '%s' is not a finite number\n", path, line_no,
                        field);
                return -1;
            }
            v[(size_t)rows * (size_t)cols + (size_t)k] = x;
        }
        if (rest) {
            fprintf(stderr, "error: %s:%ld: this row has more fields than the header (%d)\n",
                    path, line_no, cols);
            return -1;
        }
        if (rows > 0 && v[(size_t)rows * cols + tcol] < v[(size_t)(rows - 1) * cols + tcol]) {
            fprintf(stderr, "error: %s:%ld: t decreases here (t does not decrease from row to "
                    "row; a repeated t is a jump)\n", path, line_no);
            return -1;
        }
        if (rows > 1 && v[(size_t)rows * cols + tcol] == v[(size_t)(rows - 1) * cols + tcol]
            && v[(size_t)rows * cols + tcol] == v[(size_t)(rows - 2) * cols + tcol]) {
            fprintf(stderr, "error: %s:%ld: the same t a third time here (a jump is two rows of "
                    "the same t)\n", path, line_no);
            return -1;
        }
        rows++;
    }
    if (rows == 0)
        fprintf(stderr, "error: %s: no rows of data\n", path);
    return rows > 0 ? rows : -1;
}

/* The inputs' series from the rows of data v (row-major, rows x cols): the values transposed
   into bgc_input_file.values, so that each column is an array; 0, or -1 (message written). */
static int bgc_input_columns(const char *path, const double *v, int rows, int cols,
                             const int *column, int tcol)
{
    double *cm = (double *)malloc(sizeof(double) * (size_t)rows * (size_t)cols);
    int r, k;
    if (!cm) {
        fprintf(stderr, "error: out of memory reading '%s'\n", path);
        return -1;
    }
    for (r = 0; r < rows; r++)
        for (k = 0; k < cols; k++)
            cm[(size_t)k * rows + r] = v[(size_t)r * cols + k];
    bgc_input_file.values = cm;
    for (k = 0; k < cols; k++)
        if (column[k] >= 0) {
            bgc_input_series *s = &bgc_input_file.series[column[k]];
            s->n = rows;
            s->t = cm + (size_t)tcol * rows;
            s->u = cm + (size_t)k * rows;
        }
    return 0;
}

/* Reads --input's file into bgc_input_file.series; 0, or BGC_ERR_USAGE with a message. */
static int bgc_read_inputs(void)
{
    const char *path = bgc_input_file.path;
    FILE *f = fopen(path, "rb");
    char *text, *line, *next, *body;
    size_t size;
    int column[256], tcol, rows = 0, cols, rc = BGC_ERR_USAGE;
    double *v;
    if (!f) {
        fprintf(stderr, "error: cannot read the input file '%s': %s\n", path, strerror(errno));
        return BGC_ERR_USAGE;
    }
    if (!bgc_input_file.series)
        bgc_input_file.series = (bgc_input_series *)calloc((size_t)BGC_DIM(BGC_NUM_INPUTS),
                                                           sizeof *bgc_input_file.series);
    if (!bgc_input_file.series) {
        fclose(f);
        fprintf(stderr, "error: out of memory reading '%s'\n", path);
        return BGC_ERR_USAGE;
    }
    text = bgc_read_text(path, f, &size);
    if (!text)
        return BGC_ERR_USAGE;
    body = strchr(text, '\n');
    if (body)
        *body++ = '\0';
    cols = bgc_input_header(path, text, column, &tcol);
    if (cols < 0) {
        free(text);
        return BGC_ERR_USAGE;
    }
    for (line = body; line; line = next) { /* the lines cut apart, the rows of data counted */
        next = strchr(line, '\n');
        if (next)
            *next++ = '\0';
        if (strspn(line, " \t\r") != strlen(line))
            rows++;
    }
    v = (double *)malloc(sizeof(double) * (size_t)BGC_DIM(rows * cols));
    if (!v) {
        free(text);
        fprintf(stderr, "error: out of memory reading '%s'\n", path);
        return BGC_ERR_USAGE;
    }
    rows = bgc_input_rows(path, body, text + size + 1, cols, tcol, v);
    free(text);
    if (rows > 0 && bgc_input_columns(path, v, rows, cols, column, tcol) == 0)
        rc = 0;
    free(v);
    return rc;
}

static const char bgc_usage[] =
    " [--t-end T] [--dt DT] [--solver NAME] [--rtol R] [--atol A]\n"
    "       [--step H] [--max-steps N] [-p NAME=VALUE ...] [--stats] [--progress]\n"
    "       [--project-initial | --allow-inconsistent]\n"
    "       [--max-step H] [--error-states N] [--event-rows] [--events FILE] [--input FILE]\n"
    "       [--batch FILE|- [--metric KIND:OUTPUT ...] [--trajectories DIR]]\n";

static void bgc_print_usage(FILE *f)
{
    fprintf(f, "usage: %s%s", bgc_ident, bgc_usage);
}

static void bgc_help(void)
{
    bgc_settings s;
    bgc_params p;
    int j;
    bgc_settings_default(&s);
    bgc_params_defaults(&p, NULL);
    bgc_print_usage(stdout);
    printf("Simulates the model and writes CSV (t and the outputs) to stdout.\n"
           "  --t-end T          end time (%.17g; the start time is %.17g)\n"
           "  --dt DT            output interval (%.17g)\n"
           "  --solver NAME      the solver (%s), one of those listed below\n"
           "  --rtol R           relative tolerance of the adaptive solvers (%.17g)\n"
           "  --atol A           absolute tolerance of the adaptive solvers (%.17g)\n"
           "  --step H           step of the fixed-step solvers (default: dt)\n"
           "  --max-steps N      the most steps between two output times (%ld; 0: no limit)\n"
           "  --max-step H       every solver's largest step (default: no bound)\n"
           "  --error-states N   the error control weighs the first N states only (0: all)\n"
           "  --event-rows       two rows at each event: its left and right limits\n"
           "  --events FILE      the event log: t,event,change, a row per change\n"
           "  --input FILE       the inputs' data: CSV, a column t and one per input\n"
           "  -p NAME=VALUE      set a parameter; derived parameters follow\n"
           "  --project-initial  project the initial state onto the constraints\n"
           "  --allow-inconsistent  start from an initial state that violates the constraints\n"
           "                     (the correctors pull it back): neither refused nor projected\n"
           "  --stats            print the solver's counters to stderr\n"
           "  --progress         report the progress on stderr: lines bgc-progress T T0 T_END\n"
           "  --batch FILE       one run per line of FILE (- for stdin): NAME=VALUE words;\n"
           "                     writes a CSV row per run: run,status,metrics,steps,rejected,\n"
           "                     rhs,cpu,message\n"
           "  --metric K:OUTPUT  with --batch: a column, K one of final, max, min, maxabs, rms\n"
           "  --trajectories DIR with --batch: each run's CSV also to DIR/run-NNNNNN.csv\n",
           s.t_end, s.t0, s.dt, bgc_solver_names[s.solver], s.rtol, s.atol, s.max_steps);
    printf("solvers:\n");
    for (j = 0; j < BGC_NUM_SOLVERS; j++)
        printf("  %-8s %s\n", bgc_methods[j].name, bgc_methods[j].summary);
    if (BGC_NUM_PARAMS > 0)
        printf("parameters (NAME = default):\n");
    for (j = 0; j < BGC_NUM_PARAMS; j++)
        printf("  %s = %.17g\n", bgc_param_names[j], *bgc_param_ref(&p, j));
}

/* A decimal number (digits, sign, '.', exponent: no hex, inf or nan), finite. */
static int bgc_parse_number(const char *option, const char *text, double *out)
{
    char *end;
    if (*text != '\0' && strspn(text, "0123456789+-.eE") == strlen(text)) {
        *out = strtod(text, &end);
        if (*end == '\0' && isfinite(*out))
            return 0;
    }
    fprintf(stderr, "error: invalid value for %s: '%s'\n", option, text);
    return -1;
}

static int bgc_parse_param(const char *text, bgc_params *p, int *given)
{
    const char *eq = strrchr(text, '=');
    char name[256];
    size_t len = eq ? (size_t)(eq - text) : 0;
    int j;
    double v;
    if (!eq || len == 0 || len >= sizeof name) {
        fprintf(stderr, "error: -p expects NAME=VALUE, got '%s'\n", text);
        return -1;
    }
    memcpy(name, text, len);
    name[len] = '\0';
    j = bgc_param_index(name);
    if (j < 0) {
        fprintf(stderr, "error: unknown parameter '%s'\n", name);
        return -1;
    }
    if (bgc_parse_number(name, eq + 1, &v))
        return -1;
    *bgc_param_ref(p, j) = v;
    given[j] = 1;
    return 0;
}

static int bgc_parse_solver(const char *text, int *solver)
{
    int k = bgc_solver_index(text);
    if (k >= 0) {
        *solver = k;
        return 0;
    }
    fprintf(stderr, "error: unknown solver '%s' (expected %s)\n", text, BGC_SOLVER_LIST);
    return -1;
}

/* Applies option `name` (one that takes a value) to the run. */
static int bgc_apply_option(const char *name, const char *value, bgc_settings *s, bgc_params *p,
                            int *given)
{
    if (strcmp(name, "-p") == 0)
        return bgc_parse_param(value, p, given);
    if (strcmp(name, "--solver") == 0)
        return bgc_parse_solver(value, &s->solver);
    if (strcmp(name, "--max-steps") == 0) {
        double n;
        if (bgc_parse_number(name, value, &n))
            return -1;
        if (n >= 0.0 && n <= 1e15 && n == floor(n)) {
            s->max_steps = (long)n;
            return 0;
        }
        fprintf(stderr, "error: --max-steps must be a whole number from 0 (no limit) to 1e15\n");
        return -1;
    }
    if (strcmp(name, "--error-states") == 0) {
        double n;
        if (bgc_parse_number(name, value, &n))
            return -1;
        if (n >= 0.0 && n <= BGC_NUM_STATES && n == floor(n)) {
            s->error_states = (long)n;
            return 0;
        }
        fprintf(stderr, "error: --error-states must be a whole number from 0 (all) to %d\n",
                BGC_NUM_STATES);
        return -1;
    }
    if (strcmp(name, "--max-step") == 0) {
        if (bgc_parse_number(name, value, &s->hmax))
            return -1;
        if (s->hmax > 0.0)
            return 0;
        fprintf(stderr, "error: --max-step must be positive\n");
        return -1;
    }
    if (strcmp(name, "--events") == 0) {
        bgc_event_log.path = value;
        return 0;
    }
    if (strcmp(name, "--input") == 0) {
        bgc_input_file.path = value;
        return bgc_read_inputs() ? -1 : 0;
    }
    if (strcmp(name, "--step") == 0) {
        if (bgc_parse_number(name, value, &s->step))
            return -1;
        if (s->step > 0.0)
            return 0;
        fprintf(stderr, "error: --step must be positive\n");
        return -1;
    }
    return bgc_parse_number(name, value, strcmp(name, "--t-end") == 0 ? &s->t_end
                                         : strcmp(name, "--dt") == 0  ? &s->dt
                                         : strcmp(name, "--rtol") == 0 ? &s->rtol
                                                                      : &s->atol);
}

/* -1 to run, else the exit status: 0 after --help, 2 after a usage error.  *project: 1 with
   --project-initial, 2 with --allow-inconsistent (they exclude each other). */
static int bgc_parse_args(int argc, char **argv, bgc_settings *s, bgc_params *p, int *given,
                          int *project, int *stats)
{
    static const char *const with_value[] = { "--t-end", "--dt", "--solver", "--rtol",
                                              "--atol", "--step", "--max-steps", "-p",
                                              "--max-step", "--events", "--input",
                                              "--error-states" };
    int i, k;
    for (i = 1; i < argc; i++) {
        const char *arg = argv[i], *eq = strncmp(arg, "--", 2) == 0 ? strchr(arg, '=') : NULL;
        const size_t len = eq ? (size_t)(eq - arg) : strlen(arg);
        const char *value;
        if (strcmp(arg, "-h") == 0 || strcmp(arg, "--help") == 0) {
            bgc_help();
            return 0;
        }
        if (strcmp(arg, "--progress") == 0) {
            bgc_progress.on = 1;
            continue;
        }
        if (strcmp(arg, "--project-initial") == 0 || strcmp(arg, "--allow-inconsistent") == 0) {
            const int mode = arg[2] == 'p' ? 1 : 2;
            if (*project && *project != mode) {
                fprintf(stderr, "error: --project-initial and --allow-inconsistent exclude each "
                        "other\n");
                return BGC_ERR_USAGE;
            }
            *project = mode;
            continue;
        }
        if (strcmp(arg, "--stats") == 0) {
            *stats = 1;
            continue;
        }
        if (strcmp(arg, "--event-rows") == 0) {
            s->event_rows = 1;
            continue;
        }
        for (k = 0; k < BGC_COUNT(with_value); k++)
            if (strlen(with_value[k]) == len && strncmp(arg, with_value[k], len) == 0)
                break;
        if (k == BGC_COUNT(with_value)) {
            fprintf(stderr, "error: unknown option '%s'\n", arg);
            bgc_print_usage(stderr);
            return BGC_ERR_USAGE;
        }
        value = eq ? eq + 1 : (i + 1 < argc ? argv[++i] : NULL);
        if (!value) {
            fprintf(stderr, "error: option '%s' needs a value\n", arg);
            bgc_print_usage(stderr);
            return BGC_ERR_USAGE;
        }
        if (bgc_apply_option(with_value[k], value, s, p, given))
            return BGC_ERR_USAGE;
    }
    return -1;
}

/* The run's settings from the command line (and the parameters it sets), checked: -1 to
   run, else the exit status (as bgc_parse_args). */
static int bgc_settings_from_args(int argc, char **argv, bgc_settings *s, bgc_params *p,
                                  int *given, int *project, int *stats)
{
    char msg[1024];
    int rc;
    bgc_settings_default(s);
    rc = bgc_parse_args(argc, argv, s, p, given, project, stats);
    if (rc < 0 && bgc_check_settings(s, msg, sizeof msg)) {
        fprintf(stderr, "error: %s\n", msg);
        return BGC_ERR_USAGE;
    }
    return rc;
}

/* SIGINT, SIGTERM: the run stops at its next step, as a failure, its rows written. */
static void bgc_on_signal(int sig)
{
    bgc_request_stop(sig);
}

/* Started by bgc (BGC_PARENT_PID in the environment: bgc's process id), the program dies
   with it instead of running on as an orphan when bgc is killed: on Linux, the kernel sends
   it SIGKILL when its parent ends (and it ends at once if the parent did before).  Run by
   anything else, or elsewhere, this does nothing. */
static void bgc_die_with_parent(void)
{
#if defined(__linux__) && defined(PR_SET_PDEATHSIG) && defined(SIGKILL)
    const char *parent = getenv("BGC_PARENT_PID");
    if (parent == NULL || *parent == '\0')
        return;
    prctl(PR_SET_PDEATHSIG, SIGKILL);
    if ((long)getppid() != strtol(parent, NULL, 10))
        raise(SIGKILL);
#endif
}

/* The write error's message: "cannot write the output: REASON" (bgc simulate reads it). */
static void bgc_write_failed(int err)
{
    fprintf(stderr, "error: cannot write the output: %s\n",
            err > 0 ? strerror(err) : "write error");
}

static int bgc_batch_main(int argc, char **argv); /* --batch: below (batch.c) */

int main(int argc, char **argv)
{
    bgc_settings s;
    bgc_params p;
    bgc_stats st = { 0, 0, 0, 0, 0, 0, 0, 0.0, 0.0, 0.0, 0, 0, 0 };
    int given[BGC_DIM(BGC_NUM_PARAMS)] = { 0 };
    double x0[BGC_DIM(BGC_NUM_STATES)] = { 0.0 };
    char msg[1024];
    int project = 0, stats = 0, rc, i;

    bgc_die_with_parent();
    rc = bgc_batch_main(argc, argv);
    if (rc >= 0)
        return rc;
    rc = bgc_settings_from_args(argc, argv, &s, &p, given, &project, &stats);
    if (rc >= 0)
        return rc;
    bgc_params_defaults(&p, given);
    for (i = 0; i < BGC_NUM_PARAMS; i++)
        if (!isfinite(*bgc_param_ref(&p, i))) {
            fprintf(stderr, "error: parameter '%s' is not finite\n", bgc_param_names[i]);
            return BGC_ERR_RUNTIME;
        }
    bgc_init(&p, x0);
    i = bgc_first_nonfinite(x0, BGC_NUM_STATES);
    if (i >= 0) {
        fprintf(stderr, "error: at t = %.17g: state '%s' is not finite\n", s.t0, bgc_state_names[i]);
        return BGC_ERR_RUNTIME;
    }
    if (project == 1 && bgc_project_initial(s.t0, x0, &p, msg, sizeof msg)) {
        fprintf(stderr, "error: %s\n", msg);
        return BGC_ERR_CONSTRAINT;
    }
    if ((project == 2 ? bgc_check_constraints_finite : bgc_check_constraints)(s.t0, x0, &p,
                                                                              stderr))
        return BGC_ERR_CONSTRAINT;

    s.inputs = bgc_input_file.series;
    if (bgc_event_log.path) {
        bgc_event_log.file = fopen(bgc_event_log.path, "w");
        if (!bgc_event_log.file) {
            fprintf(stderr, "error: cannot write the event log '%s': %s\n", bgc_event_log.path,
                    strerror(errno));
            return BGC_ERR_USAGE;
        }
        fputs("t,event,change\n", bgc_event_log.file);
        s.on_event = bgc_log_event;
        s.event_ctx = bgc_event_log.file;
    }
    signal(SIGINT, bgc_on_signal);
    signal(SIGTERM, bgc_on_signal);
    bgc_out.file = stdout;
    bgc_csv_header(stdout);
    bgc_progress.t0 = bgc_progress.next = s.t0;
    bgc_progress.t_end = s.t_end;
    rc = bgc_simulate(&s, &p, x0, bgc_csv_row, &bgc_out, &st, msg, sizeof msg);
    bgc_flush(&bgc_out);
    errno = 0;
    if (fflush(stdout) != 0 && !bgc_out.failed)
        bgc_out.failed = errno ? errno : -1;
    if (bgc_event_log.file && fclose(bgc_event_log.file) != 0 && !bgc_event_log.failed)
        bgc_event_log.failed = errno ? errno : -1;
    if (bgc_event_log.failed && !bgc_out.failed)
        bgc_out.failed = bgc_event_log.failed;
    if (bgc_out.failed) {
        bgc_write_failed(bgc_out.failed);
        return BGC_ERR_RUNTIME;
    }
    if (stats)
        bgc_print_stats(stderr, &st);
    if (rc) {
        fprintf(stderr, "error: %s\n", msg);
        return BGC_ERR_RUNTIME;
    }
    return 0;
}
#endif /* BGC_NO_MAIN */

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
