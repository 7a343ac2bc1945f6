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

