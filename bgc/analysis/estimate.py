"""Sensitivities and parameter estimation: `bgc.sensitivities` and `bgc fit`.

`sensitivities` runs a model's program augmented with the states' sensitivities to chosen
parameters (bgc.codegen.sensitivity; built by the lowering stage, so either backend and every solver
integrate it) and returns the arrays.  `fit` estimates parameters from measured samples by
Levenberg-Marquardt on the residuals y_model(t_i; theta) - y_measured(t_i), whose Jacobian
dy/dtheta comes from the same runs (one run of the augmented program gives the residuals and
their Jacobian together): no finite differences.  The program is compiled once per fit and run
with the trial values as parameter overrides (`-p`), as `bgc simulate` runs it.

Bounds (`--vary k=LO..HI`) are kept by projection: a trial point outside the box is clipped
onto it, and the reported intervals are those of the unconstrained linearisation at the
estimate (a parameter that ends on its bound is flagged).  Standard errors are
sqrt(diag(s^2 (J'J)^-1)) with s^2 = 2 cost / (N - P); the 95 % intervals use the Student-t
quantile with N - P degrees of freedom (`t_quantile`, written here: SciPy is not a runtime
dependency).
"""
from __future__ import annotations

import json
import math
import os
import re
from dataclasses import dataclass, field, replace

import numpy as np

from .. import api
from ..execute import runner
from ..codegen.lower import lower
from ..base.diagnostics import ModelError
from ..codegen.sensitivity import SensitivityError, column


class FitError(Exception):
    """A fit that cannot be done or did not work (the message says why, for people)."""


class FitArgumentError(FitError, ValueError):
    """An argument or data file the fit refuses: a usage error."""


# ---------------------------------------------------------------- Student's t quantile


def _betacf(a: float, b: float, x: float) -> float:
    """The continued fraction of the regularised incomplete beta function (modified Lentz)."""
    tiny = 1e-300
    qab, qap, qam = a + b, a + 1.0, a - 1.0
    c, d = 1.0, 1.0 - qab * x / qap
    d = 1.0 / (d if abs(d) > tiny else tiny)
    h = d
    for m in range(1, 10000):
        m2 = 2 * m
        aa = m * (b - m) * x / ((qam + m2) * (a + m2))
        d = 1.0 + aa * d
        d = 1.0 / (d if abs(d) > tiny else tiny)
        c = 1.0 + aa / c
        c = c if abs(c) > tiny else tiny
        h *= d * c
        aa = -(a + m) * (qab + m) * x / ((a + m2) * (qap + m2))
        d = 1.0 + aa * d
        d = 1.0 / (d if abs(d) > tiny else tiny)
        c = 1.0 + aa / c
        c = c if abs(c) > tiny else tiny
        delta = d * c
        h *= delta
        if abs(delta - 1.0) < 1e-16:
            break
    return h


def _betainc(a: float, b: float, x: float, y: float) -> float:
    """I_x(a, b), the regularised incomplete beta function; y = 1 - x, given apart so that
    neither loses digits when the other is near 1."""
    if x <= 0.0:
        return 0.0
    if y <= 0.0:
        return 1.0
    ln = math.lgamma(a + b) - math.lgamma(a) - math.lgamma(b) + a * math.log(x) \
        + b * math.log(y)
    if x < (a + 1.0) / (a + b + 2.0):
        return math.exp(ln) * _betacf(a, b, x) / a
    return 1.0 - math.exp(ln) * _betacf(b, a, y) / b


def t_cdf(t: float, df: float) -> float:
    """P(T <= t) for Student's t with df degrees of freedom."""
    tail = 0.5 * _betainc(0.5 * df, 0.5, df / (df + t * t), t * t / (df + t * t))
    return 1.0 - tail if t > 0 else tail


def _t_pdf(t: float, df: float) -> float:
    return math.exp(math.lgamma(0.5 * (df + 1)) - math.lgamma(0.5 * df)
                    - 0.5 * math.log(df * math.pi) - 0.5 * (df + 1) * math.log1p(t * t / df))


def t_quantile(q: float, df: float) -> float:
    """The q-quantile of Student's t with df > 0 degrees of freedom (0 < q < 1): bisection on
    t_cdf to a bracket, then Newton's method, to about 1e-12 relative."""
    if not 0.0 < q < 1.0 or not df > 0:
        raise ValueError("t_quantile needs 0 < q < 1 and df > 0")
    if q == 0.5:
        return 0.0
    if q < 0.5:
        return -t_quantile(1.0 - q, df)
    lo, hi = 0.0, 1.0
    while t_cdf(hi, df) < q:
        lo, hi = hi, hi * 2.0
        if hi > 1e300:
            return math.inf
    for _ in range(60):  # bisection until the bracket is narrow, then Newton
        mid = 0.5 * (lo + hi)
        if t_cdf(mid, df) < q:
            lo = mid
        else:
            hi = mid
        if hi - lo < 1e-3 * max(1.0, lo):
            break
    t = 0.5 * (lo + hi)
    for _ in range(50):
        step = (t_cdf(t, df) - q) / _t_pdf(t, df)
        t_new = min(max(t - step, lo), hi)
        if abs(t_new - t) <= 1e-14 * max(1.0, abs(t)):
            return t_new
        t = t_new
    return t


# ---------------------------------------------------------------- the augmented program


def build(model, params, scene=None, given=(), state_outputs=False, algebra="auto",
          outputs=None, effects=None, project_initial=False, allow_inconsistent=False,
          option_names=("outputs=", "effects=", "scene=")) -> api.Compiled:
    """model's scene compiled with the sensitivities to `params` (names): bgc.api.build up to
    the reduce stage, then the lowering stage with them (bgc.codegen.sensitivity says what given and
    state_outputs mean).  Raises api's errors, FitArgumentError for parameters it refuses and
    FitError for a model it cannot do, BgcModelError for one whose events the sensitivities
    cannot pass (located)."""
    if project_initial:
        raise FitArgumentError(
            "sensitivities and --project-initial exclude each other: the projection of the "
            "initial values is not differentiated (give initial values that satisfy the "
            "constraints, or --allow-inconsistent to start from them as they are)")
    compiled = api.build(model, scene, project_initial, algebra, program=False,
                         outputs=outputs, effects=effects, option_names=option_names,
                         allow_inconsistent=allow_inconsistent)
    names = [p.name for p in compiled.reduced.parameters]
    unknown = [p for p in params if p not in names]
    if unknown or not params or len(set(params)) != len(params):
        raise FitArgumentError(
            f"unknown parameter {unknown[0]!r} (parameters: {', '.join(names) or 'none'})"
            if unknown else "no parameter given" if not params else "a parameter is named twice")
    try:
        program = lower(compiled.reduced, tuple(params), tuple(given), state_outputs)
    except SensitivityError as error:
        raise FitError(str(error)) from None
    except ModelError as error:  # (located: an event the sensitivities cannot pass)
        raise api.BgcModelError(error, compiled.source) from None
    return replace(compiled, program=program)


@dataclass(frozen=True)
class Sensitivities:
    """A run with sensitivities: S[k, i, j] = d states[i] / d params[j] at t[k], and the same
    of the outputs in dy."""

    t: np.ndarray
    params: tuple[str, ...]
    states: tuple[str, ...]
    x: np.ndarray  # (len(t), len(states))
    S: np.ndarray  # (len(t), len(states), len(params))
    outputs: tuple[str, ...]
    y: np.ndarray  # (len(t), len(outputs))
    dy: np.ndarray  # (len(t), len(outputs), len(params))


def sensitivities(model, params, scene=None, backend="c", algebra="auto", outputs=None,
                  effects=None, values=None, **options) -> Sensitivities:
    """A run of model's scene with the sensitivities of its states and outputs to `params`
    (a list of parameter names, or one name, or "k,c"); values: parameter overrides
    {name: value} (simulate's params=: a parameter computed from a chosen one follows it
    unless it is overridden); options as bgc.simulate's (inputs= the data of the model's
    inputs, {name: (t, values)}: the sensitivities run through them).  Raises as bgc.simulate, and
    FitArgumentError for unknown parameters, BgcModelError (located) for a model whose events
    the sensitivities cannot pass (a discrete value sampled from the states)."""
    if isinstance(params, str):
        params = [p.strip() for p in params.split(",") if p.strip()]
    chosen = tuple(params)
    values = dict(values or {})
    options["params"] = values
    inputs = options.pop("inputs", None)
    compiled = build(model, chosen, scene, tuple(values), True, algebra, outputs, effects,
                     options.get("project_initial", False),
                     options.get("allow_inconsistent", False))
    program = compiled.program
    if inputs is not None:
        options["input_data"] = _input_data(program, inputs)
    settings = runner.settings_for(program.scene, [p.name for p in program.params], **options)
    backend, _ = runner.choose_backend(backend)
    ran = runner.prepare(compiled, backend, in_process=backend == "python")
    t, Y = api.arrays(runner.run(ran, settings))
    m = len(chosen)
    width = len(program.outputs) // (1 + m)
    n = len(program.states) // (1 + m)
    M = width - n
    Y = Y.reshape(len(t), 1 + m, width)
    return Sensitivities(t, chosen, tuple(program.states[:n]), Y[:, 0, M:],
                         np.moveaxis(Y[:, 1:, M:], 1, 2), tuple(program.outputs[:M]),
                         Y[:, 0, :M], np.moveaxis(Y[:, 1:, :M], 1, 2))


def _input_data(program, inputs) -> tuple:
    """inputs ({name: (t, values)}, the data of the model's declared inputs, as
    bgc.simulate's inputs=) checked against program's inputs, as RunSettings.input_data;
    FitArgumentError for people."""
    from ..base.run_settings import input_data
    names = [u.name for u in program.inputs]
    for name in inputs:
        if name not in names:
            raise FitArgumentError(f"unknown input {name!r} (inputs: "
                                   f"{', '.join(names) or 'none'})")
    try:
        return input_data(dict(inputs))
    except (TypeError, ValueError) as error:
        raise FitArgumentError(str(error)) from None


# ---------------------------------------------------------------- measured data

MAX_DATA_BYTES = 64 << 20


@dataclass(frozen=True)
class Data:
    path: str
    columns: tuple[str, ...]  # the measured outputs (t apart)
    t: np.ndarray
    y: np.ndarray  # (len(t), len(columns))


def read_data(path: str) -> Data:
    """A measured CSV: a header naming a column `t` and the outputs, then rows of numbers."""
    try:
        with open(os.fspath(path), "rb") as fh:
            raw = fh.read(MAX_DATA_BYTES + 1)  # (a longer file, or a pipe, read no further)
    except FileNotFoundError:
        raise FitArgumentError(f"{path}: no such file") from None
    except OSError as error:
        raise FitArgumentError(f"{path}: {error.strerror or error}") from None
    if len(raw) > MAX_DATA_BYTES:
        raise FitArgumentError(f"{path}: larger than {MAX_DATA_BYTES >> 20} MiB")
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError:
        raise FitArgumentError(f"{path}: not UTF-8 text") from None
    lines = [ln for ln in text.splitlines()]
    while lines and not lines[-1].strip():
        lines.pop()
    if not lines:
        raise FitArgumentError(f"{path}: empty (expected a header: t, then the outputs)")
    header = [h.strip() for h in lines[0].split(",")]
    if "t" not in header:
        raise FitArgumentError(f"{path}:1: no column 't' (the header is {', '.join(header)})")
    if len(set(header)) != len(header):
        raise FitArgumentError(f"{path}:1: a column is named twice")
    for h in header:
        if not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_.\[\]]*", h):
            raise FitArgumentError(f"{path}:1: '{h}' is not a variable's name")
    rows = np.empty((len(lines) - 1, len(header)))
    for k, line in enumerate(lines[1:], start=2):
        cells = line.split(",")
        if len(cells) != len(header):
            raise FitArgumentError(f"{path}:{k}: {len(cells)} values, the header has "
                                   f"{len(header)}")
        for j, c in enumerate(cells):
            try:
                v = float(c)
            except ValueError:
                raise FitArgumentError(f"{path}:{k}: '{c.strip()}' is not a number "
                                       f"(column {header[j]})") from None
            if not math.isfinite(v):
                raise FitArgumentError(f"{path}:{k}: column {header[j]} is not finite "
                                       f"({c.strip()})")
            rows[k - 2, j] = v
    ti = header.index("t")
    columns = tuple(h for h in header if h != "t")
    if not columns:
        raise FitArgumentError(f"{path}:1: no output column besides t")
    t = rows[:, ti]
    if len(t) and np.any(np.diff(t) <= 0):
        k = int(np.argmax(np.diff(t) <= 0)) + 3
        raise FitArgumentError(f"{path}:{k}: the times do not increase")
    return Data(str(path), columns, t, rows[:, [j for j, h in enumerate(header) if h != "t"]])


def _grid(data: Data, t0: float) -> tuple[float, float, np.ndarray]:
    """The run's output step, its end and the rows that are the samples: the samples must lie
    on one uniform grid t0 + k dt."""
    t = data.t
    if len(t) < 2:
        raise FitArgumentError(f"{data.path}: too few samples ({len(t)})")
    dt = float(t[1] - t[0])
    k = (t - t0) / dt
    rows = np.rint(k)
    if t[0] < t0 - 1e-9 * dt or np.any(np.abs(k - rows) > 1e-6):
        raise FitArgumentError(
            f"{data.path}: the samples are not on one uniform grid t0 + k*dt from the scene's "
            f"start t0 = {t0:g} (the run writes its rows there)")
    return dt, t0 + float(rows[-1]) * dt, rows.astype(int)


# ---------------------------------------------------------------- Levenberg-Marquardt


@dataclass(frozen=True)
class Vary:
    name: str
    lo: float = -math.inf
    hi: float = math.inf


def parse_vary(text: str) -> Vary:
    """NAME or NAME=LO..HI (either bound may be left out: k=0.. , k=..10)."""
    name, sep, rest = text.partition("=")
    name = name.strip()
    if not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_.\[\]]*", name):
        raise FitArgumentError(f"--vary: '{text}' is not NAME or NAME=LO..HI")
    if not sep:
        return Vary(name)
    lo_s, dots, hi_s = rest.partition("..")
    if not dots:
        raise FitArgumentError(f"--vary {name}: expected LO..HI, got '{rest}'")
    try:
        lo = float(lo_s) if lo_s.strip() else -math.inf
        hi = float(hi_s) if hi_s.strip() else math.inf
    except ValueError:
        raise FitArgumentError(f"--vary {name}: '{rest}' is not LO..HI (two numbers)") from None
    if math.isnan(lo) or math.isnan(hi) or not lo < hi:
        raise FitArgumentError(f"--vary {name}: the bounds {rest} are empty")
    return Vary(name, lo, hi)


@dataclass
class Fit:
    """The result of `fit`."""

    names: tuple[str, ...]
    estimates: np.ndarray
    start: np.ndarray
    stderr: np.ndarray
    lower: np.ndarray  # the 95 % interval
    upper: np.ndarray
    correlation: np.ndarray
    cost: float  # sum of squared residuals / 2
    residual_sd: float  # s = sqrt(2 cost / (N - P))
    samples: int  # residuals N
    iterations: int
    runs: int  # runs of the model (each gives the residuals and their Jacobian)
    stopped: str  # why
    converged: bool
    at_bound: tuple[str, ...]
    columns: tuple[str, ...]
    t: np.ndarray = field(repr=False, default=None)
    measured: np.ndarray = field(repr=False, default=None)
    fitted: np.ndarray = field(repr=False, default=None)

    def as_dict(self) -> dict:
        def num(v):
            v = float(v)
            return v if math.isfinite(v) else None
        return {
            "parameters": {n: {"estimate": num(e), "start": num(s), "stderr": num(se),
                               "ci95": [num(lo), num(hi)], "at_bound": n in self.at_bound}
                           for n, e, s, se, lo, hi in zip(self.names, self.estimates,
                                                          self.start, self.stderr, self.lower,
                                                          self.upper)},
            "correlation": [[num(v) for v in row] for row in self.correlation],
            "cost": num(self.cost), "residual_sd": num(self.residual_sd),
            "residuals": self.samples, "columns": list(self.columns),
            "iterations": self.iterations, "runs": self.runs, "converged": self.converged,
            "stopped": self.stopped}

    def json(self) -> str:
        return json.dumps(self.as_dict(), indent=2) + "\n"

    def table(self, units: dict | None = None) -> str:
        """The report: each parameter's estimate, standard error and interval (in its unit,
        from units, bgc.api.units, where known), the correlations, the cost and the run."""
        units = units or {}
        w = max([len(n) for n in self.names] + [9])
        lines = [f"{'parameter':<{w}}  {'estimate':>13}  {'std. error':>10}  "
                 f"95% interval"]
        for n, e, se, lo, hi in zip(self.names, self.estimates, self.stderr, self.lower,
                                    self.upper):
            flag = "  (at its bound)" if n in self.at_bound else ""
            unit = f" {units[n]}" if units.get(n) else ""
            lines.append(f"{n:<{w}}  {e:>13.7g}  {se:>10.4g}  [{lo:.7g}, {hi:.7g}]{unit}{flag}")
        if len(self.names) > 1:
            lines.append("correlation:")
            for n, row in zip(self.names, self.correlation):
                lines.append(f"  {n:<{w}}" + "".join(f"  {v:>7.4f}" for v in row))
        lines.append(f"cost {self.cost:.6g} (half the sum of squared residuals), {self.samples} "
                     f"residuals, residual s.d. {self.residual_sd:.4g}")
        lines.append(f"{self.iterations} iterations, {self.runs} runs: {self.stopped}")
        return "\n".join(lines) + "\n"


class _Model:
    """The augmented program compiled once, run at trial values: residuals and Jacobian."""

    def __init__(self, compiled, backend, data: Data, rows, settings, names, fixed):
        self.compiled, self.data, self.rows = compiled, data, rows
        self.settings, self.names, self.fixed = settings, names, fixed
        backend, _ = runner.choose_backend(backend)
        self.program = runner.prepare(compiled, backend, in_process=backend == "python")
        self.m = len(names)
        self.width = len(compiled.program.outputs) // (1 + self.m)
        self.runs = 0

    def __call__(self, theta):
        values = dict(self.fixed)
        values.update(zip(self.names, (float(v) for v in theta)))
        settings = replace(self.settings, params=tuple(values.items()))
        self.runs += 1
        where = ", ".join(f"{n}={float(v):.9g}" for n, v in zip(self.names, theta))
        try:
            result = runner.run(self.program, settings)
            Y = _values(result)
        except Exception as error:  # the module's SimulationError, a failed process
            if isinstance(error, (KeyboardInterrupt, MemoryError)):
                raise
            message = str(error).strip().splitlines()
            raise FitError(f"the run failed at {where}: "
                           f"{message[-1] if message else type(error).__name__}") from None
        if Y.shape[0] <= self.rows[-1]:
            raise FitError(f"the run at {where} stopped early ({Y.shape[0]} rows)")
        Y = Y[self.rows].reshape(len(self.rows), 1 + self.m, self.width)
        y, dy = Y[:, 0, :], Y[:, 1:, :]  # dy: (samples, params, outputs)
        if not (np.all(np.isfinite(y)) and np.all(np.isfinite(dy))):
            raise FitError(f"the run at {where} gives values that are not finite")
        r = (y - self.data.y).ravel()
        J = np.transpose(dy, (0, 2, 1)).reshape(-1, self.m)
        return r, J, y


def _values(result) -> np.ndarray:
    if result.t is not None:
        return np.asarray(result.values, dtype=float)
    if result.status != 0:
        raise RuntimeError(result.message)
    body = result.csv[result.csv.index("\n") + 1:]
    lines = body.count("\n")
    flat = np.array(body.replace("\n", ",").split(",")[:-1], dtype=float)
    return flat.reshape(lines, -1)[:, 1:]


def levenberg_marquardt(f, x0, lo, hi, max_iter=100, xtol=1e-10, ftol=1e-10, gtol=1e-12):
    """Minimise cost = |r|^2 / 2 for (r, J, extra) = f(x), x kept in [lo, hi] by projection:
    a parameter on its bound whose gradient pushes it out is held there for the iteration,
    the others take the damped Gauss-Newton step, which is then clipped onto the box.
    Marquardt's scaling (diag J'J), Nielsen's update of the damping.  A trial point where f
    raises FitError (the model's run fails there) is a rejected step; at the start it is the
    fit's error.  Returns (x, r, J, extra, iterations, why, converged)."""
    x = np.clip(np.asarray(x0, dtype=float), lo, hi)
    r, J, extra = f(x)
    cost = 0.5 * float(r @ r)
    A, g = J.T @ J, J.T @ r
    mu, nu = 1e-3, 2.0  # (relative to Marquardt's scaling D = diag J'J)
    why, converged = f"stopped after {max_iter} iterations", False
    failed = None  # the last trial run that failed since the last accepted step
    it = 0
    while it < max_iter:
        it += 1
        free = ~(((x <= lo) & (g > 0)) | ((x >= hi) & (g < 0)))
        if not np.any(free) or np.max(np.abs(g[free])) <= gtol * max(1.0, cost):
            why, converged = "the gradient is zero to rounding", True
            break
        if cost == 0.0:
            why, converged = "the residuals are zero", True
            break
        D = np.maximum(np.diag(A), 1e-300 + 1e-12 * np.max(np.diag(A)))
        step = np.zeros_like(x)  # (a parameter held on its bound does not move)
        Af = A[np.ix_(free, free)] + mu * np.diag(D[free])
        try:
            step[free] = np.linalg.solve(Af, -g[free])
        except np.linalg.LinAlgError:
            mu, nu = mu * nu, nu * 2
            continue
        xn = np.clip(x + step, lo, hi)
        dx = xn - x
        if np.all(np.abs(dx) <= xtol * (np.abs(x) + xtol)):
            if failed is not None:  # (shrunk by runs that fail, not by the cost)
                raise failed
            why, converged = f"the step is below {xtol:g} relative", True
            break
        try:
            rn, Jn, extra_n = f(xn)
        except FitError as error:  # (a trial point where the model cannot run: a shorter
            failed = error         #  step, unless the damping runs out)
            mu, nu = mu * nu, nu * 2
            if not math.isfinite(mu) or mu > 1e300:
                raise failed
            continue
        cn = 0.5 * float(rn @ rn)
        predicted = -(g @ dx) - 0.5 * float(dx @ (A @ dx))
        rho = (cost - cn) / predicted if predicted > 0 else -1.0
        if rho > 0 and cn < cost:
            failed = None
            reduction = (cost - cn) / cost
            x, r, J, extra, cost = xn, rn, Jn, extra_n, cn
            A, g = J.T @ J, J.T @ r
            mu *= max(1 / 3, 1 - (2 * rho - 1) ** 3)
            nu = 2.0
            if reduction <= ftol:
                why, converged = f"the cost fell by less than {ftol:g} relative", True
                break
        else:
            mu, nu = mu * nu, nu * 2
            if not math.isfinite(mu) or mu > 1e300:
                why, converged = "no step reduces the cost (the damping overflowed)", True
                break
    return x, r, J, extra, it, why, converged


def fit(model, data, vary, scene=None, params=None, backend="c", algebra="auto",
        max_iter=100, effects=None, on_build=None, **options) -> Fit:
    """Estimate the parameters `vary` (names, or "k=LO..HI" texts, or Vary) of model's scene
    from the measured CSV `data` (a path, or a Data): its columns are matched to the model's
    variables by name (the scene's outputs are replaced by them), the time column is `t`,
    and the samples lie on a uniform grid from the scene's start.  params: fixed overrides;
    effects: the effects in, replacing the scene's; options: solver, rtol, atol, max_steps,
    ... as bgc.simulate's (t_end and dt come from the data), inputs= ({name: (t, values)})
    the data of the model's declared inputs the runs follow; on_build(compiled), if given,
    is called once the model is compiled, before any run (the command line checks its
    outputs against the files the model read).  Raises api's errors, FitArgumentError,
    FitError."""
    data = data if isinstance(data, Data) else read_data(data)
    vary = [v if isinstance(v, Vary) else parse_vary(v) for v in vary]
    if not vary:
        raise FitArgumentError("nothing to fit: name a parameter with --vary")
    names = tuple(v.name for v in vary)
    fixed = dict(params or {})
    both = [n for n in names if n in fixed]
    if both:
        raise FitArgumentError(f"'{both[0]}' is both varied and fixed (-p)")
    outputs = ", ".join(data.columns)
    inputs = options.pop("inputs", None)
    compiled = build(model, names, scene, tuple(fixed), False, algebra, outputs, effects,
                     options.get("project_initial", False),
                     options.get("allow_inconsistent", False),
                     option_names=("--data columns", "--effects", "--scene"))
    if on_build is not None:
        on_build(compiled)
    program = compiled.program
    N, P = data.y.size, len(names)
    if N <= P:
        raise FitArgumentError(f"{data.path}: too few samples: {N} measured values for {P} "
                               f"parameters (more are needed for the errors)")
    dt, t_end, rows = _grid(data, program.scene.t0)
    if inputs is not None:
        options["input_data"] = _input_data(program, inputs)
    try:
        settings = runner.settings_for(program.scene, [p.name for p in program.params],
                                       params=fixed, t_end=t_end, dt=dt, **options)
    except ValueError as error:
        raise FitArgumentError(str(error)) from None
    start = np.array([_default(compiled, n, fixed) for n in names])
    lo = np.array([v.lo for v in vary])
    hi = np.array([v.hi for v in vary])
    model_ = _Model(compiled, backend, data, rows, settings, names, fixed)
    x, r, J, y, iterations, why, converged = levenberg_marquardt(model_, start, lo, hi,
                                                                 max_iter)
    cost = 0.5 * float(r @ r)
    s2 = 2 * cost / (N - P)
    se, corr = np.full(P, math.inf), np.full((P, P), math.nan)
    norms = np.sqrt(np.sum(J * J, axis=0))
    seen = norms > 1e-12 * max(float(np.max(norms)), 1e-300)  # the outputs depend on it
    blind = [n for n, k in zip(names, seen) if not k]
    try:
        keep = np.flatnonzero(seen)
        cov = s2 * np.linalg.inv(J[:, keep].T @ J[:, keep])
        se[keep] = np.sqrt(np.maximum(np.diag(cov), 0.0))
        with np.errstate(invalid="ignore", divide="ignore"):
            corr[np.ix_(keep, keep)] = cov / np.outer(se[keep], se[keep])
    except np.linalg.LinAlgError:
        se[:] = math.inf
        corr[:] = math.nan
        why += "; J'J is singular: the parameters cannot all be told apart by these data"
    if blind:
        why += f"; the outputs do not depend on {', '.join(blind)} (no error for "\
               f"{'it' if len(blind) == 1 else 'them'})"
    q = t_quantile(0.975, N - P)
    at_bound = tuple(n for n, v, a, b in zip(names, x, lo, hi) if v <= a or v >= b)
    return Fit(names, x, start, se, x - q * se, x + q * se, corr, cost, math.sqrt(s2), N,
               iterations, model_.runs, why, converged, at_bound, data.columns, data.t,
               data.y, y)


def _default(compiled, name, fixed) -> float:
    """A parameter's value in the scene (its default, computed from the overrides)."""
    from ..front.graph import var
    from ..ir import as_expr
    values = {}
    for p in compiled.reduced.parameters:
        values[var(p.name)] = as_expr(float(fixed[p.name])) if p.name in fixed else \
            p.expr.xreplace(values)
    v = float(values[var(name)])
    if not math.isfinite(v):
        raise FitArgumentError(f"the starting value of {name} is not finite")
    return v


def plot_residuals(result: Fit, target, fmt: str = "png", units: dict | None = None) -> None:
    """The measured and fitted outputs against time, and the residuals below (matplotlib);
    units: of the outputs by name (bgc.api.units), on the axes where the outputs share one."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, (top, bottom) = plt.subplots(2, 1, sharex=True, figsize=(7, 5.5),
                                      gridspec_kw={"height_ratios": [2, 1]})
    for j, name in enumerate(result.columns):
        dots = top.plot(result.t, result.measured[:, j], ".", ms=2, alpha=0.5,
                        label=f"{name} measured")[0]
        top.plot(result.t, result.fitted[:, j], "-", lw=1.2, color=dots.get_color(),
                 label=f"{name} fitted")
        bottom.plot(result.t, result.fitted[:, j] - result.measured[:, j], ".", ms=2,
                    color=dots.get_color(), label=name)
    top.legend(fontsize=8)
    shared = {(units or {}).get(name) for name in result.columns}
    unit = f" [{shared.pop()}]" if len(shared) == 1 and None not in shared else ""
    top.set_ylabel((result.columns[0] if len(result.columns) == 1 else "outputs") + unit)
    bottom.set_ylabel("fitted - measured" + unit)
    bottom.set_xlabel("time t [s]")
    fig.tight_layout()
    fig.savefig(target, format=fmt)
    plt.close(fig)


__all__ = ["Fit", "FitError", "FitArgumentError", "Sensitivities", "column", "fit",
           "levenberg_marquardt", "read_data", "sensitivities", "t_quantile"]
