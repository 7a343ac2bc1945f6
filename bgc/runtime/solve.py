# ================================================================== solve ===
# The step driver (_drive, as bgc_drive in the C runtime's drive.c: see there for the
# contract between the driver and a method family), the explicit Runge-Kutta families (read
# from _METHODS, printed from bgc/solvers.py) and _integrate; the stiff families follow
# (bgc/runtime/stiff.py).  The explicit solvers keep small states as lists and large ones as
# numpy vectors (see _LIST_STATES); the arithmetic is the C runtime's, in the same order.

import time  # process_time(): the processor time a run reports in its stats


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


_STOP = [0]  # a signal's number: the run stops at its next accepted step (request_stop)


def request_stop(sig):
    """Asks a run in progress to stop at its next accepted step, as a failure ("interrupted by
    signal sig"), the rows before it kept; a signal handler may call it.  0 clears it."""
    _STOP[0] = sig


def _accept(run, t):
    """Counts an accepted step ending at t; raises _Failure if a stop was asked or the step
    budget since the last output is spent."""
    run.st["steps"] += 1
    if _STOP[0]:
        raise _Failure("at t = %.17g: interrupted by signal %d" % (t, _STOP[0]), t)
    if run.s.max_steps > 0 and run.st["steps"] - run.steps_out > run.s.max_steps:
        raise _Failure("at t = %.17g: step budget spent: %d steps since the output at t = %.17g "
                       "(the step size runs away; --max-steps raises the budget)"
                       % (t, run.s.max_steps, run.t_out), t)


def _block_failed(failure):
    return _Failure(str(failure), failure.t)


def _new_stats():
    return {"steps": 0, "rejected": 0, "rhs": 0, "jac": 0, "lu": 0, "solves": 0,
            "switched": False, "t_switch": 0.0, "cpu": 0.0, "h_next": 0.0, "order_next": 0}


def _stats_line(st):
    line = ("stats: steps=%(steps)d rejected=%(rejected)d rhs=%(rhs)d jac=%(jac)d lu=%(lu)d "
            "solves=%(solves)d" % st)
    if st["switched"]:
        line += " stiff_from=%.17g" % st["t_switch"]
    return line + " cpu=%.6e" % st["cpu"]


class _Stiff(Exception):
    """An auto run's explicit phase found the problem stiff."""


class _Run:
    """A run in progress (see bgc_run in the C runtime): a run function is a generator that
    integrates from (run.t, y) to s.t_end, yields the rows (t, outputs) of the output times
    run.kout .. run.nout as it passes them, keeps run.t and run.y at its last accepted step,
    and returns; or raises _Failure, _Stiff (run.h: its last step size)."""

    __slots__ = ("s", "p", "w", "st", "nout", "kout", "t", "h", "y", "detect_stiffness",
                 "steps_out", "t_out", "m", "name", "fixed")

    def __init__(self, s, p, w, st, y):
        self.s, self.p, self.w, self.st = s, p, w, st
        self.steps_out, self.t_out = st["steps"], s.t0  # the steps at the last output, its t
        self.nout, self.kout = _output_count(s), 1
        self.t, self.h, self.y = s.t0, s.h0, y
        self.detect_stiffness = False
        self.m, self.name, self.fixed = None, "", False  # the method running, see _run_solver

    def f(self, t, y):
        """dy/dt as a numpy vector; a failed algebraic block raises _BlockFailure."""
        out = [0.0] * _N
        _rhs(t, y.tolist(), self.p, self.w, out)
        return numpy.array(out, dtype=float)

    def fv(self, t, y):
        """dy/dt for the explicit solvers, in _V's kind of vector."""
        if _V is _ArrayVectors:
            return self.f(t, y)
        out = [0.0] * _N
        _rhs(t, y, self.p, self.w, out)
        return out

    def emit(self, t, x):
        if isinstance(x, numpy.ndarray):
            x = x.tolist()
        y = [0.0] * len(OUTPUTS)
        try:
            _out(t, x, self.p, self.w, y)
        except _BlockFailure as failure:
            raise _block_failed(failure) from None
        j = _first_nonfinite(y)
        if j >= 0:
            raise _fail(t, "output", OUTPUTS[j])
        self.steps_out, self.t_out = self.st["steps"], t
        yield t, y

    def emit_step(self, t, h, tph, y1, dense):
        """The output times in (t, tph] after an accepted step: tph from y1, the others from
        at(theta), the function that dense() prepares on first use."""
        at = None
        while self.kout <= self.nout:
            tk = _output_time(self.s, self.kout, self.nout)
            if tk > tph:
                break
            if tk == tph:
                yield from self.emit(tk, y1)
            else:
                if at is None:
                    at = dense()
                yield from self.emit(tk, at((tk - t) / h))
            self.kout += 1


# Byte parity with the C runtime: sums in C's sequence (never numpy.sum, dot or @, whose
# pairwise or SIMD order depends on the machine; never the builtin sum, compensated from
# Python 3.12 on), bgc_max's choice for a NaN.

def _seq_sum(v):
    """0.0 + v_0 + v_1 + ... in this order, as C's `acc = 0.0; acc += v[l]` loops."""
    return 0.0 + float(numpy.add.accumulate(v)[-1]) if len(v) else 0.0


def _seq_minus(acc, terms):
    """acc - terms_0 - terms_1 - ... in this order (C's back substitution)."""
    if len(terms) < 2:
        return acc - terms[0] if len(terms) else acc
    return numpy.subtract.accumulate(numpy.concatenate(([acc], terms)))[-1]


def _c_max(a, b):
    """bgc_max element-wise: b where b > a, else a (a NaN b is never larger)."""
    return numpy.where(b > a, b, a)


def _worst(q):
    """C's running `if (q > big)` from big = -1: the first largest non-NaN q_i, or -1."""
    q = numpy.where(q == q, q, -1.0)
    i = int(numpy.argmax(q)) if len(q) else -1
    return i if i >= 0 and q[i] > -1.0 else -1


def _weights(s, y, y1):
    """Hairer's error-norm weights atol + rtol * max(|y_i|, |y1_i|) (bgc_weight)."""
    return s.atol + s.rtol * _c_max(numpy.abs(y), numpy.abs(y1))


def _initial_step(run, q, y, f0, hmax):
    """Hairer's initial step size guess (HINIT) for a method of order q."""
    s = run.s
    y, f0 = numpy.asarray(y, dtype=float), numpy.asarray(f0, dtype=float)
    sk = s.atol + s.rtol * numpy.abs(y)
    with numpy.errstate(all="ignore"):  # IEEE as in C: an overflow gives inf, then h = 0
        qf, qy = f0 / sk, y / sk
        dnf, dny = _seq_sum(qf * qf), _seq_sum(qy * qy)
        h = 1e-6 if (dnf <= 1e-10 or dny <= 1e-10) else math.sqrt(dny / dnf) * 0.01
    h = min(h, hmax)
    run.st["rhs"] += 1
    try:
        f1 = run.f(run.t + h, y + h * f0)
    except _BlockFailure:
        return h  # a block failed there: start small, the step control takes over
    with numpy.errstate(all="ignore"):
        d = (f1 - f0) / (s.atol + s.rtol * numpy.abs(y))
        der2 = float(numpy.float64(math.sqrt(_seq_sum(d * d))) / numpy.float64(h))
    der12 = max(math.sqrt(dnf), abs(der2))  # a NaN der2 is ignored
    h1 = max(1e-6, h * 1e-3) if der12 <= 1e-15 else (0.01 / der12) ** (1.0 / q)
    if not h1 > 0.0:
        h1 = h * 1e-3
    return min(min(100.0 * h, h1), hmax)


# ---------------------------------------------------------------- explicit Runge-Kutta
# An explicit step's cost beside the model's right side is a few vector operations per
# stage.  On a handful of states a numpy call costs more than a list comprehension over the
# whole vector, so the explicit solvers keep their states as lists up to _LIST_STATES states
# and as numpy vectors above; both kits compute the same values in the same order as the C
# runtime (bgc_combine: stage by stage, left to right).

_LIST_STATES = 48


def _weighted(w, count, stride=None):
    """The (weight, stage) pairs of w[j] (w[j][stride]) over j < count, zero weights dropped."""
    pairs = []
    for j in range(min(count, len(w))):
        a = w[j] if stride is None else w[j][stride]
        if a != 0.0:
            pairs.append((a, j))
    return tuple(pairs)


def _list_terms(acc, pairs, K):
    """acc + a_0 K_j0 + ... (up to four pairs, left to right; acc None: no acc)."""
    n = len(pairs)
    (a, i) = pairs[0]
    if n == 1:
        if acc is None:
            return [a * u for u in K[i]]
        return [s + a * u for s, u in zip(acc, K[i])]
    (b, j) = pairs[1]
    if n == 2:
        if acc is None:
            return [a * u + b * v for u, v in zip(K[i], K[j])]
        return [s + a * u + b * v for s, u, v in zip(acc, K[i], K[j])]
    (c, k) = pairs[2]
    if n == 3:
        if acc is None:
            return [a * u + b * v + c * w for u, v, w in zip(K[i], K[j], K[k])]
        return [s + a * u + b * v + c * w for s, u, v, w in zip(acc, K[i], K[j], K[k])]
    (d, l) = pairs[3]
    if acc is None:
        return [a * u + b * v + c * w + d * x for u, v, w, x in zip(K[i], K[j], K[k], K[l])]
    return [s + a * u + b * v + c * w + d * x
            for s, u, v, w, x in zip(acc, K[i], K[j], K[k], K[l])]


def _list_terms_into(y, h, pairs, K):
    """y + h * (a_0 K_j0 + ...) for up to four pairs, in one comprehension."""
    n = len(pairs)
    (a, i) = pairs[0]
    if n == 1:
        return [z + h * (a * u) for z, u in zip(y, K[i])]
    (b, j) = pairs[1]
    if n == 2:
        return [z + h * (a * u + b * v) for z, u, v in zip(y, K[i], K[j])]
    (c, k) = pairs[2]
    if n == 3:
        return [z + h * (a * u + b * v + c * w) for z, u, v, w in zip(y, K[i], K[j], K[k])]
    (d, l) = pairs[3]
    return [z + h * (a * u + b * v + c * w + d * x)
            for z, u, v, w, x in zip(y, K[i], K[j], K[k], K[l])]


class _ListVectors:
    """States as Python lists."""

    @staticmethod
    def vec(x):
        return x.tolist() if isinstance(x, numpy.ndarray) else x

    @staticmethod
    def combine(y, h, pairs, K):
        """y + h * sum a K_j over the pairs (y None: h * sum), four terms per comprehension."""
        n = len(pairs)
        if n == 0:
            acc = [0.0] * _N
        elif n <= 4 and y is not None:
            return _list_terms_into(y, h, pairs, K)
        else:
            acc = _list_terms(None, pairs[:4], K)
            for k in range(4, n, 4):
                acc = _list_terms(acc, pairs[k:k + 4], K)
        if y is None:
            return [h * u for u in acc]
        return [u + h * v for u, v in zip(y, acc)]

    @staticmethod
    def horner(y, q, theta):
        """y + theta (q_0 + theta (q_1 + ...))."""
        acc = q[-1]
        for qd in reversed(q[:-1]):
            acc = [u + theta * v for u, v in zip(qd, acc)]
        return [u + theta * v for u, v in zip(y, acc)]

    @staticmethod
    def error_sums(s, y, y1, e1, e2):
        """sum (e1_i / sk_i)^2, its largest term's index, and sum (e2_i / sk_i)^2 (e2 may be
        None), sk_i = atol + rtol * max(|y_i|, |y1_i|)."""
        rtol, atol = s.rtol, s.atol
        err = err2 = 0.0
        worst, worst_q = -1, -1.0
        for i in range(_N):
            sk = atol + rtol * max(abs(y[i]), abs(y1[i]))
            qq = e1[i] / sk
            qq = qq * qq
            err += qq
            if qq > worst_q:
                worst, worst_q = i, qq
            if e2 is not None:
                q2 = e2[i] / sk
                err2 += q2 * q2
        return err, worst, err2

    @staticmethod
    def distance2(u, v):
        acc = 0.0
        for a, b in zip(u, v):
            acc += (a - b) * (a - b)
        return acc


class _ArrayVectors:
    """States as numpy vectors."""

    @staticmethod
    def vec(x):
        return numpy.asarray(x, dtype=float)

    @staticmethod
    def combine(y, h, pairs, K):
        if pairs:
            a, j = pairs[0]
            acc = a * K[j]
            for a, j in pairs[1:]:
                acc = acc + a * K[j]
        else:
            acc = numpy.zeros(_N)
        return h * acc if y is None else y + h * acc

    @staticmethod
    def horner(y, q, theta):
        acc = q[-1]
        for qd in reversed(q[:-1]):
            acc = qd + theta * acc
        return y + theta * acc

    @staticmethod
    def error_sums(s, y, y1, e1, e2):
        sk = _weights(s, y, y1)
        with numpy.errstate(all="ignore"):
            sq = e1 / sk
            sq = sq * sq
            err = _seq_sum(sq)
            q2 = e2 / sk if e2 is not None else None
            err2 = _seq_sum(q2 * q2) if e2 is not None else 0.0
        return err, _worst(sq), err2

    @staticmethod
    def distance2(u, v):
        with numpy.errstate(all="ignore"):
            d = u - v
            return _seq_sum(d * d)


_V = _ListVectors if _N <= _LIST_STATES else _ArrayVectors


def _combine(weights, K, count):
    """sum_j weights[j] K[j] over j < count with a nonzero weight, left to right, for numpy
    vectors K[j] (the stiff solvers)."""
    acc = numpy.zeros(_N)  # C's acc = 0.0, then acc += a K_j
    for j in range(count):
        a = weights[j]
        if a != 0.0:
            acc = acc + a * K[j]
    return acc


class _ErkPlan:
    """A tableau's nonzero weights, ready for _V.combine."""

    def __init__(self, m):
        stages, c = m["stages"], m["c"]
        self.a = [_weighted(m["a"][i], i) for i in range(len(c))]
        self.b = _weighted(m["b"], stages)
        self.e = _weighted(m["e"], stages) if "e" in m else ()
        self.e2 = _weighted(m["e2"], stages) if m.get("e2") else None
        P = m.get("P")
        self.P = [_weighted(P, len(P), d) for d in range(len(P[0]))] if P else []


def _substeps(span, h):
    r = span / h
    if not r < 1e15:
        return -1
    m = math.ceil(r - 1e-6)
    return 1 if m < 1 else m


# ---------------------------------------------------------------- the step driver
# A family is a class: __init__(run), start(y) -> the first step (None on a grid), step(t,
# h, tph, y) -> (outcome, y1, hnew, why), accepted(tph, y1), dense() -> at(theta), after(tph,
# y1, last) -> True when the stiffness test fired, next_h(h, hnew) -> hnew, span_grid; a
# failure that ends the run raises _Failure.  Outcomes as drive.c's; why = (bad, bad_kind,
# block failure) after a failed attempt: bad >= 0 a non-finite component (bad_kind names its
# kind), -1 the error test, -2 a block, -3 a singular matrix, -4 Newton.

_ACCEPT, _REJECT, _RETRY, _AGAIN = 0, 1, 2, 3


def _fail_small(run, t, h, bad, bad_kind, failure, worst):
    """A step size below _hmin: the message names what made the steps shrink."""
    if bad == -2:
        return _block_failed(failure)
    if bad in (-3, -4):
        what = ("the iteration matrix is singular" if bad == -3
                else "the Newton iteration does not converge")
        return _Failure("at t = %.17g: %s: %s (step size down to h = %.3g)"
                        % (t, run.name, what, h), t)
    if bad >= 0:
        return _fail(t, bad_kind, STATES[bad])
    return _fail_step(t, h, worst)


class _Grid:
    """Where a fixed-step run is: the k-th of n steps from ta to tb (the run's end on a span
    grid, else the output interval's)."""

    def __init__(self, run, span):
        s = run.s
        self.run, self.span = run, span
        self.step = s.step if s.step > 0.0 else s.dt
        self.ta = self.tb = 0.0
        self.k = self.n = 0

    def next(self, t):
        """The next step's end from t and whether it is the run's last."""
        run = self.run
        if self.k >= self.n:
            self.ta, self.k = t, 0
            self.tb = run.s.t_end if self.span else _output_time(run.s, run.kout, run.nout)
            self.n = _substeps(self.tb - self.ta, self.step)
            if self.n < 0:
                raise _fail_step(t, self.step, -1)
        end = self.k + 1 >= self.n
        tph = self.tb if end else self.ta + (self.k + 1) * self.step
        last = end and (self.span or run.kout >= run.nout)
        if not self.span:  # each step from its grid point (the same value as the last end)
            t = self.ta + self.k * self.step
        if not tph - t >= _hmin(t):
            raise _fail_step(t, tph - t, -1)
        return tph, last


def _drive(run, family, y):
    """One family's run from (run.t, y) to s.t_end: yields the rows as it passes them, keeps
    run.t and run.y at the last accepted step; raises _Failure, or _Stiff (run.h: the
    explicit phase's next step)."""
    s, st = run.s, run.st
    if run.kout > run.nout:
        return
    hmax = s.t_end - s.t0
    fam = family(run)
    h = fam.start(y)
    t = run.t
    reject = last = False
    bad, bad_kind, failure, wanted = -1, "", None, 0.0
    grid = _Grid(run, fam.span_grid)
    while True:
        if run.fixed:
            tph, last = grid.next(t)
            h = tph - t
        else:
            if not h >= _hmin(t):
                raise _fail_small(run, t, h, bad, bad_kind, failure, fam.worst)
            wanted = h
            if t + 1.01 * h - s.t_end > 0.0:
                h = s.t_end - t
                last = True
            tph = s.t_end if last else t + h
        outcome, y1, hnew, why = fam.step(t, h, tph, y)
        if outcome == _AGAIN:
            continue
        if outcome != _ACCEPT:
            if outcome == _RETRY:
                bad, bad_kind, failure = why
            reject, last = True, False
            st["rejected"] += 1
            h = hnew
            continue
        i = _first_nonfinite(y1)
        if i >= 0:
            raise _fail(tph, "state", STATES[i])
        _accept(run, tph)
        fam.accepted(tph, y1)
        yield from run.emit_step(t, h, tph, y1, fam.dense)
        y, t = y1, tph
        run.t, run.y = t, y
        grid.k += 1
        if fam.after(tph, y1, last):
            run.h = hnew
            raise _Stiff()
        if last:
            if not run.fixed:  # the step to go on with: the controller's, or the one cut short
                st["h_next"] = max(hnew, wanted)
            return
        if not run.fixed:
            hnew = min(hnew, hmax)
        if reject:
            hnew = min(hnew, h)
        reject, bad = False, -1
        h = fam.next_h(h, hnew)


class _Family:
    """What a family does not need to do (see _drive)."""

    span_grid = True
    worst = -1
    dense = None  # no output time falls inside a step of a family without a dense output

    def accepted(self, tph, y1):
        pass

    def after(self, tph, y1, last):
        return False

    def next_h(self, h, hnew):
        return hnew


# ---------------------------------------------------------------- explicit Runge-Kutta


class _FixedSteps(_Family):
    """The fixed-step methods: each step from f(t, y) afresh (no error estimate, no dense
    output: the driver lands a step on every output time)."""

    span_grid = False

    def __init__(self, run):
        m = run.m
        self.run, self.stages, self.c = run, m["stages"], m["c"]
        self.plan = _ErkPlan(m)

    def start(self, y):
        return None

    def step(self, t, h, tph, y):
        run, c, combine = self.run, self.c, _V.combine
        y = _V.vec(y)
        K = [None] * self.stages
        try:
            K[0] = run.fv(t, y)
            i = _first_nonfinite(K[0])
            if i >= 0:
                raise _fail(t, "derivative of state", STATES[i])
            for i in range(1, self.stages):
                K[i] = run.fv(t + c[i] * h, combine(y, h, self.plan.a[i], K))
        except _BlockFailure as failure:
            raise _block_failed(failure) from None
        run.st["rhs"] += self.stages
        return _ACCEPT, combine(y, h, self.plan.b, K), h, None


class _Erk(_Family):
    """Embedded explicit pairs (bgc_family_erk): Hairer's error norm and controller, outputs
    by the dense output; on fixed steps no error control.  With run.detect_stiffness,
    Hairer's stiffness test fires _Stiff once it has held on 15 accepted steps."""

    def __init__(self, run):
        m = run.m
        self.run, self.m, self.plan = run, m, _ErkPlan(m)
        self.stages, self.c = m["stages"], m["c"]
        self.last_stage = self.stages - 1
        self.fsal = m["fsal"]
        self.fsal_first = self.fsal and m["e"][self.last_stage] != 0.0
        self.stiff_i, self.stiff_j, self.stiff_bound = m.get("stiffness", (-1, -1, 0.0))
        self.expo1 = 1.0 / m["q"] - m["expo_beta"] * m["beta"]
        self.facold = 1e-4
        self.stiff_count = self.nonstiff_count = 0
        self.K = [None] * len(self.c)
        self.t = self.h = 0.0
        self.y = self.ys = self.ystiff = None

    def start(self, y):
        run = self.run
        run.st["rhs"] += 1
        try:
            self.K[0] = run.fv(run.t, _V.vec(y))
        except _BlockFailure as failure:
            raise _block_failed(failure) from None
        i = _first_nonfinite(self.K[0])
        if i >= 0:
            raise _fail(run.t, "derivative of state", STATES[i])
        if run.fixed:
            return None
        hmax = run.s.t_end - run.s.t0
        return min(run.h, hmax) if run.h > 0.0 else _initial_step(run, self.m["q"], y,
                                                                   self.K[0], hmax)

    def _error(self, h, y, y1):
        """Hairer's error norm (DOP853 combines its two estimates); NaN for an infinite
        stage."""
        s, plan, combine, K = self.run.s, self.plan, _V.combine, self.K
        e2 = plan.e2
        try:
            err, worst, err2 = _V.error_sums(
                s, y, y1, combine(None, 1.0 if e2 else h, plan.e, K),
                combine(None, 1.0, e2, K) if e2 else None)
        except (OverflowError, ValueError):  # an infinite stage: treated as NaN below
            return math.nan
        if err == err:
            self.worst = worst
        if _N == 0 or (self.run.fixed and err == err):
            return 0.0  # fixed steps: accepted as they are (a non-finite stage fails below)
        if e2:
            deno = err + 0.01 * err2
            if not deno > 0.0:
                deno = 1.0
            return abs(h) * err * math.sqrt(1.0 / (_N * deno))
        return math.sqrt(err / _N)

    def _retry(self, h, tph, y1, failure):
        """A failed attempt: a much smaller step (on fixed steps, the end of the run)."""
        run = self.run
        if run.fixed:
            if failure is not None:
                raise _block_failed(failure) from None
            raise _fail(tph, "state", STATES[max(_first_nonfinite(y1), 0)])
        if failure is not None:
            return _RETRY, None, h * self.m["fac_min"], (-2, "", failure)
        bad, bad_kind = _first_nonfinite(y1), "state"
        for i in range(1, self.stages):
            if bad >= 0:
                break
            if self.K[i] is not None:
                bad, bad_kind = _first_nonfinite(self.K[i]), "derivative of state"
        return _RETRY, None, h * self.m["fac_min"], (bad, bad_kind, None)

    def step(self, t, h, tph, y):
        run, m, K, c = self.run, self.m, self.K, self.c
        st, combine, fv = run.st, _V.combine, run.fv
        y = _V.vec(y)
        y1 = None
        try:
            for i in range(1, self.stages):
                if self.fsal and i == self.last_stage:
                    break
                ys = combine(y, h, self.plan.a[i], K)
                if i == self.stiff_i:
                    self.ystiff = ys
                self.ys = ys
                K[i] = fv(tph if c[i] == 1.0 else t + c[i] * h, ys)
                st["rhs"] += 1
            y1 = combine(y, h, self.plan.b, K)
            if self.fsal_first:
                st["rhs"] += 1
                K[self.last_stage] = fv(tph, y1)
        except _BlockFailure as failure:  # an algebraic block failed in a stage
            return self._retry(h, tph, y1, failure)
        err = self._error(h, y, y1)
        if err != err:  # a non-finite stage
            return self._retry(h, tph, y1, None)
        safe, fac_min, fac_max, beta = m["safe"], m["fac_min"], m["fac_max"], m["beta"]
        fac11 = err ** self.expo1
        fac = fac11 / self.facold ** beta
        fac = max(1.0 / fac_max, min(1.0 / fac_min, fac / safe))
        if err <= 1.0:
            self.facold = max(err, 1e-4)
            self.t, self.h, self.y = t, h, y
            return _ACCEPT, y1, run.s.step if run.fixed else h / fac, None
        return _REJECT, None, h / min(1.0 / fac_min, fac11 / safe), None

    def accepted(self, tph, y1):
        """The last stage f(t + h, y1) of an FSAL pair whose estimate does not use it."""
        if self.fsal and not self.fsal_first:
            self.run.st["rhs"] += 1
            try:
                self.K[self.last_stage] = self.run.fv(tph, y1)
            except _BlockFailure as failure:
                raise _block_failed(failure) from None

    def dense(self):
        """The dense output: the extra stages, then y(theta) = y + theta (q_0 + theta (q_1 +
        ...)), q_d = h sum_i P[i][d] K_i."""
        run, t, h, y, K = self.run, self.t, self.h, self.y, self.K
        c, combine = self.c, _V.combine
        try:
            for i in range(self.stages, len(c)):
                K[i] = run.fv(t + c[i] * h, combine(y, h, self.plan.a[i], K))
                run.st["rhs"] += 1
        except _BlockFailure as failure:
            raise _block_failed(failure) from None
        q = [combine(None, h, pairs, K) for pairs in self.plan.P]
        horner = _V.horner
        return lambda theta: horner(y, q, theta)

    def after(self, tph, y1, last):
        """Hairer's stiffness test, h |f(Y_i) - f(Y_j)| / |Y_i - Y_j| for two stages at the
        same time; then f at the new point (the FSAL stage, or evaluated)."""
        run, K = self.run, self.K
        if run.detect_stiffness and self.stiff_i >= 0 and self.ystiff is not None:
            num = _V.distance2(K[self.stiff_j], K[self.stiff_i])
            den = _V.distance2(y1 if self.stiff_j == self.last_stage else self.ys, self.ystiff)
            if den > 0.0 and self.h * math.sqrt(num / den) > self.stiff_bound:
                self.nonstiff_count = 0
                self.stiff_count += 1
                if self.stiff_count == 15:
                    return True
            else:
                self.nonstiff_count += 1
                if self.nonstiff_count == 6:
                    self.stiff_count = 0
        try:
            if self.fsal:
                K[0] = K[self.last_stage]
            elif not last:
                run.st["rhs"] += 1
                K[0] = run.fv(tph, y1)
        except _BlockFailure as failure:
            raise _block_failed(failure) from None
        return False


# ---------------------------------------------------------------- integrate


def _run_solver(run, name):
    """Runs solver `name` from (run.t, run.y) with the driver."""
    m = _METHODS[name]
    family = {"fixed": _FixedSteps, "erk": _Erk, "rosenbrock": _Rosenbrock,
              "radau": _Radau}.get(m["family"])
    if family is None:
        raise ValueError("solver '%s' cannot run by itself" % name)
    run.m, run.name = m, name
    run.fixed = run.s.step > 0.0 or m["family"] == "fixed"
    y = run.y if family in (_FixedSteps, _Erk) else numpy.asarray(run.y, dtype=float)
    yield from _drive(run, family, y)


def _integrate(s, p, x0, st):
    """Runs the solver: yields the rows (t, outputs) as it computes them; st["cpu"]: the
    processor seconds it took (the consumer's time between rows excluded)."""
    cpu = 0.0
    rows = _integrate_from(s, p, x0, st)
    try:
        while True:
            start = time.process_time()
            try:
                row = next(rows)
            except StopIteration:
                return
            finally:
                cpu += time.process_time() - start
                st["cpu"] = cpu
            yield row
    finally:
        rows.close()


def _integrate_from(s, p, x0, st):
    y = numpy.array(x0, dtype=float)
    i = _first_nonfinite(y)
    if i >= 0:
        raise _fail(s.t0, "state", STATES[i])
    run = _Run(s, p, _Work(s.rtol, s.atol), st, y)
    st["h_next"], st["order_next"] = 0.0, 0
    yield from run.emit(s.t0, y)
    m = _METHODS[s.solver]
    if m["family"] != "auto":
        yield from _run_solver(run, s.solver)
        return
    run.detect_stiffness = True
    try:
        yield from _run_solver(run, m["explicit"])
    except _Stiff:
        st["switched"], st["t_switch"] = True, run.t
        run.detect_stiffness = False
        yield from _run_solver(run, m["stiff"])
