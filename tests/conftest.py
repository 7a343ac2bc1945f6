import fcntl
import os
import pickle
import shutil
import tempfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
MODELS = ROOT / "models"

# The C backend builds at -O0 in the tests (five times faster; the same IEEE arithmetic under
# -std=c99 at every level).  The tests of the generated C itself name their own flags: -O2 and
# -O3 with every warning an error (test_golden, test_emit), sanitizers (test_sanitizers).
os.environ.setdefault("BGC_CFLAGS", "-O0 -std=c99")
# `bgc simulate` runs the C backend in the tests unless they say otherwise: its default
# (auto: the interpreter for a short run of a model not built before, docs/cli.md) is tested
# in tests/test_vm.py.
os.environ.setdefault("BGC_BACKEND", "c")
# One BLAS thread per process (set before anything imports NumPy; the xdist workers and every
# subprocess inherit it): the references' matrices are 2x2 to 50x50, where OpenBLAS's threads
# spin more than they compute (scipy.linalg.expm of a 3x3 matrix 40 times slower on two busy
# cores), and xdist already runs a worker on each core.  bgc's solvers use no BLAS.
for _blas in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_blas, "1")


def pytest_configure(config):
    """One compile cache for the whole run, shared by the xdist workers (started after this,
    with this environment), unless BGC_CACHE_DIR is set: a program that several tests build is
    compiled once, and the run neither reads nor fills the user's ~/.cache/bgc.  The tests of
    the cache itself name their own directories."""
    if "BGC_CACHE_DIR" not in os.environ and not os.environ.get("PYTEST_XDIST_WORKER"):
        os.environ["BGC_CACHE_DIR"] = tempfile.mkdtemp(prefix="bgc-test-cache-")
        config._bgc_cache_dir = os.environ["BGC_CACHE_DIR"]
    if not os.environ.get("PYTEST_XDIST_WORKER"):
        os.environ[_SHARED] = tempfile.mkdtemp(prefix="bgc-test-references-")
        config._bgc_shared_dir = os.environ[_SHARED]


def pytest_unconfigure(config):
    made = getattr(config, "_bgc_cache_dir", None)
    if made:
        shutil.rmtree(made, ignore_errors=True)
        del os.environ["BGC_CACHE_DIR"]
    shared = getattr(config, "_bgc_shared_dir", None)
    if shared:
        shutil.rmtree(shared, ignore_errors=True)
        del os.environ[_SHARED]


_SHARED = "BGC_TEST_REFERENCES"


def shared_reference(name: str, compute):
    """compute() once per test run, whichever xdist worker asks first (the others wait for it
    and read its result): a reference that costs seconds (a stiff SciPy solve at a tight
    tolerance) is not computed again in every worker.  Computed here if the run made no
    shared directory (a test module run by hand)."""
    folder = os.environ.get(_SHARED)
    if not folder or not os.path.isdir(folder):
        return compute()
    path = os.path.join(folder, name + ".pickle")
    with open(path + ".lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        try:
            with open(path, "rb") as f:
                return pickle.load(f)
        except FileNotFoundError:
            value = compute()
            with open(path + ".part", "wb") as f:
                pickle.dump(value, f)
            os.replace(path + ".part", path)
            return value


def pytest_addoption(parser):
    parser.addoption("--update-golden", action="store_true", default=False,
                     help="Rewrite golden files (tests/golden, tests/errors/*.err) from the "
                          "current output instead of comparing with them.")


@pytest.fixture
def golden(request):
    """golden(path, text): compare text with the file, or rewrite it under --update-golden."""
    update = request.config.getoption("--update-golden")

    def check(path: Path, text: str):
        if update or not path.exists():
            if not update:
                pytest.fail(f"golden file {path.relative_to(ROOT)} is missing: run "
                            "pytest --update-golden and review the diff")
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(text, encoding="utf-8")
            return
        expected = path.read_text(encoding="utf-8")
        assert text == expected, f"{path.relative_to(ROOT)} differs (pytest --update-golden " \
                                 "rewrites it; read the diff first)"
    return check


def have_cc() -> bool:
    return shutil.which(os.environ.get("CC", "cc")) is not None


class CliResult:
    """What a command line gave: returncode, stdout, stderr (as subprocess.run's result), and
    stdout's bytes (a PNG or an FMU written to standard output)."""

    def __init__(self, returncode, stdout, stderr, stdout_bytes=b""):
        self.returncode, self.stdout, self.stderr = returncode, stdout, stderr
        self.stdout_bytes = stdout_bytes


def run_bgc(*args, cwd=None, env=None, umask=None) -> CliResult:
    """`bgc ARGS` in this process (click's runner: no interpreter start, no second SymPy
    import), in directory cwd, with the environment variables env set and the umask given.
    An exception other than the command's exit is re-raised: a traceback is a failure."""
    from click.testing import CliRunner

    from bgc.cli import main

    old_dir, old_mask = os.getcwd(), os.umask(0o022 if umask is None else umask)
    os.chdir(cwd or ROOT)
    try:
        result = CliRunner().invoke(main, [str(a) for a in args], env=env)
    finally:
        os.chdir(old_dir)
        os.umask(old_mask)
    if result.exception and not isinstance(result.exception, SystemExit):
        raise result.exception
    return CliResult(result.exit_code, result.stdout, result.stderr, result.stdout_bytes)
