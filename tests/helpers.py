"""What several test files share, imported as a module (`from helpers import ...`), never
loaded by path: the scalable model families of benchmarks/families.py (which the benchmarks
run too), and one build of a model for every test of a process that reads it."""
from __future__ import annotations

import functools
import importlib.util
import sys
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
