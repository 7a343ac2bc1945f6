# bgc/runtime/main.py -- a part of the Python runtime (runtime.py's header says how the parts
# make one module); its C twin is main.c: the entry points rows() and simulate() (a run's
# settings, initial state and rows, as main() and bgc_simulate in drive.c begin one), the CSV
# they write and the command line, main().

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
         project_initial=False, stats=None, max_steps=None, allow_inconsistent=False,
         max_step=None, event_rows=False, events=None, inputs=None, input=None,
         error_states=None):
    """Runs the model, yielding each output row (t, y) as it is computed (y a list ordered as
    OUTPUTS): memory does not grow with the run's length.  A failure raises SimulationError
    after the rows before it (its .times and .rows are then empty: they were yielded).
    stats: a dict that receives the solver's counters.  allow_inconsistent: start from
    initial values that violate the constraints, neither refused nor projected (the
    correctors pull them back); it excludes project_initial.  max_step: every solver's
    largest step (a fixed step longer is cut to it); event_rows: two rows at each event (its left and right limits); events: a
    list that receives (t, event, change) for every change at an event, or a file name that
    receives them as CSV (the program's --events).  inputs: {name: (t, values)}, the data of
    the model's inputs (interpolated linearly, held outside, each t a time event; an input
    without data keeps its default); input: a CSV file of such data, as --input reads it.
    error_states: the adaptive solvers' error control weighs the first error_states states
    only (the others follow the steps chosen for them); None or 0: all."""
    if project_initial and allow_inconsistent:
        raise ValueError("project_initial and allow_inconsistent exclude each other")
    log = None
    if events is None or isinstance(events, list):
        on_event = (lambda t, what, change: events.append((t, what, change))) \
            if events is not None else None
    else:  # a file name: the event log's CSV, as --events writes it
        log = open(events, "w", encoding="utf-8", newline="")
        log.write("t,event,change\n")
        on_event = _event_writer(log)
    s = _settings(t_end, dt, solver, rtol, atol, step, max_steps, max_step, event_rows,
                  on_event, _input_series(inputs, input), error_states)
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
    finally:
        if log is not None:
            log.close()


def simulate(t_end=None, dt=None, solver=None, rtol=None, atol=None, params=None, step=None,
             project_initial=False, out=None, max_steps=None, allow_inconsistent=False,
             max_step=None, event_rows=False, events=None, inputs=None, input=None,
             error_states=None):
    """Runs the model; returns (t, Y) with Y[k] the outputs at t[k].  None: the scene's value.
    out: a file name or a text file: the CSV is written there row by row as the run goes
    (header first, as the program writes it) and nothing is kept: returns the number of rows.
    max_step, event_rows, events, inputs, input, error_states: as rows()."""
    run = rows(t_end, dt, solver, rtol, atol, params, step, project_initial,
               max_steps=max_steps, allow_inconsistent=allow_inconsistent, max_step=max_step,
               event_rows=event_rows, events=events, inputs=inputs, input=input,
               error_states=error_states)
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
    "       [--max-step H] [--error-states N] [--event-rows] [--events FILE] [--input FILE]\n"
    "       [--batch FILE|- [--metric KIND:OUTPUT ...] [--trajectories DIR]]\n"
)
_WITH_VALUE = ("--t-end", "--dt", "--solver", "--rtol", "--atol", "--step", "--max-steps", "-p",
               "--max-step", "--events", "--input", "--error-states")
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
        "  --max-step H       every solver's largest step (default: no bound)",
        "  --error-states N   the error control weighs the first N states only (0: all)",
        "  --event-rows       two rows at each event: its left and right limits",
        "  --events FILE      the event log: t,event,change, a row per change",
        "  --input FILE       the inputs' data: CSV, a column t and one per input",
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
    elif name == "--max-step":
        options["max_step"] = _parse_number(name, value)
        if not options["max_step"] > 0.0:
            raise _UsageError("error: --max-step must be positive\n")
    elif name == "--events":
        options["events"] = value
    elif name == "--input":
        options.setdefault("input", []).append(value)
    elif name == "--max-steps":
        n = _parse_number(name, value)
        if not (0.0 <= n <= 1e15 and n == math.floor(n)):
            raise _UsageError(
                "error: --max-steps must be a whole number from 0 (no limit) to 1e15\n")
        options["max_steps"] = int(n)
    elif name == "--error-states":
        n = _parse_number(name, value)
        if not (0.0 <= n <= _N and n == math.floor(n)):
            raise _UsageError("error: --error-states must be a whole number from 0 (all) to "
                              "%d\n" % _N)
        options["error_states"] = int(n)
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
        if arg in ("--project-initial", "--allow-inconsistent", "--stats", "--progress",
                   "--event-rows"):
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


def _csv_field(text):
    if any(c in text for c in ',"\r\n'):
        return '"' + text.replace('"', '""') + '"'
    return text


def _event_writer(f):
    """The event log's rows (--events), as the C program writes them."""
    def write(t, what, change):
        f.write("%.17g,%s,%s\n" % (t, _csv_field(what), _csv_field(change)))
    return write


def _stop_on_signals():
    """SIGINT and SIGTERM stop the run at its next step, its rows written (as the C program
    does); the handlers they replace, to restore.  None outside the main thread."""
    replaced = []
    if threading.current_thread() is threading.main_thread():
        for sig in (signal.SIGINT, signal.SIGTERM):
            replaced.append((sig, signal.signal(sig, lambda number, frame: request_stop(number))))
    return replaced


def _die_with_parent():
    """Started by bgc (BGC_PARENT_PID in the environment: bgc's process id), the program dies
    with it instead of running on as an orphan when bgc is killed: a thread watches the parent
    and ends the process when it has gone (as bgc_die_with_parent in the C program).  Run by
    anything else, this does nothing."""
    try:
        parent = int(os.environ.get("BGC_PARENT_PID", ""))
    except ValueError:
        return

    def watch():
        while os.getppid() == parent:
            time.sleep(0.2)
        os.kill(os.getpid(), getattr(signal, "SIGKILL", signal.SIGTERM))

    threading.Thread(target=watch, daemon=True).start()


def _write_failed(error):
    """The CSV could not be written: the message bgc simulate reads ("cannot write the output:
    REASON"); what stdout still holds goes nowhere, so that leaving does not fail again."""
    sys.stderr.write("error: cannot write the output: %s\n" % (error.strerror or error))
    try:
        null = os.open(os.devnull, os.O_WRONLY)
        os.dup2(null, sys.stdout.fileno())
        os.close(null)
    except (OSError, ValueError, AttributeError):
        pass


def _progress_reporter(s):
    """--progress: a line "bgc-progress T T0 T_END" on stderr at the first row, then as the
    rows pass at most ten a second (bgc simulate draws them as a bar)."""
    last = [None]

    def report(t):
        now = time.monotonic()
        if last[0] is None or now - last[0] >= 0.1:
            last[0] = now
            sys.stderr.write("bgc-progress %.17g %.17g %.17g\n" % (t, s.t0, s.t_end))
            sys.stderr.flush()
    return report


def main(argv=None):
    """The command line; returns the exit status."""
    argv = sys.argv[1:] if argv is None else list(argv)
    _die_with_parent()
    if any(a == "--batch" or a.startswith("--batch=") for a in argv):
        return _batch_main(argv)  # (batch mode, at the end)
    try:
        parsed = _parse_args(argv)
    except _UsageError as error:
        sys.stderr.write(str(error))
        return 2
    if parsed is None:
        return 0
    options, given, flags = parsed
    log_path = options.pop("events", None)
    input_path = options.pop("input", None)
    try:
        s = _settings(event_rows="--event-rows" in flags, **options)
        s.inputs = _input_series(None, input_path) if input_path is not None else None
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
    log = None
    if log_path is not None:
        try:
            log = open(log_path, "w", encoding="utf-8", newline="")
        except OSError as error:
            sys.stderr.write("error: cannot write the event log '%s': %s\n"
                             % (log_path, error.strerror or error))
            return 2
        log.write("t,event,change\n")
        s.on_event = _event_writer(log)
    stats = _new_stats()
    failure = lost = None
    out = sys.stdout
    handlers = _stop_on_signals()
    progress = _progress_reporter(s) if "--progress" in flags else None
    try:
        out.write(",".join(["t"] + OUTPUTS) + "\n")
        for t, y in _integrate(s, p, x0, stats):
            out.write(_row_text(t, y))
            if progress is not None:
                progress(t)
        out.flush()
    except _Failure as error:
        failure = error
    except OSError as error:  # the CSV cannot be written (a full disk, a closed pipe)
        lost = error
    finally:
        for sig, handler in handlers:
            signal.signal(sig, handler)
        request_stop(0)
        if log is not None:
            try:
                log.close()
            except OSError as error:
                lost = lost or error
    if failure is not None:
        try:
            out.flush()
        except OSError as error:
            lost = error
    if lost is not None:
        _write_failed(lost)
        return 3
    if "--stats" in flags:
        sys.stderr.write(_stats_line(stats) + "\n")
    if failure is not None:
        sys.stderr.write("error: %s\n" % failure)
        return 3
    return 0
