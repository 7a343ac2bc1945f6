"""The interpreter backend (bgc/codegen/vm.py, bgc/runtime/vm.c): the same CSV bytes as the C
program and the Python module, on models with constraint rows, a linear block, a Newton block,
events, tables and inputs, with explicit and stiff solvers (the spans short: a few steps go
through every code path); the choice `bgc simulate` makes by itself, and a program file the
interpreter refuses."""
from pathlib import Path

import pytest

import bgc
from bgc.base import processes, toolchain
from bgc.execute import runner
from bgc.codegen import vm
from bgc.api import Source, build

from conftest import run_bgc
from helpers import ball

ROOT = Path(__file__).resolve().parent.parent
pytestmark = pytest.mark.skipif(not toolchain.have_c_compiler(), reason="no C compiler")

BALL = ball("scene drop { time 0 .. 1 every 0.01; outputs x, b.p }")

# model -> (the run's settings, solvers); the Python module is run on the first solver
CASES = {
    "pendulum.bg": ({"t_end": 0.3}, ("dopri5", "rodas5p")),  # constraint rows, projection
    "diode.bg": ({"t_end": 0.2}, ("radau5", "dopri5")),  # a Newton block
    "two_link_arm.bg": ({"t_end": 0.2}, ("radau5", "vern7")),  # a linear block, its tangent
    "pendulum_wall.bg": ({"t_end": 1.0}, ("dopri5",)),  # events, a block
    "ball": ({}, ("dopri5", "rk4")),  # a when-block
}


def _compiled(name):
    return build(Source("ball.bg", BALL) if name == "ball" else ROOT / "models" / name)


@pytest.mark.parametrize("name", list(CASES))
def test_same_bytes_as_c_and_python(name):
    compiled = _compiled(name)
    options, methods = CASES[name]
    c = runner.prepare(compiled, "c")
    interpreted = runner.prepare(compiled, "vm")
    assert interpreted.interpreter is not None and interpreted.path.suffix == ".bgvm"
    for k, method in enumerate(methods):
        settings = compiled.program.scene.with_options(solver=method, **options)
        want = runner.run(c, settings, stats=True)
        got = runner.run(interpreted, settings, stats=True)
        assert want.status == 0, want.stderr
        assert got.csv == want.csv, (name, method)
        assert got.stats["rhs"] == want.stats["rhs"] and got.stats["steps"] == want.stats["steps"]
        if k == 0:  # (the module in this process: its rows as its main writes them)
            module = runner.prepare(compiled, "python", in_process=True).module
            rows = module.rows(**settings.options(compiled.program.scene))
            text = ",".join(["t"] + module.OUTPUTS) + "\n" + "".join(
                module._row_text(t, y) for t, y in rows)
            assert text == want.csv, (name, method, "python")


TABLES = """model tabs "every kind of table: of t and of a state, each interp and extrapolate"
input u = 0.25
signal a = table([[0, 1], [0.3, 2], [0.3, 0.5], [0.8, 1.5]], t)
signal b = table([[0, 1], [0.25, 2], [0.6, -1]], t, interp = step, extrapolate = linear)
signal c = table([[-1, 0], [0, 0.1], [0.5, 1.4], [1, 1.5], [2, 0.2]], x, interp = cubic,
                 extrapolate = linear)
signal d = table([[0, 0], [0.4, 1], [3, 2]], x + 1, extrapolate = error)
signal e = table(ramp.csv, t, interp = cubic)
signal f = table([[0, 2], [1, 0.5]], 3*x, interp = step)
signal x = integral(a + b - 2*c + d - e + f*u, init = 0.2)
scene run { time 0 .. 1 every 0.05; outputs x, a, b, c, d, e, u }
"""


def test_tables_and_inputs_as_the_c_program_and_python(tmp_path):
    """Tables of t (time events) and of a state (searched at each call, differentiated for the
    stiff solver's Jacobian), linear, step and cubic, held, extended and guarded, a table file
    and an input's data with a jump: the interpreter writes the C program's and the Python
    module's bytes, its event log too; a run that reads a table outside its rows (extrapolate
    = error) stops there as they do."""
    (tmp_path / "ramp.csv").write_text("x,y\n-1,0\n0.2,0.3\n0.5,0.1\n0.9,0.7\n")
    (tmp_path / "u.csv").write_text("t,u\n0,0\n0.35,1\n0.35,-0.5\n0.7,0.5\n")
    for text, fails in ((TABLES, False), (TABLES.replace("[3, 2]]", "[1.25, 2]]"), True)):
        compiled = build(Source(str(tmp_path / "tabs.bg"), text), "run")
        programs = {b: runner.prepare(compiled, b) for b in ("c", "vm", "python")}
        for method in ("dopri5", "radau5"):
            got = {}
            for backend, program in programs.items():
                log = tmp_path / f"{backend}.events.csv"
                settings = compiled.program.scene.with_options(
                    solver=method, events=str(log), input_files=(str(tmp_path / "u.csv"),))
                result = runner.run(program, settings)
                got[backend] = (result.status, result.csv, result.stderr, log.read_bytes())
            assert got["vm"] == got["c"] == got["python"], method
            assert (got["c"][0] != 0) == fails and got["c"][1].count("\n") > 1
            if fails:
                assert "is read outside its rows" in got["c"][2]


def test_parameters_and_a_failed_block_as_the_c_program():
    """-p overrides (a derived parameter's default follows), and a run that fails keeps the
    same rows and says the same."""
    compiled = _compiled("pendulum.bg")
    c, interpreted = runner.prepare(compiled, "c"), runner.prepare(compiled, "vm")
    for params in ({"l": 0.7}, {"g": float("nan")}):
        settings = runner.settings_for(compiled.program.scene, ["g", "l", "m", "theta0"],
                                       params, t_end=0.2)
        want, got = runner.run(c, settings), runner.run(interpreted, settings)
        assert (got.status, got.csv, got.stderr) == (want.status, want.csv, want.stderr)


def test_api_backend_vm():
    t, y, names = bgc.simulate(ROOT / "models" / "rlc.bg", backend="vm", t_end=0.01)
    t2, y2, names2 = bgc.simulate(ROOT / "models" / "rlc.bg", backend="c", t_end=0.01)
    assert names == names2 and (t == t2).all() and (y == y2).all()


def test_simulate_chooses_the_interpreter_for_a_short_run(tmp_path, monkeypatch):
    model = tmp_path / "rlc.bg"
    model.write_bytes((ROOT / "models" / "rlc.bg").read_bytes())
    env = {"BGC_CACHE_DIR": str(tmp_path / "cache"), "BGC_BACKEND": "auto"}
    # (the interpreter, built once per machine, is shared from the default cache)
    (tmp_path / "cache").mkdir()
    interp = vm.interpreter()
    for suffix in ("", ".sha256"):
        (tmp_path / "cache" / (interp.name + suffix)).write_bytes(
            Path(str(interp) + suffix).read_bytes())
    (tmp_path / "cache" / interp.name).chmod(0o755)

    first = run_bgc("simulate", str(model), "-o", str(tmp_path / "a.csv"), env=env)
    assert first.returncode == 0, first.stderr
    assert first.stderr.strip().splitlines() == [runner.INTERPRETED]
    assert not [p for p in (tmp_path / "cache").glob("bgc-*") if p.suffix == "" and
                not p.name.startswith("bgc-vm-")]  # no C program built
    again = run_bgc("simulate", str(model), "-o", str(tmp_path / "b.csv"), env=env)
    assert again.stderr.strip().splitlines() == [runner.INTERPRETED]  # (warm)
    built = run_bgc("simulate", str(model), "--backend", "c", "-o", str(tmp_path / "c.csv"),
                    env=env)
    assert built.returncode == 0 and built.stderr == ""
    after = run_bgc("simulate", str(model), "-o", str(tmp_path / "d.csv"), env=env)
    assert after.stderr == ""  # the model's build is cached: C
    texts = {(tmp_path / f"{k}.csv").read_bytes() for k in "abcd"}
    assert len(texts) == 1
    # a long run of a model not built before is built
    monkeypatch.setattr(runner, "VM_WORK", 10)
    model.write_text(model.read_text() + "\n")
    long = run_bgc("simulate", str(model), "-o", str(tmp_path / "e.csv"), env=env)
    assert long.returncode == 0 and long.stderr == ""
    assert (tmp_path / "e.csv").read_bytes() in texts


def test_a_damaged_program_is_refused(tmp_path):
    compiled = _compiled("rlc.bg")
    data = vm.program_bytes(compiled.program)
    interp = vm.interpreter()
    for k, bad in enumerate([data[:-4], data[:40], b"garbage", data[:-8] + b"\xff" * 8]):
        path = tmp_path / f"p{k}.bgvm"
        path.write_bytes(bad)
        done = processes.run_captured([str(interp), str(path)])
        assert done.returncode == 3 and "is not a program this interpreter runs" in done.stderr
        assert done.stdout == ""
