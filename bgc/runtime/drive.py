# bgc/runtime/drive.py -- a part of the Python runtime (runtime.py's header says how the parts
# make one module); its C twin is drive.c: the run (_Run) and its output times, the dense output
# (_Dense), the events, the error weights and the first step, the step driver (_drive), the
# family type (_Family) and the run of a solver (_run_solver, _integrate).

# ================================================================== drive ===
# The step driver (_drive, as bgc_drive in the C runtime's drive.c; the contract between the
# driver and a method family is _Family's docstring) and the run of a solver (_integrate); the
# families follow (erk.py, stiff.py).  The arithmetic is the C runtime's, in the same order.

def _output_count(s):
    """As bgc_output_count: at least 1 when t_end > t0, so that t0 and t_end are rows whatever
    dt; 0 when they are the same time (one row)."""
    n = math.ceil((s.t_end - s.t0) / s.dt - 1e-6)
    return n if n > 1 else 1 if s.t_end > s.t0 else 0


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
        raise _Failure("at t = %.17g: step budget spent: %d steps since the %s at t = %.17g "
                       "(the step size runs away; --max-steps raises the budget)"
                       % (t, run.s.max_steps, "event" if run.from_event else "output",
                          run.t_out), t)


def _block_failed(failure):
    return _Failure(str(failure), failure.t)


def _new_stats():
    return {"steps": 0, "rejected": 0, "rhs": 0, "jac": 0, "lu": 0, "solves": 0,
            "switched": False, "t_switch": 0.0, "cpu": 0.0, "h_next": 0.0, "order_next": 0,
            "events": 0, "locate_evals": 0}


def _stats_line(st):
    line = ("stats: steps=%(steps)d rejected=%(rejected)d rhs=%(rhs)d jac=%(jac)d lu=%(lu)d "
            "solves=%(solves)d" % st)
    if st["switched"]:
        line += " stiff_from=%.17g" % st["t_switch"]
    if _DISCRETE_NAMES:
        line += " events=%d locate=%d" % (st["events"], st["locate_evals"])
    return line + " cpu=%.6e" % st["cpu"]


class _Stiff(Exception):
    """An auto run's explicit phase found the problem stiff."""


class _Run:
    """A run in progress (see bgc_run in the C runtime): a run function is a generator that
    integrates from (run.t, y) to s.t_end, yields the rows (t, outputs) of the output times
    run.kout .. run.nout as it passes them, keeps run.t and run.y at its last accepted step,
    and returns; or raises _Failure, _Stiff (run.h: its last step size)."""

    __slots__ = ("s", "p", "w", "st", "nout", "kout", "t", "h", "y", "detect_stiffness",
                 "steps_out", "t_out", "from_event", "m", "name", "fixed", "doff", "g", "t_next",
                 "t_event", "chain", "kout_ev", "events_out", "sliding", "passes", "last",
                 "chain_from", "sliding_from", "out_from", "band", "gmax")

    def __init__(self, s, p, w, st, y):
        self.s, self.p, self.w, self.st = s, p, w, st
        self.steps_out, self.t_out = st["steps"], s.t0  # the steps at the last output, its t
        self.from_event = False  # (or at the last event: the step budget counts from either)
        self.nout, self.kout = _output_count(s), 1
        self.t, self.h, self.y = s.t0, s.h0, y
        self.detect_stiffness = False
        self.m, self.name, self.fixed = None, "", False  # the method running, see _run_solver
        # events (bgc_run's): d at p[doff:], the indicators at run.t, the next time event,
        # the last event's time and the events in a row closer than the resolution
        self.doff = len(p) - len(_DISCRETE_NAMES)
        # per state relation: its hysteresis band (0: none) and its indicator's largest
        # magnitude so far (bgc_run's band, gmax; _relation), kept in the workspace
        self.band, self.gmax = w.band, w.gmax
        self.g = []
        self.t_next, self.t_event, self.chain = math.inf, -math.inf, 0
        # the events since an output row (kout_ev: run.kout then) are bounded as steps are
        self.kout_ev, self.events_out = 0, 0
        self.sliding = 0  # accepted steps in a row, each ended at a located (state) event
        # what keeps changing, for the chattering messages: the event iteration's passes so
        # far, the pass that last changed each discrete value (-1: none yet), and the passes
        # where the chains the driver bounds began (events in a row, steps cut short, events
        # since an output row)
        self.passes = 0
        self.last = [-1] * len(_DISCRETE_NAMES)
        self.chain_from = self.sliding_from = self.out_from = 0

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
        self.steps_out, self.t_out, self.from_event = self.st["steps"], t, False
        yield t, y

    def emit_step(self, c, until, inclusive=True):
        """The output times in (c.t, until] (until excluded if not inclusive) after an
        accepted step: c.tph from c.y1, the others from the dense output (bgc_emit_step)."""
        while self.kout <= self.nout:
            tk = _output_time(self.s, self.kout, self.nout)
            if tk > until or (tk == until and not inclusive):
                break
            yield from self.emit(tk, c.y1 if tk == c.tph else c.at(tk))
            self.kout += 1


class _Dense:
    """The state inside the step just accepted (bgc_dense): the family's dense output, or
    the cubic Hermite interpolant for a family without one (event location only)."""

    __slots__ = ("run", "dense", "t", "h", "tph", "y", "y1", "fn", "f0", "f1")

    def __init__(self, run, dense, t, h, tph, y, y1):
        self.run, self.dense, self.t, self.h, self.tph, self.y, self.y1 = \
            run, dense, t, h, tph, y, y1
        self.fn = self.f0 = self.f1 = None

    def at(self, tk):
        if tk == self.tph:
            return self.y1
        if self.dense is not None:
            if self.fn is None:
                self.fn = self.dense()
            return self.fn((tk - self.t) / self.h)
        run = self.run
        if self.f0 is None:
            run.st["rhs"] += 2
            try:
                self.f0 = _as_list(run.f(self.t, numpy.asarray(self.y, dtype=float)))
                self.f1 = _as_list(run.f(self.tph, numpy.asarray(self.y1, dtype=float)))
            except _BlockFailure as failure:
                raise _block_failed(failure) from None
        th, h = (tk - self.t) / self.h, self.h
        y, y1, f0, f1 = _as_list(self.y), _as_list(self.y1), self.f0, self.f1
        return [(1.0 - th) * y[i] + th * y1[i]
                + th * (th - 1.0) * ((1.0 - 2.0 * th) * (y1[i] - y[i]) + (th - 1.0) * h * f0[i]
                                     + th * h * f1[i]) for i in range(_N)]


def _as_list(v):
    return v.tolist() if isinstance(v, numpy.ndarray) else list(v)


# ---------------------------------------------------------------- events
# A model's events (docs/hybrid.md), as the C runtime's drive.c handles them: the indicators
# checked at the end of every accepted step, the first change of a state relation located on
# the dense output (Illinois), time events stepped onto, the event iteration at an event.

MAX_EVENT_ITERATIONS = 100  # events at one instant (passes that change something) allowed
NAMED_CHANGES = 6  # the discrete values a chattering message names, at most


def _holds(k, g):
    return g > 0.0 if _INDICATOR_STRICT[k] else g >= 0.0


# Hysteresis (docs/hybrid.md, "Knees"; drive.c's BGC_BAND_REL): a state relation that changed
# its value at an event keeps it until its indicator goes back beyond zero by more than its
# band: the larger of what the indicator changes by in the time's resolution along the
# derivative after the event (_bands) and BAND_REL times the largest magnitude the indicator
# has had in the run.
BAND_REL = 1e-12


def _level(run, k, g):
    """bgc_level: relation k's indicator g moved by its band (g itself without one)."""
    b = run.band[k]
    if b > 0.0:
        return g + b if run.p[run.doff + k] != 0.0 else g - b
    return g


def _relation(run, k, g):
    """bgc_relation: the value relation k takes at g (within its band, the one it has)."""
    if run.band[k] > 0.0:
        if run.p[run.doff + k] != 0.0:
            return _level(run, k, g) >= 0.0
        return _level(run, k, g) > 0.0
    return _holds(k, g)


def _seen(run, g):
    """bgc_seen: the indicators at an accepted point: their largest magnitudes, and the end
    of the band of a relation whose indicator is beyond it on the relation's own side."""
    p, off, band, gmax = run.p, run.doff, run.band, run.gmax
    for k in range(len(_INDICATOR_STRICT)):
        a = abs(g[k])
        if a > gmax[k]:
            gmax[k] = a
        b = band[k]
        if b > 0.0 and (g[k] > b if p[off + k] != 0.0 else g[k] < -b):
            band[k] = 0.0


def _changed(run, g):
    p, off = run.p, run.doff
    for k in range(len(_INDICATOR_STRICT)):
        if _relation(run, k, g[k]) != (p[off + k] != 0.0):
            return k
    return -1


def _indicators(run, t, x):
    g = [0.0] * len(_INDICATOR_STRICT)
    try:
        _events(t, _as_list(x), run.p, run.w, g)
    except _BlockFailure as failure:
        raise _block_failed(failure) from None
    for k, v in enumerate(g):
        if not math.isfinite(v):
            raise _fail(t, "event condition", _DISCRETE_NAMES[k])
    return g


def _set_next_time(run, t, x):
    run.t_next = math.inf
    if not _NUM_TIMERS:
        return
    tau = [0.0] * _NUM_TIMERS
    try:
        _next_time(t, _as_list(x), run.p, run.w, tau)
    except _BlockFailure as failure:
        raise _block_failed(failure) from None
    for v in tau:
        if v > t and v < run.t_next:
            run.t_next = v


def _log(run, t, what, change):
    if run.s.on_event is not None:
        run.s.on_event(t, what, change)


def _log_discrete(run, t, k, old, new, shown):
    """bgc_log_discrete: the event log's row of discrete value k changing from old to new;
    the input whose row this pass wrote last (its three values are consecutive: one row)."""
    kind, j = _DISCRETE_LOG[2 * k], _DISCRETE_LOG[2 * k + 1]
    if kind == _LOG_INPUT:
        if j != shown:
            _log(run, t, _INPUT_NAMES[j], "%.17g -> %.17g" % (_input_value(run.w, j, t, 0),
                                                             _input_value(run.w, j, t, 1)))
        return j
    if kind == _LOG_TABLE:
        T = _TABLES[j]
        _log(run, t, _DISCRETE_NAMES[k], "%.17g -> %.17g" % (_table_limit(T, t, old),
                                                            _table(T, t, new, 0)))
    else:
        _log(run, t, _DISCRETE_NAMES[k], "%.17g -> %.17g" % (old, new))
    return -1


def _chattering(run, t, head, since, tail):
    """bgc_chattering: the run's failure, naming every discrete value a pass since the pass
    `since` changed (conditions first, at most NAMED_CHANGES of them, then how many more)."""
    changing = [_DISCRETE_NAMES[k] for k, p in enumerate(run.last) if p >= since]
    named = ["'%s'" % n for n in changing[:NAMED_CHANGES]]
    if len(changing) > NAMED_CHANGES:
        named.append("%d more" % (len(changing) - NAMED_CHANGES))
    what = (", ".join(named[:-1]) + " and " + named[-1]) if len(named) > 1 else \
        (named[0] if named else "the state")
    verb = " keep changing: " if len(changing) > 1 else " keeps changing: "
    return _Failure("at t = %.17g: chattering: %s (%s%s%s)" % (t, head, what, verb, tail), t)


def _bands(run, t, x):
    """bgc_bands: the bands of the relations that changed in the last pass, at (t, x) after
    it: each at least what its indicator changes by over the time's resolution tau along the
    derivative there (x + tau f)."""
    f = [0.0] * _N
    try:
        _rhs(t, x, run.p, run.w, f)
    except _BlockFailure as failure:
        raise _block_failed(failure) from None
    tau = max(1e-12 * abs(t), _hmin(t))
    xt = [x[i] + tau * f[i] for i in range(_N)]
    g0 = _indicators(run, t, x)
    g1 = _indicators(run, t + tau, xt)
    band, last = run.band, run.last
    for k in range(len(_INDICATOR_STRICT)):
        if last[k] == run.passes:
            d = abs(g1[k] - g0[k])
            if d > band[k]:
                band[k] = d


def _jumps_after(run, t, x, dtau):
    """bgc_jumps_after: S -= f+ dtau/dp for each parameter, f+ the right side at (t, x)."""
    if not any(d != 0.0 for d in dtau):
        return
    f = [0.0] * _N
    try:
        _rhs(t, x, run.p, run.w, f)
    except _BlockFailure as failure:
        raise _block_failed(failure) from None
    n = _N // (1 + _NUM_JUMPS)
    for j in range(_NUM_JUMPS):
        for i in range(n):
            x[n + j * n + i] = x[n + j * n + i] - f[i] * dtau[j]


def _event_iteration(run, t, x, start):
    """bgc_event_iteration: update until nothing changes; x (a list) is updated; run.g the
    indicators there after it.  With the sensitivities' jumps (_NUM_JUMPS): S changes
    nothing else and is not logged; the first pass's dtau/dp goes back into the later ones,
    then _jumps_after."""
    G, p, off = len(_INDICATOR_STRICT), run.p, run.doff
    J, ND = _NUM_JUMPS, len(_DISCRETE_NAMES)
    n = _N // (1 + J)
    dtau = [0.0] * J
    changed, it = True, 0
    while changed:
        if it > MAX_EVENT_ITERATIONS:  # the last pass still changed something
            raise _chattering(run, t, "more than %d events at one instant, the event "
                              "iteration does not settle" % MAX_EVENT_ITERATIONS,
                              run.passes - 1, "a Zeno model?")
        g = _indicators(run, t, x)
        gmax = run.gmax
        for k in range(G):
            if abs(g[k]) > gmax[k]:
                gmax[k] = abs(g[k])
        r = [1.0 if _relation(run, k, g[k]) else 0.0 for k in range(G)]
        r.append(1.0 if start and it == 0 else 0.0)
        if J:
            r.append(1.0 if not start and it == 0 else 0.0)
            r += dtau
        out = [0.0] * (_N + ND + J)
        try:
            _update(t, x, p, run.w, r, out)
        except _BlockFailure as failure:
            raise _block_failed(failure) from None
        dtau = out[_N + ND:]
        if not all(math.isfinite(d) for d in dtau):
            raise _Failure("at t = %.17g: the event's time has no derivative (an event that "
                           "grazes: its indicator's rate along the motion is zero), so the "
                           "sensitivities cannot pass it" % t, t)
        changed = False
        for i in range(_N):
            if not math.isfinite(out[i]):
                raise _fail(t, "state after the event", STATES[i])
            if out[i] != x[i] and i >= n:
                x[i] = out[i]
            elif out[i] != x[i]:
                changed = True
                if not start and run.s.on_event is not None:
                    _log(run, t, STATES[i], "%.17g -> %.17g" % (x[i], out[i]))
                x[i] = out[i]
        shown = -1
        crossed = False
        for k in range(len(_DISCRETE_NAMES)):
            v = out[_N + k]
            if not math.isfinite(v):
                raise _fail(t, "discrete value", _DISCRETE_NAMES[k])
            if v != p[off + k]:
                changed = True
                run.last[k] = run.passes
                if k < G:  # a relation that changed: its band (none at the start)
                    run.band[k] = 0.0 if start and it == 0 else BAND_REL * run.gmax[k]
                    crossed = crossed or not (start and it == 0)
                if not start and run.s.on_event is not None:
                    shown = _log_discrete(run, t, k, p[off + k], v, shown)
                p[off + k] = v
        if crossed:
            _bands(run, t, x)
        it += 1
        run.passes += 1
    if J and not start:
        _jumps_after(run, t, x, dtau)
    _seen(run, g)
    run.g = g


def _margin(run, k, g):
    """bgc_margin: how far relation k's indicator g is from changing (negative: changed)."""
    level = _level(run, k, g)
    return level if run.p[run.doff + k] != 0.0 else -level


def _hidden(run, c, gb):
    """bgc_hidden: (tm, g there) where a relation that changes and changes back inside the
    step has changed (at the middle, then at the turn of the parabola through its margins at
    the start, the middle and the end), or None."""
    ta, h = c.t, c.tph - c.t
    best = 2.0
    tm = ta + 0.5 * h
    ga = run.g
    for probe in range(2):
        g = _indicators(run, tm, c.at(tm))
        run.st["locate_evals"] += 1
        if _changed(run, g) >= 0:
            return tm, g
        if probe == 1:
            break
        for k in range(len(g)):
            s0, sm = _margin(run, k, ga[k]), _margin(run, k, g[k])
            s1 = _margin(run, k, gb[k])
            a2 = 2.0 * (s0 - 2.0 * sm + s1)
            a1 = 4.0 * sm - 3.0 * s0 - s1
            if a2 > 0.0:
                s = -a1 / (2.0 * a2)
                if s > 0.0 and s < 1.0 and s0 + s * (a1 + s * a2) < 0.0 and s < best:
                    best = s
        if best >= 2.0:
            break
        tm = ta + best * h
    return None


def _find_event(run, c):
    """bgc_find_event: None, or (te, the state there: a list); run.sliding counted."""
    G = len(_INDICATOR_STRICT)
    due = c.tph >= run.t_next
    gb = _indicators(run, c.tph, c.y1) if G else []
    tb = c.tph
    if not G or _changed(run, gb) < 0:
        hidden = _hidden(run, c, gb) if G else None
        if hidden is None:
            run.sliding = 0
            if due:
                return c.tph, _as_list(c.y1)
            run.g = gb
            _seen(run, gb)
            return None
        tb, gb = hidden
    ga, ta, wa, wb, moved = list(run.g), c.t, 1.0, 1.0, 0
    p, off = run.p, run.doff
    h = c.tph - c.t  # the time's resolution is relative to the step too (an event near t = 0)
    probed = False
    for it in range(200):
        at = max(abs(ta), abs(tb))  # (1e-12 relative in t, the resolution relative to h too)
        scale = max(at, h)
        tol = max(1e-12 * at, max(4.0 * _EPS * scale, sys.float_info.min))
        if tb - ta <= tol:
            break
        frac = 1.0
        for k in range(G):
            if _relation(run, k, gb[k]) != (p[off + k] != 0.0):
                a, b = wa * _level(run, k, ga[k]), wb * _level(run, k, gb[k])
                d = a - b  # 0: C's quotient is inf or nan, refused below as q = 0.5 is
                q = a / d if d != 0.0 else 0.5
                if not (q >= 0.0 and q <= 1.0) or (q == 0.0 and probed):
                    q = 0.5
                if q < frac:
                    frac = q
        if it >= 100:
            frac = 0.5
        if frac == 0.0:  # an indicator exactly 0 at ta: probed once at the time's resolution,
            probed = True  # then bisected (where rounding holds it at 0, the secant stalls)
        tm = ta + frac * (tb - ta)
        tm = max(tm, ta + 0.5 * tol)
        tm = min(tm, tb - 0.5 * tol)
        gm = _indicators(run, tm, c.at(tm))
        run.st["locate_evals"] += 1
        if _changed(run, gm) >= 0:
            tb, gb, wb = tm, gm, 1.0
            wa = 0.5 * wa if moved > 0 else 1.0
            moved = 1
        else:
            ta, ga, wa = tm, gm, 1.0
            wb = 0.5 * wb if moved < 0 else 1.0
            moved = -1
    run.sliding += 1
    if run.sliding == 1:
        run.sliding_from = run.passes
    return tb, _as_list(c.at(tb))


def _after_event(run, t, x):
    """bgc_after_event: the event, the rows at t (its right limit; those within the time's
    resolution of t too)."""
    yield from _handle_event(run, t, x)
    while run.kout <= run.nout:
        tk = _output_time(run.s, run.kout, run.nout)
        if tk - t > _hmin(t):
            break
        yield from run.emit(tk, x)
        run.kout += 1
    run.t = t


def _handle_event(run, t, x):
    """bgc_handle_event: the rows at the event (--event-rows), its iteration, the next time
    event; a run whose events come closer than it resolves stops."""
    run.st["events"] += 1
    if run.kout != run.kout_ev:  # the first event since an output row
        run.kout_ev, run.events_out = run.kout, run.st["events"] - 1
        run.out_from = run.passes
    scale = max(abs(t), abs(run.t_event))
    # (the run's first event has none before it: t_event is -inf, and so is the scale)
    if math.isfinite(run.t_event) and t - run.t_event <= max(1e-12 * scale, _hmin(t)):
        run.chain += 1
    else:
        run.chain, run.chain_from = 0, run.passes
    run.t_event = t
    run.steps_out, run.t_out, run.from_event = run.st["steps"], t, True  # a new step budget
    if run.s.event_rows:
        yield from run.emit(t, x)
    _event_iteration(run, t, x, False)
    if run.chain >= MAX_EVENT_ITERATIONS:
        raise _chattering(run, t, "%d events in a row, each within 1e-12 relative of the one "
                          "before" % run.chain, run.chain_from,
                          "a Zeno model, the switching outruns the time's resolution")
    # every step cut short by a state event: at most a hundredth of the step budget in a row,
    # and at least 1000
    if run.s.max_steps > 0 and \
            run.sliding >= (run.s.max_steps // 100 if run.s.max_steps > 100000 else 1000):
        raise _chattering(run, t, "%d steps in a row, each cut short by an event" % run.sliding,
                          run.sliding_from, "a sliding mode or a Zeno model? --max-steps "
                          "raises the limit, a hundredth of it")
    # the events since the last output row: as many as the step budget, and at least 1000 (a
    # small step budget is for a step size that runs away, not for events)
    if run.s.max_steps > 0 and \
            run.st["events"] - run.events_out > max(run.s.max_steps, 1000):
        raise _chattering(run, t, "%d events since the last output row"
                          % (run.st["events"] - run.events_out - 1), run.out_from,
                          "a Zeno model? --max-steps raises the budget")
    if run.s.event_rows:
        yield from run.emit(t, x)
    _set_next_time(run, t, x)


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


def _error_states(s):
    """bgc_error_states: the states the error control weighs (s.error_states, or all)."""
    return s.error_states if 0 < s.error_states < _N else _N


def _weights(s, y, y1):
    """Hairer's error-norm weights atol + rtol * max(|y_i|, |y1_i|) (bgc_weight)."""
    return s.atol + s.rtol * _c_max(numpy.abs(y), numpy.abs(y1))


def _initial_step(run, q, y, f0, hmax):
    """Hairer's initial step size guess (HINIT) for a method of order q."""
    s = run.s
    y, f0 = numpy.asarray(y, dtype=float), numpy.asarray(f0, dtype=float)
    E = _error_states(s)
    sk = s.atol + s.rtol * numpy.abs(y[:E])
    with numpy.errstate(all="ignore"):  # IEEE as in C: an overflow gives inf, then h = 0
        qf, qy = f0[:E] / sk, y[:E] / sk
        dnf, dny = _seq_sum(qf * qf), _seq_sum(qy * qy)
        h = 1e-6 if (dnf <= 1e-10 or dny <= 1e-10) else math.sqrt(dny / dnf) * 0.01
    h = min(h, hmax)
    run.st["rhs"] += 1
    try:
        f1 = run.f(run.t + h, y + h * f0)
    except _BlockFailure:
        return h  # a block failed there: start small, the step control takes over
    with numpy.errstate(all="ignore"):
        d = (f1[:E] - f0[:E]) / (s.atol + s.rtol * numpy.abs(y[:E]))
        der2 = float(numpy.float64(math.sqrt(_seq_sum(d * d))) / numpy.float64(h))
    der12 = max(math.sqrt(dnf), abs(der2))  # a NaN der2 is ignored
    h1 = max(1e-6, h * 1e-3) if der12 <= 1e-15 else (0.01 / der12) ** (1.0 / q)
    if not h1 > 0.0:
        h1 = h * 1e-3
    return min(min(100.0 * h, h1), hmax)


def _substeps(span, h):
    r = span / h
    if not r < 1e15:
        return -1
    m = math.ceil(r - 1e-6)
    return 1 if m < 1 else m


# ---------------------------------------------------------------- the step driver
# The driver and the family type: a family is a subclass of _Family, whose docstring is the
# contract between them (both runtimes'); a step's outcomes, as drive.c's BGC_STEP_*:

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
        if 0.0 < s.hmax < self.step:  # --max-step bounds a fixed step too
            self.step = s.hmax
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


def _hmax(s):
    """bgc_hmax: the run's span, and --max-step if set."""
    span = s.t_end - s.t0
    return min(span, s.hmax) if s.hmax > 0.0 else span


def _drive(run, family, y):
    """One family's run from (run.t, y) to s.t_end: yields the rows as it passes them, keeps
    run.t and run.y at the last accepted step; raises _Failure, or _Stiff (run.h: the
    explicit phase's next step)."""
    s, st = run.s, run.st
    if run.kout > run.nout:
        return
    hmax = _hmax(s)
    events = bool(_DISCRETE_NAMES)
    fam = family(run)
    h = fam.start(y)
    t = run.t
    reject = last = False
    bad, bad_kind, failure, wanted = -1, "", None, 0.0
    grid = _Grid(run, fam.span_grid)
    at_event = False
    while True:
        if run.t_next - t <= _hmin(t):  # a time event closer than a step can be
            t, at_event = run.t_next, True
        if at_event:  # the event at (t, y); the method starts afresh after it
            at_event = False
            x = _as_list(y)
            yield from _after_event(run, t, x)
            y = x if isinstance(y, list) else numpy.array(x, dtype=float)
            run.y = y
            if t >= s.t_end or run.kout > run.nout:
                return
            run.h = 0.0
            fam = family(run)
            h = fam.start(y)
            grid.k = grid.n  # a new grid from the event
            reject = last = False
            bad = -1
            continue
        if run.fixed:
            tph, last = grid.next(t)
            if run.t_next < tph:  # a time event inside: the step ends on it
                tph, last = run.t_next, False
            h = tph - t
        else:
            if not h >= _hmin(t):
                raise _fail_small(run, t, h, bad, bad_kind, failure, fam.worst)
            wanted = h
            if run.t_next < s.t_end and t + 1.01 * h - run.t_next > 0.0:
                h = run.t_next - t  # onto the time event
                tph = run.t_next
            else:
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
        c = _Dense(run, fam.dense, t, h, tph, y, y1)
        if events:
            found = _find_event(run, c)
            if found is not None:  # the step ends at the event
                te, ye = found
                yield from run.emit_step(c, te, False)
                y = ye if isinstance(y, list) else numpy.array(ye, dtype=float)
                t, at_event = te, True
                continue
        yield from run.emit_step(c, tph)
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
    """A method family: the steps of one kind of method (_FixedSteps and _Erk in erk.py,
    _Rosenbrock and _Radau in stiff.py) as the step driver, _drive, takes them.  The family
    contract, written once for both runtimes, in the order the driver calls it (C's
    bgc_family in drive.c: start is items 1 and 2, step 3, accepted 5, prepare and dense 6,
    after 7, next_h 8, finish the end of 1; erk.c and stiff.c cite the items).  The driver
    owns the rest: output times, budgets, the checks of the accepted state, events, the
    switch of `auto`.

    1. family(run): the family's state for the method run.m (its row of _METHODS: tableau
       and step control, printed from bgc/solvers.py) on run's settings, with fixed steps
       when run.fixed (--step, or a fixed-step method).  A new one at the run's start and
       after every event (C: finish, then start), so a method restarts with no history.
    2. start(y) -> h: the evaluations the method needs at the first point (run.t, y) (f;
       Rosenbrock's f, df/dt and J; Radau's f and Newton weights) and the first step of an
       adaptive run: run.h bounded by _hmax when the run goes on from an earlier phase or
       run, else Hairer's estimate (_first_step, _initial_step); None on fixed steps.
    3. step(t, h, tph, y) -> (outcome, y1, hnew, why): one attempt from (t, y) over h to tph
       (t + h, but exactly the end or the time event on a step cut onto it).  _ACCEPT: y1
       is the new point, hnew the controller's next step; _REJECT: the error test failed,
       try hnew; _RETRY: the attempt failed (a non-finite value, an algebraic block, a
       singular iteration matrix, Newton's iteration), try hnew, and why = (bad, bad_kind,
       block failure) names the cause if the steps then fall below _hmin (bad >= 0 a
       non-finite component, bad_kind its kind; -1 the error test, -2 a block, -3 a
       singular matrix, -4 Newton); _AGAIN: the same step once more, not counted as
       rejected (Radau on a fixed step, with a fresh Jacobian).  The driver counts the
       attempt, checks y1 for non-finite values and hands on the accepted step.
    4. The error estimate is the family's, inside step: Hairer's RMS norm with the weights
       atol + rtol max(|y_i|, |y1_i|) over the first _error_states(s) states (_weights,
       _V.error_sums, _stiff_norm; DOP853 combines two estimates, Radau scales rtol and atol
       as RADAU5 does); the attribute worst (-1: none) keeps the component with the largest
       share of the last estimate, for the message when the steps become too small.  On
       fixed steps no error control: an attempt is accepted unless it fails, and a failure
       ends the run (Radau's Newton iteration first tries once more with a fresh Jacobian).
    5. accepted(tph, y1): after the driver has counted the step, before its outputs and the
       event search (an FSAL pair's last stage, when its error estimate does not use it).
    6. dense() -> at(theta): the state at t + theta h inside the step just accepted, made
       once, when an output time inside the step or the event search first needs it, valid
       until the next attempt (C: prepare, then dense).  A family without a dense output
       (dense None: the fixed-step methods) has a step end on every output time (span_grid
       False); the event search then uses the cubic Hermite interpolant (_Dense).
    7. after(tph, y1, last) -> bool: after the outputs, the evaluations at the new point that
       the next step starts from (f, or an FSAL pair's last stage; Rosenbrock's f, df/dt and
       J; Radau's f and weights), none after the run's last step; True when Hairer's
       stiffness test has fired on 15 accepted steps (an explicit pair under
       run.detect_stiffness: `auto`'s explicit phase), and the driver switches (_Stiff).
    8. next_h(h, hnew) -> h: the next step, from the controller's hnew once the driver has
       bounded it (by _hmax, and by h after a rejection); Radau keeps h, and its factored
       matrices, while hnew is at most 20 % more and Newton converged fast.
    9. A Jacobian only in the stiff families: J = d rhs / d x, the model's symbolic one
       (_stiff_jacobian: dense, or its structural values on a large sparse model, _JAC_LU),
       for Rosenbrock at every new point (items 2 and 7), for Radau at the first attempt,
       after a step whose Newton iteration contracted slowly and after a failed or rejected
       attempt unless J is fresh.  Their iteration matrices are factored by the runtime's
       own LU, C's operations in C's order (_lu, _zlu, _SparseMatrix: stiff.c's
       bgc_stiff_lu, bgc_stiff_zlu, the sparse LU of bgc_splu).
    10. Statistics: a family counts its own work in run.st as it goes: rhs for each f, jac,
       lu, solves, and order_next (Radau's order at the end); the driver counts steps,
       rejected, h_next, and the events and evaluations of the event search.
    11. Failures: an algebraic block's failure (_BlockFailure) in an adaptive attempt's stages
       is a _RETRY (item 3); on fixed steps, in the Jacobian, and in start, accepted, dense
       and after, it ends the run, as do a non-finite derivative at the first point and the
       fifth singular iteration matrix in a row: the family raises _Failure (_block_failed,
       _fail) with the C program's message (C: BGC_STEP_END or a nonzero return, the message
       in r->msg).
    12. span_grid (fixed steps only): True, the steps on one grid over the run and the
       outputs from the dense output; False, each output interval in steps that land on its
       end.

    The defaults below: span_grid True, worst -1, no dense output, accepted and after doing
    nothing, next_h taking hnew (C: NULL functions)."""

    span_grid = True
    worst = -1
    dense = None  # no output time falls inside a step of a family without a dense output

    def accepted(self, tph, y1):
        pass

    def after(self, tph, y1, last):
        return False

    def next_h(self, h, hnew):
        return hnew


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
