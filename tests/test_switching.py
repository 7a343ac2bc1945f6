"""Coupled switched elements (docs/hybrid.md, section 13): a switch and its freewheeling diode
chosen together, against exact piecewise-linear references.

The references are the converters' linear circuits solved exactly between events (matrix
exponentials of the augmented system), the switching instants the square wave's edges and the
instants where the coil's current reaches zero (found by brentq on the exact solution to
1e-15 relative): nothing of bgc's."""
from __future__ import annotations

import io

import numpy as np
import pytest
from scipy.linalg import expm
from scipy.optimize import brentq

from bgc.execute import runner
from conftest import ROOT, have_cc, run_bgc
from helpers import built

BUCK = ROOT / "models" / "buck.bg"
BUCK_LIBRARY = ROOT / "tests" / "models" / "buck_library.bg"
BOOST = ROOT / "tests" / "models" / "boost.bg"
F, DUTY, L, C = 1e5, 0.5, 1e-4, 1e-5


def _modes(kind, V, R):
    """{mode: (A, b)} of x' = A x + b, x = (coil current, capacitor voltage): the switch
    closed ("on"), open with the diode conducting ("free"), open with both blocking ("dcm")."""
    load = -1 / (R * C)
    if kind == "buck":
        on = ([[0, -1 / L], [1 / C, load]], [V / L, 0])
        free = ([[0, -1 / L], [1 / C, load]], [0, 0])
    else:  # boost: closed, the switch shorts the coil to ground; open, it feeds the output
        on = ([[0, 0], [0, load]], [V / L, 0])
        free = ([[0, -1 / L], [1 / C, load]], [V / L, 0])
    dcm = ([[0, 0], [0, load]], [0, 0])
    return {k: (np.array(a, float), np.array(b, float)) for k, (a, b) in
            (("on", on), ("free", free), ("dcm", dcm))}


def _flow(mode, x, h):
    A, b = mode
    M = np.zeros((3, 3))
    M[:2, :2], M[:2, 2] = A, b
    E = expm(M * h)
    return E[:2, :2] @ x + E[:2, 2]


def reference(kind, V, R, t_out):
    """The exact trajectory at t_out from rest, and how many periods end in discontinuous
    conduction."""
    modes, T = _modes(kind, V, R), 1 / F
    x, t, k, segments = np.zeros(2), 0.0, 0, []
    while t < t_out[-1]:
        off, end = (k + DUTY) * T, (k + 1) * T
        segments.append((t, "on", x.copy()))
        x, t = _flow(modes["on"], x, off - t), off
        if _flow(modes["free"], x, end - t)[0] < 0:
            zero = brentq(lambda s: _flow(modes["free"], x, s)[0], 0, end - t, xtol=1e-18,
                          rtol=1e-15)
            segments.append((t, "free", x.copy()))
            x, t = _flow(modes["free"], x, zero), t + zero
            x[0] = 0.0
            segments.append((t, "dcm", x.copy()))
            x, t = _flow(modes["dcm"], x, end - t), end
        else:
            segments.append((t, "free", x.copy()))
            x, t = _flow(modes["free"], x, end - t), end
        k += 1
    starts = np.array([s[0] for s in segments])
    out = []
    for tt in t_out:
        t0, mode, x0 = segments[np.searchsorted(starts, tt, side="right") - 1]
        out.append(_flow(modes[mode], x0, tt - t0))
    return np.array(out), sum(1 for s in segments if s[1] == "dcm")


def simulate(tmp_path, model, backend="c", params=(), t_end="0.5e-3"):
    out = tmp_path / f"{model.stem}-{backend}-{'-'.join(params)}.csv"
    args = ["simulate", model, "--scene", "run", "-o", out, "--backend", backend,
            "--t-end", t_end]
    for p in params:
        args += ["-p", p]
    result = run_bgc(*args)
    assert result.returncode == 0, result.stderr
    return out


needs_cc = pytest.mark.skipif(not have_cc(), reason="no C compiler")


@needs_cc
@pytest.mark.parametrize("model, kind, V, R, dcm", [
    (BUCK, "buck", 12.0, 5.0, False),        # continuous conduction once started
    (BUCK, "buck", 12.0, 50.0, True),        # a light load: the coil's current stops each period
    (BUCK_LIBRARY, "buck", 12.0, 50.0, True),  # the same of the standard library's parts
    (BOOST, "boost", 5.0, 20.0, False),
    (BOOST, "boost", 5.0, 500.0, True),
])
def test_converters_as_drawn_match_their_exact_piecewise_linear_solution(
        tmp_path, model, kind, V, R, dcm):
    out = simulate(tmp_path, model, params=(f"R={R}",))
    data = np.loadtxt(out, delimiter=",", skiprows=1)
    exact, periods_in_dcm = reference(kind, V, R, data[:, 0])
    assert (periods_in_dcm > 10) == dcm
    for j in (0, 1):  # coil current, capacitor voltage: 1e-8 of their largest values
        scale = np.max(np.abs(exact[:, j]))
        assert np.max(np.abs(data[:, 1 + j] - exact[:, j])) < 1e-8 * scale


@needs_cc
def test_a_coupled_switch_and_diode_give_the_same_bytes_in_every_backend(tmp_path):
    runs = [simulate(tmp_path, BUCK, backend, ("R=50",), "0.1e-3").read_bytes()
            for backend in ("c", "python", "vm")]
    assert runs[0] == runs[1] == runs[2]


def test_the_switch_and_the_diode_are_one_block_whose_modes_are_chosen_together():
    report = run_bgc("check", BUCK)
    assert report.returncode == 0, report.stderr
    assert "sw.lambda, fw.lambda (2 unknowns)" in report.stdout
    # the switch imposes its current and the diode the node's voltage: no causal conflict
    assert "a->sw: sw -> a" in report.stdout and "k->fw: k -> fw" in report.stdout


NO_MODE = """model short "a closed switch shorts the source through a forward diode"
parameter V = 1.0
src : Se(V)
d : D
sw : Sw(t >= 0.5)
src -> a
a : 1
a -> d
a -> sw
scene run {
  time 0 .. 1 every 0.1
  outputs d.f
}
"""


@needs_cc
def test_a_model_with_no_consistent_mode_stops_at_the_instant_naming_the_elements(tmp_path):
    """Open, the switch leaves the diode blocking (its flow zero, its effort -V: no current
    can flow); closed at t = 0.5, conducting would short the source (V = 0) and blocking would
    hold a forward voltage V > 0: no combination of modes is consistent."""
    model = tmp_path / "short.bg"
    model.write_text(NO_MODE)
    out = tmp_path / "short.csv"
    result = run_bgc("simulate", model, "--scene", "run", "-o", out, "--backend", "c")
    assert result.returncode == 1
    assert "at t = 0.5: algebraic block 1 (d.lambda, sw.lambda) is singular" in result.stderr
    rows = np.loadtxt(out, delimiter=",", skiprows=1)
    assert rows[-1, 0] < 0.5 and np.all(rows[:, 1] == 0)


@needs_cc
@pytest.mark.parametrize("kind", ["ModelExchange", "CoSimulation"])
def test_the_buck_converter_runs_as_an_fmu(tmp_path, kind):
    """Co-Simulation steps bgc's own solver (the reference's 1e-8); Model Exchange is
    integrated by FMPy's CVODE, which reaches the switch's edges as the double below them
    (5e-6 as 4.9999999999999996e-06): the FMU takes such a time event there, and the run is
    CVODE's accuracy away from the exact solution."""
    fmpy = pytest.importorskip("fmpy")
    fmu = tmp_path / "buck.fmu"
    built = run_bgc("compile", BUCK, "--scene", "run", "--target", "fmu", "-o", fmu)
    assert built.returncode == 0, built.stderr
    options = {"relative_tolerance": 1e-10} if kind == "ModelExchange" else {}
    result = fmpy.simulate_fmu(str(fmu), fmi_type=kind, stop_time=1e-4, output_interval=1e-7,
                               output=["l.f", "c.e"], **options)
    t = np.array(result["time"])
    exact, _ = reference("buck", 12.0, 5.0, t)
    got = np.column_stack([result["l.f"], result["c.e"]])
    tolerance = 1e-8 if kind == "CoSimulation" else 1e-4
    for j in (0, 1):  # (the states are continuous at the edges: rows at events compare too)
        assert np.max(np.abs(got[:, j] - exact[:, j])) < tolerance * np.max(np.abs(exact[:, j]))


HBRIDGE = ROOT / "tests" / "models" / "hbridge.bg"
HBRIDGE_LIBRARY = ROOT / "tests" / "models" / "hbridge_library.bg"


@needs_cc
@pytest.mark.parametrize("model", [HBRIDGE, HBRIDGE_LIBRARY], ids=["plain", "library"])
def test_an_h_bridge_with_dead_time_drives_a_dc_motor_as_its_exact_solution(tmp_path, model):
    """Four switches with their anti-parallel diodes (eight coupled elements): s1 and s4 closed
    for 70 % of each 50 us period, s2 and s3 for 20 %, all four open for 5 % after each; in the
    dead time the diodes carry the motor's current (the bridge applies -V while it is positive,
    +V while negative, and holds it at zero where it would reverse). The motor: L di/dt =
    v - R i - k w, J dw/dt = k i - b w, exact by matrix exponentials between the instants."""
    V, f, D, dead, R, L, k, J, b = 24.0, 2e4, 0.7, 0.05, 1.0, 1e-3, 0.05, 1e-4, 1e-5
    out = simulate(tmp_path, model, t_end="1e-3")
    data = np.loadtxt(out, delimiter=",", skiprows=1)
    A = np.array([[-R / L, -k / L], [k / J, -b / J]])
    A_held = np.array([[0, 0], [0, -b / J]])  # (the current held at zero)

    def flow(x, v, h, held=False):
        M = np.zeros((3, 3))
        M[:2, :2], M[0, 2] = (A_held, 0.0) if held else (A, v / L)
        E = expm(M * h)
        return E[:2, :2] @ x + E[:2, 2]

    T, x, t, n, segments = 1 / f, np.zeros(2), 0.0, 0, []

    def dead_time(t, end, x):
        while t < end:
            if x[0] == 0:
                segments.append((t, 0.0, x, True))
                return flow(x, 0.0, end - t, True)
            v = -V if x[0] > 0 else V
            after = flow(x, v, end - t)
            if np.sign(after[0]) == np.sign(x[0]):
                segments.append((t, v, x, False))
                return after
            zero = brentq(lambda s: flow(x, v, s)[0], 0, end - t, xtol=1e-18, rtol=1e-15)
            segments.append((t, v, x, False))
            x = flow(x, v, zero)
            x[0], t = 0.0, t + zero
        return x

    while t < data[-1, 0]:
        for v, end in ((V, (n + D) * T), (None, (n + D + dead) * T), (-V, (n + 1 - dead) * T),
                       (None, (n + 1) * T)):
            if v is None:
                x = dead_time(t, end, x)
            else:
                segments.append((t, v, x, False))
                x = flow(x, v, end - t)
            t = end
        n += 1
    starts = np.array([s[0] for s in segments])
    exact = np.array([flow(segments[j][2], segments[j][1], tt - segments[j][0], segments[j][3])
                      for tt, j in zip(data[:, 0],
                                       np.searchsorted(starts, data[:, 0], side="right") - 1)])
    for j in (0, 1):
        assert np.max(np.abs(data[:, 1 + j] - exact[:, j])) < 1e-8 * np.max(np.abs(exact[:, j]))


RL_SWITCHED = """model rl "a coil at 1 A in a loop closed by a switch of a time source"
import electrical as el
coil : el.inductor(l = 1, i0 = 1)
res : el.resistor(r = 1)
sw : el.ideal_switch(on = ON)
g : el.ground()
a : 0
b : 0
a -> coil.p
coil.n -> b
b -> res.p
res.n -> sw.p
sw.n -> g.p
g2 : el.ground()
a -> g2.p
scene run {
  time 0 .. 2 every 0.01
  outputs coil.store.f
  solver dopri5(rtol = 1e-10, atol = 1e-12)
}
"""


@pytest.mark.parametrize("on", ["square(10, 0.5)", "1 - step(5)", "pulse(0, 5)"])
def test_a_switch_closed_at_t0_through_an_instance_argument_starts_closed(tmp_path, on):
    """The switch's condition reads a signal (the instance's argument) of a time source: at t0
    it reads the source's value there, so the coil's current decays as exp(-t) from the start."""
    model = tmp_path / "rl.bg"
    model.write_text(RL_SWITCHED.replace("ON", on))
    out = tmp_path / "rl.csv"
    result = run_bgc("simulate", model, "--scene", "run", "-o", out, "--backend", "python")
    assert result.returncode == 0, result.stderr
    data = np.loadtxt(out, delimiter=",", skiprows=1)
    assert np.max(np.abs(data[:, 1] - np.exp(-data[:, 0]))) < 1e-8


BRIDGE = """model bridge "a single-phase bridge of four ideal diodes with a smoothing capacitor"
parameter V = 10.0
parameter w = 314.159
parameter C = 1e-3
parameter R = 100.0
src : MSe(V*sin(w*t))
d1 : D
d2 : D
d3 : D
d4 : D
c : C(C)
r : R(R)
src -> s
s : 1
b -> s
s -> a
a : 0
b : 0
p : 0
j1 : 1
a -> j1
j1 -> p
j1 -> d1
j2 : 1
b -> j2
j2 -> p
j2 -> d2
j3 : 1
j3 -> a
j3 -> d3
j4 : 1
j4 -> b
j4 -> d4
p -> c
p -> r
scene run {
  time 0 .. 0.1 every 1e-4
  outputs c.e
  solver dopri5(rtol = 1e-10, atol = 1e-12)
}
"""


BRIDGE_LIBRARY = """model bridge_lib "the same with the standard library's diode_bridge"
import electrical as el
parameter V = 10.0
parameter w = 314.159
parameter C = 1e-3
parameter R = 100.0
src : MSe(V*sin(w*t))
bridge : el.diode_bridge()
c : C(C)
r : R(R)
p : 0
src -> bridge.ac
bridge.dc -> p
p -> c
p -> r
scene run {
  time 0 .. 0.1 every 1e-4
  outputs c.e
  solver dopri5(rtol = 1e-10, atol = 1e-12)
}
"""


@needs_cc
@pytest.mark.parametrize("text", [BRIDGE, BRIDGE_LIBRARY], ids=["plain", "library"])
def test_a_diode_bridge_with_a_smoothing_capacitor_is_the_peak_rectifier(tmp_path, text):
    """The source floats: while all four diodes block, its potential is undetermined (any
    value between the diodes' limits is taken), and while two conduct the capacitor follows
    |u| as long as their current C d|u|/dt + |u|/R is positive, i.e. until tan(w t) = -w R C
    within the half period; then it discharges, v = v_off exp(-(t - t_off)/RC), until it
    meets |u| again (brentq on the closed forms)."""
    V, w, C, R = 10.0, 314.159, 1e-3, 100.0
    model = tmp_path / "bridge.bg"
    model.write_text(text)
    out = tmp_path / "bridge.csv"
    result = run_bgc("simulate", model, "--scene", "run", "-o", out, "--backend", "c")
    assert result.returncode == 0, result.stderr
    data = np.loadtxt(out, delimiter=",", skiprows=1)
    half, tau = np.pi / w, R * C
    off = (np.pi - np.arctan(w * R * C)) / w
    segments, start, k = [], 0.0, 0
    while start < data[-1, 0]:
        t_off = k * half + off
        v_off = V * abs(np.sin(w * t_off))
        meets = brentq(lambda s: v_off * np.exp(-(s - t_off) / tau) - V * abs(np.sin(w * s)),
                       (k + 1) * half + 1e-12, (k + 1.5) * half, xtol=1e-16, rtol=1e-15)
        segments += [(start, None), (t_off, v_off)]
        start, k = meets, k + 1
    at = np.array([s[0] for s in segments])
    exact = []
    for t in data[:, 0]:
        t0, v0 = segments[np.searchsorted(at, t, side="right") - 1]
        exact.append(V * abs(np.sin(w * t)) if v0 is None else v0 * np.exp(-(t - t0) / tau))
    assert np.max(np.abs(data[:, 1] - np.array(exact))) < 1e-8 * V


CLUTCH = ROOT / "tests" / "models" / "one_way_clutch.bg"
CLUTCH_LIBRARY = ROOT / "tests" / "models" / "one_way_clutch_library.bg"


def _one_way_clutch(grid, J1=0.1, J2=0.3, b2=0.05, Fc=0.3, Fs=0.5, t_on=3.0):
    """The one-way clutch as an automaton of two modes, integrated by SciPy (DOP853 at
    rtol 1e-13) with a restart at each switch: locked (one speed, (J1 + J2) w' = tau - b2 w,
    the coupling carrying T = (J2 tau + J1 b2 w)/(J1 + J2), which the freewheel holds
    whatever it is below zero and the clutch up to Fs) until T exceeds the clutch's limit;
    slipping (w1 > w2: the freewheel runs free, the clutch carries Fc) until the speeds
    meet again.  Nothing of bgc's."""
    from scipy.integrate import solve_ivp

    def tau(t):
        return np.sin(2 * t) - 0.2

    t, y, locked, ts, ys = 0.0, np.zeros(2), True, [], []
    while t < grid[-1]:
        stop, on = (t_on, 0.0) if t < t_on else (grid[-1], 1.0)
        if locked:
            def event(t, w):
                return (J2 * tau(t) + J1 * b2 * w[0]) / (J1 + J2) - Fs * on

            def rhs(t, w):
                return [(tau(t) - b2 * w[0]) / (J1 + J2)]
            y0 = [y[0]]
        else:
            def event(t, w):
                return w[0] - w[1]

            def rhs(t, w):
                return [(tau(t) - Fc * on) / J1, (Fc * on - b2 * w[1]) / J2]
            y0 = list(y)
        event.terminal, event.direction = True, 1 if locked else -1
        s = solve_ivp(rhs, (t, stop), y0, method="DOP853", rtol=1e-13, atol=1e-16,
                      events=event, dense_output=True)
        for tt in grid[((grid > t) if ts else (grid >= t)) & (grid <= s.t[-1])]:
            v = s.sol(tt)
            ts.append(tt)
            ys.append([v[0], v[-1]])
        t, v = s.t[-1], s.y[:, -1]
        y = np.array([v[0], v[-1]])
        if s.status == 1:
            locked = not locked
        elif locked and (J2 * tau(t) + J1 * b2 * y[0]) / (J1 + J2) > Fs * (t >= t_on):
            locked = False  # (the clutch engages while the freewheel's lock carries more)
    return np.array(ys)


def _clutch_run(backend, **options):
    """The plain clutch's run scene (built once for the process), run by backend: its CSV."""
    compiled = built(CLUTCH, "run")
    names = [p.name for p in compiled.program.params]
    result = runner.run(runner.prepare(compiled, backend),
                        runner.settings_for(compiled.program.scene, names, **options))
    assert result.status == 0, result.stderr
    return result.csv


def _check_clutch(csv_text: str, log: str):
    data = np.loadtxt(io.StringIO(csv_text), delimiter=",", skiprows=1)
    exact = _one_way_clutch(data[:, 0])
    assert np.max(np.abs(data[:, 1:3] - exact)) < 1e-9 * np.max(np.abs(exact))
    assert "cl.stick,0 -> 1" in log and "fw.blocking,1 -> 0" in log  # (it slips and locks)


@needs_cc
def test_a_one_way_clutch_of_a_freewheel_beside_a_clutch_is_its_automaton(tmp_path):
    """A freewheel D and a clutch Fr on one relative speed: both hold it while locked (how
    the torque splits between them is not determined: any split inside both cones is taken),
    the clutch slips above its limit once engaged, and the freewheel alone locks before.  The
    model built once, its C, Python and interpreter runs the same bytes."""
    events = tmp_path / "events.csv"
    _check_clutch(_clutch_run("c", events=str(events)), events.read_text())
    runs = [_clutch_run(backend, t_end=5.0) for backend in ("c", "python", "vm")]
    assert runs[0] == runs[1] == runs[2]


@needs_cc
def test_the_one_way_clutch_of_library_parts_is_its_automaton_from_the_command_line(tmp_path):
    """The same clutch of mechanics.one_way_clutch, by `bgc simulate --events`."""
    out, events = tmp_path / "clutch.csv", tmp_path / "events.csv"
    result = run_bgc("simulate", CLUTCH_LIBRARY, "--scene", "run", "-o", out, "--events",
                     events, "--backend", "c")
    assert result.returncode == 0, result.stderr
    _check_clutch(out.read_text(), events.read_text())


def test_a_condition_holding_a_time_source_keeps_it():
    """SymPy's Piecewise, given (1, x > 2*step(3)), folds the condition and rewrites it as an
    ITE that takes the step's event value (a symbol) for always true: x > 2, silently.  bgc's
    conditions are unnested first (bgc.symbolic.conditions): both sides of the step stay."""
    import sympy as sp

    import bgc.symbolic  # noqa: F401 (installs the guard)
    event, x = sp.Symbol("event#0"), sp.Symbol("x")
    cond = sp.Piecewise((1, x > 2 * sp.Piecewise((1, event), (0, True))), (0, True))
    for e_value, x_value, expected in ((False, 1, 1), (True, 1, 0), (True, 3, 1),
                                       (False, -1, 0)):
        assert cond.xreplace({event: sp.true if e_value else sp.false, x: x_value}) == expected


def test_a_zero_product_of_a_selection_is_sympys():
    """groups._times(a, 0): SymPy's a*0 (zero, or NaN where a factor is infinite), without
    asking a selection finite by construction whether it is infinite."""
    import sympy as sp

    from bgc.front.graph import var
    from bgc.middle import groups
    from bgc.symbolic.algebra import Max

    x, y, e = var("a.p"), var("b.q"), sp.Symbol("event#0")
    on = sp.Piecewise((sp.Integer(1), e), (sp.Integer(0), True))
    finite = [x * y, on * (1 - (x - 2 * on) ** 2), sp.Abs(x) + Max(x, y) ** 3, on]
    others = [x * sp.oo, sp.Symbol("u") * x, 1 / x, sp.Piecewise((sp.zoo, e), (x, True))]
    for a in finite + others:
        assert groups._times(a, sp.Integer(0), {}) == a * sp.Integer(0)
        assert groups._times(a, x, {}) == a * x
    assert all(groups._finite(a, {}) for a in finite)
    assert not any(groups._finite(a, {}) for a in others)
