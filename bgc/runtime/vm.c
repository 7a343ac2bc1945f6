/* ================================================================ interpreter === */
/* bgc's interpreter backend (bgc/vm.py): the model part of a program, read from a file at the
   start and interpreted, so a model runs without a C build.  Built once per machine with the
   runtime (bgc/vm.py, c_unit): the step driver, the solvers and the command line are the
   compiled runtime's, and call the model part's functions below as they call a compiled one.

   A program file holds the model part's sizes, scene, names and tables, the blocks' plans,
   the lookup tables' rows and pieces, constants, and segments of instructions (four ints
   each: opcode and three operands) over registers.  Each instruction is one operation of the
   generated C's text, in its order, with the same C operation or libm call, so the results
   are the same bits.  The registers of the
   model functions are in the workspace (w->v, above the program's own storage): nothing is
   allocated per call.  The program file is checked whole when it is read (every register
   inside its segment's frame, every index inside its array), so that no instruction reads or
   writes outside them. */

typedef struct bgc_vm_seg {
    int frame; /* registers 0 .. frame - 1 */
    int n;     /* instructions */
    int *code;
} bgc_vm_seg;

static double *bgc_vm_consts;
static int bgc_vm_nconsts;
static bgc_vm_seg *bgc_vm_segs;
static int bgc_vm_nsegs;
static int bgc_vm_entry[BGC_VM_ENTRIES];
static int *bgc_vm_defaults; /* per parameter: the segment of its default */
static const bgc_vm_seg *bgc_vm_newton_seg; /* the Newton block bgc_vm_eval evaluates */
static const char *const *bgc_vm_idents; /* the model's name and identifier */
static const char *const *bgc_vm_inputs; /* the inputs' names (`input NAME`) */

const char *bgc_link_input_name(int j)
{
    return bgc_vm_inputs[j];
}

const char *bgc_model_name;
const char *const *bgc_state_names;
const char *const *bgc_param_names;
const char *const *bgc_output_names;
const char *const *bgc_constraint_names;
const char *const *bgc_constraint_levels;
const char *const *bgc_block_names;

/* ------------------------------------------------------------------ the loop --- */

static int bgc_vm_eval(double t, const double *x, const bgc_params *p, bgc_work *w,
                       const double *z, double *r, double *J);

/* Runs segment s over the frame f: in is jvp's v, update's r or a Newton block's z; out the
   results; J a Newton block's Jacobian (NULL: its residuals only).  0, or 1 if a block failed. */
static int bgc_vm_run(const bgc_vm_seg *s, double *f, double t, const double *x,
                      const bgc_params *p, bgc_work *w, const double *in, double *out,
                      double *J)
{
    const int *ip = s->code;
    const double *const k = bgc_vm_consts;
#if defined(__GNUC__) && !defined(BGC_VM_SWITCH)
    static const void *const labels[BGC_VM_NUM_OPS] = { BGC_VM_LABELS };
#define BGC_VM_CASE(name) bgc_vm_op_##name:
#define BGC_VM_NEXT goto *labels[*(ip += 4)]
    goto *labels[*ip];
#else
#define BGC_VM_CASE(name) case BGC_VM_##name:
#define BGC_VM_NEXT ip += 4; continue
    for (;;) switch (*ip) {
#endif
    BGC_VM_CASE(END) return 0;
    BGC_VM_CASE(LDX) f[ip[1]] = x[ip[2]]; BGC_VM_NEXT;
    BGC_VM_CASE(LDP) f[ip[1]] = p->v[ip[2]]; BGC_VM_NEXT;
    BGC_VM_CASE(LDIN) f[ip[1]] = in[ip[2]]; BGC_VM_NEXT;
    BGC_VM_CASE(LDT) f[ip[1]] = t; BGC_VM_NEXT;
    BGC_VM_CASE(LDATOL) f[ip[1]] = w->atol; BGC_VM_NEXT;
    BGC_VM_CASE(LDK) f[ip[1]] = k[ip[2]]; BGC_VM_NEXT;
    BGC_VM_CASE(MOV) f[ip[1]] = f[ip[2]]; BGC_VM_NEXT;
    BGC_VM_CASE(STO) out[ip[1]] = f[ip[2]]; BGC_VM_NEXT;
    BGC_VM_CASE(STJ) J[ip[1]] = f[ip[2]]; BGC_VM_NEXT;
    BGC_VM_CASE(JEND) if (!J) return 0; BGC_VM_NEXT;
    BGC_VM_CASE(ADD) f[ip[1]] = f[ip[2]] + f[ip[3]]; BGC_VM_NEXT;
    BGC_VM_CASE(SUB) f[ip[1]] = f[ip[2]] - f[ip[3]]; BGC_VM_NEXT;
    BGC_VM_CASE(MUL) f[ip[1]] = f[ip[2]] * f[ip[3]]; BGC_VM_NEXT;
    BGC_VM_CASE(DIV) f[ip[1]] = f[ip[2]] / f[ip[3]]; BGC_VM_NEXT;
    BGC_VM_CASE(NEG) f[ip[1]] = -f[ip[2]]; BGC_VM_NEXT;
    BGC_VM_CASE(LT) f[ip[1]] = f[ip[2]] < f[ip[3]] ? 1.0 : 0.0; BGC_VM_NEXT;
    BGC_VM_CASE(LE) f[ip[1]] = f[ip[2]] <= f[ip[3]] ? 1.0 : 0.0; BGC_VM_NEXT;
    BGC_VM_CASE(GT) f[ip[1]] = f[ip[2]] > f[ip[3]] ? 1.0 : 0.0; BGC_VM_NEXT;
    BGC_VM_CASE(GE) f[ip[1]] = f[ip[2]] >= f[ip[3]] ? 1.0 : 0.0; BGC_VM_NEXT;
    BGC_VM_CASE(EQ) f[ip[1]] = f[ip[2]] == f[ip[3]] ? 1.0 : 0.0; BGC_VM_NEXT;
    BGC_VM_CASE(NE) f[ip[1]] = f[ip[2]] != f[ip[3]] ? 1.0 : 0.0; BGC_VM_NEXT;
    BGC_VM_CASE(AND) f[ip[1]] = f[ip[2]] != 0.0 && f[ip[3]] != 0.0 ? 1.0 : 0.0; BGC_VM_NEXT;
    BGC_VM_CASE(OR) f[ip[1]] = f[ip[2]] != 0.0 || f[ip[3]] != 0.0 ? 1.0 : 0.0; BGC_VM_NEXT;
    BGC_VM_CASE(NOT) f[ip[1]] = f[ip[2]] != 0.0 ? 0.0 : 1.0; BGC_VM_NEXT;
    BGC_VM_CASE(SEL) f[ip[1]] = f[ip[1]] != 0.0 ? f[ip[2]] : f[ip[3]]; BGC_VM_NEXT;
    BGC_VM_CASE(SIN) f[ip[1]] = sin(f[ip[2]]); BGC_VM_NEXT;
    BGC_VM_CASE(COS) f[ip[1]] = cos(f[ip[2]]); BGC_VM_NEXT;
    BGC_VM_CASE(TAN) f[ip[1]] = tan(f[ip[2]]); BGC_VM_NEXT;
    BGC_VM_CASE(ASIN) f[ip[1]] = asin(f[ip[2]]); BGC_VM_NEXT;
    BGC_VM_CASE(ACOS) f[ip[1]] = acos(f[ip[2]]); BGC_VM_NEXT;
    BGC_VM_CASE(ATAN) f[ip[1]] = atan(f[ip[2]]); BGC_VM_NEXT;
    BGC_VM_CASE(SINH) f[ip[1]] = sinh(f[ip[2]]); BGC_VM_NEXT;
    BGC_VM_CASE(COSH) f[ip[1]] = cosh(f[ip[2]]); BGC_VM_NEXT;
    BGC_VM_CASE(TANH) f[ip[1]] = tanh(f[ip[2]]); BGC_VM_NEXT;
    BGC_VM_CASE(ASINH) f[ip[1]] = asinh(f[ip[2]]); BGC_VM_NEXT;
    BGC_VM_CASE(ACOSH) f[ip[1]] = acosh(f[ip[2]]); BGC_VM_NEXT;
    BGC_VM_CASE(ATANH) f[ip[1]] = atanh(f[ip[2]]); BGC_VM_NEXT;
    BGC_VM_CASE(EXP) f[ip[1]] = exp(f[ip[2]]); BGC_VM_NEXT;
    BGC_VM_CASE(LOG) f[ip[1]] = log(f[ip[2]]); BGC_VM_NEXT;
    BGC_VM_CASE(SQRT) f[ip[1]] = sqrt(f[ip[2]]); BGC_VM_NEXT;
    BGC_VM_CASE(FABS) f[ip[1]] = fabs(f[ip[2]]); BGC_VM_NEXT;
    BGC_VM_CASE(SIGN) f[ip[1]] = bgc_sign(f[ip[2]]); BGC_VM_NEXT;
    BGC_VM_CASE(ATAN2) f[ip[1]] = atan2(f[ip[2]], f[ip[3]]); BGC_VM_NEXT;
    BGC_VM_CASE(POW) f[ip[1]] = pow(f[ip[2]], f[ip[3]]); BGC_VM_NEXT;
    BGC_VM_CASE(MIN) f[ip[1]] = bgc_min(f[ip[2]], f[ip[3]]); BGC_VM_NEXT;
    BGC_VM_CASE(MAX) f[ip[1]] = bgc_max(f[ip[2]], f[ip[3]]); BGC_VM_NEXT;
    BGC_VM_CASE(HEAVISIDE) f[ip[1]] = bgc_heaviside(f[ip[2]], f[ip[3]]); BGC_VM_NEXT;
    BGC_VM_CASE(SQUARE)
        f[ip[1]] = bgc_square(f[ip[2]], f[ip[3]], f[ip[6]], f[ip[7]]);
        ip += 4;
        BGC_VM_NEXT;
    BGC_VM_CASE(SQUARENEXT)
        f[ip[1]] = bgc_square_next(f[ip[2]], f[ip[3]], f[ip[6]], f[ip[7]]);
        ip += 4;
        BGC_VM_NEXT;
    BGC_VM_CASE(PERIODICNEXT)
        f[ip[1]] = bgc_periodic_next(f[ip[2]], f[ip[3]], f[ip[6]]);
        ip += 4;
        BGC_VM_NEXT;
    BGC_VM_CASE(ARGS) BGC_VM_NEXT; /* (read by the instruction before) */
    BGC_VM_CASE(TABLE)
        f[ip[1]] = bgc_table(&bgc_tables[ip[6]], f[ip[2]], f[ip[3]], ip[7]);
        ip += 4;
        BGC_VM_NEXT;
    BGC_VM_CASE(TABLEGUARD) f[ip[1]] = bgc_table_guard(&bgc_tables[ip[3]], f[ip[2]]); BGC_VM_NEXT;
    BGC_VM_CASE(TABLEPIECE) f[ip[1]] = bgc_table_piece(&bgc_tables[ip[3]], f[ip[2]]); BGC_VM_NEXT;
    BGC_VM_CASE(TABLENEXT) f[ip[1]] = bgc_table_next(&bgc_tables[ip[3]], f[ip[2]]); BGC_VM_NEXT;
    BGC_VM_CASE(INPUT)
        f[ip[1]] = bgc_input(w, ip[6], f[ip[2]], ip[7], f[ip[3]]);
        ip += 4;
        BGC_VM_NEXT;
    BGC_VM_CASE(INPUTNEXT) f[ip[1]] = bgc_input_next(w, ip[3], f[ip[2]]); BGC_VM_NEXT;
    BGC_VM_CASE(IARGS) BGC_VM_NEXT; /* (read by the instruction before) */
    BGC_VM_CASE(SOLVE) if (bgc_block_solve(w, ip[1], t)) return 1; BGC_VM_NEXT;
    BGC_VM_CASE(RESOLVE) if (bgc_block_resolve(w, ip[1], t)) return 1; BGC_VM_NEXT;
    BGC_VM_CASE(NEWTON)
        bgc_vm_newton_seg = &bgc_vm_segs[ip[2]];
        if (bgc_newton(w, ip[1], bgc_vm_eval, t, x, p, ip[3]))
            return 1;
        BGC_VM_NEXT;
#if !(defined(__GNUC__) && !defined(BGC_VM_SWITCH))
    default:
        return 1; /* (never: the program file is checked when it is read) */
    }
#endif
#undef BGC_VM_CASE
#undef BGC_VM_NEXT
}

/* A Newton block's residuals and Jacobian: the segment its NEWTON instruction named (nothing
   runs between that instruction and bgc_newton's calls of this). */
static int bgc_vm_eval(double t, const double *x, const bgc_params *p, bgc_work *w,
                       const double *z, double *r, double *J)
{
    return bgc_vm_run(bgc_vm_newton_seg, w->v, t, x, p, w, z, r, J);
}

/* ------------------------------------------------------- the model part's contract --- */

static int bgc_vm_model(int entry, double t, const double *x, const bgc_params *p,
                        bgc_work *w, const double *in, double *out)
{
    const int s = bgc_vm_entry[entry];
    return s < 0 ? 0 : bgc_vm_run(&bgc_vm_segs[s], w->v, t, x, p, w, in, out, NULL);
}

int bgc_link_rhs(double t, const double *x, const bgc_params *p, bgc_work *w, double *out)
{
    return bgc_vm_model(BGC_VM_ENTRY_RHS, t, x, p, w, NULL, out);
}

int bgc_link_outputs(double t, const double *x, const bgc_params *p, bgc_work *w, double *out)
{
    return bgc_vm_model(BGC_VM_ENTRY_OUTPUTS, t, x, p, w, NULL, out);
}

int bgc_link_jvp(double t, const double *x, const bgc_params *p, bgc_work *w, const double *v,
                 double *out)
{
    if (bgc_vm_entry[BGC_VM_ENTRY_JVP] < 0) { /* built without it (BGC_HAS_JACOBIAN 0) */
        w->block = 0;
        w->failure = BGC_NO_JACOBIAN;
        return 1;
    }
    return bgc_vm_model(BGC_VM_ENTRY_JVP, t, x, p, w, v, out);
}

int bgc_link_events(double t, const double *x, const bgc_params *p, bgc_work *w, double *out)
{
    return bgc_vm_model(BGC_VM_ENTRY_EVENTS, t, x, p, w, NULL, out);
}

int bgc_link_next_time(double t, const double *x, const bgc_params *p, bgc_work *w,
                       double *out)
{
    return bgc_vm_model(BGC_VM_ENTRY_NEXT_TIME, t, x, p, w, NULL, out);
}

int bgc_link_update(double t, const double *x, const bgc_params *p, bgc_work *w,
                    const double *r, double *out)
{
    return bgc_vm_model(BGC_VM_ENTRY_UPDATE, t, x, p, w, r, out);
}

/* A segment that runs without a workspace (parameters, constants, x0) in a frame of its own. */
static void bgc_vm_alone(int s, const bgc_params *p, double *out)
{
    double small[256], *f = small;
    if (bgc_vm_segs[s].frame > 256) {
        f = (double *)calloc((size_t)bgc_vm_segs[s].frame, sizeof *f);
        if (!f) {
            fprintf(stderr, "error: out of memory\n");
            exit(BGC_ERR_RUNTIME);
        }
    }
    bgc_vm_run(&bgc_vm_segs[s], f, 0.0, NULL, p, NULL, NULL, out, NULL);
    if (f != small)
        free(f);
}

void bgc_params_update(bgc_params *p)
{
    p->v[BGC_NUM_PARAMS > 0 ? BGC_NUM_PARAMS : 1] = 0.0; /* (a model without constants) */
    bgc_vm_alone(bgc_vm_entry[BGC_VM_ENTRY_CONSTS], p, p->v + BGC_DIM(BGC_NUM_PARAMS));
}

void bgc_params_defaults(bgc_params *p, const int *given)
{
    int j;
    for (j = 0; j < BGC_NUM_PARAMS; j++)
        if (!given || !given[j])
            bgc_vm_alone(bgc_vm_defaults[j], p, p->v + j);
    bgc_params_update(p);
}

double *bgc_param_ref(bgc_params *p, int j)
{
    return j >= 0 && j < BGC_NUM_PARAMS ? &p->v[j] : NULL;
}

void bgc_init(const bgc_params *p, double *x0)
{
    bgc_vm_alone(bgc_vm_entry[BGC_VM_ENTRY_INIT], p, x0);
}

/* The constraint rows' functions: a workspace of their own (they run at the start of a run);
   NaN results if a block inside fails.  sparse: the results not stored are zero. */
static void bgc_vm_plain(int entry, int size, int sparse, double t, const double *x,
                         const bgc_params *p, double *out)
{
    const int s = bgc_vm_entry[entry];
    bgc_work *w;
    int k;
    if (sparse && size > 0)
        memset(out, 0, (size_t)size * sizeof *out);
    if (s < 0)
        return;
    w = bgc_work_new();
    if (!w || bgc_vm_run(&bgc_vm_segs[s], w->v, t, x, p, w, NULL, out, NULL))
        for (k = 0; k < BGC_DIM(size); k++)
            out[k] = NAN;
    bgc_work_free(w);
}

void bgc_residual(double t, const double *x, const bgc_params *p, double *r)
{
    bgc_vm_plain(BGC_VM_ENTRY_RESIDUAL, BGC_NUM_CONSTRAINTS, 0, t, x, p, r);
}

void bgc_scale(double t, const double *x, const bgc_params *p, double *s)
{
    bgc_vm_plain(BGC_VM_ENTRY_SCALE, BGC_NUM_CONSTRAINTS, 0, t, x, p, s);
}

void bgc_position_jac(double t, const double *x, const bgc_params *p, double *J)
{
    bgc_vm_plain(BGC_VM_ENTRY_POSITION_JAC, BGC_NUM_POSITION_ROWS * BGC_NUM_STATES, 1, t, x,
                 p, J);
}

void bgc_velocity_jac(double t, const double *x, const bgc_params *p, double *J)
{
    bgc_vm_plain(BGC_VM_ENTRY_VELOCITY_JAC, BGC_NUM_VELOCITY_ROWS * BGC_NUM_STATES, 1, t, x,
                 p, J);
}

void bgc_velocity_metric(double t, const double *x, const bgc_params *p, double *K)
{
    bgc_vm_plain(BGC_VM_ENTRY_VELOCITY_METRIC, BGC_NUM_VELOCITY_ROWS * BGC_NUM_STATES, 1, t, x,
                 p, K);
}

/* ----------------------------------------------------------- reading a program --- */

typedef struct bgc_vm_reader {
    const unsigned char *at, *end;
    int bad;
} bgc_vm_reader;

static int bgc_vm_int(bgc_vm_reader *r)
{
    unsigned long u;
    if (r->end - r->at < 4) {
        r->bad = 1;
        return 0;
    }
    u = (unsigned long)r->at[0] | (unsigned long)r->at[1] << 8 | (unsigned long)r->at[2] << 16
        | (unsigned long)r->at[3] << 24;
    r->at += 4;
    return u & 0x80000000UL ? -(int)(0xffffffffUL - u) - 1 : (int)u;
}

static double bgc_vm_double(bgc_vm_reader *r)
{
    unsigned long long u = 0;
    double v;
    int i;
    if (r->end - r->at < 8) {
        r->bad = 1;
        return 0.0;
    }
    for (i = 7; i >= 0; i--)
        u = u << 8 | r->at[i];
    r->at += 8;
    memcpy(&v, &u, sizeof v);
    return v;
}

/* A count of items of `size` bytes that the rest of the file can hold (-1: it cannot). */
static int bgc_vm_count(bgc_vm_reader *r, long size)
{
    const int n = bgc_vm_int(r);
    if (r->bad || n < 0 || (long)(r->end - r->at) / size < n) {
        r->bad = 1;
        return -1;
    }
    return n;
}

static void *bgc_vm_alloc(bgc_vm_reader *r, size_t n, size_t size)
{
    void *p = calloc(n > 0 ? n : 1, size);
    if (!p)
        r->bad = 1;
    return p;
}

static int *bgc_vm_ints(bgc_vm_reader *r, int *count)
{
    const int n = bgc_vm_count(r, 4);
    int *out, i;
    if (n < 0)
        return NULL;
    out = (int *)bgc_vm_alloc(r, (size_t)n, sizeof *out);
    for (i = 0; out && i < n; i++)
        out[i] = bgc_vm_int(r);
    if (count)
        *count = n;
    return out;
}

/* n doubles (the rest of the file holding them), or NULL with r->bad set. */
static double *bgc_vm_doubles(bgc_vm_reader *r, long n)
{
    double *out;
    long i;
    if (r->bad || n < 0 || (long)(r->end - r->at) / 8 < n) {
        r->bad = 1;
        return NULL;
    }
    out = (double *)bgc_vm_alloc(r, (size_t)n, sizeof *out);
    for (i = 0; out && i < n; i++)
        out[i] = bgc_vm_double(r);
    return out;
}

/* The lookup tables (bgc/tables.py): per table its rows n (at least one), extrapolate =
   error, then x[n], each piece's origin[n + 1] and a, b, c, d[4 (n + 1)]; 0, or 1. */
static int bgc_vm_tables(bgc_vm_reader *r)
{
    bgc_table_data *tables;
    int i;
    if (bgc_vm_int(r) != BGC_NUM_TABLES)
        return 1;
    tables = (bgc_table_data *)bgc_vm_alloc(r, (size_t)BGC_DIM(BGC_NUM_TABLES), sizeof *tables);
    for (i = 0; tables && i < BGC_NUM_TABLES && !r->bad; i++) {
        const int n = bgc_vm_int(r);
        if (n < 1 || n > (int)((r->end - r->at) / 8))
            return 1;
        tables[i].n = n;
        tables[i].error = bgc_vm_int(r);
        tables[i].x = bgc_vm_doubles(r, n);
        tables[i].origin = bgc_vm_doubles(r, (long)n + 1);
        tables[i].coef = bgc_vm_doubles(r, 4 * ((long)n + 1));
    }
    bgc_link_tables = tables;
    return r->bad;
}

static const char *const *bgc_vm_strings(bgc_vm_reader *r, int expect)
{
    const int n = bgc_vm_count(r, 4);
    const char **out;
    int i;
    if (n < 0 || (expect >= 0 && n != expect)) {
        r->bad = 1;
        return NULL;
    }
    out = (const char **)bgc_vm_alloc(r, (size_t)(n > 0 ? n : 1), sizeof *out);
    for (i = 0; out && i < n && !r->bad; i++) {
        const int len = bgc_vm_count(r, 1);
        char *s;
        if (len < 0)
            break;
        s = (char *)bgc_vm_alloc(r, (size_t)len + 1, 1);
        if (!s)
            break;
        memcpy(s, r->at, (size_t)len);
        r->at += len;
        out[i] = s;
    }
    if (out && n == 0)
        out[0] = "";
    return out;
}

/* Whether every operand of segment s is inside what it indexes; alone: the segment runs
   without a workspace (bgc_vm_alone), so it reads no input. */
static int bgc_vm_check(const bgc_vm_seg *s, int n_in, int alone)
{
    int i, j;
    for (i = 0; i < s->n; i++) {
        const int *c = s->code + 4 * i;
        const char *kinds;
        if (c[0] < 0 || c[0] >= BGC_VM_NUM_OPS)
            return 0;
        kinds = bgc_vm_kinds[c[0]];
        for (j = 0; j < 3; j++)
            if (kinds[j] == 'r' && (c[j + 1] < 0 || c[j + 1] >= s->frame))
                return 0;
        switch (c[0]) {
        case BGC_VM_LDX:
            if (c[2] < 0 || c[2] >= BGC_DIM(BGC_NUM_STATES))
                return 0;
            break;
        case BGC_VM_LDP:
            if (c[2] < 0 || c[2] >= LINK_PARAMS_MAX)
                return 0;
            break;
        case BGC_VM_LDIN:
            if (c[2] < 0 || c[2] >= n_in)
                return 0;
            break;
        case BGC_VM_LDK:
            if (c[2] < 0 || c[2] >= bgc_vm_nconsts)
                return 0;
            break;
        case BGC_VM_STO: case BGC_VM_STJ:
            if (c[1] < 0 || c[1] >= bgc_link_work_doubles + LINK_PARAMS_MAX)
                return 0;
            break;
        case BGC_VM_SOLVE: case BGC_VM_RESOLVE:
            if (c[1] < 0 || c[1] >= BGC_NUM_BLOCKS)
                return 0;
            break;
        case BGC_VM_NEWTON:
            if (c[1] < 0 || c[1] >= BGC_NUM_BLOCKS || c[2] < 0 || c[2] >= bgc_vm_nsegs)
                return 0;
            break;
        case BGC_VM_SQUARE: case BGC_VM_SQUARENEXT: case BGC_VM_PERIODICNEXT:
            if (i + 1 >= s->n || c[4] != BGC_VM_ARGS)
                return 0;
            break;
        case BGC_VM_TABLE:
            if (i + 1 >= s->n || c[4] != BGC_VM_IARGS || c[6] < 0 || c[6] >= BGC_NUM_TABLES
                || c[7] < 0 || c[7] > 3)
                return 0;
            break;
        case BGC_VM_TABLEGUARD: case BGC_VM_TABLEPIECE: case BGC_VM_TABLENEXT:
            if (c[3] < 0 || c[3] >= BGC_NUM_TABLES)
                return 0;
            break;
        case BGC_VM_INPUT:
            if (alone || i + 1 >= s->n || c[4] != BGC_VM_IARGS || c[6] < 0
                || c[6] >= BGC_NUM_INPUTS || c[7] < 0 || c[7] > 2)
                return 0;
            break;
        case BGC_VM_INPUTNEXT:
            if (alone || c[3] < 0 || c[3] >= BGC_NUM_INPUTS)
                return 0;
            break;
        default:
            break;
        }
    }
    return s->n > 0 && s->code[4 * (s->n - 1)] == BGC_VM_END;
}

/* Whether bgc_discrete_log (the last of the int tables, count ints) is two ints for each
   discrete value, each naming a kind and a table or an input there is: 0, or 1. */
static int bgc_vm_discrete_log(int count)
{
    int k;
    if (count != 2 * BGC_NUM_DISCRETE)
        return 1;
    for (k = 0; k < BGC_NUM_DISCRETE; k++) {
        const int kind = bgc_discrete_log[2 * k], j = bgc_discrete_log[2 * k + 1];
        if (!(kind == BGC_LOG_PLAIN || (kind == BGC_LOG_INPUT && j >= 0 && j < BGC_NUM_INPUTS)
              || (kind == BGC_LOG_TABLE && j >= 0 && j < BGC_NUM_TABLES)))
            return 1;
    }
    return 0;
}

static int bgc_vm_read(const unsigned char *data, size_t size)
{
    bgc_vm_reader rd = { data, data + size, 0 }, *r = &rd;
    bgc_block *blocks;
    int i, j, nb, n_in, counts[BGC_COUNT(bgc_vm_link_tables)];
    if (size < 12 || memcmp(data, "BGCVM\0\0\0", 8) != 0)
        return 1;
    r->at += 8;
    if (bgc_vm_int(r) != BGC_VM_FORMAT)
        return 1;
    for (i = 0; i < BGC_COUNT(bgc_vm_link_ints); i++) {
        *bgc_vm_link_ints[i] = bgc_vm_int(r);
        if (*bgc_vm_link_ints[i] < 0)
            return 1;
    }
    for (i = 0; i < BGC_COUNT(bgc_vm_link_doubles); i++)
        *bgc_vm_link_doubles[i] = bgc_vm_double(r);
    bgc_vm_idents = bgc_vm_strings(r, 2);
    if (!bgc_vm_idents)
        return 1;
    bgc_model_name = bgc_vm_idents[0];
    bgc_link_ident = bgc_vm_idents[1];
    if (BGC_DIM(BGC_NUM_PARAMS) + BGC_DIM(BGC_NUM_CONSTANTS) + BGC_NUM_DISCRETE > LINK_PARAMS_MAX
        || bgc_link_work_doubles < bgc_link_work_jac + 2 * BGC_DIM(BGC_NUM_STATES))
        return 1;
    bgc_state_names = bgc_vm_strings(r, BGC_NUM_STATES);
    bgc_param_names = bgc_vm_strings(r, BGC_NUM_PARAMS);
    bgc_output_names = bgc_vm_strings(r, BGC_NUM_OUTPUTS);
    bgc_constraint_names = bgc_vm_strings(r, BGC_NUM_CONSTRAINTS);
    bgc_constraint_levels = bgc_vm_strings(r, BGC_NUM_CONSTRAINTS);
    bgc_block_names = bgc_vm_strings(r, BGC_NUM_BLOCKS);
    bgc_link_discrete_names = bgc_vm_strings(r, BGC_NUM_DISCRETE);
    bgc_vm_inputs = bgc_vm_strings(r, BGC_NUM_INPUTS);
    for (i = 0; i < BGC_COUNT(bgc_vm_link_tables); i++) {
        const int *t = bgc_vm_ints(r, &counts[i]);
        *bgc_vm_link_tables[i] = t;
    }
    if (r->bad || bgc_vm_discrete_log(counts[BGC_COUNT(bgc_vm_link_tables) - 1]))
        return 1;
    nb = bgc_vm_int(r);
    if (nb != BGC_NUM_BLOCKS)
        return 1;
    blocks = (bgc_block *)bgc_vm_alloc(r, (size_t)nb, sizeof *blocks);
    for (i = 0; blocks && i < nb && !r->bad; i++) {
        bgc_lu_plan *lu = &blocks[i].lu;
        const int **arrays[10];
        int *offsets[11];
        arrays[0] = &lu->diag, arrays[1] = &lu->lptr, arrays[2] = &lu->lpos;
        arrays[3] = &lu->lrow, arrays[4] = &lu->uptr, arrays[5] = &lu->upos;
        arrays[6] = &lu->ucol, arrays[7] = &lu->upd, arrays[8] = &lu->prow;
        arrays[9] = &lu->pcol;
        offsets[0] = &blocks[i].save, offsets[1] = &blocks[i].lu_off;
        offsets[2] = &blocks[i].dense, offsets[3] = &blocks[i].b, offsets[4] = &blocks[i].scale;
        offsets[5] = &blocks[i].z, offsets[6] = &blocks[i].r, offsets[7] = &blocks[i].zt;
        offsets[8] = &blocks[i].rt, offsets[9] = &blocks[i].piv, offsets[10] = &blocks[i].how;
        lu->m = bgc_vm_int(r);
        lu->dense = bgc_vm_int(r);
        lu->symmetric = bgc_vm_int(r);
        lu->nnz = bgc_vm_int(r);
        for (j = 0; j < 10; j++) {
            int count;
            int *a = bgc_vm_ints(r, &count);
            *arrays[j] = a;
            if (count == 0) { /* (NULL, as a compiled model part's empty arrays) */
                free(a);
                *arrays[j] = NULL;
            }
        }
        for (j = 0; j < 11; j++)
            *offsets[j] = bgc_vm_int(r);
        blocks[i].factor = NULL;
        blocks[i].lsolve = NULL;
    }
    bgc_link_blocks = blocks;
    if (bgc_vm_tables(r))
        return 1;
    bgc_vm_nconsts = bgc_vm_count(r, 8);
    if (bgc_vm_nconsts < 0)
        return 1;
    bgc_vm_consts = (double *)bgc_vm_alloc(r, (size_t)bgc_vm_nconsts, sizeof *bgc_vm_consts);
    for (i = 0; bgc_vm_consts && i < bgc_vm_nconsts; i++)
        bgc_vm_consts[i] = bgc_vm_double(r);
    bgc_vm_nsegs = bgc_vm_count(r, 8);
    if (bgc_vm_nsegs < 0)
        return 1;
    bgc_vm_segs = (bgc_vm_seg *)bgc_vm_alloc(r, (size_t)bgc_vm_nsegs, sizeof *bgc_vm_segs);
    for (i = 0; bgc_vm_segs && i < bgc_vm_nsegs && !r->bad; i++) {
        bgc_vm_seg *s = &bgc_vm_segs[i];
        s->frame = bgc_vm_int(r);
        s->n = bgc_vm_count(r, 16);
        if (s->n < 0 || s->frame < 0)
            return 1;
        s->code = (int *)bgc_vm_alloc(r, (size_t)s->n * 4, sizeof *s->code);
        for (j = 0; s->code && j < 4 * s->n; j++)
            s->code[j] = bgc_vm_int(r);
    }
    for (i = 0; i < BGC_VM_ENTRIES; i++)
        bgc_vm_entry[i] = bgc_vm_int(r);
    bgc_vm_defaults = bgc_vm_ints(r, &j);
    if (r->bad || r->at != r->end || j != BGC_NUM_PARAMS)
        return 1;
    /* every segment checked: model functions in the workspace, the others in their own frame
       (bgc_vm_alone); a Newton block's segment reads its unknowns */
    n_in = BGC_NUM_INDICATORS + 2 + BGC_NUM_JUMPS; /* update's r (api.h) */
    if (BGC_DIM(BGC_NUM_STATES) > n_in)
        n_in = BGC_DIM(BGC_NUM_STATES);
    for (i = 0; i < nb; i++)
        if (blocks[i].lu.m > n_in)
            n_in = blocks[i].lu.m;
    for (i = 0; i < BGC_VM_ENTRIES; i++)
        if (bgc_vm_entry[i] >= bgc_vm_nsegs
            || (bgc_vm_entry[i] < 0 && (i == BGC_VM_ENTRY_CONSTS || i == BGC_VM_ENTRY_INIT)))
            return 1;
    for (j = 0; j < BGC_NUM_PARAMS; j++)
        if (bgc_vm_defaults[j] < 0 || bgc_vm_defaults[j] >= bgc_vm_nsegs)
            return 1;
    for (i = 0; i < bgc_vm_nsegs; i++) {
        int alone = i == bgc_vm_entry[BGC_VM_ENTRY_CONSTS] || i == bgc_vm_entry[BGC_VM_ENTRY_INIT];
        for (j = 0; j < BGC_NUM_PARAMS && !alone; j++)
            alone = i == bgc_vm_defaults[j];
        if (!bgc_vm_check(&bgc_vm_segs[i], n_in, alone)
            || bgc_vm_segs[i].frame > bgc_link_work_doubles + LINK_PARAMS_MAX)
            return 1;
    }
    for (i = BGC_VM_ENTRY_RHS; i < BGC_VM_ENTRIES; i++)
        if (bgc_vm_entry[i] >= 0 && i != BGC_VM_ENTRY_CONSTS && i != BGC_VM_ENTRY_INIT
            && bgc_vm_segs[bgc_vm_entry[i]].frame > bgc_link_work_doubles)
            return 1;
    return 0;
}

static int bgc_vm_load(const char *path)
{
    FILE *f = fopen(path, "rb");
    unsigned char *data = NULL;
    size_t size = 0, cap = 0, got;
    int bad;
    if (!f) {
        fprintf(stderr, "error: cannot read the program %s: %s\n", path, strerror(errno));
        return 1;
    }
    do {
        if (size == cap) {
            unsigned char *more;
            cap = cap ? 2 * cap : 65536;
            more = (unsigned char *)realloc(data, cap);
            if (!more) {
                free(data);
                fclose(f);
                fprintf(stderr, "error: out of memory\n");
                return 1;
            }
            data = more;
        }
        got = fread(data + size, 1, cap - size, f);
        size += got;
    } while (got > 0);
    fclose(f);
    bad = bgc_vm_read(data, size);
    free(data);
    if (bad)
        fprintf(stderr, "error: %s is not a program this interpreter runs (bgc/vm.py, format "
                "%d)\n", path, BGC_VM_FORMAT);
    return bad;
}

int main(int argc, char **argv)
{
    if (argc < 2) {
        fprintf(stderr, "usage: %s PROGRAM [the options of a generated program]\n", argv[0]);
        return BGC_ERR_USAGE;
    }
    if (bgc_vm_load(argv[1]))
        return BGC_ERR_RUNTIME;
    argv[1] = argv[0];
    return bgc_program_main(argc - 1, argv + 1);
}
