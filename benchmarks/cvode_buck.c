/* The CVODE baseline of benchmarks/switched.py: SUNDIALS CVODE driven from C, no Python in
   the loop, on the buck converter of models/buck.bg (an ideal switch, a freewheeling ideal
   diode, L, C parallel to R), with root finding for its events.

     cvode_buck bdf|adams RTOL ATOL T_END DT V L C R PERIOD DUTY

   The states are those of the model: l.p = L i and c.q = C v.  Three modes, the circuit
   linear in each:
     on   the switch closed (the diode blocks):   L di/dt = V - v
     off  the switch open, the diode conducting:  L di/dt = -v
     dcm  both open (i = 0, discontinuous conduction): di/dt = 0
   and C dv/dt = i - v/R in all.  Root functions: g0 = t - (the next edge of the square wave,
   computed as bgc's square(period, duty) computes it), g1 = i in the off mode (direction -1:
   the diode stops conducting; i is then set to 0 and the mode is dcm).  At every root
   CVodeReInit restarts there.  bdf: Newton with the dense linear solver and the analytic
   Jacobian; adams: the fixed-point iteration.

   Writes t, l.p and c.q every DT to stdout as CSV (CV_NORMAL: the solver interpolating), DT =
   T_END writes two rows; to stderr "stats: steps= rejected= rhs= jac= lu= events= cpu=", the
   counters summed over the restarts, cpu the clock() of the integration. */
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

enum { ON, OFF, DCM };

typedef struct {
    double V, L, C, R, period, duty;
    int mode;
    double next; /* the next edge */
    double k;    /* the period of the next edge */
    int up;      /* the next edge is a rising one */
} Data;

static int rhs(sunrealtype t, N_Vector y, N_Vector yd, void *user)
{
    Data *d = user;
    double *s = N_VGetArrayPointer(y), *ds = N_VGetArrayPointer(yd);
    double i = s[0] / d->L, v = s[1] / d->C;
    (void)t;
    ds[0] = d->mode == ON ? d->V - v : d->mode == OFF ? -v : 0.0;
    ds[1] = i - v / d->R;
    return 0;
}

static int jac(sunrealtype t, N_Vector y, N_Vector fy, SUNMatrix J, void *user,
               N_Vector t1, N_Vector t2, N_Vector t3)
{
    Data *d = user;
    (void)t, (void)y, (void)fy, (void)t1, (void)t2, (void)t3;
    SM_ELEMENT_D(J, 0, 0) = 0.0;
    SM_ELEMENT_D(J, 0, 1) = d->mode == DCM ? 0.0 : -1.0 / d->C;
    SM_ELEMENT_D(J, 1, 0) = 1.0 / d->L;
    SM_ELEMENT_D(J, 1, 1) = -1.0 / (d->R * d->C);
    return 0;
}

static int roots(sunrealtype t, N_Vector y, sunrealtype *g, void *user)
{
    Data *d = user;
    g[0] = t - d->next;
    g[1] = d->mode == OFF ? N_VGetArrayPointer(y)[0] : 1.0;
    return 0;
}

/* Past the edge at d->next: the switch's new mode and the edge after, as square(). */
static void advance(Data *d, double p)
{
    if (d->up) {
        d->mode = ON;
        d->next = (d->k + d->duty) * d->period;
        d->up = 0;
    } else {
        d->mode = p > 0.0 ? OFF : DCM;
        d->k += 1.0;
        d->next = d->k * d->period;
        d->up = 1;
    }
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
    if (argc < 12) {
        fprintf(stderr, "usage: %s bdf|adams RTOL ATOL T_END DT V L C R PERIOD DUTY\n",
                argv[0]);
        return 2;
    }
    int bdf = strcmp(argv[1], "bdf") == 0;
    double rtol = atof(argv[2]), atol = atof(argv[3]), t_end = atof(argv[4]),
           dt = atof(argv[5]);
    Data d = {atof(argv[6]), atof(argv[7]), atof(argv[8]), atof(argv[9]), atof(argv[10]),
              atof(argv[11]), ON, 0.0, 0.0, 0};
    d.next = d.duty * d.period; /* square(period, duty) is 1 from t = 0: on */

    SUNContext ctx;
    if (SUNContext_Create(NULL, &ctx))
        return 1;
    N_Vector y = N_VNew_Serial(2, ctx);
    double *s = N_VGetArrayPointer(y);
    s[0] = s[1] = 0.0;
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
    int directions[2] = {1, -1};
    CVodeRootInit(mem, 2, roots);
    CVodeSetRootDirection(mem, directions);

    Counts c = {0};
    long events = 0;
    double t = 0.0;
    long rows = (long)ceil(t_end / dt - 1e-6);
    int status = 0;
    clock_t start = clock();
    puts("t,l.p,c.q");
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
                if (found[0]) {
                    advance(&d, s[0]);
                } else if (found[1]) {
                    d.mode = DCM;
                    s[0] = 0.0;
                }
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
