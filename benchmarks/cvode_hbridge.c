/* The CVODE baseline of benchmarks/hbridge.py: SUNDIALS CVODE driven from C, no Python in
   the loop, on the H-bridge PWM drive of tests/models/hbridge.bg (four ideal switches, each
   with its anti-parallel ideal diode, with dead time, driving a DC motor), with root finding
   for its events.

     cvode_hbridge bdf|adams RTOL ATOL T_END DT V F DUTY DEAD R L K J B

   The states are those of the model: motor.ind.p = L i and motor.rotor.p = J w.  The bridge
   applies v to the motor, L di/dt = v - R i - k w, J dw/dt = k i - b w, in four modes:
     pos   s1 and s4 closed:                      v = V
     neg   s2 and s3 closed:                      v = -V
     dead  all four open, two diodes conducting:  v = -V while i > 0, +V while i < 0
     held  all four open, the current at zero:    di/dt = 0 (the diodes block)
   s1 and s4 follow square(1/F, DUTY), s2 and s3 square(1/F, 1 - DUTY - 2 DEAD, (DUTY + DEAD)/F),
   their edges computed as bgc's square(period, duty, t0) computes them (t0 + (k + duty)
   period, t0 + (k + 1) period), the three arguments as the generated program computes them.
   Root functions: g0 = t - (the next edge of either wave), g1 = i in the dead mode (the
   current reaching zero: it is then set to 0 and the mode is held).  At every root
   CVodeReInit restarts there.  bdf: Newton with the dense linear solver and the analytic
   Jacobian; adams: the fixed-point iteration.

   Writes t, motor.ind.p and motor.rotor.p every DT to stdout as CSV (CV_NORMAL: the solver
   interpolating), DT = T_END writes two rows; to stderr "stats: steps= rejected= rhs= jac=
   lu= events= cpu=", the counters summed over the restarts, cpu the clock() of the
   integration. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include <cvode/cvode.h>
#include <nvector/nvector_serial.h>
#include <sundials/sundials_context.h>
#include <sunlinsol/sunlinsol_dense.h>
#include <sunmatrix/sunmatrix_dense.h>
#include <sunnonlinsol/sunnonlinsol_fixedpoint.h>

enum { POS, NEG, DEAD, HELD };

/* One square wave: its arguments, the period k of its next edge, whether it is on (after
   the edge last passed) and the time of its next edge. */
typedef struct {
    double period, duty, t0, k, next;
    int on;
} Wave;

typedef struct {
    double V, R, L, k, J, b;
    Wave w[2]; /* s1 and s4; s2 and s3 */
    int mode;
} Data;

static void wave_start(Wave *w, double period, double duty, double t0)
{
    w->period = period, w->duty = duty, w->t0 = t0, w->k = 0.0;
    w->on = !(0.0 < t0);
    w->next = w->on ? t0 + (w->k + duty) * period : t0;
}

/* Past the wave's edge at w->next: its new value and the edge after, as square_next. */
static void wave_advance(Wave *w)
{
    if (w->on) {
        w->on = 0;
        w->k += 1.0;
        w->next = w->t0 + w->k * w->period;
    } else {
        w->on = 1;
        w->next = w->t0 + (w->k + w->duty) * w->period;
    }
}

/* The bridge's mode from the switches and the current. */
static int mode_of(const Data *d, double p)
{
    if (d->w[0].on)
        return POS;
    if (d->w[1].on)
        return NEG;
    return p == 0.0 ? HELD : DEAD;
}

static int rhs(sunrealtype t, N_Vector y, N_Vector yd, void *user)
{
    Data *d = user;
    double *s = N_VGetArrayPointer(y), *ds = N_VGetArrayPointer(yd);
    double i = s[0] / d->L, w = s[1] / d->J;
    double v = d->mode == POS ? d->V : d->mode == NEG ? -d->V : i > 0.0 ? -d->V : d->V;
    (void)t;
    ds[0] = d->mode == HELD ? 0.0 : v - d->R * i - d->k * w;
    ds[1] = d->k * i - d->b * w;
    return 0;
}

static int jac(sunrealtype t, N_Vector y, N_Vector fy, SUNMatrix J, void *user,
               N_Vector t1, N_Vector t2, N_Vector t3)
{
    Data *d = user;
    int held = d->mode == HELD;
    (void)t, (void)y, (void)fy, (void)t1, (void)t2, (void)t3;
    SM_ELEMENT_D(J, 0, 0) = held ? 0.0 : -d->R / d->L;
    SM_ELEMENT_D(J, 0, 1) = held ? 0.0 : -d->k / d->J;
    SM_ELEMENT_D(J, 1, 0) = d->k / d->L;
    SM_ELEMENT_D(J, 1, 1) = -d->b / d->J;
    return 0;
}

static int roots(sunrealtype t, N_Vector y, sunrealtype *g, void *user)
{
    Data *d = user;
    g[0] = t - fmin(d->w[0].next, d->w[1].next);
    g[1] = d->mode == DEAD ? N_VGetArrayPointer(y)[0] : 1.0;
    return 0;
}

typedef struct {
    long steps, rejected, rhs, jac, lu;
} Counts;

static void add_counts(void *mem, Counts *c, int bdf)
{
    long v = 0, w = 0;
    CVodeGetNumSteps(mem, &v);
    c->steps += v;
    CVodeGetNumErrTestFails(mem, &v);
    CVodeGetNumNonlinSolvConvFails(mem, &w);
    c->rejected += v + w;
    CVodeGetNumRhsEvals(mem, &v);
    c->rhs += v;
    if (bdf) {
        CVodeGetNumJacEvals(mem, &v);
        c->jac += v;
        CVodeGetNumLinSolvSetups(mem, &v);
        c->lu += v;
        CVodeGetNumLinRhsEvals(mem, &v);
        c->rhs += v;
    }
}

static void row(double t, N_Vector y)
{
    double *s = N_VGetArrayPointer(y);
    printf("%.17g,%.17g,%.17g\n", t, s[0], s[1]);
}

int main(int argc, char **argv)
{
    if (argc < 15) {
        fprintf(stderr, "usage: %s bdf|adams RTOL ATOL T_END DT V F DUTY DEAD R L K J B\n",
                argv[0]);
        return 2;
    }
    int bdf = strcmp(argv[1], "bdf") == 0;
    double rtol = atof(argv[2]), atol = atof(argv[3]), t_end = atof(argv[4]),
           dt = atof(argv[5]);
    double f = atof(argv[7]), duty = atof(argv[8]), dead = atof(argv[9]);
    Data d;
    memset(&d, 0, sizeof d);
    d.V = atof(argv[6]), d.R = atof(argv[10]), d.L = atof(argv[11]), d.k = atof(argv[12]),
    d.J = atof(argv[13]), d.b = atof(argv[14]);
    /* the arguments as the generated program computes them */
    double period = 1.0 / f;
    wave_start(&d.w[0], period, duty, 0.0);
    wave_start(&d.w[1], period, -duty - 2.0 * dead + 1.0, (duty + dead) / f);

    SUNContext ctx;
    if (SUNContext_Create(NULL, &ctx))
        return 1;
    N_Vector y = N_VNew_Serial(2, ctx);
    double *s = N_VGetArrayPointer(y);
    s[0] = s[1] = 0.0;
    d.mode = mode_of(&d, s[0]);
    void *mem = CVodeCreate(bdf ? CV_BDF : CV_ADAMS, ctx);
    SUNMatrix A = NULL;
    SUNLinearSolver LS = NULL;
    SUNNonlinearSolver NLS = NULL;
    CVodeInit(mem, rhs, 0.0, y);
    CVodeSStolerances(mem, rtol, atol);
    CVodeSetUserData(mem, &d);
    CVodeSetMaxNumSteps(mem, -1);
    if (bdf) {
        A = SUNDenseMatrix(2, 2, ctx);
        LS = SUNLinSol_Dense(y, A, ctx);
        CVodeSetLinearSolver(mem, LS, A);
        CVodeSetJacFn(mem, jac);
    } else {
        NLS = SUNNonlinSol_FixedPoint(y, 0, ctx);
        CVodeSetNonlinearSolver(mem, NLS);
    }
    int directions[2] = {1, 0};
    CVodeRootInit(mem, 2, roots);
    CVodeSetRootDirection(mem, directions);

    Counts c = {0};
    long events = 0;
    double t = 0.0;
    long rows = (long)ceil(t_end / dt - 1e-6);
    int status = 0;
    clock_t start = clock();
    puts("t,motor.ind.p,motor.rotor.p");
    row(0.0, y);
    for (long r = 1; r <= rows && !status; r++) {
        double tout = r == rows ? t_end : r * dt;
        while (t < tout) {
            int flag = CVode(mem, tout, y, &t, CV_NORMAL);
            if (flag < 0) {
                fprintf(stderr, "error: CVode returned %d at t = %.17g\n", flag, t);
                status = 1;
                break;
            }
            if (flag == CV_ROOT_RETURN) {
                int found[2] = {0, 0};
                CVodeGetRootInfo(mem, found);
                events++;
                if (found[1])
                    s[0] = 0.0;
                if (found[0])
                    wave_advance(&d.w[d.w[1].next < d.w[0].next]);
                d.mode = mode_of(&d, s[0]);
                add_counts(mem, &c, bdf);
                CVodeReInit(mem, t, y);
            }
        }
        row(t, y);
    }
    double cpu = (double)(clock() - start) / CLOCKS_PER_SEC;
    add_counts(mem, &c, bdf);
    fprintf(stderr, "stats: steps=%ld rejected=%ld rhs=%ld jac=%ld lu=%ld events=%ld "
                    "cpu=%e\n", c.steps, c.rejected, c.rhs, c.jac, c.lu, events, cpu);
    CVodeFree(&mem);
    if (LS)
        SUNLinSolFree(LS);
    if (A)
        SUNMatDestroy(A);
    if (NLS)
        SUNNonlinSolFree(NLS);
    N_VDestroy(y);
    SUNContext_Free(&ctx);
    return status;
}
