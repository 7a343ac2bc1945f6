"""The Python runtime (the parts of bgc/runtime/*.py, one module: bgc.codegen.emit.python_runtime)
on its own: a module that imports what it uses, passes pyflakes, and runs a small model bound by
hand through its contract (the names its head lists), no model compiled.  The generated modules'
behaviour is tested elsewhere (test_python.py, test_parity.py, ...); these tests pin the
contract, the parts' layout and a few pieces."""
import io
import math
import re
from pathlib import Path

import numpy as np
import pytest
from pyflakes import api as pyflakes_api
from pyflakes import reporter as pyflakes_reporter

from bgc.codegen.emit import C_RUNTIME, PY_RUNTIME, python_runtime, runtime_body, \
    solver_tables_python

from helpers import RUNTIME_NAME, pyruntime, pyruntime_place

ROOT = Path(__file__).resolve().parent.parent
RUNTIME = ROOT / "bgc" / "runtime"
GOLDEN = ROOT / "tests" / "golden"


def fresh_runtime():
    """A new copy of the runtime module (binding a model changes its globals) with the solver
    tables, as a generated module has them."""
    return pyruntime()


def bind(rt, **names):
    """Binds a model as a generated module does: its names replace the runtime's, then
    _bind_model()."""
    unknown = set(names) - set(rt._MODEL_NAMES)
    assert not unknown, unknown
    vars(rt).update(names)
    rt._bind_model()
    return rt


def decay(rt, k=1.0, **extra):
    """dx/dt = -k x, x(0) = 1, output x; k a parameter."""
    def fill(p, given):
        if 0 not in given:
            p[0] = k
        return p

    def rhs(t, x, p, w, out):
        out[0] = -p[0] * x[0]

    def out(t, x, p, w, out):
        out[0] = x[0]

    def jvp(t, x, p, w, v, out):
        out[0] = -p[0] * v[0]

    names = dict(MODEL="decay", STATES=["x"], OUTPUTS=["x"], _IDENT="decay", _N=1,
                 _PARAM_NAMES=["k"], _VELOCITY_MOVABLE=[True], _JAC_COLORS=[(0,)],
                 _JAC_COLUMNS=[(0,)], _fill_params=fill, _init=lambda p: [1.0], _rhs=rhs,
                 _out=out, _jvp=jvp,
                 SCENE={"t0": 0.0, "t_end": 2.0, "dt": 0.5, "solver": "dopri5", "rtol": 1e-10,
                        "atol": 1e-12, "step": None})
    names.update(extra)
    return bind(rt, **names)


def _flakes(text, name):
    out, err = io.StringIO(), io.StringIO()
    pyflakes_api.check(text, name, pyflakes_reporter.Reporter(out, err))
    return (out.getvalue() + err.getvalue()).splitlines()


# ---------------------------------------------------------------- the contract


def test_runtime_passes_pyflakes():
    """No undefined name, unused import or variable: the runtime imports what it uses and
    defines every name of the model part it reads (its contract).  Each message names the
    part and its line."""
    found = [re.sub(r"^<bgc python runtime>:(\d+):",
                    lambda m: pyruntime_place(int(m.group(1))) + ":", line)
             for line in _flakes(python_runtime(), RUNTIME_NAME)]
    assert found == []


def test_runtime_is_its_parts_less_their_headers():
    """python_runtime() is the parts PY_RUNTIME lists, each less its header (comment lines up
    to the first blank line, naming the part and its C twin), joined by two blank lines, then
    the solver tables; each part's body starts with its first line of code or comment and
    ends with one newline, so that the join is the only blank lines between parts; every
    Python file of bgc/runtime/ besides __init__.py is a part."""
    assert sorted(PY_RUNTIME) == sorted(p.name for p in RUNTIME.glob("*.py")
                                        if p.name != "__init__.py")
    bodies = []
    for name in PY_RUNTIME:
        text = (RUNTIME / name).read_text(encoding="utf-8")
        header, blank, body = text.partition("\n\n")
        lines = header.split("\n")
        assert blank and all(line.startswith("#") for line in lines), name
        assert lines[0].startswith(f"# bgc/runtime/{name} -- "), name
        twin = Path(name).with_suffix(".c").name
        assert twin in C_RUNTIME and f"C twin is {twin}" in " ".join(lines), name
        assert body == runtime_body(text), name
        assert body[:1] not in ("", "\n") and body.endswith("\n") and not body.endswith("\n\n")
        bodies.append(body)
    assert python_runtime() == "\n\n".join(bodies + [solver_tables_python()])
    with pytest.raises(ValueError):
        runtime_body("import math\n\nx = 1\n")  # no header
    assert pyruntime_place(1) == "bgc/runtime/runtime.py:%d" % (
        (RUNTIME / "runtime.py").read_text(encoding="utf-8").split("\n").index("") + 2)
    first = runtime_body((RUNTIME / "main.py").read_text(encoding="utf-8")).split("\n")[0]
    line = python_runtime().split("\n").index(first) + 1
    place = pyruntime_place(line)
    assert place.startswith("bgc/runtime/main.py:")
    assert (RUNTIME / "main.py").read_text(encoding="utf-8").split("\n")[
        int(place.split(":")[1]) - 1] == first


def test_family_contract_is_one_numbered_list_that_the_c_runtime_cites():
    """The method families' contract is written once, the numbered list of _Family's
    docstring; drive.c, erk.c and stiff.c point to it and cite only items it has."""
    rt = fresh_runtime()
    items = [int(n) for n in re.findall(r"^    (\d+)\. ", rt._Family.__doc__, re.M)]
    assert items == list(range(1, len(items) + 1)) and len(items) >= 8
    for name in ("drive.c", "erk.c", "stiff.c"):
        text = " ".join((RUNTIME / name).read_text(encoding="utf-8").split())
        assert "_Family (bgc/runtime/drive.py" in text, name
        cited = {int(n) for group in re.findall(r"\bitems? (\d+(?:(?:, | and )\d+)*)", text)
                 for n in re.findall(r"\d+", group)}
        assert cited and cited <= set(items), (name, cited - set(items))


def test_runtime_alone_is_a_model_of_no_states():
    """Imported alone, the runtime's neutral model runs: rows of t and no outputs."""
    rt = fresh_runtime()
    assert rt.PARAMETERS == {} and rt._BLOCK_TABLE == []
    t, Y = rt.simulate(t_end=1.0, dt=0.25)
    assert t.tolist() == [0.0, 0.25, 0.5, 0.75, 1.0] and Y.shape == (5, 0)
    for name in rt.__all__ + list(rt._MODEL_HELPERS) + list(rt._MODEL_NAMES):
        assert hasattr(rt, name), name


def _model_parts():
    """Each model's golden module (its other scenes differ in SCENE's values only)."""
    return sorted(GOLDEN.glob("*/default.py"))


def test_generated_model_parts_keep_the_contract():
    """Each golden model part defines every name the contract asks of it, and uses nothing of
    the runtime's beyond the contract's names and the helpers it lists (_MODEL_HELPERS)."""
    rt = fresh_runtime()
    allowed = set(rt._MODEL_NAMES) | set(rt._MODEL_HELPERS) | set(rt.__all__) | {
        "math", "numpy", "sys"}
    parts = list(_model_parts())
    assert parts
    for path in parts:
        text = path.read_text(encoding="utf-8")
        assert "[runtime: python]" in text, path
        undefined = {line.split("undefined name ")[1].strip("'")
                     for line in _flakes(text.replace("[runtime: python]", "pass"), str(path))
                     if "undefined name" in line}
        assert undefined <= allowed, (path, undefined - allowed)
        for name in rt._MODEL_NAMES:
            if name not in ("_METHODS", "SOLVERS", "_SOLVER_LIST"):  # the runtime golden's
                assert f"\n{name} = " in text or f"\ndef {name}(" in text, (path, name)


# ---------------------------------------------------------------- a model bound by hand


@pytest.mark.parametrize("solver", ["dopri5", "rodas4", "radau5"])
def test_decay_follows_exp(solver):
    """dx/dt = -x through simulate, an explicit and two stiff solvers (the stiff ones through
    the Jacobian's colouring of jvp)."""
    rt = decay(fresh_runtime())
    assert rt.PARAMETERS == {"k": 1.0}
    t, Y = rt.simulate(solver=solver)
    assert t.tolist() == [0.0, 0.5, 1.0, 1.5, 2.0]
    assert np.allclose(Y[:, 0], [math.exp(-v) for v in t], rtol=1e-7, atol=0.0)
    t, Y = rt.simulate(solver=solver, params={"k": 2.0}, t_end=1.0)
    assert abs(Y[-1, 0] - math.exp(-2.0)) < 1e-7


def test_integrate_on_a_fixed_grid():
    """_integrate directly: rk4 with --step 0.01 takes 100 steps to t = 1, within rk4's error."""
    rt = decay(fresh_runtime())
    s = rt._settings(t_end=1.0, dt=0.25, solver="rk4", step=0.01)
    p = rt._with_constants(rt._param_values({}))
    st = rt._new_stats()
    rows = list(rt._integrate(s, p, [1.0], st))
    assert [t for t, _ in rows] == [0.0, 0.25, 0.5, 0.75, 1.0]
    assert st["steps"] == 100 and st["rhs"] == 400
    for t, y in rows:
        assert abs(y[0] - math.exp(-t)) < 1e-9


def test_output_grid():
    """Rows at t0 + k dt below t_end and at t_end exactly; a grid point within 1e-6 dt of
    t_end is replaced by it."""
    rt = fresh_runtime()
    s = rt._settings(t_end=1.0, dt=0.3)
    n = rt._output_count(s)
    assert n == 4
    assert [rt._output_time(s, k, n) for k in range(n + 1)] == [0.0, 0.3, 0.6, 0.8999999999999999, 1.0]
    s = rt._settings(t_end=0.9 + 1e-9, dt=0.3)
    assert rt._output_count(s) == 3
    assert rt._output_time(s, 3, 3) == 0.9 + 1e-9


def test_substeps():
    rt = fresh_runtime()
    assert rt._substeps(1.0, 0.1) == 10  # 10.000000000000002 steps: not an 11th sliver
    assert rt._substeps(1.05, 0.1) == 11
    assert rt._substeps(0.05, 0.1) == 1
    assert rt._substeps(1e20, 1.0) == -1  # too many


def test_failures_name_the_state():
    """_Failure messages as the C program's, and a run that blows up (dx/dt = x^2 from 1, which
    ends at t = 1) raises SimulationError with the rows before it."""
    rt = decay(fresh_runtime())
    assert str(rt._fail(0.5, "state", "x")) == "at t = 0.5: state 'x' is not finite"
    failure = rt._fail_step(2.0, 1e-20, 0)
    assert isinstance(failure, rt._Failure) and failure.t == 2.0
    assert str(failure) == "at t = 2: step size too small (h = 1e-20), limited by state 'x'"

    def blow_up(t, x, p, w, out):
        out[0] = x[0] * x[0]

    bind(rt, _rhs=blow_up)
    with pytest.raises(rt.SimulationError) as error:
        rt.simulate(t_end=2.0, dt=0.25)
    assert str(error.value).startswith("at t = 0.99") and 0.99 < error.value.t < 1.0
    assert error.value.times.tolist() == [0.0, 0.25, 0.5, 0.75]


# ---------------------------------------------------------------- pieces


def test_seq_sum_is_c_order():
    """Left to right from 0.0, as C's loop: not compensated (math.fsum gives 1)."""
    rt = fresh_runtime()
    assert rt._seq_sum(np.array([1e16, 1.0, -1e16])) == 0.0
    assert rt._seq_sum(np.array([1.0, 1e16, -1e16])) == 0.0
    assert rt._seq_sum(np.array([])) == 0.0
    assert rt._seq_sum(np.array([0.1, 0.2, 0.3])) == (0.1 + 0.2) + 0.3


def test_lu_solves_and_detects_singular():
    rt = fresh_runtime()
    A = np.array([[0.0, 2.0, 1.0], [1.0, 1.0, 0.0], [3.0, 0.0, 1.0]])
    b = np.array([1.0, 2.0, 3.0])
    lu = A.copy()
    piv = rt._lu(lu)
    assert piv is not None and piv[0] == 2  # the largest of column 0
    x = rt._lu_solve(lu, piv, b)
    assert np.allclose(A @ x, b, rtol=0.0, atol=1e-14)
    assert rt._lu(np.array([[1.0, 2.0], [2.0, 4.0]])) is None
    assert rt._lu(np.zeros((1, 1))) is None


def test_libm_wrappers_give_c_values():
    """_c_*: math's value as numpy.float64, and C's inf or nan where math raises."""
    rt = fresh_runtime()
    assert rt._c_exp(1.0) == math.exp(1.0) and isinstance(rt._c_exp(1.0), np.float64)
    assert rt._c_exp(1000.0) == math.inf and rt._c_exp(-1000.0) == 0.0
    assert rt._c_log(0.0) == -math.inf and math.isnan(rt._c_log(-1.0))
    assert math.isnan(rt._c_sqrt(-1.0)) and math.isnan(rt._c_asin(2.0))
    assert rt._c_atanh(1.0) == math.inf and rt._c_atanh(-1.0) == -math.inf
    assert rt._c_sinh(1000.0) == math.inf and rt._c_sinh(-1000.0) == -math.inf
    assert rt._c_cosh(-1000.0) == math.inf
    assert rt._sq(3.0) == 9.0
