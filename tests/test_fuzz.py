"""Fuzzing `bgc check`: whatever the text, it answers 0 (the model is fine) or 1 with a located
error (`FILE:LINE:COL: error: ...`, or `FILE: error: ...` for the file as a whole), never a
traceback, never a hang, and it writes no file.

Two sources of text: models generated from the grammar (grammar/bg.lark) with random names,
keywords, kinds, numbers, operators and functions; and the models of models/ with a few tokens
deleted, duplicated, swapped, replaced or with random characters inserted.

In the suite (CI) the examples are few and fixed (derandomize=True), a few seconds in all.  Long
mode draws fresh examples, as many as BGC_FUZZ_EXAMPLES says for each of the two tests:

    BGC_FUZZ_EXAMPLES=100000 python -m pytest -q -n 0 -s tests/test_fuzz.py

Time is bounded by bgc's own limits (bgc/base/resources.py); the alarm below only turns a hang into
a failure instead of a stuck test run.  The fuzzing harness of the long runs, with simulation
and minimisation, is tools/fuzz.py (tests/test_fuzz_harness.py, docs/fuzzing.md).
"""
import os
import re
import signal
import tempfile
import time
from contextlib import contextmanager
from pathlib import Path

from click.testing import CliRunner
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from bgc.cli import main
from bgc.front.parser import KEYWORDS

MODELS = Path(__file__).resolve().parent.parent / "models"
LONG = int(os.environ.get("BGC_FUZZ_EXAMPLES", "0"))
SAFETY_SECONDS = 60  # per example; bgc's limits keep every one far below
SLOW = 5.0  # long mode prints the examples slower than this


def _settings(ci_examples: int):
    return settings(max_examples=LONG or ci_examples, derandomize=not LONG, deadline=None,
                    database=None, print_blob=True,
                    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])


@contextmanager
def _alarm(seconds):
    def expire(signum, frame):
        raise AssertionError(f"bgc check took more than {seconds} s")
    previous = signal.signal(signal.SIGALRM, expire)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)


LOCATED = re.compile(r"^m\.bg(:\d+:\d+)?: error: ")


def check_text(text: str):
    """`bgc check` on text (in a directory of its own, as the working directory too): exit 0,
    or 1 with a located error; no traceback, no file left behind."""
    cwd = os.getcwd()
    with tempfile.TemporaryDirectory() as tmp:
        Path(tmp, "m.bg").write_text(text, encoding="utf-8", errors="surrogatepass")
        os.chdir(tmp)
        try:
            start = time.perf_counter()
            with _alarm(SAFETY_SECONDS):
                result = CliRunner().invoke(main, ["check", "m.bg"])
            elapsed = time.perf_counter() - start
            left = sorted(os.listdir(tmp))
        finally:
            os.chdir(cwd)
    if result.exception is not None and not isinstance(result.exception, SystemExit):
        raise AssertionError(f"bgc check raised {result.exception!r} on:\n{text}") \
            from result.exception
    assert result.exit_code in (0, 1), (result.exit_code, result.stderr, text)
    assert "Traceback" not in result.stderr, (result.stderr, text)
    if result.exit_code == 1:
        assert LOCATED.match(result.stderr), (result.stderr, text)
    assert left == ["m.bg"], left
    if LONG and elapsed > SLOW:
        print(f"\nslow example ({elapsed:.1f} s):\n{text}")


# ---------------------------------------------------------------- models from the grammar

NODES = ("j", "k", "c", "i", "r", "s", "q", "x", "y", "m")
NAMES = NODES + ("a", "b", "t", "e", "f", "p", "lambda", "g_1", "_u")
FIELDS = ("e", "f", "p", "q", "lambda", "residual", "z")
KINDS = ("Se", "Sf", "MSe", "MSf", "I", "C", "R", "TF", "GY", "MTF", "MGY", "Q")
FUNCTIONS = ("sin", "cos", "tan", "asin", "acos", "atan", "atan2", "sinh", "cosh", "tanh",
             "exp", "log", "sqrt", "abs", "sign", "min", "max", "diag", "nope")
NUMBERS = st.one_of(
    st.integers(0, 10 ** 6).map(str),
    st.floats(0, 1e6, allow_nan=False).map(lambda x: repr(x).replace("inf", "1e999")),
    st.sampled_from(["0", "0.0", ".5", "1e-3", "6.02E23", "1e308", "1e309", "1e-320", "2",
                     "1" * 400, "9" * 5000, "64", "1024", "1e8", "100000000"]),
)
NAME = st.sampled_from(NAMES * 30 + tuple(sorted(KEYWORDS)))  # a keyword one time in 30
ARITY = {"atan2": 2, "min": 2, "max": 3, "diag": 2, "nope": 1}


def _expressions(names=NAME):
    """Expressions over numbers, names and fields; calls mostly of the right arity."""
    leaf = st.one_of(NUMBERS, names, st.builds(lambda a, b: f"{a}.{b}", NAME,
                                                st.sampled_from(FIELDS)))

    def call(inner):
        def build(f, args, wrong):
            n = ARITY.get(f, 1) + wrong
            return f"{f}({', '.join((args * 3)[:n])})"
        return st.builds(build, st.sampled_from(FUNCTIONS), st.lists(inner, min_size=1,
                                                                      max_size=3),
                         st.sampled_from([0] * 9 + [1, -1]))

    def extend(inner):
        return st.one_of(
            st.builds(lambda a, op, b: f"{a} {op} {b}", inner,
                      st.sampled_from(["+", "-", "*", "/", "^", "**"]), inner),
            st.builds(lambda a: f"({a})", inner),
            st.builds(lambda a: f"-{a}", inner),
            call(inner),
            st.builds(lambda items: f"[{', '.join(items)}]", st.lists(inner, min_size=1,
                                                                       max_size=3)),
            st.builds(lambda a, i: f"{a}[{i}]", inner, st.integers(0, 3)),
        )
    return st.recursive(leaf, extend, max_leaves=10)


EXPR = _expressions()
DIM = st.one_of(st.just(""), st.integers(0, 4).map(lambda n: f"[{n}]"),
                st.builds(lambda n, m: f"[{n}->{m}]", st.integers(1, 3), st.integers(1, 3)))
DOC = st.one_of(st.just(""), st.just(' "a doc"'))


def _element():
    arg = st.one_of(EXPR, st.builds(lambda v, e: f"{v} = {e}", st.sampled_from("efpq"), EXPR))
    init = st.one_of(st.just(""), st.builds(lambda v, e: f" init {v} = {e}",
                                            st.sampled_from("efpqx"), EXPR))
    effect = st.one_of(st.just(""), st.builds(lambda n: f" @{n}", NAME))
    return st.builds(lambda n, k, d, a, i, e, doc: f"{n} : {k}{d}({a}){i}{e}{doc}",
                     NAME, st.sampled_from(KINDS), DIM, arg, init, effect, DOC)


def _junction():
    corrector = st.sampled_from(["", " corrector none", " corrector pid(1, 2)",
                                 " corrector pd(3)"])
    constraint = st.one_of(st.just(""), st.builds(
        lambda kind, ann, corr: f" constraint{kind}{ann}{corr}",
        st.sampled_from(["", " holonomic", " nonholonomic"]),
        st.one_of(st.just(""), st.builds(lambda w, e: f"({w} = {e})",
                                         st.sampled_from(["init", "phi"]), EXPR)),
        corrector))
    return st.builds(lambda n, k, d, c: f"{n} : {k}{d}{c}", NAME, st.sampled_from("01"), DIM,
                     constraint)


def _scene():
    stmt = st.one_of(
        st.builds(lambda ns: "effects " + ", ".join(ns), st.lists(NAME, min_size=1,
                                                                    max_size=3)),
        st.just("effects none"),
        st.builds(lambda ns: "outputs " + ", ".join(ns), st.lists(
            st.one_of(NAME, st.builds(lambda a, b: f"{a}.{b}", NAME, st.sampled_from(FIELDS)),
                      st.builds(lambda a, i: f"{a}[{i}]", NAME, st.integers(0, 3))),
            min_size=1, max_size=3)),
        st.builds(lambda a, b, c: f"time {a} .. {b}{c}", EXPR, EXPR,
                  st.one_of(st.just(""), EXPR.map(lambda e: f" every {e}"))),
        st.builds(lambda n, k, e: f"solver {n}({k} = {e})",
                  st.sampled_from(["dopri5", "rk4", "euler", "radau5", "nope"]),
                  st.sampled_from(["rtol", "atol", "step", "foo"]), EXPR),
        st.builds(lambda n, e: f"set {n} = {e}", NAME, EXPR),
    )
    return st.builds(lambda n, doc, body, sep: f"scene {n}{doc} {{ {sep.join(body)} }}", NAME,
                     DOC, st.lists(stmt, max_size=4), st.sampled_from(["; ", "\n  "]))


STATEMENT = st.one_of(
    st.builds(lambda n, e, doc: f"parameter {n} = {e}{doc}", NAME, EXPR, DOC),
    _element(), _element(), _junction(), _junction(),
    st.builds(lambda n, d, e: f"signal {n}{d} = {e}", NAME, DIM, EXPR),
    st.builds(lambda n, d, e, i: f"signal {n}{d} = integral({e}, init = {i})", NAME, DIM, EXPR,
              EXPR),
    st.builds(lambda ns: " -> ".join(ns), st.lists(NAME, min_size=2, max_size=4)),
    _scene(),
)


@st.composite
def generated_models(draw):
    """A model of junctions and one-ports bonded together (most of the time declared, so that
    the later stages are reached too), parameters, signals, scenes and random statements."""
    nodes = draw(st.lists(st.sampled_from(NODES), min_size=2, max_size=6, unique=True))
    params = draw(st.lists(st.sampled_from(["a", "b", "g_1", "_u"]), max_size=3, unique=True))
    known = st.one_of(st.sampled_from(params + ["t"]), st.builds(
        lambda n, f: f"{n}.{f}", st.sampled_from(nodes), st.sampled_from("efpq")))
    expr = _expressions(st.one_of(known, NAME))
    body = [f"parameter {p} = {draw(expr)}" for p in params]
    for name in nodes:
        kind = draw(st.sampled_from(["0", "1", "Se", "Sf", "MSe", "I", "C", "R", "TF", "GY"]))
        arg = "" if kind in "01" else f"({draw(expr)})"
        body.append(f"{name} : {kind}{arg}")
    for _ in range(draw(st.integers(1, len(nodes)))):
        chain = draw(st.lists(st.sampled_from(nodes), min_size=2, max_size=3, unique=True))
        body.append(" -> ".join(chain))
    if draw(st.booleans()):
        body += draw(st.lists(STATEMENT, max_size=6))
    body = draw(st.permutations(body)) if draw(st.booleans()) else body
    head = draw(st.sampled_from(["model m\n"] * 6 + ["model m \"doc\"\n", "", "model model\n"]))
    sep = draw(st.sampled_from(["\n", "; ", "\n\n"]))
    return head + sep.join(body) + draw(st.sampled_from(["\n", ""]))


@_settings(ci_examples=30)
@given(generated_models())
def test_generated_models_get_an_answer(text):
    check_text(text)


# ---------------------------------------------------------------- mutated models

TOKEN = re.compile(r'"(?:\\.|[^"\\\n])*"|#[^\n]*|[A-Za-z_][A-Za-z0-9_]*|[0-9.]+(?:[eE][+-]?\d+)?'
                   r'|->|\*\*|\.\.|\s+|.', re.S)
CI_MODELS = ("rlc", "pendulum", "diode", "rc_pair", "knife_edge", "van_der_pol")
SOURCES = {p.stem: p.read_text(encoding="utf-8") for p in sorted(MODELS.glob("*.bg"))
           if LONG or p.stem in CI_MODELS}
ODD = ("(", ")", "[", "]", "{", "}", "->", ";", "\n", ":", "=", "^", "@", ".", ",", '"', "\\",
       "#", "\x00", "\ufeff", "é", "0", "1e999", "-", "*", "**", "/", " ", "\t", "\r")


@st.composite
def mutated_models(draw):
    tokens = TOKEN.findall(SOURCES[draw(st.sampled_from(sorted(SOURCES)))])
    for _ in range(draw(st.integers(1, 4))):
        i = draw(st.integers(0, len(tokens) - 1))
        how = draw(st.sampled_from(["delete", "duplicate", "swap", "insert", "replace"]))
        if how == "delete":
            del tokens[i]
        elif how == "duplicate":
            tokens.insert(i, tokens[i])
        elif how == "swap":
            j = draw(st.integers(0, len(tokens) - 1))
            tokens[i], tokens[j] = tokens[j], tokens[i]
        elif how == "insert":
            tokens.insert(i, draw(st.one_of(st.sampled_from(ODD), st.text(max_size=3))))
        else:
            tokens[i] = draw(st.one_of(NUMBERS, NAME, st.sampled_from(KINDS + FUNCTIONS)))
        if not tokens:
            tokens = [""]
    return "".join(tokens)


@_settings(ci_examples=20)
@given(mutated_models())
def test_mutated_models_get_an_answer(text):
    check_text(text)
