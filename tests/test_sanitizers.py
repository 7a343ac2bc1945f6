"""Generated C programs built with AddressSanitizer and UndefinedBehaviorSanitizer
(-fsanitize=address,undefined, every finding fatal) run clean: models chosen to cover the
runtime's paths (a constrained mechanism with projection, an unrolled linear block, a Newton
block, vector bonds with a larger block, the stiff solvers and their Jacobians, a run that
fails, a run interrupted by a signal).  Skipped where the compiler cannot build and run a
sanitized program.  Correct values are the other tests' business: here, no finding."""
import os
import signal
import subprocess
import time
from pathlib import Path

import pytest

import bgc
from bgc.base import toolchain
from bgc.api import Source
from bgc.codegen.emit import emit_c
from conftest import MODELS

FLAGS = ["-O0", "-std=c99", "-fsanitize=address,undefined", "-fno-sanitize-recover=all"]
ENV = dict(os.environ, ASAN_OPTIONS="abort_on_error=0:detect_leaks=1:exitcode=99",
           UBSAN_OPTIONS="print_stacktrace=1:halt_on_error=1:exitcode=98")


def _sanitizers_work(tmp) -> bool:
    if not toolchain.have_c_compiler():
        return False
    src = tmp / "probe.c"
    src.write_text("#include <stdlib.h>\nint main(void) { free(malloc(8)); return 0; }\n")
    try:
        subprocess.run([*toolchain.c_compiler(), *FLAGS, str(src), "-o", str(tmp / "probe")],
                       check=True, capture_output=True)
        subprocess.run([str(tmp / "probe")], check=True, capture_output=True, env=ENV)
    except (OSError, subprocess.CalledProcessError):
        return False
    return True


@pytest.fixture(scope="module")
def sanitized(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("san")
    if not _sanitizers_work(tmp):
        pytest.skip("the C compiler cannot build and run sanitized programs here")

    def build(model, scene=None, project_initial=False):
        (text,) = emit_c(bgc.build(model, scene, project_initial).program).values()
        name = Path(str(model.path if isinstance(model, Source) else model)).stem + (scene or "")
        src, exe = tmp / f"{name}.c", tmp / name
        src.write_text(text)
        subprocess.run([*toolchain.c_compiler(), *FLAGS, str(src), "-o", str(exe), "-lm"],
                       check=True, capture_output=True)
        return exe
    return build


def _run(exe, *args, code=0):
    done = subprocess.run([str(exe), *map(str, args)], capture_output=True, text=True, env=ENV)
    assert "Sanitizer" not in done.stderr and "runtime error" not in done.stderr, done.stderr
    assert done.returncode == code, done.stderr
    return done


RUNS = {  # model, scene, project: [(args, exit status)]
    ("pendulum", "swing", True): [(["--t-end", "1", "--project-initial", "-p", "theta0=1"], 0),
                                  (["--t-end", "1", "--solver", "radau5"], 0)],
    ("gantry_crane", "everything", False): [(["--t-end", "0.5", "--solver", "rk4",
                                              "--step", "1e-3"], 0),
                                            (["--t-end", "0.5", "--solver", "rodas4"], 0)],
    ("diode", "charge", False): [(["--t-end", "0.01"], 0),
                                 (["--t-end", "0.01", "--solver", "auto", "--stats"], 0)],
    ("car_axis_vector", "bump", False): [(["--t-end", "0.2", "--solver", "radau5"], 0),
                                         (["--t-end", "0.2", "--solver", "vern7"], 0)],
}


@pytest.mark.parametrize("model, scene, project", list(RUNS), ids=[m for m, *_ in RUNS])
def test_generated_programs_run_clean_under_sanitizers(sanitized, model, scene, project):
    exe = sanitized(MODELS / f"{model}.bg", scene, project)
    for args, code in RUNS[(model, scene, project)]:
        _run(exe, *args, code=code)


def test_a_failing_and_an_interrupted_run_stay_clean(sanitized):
    blow = Source("blow.bg", "model blow\nsignal z = integral(z^2, init = 1)\n"
                             "scene s { outputs z; time 0 .. 2 every 0.1 }\n")
    done = _run(sanitized(blow, "s"), code=3)
    assert "step size too small" in done.stderr
    slow = Source("slow.bg", "model slow\nsignal z = integral(-z, init = 1)\n"
                             "scene s { outputs z; time 0 .. 1e9 every 1; "
                             "solver rk4(step = 1e-3) }\n")
    proc = subprocess.Popen([str(sanitized(slow, "s"))], stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, text=True, env=ENV)
    time.sleep(0.5)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 3 and "interrupted by signal 15" in err, err
    assert "Sanitizer" not in err and "runtime error" not in err, err
