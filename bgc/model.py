"""The notebook API: `m = bgc.load("model.bg", scene="swing")`, then `m.states`,
`m.parameters`, `m.x0`, `m.simulate(params=...)`, `m.equations()`, `m.draw()`.

A Model is a model file's text with a scene and the options that shape its program (the
arguments of bgc.build).  It builds on first use (so a model with errors raises
bgc.BgcModelError there) and keeps what it built: the compiled model,
the generated Python module (for the parameters, the initial state and the right side, in
this process) and the C program (from bgc's cache).  Arguments are checked when they are
given, so a wrong backend or algebra is a ValueError at the call that names it.  A Model is
also a Source (`.path`, `.text`), so every function of bgc.api accepts it.
"""
from __future__ import annotations

import functools

import numpy as np

from . import api
from .base import run_settings
from .execute import runner


def load(path, text: str | None = None, scene: str | None = None, backend: str = "c",
         algebra: str = "auto", outputs=None, effects=None, project_initial: bool = False,
         allow_inconsistent: bool = False, consts=None) -> Model:
    """A model for interactive use (a Model, which is also a Source): the file read now
    (UTF-8, size-limited; `text` gives the source directly), built on first use with the
    scene and options given; consts: {name: whole number} for the model's constants."""
    source = api.read_source(path, text)
    if consts:
        source = api.Source(source.path, source.text, tuple(sorted(dict(consts).items())))
    return Model(source, scene, backend, algebra, outputs, effects,
                 project_initial, allow_inconsistent)


class Trajectory:
    """A run's output rows: `.t` (the times), `.values` (one row per time, one column per
    output), `.names` (the outputs); `tr["x"]` is a column (`tr["t"]` the times), `tr.keys()`
    the names with "t" first.  `to_records()` gives a numpy structured array (pandas:
    `pandas.DataFrame(tr.to_records())`), `to_csv(path)` the CSV bgc writes."""

    def __init__(self, t, values, names):
        self.t = np.asarray(t, dtype=float)
        self.values = np.asarray(values, dtype=float).reshape(len(self.t), len(names))
        self.names = tuple(names)

    def keys(self) -> list[str]:
        return ["t", *self.names]

    def __contains__(self, name) -> bool:
        return name == "t" or name in self.names

    def __getitem__(self, name: str) -> np.ndarray:
        if name == "t":
            return self.t
        try:
            return self.values[:, self.names.index(name)]
        except ValueError:
            raise KeyError(f"no output named {name!r} (outputs: {', '.join(self.names)})") \
                from None

    def __len__(self) -> int:
        return len(self.t)

    def to_records(self) -> np.ndarray:
        dtype = [(name, float) for name in self.keys()]
        out = np.empty(len(self.t), dtype=dtype)
        out["t"] = self.t
        for k, name in enumerate(self.names):
            out[name] = self.values[:, k]
        return out

    def to_csv(self, path) -> None:
        """The rows as bgc's CSV (17 significant digits), written atomically."""
        from .execute.outfile import write_atomic
        lines = [",".join(self.keys())]
        lines += [",".join(repr(float(v)) for v in (t, *row))
                  for t, row in zip(self.t, self.values)]
        write_atomic(str(path), "\n".join(lines) + "\n")

    def __repr__(self) -> str:
        span = f"t = {self.t[0]:g} .. {self.t[-1]:g}" if len(self.t) else "no rows"
        return f"<Trajectory: {len(self.t)} rows, {span}; {', '.join(self.names)}>"


class Equations(str):
    """Equations as text; LaTeX ones display as such in Jupyter."""

    def _repr_latex_(self):
        body = "\n".join(line for line in self.splitlines() if not line.startswith("%"))
        if not body.lstrip().startswith("\\begin"):
            return None
        body = body.replace("{align}", "{aligned}")  # (align is not allowed inside $$)
        return f"$$\n{body}\n$$"


class SVG(str):
    """An SVG drawing, which Jupyter displays."""

    def _repr_svg_(self):
        return str(self)


class Model(api.Source):
    """See the module's text.  Built with bgc.load."""

    def __init__(self, source: api.Source, scene: str | None = None, backend: str = "c",
                 algebra: str = "auto", outputs=None, effects=None,
                 project_initial: bool = False, allow_inconsistent: bool = False):
        run_settings.choice("backend", backend, run_settings.BACKENDS)
        run_settings.choice("algebra", algebra, run_settings.ALGEBRA)
        run_settings.exclusive(project_initial, allow_inconsistent)
        object.__setattr__(self, "path", source.path)
        object.__setattr__(self, "text", source.text)
        object.__setattr__(self, "consts", tuple(getattr(source, "consts", ())))
        object.__setattr__(self, "_options", dict(
            scene=scene, backend=backend, algebra=algebra, outputs=outputs, effects=effects,
            project_initial=bool(project_initial), allow_inconsistent=bool(allow_inconsistent)))

    @property
    def scene(self) -> str | None:
        return self._options["scene"]

    @property
    def backend(self) -> str:
        return self._options["backend"]

    @functools.cached_property
    def compiled(self) -> api.Compiled:
        """Every stage's value (bgc.build)."""
        o = self._options
        return api.build(api.Source(self.path, self.text, self.consts), o["scene"],
                         o["project_initial"], o["algebra"], outputs=o["outputs"],
                         effects=o["effects"], allow_inconsistent=o["allow_inconsistent"])

    @functools.cached_property
    def _python(self) -> runner.Program:
        """The generated Python, loaded in this process (runs, parameters, the right side)."""
        return runner.prepare(self.compiled, "python", in_process=True)

    @property
    def _module(self):
        return self._python.module

    @functools.cached_property
    def _c(self) -> runner.Program:
        return runner.prepare(self.compiled, "c")

    @functools.cached_property
    def _vm(self) -> runner.Program:
        return runner.prepare(self.compiled, "vm")

    @property
    def name(self) -> str:
        return self.compiled.program.name

    @property
    def states(self) -> tuple[str, ...]:
        """The state variables, in the order of the state vector (x0, rhs)."""
        return tuple(self.compiled.program.states)

    @property
    def outputs(self) -> tuple[str, ...]:
        return tuple(self.compiled.program.outputs)

    @property
    def parameters(self) -> dict[str, float]:
        """Every parameter's value in this scene (a new dict each time: changing it changes
        nothing; pass params= to simulate)."""
        return dict(self._module.PARAMETERS)

    @property
    def settings(self) -> run_settings.RunSettings:
        """The scene's run settings: t0, t_end, dt, solver, rtol, atol, step."""
        return self.compiled.settings.run

    def _p(self, params):
        """The parameter vector, ordered as `parameters`."""
        run_settings.check_run_options({"params": params})
        m = self._module
        return m._param_values(m._overrides(params))

    def initial_state(self, params: dict | None = None) -> np.ndarray:
        """The state vector a run starts from, with these parameter values: the model's
        initial values, projected onto the constraints if the Model was loaded with
        project_initial=True (a run refuses values that violate a constraint otherwise:
        ConstraintError, unless the Model was loaded with allow_inconsistent=True)."""
        m = self._module
        p = m._with_constants(self._p(params))
        o = self._options
        return np.array(m._initial_state(m._settings(), p, o["project_initial"],
                                         o["allow_inconsistent"]), dtype=float)

    @property
    def x0(self) -> np.ndarray:
        """initial_state() with the scene's parameter values."""
        return self.initial_state()

    def rhs(self, t: float, x, params: dict | None = None) -> np.ndarray:
        """dx/dt at (t, x), as the generated code computes it."""
        return np.array(self._module.rhs(float(t), list(map(float, x)), self._p(params)))

    def jacobian(self, t: float, x, params: dict | None = None) -> np.ndarray:
        """d(rhs)/dx at (t, x): the symbolic Jacobian the generated code evaluates."""
        return np.array(self._module.jacobian(float(t), list(map(float, x)), self._p(params)))

    def simulate(self, params: dict | None = None, *, t_end=None, dt=None, solver=None,
                 rtol=None, atol=None, step=None, max_steps=None,
                 backend: str | None = None) -> Trajectory:
        """Runs the model (None: the scene's setting); a Trajectory.  backend: the Model's
        unless given ("c" falls back to "python" without a C compiler)."""
        backend = self.backend if backend is None else backend
        run_settings.choice("backend", backend, run_settings.BACKENDS)
        options = dict(t_end=t_end, dt=dt, solver=solver, rtol=rtol, atol=atol, step=step,
                       max_steps=max_steps, params=params,
                       project_initial=self._options["project_initial"] or None,
                       allow_inconsistent=self._options["allow_inconsistent"] or None)
        run_settings.check_run_options(options)
        program = self.compiled.program
        settings = runner.settings_for(program.scene, [p.name for p in program.params],
                                       **options)
        backend, _ = runner.choose_backend(backend)
        program = self._python if backend == "python" else self._vm if backend == "vm" \
            else self._c
        result = runner.run(program, settings)
        return Trajectory(*api.arrays(result), self.outputs)

    def equations(self, format: str = "text") -> Equations:
        """The reduced equations, as `bgc equations` prints them; format "text" or "latex"."""
        run_settings.choice("format", format, run_settings.FORMATS)
        from .reports.report import equations_latex, equations_text
        return Equations((equations_latex if format == "latex" else equations_text)(
            self.compiled))

    def check(self) -> str:
        """The report of `bgc check`."""
        from .reports.report import check_report
        return check_report(self.compiled, api.summary(self.compiled) if self.scene else None)

    def draw(self, format: str = "svg"):
        """The bond graph with its causal strokes (`bgc draw`): format "svg" (an SVG that
        Jupyter displays; needs Graphviz's `dot`) or "dot" (the Graphviz text)."""
        run_settings.choice("format", format, ("svg", "dot"))
        from .reports import draw
        dot = draw.draw_dot(self.compiled)
        if format == "dot":
            return dot
        return SVG(draw.render(dot, "svg").decode("utf-8"))

    def __repr__(self) -> str:
        scene = f", scene {self.scene!r}" if self.scene else ""
        return (f"<Model {self.name!r} from {self.path!r}{scene}: {len(self.states)} states, "
                f"{len(self.compiled.program.params)} parameters, outputs "
                f"{', '.join(self.outputs)}>")
