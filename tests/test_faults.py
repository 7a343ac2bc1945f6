"""Fault injection: what bgc does when files, disks and processes fail under it.

Outputs never replace what is not a regular file (a device, a FIFO: written straight into; a
symbolic link: its target replaced, the link kept) nor a file the same command reads (the
model, under any name); a write that fails (a full disk, a file size limit, a closed pipe) is
one line and exit status 1, with no file left but a failed run's rows, cut back to the last
whole row; a generated program dies with bgc when bgc is killed, and its own death by a signal
is told by name, its rows kept whole; a run whose output interval exceeds its span has rows at
its start and its end, the same bytes in both backends.  The full disks are a file size limit
(RLIMIT_FSIZE, for anyone) and a 64 KiB tmpfs (when the tests run as root and may mount).

What is asserted is behaviour: exit statuses, the messages' lines, file types (os.stat), bytes.
Runs are the warm path of `bgc simulate` (the programs built once, by the fixture), in
processes of their own where a descriptor, a limit or a signal needs one.
"""
import importlib.util
import os
import resource
import shutil
import signal
import socket
import stat
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from bgc.base import cache as compile_cache, toolchain
from bgc.execute import outfile
from conftest import run_bgc

BACKENDS = ["python"] + (["c"] if toolchain.have_c_compiler() else [])
# 1e8 rk4 steps: a run that is still going when a test stops it.
DECAY = """model decay
signal z = integral(-z, init = 1)
scene s { outputs z; time 0 .. 1e5 every 0.001; solver rk4(step = 0.001) }
"""
LIMIT = 50_000  # bytes: the file size limit of the full-disk tests


@pytest.fixture(scope="module")
def warm(tmp_path_factory):
    """The model, and an environment whose cache holds both backends' programs and their warm
    records (so that a run in a process of its own starts at once)."""
    home = tmp_path_factory.mktemp("faults")
    model = home / "decay.bg"
    model.write_text(DECAY)
    env = {"BGC_CACHE_DIR": str(home / "cache")}
    for backend in BACKENDS:
        done = run_bgc("simulate", model, "-s", "s", "--t-end", "0.01", "--backend", backend,
                       env=env)
        assert done.returncode == 0, done.stderr
    return model, dict(os.environ, **env)


def bgc_process(warm, *args, cwd, **popen):
    """`bgc simulate MODEL -s s ARGS` started in a process of its own (Popen)."""
    model, env = warm
    popen.setdefault("stdout", subprocess.PIPE)
    return subprocess.Popen([sys.executable, "-m", "bgc", "simulate", str(model), "-s", "s",
                             *map(str, args)], cwd=cwd, env=env, stderr=subprocess.PIPE,
                            text=True, **popen)


def finish(proc) -> tuple[int, list[str]]:
    _, err = proc.communicate(timeout=120)
    assert "Traceback" not in err, err
    return proc.returncode, err.splitlines()


def hidden(directory: Path) -> list[str]:
    return sorted(p.name for p in directory.iterdir() if p.name.startswith("."))


def rows(path: Path) -> list[list[float]]:
    """The CSV's rows, each checked whole: ends with a newline, two numbers per line."""
    data = path.read_bytes()
    assert data.endswith(b"\n"), data[-80:]
    lines = data.decode().splitlines()
    assert lines[0] == "t,z"
    out = [[float(v) for v in line.split(",")] for line in lines[1:]]
    assert all(len(r) == 2 for r in out)
    return out


def children(pid: int) -> list[int]:
    found = []
    for task in Path(f"/proc/{pid}/task").glob("*/children"):
        try:
            found += [int(c) for c in task.read_text().split()]
        except OSError:
            pass
    return found


def running(pid: int) -> bool:
    """Whether pid is a process that runs (a zombie has ended: only its status is left)."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return False
    return fields[0] not in ("Z", "X")


def started(proc, directory: Path, size: int = 20_000) -> int:
    """The pid of the program `bgc simulate` (proc) runs, once its hidden CSV holds `size`
    bytes."""
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        assert proc.poll() is None, proc.communicate()
        kids = children(proc.pid)
        parts = [p for p in directory.iterdir() if p.name.endswith(".part")]
        if kids and parts and parts[0].stat().st_size >= size:
            return kids[0]
        time.sleep(0.02)
    raise AssertionError("the program did not start")


needs_proc = pytest.mark.skipif(not Path("/proc/self/task").is_dir(),
                                reason="needs /proc to find the program's process")


# ------------------------------------------------------------------ outputs and inputs


def test_an_output_that_is_the_model_is_refused_under_any_name(tmp_path):
    model = tmp_path / "m.bg"
    model.write_text(DECAY)
    (tmp_path / "link.bg").symlink_to("m.bg")
    os.link(model, tmp_path / "hard.bg")
    (tmp_path / "sub").mkdir()
    for given, target in (("m.bg", "m.bg"), ("m.bg", "link.bg"), ("m.bg", "hard.bg"),
                          ("link.bg", "m.bg"), ("m.bg", "sub/../m.bg"), ("m.bg", model)):
        for command in (["compile"], ["simulate", "-s", "s"]):
            done = run_bgc(*command, given, "-o", target, cwd=tmp_path)
            assert done.returncode == 1, (command, given, target, done.stderr)
            (line,) = done.stderr.splitlines()
            assert line.startswith(f"bgc: error: cannot write '{target}': it is the model "
                                   "file") and "which this command reads" in line, line
    assert model.read_text() == DECAY and (tmp_path / "link.bg").is_symlink()
    (tmp_path / "d.dot").write_text(DECAY)  # (draw writes .dot, .svg or .png only)
    done = run_bgc("draw", "d.dot", "-o", "d.dot", cwd=tmp_path)
    assert done.returncode == 1 and (tmp_path / "d.dot").read_text() == DECAY
    done = run_bgc("simulate", "m.bg", "-s", "s", "-o", "x.png", "--plot", "./x.png",
                   cwd=tmp_path)
    assert done.returncode == 1 and done.stderr.startswith("bgc: error: cannot write")
    (tmp_path / "sub" / "accuracy.csv").write_text("t,z\n0,1\n")  # (a reference CSV)
    done = run_bgc("accuracy", "m.bg", "-s", "s", "--reference", "sub/accuracy.csv", "-o",
                   "sub", cwd=tmp_path)
    assert done.returncode == 1 and "it is the reference" in done.stderr, done.stderr
    assert (tmp_path / "sub" / "accuracy.csv").read_text() == "t,z\n0,1\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["d.dot", "hard.bg", "link.bg",
                                                          "m.bg", "sub"]


READS = """model reads "a lag driven by a table and an input, beside a library it imports"
import parts
input u = 0
parameter k = 1
signal v = table(curve.csv, t)
signal z = integral(-k*z + v + u, init = 1)
scene s { outputs z; time 0 .. 1 every 0.5 }
"""
PARTS = """library parts "one component, unused: the import alone reads the file"
component spring(k = 1) "a spring at port p" {
  port p
  x : C(1/k)
  p -> x
}
"""


@pytest.fixture
def reads(tmp_path):
    """A model and every kind of file a command reads: a library it imports, a table, an
    --input CSV, a --data CSV, a --reference CSV; links to them, symbolic and hard, some of
    them inside directories an output directory names (accuracy's -o, --trajectories)."""
    files = {"reads.bg": READS, "parts.bg": PARTS, "curve.csv": "t,v\n0,1\n0.5,2\n1,0\n",
             "inp.csv": "t,u\n0,0\n1,1\n", "data.csv": "t,z\n0,1\n0.5,1.1\n1,1.4\n",
             "ref.csv": "t,z\n0,1\n0.5,1.1\n1,1.4\n"}
    for name, text in files.items():
        (tmp_path / name).write_text(text)
    for sub in ("acc", "acc2", "traj"):
        (tmp_path / sub).mkdir()
    for link, target in (("parts-link.bg", "parts.bg"), ("curve-link.csv", "curve.csv"),
                         ("inp-link.csv", "inp.csv"), ("lib.dot", "parts.bg")):
        (tmp_path / link).symlink_to(target)
    for link, target in (("parts-hard.bg", "parts.bg"), ("curve-hard.csv", "curve.csv"),
                         ("data-hard.json", "data.csv"), ("acc/accuracy.csv", "ref.csv"),
                         ("acc2/accuracy.csv", "curve.csv"),
                         ("traj/run-000001.csv", "curve.csv")):
        os.link(tmp_path / target, tmp_path / link)
    return tmp_path


def tree(directory: Path) -> dict:
    """Every path under directory: its kind, device and inode, and its bytes or link."""
    out = {}
    for p in sorted(directory.rglob("*")):
        info = os.lstat(p)
        body = os.readlink(p) if p.is_symlink() else p.read_bytes() if p.is_file() else None
        out[str(p.relative_to(directory))] = (stat.S_IFMT(info.st_mode), info.st_dev,
                                              info.st_ino, body)
    return out


LAG = ["reads.bg", "-s", "s"]
INPUT = [*LAG, "--input", "inp.csv"]
SWEEP = ["sweep", *LAG, "--grid", "k=1,2", "--metric", "final:z", "--workers", "0",
         "--backend", "python", "--no-timing"]
ACCURACY = ["accuracy", *LAG, "--solvers", "rk4", "--steps", "0.05", "--repeats", "1",
            "--no-plot"]
LIBRARY, TABLE = "the imported library", "the table file"
# (command line, the output, what it is, the name the command reads it by if another)
AIMED = [
    (["compile", "reads.bg", "-o", "parts.bg"], "parts.bg", LIBRARY, None),
    (["compile", "reads.bg", "-o", "parts-link.bg"], "parts-link.bg", LIBRARY, "parts.bg"),
    (["compile", "reads.bg", "-o", "parts-hard.bg"], "parts-hard.bg", LIBRARY, "parts.bg"),
    (["compile", "reads.bg", "-o", "curve.csv"], "curve.csv", TABLE, None),
    (["simulate", *INPUT, "-o", "inp.csv"], "inp.csv", "the --input file", None),
    (["simulate", *INPUT, "-o", "out.csv", "--events", "inp-link.csv"], "inp-link.csv",
     "the --input file", "inp.csv"),
    (["simulate", *LAG, "-o", "curve-hard.csv"], "curve-hard.csv", TABLE, "curve.csv"),
    (["sweep", *SWEEP[1:], "-o", "curve-link.csv"], "curve-link.csv", TABLE, "curve.csv"),
    (["sweep", *SWEEP[1:], "--trajectories", "traj"], "traj/run-000001.csv", TABLE,
     "curve.csv"),
    (["linearize", *LAG, "-o", "curve-hard.csv"], "curve-hard.csv", TABLE, "curve.csv"),
    (["steady", *LAG, "--json", "parts-link.bg"], "parts-link.bg", LIBRARY, "parts.bg"),
    (["draw", "reads.bg", "-o", "lib.dot"], "lib.dot", LIBRARY, "parts.bg"),
    (["fit", *LAG, "--data", "data.csv", "--vary", "k", "--backend", "python", "-o",
      "data-hard.json"], "data-hard.json", "the data file", "data.csv"),
    ([*ACCURACY, "--reference", "ref.csv", "-o", "acc"], "acc/accuracy.csv", "the reference",
     "ref.csv"),
    ([*ACCURACY, "-o", "acc2"], "acc2/accuracy.csv", TABLE, "curve.csv"),
]


@pytest.mark.parametrize("argv, target, what, name", AIMED,
                         ids=[f"{a[0]}-{t}" for a, t, _, _ in AIMED])
def test_an_output_that_is_a_file_the_command_reads_is_refused(reads, argv, target, what,
                                                                name):
    """Not only the model: a library it imports, a table it reads, --input, --data and
    --reference, under their names and through symbolic and hard links (the libraries and
    tables are known once the model is parsed: refused all the same before any output is
    opened).  The directory keeps every byte, link and inode it had."""
    before = tree(reads)
    done = run_bgc(*argv, cwd=reads)
    assert (done.returncode, done.stdout) == (1, ""), done.stderr
    again = f" '{name}'" if name else ""
    assert done.stderr.splitlines()[-1] == (
        f"bgc: error: cannot write '{target}': it is {what}{again}, which this command reads; "
        "name another output file")
    assert tree(reads) == before


def test_standard_output_that_is_a_file_the_command_reads_is_refused(reads):
    """`bgc compile reads.bg >> parts.bg`: the library it imports is its standard output."""
    before = tree(reads)
    with open(reads / "parts.bg", "ab") as out:
        done = subprocess.run([sys.executable, "-m", "bgc", "compile", "reads.bg"], cwd=reads,
                              stdout=out, stderr=subprocess.PIPE, text=True)
    assert (done.returncode, done.stderr) == (
        1, "bgc: error: cannot write standard output: it is the imported library 'parts.bg', "
           "which this command reads; name another output file\n")
    assert tree(reads) == before


have_matplotlib = importlib.util.find_spec("matplotlib") is not None
# (command line, its output option, the file it writes otherwise, what goes to stderr
# instead of stdout when the output takes it: the command's report)
DASHED = [
    (["compile", "reads.bg"], "-o", "out.c", False),
    (["simulate", *INPUT], "-o", "out.csv", False),
    (["simulate", *INPUT, "-o", "run.csv"], "--events", "events.csv", False),
    (SWEEP, "-o", "table.csv", False),
    (["draw", "reads.bg"], "-o", "graph.dot", False),
    (["steady", *LAG, "--at", "t=1"], "--json", "rest.json", True),  # (the table's last row)
    (["linearize", *LAG], "-o", "modes.json", True),
    pytest.param(["simulate", *INPUT, "-o", "run.csv"], "--plot", "run.png", False,
                 marks=pytest.mark.skipif(not have_matplotlib, reason="needs matplotlib")),
]


@pytest.mark.parametrize("argv, option, name, report", DASHED,
                         ids=["compile", "simulate", "events", "sweep", "draw", "steady",
                              "linearize", "plot"])
def test_a_dash_is_standard_output_for_every_output_option(reads, argv, option, name,
                                                           report):
    """`-o -`, `--events -`, `--json -`, `--plot -`: the bytes the same command writes into
    a file, on stdout (a PNG too: stdout is not a terminal), and no file named `-`; the report
    a command prints on stdout otherwise goes to stderr."""
    named = run_bgc(*argv, option, name, cwd=reads)
    assert named.returncode == 0, named.stderr
    (reads / name).rename(reads / f"kept-{name}")
    dashed = run_bgc(*argv, option, "-", cwd=reads)
    assert dashed.returncode == 0, dashed.stderr
    assert dashed.stdout_bytes == (reads / f"kept-{name}").read_bytes() != b""
    assert not (reads / "-").exists() and not (reads / name).exists()
    if report:
        assert named.stdout and named.stdout in dashed.stderr


@pytest.mark.parametrize("argv", [
    ["simulate", *INPUT, "-o", "-", "--events", "-"],
    ["simulate", *INPUT, "--events", "-"],  # (the CSV is on stdout without -o)
    ["simulate", *INPUT, "--plot", "-"],
    ["linearize", *LAG, "--inputs", "k", "-o", "-", "--bode", "-"],
    ["fit", *LAG, "--data", "data.csv", "--vary", "k", "-o", "-", "--plot", "-"],
    [*ACCURACY, "-o", "-"],
    [*SWEEP, "--trajectories", "-"],
], ids=["csv-events", "stdout-events", "stdout-plot", "matrices-bode", "fit-plot",
        "accuracy-dir", "trajectories-dir"])
def test_standard_output_taken_twice_or_for_a_directory_is_a_usage_error(reads, argv):
    before = tree(reads)
    done = run_bgc(*argv, cwd=reads)
    assert (done.returncode, done.stdout) == (2, ""), done.stderr
    assert "standard output" in done.stderr.splitlines()[-1]
    assert tree(reads) == before


@pytest.mark.skipif(not hasattr(os, "openpty"), reason="needs a pseudo-terminal")
def test_binary_data_is_not_written_to_a_terminal(reads):
    """`--plot -` and `--target fmu -o -` with a terminal on stdout (as gzip and tar refuse
    it): a usage error before any work, nothing written."""
    before = tree(reads)
    for argv in (["simulate", *INPUT, "-o", "run.csv", "--plot", "-"],
                 ["compile", "reads.bg", "--target", "fmu", "-o", "-"]):
        master, slave = os.openpty()
        done = subprocess.run([sys.executable, "-m", "bgc", *argv], cwd=reads, stdout=slave,
                              stderr=subprocess.PIPE, text=True)
        os.close(slave)
        os.close(master)
        assert done.returncode == 2, done.stderr
        assert done.stderr.splitlines()[-1].endswith(
            "-: binary data is not written to a terminal; redirect standard output (> FILE, "
            "| ...) or name a file")
    assert tree(reads) == before


@pytest.fixture
def read_only(tmp_path):
    """A directory that cannot be written: chmod 555, or for root (whom that does not stop)
    a read-only tmpfs, unmounted afterwards."""
    where = tmp_path / "ro"
    where.mkdir()
    if os.geteuid() != 0:
        where.chmod(0o555)
        yield where
        where.chmod(0o755)
        return
    done = subprocess.run(["mount", "-t", "tmpfs", "-o", "ro,size=64k", "tmpfs", str(where)],
                          capture_output=True, text=True) if shutil.which("mount") else None
    if done is None or done.returncode != 0:
        pytest.skip("a read-only directory for root needs a tmpfs mount")
    try:
        yield where
    finally:
        subprocess.run(["umount", "-l", str(where)], capture_output=True)


def test_accuracy_into_a_read_only_directory_fails_before_the_work(reads, read_only):
    """Its files' hidden temporaries are made before any run: with a reference the work
    would refuse (its first column is not t), the directory's refusal comes first, and no
    table is printed."""
    (reads / "ro-ref.csv").write_text("not numbers\n")
    for target, status, said in ((read_only, 2, "is not writable"),
                                 (read_only / "acc", 1, "cannot make the directory")):
        done = run_bgc(*ACCURACY, "--reference", "ro-ref.csv", "-o", target, cwd=reads)
        assert (done.returncode, done.stdout) == (status, ""), done.stderr
        assert said in done.stderr and "ro-ref.csv" not in done.stderr
    assert list(read_only.iterdir()) == []


def test_accuracy_that_fails_leaves_no_directory_it_made(reads):
    before = tree(reads)
    (reads / "ref-bad.csv").write_text("not numbers\n")
    done = run_bgc(*ACCURACY, "--reference", "ref-bad.csv", "-o", "new/acc", cwd=reads)
    assert done.returncode == 1 and "error: ref-bad.csv: " in done.stderr
    (reads / "ref-bad.csv").unlink()
    assert tree(reads) == before


def test_a_device_is_written_into_and_never_replaced(tmp_path, warm):
    """/dev/null itself is only looked at; the writes go to a private copy of it (mknod, as
    root), which must stay a character device."""
    assert outfile.destination("/dev/null") == (Path("/dev/null"), True)
    assert outfile.check_target("/dev/null") == Path("/dev/null")
    node = tmp_path / "null"
    try:
        os.mknod(node, 0o666 | stat.S_IFCHR, os.makedev(1, 3))
    except (PermissionError, OSError) as error:
        pytest.skip(f"cannot make a device node here ({error.strerror}): needs root")
    done = run_bgc("compile", warm[0], "-o", node, cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    for backend in BACKENDS:
        code, err = finish(bgc_process(warm, "--t-end", "1", "--backend", backend, "-o", node,
                                       cwd=tmp_path))
        assert code == 0 and err == []
    plotted = []
    if importlib.util.find_spec("matplotlib") is not None:  # (--plot reads a copy of the CSV)
        done = run_bgc("simulate", warm[0], "-s", "s", "--t-end", "1", "-o", node, "--plot",
                       "run.png", cwd=tmp_path, env={"BGC_CACHE_DIR": warm[1]["BGC_CACHE_DIR"]})
        assert done.returncode == 0, done.stderr
        assert (tmp_path / "run.png").read_bytes().startswith(b"\x89PNG")
        plotted = ["run.png"]
    info = os.stat(node)
    assert stat.S_ISCHR(info.st_mode) and info.st_rdev == os.makedev(1, 3)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["null", *plotted]


@pytest.mark.skipif(not hasattr(socket, "AF_UNIX"), reason="no UNIX sockets here")
def test_a_socket_or_a_directory_is_refused_before_any_work(tmp_path):
    (tmp_path / "m.bg").write_text(DECAY)
    with socket.socket(socket.AF_UNIX) as server:
        try:
            server.bind(str(tmp_path / "sock"))
        except OSError as error:
            pytest.skip(f"cannot make a socket here: {error}")
        for target, why in (("sock", "it is a socket"), (".", "it is a directory")):
            done = run_bgc("compile", "m.bg", "-o", target, cwd=tmp_path)
            assert done.returncode == 2 and why in done.stderr, done.stderr
    assert stat.S_ISSOCK(os.lstat(tmp_path / "sock").st_mode)


def _read_fifo(path: Path, into: list):
    with open(path, "rb") as f:
        into.append(f.read())


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no FIFOs here")
def test_a_fifo_is_written_into_and_never_replaced(tmp_path, warm):
    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    expected = run_bgc("compile", warm[0], cwd=tmp_path).stdout.encode()
    expected_csv = run_bgc("simulate", warm[0], "-s", "s", "--t-end", "0.5",
                           cwd=tmp_path, env={"BGC_CACHE_DIR": warm[1]["BGC_CACHE_DIR"]}).stdout
    for args, want in ((["compile", warm[0]], expected),
                       (["simulate", warm[0], "-s", "s", "--t-end", "0.5"],
                        expected_csv.encode())):
        got = []
        reader = threading.Thread(target=_read_fifo, args=(fifo, got))
        reader.start()
        done = run_bgc(*args, "-o", fifo, cwd=tmp_path,
                       env={"BGC_CACHE_DIR": warm[1]["BGC_CACHE_DIR"]})
        reader.join(timeout=60)
        assert done.returncode == 0, done.stderr
        assert got == [want]
        assert stat.S_ISFIFO(os.lstat(fifo).st_mode)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["pipe"]


def test_a_symbolic_link_keeps_pointing_at_its_target_which_gets_the_data(tmp_path, warm):
    (tmp_path / "results").mkdir()
    (tmp_path / "results" / "run.csv").write_text("an older result\n")
    (tmp_path / "run.csv").symlink_to("results/run.csv")
    (tmp_path / "new.c").symlink_to("results/new.c")  # (a link to a file not made yet)
    done = run_bgc("simulate", warm[0], "-s", "s", "--t-end", "0.5", "-o", "run.csv",
                   cwd=tmp_path, env={"BGC_CACHE_DIR": warm[1]["BGC_CACHE_DIR"]})
    assert done.returncode == 0, done.stderr
    assert len(rows(tmp_path / "results" / "run.csv")) == 501
    done = run_bgc("compile", warm[0], "-o", "new.c", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "results" / "new.c").read_text().startswith("/*")
    for link, target in (("run.csv", "results/run.csv"), ("new.c", "results/new.c")):
        assert stat.S_ISLNK(os.lstat(tmp_path / link).st_mode)
        assert os.readlink(tmp_path / link) == target
    assert hidden(tmp_path) == [] and hidden(tmp_path / "results") == []


# ------------------------------------------------------------------ full disks, closed pipes


def test_a_full_stdout_is_one_line_and_exit_1(tmp_path, warm):
    """`> /dev/full`: compile, help, and runs of both backends."""
    with open("/dev/full", "w") as full:
        runs = [[sys.executable, "-m", "bgc", "compile", str(warm[0])],
                [sys.executable, "-m", "bgc", "--help"]]
        for argv in runs:
            done = subprocess.run(argv, stdout=full, stderr=subprocess.PIPE, text=True,
                                  env=warm[1], cwd=tmp_path)
            assert (done.returncode, done.stderr) == (
                1, "bgc: error: cannot write stdout: No space left on device\n"), argv
        for backend in BACKENDS:
            code, err = finish(bgc_process(warm, "--t-end", "100", "--backend", backend,
                                           cwd=tmp_path, stdout=full))
            assert (code, err) == (1, ["bgc: error: cannot write stdout: No space left on "
                                       "device"]), backend


def test_a_closed_pipe_is_one_line_and_exit_1(tmp_path, warm):
    for backend in BACKENDS:
        read, write = os.pipe()
        os.close(read)
        proc = bgc_process(warm, "--t-end", "100", "--backend", backend, cwd=tmp_path,
                           stdout=write)
        os.close(write)
        code, err = finish(proc)
        assert (code, err) == (1, ["bgc: error: cannot write stdout: Broken pipe"]), backend


def _limit_file_size():
    resource.setrlimit(resource.RLIMIT_FSIZE, (LIMIT, resource.getrlimit(
        resource.RLIMIT_FSIZE)[1]))


@pytest.fixture
def small_disk(tmp_path):
    """A directory on a 64 KiB tmpfs (root only), unmounted afterwards."""
    where = tmp_path / "small"
    where.mkdir()
    if os.geteuid() != 0 or shutil.which("mount") is None:
        pytest.skip("mounting a small tmpfs needs root (the file size limit test runs anyway)")
    done = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=64k", "tmpfs", str(where)],
                          capture_output=True, text=True)
    if done.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here: {done.stderr.strip()}")
    try:
        yield where
    finally:
        subprocess.run(["umount", "-l", str(where)], capture_output=True)


def _check_kept(directory: Path, name: str, err: list[str], reason: str, size: int):
    """A run that filled the disk: the write error, then the kept rows, whole."""
    kept = directory / Path(name).name
    data = rows(kept)
    t = err[-1].split("t = ")[1].split()[0]
    assert float(t) == data[-1][0] and len(data) > 100 and kept.stat().st_size <= size
    assert err[-2:] == [f"bgc: error: cannot write '{name}': {reason}",
                        f"bgc: the run stopped; the rows up to t = {t} are in {name}"]
    assert hidden(directory) == []


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_file_size_limit_keeps_whole_rows(tmp_path, warm, backend):
    """RLIMIT_FSIZE on bgc and the program (SIGXFSZ ignored, as Python has it: EFBIG)."""
    code, err = finish(bgc_process(warm, "--backend", backend, "-o", "out.csv", cwd=tmp_path,
                                   preexec_fn=_limit_file_size))
    assert code == 1
    _check_kept(tmp_path, "out.csv", err, "File too large", LIMIT)


def test_a_file_size_limit_on_compile_leaves_no_file(tmp_path, warm):
    done = subprocess.run([sys.executable, "-m", "bgc", "compile", str(warm[0]), "-o", "m.c"],
                          cwd=tmp_path, env=warm[1], capture_output=True, text=True,
                          preexec_fn=_limit_file_size)
    assert (done.returncode, done.stderr) == (1, "bgc: error: cannot write 'm.c': File too "
                                                 "large\n")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_full_disk_keeps_whole_rows_and_nothing_else(small_disk, warm, backend):
    code, err = finish(bgc_process(warm, "--backend", backend, "-o", "small/out.csv",
                                   cwd=small_disk.parent))
    assert code == 1
    _check_kept(small_disk, "small/out.csv", err, "No space left on device", 64 * 1024)
    (small_disk / "out.csv").unlink()
    done = run_bgc("compile", warm[0], "-o", "small/big.c", cwd=small_disk.parent)
    assert done.returncode == 1
    assert done.stderr == "bgc: error: cannot write 'small/big.c': No space left on device\n"
    assert list(small_disk.iterdir()) == []


def test_a_full_disk_under_the_compile_cache_is_one_line(small_disk, tmp_path):
    (tmp_path / "m.bg").write_text(DECAY)
    (small_disk / "fill").write_bytes(b"\0" * 60 * 1024)
    for backend in BACKENDS:
        done = run_bgc("simulate", "m.bg", "-s", "s", "--t-end", "0.1", "--backend", backend,
                       cwd=tmp_path, env={"BGC_CACHE_DIR": str(small_disk / "cache")})
        assert done.returncode == 1 and done.stdout == ""
        assert done.stderr == f"error: cannot write into the compile cache {small_disk}/cache: " \
                              "No space left on device\n"
        assert [p.name for p in (small_disk / "cache").iterdir()
                if p.name.startswith(".build")] == []  # no temporary left behind


def _cache_is_clean(cache: Path):
    """No build directory left in the cache, and every file in it one bgc can use."""
    assert [p.name for p in cache.iterdir() if p.name.startswith("build")] == []
    for p in cache.iterdir():
        if p.name.startswith("bgc-") and p.suffix in ("", ".o"):
            assert compile_cache.usable(p, executable=p.suffix == ""), p.name


@pytest.mark.skipif(not toolchain.have_c_compiler(), reason="needs a C compiler")
def test_the_compiler_hitting_a_file_size_limit_in_the_cache_is_one_line(tmp_path, warm):
    """The runtime object is in the cache (the fixture built it); the compiler links a new
    model's program into the cache under a 50 kB file size limit (SIGXFSZ kills its linker, or
    it says File too large): one line naming the cache, exit 1, no output, the cache as it
    was (its runtime object kept, not blamed)."""
    (tmp_path / "m.bg").write_text(DECAY.replace("-z", "-2*z"))
    done = subprocess.run([sys.executable, "-m", "bgc", "simulate", "m.bg", "-s", "s",
                           "--t-end", "0.01", "-o", "out.csv"], cwd=tmp_path, env=warm[1],
                          capture_output=True, text=True, preexec_fn=_limit_file_size)
    cache = Path(warm[1]["BGC_CACHE_DIR"])
    assert (done.returncode, done.stdout, done.stderr) == (
        1, "", f"error: the C compiler cannot write into {cache}: File too large\n")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m.bg"]
    _cache_is_clean(cache)
    assert any(p.name.startswith("bgc-runtime-") for p in cache.iterdir())


@pytest.mark.skipif(not toolchain.have_c_compiler(), reason="needs a C compiler")
def test_the_compiler_hitting_a_full_disk_in_its_temporary_directory_is_one_line(
        small_disk, tmp_path, warm):
    """$TMPDIR (where the compiler writes its temporary files) on a full disk."""
    with open(small_disk / "fill", "wb") as fill:
        try:
            fill.write(b"\0" * 128 * 1024)
        except OSError:
            pass
    (tmp_path / "m.bg").write_text(DECAY.replace("-z", "-3*z"))
    done = run_bgc("simulate", "m.bg", "-s", "s", "--t-end", "0.01", "-o", "out.csv",
                   cwd=tmp_path, env={"BGC_CACHE_DIR": warm[1]["BGC_CACHE_DIR"],
                                      "TMPDIR": str(small_disk)})
    assert (done.returncode, done.stdout, done.stderr) == (
        1, "", f"error: the C compiler cannot write into {small_disk}: No space left on "
               "device\n")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m.bg", "small"]
    assert [p.name for p in small_disk.iterdir()] == ["fill"]
    _cache_is_clean(Path(warm[1]["BGC_CACHE_DIR"]))


# ------------------------------------------------------------------ kill signals


@needs_proc
@pytest.mark.parametrize("backend", BACKENDS)
def test_killing_bgc_kills_the_program(tmp_path, warm, backend):
    proc = bgc_process(warm, "--backend", backend, "-o", "out.csv", cwd=tmp_path)
    program = started(proc, tmp_path)
    proc.kill()
    proc.communicate(timeout=60)
    deadline = time.monotonic() + 10
    while running(program) and time.monotonic() < deadline:
        time.sleep(0.02)
    alive = running(program)
    if alive:
        os.kill(program, signal.SIGKILL)
    assert not alive, "the program runs on after bgc was killed"


def _descendants(pid: int) -> list[int]:
    found = []
    for child in children(pid):
        found += [child, *_descendants(child)]
    return found


def _cmdline(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode()
    except OSError:
        return ""


def _have_dask() -> bool:
    return importlib.util.find_spec("distributed") is not None


@needs_proc
def test_killing_bgc_sweep_kills_its_workers_and_their_programs(tmp_path, warm):
    """`kill -9` of `bgc sweep`, once a batch's program runs in the worker process of a local
    Dask cluster (--workers 1; without Dask, in bgc itself, --workers 0, the same code
    starting the program): every process bgc started ends."""
    workers = "1" if _have_dask() else "0"
    (tmp_path / "m.bg").write_text(DECAY.replace("model decay", "model decay\nparameter k = 1")
                                   .replace("-z", "-k*z"))
    proc = subprocess.Popen([sys.executable, "-m", "bgc", "sweep", "m.bg", "-s", "s", "--grid",
                             "k=1,2", "--metric", "final:z", "--workers", workers, "-o",
                             "table.csv"], cwd=tmp_path, env=warm[1],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline:
        assert proc.poll() is None
        started = _descendants(proc.pid)
        if any("--batch" in _cmdline(p) for p in started):
            break
        time.sleep(0.02)
    else:
        raise AssertionError("no batch started")
    proc.kill()
    proc.wait()
    deadline = time.monotonic() + 20
    while any(map(running, started)) and time.monotonic() < deadline:
        time.sleep(0.05)
    left = [(p, _cmdline(p)) for p in started if running(p)]
    for p, _ in left:
        os.kill(p, signal.SIGKILL)
    assert not left, f"still running after bgc sweep was killed: {left}"
    assert not (tmp_path / "table.csv").exists()


@needs_proc
@pytest.mark.parametrize("backend, sig", [(b, s) for b in BACKENDS
                                          for s in (signal.SIGKILL, signal.SIGSEGV)])
def test_a_program_killed_by_a_signal_is_told_and_its_rows_kept_whole(tmp_path, warm,
                                                                      backend, sig):
    proc = bgc_process(warm, "--backend", backend, "-o", "out.csv", cwd=tmp_path)
    os.kill(started(proc, tmp_path), sig)
    code, err = finish(proc)
    data = rows(tmp_path / "out.csv")
    t = err[-1].split("t = ")[1].split()[0]
    assert float(t) == data[-1][0] and len(data) > 100
    assert code == 1 and err[-2:] == [
        f"bgc: error: the generated program was killed by {sig.name} at t = {t}",
        f"bgc: the run stopped; the rows up to t = {t} are in out.csv"]
    assert hidden(tmp_path) == []


@needs_proc
def test_a_killed_program_writing_to_stdout_leaves_whole_rows_in_a_file_there(tmp_path, warm):
    """`bgc simulate > out.csv` (the file opened to write only, as a shell does)."""
    out = tmp_path / "out.csv"
    with open(out, "wb") as sink:
        proc = bgc_process(warm, "--backend", BACKENDS[-1], cwd=tmp_path, stdout=sink)
        deadline = time.monotonic() + 60
        while not (children(proc.pid) and out.stat().st_size > 20_000):
            assert time.monotonic() < deadline and proc.poll() is None
            time.sleep(0.02)
        os.kill(children(proc.pid)[0], signal.SIGKILL)
        code, err = finish(proc)
    data = rows(out)
    t = err[-1].split("t = ")[1]
    assert code == 1 and float(t) == data[-1][0]
    assert err[-1] == f"bgc: error: the generated program was killed by SIGKILL at t = {t}"


SWEPT = DECAY.replace("model decay", "model decay\nparameter k = 1").replace("-z", "-k*z")


def _interrupt_when(proc, ready, sig, group=False) -> list[int]:
    """Sends sig to bgc (to its process group, as a terminal's Ctrl-C does, if group) once
    ready(descendants) holds; every process it started by then, and until it ends."""
    seen: set[int] = set()
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline:
        assert proc.poll() is None, proc.communicate()
        found = _descendants(proc.pid)
        seen.update(found)
        if ready(found):
            break
        time.sleep(0.02)
    else:
        raise AssertionError("never ready to be interrupted")
    (os.killpg if group else os.kill)(proc.pid, sig)
    deadline = time.monotonic() + 120
    while proc.poll() is None:
        seen.update(_descendants(proc.pid))
        if time.monotonic() > deadline:  # (a failure, not a run that never ends)
            for pid in [*_descendants(proc.pid), proc.pid]:
                try:
                    os.kill(pid, signal.SIGKILL)
                except ProcessLookupError:
                    pass
            raise AssertionError(f"bgc did not end within 120 s of {sig.name}: "
                                 f"{[_cmdline(p) for p in sorted(seen)]}")
        time.sleep(0.02)
    return sorted(seen)


def _gone(started: list[int]) -> list:
    deadline = time.monotonic() + 20
    while any(map(running, started)) and time.monotonic() < deadline:
        time.sleep(0.05)
    left = [(p, _cmdline(p)) for p in started if running(p)]
    for p, _ in left:
        os.kill(p, signal.SIGKILL)
    return left


def _batch_runs(found) -> bool:
    return any("--batch" in _cmdline(p) for p in found)


def _catches_sigint(pid: int) -> bool:
    try:
        caught = [line for line in Path(f"/proc/{pid}/status").read_text().splitlines()
                  if line.startswith("SigCgt:")]
    except OSError:
        return False
    return bool(caught) and bool(int(caught[0].split()[1], 16) & (1 << (signal.SIGINT - 1)))


def _batch_stops_on_sigint(found) -> bool:
    """A batch's program runs and has its SIGINT handler (before, it ignores SIGINT as the
    worker that started it does, and ends only with the worker)."""
    return any("--batch" in _cmdline(p) and _catches_sigint(p) for p in found)


@needs_proc
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["INT", "TERM"])
def test_an_interrupted_sweep_exits_128_plus_the_signal_and_writes_nothing(tmp_path, warm,
                                                                          sig):
    """A serial sweep (--workers 0) stopped while a batch's program runs: one line, exit 130
    or 143 (not click's `Aborted!` and 1, nor a death by the signal), no table, no
    trajectory, the program gone."""
    (tmp_path / "m.bg").write_text(SWEPT)
    (tmp_path / "traj").mkdir()
    proc = subprocess.Popen([sys.executable, "-m", "bgc", "sweep", "m.bg", "-s", "s", "--grid",
                             "k=1,2", "--metric", "final:z", "--workers", "0", "--backend",
                             "python", "--trajectories", "traj", "-o", "table.csv"],
                            cwd=tmp_path, env=warm[1], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    started = _interrupt_when(proc, _batch_runs, sig)
    code, err = finish(proc)
    assert (code, err) == (128 + sig, [f"bgc: interrupted by {sig.name}"])
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m.bg", "traj"]
    assert list((tmp_path / "traj").iterdir()) == []
    assert _gone(started) == []


@needs_proc
@pytest.mark.skipif(not _have_dask(), reason="needs dask.distributed")
@pytest.mark.parametrize("when", ["start", "batch"])
def test_ctrl_c_of_a_sweep_on_dask_is_one_line_and_exit_130(tmp_path, warm, when):
    """SIGINT to the whole process group, as a terminal's Ctrl-C sends it: while the local
    cluster starts (its first process just made: Dask's clean-up of a half-made cluster was
    `AssertionError: Status.init`), and while a batch runs.  Not a worker's traceback either:
    they ignore SIGINT, bgc closes them."""
    (tmp_path / "m.bg").write_text(SWEPT)
    proc = subprocess.Popen([sys.executable, "-m", "bgc", "sweep", "m.bg", "-s", "s", "--grid",
                             "k=1,2", "--metric", "final:z", "--workers", "1", "--backend",
                             "python", "-o", "table.csv"], cwd=tmp_path, env=warm[1],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True)
    started = _interrupt_when(proc, bool if when == "start" else _batch_stops_on_sigint,
                              signal.SIGINT, group=True)
    code, err = finish(proc)
    assert (code, err) == (130, ["bgc: interrupted by SIGINT"])
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m.bg"]
    assert _gone(started) == []


@needs_proc
def test_an_interrupted_accuracy_leaves_no_directory_and_no_program(tmp_path, warm):
    """Its output files are opened (their hidden temporaries made, in a directory it makes)
    before the work; SIGTERM during the work: exit 143, the directory gone again."""
    proc = subprocess.Popen([sys.executable, "-m", "bgc", "accuracy", str(warm[0]), "-s", "s",
                             "--solvers", "rk4", "--steps", "0.001", "--repeats", "1",
                             "--backend", "python", "--no-plot", "-o", "new/acc"],
                            cwd=tmp_path, env=warm[1], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    acc = tmp_path / "new" / "acc"
    started = _interrupt_when(proc, lambda found: found and acc.is_dir() and hidden(acc),
                              signal.SIGTERM)
    code, err = finish(proc)
    assert (code, err[-1:]) == (143, ["bgc: interrupted by SIGTERM"])
    assert list(tmp_path.iterdir()) == []
    assert _gone(started) == []


# ------------------------------------------------------------------ the output grid


def test_an_output_interval_beyond_the_span_gives_the_start_and_the_end(warm):
    env = {"BGC_CACHE_DIR": warm[1]["BGC_CACHE_DIR"]}
    out = {}
    for backend in BACKENDS:
        done = run_bgc("simulate", warm[0], "-s", "s", "--t-end", "10", "--dt", "1e8",
                       "--backend", backend, env=env)
        assert done.returncode == 0, done.stderr
        out[backend] = done.stdout.encode()
        lines = done.stdout.splitlines()
        assert lines[0] == "t,z" and lines[1] == "0,1" and len(lines) == 3
        assert lines[2].startswith("10,") and abs(float(lines[2][3:]) - 4.54e-5) < 1e-7
    assert len(set(out.values())) == 1, out


# ------------------------------------------------------------------ the cut itself


def test_a_kept_file_is_cut_back_to_its_last_whole_row_and_no_further(tmp_path):
    """What was in the file before the run's start offset is never cut; a row longer than
    any read-back window still gives its time."""
    path = tmp_path / "out.csv"
    before = b"earlier text without a newline"
    long_row = b"2.5," + b",".join([b"1.25"] * 3000) + b"\n"
    whole = before + b"t,a\n1," + b"0" * 10 + b"\n" + long_row
    path.write_bytes(whole + b"3,4")
    with open(path, "r+b") as f:
        assert outfile.last_row_time_fd(f.fileno(), len(before)) == "2.5"
        outfile.cut_to_whole_rows(f.fileno(), len(before))
        assert os.lseek(f.fileno(), 0, os.SEEK_CUR) == len(whole)
    assert path.read_bytes() == whole
    path.write_bytes(before + b"t,a")  # nothing whole of ours: cut to where we started
    with open(path, "r+b") as f:
        assert outfile.last_row_time_fd(f.fileno(), len(before)) is None
        outfile.cut_to_whole_rows(f.fileno(), len(before))
    assert path.read_bytes() == before
    with open(path, "wb") as f:  # (written only: read back through /proc where there is one)
        f.write(b"t,a\n0,1\n0.5,2")
        f.flush()
        if Path(f"/proc/self/fd/{f.fileno()}").exists():
            assert outfile.last_row_time_fd(f.fileno(), 0) == "0"
            outfile.cut_to_whole_rows(f.fileno(), 0)
    if Path("/proc/self/fd").is_dir():
        assert path.read_bytes() == b"t,a\n0,1\n"
