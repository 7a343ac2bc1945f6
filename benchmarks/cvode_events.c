/* The CVODE baseline of benchmarks/events.py: SUNDIALS CVODE driven from C, no Python in
   the loop, on the two problems of the benchmark with the parameters of
   benchmarks/models/pwm_rl.bg and benchmarks/models/bouncing_ball.bg.

     cvode_events pwm|ball bdf|adams stop|root RTOL ATOL T_END DT [EVENTS_FILE]

   pwm:  L di/dt = V u(t) - R i, the state l.p = L i; u the square wave, 1 on
         [k T, (k + D) T), its edges k T and (k + D) T computed as bgc computes them.
         stop: CVodeSetStopTime at each edge, then CVodeReInit with the new input (the solver
               never sees the discontinuity);
         root: CVodeRootInit with g = t - (the next edge), the input frozen in between; at a
               root return the input switches and CVodeReInit restarts there.
   ball: x' = p/m, p' = -m g; CVodeRootInit with g = x, direction -1; at a root return
         p = -e p and CVodeReInit (stop is the same as root: the impacts are not known).
   bdf: CV_BDF with Newton's method and the dense linear solver, the analytic Jacobian;
   adams: CV_ADAMS with the fixed-point iteration (no Jacobian).

   Writes t and the state (a header, then l.p, or x and b.p) every DT to stdout as CSV (as
   bgc's programs do, the solver interpolating: CV_NORMAL), DT = T_END writes two rows; the
   event times to EVENTS_FILE (one a line, %.17g); and to stderr "stats: steps= rejected=
   rhs= jac= lu= events= cpu=", the counters summed over the restarts (rejected: error test
   and convergence failures; rhs: with the linear solver's), cpu the clock() of the
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

#define V 12.0
#define R 2.0
#define L 0.01
#define PERIOD 0.001
#define DUTY 0.3
#define M 1.0
#define G 9.81
#define E 0.8
#define H0 1.0

typedef struct {
    int ball;
    double u;    /* pwm: the input, 0 or 1 */
    double next; /* pwm: the next edge */
    double k;    /* pwm: the period of the next edge */
    int up;      /* pwm: the next edge is a rising one */
} Data;

static int rhs(sunrealtype t, N_Vector y, N_Vector yd, void *user)
{
    Data *d = user;
    double *s = N_VGetArrayPointer(y), *ds = N_VGetArrayPointer(yd);
    (void)t;
    if (d->ball) {
        ds[0] = s[1] / M;
        ds[1] = -M * G;
    } else {
        ds[0] = V * d->u - R * s[0] / L;
    }
    return 0;
}

static int jac(sunrealtype t, N_Vector y, N_Vector fy, SUNMatrix J, void *user,
               N_Vector t1, N_Vector t2, N_Vector t3)
{
    Data *d = user;
    (void)t, (void)y, (void)fy, (void)t1, (void)t2, (void)t3;
    if (d->ball) {
        SM_ELEMENT_D(J, 0, 0) = 0.0;
        SM_ELEMENT_D(J, 0, 1) = 1.0 / M;
        SM_ELEMENT_D(J, 1, 0) = 0.0;
        SM_ELEMENT_D(J, 1, 1) = 0.0;
    } else {
        SM_ELEMENT_D(J, 0, 0) = -R / L;
    }
    return 0;
}

static int roots(sunrealtype t, N_Vector y, sunrealtype *g, void *user)
{
    Data *d = user;
    g[0] = d->ball ? N_VGetArrayPointer(y)[0] : t - d->next;
    return 0;
}

/* The edge after the one at d->next: the input after it, as bgc's square(period, duty). */
static void advance(Data *d)
{
    if (d->up) {
        d->u = 1.0;
        d->next = (d->k + DUTY) * PERIOD;
        d->up = 0;
    } else {
        d->u = 0.0;
        d->k += 1.0;
        d->next = d->k * PERIOD;
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

static void row(double t, N_Vector y, int n)
{
    double *s = N_VGetArrayPointer(y);
    printf("%.17g", t);
    for (int i = 0; i < n; i++)
        printf(",%.17g", s[i]);
    putchar('\n');
}

int main(int argc, char **argv)
{
    if (argc < 8) {
        fprintf(stderr, "usage: %s pwm|ball bdf|adams stop|root RTOL ATOL T_END DT "
                        "[EVENTS_FILE]\n", argv[0]);
        return 2;
    }
    Data d = {0};
    d.ball = strcmp(argv[1], "ball") == 0;
    int bdf = strcmp(argv[2], "bdf") == 0;
    int use_roots = d.ball || strcmp(argv[3], "root") == 0;
    double rtol = atof(argv[4]), atol = atof(argv[5]), t_end = atof(argv[6]),
           dt = atof(argv[7]);
    FILE *log = argc > 8 ? fopen(argv[8], "w") : NULL;
    int n = d.ball ? 2 : 1;

    SUNContext ctx;
    if (SUNContext_Create(NULL, &ctx))
        return 1;
    N_Vector y = N_VNew_Serial(n, ctx);
    double *s = N_VGetArrayPointer(y);
    if (d.ball) {
        s[0] = H0;
        s[1] = 0.0;
    } else {
        s[0] = 0.0;
        d.u = 1.0; /* square(period, duty) is 1 from t = 0 */
        d.up = 1;
        d.k = 0.0;
        d.next = DUTY * PERIOD;
        d.up = 0;
    }
    void *mem = CVodeCreate(bdf ? CV_BDF : CV_ADAMS, ctx);
    SUNMatrix A = NULL;
    SUNLinearSolver LS = NULL;
    SUNNonlinearSolver NLS = NULL;
    CVodeInit(mem, rhs, 0.0, y);
    CVodeSStolerances(mem, rtol, atol);
    CVodeSetUserData(mem, &d);
    CVodeSetMaxNumSteps(mem, -1); /* no step budget */
    if (bdf) {
        A = SUNDenseMatrix(n, n, ctx);
        LS = SUNLinSol_Dense(y, A, ctx);
        CVodeSetLinearSolver(mem, LS, A);
        CVodeSetJacFn(mem, jac);
    } else {
        NLS = SUNNonlinSol_FixedPoint(y, 0, ctx);
        CVodeSetNonlinearSolver(mem, NLS);
    }
    if (use_roots) {
        int direction = -1;
        CVodeRootInit(mem, 1, roots);
        if (d.ball)
            CVodeSetRootDirection(mem, &direction);
    } else {
        CVodeSetStopTime(mem, d.next);
    }

    Counts c = {0};
    long events = 0;
    double t = 0.0;
    long rows = (long)ceil(t_end / dt - 1e-6);
    int status = 0;
    clock_t start = clock();
    puts(d.ball ? "t,x,b.p" : "t,l.p");
    row(0.0, y, n);
    for (long i = 1; i <= rows && !status; i++) {
        double tout = i == rows ? t_end : i * dt;
        while (t < tout) {
            int flag = CVode(mem, tout, y, &t, CV_NORMAL);
            if (flag < 0) {
                fprintf(stderr, "error: CVode returned %d at t = %.17g\n", flag, t);
                status = 1;
                break;
            }
            if (flag == CV_ROOT_RETURN || flag == CV_TSTOP_RETURN) {
                events++;
                if (log)
                    fprintf(log, "%.17g\n", t);
                if (d.ball) {
                    s[1] = -E * s[1];
                } else {
                    advance(&d);
                }
                add_counts(mem, &c, bdf);
                CVodeReInit(mem, t, y);
                if (!use_roots && d.next <= t_end)
                    CVodeSetStopTime(mem, d.next);
            }
        }
        row(t, y, n);
    }
    double cpu = (double)(clock() - start) / CLOCKS_PER_SEC;
    add_counts(mem, &c, bdf);
    fprintf(stderr, "stats: steps=%ld rejected=%ld rhs=%ld jac=%ld lu=%ld events=%ld "
                    "cpu=%e\n", c.steps, c.rejected, c.rhs, c.jac, c.lu, events, cpu);
    if (log)
        fclose(log);
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
