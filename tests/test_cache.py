"""The compile cache (bgc.base.cache): the runtime built once and linked with each model's part,
giving the bytes the standalone program gives; and a cache that verifies what it holds and
builds again whatever it cannot run (a program without its mode, a directory in its place, a
truncated or garbage file, a missing or damaged runtime object), without a traceback, also
when many runs share it at once."""
import os
import subprocess
import sys
from pathlib import Path

import pytest

from bgc import api
from bgc.base import cache as compile_cache, processes, toolchain
from bgc.execute import runner
from bgc.codegen.emit import c_runtime_unit, emit_c, linkable
from conftest import MODELS, ROOT, run_bgc

pytestmark = pytest.mark.skipif(not toolchain.have_c_compiler(), reason="no C compiler")

STRICT = ("-O2", "-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic")
# RC charging through R into C from a source V: q(t) = C V (1 - exp(-t / (R C))).
RC = """model rc
parameter V = 2.0
parameter R = 0.5
parameter C = 0.25
src : Se(V)
r : R(R)
c : C(C) init q = 0.0
j : 1
src -> j
j -> r
j -> c
scene charge { outputs c.q; time 0 .. 1 every 0.25; solver dopri5(rtol = 1e-10, atol = 1e-12) }
"""


@pytest.fixture
def cache(tmp_path, monkeypatch):
    path = tmp_path / "cache"
    monkeypatch.setenv("BGC_CACHE_DIR", str(path))
    return path


def _programs(cache: Path) -> list[Path]:
    return sorted(p for p in cache.iterdir() if p.name.startswith("bgc-")
                  and not p.name.endswith((".sha256", ".o")))


def _runtime_objects(cache: Path) -> list[Path]:
    return sorted(cache.glob("bgc-runtime-*.o"))


def _simulate(tmp_path, model=None, *args):
    if model is None:
        model = tmp_path / "rc.bg"
        model.write_text(RC)
        args = ("--scene", "charge", *args)
    done = run_bgc("simulate", model, *args, cwd=tmp_path)
    assert "Traceback" not in done.stderr, done.stderr
    return done


def _check_rc(stdout: str) -> None:
    import math
    rows = [[float(v) for v in line.split(",")] for line in stdout.splitlines()[1:]]
    assert [t for t, _ in rows] == [0.0, 0.25, 0.5, 0.75, 1.0]
    for t, q in rows:
        assert q == pytest.approx(0.5 * (1 - math.exp(-t / 0.125)), rel=1e-8, abs=1e-12)


# ---------------------------------------------------------------- the runtime built once


@pytest.mark.parametrize("model, scene, solvers", [
    ("pendulum", "swing", ("dopri5", "radau", "rodas5p", "rk4")),
    ("diode", None, ("auto", "radau5")),
    ("four_bar", None, ("vern7", "rodas4")),
])
def test_a_linked_program_writes_the_standalone_programs_bytes(cache, model, scene, solvers):
    program = api.build(MODELS / f"{model}.bg", scene).program
    assert linkable(program)
    linked = runner.c_executable(program)
    standalone = compile_cache.compile_c(next(iter(emit_c(program).values())))
    assert linked != standalone
    for solver in solvers:
        args = ["--solver", solver, "--t-end", "0.5"]
        if solver == "rk4":
            args += ["--step", "0.001"]
        a, b = processes.run_c(linked, args), processes.run_c(standalone, args)
        assert a[0] == 0 and a[:2] == b[:2], (solver, a[2])
    usage = processes.run_c(linked, ["--help"])[1]
    assert usage.startswith(f"usage: {model}") and "parameters (NAME = default)" in usage


def test_the_runtime_is_compiled_once_for_every_model(cache, tmp_path):
    first = _simulate(tmp_path)
    assert first.returncode == 0, first.stderr
    _check_rc(first.stdout)
    (runtime,) = _runtime_objects(cache)
    built = runtime.stat().st_mtime_ns
    for model in ("rlc", "pendulum"):
        assert _simulate(tmp_path, MODELS / f"{model}.bg", "--t-end", "0.5").returncode == 0
    assert _runtime_objects(cache) == [runtime] and runtime.stat().st_mtime_ns == built
    assert len(_programs(cache)) == 3


def test_the_runtime_unit_and_a_linked_part_are_strict_c99(tmp_path):
    """Built with every warning an error, the unit and a model part with Newton blocks."""
    program = api.build(MODELS / "diode.bg").program
    for name, text in (("runtime.c", c_runtime_unit()),
                       ("model.c", next(iter(emit_c(program, linked=True).values())))):
        (tmp_path / name).write_text(text)
        done = subprocess.run(["cc", *STRICT, "-c", name, "-o", name + ".o"], cwd=tmp_path,
                              capture_output=True, text=True)
        assert done.returncode == 0, done.stderr


def test_a_model_too_large_for_the_runtime_is_built_standalone(cache, monkeypatch):
    program = api.build(MODELS / "rlc.bg").program
    monkeypatch.setattr("bgc.codegen.emit.LINK_PARAMS", 1)
    assert not linkable(program)
    runner.c_executable(program)
    assert _runtime_objects(cache) == []


def test_a_large_model_part_is_compiled_at_O1_only_under_bgcs_own_flags():
    own = toolchain.C_FLAGS
    assert toolchain.model_part_flags(own, toolchain.LARGE_PART) == own
    assert toolchain.model_part_flags(own, toolchain.LARGE_PART + 1) == toolchain.LARGE_PART_FLAGS
    assert toolchain.LARGE_PART_FLAGS[0] == "-O1" and own[0] == "-O2"
    given = ("-O3", "-std=c99")  # $BGC_CFLAGS: the user's, for every part
    assert toolchain.model_part_flags(given, 10 * toolchain.LARGE_PART) == given


def test_a_part_at_another_level_than_the_runtime_writes_the_same_bytes(cache, monkeypatch):
    """The rule above, with the suite's -O0 as bgc's own flags: the runtime at -O0, the part
    at -O1, the same CSV as the standalone program at -O0 (the arithmetic is IEEE's at any
    level: -std=c99, no -ffast-math)."""
    program = api.build(MODELS / "pendulum.bg", "swing").program
    monkeypatch.setattr(toolchain, "C_FLAGS", toolchain.c_flags())
    monkeypatch.setattr(toolchain, "LARGE_PART", 0)
    built = []
    real = toolchain.build
    monkeypatch.setattr(toolchain, "build", lambda tmp, command, flags, name, *rest:
                        built.append((name, flags)) or real(tmp, command, flags, name, *rest))
    linked = runner.c_executable(program)
    assert ("model.c", toolchain.LARGE_PART_FLAGS) in built
    assert ("runtime.c", toolchain.c_flags()) in built
    standalone = compile_cache.compile_c(next(iter(emit_c(program).values())))
    args = ["--t-end", "0.5", "--solver", "rodas5p"]
    a, b = processes.run_c(linked, args), processes.run_c(standalone, args)
    assert a[0] == 0 and a[:2] == b[:2], a[2]


# ---------------------------------------------------------------- damaged entries


def _damage_program(path: Path, how: str) -> None:
    digest = path.with_name(path.name + ".sha256")
    if how == "mode 644":
        path.chmod(0o644)  # its checksum still valid
    elif how == "directory":
        path.unlink()
        (path / "inside").mkdir(parents=True)
    elif how == "truncated":
        path.write_bytes(path.read_bytes()[:1000])
    elif how == "garbage":
        path.write_bytes(os.urandom(5000))
    elif how == "garbage, checksum forged":
        import hashlib
        data = os.urandom(5000)
        path.write_bytes(data)
        digest.write_text(hashlib.sha256(data).hexdigest() + "\n")
    elif how == "missing":
        path.unlink()
    elif how == "digest a directory":
        digest.unlink()
        digest.mkdir()


@pytest.mark.parametrize("how", ["mode 644", "directory", "truncated", "garbage",
                                 "garbage, checksum forged", "missing", "digest a directory"])
def test_a_damaged_cached_program_is_built_again(cache, tmp_path, how):
    first = _simulate(tmp_path)
    assert first.returncode == 0, first.stderr
    _check_rc(first.stdout)
    (exe,) = _programs(cache)
    _damage_program(exe, how)
    again = _simulate(tmp_path)  # warm: the record names the damaged program
    assert (again.returncode, again.stdout, again.stderr) == (0, first.stdout, first.stderr)
    assert _programs(cache) == [exe] and compile_cache.usable(exe)
    assert processes.run_c(exe, [])[1] == first.stdout


@pytest.mark.parametrize("how", ["missing", "truncated", "garbage, checksum forged",
                                 "directory"])
def test_a_damaged_runtime_object_is_built_again(cache, tmp_path, how):
    assert _simulate(tmp_path).returncode == 0
    (runtime,) = _runtime_objects(cache)
    _damage_program(runtime, how)
    done = _simulate(tmp_path, MODELS / "rlc.bg", "--t-end", "0.5")  # a new model: it links
    assert done.returncode == 0 and done.stdout.startswith("t,"), done.stderr
    assert _runtime_objects(cache) == [runtime] and compile_cache.usable(runtime, executable=False)


def test_a_program_that_cannot_start_in_the_api_is_built_again(cache):
    compiled = api.build(MODELS / "rlc.bg")
    first = runner.run(compiled, compiled.program.scene)
    (exe,) = _programs(cache)
    _damage_program(exe, "garbage, checksum forged")
    second = runner.run(compiled, compiled.program.scene)
    assert (second.status, second.csv) == (0, first.csv)


def test_a_cache_where_programs_cannot_start_is_told_in_one_line(cache, tmp_path, monkeypatch):
    def refuse(argv, **options):
        raise processes.CannotStart(argv, PermissionError(13, "Permission denied"))
    monkeypatch.setattr(processes, "_start", refuse)
    done = _simulate(tmp_path)
    assert done.returncode == 1
    assert done.stderr.startswith("error: cannot start the program") and \
        "BGC_CACHE_DIR" in done.stderr


def test_a_full_disk_while_building_is_told_in_one_line(cache, tmp_path, monkeypatch):
    import errno

    def full(*args, **kwargs):
        raise OSError(errno.ENOSPC, "No space left on device")
    monkeypatch.setattr(toolchain, "run_compiler", full)
    done = _simulate(tmp_path, None, "-o", "out.csv")
    assert done.returncode == 1 and not (tmp_path / "out.csv").exists()
    assert done.stderr == f"error: cannot write into the compile cache {cache}: No space left " \
                          "on device\n"
    assert [p.name for p in cache.iterdir() if not p.name.startswith("lark-")] == []


# ---------------------------------------------------------------- runs at once


def test_concurrent_runs_share_one_cache(tmp_path):
    """Six `bgc simulate` processes, two each of three models, start together on an empty
    cache: every one builds or finds the runtime (six at once) and its program (two at once),
    and writes the right CSV."""
    cache = tmp_path / "cache"
    rc = tmp_path / "rc.bg"
    rc.write_text(RC)
    models = [rc, MODELS / "rlc.bg", MODELS / "pendulum.bg"] * 2
    env = dict(os.environ, BGC_CACHE_DIR=str(cache), PYTHONPATH=str(ROOT))
    procs = [subprocess.Popen([sys.executable, "-m", "bgc", "simulate", str(m), "--t-end", "1",
                               *(["--scene", "charge"] if m == rc else []),
                               "-o", str(tmp_path / f"out{k}.csv")], env=env, cwd=tmp_path,
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
             for k, m in enumerate(models)]
    results = [(p.wait(timeout=120), p.stderr.read()) for p in procs]
    for p in procs:
        p.stdout.close()
        p.stderr.close()
    assert all(code == 0 for code, _ in results), results
    assert not any("Traceback" in err for _, err in results)
    _check_rc((tmp_path / "out0.csv").read_text())
    for k, m in enumerate(models[:3]):
        alone = run_bgc("simulate", m, "--t-end", "1", *(["--scene", "charge"] if m == rc else []),
                        cwd=tmp_path)  # (one process, the run's own cache: not this test's)
        for out in range(k, len(models), 3):
            assert (tmp_path / f"out{out}.csv").read_text() == alone.stdout
    assert len(_runtime_objects(cache)) == 1 and len(_programs(cache)) == 3
    assert all(compile_cache.usable(p) for p in _programs(cache))
    assert not [p.name for p in cache.iterdir() if p.name.startswith(("build-", "."))]


def test_a_run_copies_what_the_install_prebuilt_instead_of_building_it(tmp_path, monkeypatch):
    """setup.py runs bgc.execute.prebuild into the package's prebuilt/ directory: the interpreter,
    the
    runtime object and the parser's tables, named as the cache names them.  A run whose cache
    lacks one copies it from there (checked, no compiler run); a damaged one is built."""
    from bgc.front import parser
    from bgc.codegen import vm
    seeds = tmp_path / "prebuilt"
    monkeypatch.setenv("BGC_CACHE_DIR", str(seeds))  # what stands for the package's directory
    vm.interpreter()
    runtime = compile_cache.compile_runtime(c_runtime_unit())
    parser.lark_parser.cache_clear()
    parser.lark_parser()
    monkeypatch.setattr(compile_cache, "PREBUILT", seeds)
    cache = tmp_path / "cache"
    monkeypatch.setenv("BGC_CACHE_DIR", str(cache))

    def no_compiler(*args, **kwargs):
        raise AssertionError("the compiler was run")
    monkeypatch.setattr(toolchain, "run_compiler", no_compiler)
    try:
        for built in (vm.interpreter(), compile_cache.compile_runtime(c_runtime_unit())):
            assert built.parent == cache and compile_cache.usable(built, built.suffix != ".o")
            assert built.read_bytes() == (seeds / built.name).read_bytes()
        assert runtime.name in {p.name for p in cache.iterdir()}
        parser.lark_parser.cache_clear()
        assert parser.parse("model m\nc : C(1)\n", "m.bg").decls
        assert [p.name for p in cache.glob("lark-*.pickle")] == \
            [p.name for p in seeds.glob("lark-*.pickle")]
    finally:
        parser.lark_parser.cache_clear()
    # a seed whose checksum does not match is not used
    (seeds / "bgc-x").write_bytes(b"damaged")
    (seeds / "bgc-x.sha256").write_text("0" * 64 + "\n")

    def build(tmp):
        (tmp / "x").write_bytes(b"new")
        return tmp / "x"
    assert compile_cache._cached("bgc-x", False, build).read_bytes() == b"new"
