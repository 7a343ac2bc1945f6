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
