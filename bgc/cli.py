"""The command line: `bgc check|equations|compile|simulate`.  The only module that uses click
and the only one that writes files.  Model errors exit 1 with a located report, usage errors 2."""
from __future__ import annotations

import os
import sys
import tempfile
from pathlib import Path

import click

from . import api, backends, solvers
from .diagnostics import format_diagnostic
from .emit import emit_c, emit_python
from .report import check_report, equations_latex, equations_text


def _warn(compiled: api.Compiled):
    for d in compiled.warnings:
        click.echo(format_diagnostic(d, compiled.source.path, compiled.source.text), err=True)


def _build(model, scene, project_initial=False, algebra="auto", program=True) -> api.Compiled:
    try:
        compiled = api.build(model, scene, project_initial, algebra, program)
    except api.BgcModelError as exc:
        click.echo(str(exc), err=True)
        sys.exit(1)
    except FileNotFoundError as exc:
        click.echo(f"error: {exc}", err=True)
        sys.exit(1)
    _warn(compiled)
    return compiled


def _write_atomic(path: str, text: str):
    """Write all of `text` or nothing: a temp file beside `path`, then rename."""
    target = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", dir=target.parent or ".")
    try:
        with os.fdopen(fd, "w", encoding="utf-8", newline="") as fh:
            fh.write(text)
        os.replace(tmp, target)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def _parse_params(values, compiled) -> dict:
    names = {p.name for p in compiled.program.params}
    out = {}
    for item in values:
        name, sep, value = item.partition("=")
        if not sep:
            raise click.UsageError(f"-p expects NAME=VALUE, got '{item}'")
        if name not in names:
            raise click.UsageError(f"unknown parameter '{name}' (parameters: "
                                   f"{', '.join(sorted(names)) or 'none'})")
        try:
            out[name] = float(value)
        except ValueError:
            raise click.UsageError(f"-p {name}: '{value}' is not a number") from None
    return out


MODEL = click.argument("model", type=click.Path(dir_okay=False))
SCENE = click.option("--scene", "-s", default=None, help="Scene to use (default: all effects, "
                                                         "every state as an output).")
ALGEBRA = click.option("--algebra", type=click.Choice(list(api.ALGEBRA)), default="auto",
                       show_default=True,
                       help="How algebraic blocks are solved: symbolically when linear and "
                            "small (auto), always symbolically, or always numerically in the "
                            "generated code.")


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(package_name="bgc")
def main():
    """bgc: compile bond-graph models (.bg) to equations, C and Python, and simulate them."""


@main.command()
@MODEL
@SCENE
@ALGEBRA
def check(model, scene, algebra):
    """Parse and assign causality; print states, constraints, algebraic blocks, warnings."""
    click.echo(check_report(_build(model, scene, algebra=algebra, program=False)), nl=False)


@main.command()
@MODEL
@SCENE
@ALGEBRA
@click.option("--format", "fmt", type=click.Choice(["text", "latex"]), default="text")
def equations(model, scene, algebra, fmt):
    """Print the reduced equations, multipliers included."""
    compiled = _build(model, scene, algebra=algebra, program=False)
    click.echo((equations_latex if fmt == "latex" else equations_text)(compiled), nl=False)


@main.command()
@MODEL
@SCENE
@ALGEBRA
@click.option("--target", type=click.Choice(["c", "python"]), default="c")
@click.option("-o", "output", default=None, help="Output file (default: stdout).")
@click.option("--project-initial", is_flag=True, help="Project initial values onto the "
                                                      "constraints instead of refusing them.")
def compile(model, scene, algebra, target, output, project_initial):
    """Emit standalone C or Python source code."""
    compiled = _build(model, scene, project_initial, algebra)
    files = (emit_c if target == "c" else emit_python)(compiled.program)
    (text,) = files.values()
    if output:
        _write_atomic(output, text)
    else:
        click.echo(text, nl=False)


@main.command()
@MODEL
@SCENE
@ALGEBRA
@click.option("--backend", type=click.Choice(["c", "python"]), default="c")
@click.option("--solver", type=click.Choice(solvers.NAMES), default=None,
              help="The solver (default: the scene's); see docs/solvers.md.")
@click.option("--rtol", type=float, default=None)
@click.option("--atol", type=float, default=None)
@click.option("--t-end", type=float, default=None)
@click.option("--dt", type=float, default=None, help="Output interval.")
@click.option("--step", type=float, default=None,
              help="Step of the fixed-step solvers (default: dt); for an adaptive solver, "
                   "fixed steps of this size without error control.")
@click.option("-p", "params", multiple=True, metavar="NAME=VALUE", help="Parameter override.")
@click.option("--project-initial", is_flag=True, help="Project initial values onto the "
                                                      "constraints instead of refusing them.")
@click.option("--stats", is_flag=True, help="Print the solver's counters (steps, rejected "
                                            "steps, right-side calls, Jacobians, "
                                            "factorisations, solves) to stderr.")
@click.option("-o", "output", default=None, help="CSV file (default: stdout).")
def simulate(model, scene, algebra, backend, solver, rtol, atol, t_end, dt, step, params,
             project_initial, stats, output):
    """Simulate and write CSV."""
    compiled = _build(model, scene, project_initial, algebra)
    for name, value in (("--rtol", rtol), ("--atol", atol), ("--dt", dt), ("--step", step)):
        if value is not None and not value > 0:
            raise click.UsageError(f"{name} must be positive")
    args = api.run_args(t_end, dt, solver, rtol, atol, step, _parse_params(params, compiled),
                        project_initial) + (["--stats"] if stats else [])
    if backend == "c" and not backends.have_c_compiler():
        click.echo("warning: no C compiler found (cc or $CC); using the Python backend", err=True)
        backend = "python"
    if backend == "c":
        (text,) = emit_c(compiled.program).values()
        code, out, err = backends.run_c(backends.compile_c(text), args)
    else:
        (text,) = emit_python(compiled.program).values()
        code, out, err = backends.run_python(text, args)
    if err:
        click.echo(err, err=True, nl=False)
    if output and (code == 0 or out):
        _write_atomic(output, out)
    elif not output:
        click.echo(out, nl=False)
    sys.exit(0 if code == 0 else 1)


if __name__ == "__main__":  # pragma: no cover
    main()
