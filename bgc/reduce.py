"""Stage 6, reduce: explicit state derivatives, multipliers and outputs in SymPy.

1. The assignments are ordered by their dependencies (strongly connected components, in a
   deterministic order); a component of more than one variable is an algebraic loop, solved
   symbolically (linear: exactly; nonlinear: SymPy's solve, or a located error).
2. Storage in derivative causality and constraint multipliers are the remaining unknowns Z: each
   derivative store gives `output = d/dt(state_expr)`, each constraint its acceleration-level
   equation with the corrector (eq. 2/3 of the paper).  Both are linear in Z; Z is solved
   symbolically (the code model could instead carry the linear system for a numeric solve).
3. A holonomic constraint's Phi comes from the balance written in the integrated coordinates
   (integrability test, antiderivative, `init`/`phi` annotation).
4. What the scene's outputs do not need is pruned.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import sympy as sp
from sympy.solvers.solveset import NonlinearError

from .diagnostics import Collector, ModelError, Span, fail, warning
from .equations import ConstraintEq, EquationSystem
from .resolve import TIME, var
from .scene import parameter_values

RELATIVE_TOLERANCE = 1e-9


@dataclass(frozen=True)
class Loop:
    variables: tuple[str, ...]
    elements: tuple[str, ...]
    linear: bool


@dataclass(frozen=True)
class ConstraintResult:
    junction: str
    kind: str  # detected or declared: holonomic | nonholonomic
    detected: bool  # kind found by the integrability test (not declared)
    corrector: str
    gains: tuple
    multiplier: sp.Expr  # explicit, in states, parameters and t
    balance: sp.Expr  # explicit: dPhi/dt (holonomic) or Phi (nonholonomic)
    phi: sp.Expr | None  # holonomic Phi(q, t)
    residual: sp.Expr  # what NAME.residual reports
    span: Span


@dataclass(frozen=True)
class StateEq:
    symbol: sp.Symbol
    name: str
    rhs: sp.Expr
    init: sp.Expr


@dataclass(frozen=True)
class Output:
    name: str
    expr: sp.Expr


@dataclass(frozen=True)
class Reduced:
    system: EquationSystem
    states: tuple[StateEq, ...]  # pruned to what the outputs need
    outputs: tuple[Output, ...]
    constraints: tuple[ConstraintResult, ...]
    eliminated: tuple[tuple[str, sp.Expr], ...]  # derivative-causality states, explicit
    loops: tuple[Loop, ...]
    pruned: tuple[str, ...]  # states not integrated because no output needs them
    warnings: tuple


# ---------------------------------------------------------------- ordering

def _components(targets, deps):
    """Tarjan's SCCs, iterative; dependencies come out before their dependents."""
    index, low, on_stack, stack, out = {}, {}, set(), [], []
    counter = 0
    for root in targets:
        if root in index:
            continue
        work = [(root, iter(deps[root]))]
        index[root] = low[root] = counter
        counter += 1
        stack.append(root)
        on_stack.add(root)
        while work:
            v, it = work[-1]
            advanced = False
            for w in it:
                if w not in index:
                    index[w] = low[w] = counter
                    counter += 1
                    stack.append(w)
                    on_stack.add(w)
                    work.append((w, iter(deps[w])))
                    advanced = True
                    break
                if w in on_stack:
                    low[v] = min(low[v], index[w])
            if advanced:
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[v])
            if low[v] == index[v]:
                comp = []
                while True:
                    w = stack.pop()
                    on_stack.discard(w)
                    comp.append(w)
                    if w == v:
                        break
                out.append(sorted(comp, key=targets.index))
    return out


def _solve_linear(eqs, unknowns, what: str, span, names):
    try:
        A, b = sp.linear_eq_to_matrix(eqs, unknowns)
    except NonlinearError:
        return None
    if len(unknowns) == 1:
        a = sp.cancel(A[0, 0])
        if a == 0:
            fail(span, f"{what} is singular: {names} cannot be determined")
        return [b[0] / a]
    if sp.simplify(A.det()) == 0:
        fail(span, f"{what} is singular: {names} cannot be determined")
    return list(A.LUsolve(b))


def _ordered(es: EquationSystem):
    """Local solutions: each variable in terms of variables outside its own component."""
    assign = {a.target: a for a in es.assignments}
    targets = [a.target for a in es.assignments]
    diags = Collector()
    seen = {}
    for a in es.assignments:
        if a.target in seen:
            diags.error(a.span, f"'{a.target}' is computed twice (by '{seen[a.target].origin}' and "
                                f"'{a.origin}'): check the causality of the model")
        seen[a.target] = a
    diags.raise_if_errors()
    deps = {v: sorted((s for s in assign[v].expr.free_symbols if s in assign),
                      key=targets.index) for v in targets}
    local, order, loops = {}, [], []
    for comp in _components(targets, deps):
        order.extend(comp)
        if len(comp) == 1 and comp[0] not in deps[comp[0]]:
            local[comp[0]] = assign[comp[0]].expr
            continue
        loops.append(_solve_loop(comp, assign, local))
    return local, order, loops


def _tear(comp, assign):
    """Substitute loop variables into each other until only tear variables remain.

    Returns (tears, equations over the tears, eliminated [(v, expr)] in elimination order)."""
    defs = {v: assign[v].expr for v in comp}
    eliminated = []
    for v in comp:
        expr = defs[v]
        if v in expr.free_symbols:
            continue  # v refers to itself by now: a tear variable
        del defs[v]
        for u in defs:
            if v in defs[u].free_symbols:
                defs[u] = defs[u].xreplace({v: expr})
        eliminated = [(w, e.xreplace({v: expr}) if v in e.free_symbols else e)
                      for w, e in eliminated]
        eliminated.append((v, expr))
    tears = [v for v in comp if v in defs]
    return tears, [v - defs[v] for v in tears], eliminated


def _solve_loop(comp, assign, local) -> Loop:
    elements = tuple(dict.fromkeys(assign[v].origin for v in comp))
    names = ", ".join(f"'{e}'" for e in elements)
    span = assign[comp[0]].span
    tears, eqs, eliminated = _tear(comp, assign)
    sol = _solve_linear(eqs, tears, f"the algebraic loop through {names}", span, names)
    linear = sol is not None
    if sol is None:
        sol = _solve_nonlinear(eqs, tears, names, span)
    solved = {v: sp.together(s) for v, s in zip(tears, sol)}
    for v, expr in eliminated:
        solved[v] = expr.xreplace(solved)
    for v in comp:
        local[v] = solved[v]
    return Loop(tuple(str(v) for v in comp), elements, linear)


def _solve_nonlinear(eqs, tears, names, span):
    # SymPy is tried on small polynomial systems only; transcendental loops would grind for
    # minutes to end in no closed form anyway.
    polynomial = all(e.is_polynomial(*tears) for e in eqs)
    try:
        sols = sp.solve(eqs, tears, dict=True) if polynomial and len(tears) <= 3 else []
    except NotImplementedError:
        sols = []
    if len(sols) != 1 or any(v not in sols[0] for v in tears):
        how = f"{len(sols)} solutions" if len(sols) > 1 else "no closed-form solution"
        fail(span, f"nonlinear algebraic loop through {names}: SymPy finds {how}; break the "
                   "loop (e.g. add a small storage element) or write a law the other way round")
    return [sols[0][v] for v in tears]


def _substituted(local, order, frozen=frozenset()):
    """Every variable in terms of leaves (states, parameters, t, unknowns, frozen variables)."""
    full = {}
    for v in order:
        if v in frozen:
            full[v] = v
            continue
        e = local[v]
        sub = {s: full[s] for s in e.free_symbols if s in full}
        full[v] = e.xreplace(sub) if sub else e
    return full


def _subst(expr, full):
    sub = {s: full[s] for s in expr.free_symbols if s in full}
    return expr.xreplace(sub) if sub else expr


def _total_derivative(expr, rates: dict):
    """d/dt of expr(x, t) given dx/dt for each state."""
    d = sp.diff(expr, TIME)
    for x, dx in rates.items():
        if expr.has(x):
            d += sp.diff(expr, x) * dx
    return _clean(d)


def _clean(expr):
    """Drop DiracDelta terms that differentiating sign/abs leaves (zero almost everywhere)."""
    if expr.has(sp.DiracDelta):
        expr = expr.replace(lambda e: isinstance(e, sp.DiracDelta), lambda e: sp.Integer(0))
    return expr


# ---------------------------------------------------------------- constraints

def _coordinates_form(c: ConstraintEq, es, local, order, states):
    """The balance as sum_i a_i(q, t) dq_i/dt + a_0(q, t), or None with a reason."""
    integrals = [s for s in es.states if s.origin in {g.name for g in es.graph.signals}]
    if not integrals:
        return None, "no integral signal integrates its flows into coordinates"
    targets = set(local)
    frozen = frozenset(_alias_chain(local, st.derivative.free_symbols & targets)
                       for st in integrals)
    frozen = frozenset().union(*frozen)
    ff = _substituted(local, order, frozen)
    balance = _subst(c.balance, ff)
    coords = [st.symbol for st in integrals]
    rates = {st.symbol: var(f"d{st.name}/dt") for st in integrals}
    others = {st.symbol for st in states} - set(coords)
    unknowns = sorted((s for s in balance.free_symbols if s in frozen or s in others), key=str)
    if unknowns:
        eqs = [_subst(st.derivative, ff) - rates[st.symbol] for st in integrals]
        eqs = [e for e in eqs if e.free_symbols & set(unknowns)]
        sols = sp.solve(eqs, unknowns, dict=True) if eqs else []
        if len(sols) != 1 or any(u not in sols[0] for u in unknowns):
            return None, "its flows are not all integrated into coordinates by integral signals"
        balance = balance.xreplace(sols[0])
    leftover = balance.free_symbols & (targets | others)
    if leftover:
        return None, "its flows are not all integrated into coordinates by integral signals"
    coeffs = {q: sp.diff(balance, rates[q]) for q in coords}
    a0 = sp.expand(balance.xreplace({r: 0 for r in rates.values()}))
    if any(co.free_symbols & set(rates.values()) for co in coeffs.values()):
        return None, "it is not linear in the coordinate rates"
    return (coeffs, a0), None


def _alias_chain(local, symbols):
    """For each symbol, what it is a plain alias of at the end of its chain (vx.f -> f[vx->mx])."""
    out = set()
    for s in symbols:
        seen = {s}
        while isinstance(local.get(s), sp.Symbol) and local[s] in local and local[s] not in seen:
            s = local[s]
            seen.add(s)
        out.add(s)
    return frozenset(out)


def _integrable(coeffs, a0) -> bool:
    """Closed 1-form test over (q, t): d a_i / d z_j == d a_j / d z_i for every pair."""
    comps = list(coeffs.items()) + [(TIME, a0)]
    zs = [q for q, _ in comps]
    for i, (qi, ai) in enumerate(comps):
        for qj, aj in comps[i + 1:]:
            if sp.simplify(sp.diff(ai, qj) - sp.diff(aj, qi)) != 0:
                return False
    return bool(zs)


def _potential(coeffs, a0, span, name):
    comps = list(coeffs.items()) + [(TIME, a0)]
    P = sp.Integer(0)
    for z, a in comps:
        rest = sp.simplify(a - sp.diff(P, z))
        if rest == 0:
            continue
        term = sp.integrate(rest, z)
        if term.has(sp.Integral):
            fail(span, f"cannot integrate the balance of '{name}' symbolically: give "
                       "'phi = ...' on the junction")
        P += term
    zero = {z: 0 for z, _ in comps}
    return sp.simplify(P - P.xreplace(zero))


def _phi(c: ConstraintEq, form, es, init_values):
    coeffs, a0 = form
    if c.annotation is not None and c.annotation[0] == "phi":
        phi, span = c.annotation[1], c.annotation[2]
        for z, a in list(coeffs.items()) + [(TIME, a0)]:
            if sp.simplify(sp.diff(phi, z) - a) != 0:
                fail(span, f"phi of '{c.junction}' does not match its flow balance: "
                           f"d(phi)/d{z} = {sp.diff(phi, z)}, the balance has {a}")
        return phi, None
    P = _potential(coeffs, a0, c.span, c.junction)
    if c.annotation is not None:
        return P + c.annotation[1], None
    t0 = sp.Float(es.settings.t0)
    const = -P.xreplace(init_values).xreplace({TIME: t0})
    msg = (f"constraint '{c.junction}' has no 'init = ...' or 'phi = ...': the geometric "
           f"constant is taken from the initial state (Phi = {P + const})")
    return P + const, msg


# ---------------------------------------------------------------- main

def reduce(es: EquationSystem, project_initial: bool = False) -> Reduced:
    diags = Collector()
    local, order, loops = _ordered(es)
    full = _substituted(local, order)
    states = list(es.states)
    rates = {st.symbol: _clean(_subst(st.derivative, full)) for st in states}
    unknowns = [s.output for s in es.stores] + [c.multiplier for c in es.constraints]
    eqs = [_store_equation(s, full, rates, unknowns) for s in es.stores]
    init_values = {st.symbol: st.init for st in states}
    results = []
    for c in es.constraints:
        try:
            eq, info = _constraint_equation(c, es, local, order, full, rates, unknowns,
                                            init_values, diags)
        except ModelError as exc:
            diags.items.extend(exc.diagnostics)
            continue
        eqs.append(eq)
        results.append(info)
    diags.raise_if_errors()
    solution = _solve_unknowns(eqs, unknowns, es)
    rates = {x: _clean(r.xreplace(solution)) for x, r in rates.items()}
    constraints = tuple(_finish_constraint(c, info, solution) for c, info in zip(es.constraints,
                                                                                    results))
    full = {v: e.xreplace(solution) for v, e in full.items()}
    eliminated = tuple((str(s.state_symbol), full[s.state_symbol]) for s in es.stores)
    outputs = _outputs(es, full, constraints)
    kept, pruned = _prune(states, rates, outputs)
    state_eqs = tuple(StateEq(st.symbol, st.name, rates[st.symbol], st.init) for st in kept)
    reduced = Reduced(es, state_eqs, outputs, constraints, eliminated, tuple(loops),
                      tuple(st.name for st in pruned), es.warnings + tuple(diags.warnings))
    if not project_initial:
        check_initial(reduced)
    return replace(reduced, warnings=reduced.warnings + _ignored_inits(es, full))


def _ignored_inits(es, full) -> tuple:
    """Warn where an init clause on a derivative-causality element disagrees with the model."""
    stores = [s for s in es.stores if s.given_init is not None]
    if not stores:
        return ()
    values = _initial_values(es)
    out = []
    for s in stores:
        implied = float(full[s.state_symbol].xreplace(values))
        given = float(s.given_init.xreplace(values))
        if abs(implied - given) > RELATIVE_TOLERANCE * max(abs(implied), abs(given), 1e-300):
            el = es.graph.element(s.element)
            out.append(warning(el.init[1].span, f"'{s.element}' is in derivative causality: its "
                                                f"state is {implied:.6g} at the start, not the "
                                                f"{given:.6g} given here, which is ignored"))
    return tuple(out)


def _store_equation(s, full, rates, unknowns):
    dep = _subst(s.state_expr, full)
    if dep.free_symbols & set(unknowns):
        fail(s.span, f"'{s.element}' is in derivative causality with an input that depends on "
                     "a multiplier or another derivative-causality element; not supported")
    return s.output - s.sign * _total_derivative(dep, rates)


def _constraint_equation(c, es, local, order, full, rates, unknowns, init_values, diags):
    balance = _subst(c.balance, full)
    if balance.free_symbols & set(unknowns):
        fail(c.span, f"the flow balance of constraint junction '{c.junction}' depends on a "
                     "multiplier directly (a resistive path?): declare it as a plain junction")
    form, reason = _coordinates_form(c, es, local, order, es.states)
    integrable = form is not None and _integrable(*form)
    kind, detected = c.kind, c.kind is None
    if kind is None:
        kind = "holonomic" if integrable else "nonholonomic"
    if kind == "holonomic" and not integrable:
        why = reason or "its coefficients have no symmetric Jacobian (not the derivative of a " \
                        "function of the coordinates)"
        fail(c.element.name_span, f"constraint '{c.junction}' is declared holonomic but is not "
                                  f"integrable: {why}")
    phi = None
    if kind == "holonomic":
        phi, msg = _phi(c, form, es, init_values)
        if msg and (c.corrector == "pid" or _residual_asked(es, c.junction)):
            diags.warning(c.element.name_span, msg)
    dB = _total_derivative(balance, rates)
    gains = c.gains
    if c.corrector == "pid":
        eq = dB + 2 * gains[0] * balance + gains[1] ** 2 * phi
    elif c.corrector == "pd":
        eq = dB + gains[0] * balance
    else:
        eq = dB
    return eq, (kind, detected, balance, phi)


def _residual_asked(es, name):
    outs = es.settings.outputs or ()
    return any(o.owner == name and o.field == "residual" for o in outs)


def _solve_unknowns(eqs, unknowns, es):
    if not unknowns:
        return {}
    names = ", ".join(str(u) for u in unknowns)
    span = (es.stores[0].span if es.stores else es.constraints[0].span)
    sol = _solve_linear(eqs, unknowns, "the system for the multipliers and derivative-"
                        "causality variables", span, names)
    if sol is None:
        fail(span, f"the equations for {names} are not linear in them; not supported")
    return {u: _tidy(s) for u, s in zip(unknowns, sol)}


def _tidy(expr):
    return sp.factor_terms(sp.cancel(expr)) if sp.count_ops(expr) < 300 else expr


def _finish_constraint(c, info, solution):
    kind, detected, balance, phi = info
    lam = solution[c.multiplier]
    residual = phi if kind == "holonomic" else balance
    return ConstraintResult(c.junction, kind, detected, c.corrector, c.gains, lam, balance, phi,
                            residual, c.span)


def _outputs(es, full, constraints) -> tuple[Output, ...]:
    refs = es.settings.outputs
    if refs is None:
        return tuple(Output(st.name, st.symbol) for st in es.states)
    diags = Collector()
    out = []
    for ref in refs:
        try:
            out.append(Output(ref.text, _output_expr(ref, es, full, constraints)))
        except ModelError as exc:
            diags.items.extend(exc.diagnostics)
    diags.raise_if_errors()
    return tuple(out)


def _output_expr(ref, es, full, constraints):
    if ref.index is not None and ref.index != 0:
        fail(ref.span, f"'{ref.owner}' is a scalar: index [{ref.index}] is out of range")
    states = {st.symbol for st in es.states}
    g = es.graph
    if ref.field is None:
        sym = var(ref.owner)
        if sym in states:
            return sym
        if sym in full:
            return full[sym]
        if any(p.name == ref.owner for p in g.parameters):
            return sym
        fail(ref.span, f"unknown output '{ref.owner}'")
    if not any(el.name == ref.owner for el in g.elements):
        fail(ref.span, f"unknown element '{ref.owner}' in outputs")
    if ref.field in ("lambda", "residual"):
        c = next((c for c in constraints if c.junction == ref.owner), None)
        if c is None:
            fail(ref.span, f"'{ref.owner}' is not a constraint junction")
        return c.multiplier if ref.field == "lambda" else c.residual
    sym = var(f"{ref.owner}.{ref.field}")
    if sym in states:
        return sym
    if sym in full:
        return full[sym]
    fail(ref.span, f"'{ref.owner}' has no variable '{ref.field}'")


def _prune(states, rates, outputs):
    by_symbol = {st.symbol: st for st in states}
    needed, todo = set(), [o.expr for o in outputs]
    while todo:
        for s in todo.pop().free_symbols:
            if s in by_symbol and s not in needed:
                needed.add(s)
                todo.append(rates[s])
    kept = [st for st in states if st.symbol in needed]
    pruned = [st for st in states if st.symbol not in needed]
    return kept, pruned


# ---------------------------------------------------------------- initial conditions

def constraint_rows(reduced: Reduced):
    """(junction, level, residual expr) for every scalar constraint row."""
    rows = []
    for c in reduced.constraints:
        if c.kind == "holonomic":
            rows.append((c.junction, "position", c.phi))
        rows.append((c.junction, "velocity", c.balance))
    return rows


def scale_of(expr):
    return sp.Add(*[sp.Abs(term) for term in sp.Add.make_args(expr)])


def _initial_values(es) -> dict:
    """Numeric parameters, initial states and t0 at the scene's defaults."""
    params = parameter_values(es.graph, es.settings.sets)
    x0 = {st.symbol: st.init.xreplace(params).xreplace({TIME: es.settings.t0})
          for st in es.states}
    return {**params, **{k: sp.Float(float(v)) for k, v in x0.items()},
            TIME: sp.Float(es.settings.t0)}


def check_initial(reduced: Reduced):
    es = reduced.system
    values = _initial_values(es)
    diags = Collector()
    for junction, level, expr in constraint_rows(reduced):
        r = float(expr.xreplace(values))
        s = float(scale_of(expr).xreplace(values))
        if abs(r) > RELATIVE_TOLERANCE * s:
            el = es.graph.element(junction)
            what = "Phi" if level == "position" else "dPhi/dt" if any(
                c.junction == junction and c.kind == "holonomic" for c in reduced.constraints) \
                else "Phi (nonholonomic)"
            diags.error(el.name_span, f"initial conditions violate constraint '{junction}': "
                                      f"{what} = {r:.6g} (relative {abs(r) / s if s else r:.3g}, "
                                      f"tolerance {RELATIVE_TOLERANCE:g}); fix the initial values "
                                      "or use --project-initial")
    diags.raise_if_errors()
