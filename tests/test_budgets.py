"""Runs that go wrong stop with a message, the same in both backends: a step size that runs
away spends the step budget (--max-steps, steps between two output times), a parameter that
leaves the model undefined is named as such, an overflowing right side ends in a step-size
failure; and the budget counts exactly (a fixed-step run needs a known number of steps)."""
import functools

import pytest

from bgc.base import cache, processes, toolchain
from bgc.api import Source, build
from bgc.codegen.emit import emit_c, emit_python
from conftest import MODELS

BACKENDS = ["python"] + (["c"] if toolchain.have_c_compiler() else [])


@functools.lru_cache(maxsize=None)
def _program(model, scene, backend):
    (text,) = (emit_c if backend == "c" else emit_python)(build(model, scene).program).values()
    return text


def _run(model, scene, backend, *args):
    """(exit status, stdout, the last line of stderr) of the generated program."""
    text = _program(model, scene, backend)
    if backend == "c":
        code, out, err = processes.run_c(cache.compile_c(text), args)
    else:
        code, out, err = processes.run_python(text, args)
    return code, out, (err.strip().splitlines() or [""])[-1]


def _both(model, scene, *args):
    results = [_run(model, scene, b, *args) for b in BACKENDS]
    assert all(r == results[0] for r in results), results  # the same rows and message
    return results[0]


def test_a_runaway_step_size_spends_the_budget_and_says_so():
    """gamma = 1e308 on the knife edge's corrector: the steps shrink towards nothing."""
    code, out, last = _both(MODELS / "knife_edge.bg", None, "-p", "gamma=1e308",
                            "--max-steps", "2000")
    assert code == 3
    assert "step budget spent: 2000 steps since the output at t = 0" in last
    assert out.count("\n") == 2  # the header and the row at t = 0, kept


def test_a_parameter_that_leaves_the_model_undefined_is_named():
    code, out, last = _both(MODELS / "pendulum.bg", "swing", "-p", "m=0")
    assert code == 1 and out == ""
    assert last == ("error: at t = 0: the velocity residual of constraint 'rod' is not finite: "
                    "the model is undefined at the initial state with these parameters (a zero "
                    "mass, say)")


def test_an_overflowing_right_side_is_a_step_size_failure():
    code, out, last = _both(MODELS / "rlc.bg", "step", "-p", "V0=1e308")
    assert code == 3 and last == "error: at t = 0: step size too small (h = 0)"


STEPS = Source("steps.bg", "model steps\nsignal z = integral(-z, init = 1)\n"
                           "scene s { outputs z; time 0 .. 3 every 1; solver rk4(step = 0.001) }\n")


@pytest.mark.parametrize("budget, code", [("999", 3), ("1000", 0), ("0", 0)])
def test_the_budget_counts_the_steps_between_outputs(budget, code):
    """rk4 at h = 0.001 takes exactly 1000 steps from one output (every 1 s) to the next."""
    got, out, last = _both(STEPS, "s", "--max-steps", budget)
    assert got == code
    if code:
        assert "step budget spent: 999 steps since the output at t = 0" in last
        assert out.count("\n") == 2


@pytest.mark.parametrize("value", ["-1", "1.5", "x"])
def test_a_bad_budget_is_a_usage_error(value):
    code, _, last = _both(STEPS, "s", "--max-steps", value)
    assert code == 2 and "--max-steps" in last
