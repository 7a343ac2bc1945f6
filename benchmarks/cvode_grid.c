/* The CVODE baseline of benchmarks/stiff_scale.py: SUNDIALS CVODE driven from C, no Python in
   the loop, on the n x n thermal RC grid of benchmarks/families.py (thermal_grid), its right
   side written by hand from the grid's formula (cell k = i n + j, 0-based row i, column j):

     c dT_k/dt = q_in [k = 0] + sum over the neighbours m of (T_m - T_k)/r - T_k/rb [j = n - 1]

   with c = 1, r = 1, rb = 2, q_in = 1 and T_k(0) = 1 + sin(k + 1), as the model's defaults.

     cvode_grid N dense|band|klu RTOL ATOL T_END

   BDF with Newton's method and the Jacobian written by hand (constant: the grid's
   conductances), in the form the linear solver takes: dense (SUNDenseMatrix, LAPACK-free LU),
   band (SUNBandMatrix with half-bandwidths N, banded LU) or klu (SUNSparseMatrix in CSC, KLU).
   Writes the state at T_END as CSV (a header, then t and the N^2 temperatures) to stdout, and
   to stderr "stats: steps= rejected= rhs= jac= lu= cpu=", cpu the clock() of the integration
   (CVodeInit to the last CVode call; building the matrix and the solver included). */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include <cvode/cvode.h>
#include <nvector/nvector_serial.h>
#include <sundials/sundials_context.h>
#include <sunlinsol/sunlinsol_band.h>
#include <sunlinsol/sunlinsol_dense.h>
#include <sunlinsol/sunlinsol_klu.h>
#include <sunmatrix/sunmatrix_band.h>
#include <sunmatrix/sunmatrix_dense.h>
#include <sunmatrix/sunmatrix_sparse.h>

#define CAP 1.0
#define RES 1.0
#define RB 2.0
#define QIN 1.0

enum { DENSE, BAND, KLU };

typedef struct {
    int n, kind;
} Grid;

static int rhs(sunrealtype t, N_Vector y, N_Vector yd, void *user)
{
    const Grid *g = user;
    const int n = g->n;
    const double *T = N_VGetArrayPointer(y);
    double *d = N_VGetArrayPointer(yd);
    (void)t;
    for (int i = 0; i < n; i++)
        for (int j = 0; j < n; j++) {
            const int k = i * n + j;
            double acc = 0.0;
            if (j + 1 < n)
                acc += (T[k + 1] - T[k]) / RES;
            if (j > 0)
                acc += (T[k - 1] - T[k]) / RES;
            if (i + 1 < n)
                acc += (T[k + n] - T[k]) / RES;
            if (i > 0)
                acc += (T[k - n] - T[k]) / RES;
            if (j == n - 1)
                acc -= T[k] / RB;
            if (k == 0)
                acc += QIN;
            d[k] = acc / CAP;
        }
    return 0;
}

/* The neighbours of cell k (in ascending order) with J's entries, the diagonal among them. */
static int column(int n, int k, int *rows, double *vals)
{
    const int i = k / n, j = k % n;
    int m = 0;
    double diag = 0.0;
    if (i > 0) {
        rows[m] = k - n;
        vals[m++] = 1.0 / (RES * CAP);
        diag -= 1.0 / (RES * CAP);
    }
    if (j > 0) {
        rows[m] = k - 1;
        vals[m++] = 1.0 / (RES * CAP);
        diag -= 1.0 / (RES * CAP);
    }
    const int at = m++;
    if (j + 1 < n) {
        rows[m] = k + 1;
        vals[m++] = 1.0 / (RES * CAP);
        diag -= 1.0 / (RES * CAP);
    }
    if (i + 1 < n) {
        rows[m] = k + n;
        vals[m++] = 1.0 / (RES * CAP);
        diag -= 1.0 / (RES * CAP);
    }
    if (j == n - 1)
        diag -= 1.0 / (RB * CAP);
    rows[at] = k;
    vals[at] = diag;
    return m;
}

static int jac(sunrealtype t, N_Vector y, N_Vector fy, SUNMatrix J, void *user, N_Vector t1,
               N_Vector t2, N_Vector t3)
{
    const Grid *g = user;
    const int n = g->n, size = n * n;
    int rows[5];
    double vals[5];
    (void)t, (void)y, (void)fy, (void)t1, (void)t2, (void)t3;
    if (g->kind == KLU) { /* J is symmetric in structure: column k holds column()'s rows */
        sunindextype *ptr = SUNSparseMatrix_IndexPointers(J);
        sunindextype *idx = SUNSparseMatrix_IndexValues(J);
        double *data = SUNSparseMatrix_Data(J);
        sunindextype q = 0;
        for (int k = 0; k < size; k++) {
            const int m = column(n, k, rows, vals);
            ptr[k] = q;
            for (int l = 0; l < m; l++) {
                idx[q] = rows[l];
                data[q++] = vals[l];
            }
        }
        ptr[size] = q;
        return 0;
    }
    SUNMatZero(J);
    for (int k = 0; k < size; k++) {
        const int m = column(n, k, rows, vals);
        for (int l = 0; l < m; l++) {
            if (g->kind == BAND)
                SM_ELEMENT_B(J, rows[l], k) = vals[l];
            else
                SM_ELEMENT_D(J, rows[l], k) = vals[l];
        }
    }
    return 0;
}

int main(int argc, char **argv)
{
    if (argc < 6) {
        fprintf(stderr, "usage: %s N dense|band|klu RTOL ATOL T_END\n", argv[0]);
        return 2;
    }
    Grid g;
    g.n = atoi(argv[1]);
    g.kind = strcmp(argv[2], "band") == 0 ? BAND : strcmp(argv[2], "klu") == 0 ? KLU : DENSE;
    const double rtol = atof(argv[3]), atol = atof(argv[4]), t_end = atof(argv[5]);
    const int size = g.n * g.n;

    SUNContext ctx;
    if (SUNContext_Create(NULL, &ctx))
        return 1;
    N_Vector y = N_VNew_Serial(size, ctx);
    double *T = N_VGetArrayPointer(y);
    for (int k = 0; k < size; k++)
        T[k] = 1.0 + sin((double)(k + 1));

    clock_t start = clock();
    void *mem = CVodeCreate(CV_BDF, ctx);
    CVodeInit(mem, rhs, 0.0, y);
    CVodeSStolerances(mem, rtol, atol);
    CVodeSetUserData(mem, &g);
    CVodeSetMaxNumSteps(mem, -1); /* no step budget */
    SUNMatrix A;
    SUNLinearSolver LS;
    if (g.kind == KLU) {
        A = SUNSparseMatrix(size, size, 5 * (sunindextype)size, CSC_MAT, ctx);
        LS = SUNLinSol_KLU(y, A, ctx);
    } else if (g.kind == BAND) {
        A = SUNBandMatrix(size, g.n, g.n, ctx);
        LS = SUNLinSol_Band(y, A, ctx);
    } else {
        A = SUNDenseMatrix(size, size, ctx);
        LS = SUNLinSol_Dense(y, A, ctx);
    }
    if (!A || !LS) {
        fprintf(stderr, "error: cannot create the linear solver\n");
        return 1;
    }
    CVodeSetLinearSolver(mem, LS, A);
    CVodeSetJacFn(mem, jac);
    double t = 0.0;
    int status = 0;
    while (t < t_end) {
        const int flag = CVode(mem, t_end, y, &t, CV_NORMAL);
        if (flag < 0) {
            fprintf(stderr, "error: CVode returned %d at t = %.17g\n", flag, t);
            status = 1;
            break;
        }
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
    printf("t");
    for (int k = 0; k < size; k++)
        printf(",T%d", k + 1);
    printf("\n%.17g", t);
    for (int k = 0; k < size; k++)
        printf(",%.17g", T[k]);
    printf("\n");
    fprintf(stderr, "stats: steps=%ld rejected=%ld rhs=%ld jac=%ld lu=%ld cpu=%e\n", steps,
            etf + ncf, nfe + nfl, nje, nsetups, cpu);
    CVodeFree(&mem);
    SUNLinSolFree(LS);
    SUNMatDestroy(A);
    N_VDestroy(y);
    SUNContext_Free(&ctx);
    return status;
}
