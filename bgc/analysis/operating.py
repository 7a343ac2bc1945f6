"""A compiled model evaluated at one operating point, for the analyses (bgc.linearize,
bgc.steady): the right side, its Jacobian, the outputs and their derivative, the derivatives
with respect to the inputs, and the constraint rows' Jacobians, all computed by the generated
Python module from the derivatives the compiler derives symbolically (bgc.ir.tangent), never by
finite differences.

The analysis program is the scene's with every state kept (a state that no output needs is
not pruned: A is the model's, whatever the outputs) and, after the outputs asked for, every
state and discrete variable as an output (so that a run to a time T gives them there) and
every constraint's multiplier.  The discrete values the right side reads (relations, time
sources, modes, discrete variables: bgc.front.events) are set as a run sets them (settle, hold). 
Its extra functions (bgc.codegen.lower.with_tangent) are the outputs' derivative along v
(`outputs_jvp`) and, for each input, the right side's and the outputs' derivative with respect to
it.

Inputs: the model's declared inputs (`input u = 0`), at their defaults: the derivative with
respect to one is taken along its value (the discrete value the generated code reads it
from, bgc.front.events.InputSlot), exactly.  A parameter may be an input too: its value is held
and the derivative is taken through everything computed from it (the parameters defined
from it, unless overridden, and the constants of the generated code).
"""
from __future__ import annotations

import bisect
import math
from dataclasses import dataclass

import numpy as np
import sympy as sp

from .. import api
from ..base import processes
from ..symbolic.differentiate import directional
from ..codegen.emit import emit_python
from ..ir import C, D, P, Assign, Store, substitute
from ..codegen.lower import with_tangent


class AnalysisError(Exception):
    """The analysis cannot be done at this point (the message says why, for people)."""


class AnalysisArgumentError(AnalysisError, ValueError):
    """An argument the model refuses (an input that is not a parameter): a usage error."""


@dataclass(frozen=True)
class Analysed:
    """The compiled model of an analysis and what the user asked of it."""

    compiled: api.Compiled  # the analysis program (every state kept)
    outputs: tuple[str, ...]  # the output columns asked for (the first of the program's)
    inputs: tuple[str, ...]  # parameter names
    multipliers: tuple[str, ...]  # the multiplier columns of the program's outputs
    residuals: tuple[str, ...]  # the constraint residual columns


def _scene_outputs(model, scene, outputs, effects, algebra):
    """The output columns of the scene (or of --outputs), the states, and the multipliers and
    residuals of its constraints: one build to find them."""
    first = api.build(model, scene, algebra=algebra, outputs=outputs, effects=effects,
                      option_names=("--outputs", "--effects", "--scene"))
    asked = first.program.outputs
    states = tuple(first.program.states) + tuple(first.reduced.pruned)
    sel = first.reduced.events  # and the discrete variables: a run to T gives their values
    states += tuple(d.name for d in sel.discretes if d.next is None) if sel else ()
    junctions = [c.junction for c in first.reduced.constraints]
    return first, asked, states, tuple(f"{j}.lambda" for j in junctions), \
        tuple(f"{j}.residual" for j in junctions)


def build(model, scene=None, outputs=None, effects=None, inputs=None,
          algebra="auto") -> Analysed:
    """The analysis program of model's scene (see the module's doc); raises api's errors.
    inputs: names of declared inputs or parameters (None: the declared inputs); algebra: how
    its algebraic blocks are solved, as bgc.build's."""
    first, asked, states, lambdas, residuals = _scene_outputs(model, scene, outputs, effects,
                                                              algebra)
    extra = [s for s in states + lambdas + residuals if s not in asked]
    names = ", ".join(list(asked) + extra) if asked or extra else None
    compiled = api.build(first.source, scene, algebra=algebra, outputs=names, effects=effects,
                         option_names=("--outputs", "--effects", "--scene"))
    params = [p.name for p in compiled.program.params]
    declared = [u.name for u in compiled.program.inputs]
    inputs = tuple(declared) if inputs is None else tuple(inputs)
    for u in inputs:
        if u not in params and u not in declared:
            raise AnalysisArgumentError(
                f"unknown input '{u}': an input is one of the model's inputs "
                f"({', '.join(declared) or 'it declares none'}) or of its parameters "
                f"({', '.join(params) or 'it has none'})")
    if len(set(inputs)) != len(inputs):
        raise AnalysisArgumentError("an input is named twice")
    outs = compiled.program.outputs
    return Analysed(compiled, tuple(asked), tuple(inputs),
                    tuple(o for o in outs if o.split("[")[0] in lambdas),
                    tuple(o for o in outs if o.split("[")[0] in residuals))


def parameter_seeds(program, j: int, given=()) -> dict:
    """The tangents of the parameters and of the generated code's constants with respect to
    parameter j: 1 for p[j], the derivative of each parameter defined from it (unless
    overridden: `given` names those) and of each constant computed from them."""
    dp = {P[j]: 1}
    for i, par in enumerate(program.params):
        if i > j and par.name not in given:
            d = directional(par.default, dp)
            if d != 0:
                dp[P[i]] = d
    seeds, env = dict(dp), {}
    for s in program.function("consts").body:
        if isinstance(s, Assign):
            env[s.target] = substitute(s.expr, env)
        elif isinstance(s, Store):
            d = directional(substitute(s.expr, env), dp)
            if d != 0:
                seeds[C[s.index]] = d
    return seeds


def input_slots(program) -> dict:
    """Each declared input's name -> the discrete value its value is read from (None: the
    scene does not use it)."""
    ev = program.events
    out = {}
    for u in program.inputs:
        found = [k for k, (kind, name) in enumerate(zip(ev.kinds, ev.names))
                 if kind == "input" and name == u.name] if ev is not None else []
        out[u.name] = found[0] if found else None
    return out


def _default(expr, params) -> float:
    """An input's default (an expression of p) at the parameters' values."""
    e = substitute(expr, {P[k]: sp.Float(v, 30) for k, v in enumerate(params)})
    return float(sp.N(e, 30))


class Evaluator:
    """The analysis program's generated Python module, at given parameter values."""

    def __init__(self, analysed: Analysed, params: dict | None = None):
        params = dict(params or {})
        program = analysed.compiled.program
        prog = with_tangent(program, "outputs", "outputs_jvp")
        index = {p.name: k for k, p in enumerate(program.params)}
        slots = input_slots(program)
        for k, u in enumerate(analysed.inputs):
            if u in slots:  # a declared input: along its value
                seeds = {D[slots[u]]: 1} if slots[u] is not None else {}
            else:
                seeds = parameter_seeds(program, index[u], params)
            prog = with_tangent(prog, "rhs", f"rhs_du{k}", seeds)
            prog = with_tangent(prog, "outputs", f"outputs_du{k}", seeds)
        (text,) = emit_python(prog).values()
        self.module = m = processes.load_python_module(text)
        self.analysed = analysed
        self.states = tuple(program.states)
        self.all_outputs = tuple(program.outputs)
        self.n = len(self.states)
        self.constraints = tuple(program.constraints)
        self.p = m._param_values(m._overrides(params))
        self.pc = m._with_constants(self.p)
        self.t0 = float(m.SCENE["t0"])
        base = len(self.p) + len(m._constants(self.p))
        for u in program.inputs:  # the inputs at their defaults
            slot = slots.get(u.name)
            if slot is not None:
                self.pc[base + slot] = _default(u.default, self.p)
        self.events = analysed.compiled.reduced.events  # bgc.front.events.Selected, or None
        self.discrete = program.events.discrete if program.events is not None else 0
        self.doff = len(self.pc) - self.discrete  # the discrete values d: pc[doff:]
        first = self.discrete - (len(self.events.discretes) if self.events else 0)
        kept = [(first + k, d.name) for k, d in enumerate(self.events.discretes)
                if d.next is None] if self.events else []
        self.held = tuple(k for k, _ in kept)  # the discrete variables' places in d
        self.held_names = tuple(name for _, name in kept)  # and their output columns

    def set_inputs(self, t: float, data: dict) -> tuple[tuple[str, float], ...]:
        """The declared inputs given data ({name: (t, values)}) set to their data at t, as a
        run reads them there (the segment of the rows at t, interpolated linearly, held
        before the first row and after the last; at a row's time the segment it starts):
        (name, value) each, the value the model reads."""
        m, off, pc = self.module, self.doff, self.pc
        names = list(m._DISCRETE_NAMES) if self.discrete else []
        out = []
        for name, (ts, us) in data.items():
            ts, us = [float(v) for v in ts], [float(v) for v in us]
            lo = bisect.bisect_right(ts, float(t))
            if lo == 0 or lo == len(ts):
                start, value, slope = 0.0, us[0] if lo == 0 else us[-1], 0.0
            else:
                k = lo - 1
                start, value, slope = ts[k], us[k], (us[k + 1] - us[k]) / (ts[k + 1] - ts[k])
            where = {label: names.index(label) for label in
                     (f"{name} (segment start)", name, f"{name} (slope)") if label in names}
            for label, v in ((f"{name} (segment start)", start), (name, value),
                             (f"{name} (slope)", slope)):
                if label in where:
                    pc[off + where[label]] = v
            out.append((name, (float(t) - start) * slope + value))
        return tuple(out)

    # ------------------------------------------------------------ the discrete values
    # A run freezes its relations, time sources and discrete variables between events
    # (bgc.front.events): the right side reads their values, d, from pc[doff:].  An analysis at
    # (t, x) must read the values a run holds there, which these set.

    def discrete_values(self) -> tuple[float, ...]:
        return tuple(self.pc[self.doff:])

    def _run(self, x):
        m = self.module
        return m._Run(m._settings(), self.pc, m._Work(), m._new_stats(), list(x))

    def settle(self, t, x, start: bool) -> np.ndarray:
        """The event iteration of a run at (t, x), as the runtimes do it at the start of a
        run (start: initial() holds, the discrete variables take their initial values) or at
        an event (the when-blocks whose conditions rose since the values d holds fire): d is
        left as it ends; returns the state after it (a when-block's reinit)."""
        xs = [float(v) for v in x]
        if not self.discrete:
            return np.asarray(xs, dtype=float)
        m = self.module
        try:
            m._event_iteration(self._run(xs), float(t), xs, start)
        except m._Failure as failure:
            raise AnalysisError(str(failure)) from None
        return np.asarray(xs, dtype=float)

    def hold(self, t, x, held=()) -> None:
        """d as a run holds it at (t, x) between events, the discrete variables given (held,
        in the order of self.held, e.g. read from a run): every other discrete value (the
        relations, the time sources, the modes) from the events' update until it settles,
        no when-block firing and the state kept."""
        if not self.discrete:
            return
        m, off, pc = self.module, self.doff, self.pc
        for k, v in zip(self.held, held):
            pc[off + k] = float(v)
        xs = [float(v) for v in x]
        run = self._run(xs)
        G = len(m._INDICATOR_STRICT)
        for _ in range(m.MAX_EVENT_ITERATIONS + 1):
            out = [0.0] * (self.n + self.discrete)
            try:
                g = m._indicators(run, float(t), xs)
                r = [1.0 if m._holds(k, g[k]) else 0.0 for k in range(G)] + [0.0]
                m._update(float(t), xs, pc, run.w, r, out)
            except m._Failure as failure:
                raise AnalysisError(str(failure)) from None
            except m._BlockFailure as failure:
                raise AnalysisError(str(failure)) from None  # (it says "at t = ...")
            changed = False
            for k in range(self.discrete):
                v = out[self.n + k]
                if k in self.held or v == pc[off + k]:
                    continue
                if not math.isfinite(v):
                    raise AnalysisError(f"at t = {t:.17g}: discrete value "
                                        f"'{m._DISCRETE_NAMES[k]}' is not finite")
                pc[off + k], changed = v, True
            if not changed:
                return
        raise AnalysisError(f"at t = {t:.17g}: the discrete values do not settle (more than "
                            f"{m.MAX_EVENT_ITERATIONS} passes change them)")

    def next_times(self, t, x) -> list[float]:
        """next_time's results at (t, x): per timer (bgc.front.events.timers) the next time event
        after t (inf or NaN: none)."""
        m = self.module
        tau = [0.0] * m._NUM_TIMERS
        if tau:
            try:
                m._next_time(float(t), [float(v) for v in x], self.pc, m._work(), tau)
            except m._BlockFailure as failure:
                raise AnalysisError(str(failure)) from None  # (it says "at t = ...")
        return tau

    def _call(self, function, t, x, size, v=None):
        m = self.module
        out = [0.0] * size
        try:
            function(float(t), m._vector(x, m._N, "x"), self.pc, m._work(),
                     *(() if v is None else (list(v),)), out)
        except m._BlockFailure as failure:
            raise AnalysisError(str(failure)) from None  # (it says "at t = ...")
        return np.asarray(out, dtype=float)

    def initial(self) -> np.ndarray:
        """The scene's initial state (its constraints checked, as a run checks them)."""
        m = self.module
        try:
            return np.asarray(m._initial_state(m._settings(), self.pc, False), dtype=float)
        except (m.ConstraintError, m.SimulationError) as error:
            raise AnalysisError(str(error)) from None

    def rhs(self, t, x) -> np.ndarray:
        return self._call(self.module._rhs, t, x, self.n)

    def jacobian(self, t, x) -> np.ndarray:
        m = self.module
        J = np.zeros((self.n, self.n))
        try:
            m._jacobian_into(float(t), m._vector(x, m._N, "x"), self.pc, m._work(), J)
        except m._BlockFailure as failure:
            raise AnalysisError(str(failure)) from None  # (it says "at t = ...")
        return J

    def outputs(self, t, x) -> np.ndarray:
        return self._call(self.module._out, t, x, len(self.all_outputs))

    def output_jacobian(self, t, x) -> np.ndarray:
        """d outputs / d x, column by column (the outputs' derivative along each unit vector)."""
        cols = []
        for j in range(self.n):
            e = np.zeros(self.n)
            e[j] = 1.0
            cols.append(self._call(self.module._outputs_jvp, t, x, len(self.all_outputs), e))
        return np.array(cols).T.reshape(len(self.all_outputs), self.n)

    def input_jacobians(self, t, x) -> tuple[np.ndarray, np.ndarray]:
        """(d rhs / d u, d outputs / d u), one column per input."""
        k = len(self.analysed.inputs)
        B, D = np.zeros((self.n, k)), np.zeros((len(self.all_outputs), k))
        zero = np.zeros(self.n)
        for j in range(k):
            B[:, j] = self._call(getattr(self.module, f"_rhs_du{j}"), t, x, self.n, zero)
            D[:, j] = self._call(getattr(self.module, f"_outputs_du{j}"), t, x,
                                 len(self.all_outputs), zero)
        return B, D

    def constraint_rows(self, t, x) -> tuple[np.ndarray, np.ndarray]:
        """(G, r): the Jacobian of the constraint rows (position rows, then velocity rows) and
        their residuals in the same order."""
        m, n = self.module, self.n
        xs = [float(v) for v in x]
        pos = np.asarray(m._position_jac(t, xs, self.pc)).reshape(-1, n)
        vel = np.asarray(m._velocity_jac(t, xs, self.pc)).reshape(-1, n)
        r = np.asarray(m._residual(t, xs, self.pc), dtype=float)
        order = list(m._POSITION_ROWS) + list(m._VELOCITY_ROWS)
        return np.vstack([pos, vel]).reshape(len(order), n), r[order]

    def constraint_names(self) -> list[str]:
        rows = [c for c in self.constraints if c.level == "position"] + \
            [c for c in self.constraints if c.level == "velocity"]
        return [f"{c.junction} ({c.level})" for c in rows]
