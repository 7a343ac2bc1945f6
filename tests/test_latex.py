"""`bgc equations --format latex`: the pendulum's equations against the paper's (Favre &
Scavarda 1998), eq. (8), (9), (11), (12) written out below from the paper's text in its own
variables x, y, their derivatives, m, g, l, α, β; the names the LaTeX uses; escaping."""
import re

import pytest
import sympy as sp

import bgc
from bgc.reports.latex import escape, latex_system, tex_names, tidy
from bgc.reports.report import equations_latex
from conftest import MODELS

PENDULUM = MODELS / "pendulum.bg"

# the paper's variables
x, y, xd, yd, m, g, l, alpha, beta = sp.symbols("x y xdot ydot m g l alpha beta", real=True)

# eq. (8) and (9): the classical Lagrange equations (no corrector)
BRACKET_9 = y * g + xd ** 2 + yd ** 2
LAMBDA_8 = m / (2 * x ** 2 + 2 * y ** 2) * BRACKET_9
XDD_9 = -x / (x ** 2 + y ** 2) * BRACKET_9
YDD_9 = g - y / (x ** 2 + y ** 2) * BRACKET_9

# eq. (11) and (12): with Baumgarte's stabilisation
BRACKET_12 = (y * g + xd ** 2 + yd ** 2 + 2 * alpha * (x * xd + y * yd)
              + beta ** 2 * (x ** 2 + y ** 2 - l ** 2) / 2)
LAMBDA_11 = m / (2 * x ** 2 + 2 * y ** 2) * BRACKET_12
XDD_12 = -x / (x ** 2 + y ** 2) * BRACKET_12
YDD_12 = g - y / (x ** 2 + y ** 2) * BRACKET_12

# the names the LaTeX must use for the model's symbols, as the paper writes them
NAMES = {"mx.p": "p_{x}", "my.p": "p_{y}", "x": "x", "y": "y", "m": "m", "g": "g", "l": "l",
         "alpha": r"\alpha", "beta": r"\beta", "rod.lambda": r"\lambda_{\mathrm{rod}}",
         "rod.residual": r"\Phi_{\mathrm{rod}}"}


def _rows(text: str) -> dict:
    """{left side: right side} of the align environment's rows."""
    assert "\\begin{align}" in text and text.rstrip().endswith("\\end{align}")
    rows = {}
    for line in text.splitlines():
        if "&=" in line:
            lhs, rhs = line.split(" &= ")
            rows[lhs] = re.sub(r" \\\\$", "", rhs)
    return rows


@pytest.fixture(scope="module", params=["swing", "unstabilised"])
def pendulum(request):
    compiled = bgc.build(PENDULUM, request.param, program=False)
    return request.param, latex_system(compiled, "pendulum"), equations_latex(compiled)


def test_pendulum_latex_is_the_papers_equations(pendulum):
    """Eq. (12) (swing) and (9) (unstabilised): under p_x = m dx/dt (the paper's eq. 6), the
    right sides the LaTeX is printed from are the paper's; the LaTeX is those right sides
    printed with the paper's names."""
    scene, system, text = pendulum
    for name, tex in NAMES.items():
        if scene == "swing" or name not in ("alpha", "beta"):
            assert system.names[name] == tex, name
    rows = _rows(text)
    assert list(rows) == [r"\dot{p}_{x}", r"\dot{p}_{y}", r"\dot{x}", r"\dot{y}",
                          r"\lambda_{\mathrm{rod}}", r"\Phi_{\mathrm{rod}}"]
    assert "mx.p" not in text and "rod.lambda" not in text
    symbols = {s.name: s for r in system.rows for s in r.rhs.free_symbols}
    paper = {"x": x, "y": y, "m": m, "g": g, "l": l, "alpha": alpha, "beta": beta,
             "mx.p": m * xd, "my.p": m * yd}
    subs = {symbols[k]: v for k, v in paper.items() if k in symbols}
    xdd, ydd, lam = (XDD_12, YDD_12, LAMBDA_11) if scene == "swing" else \
        (XDD_9, YDD_9, LAMBDA_8)
    expected = {r"\dot{p}_{x}": m * xdd, r"\dot{p}_{y}": m * ydd, r"\dot{x}": xd,
                r"\dot{y}": yd, r"\lambda_{\mathrm{rod}}": lam,
                r"\Phi_{\mathrm{rod}}": x ** 2 + y ** 2 - l ** 2}  # eq. (4)
    for lhs, want in expected.items():
        rhs = system.row(lhs).rhs
        assert sp.cancel(rhs.xreplace(subs) - want) == 0, lhs
        printed = sp.latex(rhs, symbol_names={s: NAMES[s.name] for s in rhs.free_symbols})
        assert rows[lhs] == printed, lhs
    if scene == "unstabilised":
        assert not {"alpha", "beta"} & set(symbols)


def test_names_are_greek_subscripted_escaped_and_one_to_one():
    names = tex_names(["theta0", "tau_load", "Omega", "eps", "a_b_c", "Ra", "x12", "p_x",
                       "mx.p", "cap.q", "mass.p[1]", "q[0]", "rod1.lambda", "der(x)",
                       "e[gravity->w[0]]"], {"mx.p": "x"})
    tex = {k: v.text() for k, v in names.items()}
    assert tex["theta0"] == r"\theta_{0}"
    assert tex["tau_load"] == r"\tau_{\mathrm{load}}"
    assert tex["Omega"] == r"\Omega" and tex["eps"] == r"\varepsilon"
    assert tex["a_b_c"] == r"a_{\mathrm{b\_c}}"
    assert tex["Ra"] == r"\mathrm{Ra}" and tex["x12"] == "x_{12}"
    assert tex["cap.q"] == r"q_{\mathrm{cap}}" and tex["mass.p[1]"] == r"p_{\mathrm{mass},1}"
    assert tex["q[0]"] == "q_{0}" and tex["rod1.lambda"] == r"\lambda_{\mathrm{rod}_{1}}"
    assert tex["der(x)"] == r"\dot{x}"
    assert tex["e[gravity->w[0]]"] == r"e_{\mathrm{gravity} \to w,0}"
    # the parameter p_x and the momentum of x would share p_{x}: both fall back to the names
    assert tex["p_x"] == r"\mathrm{p\_x}" and tex["mx.p"] == r"\mathrm{mx.p}"
    assert len(set(tex.values())) == len(tex)


def test_escape_leaves_no_special_character():
    assert escape("a_b\\c{d}$e%f#g&h^i~j") == (
        r"a\_b\text{\textbackslash}c\{d\}\$e\%f\#g\&h\text{\textasciicircum}i"
        r"\text{\textasciitilde}j")
    assert escape("x\ny\u00e9") == "x?y?"


def test_model_names_stay_escaped_in_the_latex():
    source = ("model esc\nparameter k_1_b = 2\nparameter lambda = 3\n"
              "spring_a : C(k_1_b)\nj_0 : 1\ndamp : R(lambda)\n"
              "j_0 -> spring_a\nj_0 -> damp\n")
    text = bgc.api.equations(bgc.api.Source("esc.bg", source), format="latex")
    assert r"\dot{q}_{\mathrm{spring}_{a}}" in text
    assert r"k_{\mathrm{1\_b}}" in text and r"\lambda" in text
    body = text.split("\\begin{align}")[1]
    assert not re.search(r"(?<!\\)_(?!\{)", body)  # every underscore escaped or a subscript
    assert body.count("{") == body.count("}")


def test_tidy_reduces_squares_of_sine_and_cosine_and_stays_bounded():
    a, b, u, m1, m2 = sp.symbols("a b u m1 m2", real=True)
    assert tidy(a * sp.sin(u) ** 2 + a * sp.cos(u) ** 2 + b) == a + b
    assert tidy(b / (sp.sin(u) ** 2 + sp.cos(u) ** 2)) == b
    got = tidy(m1 + m2 - m2 * sp.cos(u) ** 2)
    assert got == m1 + m2 * sp.sin(u) ** 2
    deep = sp.sin(u) ** 2 + sp.cos(u) ** 2
    for _ in range(300):  # deeper than resources.MAX_EXPRESSION_DEPTH: left as it is
        deep = sp.sin(deep, evaluate=False)
    assert tidy(deep) is deep
