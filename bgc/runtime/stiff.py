# ================================================================== stiff ===
# The stiff families: Rosenbrock methods in Hairer's transformed form (RODAS's design, any
# tableau of the family) and Radau IIA of order 5 (RADAU5's design), as bgc_run_rosenbrock and
# bgc_run_radau5 in the C runtime (see there).  Linear algebra: whether an iteration matrix is
# singular is decided as the C runtime decides it (its LU factorisation with partial
# pivoting, done here row-vectorised in the same operations: an exactly zero pivot column is
# singular), so both backends stop on the same matrices; a matrix that is not is inverted
# once per factorisation with numpy.linalg.inv and every solve is a matrix-vector product with
# the inverse.  The results agree with C's within rounding, not bit for bit.


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


def _radau_poly(c1, c2, z1, z2, z3):
    """The collocation polynomial through (0, 0), (c1, Z1), (c2, Z2), (1, Z3) in Newton's form:
    u(theta) = theta (b1 + (theta - c1) (b2 + (theta - c2) b3))."""
    d01 = z1 / c1
    d12 = (z2 - z1) / (c2 - c1)
    d23 = (z3 - z2) / (1.0 - c2)
    d012 = (d12 - d01) / c2
    d123 = (d23 - d12) / (1.0 - c1)
    return d01, d012, d123 - d012


def _radau_u(c1, c2, b, theta):
    return theta * (b[0] + (theta - c1) * (b[1] + (theta - c2) * b[2]))


def _run_radau5(run, m, y):
    """Radau IIA of order 5 after Hairer's RADAU5 (see bgc_run_radau5 in the C runtime)."""
    s, st = run.s, run.st
    if run.kout > run.nout:
        return
    name = _method_name(m)
    rd = m["radau"]
    c1, c2, gamma, alpha, beta = rd["c1"], rd["c2"], rd["gamma"], rd["alpha"], rd["beta"]
    T, Ti, ew = numpy.array(rd["T"]), numpy.array(rd["Ti"]), rd["e"]
    safe, fac_min, fac_max = m["safe"], m["fac_min"], m["fac_max"]
    expo = 1.0 / m["q"]
    nit, thet = 7, 0.001
    fixed = s.step > 0.0
    hmax = s.t_end - s.t0
    # Hairer's tolerances for RADAU5 and its Newton tolerance
    rtol = 0.1 * s.rtol ** (2.0 / 3.0)
    atol = rtol * (s.atol / s.rtol)
    fnewt = max(10.0 * _EPS / rtol, min(0.03, math.sqrt(rtol)))
    cfac = safe * (1 + 2 * nit)
    t_start = t = run.t
    h, hfact, hold, hacc, erracc = 0.0, 0.0, 0.0, 0.0, 1.0
    faccon, theta, thqold, dynold, hhfac = 1.0, thet, 1.0, 1.0, 0.5
    reject = last = caljac = False
    first = needjac = True
    accepted, nsing, k_fixed, n_fixed, newt = 0, 0, 0, 0, 0
    worst, bad, bad_kind, block_failure = -1, -1, "", None
    identity = numpy.eye(_N)
    J = E1inv = E2inv = None
    b = (numpy.zeros(_N),) * 3
    zlast = numpy.zeros(_N)
    if fixed:
        n_fixed = _substeps(s.t_end - t_start, s.step)
        if n_fixed < 0:
            raise _fail_step(t, s.step, -1)
    f0 = _stiff_start(run, t, y)
    scal = atol + rtol * numpy.abs(y)
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
        fac1, alphn, betan = gamma / h, alpha / h, beta / h

        # gamma/h I - J and (alpha + i beta)/h I - J, inverted (unless they are h's already)
        refactored = h != hfact
        if h != hfact:
            st["lu"] += 1
            E1inv = _stiff_inverse(identity * fac1 - J)
            E2inv = None
            if E1inv is not None:
                st["lu"] += 1
                E2inv = _stiff_inverse(identity * complex(alphn, betan) - J)
            if E2inv is None:
                hfact = 0.0
                nsing += 1
                if fixed or nsing == 5:
                    raise _stiff_fail_singular(name, t, h)
                bad, h, reject, last = -3, h * 0.5, True, False
                st["rejected"] += 1
                needjac = not caljac
                continue
            hfact = h

        # starting values: the last step's collocation polynomial, extrapolated
        if first:
            Z = numpy.zeros((3, _N))
        else:
            q = h / hold
            Z = numpy.array([_radau_u(c1, c2, b, 1.0 + c1 * q) - zlast,
                             _radau_u(c1, c2, b, 1.0 + c2 * q) - zlast,
                             _radau_u(c1, c2, b, 1.0 + q) - zlast])
        W = Ti @ Z

        # the simplified Newton iteration
        newt, failed = 0, 0
        faccon = max(faccon, _EPS) ** 0.8
        theta = thet
        while True:
            if newt >= nit:
                failed = 2
                break
            F = numpy.empty((3, _N))
            try:
                for i, ti in enumerate((t + c1 * h, t + c2 * h, tph)):
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
                g1 = G[0] - fac1 * W[0]
                g2 = G[1] - (alphn * W[1] - betan * W[2])
                g3 = G[2] - (betan * W[1] + alphn * W[2])
                dw1 = E1inv @ g1
                dwc = E2inv @ (g2 + 1j * g3)
                dW = numpy.array([dw1, dwc.real, dwc.imag])
                st["solves"] += 2
                newt += 1
                dyno = math.sqrt(float(numpy.sum((dW / scal) ** 2)) / (3 * _N)) if _N else 0.0
            if dyno != dyno or dyno == math.inf:
                failed = 2
                break
            if 1 < newt < nit:
                thq = dyno / dynold
                theta = thq if newt == 2 else math.sqrt(thq * thqold)
                thqold = thq
                if theta < 0.99:
                    faccon = theta / (1.0 - theta)
                    dyth = faccon * dyno * theta ** (nit - 1 - newt) / fnewt
                    if dyth >= 1.0 and not fixed:  # too slow: a smaller step converges sooner
                        qnewt = max(1e-4, min(20.0, dyth))
                        hhfac = 0.8 * qnewt ** (-1.0 / (4.0 + nit - 1 - newt))
                        failed = 3
                        break
                else:
                    failed = 2
                    break
            dynold = max(dyno, _EPS)
            W = W + dW
            Z = T @ W
            # converged; after one iteration only on the previous step's matrices
            if (newt > 1 or not refactored) and faccon * dyno <= fnewt:
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
            h *= hhfac if failed == 3 else 0.5
            reject, last = True, False
            st["rejected"] += 1
            needjac = not caljac
            continue

        # the error estimate
        err = 0.0
        if not fixed:
            with numpy.errstate(all="ignore"):
                f2 = (ew[0] * Z[0] + ew[1] * Z[1] + ew[2] * Z[2]) / h
                cont = E1inv @ (f2 + f0)
                st["solves"] += 1
                wt = atol + rtol * numpy.maximum(numpy.abs(y), numpy.abs(y + Z[2]))
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
                bad = -1
                h, reject, last = h * 0.5, True, False
                st["rejected"] += 1
                needjac = not caljac
                continue

        # step control: Gustafsson's, the safety factor scaled by the Newton iterations
        fac = min(safe, cfac / (newt + 2 * nit))
        quot = max(1.0 / fac_max, min(1.0 / fac_min, err ** expo / fac))
        hnew = h / quot
        if err < 1.0:
            first = False
            accepted += 1
            if accepted > 1:
                facgus = (hacc / h) * (err * err / erracc) ** expo / fac
                facgus = max(1.0 / fac_max, min(1.0 / fac_min, facgus))
                quot = max(quot, facgus)
                hnew = h / quot
            hacc, erracc = h, max(1e-2, err)
            y1 = y + Z[2]
            i = _first_nonfinite(y1)
            if i >= 0:
                raise _fail(tph, "state", STATES[i])
            b = _radau_poly(c1, c2, Z[0], Z[1], Z[2])
            zlast, hold = Z[2], h
            _accept(run, tph)
            yield from run.emit_step(t, h, tph, y1, _radau_dense(y, c1, c2, b))
            y, t = y1, tph
            run.t, run.y = t, y
            nsing, bad, caljac = 0, -1, False
            if last:
                return
            scal = atol + rtol * numpy.abs(y)
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
                hnew = h  # keep h and the factorisations
            needjac = theta > thet
            h = hnew
        else:
            reject, last = True, False
            st["rejected"] += 1
            h = 0.1 * h if first else hnew
            needjac = not caljac


def _radau_dense(y, c1, c2, b):
    def prepare():
        return lambda theta: y + _radau_u(c1, c2, b, theta)
    return prepare
