"""What several test files share, imported as a module (`from helpers import ...`), never
loaded by path: the scalable model families of benchmarks/families.py (which the benchmarks
run too), one build of a model for every test of a process that reads it, and the small models
several files test (ball: a bouncing ball by a when-block), and the Python runtime as one module
(pyruntime)."""
from __future__ import annotations

import functools
import importlib.util
import itertools
import linecache
import sys
import types
from pathlib import Path

import bgc
from bgc.api import Source

ROOT = Path(__file__).resolve().parent.parent


def _families():
    """benchmarks/families.py, executed once per process (the benchmarks, scripts run from
    their own directory, import it as `families`)."""
    name = "bgc_benchmark_families"
    if name not in sys.modules:
        spec = importlib.util.spec_from_file_location(name, ROOT / "benchmarks" / "families.py")
        module = importlib.util.module_from_spec(spec)
        sys.modules[name] = module
        spec.loader.exec_module(module)
    return sys.modules[name]


families = _families()


def built(model, scene: str | None = None, **options):
    """bgc.build(model, scene, **options) once per process, for every test file that reads
    the same build (a build is a value: frozen stages; its runs take their settings apart).
    model is a file's path (str or Path; the same file either way) or a bgc.api.Source."""
    key = model if isinstance(model, Source) else str(model)
    return _built(key, scene, tuple(sorted(options.items())))


@functools.lru_cache(maxsize=None)
def _built(model, scene, options):
    return bgc.build(model, scene, **dict(options))


def built_text(name: str, text: str, scene: str | None = None, **options):
    """built() of a model's text, under the file name its messages give."""
    return built(Source(name, text), scene, **options)


def simulated(model, scene: str | None = None, backend: str = "python", **options):
    """(t, Y, names) of a run of built(model, scene), as bgc.simulate runs it (its settings
    from the scene and options: t_end, dt, solver, params...), without building again: for
    tests of what a model computes, not of bgc.simulate itself (tests/test_simulate.py)."""
    from bgc.api import arrays
    from bgc.execute.runner import prepare, run, settings_for

    compiled = built(model, scene)
    settings = settings_for(compiled.program.scene, [p.name for p in compiled.program.params],
                            **options)
    ran = prepare(compiled, backend, in_process=True)
    return (*arrays(run(ran, settings)), list(ran.outputs))


def ball(scene: str = "scene drop { time 0 .. 3 every 0.01; outputs x, b.p }") -> str:
    """A ball dropped on a floor, bouncing by a when-block's reinit (x its height), with
    the scene given."""
    return f"""model ball "a ball dropped on a floor, bouncing by a when-block"
parameter m = 1.0
parameter g = 9.81
parameter e = 0.8
parameter h0 = 1.0
w : Se(-m*g)
b : I(m)
signal x = integral(b.f, init = h0)
w -> j
j : 1
j -> b
when x < 0 {{
  reinit b.p = -e*b.p
}}
{scene}
"""


def pwm_rl(scene: str) -> str:
    """An RL load driven by a PWM voltage (a square wave's edges its time events), with the
    scene given."""
    return f"""model pwm "an RL load driven by a PWM voltage"
parameter V = 12.0
parameter R = 2.0
parameter L = 0.01
parameter period = 0.001
parameter duty = 0.3
u : MSe(V*square(period, duty))
r : R(R)
l : I(L)
u -> j
j : 1
j -> r
j -> l
{scene}
"""


# ---------------------------------------------------------------- the Python runtime

RUNTIME_NAME = "<bgc python runtime>"  # the file name its tracebacks and compile give
_RUNTIMES = itertools.count()


def pyruntime() -> types.ModuleType:
    """The Python runtime as a generated module starts (bgc.codegen.emit.python_runtime: its
    parts joined, then the solver tables), executed as a new module at each call (binding a
    model changes its globals).  Never loaded by path: a part alone is no module."""
    from bgc.codegen.emit import python_runtime

    text = python_runtime()
    linecache.cache[RUNTIME_NAME] = (len(text), None, text.splitlines(True), RUNTIME_NAME)
    module = types.ModuleType(f"_bgc_pyruntime_{next(_RUNTIMES)}")
    exec(compile(text, RUNTIME_NAME, "exec"), vars(module))
    return module


def pyruntime_place(line: int) -> str:
    """Where line `line` (from 1) of python_runtime()'s text is written: 'bgc/runtime/PART:LINE',
    or 'solver tables:LINE' past the parts."""
    from bgc.codegen.emit import PY_RUNTIME, runtime_body, solver_tables_python

    start = 1  # the text's line where the part's body begins
    for name in PY_RUNTIME:
        text = (ROOT / "bgc" / "runtime" / name).read_text(encoding="utf-8")
        body = runtime_body(text)
        count = body.count("\n")
        if line < start + count:
            return f"bgc/runtime/{name}:{line - start + text.count(chr(10)) - count + 1}"
        start += count + 2  # and the two blank lines that join the parts
    assert solver_tables_python()
    return f"solver tables:{line - start + 1}"
