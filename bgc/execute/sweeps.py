"""Parameter sweeps and ensembles: one compile, many runs in batches.

A sweep is a list of runs (parameter sets, numbered from 0), made from a grid or a seeded
sample; the compiled program runs them in batches, one process per batch (its --batch mode,
bgc/runtime/batch.c), and the results are one Table ordered by run number.  Batches run in
this process one after the other, or as tasks of Dask distributed (a LocalCluster, or any
cluster's Client): the task is pure (a batch's results depend on its lines only) and
idempotent (it writes nothing the client sees), so Dask may rerun it when a worker dies.

Specifications are parsed here by hand (never eval):
  grid    NAME=A:B:linN | NAME=A:B:logN  N points from A to B, evenly or geometrically spaced
          NAME=V1,V2,...                 the values listed (one value: a list of one)
          The grid is the Cartesian product, the first --grid varying slowest.
  vary    NAME=uniform(A,B) | normal(MU,SIGMA) | loguniform(A,B)
          drawn with numpy's default_rng(seed): all n values of the first --vary, then the
          next's, and so on.
"""
from __future__ import annotations

import contextlib
import csv
import functools
import hashlib
import io
import itertools
import math
import os
import re
import signal
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..base import cache, processes
from . import runner

METRIC_KINDS = ("final", "max", "min", "maxabs", "rms")
COUNTERS = ("steps", "rejected", "rhs")
_NUMBER = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
_RANGE = re.compile(rf"^({_NUMBER}):({_NUMBER}):(lin|log)(\d+)$")
_DIST = re.compile(rf"^(uniform|normal|loguniform)\(\s*({_NUMBER})\s*,\s*({_NUMBER})\s*\)$")
_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_.]*$")
MAX_RUNS = 10_000_000


class SweepError(ValueError):
    """A sweep specification that is not one (the message says why, for people)."""


class BatchFailed(RuntimeError):
    """A batch's program did not run to its end (a broken toolchain, a killed process)."""


class SchedulerUnreachable(RuntimeError):
    """The Dask scheduler asked for cannot be reached (the message says which and why)."""


# ---------------------------------------------------------------- specifications


def _number(text: str, what: str) -> float:
    if not re.fullmatch(_NUMBER, text.strip()):
        raise SweepError(f"{what}: expected A:B:linN, A:B:logN or V1,V2,..; got '{text}'")
    value = float(text)
    if not math.isfinite(value):
        raise SweepError(f"{what}: '{text}' is not finite")
    return value


def _split_name(spec: str, option: str) -> tuple[str, str]:
    name, eq, rest = spec.partition("=")
    name = name.strip()
    if not eq or not _NAME.match(name):
        raise SweepError(f"{option} expects NAME=..., got '{spec}'")
    return name, rest.strip()


def parse_grid_axis(spec: str) -> tuple[str, list[float]]:
    """--grid NAME=A:B:linN|logN or NAME=V1,V2,..: the name and its values, in order."""
    name, rest = _split_name(spec, "--grid")
    m = _RANGE.match(rest.replace(" ", ""))
    if m:
        a, b, n = float(m[1]), float(m[2]), int(m[4])
        if not (math.isfinite(a) and math.isfinite(b)) or n < 1:
            raise SweepError(f"--grid {name}: a range needs finite ends and at least 1 point")
        if n > MAX_RUNS:
            raise SweepError(f"--grid {name}: more than {MAX_RUNS} points")
        if m[3] == "log":
            if not (a > 0 and b > 0):
                raise SweepError(f"--grid {name}: a log range needs positive ends")
            values = np.geomspace(a, b, n) if n > 1 else np.array([a])
        else:
            values = np.linspace(a, b, n)
        return name, [float(v) for v in values]
    items = [v for v in rest.split(",")]
    if not rest or not all(v.strip() for v in items):
        raise SweepError(f"--grid {name}: expected A:B:linN, A:B:logN or V1,V2,..; got '{rest}'")
    return name, [_number(v, f"--grid {name}") for v in items]


def parse_distribution(spec: str) -> tuple[str, str, float, float]:
    """--vary NAME=uniform(A,B)|normal(MU,SIGMA)|loguniform(A,B): (name, kind, a, b)."""
    name, rest = _split_name(spec, "--vary")
    m = _DIST.match(rest)
    if not m:
        raise SweepError(f"--vary {name}: expected uniform(A,B), normal(MU,SIGMA) or "
                         f"loguniform(A,B); got '{rest}'")
    kind, a, b = m[1], _number(m[2], f"--vary {name}"), _number(m[3], f"--vary {name}")
    if kind == "normal" and not b >= 0:
        raise SweepError(f"--vary {name}: sigma must not be negative")
    if kind != "normal" and not a <= b:
        raise SweepError(f"--vary {name}: A must not exceed B")
    if kind == "loguniform" and not a > 0:
        raise SweepError(f"--vary {name}: loguniform needs positive bounds")
    return name, kind, a, b


def grid_runs(axes) -> tuple[list[str], list[tuple[float, ...]]]:
    """The Cartesian product of the axes [(name, values)], the first varying slowest."""
    names = [n for n, _ in axes]
    _unique(names)
    total = math.prod(len(v) for _, v in axes) if axes else 0
    if total > MAX_RUNS:
        raise SweepError(f"the grid has {total} points, more than {MAX_RUNS}")
    return names, [tuple(p) for p in itertools.product(*[v for _, v in axes])]


def sample_runs(n: int, dists, seed: int) -> tuple[list[str], list[tuple[float, ...]]]:
    """n parameter sets drawn from the distributions [(name, kind, a, b)] with default_rng(seed):
    all of the first parameter's values, then the next's."""
    if not 1 <= n <= MAX_RUNS:
        raise SweepError(f"--sample must be between 1 and {MAX_RUNS}")
    names = [d[0] for d in dists]
    _unique(names)
    rng = np.random.default_rng(seed)
    columns = []
    for _, kind, a, b in dists:
        if kind == "uniform":
            columns.append(rng.uniform(a, b, n))
        elif kind == "normal":
            columns.append(rng.normal(a, b, n))
        else:
            columns.append(np.exp(rng.uniform(math.log(a), math.log(b), n)))
    return names, [tuple(float(c[i]) for c in columns) for i in range(n)]


def _unique(names):
    seen = set()
    for n in names:
        if n in seen:
            raise SweepError(f"parameter '{n}' is swept twice")
        seen.add(n)


def run_line(names, values) -> str:
    """A run as the program's batch line: NAME=VALUE words, values that read back exactly."""
    return " ".join(f"{n}={float(v)!r}" for n, v in zip(names, values))


def parse_metric(spec: str, outputs) -> str:
    """KIND:OUTPUT, checked against the program's outputs."""
    kind, colon, output = spec.partition(":")
    if not colon or kind not in METRIC_KINDS:
        raise SweepError(f"--metric expects KIND:OUTPUT with KIND one of "
                         f"{', '.join(METRIC_KINDS)}; got '{spec}'")
    if output not in outputs:
        raise SweepError(f"--metric {spec}: '{output}' is not an output (outputs: "
                         f"{', '.join(outputs)})")
    return spec


# ---------------------------------------------------------------- the task


@dataclass(frozen=True)
class SweepProgram:
    """What a task needs: the generated sources (C, and Python for workers without a C
    compiler, or alone for the Python backend), the program's arguments (settings, fixed
    parameters) and the metrics."""
    c_source: str | None
    python_source: str
    args: tuple[str, ...]
    metrics: tuple[str, ...]
    digest: str = field(default="", compare=False)


def make_program(c_source, python_source, args, metrics) -> SweepProgram:
    key = hashlib.sha256(repr((c_source, python_source, tuple(args), tuple(metrics)))
                         .encode()).hexdigest()[:16]
    return SweepProgram(c_source, python_source, tuple(args), tuple(metrics), key)


@functools.lru_cache(maxsize=8)
def _executable(c_source: str) -> str:
    return str(cache.compile_c(c_source))


@dataclass(frozen=True)
class BatchResult:
    """A batch's rows (status, metric values, steps, rejected, rhs, cpu, message) for its
    runs first, first + 1, ..., and their trajectories' CSV when asked ({run: text})."""
    first: int
    rows: tuple
    trajectories: dict | None = None
    backend: str = "c"


def run_batch(program: SweepProgram, first: int, lines: tuple[str, ...],
              trajectories: bool = False) -> BatchResult:
    """Runs one batch in one process of the program: pure and idempotent (a Dask task)."""
    with tempfile.TemporaryDirectory(prefix="bgc-sweep-") as tmp:
        # (on the worker: a worker without a C compiler runs the Python program)
        backend, _ = runner.choose_backend("c" if program.c_source is not None else "python")
        if backend == "c":
            argv = [_executable(program.c_source)]
        else:
            argv = processes.python_program(program.python_source, tmp)
        argv += ["--batch", "-", *program.args]
        for m in program.metrics:
            argv += ["--metric", m]
        traj_dir = None
        if trajectories:
            traj_dir = Path(tmp) / "runs"
            traj_dir.mkdir()
            argv += ["--trajectories", str(traj_dir)]
        # (child_env: the program dies with the process that runs it, bgc or a Dask worker,
        # when that is killed; a LocalCluster's workers die with bgc by Dask's own watch)
        done = subprocess.run(argv, input="".join(line + "\n" for line in lines),
                              capture_output=True, text=True, env=processes.child_env())
        if done.returncode != 0:
            raise BatchFailed(f"the batch of runs {first}..{first + len(lines) - 1} failed "
                             f"(status {done.returncode}): {done.stderr.strip()}")
        rows = _parse_batch(done.stdout, len(program.metrics), len(lines))
        kept = None
        if trajectories:
            kept = {first + i: (traj_dir / f"run-{i:06d}.csv").read_text(encoding="utf-8")
                    for i in range(len(lines)) if (traj_dir / f"run-{i:06d}.csv").exists()}
    return BatchResult(first, rows, kept, backend)


def _parse_batch(text: str, nmetrics: int, expected: int) -> tuple:
    reader = csv.reader(io.StringIO(text))
    next(reader)
    rows = []
    for rec in reader:
        metrics = tuple(float(v) for v in rec[2:2 + nmetrics])
        steps, rejected, rhs = (int(v) for v in rec[2 + nmetrics:5 + nmetrics])
        rows.append((rec[1], metrics, steps, rejected, rhs, float(rec[5 + nmetrics]),
                     rec[6 + nmetrics]))
    if len(rows) != expected:
        raise BatchFailed(f"a batch of {expected} runs gave {len(rows)} results")
    return tuple(rows)


# ---------------------------------------------------------------- the table


class Table:
    """The sweep's results, one row per run in run order: .columns maps each column's name
    to a numpy array (numbers) or a list (status, message)."""

    def __init__(self, columns: dict):
        self.columns = columns

    def __getitem__(self, name):
        return self.columns[name]

    def __len__(self):
        return len(self.columns["run"])

    @property
    def names(self) -> list[str]:
        return list(self.columns)

    def failures(self) -> int:
        return sum(1 for s in self.columns["status"] if s != "ok")

    def to_csv(self, path=None) -> str:
        """The table as CSV (numbers as %.17g, integers as such, the message quoted); written
        to path (atomically) if given.  Returns the text."""
        out = io.StringIO()
        out.write(",".join(self.columns) + "\n")
        cols = list(self.columns.items())
        for i in range(len(self)):
            out.write(",".join(_cell(name, col[i]) for name, col in cols) + "\n")
        text = out.getvalue()
        if path is not None:
            from . import outfile
            outfile.write_atomic(path, text)
        return text


    def to_arrow(self):
        """The table as a pyarrow.Table (numbers as float64, integers as int64, status and
        message as strings); needs pyarrow (pip install 'bgc[parquet]')."""
        import pyarrow as pa
        arrays = {}
        for name, col in self.columns.items():
            if isinstance(col, np.ndarray):
                arrays[name] = pa.array(col)
            else:
                arrays[name] = pa.array([str(v) for v in col], type=pa.string())
        return pa.table(arrays)

    def to_parquet(self, path) -> None:
        """The table as a Parquet file, written atomically (pip install 'bgc[parquet]')."""
        import pyarrow.parquet as pq
        from . import outfile
        table = self.to_arrow()
        with outfile.Partial(path) as out:
            pq.write_table(table, out.file)
            out.commit()


def have_pyarrow() -> bool:
    import importlib.util
    return importlib.util.find_spec("pyarrow") is not None


def _cell(name, value) -> str:
    if name == "message":
        return '"' + str(value).replace('"', '""') + '"'
    if isinstance(value, str):
        return value
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    return "%.17g" % value


# ---------------------------------------------------------------- running


@dataclass
class Progress:
    """What the progress callback is given after each batch."""
    done: int
    total: int
    failures: int
    elapsed: float


def batches(n: int, batch_size: int) -> list[tuple[int, int]]:
    return [(i, min(n, i + batch_size)) for i in range(0, n, batch_size)]


def default_batch_size(n: int, workers: int) -> int:
    return max(1, min(1000, math.ceil(n / (4 * max(1, workers)))))


def run_batches(program: SweepProgram, lines: list[str], batch_size: int, client=None,
        trajectories: bool = False, progress=None, on_batch=None) -> list[BatchResult]:
    """Runs every line in batches, serially in this process when client is None, else as
    tasks of client (a dask.distributed.Client).  progress(Progress) after each batch;
    on_batch(BatchResult) too (to write trajectories as they come).  Results in run order."""
    spans = batches(len(lines), batch_size)
    start = time.perf_counter()
    results, done, failures = [], 0, 0

    def account(result):
        nonlocal done, failures
        results.append(result)
        done += len(result.rows)
        failures += sum(1 for r in result.rows if r[0] != "ok")
        if on_batch:
            on_batch(result)
        if progress:
            progress(Progress(done, len(lines), failures, time.perf_counter() - start))

    if client is None:
        for a, b in spans:
            account(run_batch(program, a, tuple(lines[a:b]), trajectories))
    else:
        from distributed import as_completed
        [shared] = client.scatter([program], broadcast=True, hash=False)
        keys = [f"bgc-sweep-{program.digest}-{_batch_key(lines[a:b], trajectories)}-{a}"
                for a, b in spans]
        futures = client.map(run_batch, [shared] * len(spans), [a for a, _ in spans],
                             [tuple(lines[a:b]) for a, b in spans],
                             [trajectories] * len(spans), key=keys, pure=True)
        for future in as_completed(futures):
            account(future.result())
            future.release()
    results.sort(key=lambda r: r.first)
    return results


def _batch_key(lines, trajectories) -> str:
    h = hashlib.sha256("\n".join(lines).encode())
    h.update(b"T" if trajectories else b"F")
    return h.hexdigest()[:16]


def local_client(workers: int | None):
    """A Client of a new LocalCluster of `workers` processes (default: the cores), one
    thread each, without a dashboard.  Close both (client.close(); client.cluster.close()).
    The scheduler's HTTP server (Dask starts one even without the dashboard) takes a port
    the system chooses: its default, 8787, may be another cluster's, and Dask then warns on
    the user's terminal.
    The workers ignore SIGINT (_workers_ignore_sigint): a Ctrl-C is bgc's to handle."""
    import logging

    from distributed import Client, LocalCluster
    _workers_ignore_sigint()
    cluster = LocalCluster(n_workers=workers or os.cpu_count() or 1, threads_per_worker=1,
                           processes=True, dashboard_address=None,
                           scheduler_kwargs={"dashboard_address": ":0"},
                           silence_logs=logging.ERROR)
    return Client(cluster)


def _workers_ignore_sigint() -> None:
    """The local cluster's worker processes started with SIGINT ignored, so that a Ctrl-C,
    which the terminal sends to every process of the job, stops bgc alone (which then closes
    the cluster) rather than each worker in the middle of its start or of a task, each with
    a traceback.  The workers are forked by multiprocessing's fork server, which ignores
    SIGINT from its start (bgc.execute.forkserver_init, its first preload) and passes that on to
    each
    process it forks, its stderr on the null device (a worker's errors reach bgc through
    Dask; what one stopped halfway through its start prints does not).  bgc's own SIGINT is
    never ignored, so no Ctrl-C is lost; without a fork server the workers start as Dask
    starts them."""
    import multiprocessing
    if "forkserver" not in multiprocessing.get_all_start_methods():
        return
    import dask
    from distributed.utils import get_mp_context

    from .forkserver_init import IGNORE_SIGINT
    dask.config.set({"distributed.worker.multiprocessing-method": "forkserver"})
    get_mp_context().set_forkserver_preload(["bgc.execute.forkserver_init", "distributed"])
    from multiprocessing import forkserver
    null, stderr = os.open(os.devnull, os.O_WRONLY), os.dup(2)
    os.environ[IGNORE_SIGINT] = "1"
    try:
        os.dup2(null, 2)
        forkserver.ensure_running()
    finally:
        os.dup2(stderr, 2)
        os.close(stderr)
        os.close(null)
        os.environ.pop(IGNORE_SIGINT, None)


NO_DASK = ("note: dask.distributed is not installed (pip install 'bgc[sweep]'); running the "
           "batches serially in this process")


@contextlib.contextmanager
def signals_held():
    """SIGINT and SIGTERM held back while Dask starts or stops a client or cluster, then
    raised again, to whatever handles them, once it is done: one that interrupts Dask's start
    leaves the cluster half made, and its clean-up fails (`AssertionError: Status.init`).  A
    second one meanwhile is not held (a start that hangs can still be stopped)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    got: list[int] = []
    saved = {}

    def hold(sig, frame):
        if got:
            for number, handler in saved.items():
                signal.signal(number, handler)
            signal.raise_signal(sig)
        got.append(sig)

    for sig in (signal.SIGINT, signal.SIGTERM):
        if signal.getsignal(sig) not in (signal.SIG_IGN, None):
            saved[sig] = signal.signal(sig, hold)
    try:
        yield
    finally:
        for sig, handler in saved.items():
            signal.signal(sig, handler)
        if got:
            signal.raise_signal(got[0])


@contextlib.contextmanager
def dask_client(scheduler: str | None = None, workers: int | None = None, note=None):
    """The Dask client a sweep's batches run on, closed (with its cluster, if it made one) at
    the end: a connection to `scheduler` (SchedulerUnreachable if it does not answer), else a
    LocalCluster of `workers` processes (None: the cores); None, to run the batches serially
    in this process, for workers=0, or when dask.distributed is missing and there is a
    note(text) to say so (without one that is an ImportError)."""
    if not scheduler and workers == 0:
        yield None
        return
    if note is not None and not have_dask():
        note(NO_DASK)
        yield None
        return
    client = None
    try:
        if scheduler:
            from distributed import Client
            try:
                with signals_held():
                    client = Client(scheduler, timeout=30)
            except OSError as error:
                raise SchedulerUnreachable(f"cannot reach the scheduler {scheduler}: "
                                           f"{error}") from None
        else:
            with signals_held():  # (an interrupt meanwhile comes once client is set)
                client = local_client(workers)
        yield client
    except BaseException:
        if client is not None:
            _close(client, scheduler is None, stopped=True)
        raise
    _close(client, scheduler is None, stopped=False)


def _close(client, cluster: bool, stopped: bool) -> None:
    """Closes the client (and its cluster, if bgc made it), signals held meanwhile.  stopped:
    the sweep stopped halfway (interrupted, a batch failed): Dask's complaints about work
    cut short (a task's data lost, a worker closed in its start) are not shown, nor is a
    close that fails (bgc is leaving: the workers end with it)."""
    import logging
    loggers = [logging.getLogger(name) for name in ("distributed", "asyncio", "tornado")]
    levels = [log.level for log in loggers]
    with signals_held():
        if stopped:
            for log in loggers:
                log.setLevel(logging.CRITICAL + 1)
        try:
            made = client.cluster if cluster else None
            client.close()
            if made is not None:
                made.close()
        except Exception:
            if not stopped:
                raise
            _leave_unclosed()
        finally:
            for log, level in zip(loggers, levels):
                log.setLevel(level)


def _leave_unclosed() -> None:
    """Dask's own attempt, when bgc exits, to close a cluster whose close failed (a worker
    still in its start: `AssertionError: Status.init`) is not made: it would fail again, with
    a traceback; the workers end with bgc (they watch it)."""
    import atexit
    try:
        from distributed.deploy import spec
        atexit.unregister(spec.close_clusters)
    except (ImportError, AttributeError):
        pass


def have_dask() -> bool:
    try:
        import distributed  # noqa: F401
    except ImportError:
        return False
    return True


def table(names, values, metrics, results, timing=True) -> Table:
    """The Table: run, the swept parameters, the metrics, the counters, cpu (if timing),
    status and message."""
    rows = [r for res in results for r in res.rows]
    cols: dict = {"run": np.arange(len(rows), dtype=np.int64)}
    for j, name in enumerate(names):
        cols[name] = np.array([v[j] for v in values], dtype=float)
    for k, m in enumerate(metrics):
        cols[m] = np.array([r[1][k] for r in rows], dtype=float)
    for k, c in enumerate(COUNTERS):
        cols[c] = np.array([r[2 + k] for r in rows], dtype=np.int64)
    if timing:
        cols["cpu"] = np.array([r[5] for r in rows], dtype=float)
    cols["status"] = [r[0] for r in rows]
    cols["message"] = [r[6] for r in rows]
    return Table(cols)


def progress_line(p: Progress) -> str:
    """"[####......] 120/10000 runs, 0 failed, 3.1 s, ETA 4 min"."""
    filled = int(30 * p.done / p.total) if p.total else 30
    eta = p.elapsed / p.done * (p.total - p.done) if p.done else math.nan
    eta_text = "?" if not math.isfinite(eta) else (f"{eta:.0f} s" if eta < 120 else
                                                   f"{eta / 60:.0f} min")
    return (f"[{'#' * filled}{'.' * (30 - filled)}] {p.done}/{p.total} runs, {p.failures} "
            f"failed, {p.elapsed:.1f} s, ETA {eta_text}")


def stderr_progress():
    """A progress callback drawing progress_line on stderr when it is a terminal, else None."""
    if not sys.stderr.isatty():
        return None

    def show(p: Progress):
        sys.stderr.write("\r\033[K" + progress_line(p))
        if p.done == p.total:
            sys.stderr.write("\n")
        sys.stderr.flush()
    return show


# ---------------------------------------------------------------- the whole sweep


def runs_from(grid=None, sample=None, vary=None, seed=0):
    """(names, values) from a grid {name: "A:B:logN" | "V1,V2" | [numbers]} (in its order,
    the first slowest) or a sample of n runs of vary {name: "uniform(A,B)" ...}."""
    if (grid is None) == (sample is None):
        raise SweepError("give a grid or a sample (not both)")
    if grid is not None:
        if not grid:
            raise SweepError("the grid has no parameter")
        axes = []
        for name, spec in grid.items():
            if isinstance(spec, str):
                axes.append(parse_grid_axis(f"{name}={spec}"))
            else:
                values = [float(v) for v in spec]
                if not values or not all(math.isfinite(v) for v in values):
                    raise SweepError(f"grid {name}: give finite values")
                axes.append((name, values))
        return grid_runs(axes)
    if vary:
        dists = [parse_distribution(f"{name}={spec}") for name, spec in vary.items()]
    else:
        raise SweepError("a sample needs parameters to vary")
    return sample_runs(int(sample), dists, int(seed))


def check_names(names, params, fixed):
    """The swept names are the program's parameters, none of them fixed by -p."""
    for n in names:
        if n not in params:
            raise SweepError(f"unknown parameter '{n}' (parameters: {', '.join(params)})")
        if n in fixed:
            raise SweepError(f"parameter '{n}' is both swept and fixed (-p)")
