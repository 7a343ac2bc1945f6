"""A run builds only what its solver calls: `bgc simulate` with an explicit solver compiles a
program without jvp (the Jacobian the implicit solvers need); such a program refuses an
implicit solver instead of running without it, and a later implicit run builds it again, with
it.  The right side and the outputs do not change: the same stores in the same order."""
import json
import textwrap

import pytest

import subprocess

from conftest import have_cc, run_bgc

from bgc import api
from bgc.base import cache
from bgc.codegen import emit, vm
from bgc.codegen.emit import EmitError

needs_cc = pytest.mark.skipif(not have_cc(), reason="no C compiler")

# A driven, damped oscillator: what matters here is which functions its programs hold.
OSC = textwrap.dedent("""\
    model osc
    parameter k = 4.0
    parameter b = 0.4
    src : Se(1.0)
    m : I(1.0) init p = 0.0
    s : C(1 / k) init q = 0.0
    d : R(b)
    j : 1
    src -> j
    j -> m
    j -> s
    j -> d
    scene run {
      outputs m.p, s.q
      time 0 .. 2 every 0.25
      solver dopri5(rtol = 1e-9, atol = 1e-12)
    }
    """)


def _build(jacobian):
    return api.build(api.Source("osc.bg", OSC), "run", jacobian=jacobian)


def test_a_program_for_an_explicit_solver_has_no_jacobian_and_the_same_right_side():
    lean, full = _build(None).program, _build(True).program
    assert not lean.has_jacobian and full.has_jacobian
    assert "jvp" not in lean.functions and lean.jacobian.lu is None
    assert not lean.jacobian.colors and not any(lean.jacobian.columns)
    for name in full.functions:  # (the tangent is derived and dropped: the same numbering)
        assert name == "jvp" or lean.function(name) == full.function(name)
    (part,) = emit.emit_c(lean, linked=True).values()
    assert "#define BGC_HAS_JACOBIAN 0" in part
    with pytest.raises(EmitError, match="Jacobian"):
        emit.emit_python(lean)


@needs_cc
def test_a_program_without_its_jacobian_refuses_an_implicit_solver(tmp_path, monkeypatch):
    monkeypatch.setenv("BGC_CACHE_DIR", str(tmp_path / "cache"))
    (text,) = emit.emit_c(_build(False).program).values()
    exe = cache.compile_c(text)
    ok = subprocess.run([str(exe)], capture_output=True, text=True)
    assert ok.returncode == 0, ok.stderr
    for solver in ("radau5", "rodas5p", "auto"):
        bad = subprocess.run([str(exe), "--solver", solver], capture_output=True, text=True)
        assert bad.returncode == 2 and bad.stdout == ""
        assert "built without the Jacobian" in bad.stderr
    program = tmp_path / "osc.bgvm"
    program.write_bytes(vm.program_bytes(_build(False).program))
    bad = subprocess.run([str(vm.interpreter()), str(program), "--solver", "radau5"],
                         capture_output=True, text=True)
    assert bad.returncode == 2 and "built without the Jacobian" in bad.stderr


@needs_cc
@pytest.mark.parametrize("backend", ["c", "vm"])
def test_simulate_builds_the_jacobian_only_for_a_solver_that_calls_it(tmp_path, monkeypatch,
                                                                      backend):
    cache = tmp_path / "cache"
    monkeypatch.setenv("BGC_CACHE_DIR", str(cache))
    model = tmp_path / "osc.bg"
    model.write_text(OSC)

    def record():
        (path,) = cache.glob("warm-*.json")
        return json.loads(path.read_text())

    def python(*extra):  # the full program, in the Python backend: the reference bytes
        out = run_bgc("simulate", model, "--backend", "python", *extra,
                      env={"BGC_CACHE_DIR": str(tmp_path / "python-cache")})
        assert out.returncode == 0, out.stderr
        return out.stdout

    explicit = run_bgc("simulate", model, "--backend", backend)
    assert explicit.returncode == 0, explicit.stderr
    assert record()["jacobian"] is False
    assert explicit.stdout == python()
    implicit = run_bgc("simulate", model, "--backend", backend, "--solver", "radau5")
    assert implicit.returncode == 0, implicit.stderr  # (built again, with it)
    assert record()["jacobian"] is True
    assert implicit.stdout == python("--solver", "radau5")
    again = run_bgc("simulate", model, "--backend", backend)  # (the full program serves it)
    assert again.stdout == explicit.stdout and record()["jacobian"] is True
