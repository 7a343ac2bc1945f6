"""Laws continuous at a knee (docs/hybrid.md, "Knees"): a relation that has just crossed at an
event keeps its new value until it crosses back by more than the solver's resolution.

The B6 bridge of tests/models/b6_knee.bg has six diodes, each an R element with an on-resistance,
an off-conductance and a knee voltage written as a conditional (Modelica's IdealDiode); its run
stopped at its first event as chattering.  The reference is the bridge as an automaton, written
here: per combination of diode segments the node equations are linear, solved with numpy for that
combination into x' = A x + B V(t) + a and the knee indicators g = C x + D V(t) + c; SciPy's
Radau integrates each segment at rtol 1e-11, its events on the indicators end it, the diode
whose indicator crossed changes segment, and the next segment starts there.  Nothing of bgc's."""
from __future__ import annotations

import csv
import functools
import io

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from conftest import ROOT, have_cc, run_bgc

B6 = ROOT / "tests" / "models" / "b6_knee.bg"
P = dict(Vm=100.0, w=2 * np.pi * 50, L=1e-3, Ron=1e-2, Goff=1e-5, Vknee=0.7, Cdc=1e-3,
         Rl=20.0)
PHASES = (0.0, -2 * np.pi / 3, 2 * np.pi / 3)
# (AC node, upper): D1, D3, D5 from a, b, c to the plus rail; D4, D6, D2 from the reference
DIODES = ((0, True), (1, True), (2, True), (0, False), (1, False), (2, False))
NAMES = ("D1", "D3", "D5", "D4", "D6", "D2")


def _law(on):
    """The diode current G v + c on its segment."""
    if on:
        return 1 / P["Ron"], (P["Goff"] - 1 / P["Ron"]) * P["Vknee"]
    return P["Goff"], 0.0


def _segment(on):
    """x' = A x + B V + a and the indicators g = C x + D V + c (diode voltage minus the knee)
    for the diodes' segments `on`; x = (i_a, i_b, v_dc), V the three phase voltages."""
    # the potentials e = (e_a, e_b, e_c, e_star): K e = X x + W V + k
    K, X, W, k = np.zeros((4, 4)), np.zeros((4, 3)), np.zeros((4, 3)), np.zeros(4)
    X[0, 0] = X[1, 1] = 1.0
    X[2, 0] = X[2, 1] = -1.0  # i_c = -i_a - i_b: the star point is not connected
    for j, (n, upper) in enumerate(DIODES):
        G, c = _law(on[j])
        K[n, n] += G
        if upper:  # out of n into the plus rail at v_dc: G (e_n - v_dc) + c
            X[n, 2] += G
            k[n] -= c
        else:  # from the reference into n: G (0 - e_n) + c
            k[n] += c
    K[3, :3], K[3, 3], W[3, :] = -1.0, 3.0, -1.0  # the coils' voltages add to zero
    Ex, Ev, e0 = (np.linalg.solve(K, M) for M in (X, W, k))
    S, T = np.zeros((6, 4)), np.zeros((6, 3))  # the diode voltages S e + T x
    for j, (n, upper) in enumerate(DIODES):
        S[j, n] = 1.0 if upper else -1.0
        T[j, 2] = -1.0 if upper else 0.0
    C, D, c = S @ Ex + T, S @ Ev, S @ e0 - P["Vknee"]
    G = np.array([_law(s)[0] for s in on])
    g0 = np.array([_law(s)[1] for s in on])
    A, B, a = np.zeros((3, 3)), np.zeros((3, 3)), np.zeros(3)
    for n in range(2):  # L i_n' = e_star + V_n - e_n
        A[n] = (Ex[3] - Ex[n]) / P["L"]
        B[n] = (Ev[3] - Ev[n]) / P["L"]
        B[n, n] += 1 / P["L"]
        a[n] = (e0[3] - e0[n]) / P["L"]
    # Cdc v_dc' = the upper diodes' currents - v_dc / Rl
    A[2] = G[:3] @ (S @ Ex + T)[:3] / P["Cdc"]
    A[2, 2] -= 1 / (P["Rl"] * P["Cdc"])
    B[2] = G[:3] @ D[:3] / P["Cdc"]
    a[2] = (G[:3] @ (S @ e0)[:3] + g0[:3].sum()) / P["Cdc"]
    return A, B, a, C, D, c


def reference(t_out):
    """(the states at t_out, the switchings [(t, diode name)]) from rest, all diodes off.  The
    sources are states too, z = (x, sin(w t), cos(w t), 1), so that each segment is z' = M z:
    V = Vm (sin(w t) cos(phase) + cos(w t) sin(phase))."""
    w = P["w"]
    Phi = P["Vm"] * np.array([[np.cos(ph), np.sin(ph)] for ph in PHASES])
    z, t, on = np.array([0.0, 0.0, 0.0, 0.0, 1.0, 1.0]), 0.0, [False] * 6
    out, switched = np.full((len(t_out), 3), np.nan), []
    while True:
        A, B, a, C, D, c = _segment(on)
        M = np.zeros((6, 6))
        M[:3, :3], M[:3, 3:5], M[:3, 5] = A, B @ Phi, a
        M[3, 4], M[4, 3] = w, -w
        rows = np.hstack([C, D @ Phi, c[:, None]])
        events = []
        for j in range(6):
            def g(tt, zz, row=rows[j]):
                return row @ zz
            g.terminal, g.direction = True, (-1.0 if on[j] else 1.0)
            events.append(g)
        sol = solve_ivp(lambda tt, zz: M @ zz, (t, t_out[-1]), z, method="Radau", rtol=1e-11,
                        atol=1e-20, jac=M, events=events, dense_output=True)
        inside = (t_out >= t) & (t_out <= sol.t[-1])
        if inside.any():
            out[inside] = sol.sol(t_out[inside])[:3].T
        if sol.status != 1:
            return out, switched
        for j in range(6):
            if len(sol.t_events[j]):
                on[j] = not on[j]
                switched.append((sol.t[-1], NAMES[j]))
        z, t = sol.y[:, -1], sol.t[-1]


def _simulate(tmp_path, backend, *options, model=B6):
    out, log = tmp_path / f"b6-{backend}.csv", tmp_path / f"b6-{backend}-events.csv"
    result = run_bgc("simulate", model, "--scene", "run", "--backend", backend, "-o", out,
                     "--events", log, *options)
    assert result.returncode == 0, result.stderr
    return out, log


def _switchings(log):
    rows = list(csv.reader(io.StringIO(log.read_text())))[1:]
    return [(float(t), what.split(".")[0], change) for t, what, change in rows]


@functools.lru_cache(maxsize=None)
def _reference_at(times):
    return reference(np.array(times))


GRID = tuple(np.linspace(0.0, 0.02, 201))  # one mains period, every 1e-4 (the scene's)


def _errors(out):
    """bgc's run in out, on GRID, against the reference: the largest errors of its currents
    and DC voltage relative to their largest values, and the reference's switchings."""
    data = np.loadtxt(out, delimiter=",", skiprows=1)
    assert np.allclose(data[:, 0], GRID, rtol=0, atol=1e-15)
    exact, switched = _reference_at(GRID)
    err = np.max(np.abs(data[:, 1:] - exact), axis=0) / np.max(np.abs(exact), axis=0)
    return err, switched


@pytest.mark.parametrize("solver, bound, t_bound", [
    ("rodas5p", 1e-10, 1e-11),  # about 7e-12 (the reference's own error) and 7e-13
    ("radau5", 1e-9, 1e-7),     # the scene's: about 1.4e-10 and 5e-8
])
def test_a_b6_bridge_of_knee_diodes_matches_its_piecewise_linear_reference(
        tmp_path, solver, bound, t_bound):
    """One mains period from rest, each diode switching on and off once: bgc's currents and
    DC voltage within `bound` of their largest values of the reference, and its event log the
    reference's switchings, one row each, within t_bound of the period: no diode switches
    back at the instant it switched (the run stopped there as chattering before).  A
    blocking diode's voltage is its current through 1/Goff: its switching time is as
    sensitive, and radau5's is the less accurate."""
    backend = "c" if have_cc() else "vm"
    out, log = _simulate(tmp_path, backend, "--solver", solver, "--t-end", "0.02")
    err, switched = _errors(out)
    assert np.all(err < bound), err
    got = _switchings(log)
    assert [name for _, name, _ in got] == [name for _, name in switched]
    assert len(got) == 12
    on = dict.fromkeys(NAMES, "0")
    for t, name, change in got:  # each row a switching, alternately on and off
        assert change == f"{on[name]} -> {'1' if on[name] == '0' else '0'}"
        on[name] = change[-1]
    for (t, _, _), (t_ref, _) in zip(got, switched):
        assert abs(t - t_ref) <= t_bound * 0.02


def test_the_library_b6_bridge_matches_the_same_reference(tmp_path):
    """tests/models/b6_library.bg, the bridge as electrical.b6_bridge of knee_diodes: the
    reference's currents and DC voltage within 1e-10 of their largest values, its twelve
    switchings in order (the paths now bridge.d1.d ...)."""
    backend = "c" if have_cc() else "vm"
    out, log = _simulate(tmp_path, backend, "--solver", "rodas5p", "--t-end", "0.02",
                         model=ROOT / "tests" / "models" / "b6_library.bg")
    err, switched = _errors(out)
    assert np.all(err < 1e-10), err
    names = {f"bridge.d{k}": f"D{k}" for k in range(1, 7)}
    got = [names[".".join(what.split(".")[:2])] for _, what, _ in _switchings_paths(log)]
    assert got == [name for _, name in switched]


def _switchings_paths(log):
    rows = list(csv.reader(io.StringIO(log.read_text())))[1:]
    return [(float(t), what, change) for t, what, change in rows]


def test_the_knees_give_the_same_bytes_in_every_backend(tmp_path):
    """C, Python and the interpreter: the same CSV and event log bytes through the first
    switchings, a diode turning off at its knee among them (where the off branch's indicator
    sees the on branch's rounding magnified by 1/(Ron Goff))."""
    backends = (["c"] if have_cc() else []) + ["python", "vm"]
    runs = [_simulate(tmp_path, b, "--t-end", "0.005") for b in backends]
    assert len(_switchings(runs[0][1])) >= 4
    assert len({out.read_bytes() for out, _ in runs}) == 1
    assert len({log.read_bytes() for _, log in runs}) == 1


KNEE = """model knee "a ramp through a resistor into a diode with a knee"
parameter Ron = 0.01
parameter Goff = 1e-5
parameter Vknee = 0.7
parameter J = Goff*Vknee "the diode's current at the knee from above: continuous there"
u : Se(t)
s : 1
r : R(1)
d : R(f = if e > Vknee then (e - Vknee)/Ron + J else Goff*e)
u -> s
s -> r
s -> d
scene run { time 0 .. 2 every 0.5; outputs d.e, d.f }
"""


@pytest.mark.parametrize("backend", (["c"] if have_cc() else []) + ["python", "vm"])
def test_a_knee_switches_once_and_a_jump_at_it_still_stops_as_chattering(tmp_path, backend):
    """The diode in series with a resistor, driven by a ramp: its law continuous at the knee
    switches once (at u = Vknee (1 + Goff), its current then (u - Vknee)/(1 + Ron) in closed
    form); with a jump at the knee (J = 1: conducting, its voltage falls below the knee;
    blocking, it rises above) the event iteration does not settle, and the run stops naming
    the condition."""
    model = tmp_path / "knee.bg"
    model.write_text(KNEE)
    out, log = tmp_path / "knee.csv", tmp_path / "knee-events.csv"
    result = run_bgc("simulate", model, "--scene", "run", "--backend", backend, "-o", out,
                     "--events", log)
    assert result.returncode == 0, result.stderr
    rows = list(csv.reader(io.StringIO(log.read_text())))[1:]
    assert [r[1:] for r in rows] == [["d.e > Vknee", "0 -> 1"]]
    assert float(rows[0][0]) == pytest.approx(0.7 * (1 + 1e-5), rel=1e-12)
    data = np.loadtxt(out, delimiter=",", skiprows=1)
    t, f = data[:, 0], data[:, 2]
    assert f[t > 1] == pytest.approx((t[t > 1] - 0.7 * (1 - 1e-5 * 0.01)) / 1.01, rel=1e-12)
    result = run_bgc("simulate", model, "--scene", "run", "--backend", backend, "-o", out,
                     "-p", "J=1")
    assert result.returncode == 1
    assert "chattering: more than 100 events at one instant, the event iteration does not " \
           "settle ('d.e > Vknee' keeps changing: a Zeno model?)" in result.stderr, \
        result.stderr


@pytest.mark.skipif(not have_cc(), reason="FMU export builds its binary with a C compiler")
def test_the_bridge_as_an_fmu_in_co_simulation_and_model_exchange(tmp_path):
    """The bridge's FMU under FMPy over one period: Co-Simulation (bgc's solver inside
    fmi2DoStep) within 1e-9 of the reference, as bgc's own run; Model Exchange (CVODE locating
    the sign changes of the indicators, moved by their bands, and FMPy's event loop) runs
    through every switching, within 1e-6 at CVODE's rtol 1e-10 (about 5e-8 reached)."""
    fmpy = pytest.importorskip("fmpy")
    from bgc.codegen import fmu
    from test_events import build
    path = tmp_path / "b6.fmu"
    path.write_bytes(fmu.build_fmu(build(B6.read_text(), "run")))
    exact, _ = _reference_at(GRID)
    scale = np.max(np.abs(exact), axis=0)
    for kind, options, bound in (("CoSimulation", {}, 1e-9),
                                 ("ModelExchange", {"relative_tolerance": 1e-10,
                                                    "record_events": False}, 1e-6)):
        result = fmpy.simulate_fmu(str(path), fmi_type=kind, stop_time=0.02,
                                   output_interval=1e-4, output=["La.f", "Lb.f", "Cd.e"],
                                   **options)
        assert np.allclose(result["time"], GRID, rtol=0, atol=1e-12), kind
        got = np.column_stack([result[name] for name in ("La.f", "Lb.f", "Cd.e")])
        err = np.max(np.abs(got - exact), axis=0) / scale
        assert np.all(err < bound), (kind, err)


def _noevent_model(tmp_path):
    """The bridge with its diodes' laws under noevent: no events, the kinks inside the
    algebraic blocks (solved by Newton's method in the generated code)."""
    text = B6.read_text()
    law = "R(f = if e > Vknee then (e - Vknee)/Ron + Goff*Vknee else Goff*e)"
    assert text.count(law) == 6
    model = tmp_path / "b6_noevent.bg"
    model.write_text(text.replace(law, f"R(f = noevent({law[6:-1]}))"))
    return model


def test_the_bridge_under_noevent_converges_as_the_tolerance_tightens(tmp_path):
    """Kinks under noevent (docs/hybrid.md): radau5's error against the reference falls with
    its tolerance (about 6e-8, 4e-9 and 1e-10 at rtol 1e-8, 1e-10 and 1e-12; at atol 1e-12,
    6e-8 and 4e-9 at rtol 1e-8 and 1e-10).  At 1e-12 the
    Newton iteration of a blocking diode's node stalled: its voltage is its current's rounding
    through 1/Goff, 3e-14 V, above Newton's 0.01 rtol |z|, and the run stopped as a block that
    did not converge; a step within the tolerance where the residual cannot decrease now ends
    it.  dopri5 at 1e-12 stops naming the block where it still stalls (|z| near 0, where no
    tolerance relative to z covers the noise), or converges."""
    model = _noevent_model(tmp_path)
    backend = "c" if have_cc() else "vm"
    errors = []
    for rtol, bound in (("1e-8", 1e-6), ("1e-10", 1e-8), ("1e-12", 1e-9)):
        out = tmp_path / f"noevent-{rtol}.csv"
        result = run_bgc("simulate", model, "--scene", "run", "--backend", backend, "-o", out,
                         "--t-end", "0.02", "--rtol", rtol)
        assert result.returncode == 0, result.stderr
        err, _ = _errors(out)
        assert np.all(err < bound), (rtol, err)
        errors.append(np.max(err))
    assert errors == sorted(errors, reverse=True)
    # at a looser atol radau5 had stopped its Newton iteration after one iteration across a
    # kink, on the other branch's Jacobian: 1.3e-2 off at rtol 1e-8, 3.7e-3 at 1e-10
    errors = []
    for rtol, bound in (("1e-8", 1e-6), ("1e-10", 1e-7)):
        out = tmp_path / f"noevent-atol-{rtol}.csv"
        result = run_bgc("simulate", model, "--scene", "run", "--backend", backend, "-o", out,
                         "--t-end", "0.02", "--rtol", rtol, "--atol", "1e-12")
        assert result.returncode == 0, result.stderr
        err, _ = _errors(out)
        assert np.all(err < bound), (rtol, err)
        errors.append(np.max(err))
    assert errors[1] < errors[0]
    out = tmp_path / "noevent-dopri5.csv"
    result = run_bgc("simulate", model, "--scene", "run", "--backend", backend, "-o", out,
                     "--t-end", "0.02", "--rtol", "1e-12", "--solver", "dopri5")
    if result.returncode == 0:
        assert np.all(_errors(out)[0] < 1e-9)
    else:
        assert result.returncode == 1
        assert "algebraic block" in result.stderr and "did not converge" in result.stderr
