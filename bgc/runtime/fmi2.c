/* ========================================================================= FMI 2.0 === */
/* The FMU's interface: the functions of FMI 2.0 (Model Exchange and Co-Simulation) over the
   model part and the runtime above (bgc/runtime/fmi2.c, inlined verbatim after them by
   bgc/fmu.py).  It uses from the FMU part before it: BGC_FMI_GUID, BGC_FMI_PROJECT_INITIAL,
   bgc_fmi_output_state (the state each output is, or -1), BGC_FMI_NUM_DISCRETE_VARS and
   bgc_fmi_discrete (where each discrete variable is among the discrete values d); from the
   model part bgc_model_outputs_jvp (the outputs' derivative along a direction of the states);
   from the runtime the event iteration of bgc/runtime/drive.c (the same translation unit).

   Value references (all Real), as modelDescription.xml lists them:
     [0, P)                  parameter j            (P = BGC_NUM_PARAMS)
     [P, P + N)              state i                (N = BGC_NUM_STATES)
     [P + N, P + 2N)         the derivative of state i
     [P + 2N, P + 2N + M)    output k               (M = BGC_NUM_OUTPUTS; an output that is a
                                                     state is that state's variable instead)
     [P + 2N + M, ... + D)   discrete variable k    (D = BGC_FMI_NUM_DISCRETE_VARS)
     [P + 2N + M + D, ... + U)  input j             (U = BGC_FMI_NUM_INPUTS: `input NAME`)
     P + 2N + M + D + U      time                   (causality "independent": the
                                                     instance's time, never set by fmi2SetReal)
   An input is "continuous", set with fmi2SetReal at any time: its value holds until it is
   set again (Co-Simulation: between two fmi2DoStep; Model Exchange: the environment's
   business).  Until it is set, it keeps its default.
   Parameters are "fixed": set before fmi2ExitInitializationMode; a parameter that is not set
   follows its default expression (which may use the parameters before it).  The states are
   computed from the parameters when initialisation ends (and checked against the model's
   constraints).  Model Exchange: the environment integrates the states.  Co-Simulation:
   fmi2DoStep integrates with the scene's solver (bgc_advance), which goes on with the step
   size it had reached at the last communication point.

   Events (a model with BGC_NUM_DISCRETE > 0, docs/hybrid.md).  fmi2ExitInitializationMode
   runs the start's event iteration (both types).  Model Exchange: event indicator k is the
   state relation k's indicator g (the relation holds when g > 0 if it is strict, g >= 0 if
   not; a relation that changed at an event, within its hysteresis band, bgc_level: g moved
   by the band, the relation keeping its value where that is 0), except where it is exactly
   0: there it is BGC_FMI_ZERO on the side of the relation's value (-BGC_FMI_ZERO for a
   strict relation, which does not hold, +BGC_FMI_ZERO for another, which does).  So an
   indicator is > 0 exactly when its relation holds, and never 0: the
   relation changes its value exactly when the indicator changes sign, which is FMI's state
   event, and a root finder that stops where an indicator is 0 (CVODE does) never stops at
   a point where the relation has not changed yet.
   fmi2NewDiscreteStates runs the event iteration at the instance's (t, x) until nothing
   changes (newDiscreteStatesNeeded is never set), says whether it changed the states, and
   gives the next time event; fmi2CompletedIntegratorStep asks for event mode when a state
   relation's value differs from its frozen one (an event the environment did not locate, at
   the step's end rather than never).  The events the environment brings are bounded as the
   runtime's driver bounds its own (bgc_handle_event, bgc_fmi_count_event below): events in a
   row each within the time's resolution of the one before, state events in a row each ending
   the environment's first integrator step since the one before (every step cut short by an
   event), the events since the scene's last output time; past a bound fmi2NewDiscreteStates
   fails with the runtime's "chattering" message, so that the environment stops.
   Co-Simulation: fmi2DoStep's run locates and handles the events inside the step, as bgc's
   own runs do; the discrete values go on from step to step.

   The life cycle is FMI 2.0's state machine (its tables of the functions each state allows,
   sections 3.2.3 and 4.2.4; the masks BGC_FMI_MASK_* below): instantiated, initialization
   mode, then event and continuous-time mode (Model Exchange) or step complete
   (Co-Simulation), terminated, error.  A call its state does not allow, or with arguments it
   cannot take, returns fmi2Error, logged, and changes nothing; a failure of the model (an
   event iteration that does not settle, chattering, a Co-Simulation run that fails) puts the
   instance in the error state, where the values can still be read (for the diagnosis) and
   fmi2Reset, fmi2SetFMUstate or fmi2FreeInstance go on.  The FMU never enters step in
   progress, step failed or step canceled (fmi2DoStep is synchronous and fails with
   fmi2Error), nor fatal (no failure reaches beyond its instance: the FMU has no global state).

   The handle fmi2Instantiate returns outlives the instance: fmi2FreeInstance frees all the
   instance holds and marks the handle freed instead of freeing it, so that a call through a
   freed handle (fmi2FreeInstance twice, fmi2GetReal after it) reads memory that is still
   the handle's and returns fmi2Error (a void function: nothing), without a log (the
   environment's logger need not live beyond fmi2FreeInstance).  The price is the handle's
   few bytes for the life of the process.  A registry of live instances would free
   everything, but it is state shared by all instances, which FMI lets environments run in
   threads of their own (a lock, beyond C99), and malloc may hand a freed instance's address
   to the next one, so that a stale handle would act on another instance; a handle that is
   never freed is never another's.

   The declarations below are written from the text of the FMI 2.0 standard (its sections on
   the platform types and the common functions): the types, the status and kind enumerations,
   the callbacks and the event information, with the standard's names and layouts. */

#include <float.h>
#include <stdarg.h>

#if defined(_WIN32)
#define BGC_FMI_EXPORT __declspec(dllexport)
#elif defined(__GNUC__)
#define BGC_FMI_EXPORT __attribute__((visibility("default")))
#else
#define BGC_FMI_EXPORT
#endif

/* ------------------------------------------------------------ the FMI types --- */
typedef void *fmi2Component;            /* an instance, as fmi2Instantiate returns it */
typedef void *fmi2ComponentEnvironment; /* the environment's pointer, handed back to it */
typedef void *fmi2FMUstate;             /* a saved state (bgc_fmi_saved below) */
typedef unsigned int fmi2ValueReference;
typedef double fmi2Real;
typedef int fmi2Integer;
typedef int fmi2Boolean;
typedef char fmi2Char;
typedef const fmi2Char *fmi2String;
typedef char fmi2Byte;
#define fmi2True 1
#define fmi2False 0

typedef enum { fmi2OK, fmi2Warning, fmi2Discard, fmi2Error, fmi2Fatal, fmi2Pending } fmi2Status;
typedef enum { fmi2ModelExchange, fmi2CoSimulation } fmi2Type;
typedef enum {
    fmi2DoStepStatus,
    fmi2PendingStatus,
    fmi2LastSuccessfulTime,
    fmi2Terminated
} fmi2StatusKind;

/* The environment's functions: the logger takes a printf format and its arguments. */
typedef void (*fmi2CallbackLogger)(fmi2ComponentEnvironment env, fmi2String instanceName,
                                   fmi2Status status, fmi2String category, fmi2String message,
                                   ...);
typedef void *(*fmi2CallbackAllocateMemory)(size_t nobj, size_t size);
typedef void (*fmi2CallbackFreeMemory)(void *obj);
typedef void (*fmi2StepFinished)(fmi2ComponentEnvironment env, fmi2Status status);
typedef struct {
    const fmi2CallbackLogger logger;
    const fmi2CallbackAllocateMemory allocateMemory;
    const fmi2CallbackFreeMemory freeMemory;
    const fmi2StepFinished stepFinished;
    const fmi2ComponentEnvironment componentEnvironment;
} fmi2CallbackFunctions;

typedef struct {
    fmi2Boolean newDiscreteStatesNeeded;
    fmi2Boolean terminateSimulation;
    fmi2Boolean nominalsOfContinuousStatesChanged;
    fmi2Boolean valuesOfContinuousStatesChanged;
    fmi2Boolean nextEventTimeDefined;
    fmi2Real nextEventTime;
} fmi2EventInfo;

/* ------------------------------------------------------------- an instance --- */

/* The states of FMI 2.0's state machines (the bits of the masks below); Co-Simulation's
   "step complete" is BGC_FMI_STEP.  A freed instance, the standard's start and end, has no
   state: its handle is marked (bgc_fmi_handle). */
enum {
    BGC_FMI_INSTANTIATED, /* parameters may be set */
    BGC_FMI_INIT,         /* initialization mode: parameters may still be set */
    BGC_FMI_EVENT,        /* Model Exchange: event mode */
    BGC_FMI_CONTINUOUS,   /* Model Exchange: continuous-time mode */
    BGC_FMI_STEP,         /* Co-Simulation: step complete, between two steps */
    BGC_FMI_TERMINATED,
    BGC_FMI_ERROR         /* after a failure of the model: values for the diagnosis only */
};

#define BGC_FMI_VR_STATES ((fmi2ValueReference)BGC_NUM_PARAMS)
#define BGC_FMI_VR_DERIVATIVES (BGC_FMI_VR_STATES + (fmi2ValueReference)BGC_NUM_STATES)
#define BGC_FMI_VR_OUTPUTS (BGC_FMI_VR_DERIVATIVES + (fmi2ValueReference)BGC_NUM_STATES)
#define BGC_FMI_VR_DISCRETE (BGC_FMI_VR_OUTPUTS + (fmi2ValueReference)BGC_NUM_OUTPUTS)
#define BGC_FMI_VR_INPUTS (BGC_FMI_VR_DISCRETE + (fmi2ValueReference)BGC_FMI_NUM_DISCRETE_VARS)
#define BGC_FMI_VR_TIME (BGC_FMI_VR_INPUTS + (fmi2ValueReference)BGC_FMI_NUM_INPUTS)

/* Model Exchange's events, counted as the runtime's driver counts its own (bgc_run): an
   event mode entered from continuous-time mode, not yet counted; the last event's time and
   the events in a row within the time's resolution of the one before; the state events in a
   row, each ending the first integrator step since the one before; the first step completed
   since the last event (INFINITY: none); the scene's output time (its index) the count of
   events since it began at, and that count; the event iteration's passes so far, the pass
   that last changed each discrete value, and the passes where those chains began (for the
   chattering message's names). */
typedef struct bgc_fmi_events {
    int pending;
    long chain, sliding, since_out;
    double t_event, t_step, kout;
    double passes, chain_from, sliding_from, out_from, last[BGC_DIM(BGC_NUM_DISCRETE)];
} bgc_fmi_events;

typedef struct bgc_fmi {
    fmi2Type type;
    int phase;
    char *name;
    fmi2CallbackLogger logger;
    fmi2ComponentEnvironment env;
    int logging;
    bgc_params p;
    int given[BGC_DIM(BGC_NUM_PARAMS)]; /* set through fmi2SetReal (else the default) */
    int fresh;                          /* p (and, before initialisation ends, x) are current */
    bgc_work *w;
    double t;
    double t_start;                     /* the start time (fmi2SetupExperiment's) */
    double rtol;                        /* Co-Simulation: the solver's (the scene's, or the
                                           tolerance of fmi2SetupExperiment) */
    double x[BGC_DIM(BGC_NUM_STATES)];
    double dx[BGC_DIM(BGC_NUM_STATES)];
    double y[BGC_DIM(BGC_NUM_OUTPUTS)];
    double v[BGC_DIM(BGC_NUM_STATES)];  /* a direction, for directional derivatives */
    double jv[BGC_DIM(BGC_NUM_STATES)];
    double jy[BGC_DIM(BGC_NUM_OUTPUTS)];
    int dx_ok, y_ok;                    /* dx, y are those of (t, x) */
    int stiff;                          /* Co-Simulation, solver auto: its stiff phase began */
    bgc_stats st;
    int x_changed;                      /* the start's event iteration changed the states
                                           (the first fmi2NewDiscreteStates says so) */
    double g[BGC_DIM(BGC_NUM_INDICATORS)];
    double ev[BGC_DIM(BGC_NUM_INDICATORS + BGC_EV_SIZE)]; /* the event iteration's scratch */
    bgc_fmi_events e;                   /* Model Exchange's events, counted */
    /* the inputs: each a series of one sample once set (before: none, its default) */
    bgc_input_series in[BGC_DIM(BGC_FMI_NUM_INPUTS)];
    double in_t[BGC_DIM(BGC_FMI_NUM_INPUTS)], in_u[BGC_DIM(BGC_FMI_NUM_INPUTS)];
} bgc_fmi;

/* What fmi2Instantiate returns, never freed: fmi2FreeInstance frees the instance and sets m
   to NULL.  fmu is this binary's bgc_fmi_ours, so that the handle of another FMU (or any
   pointer to something else that starts with a pointer) is not taken for one of ours. */
typedef struct bgc_fmi_handle {
    const char *fmu;
    bgc_fmi *m;
} bgc_fmi_handle;

static const char bgc_fmi_ours[] = BGC_FMI_GUID;

#define BGC_FMI_ZERO 1e-300 /* an indicator's size where g is 0 (a product with another
                                  indicator's value does not underflow to 0) */

/* The discrete values d of the instance's model functions (in its parameters). */
#define BGC_FMI_D(m) ((double *)&(m)->p + BGC_DISCRETE_OFFSET)

/* Reports to the environment's logger: errors always, the rest when logging is on.  The text
   goes as an argument of "%s", never as the format (it may hold names from the model). */
static void bgc_fmi_log(const bgc_fmi *m, fmi2Status status, const char *fmt, ...)
{
    static const char *const categories[] = { "logAll", "logStatusWarning", "logStatusDiscard",
                                              "logStatusError", "logStatusError", "logAll" };
    char text[1024];
    va_list ap;
    if (!m->logger || (!m->logging && status < fmi2Error))
        return;
    va_start(ap, fmt);
    vsnprintf(text, sizeof text, fmt, ap);
    va_end(ap);
    m->logger(m->env, m->name, status, categories[status], "%s", text);
}

/* fmi2Error, logged: the call is not allowed now, or its arguments are wrong. */
static fmi2Status bgc_fmi_refuse(const bgc_fmi *m, const char *fn, const char *why)
{
    bgc_fmi_log(m, fmi2Error, "%s: %s", fn, why);
    return fmi2Error;
}

/* The live instance of handle c, or NULL: c NULL, freed, or not a handle of this FMU. */
static bgc_fmi *bgc_fmi_live(fmi2Component c)
{
    const bgc_fmi_handle *h = (const bgc_fmi_handle *)c;
    return h && h->fmu == bgc_fmi_ours ? h->m : NULL;
}

#define BGC_FMI_STATE_NAMES                                                                  \
    { "the instantiated state", "initialization mode", "event mode", "continuous-time mode", \
      "step complete", "the terminated state", "the error state" }

/* The instance, or NULL if c is not a live instance, or fn is not allowed in its state (mask:
   1 << state) or for its type (1: Model Exchange only, 2: Co-Simulation only, 0: both); the
   refusal is logged (no instance: no logger to tell). */
static bgc_fmi *bgc_fmi_get(fmi2Component c, const char *fn, int mask, int only)
{
    static const char *const states[] = BGC_FMI_STATE_NAMES;
    bgc_fmi *m = bgc_fmi_live(c);
    if (!m)
        return NULL;
    if (only && m->type != (only == 1 ? fmi2ModelExchange : fmi2CoSimulation)) {
        bgc_fmi_log(m, fmi2Error, "%s: not a function of %s", fn,
                    m->type == fmi2ModelExchange ? "Model Exchange" : "Co-Simulation");
        return NULL;
    }
    if (!(mask & (1 << m->phase))) {
        bgc_fmi_log(m, fmi2Error, "%s: not allowed in %s%s", fn, states[m->phase],
                    m->phase == BGC_FMI_ERROR ? " (fmi2Reset or fmi2SetFMUstate goes on)" : "");
        return NULL;
    }
    return m;
}

/* The states each function is allowed in: FMI 2.0's tables (3.2.3 for Model Exchange, 4.2.4
   for Co-Simulation), the states of both types in one mask (a state belongs to one type:
   event and continuous-time mode to Model Exchange, step complete to Co-Simulation).  What
   the tables allow for some variables only (fmi2SetReal: parameters until initialization
   ends, inputs throughout) is checked by the function. */
#define BGC_FMI_S(state) (1 << BGC_FMI_##state)
#define BGC_FMI_LIVE (BGC_FMI_S(INSTANTIATED) | BGC_FMI_S(INIT) | BGC_FMI_S(EVENT) \
                      | BGC_FMI_S(CONTINUOUS) | BGC_FMI_S(STEP) | BGC_FMI_S(TERMINATED) \
                      | BGC_FMI_S(ERROR))
#define BGC_FMI_INITIALIZING (BGC_FMI_LIVE & ~BGC_FMI_S(INSTANTIATED))
#define BGC_FMI_RUNNING (BGC_FMI_S(EVENT) | BGC_FMI_S(CONTINUOUS) | BGC_FMI_S(STEP))
#define BGC_FMI_AFTER (BGC_FMI_S(TERMINATED) | BGC_FMI_S(ERROR))
#define BGC_FMI_MASK_SetDebugLogging BGC_FMI_LIVE
#define BGC_FMI_MASK_SetupExperiment BGC_FMI_S(INSTANTIATED)
#define BGC_FMI_MASK_EnterInitializationMode BGC_FMI_S(INSTANTIATED)
#define BGC_FMI_MASK_ExitInitializationMode BGC_FMI_S(INIT)
#define BGC_FMI_MASK_Terminate BGC_FMI_RUNNING
#define BGC_FMI_MASK_Reset BGC_FMI_LIVE
#define BGC_FMI_MASK_GetValues BGC_FMI_INITIALIZING /* fmi2GetReal, ..., fmi2GetString */
#define BGC_FMI_MASK_SetReal (BGC_FMI_S(INSTANTIATED) | BGC_FMI_S(INIT) | BGC_FMI_RUNNING)
#define BGC_FMI_MASK_SetOther (BGC_FMI_S(INSTANTIATED) | BGC_FMI_S(INIT) | BGC_FMI_S(EVENT) \
                               | BGC_FMI_S(STEP)) /* fmi2SetInteger, -Boolean, -String */
#define BGC_FMI_MASK_FMUstate BGC_FMI_LIVE /* fmi2GetFMUstate, ..., fmi2DeSerializeFMUstate */
#define BGC_FMI_MASK_GetDirectionalDerivative BGC_FMI_INITIALIZING
#define BGC_FMI_MASK_EnterEventMode (BGC_FMI_S(EVENT) | BGC_FMI_S(CONTINUOUS))
#define BGC_FMI_MASK_NewDiscreteStates BGC_FMI_S(EVENT)
#define BGC_FMI_MASK_EnterContinuousTimeMode BGC_FMI_S(EVENT)
#define BGC_FMI_MASK_CompletedIntegratorStep BGC_FMI_S(CONTINUOUS)
#define BGC_FMI_MASK_SetTime (BGC_FMI_S(EVENT) | BGC_FMI_S(CONTINUOUS))
#define BGC_FMI_MASK_SetContinuousStates BGC_FMI_S(CONTINUOUS)
#define BGC_FMI_MASK_GetEventIndicators (BGC_FMI_S(INIT) | BGC_FMI_S(EVENT) \
                                         | BGC_FMI_S(CONTINUOUS) | BGC_FMI_AFTER)
#define BGC_FMI_MASK_GetContinuousStates BGC_FMI_MASK_GetEventIndicators
#define BGC_FMI_MASK_GetDerivatives (BGC_FMI_S(EVENT) | BGC_FMI_S(CONTINUOUS) | BGC_FMI_AFTER)
#define BGC_FMI_MASK_GetNominalsOfContinuousStates (BGC_FMI_S(INSTANTIATED) | BGC_FMI_S(EVENT) \
                                                    | BGC_FMI_S(CONTINUOUS) | BGC_FMI_AFTER)
#define BGC_FMI_MASK_SetRealInputDerivatives (BGC_FMI_S(INSTANTIATED) | BGC_FMI_S(INIT) \
                                              | BGC_FMI_S(STEP))
#define BGC_FMI_MASK_GetRealOutputDerivatives (BGC_FMI_S(STEP) | BGC_FMI_AFTER)
#define BGC_FMI_MASK_DoStep BGC_FMI_S(STEP)
/* (fmi2CancelStep: step in progress, never entered) */
#define BGC_FMI_MASK_GetStatus (BGC_FMI_S(STEP) | BGC_FMI_S(TERMINATED)) /* and -Real-, ... */

/* Parameters and states from the parameters set so far (before initialisation ends). */
static void bgc_fmi_refresh(bgc_fmi *m)
{
    if (m->fresh)
        return;
    bgc_params_defaults(&m->p, m->given);
    if (m->phase == BGC_FMI_INSTANTIATED || m->phase == BGC_FMI_INIT)
        bgc_init(&m->p, m->x);
    m->dx_ok = m->y_ok = 0;
    m->fresh = 1;
}

static void bgc_fmi_start(bgc_fmi *m)
{
    int j;
    for (j = 0; j < BGC_NUM_PARAMS; j++)
        m->given[j] = 0;
    memset(&m->p, 0, sizeof m->p);
    memset(&m->st, 0, sizeof m->st);
    m->phase = BGC_FMI_INSTANTIATED;
    m->fresh = 0;
    m->t = m->t_start = BGC_SCENE_T0;
    m->rtol = BGC_SCENE_RTOL;
    m->stiff = 0;
    m->x_changed = 0;
    m->e.pending = 0;
    m->e.t_event = -INFINITY;
    m->e.t_step = INFINITY;
    m->e.chain = m->e.sliding = m->e.since_out = 0;
    m->e.kout = -1.0;
    m->e.passes = m->e.chain_from = m->e.sliding_from = m->e.out_from = 0.0;
    for (j = 0; j < BGC_NUM_DISCRETE; j++)
        m->e.last[j] = -1.0;
    m->w->rtol = BGC_SCENE_RTOL;
    m->w->atol = BGC_SCENE_ATOL;
    for (j = 0; j < BGC_FMI_NUM_INPUTS; j++) {
        m->in_t[j] = m->in_u[j] = 0.0;
        m->in[j].n = 0;
        m->in[j].t = &m->in_t[j];
        m->in[j].u = &m->in_u[j];
    }
    m->w->inputs = BGC_FMI_NUM_INPUTS > 0 ? m->in : NULL;
    bgc_fmi_refresh(m);
}

/* The model's failure (an algebraic block), logged: Model Exchange discards the point (the
   integrator may try a smaller step), Co-Simulation's caller gets an error (and the instance
   is in the error state). */
static fmi2Status bgc_fmi_model_failed(bgc_fmi *m, const char *fn)
{
    const fmi2Status status = m->type == fmi2ModelExchange ? fmi2Discard : fmi2Error;
    char msg[512];
    bgc_work_message(m->w, msg, sizeof msg);
    bgc_fmi_log(m, status, "%s: %s", fn, msg);
    if (status == fmi2Error)
        m->phase = BGC_FMI_ERROR;
    return status;
}

static int bgc_fmi_derivatives(bgc_fmi *m)
{
    if (!m->dx_ok && bgc_rhs(m->t, m->x, &m->p, m->w, m->dx))
        return 1;
    m->dx_ok = 1;
    return 0;
}

static int bgc_fmi_outputs(bgc_fmi *m)
{
    if (!m->y_ok && bgc_outputs(m->t, m->x, &m->p, m->w, m->y))
        return 1;
    m->y_ok = 1;
    return 0;
}

/* ------------------------------------------------------------------- events --- */

/* Logs each change at an event (when logging is on): its time, what changed and how. */
static int bgc_fmi_on_event(void *ctx, double t, const char *what, const char *change)
{
    bgc_fmi_log((const bgc_fmi *)ctx, fmi2OK, "event at t = %.17g: %s: %s", t, what, change);
    return 0;
}

/* Model Exchange: an event at the instance's time (the event mode entered from
   continuous-time mode), counted before its event iteration as bgc_handle_event counts the
   driver's: in a row within the time's resolution of the one before (the first has none
   before it); a state event (a relation whose value at (t, x), in r->g, differs from its
   frozen one), in a row with the state events before it when no integrator step was
   completed before its instant since the last event (the environment's step was cut short
   by it, as the driver's steps that end at a located event are); and since the start of the
   scene's output interval it is in (the driver's output rows). */
static void bgc_fmi_count_event(bgc_fmi *m, const bgc_run *r)
{
    const double t = m->t, scale = bgc_max(fabs(t), fabs(m->e.t_event));
    const double k = floor((t - m->t_start) / BGC_SCENE_DT);
    if (isfinite(m->e.t_event) && t - m->e.t_event <= bgc_max(1e-12 * scale, bgc_hmin(t))) {
        m->e.chain++;
    } else {
        m->e.chain = 0;
        m->e.chain_from = m->e.passes;
    }
    m->e.t_event = t;
    if (BGC_NUM_INDICATORS == 0 || bgc_changed(r, r->g) < 0) {
        m->e.sliding = 0;
    } else {
        if (m->e.t_step < t) /* a step that no event cut short */
            m->e.sliding = 0;
        if (++m->e.sliding == 1)
            m->e.sliding_from = m->e.passes;
    }
    m->e.t_step = INFINITY;
    if (k != m->e.kout) {
        m->e.kout = k;
        m->e.since_out = 0;
        m->e.out_from = m->e.passes;
    }
    m->e.since_out++;
}

/* The driver's bounds on events (bgc_handle_event, with its default step budget) after a
   counted event's iteration: 0, or the chattering message in r->msg. */
static int bgc_fmi_bound_events(bgc_fmi *m, bgc_run *r)
{
    const long sliding = BGC_MAX_STEPS > 100000 ? BGC_MAX_STEPS / 100 : 1000;
    const long most = BGC_MAX_STEPS > 1000 ? BGC_MAX_STEPS : 1000;
    char head[128];
    if (m->e.chain >= BGC_MAX_EVENT_ITERATIONS) {
        snprintf(head, sizeof head, "%ld events in a row, each within 1e-12 relative of the "
                 "one before", m->e.chain);
        return bgc_chattering(r, m->t, head, m->e.chain_from, "a Zeno model, the switching "
                              "outruns the time's resolution");
    }
    if (m->e.sliding >= sliding) {
        snprintf(head, sizeof head, "%ld integrator steps in a row, each cut short by an event",
                 m->e.sliding);
        return bgc_chattering(r, m->t, head, m->e.sliding_from, "a sliding mode or a Zeno model?");
    }
    if (m->e.since_out > most) {
        snprintf(head, sizeof head, "%ld events since the scene's output time %.17g",
                 m->e.since_out - 1, m->t_start + m->e.kout * BGC_SCENE_DT);
        return bgc_chattering(r, m->t, head, m->e.out_from, "a Zeno model?");
    }
    return 0;
}

/* The event iteration of the runtime (bgc/runtime/drive.c) at the instance's (t, x), start:
   the run's first (the discrete values then start from the workspace's); the discrete values
   kept in the workspace too, where Co-Simulation's runs take them from; count: an event of
   Model Exchange, counted and bounded (bgc_fmi_count_event).  *x_changed: whether the states
   changed; *t_next: the next time event (INFINITY: none).  A failure (chattering, a value
   that is not finite) is logged, and the instance is in the error state. */
static fmi2Status bgc_fmi_event_iteration(bgc_fmi *m, const char *fn, int start, int count,
                                          int *x_changed, double *t_next)
{
    double x0[BGC_DIM(BGC_NUM_STATES)];
    bgc_settings s;
    bgc_run r;
    char msg[512];
    int i, rc = 0;
    *x_changed = 0;
    *t_next = INFINITY;
    if (BGC_NUM_DISCRETE == 0)
        return fmi2OK;
    bgc_settings_default(&s);
    s.on_event = bgc_fmi_on_event;
    s.event_ctx = m;
    memset(&r, 0, sizeof r);
    r.s = &s;
    r.p = &m->p;
    r.w = m->w;
    r.msg = msg;
    r.msg_size = sizeof msg;
    r.t = m->t;
    r.d = BGC_FMI_D(m);
    r.band = m->w->d + BGC_NUM_DISCRETE;
    r.gmax = r.band + BGC_NUM_INDICATORS;
    r.g = m->g;
    r.ev = m->ev;
    r.last = m->e.last;
    r.passes = m->e.passes;
    memcpy(x0, m->x, sizeof x0);
    if (start)
        memcpy(r.d, m->w->d, sizeof(double) * BGC_NUM_DISCRETE);
    /* A time event that the importer's clock stopped short of by its rounding (FMPy reaches
       5e-6 as 4.9999999999999996e-06, the double below): taken there, at its own time, not
       left a step of one ulp ahead, which no integrator can take. */
    if (!start && bgc_next_time(&r, m->t, m->x) == 0 && isfinite(r.t_next)
        && r.t_next - m->t <= 16.0 * DBL_EPSILON * fabs(r.t_next))
        m->t = r.t = r.t_next;
    if (count && BGC_NUM_INDICATORS > 0)
        rc = bgc_indicators(&r, m->t, m->x, r.g);
    if (rc == 0 && count)
        bgc_fmi_count_event(m, &r);
    if (rc == 0)
        rc = bgc_event_iteration(&r, m->t, m->x, start);
    m->e.passes = r.passes;
    if (rc == 0 && count)
        rc = bgc_fmi_bound_events(m, &r);
    if (rc == 0)
        rc = bgc_next_time(&r, m->t, m->x);
    memcpy(m->w->d, r.d, sizeof(double) * BGC_NUM_DISCRETE);
    m->w->started = 1;
    m->dx_ok = m->y_ok = 0;
    if (rc) {
        m->phase = BGC_FMI_ERROR;
        bgc_fmi_log(m, fmi2Error, "%s: %s", fn, msg);
        return fmi2Error;
    }
    for (i = 0; i < BGC_NUM_STATES; i++)
        *x_changed |= x0[i] != m->x[i];
    *t_next = r.t_next;
    return fmi2OK;
}

/* The run r as far as the state relations' values need it (bgc_relation, bgc_level,
   bgc_seen): the discrete values and the bands in the instance's workspace. */
static void bgc_fmi_bands(bgc_fmi *m, bgc_run *r)
{
    memset(r, 0, sizeof *r);
    r->d = BGC_FMI_D(m);
    r->band = m->w->d + BGC_NUM_DISCRETE;
    r->gmax = r->band + BGC_NUM_INDICATORS;
}

/* The state relations' indicators at the instance's (t, x) in m->g; nonzero if the model
   failed (an algebraic block). */
static int bgc_fmi_indicators(bgc_fmi *m)
{
    bgc_fmi_refresh(m);
    return BGC_NUM_INDICATORS > 0 && bgc_model_events(m->t, m->x, &m->p, m->w, m->g);
}

/* --------------------------------------------------------- common functions --- */

BGC_FMI_EXPORT const char *fmi2GetTypesPlatform(void)
{
    return "default";
}

BGC_FMI_EXPORT const char *fmi2GetVersion(void)
{
    return "2.0";
}

BGC_FMI_EXPORT fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn,
                                              size_t nCategories, const fmi2String categories[])
{
    static const char *const known[] = { "logStatusWarning", "logStatusDiscard",
                                         "logStatusError", "logAll" };
    bgc_fmi *m = bgc_fmi_get(c, "fmi2SetDebugLogging", BGC_FMI_MASK_SetDebugLogging, 0);
    size_t i;
    int k, found;
    if (!m)
        return fmi2Error;
    if (nCategories > 0 && !categories)
        return bgc_fmi_refuse(m, "fmi2SetDebugLogging", "no array of categories given");
    for (i = 0; i < nCategories; i++) {
        found = 0;
        for (k = 0; k < BGC_COUNT(known); k++)
            found |= categories[i] && strcmp(categories[i], known[k]) == 0;
        if (!found)
            return bgc_fmi_refuse(m, "fmi2SetDebugLogging", "unknown log category (the "
                                  "FMU's: logStatusWarning, logStatusDiscard, logStatusError, "
                                  "logAll)");
    }
    m->logging = loggingOn != fmi2False;
    return fmi2OK;
}

BGC_FMI_EXPORT fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType,
                                             fmi2String fmuGUID, fmi2String fmuResourceLocation,
                                             const fmi2CallbackFunctions *functions,
                                             fmi2Boolean visible, fmi2Boolean loggingOn)
{
    bgc_fmi_handle *h;
    bgc_fmi *m;
    const char *why = NULL;
    size_t len;
    (void)fmuResourceLocation;
    (void)visible;
    if (!functions)
        return NULL;
    if (!instanceName || !instanceName[0])
        why = "the instance name is empty";
    else if (fmuType != fmi2ModelExchange && fmuType != fmi2CoSimulation)
        why = "unknown FMU type";
    else if (!fmuGUID || strcmp(fmuGUID, BGC_FMI_GUID) != 0)
        why = "the GUID is not this FMU's (modelDescription.xml and the binary differ)";
    if (why) {
        if (functions->logger)
            functions->logger(functions->componentEnvironment, instanceName ? instanceName : "",
                              fmi2Error, "logStatusError", "fmi2Instantiate: %s", why);
        return NULL;
    }
    h = (bgc_fmi_handle *)malloc(sizeof *h);
    m = h ? (bgc_fmi *)calloc(1, sizeof *m) : NULL;
    len = strlen(instanceName);
    if (m)
        m->name = (char *)malloc(len + 1);
    if (m)
        m->w = bgc_work_new();
    if (!m || !m->name || !m->w) {
        if (m) {
            free(m->name);
            bgc_work_free(m->w);
        }
        free(m);
        free(h); /* (never handed out) */
        if (functions->logger)
            functions->logger(functions->componentEnvironment, instanceName, fmi2Error,
                              "logStatusError", "fmi2Instantiate: out of memory");
        return NULL;
    }
    memcpy(m->name, instanceName, len + 1);
    m->type = fmuType;
    m->logger = functions->logger;
    m->env = functions->componentEnvironment;
    m->logging = loggingOn != fmi2False;
    bgc_fmi_start(m);
    h->fmu = bgc_fmi_ours;
    h->m = m;
    return h;
}

/* Frees the instance and marks its handle freed (the handle itself stays: a second
   fmi2FreeInstance, or any call after it, finds it freed).  NULL is ignored (FMI 2.0), and
   so is a handle already freed or not this FMU's: nothing to free, and nobody to tell. */
BGC_FMI_EXPORT void fmi2FreeInstance(fmi2Component c)
{
    bgc_fmi *m = bgc_fmi_live(c);
    if (!m)
        return;
    ((bgc_fmi_handle *)c)->m = NULL;
    bgc_work_free(m->w);
    free(m->name);
    free(m);
}

BGC_FMI_EXPORT fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean toleranceDefined,
                                              fmi2Real tolerance, fmi2Real startTime,
                                              fmi2Boolean stopTimeDefined, fmi2Real stopTime)
{
    bgc_fmi *m = bgc_fmi_get(c, "fmi2SetupExperiment", BGC_FMI_MASK_SetupExperiment, 0);
    (void)stopTimeDefined;
    (void)stopTime;
    if (!m)
        return fmi2Error;
    if (!isfinite(startTime))
        return bgc_fmi_refuse(m, "fmi2SetupExperiment", "the start time is not finite");
    if (toleranceDefined && !(tolerance > 0.0 && isfinite(tolerance)))
        return bgc_fmi_refuse(m, "fmi2SetupExperiment", "the tolerance is not positive");
    m->t = m->t_start = startTime;
    m->rtol = toleranceDefined ? tolerance : BGC_SCENE_RTOL;
    m->dx_ok = m->y_ok = 0;
    return fmi2OK;
}

BGC_FMI_EXPORT fmi2Status fmi2EnterInitializationMode(fmi2Component c)
{
    bgc_fmi *m = bgc_fmi_get(c, "fmi2EnterInitializationMode",
                             BGC_FMI_MASK_EnterInitializationMode, 0);
    if (!m)
        return fmi2Error;
    m->phase = BGC_FMI_INIT;
    m->fresh = 0;
    return fmi2OK;
}

/* Names the first constraint row violated at (t, x), as the generated program does. */
static fmi2Status bgc_fmi_constraints(bgc_fmi *m)
{
    double r[BGC_DIM(BGC_NUM_CONSTRAINTS)] = { 0.0 }, s[BGC_DIM(BGC_NUM_CONSTRAINTS)] = { 0.0 };
    int k;
    if (BGC_NUM_CONSTRAINTS == 0)
        return fmi2OK;
    if ((BGC_FMI_ALLOW_INCONSISTENT ? bgc_check_constraints_finite
                                    : bgc_check_constraints)(m->t, m->x, &m->p, NULL) == 0)
        return fmi2OK;
    bgc_residual(m->t, m->x, &m->p, r);
    bgc_scale(m->t, m->x, &m->p, s);
    for (k = 0; k < BGC_NUM_CONSTRAINTS; k++)
        if (!(fabs(r[k]) <= 1e-9 * s[k]))
            break;
    k = k < BGC_NUM_CONSTRAINTS ? k : 0;
    bgc_fmi_log(m, fmi2Error, "fmi2ExitInitializationMode: the initial state violates "
                "constraint '%s' (%s): residual = %.17g%s", bgc_constraint_names[k],
                bgc_constraint_levels[k], r[k], isfinite(r[k]) ? "" : " (the model is "
                "undefined at the initial state with these parameters)");
    return fmi2Error;
}

/* The initial state checked (and projected, with BGC_FMI_PROJECT_INITIAL), logged if it
   is not right: fmi2OK or fmi2Error. */
static fmi2Status bgc_fmi_initial(bgc_fmi *m)
{
    char msg[512];
    int i;
    for (i = 0; i < BGC_NUM_PARAMS; i++)
        if (!isfinite(*bgc_param_ref(&m->p, i))) {
            bgc_fmi_log(m, fmi2Error, "fmi2ExitInitializationMode: parameter '%s' is not "
                        "finite", bgc_param_names[i]);
            return fmi2Error;
        }
    i = bgc_first_nonfinite(m->x, BGC_NUM_STATES);
    if (i >= 0) {
        bgc_fmi_log(m, fmi2Error, "fmi2ExitInitializationMode: state '%s' is not finite",
                    bgc_state_names[i]);
        return fmi2Error;
    }
    if (BGC_FMI_PROJECT_INITIAL && BGC_NUM_CONSTRAINTS > 0
        && bgc_project_initial(m->t, m->x, &m->p, msg, sizeof msg)) {
        bgc_fmi_log(m, fmi2Error, "fmi2ExitInitializationMode: %s", msg);
        return fmi2Error;
    }
    return bgc_fmi_constraints(m);
}

/* The initial state, then the start's event iteration; a failure of either (the model's)
   puts the instance in the error state. */
BGC_FMI_EXPORT fmi2Status fmi2ExitInitializationMode(fmi2Component c)
{
    bgc_fmi *m = bgc_fmi_get(c, "fmi2ExitInitializationMode",
                             BGC_FMI_MASK_ExitInitializationMode, 0);
    double t_next;
    if (!m)
        return fmi2Error;
    bgc_fmi_refresh(m);
    if (bgc_fmi_initial(m) != fmi2OK) {
        m->phase = BGC_FMI_ERROR;
        return fmi2Error;
    }
    m->dx_ok = m->y_ok = 0;
    if (bgc_fmi_event_iteration(m, "fmi2ExitInitializationMode", 1, 0, &m->x_changed,
                                &t_next))
        return fmi2Error;
    m->phase = m->type == fmi2ModelExchange ? BGC_FMI_EVENT : BGC_FMI_STEP;
    return fmi2OK;
}

BGC_FMI_EXPORT fmi2Status fmi2Terminate(fmi2Component c)
{
    bgc_fmi *m = bgc_fmi_get(c, "fmi2Terminate", BGC_FMI_MASK_Terminate, 0);
    if (!m)
        return fmi2Error;
    m->phase = BGC_FMI_TERMINATED;
    return fmi2OK;
}

BGC_FMI_EXPORT fmi2Status fmi2Reset(fmi2Component c)
{
    bgc_fmi *m = bgc_fmi_get(c, "fmi2Reset", BGC_FMI_MASK_Reset, 0);
    bgc_work *w;
    if (!m)
        return fmi2Error;
    w = bgc_work_new(); /* a fresh workspace: Newton blocks start as in a new instance */
    if (!w)
        return bgc_fmi_refuse(m, "fmi2Reset", "out of memory");
    bgc_work_free(m->w);
    m->w = w;
    bgc_fmi_start(m);
    return fmi2OK;
}

/* ----------------------------------------------------------------- values --- */

/* The position of vr among the n references from lo, or -1. */
static int bgc_fmi_in(fmi2ValueReference vr, fmi2ValueReference lo, int n)
{
    const long k = (long)vr - (long)lo;
    return k >= 0 && k < (long)n ? (int)k : -1;
}

/* The value of vr at the instance's (t, x): 0, 1 for an unknown reference, 2 if the model
   failed (an algebraic block). */
static int bgc_fmi_value(bgc_fmi *m, fmi2ValueReference vr, double *out)
{
    int k;
    bgc_fmi_refresh(m);
    if ((k = bgc_fmi_in(vr, 0, BGC_NUM_PARAMS)) >= 0) {
        *out = *bgc_param_ref(&m->p, k);
    } else if ((k = bgc_fmi_in(vr, BGC_FMI_VR_STATES, BGC_NUM_STATES)) >= 0) {
        *out = m->x[k];
    } else if ((k = bgc_fmi_in(vr, BGC_FMI_VR_DERIVATIVES, BGC_NUM_STATES)) >= 0) {
        if (bgc_fmi_derivatives(m))
            return 2;
        *out = m->dx[k];
    } else if ((k = bgc_fmi_in(vr, BGC_FMI_VR_OUTPUTS, BGC_NUM_OUTPUTS)) >= 0) {
        if (bgc_fmi_output_state[k] >= 0) {
            *out = m->x[bgc_fmi_output_state[k]];
        } else {
            if (bgc_fmi_outputs(m))
                return 2;
            *out = m->y[k];
        }
    } else if ((k = bgc_fmi_in(vr, BGC_FMI_VR_DISCRETE, BGC_FMI_NUM_DISCRETE_VARS)) >= 0) {
        *out = BGC_FMI_D(m)[bgc_fmi_discrete[k]];
    } else if ((k = bgc_fmi_in(vr, BGC_FMI_VR_INPUTS, BGC_FMI_NUM_INPUTS)) >= 0) {
        *out = m->in[k].n > 0 || bgc_fmi_input_slot[k] < 0 ? m->in_u[k]
                                                            : BGC_FMI_D(m)[bgc_fmi_input_slot[k]];
    } else if (vr == BGC_FMI_VR_TIME) {
        *out = m->t;
    } else {
        return 1;
    }
    return 0;
}

BGC_FMI_EXPORT fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[],
                                      size_t nvr, fmi2Real value[])
{
    bgc_fmi *m = bgc_fmi_get(c, "fmi2GetReal", BGC_FMI_MASK_GetValues, 0);
    size_t i;
    if (!m)
        return fmi2Error;
    if (nvr > 0 && (!vr || !value))
        return bgc_fmi_refuse(m, "fmi2GetReal", "no array given");
    for (i = 0; i < nvr; i++) {
        const int rc = bgc_fmi_value(m, vr[i], &value[i]);
        if (rc == 1) {
            bgc_fmi_log(m, fmi2Error, "fmi2GetReal: unknown value reference %u", vr[i]);
            return fmi2Error;
        }
        if (rc == 2)
            return bgc_fmi_model_failed(m, "fmi2GetReal");
    }
    return fmi2OK;
}

BGC_FMI_EXPORT fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[],
                                      size_t nvr, const fmi2Real value[])
{
    bgc_fmi *m = bgc_fmi_get(c, "fmi2SetReal", BGC_FMI_MASK_SetReal, 0);
    size_t i;
    if (!m)
        return fmi2Error;
    if (nvr > 0 && (!vr || !value))
        return bgc_fmi_refuse(m, "fmi2SetReal", "no array given");
    for (i = 0; i < nvr; i++) {
        const int k = bgc_fmi_in(vr[i], BGC_FMI_VR_INPUTS, BGC_FMI_NUM_INPUTS);
        if (k >= 0) {
            if (!isfinite(value[i])) {
                bgc_fmi_log(m, fmi2Error, "fmi2SetReal: input '%s' must be finite",
                            bgc_input_name(k));
                return fmi2Error;
            }
            continue;
        }
        if (vr[i] == BGC_FMI_VR_TIME)
            return bgc_fmi_refuse(m, "fmi2SetReal", "time is the independent variable (set by "
                                  "fmi2SetupExperiment, fmi2SetTime and fmi2DoStep)");
        if (bgc_fmi_in(vr[i], 0, BGC_NUM_PARAMS) < 0) {
            bgc_fmi_log(m, fmi2Error, "fmi2SetReal: value reference %u is not a parameter (the "
                        "states start from the parameters; Model Exchange sets them with "
                        "fmi2SetContinuousStates)", vr[i]);
            return fmi2Error;
        }
        if (m->phase != BGC_FMI_INSTANTIATED && m->phase != BGC_FMI_INIT) {
            bgc_fmi_log(m, fmi2Error, "fmi2SetReal: parameter '%s' is fixed once "
                        "initialisation has ended", bgc_param_names[vr[i]]);
            return fmi2Error;
        }
        if (!isfinite(value[i])) {
            bgc_fmi_log(m, fmi2Error, "fmi2SetReal: parameter '%s' must be finite",
                        bgc_param_names[vr[i]]);
            return fmi2Error;
        }
    }
    for (i = 0; i < nvr; i++) {
        const int k = bgc_fmi_in(vr[i], BGC_FMI_VR_INPUTS, BGC_FMI_NUM_INPUTS);
        if (k >= 0) { /* held from now on: the segment's value, its start and slope 0 */
            const int slot = bgc_fmi_input_slot[k];
            m->in[k].n = 1;
            m->in_u[k] = value[i];
            if (slot >= 0) {
                BGC_FMI_D(m)[slot - 1] = BGC_FMI_D(m)[slot + 1] = 0.0;
                BGC_FMI_D(m)[slot] = value[i];
                m->w->d[slot - 1] = m->w->d[slot + 1] = 0.0;
                m->w->d[slot] = value[i];
            }
            m->dx_ok = m->y_ok = 0;
            continue;
        }
        *bgc_param_ref(&m->p, (int)vr[i]) = value[i];
        m->given[vr[i]] = 1;
        m->fresh = 0;
    }
    return fmi2OK;
}

/* The FMU has no Integer, Boolean or String variables, and takes no input derivatives: only
   empty requests succeed (only: bgc_fmi_get's). */
static fmi2Status bgc_fmi_none(fmi2Component c, const char *fn, int mask, int only, size_t nvr)
{
    bgc_fmi *m = bgc_fmi_get(c, fn, mask, only);
    if (!m)
        return fmi2Error;
    return nvr == 0 ? fmi2OK : bgc_fmi_refuse(m, fn, "the FMU has no variables of this type");
}

BGC_FMI_EXPORT fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[],
                                         size_t nvr, fmi2Integer value[])
{
    (void)vr;
    (void)value;
    return bgc_fmi_none(c, "fmi2GetInteger", BGC_FMI_MASK_GetValues, 0, nvr);
}

BGC_FMI_EXPORT fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[],
                                         size_t nvr, fmi2Boolean value[])
{
    (void)vr;
    (void)value;
    return bgc_fmi_none(c, "fmi2GetBoolean", BGC_FMI_MASK_GetValues, 0, nvr);
}

BGC_FMI_EXPORT fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[],
                                        size_t nvr, fmi2String value[])
{
    (void)vr;
    (void)value;
    return bgc_fmi_none(c, "fmi2GetString", BGC_FMI_MASK_GetValues, 0, nvr);
}

BGC_FMI_EXPORT fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[],
                                         size_t nvr, const fmi2Integer value[])
{
    (void)vr;
    (void)value;
    return bgc_fmi_none(c, "fmi2SetInteger", BGC_FMI_MASK_SetOther, 0, nvr);
}

BGC_FMI_EXPORT fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[],
                                         size_t nvr, const fmi2Boolean value[])
{
    (void)vr;
    (void)value;
    return bgc_fmi_none(c, "fmi2SetBoolean", BGC_FMI_MASK_SetOther, 0, nvr);
}

BGC_FMI_EXPORT fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[],
                                        size_t nvr, const fmi2String value[])
{
    (void)vr;
    (void)value;
    return bgc_fmi_none(c, "fmi2SetString", BGC_FMI_MASK_SetOther, 0, nvr);
}

/* ------------------------------------------------------------- FMU states --- */

/* A saved state: everything an instance's future depends on -- its phase, time, parameters
   (and which were set), states and cached values, the inputs, the Co-Simulation solver's step
   size, order and counters, Model Exchange's counts of events, and the workspace (the
   algebraic blocks' last solutions, the starting values of their Newton iterations).
   Serialised as its bytes after a header that names this FMU (its GUID) and the layout's
   size: it deserialises only into the same binary. */
typedef struct bgc_fmi_saved {
    char magic[8];                      /* "bgcFMUs" */
    char guid[64];                      /* BGC_FMI_GUID */
    unsigned long size;                 /* sizeof(bgc_fmi_saved) */
    int type, phase, fresh, stiff, dx_ok, y_ok, x_changed, wstarted;
    double t, t_start, rtol;
    bgc_params p;
    int given[BGC_DIM(BGC_NUM_PARAMS)];
    double x[BGC_DIM(BGC_NUM_STATES)], dx[BGC_DIM(BGC_NUM_STATES)];
    double y[BGC_DIM(BGC_NUM_OUTPUTS)];
    bgc_stats st;
    bgc_fmi_events e;
    double in_u[BGC_DIM(BGC_FMI_NUM_INPUTS)];
    int in_n[BGC_DIM(BGC_FMI_NUM_INPUTS)];
    double wrtol, watol;
    double wv[BGC_DIM(BGC_WORK_DOUBLES)];
    int wiv[BGC_DIM(BGC_WORK_INTS)];
    double wd[BGC_DIM(BGC_NUM_DISCRETE + 2 * BGC_NUM_INDICATORS)]; /* and the bands */
} bgc_fmi_saved;

static void bgc_fmi_save(const bgc_fmi *m, bgc_fmi_saved *s)
{
    int j;
    memset(s, 0, sizeof *s);
    memcpy(s->magic, "bgcFMUs", 8);
    strncpy(s->guid, BGC_FMI_GUID, sizeof s->guid - 1);
    s->size = (unsigned long)sizeof *s;
    s->type = (int)m->type;
    s->phase = m->phase;
    s->fresh = m->fresh;
    s->stiff = m->stiff;
    s->dx_ok = m->dx_ok;
    s->y_ok = m->y_ok;
    s->x_changed = m->x_changed;
    s->wstarted = m->w->started;
    s->t = m->t;
    s->t_start = m->t_start;
    s->rtol = m->rtol;
    s->p = m->p;
    memcpy(s->given, m->given, sizeof s->given);
    memcpy(s->x, m->x, sizeof s->x);
    memcpy(s->dx, m->dx, sizeof s->dx);
    memcpy(s->y, m->y, sizeof s->y);
    s->st = m->st;
    s->e = m->e;
    for (j = 0; j < BGC_FMI_NUM_INPUTS; j++) {
        s->in_u[j] = m->in_u[j];
        s->in_n[j] = m->in[j].n;
    }
    s->wrtol = m->w->rtol;
    s->watol = m->w->atol;
    memcpy(s->wv, m->w->v, sizeof s->wv);
    memcpy(s->wiv, m->w->iv, sizeof s->wiv);
    memcpy(s->wd, m->w->d, sizeof s->wd);
}

static void bgc_fmi_restore(bgc_fmi *m, const bgc_fmi_saved *s)
{
    int j;
    m->phase = s->phase;
    m->fresh = s->fresh;
    m->stiff = s->stiff;
    m->dx_ok = s->dx_ok;
    m->y_ok = s->y_ok;
    m->x_changed = s->x_changed;
    m->w->started = s->wstarted;
    m->t = s->t;
    m->t_start = s->t_start;
    m->rtol = s->rtol;
    m->p = s->p;
    memcpy(m->given, s->given, sizeof s->given);
    memcpy(m->x, s->x, sizeof s->x);
    memcpy(m->dx, s->dx, sizeof s->dx);
    memcpy(m->y, s->y, sizeof s->y);
    m->st = s->st;
    m->e = s->e;
    for (j = 0; j < BGC_FMI_NUM_INPUTS; j++) {
        m->in_u[j] = s->in_u[j];
        m->in[j].n = s->in_n[j] ? 1 : 0;
    }
    m->w->rtol = s->wrtol;
    m->w->atol = s->watol;
    memcpy(m->w->v, s->wv, sizeof s->wv);
    memcpy(m->w->iv, s->wiv, sizeof s->wiv);
    memcpy(m->w->d, s->wd, sizeof s->wd);
    m->w->block = 0;
    m->w->failure = 0;
}

static int bgc_fmi_saved_ours(const bgc_fmi_saved *s)
{
    return memcmp(s->magic, "bgcFMUs", 8) == 0 && s->size == (unsigned long)sizeof *s
           && strncmp(s->guid, BGC_FMI_GUID, sizeof s->guid) == 0;
}

/* Whether s is a state of this FMU, for an instance of type `type`; why not in *why. */
static int bgc_fmi_saved_ok(const bgc_fmi_saved *s, int type, const char **why)
{
    if (!bgc_fmi_saved_ours(s))
        *why = "not a state of this FMU";
    else if (s->type != type)
        *why = "a state of the other FMU type (Model Exchange / Co-Simulation)";
    else if (s->phase < BGC_FMI_INSTANTIATED || s->phase > BGC_FMI_ERROR)
        *why = "not a state of this FMU (its state machine's state)";
    else
        return 1;
    return 0;
}

BGC_FMI_EXPORT fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *FMUstate)
{
    bgc_fmi *m = bgc_fmi_get(c, "fmi2GetFMUstate", BGC_FMI_MASK_FMUstate, 0);
    bgc_fmi_saved *s;
    if (!m)
        return fmi2Error;
    if (!FMUstate)
        return bgc_fmi_refuse(m, "fmi2GetFMUstate", "no place for the state");
    s = (bgc_fmi_saved *)*FMUstate; /* not NULL: overwrite that state (FMI 2.0, 2.1.8) */
    if (s) {
        if (!bgc_fmi_saved_ours(s))
            return bgc_fmi_refuse(m, "fmi2GetFMUstate", "not a state of this FMU");
    } else if (!(s = (bgc_fmi_saved *)malloc(sizeof *s))) {
        return bgc_fmi_refuse(m, "fmi2GetFMUstate", "out of memory");
    }
    bgc_fmi_save(m, s);
    *FMUstate = s;
    return fmi2OK;
}

BGC_FMI_EXPORT fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate FMUstate)
{
    bgc_fmi *m = bgc_fmi_get(c, "fmi2SetFMUstate", BGC_FMI_MASK_FMUstate, 0);
    const char *why = NULL;
    if (!m)
        return fmi2Error;
    if (!FMUstate)
        return bgc_fmi_refuse(m, "fmi2SetFMUstate", "no state given");
    if (!bgc_fmi_saved_ok((const bgc_fmi_saved *)FMUstate, (int)m->type, &why))
        return bgc_fmi_refuse(m, "fmi2SetFMUstate", why);
    bgc_fmi_restore(m, (const bgc_fmi_saved *)FMUstate);
    return fmi2OK;
}

BGC_FMI_EXPORT fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *FMUstate)
{
    bgc_fmi *m = bgc_fmi_get(c, "fmi2FreeFMUstate", BGC_FMI_MASK_FMUstate, 0);
    if (!m)
        return fmi2Error;
    if (FMUstate) {
        free(*FMUstate);
        *FMUstate = NULL;
    }
    return fmi2OK;
}

BGC_FMI_EXPORT fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate FMUstate,
                                                     size_t *size)
{
    bgc_fmi *m = bgc_fmi_get(c, "fmi2SerializedFMUstateSize", BGC_FMI_MASK_FMUstate, 0);
    if (!m)
        return fmi2Error;
    if (!FMUstate || !size)
        return bgc_fmi_refuse(m, "fmi2SerializedFMUstateSize", "no state or no size given");
    *size = sizeof(bgc_fmi_saved);
    return fmi2OK;
}

BGC_FMI_EXPORT fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate FMUstate,
                                                fmi2Byte serializedState[], size_t size)
{
    bgc_fmi *m = bgc_fmi_get(c, "fmi2SerializeFMUstate", BGC_FMI_MASK_FMUstate, 0);
    if (!m)
        return fmi2Error;
    if (!FMUstate || !serializedState)
        return bgc_fmi_refuse(m, "fmi2SerializeFMUstate", "no state or no buffer given");
    if (size < sizeof(bgc_fmi_saved))
        return bgc_fmi_refuse(m, "fmi2SerializeFMUstate",
                              "the buffer is smaller than fmi2SerializedFMUstateSize says");
    memcpy(serializedState, FMUstate, sizeof(bgc_fmi_saved));
    return fmi2OK;
}

BGC_FMI_EXPORT fmi2Status fmi2DeSerializeFMUstate(fmi2Component c,
                                                  const fmi2Byte serializedState[], size_t size,
                                                  fmi2FMUstate *FMUstate)
{
    bgc_fmi *m = bgc_fmi_get(c, "fmi2DeSerializeFMUstate", BGC_FMI_MASK_FMUstate, 0);
    bgc_fmi_saved *s;
    const char *why = NULL;
    if (!m)
        return fmi2Error;
    if (!serializedState || !FMUstate)
        return bgc_fmi_refuse(m, "fmi2DeSerializeFMUstate", "no bytes or no place given");
    if (size != sizeof(bgc_fmi_saved))
        return bgc_fmi_refuse(m, "fmi2DeSerializeFMUstate", "not a state of this FMU (size)");
    s = (bgc_fmi_saved *)malloc(sizeof *s);
    if (!s)
        return bgc_fmi_refuse(m, "fmi2DeSerializeFMUstate", "out of memory");
    memcpy(s, serializedState, sizeof *s);
    if (!bgc_fmi_saved_ok(s, (int)m->type, &why)) {
        free(s);
        return bgc_fmi_refuse(m, "fmi2DeSerializeFMUstate", why);
    }
    *FMUstate = s;
    return fmi2OK;
}

/* ------------------------------------------------- directional derivatives --- */

/* d unknowns = J d knowns, the knowns states, the unknowns derivatives (the right side's
   Jacobian, bgc_jvp), states or outputs (bgc_model_outputs_jvp), at the instance's (t, x). */
BGC_FMI_EXPORT fmi2Status fmi2GetDirectionalDerivative(fmi2Component c,
                                                       const fmi2ValueReference vUnknown_ref[],
                                                       size_t nUnknown,
                                                       const fmi2ValueReference vKnown_ref[],
                                                       size_t nKnown, const fmi2Real dvKnown[],
                                                       fmi2Real dvUnknown[])
{
    static const char fn[] = "fmi2GetDirectionalDerivative";
    bgc_fmi *m = bgc_fmi_get(c, fn, BGC_FMI_MASK_GetDirectionalDerivative, 1);
    int need_dx = 0, need_y = 0, k;
    size_t i;
    if (!m)
        return fmi2Error;
    bgc_fmi_refresh(m);
    if ((nKnown > 0 && (!vKnown_ref || !dvKnown))
        || (nUnknown > 0 && (!vUnknown_ref || !dvUnknown)))
        return bgc_fmi_refuse(m, fn, "no array given");
    for (k = 0; k < BGC_NUM_STATES; k++)
        m->v[k] = 0.0;
    for (i = 0; i < nKnown; i++) {
        k = bgc_fmi_in(vKnown_ref[i], BGC_FMI_VR_STATES, BGC_NUM_STATES);
        if (k < 0) {
            bgc_fmi_log(m, fmi2Error, "%s: value reference %u: the FMU gives derivatives with "
                        "respect to the states only", fn, vKnown_ref[i]);
            return fmi2Error;
        }
        m->v[k] += dvKnown[i];
    }
    for (i = 0; i < nUnknown; i++) {
        const fmi2ValueReference r = vUnknown_ref[i];
        if (bgc_fmi_in(r, BGC_FMI_VR_DERIVATIVES, BGC_NUM_STATES) >= 0) {
            need_dx = 1;
        } else if ((k = bgc_fmi_in(r, BGC_FMI_VR_OUTPUTS, BGC_NUM_OUTPUTS)) >= 0) {
            need_y |= bgc_fmi_output_state[k] < 0;
        } else if (bgc_fmi_in(r, BGC_FMI_VR_STATES, BGC_NUM_STATES) < 0) {
            bgc_fmi_log(m, fmi2Error, "%s: value reference %u: the FMU gives the derivatives of "
                        "state derivatives, states and outputs only", fn, r);
            return fmi2Error;
        }
    }
    if (need_dx && bgc_jvp(m->t, m->x, &m->p, m->w, m->v, m->jv))
        return bgc_fmi_model_failed(m, fn);
    if (need_y && bgc_model_outputs_jvp(m->t, m->x, &m->p, m->w, m->v, m->jy))
        return bgc_fmi_model_failed(m, fn);
    for (i = 0; i < nUnknown; i++) {
        const fmi2ValueReference r = vUnknown_ref[i];
        if ((k = bgc_fmi_in(r, BGC_FMI_VR_STATES, BGC_NUM_STATES)) >= 0)
            dvUnknown[i] = m->v[k];
        else if ((k = bgc_fmi_in(r, BGC_FMI_VR_DERIVATIVES, BGC_NUM_STATES)) >= 0)
            dvUnknown[i] = m->jv[k];
        else if ((k = bgc_fmi_in(r, BGC_FMI_VR_OUTPUTS, BGC_NUM_OUTPUTS)) >= 0)
            dvUnknown[i] = bgc_fmi_output_state[k] >= 0 ? m->v[bgc_fmi_output_state[k]]
                                                        : m->jy[k];
    }
    return fmi2OK;
}

/* ---------------------------------------------------------- Model Exchange --- */

BGC_FMI_EXPORT fmi2Status fmi2EnterEventMode(fmi2Component c)
{
    bgc_fmi *m = bgc_fmi_get(c, "fmi2EnterEventMode", BGC_FMI_MASK_EnterEventMode, 1);
    if (!m)
        return fmi2Error;
    m->e.pending |= m->phase == BGC_FMI_CONTINUOUS; /* an event (counted by the next call) */
    m->phase = BGC_FMI_EVENT;
    return fmi2OK;
}

/* The event iteration until nothing changes, all in one call; the first call after
   fmi2EnterEventMode counts the event and bounds the events (bgc_fmi_count_event). */
BGC_FMI_EXPORT fmi2Status fmi2NewDiscreteStates(fmi2Component c, fmi2EventInfo *eventInfo)
{
    static const char fn[] = "fmi2NewDiscreteStates";
    bgc_fmi *m = bgc_fmi_get(c, fn, BGC_FMI_MASK_NewDiscreteStates, 1);
    double t_next;
    int changed, count;
    if (!m)
        return fmi2Error;
    if (!eventInfo)
        return bgc_fmi_refuse(m, fn, "no event information given");
    bgc_fmi_refresh(m);
    count = m->e.pending;
    m->e.pending = 0;
    if (bgc_fmi_event_iteration(m, fn, 0, count, &changed, &t_next))
        return fmi2Error;
    eventInfo->newDiscreteStatesNeeded = fmi2False;
    eventInfo->terminateSimulation = fmi2False;
    eventInfo->nominalsOfContinuousStatesChanged = fmi2False;
    eventInfo->valuesOfContinuousStatesChanged = changed || m->x_changed;
    eventInfo->nextEventTimeDefined = isfinite(t_next) ? fmi2True : fmi2False;
    eventInfo->nextEventTime = isfinite(t_next) ? t_next : 0.0;
    m->x_changed = 0;
    return fmi2OK;
}

BGC_FMI_EXPORT fmi2Status fmi2EnterContinuousTimeMode(fmi2Component c)
{
    bgc_fmi *m = bgc_fmi_get(c, "fmi2EnterContinuousTimeMode",
                             BGC_FMI_MASK_EnterContinuousTimeMode, 1);
    if (!m)
        return fmi2Error;
    m->phase = BGC_FMI_CONTINUOUS;
    return fmi2OK;
}

BGC_FMI_EXPORT fmi2Status fmi2CompletedIntegratorStep(fmi2Component c,
                                                      fmi2Boolean noSetFMUStatePriorToCurrentPoint,
                                                      fmi2Boolean *enterEventMode,
                                                      fmi2Boolean *terminateSimulation)
{
    bgc_fmi *m = bgc_fmi_get(c, "fmi2CompletedIntegratorStep",
                             BGC_FMI_MASK_CompletedIntegratorStep, 1);
    bgc_run r;
    int k, missed = 0;
    (void)noSetFMUStatePriorToCurrentPoint;
    if (!m)
        return fmi2Error;
    if (m->t < m->e.t_step) /* the first step since the last event ended here */
        m->e.t_step = m->t;
    if (bgc_fmi_indicators(m))
        return bgc_fmi_model_failed(m, "fmi2CompletedIntegratorStep");
    bgc_fmi_bands(m, &r);
    for (k = 0; k < BGC_NUM_INDICATORS; k++)
        missed |= bgc_relation(&r, k, m->g[k]) != (r.d[k] != 0.0);
    if (!missed) /* an accepted point, as the driver's step ends */
        bgc_seen(&r, m->g);
    if (enterEventMode)
        *enterEventMode = missed ? fmi2True : fmi2False;
    if (terminateSimulation)
        *terminateSimulation = fmi2False;
    return fmi2OK;
}

BGC_FMI_EXPORT fmi2Status fmi2SetTime(fmi2Component c, fmi2Real time)
{
    bgc_fmi *m = bgc_fmi_get(c, "fmi2SetTime", BGC_FMI_MASK_SetTime, 1);
    if (!m)
        return fmi2Error;
    if (!isfinite(time))
        return bgc_fmi_refuse(m, "fmi2SetTime", "the time is not finite");
    if (time != m->t)
        m->dx_ok = m->y_ok = 0;
    m->t = time;
    return fmi2OK;
}

/* nx must be the number of states. */
static bgc_fmi *bgc_fmi_states(fmi2Component c, const char *fn, int mask, const void *a,
                               size_t nx)
{
    bgc_fmi *m = bgc_fmi_get(c, fn, mask, 1);
    if (m && nx != (size_t)BGC_NUM_STATES) {
        bgc_fmi_log(m, fmi2Error, "%s: the FMU has %d states, not %lu", fn, BGC_NUM_STATES,
                    (unsigned long)nx);
        return NULL;
    }
    if (m && nx > 0 && !a) {
        bgc_fmi_log(m, fmi2Error, "%s: no array given", fn);
        return NULL;
    }
    return m;
}

BGC_FMI_EXPORT fmi2Status fmi2SetContinuousStates(fmi2Component c, const fmi2Real x[], size_t nx)
{
    bgc_fmi *m = bgc_fmi_states(c, "fmi2SetContinuousStates",
                                BGC_FMI_MASK_SetContinuousStates, x, nx);
    size_t i;
    if (!m)
        return fmi2Error;
    for (i = 0; i < nx; i++)
        m->x[i] = x[i];
    m->dx_ok = m->y_ok = 0;
    return fmi2OK;
}

BGC_FMI_EXPORT fmi2Status fmi2GetDerivatives(fmi2Component c, fmi2Real derivatives[], size_t nx)
{
    bgc_fmi *m = bgc_fmi_states(c, "fmi2GetDerivatives", BGC_FMI_MASK_GetDerivatives,
                                derivatives, nx);
    size_t i;
    if (!m)
        return fmi2Error;
    bgc_fmi_refresh(m);
    if (bgc_fmi_derivatives(m))
        return bgc_fmi_model_failed(m, "fmi2GetDerivatives");
    for (i = 0; i < nx; i++)
        derivatives[i] = m->dx[i];
    return fmi2OK;
}

BGC_FMI_EXPORT fmi2Status fmi2GetEventIndicators(fmi2Component c, fmi2Real eventIndicators[],
                                                 size_t ni)
{
    static const char fn[] = "fmi2GetEventIndicators";
    bgc_fmi *m = bgc_fmi_get(c, fn, BGC_FMI_MASK_GetEventIndicators, 1);
    bgc_run r;
    int k;
    if (!m)
        return fmi2Error;
    if (ni != (size_t)BGC_NUM_INDICATORS) {
        bgc_fmi_log(m, fmi2Error, "%s: the FMU has %d event indicators, not %lu", fn,
                    BGC_NUM_INDICATORS, (unsigned long)ni);
        return fmi2Error;
    }
    if (ni > 0 && !eventIndicators)
        return bgc_fmi_refuse(m, fn, "no array given");
    if (bgc_fmi_indicators(m))
        return bgc_fmi_model_failed(m, fn);
    bgc_fmi_bands(m, &r);
    for (k = 0; k < BGC_NUM_INDICATORS; k++) { /* > 0 exactly when the relation holds */
        const double level = bgc_level(&r, k, m->g[k]);
        eventIndicators[k] = level != 0.0 ? level
                             : bgc_relation(&r, k, m->g[k]) ? BGC_FMI_ZERO : -BGC_FMI_ZERO;
    }
    return fmi2OK;
}

BGC_FMI_EXPORT fmi2Status fmi2GetContinuousStates(fmi2Component c, fmi2Real x[], size_t nx)
{
    bgc_fmi *m = bgc_fmi_states(c, "fmi2GetContinuousStates", BGC_FMI_MASK_GetContinuousStates,
                                x, nx);
    size_t i;
    if (!m)
        return fmi2Error;
    bgc_fmi_refresh(m);
    for (i = 0; i < nx; i++)
        x[i] = m->x[i];
    return fmi2OK;
}

BGC_FMI_EXPORT fmi2Status fmi2GetNominalsOfContinuousStates(fmi2Component c, fmi2Real x_nominal[],
                                                            size_t nx)
{
    bgc_fmi *m = bgc_fmi_states(c, "fmi2GetNominalsOfContinuousStates",
                                BGC_FMI_MASK_GetNominalsOfContinuousStates, x_nominal, nx);
    size_t i;
    if (!m)
        return fmi2Error;
    for (i = 0; i < nx; i++)
        x_nominal[i] = 1.0;
    return fmi2OK;
}

/* ------------------------------------------------------------ Co-Simulation --- */

/* Keeps the outputs of the run's last output time (the step's end). */
static int bgc_fmi_sink(void *ctx, double t, const double *x, const double *y)
{
    bgc_fmi *m = (bgc_fmi *)ctx;
    int k;
    (void)t;
    (void)x;
    for (k = 0; k < BGC_NUM_OUTPUTS; k++)
        m->y[k] = y[k];
    return 0;
}

BGC_FMI_EXPORT fmi2Status fmi2DoStep(fmi2Component c, fmi2Real currentCommunicationPoint,
                                     fmi2Real communicationStepSize,
                                     fmi2Boolean noSetFMUStatePriorToCurrentPoint)
{
    static const char fn[] = "fmi2DoStep";
    bgc_fmi *m = bgc_fmi_get(c, fn, BGC_FMI_MASK_DoStep, 2);
    const bgc_method *method;
    bgc_settings s;
    char msg[512];
    int rc;
    (void)noSetFMUStatePriorToCurrentPoint;
    if (!m)
        return fmi2Error;
    if (!(communicationStepSize >= 0.0 && isfinite(communicationStepSize)))
        return bgc_fmi_refuse(m, fn, "the step size must be a finite number, not negative");
    if (fabs(currentCommunicationPoint - m->t) > 1e-9 * bgc_max(1.0, fabs(m->t))) {
        bgc_fmi_log(m, fmi2Error, "%s: the communication point %.17g is not the FMU's time "
                    "%.17g", fn, currentCommunicationPoint, m->t);
        return fmi2Error;
    }
    if (communicationStepSize == 0.0)
        return fmi2OK;
    bgc_settings_default(&s);
    s.inputs = m->w->inputs;
    s.t0 = currentCommunicationPoint; /* the environment's clock: no drift from summing steps */
    s.t_end = currentCommunicationPoint + communicationStepSize;
    s.dt = communicationStepSize;
    s.rtol = m->rtol;
    /* the step size (and radau's order) go on from the last communication point */
    s.h0 = m->st.h_next;
    s.order0 = m->st.order_next;
    method = &bgc_methods[s.solver];
    if (method->family == BGC_FAMILY_AUTO && m->stiff)
        s.solver = method->stiff_solver; /* once stiff, as within one run */
    if (s.step == 0.0 && bgc_methods[s.solver].family == BGC_FAMILY_FIXED)
        s.step = BGC_SCENE_DT; /* the fixed step of the scene's run, whatever the interval */
    m->st.switched = 0;
    rc = bgc_advance(&s, &m->p, m->w, m->x, bgc_fmi_sink, m, &m->st, msg, sizeof msg);
    memcpy(BGC_FMI_D(m), m->w->d, sizeof(double) * BGC_NUM_DISCRETE); /* for fmi2GetReal */
    m->stiff |= m->st.switched;
    m->dx_ok = 0;
    if (rc) {
        m->y_ok = 0;
        m->phase = BGC_FMI_ERROR;
        bgc_fmi_log(m, fmi2Error, "%s: %s", fn, msg);
        return fmi2Error;
    }
    m->t = s.t_end;
    m->y_ok = 1;
    return fmi2OK;
}

BGC_FMI_EXPORT fmi2Status fmi2CancelStep(fmi2Component c)
{
    bgc_fmi *m = bgc_fmi_get(c, "fmi2CancelStep", BGC_FMI_LIVE, 2);
    return m ? bgc_fmi_refuse(m, "fmi2CancelStep", "no step in progress (fmi2DoStep never "
                              "runs asynchronously)")
             : fmi2Error;
}

BGC_FMI_EXPORT fmi2Status fmi2SetRealInputDerivatives(fmi2Component c,
                                                      const fmi2ValueReference vr[], size_t nvr,
                                                      const fmi2Integer order[],
                                                      const fmi2Real value[])
{
    (void)vr;
    (void)order;
    (void)value;
    return bgc_fmi_none(c, "fmi2SetRealInputDerivatives",
                        BGC_FMI_MASK_SetRealInputDerivatives, 2, nvr);
}

BGC_FMI_EXPORT fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c,
                                                       const fmi2ValueReference vr[], size_t nvr,
                                                       const fmi2Integer order[], fmi2Real value[])
{
    bgc_fmi *m = bgc_fmi_get(c, "fmi2GetRealOutputDerivatives",
                             BGC_FMI_MASK_GetRealOutputDerivatives, 2);
    (void)vr;
    (void)order;
    (void)value;
    if (!m)
        return fmi2Error;
    return nvr == 0 ? fmi2OK
                    : bgc_fmi_refuse(m, "fmi2GetRealOutputDerivatives",
                                     "the FMU gives no output derivatives "
                                     "(maxOutputDerivativeOrder=\"0\")");
}

/* A status the FMU does not give: fmi2Discard, logged (why: what it gives instead). */
static fmi2Status bgc_fmi_no_status(fmi2Component c, const char *fn, const char *why)
{
    bgc_fmi *m = bgc_fmi_get(c, fn, BGC_FMI_MASK_GetStatus, 2);
    if (!m)
        return fmi2Error;
    bgc_fmi_log(m, fmi2Discard, "%s: %s", fn, why);
    return fmi2Discard;
}

/* fmi2DoStep never returns fmi2Pending: the status is asked for only after it has. */
BGC_FMI_EXPORT fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s,
                                        fmi2Status *value)
{
    (void)s;
    (void)value;
    return bgc_fmi_no_status(c, "fmi2GetStatus", "fmi2DoStep never returns fmi2Pending");
}

BGC_FMI_EXPORT fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s,
                                            fmi2Real *value)
{
    bgc_fmi *m = bgc_fmi_get(c, "fmi2GetRealStatus", BGC_FMI_MASK_GetStatus, 2);
    if (!m)
        return fmi2Error;
    if (s != fmi2LastSuccessfulTime || !value) {
        bgc_fmi_log(m, fmi2Discard, "fmi2GetRealStatus: only fmi2LastSuccessfulTime");
        return fmi2Discard;
    }
    *value = m->t;
    return fmi2OK;
}

BGC_FMI_EXPORT fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s,
                                               fmi2Integer *value)
{
    (void)s;
    (void)value;
    return bgc_fmi_no_status(c, "fmi2GetIntegerStatus", "no integer status");
}

BGC_FMI_EXPORT fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s,
                                               fmi2Boolean *value)
{
    bgc_fmi *m = bgc_fmi_get(c, "fmi2GetBooleanStatus", BGC_FMI_MASK_GetStatus, 2);
    if (!m)
        return fmi2Error;
    if (s != fmi2Terminated || !value) {
        bgc_fmi_log(m, fmi2Discard, "fmi2GetBooleanStatus: only fmi2Terminated");
        return fmi2Discard;
    }
    *value = fmi2False; /* the FMU never asks to end the simulation */
    return fmi2OK;
}

BGC_FMI_EXPORT fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s,
                                              fmi2String *value)
{
    (void)s;
    (void)value;
    return bgc_fmi_no_status(c, "fmi2GetStringStatus", "no string status");
}
