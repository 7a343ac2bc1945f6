/* ============================================================== stiff === */
/* The stiff families: Rosenbrock methods in Hairer's transformed form (RODAS's design, any
   tableau of the family) and Radau IIA with 3, 5 or 7 stages, of fixed or variable order
   (RADAU5's and RADAU's design), both with the Jacobian
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
    double t = r->t, h = 0.0, hnew, hacc = 0.0, erracc = 1.0, wanted = 0.0;
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
            wanted = h;
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
            if (last) {
                if (!fixed) /* the step to go on with: the controller's, or the one cut short */
                    r->st->h_next = bgc_max(hnew, wanted);
                goto done;
            }
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
   e = (s+1)/(2s); after one iteration (the previous step's theta) only if h and J are the
   previous step's (RADAU5 allows it on any step: after a change of h the old rate does not
   hold, and the stages' Newton error of up to fnewt times the tolerance can exceed the
   method's far smaller local error); theta >= 0.99 or no convergence: h / 2; a predicted miss
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
static int bgc_run_radau(bgc_run *r, const bgc_method *method, double *y)
{
    enum { N = BGC_NUM_STATES, D = BGC_DIM(BGC_NUM_STATES), SMAX = BGC_RADAU_MAX_STAGES };
    const bgc_settings *s = r->s;
    const int fixed = s->step > 0.0, variable = method->radau_sets > 1 && !fixed;
    const double hmax = s->t_end - s->t0, thet = 0.001;
    const double t_start = r->t;
    int smax = 0, pmax, set = 0, since = 0, change = 0, unexp = 0, unexn = 0, recheck = 0;
    double *mem = NULL, *J, *E1, *Z, *W, *b, *dw, *f0, *scal, *ys, *y1, *yout, *zlast, *cont;
    double *f2, *ew;
    bgc_cplx *cmem = NULL, *Ec, *zc;
    int *piv = NULL;
    double t = r->t, h = 0.0, hnew, hfact = 0.0, hold = 0.0, hacc = 0.0, erracc = 1.0;
    double wanted = 0.0;
    double faccon = 1.0, theta = thet, thetat = 0.0, thqold = 1.0, dynold = 1.0, hhfac = 0.5;
    long n_fixed = 0, k_fixed = 0;
    int i, j, k, l, rc = 0, reject = 0, last = 0, first = 1, needjac = 1, caljac = 0;
    int accepted = 0, nsing = 0, worst = -1, bad = -1, bad_kind = 0, newt = 0, refactored = 0;
    bgc_radau_use u;
    bgc_radau_dense dense;

    for (k = 0; k < method->radau_sets; k++) {
        smax = method->radau[k].s > smax ? method->radau[k].s : smax;
        if (variable && 2 * method->radau[k].s - 1 == s->order0) {
            set = k; /* going on from an earlier run: at its order, free to change it */
            since = 10;
        }
    }
    pmax = (smax - 1) / 2;
    mem = malloc(((size_t)2 * D * D + (size_t)(4 * smax + 11) * D) * sizeof *mem);
    cmem = malloc(((size_t)pmax * D * D + (size_t)pmax * D + 1) * sizeof *cmem);
    piv = malloc((size_t)(1 + pmax) * D * sizeof *piv + sizeof *piv);
    if (!mem || !cmem || !piv) {
        rc = bgc_fail_memory(r->msg, r->msg_size);
        goto done;
    }
    J = mem;
    E1 = J + (size_t)D * D;
    Z = E1 + (size_t)D * D; /* smax x D */
    W = Z + (size_t)smax * D; /* smax x D */
    b = W + (size_t)smax * D; /* smax x D */
    zlast = b + (size_t)smax * D;
    dw = zlast + D;
    f0 = dw + D;
    scal = f0 + D;
    ys = scal + D;
    y1 = ys + D;
    yout = y1 + D;
    cont = yout + D;
    f2 = cont + D;
    ew = f2 + D;
    Ec = cmem; /* pmax x D x D */
    zc = Ec + (size_t)pmax * D * D; /* pmax x D */
    for (l = 0; l < smax * D; l++)
        b[l] = 0.0;
    for (l = 0; l < D; l++)
        zlast[l] = 0.0;
    bgc_radau_configure(&u, method, s, set);
    dense.m = u.m;
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
        scal[l] = u.atol + u.rtol * fabs(y[l]);
    if (!fixed)
        h = r->h > 0.0 ? bgc_min(r->h, hmax) : bgc_initial_step(r, method->q, y, f0, hmax, ys, y1);

    for (;;) {
        const bgc_radau *m;
        const double *T, *Ti;
        double tph, err = 0.0, fac1, alphn[SMAX], betan[SMAX], dyno = 0.0, quot, fac;
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
            wanted = h;
            if (t + 1.01 * h - s->t_end > 0.0) {
                h = s->t_end - t;
                last = 1;
            }
            tph = last ? s->t_end : t + h;
        }

        /* the order, whenever the matrices are to be factored (variable order only) */
        if (variable && (h != hfact || recheck)) {
            const double hquot = hold > 0.0 ? h / hold : 0.0;
            int next = set;
            since++;
            thetat = bgc_min(10.0, bgc_max(theta, 0.5 * thetat));
            if (newt > 1 && thetat <= 0.002 && hquot > 0.8 && hquot < 1.2 && since > 10
                && set + 1 < method->radau_sets)
                next = set + 1;
            if ((thetat >= 0.8 || unexp || unexn) && set > 0)
                next = set - 1;
            unexp = unexn = recheck = 0;
            if (next != set) {
                set = next;
                bgc_radau_configure(&u, method, s, set);
                since = 1;
                change = 1;
                hfact = 0.0;
                for (l = 0; l < N; l++)
                    scal[l] = u.atol + u.rtol * fabs(y[l]);
            }
        }
        m = u.m;
        T = m->T;
        Ti = m->Ti;
        fac1 = m->gamma / h;
        for (k = 0; k < u.pairs; k++) {
            alphn[k] = m->alpha[k] / h;
            betan[k] = m->beta[k] / h;
        }

        /* gamma/h I - J and (alpha_k + i beta_k)/h I - J, factored (unless they are h's) */
        refactored = h != hfact;
        if (h != hfact) {
            int singular;
            for (l = 0; l < N * N; l++)
                E1[l] = -J[l];
            for (l = 0; l < N; l++)
                E1[(size_t)l * N + l] += fac1;
            r->st->lu++;
            singular = bgc_stiff_lu(N, E1, piv);
            for (k = 0; k < u.pairs && !singular; k++) {
                bgc_cplx *E = Ec + (size_t)k * D * D;
                for (l = 0; l < N * N; l++)
                    E[l] = -J[l];
                for (l = 0; l < N; l++)
                    E[(size_t)l * N + l] += alphn[k] + betan[k] * _Complex_I;
                r->st->lu++;
                singular = bgc_stiff_zlu(N, E, piv + (size_t)(1 + k) * D);
            }
            if (singular) {
                hfact = 0.0;
                if (fixed || ++nsing == 5) {
                    rc = bgc_stiff_fail_singular(r, method->name, t, h);
                    goto done;
                }
                bad = -3;
                unexp = 1;
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
        if (first || change) {
            for (l = 0; l < u.ns * D; l++)
                Z[l] = W[l] = 0.0;
        } else {
            const double q = h / hold;
            for (l = 0; l < N; l++) {
                for (i = 0; i < u.ns; i++)
                    Z[(size_t)i * D + l] = bgc_radau_u(m, b, l, 1.0 + m->c[i] * q) - zlast[l];
                bgc_radau_mul(Ti, u.ns, Z + l, D, W + l, D);
            }
        }

        /* the simplified Newton iteration */
        newt = 0;
        faccon = pow(bgc_max(faccon, DBL_EPSILON), 0.8);
        theta = thet;
        for (;;) {
            double sum = 0.0;
            if (newt >= u.nit) {
                failed = 2;
                break;
            }
            /* Z_i <- f(t + c_i h, y + Z_i) */
            for (i = 0; i < u.ns && !failed; i++) {
                double *zi = Z + (size_t)i * D;
                const double ti = i == u.ns - 1 ? tph : t + m->c[i] * h;
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
                double g[SMAX];
                bgc_radau_mul(Ti, u.ns, Z + l, D, g, 1);
                dw[l] = g[0] - fac1 * W[l];
                for (k = 0; k < u.pairs; k++) {
                    const double w2 = W[(size_t)(2 * k + 1) * D + l];
                    const double w3 = W[(size_t)(2 * k + 2) * D + l];
                    zc[(size_t)k * D + l] = (g[2 * k + 1] - (alphn[k] * w2 - betan[k] * w3))
                                            + (g[2 * k + 2] - (betan[k] * w2 + alphn[k] * w3))
                                                  * _Complex_I;
                }
            }
            bgc_stiff_lu_solve(N, E1, piv, dw);
            for (k = 0; k < u.pairs; k++)
                bgc_stiff_zlu_solve(N, Ec + (size_t)k * D * D, piv + (size_t)(1 + k) * D,
                                    zc + (size_t)k * D);
            r->st->solves += 1 + u.pairs;
            newt++;
            for (l = 0; l < N; l++) {
                const double q1 = dw[l] / scal[l];
                double part = q1 * q1;
                for (k = 0; k < u.pairs; k++) {
                    const double qr = creal(zc[(size_t)k * D + l]) / scal[l];
                    const double qi = cimag(zc[(size_t)k * D + l]) / scal[l];
                    part += qr * qr;
                    part += qi * qi;
                }
                sum += part;
            }
            dyno = N > 0 ? sqrt(sum / (double)(u.ns * N)) : 0.0;
            if (dyno != dyno || dyno > DBL_MAX) {
                failed = 2;
                break;
            }
            if (newt > 1 && newt < u.nit) {
                const double thq = dyno / dynold;
                theta = newt == 2 ? thq : sqrt(thq * thqold);
                thqold = thq;
                if (theta < 0.99) {
                    const double dyth = theta / (1.0 - theta) * dyno
                                        * pow(theta, (double)(u.nit - 1 - newt)) / u.fnewt;
                    faccon = theta / (1.0 - theta);
                    if (dyth >= 1.0 && !fixed) { /* too slow: a smaller step converges sooner */
                        const double qnewt = bgc_max(1e-4, bgc_min(20.0, dyth));
                        hhfac = 0.8 * pow(qnewt, -1.0 / (4.0 + (double)(u.nit - 1 - newt)));
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
                double a[SMAX];
                a[0] = W[l] + dw[l];
                for (k = 0; k < u.pairs; k++) {
                    a[2 * k + 1] = W[(size_t)(2 * k + 1) * D + l] + creal(zc[(size_t)k * D + l]);
                    a[2 * k + 2] = W[(size_t)(2 * k + 2) * D + l] + cimag(zc[(size_t)k * D + l]);
                }
                for (i = 0; i < u.ns; i++)
                    W[(size_t)i * D + l] = a[i];
                bgc_radau_mul(T, u.ns, a, 1, Z + l, D);
            }
            /* converged; after one iteration only on the previous step's matrices, whose
               contraction faccon measured */
            if ((newt > 1 || !refactored) && faccon * dyno <= u.fnewt)
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
            if (failed == 3)
                unexn = hhfac <= 0.5;
            else
                unexp = 1;
            h *= failed == 3 ? hhfac : 0.5;
            reject = 1;
            last = 0;
            r->st->rejected++;
            needjac = !caljac;
            continue;
        }

        /* the error estimate */
        if (!fixed) {
            const double *zs = Z + (size_t)(u.ns - 1) * D;
            for (l = 0; l < N; l++) {
                double acc = m->e[0] * Z[l];
                for (j = 1; j < u.ns; j++)
                    acc += m->e[j] * Z[(size_t)j * D + l];
                f2[l] = acc / h;
                cont[l] = f2[l] + f0[l];
                ew[l] = u.atol + u.rtol * bgc_max(fabs(y[l]), fabs(y[l] + zs[l]));
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
                unexp = 1;
                h *= 0.5;
                reject = 1;
                last = 0;
                r->st->rejected++;
                needjac = !caljac;
                continue;
            }
        }

        /* step control: Gustafsson's, the safety factor scaled by the Newton iterations */
        fac = bgc_min(method->safe, u.cfac / (double)(newt + 2 * u.nit));
        quot = bgc_max(1.0 / method->fac_max,
                       bgc_min(1.0 / method->fac_min, pow(err, u.expo) / fac));
        hnew = h / quot;
        if (err < 1.0) {
            const double *zs = Z + (size_t)(u.ns - 1) * D;
            first = 0;
            accepted++;
            if (accepted > 1 && !change) {
                double facgus = (hacc / h) * pow(err * err / erracc, u.expo) / fac;
                facgus = bgc_max(1.0 / method->fac_max, bgc_min(1.0 / method->fac_min, facgus));
                quot = bgc_max(quot, facgus);
                hnew = h / quot;
            }
            change = 0;
            hacc = h;
            erracc = bgc_max(1e-2, err);
            for (l = 0; l < N; l++)
                y1[l] = y[l] + zs[l];
            i = bgc_first_nonfinite(y1, N);
            if (i >= 0) {
                rc = bgc_fail(r->msg, r->msg_size, tph, "state", bgc_state_names[i]);
                goto done;
            }
            bgc_radau_poly(m, Z, b);
            dense.m = m;
            memcpy(zlast, zs, sizeof(double) * N);
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
            if (last) {
                if (!fixed) { /* the step to go on with: the controller's, or the one cut short */
                    r->st->h_next = bgc_max(hnew, wanted);
                    r->st->order_next = 2 * u.ns - 1;
                }
                goto done;
            }
            for (l = 0; l < N; l++)
                scal[l] = u.atol + u.rtol * fabs(y[l]);
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
            if (theta <= thet && hnew / h >= 1.0 && hnew / h <= 1.2) {
                hnew = h; /* keep h and the factorisations ... */
                if (variable && ++since >= 10 && set + 1 < method->radau_sets)
                    recheck = 1; /* ... but look at the order now and then */
            }
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
