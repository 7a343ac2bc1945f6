"""The command line: `bgc check|equations|compile|simulate|accuracy|sweep|linearize|steady|fit`,
and for editors `bgc fmt|lsp` (bgc.editor).
The only module that uses click and the only one that writes files.  Model errors exit 1 with a
located report, usage errors 2."""
from __future__ import annotations

import contextlib
import errno
import functools
import io
import math
import os
import sys
import time
from dataclasses import replace
from pathlib import Path

import click

from .base import cache, processes, run_settings, solvers, toolchain
from .execute import outfile, runner, warm
from .base.resources import read_bounded


class _Later:
    """A module imported on first use: the compiler's modules import SymPy (about a second),
    which `bgc --help` and a warm `bgc simulate` (bgc.execute.warm) never need."""

    def __init__(self, name: str):
        self._name = name

    def __getattr__(self, attr):
        import importlib
        return getattr(importlib.import_module(self._name, __package__), attr)


acc, api, stability = _Later(".analysis.accuracy"), _Later(".api"), _Later(".analysis.stability")
estimate = _Later(".analysis.estimate")
emit, report = _Later(".codegen.emit"), _Later(".reports.report")
diagnostics = _Later(".base.diagnostics")
vm = _Later(".codegen.vm")


def _warnings_text(compiled) -> str:
    return "".join(diagnostics.format_diagnostic(d, compiled.source.path, compiled.source.text)
                   + "\n" for d in compiled.warnings)


def _warn(compiled):
    click.echo(_warnings_text(compiled), err=True, nl=False)


def _or_exit(call, *args, **kwargs):
    """call(*args, **kwargs), or the model's located errors (or an unreadable file) on
    stderr, exit 1; exit 2 when they are in an option's value instead (--scene, --outputs,
    --effects)."""
    try:
        return call(*args, **kwargs)
    except api.BgcModelError as exc:
        click.echo(str(exc), err=True)
        sys.exit(2 if isinstance(exc, api.BgcArgumentError) else 1)
    except FileNotFoundError as exc:
        click.echo(f"error: {exc}", err=True)
        sys.exit(1)


def _build(model, scene, project_initial=False, algebra="auto", program=True,
           residual_outputs=False, outputs=None, effects=None, allow_inconsistent=False,
           jacobian=True):
    if project_initial and allow_inconsistent:
        raise click.UsageError("--project-initial and --allow-inconsistent exclude each other")
    compiled = _or_exit(api.build, model, scene, project_initial, algebra, program,
                        residual_outputs, outputs, effects, ("--outputs", "--effects", "--scene"),
                        allow_inconsistent, jacobian)
    _warn(compiled)
    return compiled


class _Number(click.ParamType):
    """A finite number, positive when asked; anything else is a usage error (exit 2)."""

    def __init__(self, positive: bool):
        self.positive = positive
        self.name = "positive finite number" if positive else "finite number"

    def convert(self, value, param, ctx):
        try:
            x = float(value)
        except (TypeError, ValueError):
            x = math.nan
        if not math.isfinite(x) or (self.positive and not x > 0):
            self.fail(f"{value!r} is not a {self.name}", param, ctx)
        return x


POSITIVE, FINITE = _Number(positive=True), _Number(positive=False)


def _check_span(compiled, t_end, dt):
    problem = run_settings.run_span_problem(compiled.settings, t_end, dt)
    if problem:
        raise click.UsageError(problem)


def _fail(message: str):
    """bgc's own error, one line on stderr, exit 1."""
    click.echo(f"bgc: error: {message}", err=True)
    sys.exit(1)


def _output_directory(value: str, option: str) -> Path:
    """A directory a command will write its files into (made later, with its parents, if it
    does not exist): a usage error before any work if it cannot be one (an empty name, a file
    that is not a directory, a name the system refuses)."""
    if not value.strip():
        raise click.UsageError(f"{option}: an empty name is not a directory")
    if outfile.is_stdout(value):
        raise click.UsageError(f"{option} -: a directory's files cannot go to standard "
                               "output; name a directory")
    path = Path(value)
    try:
        os.stat(path)
    except FileNotFoundError:
        return path
    except OSError as error:
        raise click.UsageError(f"{option}: cannot use '{value}' as a directory: "
                               f"{outfile.reason(error)}") from None
    if not path.is_dir():
        raise click.UsageError(f"{option}: '{value}' exists and is not a directory")
    return path


@contextlib.contextmanager
def _made_directory(path: Path):
    """The directory of a command's files, made with its parents if missing (one line, exit
    1, if the system refuses); the directories made are removed again if the command fails
    before its files are in them."""
    made = [d for d in (path, *path.parents) if not os.path.lexists(d)][::-1]
    _make_directory(path)
    try:
        yield path
    except BaseException:
        for d in reversed(made):
            try:
                d.rmdir()
            except OSError:
                pass  # (not empty, or not ours any more)
        raise


def _opened(path: Path, option: str) -> outfile.Partial:
    """The output file for path, its hidden file made now, before the work, so that a folder
    that cannot take it is said at once: a usage error, as for an output option's path."""
    try:
        return outfile.Partial(path)
    except outfile.OutputError as error:
        raise click.UsageError(f"{option}: {error}") from None


def _commit(part: outfile.Partial, render) -> None:
    """render(file) into an output opened by _opened, then into place; one line, exit 1, if
    the write fails."""
    try:
        try:
            render(part.file)
        except OSError as error:
            raise part.failed(error) from None
        part.commit()
    except outfile.OutputError as error:
        _fail(str(error))


def _make_directory(path: Path) -> None:
    """Makes the directory of a command's files (and its parents): one line, exit 1, if the
    system refuses (a full disk, a file in the way, no permission)."""
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as error:
        _fail(f"cannot make the directory '{path}': {outfile.reason(error)}")


def _write_atomic(path: str, text: str | bytes):
    """Write all of `text` (or bytes) or nothing (bgc.execute.outfile), or onto standard output for
    `-`; a write that fails (a full disk) is one line, exit 1."""
    if outfile.is_stdout(path):
        _echo(text)
        return
    try:
        outfile.write_atomic(path, text)
    except outfile.OutputError as error:
        _fail(str(error))


def _write_with(path: str, render) -> None:
    """render(file) writes binary data into a file for `path` (a figure by matplotlib),
    put into place whole (bgc.execute.outfile.Partial), or onto standard output for `-`; OutputError
    if it cannot be written."""
    if outfile.is_stdout(path):
        data = io.BytesIO()
        render(data)
        _echo(data.getvalue())
        return
    with outfile.Partial(path) as part:
        try:
            render(part.file)
        except OSError as error:
            raise part.failed(error) from None
        part.commit()


def _stdout_lost(error: OSError):
    """stdout could not be written (a full disk, a closed pipe): one line, exit 1.  What is
    left in stdout's buffer goes nowhere, so that leaving does not fail (and say so) again."""
    try:
        sys.stdout.flush()
    except (OSError, ValueError):
        pass
    try:
        null = os.open(os.devnull, os.O_WRONLY)
        os.dup2(null, sys.stdout.fileno())
        os.close(null)
    except (OSError, ValueError, AttributeError, io.UnsupportedOperation):
        pass
    _fail(f"cannot write stdout: {outfile.reason(error)}")


def _echo(text: str | bytes, err: bool = False):
    """text (or bytes, as they are) on stdout (stderr if err), flushed; a write to stdout
    that fails is _stdout_lost."""
    try:
        click.echo(text, nl=False, err=err)
        sys.stdout.flush()
    except OSError as error:
        _stdout_lost(error)


def _output_file(ctx, param, value):
    """-o: a file that can be written, checked before any work (a usage error if not), or
    `-`, standard output."""
    if value is not None:
        try:
            outfile.check_target(value)
        except outfile.OutputError as error:
            raise click.BadParameter(str(error), ctx, param) from None
    return value


def _output_file_or_directory(ctx, param, value):
    """compile's -o: as _output_file, or an existing directory (--target embedded writes into
    one; compile refuses it for the other targets)."""
    return value if value is not None and os.path.isdir(value) else \
        _output_file(ctx, param, value)


def _model_path(model) -> str:
    """The model file's path (the command's MODEL, a path or, with --const, a Source); (not
    through api, whose import the warm path of simulate avoids)."""
    return model if isinstance(model, (str, os.PathLike)) else model.path


READS = {"library": "the imported library", "table": "the table file"}  # Compiled.files


class _Files:
    """What a command reads and writes, in one place.  The outputs are its output options'
    paths (`-`: standard output, bgc.execute.outfile.STDOUT); the files it reads are the model, the
    files its options name (--input, --data, --reference), and, once the model is parsed,
    the libraries it imports and the tables it reads (read()).  Each check runs before any
    output is opened: an output that is a file the command reads (under any name: device and
    inode, through a symbolic or a hard link), or the same file as another output, is one
    line, exit 1; standard output taken by two outputs, or binary data (an FMU, a PNG) sent
    to a terminal, is a usage error (exit 2)."""

    def __init__(self, model, outputs, reads=(), stdout=None, binary=()):
        """outputs: (option, path or None) pairs; reads: (what, path) pairs besides the model;
        stdout: (option, what it writes) of the output that goes to standard output when its
        option is not given (compile's code, simulate's CSV), if any; binary: the options
        whose data is binary."""
        self.outputs = [(o, p) for o, p in outputs if p is not None]
        self.reads = [("the model file", _model_path(model)), *reads]
        self.to_stdout = [o for o, p in self.outputs if outfile.is_stdout(p)]
        if stdout is not None and dict(outputs).get(stdout[0]) is None:
            if self.to_stdout:
                raise click.UsageError(
                    f"{self.to_stdout[0]} -: standard output already has {stdout[1]} (no "
                    f"{stdout[0]} FILE given); name a file for one of them")
            self.to_stdout = [stdout[0]]
        if len(self.to_stdout) > 1:
            first, second = self.to_stdout[:2]
            raise click.UsageError(f"{first} - and {second} -: standard output can take one "
                                   "of them only; name a file for the other")
        for option in set(self.to_stdout) & set(binary):
            if _isatty(sys.stdout):
                raise click.UsageError(
                    f"{option} -: binary data is not written to a terminal; redirect standard "
                    "output (> FILE, | ...) or name a file")
        self._check()

    def read(self, files) -> None:
        """The files the model read besides itself ((kind, path) pairs, api.Compiled.files),
        each refused as an output, before any output is opened."""
        self.reads += [(READS[kind], path) for kind, path in files]
        self._check()

    def write(self, outputs) -> None:
        """More outputs ((option, path) pairs), known once the model is parsed, checked."""
        self.outputs += list(outputs)
        self._check()

    def _check(self) -> None:
        seen = []
        for option, path in self.outputs:
            if outfile.is_stdout(path):
                continue
            try:
                outfile.check_target(path, self.reads)
            except outfile.OutputIsInput as error:
                _fail(str(error))
            except outfile.OutputError:
                pass  # (said by the option's own check)
            if any(outfile.same_target(path, other) for other in seen):
                _fail(f"cannot write '{path}' twice: name different output files")
            seen.append(path)
        where = outfile.stdout_identity() if self.to_stdout else None
        for what, name in self.reads if where is not None else ():
            if outfile.identity(name) == where:
                _fail(f"cannot write standard output: it is {what} '{name}', which this "
                      "command reads; name another output file")


def _isatty(stream) -> bool:
    try:
        return stream.isatty()
    except (AttributeError, ValueError):
        return False


def _plot_file(ctx, param, value):
    """--plot: a file name bgc writes figures to, where a file can be written, and matplotlib
    there; checked before any work (a usage error if not)."""
    if value is not None:
        from .reports import plot
        try:
            _plot_format(value)
            outfile.check_target(value)
        except (plot.PlotError, outfile.OutputError) as error:
            raise click.BadParameter(str(error), ctx, param) from None
        missing = plot.matplotlib_missing()
        if missing:
            raise click.BadParameter(missing, ctx, param)
    return value


def _plot_format(path: str) -> str:
    """A figure's format: its file's extension (bgc.reports.plot.check_format), PNG on stdout."""
    from .reports import plot
    return "png" if outfile.is_stdout(path) else plot.check_format(path)


def _parse_params(values, names) -> dict:
    """-p NAME=VALUE items as {name: value}, each checked in turn (its form, its name against
    the model's parameters `names` with bgc.base.run_settings.parameter_overrides, its value)."""
    out = {}
    for item in values:
        name, sep, value = item.partition("=")
        if not sep:
            raise click.UsageError(f"-p expects NAME=VALUE, got '{item}'")
        try:
            run_settings.parameter_overrides({name: value}, names)
        except ValueError as error:
            raise click.UsageError(str(error)) from None
        try:
            out[name] = float(value)
        except ValueError:
            raise click.UsageError(f"-p {name}: '{value}' is not a number") from None
        if not math.isfinite(out[name]):
            raise click.UsageError(f"-p {name}: '{value}' is not a finite number")
    return out


def _overrides(values, compiled) -> dict:
    """-p NAME=VALUE items checked against compiled's parameters: {name: value}."""
    return _parse_params(values, sorted(p.name for p in compiled.program.params))


def _consts(ctx, param, values) -> tuple:
    """--const NAME=VALUE items as ((name, int value), ...)."""
    out = {}
    for item in values:
        name, sep, value = item.partition("=")
        if not sep or not name.isidentifier():
            raise click.BadParameter(f"expects NAME=VALUE, got '{item}'", ctx, param)
        try:
            out[name] = int(value.strip())
        except ValueError:
            raise click.BadParameter(f"{name}: '{value}' is not a whole number", ctx,
                                     param) from None
        if abs(out[name]) > 2 ** 53:
            raise click.BadParameter(f"{name}: {value} is too large", ctx, param)
    return tuple(sorted(out.items()))


def _model_arg(f, as_source: bool = True):
    """The model file, and --const NAME=VALUE for its constants: given, the command gets the
    model as a Source that carries them (as_source), or the values as `consts`."""
    f = click.argument("model", type=click.Path(exists=True, dir_okay=False))(f)
    f = click.option("--const", "consts", multiple=True, metavar="NAME=VALUE",
                     callback=_consts, help="A value for one of the model's constants "
                                            "(`constant N = 8`).")(f)
    if not as_source:
        return f

    @functools.wraps(f)
    def command(*args, consts=(), **kwargs):
        if consts:
            kwargs["model"] = _or_exit(_source_with, kwargs["model"], consts)
        return f(*args, **kwargs)
    return command


def _source_with(path, consts) -> api.Source:
    return replace(api.read_source(path), consts=consts)


MODEL = _model_arg
MODEL_PATH = functools.partial(_model_arg, as_source=False)  # simulate (its cache reads the file)
SCENE = click.option("--scene", "-s", default=None, help="Scene to use (default: all effects, "
                                                         "every state as an output).")


EFFECTS = click.option("--effects", default=None, metavar="E1,E2,..|none",
                       help="The effects in (replacing the scene's): tagged items of the others "
                            "are left out.")


def ADHOC(f):
    """--outputs and --effects: a scene made on the command line."""
    f = EFFECTS(f)
    return click.option("--outputs", default=None, metavar="X,Y,..",
                        help="The outputs, in order (replacing the scene's): only what they "
                             "need is computed.")(f)


ALGEBRA = click.option("--algebra", type=click.Choice(list(run_settings.ALGEBRA)), default="auto",
                       show_default=True,
                       help="How algebraic blocks are solved: symbolically when linear and "
                            "small (auto), always symbolically, or always numerically in the "
                            "generated code.")


ALLOW_HELP = ("Start from initial values that violate the constraints, neither refusing nor "
              "projecting them: the correctors pull the drift back (docs/stability.md).")


WRITE_ERRNOS = (errno.ENOSPC, errno.EDQUOT, errno.EFBIG, errno.EIO, errno.EPIPE, errno.EROFS)


class Interrupted(KeyboardInterrupt):
    """SIGINT or SIGTERM received by bgc: the command stops where it is, as at Ctrl-C (its
    outputs in place whole or not at all, the processes it started ended), and exits with
    128 + the signal."""

    def __init__(self, number: int):
        super().__init__(number)
        self.signal = number


def _interrupt(number, frame):
    raise Interrupted(number)


@contextlib.contextmanager
def _interruptible():
    """SIGINT and SIGTERM raise Interrupted while a command runs, where they have their
    default dispositions (a SIGINT that is ignored, as in a background job, stays so)."""
    import signal
    import threading
    saved = []
    if threading.current_thread() is threading.main_thread():
        for sig, default in ((signal.SIGINT, signal.default_int_handler),
                             (signal.SIGTERM, signal.SIG_DFL)):
            if signal.getsignal(sig) is default:
                saved.append((sig, signal.signal(sig, _interrupt)))
    try:
        yield
    finally:
        for sig, handler in saved:
            signal.signal(sig, handler)


class _Group(click.Group):
    """The commands; a C toolchain that fails (bgc.base.toolchain.BackendError) is reported as such,
    exit 1, without a traceback; so is a write that fails where no command caught it (a full
    disk under the cache, a closed stdout while click writes help): one line, exit 1.  A
    command interrupted (SIGINT, SIGTERM: Interrupted) says so in one line and exits with
    128 + the signal (130, 143), not click's `Aborted!` and 1."""

    def invoke(self, ctx):
        try:
            return super().invoke(ctx)
        except toolchain.BackendError as error:
            click.echo(f"error: {error}", err=True)
            ctx.exit(1)
        except KeyboardInterrupt as error:
            number = getattr(error, "signal", 2)  # (a KeyboardInterrupt of its own: SIGINT)
            clear = "\r\033[K" if _isatty(sys.stderr) else ""  # (a progress bar's line)
            click.echo(f"{clear}bgc: interrupted by {runner.signal_name(number)}", err=True)
            ctx.exit(128 + number)

    def main(self, *args, **kwargs):
        try:
            with _interruptible():
                return super().main(*args, **kwargs)
        except OSError as error:
            if error.errno not in WRITE_ERRNOS:
                raise
            if error.filename is not None:
                _fail(f"cannot write '{error.filename}': {outfile.reason(error)}")
            if _raised_in(error, click.utils.__file__, "echo"):  # (click's help or usage line)
                _stdout_lost(error)
            if any(_raised_in(error, m.__file__) for m in (cache, toolchain, processes)):
                _fail(f"cannot write the compile cache {cache.cache_dir()}: "
                      f"{outfile.reason(error)}")
            _fail(f"a write failed: {outfile.reason(error)}")


def _raised_in(error: BaseException, filename: str, function: str | None = None) -> bool:
    """Whether the error was raised through the module `filename` (its `function`)."""
    tb = error.__traceback__
    while tb is not None:
        code = tb.tb_frame.f_code
        if code.co_filename == filename and function in (None, code.co_name):
            return True
        tb = tb.tb_next
    return False


@click.group(cls=_Group, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(package_name="bgc")
def main():
    """bgc: compile bond-graph models (.bg) to equations, C and Python, and simulate them."""


@main.command()
@MODEL
@SCENE
@ADHOC
@ALGEBRA
def check(model, scene, outputs, effects, algebra):
    """Parse and assign causality; print states, constraints, algebraic blocks, warnings.
    With a scene (or --outputs, --effects): what it leaves out and prunes, and the operations
    of the generated code against the full model."""
    adhoc = scene is not None or outputs is not None or effects is not None
    compiled = _build(model, scene, algebra=algebra, program=adhoc, outputs=outputs,
                      effects=effects)
    if not adhoc:
        _or_exit(api.check_scenes, compiled)
    summary = api.summary(compiled) if adhoc else None
    if adhoc and summary is None:
        click.echo("note: the full model (all effects) does not compile, so this scene is not "
                   "compared with it", err=True)
    _echo(report.check_report(compiled, summary))


@main.command()
@MODEL
def scenes(model):
    """List the scenes: their docs, effects, outputs, time spans, solvers and settings."""
    _echo(_or_exit(api.scenes, model))


@main.command()
@MODEL
@SCENE
@ADHOC
@ALGEBRA
@click.option("--format", "fmt", type=click.Choice(["text", "latex"]), default="text")
def equations(model, scene, outputs, effects, algebra, fmt):
    """Print the reduced equations, multipliers included."""
    compiled = _build(model, scene, algebra=algebra, program=False, outputs=outputs,
                      effects=effects)
    _echo((report.equations_latex if fmt == "latex" else report.equations_text)(compiled))


@main.command()
@MODEL
@SCENE
@ADHOC
@ALGEBRA
@click.option("--target", type=click.Choice(list(run_settings.TARGETS)), default="c",
              help="fmu: an FMI 2.0 FMU for Model Exchange and Co-Simulation, built with the "
                   "C compiler (needs -o NAME.fmu).  embedded: NAME.h and NAME.c, one fixed "
                   "step per call, no heap, no stdio (docs/embedded.md).")
@click.option("-o", "output", default=None, callback=_output_file_or_directory,
              help="Output file (default: stdout); --target embedded: the directory "
                   "(default: the current one).")
@click.option("--project-initial", is_flag=True, help="Project initial values onto the "
                                                      "constraints instead of refusing them.")
@click.option("--allow-inconsistent", is_flag=True, help=ALLOW_HELP)
@click.option("--real", type=click.Choice(["double", "float"]), default=None,
              help="--target embedded: the real type.  [default: double]")
@click.option("--solver", type=click.Choice(solvers.NAMES), default=None,
              help="--target embedded: the fixed-step method, euler, rk4 or, for a stiff "
                   "model, ros2 (rodas4, rodas5p: on fixed steps too) (default: the scene's, "
                   "if it is one of them).")
@click.option("--step", type=POSITIVE, default=None,
              help="--target embedded: the fixed step H (default: the scene's step, else its "
                   "output interval).")
@click.option("--report", is_flag=True,
              help="--target embedded: print the memory the model needs, in bytes, on stderr.")
def compile(model, scene, outputs, effects, algebra, target, output, project_initial,
            allow_inconsistent, real, solver, step, report):
    """Emit standalone C or Python source code, or an FMU."""
    if target == "embedded":
        _compile_embedded(model, scene, outputs, effects, algebra, output, project_initial,
                          allow_inconsistent, real, solver, step, report)
        return
    given = [name for name, value in (("--real", real), ("--solver", solver),
                                      ("--step", step), ("--report", report)) if value]
    if given:
        raise click.UsageError(f"{given[0]} is an option of --target embedded")
    if output is not None and os.path.isdir(output):
        raise click.BadParameter(f"cannot write '{output}': it is a directory",
                                 param_hint="'-o'")
    if target == "fmu" and not output:
        raise click.UsageError("--target fmu writes a zip archive: name it with -o NAME.fmu "
                               "(or -o - for standard output)")
    files = _Files(model, [("-o", output)], stdout=("-o", "the code"),
                   binary=("-o",) if target == "fmu" else ())
    compiled = _build(model, scene, project_initial, algebra, outputs=outputs, effects=effects,
                      allow_inconsistent=allow_inconsistent)
    files.read(compiled.files)
    if target == "fmu":
        from .codegen import fmu
        try:
            data = fmu.build_fmu(compiled, project_initial,
                                 allow_inconsistent=allow_inconsistent)
        except fmu.FmuError as error:
            click.echo(f"error: {error}", err=True)
            sys.exit(1)
        _write_atomic(output, data)
        return
    emitted = (emit.emit_c if target == "c" else emit.emit_python)(compiled.program)
    (text,) = emitted.values()
    _write_atomic(output or outfile.STDOUT, text)


def _compile_embedded(model, scene, outputs, effects, algebra, output, project_initial,
                      allow_inconsistent, real, solver, step, report):
    """compile --target embedded: DIR/NAME.h and DIR/NAME.c, both or neither."""
    if project_initial or allow_inconsistent:
        raise click.UsageError("--target embedded starts from the model's initial values as "
                               "they are: leave out --project-initial and --allow-inconsistent")
    from .codegen.embedded import SOLVERS as fixed
    if solver is not None and solver not in fixed:
        raise click.BadParameter(f"'{solver}' is not a fixed-step method: the embedded target "
                                 f"takes one fixed step per call ({', '.join(fixed)})",
                                 param_hint="'--solver'")
    directory = Path(output or ".")
    if outfile.is_stdout(str(directory)) or not directory.is_dir():
        raise click.BadParameter(f"'{directory}' is not a directory: --target embedded writes "
                                 "NAME.h and NAME.c into one", param_hint="'-o'")
    compiled = _build(model, scene, False, algebra, outputs=outputs, effects=effects)
    files = _or_exit(api.compile_embedded, compiled, real or "double", solver, step)
    targets = [(directory / name, text) for name, text in files.items()]
    checker = _Files(model, [("-o", str(path)) for path, _ in targets])
    checker.read(compiled.files)
    for path, text in targets:
        _write_atomic(str(path), text)
    if report:
        from .codegen import embedded
        sizes = embedded.memory(compiled.program, real or "double",
                                solver or compiled.settings.solver)
        click.echo("memory (bytes): " + ", ".join(f"{k}={v}" for k, v in sizes.items()),
                   err=True)
        ident = next(iter(files))[:-2]
        frames = toolchain.stack_usage(directory / f"{ident}.c", directory)
        if frames is None:
            click.echo("stack: not measured (no C compiler with -fstack-usage)", err=True)
        else:
            click.echo(f"stack (bytes, this machine's cc -O2 -fstack-usage): "
                       f"{ident}_step={frames.get(ident + '_step', 0)}, every function's "
                       f"frame together={sum(frames.values())} (a bound on any call chain: "
                       f"no recursion)", err=True)


@main.command()
@MODEL_PATH
@SCENE
@ADHOC
@ALGEBRA
@click.option("--backend", type=click.Choice(["auto", "c", "vm", "python"]), default="auto",
              envvar="BGC_BACKEND", show_envvar=True,
              help="c: the model built in C (cached); vm: run in bgc's interpreter, no C build "
                   "per model; python: the generated Python module.  auto: c when this model's "
                   "build is cached or the run is long, else vm (docs/cli.md).  [default: "
                   "auto]")
@click.option("--solver", type=click.Choice(solvers.NAMES), default=None,
              help="The solver (default: the scene's); see docs/solvers.md.")
@click.option("--rtol", type=POSITIVE, default=None)
@click.option("--atol", type=POSITIVE, default=None)
@click.option("--t-end", type=FINITE, default=None)
@click.option("--dt", type=POSITIVE, default=None, help="Output interval.")
@click.option("--step", type=POSITIVE, default=None,
              help="Step of the fixed-step solvers (default: dt); for an adaptive solver, "
                   "fixed steps of this size without error control.")
@click.option("--max-steps", type=click.IntRange(0, 10**15), default=None,
              help="The most steps between two output times: a run that needs more stops "
                   "with a message (a step size running away); 0: no limit.  [default: "
                   "100000]")
@click.option("--max-step", type=POSITIVE, default=None,
              help="Every solver's largest step, fixed or adaptive (default: the scene's "
                   "hmax, else no bound but the span).")
@click.option("-p", "params", multiple=True, metavar="NAME=VALUE", help="Parameter override.")
@click.option("--project-initial", is_flag=True, help="Project initial values onto the "
                                                      "constraints instead of refusing them.")
@click.option("--allow-inconsistent", is_flag=True, help=ALLOW_HELP)
@click.option("--stats", is_flag=True, help="Print the solver's counters (steps, rejected "
                                            "steps, right-side calls, Jacobians, "
                                            "factorisations, solves, events) to stderr.")
@click.option("--event-rows", is_flag=True,
              help="Two more rows at each event: its left and right limits.")
@click.option("--events", "events_file", default=None, metavar="FILE.csv",
              callback=_output_file,
              help="The event log: t,event,change, a row per change at an event (docs/"
                   "hybrid.md); a failed run keeps the events before it.")
@click.option("--input", "input_files", multiple=True, metavar="FILE.csv",
              help="The inputs' data (`input NAME` in the model): CSV with a column t "
                   "(not decreasing; a repeated t is a jump) and a column per input, "
                   "interpolated linearly, each t a time event; an input without data keeps "
                   "its default.  May be repeated.")
@click.option("-o", "output", default=None, callback=_output_file,
              help="CSV file (default: stdout), written as the run goes and renamed into "
                   "place at its end; a failed run keeps the rows it computed.")
@click.option("--plot", "plot_file", default=None, metavar="FILE.png", callback=_plot_file,
              help="Also draw the run's outputs, one panel per kind, into FILE (.png, .svg "
                   "or .pdf; needs matplotlib: pip install 'bgc[plot]').")
@click.option("--sensitivities", default=None, metavar="P1,P2,..",
              help="Also the outputs' sensitivities to these parameters: a column "
                   "d(Y)/d(P) after the outputs for each parameter P and output Y, integrated "
                   "with the states (docs/analysis.md).")
@click.option("--units", "units_row", is_flag=True,
              help="A second header row: the unit of each column (s for t; declared or "
                   "inferred, docs/units.md; empty where it is not known).")
def simulate(model, scene, outputs, effects, algebra, backend, solver, rtol, atol, t_end, dt,
             step, max_steps, max_step, params, project_initial, allow_inconsistent, stats,
             event_rows, events_file, input_files, output, plot_file, sensitivities, units_row,
             consts):
    """Simulate and write CSV.  A model compiled before with the same options runs at once
    (bgc.execute.warm); otherwise it is compiled, and the result kept for the next run.  On a
    terminal, a run that takes more than a second shows its progress on stderr."""
    files = _Files(model, [("-o", output), ("--events", events_file), ("--plot", plot_file)],
                   [("the --input file", path) for path in input_files],
                   stdout=("-o", "the CSV"), binary=("--plot",))
    output = None if outfile.is_stdout(output) else output
    if project_initial and allow_inconsistent:
        raise click.UsageError("--project-initial and --allow-inconsistent exclude each other")
    chosen = _names(sensitivities)  # (a program with sensitivities is built each time)
    policy = runner.run_policy(backend, t_end, dt, warm=not chosen)
    if policy.warning:
        click.echo(policy.warning, err=True)
    request = warm.Request(model, scene, outputs, effects, algebra, project_initial,
                           allow_inconsistent, policy.backend, consts)
    if sensitivities is not None and not chosen:
        raise click.UsageError("--sensitivities: name one parameter or more (P1,P2,..)")
    found = warm.lookup(request) if policy.warm else None
    if found is None and policy.auto and policy.warm:  # no build of this model: its
        interpreted = replace(request, backend="vm")  # interpreted program, if the run is short
        found = warm.lookup(interpreted)
        if found is not None and policy.interpreted(found[0].settings, found[0].rhs_ops,
                                                    found[0].states):
            request = interpreted
            click.echo(runner.INTERPRETED, err=True)
        else:
            found = None
    if found is not None and warm.needs_model(found[0], solver, step):
        found = None
    if chosen:
        record, program, compiled = _compile_sensitivities(
            request, chosen, [item.partition("=")[0] for item in params])
    elif found is None:
        record, program, compiled = _compile_for_run(
            request, policy if policy.auto and request.backend == "c" else None, solver)
    else:
        (record, path), compiled = found, None
        program = warm.program(record, path)
        click.echo(record.warnings, err=True, nl=False)
    files.read(compiled.files if compiled is not None else
               [("table", name) for name, _ in record.files])
    problem = run_settings.run_span_problem(record.settings, t_end, dt)  # (before -p, as always)
    if problem:
        raise click.UsageError(problem)
    names = sorted(record.params)
    given = _parse_params(params, names)
    if given:  # (bgc.api imports SymPy: a warm run without -p does without)
        _or_exit(api.check_parameters, model, scene, given, outputs, effects,
                 ("--outputs", "--effects"))
    try:
        settings = runner.settings_for(
            record.settings, names, given, t_end=t_end, dt=dt,
            solver=solver, rtol=rtol, atol=atol, step=step, max_steps=max_steps,
            project_initial=project_initial, allow_inconsistent=allow_inconsistent,
            max_step=max_step, event_rows=event_rows or None)
    except ValueError as error:
        raise click.UsageError(str(error)) from None
    seen: set = set()
    for path in input_files:
        problem = run_settings.input_file_problem(path, record.inputs)
        if problem:
            _fail(problem)
        with open(path, encoding="utf-8") as f:
            columns = [c.strip() for c in f.readline().split(",") if c.strip() != "t"]
        again = seen.intersection(columns)
        if again:
            _fail(f"{path}: input '{sorted(again)[0]}' is given twice")
        seen.update(columns)
    if input_files:
        settings = replace(settings, input_files=tuple(os.path.abspath(p) for p in input_files))
    with _scratch(events_file is not None) as logs:
        if logs:
            settings = replace(settings, events=str(Path(logs) / "events.csv"))
        status = _simulate_run(settings, record, program, compiled, request, stats, output,
                               plot_file, units_row)
        if logs:
            status = _keep_events(Path(logs) / "events.csv", events_file, status)
    sys.exit(status)


def _keep_events(log: Path, target: str, status: int) -> int:
    """The run's event log, moved to its place (a failed run's too: the events before it)."""
    if not log.exists():
        return status
    if outfile.is_stdout(target):
        _echo(log.read_bytes())
        return status
    try:
        outfile.write_atomic(target, log.read_bytes())
    except (outfile.OutputError, OSError) as error:
        click.echo(f"error: no event log written to {target}: {error}", err=True)
        return status or 1
    return status


def _simulate_run(settings, record, program, compiled, request, stats, output, plot_file,
                  units_row=False):
    """simulate's run proper (the CSV, the plot); its exit status.  units_row: the CSV's
    second row the columns' units (the warm record's, bgc.reports.plot.columns)."""
    if compiled is not None and record.correctors:
        for message in stability.warnings_for_run(compiled, settings.solver, settings.step,
                                                  settings.dt, dict(settings.params)):
            click.echo(message, err=True)
    # (--plot reads the CSV back: from a copy when it goes to stdout, a device or a FIFO)
    with _scratch(plot_file and (not output or outfile.destination(output)[1])) as tmp:
        copy = Path(tmp) / "run.csv" if tmp else None  # (the CSV that --plot reads)
        # (not while the CSV itself goes to the terminal: the bar would cut its lines)
        progress = _RunProgress() if sys.stderr.isatty() and (
            output or not sys.stdout.isatty()) else None
        units = None
        if units_row:  # (the outputs' from the record, a warm run's too; the rest's: the model's)
            units = dict(compiled.graph.units) if compiled is not None else {}
            units.update({c[0]: c[3] for c in record.plot_columns if c[3]})
        try:
            status, rows = _run_to_output(program, settings, stats, output, copy, progress, units)
        except processes.CannotStart:  # (damaged behind its checksum: evicted, built again)
            record, program, compiled = _compile_for_run(request, None, settings.solver)
            status, rows = _run_to_output(program, settings, stats, output, copy, progress, units)
        if progress is not None:
            progress.close()
        if plot_file:
            status = _plot(record, copy or output, plot_file, status, rows)
    return status


def _backend(backend: str) -> str:
    """The backend that runs (bgc.execute.runner.choose_backend), its fallback said on stderr."""
    backend, warning = runner.choose_backend(backend)
    if warning:
        click.echo(warning, err=True)
    return backend


def _scratch(needed: bool):
    """A temporary directory if needed, else None (a run does not create one for nothing)."""
    if not needed:
        return contextlib.nullcontext(None)
    import tempfile
    return tempfile.TemporaryDirectory(prefix="bgc-")


def _compile_for_run(request: warm.Request, policy=None, solver: str | None = None):
    """The cold path: build the model, compile its program into the cache, keep a warm
    record of it; (record, program, the compiled model).  policy: the run's
    (bgc.execute.runner.RunPolicy) when bgc chooses its backend: the interpreter where the
    policy says so (interpreted), which is said on stderr, else the C backend.  solver: the
    run's (None: the scene's); for an explicit one, C and the interpreter get a program
    without the Jacobian (nothing the run does not call is built: warm.needs_model sends a
    later implicit run here again)."""
    r = request
    try:
        data = read_bounded(r.model)
    except OSError as exc:
        click.echo(f"error: {r.model}: cannot read: {exc.strerror}", err=True)
        sys.exit(1)
    source = replace(_or_exit(api.source_from_bytes, r.model, data), consts=r.consts)
    jacobian = True if r.backend == "python" else (
        None if solver is None else solvers.get(solver).uses_jacobian)
    compiled = _build(source, r.scene, r.project_initial, r.algebra, outputs=r.outputs,
                      effects=r.effects, allow_inconsistent=r.allow_inconsistent,
                      jacobian=jacobian)
    p = compiled.program
    if policy is not None and vm.supports(p) and policy.interpreted(p.scene, warm.rhs_ops(p),
                                                                    len(p.states)):
        request = replace(request, backend="vm")
        click.echo(runner.INTERPRETED, err=True)
    program = runner.prepare(compiled, request.backend)
    record = warm.record_for(compiled, program, _warnings_text(compiled))
    warm.store(request, data, record)
    return record, program, compiled


def _compile_sensitivities(request: warm.Request, chosen, given):
    """The program augmented with the sensitivities to `chosen` (parameters), not kept warm;
    given: the parameters -p overrides.  (record, program, the compiled model)."""
    r = request
    source = replace(_or_exit(api.read_source, r.model), consts=r.consts)
    compiled = _estimation(estimate.build, source, tuple(chosen), r.scene, tuple(given), False,
                           r.algebra, r.outputs, r.effects, r.project_initial,
                           r.allow_inconsistent, ("--outputs", "--effects", "--scene"))
    _warn(compiled)
    program = runner.prepare(compiled, r.backend)
    return warm.record_for(compiled, program, _warnings_text(compiled)), program, compiled


def _plot(record, csv, target: str, status: int, rows: bool) -> int:
    """The run's plot (bgc.reports.plot) from its CSV, written atomically, with what the warm record
    says of the model's outputs; a failed run's rows are plotted too (the title says where it
    stopped), a run without rows has no plot.  The exit status: the run's, or 1 if the plot
    could not be written."""
    from .reports import plot
    if not rows:
        if status != 2:  # (refused settings: a usage error, said as such)
            click.echo(f"bgc: no rows computed; no plot written to {target}", err=True)
        return status
    try:
        table = plot.read_csv(csv)
        cols = [plot.Column(*c) for c in record.plot_columns]
        _write_with(target, lambda file: plot.plot_run(
            table, cols, file, _plot_format(target), list(record.plot_title),
            stopped=status != 0))
    except (plot.PlotError, outfile.OutputError, OSError) as error:
        click.echo(f"error: no plot written: {error}", err=True)
        return status or 1
    return status


class _Tee:
    """stdout, and a copy of what is written to it in a file (the CSV a plot reads)."""

    def __init__(self, stream, path: Path):
        self.stream, self.copy = stream, open(path, "w", encoding="utf-8", newline="")

    def write(self, text: str) -> None:
        self.stream.write(text)
        self.copy.write(text)

    def flush(self) -> None:
        self.stream.flush()
        self.copy.flush()


class _UnitsRow:
    """A CSV sink that writes, after the header line, the row of the columns' units (`s` for
    t, '' where unknown): what `simulate --units` adds.  It has no descriptor, so that the
    program's output comes through it in whole lines."""

    def __init__(self, stream, units: dict):
        self.stream, self.units, self.done = stream, units, False

    def write(self, text: str) -> None:
        if not self.done:
            cut = text.find("\n")
            if cut >= 0:
                names = text[:cut].rstrip("\r").split(",")
                row = ",".join(self._unit(n) for n in names)
                text = text[:cut + 1] + row + "\n" + text[cut + 1:]
                self.done = True
        self.stream.write(text)

    def flush(self) -> None:
        self.stream.flush()

    def _unit(self, name: str) -> str:
        if name == "t":
            return "s"
        if name.startswith("d(") and ")/d(" in name and name.endswith(")"):  # a sensitivity
            from .front.units import ratio
            y, p = name[2:-1].split(")/d(", 1)
            return ratio(self.units.get(y), self.units.get(p)) or ""
        return self.units.get(name, "")


def _run_to_output(program, settings, stats: bool, output: str | None,
                   copy: Path | None = None, progress=None,
                   units: dict | None = None) -> tuple[int, bool]:
    """Runs the program (bgc.execute.runner.run), its CSV streamed to `output` (else stdout, and a
    copy into `copy` if given); the exit status, and whether rows were written.  A failed
    run's rows are kept, cut back to the last whole row, and the last line on stderr says so.
    progress: a _RunProgress for the program's progress lines.  units: the row of units
    after the header (--units), by column."""
    if not output:
        return _run_to_stdout(program, settings, stats, copy, progress, units)
    try:
        part = outfile.Partial(output)
    except outfile.OutputError as error:
        click.echo(f"bgc: error: {error}", err=True)
        return 1, False
    with part:
        sink = part.file
        if part.direct and copy is not None:  # (a device or a FIFO, and a copy for --plot)
            sink = _Tee(io.TextIOWrapper(part.file, encoding="utf-8", newline="",
                                         write_through=True), copy)
        if units is not None:
            sink = _UnitsRow(sink if sink is not part.file else io.TextIOWrapper(
                part.file, encoding="utf-8", newline="", write_through=True), units)
        tee = sink.stream if isinstance(sink, _UnitsRow) else sink
        with tee.copy if isinstance(tee, _Tee) else contextlib.nullcontext():
            done = runner.run(program, settings, sink, progress, stats)
            sink.flush()
        last = part.rows_end() if copy is None else outfile.last_row_time(copy)
        _say(done, f"'{output}'", last)
        try:
            if done.status == 0:
                part.commit()
                return 0, True
            if part.direct:  # (a device or a FIFO has what it was given)
                part.commit()
                return done.status, last is not None
            if last is None:
                if done.status != 2:  # (refused settings: a usage error, said as such)
                    click.echo(f"bgc: no rows computed; nothing written to {output}", err=True)
                return done.status, False
            part.keep()
        except outfile.OutputError as error:
            _fail(str(error))
        click.echo(f"bgc: the run stopped; the rows up to t = {last} are in {output}",
                   err=True)
    return done.status, True


def _run_to_stdout(program, settings, stats, copy, progress, units=None) -> tuple[int, bool]:
    """_run_to_output with the CSV on stdout: a regular file there (`> out.csv`) is cut back to
    its last whole row if the run fails, as a named file is."""
    tee = sys.stdout if copy is None else _Tee(sys.stdout, copy)
    sink = tee if units is None else _UnitsRow(tee, units)
    try:
        fd = sys.stdout.fileno()
        sys.stdout.flush()
        start = outfile.offset(fd)
    except (OSError, ValueError, AttributeError, io.UnsupportedOperation):
        fd = start = None  # (a pipe, a test's captured output)
    with tee.copy if copy is not None else contextlib.nullcontext():
        done = runner.run(program, settings, sink, progress, stats)
        sink.flush()
    if fd is not None:
        if done.status != 0:
            outfile.cut_to_whole_rows(fd, start)
        last = outfile.last_row_time_fd(fd, start)
    else:
        last = outfile.last_row_time_text(done.last_line + "\n")
    _say(done, "stdout", last)
    if done.write_error is not None:
        _stdout_lost(OSError(0, done.write_error))
    return done.status, copy is not None and outfile.last_row_time(copy) is not None


def _say(done, where: str, last: str | None) -> None:
    """The program's messages on stderr, and bgc's own line for a program killed by a signal
    (at the time of its last row, if known) or a CSV that could not be written."""
    click.echo(done.messages, err=True, nl=False)
    if done.killed:
        at = f" at t = {last}" if last is not None else ""
        click.echo(f"bgc: error: the generated program was killed by "
                   f"{runner.signal_name(done.killed)}{at}", err=True)
    if done.write_error is not None and where != "stdout":
        click.echo(f"bgc: error: cannot write {where}: {done.write_error}", err=True)


def _numbers(text: str | None, option: str) -> list[float] | None:
    if text is None:
        return None
    try:
        values = [float(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise click.UsageError(f"{option} expects comma-separated numbers, got '{text}'") \
            from None
    if not values or not all(math.isfinite(v) and v >= 0 for v in values):
        raise click.UsageError(f"{option} expects non-negative numbers, got '{text}'")
    return values


class _Progress:
    """A one-line progress bar on stderr when it is a terminal; silent otherwise."""

    def __init__(self):
        self.live = sys.stderr.isatty()

    def __call__(self, text, done=None, total=None, start=0):
        if not self.live:
            return
        if text is None:
            sys.stderr.write("\r\033[K")
        else:
            bar = ""
            if total:
                filled = min(30, max(0, int(30 * (done - start) / (total - start))))
                bar = f"[{'#' * filled}{'.' * (30 - filled)}] {done:.6g}/{total:.6g} "
            sys.stderr.write(f"\r\033[K{bar}{text}")
        sys.stderr.flush()


def _seconds(s: float) -> str:
    return f"{s:.1f} s" if s < 10 else f"{s:.0f} s" if s < 120 else f"{s / 60:.0f} min"


PROGRESS_AFTER = 1.0  # seconds a run takes before `bgc simulate` shows its progress


class _RunProgress:
    """`bgc simulate`'s progress bar: the program's progress lines (t, t0, t_end) drawn by
    _Progress once the run has taken `after` seconds (PROGRESS_AFTER), on a terminal only;
    close() clears it."""

    def __init__(self, after: float | None = None, clock=time.monotonic, bar=None):
        self.after = PROGRESS_AFTER if after is None else after
        self.clock = clock
        self.start = clock()
        self.bar = bar or _Progress()
        self.shown = False

    def __call__(self, t: float, t0: float, t_end: float) -> None:
        elapsed = self.clock() - self.start
        if elapsed < self.after or not t_end > t0:
            return
        frac = min(1.0, max(0.0, (t - t0) / (t_end - t0)))
        eta = elapsed / frac * (1 - frac) if frac > 0 else math.nan
        self.bar(f"t, {100 * frac:.0f}%, {_seconds(elapsed)}, ETA "
                 f"{_seconds(eta) if math.isfinite(eta) else '?'}", t, t_end, t0)
        self.shown = True

    def close(self) -> None:
        if self.shown:
            self.bar(None)
            self.shown = False


@main.command()
@MODEL
@SCENE
@ADHOC
@ALGEBRA
@click.option("--backend", type=click.Choice(["c", "vm", "python"]), default="c")
@click.option("--solvers", "solver_list", default=None, metavar="A,B,...",
              help="Solvers to sweep (default: all; with --gains: the scene's and rk4).")
@click.option("--rtols", default=None, metavar="R1,R2,...",
              help="Tolerances of the adaptive solvers (default 1e-3 .. 1e-10); atol follows "
                   "in the scene's atol/rtol ratio.")
@click.option("--steps", default=None, metavar="H1,H2,...",
              help="Steps of the fixed-step solvers (default: dt, dt/2, .. dt/32).")
@click.option("--reference", default=None, type=click.Path(dir_okay=False),
              help="CSV to measure the errors against (t and the scene's outputs on its grid); "
                   "default: bgc at a far tighter tolerance with another method.")
@click.option("--gains", default=None, metavar="G1,G2,...",
              help="Sweep the corrector gains instead: every gain parameter set to each value.")
@click.option("--repeats", type=click.IntRange(1, 100), default=3, show_default=True,
              help="Timing runs per point (the best is kept).")
@click.option("--timeout", type=POSITIVE, default=60.0, show_default=True,
              help="Seconds a run may take; a solver that exceeds it skips its harder points.")
@click.option("--t-end", type=FINITE, default=None)
@click.option("--dt", type=POSITIVE, default=None, help="Output interval.")
@click.option("-p", "params", multiple=True, metavar="NAME=VALUE", help="Parameter override.")
@click.option("--no-plot", is_flag=True, help="Do not write the PNG.")
@click.option("-o", "output", default=None, metavar="DIR",
              help="Directory for accuracy.csv and accuracy.png (gains.csv, gains.png with "
                   "--gains); default: accuracy-MODEL[-SCENE].")
def accuracy(model, scene, outputs, effects, algebra, backend, solver_list, rtols, steps,
             reference, gains, repeats, timeout, t_end, dt, params, no_plot, output):
    """Measure each solver's error and cost on the model: table, CSV and work-precision plot."""
    stem = Path(_model_path(model)).stem + (f"-{scene}" if scene else "")
    directory = _output_directory(f"accuracy-{stem}" if output is None else output, "-o")
    base = "gains" if gains is not None else "accuracy"
    written = [directory / f"{base}.csv"]
    if not no_plot:
        try:
            import matplotlib  # noqa: F401
        except ImportError:
            click.echo("warning: matplotlib is not installed (pip install 'bgc[plot]'): no plot "
                       "written", err=True)
        else:
            written.append(directory / f"{base}.png")
    files = _Files(model, [("-o", str(path)) for path in written],
                   [("the reference", reference)] if reference else ())
    names = [n.strip() for n in solver_list.split(",")] if solver_list else None
    for n in names or []:
        if n not in solvers.SOLVERS:
            raise click.UsageError(f"unknown solver '{n}' (solvers: {', '.join(solvers.NAMES)})")
    rtol_values = _numbers(rtols, "--rtols")
    step_values = _numbers(steps, "--steps")
    gain_values = _numbers(gains, "--gains")
    for option, vals in (("--rtols", rtol_values), ("--steps", step_values)):
        if vals and not all(v > 0 for v in vals):
            raise click.UsageError(f"{option} must be positive")
    compiled = _build(model, scene, algebra=algebra, program=True, residual_outputs=True,
                      outputs=outputs, effects=effects)
    files.read(compiled.files)
    _check_span(compiled, t_end, dt)
    overrides = _overrides(params, compiled)
    backend = _backend(backend)
    progress = _Progress()
    with _made_directory(directory), contextlib.ExitStack() as stack:
        parts = [stack.enter_context(_opened(path, "-o")) for path in written]
        try:
            if gain_values is not None:
                result = acc.run_gains(
                    compiled, gain_values,
                    acc.plan_gains(compiled, names, rtol_values, step_values, dt),
                    backend, repeats, t_end, dt, overrides, timeout, progress)
            else:
                result = acc.run_sweep(
                    compiled, acc.plan(compiled, names, rtol_values, step_values, dt),
                    backend, repeats, reference, overrides, t_end, dt, timeout, progress)
        except acc.AccuracyError as exc:
            progress(None)
            click.echo(f"error: {exc}", err=True)
            sys.exit(1)
        _echo(acc.table(result, gains=gain_values is not None))
        _commit(parts[0], lambda file: file.write(acc.csv_text(result).encode("utf-8")))
        if len(parts) > 1:
            _commit(parts[1], lambda file: acc.plot(result, file, gains=gain_values is not None))
    click.echo(f"wrote {', '.join(map(str, written))}", err=True)


@main.command()
@MODEL
@SCENE
@ALGEBRA
@click.option("--grid", "grids", multiple=True, metavar="NAME=A:B:linN|logN|V1,V2,..",
              help="A grid axis: N points from A to B, evenly or geometrically spaced, or the "
                   "values listed; the grid is their product, the first axis slowest.")
@click.option("--sample", type=int, default=None, metavar="N",
              help="N runs drawn at random (with --vary and --seed) instead of a grid.")
@click.option("--vary", "varies", multiple=True,
              metavar="NAME=uniform(A,B)|normal(MU,SIGMA)|loguniform(A,B)",
              help="A parameter of the sample and its distribution.")
@click.option("--seed", type=int, default=0, show_default=True, help="The sample's seed.")
@click.option("--metric", "metrics", multiple=True, metavar="KIND:OUTPUT",
              help="A column: KIND one of final, max, min, maxabs, rms (per output row) of "
                   "an output.  steps, rejected, rhs and cpu are always there.")
@click.option("--backend", type=click.Choice(["c", "python"]), default="c")
@click.option("--solver", type=click.Choice(solvers.NAMES), default=None)
@click.option("--rtol", type=POSITIVE, default=None)
@click.option("--atol", type=POSITIVE, default=None)
@click.option("--t-end", type=FINITE, default=None)
@click.option("--dt", type=POSITIVE, default=None, help="Output interval.")
@click.option("--step", type=POSITIVE, default=None, help="Step of the fixed-step solvers.")
@click.option("-p", "params", multiple=True, metavar="NAME=VALUE",
              help="A fixed parameter for every run.")
@click.option("--project-initial", is_flag=True)
@click.option("--allow-inconsistent", is_flag=True, help=ALLOW_HELP)
@click.option("--workers", type=click.IntRange(0, 4096), default=None,
              help="Processes of the local Dask cluster (default: the cores); 0: run the "
                   "batches one after the other in this process.")
@click.option("--scheduler", default=None, metavar="ADDRESS",
              help="Run the batches on this Dask cluster (tcp://host:8786) instead.")
@click.option("--batch-size", type=click.IntRange(1, 1_000_000), default=None,
              help="Runs per task (one program process each); default: about four tasks "
                   "per worker, at most 1000 runs.")
@click.option("--trajectories", default=None, metavar="DIR",
              help="Also keep each run's CSV, as DIR/run-NNNNNN.csv.")
@click.option("--no-timing", is_flag=True, help="Leave out the cpu column (the table is "
                                                "then the same whatever runs it).")
@click.option("-o", "output", default=None, callback=_output_file,
              help="The table's file (default: stdout, as CSV): CSV, or Parquet when the name "
                   "ends in .parquet (pip install 'bgc[parquet]').")
def sweep(model, scene, algebra, grids, sample, varies, seed, metrics, backend, solver, rtol,
          atol, t_end, dt, step, params, project_initial, allow_inconsistent, workers, scheduler,
          batch_size, trajectories, no_timing, output):
    """Run the model for many parameter sets (a grid or a seeded sample), compiled once, in
    batches on Dask or serially; write one table: run, parameters, metrics, counters, status,
    message.  A run that fails is a row with its status and message; see docs/sweeps.md."""
    from .execute import sweeps as sw
    files = _Files(model, [("-o", output)], stdout=("-o", "the table"))
    output = None if outfile.is_stdout(output) else output
    parquet = bool(output) and output.lower().endswith(".parquet")
    if parquet and not sw.have_pyarrow():
        raise click.UsageError("writing Parquet needs pyarrow: pip install 'bgc[parquet]' "
                               "(or write CSV: -o FILE.csv)")
    try:
        grid = dict(sw.parse_grid_axis(g) for g in grids) if grids else None
        vary = {v[0]: f"{v[1]}({v[2]!r},{v[3]!r})" for v in map(sw.parse_distribution, varies)}
        if sample is not None and grids:
            raise sw.SweepError("give --grid or --sample, not both")
        if sample is None and not grids:
            raise sw.SweepError("give --grid or --sample with --vary")
        if varies and sample is None:
            raise sw.SweepError("--vary needs --sample")
        if workers is not None and scheduler:
            raise sw.SweepError("--workers and --scheduler exclude each other")
        for name, value in (("--rtol", rtol), ("--atol", atol), ("--dt", dt), ("--step", step)):
            if value is not None and not value > 0:
                raise sw.SweepError(f"{name} must be positive")
        if trajectories:
            _make_directory(_output_directory(trajectories, "--trajectories"))
            outfile.check_target(Path(trajectories) / "run-000000.csv")
    except (sw.SweepError, OSError, outfile.OutputError) as error:
        raise click.UsageError(str(error)) from None
    compiled = _build(model, scene, project_initial, algebra,
                      allow_inconsistent=allow_inconsistent)
    files.read(compiled.files)
    if trajectories:
        files.write(("--trajectories", str(path)) for path in _trajectory_files(trajectories))
    overrides = _overrides(params, compiled)
    backend = _backend(backend)

    def keep(result):
        for number, text in (result.trajectories or {}).items():
            _write_atomic(str(Path(trajectories) / f"run-{number:06d}.csv"), text)

    try:
        with sw.dask_client(scheduler, workers, lambda text: click.echo(text, err=True)) \
                as client:
            start = time.perf_counter()  # (the cluster's start apart)
            table = api.sweep(compiled, scene, grid=grid,
                              sample=sample, vary=vary or None, seed=seed, metrics=metrics,
                              client=client, batch_size=batch_size, backend=backend,
                              algebra=algebra, timing=not no_timing,
                              progress=sw.stderr_progress(),
                              on_batch=keep if trajectories else None,
                              trajectories=bool(trajectories), t_end=t_end, dt=dt,
                              solver=solver, rtol=rtol, atol=atol, step=step, params=overrides,
                              project_initial=project_initial,
                              allow_inconsistent=allow_inconsistent)
    except sw.SchedulerUnreachable as error:
        click.echo(f"error: {error}", err=True)
        sys.exit(1)
    except sw.SweepError as error:
        raise click.UsageError(str(error)) from None
    except sw.BatchFailed as error:
        click.echo(f"error: {error}", err=True)
        sys.exit(1)
    wall = time.perf_counter() - start
    if parquet:
        try:
            table.to_parquet(output)
        except outfile.OutputError as error:
            click.echo(f"error: {error}", err=True)
            sys.exit(1)
    elif output:
        _write_atomic(output, table.to_csv())
    else:
        _echo(table.to_csv())
    click.echo(f"bgc sweep: {len(table)} runs, {table.failures()} failed, {wall:.2f} s "
               f"({len(table) / wall:.0f} runs/s)", err=True)


def _trajectory_files(directory: str) -> list[Path]:
    """The files in `directory` that a sweep's --trajectories may replace: run-NNNNNN.csv."""
    import re
    try:
        entries = sorted(os.listdir(directory))
    except OSError:
        return []
    return [Path(directory) / name for name in entries
            if re.fullmatch(r"run-\d{6}\.csv", name)]


# ---------------------------------------------------------------- bgc draw


def _drawing_target(ctx, param, value):
    """-o for `bgc draw`: FILE.dot, FILE.svg or FILE.png (the extension says which; `-` is
    DOT on stdout), checked before any work; anything else is a usage error."""
    from .reports import draw as drawing
    if value is None or value == "-":
        return value
    if drawing.format_of(value) is None:
        raise click.BadParameter(f"'{value}': a drawing is written as FILE.dot, FILE.svg or "
                                 "FILE.png (the extension says which), or - for DOT on stdout",
                                 ctx, param)
    return _output_file(ctx, param, value)


@main.command()
@MODEL
@SCENE
@ADHOC
@click.option("-o", "output", default=None, callback=_drawing_target,
              metavar="FILE.dot|FILE.svg|FILE.png|-",
              help="The drawing: DOT (needs nothing), or SVG or PNG made by Graphviz's `dot` "
                   "(default: DOT on stdout).")
@click.option("--depth", type=click.IntRange(min=0), default=None, metavar="N",
              help="Draw instances of components N levels deep as clusters and collapse the "
                   "deeper ones into boxes with their ports (0: every instance a box; "
                   "default: every level).")
def draw(model, scene, outputs, effects, output, depth):
    """Draw the bond graph with its causal strokes as Graphviz DOT, SVG or PNG: half-arrows
    for power, the stroke where the effort is received, multibonds as double lines, the
    constraint correctors as block diagrams, what the scene leaves out in grey; each instance
    of a component is a cluster."""
    from .reports import draw as drawing
    files = _Files(model, [("-o", output)], stdout=("-o", "the drawing"))
    output = output or outfile.STDOUT
    fmt = "dot" if outfile.is_stdout(output) else drawing.format_of(output)
    if fmt != "dot" and not drawing.have_graphviz():
        click.echo(f"error: {drawing.GRAPHVIZ_HELP}", err=True)
        sys.exit(1)
    compiled = _build(model, scene, program=False, outputs=outputs, effects=effects)
    files.read(compiled.files)
    text = drawing.draw_dot(compiled, depth)
    if fmt == "dot":
        _write_atomic(output, text)
        return
    try:
        data = drawing.render(text, fmt)
    except (drawing.GraphvizMissing, drawing.GraphvizFailed) as error:
        click.echo(f"error: {error}", err=True)
        sys.exit(1)
    _write_atomic(output, data)


# ---------------------------------------------------------------- analyses


analysis, linear = _Later(".analysis.operating"), _Later(".analysis.linear")
equilibria = _Later(".analysis.equilibrium")


def _analysed(call, *args):
    """call(*args) of an analysis: the model's errors as _or_exit says them, an argument the
    analysis refuses a usage error (exit 2), an analysis that cannot be done one line, exit 1."""
    try:
        return _or_exit(call, *args)
    except analysis.AnalysisArgumentError as error:
        raise click.UsageError(str(error)) from None
    except analysis.AnalysisError as error:
        _fail(str(error))


def _at(ctx, param, value):
    """--at: t=TIME or steady, checked before any work."""
    try:
        linear.parse_at(value)
    except ValueError as error:
        raise click.BadParameter(str(error), ctx, param) from None
    return value


def _steady_at(ctx, param, value):
    """steady's --at: t=TIME, checked before any work (its start, once the model is built)."""
    try:
        equilibria.parse_at(value, -math.inf)
    except ValueError as error:
        raise click.BadParameter(str(error), ctx, param) from None
    return value


def _matrices_file(ctx, param, value):
    """-o of linearize: FILE.json, .npz or .csv where a file can be written."""
    if value is not None and not outfile.is_stdout(value):
        try:
            linear.check_format(value)
        except ValueError as error:
            raise click.BadParameter(str(error), ctx, param) from None
    return _output_file(ctx, param, value)


def _names(value) -> tuple:
    return tuple(v.strip() for v in value.split(",") if v.strip()) if value else ()


def _analysis_params(model, scene, params, analysed, outputs=None, effects=None) -> dict:
    """-p items checked against the analysis program's parameters and the model's laws."""
    given = _parse_params(params, sorted(p.name for p in analysed.compiled.program.params))
    if given:
        _or_exit(api.check_parameters, model, scene, given, outputs, effects,
                 ("--outputs", "--effects"))
    return given


@main.command()
@MODEL
@SCENE
@ADHOC
@ALGEBRA
@click.option("--at", default=None, metavar="t=TIME|steady", callback=_at,
              help="The operating point: the state of the scene's run at TIME, or an "
                   "equilibrium (bgc steady).  [default: the initial state]")
@click.option("--inputs", default=None, metavar="U1,U2,..",
              help="The inputs: the model's inputs (`input NAME`, at their defaults), or "
                   "parameters, each taken as a signal held at its value.  [default: the "
                   "model's inputs]")
@click.option("-p", "params", multiple=True, metavar="NAME=VALUE", help="Parameter override.")
@click.option("-o", "output", default=None, callback=_matrices_file, metavar="FILE",
              help="Write the matrices, eigenvalues and the point to FILE.json, .npz or .csv.")
@click.option("--bode", "bode_file", default=None, metavar="FILE.png", callback=_plot_file,
              help="Draw the Bode plot of every input-output pair into FILE (.png, .svg or "
                   ".pdf; needs matplotlib: pip install 'bgc[plot]').")
@click.option("--max-steps", type=click.IntRange(0, 10**15), default=None, metavar="N",
              help="The most steps of the run to --at t=TIME (0: no limit).  [default: "
                   "10000000]")
@click.option("--input", "input_files", multiple=True, metavar="FILE.csv",
              type=click.Path(dir_okay=False),
              help="Data for the model's inputs (a column t and one per input, as simulate's "
                   "--input): the run to --at t=TIME follows them, and the point takes their "
                   "values at its time (printed).  Repeat for more files.")
def linearize(model, scene, outputs, effects, algebra, at, inputs, params, output, bode_file,
              max_steps, input_files):
    """Linearise: A, B, C, D from the Jacobians the compiler derives; constrained models in
    independent coordinates, the correctors' artificial modes apart.  Prints the eigenvalues
    with their natural frequencies and damping ratios."""
    binary = output is not None and not outfile.is_stdout(output) and \
        linear.check_format(output) == "npz"
    files = _Files(model, [("-o", output), ("--bode", bode_file)],
                   [("the --input file", p) for p in input_files],
                   binary=("--bode",) + (("-o",) if binary else ()))
    names = None if inputs is None else _names(inputs)
    analysed = _analysed(analysis.build, model, scene, outputs, effects, names, algebra)
    files.read(analysed.compiled.files)
    if bode_file and not analysed.inputs:
        raise click.UsageError("--bode needs an input: the model declares none; name a "
                               "parameter with --inputs")
    _warn(analysed.compiled)
    given = _analysis_params(model, scene, params, analysed, outputs, effects)
    data = _input_data(input_files, [u.name for u in analysed.compiled.program.inputs])
    data = _analysed(linear.check_input_data, analysed, data, at)
    evaluator = _analysed(analysis.Evaluator, analysed, given)
    point = _analysed(linear.operating_point, evaluator, at,
                      lambda T: linear.run_to(evaluator, given, T, max_steps, data))
    result = _analysed(linear.linearization, evaluator, *point, data)
    if output:
        fmt = "json" if outfile.is_stdout(output) else linear.check_format(output)
        _write_atomic(output, linear.render(result, fmt))
    if bode_file:
        try:
            known = dict(analysed.compiled.graph.units)
            _write_with(bode_file, lambda file: linear.bode(result, file,
                                                            _plot_format(bode_file), known))
        except outfile.OutputError as error:
            _fail(str(error))
    _echo(linear.modes_table(result), err=bool(files.to_stdout))


@main.command()
@MODEL
@SCENE
@EFFECTS
@ALGEBRA
@click.option("-p", "params", multiple=True, metavar="NAME=VALUE", help="Parameter override.")
@click.option("--json", "json_file", default=None, callback=_output_file, metavar="FILE",
              help="Also write the equilibrium to FILE as JSON.")
@click.option("--at", default=None, metavar="t=TIME", callback=_steady_at,
              help="The time the time sources (step, pulse, square, tables of t, ...) are "
                   "evaluated at; they must be constant from there on.  [default: the "
                   "scene's start]")
def steady(model, scene, effects, algebra, params, json_file, at):
    """An equilibrium by Newton's method on the right side, with the exact Jacobian: one
    line per state, multiplier and constraint residual, then the residual max |dx/dt|; no
    equilibrium found: exit 1 and why."""
    files = _Files(model, [("--json", json_file)])
    analysed = _analysed(analysis.build, model, scene, None, effects, None, algebra)
    files.read(analysed.compiled.files)
    _warn(analysed.compiled)
    given = _analysis_params(model, scene, params, analysed, None, effects)
    evaluator = _analysed(analysis.Evaluator, analysed, given)
    found = _analysed(equilibria.solve, evaluator, None,
                      _analysed(equilibria.parse_at, at, evaluator.t0))
    if found.sources:
        click.echo(f"note: time sources evaluated at t = {found.t:.17g}: "
                   f"{', '.join(found.sources)}", err=True)
    if found.free:
        click.echo(f"note: the Jacobian is singular ({found.free} free direction"
                   f"{'s' if found.free > 1 else ''}): the equilibria form a family; this is "
                   "the one nearest the initial state", err=True)
    if json_file:
        _write_atomic(json_file, linear.json_lines(found.as_dict()))
    _echo(found.lines(), err=bool(files.to_stdout))


@main.command()
@MODEL
@SCENE
@ADHOC
@ALGEBRA
@click.option("--period", default=None, metavar="T|auto",
              help="The period.  [default: auto, the model's time sources' (square waves, "
                   "sin and cos of t): their least common multiple]")
@click.option("-p", "params", multiple=True, metavar="NAME=VALUE", help="Parameter override.")
@click.option("--dt", type=POSITIVE, default=None,
              help="The orbit's output interval.  [default: the scene's, or a 200th of the "
                   "period where that is longer]")
@click.option("--backend", type=click.Choice(["c", "vm", "python"]), default="c",
              show_default=True, help="What runs the period map.")
@click.option("-o", "output", default=None, callback=_output_file, metavar="FILE.csv",
              help="Write one period of the outputs to FILE (CSV, as simulate writes).")
@click.option("--json", "json_file", default=None, callback=_output_file, metavar="FILE",
              help="Also write the orbit's figures (x0, mean/min/max/ripple, multipliers, "
                   "the monodromy matrix) to FILE as JSON.")
@click.option("--plot", "plot_file", default=None, metavar="FILE.png", callback=_plot_file,
              help="Draw one period of the outputs into FILE (.png, .svg or .pdf; needs "
                   "matplotlib: pip install 'bgc[plot]').")
def periodic(model, scene, outputs, effects, algebra, period, params, dt, backend, output,
             json_file, plot_file):
    """The periodic steady state of a periodically driven model, by shooting: Newton on the
    period map with its exact monodromy matrix.  Prints the orbit's initial state, each
    output's mean, min, max and ripple over one period, and the Floquet multipliers; no
    orbit: exit 1 and why."""
    from .analysis import periodic as periodic_
    files = _Files(model, [("-o", output), ("--json", json_file), ("--plot", plot_file)])
    T = None
    if period is not None and period != "auto":
        try:
            T = float(period)
        except ValueError:
            raise click.BadParameter(f"{period!r} is not a number nor 'auto'",
                                     param_hint="--period") from None
        if not (math.isfinite(T) and T > 0):
            raise click.BadParameter(f"{period!r}: a period is a positive number",
                                     param_hint="--period")
    first = _or_exit(api.build, model, scene, False, algebra, True, False, outputs, effects,
                     ("--outputs", "--effects", "--scene"))
    files.read(first.files)
    _warn(first)
    given = _parse_params(params, sorted(p.name for p in first.program.params))
    if given:
        _or_exit(api.check_parameters, model, scene, given, outputs, effects,
                 ("--outputs", "--effects"))
    try:
        orbit = _or_exit(periodic_.periodic, first.source, scene, T, given, outputs, effects,
                         backend, algebra, dt)
    except analysis.AnalysisArgumentError as error:
        raise click.UsageError(str(error)) from None
    except analysis.AnalysisError as error:
        _fail(str(error))
    if output:
        _write_atomic(output, orbit.csv())
    if json_file:
        _write_atomic(json_file, linear.json_lines(orbit.as_dict()))
    if plot_file:
        try:
            _write_with(plot_file, lambda file: periodic_.plot(orbit, file,
                                                               _plot_format(plot_file)))
        except outfile.OutputError as error:
            _fail(str(error))
    _echo("\n".join(orbit.lines()) + "\n", err=bool(files.to_stdout))


# ---------------------------------------------------------------- estimation


def _estimation(call, *args, **kwargs):
    """call(*args, **kwargs) of bgc.analysis.estimate: the model's errors as _or_exit says them, an
    argument or data file refused a usage error (exit 2), a fit that cannot be done one line,
    exit 1."""
    try:
        return _or_exit(call, *args, **kwargs)
    except estimate.FitArgumentError as error:
        raise click.UsageError(str(error)) from None
    except estimate.FitError as error:
        _fail(str(error))


def _input_data(paths, names) -> dict:
    """The --input files' data ({name: (t, values)}), each file checked as simulate checks
    it (exit 1 with the reason; names: the model's inputs, None: any column), an input given
    twice refused."""
    data: dict = {}
    for path in paths:
        problem = run_settings.input_file_problem(path, names if names is not None else
                                                  run_settings.input_file_columns(path))
        if problem:
            _fail(problem)
        for name, series in run_settings.input_file_data(path).items():
            if name in data:
                _fail(f"{path}: input '{name}' is given twice")
            data[name] = series
    return data


@main.command()
@MODEL
@SCENE
@EFFECTS
@ALGEBRA
@click.option("--data", required=True, type=click.Path(exists=True, dir_okay=False),
              metavar="MEASURED.csv",
              help="The measured samples: a column t, and columns named as the model's "
                   "variables (they become the outputs), on a uniform time grid.")
@click.option("--vary", "varies", multiple=True, required=True, metavar="NAME[=LO..HI]",
              help="A parameter to estimate, from its value in the scene (or -p), kept "
                   "within LO..HI if given (either may be left out).  Repeat for each.")
@click.option("-p", "params", multiple=True, metavar="NAME=VALUE",
              help="A fixed parameter override.")
@click.option("--backend", type=click.Choice(["c", "python"]), default="c")
@click.option("--solver", type=click.Choice(solvers.NAMES), default=None)
@click.option("--rtol", type=POSITIVE, default=None)
@click.option("--atol", type=POSITIVE, default=None)
@click.option("--max-iter", type=click.IntRange(1, 10000), default=100, show_default=True,
              help="The most Levenberg-Marquardt iterations.")
@click.option("-o", "output", default=None, callback=_output_file, metavar="FILE.json",
              help="Also write the result (estimates, standard errors, intervals, "
                   "correlations, cost, iterations, why it stopped) as JSON.")
@click.option("--plot", "plot_file", default=None, metavar="FILE.png", callback=_plot_file,
              help="Draw the measured and fitted outputs and the residuals into FILE (needs "
                   "matplotlib).")
@click.option("--input", "input_files", multiple=True, metavar="FILE.csv",
              type=click.Path(dir_okay=False),
              help="Data for the model's inputs (a column t and one per input, as simulate's "
                   "--input), which every run of the fit follows.  Repeat for more files.")
def fit(model, scene, effects, algebra, data, varies, params, backend, solver, rtol, atol,
        max_iter, output, plot_file, input_files):
    """Estimate parameters from measured data by Levenberg-Marquardt on the residuals, with
    their Jacobian from the forward sensitivities the compiler derives: estimates, standard
    errors, 95 % confidence intervals, correlations."""
    files = _Files(model, [("-o", output), ("--plot", plot_file)],
                   [("the data file", data)] + [("the --input file", p) for p in input_files],
                   binary=("--plot",))
    vary = [_estimation(estimate.parse_vary, v) for v in varies]
    measured = _estimation(estimate.read_data, data)
    fixed = {}
    for item in params:
        name, sep, value = item.partition("=")
        try:
            fixed[name] = float(value) if sep else math.nan
        except ValueError:
            fixed[name] = math.nan
        if not math.isfinite(fixed[name]):
            raise click.UsageError(f"-p expects NAME=VALUE with a finite number, got '{item}'")
    backend = _backend(backend)
    options = {k: v for k, v in (("solver", solver), ("rtol", rtol), ("atol", atol))
               if v is not None}
    if input_files:  # (their columns checked against the model's inputs by the fit)
        options["inputs"] = _input_data(input_files, None)
    result = _estimation(estimate.fit, model, measured, vary, scene, fixed, backend, algebra,
                         max_iter, effects, on_build=lambda c: files.read(c.files),
                         **options)
    if output:
        _write_atomic(output, result.json())
    known = _or_exit(api.units, model)
    if plot_file:
        try:
            _write_with(plot_file, lambda file: estimate.plot_residuals(
                result, file, _plot_format(plot_file), known))
        except outfile.OutputError as error:
            _fail(str(error))
    _echo(result.table(known), err=bool(files.to_stdout))
    if not result.converged:
        click.echo(f"warning: the fit did not converge ({result.stopped})", err=True)
        sys.exit(1)


# ---------------------------------------------------------------- editors


@main.command("fmt")
@click.argument("models", nargs=-1, required=True,
                type=click.Path(exists=True, dir_okay=False, allow_dash=True))
@click.option("--check", is_flag=True, help="Change nothing: name each file that is not in "
                                            "the canonical layout, and exit 1 if one is not.")
@click.option("--diff", is_flag=True, help="Change nothing: print what formatting changes, "
                                           "as a unified diff.")
def fmt(models, check, diff):
    """Lay models out in the canonical layout (docs/editors.md): indentation, spacing, one
    statement a line, declarations aligned, lines wrapped at 100 columns; every comment and
    doc string kept, the meaning unchanged.  `-` reads the standard input and writes the
    standard output.  A file with a syntax error is reported and left as it is (exit 1)."""
    from .editor import fmt as layout
    status = 0
    for path in models:
        status = max(status, _fmt_file(layout, path, check, diff))
    sys.exit(status)


def _fmt_file(layout, path: str, check: bool, diff: bool) -> int:
    """bgc fmt of one file (`-`: the standard input): its exit status."""
    import difflib

    from .base.resources import max_source_bytes
    name = "<stdin>" if path == "-" else path
    try:
        data = sys.stdin.buffer.read(max_source_bytes() + 1) if path == "-" else \
            read_bounded(path)
    except OSError as error:
        click.echo(f"error: {name}: cannot read: {outfile.reason(error)}", err=True)
        return 1
    try:
        source = api.source_from_bytes(name, data)
        text = layout.format_text(source.text, name)
    except api.BgcModelError as error:
        click.echo(str(error), err=True)
        return 1
    except diagnostics.ModelError as error:
        click.echo(str(api.BgcModelError(error, source)), err=True)
        return 1
    except layout.FormatBug as error:
        click.echo(f"bgc: error: {error}: a bug of bgc fmt, the file is left as it is",
                   err=True)
        return 1
    changed = text != source.text
    if diff and changed:
        lines = difflib.unified_diff(source.text.splitlines(True), text.splitlines(True),
                                     name, f"{name} (formatted)")
        _echo("".join(x if x.endswith("\n") else x + "\n\\ No newline at end of file\n"
                      for x in lines))
    if check:
        if changed and not diff:
            _echo(f"{name}\n")
        return 1 if changed else 0
    if diff:
        return 0
    if path == "-":
        _echo(text)
    elif changed:
        _write_formatted(path, text)
    return 0


def _write_formatted(path: str, text: str):
    """The model's file replaced by its formatted text, whole or not at all, its permissions
    kept (bgc.execute.outfile)."""
    import stat
    try:
        with outfile.Partial(path) as part:
            try:
                if part.tmp is not None:
                    os.fchmod(part.file.fileno(), stat.S_IMODE(os.stat(path).st_mode))
            except OSError:
                pass  # (the user's umask, as for any new file)
            part.write(text.encode("utf-8"))
            part.commit()
    except outfile.OutputError as error:
        _fail(str(error))


@main.command()
def lsp():
    """A Language Server Protocol server on the standard input and output, for editors
    (docs/editors.md): diagnostics, hover, definitions, completion, outline, formatting.
    Needs pygls: pip install 'bgc[lsp]'."""
    try:
        from .editor import lsp as server
    except ImportError as error:
        _fail(f"bgc lsp needs pygls ({error}): pip install 'bgc[lsp]'")
    server.main()


if __name__ == "__main__":  # pragma: no cover
    main()
