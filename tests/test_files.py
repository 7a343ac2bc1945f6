"""What `bgc simulate` and `bgc compile` do with files: output paths checked before any work,
files created with the user's umask and renamed into place, a run's CSV streamed (memory does
not grow with it), a failed or interrupted run's rows kept, nothing hidden left behind; the
compile cache keyed by the compiler and verified before use, a broken compiler told as such;
and the Python module's streaming interface.  Values are checked against closed forms."""
import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from bgc.base import processes, toolchain
from conftest import MODELS, run_bgc

needs_cc = pytest.mark.skipif(not toolchain.have_c_compiler(), reason="no C compiler")
BACKENDS = ["python"] + (["c"] if toolchain.have_c_compiler() else [])

BLOW = """model blow
signal z = integral(z^2, init = 1)
scene s { outputs z; time 0 .. 2 every 0.1 }
"""
DECAY = """model decay
signal z = integral(-z, init = 1)
scene s { outputs z; time 0 .. 1e5 every 0.001; solver rk4(step = 0.001) }
"""


def bgc(*args, cwd, env=None, umask=None):
    return run_bgc(*args, cwd=cwd, env=env, umask=umask)


def _leftovers(directory: Path) -> list[str]:
    return sorted(p.name for p in directory.iterdir() if p.name.startswith("."))


@pytest.mark.parametrize("target, why", [
    ("missing/out.csv", "directory 'missing' does not exist"),
    (".", "it is a directory"),
    ("afile/out.csv", "directory 'afile' does not exist"),
])
def test_an_output_path_that_cannot_be_written_is_a_usage_error_before_any_work(tmp_path,
                                                                                 target, why):
    (tmp_path / "afile").write_text("")
    for command in ("simulate", "compile"):
        done = bgc(command, MODELS / "rlc.bg", "-o", target, cwd=tmp_path)
        assert done.returncode == 2, done.stderr
        assert why in done.stderr and "Traceback" not in done.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["afile"]


@pytest.mark.parametrize("umask", [0o022, 0o077])
def test_output_files_get_the_users_umask(tmp_path, umask):
    for command, name in (("compile", "rlc.c"), ("simulate", "rlc.csv")):
        done = bgc(command, MODELS / "rlc.bg", "--backend" if command == "simulate" else
                   "--target", "python", "-o", name, cwd=tmp_path, umask=umask)
        assert done.returncode == 0, done.stderr
        assert (tmp_path / name).stat().st_mode & 0o777 == 0o666 & ~umask
    assert _leftovers(tmp_path) == []


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_failed_run_keeps_its_rows_in_the_named_file_and_says_so(tmp_path, backend):
    """z' = z^2, z(0) = 1: z = 1/(1 - t) until the step size underflows near t = 1."""
    (tmp_path / "blow.bg").write_text(BLOW)
    (tmp_path / "out.csv").write_text("an older result\n")
    done = bgc("simulate", "blow.bg", "--scene", "s", "--backend", backend, "-o", "out.csv",
               cwd=tmp_path)
    assert done.returncode == 1
    lines = done.stderr.strip().splitlines()
    assert "step size too small" in lines[-2]
    assert lines[-1] == "bgc: the run stopped; the rows up to t = 1 are in out.csv"
    data = np.loadtxt(tmp_path / "out.csv", delimiter=",", skiprows=1)
    assert data[-1, 0] == 1.0 and len(data) == 11
    t = data[:-1, 0]
    assert np.allclose(data[:-1, 1], 1 / (1 - t), rtol=1e-5)
    assert _leftovers(tmp_path) == []


def test_a_run_that_computes_no_row_leaves_an_existing_file_alone(tmp_path):
    """Initial values off the constraint (init = -2 l^2 where x^2 + y^2 = l^2): refused."""
    bad = (MODELS / "pendulum.bg").read_text().replace("init = -l^2", "init = -2*l^2")
    (tmp_path / "bad.bg").write_text(bad)
    (tmp_path / "pend.csv").write_text("an older result\n")
    done = bgc("simulate", "bad.bg", "--scene", "swing", "--backend", "python", "-o",
               "pend.csv", cwd=tmp_path)
    assert done.returncode == 1 and "Traceback" not in done.stderr
    assert (tmp_path / "pend.csv").read_text() == "an older result\n"
    assert _leftovers(tmp_path) == []


@pytest.mark.parametrize("backend", BACKENDS)
def test_an_interrupted_run_keeps_the_rows_computed(tmp_path, backend):
    """SIGTERM to bgc: the program stops at its next step; the rows so far are renamed into
    place (z = exp(-t) at rk4's accuracy), exit status 128 + 15, nothing hidden left."""
    (tmp_path / "decay.bg").write_text(DECAY)
    proc = subprocess.Popen([sys.executable, "-m", "bgc", "simulate", "decay.bg", "--scene", "s",
                             "--backend", backend, "-o", "out.csv"], cwd=tmp_path,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and proc.poll() is None:  # until rows arrive
        parts = [p for p in tmp_path.iterdir() if p.name.endswith(".part")]
        if parts and parts[0].stat().st_size > 100_000:
            break
        time.sleep(0.05)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 128 + signal.SIGTERM, err
    assert "interrupted by signal 15" in err and "are in out.csv" in err.strip().splitlines()[-1]
    data = np.loadtxt(tmp_path / "out.csv", delimiter=",", skiprows=1)
    assert len(data) > 1000
    assert np.allclose(data[:, 1], np.exp(-data[:, 0]), rtol=1e-9)
    assert _leftovers(tmp_path) == []


@needs_cc
def test_memory_does_not_grow_with_the_csv(tmp_path):
    """bgc's own peak memory is the same for a CSV 100 times longer (about 0.5 and 50 MB)."""
    (tmp_path / "decay.bg").write_text(DECAY)
    peaks = []
    for t_end in (10, 1000):
        proc = subprocess.Popen([sys.executable, "-m", "bgc", "simulate", "decay.bg", "--scene",
                                 "s", "--t-end", str(t_end), "-o", "out.csv"], cwd=tmp_path,
                                stderr=subprocess.PIPE)
        _, status, usage = os.wait4(proc.pid, 0)
        assert status == 0
        peaks.append(usage.ru_maxrss * 1024)  # bytes, on Linux
    size = (tmp_path / "out.csv").stat().st_size
    assert size > 25e6
    assert peaks[1] - peaks[0] < 0.1 * size


@needs_cc
def test_the_cache_rebuilds_a_program_that_is_not_the_one_built(tmp_path):
    env = {"BGC_CACHE_DIR": str(tmp_path / "cache")}
    first = bgc("simulate", MODELS / "rlc.bg", "--t-end", "1", cwd=tmp_path, env=env)
    assert first.returncode == 0
    (exe,) = [p for p in (tmp_path / "cache").iterdir() if p.name.startswith("bgc-")
              and not p.name.endswith((".sha256", ".o"))]
    exe.write_bytes(b"#!/bin/sh\necho t,forged\n")  # someone replaced the cached binary
    second = bgc("simulate", MODELS / "rlc.bg", "--t-end", "1", cwd=tmp_path, env=env)
    assert second.returncode == 0 and second.stdout == first.stdout


@needs_cc
def test_an_unwritable_cache_directory_falls_back_to_a_temporary_one(tmp_path):
    (tmp_path / "file").write_text("")
    env = {"BGC_CACHE_DIR": str(tmp_path / "file" / "cache")}
    done = bgc("simulate", MODELS / "rlc.bg", "--t-end", "1", cwd=tmp_path, env=env)
    assert done.returncode == 0, done.stderr
    assert "cannot be written" in done.stderr and done.stdout.startswith("t,")


@needs_cc
def test_a_broken_compiler_is_told_as_such_not_as_a_bug_in_bgc(tmp_path):
    env = {"CC": "false", "BGC_CACHE_DIR": str(tmp_path / "cache")}
    done = bgc("simulate", MODELS / "rlc.bg", "-o", "out.csv", cwd=tmp_path, env=env)
    assert done.returncode == 1 and "Traceback" not in done.stderr
    assert "the C compiler does not work" in done.stderr and "bug in bgc" not in done.stderr
    assert not (tmp_path / "out.csv").exists() and _leftovers(tmp_path) == []


@needs_cc
def test_generated_c_refuses_fast_math(tmp_path):
    done = bgc("compile", MODELS / "rlc.bg", "-o", "rlc.c", cwd=tmp_path)
    assert done.returncode == 0
    cc = toolchain.c_compiler()  # the guard is in the preprocessor: -E is enough
    fast = subprocess.run([*cc, "-E", "-ffast-math", "-std=c99", "rlc.c", "-o", "rlc.i"],
                          cwd=tmp_path, capture_output=True, text=True)
    assert fast.returncode != 0 and "-ffast-math" in fast.stderr
    allowed = subprocess.run([*cc, "-E", "-ffast-math", "-DBGC_ALLOW_FAST_MATH", "-std=c99",
                              "rlc.c", "-o", "rlc.i"], cwd=tmp_path, capture_output=True)
    plain = subprocess.run([*cc, "-E", "-std=c99", "rlc.c", "-o", "rlc.i"], cwd=tmp_path,
                           capture_output=True)
    assert allowed.returncode == 0 and plain.returncode == 0


def test_the_python_module_streams_rows_to_a_file_or_yields_them(tmp_path):
    """rows() and simulate(out=...) give what simulate() returns, and the CSV the program
    writes; z = exp(-t) at rk4's accuracy."""
    from bgc.api import Source, build
    from bgc.codegen.emit import emit_python

    (text,) = emit_python(build(Source("decay.bg", DECAY), "s").program).values()
    module = processes.load_python_module(text)
    t, Y = module.simulate(t_end=2.0, dt=0.01)
    assert np.allclose(Y[:, 0], np.exp(-t), rtol=1e-9)
    stats = {}
    rows = list(module.rows(t_end=2.0, dt=0.01, stats=stats))
    assert [r[0] for r in rows] == list(t) and [r[1] for r in rows] == Y.tolist()
    assert stats["steps"] == 2000
    assert module.simulate(t_end=2.0, dt=0.01, out=tmp_path / "a.csv") == len(t)
    code, out, _ = processes.run_python(text, ["--t-end", "2", "--dt", "0.01"])
    assert code == 0 and (tmp_path / "a.csv").read_text() == out
    gen = module.rows(t_end=1e5, dt=0.01)  # a generator stops when its consumer does
    first = [next(gen) for _ in range(3)]
    gen.close()
    assert [r[0] for r in first] == [0.0, 0.01, 0.02]
    assert math.isclose(first[2][1][0], math.exp(-0.02), rel_tol=1e-9)
