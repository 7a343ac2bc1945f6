# ====================================================================== runtime ===
# bgc's runtime: model-independent, the same in every generated module (bgc/runtime/runtime.py,
# inlined verbatim).  It uses the model part above: the sizes, _rhs, _out and _jvp, the blocks'
# plans and the Jacobian's colouring; it does the same arithmetic as the C runtime.


class SimulationError(RuntimeError):
    """A non-finite value, a step size too small or an algebraic block that failed; .times and
    .rows hold the rows computed before it."""

    def __init__(self, message, t, times, rows):
        super().__init__(message)
        self.t = t
        self.times = times
        self.rows = rows


class ConstraintError(RuntimeError):
    """The initial conditions violate a constraint (or cannot be projected onto them)."""

    def __init__(self, message, messages=()):
        super().__init__(message)
        self.messages = list(messages) or [message]


class BlockError(RuntimeError):
    """An algebraic block solved in the model functions was singular or did not converge."""


class _Failure(Exception):
    def __init__(self, message, t):
        super().__init__(message)
        self.t = t


class _BlockFailure(Exception):
    _HOW = {1: "is singular", 2: "did not converge", 3: "has a non-finite residual"}

    def __init__(self, block, failure, t):
        super().__init__("at t = %.17g: algebraic block %d (%s) %s" % (
            t, block + 1, _BLOCK_NAMES[block], self._HOW[failure]))
        self.t = t


def _sign(a):
    return 1.0 if a > 0.0 else (-1.0 if a < 0.0 else a)


def _heaviside(a, at_zero):
    return 1.0 if a > 0.0 else (0.0 if a < 0.0 else (at_zero if a == 0.0 else a))


def _sq(a):
    return a * a  # as C's bgc_sq (a ** 2 on a float is libm's pow, not always a * a)


# The model functions' IEEE variant (run when the math variant raised) calls these: the C
# program's functions, bit for bit.  math calls the platform's libm, as C does (numpy's exp,
# log, power, tanh, ... are SIMD kernels of their own that round differently); where math
# raises, C99 Annex F's result.  numpy.float64 results keep the arithmetic around them IEEE.

def _libm(f, fails):
    def call(*args):
        try:
            return numpy.float64(f(*args))
        except (ValueError, OverflowError):
            return numpy.float64(fails(*args))
    return call


def _pow_fails(x, y):
    """C's pow(x, y) where math.pow raises: x < 0, y not an integer: nan; an overflow or
    0 to a negative power: inf, negative for a negative x and an odd integer y."""
    if x < 0.0 and y != math.floor(y):
        return math.nan
    odd = y == math.floor(y) and math.fmod(y, 2.0) != 0.0
    return math.copysign(math.inf, x) if odd else math.inf


_c_exp = _libm(math.exp, lambda x: math.inf)
_c_log = _libm(math.log, lambda x: -math.inf if x == 0.0 else math.nan)
_c_sqrt = _libm(math.sqrt, lambda x: math.nan)
_c_sin = _libm(math.sin, lambda x: math.nan)
_c_cos = _libm(math.cos, lambda x: math.nan)
_c_tan = _libm(math.tan, lambda x: math.nan)
_c_asin = _libm(math.asin, lambda x: math.nan)
_c_acos = _libm(math.acos, lambda x: math.nan)
_c_atan = _libm(math.atan, lambda x: math.nan)
_c_atan2 = _libm(math.atan2, lambda y, x: math.nan)
_c_sinh = _libm(math.sinh, lambda x: math.copysign(math.inf, x))
_c_cosh = _libm(math.cosh, lambda x: math.inf)
_c_tanh = _libm(math.tanh, lambda x: math.nan)
_c_asinh = _libm(math.asinh, lambda x: math.nan)
_c_atanh = _libm(math.atanh, lambda x: math.copysign(math.inf, x) if abs(x) == 1.0 else math.nan)
_c_pow = _libm(math.pow, _pow_fails)


# ---------------------------------------------------------------- workspace


class _Block:
    __slots__ = ("m", "dense", "symmetric", "nnz", "diag", "lptr", "lpos", "lrow", "uptr", "upos", "ucol",
                 "upd", "prow", "pcol", "save", "lu", "dense_off", "b", "scale", "z", "r", "zt",
                 "rt", "piv", "how", "factor", "lsolve")

    def __init__(self, values):
        for key, value in zip(self.__slots__, values):
            setattr(self, key, value)


_BLOCK_TABLE = [_Block(row) for row in _BLOCKS]


class _Work:
    """The model functions' workspace: values shared between their parts, the blocks' storage
    (each Newton block's last solution is its next starting value), the Newton tolerance."""

    __slots__ = ("v", "iv", "rtol", "atol")

    def __init__(self, rtol=None, atol=None):
        self.v = [0.0] * max(_WORK_DOUBLES, 1)
        self.iv = [0] * max(_WORK_INTS, 1)
        self.rtol = SCENE["rtol"] if rtol is None else rtol
        self.atol = SCENE["atol"] if atol is None else atol


# ---------------------------------------------------------------- linear solves


def _row_scales(b, a, base):
    m = b.m
    scale = [0.0] * m
    for q in range(b.nnz):
        i = q // m if b.dense else b.prow[q]
        v = abs(a[base + q])
        if v > scale[i]:
            scale[i] = v
    return scale


def _lu_dense(m, a, base, piv, pbase, scale):
    """LU with partial pivoting of the m x m matrix at a[base:], in place; False if singular."""
    for k in range(m):
        r = k
        for i in range(k + 1, m):
            if abs(a[base + i * m + k]) > abs(a[base + r * m + k]):
                r = i
        piv[pbase + k] = r
        pivot = a[base + r * m + k]
        if not (abs(pivot) > 1e-14 * scale[r]) or not math.isfinite(pivot):
            return False
        if r != k:
            scale[k], scale[r] = scale[r], scale[k]
            for j in range(m):
                a[base + k * m + j], a[base + r * m + j] = a[base + r * m + j], a[base + k * m + j]
        for i in range(k + 1, m):
            f = a[base + i * m + k] / a[base + k * m + k]
            a[base + i * m + k] = f
            for j in range(k + 1, m):
                a[base + i * m + j] -= f * a[base + k * m + j]
    return True


def _lu_dense_solve(m, a, base, piv, pbase, x, xbase):
    # _lu_dense swapped whole rows (multipliers included): all the swaps first
    for k in range(m):
        r = piv[pbase + k]
        if r != k:
            x[xbase + k], x[xbase + r] = x[xbase + r], x[xbase + k]
    for k in range(m):
        for i in range(k + 1, m):
            x[xbase + i] -= a[base + i * m + k] * x[xbase + k]
    for i in range(m - 1, -1, -1):
        total = x[xbase + i]
        for j in range(i + 1, m):
            total -= a[base + i * m + j] * x[xbase + j]
        x[xbase + i] = total / a[base + i * m + i]


def _lu_static(b, a, base, scale):
    """LU in the plan's static order, in place; False if a pivot fails its test (one sign for
    a symmetric matrix, else the threshold; clearly nonzero for its row)."""
    q = 0
    lptr, lpos, uptr, upos, upd = b.lptr, b.lpos, b.uptr, b.upos, b.upd
    sign = -1.0 if b.m > 0 and a[base + b.diag[0]] < 0.0 else 1.0
    for k in range(b.m):
        pivot = a[base + b.diag[k]]
        if b.symmetric:
            if not sign * pivot > 1e-14 * scale[k] or not math.isfinite(pivot):
                return False
        else:
            largest = abs(pivot)
            for l in range(lptr[k], lptr[k + 1]):
                v = abs(a[base + lpos[l]])
                if v > largest:
                    largest = v
            if not (abs(pivot) >= 0.1 * largest and abs(pivot) > 1e-14 * scale[k]) \
                    or not math.isfinite(pivot):
                return False
        for l in range(lptr[k], lptr[k + 1]):
            f = a[base + lpos[l]] / pivot
            a[base + lpos[l]] = f
            for u in range(uptr[k], uptr[k + 1]):
                a[base + upd[q]] -= f * a[base + upos[u]]
                q += 1
    return True


def _lu_static_solve(b, a, base, x, xbase):
    for k in range(b.m):
        for l in range(b.lptr[k], b.lptr[k + 1]):
            x[xbase + b.lrow[l]] -= a[base + b.lpos[l]] * x[xbase + k]
    for k in range(b.m - 1, -1, -1):
        total = x[xbase + k]
        for u in range(b.uptr[k], b.uptr[k + 1]):
            total -= a[base + b.upos[u]] * x[xbase + b.ucol[u]]
        x[xbase + k] = total / a[base + b.diag[k]]


def _block_factor(w, b):
    """Factor the matrix assembled at b.save: the static order (unrolled in the model part
    when the plan is small: b.factor), else densely; False if singular.  Records which in
    w.iv[b.how]."""
    v = w.v
    if b.factor is not None and b.factor(v):
        w.iv[b.how] = 0
        return True
    scale = _row_scales(b, v, b.save)
    if not b.dense:
        if b.factor is None:
            v[b.lu:b.lu + b.nnz] = v[b.save:b.save + b.nnz]
            if _lu_static(b, v, b.lu, scale):
                w.iv[b.how] = 0
                return True
        m = b.m
        v[b.dense_off:b.dense_off + m * m] = [0.0] * (m * m)
        for q in range(b.nnz):
            v[b.dense_off + b.prow[q] * m + b.pcol[q]] = v[b.save + q]
    else:
        v[b.dense_off:b.dense_off + b.nnz] = v[b.save:b.save + b.nnz]
    w.iv[b.how] = 1
    return _lu_dense(b.m, v, b.dense_off, w.iv, b.piv, scale)


def _block_lsolve(w, b, xbase):
    if w.iv[b.how] == 0 and b.lsolve is not None:
        b.lsolve(w.v, xbase)
    elif w.iv[b.how] == 0:
        _lu_static_solve(b, w.v, b.lu, w.v, xbase)
    else:
        _lu_dense_solve(b.m, w.v, b.dense_off, w.iv, b.piv, w.v, xbase)


def _block_solve(w, k, t):
    b = _BLOCK_TABLE[k]
    if not _block_factor(w, b):
        raise _BlockFailure(k, 1, t)
    _block_lsolve(w, b, b.b)


def _block_resolve(w, k, t):
    b = _BLOCK_TABLE[k]
    _block_lsolve(w, b, b.b)


def _norm2(v, base, m):
    s = 0.0  # summed in C's order (the builtin sum is compensated from Python 3.12 on)
    for i in range(base, base + m):
        s += v[i] * v[i]
    return math.sqrt(s)


_NEWTON_MAXIT = 50


def _newton(w, k, f, t, x, p, final_factor):
    """Newton's method from the unknowns' last values, damped (Armijo), as the C runtime."""
    b = _BLOCK_TABLE[k]
    m, v = b.m, w.v
    zt = [0.0] * m
    rt = [0.0] * m
    f(t, x, p, w, v, b.z, v, b.r, v, b.save)
    norm = _norm2(v, b.r, m)
    if not math.isfinite(norm) or not all(math.isfinite(v[b.z + i]) for i in range(m)):
        for i in range(m):
            v[b.z + i] = 0.0
        f(t, x, p, w, v, b.z, v, b.r, v, b.save)
        norm = _norm2(v, b.r, m)
        if not math.isfinite(norm):
            raise _BlockFailure(k, 3, t)
    it = 0
    while norm > 0.0:
        if it == _NEWTON_MAXIT:
            raise _BlockFailure(k, 2, t)
        it += 1
        if not _block_factor(w, b):
            raise _BlockFailure(k, 1, t)
        for i in range(m):
            v[b.b + i] = -v[b.r + i]
        _block_lsolve(w, b, b.b)
        small = True  # a full step this small ends the iteration (quadratic convergence)
        for i in range(m):
            dz, z = v[b.b + i], v[b.z + i]
            if abs(dz) > 0.01 * (w.atol + w.rtol * abs(z)) and abs(dz) > 4.0 * _EPS * abs(z):
                small = False
        lam = 1.0
        while True:
            for i in range(m):
                zt[i] = v[b.z + i] + lam * v[b.b + i]
            f(t, x, p, w, zt, 0, rt, 0, None, 0)
            trial = _norm2(rt, 0, m)
            if small or trial <= (1.0 - 1e-4 * lam) * norm or lam < 1e-3:
                break
            lam *= 0.5
        for i in range(m):
            v[b.z + i] = zt[i]
            v[b.r + i] = rt[i]
        norm = trial
        if not math.isfinite(norm):
            raise _BlockFailure(k, 3, t)
        if small:
            break
        f(t, x, p, w, v, b.z, v, b.r, v, b.save)
    if final_factor:
        f(t, x, p, w, v, b.z, v, b.r, v, b.save)
        if not _block_factor(w, b):
            raise _BlockFailure(k, 1, t)


# ---------------------------------------------------------------- public functions


_WORK = []


def _work():
    if not _WORK:
        _WORK.append(_Work())
    return _WORK[0]


def _vector(v, n, what):
    values = numpy.asarray(v, dtype=float).reshape(-1).tolist()
    if len(values) != n:
        raise ValueError(f"{what} must have {n} elements, not {len(values)}")
    return values


def _public(function, t, x, p, size, *extra):
    p = _with_constants(_vector(p, len(_PARAM_NAMES), "p"))
    out = [0.0] * size
    try:
        function(float(t), _vector(x, _N, "x"), p, _work(), *extra, out)
    except _BlockFailure as failure:
        raise BlockError(str(failure)) from None
    return numpy.array(out, dtype=float)


def rhs(t, x, p):
    """dx/dt at (t, x) with parameters p (a 1-D array ordered as PARAMETERS)."""
    return _public(_rhs, t, x, p, _N)


def outputs(t, x, p):
    """The outputs at (t, x), ordered as OUTPUTS."""
    return _public(_out, t, x, p, len(OUTPUTS))


def jvp(t, x, p, v):
    """J v, the derivative of rhs with respect to x along v (derived symbolically)."""
    return _public(_jvp, t, x, p, _N, _vector(v, _N, "v"))


def jacobian(t, x, p):
    """J = d rhs / d x at (t, x), shape (len(STATES), len(STATES)): one jvp per colour of
    the Jacobian's columns (columns of a colour share no row)."""
    p = _with_constants(_vector(p, len(_PARAM_NAMES), "p"))
    x = _vector(x, _N, "x")
    J = numpy.zeros((_N, _N))
    try:
        _jacobian_into(float(t), x, p, _work(), J)
    except _BlockFailure as failure:
        raise BlockError(str(failure)) from None
    return J


def _jacobian_into(t, x, p, w, J):
    v = [0.0] * _N
    jv = [0.0] * _N
    for cols in _JAC_COLORS:
        for j in cols:
            v[j] = 1.0
        _jvp(t, x, p, w, v, jv)
        for j in cols:
            v[j] = 0.0
            for i in _JAC_COLUMNS[j]:
                J[i, j] = jv[i]


def _param_values(overrides):
    """All parameter values: the overrides {index: value}, the rest from their defaults."""
    p = [0.0] * len(_PARAM_NAMES)
    for j, value in overrides.items():
        p[j] = float(value)
    return _fill_params(p, overrides)


def _with_constants(p):
    """The parameters followed by the constants computed from them, as the model functions
    take them."""
    return list(p) + _constants(p)


PARAMETERS = dict(zip(_PARAM_NAMES, _param_values({})))


# ---------------------------------------------------------------- constraints


def _check_constraints(t, x, p, allow=False):
    """Messages for the violated constraint rows at (t, x); with allow (a run started off its
    constraints on purpose, --allow-inconsistent) only for the rows that are not finite."""
    r, s = _residual(t, x, p), _scale(t, x, p)
    return [
        ("initial conditions violate constraint '%s' (%s): residual = %.17g"
         % (CONSTRAINTS[k][0], CONSTRAINTS[k][1], r[k])) if math.isfinite(r[k]) else
        ("at t = %.17g: the %s residual of constraint '%s' is not finite: the model is undefined "
         "at the initial state with these parameters (a zero mass, say)"
         % (t, CONSTRAINTS[k][1], CONSTRAINTS[k][0]))
        for k in range(len(CONSTRAINTS))
        if not (abs(r[k]) <= 1e-9 * s[k] or (allow and math.isfinite(r[k])))
    ]


def _solve(m, A, b):
    """Gaussian elimination with partial pivoting (A row-major m x m); None if singular."""
    scale = 0.0
    for a in A:
        scale = max(scale, abs(a))
    for k in range(m):
        piv = k
        for i in range(k + 1, m):
            if abs(A[i * m + k]) > abs(A[piv * m + k]):
                piv = i
        if not abs(A[piv * m + k]) > 1e-14 * scale:
            return None
        if piv != k:
            for j in range(m):
                A[k * m + j], A[piv * m + j] = A[piv * m + j], A[k * m + j]
            b[k], b[piv] = b[piv], b[k]
        for i in range(k + 1, m):
            f = A[i * m + k] / A[k * m + k]
            for j in range(k, m):
                A[i * m + j] -= f * A[k * m + j]
            b[i] -= f * b[k]
    for i in range(m - 1, -1, -1):
        total = b[i]
        for j in range(i + 1, m):
            total -= A[i * m + j] * b[j]
        b[i] = total / A[i * m + i]
    return b


def _project_rows(t, x, p, rows, jac, movable):
    """Gauss-Newton minimum-norm projection onto rows; None or the reason it failed."""
    m, n = len(rows), _N
    for it in range(51):
        r, s = _residual(t, x, p), _scale(t, x, p)
        z = [r[k] for k in rows]
        if all(abs(z[i]) <= 1e-9 * s[k] for i, k in enumerate(rows)):
            return None
        if it == 50:
            return "no convergence after 50 iterations"
        J = jac(t, x, p)
        if movable is not None:
            J = [0.0 if not movable[c % n] else v for c, v in enumerate(J)]
        A = [0.0] * (m * m)
        for i in range(m):
            for j in range(m):
                total = 0.0
                for k in range(n):
                    total += J[i * n + k] * J[j * n + k]
                A[i * m + j] = total
        if _solve(m, A, z) is None:
            return "the constraint Jacobian is singular"
        for k in range(n):
            dx = 0.0
            for i in range(m):
                dx += J[i * n + k] * z[i]
            x[k] -= dx
    return None


def _project_initial(t, x, p):
    why = _project_rows(t, x, p, _POSITION_ROWS, _position_jac, None)
    level = "position"
    if why is None:
        why = _project_rows(t, x, p, _VELOCITY_ROWS, _velocity_jac, _VELOCITY_MOVABLE)
        level = "velocity"
    if why is not None:
        raise ConstraintError(
            "cannot project the initial conditions onto the %s constraints: %s" % (level, why))


# ---------------------------------------------------------------- settings


class _Settings:
    __slots__ = ("t0", "t_end", "dt", "solver", "rtol", "atol", "step", "max_steps", "h0",
                 "order0")

    def __init__(self, **values):
        values.setdefault("h0", 0.0)  # a run that goes on from an earlier one (bgc_settings):
        values.setdefault("order0", 0)  # its step size and radau's order
        for key in self.__slots__:
            setattr(self, key, values[key])


MAX_STEPS = 100000  # the most steps accepted between two output times, unless set (0: no limit)


def _settings(t_end=None, dt=None, solver=None, rtol=None, atol=None, step=None,
              max_steps=None):
    given = {"t_end": t_end, "dt": dt, "solver": solver, "rtol": rtol, "atol": atol, "step": step,
             "max_steps": max_steps}
    values = dict(SCENE, max_steps=MAX_STEPS)
    values.update((k, v) for k, v in given.items() if v is not None)
    for key in ("t0", "t_end", "dt", "rtol", "atol"):
        values[key] = float(values[key])
    values["step"] = 0.0 if values["step"] is None else float(values["step"])
    s = _Settings(**values)
    message = _check_settings(s)
    if message:
        raise ValueError(message)
    return s


def _check_settings(s):
    if not all(math.isfinite(v) for v in (s.t0, s.t_end, s.dt, s.rtol, s.atol, s.step)):
        return "settings must be finite numbers"
    if not s.dt > 0.0:
        return "--dt must be positive"
    if s.t_end < s.t0:
        return "--t-end must not be before the start time"
    if not (s.rtol > 0.0 and s.atol > 0.0):
        return "--rtol and --atol must be positive"
    if s.step < 0.0:
        return "--step must be positive"
    if not (s.max_steps >= 0 and s.max_steps == int(s.max_steps)):
        return "--max-steps must be a whole number from 0 (no limit) to 1e15"
    if s.solver not in SOLVERS:
        return "unknown solver"
    if not (s.t_end - s.t0) / s.dt <= 1e9:
        return "too many output rows (more than 1e9): increase --dt"
    return None


# ---------------------------------------------------------------- simulate


def _overrides(params):
    given = {}
    for name, value in (params or {}).items():
        if name not in _PARAM_NAMES:
            raise ValueError("unknown parameter '%s'" % name)
        given[_PARAM_NAMES.index(name)] = float(value)
    return given


def _initial_state(s, p, project_initial, allow_inconsistent=False):
    """x0 for the run: initialised, checked finite, projected if asked, constraints checked
    (only for finite residuals with allow_inconsistent).  p: the parameters and their
    constants."""
    j = _first_nonfinite(p[:len(_PARAM_NAMES)])
    if j >= 0:
        raise SimulationError("parameter '%s' is not finite" % _PARAM_NAMES[j], s.t0,
                              numpy.zeros(0), numpy.zeros((0, len(OUTPUTS))))
    x0 = _init(p)
    i = _first_nonfinite(x0)
    if i >= 0:
        raise SimulationError(str(_fail(s.t0, "state", STATES[i])), s.t0, numpy.zeros(0),
                              numpy.zeros((0, len(OUTPUTS))))
    if project_initial:
        _project_initial(s.t0, x0, p)
    messages = _check_constraints(s.t0, x0, p, allow_inconsistent)
    if messages:
        raise ConstraintError("; ".join(messages), messages)
    return x0


def rows(t_end=None, dt=None, solver=None, rtol=None, atol=None, params=None, step=None,
         project_initial=False, stats=None, max_steps=None, allow_inconsistent=False):
    """Runs the model, yielding each output row (t, y) as it is computed (y a list ordered as
    OUTPUTS): memory does not grow with the run's length.  A failure raises SimulationError
    after the rows before it (its .times and .rows are then empty: they were yielded).
    stats: a dict that receives the solver's counters.  allow_inconsistent: start from
    initial values that violate the constraints, neither refused nor projected (the
    correctors pull them back); it excludes project_initial."""
    if project_initial and allow_inconsistent:
        raise ValueError("project_initial and allow_inconsistent exclude each other")
    s = _settings(t_end, dt, solver, rtol, atol, step, max_steps)
    p = _with_constants(_param_values(_overrides(params)))
    x0 = _initial_state(s, p, project_initial, allow_inconsistent)
    st = _new_stats() if stats is None else stats
    st.update(_new_stats())
    try:
        for t, y in _integrate(s, p, x0, st):
            yield t, y
    except _Failure as failure:
        raise SimulationError(str(failure), failure.t, numpy.zeros(0),
                              numpy.zeros((0, len(OUTPUTS)))) from None


def simulate(t_end=None, dt=None, solver=None, rtol=None, atol=None, params=None, step=None,
             project_initial=False, out=None, max_steps=None, allow_inconsistent=False):
    """Runs the model; returns (t, Y) with Y[k] the outputs at t[k].  None: the scene's value.
    out: a file name or a text file: the CSV is written there row by row as the run goes
    (header first, as the program writes it) and nothing is kept: returns the number of rows."""
    run = rows(t_end, dt, solver, rtol, atol, params, step, project_initial,
               max_steps=max_steps, allow_inconsistent=allow_inconsistent)
    if out is not None:
        return _stream(run, out)
    times, values = [], []
    try:
        for t, y in run:
            times.append(t)
            values.append(y)
    except SimulationError as error:
        raise SimulationError(str(error), error.t, numpy.array(times, dtype=float),
                              numpy.array(values, dtype=float).reshape(len(times), len(OUTPUTS))) \
            from None
    return (numpy.array(times, dtype=float),
            numpy.array(values, dtype=float).reshape(len(times), len(OUTPUTS)))


def _stream(run, out):
    if not hasattr(out, "write"):
        with open(out, "w", encoding="utf-8", newline="") as f:
            return _stream(run, f)
    out.write(",".join(["t"] + OUTPUTS) + "\n")
    count = 0
    for t, y in run:
        out.write(_row_text(t, y))
        count += 1
    return count


def _row_text(t, y):
    return ",".join(["%.17g" % t] + ["%.17g" % v for v in y]) + "\n"


# ---------------------------------------------------------------- command line

USAGE = (
    " [--t-end T] [--dt DT] [--solver NAME] [--rtol R] [--atol A]\n"
    "       [--step H] [--max-steps N] [-p NAME=VALUE ...] [--stats] [--progress]\n"
    "       [--project-initial | --allow-inconsistent]\n"
    "       [--batch FILE|- [--metric KIND:OUTPUT ...] [--trajectories DIR]]\n"
)
_WITH_VALUE = ("--t-end", "--dt", "--solver", "--rtol", "--atol", "--step", "--max-steps", "-p")
_NUMBER_CHARS = frozenset("0123456789+-.eE")


class _UsageError(Exception):
    pass


def _usage():
    return "usage: " + _IDENT + USAGE


def _help():
    s = _settings()
    lines = [
        _usage() + "Simulates the model and writes CSV (t and the outputs) to stdout.",
        "  --t-end T          end time (%.17g; the start time is %.17g)" % (s.t_end, s.t0),
        "  --dt DT            output interval (%.17g)" % s.dt,
        "  --solver NAME      the solver (%s), one of those listed below" % s.solver,
        "  --rtol R           relative tolerance of the adaptive solvers (%.17g)" % s.rtol,
        "  --atol A           absolute tolerance of the adaptive solvers (%.17g)" % s.atol,
        "  --step H           step of the fixed-step solvers (default: dt)",
        "  --max-steps N      the most steps between two output times (%d; 0: no limit)"
        % s.max_steps,
        "  -p NAME=VALUE      set a parameter; derived parameters follow",
        "  --project-initial  project the initial state onto the constraints",
        "  --allow-inconsistent  start from an initial state that violates the constraints",
        "                     (the correctors pull it back): neither refused nor projected",
        "  --stats            print the solver's counters to stderr",
        "  --progress         report the progress on stderr: lines bgc-progress T T0 T_END",
        "  --batch FILE       one run per line of FILE (- for stdin): NAME=VALUE words;",
        "                     writes a CSV row per run: run,status,metrics,steps,rejected,",
        "                     rhs,cpu,message",
        "  --metric K:OUTPUT  with --batch: a column, K one of final, max, min, maxabs, rms",
        "  --trajectories DIR with --batch: each run's CSV also to DIR/run-NNNNNN.csv",
        "solvers:",
    ]
    lines += ["  %-8s %s" % (name, m["summary"]) for name, m in _METHODS.items()]
    if PARAMETERS:
        lines.append("parameters (NAME = default):")
    lines += ["  %s = %.17g" % (name, value) for name, value in PARAMETERS.items()]
    sys.stdout.write("\n".join(lines) + "\n")


def _parse_number(option, text):
    """A decimal number (digits, sign, '.', exponent: no hex, inf or nan), finite."""
    if text and set(text) <= _NUMBER_CHARS:
        try:
            value = float(text)
        except ValueError:
            value = math.nan
        if math.isfinite(value):
            return value
    raise _UsageError("error: invalid value for %s: '%s'\n" % (option, text))


def _parse_param(text, given):
    name, eq, value = text.rpartition("=")
    if not eq or not name:
        raise _UsageError("error: -p expects NAME=VALUE, got '%s'\n" % text)
    if name not in _PARAM_NAMES:
        raise _UsageError("error: unknown parameter '%s'\n" % name)
    given[_PARAM_NAMES.index(name)] = _parse_number(name, value)


def _apply_option(name, value, options, given):
    if name == "-p":
        _parse_param(value, given)
    elif name == "--solver":
        if value not in SOLVERS:
            raise _UsageError(
                "error: unknown solver '%s' (expected %s)\n" % (value, _SOLVER_LIST))
        options["solver"] = value
    elif name == "--step":
        options["step"] = _parse_number(name, value)
        if not options["step"] > 0.0:
            raise _UsageError("error: --step must be positive\n")
    elif name == "--max-steps":
        n = _parse_number(name, value)
        if not (0.0 <= n <= 1e15 and n == math.floor(n)):
            raise _UsageError(
                "error: --max-steps must be a whole number from 0 (no limit) to 1e15\n")
        options["max_steps"] = int(n)
    else:
        options[name[2:].replace("-", "_")] = _parse_number(name, value)


def _parse_args(argv):
    """(options, given parameters, flags), or None after --help."""
    options, given, flags = {}, {}, set()
    i = 0
    while i < len(argv):
        arg = argv[i]
        if arg in ("-h", "--help"):
            _help()
            return None
        if arg in ("--project-initial", "--allow-inconsistent", "--stats", "--progress"):
            flags.add(arg)
            if {"--project-initial", "--allow-inconsistent"} <= flags:
                raise _UsageError(
                    "error: --project-initial and --allow-inconsistent exclude each other\n")
            i += 1
            continue
        name, eq, value = arg.partition("=") if arg.startswith("--") else (arg, "", "")
        if name not in _WITH_VALUE:
            raise _UsageError("error: unknown option '%s'\n%s" % (arg, _usage()))
        if not eq:
            if i + 1 >= len(argv):
                raise _UsageError("error: option '%s' needs a value\n%s" % (arg, _usage()))
            i += 1
            value = argv[i]
        _apply_option(name, value, options, given)
        i += 1
    return options, given, flags


def _stop_on_signals():
    """SIGINT and SIGTERM stop the run at its next step, its rows written (as the C program
    does); the handlers they replace, to restore.  None outside the main thread."""
    replaced = []
    if threading.current_thread() is threading.main_thread():
        for sig in (signal.SIGINT, signal.SIGTERM):
            replaced.append((sig, signal.signal(sig, lambda number, frame: request_stop(number))))
    return replaced


def _progress_reporter(s):
    """--progress: a line "bgc-progress T T0 T_END" on stderr at the first row, then as the
    rows pass at most ten a second (bgc simulate draws them as a bar)."""
    last = [None]

    def report(t):
        now = time.monotonic()  # (time: imported by solve.py, below)
        if last[0] is None or now - last[0] >= 0.1:
            last[0] = now
            sys.stderr.write("bgc-progress %.17g %.17g %.17g\n" % (t, s.t0, s.t_end))
            sys.stderr.flush()
    return report


def main(argv=None):
    """The command line; returns the exit status."""
    argv = sys.argv[1:] if argv is None else list(argv)
    if any(a == "--batch" or a.startswith("--batch=") for a in argv):
        return _batch_main(argv)  # batch.py
    try:
        parsed = _parse_args(argv)
    except _UsageError as error:
        sys.stderr.write(str(error))
        return 2
    if parsed is None:
        return 0
    options, given, flags = parsed
    try:
        s = _settings(**options)
    except ValueError as error:
        sys.stderr.write("error: %s\n" % error)
        return 2
    p = _with_constants(_param_values(given))
    try:
        x0 = _initial_state(s, p, "--project-initial" in flags,
                            "--allow-inconsistent" in flags)
    except ConstraintError as error:
        sys.stderr.write("".join("error: %s\n" % m for m in error.messages))
        return 1
    except SimulationError as error:
        sys.stderr.write("error: %s\n" % error)
        return 3
    stats = _new_stats()
    failure = None
    out = sys.stdout
    out.write(",".join(["t"] + OUTPUTS) + "\n")
    handlers = _stop_on_signals()
    progress = _progress_reporter(s) if "--progress" in flags else None
    try:
        for t, y in _integrate(s, p, x0, stats):
            out.write(_row_text(t, y))
            if progress is not None:
                progress(t)
    except _Failure as error:
        failure = error
    finally:
        for sig, handler in handlers:
            signal.signal(sig, handler)
        request_stop(0)
    out.flush()
    if "--stats" in flags:
        sys.stderr.write(_stats_line(stats) + "\n")
    if failure is not None:
        sys.stderr.write("error: %s\n" % failure)
        return 3
    return 0

