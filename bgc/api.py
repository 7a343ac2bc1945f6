"""The pipeline as functions: load -> parse -> resolve -> scene -> causality -> equations ->
reduce -> code model -> emit.  `bgc.cli` and the tests use exactly these."""
from __future__ import annotations

import io
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from . import ast
from .causality import Causality, assign_causality
from .codemodel import CodeModel, lower
from .diagnostics import ModelError, format_diagnostic
from .equations import build_equations
from .parser import decode, parse
from .reduce import Reduced, reduce
from .resolve import Graph, resolve
from .scene import Settings, apply_scene


@dataclass(frozen=True)
class Source:
    path: str
    text: str


@dataclass(frozen=True)
class Compiled:
    source: Source
    graph: Graph  # with the scene's effects applied
    settings: Settings
    causality: Causality
    reduced: Reduced
    code: CodeModel

    @property
    def warnings(self):
        return tuple(self.graph.warnings) + tuple(self.reduced.warnings)


class BgcModelError(Exception):
    """A model error with its diagnostics formatted against the source (`str()` is the report)."""

    def __init__(self, error: ModelError, source: Source):
        self.diagnostics = error.diagnostics
        self.source = source
        super().__init__("\n".join(format_diagnostic(d, source.path, source.text)
                                   for d in error.diagnostics))


def load(path, text: str | None = None) -> Source:
    """Read a model file (UTF-8, size-limited); `text` gives the source directly."""
    path = str(path)
    if text is None:
        try:
            data = Path(path).read_bytes()
        except OSError as exc:
            raise FileNotFoundError(f"{path}: cannot read: {exc.strerror}") from None
        try:
            text = decode(data)
        except ModelError as exc:
            raise BgcModelError(exc, Source(path, data.decode("utf-8", "replace"))) from None
    return Source(path, text)


def _source(model) -> Source:
    return model if isinstance(model, Source) else load(model)


def parse_model(model) -> ast.Model:
    src = _source(model)
    try:
        return parse(src.text, src.path)
    except ModelError as exc:
        raise BgcModelError(exc, src) from None


def build(model, scene: str | None = None, project_initial: bool = False) -> Compiled:
    """Run the pipeline up to the code model."""
    src = _source(model)
    try:
        graph = resolve(parse(src.text, src.path))
        graph, settings = apply_scene(graph, scene)
        causality = assign_causality(graph)
        system = build_equations(graph, causality, settings)
        reduced = reduce(system, project_initial=project_initial)
        code = lower(reduced)
    except ModelError as exc:
        raise BgcModelError(exc, src) from None
    return Compiled(src, graph, settings, causality, reduced, code)


def check(model, scene: str | None = None) -> str:
    from .report import check_report

    return check_report(build(model, scene))


def equations(model, scene: str | None = None, format: str = "text") -> str:
    from .report import equations_latex, equations_text

    compiled = build(model, scene)
    return equations_latex(compiled) if format == "latex" else equations_text(compiled)


def compile(model, target: str = "c", scene: str | None = None,
            project_initial: bool = False) -> dict[str, str]:
    """Standalone source code: {filename: text}."""
    from .emit import emit_c, emit_python

    code = build(model, scene, project_initial).code
    return emit_c(code) if target == "c" else emit_python(code)


def run_args(t_end=None, dt=None, solver=None, rtol=None, atol=None, step=None, params=None,
             project_initial=False) -> list[str]:
    """The generated program's command line for these settings."""
    args = []
    for flag, value in (("--t-end", t_end), ("--dt", dt), ("--solver", solver),
                        ("--rtol", rtol), ("--atol", atol), ("--step", step)):
        if value is not None:
            args += [flag, repr(value) if isinstance(value, float) else str(value)]
    for name, value in (params or {}).items():
        args += ["-p", f"{name}={float(value)!r}"]
    if project_initial:
        args.append("--project-initial")
    return args


def simulate(model, scene: str | None = None, backend: str = "c", **options):
    """Simulate; returns (t, Y, names).  options: t_end, dt, solver, rtol, atol, step, params,
    project_initial.  backend "c" falls back to "python" when there is no C compiler."""
    from . import backends

    compiled = build(model, scene, options.get("project_initial", False))
    if backend == "c" and not backends.have_c_compiler():
        backend = "python"
    if backend == "python":
        return _simulate_python(compiled, options)
    from .emit import emit_c

    (text,) = emit_c(compiled.code).values()
    exe = backends.compile_c(text)
    code, out, err = backends.run_c(exe, run_args(**options))
    if code != 0:
        raise SimulationFailed(err.strip(), out)
    return _parse_csv(out)


class SimulationFailed(RuntimeError):
    """The generated program stopped with an error; `partial_csv` holds the rows written."""

    def __init__(self, message: str, partial_csv: str = ""):
        super().__init__(message)
        self.partial_csv = partial_csv


def _simulate_python(compiled, options):
    from . import backends
    from .emit import emit_python

    (text,) = emit_python(compiled.code).values()
    module = backends.load_python_module(text)
    opts = dict(options)
    t, Y = module.simulate(**opts)
    return np.asarray(t), np.asarray(Y), list(module.OUTPUTS)


def _parse_csv(text: str):
    lines = text.splitlines()
    names = lines[0].split(",")[1:]
    data = np.loadtxt(io.StringIO("\n".join(lines[1:])), delimiter=",", ndmin=2)
    return data[:, 0], data[:, 1:], names
