"""The fuzzing harness (tools/fuzz.py) in the suite: a short seeded campaign, and every
regression file it found replayed.

The campaign is the long run's, made small: models generated from the grammar and mutations of
every shipped model through `bgc check` in this process, a few of the accepted ones through
`bgc simulate` in both backends.  Any exception other than the command's exit, an exit status
other than 0 and 1 (check), a model error without a location, a traceback in the output, a
file left behind, a cut CSV row is a failure (tools/fuzz.py says which).  The long run:

    python tools/fuzz.py --seed 28 --cases 100000 --simulate-every 5 --out fuzz-out

tests/fuzz_regressions/: the failures the harness found, minimised, once fixed.  Each must give
exit 0, or exit 1 with a located error; NAME.err, when there is one, is the first line it
must give.
"""
import importlib.util
import os
import random
import re
import signal
from contextlib import contextmanager
from pathlib import Path

import pytest
from click.testing import CliRunner

from bgc.cli import main
from conftest import have_cc

ROOT = Path(__file__).resolve().parent.parent
REGRESSIONS = ROOT / "tests" / "fuzz_regressions"
SEED = 2028
CASES = 200  # through check
SIMULATED = 2  # accepted models through simulate, in each backend
SAFETY_SECONDS = 60  # per case: turns a hang into a failure instead of a stuck suite


def _load_harness():
    spec = importlib.util.spec_from_file_location("bgc_fuzz_harness", ROOT / "tools" / "fuzz.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


fuzz = _load_harness()


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


def _campaign():
    """The seeded cases: [(index, how, bytes)], the same on every run."""
    rng = random.Random(SEED)
    seeds = fuzz.seed_models()
    return [(i, *fuzz.case(rng, seeds, i)) for i in range(CASES)]


def test_the_generators_cover_the_language():
    """The campaign reaches what it claims: every shipped model mutated, generated models
    that bgc accepts, every function, arrays, constraints and scenes."""
    cases = _campaign()
    text = "\n".join(d.decode("utf-8", "replace") for _, _, d in cases)
    for f in fuzz.FUNCTIONS:
        assert f + "(" in text, f
    for construct in ("constraint", "MTF[", "0[", "scene ", "integral(", "@", "GY(", "\r\n",
                      # events and contact (docs/hybrid.md), components (docs/language.md)
                      "when ", "reinit ", "discrete ", " then ", " else ", "Fr(",
                      "Sw(", "unilateral", "component ", "for i in ", "import "):
        assert construct in text, construct
    assert re.search(r" : D(\n|;)", text), "an ideal diode"
    assert {how for _, how, _ in cases} >= {"generated", "generated+mutated",
                                            "parallel branches"}
    assert len({how for _, how, _ in cases if how.startswith("mutated ")}) >= 10


def test_generated_hybrid_models_and_components_pass_check():
    """The generator's events, contact elements and components are models bgc accepts (most
    campaign cases mix them with other pieces that bgc refuses)."""
    rng = random.Random(SEED)
    accepted = {"hybrid": 0, "component": 0}
    for i in range(16):
        g = fuzz.Gen(rng)
        g.emit("model m")
        g.parameter()
        kind = "hybrid" if i % 2 else "component"
        getattr(g, kind)()
        with _alarm(SAFETY_SECONDS):
            res = fuzz.check_case(("\n".join(g.lines) + "\n").encode())
        assert res["failure"] is None, res
        accepted[kind] += res["exit"] == 0
    assert min(accepted.values()) >= 2, accepted


def test_seeded_campaign_check_and_simulate(tmp_path):
    accepted, failures = [], []
    for i, how, data in _campaign():
        with _alarm(SAFETY_SECONDS):
            res = fuzz.check_case(data)
        if res["failure"]:
            failures.append((i, how, res["failure"], res["stderr"][-2000:],
                             data.decode("utf-8", "replace")))
        elif res["exit"] == 0:
            accepted.append(data)
    assert not failures, failures[0]
    assert len(accepted) >= SIMULATED
    backends = ["python"] + (["c"] if have_cc() else [])
    for data in accepted[:SIMULATED]:
        for backend in backends:
            res = fuzz.simulate_case(data, backend, SAFETY_SECONDS, in_process=True)
            assert res["failure"] is None, (backend, res, data.decode())
            assert res["exit"] in (0, 1), res


def test_a_failure_is_minimised_and_written(tmp_path):
    """The minimiser keeps the failure's signature: here 'the text has a NUL byte and a
    division', a stand-in for a bug, from a whole model down to those two tokens."""
    data = (ROOT / "models" / "rlc.bg").read_bytes().replace(b"\n", b"\n\x00", 1) + b"x = 1/2\n"
    small = fuzz.minimise(data, lambda d: b"\x00" in d and b"/" in d, seconds=30)
    assert b"\x00" in small and b"/" in small and len(small) <= 3
    path = fuzz.write_regression(tmp_path, "check: ValueError at x.py:f", small, "mutated",
                                 1, 7, data)
    assert path.read_bytes() == small
    note = path.with_suffix(".note").read_text()
    assert "check: ValueError at x.py:f" in note and "--seed 1, case 7" in note


REPLAYED = sorted(p.name for p in REGRESSIONS.glob("*.bg"))
# (an error in a library the model imports is located there, with a note at the instance)
LOCATED = re.compile(r"^(tests/fuzz_regressions/[^:]+\.bg(:\d+:\d+)?"
                     r"|\S+/bgc/library/\w+\.bg:\d+:\d+): error: ", re.M)


@pytest.mark.parametrize("name", REPLAYED)
def test_regression_replayed(name, monkeypatch):
    monkeypatch.chdir(ROOT)
    path = f"tests/fuzz_regressions/{name}"
    with _alarm(SAFETY_SECONDS):
        result = CliRunner().invoke(main, ["check", path])
    if result.exception is not None and not isinstance(result.exception, SystemExit):
        raise result.exception
    assert result.exit_code in (0, 1), result.output
    assert "Traceback" not in result.stderr
    if result.exit_code == 1:
        assert LOCATED.search(result.stderr), result.stderr
    expected = REGRESSIONS / name.replace(".bg", ".err")
    if expected.exists():
        assert result.exit_code == 1
        first = next(line for line in result.stderr.splitlines() if ": error: " in line)
        assert first == expected.read_text(encoding="utf-8").strip()


def test_parameter_given_on_the_command_line_that_makes_a_law_complex(tmp_path):
    """`-p a=2` for `C(asin(a))`: a located error naming the value, exit 1; not a traceback,
    not a run from NaN (the model's own value a = 0.5 is fine)."""
    model = tmp_path / "m.bg"
    model.write_text("model m\nparameter a = 0.5\nparameter b = a\nj : 0\nc : C(asin(b))\n"
                     "r : R(2)\nj -> c\nj -> r\nk : 0\ne : C(1) init q = sqrt(a)\n"
                     "s : R(1)\nk -> e\nk -> s\n", encoding="utf-8")
    env = {"BGC_CACHE_DIR": str(tmp_path / "cache")}
    runner = CliRunner()
    cwd = os.getcwd()
    os.chdir(tmp_path)
    try:
        ok = runner.invoke(main, ["simulate", "m.bg", "--backend", "python", "--t-end", "0.01"],
                           env=env)
        bad = runner.invoke(main, ["simulate", "m.bg", "--backend", "python", "--t-end", "0.01",
                                   "-p", "a=2", "-o", "out.csv"], env=env)
        neg = runner.invoke(main, ["simulate", "m.bg", "--backend", "python", "--t-end", "0.01",
                                   "-p", "a=-2"], env=env)
    finally:
        os.chdir(cwd)
    assert ok.exit_code == 0, ok.output
    assert bad.exception is None or isinstance(bad.exception, SystemExit)
    assert bad.exit_code == 1, bad.output
    assert bad.stderr.startswith("m.bg:5:7: error: the law of 'c' evaluates to a complex number: "
                                 "asin(b) with b = 2 (|b| > 1)"), bad.stderr
    assert "m.bg: note: with the parameter values given for the run: a=2" in bad.stderr
    assert not (tmp_path / "out.csv").exists()
    assert neg.exit_code == 1
    assert "m.bg:10:19: error: the initial value of 'e' evaluates to a complex number: sqrt(a) " \
           "with a = -2" in neg.stderr


FAST_EVENTS = """model fast_events
signal x = integral(1, init = 0)
discrete n = 0
when sin(1.2566370614359172e6 * t) > 0.5 {
  n = n + 1
}
signal y = n
"""


def test_events_without_end_stop_at_the_step_budget(tmp_path):
    """A condition that changes 400 000 times a second, with steps between its changes (at
    most 1e-6 long, five a period): the run stops once more events have come since the last
    output row than --max-steps allows (and at least 1000), in both backends alike."""
    from conftest import run_bgc
    model = tmp_path / "fast.bg"
    model.write_text(FAST_EVENTS, encoding="utf-8")
    said = {}
    for backend in ["python"] + (["c"] if have_cc() else []):
        with _alarm(SAFETY_SECONDS):
            done = run_bgc("simulate", model, "--t-end", "0.02", "--dt", "0.01", "--max-step",
                           "1e-6", "--outputs", "x,y", "--max-steps", "1500", "--backend",
                           backend, "-o", tmp_path / f"{backend}.csv",
                           env={"BGC_CACHE_DIR": str(tmp_path / "cache")})
        assert done.returncode == 1, done.stderr
        said[backend] = done.stderr.splitlines()[0]
        assert re.fullmatch(r"error: at t = \S+: chattering: 1500 events since the last output "
                            r"row \('.+' keeps? changing: a Zeno model\? --max-steps raises "
                            r"the budget\)", said[backend]), said[backend]
    assert len(set(said.values())) == 1, said


def test_steps_each_cut_short_by_an_event_stop_as_chattering(tmp_path):
    """tests/fuzz_regressions/friction_negative_mass_zeno.bg: a negative mass against dry
    friction sticks and breaks away at every step, each event further than 1e-12 from the
    last (once 10^8 events in 0.05 s, minutes in C): 1000 steps in a row, each ended by an
    event, stop it as chattering, in both backends alike."""
    from conftest import run_bgc
    model = REGRESSIONS / "friction_negative_mass_zeno.bg"
    said = {}
    for backend in ["python"] + (["c"] if have_cc() else []):
        with _alarm(SAFETY_SECONDS):
            done = run_bgc("simulate", model, "--t-end", "0.05", "--backend", backend, "-o",
                           tmp_path / f"{backend}.csv",
                           env={"BGC_CACHE_DIR": str(tmp_path / "cache")})
        assert done.returncode == 1, done.stderr
        said[backend] = done.stderr.splitlines()[0]
        assert re.fullmatch(r"error: at t = \S+: chattering: 1000 steps in a row, each cut short "
                            r"by an event \('.+' keeps? changing: a sliding mode or a Zeno "
                            r"model\? --max-steps raises the limit, a hundredth of it\)",
                            said[backend]), said[backend]
    assert len(set(said.values())) == 1, said


def test_an_indicator_held_at_zero_by_rounding_is_located_by_bisection(tmp_path):
    """tests/fuzz_regressions/event_indicator_zero_at_start.bg: `x14 >= p1` with x14 starting
    at p1 holds with an indicator of exactly 0, and rounding keeps it 0 for a while as x14
    falls: the secant's next point was always the interval's start, so each event took about
    150 evaluations (crawling by half the time's resolution, then bisecting); one probe there,
    then bisection, takes a few.  Chattering, the run stops at the event budget in both
    backends alike (every step cut short by an event), with the evaluations counted in
    --stats (locate=)."""
    from conftest import run_bgc
    model = REGRESSIONS / "event_indicator_zero_at_start.bg"
    said = {}
    for backend in ["python"] + (["c"] if have_cc() else []):
        with _alarm(SAFETY_SECONDS):
            done = run_bgc("simulate", model, "--stats", "--backend",
                           backend, "-o", tmp_path / f"{backend}.csv",
                           env={"BGC_CACHE_DIR": str(tmp_path / "cache")})
        assert done.returncode == 1, done.stderr
        stats = next(ln for ln in done.stderr.splitlines() if ln.startswith("stats:"))
        events = int(re.search(r" events=(\d+)", stats).group(1))
        located = int(re.search(r" locate=(\d+)", stats).group(1))
        assert events == 1000 and located <= 10 * events, stats
        said[backend] = (re.sub(r" cpu=\S+", "", stats),
                         next(ln for ln in done.stderr.splitlines() if ln.startswith("error:")))
        assert "chattering: 1000 steps in a row, each cut short by an event" in said[backend][1]
    assert len(set(said.values())) == 1, said


def test_a_block_that_divides_by_its_unknown_fails_alike_in_both_backends(tmp_path):
    """tests/fuzz_regressions/block_divides_by_its_unknown.bg: a division by a block's unknown
    that is zero gives inf in the Python module's IEEE variant as in C (not a
    ZeroDivisionError): the same error line and the same kept rows in both backends."""
    from conftest import run_bgc
    model = REGRESSIONS / "block_divides_by_its_unknown.bg"
    said, kept = {}, {}
    for backend in ["python"] + (["c"] if have_cc() else []):
        out = tmp_path / f"{backend}.csv"
        with _alarm(SAFETY_SECONDS):
            done = run_bgc("simulate", model, "--backend", backend, "-o", out,
                           env={"BGC_CACHE_DIR": str(tmp_path / "cache")})
        assert done.returncode == 1 and "Traceback" not in done.stderr, done.stderr
        said[backend], kept[backend] = done.stderr.splitlines()[0], out.read_bytes()
        assert re.fullmatch(r"error: at t = \S+: algebraic block \d \(.+\) is singular",
                            said[backend]), said[backend]
    assert len(set(said.values())) == 1 and len(set(kept.values())) == 1, said


@pytest.mark.parametrize("name, what", [
    ("constraint_second_derivative_beyond_double.bg", "a number beyond a double"),
    ("derivatives_divide_by_zero.bg", "a division by zero (zoo)")])
def test_equations_not_finite_once_differentiated_are_the_models_error(name, what, tmp_path):
    """Models `check` accepts whose generated equations are not finite (found through
    `simulate`): the model's error before any code is written, exit 1, no output."""
    from conftest import run_bgc
    model = REGRESSIONS / name
    with _alarm(SAFETY_SECONDS):
        done = run_bgc("simulate", model, "--backend", "python", "--t-end", "0.05", "-o",
                       tmp_path / "out.csv")
    assert done.returncode == 1
    assert done.stderr.startswith(f"{model}: error: the generated equations are not finite: "
                                  f"the derivatives of the states hold {what}"), done.stderr
    assert list(tmp_path.iterdir()) == []
