/* ============================================================== stiff === */
/* The stiff families: Rosenbrock methods in Hairer's transformed form (RODAS's design, any
   tableau of the family) and Radau IIA of order 5 (RADAU5's design), both with the Jacobian
   that bgc_jacobian derives symbolically and dense LU factorisations of their own (below). */
#include <complex.h>
#undef I /* C99 7.3.1: the program may undefine it; _Complex_I is used below */
#undef complex

typedef double _Complex bgc_cplx;

/* ------------------------------------------------------ dense linear algebra --- */

/* LU factorisation with partial pivoting of the n x n row-major matrix a, in place (L below
   the diagonal with a unit diagonal, U on and above it); piv[k]: the row swapped with row k.
   Returns 0, or k + 1 when column k has no nonzero pivot (a singular matrix; NaNs go through,
   as in LAPACK, and show as non-finite stages). */
static int bgc_stiff_lu(int n, double *a, int *piv)
{
    int i, j, k;
    for (k = 0; k < n; k++) {
        double *ak = a + (size_t)k * n, big = fabs(ak[k]);
        int p = k;
        for (i = k + 1; i < n; i++)
            if (fabs(a[(size_t)i * n + k]) > big) {
                big = fabs(a[(size_t)i * n + k]);
                p = i;
            }
        piv[k] = p;
        if (big == 0.0)
            return k + 1;
        if (p != k) {
            double *ap = a + (size_t)p * n;
            for (j = 0; j < n; j++) {
                const double tmp = ak[j];
                ak[j] = ap[j];
                ap[j] = tmp;
            }
        }
        for (i = k + 1; i < n; i++) {
            double *ai = a + (size_t)i * n;
            const double l = ai[k] / ak[k];
            ai[k] = l;
            if (l != 0.0)
                for (j = k + 1; j < n; j++)
                    ai[j] -= l * ak[j];
        }
    }
    return 0;
}

/* Solves with the factors of bgc_stiff_lu: b is overwritten by the solution. */
static void bgc_stiff_lu_solve(int n, const double *lu, const int *piv, double *b)
{
    int i, k;
    /* the factorisation swapped whole rows (multipliers included): all the swaps first,
       then L y = P b */
    for (k = 0; k < n; k++) {
        const double bk = b[piv[k]];
        b[piv[k]] = b[k];
        b[k] = bk;
    }
    for (k = 0; k < n; k++) {
        const double bk = b[k];
        if (bk != 0.0)
            for (i = k + 1; i < n; i++)
                b[i] -= lu[(size_t)i * n + k] * bk;
    }
    for (k = n - 1; k >= 0; k--) {
        const double *row = lu + (size_t)k * n;
        double acc = b[k];
        for (i = k + 1; i < n; i++)
            acc -= row[i] * b[i];
        b[k] = acc / row[k];
    }
}

/* The same for a complex matrix (pivots by |re| + |im|). */
static double bgc_cabs1(bgc_cplx z)
{
    return fabs(creal(z)) + fabs(cimag(z));
}

static int bgc_stiff_zlu(int n, bgc_cplx *a, int *piv)
{
    int i, j, k;
    for (k = 0; k < n; k++) {
        bgc_cplx *ak = a + (size_t)k * n;
        double big = bgc_cabs1(ak[k]);
        int p = k;
        for (i = k + 1; i < n; i++)
            if (bgc_cabs1(a[(size_t)i * n + k]) > big) {
                big = bgc_cabs1(a[(size_t)i * n + k]);
                p = i;
            }
        piv[k] = p;
        if (big == 0.0)
            return k + 1;
        if (p != k) {
            bgc_cplx *ap = a + (size_t)p * n;
            for (j = 0; j < n; j++) {
                const bgc_cplx tmp = ak[j];
                ak[j] = ap[j];
                ap[j] = tmp;
            }
        }
        for (i = k + 1; i < n; i++) {
            bgc_cplx *ai = a + (size_t)i * n;
            const bgc_cplx l = ai[k] / ak[k];
            ai[k] = l;
            if (l != 0.0)
                for (j = k + 1; j < n; j++)
                    ai[j] -= l * ak[j];
        }
    }
    return 0;
}

static void bgc_stiff_zlu_solve(int n, const bgc_cplx *lu, const int *piv, bgc_cplx *b)
{
    int i, k;
    /* the factorisation swapped whole rows (multipliers included): all the swaps first,
       then L y = P b */
    for (k = 0; k < n; k++) {
        const bgc_cplx bk = b[piv[k]];
        b[piv[k]] = b[k];
        b[k] = bk;
    }
    for (k = 0; k < n; k++) {
        const bgc_cplx bk = b[k];
        if (bk != 0.0)
            for (i = k + 1; i < n; i++)
                b[i] -= lu[(size_t)i * n + k] * bk;
    }
    for (k = n - 1; k >= 0; k--) {
        const bgc_cplx *row = lu + (size_t)k * n;
        bgc_cplx acc = b[k];
        for (i = k + 1; i < n; i++)
            acc -= row[i] * b[i];
        b[k] = acc / row[k];
    }
}

/* The error norm of the stiff families: sqrt(mean((v_i / w_i)^2)), 0 without states; *worst:
   the component with the largest share. */
static double bgc_stiff_norm(const double *v, const double *w, int *worst)
{
    enum { N = BGC_NUM_STATES };
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

/* A step size below bgc_hmin: the message names what made the steps shrink. bad: -2 an
   algebraic block failed, -3 the iteration matrix was singular, -4 Newton did not converge,
   >= 0 a non-finite component (kind 1 a state, else a derivative), else the error test. */
static int bgc_stiff_fail_step(bgc_run *r, const char *name, double t, double h, int bad,
                               int bad_kind, int worst)
{
    if (bad == -2)
        return bgc_fail_block(r->msg, r->msg_size, r->w);
    if (bad == -3) {
        snprintf(r->msg, r->msg_size,
                 "at t = %.17g: %s: the iteration matrix is singular (step size down to h = %.3g)",
                 t, name, h);
        return BGC_ERR_RUNTIME;
    }
    if (bad == -4) {
        snprintf(r->msg, r->msg_size,
                 "at t = %.17g: %s: the Newton iteration does not converge (step size down to "
                 "h = %.3g)", t, name, h);
        return BGC_ERR_RUNTIME;
    }
    if (bad >= 0)
        return bgc_fail(r->msg, r->msg_size, t, bad_kind == 1 ? "state" : "derivative of state",
                        bgc_state_names[bad]);
    return bgc_fail_step(r->msg, r->msg_size, t, h, worst);
}

static int bgc_stiff_fail_singular(bgc_run *r, const char *name, double t, double h)
{
    snprintf(r->msg, r->msg_size, "at t = %.17g: %s: the iteration matrix is singular (h = %.3g)",
             t, name, h);
    return BGC_ERR_RUNTIME;
}

/* Fixed steps (s->step > 0): the grid t_start + k * step, the last step ending on t_end. */
static double bgc_stiff_grid(const bgc_settings *s, double t_start, long k, long n)
{
    return k >= n ? s->t_end : t_start + (double)k * s->step;
}

/* ------------------------------------------------------- Rosenbrock methods --- */

/* The dense output of a Rosenbrock step: y(theta) = (1 - theta) y0 + theta (y1 + (1 - theta)
   (q_1 + theta (q_2 + ... + theta q_R))), q_r = sum_j H_rj k_j (formed when first needed). */
typedef struct bgc_ros_dense {
    const bgc_rosenbrock *m;
    const double *y, *y1, *k;
    double *q; /* R rows of D */
} bgc_ros_dense;

static int bgc_ros_prepare(void *dctx)
{
    enum { N = BGC_NUM_STATES, D = BGC_DIM(BGC_NUM_STATES) };
    bgc_ros_dense *d = dctx;
    const int S = d->m->stages, R = d->m->dense_rows;
    int j, l, r;
    for (r = 0; r < R; r++) {
        const double *H = d->m->H + (size_t)r * S;
        double *q = d->q + (size_t)r * D;
        for (l = 0; l < N; l++) {
            double acc = 0.0;
            for (j = 0; j < S; j++)
                acc += H[j] * d->k[(size_t)j * D + l];
            q[l] = acc;
        }
    }
    return 0;
}

static void bgc_ros_dense_at(const void *dctx, double theta, double *yout)
{
    enum { N = BGC_NUM_STATES, D = BGC_DIM(BGC_NUM_STATES) };
    const bgc_ros_dense *d = dctx;
    const int R = d->m->dense_rows;
    const double s1 = 1.0 - theta;
    int l, r;
    for (l = 0; l < N; l++) {
        double acc = d->q[(size_t)(R - 1) * D + l];
        for (r = R - 2; r >= 0; r--)
            acc = d->q[(size_t)r * D + l] + theta * acc;
        yout[l] = s1 * d->y[l] + theta * (d->y1[l] + s1 * acc);
    }
}

/* Rosenbrock methods as Hairer's RODAS: at every new point f(t, y), df/dt (a forward
   difference, unless the model is autonomous) and the Jacobian J; per step attempt one
   factorisation of E = I/(gamma h) - J and one solve per stage,
   E k_i = f(t + c_i h, y + sum_j a_ij k_j) + sum_j C_ij k_j / h + h d_i df/dt;
   y1 = y + sum m_j k_j, the error sum e_j k_j in Hairer's norm, Gustafsson's predictive step
   control, outputs by the dense output.  A singular E, a failed block or a non-finite stage
   halve the step.  With s->step > 0: steps of that size, accepted without error control. */
static int bgc_run_rosenbrock(bgc_run *r, const bgc_method *method, double *y)
{
    enum { N = BGC_NUM_STATES, D = BGC_DIM(BGC_NUM_STATES) };
    const bgc_rosenbrock *m = method->ros;
    const bgc_settings *s = r->s;
    const int S = m->stages, fixed = s->step > 0.0;
    const int R = m->dense_rows > 2 ? m->dense_rows : 2; /* q2, q3 also hold the error */
    const double hmax = s->t_end - s->t0, expo = 1.0 / (double)method->q;
    const double t_start = r->t;
    double *mem = malloc(((size_t)2 * D * D + (size_t)(S + 5 + R) * D) * sizeof *mem);
    int *piv = malloc((size_t)D * sizeof *piv);
    double *J, *E, *k, *f0, *ft, *ys, *y1, *yout, *q2, *q3; /* q2: dense.q, R rows */
    double t = r->t, h = 0.0, hnew, hacc = 0.0, erracc = 1.0;
    long n_fixed = 0, k_fixed = 0;
    int i, j, l, rc = 0, reject = 0, last = 0, fresh = 1, accepted = 0, nsing = 0;
    int worst = -1, bad = -1, bad_kind = 0;
    bgc_ros_dense dense;

    if (!mem || !piv) {
        rc = bgc_fail_memory(r->msg, r->msg_size);
        goto done;
    }
    J = mem;
    E = J + (size_t)D * D;
    k = E + (size_t)D * D;
    f0 = k + (size_t)S * D;
    ft = f0 + D;
    ys = ft + D;
    y1 = ys + D;
    yout = y1 + D;
    q2 = yout + D;
    q3 = q2 + D;
    for (l = 0; l < N; l++)
        ft[l] = 0.0;
    dense.m = m;
    dense.y = y;
    dense.y1 = y1;
    dense.k = k;
    dense.q = q2;
    if (r->kout > r->nout)
        goto done;
    if (fixed) {
        n_fixed = bgc_substeps(s->t_end - t_start, s->step);
        if (n_fixed < 0) {
            rc = bgc_fail_step(r->msg, r->msg_size, t, s->step, -1);
            goto done;
        }
    }

    for (;;) {
        double tph, err, fac;
        int failed = 0;
        if (fresh) { /* a new point: f, df/dt, J */
            r->st->rhs++;
            if (bgc_model_rhs(t, y, r->p, r->w, f0)) {
                rc = bgc_fail_block(r->msg, r->msg_size, r->w);
                goto done;
            }
            i = bgc_first_nonfinite(f0, N);
            if (i >= 0) {
                rc = bgc_fail(r->msg, r->msg_size, t, "derivative of state", bgc_state_names[i]);
                goto done;
            }
            if (!BGC_AUTONOMOUS) {
                const double delta = sqrt(DBL_EPSILON * bgc_max(1e-5, fabs(t)));
                r->st->rhs++;
                if (bgc_model_rhs(t + delta, y, r->p, r->w, ft)) {
                    rc = bgc_fail_block(r->msg, r->msg_size, r->w);
                    goto done;
                }
                for (l = 0; l < N; l++)
                    ft[l] = (ft[l] - f0[l]) / delta;
            }
            r->st->jac++;
            if (bgc_jacobian(t, y, r->p, r->w, J)) {
                rc = bgc_fail_block(r->msg, r->msg_size, r->w);
                goto done;
            }
            if (h == 0.0 && !fixed)
                h = r->h > 0.0 ? bgc_min(r->h, hmax)
                               : bgc_initial_step(r, method->q, y, f0, hmax, ys, y1);
            fresh = 0;
        }
        if (fixed) {
            last = k_fixed + 1 >= n_fixed;
            tph = bgc_stiff_grid(s, t_start, k_fixed + 1, n_fixed);
            h = tph - t;
            if (!(h >= bgc_hmin(t))) {
                rc = bgc_fail_step(r->msg, r->msg_size, t, h, -1);
                goto done;
            }
        } else {
            if (!(h >= bgc_hmin(t))) {
                rc = bgc_stiff_fail_step(r, method->name, t, h, bad, bad_kind, worst);
                goto done;
            }
            if (t + 1.01 * h - s->t_end > 0.0) {
                h = s->t_end - t;
                last = 1;
            }
            tph = last ? s->t_end : t + h;
        }

        /* E = I/(gamma h) - J, factored */
        for (l = 0; l < N * N; l++)
            E[l] = -J[l];
        for (l = 0; l < N; l++)
            E[(size_t)l * N + l] += 1.0 / (m->gamma * h);
        r->st->lu++;
        if (bgc_stiff_lu(N, E, piv)) {
            if (fixed || ++nsing == 5) {
                rc = bgc_stiff_fail_singular(r, method->name, t, h);
                goto done;
            }
            bad = -3;
            h *= 0.5;
            reject = 1;
            last = 0;
            r->st->rejected++;
            continue;
        }

        /* the stages */
        for (i = 0; i < S; i++) {
            const double *a = m->a + (size_t)i * S, *C = m->C + (size_t)i * S;
            double *ki = k + (size_t)i * D;
            if (i == 0) {
                for (l = 0; l < N; l++)
                    ki[l] = f0[l];
            } else {
                for (l = 0; l < N; l++) {
                    double acc = 0.0;
                    for (j = 0; j < i; j++)
                        if (a[j] != 0.0)
                            acc += a[j] * k[(size_t)j * D + l];
                    ys[l] = y[l] + acc;
                }
                r->st->rhs++;
                failed = bgc_model_rhs(m->c[i] == 1.0 ? tph : t + m->c[i] * h, ys, r->p, r->w, ki);
                if (failed)
                    break;
            }
            for (l = 0; l < N; l++) {
                double acc = 0.0;
                for (j = 0; j < i; j++)
                    if (C[j] != 0.0)
                        acc += C[j] * k[(size_t)j * D + l];
                ki[l] += acc / h;
                if (!BGC_AUTONOMOUS && m->d[i] != 0.0)
                    ki[l] += h * m->d[i] * ft[l];
            }
            bgc_stiff_lu_solve(N, E, piv, ki);
            r->st->solves++;
        }
        if (failed && fixed) {
            rc = bgc_fail_block(r->msg, r->msg_size, r->w);
            goto done;
        }
        if (failed) { /* an algebraic block failed in a stage */
            bad = -2;
            h *= 0.5;
            reject = 1;
            last = 0;
            r->st->rejected++;
            continue;
        }

        /* the solution, the error estimate (in q2) and Hairer's norm (weights in q3) */
        for (l = 0; l < N; l++) {
            double acc = 0.0, e = 0.0;
            for (j = 0; j < S; j++) {
                const double kj = k[(size_t)j * D + l];
                if (m->m[j] != 0.0)
                    acc += m->m[j] * kj;
                if (m->e[j] != 0.0)
                    e += m->e[j] * kj;
            }
            y1[l] = y[l] + acc;
            q2[l] = e;
            q3[l] = bgc_weight(s, y[l], y1[l]);
        }
        err = bgc_stiff_norm(q2, q3, &worst);
        i = bgc_first_nonfinite(y1, N);
        if (err != err || err > DBL_MAX || i >= 0) {
            if (fixed) {
                rc = bgc_fail(r->msg, r->msg_size, tph, "state", bgc_state_names[i >= 0 ? i : 0]);
                goto done;
            }
            bad = i;
            bad_kind = 1;
            for (j = 1; j < S && bad < 0; j++) {
                bad = bgc_first_nonfinite(k + (size_t)j * D, N);
                bad_kind = 2;
            }
            h *= 0.5;
            reject = 1;
            last = 0;
            r->st->rejected++;
            continue;
        }
        if (fixed)
            err = 0.0;

        /* Gustafsson's predictive controller (rodas.f) */
        fac = bgc_max(1.0 / method->fac_max,
                      bgc_min(1.0 / method->fac_min, pow(err, expo) / method->safe));
        hnew = h / fac;
        if (err <= 1.0) {
            if (accepted > 0) {
                double facgus = (hacc / h) * pow(err * err / erracc, expo) / method->safe;
                facgus = bgc_max(1.0 / method->fac_max, bgc_min(1.0 / method->fac_min, facgus));
                fac = bgc_max(fac, facgus);
                hnew = h / fac;
            }
            hacc = h;
            erracc = bgc_max(1e-2, err);
            accepted++;
            rc = bgc_accept(r, tph);
            if (rc)
                goto done;
            rc = bgc_emit_step(r, t, h, tph, y1, bgc_ros_prepare, bgc_ros_dense_at, &dense, yout);
            if (rc)
                goto done;
            memcpy(y, y1, sizeof(double) * N);
            t = tph;
            r->t = t;
            fresh = 1;
            nsing = 0;
            bad = -1;
            if (last)
                goto done;
            k_fixed++;
            hnew = bgc_min(hnew, hmax);
            if (reject)
                hnew = bgc_min(hnew, h);
            reject = 0;
        } else {
            reject = 1;
            last = 0;
            r->st->rejected++;
        }
        h = hnew;
    }
done:
    free(piv);
    free(mem);
    return rc;
}

/* ------------------------------------------------------- Radau IIA (RADAU5) --- */

/* The collocation polynomial of an accepted step through (0, 0), (c1, Z1), (c2, Z2), (1, Z3)
   in Newton's form: u(theta) = theta (b1 + (theta - c1) (b2 + (theta - c2) b3)); the state
   is y0 + u(theta).  b: 3 x D. */
static void bgc_radau_poly(const bgc_radau *m, const double *z1, const double *z2,
                           const double *z3, double *b)
{
    enum { N = BGC_NUM_STATES, D = BGC_DIM(BGC_NUM_STATES) };
    int l;
    for (l = 0; l < N; l++) {
        const double d01 = z1[l] / m->c1, d12 = (z2[l] - z1[l]) / (m->c2 - m->c1);
        const double d23 = (z3[l] - z2[l]) / (1.0 - m->c2);
        const double d012 = (d12 - d01) / m->c2, d123 = (d23 - d12) / (1.0 - m->c1);
        b[l] = d01;
        b[D + l] = d012;
        b[2 * D + l] = d123 - d012;
    }
}

static double bgc_radau_u(const bgc_radau *m, const double *b, int l, double theta)
{
    enum { D = BGC_DIM(BGC_NUM_STATES) };
    return theta * (b[l] + (theta - m->c1) * (b[D + l] + (theta - m->c2) * b[2 * D + l]));
}

typedef struct bgc_radau_dense {
    const bgc_radau *m;
    const double *y, *b;
} bgc_radau_dense;

static void bgc_radau_dense_at(const void *dctx, double theta, double *yout)
{
    enum { N = BGC_NUM_STATES };
    const bgc_radau_dense *d = dctx;
    int l;
    for (l = 0; l < N; l++)
        yout[l] = d->y[l] + bgc_radau_u(d->m, d->b, l, theta);
}

/* Radau IIA of order 5 after Hairer's RADAU5.  The stage increments Z_i = Y_i - y solve
   Z = h (A x I) F(Z); with W = (T^-1 x I) Z the simplified Newton iteration decouples into
   (gamma/h I - J) dW1 = (T^-1 F)_1 - gamma/h W1 and, for dW2 + i dW3, the complex system
   ((alpha + i beta)/h I - J) with the right side (T^-1 F)_2 + i (T^-1 F)_3
   - (alpha + i beta)/h (W2 + i W3): one real and one complex factorisation per h and J.
   Tolerances as RADAU5 transforms them: rtol' = 0.1 rtol^(2/3), atol' = rtol' atol / rtol;
   Newton's weights atol' + rtol' |y| at the step's start.  Newton: at most 7 iterations from
   the previous step's collocation polynomial (zero on the first step), convergence rate
   theta, stop when theta/(1 - theta) |dW| <= fnewt = max(10 eps/rtol', min(0.03,
   rtol'^(1/2))), theta the rate of this step's iterations; after one iteration (the previous
   step's theta) only if h and J are the previous step's (RADAU5 allows it on any step: after
   a change of h the old rate does not hold, and the stages' Newton error of up to fnewt
   times the tolerance can exceed the method's far smaller local error);
   theta >= 0.99 or no convergence: h / 2; a predicted miss of fnewt within 7 iterations: h
   shrunk accordingly.  Error estimate: (gamma/h I - J) err = f(t, y) + sum_j e_j Z_j / h,
   refined once with f(t, y + err) on the first step and after a rejection, in Hairer's norm
   with the weights atol' + rtol' max(|y|, |y1|) of the other solvers.  Step control:
   Gustafsson's, both the standard and the predictive factor with the safety
   min(safe, safe (1 + 2 * 7) / (newton + 2 * 7)) (RADAU5 uses safe in the predictive one),
   hnew/h in [fac_min, fac_max].  J is recomputed when the contraction was poorer than 0.001,
   the matrices are refactored unless hnew/h stays in [1, 1.2] (h is then kept).  Outputs by the
   collocation polynomial.  Counts: each real or complex factorisation and each real or
   complex solve.  With s->step > 0: steps of that size, no error estimate, and Newton's
   failure (after a fresh Jacobian) ends the run. */
static int bgc_run_radau5(bgc_run *r, const bgc_method *method, double *y)
{
    enum { N = BGC_NUM_STATES, D = BGC_DIM(BGC_NUM_STATES), NIT = 7 };
    const bgc_radau *m = method->radau;
    const bgc_settings *s = r->s;
    const int fixed = s->step > 0.0;
    const double hmax = s->t_end - s->t0, expo = 1.0 / (double)method->q, thet = 0.001;
    const double rtol = 0.1 * pow(s->rtol, 2.0 / 3.0), atol = rtol * (s->atol / s->rtol);
    const double fnewt = bgc_max(10.0 * DBL_EPSILON / rtol, bgc_min(0.03, sqrt(rtol)));
    const double cfac = method->safe * (double)(1 + 2 * NIT);
    const double *T = m->T, *Ti = m->Ti;
    const double t_start = r->t;
    double *mem = malloc(((size_t)2 * D * D + (size_t)18 * D) * sizeof *mem);
    bgc_cplx *cmem = malloc(((size_t)D * D + (size_t)D) * sizeof *cmem);
    int *piv = malloc((size_t)2 * D * sizeof *piv);
    double *J, *E1, *z1, *z2, *z3, *w1, *w2, *w3, *f0, *scal, *ys, *y1, *yout, *b, *zlast;
    double *cont, *f2, *ew;
    bgc_cplx *E2, *zc;
    double t = r->t, h = 0.0, hnew, hfact = 0.0, hold = 0.0, hacc = 0.0, erracc = 1.0;
    double faccon = 1.0, theta = thet, thqold = 1.0, dynold = 1.0, hhfac = 0.5;
    long n_fixed = 0, k_fixed = 0;
    int i, l, rc = 0, reject = 0, last = 0, first = 1, needjac = 1, caljac = 0;
    int accepted = 0, nsing = 0, worst = -1, bad = -1, bad_kind = 0, newt = 0, refactored = 0;
    bgc_radau_dense dense;

    if (!mem || !cmem || !piv) {
        rc = bgc_fail_memory(r->msg, r->msg_size);
        goto done;
    }
    J = mem;
    E1 = J + (size_t)D * D;
    z1 = E1 + (size_t)D * D;
    z2 = z1 + D;
    z3 = z2 + D;
    w1 = z3 + D;
    w2 = w1 + D;
    w3 = w2 + D;
    f0 = w3 + D;
    scal = f0 + D;
    ys = scal + D;
    y1 = ys + D;
    yout = y1 + D;
    b = yout + D; /* 3 D */
    zlast = b + 3 * (size_t)D;
    cont = zlast + D;
    f2 = cont + D;
    ew = f2 + D;
    E2 = cmem;
    zc = E2 + (size_t)D * D;
    for (l = 0; l < 3 * D; l++)
        b[l] = 0.0;
    for (l = 0; l < D; l++)
        zlast[l] = 0.0;
    dense.m = m;
    dense.y = y;
    dense.b = b;
    if (r->kout > r->nout)
        goto done;
    if (fixed) {
        n_fixed = bgc_substeps(s->t_end - t_start, s->step);
        if (n_fixed < 0) {
            rc = bgc_fail_step(r->msg, r->msg_size, t, s->step, -1);
            goto done;
        }
    }
    r->st->rhs++;
    if (bgc_model_rhs(t, y, r->p, r->w, f0)) {
        rc = bgc_fail_block(r->msg, r->msg_size, r->w);
        goto done;
    }
    i = bgc_first_nonfinite(f0, N);
    if (i >= 0) {
        rc = bgc_fail(r->msg, r->msg_size, t, "derivative of state", bgc_state_names[i]);
        goto done;
    }
    for (l = 0; l < N; l++)
        scal[l] = atol + rtol * fabs(y[l]);
    if (!fixed)
        h = r->h > 0.0 ? bgc_min(r->h, hmax) : bgc_initial_step(r, method->q, y, f0, hmax, ys, y1);

    for (;;) {
        double tph, err = 0.0, fac1, alphn, betan, dyno = 0.0, quot, fac;
        int failed = 0;
        if (needjac) {
            r->st->jac++;
            if (bgc_jacobian(t, y, r->p, r->w, J)) {
                rc = bgc_fail_block(r->msg, r->msg_size, r->w);
                goto done;
            }
            needjac = 0;
            caljac = 1;
            hfact = 0.0;
        }
        if (fixed) {
            last = k_fixed + 1 >= n_fixed;
            tph = bgc_stiff_grid(s, t_start, k_fixed + 1, n_fixed);
            h = tph - t;
            if (!(h >= bgc_hmin(t))) {
                rc = bgc_fail_step(r->msg, r->msg_size, t, h, -1);
                goto done;
            }
        } else {
            if (!(h >= bgc_hmin(t))) {
                rc = bgc_stiff_fail_step(r, method->name, t, h, bad, bad_kind, worst);
                goto done;
            }
            if (t + 1.01 * h - s->t_end > 0.0) {
                h = s->t_end - t;
                last = 1;
            }
            tph = last ? s->t_end : t + h;
        }
        fac1 = m->gamma / h;
        alphn = m->alpha / h;
        betan = m->beta / h;

        /* gamma/h I - J and (alpha + i beta)/h I - J, factored (unless they are h's already) */
        refactored = h != hfact;
        if (h != hfact) {
            int singular;
            for (l = 0; l < N * N; l++) {
                E1[l] = -J[l];
                E2[l] = -J[l];
            }
            for (l = 0; l < N; l++) {
                E1[(size_t)l * N + l] += fac1;
                E2[(size_t)l * N + l] += alphn + betan * _Complex_I;
            }
            r->st->lu++;
            singular = bgc_stiff_lu(N, E1, piv);
            if (!singular) {
                r->st->lu++;
                singular = bgc_stiff_zlu(N, E2, piv + D);
            }
            if (singular) {
                hfact = 0.0;
                if (fixed || ++nsing == 5) {
                    rc = bgc_stiff_fail_singular(r, method->name, t, h);
                    goto done;
                }
                bad = -3;
                h *= 0.5;
                reject = 1;
                last = 0;
                r->st->rejected++;
                needjac = !caljac;
                continue;
            }
            hfact = h;
        }

        /* starting values: the last step's collocation polynomial, extrapolated */
        if (first) {
            for (l = 0; l < N; l++)
                z1[l] = z2[l] = z3[l] = w1[l] = w2[l] = w3[l] = 0.0;
        } else {
            const double q = h / hold;
            for (l = 0; l < N; l++) {
                const double a1 = bgc_radau_u(m, b, l, 1.0 + m->c1 * q) - zlast[l];
                const double a2 = bgc_radau_u(m, b, l, 1.0 + m->c2 * q) - zlast[l];
                const double a3 = bgc_radau_u(m, b, l, 1.0 + q) - zlast[l];
                z1[l] = a1;
                z2[l] = a2;
                z3[l] = a3;
                w1[l] = Ti[0] * a1 + Ti[1] * a2 + Ti[2] * a3;
                w2[l] = Ti[3] * a1 + Ti[4] * a2 + Ti[5] * a3;
                w3[l] = Ti[6] * a1 + Ti[7] * a2 + Ti[8] * a3;
            }
        }

        /* the simplified Newton iteration */
        newt = 0;
        faccon = pow(bgc_max(faccon, DBL_EPSILON), 0.8);
        theta = thet;
        for (;;) {
            double sum = 0.0;
            if (newt >= NIT) {
                failed = 2;
                break;
            }
            /* z_i <- f(t + c_i h, y + z_i) */
            for (i = 0; i < 3 && !failed; i++) {
                double *zi = i == 0 ? z1 : (i == 1 ? z2 : z3);
                const double ti = i == 0 ? t + m->c1 * h : (i == 1 ? t + m->c2 * h : tph);
                for (l = 0; l < N; l++)
                    ys[l] = y[l] + zi[l];
                r->st->rhs++;
                if (bgc_model_rhs(ti, ys, r->p, r->w, zi)) {
                    failed = 1;
                    bad = -2;
                } else if ((l = bgc_first_nonfinite(zi, N)) >= 0) {
                    failed = 1;
                    bad = l;
                    bad_kind = 2;
                }
            }
            if (failed)
                break;
            for (l = 0; l < N; l++) {
                const double a1 = z1[l], a2 = z2[l], a3 = z3[l];
                z1[l] = Ti[0] * a1 + Ti[1] * a2 + Ti[2] * a3 - fac1 * w1[l];
                zc[l] = (Ti[3] * a1 + Ti[4] * a2 + Ti[5] * a3 - (alphn * w2[l] - betan * w3[l]))
                        + (Ti[6] * a1 + Ti[7] * a2 + Ti[8] * a3 - (betan * w2[l] + alphn * w3[l]))
                              * _Complex_I;
            }
            bgc_stiff_lu_solve(N, E1, piv, z1);
            bgc_stiff_zlu_solve(N, E2, piv + D, zc);
            r->st->solves += 2;
            newt++;
            for (l = 0; l < N; l++) {
                const double q1 = z1[l] / scal[l], q2 = creal(zc[l]) / scal[l];
                const double q3 = cimag(zc[l]) / scal[l];
                sum += q1 * q1 + q2 * q2 + q3 * q3;
            }
            dyno = N > 0 ? sqrt(sum / (double)(3 * N)) : 0.0;
            if (dyno != dyno || dyno > DBL_MAX) {
                failed = 2;
                break;
            }
            if (newt > 1 && newt < NIT) {
                const double thq = dyno / dynold;
                theta = newt == 2 ? thq : sqrt(thq * thqold);
                thqold = thq;
                if (theta < 0.99) {
                    const double dyth = theta / (1.0 - theta) * dyno
                                        * pow(theta, (double)(NIT - 1 - newt)) / fnewt;
                    faccon = theta / (1.0 - theta);
                    if (dyth >= 1.0 && !fixed) { /* too slow: a smaller step converges sooner */
                        const double qnewt = bgc_max(1e-4, bgc_min(20.0, dyth));
                        hhfac = 0.8 * pow(qnewt, -1.0 / (4.0 + (double)(NIT - 1 - newt)));
                        failed = 3;
                        break;
                    }
                } else {
                    failed = 2;
                    break;
                }
            }
            dynold = bgc_max(dyno, DBL_EPSILON);
            for (l = 0; l < N; l++) {
                const double a1 = w1[l] + z1[l], a2 = w2[l] + creal(zc[l]);
                const double a3 = w3[l] + cimag(zc[l]);
                w1[l] = a1;
                w2[l] = a2;
                w3[l] = a3;
                z1[l] = T[0] * a1 + T[1] * a2 + T[2] * a3;
                z2[l] = T[3] * a1 + T[4] * a2 + T[5] * a3;
                z3[l] = T[6] * a1 + T[7] * a2 + T[8] * a3;
            }
            /* converged; after one iteration only on the previous step's matrices, whose
               contraction faccon measured */
            if ((newt > 1 || !refactored) && faccon * dyno <= fnewt)
                break;
        }
        if (failed) {
            if (fixed) {
                if (failed == 1) {
                    rc = bad == -2 ? bgc_fail_block(r->msg, r->msg_size, r->w)
                                   : bgc_fail(r->msg, r->msg_size, t, "derivative of state",
                                              bgc_state_names[bad]);
                    goto done;
                }
                if (!caljac) { /* once more with a fresh Jacobian */
                    needjac = 1;
                    continue;
                }
                snprintf(r->msg, r->msg_size,
                         "at t = %.17g: %s: the Newton iteration does not converge with the "
                         "fixed step h = %.3g", t, method->name, h);
                rc = BGC_ERR_RUNTIME;
                goto done;
            }
            if (failed != 1)
                bad = -4;
            h *= failed == 3 ? hhfac : 0.5;
            reject = 1;
            last = 0;
            r->st->rejected++;
            needjac = !caljac;
            continue;
        }

        /* the error estimate */
        if (!fixed) {
            for (l = 0; l < N; l++) {
                f2[l] = (m->e[0] * z1[l] + m->e[1] * z2[l] + m->e[2] * z3[l]) / h;
                cont[l] = f2[l] + f0[l];
                ew[l] = atol + rtol * bgc_max(fabs(y[l]), fabs(y[l] + z3[l]));
            }
            bgc_stiff_lu_solve(N, E1, piv, cont);
            r->st->solves++;
            err = bgc_max(bgc_stiff_norm(cont, ew, &worst), 1e-10);
            if (err >= 1.0 && (first || reject)) { /* refined: f at y + err */
                for (l = 0; l < N; l++)
                    ys[l] = y[l] + cont[l];
                r->st->rhs++;
                if (bgc_model_rhs(t, ys, r->p, r->w, yout) == 0) {
                    for (l = 0; l < N; l++)
                        cont[l] = yout[l] + f2[l];
                    bgc_stiff_lu_solve(N, E1, piv, cont);
                    r->st->solves++;
                    err = bgc_max(bgc_stiff_norm(cont, ew, &worst), 1e-10);
                }
            }
            if (err != err || err > DBL_MAX) {
                bad = -1;
                h *= 0.5;
                reject = 1;
                last = 0;
                r->st->rejected++;
                needjac = !caljac;
                continue;
            }
        }

        /* step control: Gustafsson's, the safety factor scaled by the Newton iterations */
        fac = bgc_min(method->safe, cfac / (double)(newt + 2 * NIT));
        quot = bgc_max(1.0 / method->fac_max,
                       bgc_min(1.0 / method->fac_min, pow(err, expo) / fac));
        hnew = h / quot;
        if (err < 1.0) {
            first = 0;
            accepted++;
            if (accepted > 1) {
                double facgus = (hacc / h) * pow(err * err / erracc, expo) / fac;
                facgus = bgc_max(1.0 / method->fac_max, bgc_min(1.0 / method->fac_min, facgus));
                quot = bgc_max(quot, facgus);
                hnew = h / quot;
            }
            hacc = h;
            erracc = bgc_max(1e-2, err);
            for (l = 0; l < N; l++)
                y1[l] = y[l] + z3[l];
            i = bgc_first_nonfinite(y1, N);
            if (i >= 0) {
                rc = bgc_fail(r->msg, r->msg_size, tph, "state", bgc_state_names[i]);
                goto done;
            }
            bgc_radau_poly(m, z1, z2, z3, b);
            memcpy(zlast, z3, sizeof(double) * N);
            hold = h;
            rc = bgc_accept(r, tph);
            if (rc)
                goto done;
            rc = bgc_emit_step(r, t, h, tph, y1, NULL, bgc_radau_dense_at, &dense, yout);
            if (rc)
                goto done;
            memcpy(y, y1, sizeof(double) * N);
            t = tph;
            r->t = t;
            nsing = 0;
            bad = -1;
            caljac = 0;
            if (last)
                goto done;
            for (l = 0; l < N; l++)
                scal[l] = atol + rtol * fabs(y[l]);
            r->st->rhs++;
            if (bgc_model_rhs(t, y, r->p, r->w, f0)) {
                rc = bgc_fail_block(r->msg, r->msg_size, r->w);
                goto done;
            }
            k_fixed++;
            hnew = bgc_min(hnew, hmax);
            if (reject)
                hnew = bgc_min(hnew, h);
            reject = 0;
            if (theta <= thet && hnew / h >= 1.0 && hnew / h <= 1.2)
                hnew = h; /* keep h and the factorisations */
            needjac = theta > thet;
            h = hnew;
        } else {
            reject = 1;
            last = 0;
            r->st->rejected++;
            h = first ? 0.1 * h : hnew;
            needjac = !caljac;
        }
    }
done:
    free(piv);
    free(cmem);
    free(mem);
    return rc;
}
