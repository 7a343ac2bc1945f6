"""Algebraic blocks solved in the generated code, the emitted Jacobian, and scale.

Every reference here is computed independently of bgc, inside the test:
- the N-link pendulum chain in minimal (angle) coordinates: its mass matrix and forces from the
  Lagrangian, typed by hand, integrated with SciPy's DOP853 at rtol 1e-12;
- algebraic loops (a diode, a resistor law with no inverse) solved at every evaluation with
  SciPy's brentq at the limit of double precision;
- the Jacobian against central finite differences of the generated right side;
- the symbolic and the numeric solution of the same block against each other.
"""
from __future__ import annotations

import ctypes
import math
import subprocess
from pathlib import Path

import numpy as np
import pytest
import sympy as sp
from scipy.integrate import solve_ivp
from scipy.optimize import brentq

import bgc
from bgc.base import processes, toolchain
from bgc.api import Source
from bgc.codegen.emit import emit_c, emit_python
from helpers import built, families

ROOT = Path(__file__).resolve().parent.parent
MODELS = sorted((ROOT / "models").glob("*.bg"))
BACKENDS = ["python"] + (["c"] if toolchain.have_c_compiler() else [])



def close(got, ref, rel=1e-6):
    """max |got - ref| <= rel * max(1, max |ref|)."""
    got, ref = np.asarray(got, float), np.asarray(ref, float)
    return float(np.max(np.abs(got - ref))) <= rel * max(1.0, float(np.max(np.abs(ref))))


# ---------------------------------------------------------------- the pendulum chain


def chain_reference(n, t, theta0=0.5, dtheta=0.15, m=1.0, l=1.0, g=9.81):
    """Positions of the n-link chain from Lagrange's equations in the link angles (from the
    downward vertical, y down): with a_jk = n - max(j, k) masses beyond both links j and k,
    M_jk = m l^2 a_jk cos(th_j - th_k), and
    M th'' = -m l^2 (a_jk sin(th_j - th_k)) th'^2 - m g l (n - j) sin(th_j)."""
    a = np.array([[n - max(j, k) for k in range(n)] for j in range(n)], float)
    count = n - np.arange(n)

    def f(_, s):
        th, om = s[:n], s[n:]
        d = th[:, None] - th[None, :]
        M = m * l * l * a * np.cos(d)
        force = -m * l * l * (a * np.sin(d)) @ (om * om) - m * g * l * count * np.sin(th)
        return np.concatenate([om, np.linalg.solve(M, force)])

    th0 = theta0 + dtheta * np.arange(n)
    sol = solve_ivp(f, (t[0], t[-1]), np.concatenate([th0, np.zeros(n)]), method="DOP853",
                    rtol=1e-12, atol=1e-12, t_eval=t)
    assert sol.success
    th = sol.y[:n]
    return l * np.cumsum(np.sin(th), axis=0), l * np.cumsum(np.cos(th), axis=0)


@pytest.mark.parametrize("backend", BACKENDS)
def test_three_link_chain_matches_minimal_coordinates(backend):
    src = Source("chain3.bg", families.pendulum_chain(3))
    (block,) = built(src, "swing").reduced.blocks
    assert block.method == "lu" and len(block.unknowns) == 3  # the coupled multipliers
    t, Y, names = bgc.simulate(src, scene="swing", backend=backend)
    assert t[-1] == 5.0 and names == ["x1", "y1", "x2", "y2", "x3", "y3"]
    x, y = chain_reference(3, t)
    for k in range(3):
        assert close(Y[:, 2 * k], x[k]) and close(Y[:, 2 * k + 1], y[k]), names[2 * k]


def test_eight_link_model_matches_minimal_coordinates():
    t, Y, names = bgc.simulate(ROOT / "models" / "pendulum_chain.bg", scene="swing",
                               backend="c" if "c" in BACKENDS else "python", t_end=2.0)
    x, y = chain_reference(8, t)
    for k in range(8):
        assert close(Y[:, 2 * k], x[k]) and close(Y[:, 2 * k + 1], y[k]), names[2 * k]


# ---------------------------------------------------------------- nonlinear loops


def diode_reference(t, V=5.0, Rs=100.0, Is=1e-12, Vt=0.02585, C=1e-4):
    """Capacitor voltage, diode voltage and current: the loop V = Rs i + vd + vc with
    i = Is (exp(vd/Vt) - 1) solved for vd by brentq at every evaluation."""

    def diode_voltage(vc):
        g = lambda vd: Is * math.expm1(vd / Vt) - (V - vd - vc) / Rs  # noqa: E731
        return brentq(g, min(0.0, V - vc), max(0.0, V - vc), xtol=1e-16, rtol=8.9e-16)

    def f(_, s):
        vc = s[0] / C
        return [(V - diode_voltage(vc) - vc) / Rs]

    sol = solve_ivp(f, (t[0], t[-1]), [0.0], method="DOP853", rtol=1e-12, atol=1e-16,
                    t_eval=t)
    vc = sol.y[0] / C
    vd = np.array([diode_voltage(v) for v in vc])
    return vc, vd, (V - vd - vc) / Rs


@pytest.mark.parametrize("backend", BACKENDS)
def test_diode_loop_solved_by_newton_matches_brentq(backend):
    path = ROOT / "models" / "diode.bg"
    (block,) = built(path, "charge").reduced.blocks
    assert not block.linear and block.method == "newton"
    assert block.unknowns == ("e[loop->d1]",)  # torn at the exponential's input
    t, Y, names = bgc.simulate(path, scene="charge", backend=backend)
    assert names == ["cap.e", "d1.e", "d1.f"]
    vc, vd, i = diode_reference(t)
    assert close(Y[:, 0], vc) and close(Y[:, 1], vd) and close(Y[:, 2], i, rel=1e-7)


NONINVERTIBLE = """model nl "A resistor whose law has no inverse, in conductance causality"
parameter E = 3; parameter r = 2; parameter a = 1.5; parameter Cc = 0.5
src : Se(E)
j : 1
res : R(e = r*f + a*sin(f))
cap : C(Cc)
src -> j
j -> res
j -> cap
scene run { outputs cap.q, res.f; time 0 .. 3 every 0.01; solver dopri5(rtol = 1e-10, atol = 1e-12) }
"""


@pytest.mark.parametrize("backend", BACKENDS)
def test_resistor_without_closed_form_inverse_matches_brentq(backend):
    src = Source("nl.bg", NONINVERTIBLE)
    (block,) = built(src, "run").reduced.blocks
    assert block.method == "newton"
    t, Y, _ = bgc.simulate(src, scene="run", backend=backend)
    E, r, a, C = 3.0, 2.0, 1.5, 0.5

    def flow(e):  # r f + a sin f = e: monotonic in f since r > a
        return brentq(lambda f: r * f + a * math.sin(f) - e, (e - a) / r - 1, (e + a) / r + 1,
                      xtol=1e-16, rtol=8.9e-16)

    sol = solve_ivp(lambda _, s: [flow(E - s[0] / C)], (0, 3), [0.0], method="DOP853",
                    rtol=1e-12, atol=1e-14, t_eval=t)
    q = sol.y[0]
    assert close(Y[:, 0], q) and close(Y[:, 1], [flow(E - v / C) for v in q])


TWO_LAWS = """model loop2 "Two nonlinear resistors in one algebraic loop"
parameter E = 1
src : Se(E)
s1 : 1
r1 : R(e = f^3 + sin(f))
n : 0
r2 : R(e = exp(f) - 1)
s2 : 1
r3 : R(1)
cap : C(1)
src -> s1
s1 -> r1
s1 -> n
n -> r2
n -> s2
s2 -> r3
s2 -> cap
"""


def test_nonlinear_loop_of_two_laws_is_consistent():
    """Once a SymPy error ("no closed-form solution"), now a Newton block: its solution
    satisfies both laws and Kirchhoff's laws at random states, to rounding."""
    src = Source("loop2.bg", TWO_LAWS)
    compiled = bgc.build(src)
    assert any(b.method == "newton" for b in compiled.reduced.blocks)
    (text,) = emit_python(compiled.program).values()
    module = processes.load_python_module(text)
    rng = np.random.default_rng(3)
    for q in rng.uniform(-1, 1, 5):
        dq = module.rhs(0.0, [q], [1.0])[0]  # the capacitor's current = r3's current
        i3 = dq
        e_n = i3 * 1.0 + q  # 0-junction voltage: across r3 and the capacitor
        i2 = math.log(1 + e_n)  # r2: e = exp(f) - 1
        i1 = i2 + i3
        assert abs(i1 ** 3 + math.sin(i1) + e_n - 1.0) < 1e-12  # E = e_r1 + e_n


def test_symbolic_algebra_refuses_a_loop_without_closed_form():
    with pytest.raises(bgc.BgcModelError, match="no clean closed-form solution"):
        bgc.build(ROOT / "models" / "diode.bg", algebra="symbolic")


@pytest.mark.parametrize("backend", BACKENDS)
def test_block_failure_stops_the_run_with_time_and_unknowns(backend):
    """A law with no solution beyond some time: the run stops there with the block's unknowns
    named, and the rows computed before are kept."""
    src = Source("fail.bg", """model fail
src : MSe(2 - t)
j : 1
res : R(e = f^2 + f + 1)
cap : C(1)
src -> j
j -> res
j -> cap
scene run { outputs cap.q; time 0 .. 2 every 0.1; solver rk4 }
""")
    with pytest.raises(bgc.SimulationFailed if backend == "c" else Exception) as info:
        bgc.simulate(src, scene="run", backend=backend)
    message = str(info.value)
    assert "algebraic block 1 (f[j->res])" in message
    when = float(message.split("at t = ")[1].split(":")[0])
    # e = 2 - t - q = f^2 + f + 1 >= 3/4 has a real f while 5/4 - t - q >= 0, q >= 0
    assert 0.0 < when <= 1.25


# ---------------------------------------------------------------- symbolic against numeric


def _blocks_both_ways(path):
    auto = built(path)
    return any(b.linear for b in auto.reduced.blocks)


# The vector forms' blocks are their scalar twins', and the four-bar's 3x3 multiplier block and
# the pendulum chain's 8x8 one have the structure of the double pendulum's 2x2 chain of
# multipliers: their symbolic solves (seconds each, 17 s for the chain) would add no case.  The
# coupled fields under constraints (the arm on its wall, the slider-crank, Andrews' mechanism,
# whose augmented block has 13 unknowns, beyond --algebra symbolic's limit) have the two-link
# arm's 2x2 field block and augmented blocks solved by the same LU path.
SAME_BLOCKS = ("double_pendulum_vector", "pendulum_vector", "car_axis_vector", "four_bar",
               "pendulum_chain", "andrews", "two_link_arm_wall", "slider_crank")


# The models of _blocks_both_ways less SAME_BLOCKS, named so that collecting the tests builds no
# model (test_models_with_linear_blocks_are_listed keeps the list true).
BOTH_WAYS = ("buck", "car_axis", "double_pendulum", "gantry_crane", "knife_edge", "ladder",
             "parallel_caps", "parallel_caps_dual", "pendulum", "pendulum_wall", "two_link_arm")


@pytest.mark.parametrize("path", [p for p in MODELS
                                  if p.stem not in SAME_BLOCKS + BOTH_WAYS],
                         ids=lambda p: p.stem)
def test_models_with_linear_blocks_are_listed(path):
    assert not _blocks_both_ways(path)


@pytest.mark.parametrize("path", [p for p in MODELS if p.stem in BOTH_WAYS],
                         ids=lambda p: p.stem)
def test_symbolic_and_numeric_blocks_agree(path):
    assert _blocks_both_ways(path), "BOTH_WAYS names it"
    modules = {}
    for algebra in ("symbolic", "numeric"):
        (text,) = emit_python(bgc.build(path, algebra=algebra).program).values()
        modules[algebra] = processes.load_python_module(text)
    sym, num = modules["symbolic"], modules["numeric"]
    params = list(sym.PARAMETERS.values())
    x0 = sym._init(sym._with_constants(params))
    rng = np.random.default_rng(7)
    for _ in range(5):
        x = np.array(x0) + rng.normal(0, 0.05, len(x0))
        a, b = sym.rhs(0.3, x, params), num.rhs(0.3, x, params)
        assert np.allclose(a, b, rtol=1e-10, atol=1e-10 * max(1.0, np.max(np.abs(a))))
        ya, yb = sym.outputs(0.3, x, params), num.outputs(0.3, x, params)
        assert np.allclose(ya, yb, rtol=1e-10, atol=1e-10 * max(1.0, np.max(np.abs(ya))))


# ---------------------------------------------------------------- the Jacobian


def _random_state(module, rng):
    params = list(module.PARAMETERS.values())
    x0 = np.array(module._init(module._with_constants(params)))
    return params, x0 + rng.normal(0, 0.05, len(x0)) * np.maximum(1.0, np.abs(x0))


def finite_difference_jacobian(rhs, t, x):
    n = len(x)
    J = np.zeros((n, n))
    for j in range(n):
        h = 1e-6 * max(1.0, abs(x[j]))
        up, down = x.copy(), x.copy()
        up[j] += h
        down[j] -= h
        J[:, j] = (rhs(t, up) - rhs(t, down)) / (2 * h)
    return J


def assert_jacobian_close(J, FD):
    scale = max(1.0, float(np.max(np.abs(FD))))
    assert float(np.max(np.abs(J - FD))) <= 1e-6 * scale, np.max(np.abs(J - FD))


JACOBIAN_MODELS = MODELS + [Source("nl.bg", NONINVERTIBLE), Source("loop2.bg", TWO_LAWS)]


@pytest.mark.parametrize("model", JACOBIAN_MODELS,
                         ids=lambda m: m.stem if isinstance(m, Path) else m.path)
def test_python_jacobian_matches_finite_differences(model):
    (text,) = emit_python(built(model).program).values()
    module = processes.load_python_module(text)
    rng = np.random.default_rng(11)
    for _ in range(2):
        params, x = _random_state(module, rng)
        J = module.jacobian(0.2, x, params)
        FD = finite_difference_jacobian(lambda t, y: module.rhs(t, y, params), 0.2, x)
        assert_jacobian_close(J, FD)
        v = rng.normal(size=len(x))
        assert np.allclose(module.jvp(0.2, x, params, v), J @ v, rtol=1e-9, atol=1e-9)


@pytest.mark.skipif(not toolchain.have_c_compiler(), reason="no C compiler")
@pytest.mark.parametrize("model", JACOBIAN_MODELS,
                         ids=lambda m: m.stem if isinstance(m, Path) else m.path)
def test_c_jacobian_matches_finite_differences(model, tmp_path):
    program = built(model).program
    (text,) = emit_c(program).values()
    lib = tmp_path / "model.so"
    src = tmp_path / "model.c"
    src.write_text(text)
    cc = toolchain.c_compiler()
    subprocess.run([*cc, "-O0", "-std=c99", "-shared", "-fPIC", "-DBGC_NO_MAIN", str(src), "-o",
                    str(lib), "-lm"], check=True, capture_output=True)
    so = ctypes.CDLL(str(lib))
    n = len(program.states)
    params = (ctypes.c_double * (len(program.params) + max(program.n_consts, 1)))()
    so.bgc_params_defaults(params, None)
    so.bgc_work_new.restype = ctypes.c_void_p
    work = ctypes.c_void_p(so.bgc_work_new())
    x0 = (ctypes.c_double * n)()
    so.bgc_init(params, x0)
    dbl = ctypes.c_double

    def rhs(t, y):
        out = (dbl * n)()
        assert so.bgc_rhs(dbl(t), (dbl * n)(*y), params, work, out) == 0
        return np.array(out[:])

    rng = np.random.default_rng(11)
    for _ in range(2):
        x = np.array(x0[:]) + rng.normal(0, 0.05, n) * np.maximum(1.0, np.abs(x0[:]))
        J = (dbl * (n * n))()
        assert so.bgc_jacobian(dbl(0.2), (dbl * n)(*x), params, work, J) == 0
        assert_jacobian_close(np.array(J[:]).reshape(n, n),
                              finite_difference_jacobian(rhs, 0.2, x))
    so.bgc_work_free(work)


# ---------------------------------------------------------------- size and depth


def test_long_sum_deep_chain_and_deep_nesting():
    terms = " + ".join(f"{k}*x" for k in range(1, 501))  # a sum of 500 terms
    c = bgc.build(Source("sum.bg", f"model s\nparameter x = 1\nparameter y = {terms}\n"))
    assert c.program.params[1].default.subs(sp.IndexedBase("p")[0], 1) == 500 * 501 // 2
    chain = ["model chain", "src : Se(1)", "r : R(2)"] + [f"j{k} : {k % 2}" for k in range(400)]
    chain += ["src -> " + " -> ".join(f"j{k}" for k in range(400)) + " -> r"]
    t, Y, _ = bgc.simulate(Source("chain.bg", "\n".join(chain) + "\n"), backend="python",
                           t_end=0.1)  # no states; it compiles and runs
    parens = "model d\nparameter x = " + "(" * 10000 + "1" + ")" * 10000 + "\n"
    assert bgc.build(Source("parens.bg", parens)).program.params[0].default == 1
    deep = "model d\nparameter x = " + "-(" * 10000 + "1" + ")" * 10000 + "\n"
    with pytest.raises(bgc.BgcModelError, match="nested too deeply") as info:
        bgc.build(Source("deep.bg", deep))
    assert str(info.value).startswith("deep.bg:2:")
    right = "model d\nparameter x = 1" + " + (1" * 3000 + ")" * 3000 + "\n"
    c = bgc.build(Source("right.bg", right))
    assert c.program.params[0].default == 3001


def test_values_at_a_point_are_sympys_xreplace():
    """The random-point tests evaluate a matrix's entries with their shared subexpressions
    rebuilt once per point (canonical.xreplace with a memo): node for node what SymPy's
    xreplace builds."""
    from bgc.symbolic.canonical import xreplace
    x, y = sp.symbols("x y", real=True)
    shared = sp.sin(x - y) * sp.sqrt(x ** 2 + y ** 2)
    entries = [shared + 1, 2 * shared * y, sp.Abs(x - y, evaluate=False) + shared, x,
               sp.Integer(3)]
    point = {x: sp.Float(0.7, 20), y: sp.Float(1.3, 20)}
    memo: dict = {}
    for e in entries:
        built, expected = xreplace(e, point, memo), e.xreplace(point)
        assert built == expected and type(built) is type(expected)


# ------------------------------------------------------------------ parallel branches
RC_BRANCHES = """model rc_branches "N series RC branches on one 0-junction, fed by a current"
constant N = 40
parameter F = 2
component branch(r = 1, c = 1) {
  port a
  s : 1
  res : R(r)
  cap : C(c)
  a -> s
  s -> res
  s -> cap
}
src : Sf(F)
j : 0
src -> j
for i in 1..N {
  b[i] : branch(r = i, c = 2/(i + 1))
  j -> b[i].a
}
scene run { outputs j.e, b[1].cap.q, b[N].cap.q; time 0 .. 2 every 0.5 }
"""


def test_parallel_rc_branches_against_scipy(monkeypatch):
    """The block of the junction's effort is one linear unknown whose solution is a sum of N
    terms over a sum of N reciprocals: solved symbolically without cancelling that fraction
    (SymPy's heuristic gcd of it grows as 2^N: minutes at N = 30), in time linear in N; the
    run against SciPy on the same linear ODE, u = (F + sum q_k/(c_k r_k)) / sum 1/r_k,
    dq_i/dt = (u - q_i/c_i) / r_i."""
    cancelled = []
    real_cancel = sp.cancel
    monkeypatch.setattr(sp, "cancel", lambda e, *a, **k: cancelled.append(
        len(e.free_symbols)) or real_cancel(e, *a, **k))
    compiled = bgc.build(Source("rc.bg", RC_BRANCHES), "run")
    monkeypatch.undo()
    assert max(cancelled, default=0) < 20
    (block,) = compiled.reduced.blocks
    assert block.method == "symbolic" and block.note == ""
    t, Y, names = bgc.simulate(Source("rc.bg", RC_BRANCHES), "run", backend="vm", rtol=1e-11,
                               atol=1e-13)
    n, F = 40, 2.0
    r = np.arange(1, n + 1, dtype=float)
    c = 2 / (r + 1)

    def rates(_, q):
        u = (F + np.sum(q / (c * r))) / np.sum(1 / r)
        return (u - q / c) / r
    ref = solve_ivp(rates, (0, 2), np.zeros(n), t_eval=t, rtol=1e-12, atol=1e-14,
                    method="LSODA")
    u = (F + (ref.y / (c * r)[:, None]).sum(axis=0)) / np.sum(1 / r)
    assert names == ["j.e", "b[1].cap.q", "b[40].cap.q"]
    close(Y, np.column_stack([u, ref.y[0], ref.y[-1]]), 1e-7)


def test_a_block_too_large_to_solve_symbolically_says_why_in_check(monkeypatch):
    from bgc.middle import reduce
    from bgc.reports.report import check_report
    monkeypatch.setattr(reduce, "SYMBOLIC_MAX_OPS", 10)
    compiled = bgc.build(Source("rc.bg", RC_BRANCHES.replace("N = 40", "N = 4")), "run")
    (block,) = compiled.reduced.blocks
    assert block.method == "lu"
    assert "linear, solved numerically (LU); not symbolically: its coefficients are too " \
           "large" in check_report(compiled)


def _heugcd_bits(monkeypatch, expr) -> int:
    """The largest integer SymPy's heuristic gcd builds while cancelling expr, in bits."""
    from sympy.polys import heuristicgcd, rings
    seen = [0]
    real = heuristicgcd.heugcd

    def spy(f, g):
        seen[0] = max(seen[0], f.max_norm().bit_length(), g.max_norm().bit_length())
        return real(f, g)
    monkeypatch.setattr(rings, "heugcd", spy)
    monkeypatch.setattr(heuristicgcd, "heugcd", spy)
    sp.cancel(expr)
    monkeypatch.undo()
    return seen[0]


@pytest.mark.parametrize("n", [2, 4, 6, 8])
def test_the_gcd_estimate_bounds_sympys_heuristic(monkeypatch, n):
    """gcd_bits against the integers SymPy's heugcd really builds: above them, and growing
    as they do (each further parameter shared by numerator and denominator multiplies)."""
    from bgc.symbolic.algebra import gcd_bits
    r, q = sp.symbols(f"r0:{n}", positive=True), sp.symbols(f"q0:{n}")
    expr = (1 + sum(q[i] / r[i] for i in range(n))) / sum(1 / r[i] for i in range(n))
    real = _heugcd_bits(monkeypatch, expr)
    estimate = gcd_bits(*expr.as_numer_denom())
    assert real <= estimate <= 64 * real


def test_the_lu_estimate_bounds_the_solution_sympy_builds():
    from bgc.symbolic.algebra import lu_solution_nodes
    rng = np.random.default_rng(3)
    x = sp.symbols("x0:9", real=True)
    for m in (1, 2, 3, 5):
        A = sp.Matrix(m, m, lambda i, k: 0 if rng.random() < 0.3 and i != k else
                      x[int(rng.integers(9))] + int(rng.integers(1, 4)) * x[(i + k) % 9])
        b = sp.Matrix(m, 1, lambda i, _: x[i % 9] ** 2)
        nodes = sum(_tree_nodes(s) for s in A.LUsolve(b))
        assert nodes <= lu_solution_nodes(A, b, 10 ** 9) <= 50 * nodes


def _tree_nodes(e) -> int:
    return 1 + sum(_tree_nodes(a) for a in e.args)
