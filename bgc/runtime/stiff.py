# ================================================================== stiff ===
# The stiff families: Rosenbrock methods in Hairer's transformed form (RODAS's design, any
# tableau of the family) and Radau IIA with 3, 5 or 7 stages, of fixed or variable order
# (RADAU5's and RADAU's design), as bgc_run_rosenbrock and bgc_run_radau in the C runtime (see
# there).  Linear algebra: whether an iteration matrix is singular is decided as the C runtime
# decides it (its LU factorisation with partial pivoting, done here row-vectorised in the same
# operations: an exactly zero pivot column is singular), so both backends stop on the same
# matrices; a matrix that is not is inverted once per factorisation with numpy.linalg.inv and
# every solve is a matrix-vector product with the inverse.  The results agree with C's within
# rounding, not bit for bit.


def _stiff_norm(v, w):
    """sqrt(mean((v_i / w_i)^2)) (0 without states) and the component with the largest share."""
    if _N == 0:
        return 0.0, -1
    with numpy.errstate(all="ignore"):
        q = (v / w) ** 2
        total = float(numpy.sum(q))
    worst = int(numpy.argmax(q)) if total == total else -1
    return math.sqrt(total / _N), worst


def _stiff_fail_step(name, t, h, bad, bad_kind, worst, block_failure):
    """A step size below _hmin: the message names what made the steps shrink (bad: -2 a failed
    block, -3 a singular matrix, -4 Newton, >= 0 a non-finite component, else the error)."""
    if bad == -2:
        return _block_failed(block_failure)
    if bad == -3:
        return _Failure("at t = %.17g: %s: the iteration matrix is singular (step size down to "
                        "h = %.3g)" % (t, name, h), t)
    if bad == -4:
        return _Failure("at t = %.17g: %s: the Newton iteration does not converge (step size "
                        "down to h = %.3g)" % (t, name, h), t)
    if bad >= 0:
        return _fail(t, bad_kind, STATES[bad])
    return _fail_step(t, h, worst)


def _stiff_fail_singular(name, t, h):
    return _Failure("at t = %.17g: %s: the iteration matrix is singular (h = %.3g)"
                    % (t, name, h), t)


def _stiff_singular(E):
    """Whether bgc_stiff_lu (bgc_stiff_zlu for a complex E) finds a column without a nonzero
    pivot: the same pivots (the first largest |a_ik|, |re| + |im| for complex), the same
    eliminations (rows whose multiplier is zero left alone)."""
    a = numpy.array(E)
    n = a.shape[0]
    size = (lambda v: numpy.abs(v.real) + numpy.abs(v.imag)) if a.dtype.kind == "c" \
        else numpy.abs
    with numpy.errstate(all="ignore"):
        for k in range(n):
            column = size(a[k:, k])
            # C's scan: from |a_kk|, the first entry larger than the largest so far (a NaN
            # is never larger, and a NaN |a_kk| stays)
            p = k
            if column[0] == column[0] and len(column) > 1:
                rest = numpy.where(column[1:] == column[1:], column[1:], -1.0)
                if rest.max() > column[0]:
                    p = k + 1 + int(numpy.argmax(rest))
            if column[p - k] == 0.0:
                return True
            if p != k:
                a[[k, p]] = a[[p, k]]
            lower = a[k + 1:, k] / a[k, k]
            rows = numpy.nonzero(lower != 0.0)[0] + k + 1
            if len(rows):
                a[rows, k + 1:] -= lower[rows - k - 1, None] * a[k, k + 1:]
    return False


def _stiff_inverse(E):
    """E^-1, or None if E is singular (as the C runtime's factorisation finds it)."""
    if _stiff_singular(E):
        return None
    try:
        with numpy.errstate(all="ignore"):
            return numpy.linalg.inv(E)
    except numpy.linalg.LinAlgError:
        return None


def _method_name(m):
    """The solver's name for messages (m is one of _METHODS' entries)."""
    return next(name for name, entry in _METHODS.items() if entry is m)


def _stiff_grid(s, t_start, k, n):
    """Fixed steps: the grid t_start + k * step, the last step ending on t_end."""
    return s.t_end if k >= n else t_start + k * s.step


def _stiff_jacobian(run, t, y):
    J = numpy.zeros((_N, _N))
    run.st["jac"] += 1
    try:
        _jacobian_into(t, y.tolist(), run.p, run.w, J)
    except _BlockFailure as failure:
        raise _block_failed(failure) from None
    return J


def _stiff_start(run, t, y):
    """f(t, y) at the start of a run or after an accepted step: a failure ends the run."""
    run.st["rhs"] += 1
    try:
        f0 = run.f(t, y)
    except _BlockFailure as failure:
        raise _block_failed(failure) from None
    i = _first_nonfinite(f0)
    if i >= 0:
        raise _fail(t, "derivative of state", STATES[i])
    return f0


# ---------------------------------------------------------------- Rosenbrock methods


def _run_rosenbrock(run, m, y):
    """Rosenbrock methods as Hairer's RODAS (see bgc_run_rosenbrock in the C runtime)."""
    s, st = run.s, run.st
    if run.kout > run.nout:
        return
    name = _method_name(m)
    stages, gamma = m["stages"], m["gamma"]
    c, d, a, C = m["c"], m["d"], m["a"], m["C"]
    mw, ew, H = m["m"], m["e"], m["H"]
    safe, fac_min, fac_max = m["safe"], m["fac_min"], m["fac_max"]
    expo = 1.0 / m["q"]
    fixed = s.step > 0.0
    hmax = s.t_end - s.t0
    t_start = t = run.t
    h, hacc, erracc = 0.0, 0.0, 1.0
    reject = last = False
    fresh, accepted, nsing, k_fixed, n_fixed = True, 0, 0, 0, 0
    worst, bad, bad_kind, block_failure = -1, -1, "", None
    identity = numpy.eye(_N)
    ft = numpy.zeros(_N)
    f0 = J = None
    if fixed:
        n_fixed = _substeps(s.t_end - t_start, s.step)
        if n_fixed < 0:
            raise _fail_step(t, s.step, -1)
    while True:
        if fresh:  # a new point: f, df/dt, J
            f0 = _stiff_start(run, t, y)
            if not _AUTONOMOUS:
                delta = math.sqrt(_EPS * max(1e-5, abs(t)))
                st["rhs"] += 1
                try:
                    ft = (run.f(t + delta, y) - f0) / delta
                except _BlockFailure as failure:
                    raise _block_failed(failure) from None
            J = _stiff_jacobian(run, t, y)
            if h == 0.0 and not fixed:
                h = min(run.h, hmax) if run.h > 0.0 else _initial_step(run, m["q"], y, f0, hmax)
            fresh = False
        if fixed:
            last = k_fixed + 1 >= n_fixed
            tph = _stiff_grid(s, t_start, k_fixed + 1, n_fixed)
            h = tph - t
            if not h >= _hmin(t):
                raise _fail_step(t, h, -1)
        else:
            if not h >= _hmin(t):
                raise _stiff_fail_step(name, t, h, bad, bad_kind, worst, block_failure)
            if t + 1.01 * h - s.t_end > 0.0:
                h = s.t_end - t
                last = True
            tph = s.t_end if last else t + h

        # E = I/(gamma h) - J, inverted
        st["lu"] += 1
        Einv = _stiff_inverse(identity * (1.0 / (gamma * h)) - J)
        if Einv is None:
            nsing += 1
            if fixed or nsing == 5:
                raise _stiff_fail_singular(name, t, h)
            bad, h, reject, last = -3, h * 0.5, True, False
            st["rejected"] += 1
            continue

        K = [None] * stages
        try:
            with numpy.errstate(all="ignore"):
                for i in range(stages):
                    if i == 0:
                        rhs = f0.copy()
                    else:
                        st["rhs"] += 1
                        rhs = run.f(tph if c[i] == 1.0 else t + c[i] * h, y + _combine(a[i], K, i))
                    rhs = rhs + _combine(C[i], K, i) / h
                    if not _AUTONOMOUS and d[i] != 0.0:
                        rhs = rhs + h * d[i] * ft
                    K[i] = Einv @ rhs
                    st["solves"] += 1
        except _BlockFailure as failure:  # an algebraic block failed in a stage
            if fixed:
                raise _block_failed(failure) from None
            bad, block_failure = -2, failure
            h, reject, last = h * 0.5, True, False
            st["rejected"] += 1
            continue

        with numpy.errstate(all="ignore"):
            y1 = y + _combine(mw, K, stages)
            err, worst_now = _stiff_norm(_combine(ew, K, stages), _weights(s, y, y1))
        worst = worst_now if worst_now >= 0 else worst
        i = _first_nonfinite(y1)
        if err != err or err == math.inf or i >= 0:
            if fixed:
                raise _fail(tph, "state", STATES[max(i, 0)])
            bad, bad_kind = i, "state"
            for j in range(1, stages):
                if bad >= 0:
                    break
                bad, bad_kind = _first_nonfinite(K[j]), "derivative of state"
            h, reject, last = h * 0.5, True, False
            st["rejected"] += 1
            continue
        if fixed:
            err = 0.0

        # Gustafsson's predictive controller (rodas.f)
        fac = max(1.0 / fac_max, min(1.0 / fac_min, err ** expo / safe))
        hnew = h / fac
        if err <= 1.0:
            if accepted > 0:
                facgus = (hacc / h) * (err * err / erracc) ** expo / safe
                facgus = max(1.0 / fac_max, min(1.0 / fac_min, facgus))
                fac = max(fac, facgus)
                hnew = h / fac
            hacc, erracc = h, max(1e-2, err)
            accepted += 1
            _accept(run, tph)
            yield from run.emit_step(t, h, tph, y1, _rosenbrock_dense(y, y1, K, H))
            y, t = y1, tph
            run.t, run.y = t, y
            fresh, nsing, bad = True, 0, -1
            if last:
                return
            k_fixed += 1
            hnew = min(hnew, hmax)
            if reject:
                hnew = min(hnew, h)
            reject = False
        else:
            reject, last = True, False
            st["rejected"] += 1
        h = hnew


def _rosenbrock_dense(y, y1, K, H):
    """y(theta) = (1 - theta) y0 + theta (y1 + (1 - theta) (q_1 + theta (q_2 + ... theta q_R)))."""
    def prepare():
        q = [_combine(row, K, len(K)) for row in H]

        def at(theta):
            s1 = 1.0 - theta
            acc = q[-1]
            for qr in q[-2::-1]:
                acc = qr + theta * acc
            return s1 * y + theta * (y1 + s1 * acc)
        return at
    return prepare


# ---------------------------------------------------------------- Radau IIA (RADAU5)


def _radau_poly(c, Z):
    """The collocation polynomial through (0, 0) and (c_i, Z_i) in Newton's form:
    u(theta) = theta (b_1 + (theta - c_1) (b_2 + ... + (theta - c_{s-1}) b_s)); b: s x N."""
    x = (0.0,) + tuple(c)
    d = [numpy.zeros(_N)] + [Z[i] for i in range(len(c))]
    s = len(c)
    with numpy.errstate(all="ignore"):
        for j in range(1, s + 1):  # divided differences, in place
            for k in range(s, j - 1, -1):
                d[k] = (d[k] - d[k - 1]) / (x[k] - x[k - j])
    return d[1:]


def _radau_u(c, b, theta):
    k = len(b) - 1
    acc = b[k]
    while k > 0:
        k -= 1
        acc = b[k] + (theta - c[k]) * acc
    return theta * acc


class _RadauUse:
    """What follows from a stage set (see bgc_radau_configure in the C runtime)."""

    def __init__(self, m, s, k):
        rd = m["radau"][k]
        self.ns, self.c, self.gamma = rd["s"], rd["c"], rd["gamma"]
        self.alpha, self.beta, self.e = rd["alpha"], rd["beta"], rd["e"]
        self.T, self.Ti = numpy.array(rd["T"]), numpy.array(rd["Ti"])
        self.pairs = (self.ns - 1) // 2
        self.nit = 7 + 5 * ((self.ns - 3) // 2)
        expm = (self.ns + 1) / (2.0 * self.ns)
        en = 1.0 / expm - 1.0
        self.rtol = 0.1 * s.rtol ** expm
        self.atol = self.rtol * (s.atol / s.rtol)
        self.fnewt = max(10.0 * _EPS / self.rtol,
                         min(0.03, math.sqrt(self.rtol) if en == 0.5 else self.rtol ** en))
        self.cfac = m["safe"] * (1 + 2 * self.nit)
        self.expo = 1.0 / (self.ns + 1)


def _run_radau(run, m, y):
    """Radau IIA after Hairer's RADAU5 and RADAU, fixed or variable order (see bgc_run_radau in
    the C runtime)."""
    s, st = run.s, run.st
    if run.kout > run.nout:
        return
    name = _method_name(m)
    safe, fac_min, fac_max = m["safe"], m["fac_min"], m["fac_max"]
    thet = 0.001
    fixed = s.step > 0.0
    nsets = len(m["radau"])
    variable = nsets > 1 and not fixed
    hmax = s.t_end - s.t0
    k_set, since, change, unexp, unexn, recheck = 0, 0, False, False, False, False
    u = _RadauUse(m, s, k_set)
    t_start = t = run.t
    h, hfact, hold, hacc, erracc = 0.0, 0.0, 0.0, 0.0, 1.0
    faccon, theta, thetat, thqold, dynold, hhfac = 1.0, thet, 0.0, 1.0, 1.0, 0.5
    reject = last = caljac = False
    first = needjac = True
    accepted, nsing, k_fixed, n_fixed, newt = 0, 0, 0, 0, 0
    worst, bad, bad_kind, block_failure = -1, -1, "", None
    identity = numpy.eye(_N)
    J = E1inv = None
    Ecinv = []
    b = [numpy.zeros(_N)] * u.ns
    zlast = numpy.zeros(_N)
    if fixed:
        n_fixed = _substeps(s.t_end - t_start, s.step)
        if n_fixed < 0:
            raise _fail_step(t, s.step, -1)
    f0 = _stiff_start(run, t, y)
    scal = u.atol + u.rtol * numpy.abs(y)
    if not fixed:
        h = min(run.h, hmax) if run.h > 0.0 else _initial_step(run, m["q"], y, f0, hmax)
    while True:
        if needjac:
            J = _stiff_jacobian(run, t, y)
            needjac, caljac, hfact = False, True, 0.0
        if fixed:
            last = k_fixed + 1 >= n_fixed
            tph = _stiff_grid(s, t_start, k_fixed + 1, n_fixed)
            h = tph - t
            if not h >= _hmin(t):
                raise _fail_step(t, h, -1)
        else:
            if not h >= _hmin(t):
                raise _stiff_fail_step(name, t, h, bad, bad_kind, worst, block_failure)
            if t + 1.01 * h - s.t_end > 0.0:
                h = s.t_end - t
                last = True
            tph = s.t_end if last else t + h

        # the order, whenever the matrices are to be factored (variable order only)
        if variable and (h != hfact or recheck):
            hquot = h / hold if hold > 0.0 else 0.0
            nxt = k_set
            since += 1
            thetat = min(10.0, max(theta, 0.5 * thetat))
            if (newt > 1 and thetat <= 0.002 and 0.8 < hquot < 1.2 and since > 10
                    and k_set + 1 < nsets):
                nxt = k_set + 1
            if (thetat >= 0.8 or unexp or unexn) and k_set > 0:
                nxt = k_set - 1
            unexp = unexn = recheck = False
            if nxt != k_set:
                k_set = nxt
                u = _RadauUse(m, s, k_set)
                since, change, hfact = 1, True, 0.0
                scal = u.atol + u.rtol * numpy.abs(y)
        c, T, Ti, ns = u.c, u.T, u.Ti, u.ns
        fac1 = u.gamma / h
        alphn = [a / h for a in u.alpha]
        betan = [bb / h for bb in u.beta]

        # gamma/h I - J and (alpha_k + i beta_k)/h I - J, inverted (unless they are h's)
        refactored = h != hfact
        if h != hfact:
            st["lu"] += 1
            E1inv = _stiff_inverse(identity * fac1 - J)
            Ecinv = []
            singular = E1inv is None
            for k in range(u.pairs):
                if singular:
                    break
                st["lu"] += 1
                inv = _stiff_inverse(identity * complex(alphn[k], betan[k]) - J)
                singular = inv is None
                Ecinv.append(inv)
            if singular:
                hfact = 0.0
                nsing += 1
                if fixed or nsing == 5:
                    raise _stiff_fail_singular(name, t, h)
                bad, unexp, h, reject, last = -3, True, h * 0.5, True, False
                st["rejected"] += 1
                needjac = not caljac
                continue
            hfact = h

        # starting values: the last step's collocation polynomial, extrapolated
        if first or change:
            Z = numpy.zeros((ns, _N))
        else:
            q = h / hold
            Z = numpy.array([_radau_u(c, b, 1.0 + c[i] * q) - zlast for i in range(ns)])
        W = Ti @ Z

        # the simplified Newton iteration
        newt, failed = 0, 0
        faccon = max(faccon, _EPS) ** 0.8
        theta = thet
        while True:
            if newt >= u.nit:
                failed = 2
                break
            F = numpy.empty((ns, _N))
            try:
                for i in range(ns):
                    ti = tph if i == ns - 1 else t + c[i] * h
                    st["rhs"] += 1
                    F[i] = run.f(ti, y + Z[i])
                    j = _first_nonfinite(F[i])
                    if j >= 0:
                        failed, bad, bad_kind = 1, j, "derivative of state"
                        break
            except _BlockFailure as failure:
                failed, bad, block_failure = 1, -2, failure
            if failed:
                break
            with numpy.errstate(all="ignore"):
                G = Ti @ F
                dW = numpy.empty((ns, _N))
                dW[0] = E1inv @ (G[0] - fac1 * W[0])
                for k in range(u.pairs):
                    w2, w3 = W[2 * k + 1], W[2 * k + 2]
                    g2 = G[2 * k + 1] - (alphn[k] * w2 - betan[k] * w3)
                    g3 = G[2 * k + 2] - (betan[k] * w2 + alphn[k] * w3)
                    dwc = Ecinv[k] @ (g2 + 1j * g3)
                    dW[2 * k + 1], dW[2 * k + 2] = dwc.real, dwc.imag
                st["solves"] += 1 + u.pairs
                newt += 1
                dyno = (math.sqrt(float(numpy.sum((dW / scal) ** 2)) / (ns * _N)) if _N
                        else 0.0)
            if dyno != dyno or dyno == math.inf:
                failed = 2
                break
            if 1 < newt < u.nit:
                thq = dyno / dynold
                theta = thq if newt == 2 else math.sqrt(thq * thqold)
                thqold = thq
                if theta < 0.99:
                    faccon = theta / (1.0 - theta)
                    dyth = faccon * dyno * theta ** (u.nit - 1 - newt) / u.fnewt
                    if dyth >= 1.0 and not fixed:  # too slow: a smaller step converges sooner
                        qnewt = max(1e-4, min(20.0, dyth))
                        hhfac = 0.8 * qnewt ** (-1.0 / (4.0 + u.nit - 1 - newt))
                        failed = 3
                        break
                else:
                    failed = 2
                    break
            dynold = max(dyno, _EPS)
            W = W + dW
            Z = T @ W
            # converged; after one iteration only on the previous step's matrices
            if (newt > 1 or not refactored) and faccon * dyno <= u.fnewt:
                break
        if failed:
            if fixed:
                if failed == 1:
                    if bad == -2:
                        raise _block_failed(block_failure)
                    raise _fail(t, bad_kind, STATES[bad])
                if not caljac:  # once more with a fresh Jacobian
                    needjac = True
                    continue
                raise _Failure("at t = %.17g: %s: the Newton iteration does not converge with "
                               "the fixed step h = %.3g" % (t, name, h), t)
            if failed != 1:
                bad = -4
            if failed == 3:
                unexn = hhfac <= 0.5
            else:
                unexp = True
            h *= hhfac if failed == 3 else 0.5
            reject, last = True, False
            st["rejected"] += 1
            needjac = not caljac
            continue

        # the error estimate
        err = 0.0
        if not fixed:
            with numpy.errstate(all="ignore"):
                f2 = sum(u.e[j] * Z[j] for j in range(ns)) / h
                cont = E1inv @ (f2 + f0)
                st["solves"] += 1
                wt = u.atol + u.rtol * numpy.maximum(numpy.abs(y), numpy.abs(y + Z[ns - 1]))
                err, worst_now = _stiff_norm(cont, wt)
                err = max(err, 1e-10)
                if err >= 1.0 and (first or reject):  # refined: f at y + err
                    st["rhs"] += 1
                    try:
                        f1 = run.f(t, y + cont)
                    except _BlockFailure:
                        f1 = None
                    if f1 is not None:
                        cont = E1inv @ (f1 + f2)
                        st["solves"] += 1
                        err, worst_now = _stiff_norm(cont, wt)
                        err = max(err, 1e-10)
            worst = worst_now if worst_now >= 0 else worst
            if err != err or err == math.inf:
                bad, unexp = -1, True
                h, reject, last = h * 0.5, True, False
                st["rejected"] += 1
                needjac = not caljac
                continue

        # step control: Gustafsson's, the safety factor scaled by the Newton iterations
        fac = min(safe, u.cfac / (newt + 2 * u.nit))
        quot = max(1.0 / fac_max, min(1.0 / fac_min, err ** u.expo / fac))
        hnew = h / quot
        if err < 1.0:
            first = False
            accepted += 1
            if accepted > 1 and not change:
                facgus = (hacc / h) * (err * err / erracc) ** u.expo / fac
                facgus = max(1.0 / fac_max, min(1.0 / fac_min, facgus))
                quot = max(quot, facgus)
                hnew = h / quot
            change = False
            hacc, erracc = h, max(1e-2, err)
            y1 = y + Z[ns - 1]
            i = _first_nonfinite(y1)
            if i >= 0:
                raise _fail(tph, "state", STATES[i])
            b = _radau_poly(c, Z)
            zlast, hold = Z[ns - 1], h
            _accept(run, tph)
            yield from run.emit_step(t, h, tph, y1, _radau_dense(y, c, b))
            y, t = y1, tph
            run.t, run.y = t, y
            nsing, bad, caljac = 0, -1, False
            if last:
                return
            scal = u.atol + u.rtol * numpy.abs(y)
            st["rhs"] += 1
            try:
                f0 = run.f(t, y)
            except _BlockFailure as failure:
                raise _block_failed(failure) from None
            k_fixed += 1
            hnew = min(hnew, hmax)
            if reject:
                hnew = min(hnew, h)
            reject = False
            if theta <= thet and 1.0 <= hnew / h <= 1.2:
                hnew = h  # keep h and the factorisations ...
                since += 1
                if variable and since >= 10 and k_set + 1 < nsets:
                    recheck = True  # ... but look at the order now and then
            needjac = theta > thet
            h = hnew
        else:
            reject, last = True, False
            st["rejected"] += 1
            h = 0.1 * h if first else hnew
            needjac = not caljac


def _radau_dense(y, c, b):
    def prepare():
        return lambda theta: y + _radau_u(c, b, theta)
    return prepare
