"""The emitters, solvers and backends, on hand-built programs (no front end involved).

The models have closed forms (oscillator, decay, blow-up, uniform circular motion) so the
generated C and Python are checked against mathematics, and against each other.
"""
from __future__ import annotations

import ast
import contextlib
import dataclasses
import io
import math
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import sympy as sp

from bgc import api
from bgc.base import solvers, toolchain
from bgc.base.cache import compile_c
from bgc.base.processes import load_python_module, run_c
from bgc.base.toolchain import BackendError, have_c_compiler
from bgc.codegen.emit import (POW10_RANGE, EmitError, c_param_fields, c_string_literal, emit_c,
                      emit_python, pow10_table)
from bgc.symbolic.algebra import Max, Min
from bgc.ir import C, ConstraintRow, Function, P, Param, SceneSettings, Store, T, X
from bgc.ir import expressions as ir_expressions
from bgc.codegen.lower import explicit_program, hoist_constants
from bgc.ir.printers import CPrinter, PythonPrinter, UnsupportedExpressionError

STRICT = ("-O2", "-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic")
# What the tests of a program's behaviour build with: every warning an error, at -O0 (a quarter
# of -O2's compile time; the same IEEE arithmetic under -std=c99 at every level, tests/conftest.py).
# test_c_compiles_with_strict_warnings builds each model at -O1, -O2 and -O3, the parity tests
# below (C and Python agree) at -O2.
BEHAVIOUR = ("-O0",) + STRICT[1:]
HERE = Path(__file__).resolve().parent
needs_cc = pytest.mark.skipif(not have_c_compiler(), reason="no C compiler")


@pytest.fixture(autouse=True, scope="session")
def _cache_dir(tmp_path_factory):
    old = os.environ.get("BGC_CACHE_DIR")
    os.environ["BGC_CACHE_DIR"] = str(tmp_path_factory.mktemp("bgc-cache"))
    yield
    if old is None:
        del os.environ["BGC_CACHE_DIR"]
    else:
        os.environ["BGC_CACHE_DIR"] = old


# ---------------------------------------------------------------- models


def scene(t_end=10.0, dt=0.1, solver="dopri5", rtol=1e-6, atol=1e-9, step=None, t0=0.0):
    return SceneSettings(t0, t_end, dt, solver, rtol, atol, step)


def model(name, states, params, outputs, init, rhs, out, sc=None, **constraint_parts):
    return explicit_program(name, states, params, outputs, init, rhs, out, sc or scene(),
                            **constraint_parts)


def oscillator(**kw):
    """m x'' = -k x, x(0) = 1: x = cos(w t), p = m x' = -m w sin(w t), w = sqrt(k/m) (derived)."""
    k, m, w = P[0], P[1], P[2]
    params = (Param("k", sp.Integer(4)), Param("m", sp.Integer(1)), Param("w", sp.sqrt(k / m)))
    return model("osc", ("x", "mx.p"), params, ("x", "v", "xref"), [1, 0],
                 [X[1] / m, -k * X[0]], [X[0], X[1] / m, sp.cos(w * T)], scene(**kw))


def hoisted_oscillator(**kw):
    """The oscillator, whose parameter-only subexpressions become constants (1/m, -k) as in
    every program: the constants must follow -p overrides of k and m."""
    program = oscillator(**kw)
    k, m = P[0], P[1]
    assert [st.expr for st in program.function("consts").body] == [1 / m, -k]
    return program


def decay(**kw):
    """x' = -a x, x(0) = x0: x = x0 exp(-a t)."""
    params = (Param("a", sp.Float(0.7)), Param("x0", sp.Integer(2)))
    return model("decay", ("x",), params, ("x", "exact"), [P[1]], [-P[0] * X[0]],
                 [X[0], P[1] * sp.exp(-P[0] * T)], scene(**kw))


def blowup(state="x", **kw):
    """x' = x^2, x(0) = 1: x = 1/(1 - t), infinite at t = 1."""
    return model("blowup", (state,), (), (state,), [1], [X[0] ** 2], [X[0]], scene(**kw))


def sqrt_of_negative(**kw):
    """x' = sqrt(x - 2) at x = 1: the derivative is not a number at once."""
    return model("neg", ("x",), (), ("x",), [1], [sp.sqrt(X[0] - 2)], [X[0]], scene(**kw))


def damped(**kw):
    """A forced, damped, nonlinear oscillator that uses many functions."""
    c, k, f = P[0], P[1], P[2]
    params = (Param("c", sp.Float(0.3)), Param("k", sp.Integer(2)), Param("F", sp.Rational(1, 3)))
    rhs = [X[1], -c * X[1] * sp.Abs(X[1]) - k * sp.sin(X[0]) + f * sp.cos(sp.pi * T / 3)
           + sp.tanh(X[0]) / 10 - X[0] ** 3 / 7]
    out = [X[0], X[1], sp.atan2(X[1], X[0] + 3), sp.exp(-X[0] ** 2) * sp.log(2 + X[1] ** 2)]
    return model("damped", ("q", "p"), params, ("q", "p", "angle", "g"), [sp.Rational(1, 2), 0],
                 rhs, out, scene(**kw))


def functions_model():
    """One constant state; outputs exercise every function the printers know."""
    a = T / 10 - sp.Rational(1, 2)  # in [-0.5, 0.5] for t in [0, 10]
    exprs = [sp.sin(a), sp.cos(a), sp.tan(a), sp.asin(a), sp.acos(a), sp.atan(a),
             sp.atan2(a, 1 + T), sp.sinh(a), sp.cosh(a), sp.tanh(a), sp.exp(a), sp.log(2 + a),
             sp.sqrt(1 + a), sp.Abs(a), sp.sign(a), Min(a, X[0], T), Max(a, X[0] / 10),
             sp.Heaviside(a), (1 + a) ** sp.Rational(3, 2), (2 + a) ** -3, 1 / sp.sqrt(2 + a),
             (a + 1) ** 2, X[0] ** 5, sp.pi * sp.E * a]
    names = [f"f{i}" for i in range(len(exprs))]
    return model("funcs", ("x",), (), names, [sp.Rational(1, 4)], [0], exprs,
                 scene(t_end=10.0, dt=0.25)), exprs


def circle(x0=1.0, y0=0.0, vx0=0.0, vy0=1.0, **kw):
    """Uniform circular motion; constraint 'rod': x^2 + y^2 = 1 and x vx + y vy = 0."""
    params = tuple(Param(n, sp.Float(v)) for n, v in
                   (("x0", x0), ("y0", y0), ("vx0", vx0), ("vy0", vy0)))
    x, y, vx, vy = (X[i] for i in range(4))
    v2 = vx ** 2 + vy ** 2
    return model(
        "circle", ("x", "y", "vx", "vy"), params, ("x", "y", "vx", "vy"),
        [P[0], P[1], P[2], P[3]], [vx, vy, -x * v2, -y * v2], [x, y, vx, vy], scene(**kw),
        constraints=(ConstraintRow("rod", "position"), ConstraintRow("rod", "velocity")),
        residual=[x ** 2 + y ** 2 - 1, x * vx + y * vy],
        scale=[1, 1],
        position_jac=[2 * x, 2 * y, 0, 0],
        velocity_jac=[vx, vy, x, y],
        velocity_movable=(False, False, True, True))


EVIL = ('a"; system("rm -rf /"); //', "new\nline */ /* \\ ??= ??/ %s%n", "caf\u00e9 \u2603",
        "tab\t'q'", "q[1]")


def evil(**kw):
    """Names that must never reach code except as escaped literals; keyword-named params."""
    names = ("int", "double", "a.b", "a_b", "p", "x", "t", "w0", "bgc_sq", "main", EVIL[0],
             EVIL[1])
    params = tuple(Param(n, sp.Integer(j + 1)) for j, n in enumerate(names))
    total = sum(P[j] for j in range(len(names)))
    return model(EVIL[0], (EVIL[0], EVIL[1]), params, (EVIL[2], EVIL[3], EVIL[4]), [1, 0],
                 [X[1], -X[0] * P[0] / total], [X[0], X[1], total], scene(**kw))


# ---------------------------------------------------------------- helpers


def c_program(cm, flags=BEHAVIOUR):
    (source,) = emit_c(cm).values()
    return compile_c(source, flags=flags)


def run_python_program(cm, args, tmp_path):
    (name, source), = emit_python(cm).items()
    path = tmp_path / name
    path.write_text(source, encoding="utf-8")
    env = dict(os.environ, PYTHONIOENCODING="utf-8")
    done = subprocess.run([sys.executable, str(path), *args], capture_output=True, text=True,
                          encoding="utf-8", env=env)
    return done.returncode, done.stdout, done.stderr


def python_module(cm):
    (source,) = emit_python(cm).values()
    return load_python_module(source)


def parse_csv(text):
    lines = text.splitlines()
    return lines[0], np.array([[float(v) for v in line.split(",")] for line in lines[1:]])


def run_c_csv(cm, *args):
    code, out, err = run_c(c_program(cm), args)
    assert code == 0, err
    return parse_csv(out)


# ---------------------------------------------------------------- printers


def test_printer_powers_and_numbers():
    c = CPrinter(2, ("p_k",))
    py = PythonPrinter(2, 1)
    assert c.doprint(X[0] ** 2) == "x[0]*x[0]"
    assert c.doprint(X[0] ** -2) == "1.0/(x[0]*x[0])"
    assert c.doprint((X[0] + X[1]) ** 2) == "bgc_sq(x[0] + x[1])"
    assert py.doprint((X[0] + X[1]) ** 2) == "_sq(x[0] + x[1])"  # a * a: ** 2 is libm's pow
    assert c.doprint(sp.sqrt(X[0])) == "sqrt(x[0])"
    assert c.doprint(X[0] ** sp.Rational(-1, 2)) == "1.0/sqrt(x[0])"
    assert c.doprint(X[0] ** 7) == "pow(x[0], 7.0)"
    assert py.doprint(X[0] ** 7) == "math.pow(x[0], 7.0)"
    ieee = PythonPrinter(2, 1, ieee=True)  # the fallback: libm through math, C's inf and nan
    assert ieee.doprint(X[0] ** 7) == "_c_pow(x[0], 7.0)"
    assert ieee.doprint(sp.exp(X[0]) + sp.tanh(X[1])) == "_c_exp(x[0]) + _c_tanh(x[1])"
    assert c.doprint(X[0] / 3) == "x[0]/3.0"
    assert c.doprint(P[0] * X[0] / 2) == "0.5*p->p_k*x[0]"
    assert c.doprint(sp.Float(0.1) * T) == "0.10000000000000001*t"
    assert c.doprint(sp.Integer(10) ** 30 * T) == "1e+30*t"


def test_printer_constants():
    c = CPrinter(1, ("p_k",), 2)
    py = PythonPrinter(1, 1, n_consts=2)
    assert c.doprint(C[1] * X[0] + P[0]) == "p->c[1]*x[0] + p->p_k"
    assert py.doprint(C[1] * X[0] + P[0]) == "p[2]*x[0] + p[0]"  # constants follow parameters
    for printer in (c, py, CPrinter(1, ("p_k",)), PythonPrinter(1, 1)):
        with pytest.raises(UnsupportedExpressionError):
            printer.doprint(C[2] if printer in (c, py) else C[0])


def test_printer_layout_for_latency():
    c = CPrinter(5, ())
    assert c.doprint(X[0] + X[1] + X[2] + X[3]) == "x[0] + x[1] + (x[2] + x[3])"
    assert c.doprint(X[0] - X[1] - X[2] + X[3] + T) == "t - x[1] - x[2] + (x[0] + x[3])"
    assert c.doprint(sum(X[i] for i in range(5)) + T) == "t + x[0] + x[1] + (x[2] + x[3] + x[4])"
    # the simple factors are divided while the sum is being added up
    assert c.doprint(sp.sin(X[0]) * (X[0] + X[1]) * X[2] * X[4] / (X[3] + 1)) == \
        "(x[0] + x[1])*sin(x[0])*(x[2]*x[4]/(x[3] + 1.0))"
    assert c.doprint(X[2] / (X[3] + 1)) == "x[2]/(x[3] + 1.0)"
    assert c.doprint((X[0] + X[1]) / (X[3] + 1)) == "(x[0] + x[1])/(x[3] + 1.0)"


def test_printer_refuses_unsupported():
    c = CPrinter(1, ())
    for bad in (sp.Symbol("y"), sp.Piecewise((1, X[0] > 0)), sp.oo * X[0],
                sp.floor(X[0]), X[1], P[0], sp.IndexedBase("q")[0], sp.I * X[0],
                sp.Function("f")(X[0]), sp.nan, sp.zoo):
        with pytest.raises(UnsupportedExpressionError):
            c.doprint(bad)


def test_printers_write_conditionals_alike():
    """A conditional (the language's if/elif/else over relations, bgc.front.events) prints as nested
    conditional expressions in both languages, and a condition is never a number."""
    e = sp.Piecewise((X[0], sp.And(X[0] > 1, sp.Not(sp.Eq(P[0], 2)))), (2 * X[0], X[0] <= -1),
                     (0, True))
    c, py = CPrinter(1, ("k",)), PythonPrinter(1, 1)
    assert c.doprint(e) == \
        "(((x[0] > 1.0) && (p->k != 2.0)) ? x[0] : ((x[0] <= -1.0) ? 2.0*x[0] : 0.0))"
    assert py.doprint(e) == \
        "(x[0] if ((x[0] > 1.0) and (p[0] != 2.0)) else (2.0*x[0] if (x[0] <= -1.0) " \
        "else 0.0))"
    for x0, want in ((2.0, 2.0), (-3.0, -6.0), (0.0, 0.0)):
        assert eval(py.doprint(e), {"x": [x0], "p": [1.0]}) == want  # noqa: S307 (test)


def test_c_string_literal_escapes():
    assert c_string_literal('a"b\\c?') == '"a\\"b\\\\c\\?"'
    assert c_string_literal("x\ny\u00e9") == '"x\\012y\\303\\251"'
    assert c_string_literal("??=") == '"\\?\\?="'


def test_param_fields_are_safe_and_unique():
    assert c_param_fields(("int", "k")) == ("p_int", "p_k")
    fields = c_param_fields(("a.b", "a_b", EVIL[0]))
    assert len(set(fields)) == 3 and all(f.replace("_", "a").isalnum() for f in fields)


def test_python_literals_round_trip():
    (source,) = emit_python(evil()).values()
    tree = ast.parse(source)
    values = {node.targets[0].id: ast.literal_eval(node.value) for node in tree.body
              if isinstance(node, ast.Assign) and isinstance(node.targets[0], ast.Name)
              and node.targets[0].id in ("STATES", "OUTPUTS", "MODEL")}
    assert values == {"MODEL": EVIL[0], "STATES": list(EVIL[:2]), "OUTPUTS": list(EVIL[2:])}


def _with_function(program, name, exprs, size=None):
    f = Function(name, program.function(name).args, len(exprs) if size is None else size,
                 tuple(Store(k, sp.sympify(e) if not isinstance(e, sp.Basic) else e)
                       for k, e in enumerate(exprs)))
    return dataclasses.replace(program, functions={**program.functions, name: f})


def test_invalid_programs_are_refused():
    cm = oscillator()
    with pytest.raises(EmitError):
        emit_c(_with_function(cm, "init", [T, 0]))
    with pytest.raises(EmitError):
        emit_c(dataclasses.replace(cm, params=(Param("k", P[1]), Param("m", P[0]),
                                               Param("w", sp.Integer(2)))))
    with pytest.raises(EmitError):
        emit_python(_with_function(cm, "rhs", [X[0]]))
    for consts in ([X[0]], [T * P[0]], [C[0]]):  # constants use parameters only
        with pytest.raises(EmitError):
            emit_c(_with_function(cm, "consts", consts))
    with pytest.raises(EmitError):  # and parameter defaults do not use constants
        emit_c(dataclasses.replace(cm, params=(Param("k", C[0]), Param("m", sp.Integer(1)),
                                               Param("w", sp.Integer(2)))))


# ---------------------------------------------------------------- hoisted constants


def _stores(*exprs):
    return Function("rhs", ("t", "x", "p"), len(exprs), tuple(Store(k, e)
                                                             for k, e in enumerate(exprs)))


def test_hoist_constants_moves_parameter_only_parts():
    m, g, k = P[0], P[1], P[2]
    groups = ([2 * m * g * X[0] + X[1] / m, sp.sin(k * m * T) + m],
              [X[0] / m + 1, sp.cos(g) + X[0], -k * X[0], m, T * X[0]])
    consts, rewritten = hoist_constants([_stores(*group) for group in groups])
    assert consts == (1 / m, 2 * m * g, k * m, sp.cos(g), -k)  # in order of first occurrence
    got = [tuple(st.expr for st in f.body) for f in rewritten]
    assert got == [(C[0] * X[1] + C[1] * X[0], sp.sin(C[2] * T) + m),
                   (C[0] * X[0] + 1, C[3] + X[0], C[4] * X[0], m, T * X[0])]
    back = {C[j]: c for j, c in enumerate(consts)}
    for old, new in zip(groups[0] + groups[1], got[0] + got[1]):
        assert sp.simplify(new.xreplace(back) - old) == 0
    consts, (f,) = hoist_constants([_stores(X[0] + 1, 2 * T)])
    assert consts == () and [st.expr for st in f.body] == [X[0] + 1, 2 * T]


def test_front_end_hoists_constants():
    import bgc

    program = bgc.build(HERE.parent / "models" / "pendulum.bg", "long").program
    assert program.n_consts > 0
    for name in ("rhs", "outputs", "jvp"):
        exprs = [e for s in program.function(name).body for e in ir_expressions(s)]
        assert not any(e.has(P) for e in exprs)  # every parameter use became a constant
        assert any(e.has(C) for e in exprs)
    assert not any(st.expr.has(C) or st.expr.has(X) for st in program.function("consts").body)


@needs_cc
def test_hoisted_constants_follow_parameter_overrides(tmp_path):
    cm = hoisted_oscillator(rtol=1e-10, atol=1e-12)
    _, data = run_c_csv(cm)
    assert oscillator_error(data[:, 0], data[:, 1:]) < 1e-8
    for params in ({"k": 9.0}, {"m": 4.0, "k": 16.0}):  # w = sqrt(k/m) = 3, 2
        k, m = params.get("k", 4.0), params.get("m", 1.0)
        args = [a for name, value in params.items() for a in ("-p", f"{name}={value}")]
        _, data = run_c_csv(cm, *args)
        assert oscillator_error(data[:, 0], data[:, 1:], k=k, m=m) < 1e-8
        t, Y = python_module(cm).simulate(params=params)
        assert np.array_equal(t, data[:, 0]) and np.array_equal(Y, data[:, 1:])
        code, out, err = run_python_program(cm, args, tmp_path)
        assert code == 0 and parse_csv(out)[1].tolist() == data.tolist(), err
    mod = python_module(cm)  # the public functions take the parameters alone
    assert mod.rhs(0.0, [1.0, 2.0], [9.0, 4.0, 1.5]).tolist() == [0.5, -9.0]
    assert mod.outputs(0.0, [1.0, 2.0], [9.0, 4.0, 1.5]).tolist() == [1.0, 0.5, 1.0]


@needs_cc
def test_c_library_updates_constants():
    (source,) = emit_c(hoisted_oscillator()).values()
    user = source + """
#include <assert.h>
static double last_x;
static int keep(void *ctx, double t, const double *x, const double *y)
{
    (void)ctx;
    (void)t;
    (void)y;
    last_x = x[0];
    return 0;
}
int main(void)
{
    bgc_params p;
    bgc_settings s;
    bgc_stats st = {0};
    bgc_work *w = bgc_work_new();
    double x[2] = {1.0, 2.0}, dx[2];
    char msg[256];
    assert(w != NULL);
    bgc_params_defaults(&p, NULL);
    assert(bgc_rhs(0.0, x, &p, w, dx) == 0);
    assert(dx[0] == 2.0 && dx[1] == -4.0);
    p.p_k = 9.0;
    p.p_m = 4.0;
    bgc_params_update(&p);
    assert(bgc_rhs(0.0, x, &p, w, dx) == 0);
    assert(dx[0] == 0.5 && dx[1] == -9.0);
    bgc_work_free(w);
    p.p_k = 16.0; /* bgc_simulate updates a copy: w = sqrt(16/4) = 2 */
    bgc_settings_default(&s);
    s.t_end = 3.0;
    s.rtol = 1e-10;
    s.atol = 1e-12;
    x[1] = 0.0;
    assert(bgc_simulate(&s, &p, x, keep, NULL, &st, msg, sizeof msg) == 0);
    assert(fabs(last_x - cos(6.0)) < 1e-8);
    return 0;
}
"""
    exe = compile_c(user, flags=BEHAVIOUR + ("-DBGC_NO_MAIN",))
    code, _, err = run_c(exe)
    assert code == 0, err


@needs_cc
def test_c_advance_goes_on_with_its_step_size():
    """bgc_advance in 10 pieces of 0.3 s over the oscillator (x = cos 2t), as the FMU's
    fmi2DoStep calls it: passing stats.h_next on as s.h0 the adaptive solvers go on with their
    step size (radau its order too) and take fewer steps than starting each piece afresh; both
    follow the closed form within the tolerance's reach, and the pieces take at most one step
    more each than one run over the whole span (the step cut short at each piece's end).
    Measured (afresh, carried on, whole): dopri5 104, 90, 81; rodas5p 69, 58, 54; radau 90, 20,
    20 (afresh, each piece restarts at order 5)."""
    (source,) = emit_c(oscillator()).values()
    user = source + """
#include <assert.h>
static double run(int solver, int carry, long *steps, long whole)
{
    bgc_params p;
    bgc_settings s;
    bgc_stats st = {0};
    bgc_work *w = bgc_work_new();
    double x[2] = {1.0, 0.0};
    char msg[256];
    int k;
    assert(w != NULL);
    bgc_params_defaults(&p, NULL);
    bgc_settings_default(&s);
    s.solver = solver;
    s.rtol = 1e-8;
    s.atol = 1e-10;
    for (k = 0; k < (whole ? 1 : 10); k++) {
        s.t0 = whole ? 0.0 : 0.3 * k;
        s.t_end = whole ? 3.0 : 0.3 * (k + 1);
        s.dt = s.t_end - s.t0;
        s.h0 = carry ? st.h_next : 0.0;
        s.order0 = carry ? st.order_next : 0;
        assert(bgc_advance(&s, &p, w, x, NULL, NULL, &st, msg, sizeof msg) == 0);
        assert(st.h_next > 0.0);
    }
    bgc_work_free(w);
    *steps = st.steps;
    return fabs(x[0] - cos(6.0)) + fabs(x[1] + 2.0 * sin(6.0));
}
int main(void)
{
    const int solvers[] = { BGC_SOLVER_DOPRI5, BGC_SOLVER_RODAS5P, BGC_SOLVER_RADAU };
    int i;
    for (i = 0; i < 3; i++) {
        long afresh, carried, whole;
        const double e_afresh = run(solvers[i], 0, &afresh, 0);
        const double e_carried = run(solvers[i], 1, &carried, 0);
        const double e_whole = run(solvers[i], 0, &whole, 1);
        printf("%s %ld %ld %ld %.3g %.3g %.3g\\n", bgc_solver_names[solvers[i]], afresh,
               carried, whole, e_afresh, e_carried, e_whole);
    }
    return 0;
}
"""
    exe = compile_c(user, flags=BEHAVIOUR + ("-DBGC_NO_MAIN",))
    code, out, err = run_c(exe)
    assert code == 0, err
    for line in out.splitlines():
        name, afresh, carried, whole, *errors = line.split()
        afresh, carried, whole = int(afresh), int(carried), int(whole)
        assert carried < afresh and carried <= whole + 10, line
        assert max(float(e) for e in errors) < 1e-6, line


# ---------------------------------------------------------------- determinism

_DIGEST_SCRIPT = """
import hashlib, test_emit as m
from bgc.codegen.emit import emit_c, emit_python
h = hashlib.sha256()
for cm in (m.oscillator(), m.damped(), m.circle(), m.evil(), m.functions_model()[0],
           m.hoisted_oscillator()):
    for files in (emit_c(cm), emit_python(cm)):
        for name, text in sorted(files.items()):
            h.update(name.encode() + text.encode())
print(h.hexdigest())
"""


def _store_lines(n, dest="out", src="x", step=1, numbers=False):
    return [f"{dest}[{i}] = {_number_text(i) if numbers else f'{src}[{5 + step * i}]'};"
            for i in range(n)]


def _number_text(i):
    return repr(1.0 / (i + 3)) if i % 3 else ("-0.0" if i % 2 else "2.5e-300")


def test_long_runs_of_stores_become_loops():
    """Runs of COPY_RUN or more copies (or numbers) into one array become one loop over index
    tables; shorter runs, and a change of array, are left as lines."""
    from bgc.codegen.emit import COPY_RUN, _copy_loops
    short = _store_lines(COPY_RUN - 1)
    assert _copy_loops(short) == short
    loop = _copy_loops(_store_lines(COPY_RUN))
    assert loop[-2:] == ["        out[bgc_k] = x[5 + bgc_k];", "}"] and len(loop) == 5
    table = "\n".join(_copy_loops(_store_lines(COPY_RUN, dest="wv", src="wv", step=2)))
    assert "static const int bgc_from[" in table and "wv[bgc_k] = wv[bgc_from[bgc_k]];" in table
    mixed = _copy_loops(["w1 = x[0];", *_store_lines(COPY_RUN), *_store_lines(3, src="v")])
    assert mixed[0] == "w1 = x[0];" and mixed[-3:] == _store_lines(3, src="v")


@needs_cc
def test_store_loops_write_what_the_lines_write(tmp_path):
    """The loops against the lines they replace, compiled: the same doubles, bit for bit, in
    every slot (the untouched ones included)."""
    from bgc.codegen.emit import COPY_RUN, _copy_loops
    n = COPY_RUN + 7
    lines = [*_store_lines(n), "out[500] = x[1];", *_store_lines(n, dest="wv", src="x", step=3),
             *_store_lines(n, dest="x0", numbers=True), *_store_lines(COPY_RUN + 1, dest="out", src="wv")]
    assert len(_copy_loops(lines)) < len(lines) // 4

    def body(name, ls):
        return (f"static void {name}(const double *x, double *out, double *wv, double *x0)\n{{\n"
                + "\n".join(f"    {line}" for line in ls) + "\n}\n")

    src = tmp_path / "loops.c"
    src.write_text("#include <stdio.h>\n#include <string.h>\n"
                   + body("lines", lines) + body("loops", _copy_loops(lines)) + """
int main(void)
{
    static double x[1000], a[4][1000], b[4][1000];
    int i;
    for (i = 0; i < 1000; ++i)
        x[i] = 1.0 / (i + 0.5);
    memset(a, 0xab, sizeof a);
    memset(b, 0xab, sizeof b);
    lines(x, a[0], a[1], a[2]);
    loops(x, b[0], b[1], b[2]);
    puts(memcmp(a, b, sizeof a) == 0 ? "same" : "differ");
    return 0;
}
""")
    exe = tmp_path / "loops"
    subprocess.run([*toolchain.c_compiler(None), "-std=c99", "-O1", str(src), "-o", str(exe)],
                   check=True)
    assert subprocess.run([str(exe)], capture_output=True, text=True).stdout == "same\n"


def test_emit_is_byte_identical_under_hash_seeds():
    """The emitter's output for hand-built models in a process with a fixed hash seed and in
    this one (whose seed is random, or another fixed one)."""
    seed = "12345" if os.environ.get("PYTHONHASHSEED") != "12345" else "1"
    env = dict(os.environ, PYTHONHASHSEED=seed,
               PYTHONPATH=os.pathsep.join([str(HERE), str(HERE.parent)]))
    done = subprocess.run([sys.executable, "-c", _DIGEST_SCRIPT], capture_output=True,
                          text=True, env=env, cwd=HERE)
    assert done.returncode == 0, done.stderr
    here = io.StringIO()
    with contextlib.redirect_stdout(here):
        exec(compile(_DIGEST_SCRIPT, "<digest>", "exec"), {})
    assert done.stdout == here.getvalue()


def test_no_stamps_in_generated_code():
    for emit in (emit_c, emit_python):
        (text,) = emit(oscillator()).values()
        assert emit(oscillator()) == emit(oscillator())
        assert not re.search(r"\b(19|20)\d\d-\d\d-\d\d|\d\d:\d\d:\d\d|0\.1\.0", text)


# ---------------------------------------------------------------- C compiles


def empty():
    return model("empty", (), (), (), [], [], [])


@needs_cc
@pytest.mark.parametrize("make, level", [
    *[(make, "-O2") for make in (oscillator, decay, damped, circle, evil, blowup, empty)],
    # the runtime (the same bytes in every program) and the model of every function, at
    # every level
    *[(lambda: functions_model()[0], level) for level in ("-O1", "-O2", "-O3")]])
def test_c_compiles_with_strict_warnings(make, level):
    exe = c_program(make(), (level,) + STRICT[1:])
    assert exe.is_file()


@needs_cc
def test_model_without_states_or_outputs(tmp_path):
    for code, out, _ in (run_c(c_program(empty()), ["--t-end", "0.2"]),
                         run_python_program(empty(), ["--t-end", "0.2"], tmp_path)):
        assert code == 0 and out.splitlines() == ["t", "0", "0.10000000000000001",
                                                  "0.20000000000000001"]


@needs_cc
def test_c_compiles_as_library():
    (source,) = emit_c(circle()).values()
    user = source + """
#include <assert.h>
int main(void)
{
    bgc_params p;
    bgc_settings s;
    bgc_stats st = {0};
    bgc_work *w = bgc_work_new();
    double x[BGC_NUM_STATES], dx[BGC_NUM_STATES], J[BGC_NUM_STATES * BGC_NUM_STATES];
    char msg[256];
    bgc_params_defaults(&p, NULL);
    bgc_init(&p, x);
    if (!w || bgc_rhs(0.0, x, &p, w, dx) || bgc_jacobian(0.0, x, &p, w, J))
        return 2;
    /* circle: d(vx)/dt = -x (vx^2 + vy^2): d/dvx = -2 x vx = 0 at (1, 0, 0, 1) */
    if (J[2 * BGC_NUM_STATES + 2] != 0.0 || J[2 * BGC_NUM_STATES + 0] != -1.0)
        return 3;
    bgc_work_free(w);
    bgc_settings_default(&s);
    s.t_end = 1.0;
    return bgc_simulate(&s, &p, x, NULL, NULL, &st, msg, sizeof msg) != 0 || st.steps == 0;
}
"""
    exe = compile_c(user, flags=BEHAVIOUR + ("-DBGC_NO_MAIN",))
    assert run_c(exe)[0] == 0


@needs_cc
def test_compile_cache_hit_does_not_compile(monkeypatch):
    (source,) = emit_c(decay()).values()
    first = compile_c(source)

    def no_compiler(*args, **kwargs):
        raise AssertionError("compiled again")

    monkeypatch.setattr(toolchain, "run_compiler", no_compiler)
    assert compile_c(source) == first


@needs_cc
def test_compiler_failure_is_a_backend_error():
    with pytest.raises(BackendError, match="bug in bgc"):
        compile_c("int main(void) { return undefined_thing; }\n")


def test_no_eval_or_exec_in_backends():
    for name in ("ir/printers.py", "codegen/emit.py", "base/cache.py", "base/toolchain.py",
                 "base/processes.py", "codegen/lower.py", "ir/program.py"):
        text = (HERE.parent / "bgc" / name).read_text()
        assert "eval(" not in text and "exec(" not in text, name


# ---------------------------------------------------------------- accuracy


def oscillator_error(t, Y, k=4.0, m=1.0):
    w = math.sqrt(k / m)
    return max(np.max(np.abs(Y[:, 0] - np.cos(w * t))),
               np.max(np.abs(Y[:, 1] + w * np.sin(w * t))))


@needs_cc
def test_c_dopri5_matches_closed_form():
    header, data = run_c_csv(oscillator(), "--rtol", "1e-10", "--atol", "1e-12")
    assert header == "t,x,v,xref"
    assert oscillator_error(data[:, 0], data[:, 1:]) < 1e-8
    header, data = run_c_csv(decay(), "--rtol", "1e-10", "--atol", "1e-12")
    assert np.max(np.abs(data[:, 1] - data[:, 2])) < 1e-8


def test_python_dopri5_matches_closed_form():
    mod = python_module(oscillator())
    t, Y = mod.simulate(rtol=1e-10, atol=1e-12)
    assert Y.shape == (101, 3)
    assert oscillator_error(t, Y) < 1e-8
    t, Y = python_module(decay()).simulate(rtol=1e-10, atol=1e-12)
    assert np.max(np.abs(Y[:, 0] - Y[:, 1])) < 1e-8


def test_dopri5_dense_output_does_not_shorten_steps():
    mod = python_module(oscillator())
    steps = {}
    for dt in (1.0, 0.001):
        st = {}
        for _ in mod.rows(dt=dt, stats=st):
            pass
        steps[dt] = st["steps"]
    assert abs(steps[1.0] - steps[0.001]) <= 2


@pytest.mark.parametrize("solver, order", [("euler", 1), ("rk4", 4)])
def test_fixed_step_convergence_order(solver, order):
    mod = python_module(decay())
    errors = []
    for h in (0.02, 0.01):
        t, Y = mod.simulate(t_end=2.0, dt=0.1, solver=solver, step=h)
        errors.append(np.max(np.abs(Y[:, 0] - Y[:, 1])))
    assert 0.85 * 2 ** order < errors[0] / errors[1] < 1.15 * 2 ** order


@needs_cc
@pytest.mark.parametrize("solver, order", [("euler", 1), ("rk4", 4)])
def test_c_fixed_step_convergence_order(solver, order):
    errors = []
    for h in ("0.02", "0.01"):
        _, data = run_c_csv(decay(), "--t-end", "2", "--solver", solver, "--step", h)
        errors.append(np.max(np.abs(data[:, 1] - data[:, 2])))
    assert 0.85 * 2 ** order < errors[0] / errors[1] < 1.15 * 2 ** order


def test_damped_model_matches_scipy():
    from scipy.integrate import solve_ivp

    def f(t, y):
        q, p = y
        return [p, -0.3 * p * abs(p) - 2 * math.sin(q) + math.cos(math.pi * t / 3) / 3
                + math.tanh(q) / 10 - q ** 3 / 7]

    t, Y = python_module(damped()).simulate(rtol=1e-11, atol=1e-12)
    ref = solve_ivp(f, (0, 10), [0.5, 0.0], t_eval=t, rtol=1e-12, atol=1e-13, method="DOP853")
    assert np.max(np.abs(Y[:, :2] - ref.y.T)) < 1e-8
    assert np.allclose(Y[:, 2], np.arctan2(Y[:, 1], Y[:, 0] + 3), rtol=1e-14)


@needs_cc
def test_every_function_prints_correctly_in_both_languages():
    cm, exprs = functions_model()
    header, data = run_c_csv(cm)
    t, Y = python_module(cm).simulate()
    assert np.array_equal(data[:, 0], t)
    ref = np.array([[float(e.subs({T: tk, X[0]: 0.25}).evalf(30)) for e in exprs] for tk in t])
    assert np.allclose(data[:, 1:], ref, rtol=1e-14, atol=1e-15)
    assert np.allclose(Y, ref, rtol=1e-14, atol=1e-15)


def test_python_rhs_matches_independent_evaluation():
    mod = python_module(damped())
    rng = np.random.default_rng(1)
    c, k, f = mod.PARAMETERS.values()
    for _ in range(20):
        t, (q, p) = rng.uniform(0, 10), rng.normal(size=2)
        expected = [p, -c * p * abs(p) - k * np.sin(q) + f * np.cos(np.pi * t / 3)
                    + np.tanh(q) / 10 - q ** 3 / 7]
        assert np.allclose(mod.rhs(t, [q, p], [c, k, f]), expected, rtol=1e-13, atol=1e-15)
        assert mod.outputs(t, [q, p], [c, k, f]).shape == (4,)


# ---------------------------------------------------------------- C and Python agree


@needs_cc
@pytest.mark.parametrize("args", [(), ("--solver", "rk4"), ("--solver", "euler", "--step", "0.01"),
                                  ("--t-end", "3.05", "--dt", "0.2", "-p", "k=9")])
def test_c_and_python_programs_agree(args, tmp_path):
    cm = damped() if not args else oscillator()
    code, c_out, c_err = run_c(c_program(cm, STRICT), args)
    py_code, py_out, py_err = run_python_program(cm, args, tmp_path)
    assert (code, py_code) == (0, 0), c_err + py_err
    c_header, c_data = parse_csv(c_out)
    py_header, py_data = parse_csv(py_out)
    assert c_header == py_header and c_data.shape == py_data.shape
    assert np.array_equal(c_data[:, 0], py_data[:, 0])
    assert np.allclose(c_data, py_data, rtol=1e-12, atol=1e-14)


@needs_cc
def test_stats_line(tmp_path):
    code, _, err = run_c(c_program(oscillator()), ["--stats"])
    py_code, _, py_err = run_python_program(oscillator(), ["--stats"], tmp_path)
    assert code == py_code == 0
    for text in (err, py_err):
        (line,) = [ln for ln in text.splitlines() if ln.startswith("stats:")]
        counts = dict(part.split("=") for part in line.split()[1:])
        steps, rejected, rhs = (int(counts[k]) for k in ("steps", "rejected", "rhs"))
        assert steps > 10 and rhs >= 6 * (steps + rejected)
        assert counts["jac"] == counts["lu"] == counts["solves"] == "0"  # dopri5


# ---------------------------------------------------------------- CSV and options


@needs_cc
@pytest.mark.parametrize("t_end, dt, times", [
    ("1", "0.3", [0, 0.3, 0.6, 0.9, 1.0]),
    ("1", "0.1", [round(0.1 * k, 12) for k in range(11)]),
    ("0.9999999999", "0.1", [round(0.1 * k, 12) for k in range(10)] + [0.9999999999]),
    ("0", "0.1", [0.0]),
])
def test_output_times(t_end, dt, times, tmp_path):
    for solver in ("dopri5", "rk4"):
        args = ("--t-end", t_end, "--dt", dt, "--solver", solver)
        code, out, _ = run_c(c_program(oscillator()), args)
        py_code, py_out, _ = run_python_program(oscillator(), args, tmp_path)
        assert code == py_code == 0
        for text in (out, py_out):
            lines = text.splitlines()
            assert lines[0] == "t,x,v,xref" and len(lines) == len(times) + 1
            assert [float(ln.split(",")[0]) for ln in lines[1:]] == pytest.approx(times)
            assert lines[-1].split(",")[0] == "%.17g" % float(t_end)  # exactly t_end
            assert lines[1].split(",")[1:3] == ["1", "0"]  # t0 row: the initial state


@needs_cc
def test_csv_numbers_are_printf_17g():
    _, out, _ = run_c(c_program(decay()), ["--t-end", "1"])
    for line in out.splitlines()[1:]:
        for field in line.split(","):
            assert field == "%.17g" % float(field)


@needs_cc
def test_parameter_override_recomputes_derived(tmp_path):
    header, data = run_c_csv(oscillator(), "-p", "k=9", "--rtol", "1e-10", "--atol", "1e-12")
    assert np.allclose(data[:, 3], np.cos(3 * data[:, 0]), atol=1e-15)  # w = sqrt(k/m) = 3
    assert oscillator_error(data[:, 0], data[:, 1:], k=9.0) < 1e-8
    _, data = run_c_csv(oscillator(), "-p", "k=9", "-p", "w=1")  # given w is not recomputed
    assert np.allclose(data[:, 3], np.cos(data[:, 0]), atol=1e-15)
    mod = python_module(oscillator())
    assert list(mod.PARAMETERS.items()) == [("k", 4.0), ("m", 1.0), ("w", 2.0)]
    t, Y = mod.simulate(params={"k": 9.0, "m": 1.0})
    assert np.allclose(Y[:, 2], np.cos(3 * t), atol=1e-15)
    with pytest.raises(ValueError, match="unknown parameter 'nope'"):
        mod.simulate(params={"nope": 1})


@needs_cc
@pytest.mark.parametrize("args, message", [
    (["--bogus"], "error: unknown option '--bogus'"),
    (["-p", "nope=1"], "error: unknown parameter 'nope'"),
    (["-p", "k"], "error: -p expects NAME=VALUE, got 'k'"),
    (["--dt", "abc"], "error: invalid value for --dt: 'abc'"),
    (["--dt", "0"], "error: --dt must be positive"),
    (["--dt"], "error: option '--dt' needs a value"),
    (["--solver", "rk45"], "error: unknown solver 'rk45' (expected "
                           f"{solvers.names_text()})"),
    (["--t-end", "-1"], "error: --t-end must not be before the start time"),
    (["-p", "k=nan"], "error: invalid value for k: 'nan'"),
])
def test_usage_errors_exit_2(args, message, tmp_path):
    for code, out, err in (run_c(c_program(oscillator()), args),
                           run_python_program(oscillator(), args, tmp_path)):
        assert code == 2 and out == ""
        assert err.splitlines()[0] == message


@needs_cc
def test_help_lists_parameters(tmp_path):
    for code, out, _ in (run_c(c_program(oscillator()), ["--help"]),
                         run_python_program(oscillator(), ["--help"], tmp_path)):
        assert code == 0 and out.startswith("usage: osc ") and "  w = 2\n" in out


# ---------------------------------------------------------------- runtime failures


@needs_cc
def test_non_finite_state_stops_with_partial_rows(tmp_path):
    args = ["--t-end", "2", "--dt", "0.1", "--solver", "rk4", "--step", "0.01"]
    for code, out, err in (run_c(c_program(blowup("mx.p")), args),
                           run_python_program(blowup("mx.p"), args, tmp_path)):
        assert code == 3
        assert "error: at t = " in err and "state 'mx.p' is not finite" in err
        t_fail = float(err.split("at t = ")[1].split(":")[0])
        assert 1.0 < t_fail < 1.1  # rk4 steps across the pole at t = 1, then overflows
        _, data = parse_csv(out)
        assert len(data) == 11 and data[-1, 0] == 1.0 and np.all(np.isfinite(data))
        assert data[-2, 1] == pytest.approx(10.0, rel=1e-3)  # the rows before are kept
    mod = python_module(blowup("mx.p"))
    with pytest.raises(mod.SimulationError, match="state 'mx.p' is not finite") as info:
        mod.simulate(t_end=2.0, solver="rk4", step=0.01)
    assert 1.0 < info.value.t < 1.1 and info.value.rows.shape == (11, 1)
    assert info.value.times[-1] == 1.0


@needs_cc
def test_step_size_too_small_names_time_and_state(tmp_path):
    args = ["--t-end", "2", "--dt", "0.25", "--rtol", "1e-8", "--atol", "1e-8"]
    for code, out, err in (run_c(c_program(blowup()), args),
                           run_python_program(blowup(), args, tmp_path)):
        assert code == 3
        assert "step size too small" in err and "state 'x'" in err
        t_fail = float(err.split("at t = ")[1].split(":")[0])
        assert abs(t_fail - 1.0) < 1e-6  # the pole of x = 1/(1 - t)
        assert parse_csv(out)[1][:4, 0].tolist() == [0, 0.25, 0.5, 0.75]


@needs_cc
def test_non_finite_derivative_at_start(tmp_path):
    for solver in ("dopri5", "euler"):
        args = ["--solver", solver]
        for code, out, err in (run_c(c_program(sqrt_of_negative()), args),
                               run_python_program(sqrt_of_negative(), args, tmp_path)):
            assert code == 3
            assert err.strip() == "error: at t = 0: derivative of state 'x' is not finite"
            assert out.splitlines() == ["t,x", "0,1"]


def test_python_ieee_fallback_gives_c_semantics():
    mod = python_module(sqrt_of_negative())
    dx = mod.rhs(0.0, [1.0], [])
    assert math.isnan(dx[0])
    assert mod.rhs(0.0, [6.0], [])[0] == 2.0


# ---------------------------------------------------------------- constraints


@needs_cc
def test_consistent_constraints_run(tmp_path):
    _, data = run_c_csv(circle(), "--rtol", "1e-10", "--atol", "1e-12")
    assert np.allclose(data[:, 1], np.cos(data[:, 0]), atol=1e-8)
    t, Y = python_module(circle()).simulate(rtol=1e-10, atol=1e-12)
    assert np.allclose(Y[:, 1], np.sin(t), atol=1e-8)


@needs_cc
def test_constraint_violation_exits_1_without_csv(tmp_path):
    cm = circle(x0=1.1, vx0=0.1)
    expected = ["error: initial conditions violate constraint 'rod' (position): residual = %.17g"
                % (1.1 * 1.1 - 1),
                "error: initial conditions violate constraint 'rod' (velocity): residual = %.17g"
                % (1.1 * 0.1)]
    for code, out, err in (run_c(c_program(cm), []), run_python_program(cm, [], tmp_path)):
        assert code == 1 and out == ""
        assert err.splitlines() == expected
    mod = python_module(cm)
    with pytest.raises(mod.ConstraintError) as info:
        mod.simulate()
    assert len(info.value.messages) == 2


@needs_cc
def test_project_initial(tmp_path):
    cm = circle(x0=1.1, y0=0.2, vx0=0.1, vy0=0.9)
    for code, out, err in (run_c(c_program(cm), ["--project-initial"]),
                           run_python_program(cm, ["--project-initial"], tmp_path)):
        assert code == 0, err
        x, y, vx, vy = parse_csv(out)[1][0, 1:]
        assert abs(x * x + y * y - 1) <= 1e-9 and abs(x * vx + y * vy) <= 1e-9
        assert math.atan2(y, x) == pytest.approx(math.atan2(0.2, 1.1))  # minimum-norm move
        assert (vx, vy) != (0.1, 0.9)
    t, Y = python_module(cm).simulate(project_initial=True)
    assert Y[0, 0] ** 2 + Y[0, 1] ** 2 == pytest.approx(1.0, abs=1e-9)


@needs_cc
def test_project_initial_singular_fails(tmp_path):
    cm = circle(x0=0.0, y0=0.0)  # J = [0, 0, 0, 0] at the origin
    for code, out, err in (run_c(c_program(cm), ["--project-initial"]),
                           run_python_program(cm, ["--project-initial"], tmp_path)):
        assert code == 1 and out == ""
        assert "cannot project the initial conditions onto the position constraints" in err
        assert "singular" in err


# ---------------------------------------------------------------- names


@needs_cc
def test_malicious_names_stay_literals(tmp_path):
    cm = evil()
    (source,) = emit_c(cm).values()
    assert 'system("rm' not in source and "\nline" not in source
    code, out, err = run_c(c_program(cm), ["-p", "int=3", "-p", EVIL[1] + "=2"])
    assert code == 0, err
    assert out.startswith("t," + ",".join(EVIL[2:]) + "\n")
    py_code, py_out, py_err = run_python_program(cm, ["-p", "int=3", "-p", EVIL[1] + "=2"],
                                                 tmp_path)
    assert py_code == 0, py_err
    assert py_out.startswith("t," + ",".join(EVIL[2:]) + "\n")
    mod = python_module(cm)
    assert mod.STATES == list(EVIL[:2]) and mod.OUTPUTS == list(EVIL[2:])
    assert list(mod.PARAMETERS)[-2:] == list(EVIL[:2])
    code, _, err = run_c(c_program(cm), ["-p", EVIL[0] + "=x"])
    assert code == 2 and err == "error: invalid value for %s: 'x'\n" % EVIL[0]


# ---------------------------------------------------------------- the %.17g formatter

_FORMAT_DRIVER = r"""
#undef main
static unsigned long long rng = 88172645463325252ULL;
static unsigned long long next64(void)
{
    rng ^= rng << 13;
    rng ^= rng >> 7;
    rng ^= rng << 17;
    return rng;
}
static double unif(void) { return (double)(next64() >> 11) / 9007199254740992.0; }
static double pick(long i)
{
    double v;
    unsigned long long b;
    long j;
    switch (i % 8) {
    case 0: /* any bit pattern but NaN */
        do {
            b = next64();
            memcpy(&v, &b, sizeof v);
        } while (v != v);
        return v;
    case 1: return ldexp(1.0 + unif(), (int)(next64() % 220) - 70);
    case 2: return unif() * pow(10.0, (int)(next64() % 100) - 50); /* across 1e-40..1e40 */
    case 3: /* powers of ten and their neighbours */
        v = pow(10.0, (int)(next64() % 60) - 14);
        for (j = (long)(next64() % 7) - 3; j > 0; j--)
            v = nextafter(v, HUGE_VAL);
        for (j = (long)(next64() % 7) - 3; j < 0; j++)
            v = nextafter(v, 0.0);
        return v;
    case 4: return ldexp((double)(next64() % 100000000), -(int)(next64() % 60)); /* ties */
    case 5: return (double)(long)(next64() % 100000) * 0.01;
    case 6: return (double)(next64() >> (next64() % 64));
    default: return -pick(i + 1 + (long)(next64() % 6));
    }
}
int main(int argc, char **argv)
{
    long n = atol(argv[1]), i, bad = 0;
    unsigned long typical_slow;
    char a[64], b[64];
    static const double edge[] = { 0.0, -0.0, 1.0, -1.0, 0.1, 1e16, 1e17, 9.9999999999999998e16,
                                   1e-5, 1e-4, 123456789012345680.0, 5e-324, 2.2250738585072014e-308,
                                   1.7976931348623157e308, 1e23, 8.5e-12, 9.5e43, 0.5 };
    for (i = 0; i < n; i++) {
        double v = i < 18 ? edge[i] : i < 20 ? (i == 18 ? HUGE_VAL : -HUGE_VAL) : pick(i);
        bgc_fmt17(a, v);
        snprintf(b, sizeof b, "%.17g", v);
        if (strcmp(a, b) != 0 && bad++ < 10)
            printf("mismatch %a: %s %s\n", v, a, b);
    }
    bgc_fmt17(a, nan(""));
    bgc_fmt_slow_count = 0;
    for (i = 0; i < 100000; i++)
        bgc_fmt17(b, (unif() - 0.5) * pow(10.0, (int)(i % 12) - 5));
    typical_slow = bgc_fmt_slow_count;
    printf("mismatches=%ld nan=%s typical_slow=%lu\n", bad, a, typical_slow);
    return 0;
}
"""


@needs_cc
@pytest.mark.parametrize("flags", [(), ("-DBGC_NO_INT128",)], ids=["int128", "portable"])
def test_fast_formatter_equals_snprintf(flags):
    (source,) = emit_c(oscillator()).values()
    exe = compile_c(source + _FORMAT_DRIVER,
                    flags=("-O2", "-std=c99", "-Dmain=bgc_main") + flags)
    code, out, err = run_c(exe, ["1200000"], timeout=120)
    assert code == 0, err
    summary = out.splitlines()[-1]
    fields = dict(item.split("=") for item in summary.split())
    assert fields["mismatches"] == "0", out
    assert fields["nan"] == "nan"
    assert int(fields["typical_slow"]) < 10  # the fast path decides all but exact ties


_DIGITS_DRIVER = r"""
#undef main
int main(void)
{
    unsigned long v, bad = 0, n = 0;
    for (v = 0; v < 100000000UL; v += v < 200000UL || v > 99800000UL ? 1 : 997) {
        bgc_u64 w = bgc_digits8(v), u = v;
        int i;
        for (i = 7; i >= 0; i--, u /= 10)
            if ((int)((w >> (8 * i)) & 0xff) != '0' + (int)(u % 10) && bad++ < 10)
                printf("wrong digits of %lu\n", v);
        n++;
    }
    printf("checked=%lu bad=%lu\n", n, bad);
    return 0;
}
"""


def test_runtime_carries_the_pow10_table():
    """The formatter's table in bgc/runtime/main.c is pow10_table(POW10_RANGE), exactly."""
    runtime = (HERE.parent / "bgc" / "runtime" / "main.c").read_text()
    rows = re.findall(r"\{ 0x([0-9a-f]{16})ULL, 0x([0-9a-f]{16})ULL, (-?\d+) \}, /\* 1e(-?\d+) \*/",
                      runtime)
    expected = [(r["hi"], r["lo"], str(r["e2"]), str(r["m"])) for r in pow10_table(*POW10_RANGE)]
    assert rows == expected
    assert f"#define BGC_POW10_MIN ({POW10_RANGE[0]})" in runtime
    assert f"#define BGC_POW10_MAX {POW10_RANGE[1]}" in runtime


@needs_cc
def test_digit_words_are_exact():
    (source,) = emit_c(oscillator()).values()
    exe = compile_c(source + _DIGITS_DRIVER, flags=("-O2", "-std=c99", "-Dmain=bgc_main"))
    code, out, err = run_c(exe)
    assert code == 0, err
    assert out.splitlines()[-1].endswith(" bad=0"), out



def test_straight_line_code_splits_where_no_temporary_crosses():
    """The parameters' defaults and constants, when long, as chunks of about
    PARAMETER_CHUNK lines, each ending where every temporary it defines is read no more."""
    from bgc.codegen.emit import _line_chunks
    short = [f"p->c[{k}] = 1.0/p->p_r{k};" for k in range(10)]
    assert _line_chunks(short, 4) == [short[0:4], short[4:8], short[8:10]]
    assert _line_chunks(short, 10) == [short]
    held = ["const double w1 = p->p_a*p->p_b;", "p->c[0] = w1;", "p->c[1] = 2.0;",
            "p->c[2] = w1 + 1.0;", "const double w2 = p->p_c;", "p->c[3] = w2;", "p->c[4] = 3.0;"]
    assert _line_chunks(held, 2) == [held[0:4], held[4:6], held[6:]]


@needs_cc
def test_parameters_and_constants_in_several_functions_give_the_python_bytes(tmp_path,
                                                                             monkeypatch):
    """A ladder whose every element has its own parameter, its defaults and constants split
    into functions of 8 lines (PARAMETER_CHUNK, 256 in use, made small here): the C program
    gives the Python module's numbers, bit for bit, with the defaults and with a late
    parameter given."""
    from bgc.codegen import emit
    monkeypatch.setattr(emit, "PARAMETER_CHUNK", 8)
    n = 12
    lines = ['model many "a ladder with a parameter per element"', "src : Se(1.0)"]
    for k in range(1, n + 1):
        before = "src" if k == 1 else f"n{k - 1}"
        lines += [f"parameter r{k} = 1.0 + 0.01*{k}", f"parameter c{k} = 0.01*(1 + {k % 7})",
                  f"j{k} : 1", f"res{k} : R(r{k})", f"n{k} : 0", f"cap{k} : C(c{k})",
                  f"{before} -> j{k} -> n{k}", f"j{k} -> res{k}", f"n{k} -> cap{k}"]
    lines += ["open : Sf(0)", f"n{n} -> open",
              f"scene run {{ outputs cap1.q, cap{n}.q; time 0 .. 0.2 every 0.05 }}"]
    model = tmp_path / "many.bg"
    model.write_text("\n".join(lines) + "\n")
    (text,) = emit_c(api.build(model, "run").program, linked=True).values()
    assert "bgc_params_defaults_2(p, given);" in text and "bgc_params_update_2(p);" in text
    for params in (None, {f"c{n - 1}": 0.02}):
        t, y, _ = api.simulate(model, "run", backend="c", params=params)
        t_py, y_py, _ = api.simulate(model, "run", backend="python", params=params)
        assert np.array_equal(t, t_py) and np.array_equal(y, y_py) and np.all(y[1:] > 0)


def test_a_long_chunk_splits_between_statements_outside_braces():
    """A split never falls inside braces (a loop of stores), between an `if` and the line it
    guards, nor where a temporary is still to be read."""
    from bgc.codegen.emit import _line_chunks
    lines = ["wv[0] = x[0];", "{", "    int bgc_k;", "    for (bgc_k = 0; bgc_k < 9; ++bgc_k)",
             "        out[bgc_k] = x[bgc_k];", "}", "wv[1] = x[1];",
             "if (bgc_block_solve(w, 0, t))", "    return 1;", "const double w3 = wv[5];",
             "out[0] = wv[2];", "out[1] = w3;", "out[2] = 1.0;"]
    assert _line_chunks(lines, 1) == [lines[:1], lines[1:6], lines[6:7], lines[7:9],
                                      lines[9:12], lines[12:]]


@needs_cc
def test_model_functions_split_into_short_functions_write_the_python_bytes(monkeypatch):
    """A right side in chunks of few operations, each chunk's lines in functions of at most
    8 (FUNCTION_LINES, 500 in use, made small here), block solves among them: the C program
    writes the Python module's bytes."""
    from bgc.codegen import emit
    ladder = ['model rl "resistor ladder with symbolic resistances"', "parameter V0 = 10.0",
              "parameter Cc = 0.2", "src : Se(V0)", "cap : C(Cc)"]
    before = "src"
    for k in range(1, 9):
        ladder += [f"parameter Rs{k} = {1 + k / 10}", f"parameter Rp{k} = {2 + k / 20}",
                   f"s{k} : 1", f"rs{k} : R(Rs{k})", f"n{k} : 0", f"rp{k} : R(Rp{k})",
                   f"{before} -> s{k} -> n{k}", f"s{k} -> rs{k}", f"n{k} -> rp{k}"]
        before = f"n{k}"
    ladder += ["last : 1", "rl : R(Rs1)", f"{before} -> last -> cap", "last -> rl"]
    program = api.build(api.Source("rl.bg", "\n".join(ladder) + "\n"), None).program
    outs = []
    for lines in (500, 8):
        monkeypatch.setattr(emit, "FUNCTION_LINES", lines)
        (text,) = emit_c(program, chunk_ops=30).values()
        outs.append(run_c(compile_c(text), ["--t-end", "0.5"]))
        assert len(re.findall(r"^static int bgc_rhs_\d+\(", text, re.M)) > (6 if lines == 8 else 0)
    (py,) = emit_python(program, chunk_ops=30).values()
    from bgc.base.processes import run_python
    outs.append(run_python(py, ["--t-end", "0.5"]))
    assert outs[0][0] == 0 and outs[0] == outs[1] == outs[2], outs[0][2]
