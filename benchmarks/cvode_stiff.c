/* The CVODE-C baseline of benchmarks/solvers.py: SUNDIALS CVODE driven from C, no Python in
   the loop, on its two stiff problems with the parameters of models/rc_pair.bg and
   models/van_der_pol.bg, the right sides and Jacobians written by hand:

     cvode_stiff rc|vdp MU RTOL ATOL T_END DT

   rc:  v' = A v + b, v the two capacitor voltages, A = [[-(a + b), b], [d, -d]],
        b = (V0 a, 0), a = 1/(R1 C1), b = 1/(R2 C1), d = 1/(R2 C2); v(0) = 0 (MU unused).
   vdp: Hairer's scaled Van der Pol, eps = 1/MU^2: y1' = y2, eps y2' = (1 - y1^2) y2 - y1;
        y(0) = (2, -2/3 + 10/81 eps).
   BDF with Newton's method, the dense linear solver and the analytic Jacobian, as the
   scikit-sundae baseline ("CVODE BDF") but without Python.  Writes t and the two states every
   DT to stdout as CSV (a header, then the rows; the solver interpolating: CV_NORMAL), DT =
   T_END writes two rows; to stderr "stats: steps= rejected= rhs= jac= lu= cpu=", cpu the
   clock() of the integration (CVodeInit to the last row). */
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

#define V0 1.0
#define R1 1e-6
#define C1 1.0
#define R2 1.0
#define C2 1.0

typedef struct {
    int vdp;
    double eps;
} Problem;

static int rhs(sunrealtype t, N_Vector y, N_Vector yd, void *user)
{
    const Problem *p = user;
    const double *s = N_VGetArrayPointer(y);
    double *d = N_VGetArrayPointer(yd);
    (void)t;
    if (p->vdp) {
        d[0] = s[1];
        d[1] = ((1.0 - s[0] * s[0]) * s[1] - s[0]) / p->eps;
    } else {
        const double a = 1.0 / (R1 * C1), b = 1.0 / (R2 * C1), c = 1.0 / (R2 * C2);
        d[0] = -(a + b) * s[0] + b * s[1] + V0 * a;
        d[1] = c * s[0] - c * s[1];
    }
    return 0;
}

static int jac(sunrealtype t, N_Vector y, N_Vector fy, SUNMatrix J, void *user, N_Vector t1,
               N_Vector t2, N_Vector t3)
{
    const Problem *p = user;
    const double *s = N_VGetArrayPointer(y);
    (void)t, (void)fy, (void)t1, (void)t2, (void)t3;
    if (p->vdp) {
        SM_ELEMENT_D(J, 0, 0) = 0.0;
        SM_ELEMENT_D(J, 0, 1) = 1.0;
        SM_ELEMENT_D(J, 1, 0) = (-2.0 * s[0] * s[1] - 1.0) / p->eps;
        SM_ELEMENT_D(J, 1, 1) = (1.0 - s[0] * s[0]) / p->eps;
    } else {
        const double a = 1.0 / (R1 * C1), b = 1.0 / (R2 * C1), c = 1.0 / (R2 * C2);
        SM_ELEMENT_D(J, 0, 0) = -(a + b);
        SM_ELEMENT_D(J, 0, 1) = b;
        SM_ELEMENT_D(J, 1, 0) = c;
        SM_ELEMENT_D(J, 1, 1) = -c;
    }
    return 0;
}

int main(int argc, char **argv)
{
    if (argc < 7) {
        fprintf(stderr, "usage: %s rc|vdp MU RTOL ATOL T_END DT\n", argv[0]);
        return 2;
    }
    Problem p;
    p.vdp = strcmp(argv[1], "vdp") == 0;
    const double mu = atof(argv[2]), rtol = atof(argv[3]), atol = atof(argv[4]),
                 t_end = atof(argv[5]), dt = atof(argv[6]);
    p.eps = 1.0 / (mu * mu);

    SUNContext ctx;
    if (SUNContext_Create(NULL, &ctx))
        return 1;
    N_Vector y = N_VNew_Serial(2, ctx);
    double *s = N_VGetArrayPointer(y);
    s[0] = p.vdp ? 2.0 : 0.0;
    s[1] = p.vdp ? -2.0 / 3.0 + 10.0 / 81.0 * p.eps : 0.0;
    printf("t,y1,y2\n%.17g,%.17g,%.17g\n", 0.0, s[0], s[1]);
    clock_t start = clock();
    void *mem = CVodeCreate(CV_BDF, ctx);
    CVodeInit(mem, rhs, 0.0, y);
    CVodeSStolerances(mem, rtol, atol);
    CVodeSetUserData(mem, &p);
    CVodeSetMaxNumSteps(mem, -1); /* no step budget */
    SUNMatrix A = SUNDenseMatrix(2, 2, ctx);
    SUNLinearSolver LS = SUNLinSol_Dense(y, A, ctx);
    CVodeSetLinearSolver(mem, LS, A);
    CVodeSetJacFn(mem, jac);
    double t = 0.0;
    int status = 0;
    const long rows = (long)ceil(t_end / dt - 1e-6);
    for (long i = 1; i <= rows && !status; i++) {
        const double tout = i == rows ? t_end : i * dt;
        while (t < tout) {
            const int flag = CVode(mem, tout, y, &t, CV_NORMAL);
            if (flag < 0) {
                fprintf(stderr, "error: CVode returned %d at t = %.17g\n", flag, t);
                status = 1;
                break;
            }
        }
        printf("%.17g,%.17g,%.17g\n", t, s[0], s[1]);
    }
    const double cpu = (double)(clock() - start) / CLOCKS_PER_SEC;
    long steps = 0, etf = 0, ncf = 0, nfe = 0, nfl = 0, nje = 0, nsetups = 0;
    CVodeGetNumSteps(mem, &steps);
    CVodeGetNumErrTestFails(mem, &etf);
    CVodeGetNumNonlinSolvConvFails(mem, &ncf);
    CVodeGetNumRhsEvals(mem, &nfe);
    CVodeGetNumLinRhsEvals(mem, &nfl);
    CVodeGetNumJacEvals(mem, &nje);
    CVodeGetNumLinSolvSetups(mem, &nsetups);
    fprintf(stderr, "stats: steps=%ld rejected=%ld rhs=%ld jac=%ld lu=%ld cpu=%e\n", steps,
            etf + ncf, nfe + nfl, nje, nsetups, cpu);
    CVodeFree(&mem);
    SUNLinSolFree(LS);
    SUNMatDestroy(A);
    N_VDestroy(y);
    SUNContext_Free(&ctx);
    return status;
}
