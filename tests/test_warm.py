"""Warm runs (bgc.execute.warm): a model `bgc simulate` has compiled before runs from its cached
program without SymPy, exactly as a cold run would; anything that changes the program misses."""
import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from conftest import MODELS, ROOT, have_cc, run_bgc

BACKEND = "c" if have_cc() else "python"

# An RC circuit with a junction that has no bonds (a warning) and a closed form:
# q(t) = C V (1 - exp(-t/(R C))).
RC = textwrap.dedent("""\
    model rc
    parameter V = 2.0
    parameter R = 0.5
    parameter C = 0.25
    src : Se(V)
    r : R(R)
    c : C(C) init q = 0.0
    spare : 0
    j : 1
    src -> j
    j -> r
    j -> c
    scene charge {
      outputs c.q
      time 0 .. 1 every 0.25
    }
    """)


def _closed_form(t, V=2.0, R=0.5, C=0.25):
    import math
    return C * V * (1 - math.exp(-t / (R * C)))


@pytest.fixture
def cache(tmp_path, monkeypatch):
    path = tmp_path / "cache"
    monkeypatch.setenv("BGC_CACHE_DIR", str(path))
    return path


def _model(tmp_path, text=RC) -> Path:
    path = tmp_path / "rc.bg"
    path.write_text(text)
    return path


def _rows(stdout: str) -> list[list[float]]:
    return [[float(v) for v in line.split(",")] for line in stdout.splitlines()[1:]]


def test_a_warm_run_equals_the_cold_run_and_an_edit_misses(tmp_path, cache):
    model = _model(tmp_path)
    args = ["simulate", model, "--scene", "charge", "--backend", BACKEND, "--solver", "dopri5",
            "--rtol", "1e-10", "--atol", "1e-12"]
    cold = run_bgc(*args)
    assert cold.returncode == 0, cold.stderr
    assert "junction 'spare' has no bonds" in cold.stderr
    for t, q in _rows(cold.stdout):
        assert q == pytest.approx(_closed_form(t), rel=1e-8, abs=1e-12)
    records = sorted(cache.glob("warm-*.json"))
    assert len(records) == 1
    record = json.loads(records[0].read_text())
    assert record["params"] == ["V", "R", "C"] and record["settings"]["solver"] \
        and not record["correctors"]

    warm = run_bgc(*args)
    assert (warm.returncode, warm.stdout, warm.stderr) == (0, cold.stdout, cold.stderr)
    # the warm path checks what the cold path checks, with the same words
    for extra in (["-p", "L=1"], ["--t-end", "-1"]):
        bad_warm = run_bgc(*args, *extra)
        records[0].unlink()
        bad_cold = run_bgc(*args, *extra)
        assert bad_warm.returncode == bad_cold.returncode == 2
        assert bad_warm.stderr == bad_cold.stderr
    # overrides reach the cached program
    warm = run_bgc(*args, "-p", "V=4")
    assert _rows(warm.stdout)[-1][1] == pytest.approx(_closed_form(1.0, V=4.0), rel=1e-8)

    # an edit misses (same path, other text)
    model.write_text(RC.replace("parameter V = 2.0", "parameter V = 3.0"))
    edited = run_bgc(*args)
    assert _rows(edited.stdout)[-1][1] == pytest.approx(_closed_form(1.0, V=3.0), rel=1e-8)
    assert len(list(cache.glob("warm-*.json"))) == 2


def test_a_tampered_program_or_record_is_not_used(tmp_path, cache):
    model = _model(tmp_path)
    args = ["simulate", model, "--scene", "charge", "--backend", BACKEND]
    cold = run_bgc(*args)
    (record,) = cache.glob("warm-*.json")
    program = cache / json.loads(record.read_text())["program"]
    program.write_bytes(b"#!/bin/sh\necho tampered\n")
    assert run_bgc(*args).stdout == cold.stdout  # rebuilt: the SHA-256 did not match
    record.write_text("{not json")
    assert run_bgc(*args).stdout == cold.stdout
    data = json.loads(record.read_text())  # rewritten whole by the cold run
    data["program"] = "../elsewhere"
    record.write_text(json.dumps(data))
    assert run_bgc(*args).stdout == cold.stdout


def test_a_fixed_step_on_a_corrector_is_checked_warm_or_cold(tmp_path, cache):
    args = ["simulate", MODELS / "pendulum.bg", "--scene", "swing", "--backend", "python",
            "--solver", "rk4", "--step", "0.6", "--t-end", "1.2"]
    first, second = run_bgc(*args), run_bgc(*args)
    assert "is unstable on the corrector" in first.stderr
    assert first.stderr == second.stderr and first.stdout == second.stdout


@pytest.mark.skipif(sys.platform == "win32", reason="POSIX paths in the command")
def test_warm_run_and_help_do_not_import_sympy(tmp_path, cache):
    """In a fresh interpreter: after one cold run, a warm `bgc simulate` and `bgc --help`
    import neither SymPy nor numpy (nor jinja2, lark)."""
    model = _model(tmp_path)
    args = ["simulate", str(model), "--scene", "charge", "--backend", "python"]
    assert run_bgc(*args).returncode == 0
    probe = textwrap.dedent("""\
        import sys
        from bgc.cli import main
        try:
            main(sys.argv[1:])
        except SystemExit as exit:
            code = exit.code
        heavy = sorted(m for m in ("sympy", "numpy", "jinja2", "lark") if m in sys.modules)
        print("IMPORTED", code, ",".join(heavy) or "-", file=sys.stderr)
        """)
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    for argv in (args, ["--help"]):
        done = subprocess.run([sys.executable, "-c", probe, *argv], capture_output=True,
                              text=True, env=env, timeout=60)
        assert done.stderr.splitlines()[-1] == "IMPORTED 0 -", done.stderr


def test_an_edited_table_file_or_an_import_after_a_semicolon_misses(tmp_path, cache):
    """The table's rows are compiled into the program, the library's laws too: a warm run of
    the same model text must see the edited file (each recorded with its SHA-256)."""
    model = tmp_path / "tab.bg"
    model.write_text("model tab\nsignal a = table(data.csv, t)\n"
                     "scene run { outputs a; time 0 .. 1 every 1 }\n")
    args = ["simulate", model, "--scene", "run", "--backend", BACKEND]
    for last in ("3", "9", "9", "4"):
        (tmp_path / "data.csv").write_text(f"x,y\n0,1\n1,{last}\n")
        run = run_bgc(*args)
        assert run.returncode == 0, run.stderr
        assert _rows(run.stdout) == [[0.0, 1.0], [1.0, float(last)]]
    (record,) = cache.glob("warm-*.json")  # one record, rewritten by each cold run
    assert [f[0] for f in json.loads(record.read_text())["files"]] == [str(tmp_path / "data.csv")]

    lib = tmp_path / "slib.bg"
    semi = tmp_path / "semi.bg"
    semi.write_text("model semi; import slib\nsrc : Se(1)\nj : 1\nr : slib.res(r = 2)\n"
                    "src -> j\nj -> r.p\nscene run { outputs r.x.f; time 0 .. 1 every 1 }\n")
    for factor in ("1", "5"):
        lib.write_text(f"library slib\ncomponent res(r = 1) {{\n  port p\n  x : R({factor}*r)\n"
                       "  p -> x\n}\n")
        run = run_bgc("simulate", semi, "--scene", "run", "--backend", BACKEND)
        assert run.returncode == 0, run.stderr
        assert _rows(run.stdout)[-1][1] == pytest.approx(1 / (2 * float(factor)), rel=1e-12)


IMPORTING = textwrap.dedent("""\
    model importing
    import electrical as e
    import mylib
    parameter V = 3
    src : Se(V)
    a : 0
    b : 0
    res : e.resistor(r = 1)
    load : mylib.load(r = 2)
    src -> a
    a -> res.p
    res.n -> b
    b -> load.p
    scene run { outputs load.x.f; time 0 .. 1 every 1 }
    """)


def _load_library(factor) -> str:
    return f"library mylib\ncomponent load(r = 1) {{\n  port p\n  x : R({factor}*r)\n  p -> x\n}}\n"


def test_a_model_importing_libraries_runs_warm_and_sees_an_edited_library(tmp_path, cache,
                                                                          monkeypatch):
    """The standard library's electrical and a library beside the model: the second run uses
    the record (no compile); an edit of the library, or a library of the standard one's name
    made beside the model (which an import finds first), is compiled and seen.  The current
    through the series resistors: V / (1 + factor * 2)."""
    from bgc import cli
    from bgc.execute import warm
    compiles, found = [], []
    real_compile, real_lookup = cli._compile_for_run, warm.lookup
    monkeypatch.setattr(cli, "_compile_for_run",
                        lambda *a, **k: compiles.append(1) or real_compile(*a, **k))
    monkeypatch.setattr(warm, "lookup",
                        lambda *a, **k: found.append(real_lookup(*a, **k)) or found[-1])
    model = tmp_path / "importing.bg"
    model.write_text(IMPORTING)
    lib = tmp_path / "mylib.bg"

    def current():
        done = run_bgc("simulate", model, "--scene", "run", "--backend", "python")
        assert done.returncode == 0, done.stderr
        return _rows(done.stdout)[-1][1]
    for factor, runs in (("1", 2), ("4", 1)):
        lib.write_text(_load_library(factor))
        for k in range(runs):
            del compiles[:], found[:]
            assert current() == pytest.approx(3 / (1 + 2 * float(factor)), rel=1e-12)
            assert (len(compiles), found[0] is not None) == ((1, False) if k == 0 else
                                                              (0, True))
    (record,) = cache.glob("warm-*.json")
    files = dict(map(tuple, json.loads(record.read_text())["files"]))
    assert files[str(tmp_path / "electrical.bg")] is None  # looked at first, no file
    assert files[str(lib)] is not None and len(files) == 3
    # a library made where an import looks first: found now, so the record is not used
    (tmp_path / "electrical.bg").write_text(
        "library electrical\ncomponent resistor(r = 1) {\n  port p, n\n  s : 1\n"
        "  x : R(10*r)\n  p -> s\n  s -> x\n  s -> n\n}\n")
    del compiles[:]
    assert current() == pytest.approx(3 / (10 + 2 * 4), rel=1e-12)
    assert len(compiles) == 1
