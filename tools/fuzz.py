#!/usr/bin/env python3
"""Fuzzing bgc: models generated from the grammar and mutations of every shipped model, through
`bgc check` in process and, for a sample, through `bgc simulate` in both backends.

    python tools/fuzz.py --seed 28 --cases 100000 --simulate-every 5 --out fuzz-out

What counts as a failure:
- check (run in a worker process, the function the command line calls, click's runner around
  it): an exception other than the command's exit; an exit status other than 0 and 1; exit 1
  without a located error (`m.bg:LINE:COL: error:` or `m.bg: error:`); a traceback in the
  output; a file left behind; a case that runs longer than --time-limit (a hang: the worker is
  killed and started again, the harness goes on);
- simulate (in the worker process, or bgc as a subprocess with --simulate-subprocess; C and
  Python backends, a short --t-end): an exception or a traceback on stderr;
  an exit status other than 0, 1 and 2 (2 only for a usage error: `Usage:` or `Error:` from
  the option parser), a death by a signal of bgc or of the generated program (bgc reports it
  as 128 + the signal), a run longer than --sim-time-limit; exit 1 without a message; a CSV
  that ends in a cut row or whose rows have fewer or more columns than its header, or that
  holds a NaN or an infinity; a partial file left beside it; a process that outlives bgc;
- the FMU (--fmu-every K: every K-th case check accepts, exported as an FMU whose life cycle
  tools/fuzz_fmu.py fuzzes with random sequences of FMI calls through ctypes): a crash, a
  call the FMI 2.0 state machine does not allow that does not return fmi2Error, a legal one
  that fails for no reason of the model's (tools/fuzz_fmu.py says each).

Each failure's signature (its kind, the exception's type and the innermost frame in bgc) is
minimised once by delta debugging, on lines, tokens, then characters, keeping the signature, and
written as tests/fuzz_regressions/NAME.bg with NAME.note (what failed, the seed and the case).
The summary (cases, failures by signature) is printed at the end and written to OUT/summary.json.

The generators are importable (tests/test_fuzz_harness.py runs a short seeded campaign in
process): generate(rng), mutate(rng, text), case(rng, seeds, i) and check_case(data).
"""
from __future__ import annotations

import argparse
import base64
import hashlib
import json
import os
import random
import re
import select
import shutil
import signal
import subprocess
import sys
import tempfile
import time
import traceback
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
SEED_DIRS = (ROOT / "models", ROOT / "tests" / "models")
REGRESSIONS = ROOT / "tests" / "fuzz_regressions"

# ------------------------------------------------------------------------- generation

FUNCTIONS = {"sin": 1, "cos": 1, "tan": 1, "asin": 1, "acos": 1, "atan": 1, "atan2": 2,
             "sinh": 1, "cosh": 1, "tanh": 1, "exp": 1, "log": 1, "sqrt": 1, "abs": 1,
             "sign": 1, "min": 2, "max": 2}
EXTREME = ("1e308", "1.7976931348623157e308", "1e309", "1e-320", "4.9e-324", "1e-400", "0",
           "0.0", "-0", "-0.0", "2", "1" * 20, "9007199254740993", "9" * 309, "1" * 310,
           "1e-308", "2.2250738585072014e-308", "123456789012345678901234567890", "1000",
           "0.5", "1e8", "64", "65", "1024")
EXTREME_TIMES = ("1e308", "1.7976931348623157e308", "8.98846567431158e307", "1e-300",
                 "4.9e-324", "1e-6", "0", "1e10", "1e16")
NAN_MAKERS = ("0/0", "log(0)", "sqrt(-1)", "asin(2)", "acos(-3)", "1e308*10", "exp(1000)",
              "exp(1000) - exp(1000)", "1/0", "0^0", "0^-1", "(-8)^(1/3)", "log(-1)",
              "atan2(0, 0)", "tan(asin(1))", "1e308^2", "(-1)^0.5", "sign(0)/0",
              "min(1e308*10, 0)", "max(0/0, 1)", "1/sinh(0.25^1000) - 1", "2^1024",
              "0.5^2^2^2^2", "10^-400")
TAME = ("sin", "cos", "atan", "tanh", "abs", "min", "max", "exp", "cosh", "sign", "atan2")
KINDS_1 = ("Se", "Sf", "MSe", "MSf", "I", "C", "R")
SOLVERS = ("dopri5", "dop853", "rk4", "euler", "radau5", "rodas4", "auto", "nope")
UNICODE = ("é", "π", "ℌ", "𝑥", "x\u0301", "Ω", "ﬁ", "\u200b", "\u00a0", "٣", "１", "—", "≤",
           "\u202e", "\ud800", "\U0001f600", "µ")


class Gen:
    """One random model: names it has declared, so that expressions mostly refer to them."""

    def __init__(self, rng: random.Random):
        self.rng = rng
        self.params: list[str] = []
        self.values: list[str] = []  # fields and signals usable in laws: j.f, x, q[0] ...
        self.lines: list[str] = []
        self.effects: list[str] = []
        self.outputs: list[str] = []
        self.n = 0
        self.wild = rng.choice([0.0, 0.0, 0.0, 0.01, 0.05])  # how often a number is extreme

    def name(self, prefix: str) -> str:
        self.n += 1
        return f"{prefix}{self.n}"

    def number(self) -> str:
        r = self.rng
        x = r.random()
        if x < self.wild:
            return r.choice(EXTREME)
        if x < 0.5:
            return str(r.randint(0, 20))
        return repr(round(r.uniform(0.01, 10), r.randint(0, 4)))

    def expr(self, depth: int = 3, names=None, vector: int = 0) -> str:
        """An expression over numbers and names (names: None = parameters only)."""
        r = self.rng
        pool = self.params if names is None else names
        if vector:
            return "[" + ", ".join(self.expr(depth - 1, names) for _ in range(vector)) + "]"
        if depth <= 0 or r.random() < 0.3:
            if pool and r.random() < 0.55:
                return r.choice(pool)
            if r.random() < self.wild / 3:
                return r.choice(NAN_MAKERS)
            return self.number()
        k = r.random()
        if k < 0.35:
            op = r.choice(["+", "-", "*", "/", "^", "**", "+", "*"])
            a, b = self.expr(depth - 1, names), self.expr(depth - 1, names)
            if op in ("^", "**") and (r.random() < 0.6 or not self.wild):
                b = r.choice(["2", "3", "0.5", "-1", "1000", "64", "65", "-2", "1/3", "2.5"]
                             if self.wild else ["2", "3", "-2"])
            return f"{a} {op} {b}" if r.random() < 0.5 else f"({a}) {op} ({b})"
        if k < 0.45:
            return f"-{self.expr(depth - 1, names)}"
        if k < 0.85:
            f = r.choice(list(FUNCTIONS) if self.wild else TAME)
            n = FUNCTIONS[f] + (r.randint(0, 3) if f in ("min", "max") else 0)
            if r.random() < self.wild:
                n += r.choice([-1, 1])
            return f"{f}({', '.join(self.expr(depth - 1, names) for _ in range(max(n, 0)))})"
        if k < 0.9:
            n = r.randint(1, 12)
            return "(" * n + self.expr(depth - 1, names) + ")" * n
        return f"({self.expr(depth - 1, names)})"

    def law_names(self):
        return self.params + self.values + ["t"]

    def emit(self, line: str):
        self.lines.append(line)

    def tag(self) -> str:
        r = self.rng
        if r.random() < 0.15:
            e = r.choice(["friction", "gravity", "load", "drive"])
            self.effects.append(e)
            return f" @{e}"
        return ""

    def doc(self) -> str:
        return ' "a doc"' if self.rng.random() < 0.1 else ""

    # -- pieces
    def parameter(self):
        p = self.name("p")
        self.emit(f"parameter {p} = {self.expr(2)}{self.doc()}")
        self.params.append(p)

    def one_port(self, junction: str, jtype: str, kind: str | None = None):
        r = self.rng
        if kind is None:  # what the junction can take, most of the time
            if self.wild and r.random() < 0.3:
                kind = r.choice(KINDS_1)
            else:
                kind = r.choice(["R", "R", "Se", "MSe", "I"] if jtype == "1"
                                else ["R", "R", "Sf", "MSf", "C"])
        e = self.name(kind.lower())
        init = ""
        if kind in ("I", "C") and r.random() < 0.6:
            arg = (f"f = p * ({self.expr(2, self.params + ['p'])})" if kind == "I" and
                   r.random() < 0.2 else f"e = q * ({self.expr(2, self.params + ['q'])})"
                   if kind == "C" and r.random() < 0.3 else self.expr(2))
            if r.random() < 0.5:
                init = f" init {r.choice('pf' if kind == 'I' else 'qe')} = {self.expr(2)}"
                if kind == "I" and r.random() < 0.5:
                    init = f" init f = {self.expr(2)}"
        elif kind == "R" and r.random() < 0.4:
            v = r.choice("ef")
            arg = f"{'f' if v == 'e' else 'e'} = {v} * ({self.expr(2, self.params + [v])})"
        elif kind in ("MSe", "MSf"):
            arg = self.expr(3, self.law_names())
        else:
            arg = self.expr(2)
        self.emit(f"{e} : {kind}({arg}){init}{self.tag()}{self.doc()}")
        if kind in ("Se", "Sf", "MSe", "MSf") and r.random() < 0.8:
            self.emit(f"{e} -> {junction}")
        else:
            self.emit(f"{junction} -> {e}")
        if kind in ("I", "C", "R"):
            self.outputs.append(f"{e}.{r.choice('ef')}")
        if kind in ("I", "C"):
            self.values.append(f"{e}.{'p' if kind == 'I' else 'q'}")
        return e

    def junction(self, kind: str | None = None) -> str:
        kind = kind or self.rng.choice("01")
        j = self.name("j")
        self.emit(f"{j} : {kind}{self.doc()}")
        self.values.append(f"{j}.{'f' if kind == '1' else 'e'}")
        return j

    def two_port(self, a: str, b: str):
        r = self.rng
        kind = r.choice(["TF", "GY", "MTF", "MGY"])
        x = self.name(kind.lower())
        arg = self.expr(2, self.law_names() if kind[0] == "M" else None)
        self.emit(f"{x} : {kind}({arg}){self.tag()}")
        self.emit(f"{a} -> {x} -> {b}")

    def constraint(self):
        """A pendulum-like constraint: a 1-junction (velocity), a mass, an integral position
        and a constraint junction reached through an MTF."""
        r = self.rng
        v, m, x = self.name("v"), self.name("m"), self.name("x")
        self.emit(f"{v} : 1")
        self.emit(f"{m} : I({self.expr(1)})")
        self.emit(f"{v} -> {m}")
        self.emit(f"signal {x} = integral({v}.f, init = {self.expr(1)})")
        tf, c = self.name("tf"), self.name("rod")
        self.emit(f"{tf} : MTF({self.expr(2, [x] + self.params)})")
        kind = r.choice(["", " holonomic", " nonholonomic"])
        ann = r.choice(["", f"(init = {self.expr(1)})",
                        f"(phi = {self.expr(2, [x] + self.params)})"])
        corr = r.choice(["", " corrector none", f" corrector pid({self.expr(1)}, {self.expr(1)})"]
                        + ([f" corrector pd({self.expr(1)})"] if "non" in kind else []))
        self.emit(f"{c} : 0 constraint{kind}{ann}{corr}{self.tag()}")
        self.emit(f"{v} -> {tf} -> {c}")
        if r.random() < 0.7:
            s = self.name("se")
            self.emit(f"{s} : Se({self.expr(2)})")
            self.emit(f"{s} -> {v}")
        self.values.append(x)
        self.outputs += [x, f"{c}.lambda"]

    def array(self):
        """Multibonds: a junction array, a mass field, sources, a matrix transformer onto a
        constraint array (the car axis's shape), an integral signal vector."""
        r = self.rng
        n, m = r.randint(2, 4), r.randint(2, 3)
        v, mass, q = self.name("v"), self.name("mass"), self.name("q")
        self.emit(f"{v} : 1[{n}]")
        self.emit(f"{mass} : I[{n}]({self.expr(1)})" + (
            f" init f = {self.expr(1, vector=n)}" if r.random() < 0.6 else ""))
        self.emit(f"{v} -> {mass}")
        self.emit(f"signal {q}[{n}] = integral({v}.f, init = {self.expr(1, vector=n)})")
        qs = [f"{q}[{i}]" for i in range(n)] + self.params
        if r.random() < 0.7:
            w = self.name("w")
            self.emit(f"{w} : Se[{n}]({self.expr(1, vector=n)}){self.tag()}")
            self.emit(f"{w} -> {v}")
        if r.random() < 0.5:
            s = self.name("spring")
            self.emit(f"{s} : MSe[{n}]({self.expr(2, qs, vector=n)})")
            self.emit(f"{s} -> {v}")
        if r.random() < 0.6:
            J, links = self.name("J"), self.name("links")
            rows = ", ".join(self.expr(1, qs, vector=n) for _ in range(m))
            self.emit(f"{J} : MTF[{n}->{m}]([{rows}])")
            corr = r.choice(["", " corrector none", " corrector pid(5, 5)"])
            init = r.choice(["", f"(init = {self.expr(1, vector=m)})"])
            self.emit(f"{links} : 0[{m}] constraint holonomic{init}{corr}")
            self.emit(f"{v} -> {J} -> {links}")
            self.outputs.append(f"{links}.lambda[{r.randint(0, m)}]")
        self.outputs.append(f"{q}[{r.randint(0, n)}]")

    def condition(self, names=None, depth: int = 1) -> str:
        """A relation (or several, with and/or/not) over names and numbers."""
        r = self.rng
        pool = (self.values + ["t"]) if names is None else names
        a = r.choice(pool) if pool and r.random() < 0.8 else self.expr(1)
        rel = f"{a} {r.choice(['<', '>', '<=', '>=', '<', '>'])} {self.expr(1)}"
        if depth > 0 and r.random() < 0.25:
            rel = f"{rel} {r.choice(['and', 'or'])} {self.condition(names, depth - 1)}"
        if r.random() < 0.1:
            rel = f"not ({rel})"
        return rel

    def conditional(self, names) -> str:
        """if C then A [elif C then B] else D, or a time function, or noevent(...)."""
        r = self.rng
        k = r.random()
        if k < 0.5:
            out = f"if {self.condition(names)} then {self.expr(1, names)}"
            if r.random() < 0.3:
                out += f" elif {self.condition(names)} then {self.expr(1, names)}"
            return out + f" else {self.expr(1, names)}"
        if k < 0.6:
            return f"noevent(if {self.condition(names)} then {self.expr(1, names)} else 0)"
        f = r.choice([f"step({self.time()})", f"ramp({self.time()})",
                      f"pulse({self.time()}, {self.time()})",
                      f"square({self.time()}, {r.choice(['0.5', '0.25', self.expr(1)])})",
                      f"square({self.time()}, 0.5, {self.time()})"])
        return f"{self.expr(1)} * {f}"

    def time(self) -> str:
        """A time source's argument: now and then one at the ends of a double, whose events
        overflow (pulse(1e308, 1e308) ends at 2e308) or come closer than the time's
        resolution (square(1e-300, 0.5))."""
        r = self.rng
        return r.choice(EXTREME_TIMES) if r.random() < 0.1 else self.expr(1)

    def hybrid(self):
        """Events (docs/hybrid.md): a mass under gravity with an integral position, a
        when-block with reinit and discrete assignments, if-then-else laws, and one or two
        of: an ideal diode D, dry friction Fr, a switch Sw, a unilateral constraint junction."""
        r = self.rng
        v, m, x = self.name("v"), self.name("b"), self.name("x")
        self.emit(f"{v} : 1")
        self.emit(f"{m} : I({self.expr(1)})" + (f" init p = {self.expr(1)}"
                                                if r.random() < 0.3 else ""))
        self.emit(f"{v} -> {m}")
        w = self.name("w")
        self.emit(f"{w} : {r.choice(['Se', 'MSe'])}(-{self.expr(1)})")
        self.emit(f"{w} -> {v}")
        self.emit(f"signal {x} = integral({v}.f, init = {self.expr(1)})")
        self.values.append(x)
        self.outputs += [x, f"{m}.p"]
        disc = []
        for _ in range(r.choice([0, 0, 1, 2])):
            d = self.name("d")
            self.emit(f"discrete {d} = {r.choice(['0', '1', self.expr(1)])}{self.doc()}")
            disc.append(d)
        names = self.params + self.values + ["t"] + disc
        if r.random() < 0.5:
            s = self.name("s")
            self.emit(f"signal {s} = {self.conditional(names)}")
            self.values.append(s)
        for _ in range(r.choice([0, 1, 1, 2])):
            stmts = []
            if r.random() < 0.8:
                stmts.append(f"reinit {r.choice([f'{m}.p', x])} = "
                             f"{r.choice(['-', ''])}{self.expr(1)}*{m}.p")
            for d in disc:
                if r.random() < 0.6:
                    stmts.append(f"{d} = {r.choice(['1 - ' + d, '0', '1', self.expr(1, names)])}")
            cond = self.condition([x, f"{m}.p", "t"] + disc)
            if disc and r.random() < 0.2:
                cond = f"{r.choice(disc)} {r.choice(['==', '!='])} {r.choice(['0', '1'])}"
            sep = r.choice(["\n  ", "; "])
            self.emit(f"when {cond} {{{sep}{sep.join(stmts)}\n}}")
        for kind in r.sample(["D", "Fr", "Sw", "unilateral", "law"], r.randint(1, 2)):
            if kind == "D":
                d = self.name("diode")
                self.emit(f"{d} : D")
                self.emit(f"{v} -> {d}" if r.random() < 0.8 else f"{d} -> {v}")
                self.outputs.append(f"{d}.e")
            elif kind == "Fr":
                f = self.name("fr")
                self.emit(f"{f} : Fr({self.expr(1)}, {self.expr(1)})")
                self.emit(f"{v} -> {f}")
                self.outputs.append(f"{f}.e")
            elif kind == "Sw":
                sw, j0, c = self.name("sw"), self.name("j"), self.name("c")
                self.emit(f"{sw} : Sw({self.condition(['t', x] + disc)})")
                self.emit(f"{j0} : 0")
                self.emit(f"{c} : C({self.expr(1)}) init e = {self.expr(1)}")
                self.emit(f"{v} -> {sw}" if r.random() < 0.5 else f"{v} -> {j0}")
                self.emit(f"{j0} -> {c}")
                if r.random() < 0.7:
                    self.emit(f"{j0} -> {sw}")
                self.outputs.append(f"{c}.q")
            elif kind == "unilateral":
                g = self.name("gap")
                extra = r.choice(["", f" restitution({self.expr(1)})"])
                corr = r.choice(["", " corrector pid(10, 10)", " corrector none"])
                self.emit(f"{g} : 0 constraint unilateral(phi = {x}"
                          f"{r.choice(['', ' + 1', ' - ' + self.expr(1)])}){extra}{corr}")
                self.emit(f"{v} -> {g}")
                self.outputs.append(f"{g}.lambda")
            else:
                rr = self.name("r")
                self.emit(f"{rr} : R(f = {self.conditional([*names, 'e'])})")
                self.emit(f"{v} -> {rr}")

    def component(self):
        """A component with ports, parameters and a body, instances of it in a for loop,
        bonds between them; or parts of the standard library."""
        r = self.rng
        if r.random() < 0.3:
            self.lines.insert(1, "import electrical as el")
            src, res, cap, gnd = (self.name(k) for k in ("src", "res", "cap", "gnd"))
            self.emit(f"{src} : el.voltage_source(v = {self.expr(1)})")
            self.emit(f"{res} : el.resistor(r = {self.expr(1)})")
            self.emit(f"{cap} : el.capacitor(c = {self.expr(1)})")
            self.emit(f"{gnd} : el.ground()")
            self.emit(f"{src}.p -> {res}.p")
            self.emit(f"{res}.n -> {cap}.p")
            self.emit(f"{cap}.n -> {gnd}.p")
            return
        c = self.name("sec")
        a, b = r.choice(["1", "2", "3"]), r.choice(["4", "5", "3"])
        self.emit(f"component {c}(r = {self.expr(1, [])}, k = {self.expr(1, [])}){self.doc()} {{")
        body = ["port a", "port b", "node : 0", "link : 1", "res : R(r)",
                r.choice(["cap : C(k)", "cap : I(k)", "cap : C(1/k) init q = k"]),
                "a -> link", "link -> res", "link -> node", "node -> cap", "node -> b"]
        if r.random() < 0.3:
            body.append(f"constant half = {r.choice(['1', '2', self.expr(1, [])])}")
        if r.random() < 0.2:
            r.shuffle(body)
        self.lines.extend("  " + line for line in body)
        self.emit("}")
        n = self.name("n")
        src = self.name("src")
        self.emit(f"{src} : Se({self.expr(1)})")
        arg = self.expr(1, ["i"] + self.params)
        self.emit(f"for i in {a}..{b} {{\n  {n}[i] : {c}(r = {arg})\n}}")
        self.emit(f"{src} -> {n}[{a}].a")
        self.emit(f"for i in {int(a) + 1}..{b} {{ {n}[i-1].b -> {n}[i].a }}")
        load = self.name("load")
        self.emit(f"{load} : R({self.expr(1)})")
        self.emit(f"{n}[{b}].b -> {load}")
        self.outputs += [f"{n}[{a}].cap.q", f"{n}[{b}].res.f"]

    def signal(self):
        s = self.name("s")
        self.emit(f"signal {s} = {self.expr(3, self.law_names())}")
        self.values.append(s)

    def scene(self):
        r = self.rng
        body = []
        if self.effects and r.random() < 0.6:
            chosen = r.sample(self.effects, r.randint(1, len(self.effects)))
            body.append("effects " + ", ".join(chosen))
        elif r.random() < 0.2:
            body.append("effects none")
        if self.outputs and r.random() < 0.7:
            chosen = r.sample(self.outputs, r.randint(1, min(3, len(self.outputs))))
            body.append("outputs " + ", ".join(chosen))
        if r.random() < 0.7:
            t1 = r.choice(["1", "0.1", "10", self.expr(1), "1e308", "0"])
            body.append(f"time {r.choice(['0', '0', '1', self.expr(1)])} .. {t1}"
                        + (" every " + r.choice(['0.01', '0.1', self.expr(1)]
                                                + (['1e-320'] if self.wild else []))
                           if r.random() < 0.6 else ""))
        if r.random() < 0.5:
            kw = ", ".join(f"{k} = {r.choice(['1e-6', '1e-3', '0.01', self.expr(1), '0', '1e308'])}"
                           for k in r.sample(["rtol", "atol", "step", "foo"], r.randint(0, 2)))
            name = r.choice(SOLVERS[:-1] if not self.wild else SOLVERS)
            body.append(f"solver {name}" + (f"({kw})" if kw or r.random() < 0.3 else ""))
        if self.params and r.random() < 0.5:
            body.append(f"set {r.choice(self.params)} = {self.expr(2, [])}")
        sep = r.choice(["\n  ", "; "])
        self.emit(f"scene {self.name('sc')}{self.doc()} {{{sep}{sep.join(body)}\n}}")


def generate(rng: random.Random) -> str:
    """A model from the grammar, built so that most of it resolves and reaches causality,
    equations and code: parameters, junctions with one-ports and two-ports between them,
    constraints, multibond arrays, signals, scenes."""
    g = Gen(rng)
    g.emit(rng.choice(["model m", "model m \"doc\"", "model fuzz"]))
    for _ in range(rng.randint(0, 4)):
        g.parameter()
    junctions = [g.junction() for _ in range(rng.randint(1, 3))]
    kinds = {j: g.lines[-len(junctions) + k].split(" : ")[1][0] for k, j in enumerate(junctions)}
    for j in junctions:  # a storage element on each: effort or flow set by one bond
        if rng.random() < 0.9:
            g.one_port(j, kinds[j], "I" if kinds[j] == "1" else "C")
    for a, b in zip(junctions, junctions[1:]):
        if rng.random() < 0.7:
            g.two_port(a, b)
        else:
            g.emit(f"{a} -> {b}")
    for _ in range(rng.randint(1, 4)):
        j = rng.choice(junctions)
        g.one_port(j, kinds[j])
    if rng.random() < 0.3:
        g.signal()
    if rng.random() < 0.25:
        g.constraint()
    if rng.random() < 0.2:
        g.array()
    if rng.random() < 0.3:
        g.hybrid()
    if rng.random() < 0.1:
        g.component()
    for _ in range(rng.randint(0, 2)):
        g.scene()
    head, lines = g.lines[:1], g.lines[1:]
    if rng.random() < 0.1 and not any(l.startswith("  ") for l in lines):
        rng.shuffle(lines)
    lines = head + lines
    return rng.choice(["\n", "\n", "; "]).join(lines) + "\n"


def parallel_branches(rng: random.Random) -> str:
    """The parallel-branch family: N instances of one component in a `for` loop, each a
    branch of its own parameters on one junction, driven by a source, N up to 60.  A block
    through every branch (the junction's effort, or its flow) is as wide as N, with as many
    parameters: symbolic work that grows faster than its size shows as a hang (SymPy's gcd
    of a fraction over N parameters, issue 37: minutes at N = 30)."""
    n = rng.choice([1, 2, 5, 10, 20, 30, 40, 60])
    on = rng.choice(["0", "1"])
    inner, source = ("1", "Sf") if on == "0" else ("0", "Se")
    storage = rng.choice(["C(c)", "I(c)", "C(c) init q = c/2", "I(1/c)"])
    law = rng.choice(["R(r)", "R(r)", "R(e = r*f + f^3)", "R(r*(1 + 0.1*i0))"])
    body = ["port a", f"s : {inner}", f"res : {law}", f"st : {storage}", "a -> s",
            "s -> res", "s -> st"]
    if rng.random() < 0.3:
        body += ["extra : R(2*r)", "s -> extra"]
    params = rng.choice([("r = i", "c = 1/(i + 1)"), ("r = r0*i", "c = c0/i"),
                         ("r = r0 + i", "c = c0"), ("r = i^2", "c = 1/i")])
    lines = [f"model branches{n}", "constant N = " + str(n), "parameter r0 = 1.5",
             "parameter c0 = 0.5", "component branch(r = 1, c = 1, i0 = 0) {"]
    lines += ["  " + b for b in body] + ["}", f"src : {source}({rng.choice(['1', 'r0', 'sin(t)'])})",
                                         f"j : {on}", "src -> j", "for i in 1..N {",
                                         f"  b[i] : branch({', '.join(params)}, i0 = i)",
                                         "  j -> b[i].a", "}"]
    outputs = ("j.e" if on == "0" else "j.f") + (", b[1].st.q" if storage[0] == "C" else
                                                 ", b[1].st.p") + ", b[N].res.f"
    lines.append(f"scene run {{ outputs {outputs}; time 0 .. 0.1 every 0.05 }}")
    return "\n".join(lines) + "\n"


# ------------------------------------------------------------------------- mutation

TOKEN = re.compile(r'"(?:\\.|[^"\\\n])*"|#[^\n]*|[A-Za-z_][A-Za-z0-9_]*'
                   r'|[0-9]*\.?[0-9]+(?:[eE][+-]?\d+)?|->|\*\*|\.\.|\s+|.', re.S)
ODD = ("(", ")", "[", "]", "{", "}", "->", ";", "\n", ":", "=", "^", "@", ".", ",", '"', "\\",
       "#", "\x00", "\ufeff", "0", "-", "*", "**", "/", " ", "\t", "\r", "..", "init", "every",
       "constraint", "scene", "signal", "integral", "[1]", "[2->1]", "[0]", "\\\n")
NUMBER = re.compile(r"[0-9]*\.?[0-9]+(?:[eE][+-]?\d+)?$")
NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*$")


def _nest(rng, token: str) -> str:
    n = rng.choice([5, 50, 99, 100, 101, 150, 300, 1000])
    how = rng.randrange(5)
    if how == 0:
        return "(" * n + token + ")" * n
    if how == 1:
        return "-" * n + token
    if how == 2:
        return "sin(" * n + token + ")" * n
    if how == 3:
        return "[" * n + token + "]" * n
    return " + ".join([token] * n)


def mutate(rng: random.Random, text: str) -> str:
    """text with a few token-level edits (delete, duplicate, swap, insert, replace a number
    with an extreme one, a name with unicode or a keyword, nest deeply), sometimes whole-text
    edits (CRLF, a BOM, NUL bytes, truncation)."""
    tokens = TOKEN.findall(text) or [""]
    for _ in range(rng.choice([1, 1, 1, 2, 2, 3, 4, 8])):
        i = rng.randrange(len(tokens))
        tok = tokens[i]
        how = rng.randrange(10)
        if how == 0:
            del tokens[i]
        elif how == 1:
            tokens.insert(i, tok)
        elif how == 2:
            j = rng.randrange(len(tokens))
            tokens[i], tokens[j] = tokens[j], tokens[i]
        elif how == 3:
            tokens.insert(i, rng.choice(ODD))
        elif how == 4:  # an extreme number or a nan-maker for a number
            nums = [k for k, t in enumerate(tokens) if NUMBER.match(t)]
            k = rng.choice(nums) if nums else i
            tokens[k] = rng.choice(EXTREME + NAN_MAKERS)
        elif how == 5:  # a name becomes another name of the model, a keyword or unicode
            names = [k for k, t in enumerate(tokens) if NAME.match(t)]
            k = rng.choice(names) if names else i
            pool = [t for t in tokens if NAME.match(t)] or ["x"]
            tokens[k] = rng.choice([rng.choice(pool), rng.choice(pool), rng.choice(UNICODE),
                                    tokens[k] + rng.choice(UNICODE), rng.choice(
                                        ["init", "t", "model", "lambda", "e", "f", "p", "q"])])
        elif how == 6:  # deep nesting around a number or a name
            cand = [k for k, t in enumerate(tokens) if NUMBER.match(t) or NAME.match(t)]
            k = rng.choice(cand) if cand else i
            tokens[k] = _nest(rng, tokens[k])
        elif how == 7:  # a function around a number or name
            cand = [k for k, t in enumerate(tokens) if NUMBER.match(t) or NAME.match(t)]
            k = rng.choice(cand) if cand else i
            f = rng.choice(list(FUNCTIONS))
            tokens[k] = f"{f}({', '.join([tokens[k]] * FUNCTIONS[f])})"
        elif how == 8:  # an operator changed
            ops = [k for k, t in enumerate(tokens) if t in ("+", "-", "*", "/", "^", "**")]
            if ops:
                tokens[rng.choice(ops)] = rng.choice(["+", "-", "*", "/", "^", "**", "^1000*"])
        else:
            tokens.insert(i, "".join(rng.choice(UNICODE + ODD) for _ in range(rng.randint(1, 3))))
        if not tokens:
            tokens = [""]
    out = "".join(tokens)
    x = rng.random()
    if x < 0.04:
        out = out.replace("\n", "\r\n")
    elif x < 0.07:
        out = "\ufeff" + out
    elif x < 0.09:
        k = rng.randrange(len(out) + 1)
        out = out[:k] + "\x00" + out[k:]
    elif x < 0.13:
        out = out[:rng.randrange(len(out) + 1)]
    elif x < 0.14:
        out = out.replace("\n", "\r")
    return out


DOC_BLOCK = re.compile(r"^```bg([^\n]*)\n(.*?)^```", re.M | re.S)


def seed_models() -> dict[str, str]:
    """Every shipped model: models/ and tests/models/ (by file name), the standard library's
    files, and the models shown in docs/ (the hybrid ones, components, imports: the language
    as documented, by page and block number)."""
    out = {}
    for d in SEED_DIRS + (ROOT / "bgc" / "library",):
        for p in sorted(d.glob("*.bg")):
            out[f"{d.relative_to(ROOT)}/{p.name}"] = p.read_text(encoding="utf-8")
    for page in sorted((ROOT / "docs").glob("*.md")):
        for k, m in enumerate(DOC_BLOCK.finditer(page.read_text(encoding="utf-8"))):
            out[f"docs/{page.name}#{k}"] = m.group(2)
    return out


def to_bytes(text: str, rng: random.Random | None = None) -> bytes:
    data = text.encode("utf-8", "surrogatepass")
    if rng is not None and rng.random() < 0.01:  # bytes that are not UTF-8
        k = rng.randrange(len(data) + 1)
        data = data[:k] + rng.choice([b"\xff", b"\xc3", b"\xe2\x82", b"\x80\x80"]) + data[k:]
    return data


def case(rng: random.Random, seeds: dict[str, str], i: int) -> tuple[str, bytes]:
    """Case number i: (how it was made, its bytes).  Even cases are generated, odd ones are
    mutations of a shipped model (or, one time in four, of a generated one)."""
    if i % 50 == 49:  # (a family of models that grow with N: costs that grow too fast)
        return "parallel branches", to_bytes(parallel_branches(rng))
    if i % 2 == 0:
        text = generate(rng)
        if rng.random() < 0.25:
            text = mutate(rng, text)
            return "generated+mutated", to_bytes(text, rng)
        return "generated", to_bytes(text, rng)
    if rng.random() < 0.25:
        return "generated+mutated", to_bytes(mutate(rng, generate(rng)), rng)
    name = rng.choice(sorted(seeds))
    return f"mutated {name}", to_bytes(mutate(rng, seeds[name]), rng)


# ------------------------------------------------------------------------- check, in process

# (after warnings, if any; an error in a library the model imports is located there)
LOCATED = re.compile(r"^(m\.bg|\S+\.bg:\d+:\d+)(:\d+:\d+)?: error: ", re.M)


def _innermost_bgc_frame(exc: BaseException) -> str:
    frames = traceback.extract_tb(exc.__traceback__)
    inside = [f for f in frames if f"{os.sep}bgc{os.sep}" in f.filename]
    f = (inside or frames or [None])[-1]
    return f"{Path(f.filename).name}:{f.name}" if f else "?"


def check_case(data: bytes, args=("check", "m.bg")) -> dict:
    """`bgc check m.bg` on data, in a directory of its own (also the working directory), with
    click's runner (the function the command line calls, in this process).  Returns
    {"exit", "stderr", "failure"}: failure None, or the failure's signature."""
    from click.testing import CliRunner

    from bgc.cli import main

    cwd = os.getcwd()
    with tempfile.TemporaryDirectory(prefix="bgcfuzz-") as tmp:
        Path(tmp, "m.bg").write_bytes(data)
        os.chdir(tmp)
        try:
            result = CliRunner().invoke(main, list(args))
            left = sorted(os.listdir(tmp))
        finally:
            os.chdir(cwd)
    exc = result.exception
    stderr = result.stderr
    failure = None
    if exc is not None and not isinstance(exc, SystemExit):
        failure = f"check: {type(exc).__name__} at {_innermost_bgc_frame(exc)}"
        stderr += "".join(traceback.format_exception(exc))
    elif result.exit_code not in (0, 1):
        failure = f"check: exit {result.exit_code}"
    elif "Traceback" in stderr or "Traceback" in result.stdout:
        failure = "check: traceback in the output"
    elif result.exit_code == 1 and not LOCATED.search(stderr):
        failure = "check: exit 1 without a located error"
    elif left != ["m.bg"]:
        failure = "check: files left behind"
    return {"exit": result.exit_code, "stderr": stderr[-4000:], "failure": failure}


def _children() -> list[int]:
    """The processes this one started that still exist (zombies apart)."""
    out = []
    for task in Path("/proc/self/task").iterdir():
        try:
            out += [int(p) for p in (task / "children").read_text().split()]
        except OSError:
            pass
    alive = []
    for pid in out:
        try:
            state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
        except OSError:
            continue
        if state != "Z":
            alive.append(pid)
    return alive


def _kill(pids) -> None:
    """Kill and reap the processes a command left running."""
    for pid in pids:
        try:
            os.kill(pid, signal.SIGKILL)
            os.waitpid(pid, 0)
        except (OSError, ChildProcessError):
            pass


def _worker_main():
    """The worker: reads one case a line (JSON, the bytes in base64), answers one line.  A
    request with "simulate": BACKEND runs `bgc simulate` in process (simulate_case), then
    looks for a process the command left running (an orphan once bgc is gone)."""
    import bgc.cli  # noqa: F401  (imported once, before the first case)
    # the protocol gets a descriptor of its own: whatever else writes on descriptor 1 (a
    # print, a generated program) goes nowhere
    out = os.fdopen(os.dup(1), "w")
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, 1)
    sys.stdout = sys.stderr
    for line in sys.stdin:
        req = json.loads(line)
        data = base64.b64decode(req["data"])
        if req.get("simulate"):
            res = simulate_case(data, req["simulate"], 0, t_end=req.get("t_end", "0.05"),
                                in_process=True)
            left = _children()
            if left and not res["failure"]:
                res["failure"] = f"simulate {req['simulate']}: a process outlived the command"
            _kill(left)
        elif req.get("command"):
            res = command_case(data, req["command"])
            _kill(_children())
        else:
            res = check_case(data, tuple(req.get("args", ("check", "m.bg"))))
        out.write(json.dumps(res) + "\n")
        out.flush()


class Worker:
    """A process running check_case, killed and started again when a case exceeds the time
    limit (a hang) or the worker dies; restarted every `recycle` cases (SymPy's caches)."""

    def __init__(self, time_limit: float, recycle: int = 2000):
        self.time_limit, self.recycle = time_limit, recycle
        self.proc = None
        self.done = 0

    def _start(self):
        env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
        self.proc = subprocess.Popen([sys.executable, str(Path(__file__).resolve()), "--worker"],
                                     stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                     stderr=subprocess.DEVNULL, env=env, start_new_session=True)
        self.done = 0

    def stop(self):
        if self.proc is not None:
            try:
                os.killpg(self.proc.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
            self.proc.wait()
            for f in (self.proc.stdin, self.proc.stdout):
                try:
                    f.close()
                except OSError:
                    pass
            self.proc = None

    def run(self, data: bytes, args=("check", "m.bg"), simulate: str | None = None,
            time_limit: float | None = None, command: str | None = None) -> dict:
        """check (args) or, with simulate=BACKEND, `bgc simulate` on data, or one of COMMANDS
        (command=NAME); time_limit in seconds (by default the worker's)."""
        if self.proc is None or self.done >= self.recycle:
            self.stop()
            self._start()
        self.done += 1
        what = f"simulate {simulate}" if simulate else command or "check"
        req = json.dumps({"data": base64.b64encode(data).decode(), "args": list(args),
                          "simulate": simulate, "command": command}) + "\n"
        start = time.monotonic()
        try:
            self.proc.stdin.write(req.encode())
            self.proc.stdin.flush()
        except BrokenPipeError:
            self.stop()
            return {"exit": None, "stderr": "", "failure": f"{what}: the worker died"}
        # the first case of a worker includes its start (imports): allowed 20 s more
        limit = (time_limit or self.time_limit) + (20 if self.done == 1 else 0)
        ready, _, _ = select.select([self.proc.stdout], [], [], limit)
        if not ready:
            self.stop()
            return {"exit": None, "stderr": "", "failure": f"{what}: hang",
                    "seconds": time.monotonic() - start}
        line = self.proc.stdout.readline()
        if not line:
            code = self.proc.wait()
            self.stop()
            return {"exit": code, "stderr": "", "failure": f"{what}: the worker died ({code})"}
        res = json.loads(line)
        res["seconds"] = time.monotonic() - start
        return res


# ------------------------------------------------------------------------- simulate

def _csv_problem(path: Path) -> str | None:
    data = path.read_bytes()
    if not data:
        return "an empty CSV"
    if not data.endswith(b"\n"):
        return "a CSV that ends in a cut row"
    lines = data.decode("utf-8", "replace").splitlines()
    width = lines[0].count(",")
    if any(line.count(",") != width for line in lines[1:]):
        return "a CSV row of the wrong width"
    if re.search(r"(^|,)[-+]?(nan|inf)", "\n".join(lines[1:]), re.I | re.M):
        return "a non-finite value in the CSV"  # (the programs stop on one, with a message)
    return None


def _simulate_in_process(tmp: str, args: list[str], env: dict):
    """bgc simulate ARGS with click's runner in directory tmp: (exit status, stderr, failure
    or None).  (For the suite: no interpreter start, no second SymPy import.)"""
    from click.testing import CliRunner

    from bgc.cli import main

    cwd = os.getcwd()
    os.chdir(tmp)
    try:
        result = CliRunner().invoke(main, args, env=env)
    finally:
        os.chdir(cwd)
    exc = result.exception
    if exc is not None and not isinstance(exc, SystemExit):
        return None, "".join(traceback.format_exception(exc)), \
            f"{type(exc).__name__} at {_innermost_bgc_frame(exc)}"
    return result.exit_code, result.stderr, None


def simulate_case(data: bytes, backend: str, time_limit: float, t_end: str = "0.05",
                  in_process: bool = False) -> dict:
    """`bgc simulate m.bg --backend B --t-end T -o out.csv` in a directory of its own, with a
    cache of its own, as a subprocess (in_process: with click's runner, no time limit);
    {"exit", "stderr", "failure"}."""
    with tempfile.TemporaryDirectory(prefix="bgcfuzz-sim-") as tmp:
        Path(tmp, "m.bg").write_bytes(data)
        env = {"BGC_CACHE_DIR": str(Path(tmp, "cache")),
               "BGC_CFLAGS": os.environ.get("BGC_CFLAGS", "-O0 -std=c99")}
        args = ["simulate", "m.bg", "--backend", backend, "--t-end", t_end, "-o", "out.csv"]
        orphan = False
        if in_process:
            code, stderr, raised = _simulate_in_process(tmp, args, env)
            if raised:
                return {"exit": None, "stderr": stderr[-4000:],
                        "failure": f"simulate {backend}: {raised}"}
        else:
            env = dict(os.environ, **env, PYTHONPATH=str(ROOT) + os.pathsep
                       + os.environ.get("PYTHONPATH", ""))
            proc = subprocess.Popen([sys.executable, "-m", "bgc", *args], cwd=tmp, env=env,
                                    stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                    start_new_session=True)
            try:
                _, err = proc.communicate(timeout=time_limit)
            except subprocess.TimeoutExpired:
                os.killpg(proc.pid, signal.SIGKILL)
                proc.communicate()
                return {"exit": None, "stderr": "", "failure": f"simulate {backend}: hang"}
            finally:
                try:  # the generated program, if it outlived bgc (an orphan)
                    os.killpg(proc.pid, signal.SIGKILL)
                    orphan = True
                except ProcessLookupError:
                    pass
            stderr = err.decode("utf-8", "replace")
            code = proc.returncode
        out = Path(tmp, "out.csv")
        left = sorted(p for p in os.listdir(tmp) if p not in ("m.bg", "out.csv", "cache"))
        failure = None
        if code < 0:
            failure = f"simulate {backend}: bgc killed by signal {-code}"
        elif "Traceback" in stderr:
            last = [l for l in stderr.splitlines() if l.strip()][-1:]
            kind = last[0].split(":")[0] if last else "?"
            failure = f"simulate {backend}: traceback ({kind})"
        elif code not in (0, 1, 2):
            failure = f"simulate {backend}: exit {code}"
        elif code == 2 and not re.search(r"^(Usage:|Error:)", stderr, re.M):
            failure = f"simulate {backend}: exit 2 without a usage error"
        elif code == 1 and not stderr.strip():
            failure = f"simulate {backend}: exit 1 without a message"
        elif code == 0 and not out.exists():
            failure = f"simulate {backend}: exit 0 without the CSV"
        elif out.exists() and _csv_problem(out):
            failure = f"simulate {backend}: {_csv_problem(out)}"
        elif left:
            failure = f"simulate {backend}: files left behind"
        elif orphan:
            failure = f"simulate {backend}: a process outlived bgc"
        elif Path(tmp, "m.bg").read_bytes() != data:
            failure = f"simulate {backend}: the model file changed"
        digest = hashlib.sha256(out.read_bytes()).hexdigest() \
            if code == 0 and out.exists() else None
        return {"exit": code, "stderr": stderr[-4000:], "failure": failure, "digest": digest}


# ------------------------------------------------------------------------- minimisation

def _ddmin(parts: list[str], fails, budget_end: float) -> list[str]:
    """Delta debugging: a smaller list of parts whose join still fails (the same way)."""
    n = 2
    while len(parts) >= 2 and time.monotonic() < budget_end:
        chunk = max(1, len(parts) // n)
        reduced = False
        for start in range(0, len(parts), chunk):
            if time.monotonic() >= budget_end:
                break
            candidate = parts[:start] + parts[start + chunk:]
            if candidate and fails(candidate):
                parts, n, reduced = candidate, max(n - 1, 2), True
                break
        if not reduced:
            if chunk == 1:
                break
            n = min(len(parts), n * 2)
    return parts


def minimise(data: bytes, still_fails, seconds: float = 180.0) -> bytes:
    """data made smaller by ddmin on lines, then on tokens, then on characters (once small);
    still_fails(bytes) -> bool.  Stops after `seconds` with the smallest failing data found."""
    end = time.monotonic() + seconds
    text = data.decode("utf-8", "surrogateescape")
    enc = lambda s: s.encode("utf-8", "surrogateescape")  # noqa: E731
    lines = text.splitlines(keepends=True)
    lines = _ddmin(lines, lambda ps: still_fails(enc("".join(ps))), end)
    tokens = TOKEN.findall("".join(lines))
    tokens = _ddmin(tokens, lambda ps: still_fails(enc("".join(ps))), end)
    chars = list("".join(tokens))  # (inside comments, strings and numbers too)
    if len(chars) <= 4000:
        chars = _ddmin(chars, lambda ps: still_fails(enc("".join(ps))), end)
    return enc("".join(chars))


def _slug(signature: str) -> str:
    return re.sub(r"[^a-z0-9]+", "_", signature.lower()).strip("_")[:60]


def write_regression(directory: Path, signature: str, data: bytes, how: str, seed: int,
                     index: int, original: bytes) -> Path:
    directory.mkdir(parents=True, exist_ok=True)
    stem = _slug(signature)
    path = directory / f"{stem}.bg"
    k = 2
    while path.exists():
        path, k = directory / f"{stem}_{k}.bg", k + 1
    path.write_bytes(data)
    path.with_suffix(".note").write_text(
        f"failure: {signature}\nfound by: tools/fuzz.py --seed {seed}, case {index} ({how})\n"
        f"the case before minimisation ({len(original)} bytes):\n"
        + original.decode("utf-8", "backslashreplace") + "\n", encoding="utf-8")
    return path


# ------------------------------------------------------------------------- the FMU

COMMANDS = {  # --full-every: the other commands, each with the outputs it must write on exit 0
    "compile c": (["compile", "m.bg", "--target", "c", "-o", "m.c"], ["m.c"]),
    "compile python": (["compile", "m.bg", "--target", "python", "-o", "m.py"], ["m.py"]),
    "compile fmu": (["compile", "m.bg", "--target", "fmu", "-o", "m.fmu"], ["m.fmu"]),
    "linearize": (["linearize", "m.bg", "-o", "lin.json"], ["lin.json"]),
    "steady": (["steady", "m.bg", "--json", "eq.json"], ["eq.json"]),
}


def command_case(data: bytes, what: str) -> dict:
    """One of COMMANDS on data, in process (click's runner) in a directory of its own with a
    cache of its own.  A failure: an exception or a traceback, an exit status other than 0, 1
    and 2 (2 only with a usage message), exit 1 without a message, exit 0 without its output,
    a file left behind that is not its output, the model file changed."""
    from click.testing import CliRunner

    from bgc.cli import main

    args, outputs = COMMANDS[what]
    cwd = os.getcwd()
    with tempfile.TemporaryDirectory(prefix="bgcfuzz-cmd-") as tmp:
        Path(tmp, "m.bg").write_bytes(data)
        env = {"BGC_CACHE_DIR": str(Path(tmp, "cache")),
               "BGC_CFLAGS": os.environ.get("BGC_CFLAGS", "-O0 -std=c99")}
        os.chdir(tmp)
        try:
            result = CliRunner().invoke(main, args, env=env)
            left = sorted(p for p in os.listdir(tmp) if p not in ("m.bg", "cache", *outputs))
            written = [o for o in outputs if Path(tmp, o).exists()]
            same = Path(tmp, "m.bg").read_bytes() == data
        finally:
            os.chdir(cwd)
    exc, stderr, code = result.exception, result.stderr, result.exit_code
    failure = None
    if exc is not None and not isinstance(exc, SystemExit):
        failure = f"{what}: {type(exc).__name__} at {_innermost_bgc_frame(exc)}"
        stderr += "".join(traceback.format_exception(exc))
    elif "Traceback" in stderr or "Traceback" in result.stdout:
        failure = f"{what}: traceback in the output"
    elif code not in (0, 1, 2):
        failure = f"{what}: exit {code}"
    elif code == 2 and not re.search(r"^(Usage:|Error:)", stderr, re.M):
        failure = f"{what}: exit 2 without a usage error"
    elif code == 1 and not stderr.strip():
        failure = f"{what}: exit 1 without a message"
    elif code == 0 and len(written) != len(outputs):
        failure = f"{what}: exit 0 without its output"
    elif code != 0 and written:
        failure = f"{what}: an output written by a command that failed"
    elif left:
        failure = f"{what}: files left behind ({', '.join(left)})"
    elif not same:
        failure = f"{what}: the model file changed"
    return {"exit": code, "stderr": stderr[-4000:], "failure": failure}


def fmu_case(data: bytes, seed: int, sequences: int, out: Path, time_limit: float) -> dict | None:
    """The case's FMU, its life cycle fuzzed by tools/fuzz_fmu.py in a process of its own
    (the export and the calls limited to time_limit seconds): None if bgc exports none (a
    model error, a model an FMU cannot hold, no C compiler); else {"calls", "failure": None
    or the first failing sequence's signature, "stderr": what failed}."""
    with tempfile.TemporaryDirectory(prefix="bgcfuzz-fmu-") as tmp:
        Path(tmp, "m.bg").write_bytes(data)
        env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""),
                   BGC_CACHE_DIR=str(Path(tmp, "cache")),
                   BGC_CFLAGS=os.environ.get("BGC_CFLAGS", "-O0 -std=c99"))
        try:
            done = subprocess.run([sys.executable, str(ROOT / "tools" / "fuzz_fmu.py"), "--model",
                                   str(Path(tmp, "m.bg")), "--seed", str(seed), "--sequences",
                                   str(sequences), "--out", str(out)], capture_output=True,
                                  text=True, env=env, timeout=time_limit)
        except subprocess.TimeoutExpired:
            return {"calls": 0, "stderr": "", "failure": "fmu: hang"}
    lines = done.stdout.strip().splitlines()
    if done.returncode != 0 or not lines:
        return {"calls": 0, "stderr": done.stderr[-4000:],
                "failure": f"fmu: the harness failed (exit {done.returncode})"}
    res = json.loads(lines[-1])
    if res is None:
        return None
    first = res["failures"][0] if res["failures"] else None
    return {"calls": res["calls"], "stderr": first or "",
            "failure": None if first is None
            else "fmu: " + re.sub(r" \(.*", "", first.splitlines()[0]).strip()}


# ------------------------------------------------------------------------- the campaign

def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--cases", type=int, default=1000)
    ap.add_argument("--simulate-every", type=int, default=50, metavar="K",
                    help="simulate every K-th case that check accepts (0: never)")
    ap.add_argument("--time-limit", type=float, default=30.0, help="seconds per check")
    ap.add_argument("--sim-time-limit", type=float, default=120.0,
                    help="seconds per simulate (compilation included)")
    ap.add_argument("--out", type=Path, default=Path("fuzz-out"),
                    help="the log, the failing cases as found, summary.json")
    ap.add_argument("--regressions", type=Path, default=REGRESSIONS,
                    help="where minimised failures go")
    ap.add_argument("--simulate-subprocess", action="store_true",
                    help="simulate with bgc as a subprocess of its own (slower: an interpreter "
                    "start per run) instead of in the worker process")
    ap.add_argument("--max-seconds", type=float, default=0,
                    help="stop (with the summary) after this many seconds (0: no limit)")
    ap.add_argument("--no-minimise", action="store_true")
    ap.add_argument("--fmu-every", type=int, default=0, metavar="K",
                    help="export every K-th case that check accepts as an FMU and fuzz its life "
                    "cycle (tools/fuzz_fmu.py; 0: never)")
    ap.add_argument("--fmu-sequences", type=int, default=20,
                    help="random sequences of FMI calls on each FMU")
    ap.add_argument("--full-every", type=int, default=0, metavar="K",
                    help="every K-th case that check accepts through everything: simulate in "
                    "the three backends (C, Python, the interpreter) with their CSVs compared "
                    "byte for byte, compile to C, Python and an FMU, linearize and steady "
                    "(0: never)")
    ap.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.worker:
        _worker_main()
        return 0
    def stop(signum, frame):
        raise KeyboardInterrupt
    # (a run in the background of a shell starts with SIGINT ignored: TERM stops it too, with
    # its summary)
    signal.signal(signal.SIGINT, stop)
    signal.signal(signal.SIGTERM, stop)
    a.out.mkdir(parents=True, exist_ok=True)
    log = open(a.out / "log.txt", "a", encoding="utf-8")
    rng = random.Random(a.seed)
    seeds = seed_models()
    worker = Worker(a.time_limit)
    counts = {"check": 0, "check_ok": 0, "check_error": 0, "simulate": 0, "simulate_c": 0,
              "simulate_python": 0, "simulate_vm": 0, "backends_compared": 0, "fmu": 0,
              "fmu_calls": 0, **{k.replace(" ", "_"): 0 for k in COMMANDS}}
    failures: dict[str, dict] = {}
    accepted = 0
    start = time.monotonic()

    def say(msg):
        print(msg, flush=True)
        log.write(msg + "\n")
        log.flush()

    def record(signature, i, how, data, res, rerun):
        entry = failures.setdefault(signature, {"count": 0, "first_case": i, "regression": None})
        entry["count"] += 1
        raw = a.out / "failures" / f"{i:07d}.bg"
        raw.parent.mkdir(exist_ok=True)
        raw.write_bytes(data)
        say(f"case {i} ({how}): FAILURE {signature}\n{res.get('stderr', '')[-1500:]}")
        if entry["count"] == 1 and not a.no_minimise:
            small = minimise(data, lambda d: rerun(d) == signature,
                             seconds=60 if "hang" in signature else 180)
            path = write_regression(a.regressions, signature, small, how, a.seed, i, data)
            entry["regression"] = str(path)
            say(f"  minimised to {len(small)} bytes: {path}")

    try:
        for i in range(a.cases):
            if a.max_seconds and time.monotonic() - start > a.max_seconds:
                say(f"stopped after {a.max_seconds:.0f} s (--max-seconds)")
                break
            how, data = case(rng, seeds, i)
            res = worker.run(data)
            counts["check"] += 1
            if res["failure"]:
                record(res["failure"], i, how, data, res, lambda d: worker.run(d)["failure"])
                continue
            counts["check_ok" if res["exit"] == 0 else "check_error"] += 1
            if res.get("seconds", 0) > 5:
                say(f"case {i} ({how}): slow check, {res['seconds']:.1f} s")
            if res["exit"] == 0:
                accepted += 1
                if a.simulate_every and accepted % a.simulate_every == 0:
                    counts["simulate"] += 1
                    for backend in ("c", "python"):
                        counts[f"simulate_{backend}"] += 1
                        if a.simulate_subprocess:
                            sim = lambda d, b=backend: simulate_case(  # noqa: E731
                                d, b, a.sim_time_limit)
                        else:
                            sim = lambda d, b=backend: worker.run(  # noqa: E731
                                d, simulate=b, time_limit=a.sim_time_limit)
                        s = sim(data)
                        if s["failure"]:
                            record(s["failure"], i, how, data, s,
                                   lambda d, sim=sim: sim(d)["failure"])
                if a.full_every and accepted % a.full_every == 0:
                    digests = {}
                    for backend in ("c", "python", "vm"):
                        counts[f"simulate_{backend}"] += 1
                        sim = lambda d, b=backend: worker.run(  # noqa: E731
                            d, simulate=b, time_limit=a.sim_time_limit)
                        s = sim(data)
                        if s["failure"]:
                            record(s["failure"], i, how, data, s,
                                   lambda d, sim=sim: sim(d)["failure"])
                        else:
                            digests[backend] = (s["exit"], s.get("digest"))
                    if len(digests) == 3:
                        counts["backends_compared"] += 1
                        if len(set(digests.values())) > 1:
                            def differ(d):
                                out = {b: worker.run(d, simulate=b,
                                                     time_limit=a.sim_time_limit)
                                       for b in ("c", "python", "vm")}
                                if any(r["failure"] for r in out.values()):
                                    return None
                                seen = {(r["exit"], r.get("digest")) for r in out.values()}
                                return "simulate: the backends differ" if len(seen) > 1 \
                                    else None
                            record("simulate: the backends differ", i, how, data,
                                   {"stderr": json.dumps(digests)}, differ)
                    for what in COMMANDS:
                        counts[what.replace(" ", "_")] += 1
                        run = lambda d, w=what: worker.run(  # noqa: E731
                            d, command=w, time_limit=a.sim_time_limit)
                        r = run(data)
                        if r["failure"]:
                            record(r["failure"], i, how, data, r,
                                   lambda d, run=run: run(d)["failure"])
                if a.fmu_every and accepted % a.fmu_every == 0:
                    fmu = lambda d: fmu_case(d, a.seed * 1000003 + i,  # noqa: E731
                                             a.fmu_sequences, a.out / "fmu",
                                             a.sim_time_limit)
                    f = fmu(data)
                    if f is not None:
                        counts["fmu"] += 1
                        counts["fmu_calls"] += f["calls"]
                        if f["failure"]:
                            record(f["failure"], i, how, data, f,
                                   lambda d: (fmu(d) or {}).get("failure"))
            if (i + 1) % 500 == 0:
                el = time.monotonic() - start
                say(f"{i + 1} cases, {counts}, {sum(f['count'] for f in failures.values())} "
                    f"failures ({len(failures)} kinds), {el:.0f} s")
    except KeyboardInterrupt:
        say("interrupted")
    finally:
        worker.stop()
        summary = {"seed": a.seed, "cases_requested": a.cases, **counts,
                   "seconds": round(time.monotonic() - start),
                   "failures": failures}
        (a.out / "summary.json").write_text(json.dumps(summary, indent=1) + "\n")
        say(json.dumps(summary, indent=1))
        log.close()
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
