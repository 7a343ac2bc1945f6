# bgc/runtime/batch.py -- the Python runtime's last part (runtime.py's header says how the
# parts make one module); its C twin is batch.c: the batch mode, batch_rows(), batch() and the
# command line's --batch.  Last of all the binding, _bind_model() and its call, which read
# names of every part.

# ====================================================================== batch ===
# Batch mode, as the C program's (bgc/runtime/batch.c, which describes it): many runs in one
# process, each from the same state as a new process (fresh parameters, workspace, Newton
# starting values and counters), one result per run; a run that fails is a result too.

METRIC_KINDS = ("final", "max", "min", "maxabs", "rms")
BATCH_COLUMNS = ("run", "status", "steps", "rejected", "rhs", "cpu", "message")  # + metrics


class _LineError(Exception):
    pass


def _metric_spec(spec):
    """KIND:OUTPUT as (kind, output index); ValueError if it is not one."""
    kind, colon, output = spec.partition(":")
    if not colon or kind not in METRIC_KINDS:
        raise ValueError("--metric expects KIND:OUTPUT with KIND one of final, max, min, "
                         "maxabs, rms; got '%s'" % spec)
    if output not in OUTPUTS:
        raise ValueError("--metric %s: '%s' is not an output" % (spec, output))
    return kind, OUTPUTS.index(output)


def _line_overrides(run):
    """A run's parameters {index: value}: from a line of NAME=VALUE words, or a dict."""
    if isinstance(run, dict):
        words = [(str(k), v) for k, v in run.items()]
    else:
        text = run.replace("\t", " ").replace("\r", " ").replace("\n", " ")
        words = []
        for word in text.split(" "):
            if word:
                name, eq, value = word.partition("=")
                if not eq or not name:
                    raise _LineError("expected NAME=VALUE, got '%s'" % word[:200])
                words.append((name, value))
    given = {}
    for name, value in words:
        if name not in _PARAM_NAMES:
            raise _LineError("unknown parameter '%s'" % name[:200])
        if isinstance(value, str):
            try:
                value = _parse_number(name, value)
            except _UsageError:
                raise _LineError("invalid value for %s: '%s'" % (name, value[:200])) from None
        value = float(value)
        if not math.isfinite(value):
            raise _LineError("invalid value for %s: '%r'" % (name, value))
        given[_PARAM_NAMES.index(name)] = value
    return given


def _batch_run(s, base, project, run, specs, trajectory, allow=False):
    """One run: (status, message, metric values, stats)."""
    st = _new_stats()
    nan = [math.nan] * len(specs)
    try:
        given = dict(base)
        given.update(_line_overrides(run))
    except _LineError as error:
        return "invalid", str(error), nan, st
    p = _with_constants(_param_values(given))
    try:
        x0 = _initial_state(s, p, project, allow)
    except SimulationError as error:
        return "failed", str(error), nan, st
    except ConstraintError as error:
        return "constraint", "; ".join(error.messages), nan, st
    acc = [0.0] * len(specs)
    count = 0
    out = None
    if trajectory is not None:
        out = open(trajectory, "w", encoding="utf-8", newline="")
        out.write(",".join(["t"] + OUTPUTS) + "\n")
    try:
        for t, y in _integrate(s, p, x0, st):
            for k, (kind, j) in enumerate(specs):
                v = y[j]
                if kind == "final":
                    acc[k] = v
                elif kind == "max":
                    if count == 0 or v > acc[k]:
                        acc[k] = v
                elif kind == "min":
                    if count == 0 or v < acc[k]:
                        acc[k] = v
                elif kind == "maxabs":
                    if count == 0 or abs(v) > acc[k]:
                        acc[k] = abs(v)
                else:
                    acc[k] = v * v if count == 0 else acc[k] + v * v
            count += 1
            if out is not None:
                out.write(_row_text(t, y))
    except _Failure as failure:
        return "failed", str(failure), nan, st
    finally:
        if out is not None:
            out.close()
    if count == 0:
        return "ok", "", nan, st
    values = [math.sqrt(a / count) if kind == "rms" else a for a, (kind, j) in zip(acc, specs)]
    return "ok", "", values, st


def batch_rows(runs, metrics=(), t_end=None, dt=None, solver=None, rtol=None, atol=None,
               params=None, step=None, project_initial=False, trajectories=None,
               max_steps=None, allow_inconsistent=False, error_states=None):
    """Runs each of `runs` (a line of NAME=VALUE words, or a dict {name: value}) on top of the
    defaults and `params`, yielding one dict per run as it completes: run (its number from 0),
    status (ok, failed, constraint, invalid), each metric ("KIND:OUTPUT", see METRIC_KINDS),
    steps, rejected, rhs, cpu, message.  trajectories: a directory for each run's CSV
    (run-NNNNNN.csv).  error_states: as rows().  ValueError for bad settings or metrics,
    before any run."""
    if project_initial and allow_inconsistent:
        raise ValueError("project_initial and allow_inconsistent exclude each other")
    s = _settings(t_end, dt, solver, rtol, atol, step, max_steps, error_states=error_states)
    base = _overrides(params)
    specs = [_metric_spec(m) for m in metrics]
    index = 0
    for run in runs:
        if isinstance(run, str) and run.startswith("#"):
            continue
        path = None
        if trajectories is not None:
            path = "%s/run-%06d.csv" % (trajectories, index)
        status, message, values, st = _batch_run(s, base, project_initial, run, specs, path,
                                                 allow_inconsistent)
        row = {"run": index, "status": status}
        row.update(zip(metrics, values))
        row.update(steps=st["steps"], rejected=st["rejected"], rhs=st["rhs"], cpu=st["cpu"],
                   message=message)
        index += 1
        yield row
        if _STOP[0]:
            return


def batch(runs, metrics=(), **options):
    """batch_rows as a list."""
    return list(batch_rows(runs, metrics, **options))


def _quoted(text):
    return '"' + text.replace('"', '""').replace("\n", " ").replace("\r", " ") + '"'


def _batch_main(argv):
    """The program with --batch (see bgc/runtime/batch.c); the exit status."""
    rest, own = [], {"--batch": None, "--trajectories": None}
    metrics = []
    i = 0
    while i < len(argv):
        name, eq, value = argv[i].partition("=")
        if name not in ("--batch", "--metric", "--trajectories"):
            rest.append(argv[i])
            i += 1
            continue
        if not eq:
            if i + 1 >= len(argv):
                sys.stderr.write("error: option '%s' needs a value\n" % argv[i])
                return 2
            i += 1
            value = argv[i]
        if name == "--metric":
            metrics.append(value)
        else:
            own[name] = value
        i += 1
    try:
        parsed = _parse_args(rest)
        for m in metrics:
            _metric_spec(m)
    except _UsageError as error:
        sys.stderr.write(str(error))
        return 2
    except ValueError as error:
        sys.stderr.write("error: %s\n" % error)
        return 2
    if parsed is None:
        return 0
    options, given, flags = parsed
    try:
        _settings(**options)
    except ValueError as error:
        sys.stderr.write("error: %s\n" % error)
        return 2
    params = {_PARAM_NAMES[j]: v for j, v in given.items()}
    try:
        source = sys.stdin if own["--batch"] == "-" else open(own["--batch"], encoding="utf-8")
    except OSError:
        sys.stderr.write("error: cannot read '%s'\n" % own["--batch"])
        return 2
    out = sys.stdout
    out.write(",".join(["run", "status"] + metrics + ["steps", "rejected", "rhs", "cpu",
                                                       "message"]) + "\n")
    if source is sys.stdin:
        out.flush()
    handlers = _stop_on_signals()
    try:
        for row in batch_rows((line for line in source), metrics, params=params,
                              project_initial="--project-initial" in flags,
                              allow_inconsistent="--allow-inconsistent" in flags,
                              trajectories=own["--trajectories"], **options):
            out.write("%d,%s%s,%d,%d,%d,%.17g,%s\n" % (
                row["run"], row["status"], "".join(",%.17g" % row[m] for m in metrics),
                row["steps"], row["rejected"], row["rhs"], row["cpu"],
                _quoted(row["message"])))
            if source is sys.stdin:  # (each result as it is known, as the C program's)
                out.flush()
    finally:
        for sig, handler in handlers:
            signal.signal(sig, handler)
        stopped = _STOP[0]
        request_stop(0)
        if source is not sys.stdin:
            source.close()
    out.flush()
    if stopped:
        sys.stderr.write("error: interrupted by signal %d\n" % stopped)
        return 3
    return 0


# ---------------------------------------------------------------- binding


def _bind_model():
    """Derives the runtime's tables from the model part's names (the contract above): call it
    after (re)defining them."""
    global PARAMETERS, _V
    _BLOCK_TABLE[:] = [_Block(row) for row in _BLOCKS]
    PARAMETERS = dict(zip(_PARAM_NAMES, _param_values({})))
    _V = _ListVectors if _N <= _LIST_STATES else _ArrayVectors
    _WORK.clear()  # a workspace of the model's sizes, made when first needed


PARAMETERS = {}
_bind_model()
