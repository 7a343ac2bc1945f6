/* ====================================================================== runtime === */
/* bgc's runtime: model-independent, the same in every generated program (bgc/runtime/runtime.c,
   inlined verbatim).  It uses the model part above: the sizes, bgc_model_rhs, _outputs and
   _jvp, the blocks' plans and the Jacobian's colouring. */

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
    if (!w->v || !w->iv) {
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
    free(w);
}

void bgc_work_message(const bgc_work *w, char *msg, size_t msg_size)
{
    static const char *const how[] = { "failed", "is singular", "did not converge",
                                       "has a non-finite residual" };
    const int k = w->block - 1;
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
    for (k = 0; k < m; k++) {
        if (piv[k] != k) {
            const double tmp = b[k];
            b[k] = b[piv[k]];
            b[piv[k]] = tmp;
        }
        for (i = k + 1; i < m; i++)
            b[i] -= a[i * m + k] * b[k];
    }
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

/* Factors block k's matrix (assembled at .save): the static order, else densely with
   partial pivoting.  Records which in .how; -1 if the matrix is singular. */
static int bgc_block_factor(bgc_work *w, const bgc_block *b)
{
    const bgc_lu_plan *pl = &b->lu;
    double *save = w->v + b->save, *lu = w->v + b->lu_off, *dense = w->v + b->dense;
    double *scale = w->v + b->scale;
    int *piv = w->iv + b->piv, q, how = 0;
    bgc_row_scales(pl, save, scale);
    if (!pl->dense) {
        memcpy(lu, save, (size_t)pl->nnz * sizeof *lu);
        if (bgc_lu_static(pl, lu, scale) == 0) {
            w->iv[b->how] = 0;
            return 0;
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
    if (w->iv[b->how] == 0)
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
    int it, i, small;
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
        for (i = 0; i < m; i++)
            if (fabs(dz[i]) > 0.01 * (w->atol + w->rtol * fabs(z[i])) &&
                fabs(dz[i]) > 4.0 * DBL_EPSILON * fabs(z[i]))
                small = 0;
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
        norm = trial;
        if (!isfinite(norm))
            return bgc_block_fail(w, k, BGC_BLOCK_NONFINITE, t);
        if (small)
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

int bgc_jacobian(double t, const double *x, const bgc_params *p, bgc_work *w, double *J)
{
    enum { N = BGC_NUM_STATES };
    double *v = w->v + BGC_WORK_JAC, *jv = w->v + BGC_WORK_JAC + BGC_DIM(N);
    int c, k, i, q;
    for (q = 0; q < N * N; q++)
        J[q] = 0.0;
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
                J[bgc_jac_col_rows[q] * N + j] = jv[bgc_jac_col_rows[q]];
        }
    }
    return 0;
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

int bgc_check_constraints(double t, const double *x, const bgc_params *p, FILE *err)
{
    double r[BGC_DIM(BGC_NUM_CONSTRAINTS)] = { 0.0 }, s[BGC_DIM(BGC_NUM_CONSTRAINTS)] = { 0.0 };
    bgc_params q = *p;
    int k, bad = 0;
    bgc_params_update(&q);
    bgc_residual(t, x, &q, r);
    bgc_scale(t, x, &q, s);
    for (k = 0; k < BGC_NUM_CONSTRAINTS; k++) {
        if (fabs(r[k]) <= 1e-9 * s[k])
            continue;
        bad++;
        if (err)
            fprintf(err, "error: initial conditions violate constraint '%s' (%s): residual = %.17g\n",
                    bgc_constraint_names[k], bgc_constraint_levels[k], r[k]);
    }
    return bad;
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
   with movable[i] (all if movable is NULL) change.  0, or -1 singular, -2 no convergence. */
static int bgc_project_rows(double t, double *x, const bgc_params *p, const int *rows, int m,
                            void (*jac)(double, const double *, const bgc_params *, double *),
                            const int *movable)
{
    enum { N = BGC_NUM_STATES, M = BGC_DIM(BGC_NUM_CONSTRAINTS) };
    double r[M] = { 0.0 }, s[M] = { 0.0 }, z[M] = { 0.0 }, A[M * M] = { 0.0 }, J[M * BGC_DIM(N)] = { 0.0 };
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
        for (i = 0; i < m; i++)
            for (k = 0; k < N; k++)
                if (movable && !movable[k])
                    J[i * N + k] = 0.0;
        for (i = 0; i < m; i++)
            for (j = 0; j < m; j++) {
                double sum = 0.0;
                for (k = 0; k < N; k++)
                    sum += J[i * N + k] * J[j * N + k];
                A[i * m + j] = sum;
            }
        if (bgc_solve(m, A, z))
            return -1;
        for (k = 0; k < N; k++) {
            double dx = 0.0;
            for (i = 0; i < m; i++)
                dx += J[i * N + k] * z[i];
            x[k] -= dx;
        }
    }
}

int bgc_project_initial(double t, double *x, const bgc_params *p, char *msg, size_t msg_size)
{
    static const char *const why[] = { "", "the constraint Jacobian is singular",
                                       "no convergence after 50 iterations" };
    bgc_params q = *p;
    const char *level = "position";
    int rc;
    bgc_params_update(&q);
    rc = bgc_project_rows(t, x, &q, bgc_position_rows, BGC_NUM_POSITION_ROWS, bgc_position_jac,
                          NULL);
    if (rc == 0) {
        rc = bgc_project_rows(t, x, &q, bgc_velocity_rows, BGC_NUM_VELOCITY_ROWS,
                              bgc_velocity_jac, bgc_velocity_movable);
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
}

int bgc_check_settings(const bgc_settings *s, char *msg, size_t msg_size)
{
    const char *bad = NULL;
    if (!(isfinite(s->t0) && isfinite(s->t_end) && isfinite(s->dt) && isfinite(s->rtol)
          && isfinite(s->atol) && isfinite(s->step)))
        bad = "settings must be finite numbers";
    else if (!(s->dt > 0.0))
        bad = "--dt must be positive";
    else if (s->t_end < s->t0)
        bad = "--t-end must not be before the start time";
    else if (!(s->rtol > 0.0 && s->atol > 0.0))
        bad = "--rtol and --atol must be positive";
    else if (s->step < 0.0)
        bad = "--step must be positive";
    else if (s->solver < BGC_EULER || s->solver > BGC_DOPRI5)
        bad = "unknown solver";
    else if (!((s->t_end - s->t0) / s->dt <= 1e9))
        bad = "too many output rows (more than 1e9): increase --dt";
    if (!bad)
        return 0;
    snprintf(msg, msg_size, "%s", bad);
    return BGC_ERR_USAGE;
}

/* =============================================================== solve === */

/* Output times: t0 + k*dt for k < n, and t_end for k = n (see the top of the file). */
static long bgc_output_count(const bgc_settings *s)
{
    double n = ceil((s->t_end - s->t0) / s->dt - 1e-6);
    return n > 0.0 ? (long)n : 0;
}

static double bgc_output_time(const bgc_settings *s, long k, long n)
{
    return k >= n ? s->t_end : s->t0 + (double)k * s->dt;
}

/* Steps below this are too small for floating point to resolve at t (16 units in the last
   place of t; DBL_MIN at t = 0). */
static double bgc_hmin(double t)
{
    return bgc_max(16.0 * DBL_EPSILON * fabs(t), DBL_MIN);
}

static int bgc_fail(char *msg, size_t msg_size, double t, const char *what, const char *name)
{
    snprintf(msg, msg_size, "at t = %.17g: %s '%s' is not finite", t, what, name);
    return BGC_ERR_RUNTIME;
}

static int bgc_fail_step(char *msg, size_t msg_size, double t, double h, int worst)
{
    if (worst >= 0)
        snprintf(msg, msg_size, "at t = %.17g: step size too small (h = %.3g), limited by state '%s'",
                 t, h, bgc_state_names[worst]);
    else
        snprintf(msg, msg_size, "at t = %.17g: step size too small (h = %.3g)", t, h);
    return BGC_ERR_RUNTIME;
}

static int bgc_fail_block(char *msg, size_t msg_size, const bgc_work *w)
{
    bgc_work_message(w, msg, msg_size);
    return BGC_ERR_RUNTIME;
}

/* Evaluates the outputs at (t, x), checks them and hands them to the sink. */
static int bgc_emit(const bgc_params *p, bgc_work *w, double t, const double *x, bgc_sink sink,
                    void *ctx, char *msg, size_t msg_size)
{
    double *y = w->v + BGC_WORK_Y;
    int j;
    if (bgc_model_outputs(t, x, p, w, y))
        return bgc_fail_block(msg, msg_size, w);
    j = bgc_first_nonfinite(y, BGC_NUM_OUTPUTS);
    if (j >= 0)
        return bgc_fail(msg, msg_size, t, "output", bgc_output_names[j]);
    return sink ? sink(ctx, t, x, y) : 0;
}

/* Number of fixed steps of size about h in span: steps of h, the last one shorter. */
static long bgc_substeps(double span, double h)
{
    double r = span / h, m;
    if (!(r < 1e15))
        return -1;
    m = ceil(r - 1e-6);
    return m < 1.0 ? 1 : (long)m;
}

/* One explicit Euler (order 1) or classical Runge-Kutta (order 4) step from (t, y) to t + h;
   the stages are in the workspace. */
static int bgc_fixed_step(int solver, const bgc_params *p, bgc_work *w, double t, double h,
                          double *y, bgc_stats *st, char *msg, size_t msg_size)
{
    enum { N = BGC_NUM_STATES, D = BGC_DIM(BGC_NUM_STATES) };
    double *const work = w->v + BGC_WORK_STAGES;
    double *k1 = work, *k2 = work + D, *k3 = work + 2 * D, *k4 = work + 3 * D, *yt = work + 4 * D;
    const double h2 = 0.5 * h, h6 = h / 6.0;
    int i;
    if (bgc_model_rhs(t, y, p, w, k1))
        return bgc_fail_block(msg, msg_size, w);
    st->rhs++;
    i = bgc_first_nonfinite(k1, N);
    if (i >= 0)
        return bgc_fail(msg, msg_size, t, "derivative of state", bgc_state_names[i]);
    if (solver == BGC_EULER) {
        for (i = 0; i < N; i++)
            y[i] = y[i] + h * k1[i];
    } else {
        for (i = 0; i < N; i++)
            yt[i] = y[i] + h2 * k1[i];
        if (bgc_model_rhs(t + h2, yt, p, w, k2))
            return bgc_fail_block(msg, msg_size, w);
        for (i = 0; i < N; i++)
            yt[i] = y[i] + h2 * k2[i];
        if (bgc_model_rhs(t + h2, yt, p, w, k3))
            return bgc_fail_block(msg, msg_size, w);
        for (i = 0; i < N; i++)
            yt[i] = y[i] + h * k3[i];
        if (bgc_model_rhs(t + h, yt, p, w, k4))
            return bgc_fail_block(msg, msg_size, w);
        st->rhs += 3;
        for (i = 0; i < N; i++)
            y[i] = y[i] + h6 * (k1[i] + 2.0 * (k2[i] + k3[i]) + k4[i]);
    }
    st->steps++;
    i = bgc_first_nonfinite(y, N);
    if (i >= 0)
        return bgc_fail(msg, msg_size, t + h, "state", bgc_state_names[i]);
    return 0;
}

/* euler/rk4: steps of s->step (or dt) that land exactly on every output time. */
static int bgc_run_fixed(const bgc_settings *s, const bgc_params *p, bgc_work *w, double *y,
                         bgc_sink sink, void *ctx, bgc_stats *st, char *msg, size_t msg_size)
{
    const long nout = bgc_output_count(s);
    const double hstep = s->step > 0.0 ? s->step : s->dt;
    double ta = s->t0;
    long k, j;
    int rc = bgc_emit(p, w, ta, y, sink, ctx, msg, msg_size);
    for (k = 1; k <= nout && rc == 0; k++) {
        const double tb = bgc_output_time(s, k, nout);
        const long m = bgc_substeps(tb - ta, hstep);
        if (m < 0)
            return bgc_fail_step(msg, msg_size, ta, hstep, -1);
        for (j = 0; j < m && rc == 0; j++) {
            const double t = ta + (double)j * hstep;
            const double t1 = j + 1 == m ? tb : ta + (double)(j + 1) * hstep;
            if (!(t1 - t >= bgc_hmin(t)))
                return bgc_fail_step(msg, msg_size, t, t1 - t, -1);
            rc = bgc_fixed_step(s->solver, p, w, t, t1 - t, y, st, msg, msg_size);
        }
        if (rc == 0)
            rc = bgc_emit(p, w, tb, y, sink, ctx, msg, msg_size);
        ta = tb;
    }
    return rc;
}

/* Dormand-Prince 5(4) coefficients, as in Hairer's DOPRI5. */
#define BGC_C2 (1.0 / 5.0)
#define BGC_C3 (3.0 / 10.0)
#define BGC_C4 (4.0 / 5.0)
#define BGC_C5 (8.0 / 9.0)
#define BGC_A21 (1.0 / 5.0)
#define BGC_A31 (3.0 / 40.0)
#define BGC_A32 (9.0 / 40.0)
#define BGC_A41 (44.0 / 45.0)
#define BGC_A42 (-56.0 / 15.0)
#define BGC_A43 (32.0 / 9.0)
#define BGC_A51 (19372.0 / 6561.0)
#define BGC_A52 (-25360.0 / 2187.0)
#define BGC_A53 (64448.0 / 6561.0)
#define BGC_A54 (-212.0 / 729.0)
#define BGC_A61 (9017.0 / 3168.0)
#define BGC_A62 (-355.0 / 33.0)
#define BGC_A63 (46732.0 / 5247.0)
#define BGC_A64 (49.0 / 176.0)
#define BGC_A65 (-5103.0 / 18656.0)
#define BGC_A71 (35.0 / 384.0)
#define BGC_A73 (500.0 / 1113.0)
#define BGC_A74 (125.0 / 192.0)
#define BGC_A75 (-2187.0 / 6784.0)
#define BGC_A76 (11.0 / 84.0)
#define BGC_E1 (71.0 / 57600.0)
#define BGC_E3 (-71.0 / 16695.0)
#define BGC_E4 (71.0 / 1920.0)
#define BGC_E5 (-17253.0 / 339200.0)
#define BGC_E6 (22.0 / 525.0)
#define BGC_E7 (-1.0 / 40.0)
#define BGC_D1 (-12715105075.0 / 11282082432.0)
#define BGC_D3 (87487479700.0 / 32700410799.0)
#define BGC_D4 (-10690763975.0 / 1880347072.0)
#define BGC_D5 (701980252875.0 / 199316789632.0)
#define BGC_D6 (-1453857185.0 / 822651844.0)
#define BGC_D7 (69997945.0 / 29380423.0)
/* Step size control: safety factor, factor limits, Lund stabilisation (beta). */
#define BGC_SAFE 0.9
#define BGC_FACC1 5.0  /* 1 / smallest factor 0.2 */
#define BGC_FACC2 0.1  /* 1 / largest factor 10 */
#define BGC_BETA 0.04
#define BGC_EXPO1 (0.2 - BGC_BETA * 0.75)

/* Hairer's initial step size guess (HINIT with order 5). */
static double bgc_initial_step(const bgc_settings *s, const bgc_params *p, bgc_work *w,
                               double t, const double *y, const double *f0, double hmax,
                               double *y1, double *f1, bgc_stats *st)
{
    enum { N = BGC_NUM_STATES };
    double dnf = 0.0, dny = 0.0, der2 = 0.0, der12, h, h1;
    int i;
    for (i = 0; i < N; i++) {
        const double sk = s->atol + s->rtol * fabs(y[i]);
        const double qf = f0[i] / sk, qy = y[i] / sk;
        dnf += qf * qf;
        dny += qy * qy;
    }
    h = (dnf <= 1e-10 || dny <= 1e-10) ? 1e-6 : sqrt(dny / dnf) * 0.01;
    h = bgc_min(h, hmax);
    for (i = 0; i < N; i++)
        y1[i] = y[i] + h * f0[i];
    st->rhs++;
    if (bgc_model_rhs(t + h, y1, p, w, f1))
        return h; /* a block failed there: start small, the step control takes over */
    for (i = 0; i < N; i++) {
        const double q = (f1[i] - f0[i]) / (s->atol + s->rtol * fabs(y[i]));
        der2 += q * q;
    }
    der2 = sqrt(der2) / h;
    der12 = bgc_max(sqrt(dnf), fabs(der2)); /* a NaN der2 is ignored */
    h1 = der12 <= 1e-15 ? bgc_max(1e-6, h * 1e-3) : pow(0.01 / der12, 0.2);
    if (!(h1 > 0.0))
        h1 = h * 1e-3;
    return bgc_min(bgc_min(100.0 * h, h1), hmax);
}

/* First non-finite value of a failed dopri5 trial step: *kind 1 state, 2 derivative. */
static int bgc_trial_culprit(const double *y1, const double *const *k, int *kind)
{
    int i, j;
    *kind = 1;
    i = bgc_first_nonfinite(y1, BGC_NUM_STATES);
    for (j = 0; j < 6 && i < 0; j++) {
        *kind = 2;
        i = bgc_first_nonfinite(k[j], BGC_NUM_STATES);
    }
    return i;
}

/* Dense output: Hairer's continuous extension of order 4 (CONTD5) at theta in [0, 1]. */
static void bgc_dense(const double *const *r, double theta, double *yout)
{
    const double theta1 = 1.0 - theta;
    int i;
    for (i = 0; i < BGC_NUM_STATES; i++)
        yout[i] = r[0][i] + theta * (r[1][i] + theta1 * (r[2][i] + theta * (r[3][i] + theta1 * r[4][i])));
}

/* dopri5: adaptive steps (never shortened for output), outputs by dense output. */
static int bgc_run_dopri5(const bgc_settings *s, const bgc_params *p, bgc_work *w, double *y,
                          bgc_sink sink, void *ctx, bgc_stats *st, char *msg, size_t msg_size)
{
    enum { N = BGC_NUM_STATES, D = BGC_DIM(BGC_NUM_STATES) };
    double *const work = w->v + BGC_WORK_STAGES;
    double *ys = work, *y1 = work + D, *yout = work + 2 * D, *k1 = work + 3 * D;
    double *k2 = work + 4 * D, *k3 = work + 5 * D, *k4 = work + 6 * D, *k5 = work + 7 * D;
    double *k6 = work + 8 * D, *k7 = work + 9 * D, *r1 = work + 10 * D, *r2 = work + 11 * D;
    double *r3 = work + 12 * D, *r4 = work + 13 * D, *r5 = work + 14 * D;
    const double *const stages[6] = { k2, k3, k4, k5, k6, k7 };
    const double *const dense[5] = { r1, r2, r3, r4, r5 };
    const long nout = bgc_output_count(s);
    const double hmax = s->t_end - s->t0;
    double t = s->t0, h, hnew, facold = 1e-4;
    long kout = 1;
    int i, rc, reject = 0, last = 0, worst = -1, bad = -1, bad_kind = 0, failed;

    rc = bgc_emit(p, w, t, y, sink, ctx, msg, msg_size);
    if (rc || nout == 0)
        return rc;
    st->rhs++;
    if (bgc_model_rhs(t, y, p, w, k1))
        return bgc_fail_block(msg, msg_size, w);
    i = bgc_first_nonfinite(k1, N);
    if (i >= 0)
        return bgc_fail(msg, msg_size, t, "derivative of state", bgc_state_names[i]);
    h = bgc_initial_step(s, p, w, t, y, k1, hmax, ys, k2, st);

    for (;;) {
        double tph, err = 0.0, worst_q = -1.0, fac11, fac;
        if (!(h >= bgc_hmin(t))) {
            if (bad == -2)
                return bgc_fail_block(msg, msg_size, w);
            if (bad >= 0)
                return bgc_fail(msg, msg_size, t, bad_kind == 1 ? "state" : "derivative of state",
                                bgc_state_names[bad]);
            return bgc_fail_step(msg, msg_size, t, h, worst);
        }
        if (t + 1.01 * h - s->t_end > 0.0) {
            h = s->t_end - t;
            last = 1;
        }
        tph = last ? s->t_end : t + h;
        for (i = 0; i < N; i++)
            ys[i] = y[i] + h * BGC_A21 * k1[i];
        failed = bgc_model_rhs(t + BGC_C2 * h, ys, p, w, k2);
        for (i = 0; i < N; i++)
            ys[i] = y[i] + h * (BGC_A31 * k1[i] + BGC_A32 * k2[i]);
        failed = failed || bgc_model_rhs(t + BGC_C3 * h, ys, p, w, k3);
        for (i = 0; i < N; i++)
            ys[i] = y[i] + h * (BGC_A41 * k1[i] + BGC_A42 * k2[i] + BGC_A43 * k3[i]);
        failed = failed || bgc_model_rhs(t + BGC_C4 * h, ys, p, w, k4);
        for (i = 0; i < N; i++)
            ys[i] = y[i] + h * (BGC_A51 * k1[i] + BGC_A52 * k2[i] + BGC_A53 * k3[i] + BGC_A54 * k4[i]);
        failed = failed || bgc_model_rhs(t + BGC_C5 * h, ys, p, w, k5);
        for (i = 0; i < N; i++)
            ys[i] = y[i] + h * (BGC_A61 * k1[i] + BGC_A62 * k2[i] + BGC_A63 * k3[i] + BGC_A64 * k4[i]
                                + BGC_A65 * k5[i]);
        failed = failed || bgc_model_rhs(tph, ys, p, w, k6);
        for (i = 0; i < N; i++)
            y1[i] = y[i] + h * (BGC_A71 * k1[i] + BGC_A73 * k3[i] + BGC_A74 * k4[i] + BGC_A75 * k5[i]
                                + BGC_A76 * k6[i]);
        failed = failed || bgc_model_rhs(tph, y1, p, w, k7);
        st->rhs += 6;
        if (failed) { /* an algebraic block failed in a stage: retry with a much smaller step */
            bad = -2;
            h = h / BGC_FACC1;
            reject = 1;
            last = 0;
            st->rejected++;
            continue;
        }

        /* Hairer's error norm: RMS of err_i / (atol + rtol * max(|y_i|, |y1_i|)). */
        for (i = 0; i < N; i++) {
            const double sk = s->atol + s->rtol * bgc_max(fabs(y[i]), fabs(y1[i]));
            const double q = h * (BGC_E1 * k1[i] + BGC_E3 * k3[i] + BGC_E4 * k4[i] + BGC_E5 * k5[i]
                                  + BGC_E6 * k6[i] + BGC_E7 * k7[i]) / sk;
            err += q * q;
            if (q * q > worst_q) {
                worst_q = q * q;
                worst = i;
            }
        }
        err = N > 0 ? sqrt(err / N) : 0.0;
        if (err != err) { /* a non-finite stage: retry with a much smaller step */
            bad = bgc_trial_culprit(y1, stages, &bad_kind);
            h = h / BGC_FACC1;
            reject = 1;
            last = 0;
            st->rejected++;
            continue;
        }

        fac11 = pow(err, BGC_EXPO1);
        fac = fac11 / pow(facold, BGC_BETA);
        fac = bgc_max(BGC_FACC2, bgc_min(BGC_FACC1, fac / BGC_SAFE));
        hnew = h / fac;
        if (err <= 1.0) {
            facold = bgc_max(err, 1e-4);
            st->steps++;
            i = bgc_first_nonfinite(y1, N);
            if (i >= 0)
                return bgc_fail(msg, msg_size, tph, "state", bgc_state_names[i]);
            for (i = 0; i < N; i++) {
                const double ydiff = y1[i] - y[i], bspl = h * k1[i] - ydiff;
                r1[i] = y[i];
                r2[i] = ydiff;
                r3[i] = bspl;
                r4[i] = -h * k7[i] + ydiff - bspl;
                r5[i] = h * (BGC_D1 * k1[i] + BGC_D3 * k3[i] + BGC_D4 * k4[i] + BGC_D5 * k5[i]
                             + BGC_D6 * k6[i] + BGC_D7 * k7[i]);
            }
            for (; kout <= nout; kout++) {
                const double tk = bgc_output_time(s, kout, nout);
                if (tk > tph)
                    break;
                if (tk == tph) {
                    rc = bgc_emit(p, w, tk, y1, sink, ctx, msg, msg_size);
                } else {
                    bgc_dense(dense, (tk - t) / h, yout);
                    rc = bgc_emit(p, w, tk, yout, sink, ctx, msg, msg_size);
                }
                if (rc)
                    return rc;
            }
            for (i = 0; i < N; i++) {
                k1[i] = k7[i];
                y[i] = y1[i];
            }
            t = tph;
            if (last)
                return 0;
            if (fabs(hnew) > hmax)
                hnew = hmax;
            if (reject)
                hnew = bgc_min(hnew, h);
            reject = 0;
            bad = -1;
        } else {
            hnew = h / bgc_min(BGC_FACC1, fac11 / BGC_SAFE);
            reject = 1;
            last = 0;
            st->rejected++;
        }
        h = hnew;
    }
}

int bgc_simulate(const bgc_settings *s, const bgc_params *p, const double *x0, bgc_sink sink,
                 void *ctx, bgc_stats *stats, char *msg, size_t msg_size)
{
    bgc_params q = *p;
    bgc_work *w;
    double *y;
    int i, rc = bgc_check_settings(s, msg, msg_size);
    if (rc)
        return rc;
    w = bgc_work_new();
    if (!w) {
        snprintf(msg, msg_size, "out of memory");
        return BGC_ERR_RUNTIME;
    }
    w->rtol = s->rtol;
    w->atol = s->atol;
    y = w->v + BGC_WORK_Y0;
    bgc_params_update(&q);
    for (i = 0; i < BGC_NUM_STATES; i++)
        y[i] = x0[i];
    i = bgc_first_nonfinite(y, BGC_NUM_STATES);
    if (i >= 0)
        rc = bgc_fail(msg, msg_size, s->t0, "state", bgc_state_names[i]);
    else if (s->solver == BGC_DOPRI5)
        rc = bgc_run_dopri5(s, &q, w, y, sink, ctx, stats, msg, msg_size);
    else
        rc = bgc_run_fixed(s, &q, w, y, sink, ctx, stats, msg, msg_size);
    bgc_work_free(w);
    return rc;
}

#ifndef BGC_NO_MAIN
/* ================================================================ CSV === */

/* Numbers are written exactly as printf("%.17g") writes them (NaN as "nan"), in integer
   arithmetic: |v| = M 2^q (M < 2^53) times 10^m, a 128-bit mantissa from bgc_pow10 rounded
   down, is one 192-bit product whose integer part is v's 17 significant digits and whose
   next 64 bits, the fraction, are off by less than 1/8 of their last place.  That decides
   the rounding to nearest unless the fraction lies within that error of one half (exact
   ties, about one value in 2^63 otherwise): snprintf writes those, and subnormals,
   infinities and |v| outside 1e-40..1e40 (the range of the table).  Compile with
   -DBGC_PLAIN_PRINTF to always use snprintf. */
#define BGC_FMT_SIZE 32 /* bgc_fmt17 writes at most 26 bytes (it stores whole words) */
static unsigned long bgc_fmt_slow_count; /* snprintf fallbacks, for tests */

static int bgc_fmt_printf(char *buf, double v)
{
    bgc_fmt_slow_count++;
    if (v != v) {
        memcpy(buf, "nan", 4);
        return 3;
    }
    return snprintf(buf, BGC_FMT_SIZE, "%.17g", v);
}

#if !defined(BGC_PLAIN_PRINTF) && FLT_RADIX == 2 && DBL_MANT_DIG == 53 && DBL_MAX_EXP == 1024 \
    && ULLONG_MAX == 0xffffffffffffffffULL
typedef unsigned long long bgc_u64;

#if defined(__SIZEOF_INT128__) && !defined(BGC_NO_INT128)
__extension__ typedef unsigned __int128 bgc_u128;
/* a * b = (returned) 2^64 + *lo. */
static inline bgc_u64 bgc_mul64(bgc_u64 a, bgc_u64 b, bgc_u64 *lo)
{
    const bgc_u128 prod = (bgc_u128)a * b;
    *lo = (bgc_u64)prod;
    return (bgc_u64)(prod >> 64);
}
#else
/* a * b = (returned) 2^64 + *lo, from 32-bit halves (C99 has no 128-bit integer). */
static inline bgc_u64 bgc_mul64(bgc_u64 a, bgc_u64 b, bgc_u64 *lo)
{
    const bgc_u64 mask = 0xffffffffULL, a0 = a & mask, a1 = a >> 32, b0 = b & mask, b1 = b >> 32;
    const bgc_u64 p00 = a0 * b0, p01 = a0 * b1, p10 = a1 * b0;
    const bgc_u64 mid = (p00 >> 32) + (p01 & mask) + (p10 & mask);
    *lo = (mid << 32) | (p00 & mask);
    return a1 * b1 + (p01 >> 32) + (p10 >> 32) + (mid >> 32);
}
#endif

/* 10^m = (hi 2^64 + lo) 2^e2 rounded down, 2^127 <= hi 2^64 + lo < 2^128, for m in
   BGC_POW10_MIN..BGC_POW10_MAX. */
#define BGC_POW10_MIN (-24)
#define BGC_POW10_MAX 56
static const struct bgc_pow10_entry {
    bgc_u64 hi, lo;
    int e2;
} bgc_pow10[] = {
    { 0x9abe14cd44753b52ULL, 0xc4926a9672793542ULL, -207 }, /* 1e-24 */
    { 0xc16d9a0095928a27ULL, 0x75b7053c0f178293ULL, -204 }, /* 1e-23 */
    { 0xf1c90080baf72cb1ULL, 0x5324c68b12dd6338ULL, -201 }, /* 1e-22 */
    { 0x971da05074da7beeULL, 0xd3f6fc16ebca5e03ULL, -197 }, /* 1e-21 */
    { 0xbce5086492111aeaULL, 0x88f4bb1ca6bcf584ULL, -194 }, /* 1e-20 */
    { 0xec1e4a7db69561a5ULL, 0x2b31e9e3d06c32e5ULL, -191 }, /* 1e-19 */
    { 0x9392ee8e921d5d07ULL, 0x3aff322e62439fcfULL, -187 }, /* 1e-18 */
    { 0xb877aa3236a4b449ULL, 0x09befeb9fad487c2ULL, -184 }, /* 1e-17 */
    { 0xe69594bec44de15bULL, 0x4c2ebe687989a9b3ULL, -181 }, /* 1e-16 */
    { 0x901d7cf73ab0acd9ULL, 0x0f9d37014bf60a10ULL, -177 }, /* 1e-15 */
    { 0xb424dc35095cd80fULL, 0x538484c19ef38c94ULL, -174 }, /* 1e-14 */
    { 0xe12e13424bb40e13ULL, 0x2865a5f206b06fb9ULL, -171 }, /* 1e-13 */
    { 0x8cbccc096f5088cbULL, 0xf93f87b7442e45d3ULL, -167 }, /* 1e-12 */
    { 0xafebff0bcb24aafeULL, 0xf78f69a51539d748ULL, -164 }, /* 1e-11 */
    { 0xdbe6fecebdedd5beULL, 0xb573440e5a884d1bULL, -161 }, /* 1e-10 */
    { 0x89705f4136b4a597ULL, 0x31680a88f8953030ULL, -157 }, /* 1e-9 */
    { 0xabcc77118461cefcULL, 0xfdc20d2b36ba7c3dULL, -154 }, /* 1e-8 */
    { 0xd6bf94d5e57a42bcULL, 0x3d32907604691b4cULL, -151 }, /* 1e-7 */
    { 0x8637bd05af6c69b5ULL, 0xa63f9a49c2c1b10fULL, -147 }, /* 1e-6 */
    { 0xa7c5ac471b478423ULL, 0x0fcf80dc33721d53ULL, -144 }, /* 1e-5 */
    { 0xd1b71758e219652bULL, 0xd3c36113404ea4a8ULL, -141 }, /* 1e-4 */
    { 0x83126e978d4fdf3bULL, 0x645a1cac083126e9ULL, -137 }, /* 1e-3 */
    { 0xa3d70a3d70a3d70aULL, 0x3d70a3d70a3d70a3ULL, -134 }, /* 1e-2 */
    { 0xccccccccccccccccULL, 0xccccccccccccccccULL, -131 }, /* 1e-1 */
    { 0x8000000000000000ULL, 0x0000000000000000ULL, -127 }, /* 1e0 */
    { 0xa000000000000000ULL, 0x0000000000000000ULL, -124 }, /* 1e1 */
    { 0xc800000000000000ULL, 0x0000000000000000ULL, -121 }, /* 1e2 */
    { 0xfa00000000000000ULL, 0x0000000000000000ULL, -118 }, /* 1e3 */
    { 0x9c40000000000000ULL, 0x0000000000000000ULL, -114 }, /* 1e4 */
    { 0xc350000000000000ULL, 0x0000000000000000ULL, -111 }, /* 1e5 */
    { 0xf424000000000000ULL, 0x0000000000000000ULL, -108 }, /* 1e6 */
    { 0x9896800000000000ULL, 0x0000000000000000ULL, -104 }, /* 1e7 */
    { 0xbebc200000000000ULL, 0x0000000000000000ULL, -101 }, /* 1e8 */
    { 0xee6b280000000000ULL, 0x0000000000000000ULL, -98 }, /* 1e9 */
    { 0x9502f90000000000ULL, 0x0000000000000000ULL, -94 }, /* 1e10 */
    { 0xba43b74000000000ULL, 0x0000000000000000ULL, -91 }, /* 1e11 */
    { 0xe8d4a51000000000ULL, 0x0000000000000000ULL, -88 }, /* 1e12 */
    { 0x9184e72a00000000ULL, 0x0000000000000000ULL, -84 }, /* 1e13 */
    { 0xb5e620f480000000ULL, 0x0000000000000000ULL, -81 }, /* 1e14 */
    { 0xe35fa931a0000000ULL, 0x0000000000000000ULL, -78 }, /* 1e15 */
    { 0x8e1bc9bf04000000ULL, 0x0000000000000000ULL, -74 }, /* 1e16 */
    { 0xb1a2bc2ec5000000ULL, 0x0000000000000000ULL, -71 }, /* 1e17 */
    { 0xde0b6b3a76400000ULL, 0x0000000000000000ULL, -68 }, /* 1e18 */
    { 0x8ac7230489e80000ULL, 0x0000000000000000ULL, -64 }, /* 1e19 */
    { 0xad78ebc5ac620000ULL, 0x0000000000000000ULL, -61 }, /* 1e20 */
    { 0xd8d726b7177a8000ULL, 0x0000000000000000ULL, -58 }, /* 1e21 */
    { 0x878678326eac9000ULL, 0x0000000000000000ULL, -54 }, /* 1e22 */
    { 0xa968163f0a57b400ULL, 0x0000000000000000ULL, -51 }, /* 1e23 */
    { 0xd3c21bcecceda100ULL, 0x0000000000000000ULL, -48 }, /* 1e24 */
    { 0x84595161401484a0ULL, 0x0000000000000000ULL, -44 }, /* 1e25 */
    { 0xa56fa5b99019a5c8ULL, 0x0000000000000000ULL, -41 }, /* 1e26 */
    { 0xcecb8f27f4200f3aULL, 0x0000000000000000ULL, -38 }, /* 1e27 */
    { 0x813f3978f8940984ULL, 0x4000000000000000ULL, -34 }, /* 1e28 */
    { 0xa18f07d736b90be5ULL, 0x5000000000000000ULL, -31 }, /* 1e29 */
    { 0xc9f2c9cd04674edeULL, 0xa400000000000000ULL, -28 }, /* 1e30 */
    { 0xfc6f7c4045812296ULL, 0x4d00000000000000ULL, -25 }, /* 1e31 */
    { 0x9dc5ada82b70b59dULL, 0xf020000000000000ULL, -21 }, /* 1e32 */
    { 0xc5371912364ce305ULL, 0x6c28000000000000ULL, -18 }, /* 1e33 */
    { 0xf684df56c3e01bc6ULL, 0xc732000000000000ULL, -15 }, /* 1e34 */
    { 0x9a130b963a6c115cULL, 0x3c7f400000000000ULL, -11 }, /* 1e35 */
    { 0xc097ce7bc90715b3ULL, 0x4b9f100000000000ULL, -8 }, /* 1e36 */
    { 0xf0bdc21abb48db20ULL, 0x1e86d40000000000ULL, -5 }, /* 1e37 */
    { 0x96769950b50d88f4ULL, 0x1314448000000000ULL, -1 }, /* 1e38 */
    { 0xbc143fa4e250eb31ULL, 0x17d955a000000000ULL, 2 }, /* 1e39 */
    { 0xeb194f8e1ae525fdULL, 0x5dcfab0800000000ULL, 5 }, /* 1e40 */
    { 0x92efd1b8d0cf37beULL, 0x5aa1cae500000000ULL, 9 }, /* 1e41 */
    { 0xb7abc627050305adULL, 0xf14a3d9e40000000ULL, 12 }, /* 1e42 */
    { 0xe596b7b0c643c719ULL, 0x6d9ccd05d0000000ULL, 15 }, /* 1e43 */
    { 0x8f7e32ce7bea5c6fULL, 0xe4820023a2000000ULL, 19 }, /* 1e44 */
    { 0xb35dbf821ae4f38bULL, 0xdda2802c8a800000ULL, 22 }, /* 1e45 */
    { 0xe0352f62a19e306eULL, 0xd50b2037ad200000ULL, 25 }, /* 1e46 */
    { 0x8c213d9da502de45ULL, 0x4526f422cc340000ULL, 29 }, /* 1e47 */
    { 0xaf298d050e4395d6ULL, 0x9670b12b7f410000ULL, 32 }, /* 1e48 */
    { 0xdaf3f04651d47b4cULL, 0x3c0cdd765f114000ULL, 35 }, /* 1e49 */
    { 0x88d8762bf324cd0fULL, 0xa5880a69fb6ac800ULL, 39 }, /* 1e50 */
    { 0xab0e93b6efee0053ULL, 0x8eea0d047a457a00ULL, 42 }, /* 1e51 */
    { 0xd5d238a4abe98068ULL, 0x72a4904598d6d880ULL, 45 }, /* 1e52 */
    { 0x85a36366eb71f041ULL, 0x47a6da2b7f864750ULL, 49 }, /* 1e53 */
    { 0xa70c3c40a64e6c51ULL, 0x999090b65f67d924ULL, 52 }, /* 1e54 */
    { 0xd0cf4b50cfe20765ULL, 0xfff4b4e3f741cf6dULL, 55 }, /* 1e55 */
    { 0x82818f1281ed449fULL, 0xbff8f10e7a8921a4ULL, 59 }, /* 1e56 */
};

/* floor(log10(2^e)) for |e| <= 1650 (the constant is Ryu's). */
static int bgc_floor_log10_pow2(int e)
{
    return e >= 0 ? (int)(((unsigned long)e * 78913UL) >> 18)
                  : -(int)((((unsigned long)-e * 78913UL) >> 18) + 1);
}

/* floor(mant 2^q 10^m) and (in *frac) the next 64 bits, for mant < 2^53 and a result in
   [2^53, 2^60); the fraction is short by less than 1/8 of its last place. */
static inline bgc_u64 bgc_scaled(bgc_u64 mant, int q, int m, bgc_u64 *frac)
{
    const struct bgc_pow10_entry *p = &bgc_pow10[m - BGC_POW10_MIN];
    bgc_u64 w0, w1, w2, mid_lo;
    const bgc_u64 mid = bgc_mul64(mant, p->lo, &w0);
    int shift;
    w2 = bgc_mul64(mant, p->hi, &mid_lo);
    w1 = mid + mid_lo;
    w2 += w1 < mid; /* the product is w2 2^128 + w1 2^64 + w0 */
    shift = -(q + p->e2) - 64; /* 56..63: the binary point lies that far into w1 */
    *frac = (w1 << (64 - shift)) | (w0 >> shift);
    return (w2 << (64 - shift)) | (w1 >> shift);
}

/* The 8 digits of v < 10^8, all at once, as the word whose byte i (bits 8i..8i+7) is the
   character of digit i: v splits into two 4-digit lanes, each into two 2-digit lanes, each
   of those into two digits (the multiply-shifts divide exactly in these ranges). */
static inline bgc_u64 bgc_digits8(bgc_u64 v)
{
    const bgc_u64 high4 = (v * 109951163U) >> 40; /* v / 10000 */
    const bgc_u64 quads = high4 | (v - 10000U * high4) << 32;
    const bgc_u64 top2 = ((quads * 10486U) >> 20) & 0x0000007f0000007fULL; /* quads / 100 */
    const bgc_u64 pairs = (quads - 100U * top2) << 16 | top2;
    const bgc_u64 top1 = ((pairs * 103U) >> 10) & 0x000f000f000f000fULL; /* pairs / 10 */
    return ((pairs - 10U * top1) << 8 | top1) | 0x3030303030303030ULL;
}

/* Byte i of w into o[i], i < 8: one store where the bytes of a word are in that order
   (the test is a constant that compilers fold). */
static inline void bgc_store8(char *o, bgc_u64 w)
{
    const bgc_u64 one = 1;
    char first;
    int i;
    memcpy(&first, &one, 1);
    if (first == 1) {
        memcpy(o, &w, 8);
        return;
    }
    for (i = 0; i < 8; i++)
        o[i] = (char)(w >> (8 * i));
}

/* The %g layout of the 17 digits of d (10^16 <= d < 10^17) with decimal exponent x: fixed
   for -4 <= x < 17, else e-style.  The digits stay in registers (never stored and read
   back); whole words are stored, so it writes up to o[24]. */
static inline char *bgc_layout(char *o, bgc_u64 d, int x)
{
    const bgc_u64 high9 = d / 100000000U, low8 = d - 100000000U * high9;
    const bgc_u64 lead = high9 / 100000000U;
    const bgc_u64 w1 = bgc_digits8(high9 - 100000000U * lead), w2 = bgc_digits8(low8);
    int nd = 17, ax; /* significant digits without the trailing zeros */
    if ((w2 >> 56) == '0') /* the last digit */
        for (d /= 10U, nd--; d % 10U == 0; d /= 10U)
            nd--;
    o[0] = (char)('0' + lead);
    if (x >= 0 && x < 17) { /* digits 0..x, and '.' and digits x+1..nd-1 if nd > x + 1 */
        bgc_store8(o + 1, w1);
        bgc_store8(o + 9, w2);
        if (nd <= x + 1)
            return o + x + 1;
        if (x == 0) {
            bgc_store8(o + 2, w1);
            bgc_store8(o + 10, w2);
        } else if (x < 8) { /* digits x+1.. are w1:w2 shifted down by x bytes */
            bgc_store8(o + x + 2, w1 >> (8 * x) | w2 << (64 - 8 * x));
            bgc_store8(o + x + 10, w2 >> (8 * x));
        } else {
            bgc_store8(o + x + 2, w2 >> (8 * x - 64));
        }
        o[x + 1] = '.';
        return o + nd + 1;
    }
    if (x < 0 && x >= -4) { /* "0.", -x - 1 zeros, the digits */
        const char lead_char = o[0];
        memcpy(o, "0.000", 5);
        o += 1 - x;
        o[0] = lead_char;
        bgc_store8(o + 1, w1);
        bgc_store8(o + 9, w2);
        return o + nd;
    }
    o[1] = '.';
    bgc_store8(o + 2, w1);
    bgc_store8(o + 10, w2);
    o += nd > 1 ? nd + 1 : 1;
    ax = x < 0 ? -x : x;
    *o++ = 'e';
    *o++ = x < 0 ? '-' : '+';
    if (ax >= 100) {
        *o++ = (char)('0' + ax / 100);
        ax %= 100;
    }
    o[0] = (char)('0' + ax / 10);
    o[1] = (char)('0' + ax % 10);
    return o + 2;
}

/* Writes v into buf (>= BGC_FMT_SIZE bytes) as printf("%.17g", v); returns the length. */
static int bgc_fmt17(char *buf, double v)
{
    const bgc_u64 half = 1ULL << 63, ten17 = 100000000000000000ULL;
    bgc_u64 bits, mant, d, frac;
    char *o = buf;
    int e2, x, m;
    memcpy(&bits, &v, sizeof bits);
    e2 = (int)((bits >> 52) & 0x7ff); /* biased binary exponent */
    if (e2 == 0 || e2 == 0x7ff) {
        if (v != 0.0)
            return bgc_fmt_printf(buf, v); /* subnormal, inf or nan */
        if (signbit(v))
            *o++ = '-';
        *o++ = '0';
        *o = '\0';
        return (int)(o - buf);
    }
    mant = (bits & 0xfffffffffffffULL) | (1ULL << 52);
    x = bgc_floor_log10_pow2(e2 - 1023); /* floor(log10|v|) or one less */
    m = 16 - x;
    if (m - 1 < BGC_POW10_MIN || m > BGC_POW10_MAX)
        return bgc_fmt_printf(buf, v);
    d = bgc_scaled(mant, e2 - 1075, m, &frac);
    if (d >= ten17) {
        x++;
        d = bgc_scaled(mant, e2 - 1075, --m, &frac);
    }
    if (frac - (half - 1) <= 1)
        return bgc_fmt_printf(buf, v); /* too close to a tie to decide */
    d += frac >> 63; /* rounded to nearest */
    if (d == ten17) {
        d /= 10;
        x++;
    }
    *o = '-';
    o = bgc_layout(o + (bits >> 63), d, x);
    *o = '\0';
    return (int)(o - buf);
}
#else
static int bgc_fmt17(char *buf, double v)
{
    return bgc_fmt_printf(buf, v);
}
#endif

typedef struct bgc_writer {
    FILE *file;
    size_t len;
    int failed;
    char buf[1 << 16];
} bgc_writer;

static bgc_writer bgc_out;

static void bgc_flush(bgc_writer *w)
{
    if (w->len && fwrite(w->buf, 1, w->len, w->file) != w->len)
        w->failed = 1;
    w->len = 0;
}

static void bgc_put_number(bgc_writer *w, double v)
{
    if (sizeof w->buf - w->len < BGC_FMT_SIZE + 2)
        bgc_flush(w);
    w->len += (size_t)bgc_fmt17(w->buf + w->len, v);
}

static int bgc_csv_row(void *ctx, double t, const double *x, const double *y)
{
    bgc_writer *w = (bgc_writer *)ctx;
    int j;
    (void)x;
    bgc_put_number(w, t);
    for (j = 0; j < BGC_NUM_OUTPUTS; j++) {
        w->buf[w->len++] = ',';
        bgc_put_number(w, y[j]);
    }
    w->buf[w->len++] = '\n';
    return w->failed ? BGC_ERR_RUNTIME : 0;
}

static void bgc_csv_header(FILE *f)
{
    int j;
    fputs("t", f);
    for (j = 0; j < BGC_NUM_OUTPUTS; j++) {
        fputc(',', f);
        fputs(bgc_output_names[j], f);
    }
    fputc('\n', f);
}

/* ======================================================== command line === */

static const char bgc_usage[] =
    " [--t-end T] [--dt DT] [--solver euler|rk4|dopri5] [--rtol R] [--atol A]\n"
    "       [--step H] [-p NAME=VALUE ...] [--project-initial] [--stats]\n";

static void bgc_print_usage(FILE *f)
{
    fprintf(f, "usage: %s%s", bgc_ident, bgc_usage);
}

static void bgc_help(void)
{
    bgc_settings s;
    bgc_params p;
    int j;
    static const char *const solvers[] = { "euler", "rk4", "dopri5" };
    bgc_settings_default(&s);
    bgc_params_defaults(&p, NULL);
    bgc_print_usage(stdout);
    printf("Simulates the model and writes CSV (t and the outputs) to stdout.\n"
           "  --t-end T          end time (%.17g; the start time is %.17g)\n"
           "  --dt DT            output interval (%.17g)\n"
           "  --solver NAME      euler, rk4 or dopri5 (%s)\n"
           "  --rtol R           relative tolerance of dopri5 (%.17g)\n"
           "  --atol A           absolute tolerance of dopri5 (%.17g)\n"
           "  --step H           fixed step of euler and rk4 (default: dt)\n"
           "  -p NAME=VALUE      set a parameter; derived parameters follow\n"
           "  --project-initial  project the initial state onto the constraints\n"
           "  --stats            print step statistics to stderr\n",
           s.t_end, s.t0, s.dt, solvers[s.solver], s.rtol, s.atol);
    if (BGC_NUM_PARAMS > 0)
        printf("parameters (NAME = default):\n");
    for (j = 0; j < BGC_NUM_PARAMS; j++)
        printf("  %s = %.17g\n", bgc_param_names[j], *bgc_param_ref(&p, j));
}

/* A decimal number (digits, sign, '.', exponent: no hex, inf or nan), finite. */
static int bgc_parse_number(const char *option, const char *text, double *out)
{
    char *end;
    if (*text != '\0' && strspn(text, "0123456789+-.eE") == strlen(text)) {
        *out = strtod(text, &end);
        if (*end == '\0' && isfinite(*out))
            return 0;
    }
    fprintf(stderr, "error: invalid value for %s: '%s'\n", option, text);
    return -1;
}

static int bgc_parse_param(const char *text, bgc_params *p, int *given)
{
    const char *eq = strrchr(text, '=');
    char name[256];
    size_t len = eq ? (size_t)(eq - text) : 0;
    int j;
    double v;
    if (!eq || len == 0 || len >= sizeof name) {
        fprintf(stderr, "error: -p expects NAME=VALUE, got '%s'\n", text);
        return -1;
    }
    memcpy(name, text, len);
    name[len] = '\0';
    j = bgc_param_index(name);
    if (j < 0) {
        fprintf(stderr, "error: unknown parameter '%s'\n", name);
        return -1;
    }
    if (bgc_parse_number(name, eq + 1, &v))
        return -1;
    *bgc_param_ref(p, j) = v;
    given[j] = 1;
    return 0;
}

static int bgc_parse_solver(const char *text, int *solver)
{
    static const char *const names[] = { "euler", "rk4", "dopri5" };
    int k;
    for (k = 0; k < 3; k++)
        if (strcmp(text, names[k]) == 0) {
            *solver = k;
            return 0;
        }
    fprintf(stderr, "error: unknown solver '%s' (expected euler, rk4 or dopri5)\n", text);
    return -1;
}

/* Applies option `name` (one that takes a value) to the run. */
static int bgc_apply_option(const char *name, const char *value, bgc_settings *s, bgc_params *p,
                            int *given)
{
    if (strcmp(name, "-p") == 0)
        return bgc_parse_param(value, p, given);
    if (strcmp(name, "--solver") == 0)
        return bgc_parse_solver(value, &s->solver);
    if (strcmp(name, "--step") == 0) {
        if (bgc_parse_number(name, value, &s->step))
            return -1;
        if (s->step > 0.0)
            return 0;
        fprintf(stderr, "error: --step must be positive\n");
        return -1;
    }
    return bgc_parse_number(name, value, strcmp(name, "--t-end") == 0 ? &s->t_end
                                         : strcmp(name, "--dt") == 0  ? &s->dt
                                         : strcmp(name, "--rtol") == 0 ? &s->rtol
                                                                      : &s->atol);
}

/* -1 to run, else the exit status: 0 after --help, 2 after a usage error. */
static int bgc_parse_args(int argc, char **argv, bgc_settings *s, bgc_params *p, int *given,
                          int *project, int *stats)
{
    static const char *const with_value[] = { "--t-end", "--dt", "--solver", "--rtol",
                                              "--atol", "--step", "-p" };
    int i, k;
    for (i = 1; i < argc; i++) {
        const char *arg = argv[i], *eq = strncmp(arg, "--", 2) == 0 ? strchr(arg, '=') : NULL;
        const size_t len = eq ? (size_t)(eq - arg) : strlen(arg);
        const char *value;
        if (strcmp(arg, "-h") == 0 || strcmp(arg, "--help") == 0) {
            bgc_help();
            return 0;
        }
        if (strcmp(arg, "--project-initial") == 0 || strcmp(arg, "--stats") == 0) {
            *(arg[2] == 'p' ? project : stats) = 1;
            continue;
        }
        for (k = 0; k < 7; k++)
            if (strlen(with_value[k]) == len && strncmp(arg, with_value[k], len) == 0)
                break;
        if (k == 7) {
            fprintf(stderr, "error: unknown option '%s'\n", arg);
            bgc_print_usage(stderr);
            return BGC_ERR_USAGE;
        }
        value = eq ? eq + 1 : (i + 1 < argc ? argv[++i] : NULL);
        if (!value) {
            fprintf(stderr, "error: option '%s' needs a value\n", arg);
            bgc_print_usage(stderr);
            return BGC_ERR_USAGE;
        }
        if (bgc_apply_option(with_value[k], value, s, p, given))
            return BGC_ERR_USAGE;
    }
    return -1;
}

int main(int argc, char **argv)
{
    bgc_settings s;
    bgc_params p;
    bgc_stats st = { 0, 0, 0 };
    int given[BGC_DIM(BGC_NUM_PARAMS)] = { 0 };
    double x0[BGC_DIM(BGC_NUM_STATES)] = { 0.0 };
    char msg[1024];
    int project = 0, stats = 0, rc, i;

    bgc_settings_default(&s);
    rc = bgc_parse_args(argc, argv, &s, &p, given, &project, &stats);
    if (rc >= 0)
        return rc;
    if (bgc_check_settings(&s, msg, sizeof msg)) {
        fprintf(stderr, "error: %s\n", msg);
        return BGC_ERR_USAGE;
    }
    bgc_params_defaults(&p, given);
    for (i = 0; i < BGC_NUM_PARAMS; i++)
        if (!isfinite(*bgc_param_ref(&p, i))) {
            fprintf(stderr, "error: parameter '%s' is not finite\n", bgc_param_names[i]);
            return BGC_ERR_RUNTIME;
        }
    bgc_init(&p, x0);
    i = bgc_first_nonfinite(x0, BGC_NUM_STATES);
    if (i >= 0) {
        fprintf(stderr, "error: at t = %.17g: state '%s' is not finite\n", s.t0, bgc_state_names[i]);
        return BGC_ERR_RUNTIME;
    }
    if (project && bgc_project_initial(s.t0, x0, &p, msg, sizeof msg)) {
        fprintf(stderr, "error: %s\n", msg);
        return BGC_ERR_CONSTRAINT;
    }
    if (bgc_check_constraints(s.t0, x0, &p, stderr))
        return BGC_ERR_CONSTRAINT;

    bgc_out.file = stdout;
    bgc_csv_header(stdout);
    rc = bgc_simulate(&s, &p, x0, bgc_csv_row, &bgc_out, &st, msg, sizeof msg);
    bgc_flush(&bgc_out);
    if (fflush(stdout) != 0 || bgc_out.failed) {
        fprintf(stderr, "error: cannot write the output\n");
        return BGC_ERR_RUNTIME;
    }
    if (stats)
        fprintf(stderr, "stats: steps=%ld rejected=%ld rhs=%ld\n", st.steps, st.rejected, st.rhs);
    if (rc) {
        fprintf(stderr, "error: %s\n", msg);
        return BGC_ERR_RUNTIME;
    }
    return 0;
}
#endif /* BGC_NO_MAIN */
