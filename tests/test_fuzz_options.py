"""The command-line fuzzer (tools/fuzz_options.py) in the suite: a short seeded campaign over
every command's options, and the command lines it found failing, replayed.

Each case is a valid command line on a small model changed one to four times (values of each
option's kind taken to extremes, unknown names, paths that are directories, devices, FIFOs,
links to the model or missing, repeated and unknown options, an output aimed at a file the
command reads, `-` for output options), run in a directory of its own through the function
the command line calls.  Nothing may raise, print a traceback, exit with a status outside 0,
1, 2 or without a message, leave a hidden or unasked-for file or one named `-`, write after a
usage error, cut a CSV row, change or replace a file the command reads (its model, library,
table, --input, --data, --reference, under any name), or replace a device, a FIFO, a link or
a directory (tools/fuzz_options.py says which).  The long run:

    python tools/fuzz_options.py --seed 1 --cases 20000 --out fuzz-options-out
"""
import importlib.util
import random
import signal
from contextlib import contextmanager
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
SEED = 28
CASES = 20
SAFETY_SECONDS = 60  # per case: a hang fails the test instead of stopping the suite


def _load():
    spec = importlib.util.spec_from_file_location("bgc_fuzz_options",
                                                  ROOT / "tools" / "fuzz_options.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


fo = _load()


@contextmanager
def _alarm(seconds):
    def expire(signum, frame):
        raise AssertionError(f"a case took more than {seconds} s")
    previous = signal.signal(signal.SIGALRM, expire)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)


@pytest.fixture(scope="module")
def env():
    return None  # (the suite's compile cache: the runtime and the parser's tables built once)


# Command lines the fuzzer found failing (each fixed where it arose), and what each must give:
# (argv, exit status, a piece of the message).
LONG = "a" * 300
ACCURACY = ["accuracy", "m.bg", "-s", "other", "--solvers", "rk4", "--steps", "0.05",
            "--repeats", "1", "--no-plot"]
FOUND = [
    # --const made MODEL a Source that the output checks and accuracy's file names took for a
    # path: a TypeError
    (["compile", "m.bg", "-o", "m.bg", "--const", "N=1"], 1, "it is the model file"),
    (["accuracy", "m.bg", "-s", "other", "--solvers", "rk4", "--steps", "0.05", "--no-plot",
      "-o", "acc", "--const", "nope=1"], 2, "nope"),
    # a file name longer than the system allows: OSError from the output check
    (["simulate", "m.bg", "-s", "run", "--events", LONG + ".csv"], 2, "File name too long"),
    (["steady", "m.bg", "-s", "run", "--json", LONG + ".json"], 2, "File name too long"),
    (["sweep", "m.bg", "-s", "run", "--grid", "R=1,2", "--metric", "final:c.q", "--workers",
      "0", "-o", LONG], 2, "File name too long"),
    # a name the system allows whose hidden file beside it would not be: written all the same
    (["compile", "m.bg", "-o", "b" * 250 + ".c"], 0, ""),
    # accuracy's -o DIR naming a file (FileExistsError after the work) or nothing (the
    # default directory written instead); a --timeout beyond what a wait takes (OverflowError)
    (ACCURACY + ["-o", "m.bg"], 2, "'m.bg' exists and is not a directory"),
    (ACCURACY + ["-o", ""], 2, "an empty name is not a directory"),
    (ACCURACY + ["-o", "acc", "--timeout", "10000001"], 0, ""),
    (["sweep", "m.bg", "-s", "run", "--grid", "R=1,2", "--metric", "final:c.q", "--workers",
      "0", "--backend", "python", "--trajectories", "link"], 2, "is not a directory"),
    # a reference that is not a CSV (numpy's ValueError)
    (ACCURACY + ["-o", "acc", "--reference", "m.bg"], 1, "m.bg: not a CSV of numbers"),
    # an output that is a library or a table the model reads, or an --input, through links:
    # replaced, exit 0; `-` written as a file named `-`
    (["compile", "lm.bg", "-o", "parts-hard.bg"], 1,
     "it is the imported library 'parts.bg', which this command reads"),
    (["simulate", "lm.bg", "-s", "run", "--input", "inp.csv", "-o", "out.csv", "--events",
      "inp-link.csv"], 1, "it is the --input file 'inp.csv'"),
    (["sweep", "lm.bg", "-s", "run", "--grid", "R=1,2", "--metric", "final:c.q", "--workers",
      "0", "--backend", "python", "--trajectories", "trajdir"], 1,
     "cannot write 'trajdir/run-000000.csv': it is the table file 'curve.csv'"),
    (["steady", "m.bg", "-s", "run", "--json", "-"], 0, "c.q = "),
    (["simulate", "m.bg", "-s", "run", "--events", "-"], 2,
     "--events -: standard output already has the CSV"),
]


def test_a_reference_that_never_ends_is_refused(env):
    """`--reference` naming a copy of /dev/full (zeros without end) was read for ever: it is
    read up to its limit (64 MiB), then refused."""
    with _alarm(SAFETY_SECONDS):
        res = fo.run_case(ACCURACY + ["-o", "acc", "--reference", "fulldev"], env)
    assert res["failure"] is None, res
    if res["exit"] == 2 and "does not exist" in res["stderr"]:
        pytest.skip("no device could be made here (mknod needs root)")
    assert res["exit"] == 1 and "fulldev: too large for a reference" in res["stderr"], res


@pytest.mark.parametrize("argv, status, said", FOUND, ids=lambda v: None)
def test_found_command_lines(argv, status, said, env):
    with _alarm(SAFETY_SECONDS):
        res = fo.run_case(argv, env)
    assert res["failure"] is None, res
    assert res["exit"] == status and said in res["stderr"], res


def test_seeded_campaign(env):
    """Every command comes up; none breaks a promise."""
    rng = random.Random(SEED)
    seen, failures = {}, []
    for i in range(CASES):
        argv = fo.options(rng, quick=True)
        with _alarm(SAFETY_SECONDS):
            res = fo.run_case(argv, env)
        seen.setdefault(argv[0] if argv else "", set()).add(res["exit"])
        if res["failure"]:
            failures.append((i, argv, res))
    assert not failures, failures[0]
    assert len(seen) >= 7, seen
    assert {0, 2} <= set().union(*seen.values()), seen


def test_seeded_outputs_aimed_at_inputs_and_at_standard_output(env):
    """The two classes of issue 37, one case each for every command of the quick campaign:
    an output aimed at a file the command reads (lm.bg, its library and table, an --input),
    and every output option given `-`."""
    rng = random.Random(SEED)
    failures = []
    for command in sorted(c for c in fo.BASE if c not in fo.SLOW):
        opts = fo._options(command)
        aimed = list(fo.BASE[command]) + (["--backend", "python"] if command == "sweep" else [])
        dashed = list(aimed)
        fo._aim_at_input(rng, command, aimed, opts)
        for names, _, _ in opts:
            if names[0] in fo.OUTPUT_OPTIONS:
                dashed += [names[0], "-"]
        for argv in (aimed, dashed):
            with _alarm(SAFETY_SECONDS):
                res = fo.run_case(argv, env)
            if res["failure"]:
                failures.append((argv, res))
    assert not failures, failures[0]
