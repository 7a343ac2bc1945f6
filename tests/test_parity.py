"""Byte parity: the Python module writes the C program's CSV bytes, for every solver, adaptive
and with fixed steps, on explicit and stiff models of 1 to 256 states (the lists and the numpy
vectors of the explicit solvers, real and complex LU factorisations of every size), a model
with exp in its right side; and the stats line's counters agree.  The C program is the
reference: the Python runtime performs its floating-point operations in its order, so no
tolerance is needed, whatever BLAS or SIMD kernels numpy picks on the machine (see
docs/solvers.md).  Spans are short: a few steps of the large models are enough to go through
every code path, the whole file takes some twenty seconds."""
import contextlib
import io
import subprocess
from pathlib import Path

import pytest

import bgc
from bgc.base import cache, processes, solvers, toolchain
from bgc.api import Source
from bgc.codegen.emit import emit_c, emit_python

from cbits import C_IO
from helpers import families

ROOT = Path(__file__).resolve().parent.parent
pytestmark = pytest.mark.skipif(not toolchain.have_c_compiler(), reason="no C compiler")


def _source(name):
    if name.endswith(".bg"):
        return ROOT / "models" / name
    family, n = name.rsplit("_", 1)
    return Source(f"{name}.bg", getattr(families, family)(int(n)))


# model -> (states, adaptive run's options, fixed-step run's options)
MODELS = {
    "pendulum.bg": (4, ["--t-end", "0.5"], ["--t-end", "0.05", "--step", "0.001"]),
    "diode.bg": (1, ["--t-end", "0.5"], ["--t-end", "0.05", "--step", "0.001"]),
    "van_der_pol.bg": (2, ["--t-end", "0.002", "--dt", "0.0005"],
                       ["--t-end", "0.002", "--dt", "0.001", "--step", "0.0002"]),
    "rc_ladder_26": (26, ["--t-end", "0.05", "--dt", "0.01"],
                     ["--t-end", "0.005", "--dt", "0.0025", "--step", "0.0005"]),
    "pendulum_chain_16": (64, ["--t-end", "0.01", "--dt", "0.005"],
                          ["--t-end", "0.002", "--dt", "0.001", "--step", "0.0005"]),
    "rc_ladder_256": (256, ["--t-end", "0.0002", "--dt", "0.0001"],
                      ["--t-end", "0.0001", "--dt", "0.0001", "--step", "0.00005"]),
}


@pytest.fixture(scope="module", params=sorted(MODELS))
def programs(request):
    """(the C program, the loaded Python module) of a model: each compiled once."""
    compiled = bgc.build(_source(request.param))
    assert len(compiled.program.states) == MODELS[request.param][0]
    (c_text,) = emit_c(compiled.program).values()
    (py_text,) = emit_python(compiled.program).values()
    return request.param, cache.compile_c(c_text), processes.load_python_module(py_text)


def _c(exe, argv):
    done = subprocess.run([str(exe), *argv], capture_output=True)
    return done.returncode, done.stdout, done.stderr.decode()


def _python(module, argv):
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = module.main(argv)
    return code, out.getvalue().encode(), err.getvalue()


def _without_cpu(stderr):
    """The stats line's counters (steps, rejected, rhs, jac, lu, solves, stiff_from): all but
    the processor time; and every other line as it is."""
    return [" ".join(w for w in line.split() if not w.startswith("cpu=")) for line in
            stderr.splitlines()]


def _runs(name):
    _, adaptive, fixed = MODELS[name]
    for solver in solvers.NAMES:
        if solvers.SOLVERS[solver].family != "fixed":
            yield solver, ["--solver", solver, *adaptive]
        yield f"{solver} --step", ["--solver", solver, *fixed]


def test_python_writes_the_c_programs_bytes(programs):
    name, exe, module = programs
    differ = []
    for label, argv in _runs(name):
        argv = [*argv, "--stats"]
        c_code, c_out, c_err = _c(exe, argv)
        p_code, p_out, p_err = _python(module, argv)
        assert c_out.count(b"\n") >= 2 or c_code != 0, (label, c_err)
        if (c_code, c_out, _without_cpu(c_err)) != (p_code, p_out, _without_cpu(p_err)):
            differ.append((label, c_code, p_code, c_err.strip()[-200:], p_err.strip()[-200:]))
    assert not differ, (name, differ)


LIBM = r"""
#include <math.h>
""" + C_IO + r"""
int main(void)
{
    int n;
    while (scanf("%d", &n) == 1) {
        const double x = rd(), y = rd();
        double (*const f1[])(double) = {exp, log, sqrt, sin, cos, tan, asin, acos, atan,
                                        sinh, cosh, tanh, asinh, atanh};
        wr(n < 14 ? f1[n](x) : n == 14 ? pow(x, y) : atan2(x, y));
        printf("\n");
    }
    return 0;
}
"""
LIBM_NAMES = ["exp", "log", "sqrt", "sin", "cos", "tan", "asin", "acos", "atan", "sinh", "cosh",
              "tanh", "asinh", "atanh", "pow", "atan2"]


def test_model_functions_are_the_c_programs(tmp_path):
    """The model code's fallback functions (_c_exp, ...: libm through math, C's inf and nan
    where math raises) against the C program's libm calls, bit for bit (any NaN as one), at
    the special arguments and at random ones, and the fast variant's math functions too."""
    import math
    import random

    import numpy as np
    (tmp_path / "libm.c").write_text(LIBM)
    subprocess.run(["cc", "-O2", "-std=c99", str(tmp_path / "libm.c"), "-o",
                    str(tmp_path / "libm"), "-lm"], check=True)
    (py,) = emit_python(bgc.build(ROOT / "models" / "diode.bg").program).values()
    module = processes.load_python_module(py)
    rng = random.Random(5)
    special = [0.0, -0.0, 1.0, -1.0, 0.5, -0.5, 2.0, -3.0, 1e-310, 710.0, -746.0, 1e308,
               -1e308, math.inf, -math.inf, math.nan, 3.0, 0.1, 800.0, -800.0]
    cases = [(k, x, y) for k in range(len(LIBM_NAMES)) for x in special
             for y in (special if k >= 14 else [0.0])]
    cases += [(k, rng.uniform(-20, 20), rng.uniform(-5, 5)) for k in range(len(LIBM_NAMES))
              for _ in range(300)]

    def bits(v):
        return "nan" if v != v else "%x" % np.float64(v).view(np.uint64)

    lines = ["%d %x %x" % (k, np.float64(x).view(np.uint64), np.float64(y).view(np.uint64))
             for k, x, y in cases]
    done = subprocess.run([str(tmp_path / "libm")], input="\n".join(lines) + "\n",
                          capture_output=True, text=True, check=True)
    for (k, x, y), word in zip(cases, done.stdout.split()):
        want = np.uint64(int(word, 16)).view(np.float64)
        f = getattr(module, "_c_" + LIBM_NAMES[k])
        args = (x, y) if k >= 14 else (x,)
        got = f(*args)
        assert isinstance(got, np.float64)
        assert bits(got) == bits(want), (LIBM_NAMES[k], args, got, want)
        try:  # the fast variant: math's function where it does not raise
            fast = getattr(math, LIBM_NAMES[k])(*args)
        except (ValueError, OverflowError):
            continue
        assert bits(fast) == bits(want), (LIBM_NAMES[k], args)
