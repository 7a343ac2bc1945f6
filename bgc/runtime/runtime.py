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


# ---------------------------------------------------------------- workspace


class _Block:
    __slots__ = ("m", "dense", "symmetric", "nnz", "diag", "lptr", "lpos", "lrow", "uptr", "upos", "ucol",
                 "upd", "prow", "pcol", "save", "lu", "dense_off", "b", "scale", "z", "r", "zt",
                 "rt", "piv", "how")

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
    for k in range(m):
        r = piv[pbase + k]
        if r != k:
            x[xbase + k], x[xbase + r] = x[xbase + r], x[xbase + k]
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
    """Factor the matrix assembled at b.save: the static order, else densely; False if
    singular.  Records which in w.iv[b.how]."""
    v = w.v
    scale = _row_scales(b, v, b.save)
    if not b.dense:
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
    if w.iv[b.how] == 0:
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
    return math.sqrt(sum(v[base + i] * v[base + i] for i in range(m)))


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


def _check_constraints(t, x, p):
    """Messages for the violated constraint rows at (t, x)."""
    r, s = _residual(t, x, p), _scale(t, x, p)
    return [
        "initial conditions violate constraint '%s' (%s): residual = %.17g"
        % (CONSTRAINTS[k][0], CONSTRAINTS[k][1], r[k])
        for k in range(len(CONSTRAINTS))
        if not abs(r[k]) <= 1e-9 * s[k]
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
    __slots__ = ("t0", "t_end", "dt", "solver", "rtol", "atol", "step")

    def __init__(self, **values):
        for key in self.__slots__:
            setattr(self, key, values[key])


def _settings(t_end=None, dt=None, solver=None, rtol=None, atol=None, step=None):
    given = {"t_end": t_end, "dt": dt, "solver": solver, "rtol": rtol, "atol": atol, "step": step}
    values = dict(SCENE, **{k: v for k, v in given.items() if v is not None})
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
    if s.solver not in SOLVERS:
        return "unknown solver"
    if not (s.t_end - s.t0) / s.dt <= 1e9:
        return "too many output rows (more than 1e9): increase --dt"
    return None


# ---------------------------------------------------------------- solvers


def _output_count(s):
    n = math.ceil((s.t_end - s.t0) / s.dt - 1e-6)
    return n if n > 0 else 0


def _output_time(s, k, n):
    return s.t_end if k >= n else s.t0 + k * s.dt


def _hmin(t):
    """Steps below this are too small to resolve at t (16 ulps of t; the least normal at 0)."""
    return max(16.0 * _EPS * abs(t), sys.float_info.min)


def _first_nonfinite(v):
    for i, a in enumerate(v):
        if not math.isfinite(a):
            return i
    return -1


def _fail(t, what, name):
    return _Failure("at t = %.17g: %s '%s' is not finite" % (t, what, name), t)


def _fail_step(t, h, worst):
    if worst >= 0:
        message = "at t = %.17g: step size too small (h = %.3g), limited by state '%s'" % (
            t, h, STATES[worst])
    else:
        message = "at t = %.17g: step size too small (h = %.3g)" % (t, h)
    return _Failure(message, t)


def _f(t, y, p, w):
    """dy/dt; a failed algebraic block raises _BlockFailure."""
    out = [0.0] * _N
    _rhs(t, y, p, w, out)
    return out


def _block_failed(failure):
    return _Failure(str(failure), failure.t)


def _emit(p, w, t, x, sink):
    y = [0.0] * len(OUTPUTS)
    try:
        _out(t, x, p, w, y)
    except _BlockFailure as failure:
        raise _block_failed(failure) from None
    j = _first_nonfinite(y)
    if j >= 0:
        raise _fail(t, "output", OUTPUTS[j])
    sink(t, x, y)


def _substeps(span, h):
    r = span / h
    if not r < 1e15:
        return -1
    m = math.ceil(r - 1e-6)
    return 1 if m < 1 else m


def _fixed_step(solver, p, w, t, h, y, st):
    """One Euler or classical Runge-Kutta step from (t, y) to t + h; returns the new y."""
    try:
        k1 = _f(t, y, p, w)
        st["rhs"] += 1
        i = _first_nonfinite(k1)
        if i >= 0:
            raise _fail(t, "derivative of state", STATES[i])
        if solver == "euler":
            y = [a + h * b for a, b in zip(y, k1)]
        else:
            h2, h6 = 0.5 * h, h / 6.0
            k2 = _f(t + h2, [a + h2 * b for a, b in zip(y, k1)], p, w)
            k3 = _f(t + h2, [a + h2 * b for a, b in zip(y, k2)], p, w)
            k4 = _f(t + h, [a + h * b for a, b in zip(y, k3)], p, w)
            st["rhs"] += 3
            y = [a + h6 * (b1 + 2.0 * (b2 + b3) + b4)
                 for a, b1, b2, b3, b4 in zip(y, k1, k2, k3, k4)]
    except _BlockFailure as failure:
        raise _block_failed(failure) from None
    st["steps"] += 1
    i = _first_nonfinite(y)
    if i >= 0:
        raise _fail(t + h, "state", STATES[i])
    return y


def _run_fixed(s, p, w, y, sink, st):
    nout = _output_count(s)
    hstep = s.step if s.step > 0.0 else s.dt
    ta = s.t0
    _emit(p, w, ta, y, sink)
    for k in range(1, nout + 1):
        tb = _output_time(s, k, nout)
        m = _substeps(tb - ta, hstep)
        if m < 0:
            raise _fail_step(ta, hstep, -1)
        for j in range(m):
            t = ta + j * hstep
            t1 = tb if j + 1 == m else ta + (j + 1) * hstep
            if not t1 - t >= _hmin(t):
                raise _fail_step(t, t1 - t, -1)
            y = _fixed_step(s.solver, p, w, t, t1 - t, y, st)
        _emit(p, w, tb, y, sink)
        ta = tb


# Dormand-Prince 5(4) coefficients, as in Hairer's DOPRI5.
C2, C3, C4, C5 = 1.0 / 5.0, 3.0 / 10.0, 4.0 / 5.0, 8.0 / 9.0
A21 = 1.0 / 5.0
A31, A32 = 3.0 / 40.0, 9.0 / 40.0
A41, A42, A43 = 44.0 / 45.0, -56.0 / 15.0, 32.0 / 9.0
A51, A52, A53, A54 = 19372.0 / 6561.0, -25360.0 / 2187.0, 64448.0 / 6561.0, -212.0 / 729.0
A61, A62, A63 = 9017.0 / 3168.0, -355.0 / 33.0, 46732.0 / 5247.0
A64, A65 = 49.0 / 176.0, -5103.0 / 18656.0
A71, A73, A74 = 35.0 / 384.0, 500.0 / 1113.0, 125.0 / 192.0
A75, A76 = -2187.0 / 6784.0, 11.0 / 84.0
E1, E3, E4 = 71.0 / 57600.0, -71.0 / 16695.0, 71.0 / 1920.0
E5, E6, E7 = -17253.0 / 339200.0, 22.0 / 525.0, -1.0 / 40.0
D1, D3 = -12715105075.0 / 11282082432.0, 87487479700.0 / 32700410799.0
D4, D5 = -10690763975.0 / 1880347072.0, 701980252875.0 / 199316789632.0
D6, D7 = -1453857185.0 / 822651844.0, 69997945.0 / 29380423.0
SAFE, FACC1, FACC2, BETA = 0.9, 5.0, 0.1, 0.04  # FACC1 = 1/0.2, FACC2 = 1/10
EXPO1 = 0.2 - BETA * 0.75


def _initial_step(s, p, w, t, y, f0, hmax, st):
    """Hairer's initial step size guess (HINIT with order 5)."""
    dnf = dny = der2 = 0.0
    for a, f in zip(y, f0):
        sk = s.atol + s.rtol * abs(a)
        qf, qy = f / sk, a / sk
        dnf += qf * qf
        dny += qy * qy
    h = 1e-6 if (dnf <= 1e-10 or dny <= 1e-10) else math.sqrt(dny / dnf) * 0.01
    h = min(h, hmax)
    st["rhs"] += 1
    try:
        f1 = _f(t + h, [a + h * f for a, f in zip(y, f0)], p, w)
    except _BlockFailure:
        return h  # a block failed there: start small, the step control takes over
    for a, f, g in zip(y, f0, f1):
        q = (g - f) / (s.atol + s.rtol * abs(a))
        der2 += q * q
    der2 = math.sqrt(der2) / h
    der12 = max(math.sqrt(dnf), abs(der2))  # a NaN der2 is ignored
    h1 = max(1e-6, h * 1e-3) if der12 <= 1e-15 else (0.01 / der12) ** 0.2
    if not h1 > 0.0:
        h1 = h * 1e-3
    return min(min(100.0 * h, h1), hmax)


def _trial_culprit(y1, stages):
    i = _first_nonfinite(y1)
    if i >= 0:
        return i, "state"
    for k in stages:
        i = _first_nonfinite(k)
        if i >= 0:
            break
    return i, "derivative of state"


def _stages(s, p, w, t, h, tph, y, k1):
    k2 = _f(t + C2 * h, [a + h * A21 * b1 for a, b1 in zip(y, k1)], p, w)
    k3 = _f(t + C3 * h, [a + h * (A31 * b1 + A32 * b2) for a, b1, b2 in zip(y, k1, k2)], p, w)
    k4 = _f(t + C4 * h, [a + h * (A41 * b1 + A42 * b2 + A43 * b3)
                         for a, b1, b2, b3 in zip(y, k1, k2, k3)], p, w)
    k5 = _f(t + C5 * h, [a + h * (A51 * b1 + A52 * b2 + A53 * b3 + A54 * b4)
                         for a, b1, b2, b3, b4 in zip(y, k1, k2, k3, k4)], p, w)
    k6 = _f(tph, [a + h * (A61 * b1 + A62 * b2 + A63 * b3 + A64 * b4 + A65 * b5)
                  for a, b1, b2, b3, b4, b5 in zip(y, k1, k2, k3, k4, k5)], p, w)
    y1 = [a + h * (A71 * b1 + A73 * b3 + A74 * b4 + A75 * b5 + A76 * b6)
          for a, b1, b3, b4, b5, b6 in zip(y, k1, k3, k4, k5, k6)]
    k7 = _f(tph, y1, p, w)
    return k2, k3, k4, k5, k6, k7, y1


def _run_dopri5(s, p, w, y, sink, st):
    nout = _output_count(s)
    hmax = s.t_end - s.t0
    t, facold, kout = s.t0, 1e-4, 1
    reject, last, worst, bad, bad_kind = False, False, -1, -1, ""
    block_failure = None
    n = _N
    _emit(p, w, t, y, sink)
    if nout == 0:
        return
    st["rhs"] += 1
    try:
        k1 = _f(t, y, p, w)
    except _BlockFailure as failure:
        raise _block_failed(failure) from None
    i = _first_nonfinite(k1)
    if i >= 0:
        raise _fail(t, "derivative of state", STATES[i])
    h = _initial_step(s, p, w, t, y, k1, hmax, st)
    while True:
        if not h >= _hmin(t):
            if bad == -2:
                raise _block_failed(block_failure)
            if bad >= 0:
                raise _fail(t, bad_kind, STATES[bad])
            raise _fail_step(t, h, worst)
        if t + 1.01 * h - s.t_end > 0.0:
            h = s.t_end - t
            last = True
        tph = s.t_end if last else t + h
        st["rhs"] += 6
        try:
            k2, k3, k4, k5, k6, k7, y1 = _stages(s, p, w, t, h, tph, y, k1)
        except _BlockFailure as failure:  # retry with a much smaller step
            bad, block_failure = -2, failure
            h = h / FACC1
            reject, last = True, False
            st["rejected"] += 1
            continue

        # Hairer's error norm: RMS of err_i / (atol + rtol * max(|y_i|, |y1_i|)).
        err, worst_q = 0.0, -1.0
        for i in range(n):
            sk = s.atol + s.rtol * max(abs(y[i]), abs(y1[i]))
            q = h * (E1 * k1[i] + E3 * k3[i] + E4 * k4[i] + E5 * k5[i] + E6 * k6[i]
                     + E7 * k7[i]) / sk
            err += q * q
            if q * q > worst_q:
                worst_q, worst = q * q, i
        err = math.sqrt(err / n) if n > 0 else 0.0
        if err != err:  # a non-finite stage: retry with a much smaller step
            bad, bad_kind = _trial_culprit(y1, (k2, k3, k4, k5, k6, k7))
            h = h / FACC1
            reject, last = True, False
            st["rejected"] += 1
            continue

        fac11 = err ** EXPO1
        fac = fac11 / facold ** BETA
        fac = max(FACC2, min(FACC1, fac / SAFE))
        hnew = h / fac
        if err <= 1.0:
            facold = max(err, 1e-4)
            st["steps"] += 1
            i = _first_nonfinite(y1)
            if i >= 0:
                raise _fail(tph, "state", STATES[i])
            rcont = None
            while kout <= nout:
                tk = _output_time(s, kout, nout)
                if tk > tph:
                    break
                if tk == tph:
                    _emit(p, w, tk, y1, sink)
                else:
                    if rcont is None:
                        rcont = _dense_coefficients(h, y, y1, k1, k3, k4, k5, k6, k7)
                    _emit(p, w, tk, _dense(rcont, (tk - t) / h), sink)
                kout += 1
            k1, y, t = k7, y1, tph
            if last:
                return
            if abs(hnew) > hmax:
                hnew = hmax
            if reject:
                hnew = min(hnew, h)
            reject, bad = False, -1
        else:
            hnew = h / min(FACC1, fac11 / SAFE)
            reject, last = True, False
            st["rejected"] += 1
        h = hnew


def _dense_coefficients(h, y, y1, k1, k3, k4, k5, k6, k7):
    rcont = []
    for i in range(len(y)):
        ydiff = y1[i] - y[i]
        bspl = h * k1[i] - ydiff
        rcont.append((y[i], ydiff, bspl, -h * k7[i] + ydiff - bspl,
                      h * (D1 * k1[i] + D3 * k3[i] + D4 * k4[i] + D5 * k5[i] + D6 * k6[i]
                           + D7 * k7[i])))
    return rcont


def _dense(rcont, theta):
    """Hairer's continuous extension of order 4 (CONTD5) at theta in [0, 1]."""
    theta1 = 1.0 - theta
    return [r1 + theta * (r2 + theta1 * (r3 + theta * (r4 + theta1 * r5)))
            for r1, r2, r3, r4, r5 in rcont]


def _integrate(s, p, x0, sink, st):
    y = list(x0)
    i = _first_nonfinite(y)
    if i >= 0:
        raise _fail(s.t0, "state", STATES[i])
    w = _Work(s.rtol, s.atol)
    if s.solver == "dopri5":
        _run_dopri5(s, p, w, y, sink, st)
    else:
        _run_fixed(s, p, w, y, sink, st)


# ---------------------------------------------------------------- simulate


def _overrides(params):
    given = {}
    for name, value in (params or {}).items():
        if name not in _PARAM_NAMES:
            raise ValueError("unknown parameter '%s'" % name)
        given[_PARAM_NAMES.index(name)] = float(value)
    return given


def _initial_state(s, p, project_initial):
    """x0 for the run: initialised, checked finite, projected if asked, constraints checked.
    p: the parameters and their constants."""
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
    messages = _check_constraints(s.t0, x0, p)
    if messages:
        raise ConstraintError("; ".join(messages), messages)
    return x0


def simulate(t_end=None, dt=None, solver=None, rtol=None, atol=None, params=None, step=None,
             project_initial=False):
    """Runs the model; returns (t, Y) with Y[k] the outputs at t[k].  None: the scene's value."""
    s = _settings(t_end, dt, solver, rtol, atol, step)
    p = _with_constants(_param_values(_overrides(params)))
    x0 = _initial_state(s, p, project_initial)
    times, rows = [], []

    def sink(t, x, y):
        times.append(t)
        rows.append(y)

    try:
        _integrate(s, p, x0, sink, {"steps": 0, "rejected": 0, "rhs": 0})
    except _Failure as failure:
        raise SimulationError(str(failure), failure.t, numpy.array(times, dtype=float),
                              numpy.array(rows, dtype=float).reshape(len(times), len(OUTPUTS)))
    return (numpy.array(times, dtype=float),
            numpy.array(rows, dtype=float).reshape(len(times), len(OUTPUTS)))


# ---------------------------------------------------------------- command line

USAGE = (
    " [--t-end T] [--dt DT] [--solver euler|rk4|dopri5] [--rtol R] [--atol A]\n"
    "       [--step H] [-p NAME=VALUE ...] [--project-initial] [--stats]\n"
)
_WITH_VALUE = ("--t-end", "--dt", "--solver", "--rtol", "--atol", "--step", "-p")
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
        "  --solver NAME      euler, rk4 or dopri5 (%s)" % s.solver,
        "  --rtol R           relative tolerance of dopri5 (%.17g)" % s.rtol,
        "  --atol A           absolute tolerance of dopri5 (%.17g)" % s.atol,
        "  --step H           fixed step of euler and rk4 (default: dt)",
        "  -p NAME=VALUE      set a parameter; derived parameters follow",
        "  --project-initial  project the initial state onto the constraints",
        "  --stats            print step statistics to stderr",
    ]
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
                "error: unknown solver '%s' (expected euler, rk4 or dopri5)\n" % value)
        options["solver"] = value
    elif name == "--step":
        options["step"] = _parse_number(name, value)
        if not options["step"] > 0.0:
            raise _UsageError("error: --step must be positive\n")
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
        if arg in ("--project-initial", "--stats"):
            flags.add(arg)
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


def _write_rows(out, times, rows):
    out.write("".join(
        ",".join(["%.17g" % t] + ["%.17g" % v for v in y]) + "\n" for t, y in zip(times, rows)))


def main(argv=None):
    """The command line; returns the exit status."""
    argv = sys.argv[1:] if argv is None else list(argv)
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
        x0 = _initial_state(s, p, "--project-initial" in flags)
    except ConstraintError as error:
        sys.stderr.write("".join("error: %s\n" % m for m in error.messages))
        return 1
    except SimulationError as error:
        sys.stderr.write("error: %s\n" % error)
        return 3
    times, rows = [], []
    stats = {"steps": 0, "rejected": 0, "rhs": 0}
    failure = None
    try:
        _integrate(s, p, x0, lambda t, x, y: (times.append(t), rows.append(y)), stats)
    except _Failure as error:
        failure = error
    out = sys.stdout
    out.write(",".join(["t"] + OUTPUTS) + "\n")
    _write_rows(out, times, rows)
    out.flush()
    if "--stats" in flags:
        sys.stderr.write("stats: steps=%(steps)d rejected=%(rejected)d rhs=%(rhs)d\n" % stats)
    if failure is not None:
        sys.stderr.write("error: %s\n" % failure)
        return 3
    return 0


if __name__ == "__main__":
    sys.exit(main())
