# bgc/runtime/erk.py -- a part of the Python runtime (runtime.py's header says how the parts
# make one module); its C twin is erk.c: the explicit Runge-Kutta families, the fixed-step
# methods (_FixedSteps) and the embedded pairs (_Erk), with the vectors their states are kept
# in (_ListVectors, _ArrayVectors) and their tableaus' plans (_ErkPlan).

# ==================================================================== erk ===
# The explicit Runge-Kutta families, read from _METHODS (printed from bgc/solvers.py), as
# erk.c's: the fixed-step methods and the embedded pairs.  An explicit step's cost beside the
# model's right side is a few vector operations per stage.  On a handful of states a numpy
# call costs more than a list comprehension over the whole vector, so the explicit solvers
# keep their states as lists up to _LIST_STATES states and as numpy vectors above; both kits
# compute the same values in the same order as the C runtime (bgc_combine: stage by stage,
# left to right).

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
        None), sk_i = atol + rtol * max(|y_i|, |y1_i|), over the states the error control
        weighs."""
        rtol, atol = s.rtol, s.atol
        err = err2 = 0.0
        worst, worst_q = -1, -1.0
        for i in range(_error_states(s)):
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
        E = _error_states(s)
        sk = _weights(s, y[:E], y1[:E])
        with numpy.errstate(all="ignore"):
            sq = e1[:E] / sk
            sq = sq * sq
            err = _seq_sum(sq)
            q2 = e2[:E] / sk if e2 is not None else None
            err2 = _seq_sum(q2 * q2) if e2 is not None else 0.0
        return err, _worst(sq), err2

    @staticmethod
    def distance2(u, v):
        with numpy.errstate(all="ignore"):
            d = u - v
            return _seq_sum(d * d)


_V = _ListVectors  # the vectors for _N states: lists up to _LIST_STATES (_bind_model)


def _erk_plan(m):
    """The method's _ErkPlan, made once (a run restarts its method at every event)."""
    plan = _ERK_PLANS.get(id(m))
    if plan is None or plan[0] is not m:
        plan = _ERK_PLANS[id(m)] = (m, _ErkPlan(m))
    return plan[1]


_ERK_PLANS = {}


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


# ---------------------------------------------------------------- the families


class _FixedSteps(_Family):
    """The fixed-step methods: each step from f(t, y) afresh (no error estimate, no dense
    output: the driver lands a step on every output time)."""

    span_grid = False

    def __init__(self, run):
        m = run.m
        self.run, self.stages, self.c = run, m["stages"], m["c"]
        self.plan = _erk_plan(m)

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
        self.run, self.m, self.plan = run, m, _erk_plan(m)
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
        return None if run.fixed else _first_step(run, y, self.K[0])

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
            return abs(h) * err * math.sqrt(1.0 / (_error_states(s) * deno))
        return math.sqrt(err / _error_states(s))

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
