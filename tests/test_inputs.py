"""Inputs (`input NAME = DEFAULT`): data from `bgc simulate --input`, the programs' --input,
simulate(inputs=...), FMU input variables, linearize's B and D.  References: closed forms
(the RC circuit under a piecewise-linear voltage, a mass-spring-damper's matrices) and SciPy
driving the FMU through FMPy, computed here."""
import ctypes
import math

import numpy as np
import pytest

import bgc
from bgc.base import toolchain
from bgc.api import Source

from conftest import have_cc


class _Done:
    def __init__(self, result):
        self.returncode = result.exit_code
        self.stderr = result.stderr


def run_bgc(*args, cwd):
    """bgc's command line in this process, in directory cwd."""
    import os
    from click.testing import CliRunner
    from bgc.cli import main
    here = os.getcwd()
    os.chdir(cwd)
    try:
        return _Done(CliRunner().invoke(main, [str(a) for a in args]))
    finally:
        os.chdir(here)

BACKENDS = ["c", "python"] if have_cc() else ["python"]

RC = """model rc "an RC circuit driven by a voltage from outside"
parameter R = 2.0
parameter C = 0.25
input v = 0.5 "the source voltage [V]"
src : Se(v)
r : R(R)
c : C(C)
j : 1
src -> j
j -> r
j -> c
scene run { time 0 .. 2 every 0.05; outputs c.e, v; solver dopri5(rtol = 1e-10, atol = 1e-12) }
"""
TAU = 0.5  # R C
# a piecewise-linear voltage at non-round times
VOLTAGE = [(0.0, 0.0), (0.37, 1.2), (0.41, 1.2), (1.13, -0.4), (1.9, 0.3)]


def rc_exact(t, data=VOLTAGE, tau=TAU):
    """The capacitor's voltage: on each piece v = a + b s (s = t - t_k) the solution of
    tau e' = v - e is a + b (s - tau) + (e_k - a + b tau) exp(-s / tau); v held outside."""
    pieces = [(ta, tb, ua, (ub - ua) / (tb - ta)) for (ta, ua), (tb, ub) in zip(data, data[1:])
              if tb > ta]  # (a repeated t, a jump, is no piece)
    pieces.insert(0, (-math.inf, data[0][0], data[0][1], 0.0))
    pieces.append((data[-1][0], math.inf, data[-1][1], 0.0))
    out, e, start = [], 0.0, 0.0
    for T in t:
        value = None
        e, start = 0.0, 0.0
        for ta, tb, a, b in pieces:
            if tb <= start:
                continue
            s0 = max(ta, start)
            a0 = a + b * (s0 - ta) if math.isfinite(ta) else a
            end = min(tb, T)
            s = end - s0
            e = a0 + b * (s - tau) + (e - a0 + b * tau) * math.exp(-s / tau)
            start = end
            if end >= T:
                value = e
                break
        out.append(value)
    return np.array(out)


def write_voltage(path, rows=VOLTAGE, name="v"):
    path.write_text(f"t,{name}\n" + "".join(f"{t!r},{u!r}\n" for t, u in rows), encoding="utf-8")


def read_csv(path):
    lines = path.read_text().splitlines()
    return lines[0].split(","), np.array([[float(v) for v in line.split(",")]
                                          for line in lines[1:]])


def test_an_rc_circuit_driven_through_input_matches_its_closed_form(tmp_path):
    (tmp_path / "rc.bg").write_text(RC, encoding="utf-8")
    write_voltage(tmp_path / "v.csv")
    texts = {}
    for backend in BACKENDS:
        out = tmp_path / f"{backend}.csv"
        done = run_bgc("simulate", "rc.bg", "--scene", "run", "--input", "v.csv", "--backend",
                       backend, "-o",
                       out, "--stats", cwd=tmp_path)
        assert done.returncode == 0, done.stderr
        assert "events=4" in done.stderr  # every sample of the data after the start
        texts[backend] = out.read_bytes()
    assert len(set(texts.values())) == 1  # the same bytes from both backends
    head, y = read_csv(tmp_path / f"{BACKENDS[0]}.csv")
    assert head == ["t", "c.e", "v"]
    ref = rc_exact(y[:, 0])
    assert np.max(np.abs(y[:, 1] - ref)) < 1e-6 * np.max(np.abs(ref))
    v = np.interp(y[:, 0], [t for t, _ in VOLTAGE], [u for _, u in VOLTAGE])
    assert np.allclose(y[:, 2], v, rtol=0, atol=1e-15)
    # without data the input keeps its default: e = 0.5 (1 - exp(-t / tau))
    done = run_bgc("simulate", "rc.bg", "--scene", "run", "-o", tmp_path / "d.csv",
                   cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    _, y = read_csv(tmp_path / "d.csv")
    assert np.allclose(y[:, 1], 0.5 * (1 - np.exp(-y[:, 0] / TAU)), rtol=0, atol=1e-9)
    assert np.all(y[:, 2] == 0.5)
    # the API's inputs= gives what --input gives
    for backend in BACKENDS:
        t, Y, names = bgc.simulate(Source(str(tmp_path / "rc.bg"), RC), "run", backend=backend,
                                   inputs={"v": ([t for t, _ in VOLTAGE],
                                                 [u for _, u in VOLTAGE])})
        assert names == ["c.e", "v"]
        _, y = read_csv(tmp_path / f"{BACKENDS[0]}.csv")
        assert np.array_equal(Y, y[:, 1:]) and np.array_equal(t, y[:, 0])


@pytest.mark.parametrize("content, message", [
    ("t,w\n0,1\n", "'w' is not an input of the model (its inputs: v)"),
    ("time,v\n0,1\n", "the header has no column 't'"),
    ("t,v\n0,1\n0.5,2\n0.4,3\n", "row 4: t decreases here (t does not decrease from row to row; "
                                  "a repeated t is a jump)"),
    ("t,v\n0,1\n0.5,2\n0.5,3\n0.5,4\n", "row 5: the same t a third time here (a jump is two "
                                         "rows of the same t)"),
    ("t,v\n0,1\n1,nan\n", "row 3: 'nan' is not a finite number"),
])
def test_a_bad_input_file_is_one_line_and_exit_1(tmp_path, content, message):
    (tmp_path / "rc.bg").write_text(RC, encoding="utf-8")
    (tmp_path / "bad.csv").write_text(content, encoding="utf-8")
    done = run_bgc("simulate", "rc.bg", "--scene", "run", "--input", "bad.csv", cwd=tmp_path)
    assert done.returncode == 1
    assert done.stderr.strip().splitlines() == [f"bgc: error: bad.csv: {message}"], done.stderr


STEPS = [(0.0, 0.0), (0.6, 0.0), (0.6, 1.0), (1.3, 1.0), (1.3, 0.25), (1.7, 0.25)]  # two jumps


def test_a_repeated_t_is_a_jump_of_the_input(tmp_path):
    """An RC driven by a stepped input (a repeated t: the row before it on the left, the row
    after it on the right): the capacitor's voltage is the closed form's, each piece an
    exponential, the input's column the steps; the same bytes from C, the Python module and
    the interpreter, and from the data given as numbers."""
    (tmp_path / "rc.bg").write_text(RC, encoding="utf-8")
    write_voltage(tmp_path / "v.csv", STEPS)
    texts = {}
    for backend in BACKENDS + (["vm"] if "c" in BACKENDS else []):
        out = tmp_path / f"{backend}.csv"
        done = run_bgc("simulate", "rc.bg", "--scene", "run", "--input", "v.csv", "--backend",
                       backend, "-o", out, "--stats", cwd=tmp_path)
        assert done.returncode == 0, done.stderr
        assert "events=3" in done.stderr  # at 0.6, 1.3 and 1.7
        texts[backend] = out.read_bytes()
    assert len(set(texts.values())) == 1
    _, y = read_csv(tmp_path / f"{BACKENDS[0]}.csv")
    t = y[:, 0]
    ref = rc_exact(t, STEPS)
    assert np.max(np.abs(y[:, 1] - ref)) < 1e-9
    assert np.array_equal(y[:, 2], np.where(t < 0.6, 0.0, np.where(t < 1.3, 1.0, 0.25)))
    data = {"v": ([t for t, _ in STEPS], [u for _, u in STEPS])}
    for backend in BACKENDS:
        _, Y, _ = bgc.simulate(Source(str(tmp_path / "rc.bg"), RC), "run", backend=backend,
                               inputs=data)
        assert np.array_equal(Y, y[:, 1:])
    three = {"v": ([0.0, 1.0, 1.0, 1.0], [0.0, 1.0, 2.0, 3.0])}
    with pytest.raises(ValueError, match="the same t a third time at t.3."):
        bgc.simulate(Source(str(tmp_path / "rc.bg"), RC), "run", inputs=three)
    from bgc.execute import runner  # the generated module's own simulate(inputs=...)
    module = runner.prepare(bgc.build(Source(str(tmp_path / "rc.bg"), RC), "run"), "python",
                            in_process=True).module
    assert np.array_equal(module.simulate(inputs=data)[1], y[:, 1:])
    with pytest.raises(ValueError, match="the same t a third time at t.3."):
        module.simulate(inputs=three)


def test_the_programs_own_input_refuses_the_same_rows(tmp_path):
    """The generated programs read --input themselves: a repeated t is a jump there too, a t
    that decreases or comes a third time the same line from each (exit 2)."""
    import subprocess
    from bgc.execute import runner
    compiled = bgc.build(Source(str(tmp_path / "rc.bg"), RC), "run")
    (tmp_path / "jump.csv").write_text("t,v\n0,0\n1,0\n1,2\n", encoding="utf-8")
    (tmp_path / "bad.csv").write_text("t,v\n0,1\n1,2\n1,3\n1,4\n", encoding="utf-8")
    said = set()
    for backend in BACKENDS + (["vm"] if "c" in BACKENDS else []):
        argv = runner.prepare(compiled, backend).argv()
        ok = subprocess.run(argv + ["--input", "jump.csv", "--t-end", "2"], cwd=tmp_path,
                            capture_output=True, text=True)
        assert ok.returncode == 0, ok.stderr
        last = [float(v) for v in ok.stdout.splitlines()[-1].split(",")]
        assert last[0] == 2.0 and last[2] == 2.0  # v after the jump
        bad = subprocess.run(argv + ["--input", "bad.csv"], cwd=tmp_path, capture_output=True,
                             text=True)
        assert bad.returncode == 2 and bad.stdout == ""
        said.add(bad.stderr)
    assert said == {"error: bad.csv:5: the same t a third time here (a jump is two rows of the "
                    "same t)\n"}


def test_inputs_inside_components_take_their_paths(tmp_path):
    text = """model two "two sources from outside, in components"
component Source() {
  port p : electrical
  input u = 1
  s : Se(u)
  s -> p
}
a : Source
b : Source
r : R(1)
j : 1
a.p -> j
b.p -> j
j -> r
scene run { time 0 .. 1 every 0.5; outputs r.e }
"""
    (tmp_path / "two.bg").write_text(text, encoding="utf-8")
    write_voltage(tmp_path / "b.csv", [(0.0, 2.0), (1.0, 4.0)], name="b.u")
    done = run_bgc("simulate", "two.bg", "--scene", "run", "--input", "b.csv", "-o",
                   tmp_path / "o.csv", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    _, y = read_csv(tmp_path / "o.csv")
    assert np.allclose(y[:, 1], 1.0 + 2.0 + 2.0 * y[:, 0], rtol=0, atol=1e-14)


MSD = """model msd "a mass on a spring and a damper, pushed by a force from outside"
parameter m = 2.0
parameter k = 8.0
parameter c = 0.5
input F = 1.5 "the applied force"
f : Se(F)
mass : I(m)
spring : C(1/k)
damper : R(c)
j : 1
f -> j
j -> mass
j -> spring
j -> damper
scene run { time 0 .. 1 every 0.1; outputs spring.q, damper.e, F }
"""


def test_linearize_takes_the_declared_inputs():
    """States (p, q): p' = F - c p / m - k q, q' = p / m; outputs q, c p / m, F."""
    lin = bgc.linearize(Source("msd.bg", MSD), "run")
    m, k, c = 2.0, 8.0, 0.5
    assert lin.inputs == ("F",) and lin.states == ("mass.p", "spring.q")
    assert np.array_equal(lin.A, [[-c / m, -k], [1 / m, 0.0]])
    assert np.array_equal(lin.B, [[1.0], [0.0]])
    assert np.array_equal(lin.C, [[0.0, 1.0], [c / m, 0.0], [0.0, 0.0]])
    assert np.array_equal(lin.D, [[0.0], [0.0], [1.0]])
    both = bgc.linearize(Source("msd.bg", MSD), "run", inputs=["F", "c"])  # a parameter too
    assert np.array_equal(both.B[:, 0], [1.0, 0.0])


# ---------------------------------------------------------------- the FMU


@pytest.fixture(scope="module")
def rc_fmu(tmp_path_factory):
    if not toolchain.have_c_compiler():
        pytest.skip("FMU export builds its binary with a C compiler")
    tmp = tmp_path_factory.mktemp("fmu")
    (tmp / "rc.bg").write_text(RC, encoding="utf-8")
    done = run_bgc("compile", "rc.bg", "--scene", "run", "--target", "fmu", "-o", "rc.fmu",
                   cwd=tmp)
    assert done.returncode == 0, done.stderr
    return tmp


def test_an_fmu_with_an_input_matches_bgc_simulate_input(rc_fmu):
    fmpy = pytest.importorskip("fmpy")
    from fmpy.fmi2 import FMU2Model, FMU2Slave
    from fmpy.validation import validate_fmu
    from scipy.integrate import solve_ivp
    path = rc_fmu / "rc.fmu"
    assert validate_fmu(str(path)) == []
    md = fmpy.read_model_description(str(path))
    var = {v.name: v for v in md.modelVariables}
    assert var["v"].causality == "input" and var["v"].variability == "continuous"
    assert float(var["v"].start) == 0.5
    vr = {name: v.valueReference for name, v in var.items()}
    unzip = fmpy.extract(str(path))
    write_voltage(rc_fmu / "v.csv")
    done = run_bgc("simulate", "rc.bg", "--scene", "run", "--input", "v.csv", "-o", "out.csv",
                   cwd=rc_fmu)
    assert done.returncode == 0, done.stderr
    _, want = read_csv(rc_fmu / "out.csv")
    # Model Exchange: the input set at every evaluation, SciPy integrating piece by piece
    ts, us = [t for t, _ in VOLTAGE], [u for _, u in VOLTAGE]
    model = FMU2Model(guid=md.guid, unzipDirectory=unzip,
                      modelIdentifier=md.modelExchange.modelIdentifier, instanceName="me")
    try:
        model.instantiate()
        model.setupExperiment(startTime=0.0)
        model.enterInitializationMode()
        model.setReal([vr["v"]], [0.0])
        model.exitInitializationMode()
        model.newDiscreteStates()
        model.enterContinuousTimeMode()

        def rhs(t, x):
            model.setTime(t)
            model.setReal([vr["v"]], [float(np.interp(t, ts, us))])
            model.setContinuousStates((ctypes.c_double * 1)(*x), 1)
            dx = (ctypes.c_double * 1)()
            model.getDerivatives(dx, 1)
            return [dx[0]]
        x, got = [0.0], []
        grid = want[:, 0]
        edges = [0.0] + [t for t in ts if 0.0 < t < grid[-1]] + [grid[-1]]
        for a, b in zip(edges, edges[1:]):
            sol = solve_ivp(rhs, (a, b), x, rtol=1e-12, atol=1e-14, dense_output=True,
                            method="DOP853")
            inside = (grid >= a) & ((grid < b) | (b == grid[-1]))
            got += list(zip(grid[inside], sol.sol(grid[inside])[0]))
            x = sol.y[:, -1]
        got = np.array(sorted(dict(got).items()))
        assert np.max(np.abs(got[:, 1] / 0.25 - want[:, 1])) < 1e-6  # q / C
    finally:
        model.terminate()
        model.freeInstance()
    # Co-Simulation: the input set between steps, held during each: the closed form of a
    # staircase, each stair's exponential from where the last one left
    slave = FMU2Slave(guid=md.guid, unzipDirectory=unzip,
                      modelIdentifier=md.coSimulation.modelIdentifier, instanceName="cs")
    try:
        slave.instantiate()
        slave.setupExperiment(startTime=0.0)
        slave.enterInitializationMode()
        slave.exitInitializationMode()
        e, h = 0.0, 0.1
        for k in range(20):
            u = math.sin(0.7 * k) + 0.3
            slave.setReal([vr["v"]], [u])
            slave.doStep(k * h, h)
            e = u + (e - u) * math.exp(-h / TAU)
            assert abs(slave.getReal([vr["c.e"]])[0] - e) < 1e-6
    finally:
        slave.terminate()
        slave.freeInstance()
