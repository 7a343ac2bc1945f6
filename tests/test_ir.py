"""The code model between reduce and emit: one statement vocabulary (bgc.ir), one pruning
pass, one forward-mode pass that every derived function comes from."""
from __future__ import annotations

from pathlib import Path

import sympy as sp

from bgc import api, ir
from bgc.symbolic import canonical
from bgc.symbolic.differentiate import directional
from bgc.ir import P, T, V, W, X, Assign, Newton, Param, Resolve, SceneSettings, Solve, Store
from bgc.codegen.lower import explicit_program, with_tangent
from helpers import families

ROOT = Path(__file__).resolve().parent.parent
SCENE = SceneSettings(0.0, 1.0, 0.1, "dopri5", 1e-6, 1e-9, None)


def evaluate(f: ir.Function, values: dict) -> list:
    """The results of a function without blocks, by substitution, statement by statement."""
    env, out = dict(values), [None] * f.size
    for s in f.body:
        assert isinstance(s, (Assign, Store)), s
        value = s.expr.xreplace(env)
        if isinstance(s, Assign):
            env[s.target] = value
        else:
            out[s.index] = value
    return out


def test_reduce_hands_on_ir_statements():
    """A pendulum chain solved numerically: reduce's steps are IR statements over model
    symbols, each block's statement indexing its plan, the unknowns in the plan's order."""
    compiled = api.build(ROOT / "models" / "double_pendulum.bg", algebra="numeric")
    steps, plans = compiled.reduced.steps, compiled.reduced.plans
    assert {type(s) for s in steps} <= {Assign, Solve, Newton}
    blocks = [s for s in steps if not isinstance(s, Assign)]
    assert blocks and [s.block for s in blocks] == list(range(len(plans)))
    for s in blocks:
        lu = plans[s.block].lu
        assert tuple(u.name for u in s.unknowns) == tuple(plans[s.block].unknowns[c]
                                                          for c in lu.col_of)
        if isinstance(s, Solve):
            assert len(s.matrix) == len(plans[s.block].pattern) == len(lu.entries)


def test_prune_keeps_what_the_stores_need():
    """Backwards from the stores: an unused assignment goes, a Resolve keeps its block's Solve
    though nothing reads the Solve's unknowns."""
    a, b, z, dz = W(0), W(1), W(2), W(3)
    body = (Assign(a, X[0] + 1), Assign(b, X[1] * 2),
            Solve(0, (z,), (X[0],), (X[1],)), Resolve(0, (dz,), (V[0],)), Store(0, dz + b))
    assert ir.prune(body) == body[1:]
    assert ir.prune(body[:3] + (Store(0, b),)) == (body[1], Store(0, b))
    assert ir.prune(body[:3] + (Store(0, z * a),)) == (body[0], body[2], Store(0, z * a))


def test_output_tangents_are_the_outputs_directional_derivatives():
    """with_tangent on a finished program (constants hoisted, temporaries named): the FMU's
    outputs_jvp equals the derivative of each output along v."""
    x0, x1, k = X[0], X[1], P[0]
    outputs = [k * sp.sin(x0) * x1 + x0 ** 2, sp.exp(k * 2 * x1) * sp.sin(x0), x1]
    program = explicit_program("m", ("a", "b"), (Param("k", sp.Float(1.5)),), ("y0", "y1", "y2"),
                               [0, 0], [x1, -k * x0], outputs, SCENE)
    derived = with_tangent(program, "outputs", "outputs_jvp")
    assert set(derived.functions) == set(program.functions) | {"outputs_jvp"}
    f = derived.function("outputs_jvp")
    assert f.args == ("t", "x", "p", "v") and f.size == len(outputs)
    point = {x0: sp.Rational(3, 10), x1: sp.Rational(-7, 10), V[0]: 2, V[1]: sp.Rational(1, 3),
             k: sp.Rational(3, 2), T: 0}
    consts = evaluate(derived.function("consts"), point)
    point.update({ir.C[j]: c for j, c in enumerate(consts)})
    got = evaluate(f, point)
    for y, g in zip(outputs, got):
        want = directional(y, {x0: V[0], x1: V[1]}).xreplace(point)
        assert abs(float(g - want)) < 1e-12


def test_output_tangents_go_through_a_newton_block():
    """The diode's current is solved by Newton's method: its tangent function solves the block
    with its final factors and resolves with them."""
    compiled = api.build(ROOT / "models" / "diode.bg", "charge")
    assert any(isinstance(s, Newton) for s in compiled.program.function("outputs").body)
    f = with_tangent(compiled.program, "outputs", "outputs_jvp").function("outputs_jvp")
    newtons = [s for s in f.body if isinstance(s, Newton)]
    resolves = [s for s in f.body if isinstance(s, Resolve)]
    assert newtons and all(s.final_factor for s in newtons)
    assert {s.block for s in resolves} == {s.block for s in newtons}


def test_remembered_free_symbols_are_sympys():
    a, b, u = sp.symbols("a b u")
    f = sp.Function("f")
    shared = sp.sin(X[0] * a) + P[1]
    for e in (shared, shared * W(3) + 1, sp.Derivative(f(u) * a, u), sp.Integer(2),
              sp.Piecewise((X[2], sp.Gt(u, 0)), (b, True)), sp.Abs(a - W(0)) ** 2, X[1]):
        assert ir.free_symbols(e) == e.free_symbols
        assert ir.free_symbols(e) is ir.free_symbols(e)  # remembered


def test_the_collector_is_restored_after_a_compile():
    import gc

    from bgc.base.resources import COMPILE_GC_THRESHOLD, quiet_collector

    before = gc.get_threshold()
    with quiet_collector():
        assert gc.get_threshold()[0] == COMPILE_GC_THRESHOLD
        with quiet_collector():  # nested: the outer one's
            assert gc.get_threshold()[0] == COMPILE_GC_THRESHOLD
        assert gc.get_threshold()[0] == COMPILE_GC_THRESHOLD
    assert gc.get_threshold() == before and gc.get_freeze_count() == 0


def test_a_parsed_model_is_set_aside_for_the_compile_only():
    """Within a compile the parsed model is left out of the collector's walks (gc.freeze);
    the compile's end undoes it, and a parse outside a compile freezes nothing."""
    import gc

    from bgc.base.resources import quiet_collector
    from bgc.front.parser import parse

    text = "model m\nx : C(1)\ny : R(2)\nx -> y\n"
    parse(text)
    assert gc.get_freeze_count() == 0 and gc.isenabled()
    with quiet_collector():
        model = parse(text)
        assert gc.get_freeze_count() > 0 and gc.isenabled()
    assert gc.get_freeze_count() == 0 and model.decls


def test_one_pruning_walk_keeps_what_each_function_needs():
    """ir.prune_each prunes the steps for several functions in one walk: each function's
    statements are what ir.prune keeps for its stores alone (the double pendulum's program,
    with a block, and stores that read different parts of it, none at all included)."""
    compiled = api.build(ROOT / "models" / "double_pendulum.bg", algebra="numeric")
    reduced = compiled.reduced
    steps = list(reduced.steps)
    states = [st.symbol for st in reduced.states]
    rates = [Store(k, e) for k, e in enumerate(reduced.rates)]
    results = [rates, [Store(0, states[0])], [], rates[1:2] + [Store(1, states[-1] * 2)],
               [Store(k, o.expr) for k, o in enumerate(reduced.outputs)]]
    assert ir.prune_each(steps, results) == [ir.prune(steps + r) for r in results]
    assert any(isinstance(s, Solve) for s in ir.prune_each(steps, results)[0])
    # a body holding a Resolve keeps the rule that a kept Resolve keeps its block's Solve
    a, z, dz = W(0), W(2), W(3)
    body = [Assign(a, X[0] + 1), Solve(0, (z,), (X[0],), (X[1],)), Resolve(0, (dz,), (V[0],))]
    stores = [[Store(0, dz)], [Store(0, a)]]
    assert ir.prune_each(body, stores) == [ir.prune(body + r) for r in stores]


def test_remembered_integral_floats_are_integers():
    """ir.integral_floats: floats with an integral value become integers, others stay, in a
    subexpression met again too."""
    a = sp.Symbol("a")
    inner = sp.Float(2.0) * sp.sin(a) + sp.Float(0.5)
    assert ir.integral_floats(inner) == 2 * sp.sin(a) + sp.Float(0.5)
    outer = inner * X[0] + sp.Float(3.0)
    assert ir.integral_floats(outer) == (2 * sp.sin(a) + sp.Float(0.5)) * X[0] + 3
    assert ir.integral_floats(sp.Float(2.0 ** 60) * a) == sp.Float(2.0 ** 60) * a  # beyond 2^53
    assert ir.integral_floats(a + 1) is not None and ir.integral_floats(X[1]) == X[1]


def test_sums_and_products_built_the_short_way_are_sympys(monkeypatch):
    """bgc.symbolic.canonical.new builds Add and Mul without SymPy's flattening where it would only
    sort: node
    for node (the same arguments in the same order) what SymPy's constructor builds, on cases
    where terms or factors combine, a number multiplies a sum, or the numbers are special, and
    on every sum and product the passes build while compiling two whole models."""
    x, y, z = sp.symbols("x y z", real=True)
    w, u = W(3), W(12)
    half = sp.Float(0.5)
    unevaluated = sp.Abs(x, evaluate=False)
    cases = {
        sp.Add: [(x, y), (x, 2 * x), (x,), (), (0, x), (sp.S.Zero, -2), (x, 1), (2.5, x), (3, x * y), (half, x, -y), (x, x + y), (x ** 2, x),
                 (sp.sqrt(2), 3), (sp.Float(0.0), x), (sp.Mul(2, x + y, evaluate=False), z),
                 (sp.Mul(1, x, evaluate=False), y), (sp.oo, x), (sp.nan, x), (sp.zoo, x),
                 (sp.exp(x), sp.exp(y)), (X[0], -X[1], 2 * P[0] * w), (w, u, -w * u),
                 (sp.Pow(2, 3, evaluate=False), x), (sp.Rational(1, 3) * w, 2.5 * u),
                 (unevaluated, -unevaluated), (sp.sin(x), -sp.sin(x) * y, sp.cos(x)),
                 (x, y + z), (half, sp.Add(1.5, x), y), (2 * x, sp.Add(y, -2 * x)),
                 (sp.Float(0.1), sp.Float(0.2), sp.Add(sp.Float(0.3), x, evaluate=False))],
        sp.Mul: [(x, y), (2, x + y), (2.0, x + y), (-1, x + y), (x + y, z), (x, x ** 2),
                 (sp.exp(x), sp.exp(y)), (sp.exp_polar(x), sp.exp_polar(y)), (2, 3, x), (sp.sqrt(2), sp.sqrt(3)), (x, 1 / x),
                 (-1, x), (sp.Float(1.0), x), (0, x), (sp.I, x), (2 ** x, 3 ** x),
                 (x ** 2, y ** -1, w), (unevaluated, unevaluated ** 2), (2 * x, y),
                 (sp.Rational(1, 2), w, u ** -2, X[0] + P[1]), (half, sp.oo, x),
                 (sp.Piecewise((x, y > 0), (0, True)), w), (sp.Abs(x), X[2]),
                 (2, sp.Mul(3, x + y, evaluate=False)), (x, sp.Mul(2, x + y, evaluate=False)),
                 (x * y, 2 * z), (3, 2 * x * y), (x,), (), (sp.S.One, x), (2, sp.S.One), (x, y * x ** -1), (half, 3 * w, u),
                 (sp.Float(0.1), sp.Mul(sp.Float(0.3), x, evaluate=False), sp.Float(0.7))],
    }
    for cls, all_args in cases.items():
        for args in all_args:
            built, expected = canonical.new(cls, args), cls(*args)
            assert type(built) is type(expected) and built == expected, (cls, args)
            assert built.args == expected.args, (cls, args)
    monkeypatch.setattr(canonical, "VERIFY", True)  # every short way checked against SymPy's
    short = []
    checked = canonical._checked
    monkeypatch.setattr(canonical, "_checked", lambda cls, args, fast: short.append(fast is not None)
                        or checked(cls, args, fast))
    api.build(api.Source("chain3.bg", families.pendulum_chain(3)), "swing")
    api.build(api.Source("ladder.bg", families.resistor_ladder(4)))
    assert sum(short) > 0.8 * len(short)  # (most go the short way)


def test_substitution_the_short_way_is_sympys_xreplace():
    """bgc.symbolic.canonical.xreplace (reduce's leaf forms): node for node what SymPy's xreplace
    builds,
    functions evaluated (an unevaluated Abs too), sums and products merged where they meet."""
    x, y, z = sp.symbols("x y z", real=True)
    exprs = [x + y, x * y + 2 * z, sp.Abs(x - y, evaluate=False) * z, sp.sin(x) ** 2 + x * y,
             sp.Piecewise((x, y > 0), (z, True)) + 1, (x + y) ** -1 * z, x]
    for rule in ({x: y}, {x: -y, z: 2 * y}, {x: sp.Integer(0)}, {y: x + z, z: sp.Float(1.5)},
                 {x: sp.Integer(-3)}, {}):
        for e in exprs:
            built, expected = canonical.xreplace(e, rule), e.xreplace(rule)
            assert type(built) is type(expected) and built == expected, (e, rule)
            assert built.args == expected.args, (e, rule)
