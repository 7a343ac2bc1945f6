"""The pipeline as functions: parse -> resolve -> flatten -> units -> scene -> causality -> equations
(bgc.middle.system) -> reduce -> lower -> emit, and runs of the result (bgc.execute.runner's run,
the one way bgc runs a program).  `bgc.cli`, bgc.model and the tests use exactly these.  bgc.load,
the notebook's entry, is bgc.model's (it returns a Model, which is built with this module)."""
from __future__ import annotations

import io
import time
from dataclasses import dataclass, replace

from .middle.causality import CausalGraph, assign_causality
from .base.diagnostics import ModelError, Note, format_diagnostic
from .codegen.emit import emit_c, emit_python
from .front.flatten import flatten
from .middle.system import EquationSystem, build_equations, with_residual_outputs
from .front.graph import Graph
from .ir import Program
from .front.instantiate import front, instantiate  # noqa: F401 (front: the API's too)
from .codegen.lower import lower
from .front.parser import decode, parse, parse_option
from .middle.reduce import Reduced, reduce
from .reports.report import (SceneSummary, check_report, scenes_report, equations_latex,
                             equations_text, scene_summary)
from .front.resolve import resolve
from .front.units import check_units
from .base import solvers
from .base.resources import compile_scope, quiet_collector, read_bounded
from .middle.scene import Override, Settings, apply_scene, check_parameters as check_parameters_of
from .base.run_settings import (ALGEBRA, BACKENDS, FORMATS, SIMULATE_OPTIONS, SWEEP_BACKENDS,
                                TARGETS, check_run_options, choice as _choice, exclusive,
                                input_data)
from .base.run_settings import RunSettings, run_args  # noqa: F401  (the API's)
# the one run function and its helpers (bgc.execute.runner), as the API offers them
from .execute.runner import Result, choose_backend, prepare, run, settings_for


@dataclass(frozen=True)
class Source:
    path: str
    text: str
    consts: tuple = ()  # ((name, value), ...): values for the model's constants (--const)


@dataclass(frozen=True)
class Compiled:
    """Every stage's value, for reports and tests (each stage took only the one before)."""

    source: Source
    causal: CausalGraph  # the scene's graph, its settings, the causal strokes
    system: EquationSystem
    reduced: Reduced
    program: Program | None  # None when built for a report only
    timings: tuple[tuple[str, float], ...] = ()  # (stage, seconds), for benchmarks
    files: tuple[tuple[str, str], ...] = ()  # what the model read besides itself: ("library",
    #   path) of each library file, ("table", path) of each table's CSV file, as opened

    @property
    def graph(self) -> Graph:  # with the scene's effects applied
        return self.causal.graph

    @property
    def settings(self) -> Settings:
        return self.causal.settings

    @property
    def warnings(self):
        return tuple(self.reduced.warnings)


class BgcModelError(Exception):
    """A model error with its diagnostics formatted against the source (`str()` is the report)."""

    def __init__(self, error: ModelError, source: Source):
        self.diagnostics = error.diagnostics
        self.source = source
        super().__init__("\n".join(format_diagnostic(d, source.path, source.text)
                                   for d in error.diagnostics))


class BgcArgumentError(BgcModelError, ValueError):
    """An argument that the model refuses (a scene it does not have, outputs or effects it
    does not know), reported in the argument's own text; the command line exits 2 for it."""


def _model_error(exc: ModelError, source: Source) -> BgcModelError:
    """BgcArgumentError when every error is located in an argument, else BgcModelError."""
    outside = all(d.span is not None and d.span.origin is not None and not d.span.origin.file
                  for d in exc.diagnostics)
    return (BgcArgumentError if outside else BgcModelError)(exc, source)


def read_source(path, text: str | None = None) -> Source:
    """Read a model file (UTF-8, size-limited); `text` gives the source directly."""
    path = str(path)
    if text is None:
        try:
            data = read_bounded(path)
        except OSError as exc:
            raise FileNotFoundError(f"{path}: cannot read: {exc.strerror}") from None
        return source_from_bytes(path, data)
    return Source(path, text)


def source_from_bytes(path: str, data: bytes) -> Source:
    """A model file's bytes as a Source (BgcModelError if they are not a model's text)."""
    try:
        return Source(path, decode(data))
    except ModelError as exc:
        raise BgcModelError(exc, Source(path, data.decode("utf-8", "replace"))) from None


def _source(model) -> Source:
    if isinstance(model, Source):
        return Source(model.path, model.text, tuple(getattr(model, "consts", ())))
    return read_source(model)


def _option_text(value, what: str) -> str:
    if isinstance(value, str):
        return value
    try:
        items = list(value)
    except TypeError:
        raise TypeError(f"{what} must be a string or a list of strings") from None
    if not all(isinstance(v, str) for v in items):
        raise TypeError(f"{what} must be a string or a list of strings")
    return ", ".join(items) if items else ("none" if what == "effects" else "")


def scene_override(outputs=None, effects=None, names=("outputs=", "effects=")) -> Override | None:
    """An ad-hoc scene: outputs ("x, rod.lambda" or ["x", "rod.lambda"]) and effects ("gravity",
    ["gravity"], "none" or []), parsed by the model grammar; names: how errors call them."""
    if outputs is None and effects is None:
        return None
    outs = effs = None
    if outputs is not None:
        outs = parse_option("outputs", _option_text(outputs, "outputs"), names[0])
    if effects is not None:
        effs = parse_option("effects", _option_text(effects, "effects"), names[1])
    return Override(outs, effs)


@quiet_collector()
@compile_scope()
def build(model, scene: str | None = None, project_initial: bool = False,
          algebra: str = "auto", program: bool = True,
          residual_outputs: bool = False, outputs=None, effects=None,
          option_names=("outputs=", "effects=", "scene="),
          allow_inconsistent: bool = False, jacobian: bool | None = True) -> Compiled:
    """Run the pipeline up to the program IR (program=False: up to the reduce stage, all that
    `check` and `equations` need; Compiled.program is then None).  residual_outputs: every
    constraint's residual `J.residual` is an output too (after the scene's), for reports on
    the drift.  outputs, effects: an ad-hoc scene, replacing the scene's (see
    scene_override); option_names: how errors name outputs, effects and scene (the CLI's
    `--outputs`).  project_initial, allow_inconsistent: initial values that violate a
    constraint are not refused here (the program projects them, or starts from them).
    jacobian: whether the program has jvp, the Jacobian the implicit solvers need (None: as
    the scene's solver needs; a program without it runs the explicit solvers only, in C or
    the interpreter: what `bgc simulate` builds for such a run).  Raises BgcModelError, or BgcArgumentError for a scene, outputs or effects that the model
    refuses; ValueError or TypeError for an argument wrong in itself."""
    _choice("algebra", algebra, ALGEBRA)
    exclusive(project_initial, allow_inconsistent)
    if scene is not None and not isinstance(scene, str):
        raise TypeError(f"scene must be a string or None, not {type(scene).__name__}")
    src = _source(model)
    clock = _Clock()
    try:
        override = scene_override(outputs, effects, option_names[:2])
        ast_ = clock("parse", parse, src.text, src.path)
        ast_ = clock("instantiate", instantiate, ast_, dict(src.consts))
        graph = clock("resolve", resolve, ast_)
        files = tuple(("library", p) for p, sha in ast_.libraries if sha is not None) + tuple(
            ("table", t.file) for t in graph.tables if t.file)
        graph = clock("flatten", flatten, graph)
        graph = clock("units", check_units, graph)
        scenario = clock("scene", apply_scene, graph, scene, override, option_names[2])
        causal = clock("causality", assign_causality, scenario)
        system = clock("equations", build_equations, causal)
        if residual_outputs:
            system = with_residual_outputs(system)
        reduced = clock("reduce", reduce, system, project_initial or allow_inconsistent,
                        algebra)
        if jacobian is None:
            jacobian = solvers.get(reduced.run.solver).uses_jacobian
        ir_program = clock("lower", lower, reduced, (), (), False, jacobian) if program \
            else None
    except ModelError as exc:
        raise _model_error(exc, src) from None
    return Compiled(src, causal, system, reduced, ir_program, tuple(clock.times), files)


def check_parameters(model, scene: str | None, params: dict, outputs=None, effects=None,
                     option_names=("outputs=", "effects=")) -> None:
    """Parameter values of a run (name -> float: `bgc simulate -p`) against the model: a
    parameter computed from them, or a law or initial value of parameters only, that becomes
    complex or not finite is a BgcModelError located where the model computes it, with a note
    naming the values given (the run would otherwise start from NaN)."""
    if not params:
        return
    src = _source(model)
    try:
        graph = flatten(resolve(front(src)))
        check_parameters_of(graph, scene, scene_override(outputs, effects, option_names),
                            {name: float(v) for name, v in params.items()})
    except ModelError as exc:
        shown = ", ".join(f"{k}={v:.17g}" for k, v in params.items())
        raise BgcModelError(ModelError([replace(d, notes=d.notes + (
            Note(None, f"with the parameter values given for the run: {shown}"),))
            for d in exc.diagnostics]), src) from None


def check_scenes(compiled: Compiled):
    """Build every scene of compiled's model (to the reduce stage, with its algebra; the text
    parsed once more, not once per scene), so that `bgc check` without a scene answers for all
    of them: BgcModelError with the errors of each scene that fails, a note naming the scene
    unless the error is in it.  compiled is a build of the model's text that succeeded."""
    src = compiled.source
    graph = flatten(resolve(front(src)))
    diagnostics = []
    for sc in graph.scenes:
        try:
            causal = assign_causality(apply_scene(graph, sc.name))
            reduce(build_equations(causal), False, compiled.reduced.algebra)
        except ModelError as exc:
            for d in exc.diagnostics:
                inside = d.span is not None and not d.span.chain and d.span.origin is None \
                    and sc.span.line <= d.span.line <= sc.span.end_line
                diagnostics.append(d if inside else replace(
                    d, notes=d.notes + (Note(sc.span, f"in scene '{sc.name}'"),)))
    if diagnostics:
        raise BgcModelError(ModelError(diagnostics), src)


class _Clock:
    """Runs the stages, noting how long each took."""

    def __init__(self):
        self.times: list[tuple[str, float]] = []

    def __call__(self, name, stage, *args):
        start = time.perf_counter()
        value = stage(*args)
        self.times.append((name, time.perf_counter() - start))
        return value


def summary(compiled: Compiled) -> SceneSummary | None:
    """What compiled's scene saves against the full model (its default scene, built with the
    same algebra), or None when the full model does not compile (effects that exclude each
    other, say)."""
    if compiled.program is None:
        raise ValueError("summary() needs a build with its program (program=True)")
    try:
        full = build(compiled.source, None, algebra=compiled.reduced.algebra)
    except BgcModelError:
        return None
    return scene_summary(compiled, full)


def check(model, scene: str | None = None, algebra: str = "auto", outputs=None,
          effects=None) -> str:
    """`bgc check`: with a scene (or outputs, effects) it also compares with the full model;
    without, it checks every scene of the model too (check_scenes)."""
    adhoc = scene is not None or outputs is not None or effects is not None
    compiled = build(model, scene, algebra=algebra, program=adhoc, outputs=outputs,
                     effects=effects)
    if not adhoc:
        check_scenes(compiled)
    return check_report(compiled, summary(compiled) if adhoc else None)


def units(model) -> dict:
    """The unit of every quantity of the model whose unit is known (name -> unit string:
    declared, from the ports' domains, or inferred; docs/units.md), after the units check;
    BgcModelError for a mismatch."""
    src = _source(model)
    try:
        return dict(check_units(flatten(resolve(front(src)))).units)
    except ModelError as exc:
        raise BgcModelError(exc, src) from None


def scenes(model) -> str:
    """`bgc scenes`: the model's scenes with their docs, effects, outputs and settings."""
    src = _source(model)
    try:
        graph = resolve(front(src))
    except ModelError as exc:
        raise BgcModelError(exc, src) from None
    return scenes_report(graph, src.text)




def equations(model, scene: str | None = None, format: str = "text",
              algebra: str = "auto", outputs=None, effects=None) -> str:
    """`bgc equations`: the reduced equations as text or LaTeX."""
    _choice("format", format, FORMATS)
    compiled = build(model, scene, algebra=algebra, program=False, outputs=outputs,
                     effects=effects)
    return equations_latex(compiled) if format == "latex" else equations_text(compiled)


def compile(model, target: str = "c", scene: str | None = None,
            project_initial: bool = False, algebra: str = "auto", outputs=None,
            effects=None, allow_inconsistent: bool = False,
            embedded: dict | None = None) -> dict[str, str | bytes]:
    """Standalone source code: {filename: text}; target "fmu": {"<id>.fmu": the bytes of an
    FMI 2.0 FMU for Model Exchange and Co-Simulation} (bgc.codegen.fmu; needs a C compiler:
    bgc.base.toolchain.BackendError without one; bgc.codegen.fmu.FmuError for a model an FMU cannot
    hold); target "embedded": {"<id>.h", "<id>.c"} (bgc.codegen.embedded; embedded: its
    options real, solver, step as compile_embedded takes them)."""
    _choice("target", target, TARGETS)
    compiled = build(model, scene, project_initial, algebra, outputs=outputs, effects=effects,
                     allow_inconsistent=allow_inconsistent)
    if target == "embedded":
        return compile_embedded(compiled, **(embedded or {}))
    if target == "fmu":
        from .codegen import fmu
        return {fmu.file_name(compiled): fmu.build_fmu(compiled, project_initial,
                                                       allow_inconsistent=allow_inconsistent)}
    return emit_c(compiled.program) if target == "c" else emit_python(compiled.program)


def compile_embedded(compiled: Compiled, real: str = "double", solver: str | None = None,
                     step: float | None = None) -> dict[str, str]:
    """The embedded C target of a built model: {"<id>.h", "<id>.c"} (docs/embedded.md).  solver:
    euler, rk4 or a Rosenbrock method (ros2, ...) on fixed steps (default: the scene's, which
    must then be one of them); step: the fixed step
    (default: the scene's step, else its output interval).  What the target cannot run is
    refused with a located BgcModelError."""
    from .codegen import embedded
    _choice("real", real, embedded.REALS)
    if step is not None and not (isinstance(step, (int, float)) and 0 < step < float("inf")):
        raise ValueError(f"step must be a positive finite number, not {step!r}")
    chosen = solver or compiled.settings.solver
    scene = next((s for s in compiled.graph.scenes if s.name == compiled.settings.scene), None)
    if solver is not None:
        _choice("solver", solver, solvers.NAMES)
    try:
        embedded.check_supported(compiled.program, compiled.graph,
                                 None if solver else scene, chosen, real, step)
    except ModelError as exc:
        raise BgcModelError(exc, compiled.source) from None
    return embedded.emit_embedded(compiled.program, real, chosen, step)


def simulate(model, scene: str | None = None, backend: str = "c", algebra: str = "auto",
             outputs=None, effects=None, **options):
    """Simulate; returns (t, Y, names).  outputs, effects: an ad-hoc scene (see build).
    options: t_end, dt, solver, rtol, atol, step, params, project_initial, max_steps,
    allow_inconsistent (start from initial values that violate the constraints, neither
    refused nor projected: the correctors pull them back), max_step, event_rows, events;
    inputs: {name: (t, values)}, the data of the model's inputs (`input NAME`: interpolated
    linearly, held outside, each t a time event; an input without data keeps its default).
    backend "c" (and "vm", the interpreter: no C build per model, bgc/codegen/vm.py) falls back to
    "python" when there is no C compiler."""
    _choice("backend", backend, BACKENDS)
    inputs = options.pop("inputs", None)
    unknown = sorted(set(options) - set(SIMULATE_OPTIONS))
    if unknown:
        raise TypeError(f"simulate() got unknown options: {', '.join(unknown)}")
    check_run_options(options)
    if inputs is not None:
        options["input_data"] = input_data(inputs)
    compiled = build(model, scene, options.get("project_initial", False), algebra,
                     outputs=outputs, effects=effects,
                     allow_inconsistent=options.get("allow_inconsistent", False))
    program = compiled.program
    names = [u.name for u in program.inputs]
    for name, _, _ in options.get("input_data", ()):
        if name not in names:
            raise ValueError(f"unknown input {name!r} (inputs: {', '.join(names) or 'none'})")
    settings = settings_for(program.scene, [p.name for p in program.params], **options)
    backend, _ = choose_backend(backend)
    ran = prepare(compiled, backend, in_process=True)
    result = run(ran, settings)
    return (*arrays(result), list(ran.outputs))


def arrays(result: Result):
    """A run's rows as numpy arrays (t, Y); SimulationFailed if it failed."""
    if result.t is not None:
        import numpy as np  # (not at import: the command line's compile does not need it)
        return np.asarray(result.t), np.asarray(result.values)
    if result.status != 0:
        csv = result.csv or ""
        raise SimulationFailed(result.stderr.strip() or result.message,
                               csv[:csv.rfind("\n") + 1])  # (whole rows: a killed program's
        #                                                    last one may be cut)
    t, Y, _ = _parse_csv(result.csv)
    return t, Y


class SimulationFailed(RuntimeError):
    """The generated program stopped with an error; `partial_csv` holds the rows written."""

    def __init__(self, message: str, partial_csv: str = ""):
        super().__init__(message)
        self.partial_csv = partial_csv


def _parse_csv(text: str):
    lines = text.splitlines()
    names = lines[0].split(",")[1:]
    import numpy as np
    data = np.loadtxt(io.StringIO("\n".join(lines[1:])), delimiter=",", ndmin=2)
    return data[:, 0], data[:, 1:], names


def sweep(model, scene: str | None = None, grid=None, sample=None, vary=None, seed: int = 0,
          metrics=(), client=None, workers: int | None = None, batch_size: int | None = None,
          backend: str = "c", algebra: str = "auto", timing: bool = True, progress=None,
          on_batch=None, trajectories: bool = False, **options):
    """Many runs of one compiled program (docs/sweeps.md); returns a sweeps.Table.  model: a
    path, a Source, or a Compiled (then scene and algebra are its own).
    grid: {name: "A:B:linN" | "A:B:logN" | "V1,V2,.." | [values]}, the Cartesian product with
    the first name slowest; or sample=n with vary={name: "uniform(A,B)" | "normal(MU,SIGMA)" |
    "loguniform(A,B)"} and seed.  metrics: ["final:x", "max:rod.residual", ...].  client: a
    dask.distributed.Client to run the batches on; else workers=N: a LocalCluster of N
    processes for this sweep; else serially in this process.  options: as simulate's
    (params are the fixed ones)."""
    import contextlib

    from .execute import sweeps as sw
    _choice("backend", backend, SWEEP_BACKENDS)
    unknown = sorted(set(options) - set(SIMULATE_OPTIONS))
    if unknown:
        raise TypeError(f"sweep() got unknown options: {', '.join(unknown)}")
    names, values = sw.runs_from(grid, sample, vary, seed)
    compiled = model if isinstance(model, Compiled) else \
        build(model, scene, options.get("project_initial", False), algebra,
              allow_inconsistent=options.get("allow_inconsistent", False))
    program = compiled.program
    sw.check_names(names, [p.name for p in program.params], options.get("params") or {})
    backend, _ = choose_backend(backend)
    settings = program.scene.with_options(**options)
    (py_text,) = emit_python(program).values()
    metrics = tuple(sw.parse_metric(m, list(program.outputs)) for m in metrics)
    c_text = next(iter(emit_c(program).values())) if backend == "c" else None
    prog = sw.make_program(c_text, py_text, settings.args(program.scene), metrics)
    lines = [sw.run_line(names, v) for v in values]
    session = sw.dask_client(workers=workers) if client is None and workers else \
        contextlib.nullcontext(client)
    with session as client:
        size = batch_size or sw.default_batch_size(
            len(lines), len(client.scheduler_info()["workers"]) if client is not None else 1)
        results = sw.run_batches(prog, lines, size, client, trajectories, progress, on_batch)
    return sw.table(names, values, metrics, results, timing)
