# bgc/runtime/erk.py -- a part of the Python runtime (runtime.py's header says how the parts
# make one module); its C twin is erk.c: the explicit Runge-Kutta families, the fixed-step
# methods (_FixedSteps) and the embedded pairs (_Erk).  After them, the run of a solver
# (_run_solver, _integrate: drive.c's bgc_run_solver, bgc_integrate in C): the parts keep the
# order of the one file they were cut from.

# ---------------------------------------------------------------- explicit Runge-Kutta


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


def _integrate_from(s, p, x0, st, w=None):
    y = numpy.array(x0, dtype=float)
    i = _first_nonfinite(y)
    if i >= 0:
        raise _fail(s.t0, "state", STATES[i])
    run = _Run(s, p, _Work(s.rtol, s.atol) if w is None else w, st, y)
    run.w.inputs = s.inputs
    st["h_next"], st["order_next"] = 0.0, 0
    if _DISCRETE_NAMES:  # the event iteration at the start (bgc_integrate)
        w = run.w
        p[run.doff:] = w.d
        x = y.tolist()
        _event_iteration(run, s.t0, x, not w.started)
        w.started = True
        _set_next_time(run, s.t0, x)
        y = run.y = numpy.array(x, dtype=float)
    try:
        yield from _integrate_run(run, s, y, st)
    finally:
        if _DISCRETE_NAMES:
            run.w.d = p[run.doff:]


def _integrate_run(run, s, y, st):
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
