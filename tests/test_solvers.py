"""The solver registry (bgc/base/solvers.py) against the order conditions of its methods, and the
explicit family in both runtimes: orders by step halving against closed forms, dense output,
and the work a high-order pair saves on the paper's pendulum (counted, not timed)."""
from fractions import Fraction
from pathlib import Path

import mpmath
import numpy as np
import pytest
import sympy as sp

import bgc
from bgc.base import solvers
from bgc.base.cache import compile_c
from bgc.base.processes import load_python_module, run_c
from bgc.base.toolchain import have_c_compiler
from bgc.codegen.emit import emit_c, emit_python
from bgc.ir import P, Param, SceneSettings, T, X
from bgc.codegen.lower import explicit_program

ROOT = Path(__file__).resolve().parent.parent
BACKENDS = ["python"] + (["c"] if have_c_compiler() else [])
ERK = [s for s in solvers.SOLVER_LIST if isinstance(s.tableau, solvers.ERKTableau)]


# ---------------------------------------------------------------- the registry


def test_names_are_unique_and_families_known():
    assert len(set(solvers.NAMES)) == len(solvers.NAMES)
    assert all(s.family in solvers.FAMILIES for s in solvers.SOLVER_LIST)
    assert solvers.DEFAULT in solvers.SOLVERS
    for s in solvers.SOLVER_LIST:
        if s.family == "auto":
            assert solvers.get(s.explicit).stiffness is not None
            assert solvers.get(s.stiff).uses_jacobian


# The order of each pair's embedded estimates (error, error2) and of its dense output.
EMBEDDED = {"dopri5": (4,), "vern7": (6,), "dop853": (5, 3)}
DENSE = {"dopri5": 4, "vern7": 7, "dop853": 7}


def _grown(tree):
    """The trees with one node more than `tree`: a new leaf on each of its nodes.  A tree is
    the sorted tuple of its root's subtrees (a single node is ())."""
    yield tuple(sorted(tree + ((),)))
    for k, sub in enumerate(tree):
        for bigger in _grown(sub):
            yield tuple(sorted(tree[:k] + (bigger,) + tree[k + 1:]))


def _trees(order):
    """Butcher's rooted trees with 1 .. order nodes, by number of nodes."""
    trees = [[()]]
    while len(trees) < order:
        trees.append(sorted({bigger for tree in trees[-1] for bigger in _grown(tree)}))
    return trees


def _density(tree):
    """gamma(t): the tree's number of nodes times its subtrees' densities."""
    g = _nodes(tree)
    for sub in tree:
        g *= _density(sub)
    return g


def _nodes(tree):
    return 1 + sum(_nodes(sub) for sub in tree)


class _Conditions:
    """Butcher's order conditions of an explicit tableau (its dense output's extra stages
    included), in exact arithmetic: weights w satisfy the condition of tree t when
    sum_i w_i Phi_i(t) = 1/gamma(t), Phi_i(t) the product over the root's subtrees u of
    sum_j a_ij Phi_j(u)."""

    def __init__(self, tab):
        rows = tab.a + tab.extra_a
        self.stages = len(rows)
        self.rows = [[(j, a) for j, a in enumerate(row) if a] for row in rows]
        self.phis, self.products = {(): [Fraction(1)] * self.stages}, {}

    def phi(self, tree):
        if tree not in self.phis:
            phi = [Fraction(1)] * self.stages
            for sub in tree:
                phi = [u * v for u, v in zip(phi, self.product(sub))]
            self.phis[tree] = phi
        return self.phis[tree]

    def product(self, tree):
        """A Phi(tree)."""
        if tree not in self.products:
            phi = self.phi(tree)
            self.products[tree] = [sum(a * phi[j] for j, a in row) for row in self.rows]
        return self.products[tree]

    def weigh(self, weights, tree):
        return sum(w * p for w, p in zip(weights, self.phi(tree)))

    def defects(self, weights, order):
        """sum_i w_i Phi_i(t) - 1/gamma(t) for every tree of 1 .. order nodes."""
        weights = list(weights) + [0] * (self.stages - len(weights))
        return [self.weigh(weights, t) - Fraction(1, _density(t))
                for trees in _trees(order) for t in trees]

    def dense_defects(self, P, order):
        """y(theta) = y0 + h sum_i b_i(theta) k_i is of order `order` when
        sum_i b_i(theta) Phi_i(t) = theta^|t| / gamma(t) for every theta and every tree of
        1 .. order nodes: the defect of each power of theta, theta .. theta^degree."""
        out = []
        for d in range(len(P[0])):
            weights = [row[d] for row in P]
            for n, trees in enumerate(_trees(order), 1):
                out += [self.weigh(weights, t) - (Fraction(1, _density(t)) if d + 1 == n else 0)
                        for t in trees]
        return out


def test_rooted_trees():
    """1, 1, 2, 4, 9, 20, 48, 115 trees of 1 .. 8 nodes (85 through order 7), each once."""
    trees = _trees(8)
    assert [len(t) for t in trees] == [1, 1, 2, 4, 9, 20, 48, 115]
    assert sum(len(t) for t in trees[:7]) == 85
    assert all(_nodes(t) == n for n, ts in enumerate(trees, 1) for t in ts)
    assert trees[2] == [((), ()), (((),),)]  # [., .] and [[.]]
    assert [_density(t) for t in trees[2]] == [3, 6]


@pytest.mark.parametrize("solver", ERK, ids=lambda s: s.name)
def test_explicit_tableaus_satisfy_their_conditions(solver):
    """Every rooted-tree condition through the method's order for b, through the estimates'
    orders for the embedded weights b - e, through the dense output's order for each power
    of theta: defects below 1e-14 (the decimal coefficients have 16 to 40 digits; the exact
    zeros of Verner's rational pair are checked below)."""
    tab = solver.tableau
    conditions = _Conditions(tab)
    # the nodes are the row sums (stages and the dense output's extra stages)
    for ci, row in zip(tab.c + tab.extra_c, tab.a + tab.extra_a):
        assert abs(float(ci - sum(row))) < 1e-14
    assert max(abs(float(d)) for d in conditions.defects(tab.b, solver.order)) < 1e-14
    for e, order in zip((tab.error, tab.error2), EMBEDDED.get(solver.name, ())):
        embedded = [b - ei for b, ei in zip(tab.b, e)]
        assert max(abs(float(d)) for d in conditions.defects(embedded, order)) < 1e-14
        # ... and no more: the estimate measures the error of order + 1
        assert max(abs(float(d)) for d in conditions.defects(embedded, order + 1)) > 1e-6
    if tab.error:  # an embedded estimate compares two solutions: its weights sum to zero
        assert abs(float(sum(tab.error))) < 1e-14
    if tab.fsal:  # the last stage is f(t + h, y1)
        assert tab.c[-1] == 1 and tuple(tab.a[-1]) == tuple(tab.b[:-1])
    if tab.dense:  # y(t + h) from the dense output is y1: sum_j P[i][j] = b_i
        for i, row in enumerate(tab.dense):
            bi = tab.b[i] if i < len(tab.b) else 0
            assert abs(float(sum(row) - bi)) < 1e-14
        defects = conditions.dense_defects(tab.dense, DENSE[solver.name])
        assert max(abs(float(d)) for d in defects) < 1e-14


def test_vern7_pair_is_exact():
    """Verner's rational pair satisfies its conditions exactly: the 85 of order 7 for b, the 37
    of order 6 for the embedded weights; its interpolant, at a few theta, to the 36 digits of
    its extra stages."""
    tab = solvers.get("vern7").tableau
    conditions = _Conditions(tab)
    assert all(tab.c[i] == sum(tab.a[i]) for i in range(tab.stages))
    defects = conditions.defects(tab.b, 7)
    assert len(defects) == 85 and not any(defects)
    assert not any(conditions.defects([b - e for b, e in zip(tab.b, tab.error)], 6))
    for theta in (Fraction(1, 5), Fraction(1, 2), Fraction(9, 10)):
        weights = [sum(p * theta ** (j + 1) for j, p in enumerate(row)) for row in tab.dense]
        for n, trees in enumerate(_trees(7), 1):
            for t in trees:
                defect = conditions.weigh(weights, t) - theta ** n / _density(t)
                assert abs(float(defect)) < 1e-30


def _rosenbrock_stability(tab, z):
    """R(z) of a Rosenbrock method in Hairer's transformed form on y' = lambda y (exact
    Jacobian), z = h lambda: (1/gamma - z) k_i = z (1 + sum_j a_ij k_j) + sum_j C_ij k_j."""
    g = float(tab.gamma)
    k = []
    for i in range(tab.stages):
        arg = 1 + sum(float(a) * kj for a, kj in zip(tab.a[i], k))
        k.append((z * arg + sum(float(c) * kj for c, kj in zip(tab.C[i], k))) / (1 / g - z))
    return 1 + sum(float(m) * kj for m, kj in zip(tab.m, k)), sum(float(e) * kj
                                                                   for e, kj in zip(tab.e, k))


def test_rodas4_is_of_order_4_and_l_stable():
    tab = solvers.get("rodas4").tableau
    assert tab.m == tab.a[-1] + (Fraction(1),)  # stiffly accurate: y1 = Y_6 + k_6
    # R(z) - e^z = O(z^5): the defect falls by 2^5 when z halves
    d = [abs(_rosenbrock_stability(tab, z)[0] - np.exp(z)) for z in (0.1, 0.05)]
    assert 2 ** 4.7 < d[0] / d[1] < 2 ** 5.3, d
    # L-stable: R(z) -> 0 as z -> -inf; A-stable along the imaginary axis
    assert abs(_rosenbrock_stability(tab, -1e10)[0]) < 1e-8
    assert all(abs(_rosenbrock_stability(tab, 1j * w)[0]) <= 1 + 1e-12
               for w in (0.1, 1.0, 10.0, 1e3, 1e6))



ROSENBROCK = [s for s in solvers.SOLVER_LIST if isinstance(s.tableau, solvers.RosenbrockTableau)]
# The order of each Rosenbrock method's embedded estimate and of its dense output.
ROS_EMBEDDED = {"ros2": 1, "rodas4": 3, "rodas5p": 4}
ROS_DENSE = {"ros2": 2, "rodas4": 3, "rodas5p": 4}


def _classical(tab):
    """The transformed tableau back in the classical form, in 40-digit arithmetic: Gamma =
    (diag(1/gamma) - C)^-1, alpha = a Gamma, b = m Gamma, b_hat = (m - e) Gamma; the dense
    output's weights on the stages, b(theta) = w(theta) Gamma, w(theta) = theta m + sum_r
    (theta^r - theta^(r+1)) H_r, as coefficients of theta, theta^2, ..."""
    s, mpf = tab.stages, lambda q: mpmath.mpf(q.numerator) / q.denominator
    Gi, am = mpmath.zeros(s, s), mpmath.zeros(s, s)
    for i in range(s):
        Gi[i, i] = 1 / mpf(tab.gamma)
        for j in range(i):
            Gi[i, j], am[i, j] = -mpf(tab.C[i][j]), mpf(tab.a[i][j])
    G = Gi ** -1
    row = lambda w: list(mpmath.matrix([list(w)]) * G)  # noqa: E731
    m = [mpf(q) for q in tab.m]
    P = [[mpmath.mpf(0)] * s for _ in range(len(tab.dense) + 1)]
    P[0] = list(m)
    for r, H in enumerate(tab.dense):
        for j, h in enumerate(H):
            P[r][j] += mpf(h)
            P[r + 1][j] -= mpf(h)
    return (am * G, G, row(m), row(u - mpf(e) for u, e in zip(m, tab.e)),
            [row(w) for w in P])


def _ros_defects(alpha, G, weights, order):
    """Rosenbrock order conditions (exact Jacobian): sum_i w_i Phi_i(t) = 1/gamma(t), Phi as
    for Runge-Kutta with alpha, except that a node with exactly one son uses alpha + Gamma;
    the defects of the trees of exactly `order` nodes."""
    s, B, memo = len(weights), alpha + G, {}

    def phi(t):
        if t not in memo:
            v = [mpmath.mpf(1)] * s
            for sub in t:
                M, u = B if len(t) == 1 else alpha, phi(sub)
                v = [v[i] * mpmath.fsum(M[i, j] * u[j] for j in range(s)) for i in range(s)]
            memo[t] = v
        return memo[t]
    return [mpmath.fsum(w * p for w, p in zip(weights, phi(t))) - mpmath.mpf(1) / _density(t)
            for t in _trees(order)[order - 1]]


@pytest.mark.parametrize("solver", ROSENBROCK, ids=lambda s: s.name)
def test_rosenbrock_tableaus_satisfy_their_conditions(solver):
    """Back in the classical form, in 40 digits: c_i = sum_j alpha_ij and d_i = sum_j gamma_ij;
    the solution's conditions through the method's order, the embedded estimate's through its
    order, the dense output's through its order (each power of theta), with defects below
    1e-12 (the coefficients have 16 or 17 digits), and the first order beyond clearly
    violated."""
    tab, name = solver.tableau, solver.name
    with mpmath.workdps(40):
        alpha, G, b, b_hat, P = _classical(tab)
        s = tab.stages
        for i in range(s):
            assert abs(mpmath.fsum(alpha[i, j] for j in range(s)) - mpmath.mpf(float(tab.c[i]))) < 1e-14
            assert abs(mpmath.fsum(G[i, j] for j in range(s)) - mpmath.mpf(float(tab.d[i]))) < 1e-14
        for weights, order in ((b, solver.order), (b_hat, ROS_EMBEDDED[name])):
            assert max(abs(d) for n in range(1, order + 1)
                       for d in _ros_defects(alpha, G, weights, n)) < 1e-12
            assert max(abs(d) for d in _ros_defects(alpha, G, weights, order + 1)) > 1e-4
        order = ROS_DENSE[name]
        for n in range(1, order + 2):
            defects = []
            for k, w in enumerate(P):  # the coefficient of theta^(k+1)
                ds = _ros_defects(alpha, G, w, n)
                defects += [d + (mpmath.mpf(1) / _density(t) if k + 1 != n else 0)
                            for d, t in zip(ds, _trees(n)[n - 1])]
            big = max(abs(d) for d in defects)
            assert (big < 1e-12) if n <= order else (big > 1e-4), (n, big)


@pytest.mark.parametrize("solver", ROSENBROCK, ids=lambda s: s.name)
def test_rosenbrock_stability(solver):
    """R(z) = 1 + z b^T (I - z (alpha + Gamma))^-1 1 = 1 + sum_k z^(k+1) b^T B^k 1 matches e^z
    through z^p (ros2: p = 2; rodas4: p = 4; rodas5p: p = 6, one more than its order), in 40
    digits; L-stable: R(z) -> 0 as z -> -inf (rodas4, rodas5p: stiffly accurate; ros2: by its
    gamma, the root of gamma^2 - 2 gamma + 1/2 that makes R's numerator of degree 1), and
    |R(iy)| <= 1 on the imaginary axis."""
    tab = solver.tableau
    p = {"ros2": 2, "rodas4": 4, "rodas5p": 6}[solver.name]
    with mpmath.workdps(40):
        alpha, G, b, _, _ = _classical(tab)
        v, B = mpmath.matrix([1] * tab.stages), alpha + G
        for k in range(p + 1):
            defect = mpmath.fsum(u * w for u, w in zip(b, v)) - 1 / mpmath.factorial(k + 1)
            assert (abs(defect) < 1e-13) if k < p else (abs(defect) > 1e-6), (k, defect)
            v = B * v
    if solver.name != "ros2":
        assert tab.m == tab.a[-1] + (Fraction(1),)  # stiffly accurate: y1 = Y_s + k_s
    assert abs(_rosenbrock_stability(tab, -1e10)[0]) < 1e-8
    assert all(abs(_rosenbrock_stability(tab, 1j * w)[0]) <= 1 + 1e-12
               for w in np.logspace(-3, 8, 89))


# ---------------------------------------------------------------- models with closed forms


def _program(name, states, params, outputs, init, rhs, out, **scene):
    settings = dict(t0=0.0, t_end=2.0, dt=0.1, solver="dopri5", rtol=1e-6, atol=1e-9, step=None)
    settings.update(scene)
    return explicit_program(name, states, params, outputs, init, rhs, out,
                            SceneSettings(**settings))


def forced_decay():
    """x' = -a x + sin(w t), x(0) = x0 (non-autonomous): the closed form as an output."""
    a, w, x0 = P[0], P[1], P[2]
    params = (Param("a", sp.Float(0.7)), Param("w", sp.Integer(3)), Param("x0", sp.Integer(2)))
    exact = ((x0 + w / (a ** 2 + w ** 2)) * sp.exp(-a * T)
             + (a * sp.sin(w * T) - w * sp.cos(w * T)) / (a ** 2 + w ** 2))
    return _program("forced", ("x",), params, ("x", "exact"), [x0], [-a * X[0] + sp.sin(w * T)],
                    [X[0], exact])


def oscillator():
    """x'' = -4 x, x(0) = 1: x = cos 2t, v = -2 sin 2t."""
    return _program("osc", ("x", "v"), (Param("k", sp.Integer(4)),), ("x", "v", "xe", "ve"),
                    [1, 0], [X[1], -P[0] * X[0]], [X[0], X[1], sp.cos(2 * T), -2 * sp.sin(2 * T)])


_CACHE = {}


def run(program, backend, **options):
    """(t, Y) of the program at these settings, in one backend."""
    key = (id(program), backend)
    if backend == "python":
        if key not in _CACHE:
            _CACHE[key] = (program, load_python_module(next(iter(emit_python(program).values()))))
        return _CACHE[key][1].simulate(**options)
    if key not in _CACHE:
        _CACHE[key] = (program, compile_c(next(iter(emit_c(program).values()))))
    args = []
    for name, value in options.items():
        args += ["--" + name.replace("_", "-"), repr(value) if isinstance(value, float) else value]
    code, out, err = run_c(_CACHE[key][1], [str(a) for a in args])
    assert code == 0, err
    data = np.loadtxt(out.splitlines()[1:], delimiter=",", ndmin=2)
    return data[:, 0], data[:, 1:]


FORCED, OSC = forced_decay(), oscillator()


def _error(program, backend, **options):
    _, Y = run(program, backend, **options)
    half = Y.shape[1] // 2
    return np.max(np.abs(Y[:, :half] - Y[:, half:]))


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("name, steps", [("euler", (0.02, 0.01)), ("rk4", (0.1, 0.05)),
                                         ("dopri5", (0.2, 0.1)), ("vern7", (0.4, 0.2)),
                                         ("dop853", (0.4, 0.2))])
def test_order_by_step_halving(backend, name, steps):
    """Fixed steps (--step; for the adaptive pairs without error control): the error at the
    output times shrinks by 2^order when the step halves.  Outputs at the step ends only
    (dt a multiple of the step), so the dense output does not enter."""
    order = solvers.get(name).order
    errors = [_error(FORCED, backend, t_end=2.0, dt=0.4, solver=name, step=h) for h in steps]
    ratio = errors[0] / errors[1]
    assert 2 ** (order - 0.3) < ratio < 2 ** (order + 0.5), (errors, np.log2(ratio))


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("name, degree", sorted(DENSE.items()))
def test_dense_output_order(backend, name, degree):
    """Outputs between the steps come from the continuous extension: with fixed steps and
    outputs inside them, the error shrinks at least as 2^(degree) on halving (the local error
    of the extension is O(h^(degree+1)))."""
    errors = [_error(OSC, backend, t_end=2.0, dt=0.1, solver=name, step=h)
              for h in (0.4 / 3, 0.2 / 3)]
    assert errors[0] / errors[1] > 2 ** (degree - 0.5), errors


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("name", ["dopri5", "vern7", "dop853"])
def test_error_follows_the_tolerance(backend, name):
    """Adaptive runs: the error over the output grid falls as the tolerance tightens and
    stays within a small multiple of it."""
    errors = [_error(FORCED, backend, t_end=5.0, dt=0.05, solver=name, rtol=tol, atol=tol)
              for tol in (1e-5, 1e-7, 1e-9, 1e-11)]
    assert all(a > b for a, b in zip(errors, errors[1:])), errors
    assert errors[-1] < 1e-9


def test_backends_take_the_same_steps():
    if "c" not in BACKENDS:
        pytest.skip("no C compiler")
    for name in ("dopri5", "vern7", "dop853"):
        options = dict(t_end=5.0, dt=0.05, solver=name, rtol=1e-8, atol=1e-10)
        (tc, yc), (tp, yp) = run(FORCED, "c", **options), run(FORCED, "python", **options)
        assert np.array_equal(tc, tp)
        assert np.allclose(yc, yp, rtol=1e-13, atol=1e-15)


def _pendulum_work():
    """work(solver, tol, dt): the paper's pendulum (scene swing: 0..10 s, outputs every dt,
    0.01 s unless given) in the Python backend, as (error at the final time, largest error
    over the output grid, right-side calls); errors in x and y against eq. (12) integrated by
    SciPy's DOP853 at rtol 1e-13."""
    from test_simulate import pendulum_reference

    compiled = bgc.build(ROOT / "models" / "pendulum.bg", "swing")
    module = load_python_module(next(iter(emit_python(compiled.program).values())))
    references = {}

    def work(solver, tol, dt=None):
        st = {}
        rows = np.array([(t, y[0], y[1]) for t, y in
                         module.rows(solver=solver, rtol=tol, atol=tol, dt=dt, stats=st)])
        if dt not in references:
            references[dt] = np.array(pendulum_reference(rows[:, 0])[:2]).T
        err = np.max(np.abs(rows[:, 1:] - references[dt]), axis=1)
        return err[-1], err.max(), st["rhs"]

    return work


def _calls_for(runs, column, target):
    """The calls a pair needs for the error `target`, read off its work-precision line (log
    calls on log error, least squares over its runs' error in `column`); `target` within the
    runs' errors (interpolated, not extrapolated)."""
    errors = runs[:, column]
    assert errors.min() < target < errors.max(), (target, runs)
    slope, intercept = np.polyfit(np.log(errors), np.log(runs[:, 2]), 1)
    return np.exp(intercept + slope * np.log(target))


def test_dop853_halves_the_work_on_the_pendulum():
    """The issue's bar: on the paper's pendulum dopri5 at rtol 1e-10 reaches some error; the
    high-order pair reaches that error with at most half of its right-side calls, read off its
    work-precision line over tolerances in quarter decades.  The error at the final time (a
    step end) is the bar; over the whole output grid the pair's order-7 interpolant costs it a
    little more (0.51x measured when this was written): held to 0.55x."""
    work = _pendulum_work()
    final, grid, calls = work("dopri5", 1e-10)
    runs = np.array([work("dop853", 10 ** (-k / 4)) for k in range(34, 44)])
    for column, target, bound in ((0, final, 0.5), (1, grid, 0.55)):
        needed = _calls_for(runs, column, target)
        assert needed <= bound * calls, (column, target, calls, needed, runs)


def test_vern7_work_on_the_pendulum():
    """vern7 against dopri5 at rtol 1e-10, as above.  Its steps alone (outputs at the final
    time only) take 0.37x dopri5's calls (dop853: 0.33x); at the scene's 0.01 s outputs every
    step holds an output time and its order-7 interpolant adds five calls to the step's ten,
    so it needs 0.56x dopri5's calls for dopri5's final-time error and 0.60x for its error over
    the grid (dop853, with three extra stages and fewer steps: 0.40x and 0.51x), measured when
    this was written: held to 0.5x, 0.6x and 0.65x."""
    work = _pendulum_work()
    runs = {dt: np.array([work("vern7", 10 ** (-k / 4), dt) for k in range(30, 40)])
            for dt in (None, 10.0)}
    final, grid, calls = work("dopri5", 1e-10)
    for column, target, bound in ((0, final, 0.6), (1, grid, 0.65)):
        needed = _calls_for(runs[None], column, target)
        assert needed <= bound * calls, (column, target, calls, needed, runs[None])
    final, _, calls = work("dopri5", 1e-10, 10.0)
    needed = _calls_for(runs[10.0], 0, final)
    assert needed <= 0.5 * calls, (final, calls, needed, runs[10.0])
