"""The stiff solvers (rodas4, rodas5p, radau5, radau9, radau13 and the variable-order radau,
auto's stiff phase) in both runtimes, against closed forms and SciPy: a stiff RC pair, Van der
Pol at mu = 1e5, the orders by step halving in the fixed-step mode, the switch of `auto`, the
counters, failures; and radau5's constants in the registry against the Radau IIA Butcher
matrix (tests/test_radau.py: every stage set against its definition)."""
import contextlib
import functools
import io
import math

import numpy as np
import pytest
import sympy as sp

from bgc.base import solvers
from bgc.base.cache import compile_c
from bgc.base.processes import load_python_module, run_c
from bgc.base.toolchain import have_c_compiler
from bgc.codegen.emit import emit_c, emit_python
from bgc.ir import P, Param, SceneSettings, T, X
from bgc.codegen.lower import explicit_program
from conftest import shared_reference

# Every warning an error, at -O0 (a quarter of -O2's compile time; the same IEEE arithmetic
# under -std=c99 at every level: tests/conftest.py; test_emit builds programs at -O1 to -O3).
STRICT = ("-O0", "-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic")
BACKENDS = ["python"] + (["c"] if have_c_compiler() else [])
STIFF = ["rodas4", "rodas5p", "radau5", "radau"]


# ---------------------------------------------------------------- radau5's constants


def _radau_iia():
    """The Butcher matrix and nodes of Radau IIA of order 5 (Hairer & Wanner II, Table 5.6)."""
    s6 = math.sqrt(6.0)
    A = np.array([[(88 - 7 * s6) / 360, (296 - 169 * s6) / 1800, (-2 + 3 * s6) / 225],
                  [(296 + 169 * s6) / 1800, (88 + 7 * s6) / 360, (-2 - 3 * s6) / 225],
                  [(16 - s6) / 36, (16 + s6) / 36, 1 / 9]])
    return A, np.array([(4 - s6) / 10, (4 + s6) / 10, 1.0])


def test_radau5_constants_transform_the_butcher_matrix():
    (tab,) = solvers.get("radau5").tableau
    assert isinstance(tab, solvers.RadauTableau) and tab.stages == 3
    A, c = _radau_iia()
    # the matrix is the collocation method's: sum_j a_ij c_j^(k-1) = c_i^k / k, k = 1..3
    for k in (1, 2, 3):
        assert np.allclose(A @ c ** (k - 1), c ** k / k, rtol=0, atol=1e-15)
    assert np.abs(np.array(tab.c, dtype=float) - c).max() < 1e-16
    T, Ti = np.array(tab.T, dtype=float), np.array(tab.Ti, dtype=float)
    g, (a,), (b,) = float(tab.gamma), tab.alpha, tab.beta
    a, b = float(a), float(b)
    assert np.abs(T @ Ti - np.eye(3)).max() < 1e-14
    block = np.array([[g, 0, 0], [0, a, -b], [0, b, a]])
    assert np.abs(Ti @ np.linalg.inv(A) @ T - block).max() < 1e-14
    eig = np.linalg.eigvals(np.linalg.inv(A))
    want = np.sort_complex([g, a + 1j * b, a - 1j * b])
    assert np.abs(np.sort_complex(eig) - want).max() < 1e-13
    # the error estimate err = (I - h/gamma J)^-1 (h/gamma) (f0 + sum_j e_j Z_j / h), with
    # Z = h A F, compares with an embedded formula of order 3 on nodes 0, c: the weights
    # (1, A^T e) on (f0, F) annihilate 1, c, c^2, not c^3
    w = A.T @ np.array(tab.e, dtype=float)
    moments = [(1.0 if k == 0 else 0.0) + w @ c ** k for k in range(4)]
    assert np.abs(moments[:3]).max() < 1e-13 and abs(moments[3]) > 0.05


# ---------------------------------------------------------------- models


def _scene(**kw):
    settings = dict(t0=0.0, t_end=5.0, dt=0.05, solver="rodas4", rtol=1e-6, atol=1e-9,
                    step=None)
    settings.update(kw)
    return SceneSettings(**settings)


TAU1, TAU2 = 1e-6, 1.0


def rc_pair():
    """Two RC stages driven by a unit step: x1' = (1 - x1)/tau1, x2' = (x1 - x2)/tau2 from 0,
    time constants 1e-6 s and 1 s.  x1 = 1 - e^(-t/tau1),
    x2 = 1 - (tau2 e^(-t/tau2) - tau1 e^(-t/tau1)) / (tau2 - tau1)."""
    params = (Param("tau1", sp.Float(TAU1)), Param("tau2", sp.Float(TAU2)))
    return explicit_program("rc", ("x1", "x2"), params, ("x1", "x2"), [0, 0],
                            [(1 - X[0]) / P[0], (X[0] - X[1]) / P[1]], [X[0], X[1]], _scene())


def rc_exact(t):
    x1 = 1 - np.exp(-t / TAU1)
    x2 = 1 - (TAU2 * np.exp(-t / TAU2) - TAU1 * np.exp(-t / TAU1)) / (TAU2 - TAU1)
    return np.column_stack([x1, x2])


EPS_VDP = 1e-10  # mu = 1e5


def van_der_pol():
    """Van der Pol in Hairer's scaled form (t the classic time over mu, eps = 1/mu^2):
    y1' = y2, eps y2' = (1 - y1^2) y2 - y1, from (2, -2/3 + 10/81 eps) near the slow manifold;
    the period is about 3 - 2 ln 2 = 1.61."""
    params = (Param("eps", sp.Float(EPS_VDP)),)
    return explicit_program("vdp", ("y1", "y2"), params, ("y1", "y2"),
                            [2, sp.Rational(-2, 3) + sp.Rational(10, 81) * P[0]],
                            [X[1], ((1 - X[0] ** 2) * X[1] - X[0]) / P[0]], [X[0], X[1]],
                            _scene(t_end=2.0, dt=0.02))


@functools.lru_cache(maxsize=None)
def van_der_pol_reference():
    """SciPy's Radau at rtol 1e-10 on 101 points (some seconds: once per test run)."""
    return shared_reference("van_der_pol_radau", _van_der_pol_reference)


def _van_der_pol_reference():
    from scipy.integrate import solve_ivp

    def f(t, y):
        return [y[1], ((1 - y[0] ** 2) * y[1] - y[0]) / EPS_VDP]

    def jac(t, y):
        return [[0.0, 1.0], [(-2 * y[0] * y[1] - 1) / EPS_VDP, (1 - y[0] ** 2) / EPS_VDP]]

    times = np.linspace(0.0, 2.0, 101)
    ref = solve_ivp(f, (0.0, 2.0), [2.0, -2 / 3 + 10 / 81 * EPS_VDP], method="Radau",
                    t_eval=times, jac=jac, rtol=1e-10, atol=1e-10)
    assert ref.status == 0
    return ref.t, ref.y.T


A_FORCED = 2.0


def forced():
    """x' = -a x + sin t, x(0) = 1 (non-autonomous, not stiff):
    x = (1 + 1/(a^2 + 1)) e^(-a t) + (a sin t - cos t)/(a^2 + 1)."""
    params = (Param("a", sp.Float(A_FORCED)),)
    return explicit_program("forced", ("x",), params, ("x",), [1],
                            [-P[0] * X[0] + sp.sin(T)], [X[0]], _scene(t_end=2.0, dt=0.4))


def forced_exact(t):
    a = A_FORCED
    return (1 + 1 / (a * a + 1)) * np.exp(-a * t) + (a * np.sin(t) - np.cos(t)) / (a * a + 1)


def blowup():
    """x' = x^2, x(0) = 1: x = 1/(1 - t), infinite at t = 1."""
    return explicit_program("blowup", ("x",), (), ("x",), [1], [X[0] ** 2], [X[0]],
                            _scene(t_end=2.0, dt=0.1))


# ---------------------------------------------------------------- running


@functools.lru_cache(maxsize=None)
def _built(make, backend):
    program = make()
    if backend == "python":
        return load_python_module(next(iter(emit_python(program).values())))
    return compile_c(next(iter(emit_c(program).values())), flags=STRICT)


def _parse_stats(line):
    counts = dict(part.split("=") for part in line.split()[1:])
    return {k: (float(v) if k in ("stiff_from", "cpu") else int(v)) for k, v in counts.items()}


@functools.lru_cache(maxsize=None)
def _run(make, backend, **options):
    """(t, Y, stats) of a model at these settings in one backend; stats as the stats line
    reads (steps, rejected, rhs, jac, lu, solves and, after a switch, stiff_from).  params:
    ((name, value), ...) overrides."""
    built = _built(make, backend)
    params = dict(options.pop("params", ()))
    if backend == "python":
        st = {}
        out = list(built.rows(params=params, stats=st, **options))
        return (np.array([t for t, _ in out]), np.array([y for _, y in out]),
                _parse_stats(built._stats_line(st)))
    args = ["--stats"]
    for name, value in params.items():
        args += ["-p", f"{name}={value!r}"]
    for name, value in options.items():
        args += ["--" + name.replace("_", "-"), repr(value) if isinstance(value, float) else value]
    code, out, err = run_c(built, [str(a) for a in args])
    assert code == 0, err
    data = np.loadtxt(out.splitlines()[1:], delimiter=",", ndmin=2)
    (line,) = [ln for ln in err.splitlines() if ln.startswith("stats:")]
    return data[:, 0], data[:, 1:], _parse_stats(line)


def _scaled_error(Y, ref):
    """The largest error of each column relative to the column's scale (its largest |value|)."""
    return np.max(np.abs(Y - ref), axis=0) / np.max(np.abs(ref), axis=0)


# ---------------------------------------------------------------- accuracy and work


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("solver", STIFF)
def test_stiff_rc_pair_matches_the_closed_form(backend, solver):
    t, Y, st = _run(rc_pair, backend, solver=solver, t_end=5.0, dt=0.05, rtol=1e-6, atol=1e-9)
    assert len(t) == 101 and t[-1] == 5.0
    assert np.all(_scaled_error(Y, rc_exact(t)) < 1e-5), _scaled_error(Y, rc_exact(t))
    assert 10 < st["steps"] < 150, st
    # counters: the Jacobian, factorisations and solves of each family
    assert st["jac"] > 0 and st["lu"] > 0 and st["solves"] > 0
    attempts = st["steps"] + st["rejected"]
    if solver.startswith("rodas"):  # a Jacobian at every step's start, S stages per attempt
        S = solvers.get(solver).tableau.stages
        assert st["jac"] == st["steps"]
        assert st["lu"] == attempts and st["solves"] == S * attempts
        assert st["rhs"] >= (S - 1) * attempts + st["steps"]
    else:  # per step a Newton iteration (2 solves) and an estimate; radau5 factors pairs
        # (a real and a complex matrix), radau's five and seven stages three and four
        assert st["lu"] % 2 == 0 or solver == "radau"
        assert st["jac"] <= st["lu"] // 2
        assert st["solves"] >= 3 * st["steps"] and st["rhs"] >= 3 * attempts


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("solver", STIFF)
def test_van_der_pol_mu_1e5_matches_scipy(backend, solver):
    """One period and a little more; SciPy's Radau at rtol 1e-10 is the reference.  An rtol of
    1e-6 keeps the error within 5e-5 of each column's scale (measured: 8.6e-6 at most, y2 near
    the jump that ends the period)."""
    tr, ref = van_der_pol_reference()
    t, Y, st = _run(van_der_pol, backend, solver=solver, t_end=2.0, dt=0.02, rtol=1e-6,
                    atol=1e-6)
    assert np.allclose(t, tr, rtol=0, atol=1e-12)
    assert ref[:, 0].min() < -1.9 and ref[-1, 0] > 1.5  # over a period: both branches
    err = _scaled_error(Y, ref)
    assert np.all(err < 5e-5), err
    assert st["jac"] > 0 and st["lu"] > 0 and st["solves"] >= 3 * st["steps"]
    assert st["steps"] < 3000, st
    if solver == "radau5":
        # loose tolerances: Radau IIA's step error lies far below its estimate, so the error
        # stays under rtol / 3 -- unless Newton stops short (after one iteration, on a
        # contraction rate the step's new matrices need not have): then 7.6e-2 at rtol 1e-2
        # and 2.3e-3 at 1e-3.  Measured now: 9.1e-4 and 7.9e-5.
        for rtol in (1e-2, 1e-3):
            _, Y, _ = _run(van_der_pol, backend, solver=solver, t_end=2.0, dt=0.02, rtol=rtol,
                           atol=rtol * 1e-3)
            assert np.all(_scaled_error(Y, ref) < rtol / 3), (rtol, _scaled_error(Y, ref))


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("solver, steps, dt", [
    ("rodas4", (0.2, 0.1, 0.05), 0.4), ("rodas5p", (0.2, 0.1, 0.05), 0.4),
    ("radau5", (0.4, 0.2, 0.1), 0.4), ("radau9", (1.0, 0.5, 0.25), 1.0),
    ("radau13", (2.0, 1.0), 2.0)])
def test_order_by_step_halving(backend, solver, steps, dt):
    """The fixed-step mode (--step): outputs at step ends (dt a multiple of the step), no error
    control; the error at the outputs shrinks by 2^order as the step halves (measured
    4.02 .. 4.07 for rodas4, 4.93 .. 4.99 for radau5, 8.96 .. 9.05 for radau9, 13.09 for
    radau13, whose next halving reaches rounding).  The right side reads t: rodas4's df/dt
    term is part of its order."""
    order = solvers.get(solver).order
    errors = []
    for h in steps:
        t, Y, st = _run(forced, backend, solver=solver, t_end=2.0, dt=dt, step=h, rtol=1e-12,
                        atol=1e-12)
        assert st["steps"] == round(2.0 / h) and st["rejected"] == 0
        errors.append(np.max(np.abs(Y[:, 0] - forced_exact(t))))
    observed = [math.log2(a / b) for a, b in zip(errors, errors[1:])]
    assert all(abs(p - order) < 0.25 for p in observed), (errors, observed)


@pytest.mark.parametrize("backend", BACKENDS)
def test_variable_order_radau_with_a_fixed_step_runs_its_first_stage_set(backend):
    """radau's fixed-step mode is radau5's: the same rows, bit for bit in one backend."""
    runs = [_run(forced, backend, solver=name, t_end=2.0, dt=0.4, step=0.1, rtol=1e-12,
                 atol=1e-12) for name in ("radau", "radau5")]
    counts = [{k: v for k, v in st.items() if k != "cpu"} for _, _, st in runs]
    assert np.array_equal(runs[0][1], runs[1][1]) and counts[0] == counts[1]


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("solver", STIFF)
def test_error_follows_the_tolerance(backend, solver):
    """Adaptive runs on the non-autonomous problem: the error over the output grid (mostly
    dense output) falls with the tolerance and stays within a small multiple of it (measured:
    at most 9 times the tolerance, radau5 at 1e-8)."""
    errors = []
    tolerances = (1e-4, 1e-6, 1e-8)
    for tol in tolerances:
        t, Y, _ = _run(forced, backend, solver=solver, t_end=2.0, dt=0.05, rtol=tol, atol=tol)
        errors.append(np.max(np.abs(Y[:, 0] - forced_exact(t))))
    assert errors[0] > errors[1] > errors[2], errors
    assert all(e < 30 * tol for e, tol in zip(errors, tolerances)), errors


@pytest.mark.parametrize("backend", BACKENDS)
def test_auto_switches_to_radau_on_the_rc_pair(backend):
    t, Y, st = _run(rc_pair, backend, solver="auto", t_end=5.0, dt=0.05, rtol=1e-6, atol=1e-9)
    assert "stiff_from" in st and 0.0 < st["stiff_from"] < 0.01, st
    assert np.all(_scaled_error(Y, rc_exact(t)) < 1e-5), _scaled_error(Y, rc_exact(t))
    assert st["jac"] > 0 and st["lu"] > 0 and st["steps"] < 200, st
    # its stiff phase, radau alone, takes about the steps after the switch (the test fires
    # after 15 stiff-looking explicit steps; measured: 58 steps, radau alone 25)
    assert st["steps"] < 40 + _run(rc_pair, backend, solver="radau", t_end=5.0, dt=0.05,
                                   rtol=1e-6, atol=1e-9)[2]["steps"]


def test_backends_agree():
    """Byte parity: the Python runtime does the C runtime's floating-point operations in C's
    order (its LU factors, sums in sequence, libm's functions), so the two write the same CSV
    bytes and count the same steps, even where Van der Pol's jumps would amplify a rounding
    difference into other steps (docs/solvers.md)."""
    if "c" not in BACKENDS:
        pytest.skip("no C compiler")
    exe, module = _built(van_der_pol, "c"), _built(van_der_pol, "python")
    for solver in STIFF + ["radau9", "radau13"]:
        argv = ["--solver", solver, "--t-end", "2.0", "--dt", "0.02", "--rtol", "1e-6",
                "--atol", "1e-6", "--stats"]
        code, c_out, c_err = run_c(exe, argv)
        out, err = io.StringIO(), io.StringIO()
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            assert module.main(argv) == code == 0
        assert out.getvalue() == c_out, solver
        counters = [[w for w in e.split() if not w.startswith("cpu=")]
                    for e in (c_err, err.getvalue())]
        assert counters[0] == counters[1], (solver, c_err, err.getvalue())


# ---------------------------------------------------------------- failures


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("solver", STIFF)
def test_blow_up_fails_with_step_size_too_small(backend, solver):
    message, t_fail = _failure(blowup, backend, solver=solver, t_end=2.0, dt=0.1)
    assert "step size too small" in message and "state 'x'" in message, message
    assert abs(t_fail - 1.0) < 1e-6


@pytest.mark.parametrize("backend", BACKENDS)
def test_radau5_fixed_step_newton_failure_is_reported(backend):
    """x' = x^2 from 1 with a step of 0.5: the stage equations have no solution near the
    start, Newton cannot converge (even with a fresh Jacobian) and the run stops."""
    message, t_fail = _failure(blowup, backend, solver="radau5", t_end=2.0, dt=0.1, step=0.5)
    assert "Newton iteration does not converge" in message and "fixed step" in message
    assert t_fail == 0.0


def growth():
    """x' = lam x, x(0) = 1."""
    return explicit_program("growth", ("x",), (Param("lam", sp.Integer(1)),), ("x",), [1],
                            [P[0] * X[0]], [X[0]], _scene(t_end=2.0, dt=0.5))


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("solver", STIFF)
def test_singular_iteration_matrix_is_reported(backend, solver):
    """Fixed steps of 0.5 on x' = lam x with lam = gamma/h, the eigenvalue that makes the
    iteration matrix (gamma/h I - J: rodas4's 1/(gamma h) I - J) exactly singular."""
    tab = solvers.get(solver).tableau
    gamma = float((tab[0] if isinstance(tab, tuple) else tab).gamma)  # radau: its first set
    lam = 1.0 / (gamma * 0.5) if solver.startswith("rodas") else gamma / 0.5
    message, t_fail = _failure(growth, backend, solver=solver, t_end=2.0, dt=0.5, step=0.5,
                               params={"lam": lam})
    assert "iteration matrix is singular" in message and solver in message, message
    assert t_fail == 0.0
    # the same run with another step goes through
    _run(growth, backend, solver=solver, t_end=2.0, dt=0.5, step=0.25, params=(("lam", lam),))


def _failure(make, backend, **options):
    built = _built(make, backend)
    if backend == "python":
        with pytest.raises(built.SimulationError) as info:
            built.simulate(**options)
        return str(info.value), info.value.t
    args = []
    for name, value in options.pop("params", {}).items():
        args += ["-p", f"{name}={value!r}"]
    for name, value in options.items():
        args += ["--" + name.replace("_", "-"), repr(value) if isinstance(value, float) else value]
    code, _, err = run_c(built, [str(a) for a in args])
    assert code == 3, err
    message = err.strip()
    return message, float(message.split("at t = ")[1].split(":")[0])


def _c_stiff_lu_is_singular(E) -> bool:
    """bgc_stiff_lu / bgc_stiff_zlu of bgc/runtime/stiff.c, transcribed loop for loop in plain
    Python floats: True when a column has no nonzero pivot."""
    a = [list(row) for row in E]
    n = len(a)
    size = (lambda v: abs(v.real) + abs(v.imag)) if a and isinstance(a[0][0], complex) else abs
    for k in range(n):
        big, p = size(a[k][k]), k
        for i in range(k + 1, n):
            if size(a[i][k]) > big:
                big, p = size(a[i][k]), i
        if big == 0.0:
            return True
        a[k], a[p] = a[p], a[k]
        for i in range(k + 1, n):
            l = a[i][k] / a[k][k]
            a[i][k] = l
            if l != 0.0:
                for j in range(k + 1, n):
                    a[i][j] -= l * a[k][j]
    return False


def test_python_runtime_finds_singular_iteration_matrices_as_c_does():
    """The Python runtime's factorisation (_lu, _zlu) is the C runtime's: on random real
    matrices with zeros, repeated rows, 1e308, 1e-308 and NaN, the same verdict as the C loops
    transcribed above (tests/test_lu.py compares the factors bit for bit with the C runtime's,
    complex ones too)."""
    import random
    module = _built(rc_pair, "python")

    def singular(E):
        if E.dtype.kind == "c":
            return module._zlu(E.real.copy(), E.imag.copy()) is None
        return module._lu(E.copy()) is None

    rng = random.Random(3)
    values = [0.0, 1.0, -1.0, 2.0, 0.5, 1e308, -1e308, 1e-308, float("nan")]
    seen = set()
    for trial in range(3000):
        n = rng.randint(1, 5)
        E = np.array([[rng.choice(values) for _ in range(n)] for _ in range(n)])
        if n > 1 and rng.random() < 0.4:
            E[rng.randrange(n)] = E[rng.randrange(n)]
        with np.errstate(all="ignore"):
            try:
                expected = _c_stiff_lu_is_singular(E.tolist())
            except ZeroDivisionError:  # (a NaN pivot in Python floats; C goes on with NaN)
                continue
            assert singular(E) == expected, E
        seen.add(expected)
    assert seen == {True, False}
    E2 = np.array([[1 + 2j, 0, 3j], [2 - 1j, 0, 1], [0.5j, 0, 2 + 2j]])
    assert singular(E2) and not singular(E2 + np.eye(3))
