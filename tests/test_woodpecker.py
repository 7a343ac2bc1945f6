"""The woodpecker toy (LANGUAGE 10b, docs/hybrid.md "Frictional contacts"): Glocker's data,
tests/models/woodpecker.bg, against an event-driven reference written here from Pfeiffer
and Glocker's equations (the mass matrix, the contacts' normal and tangential directions,
Newton's restitution and Coulomb friction at the impulse level and at the level of the
accelerations, each mode's linear system solved by NumPy, the flight between events by
SciPy's DOP853 at rtol 1e-12 with its event location).  Nothing of bgc is used by it."""
import csv
import io
import itertools
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import solve_ivp

import bgc
from bgc.api import Source
from bgc.execute import runner

from conftest import have_cc

MODEL = (Path(__file__).resolve().parent / "models" / "woodpecker.bg").read_text()
DATA = dict(mM=3.0e-4, JM=5.0e-9, mS=4.5e-3, JS=7.0e-7, r=2.5e-3, rM=3.1e-3, hM=5.8e-3,
            lM=1.0e-2, lG=1.5e-2, hS=2.0e-2, lS=2.01e-2, cp=5.6e-3, mu=0.3, eN=0.5, g=9.81)
T_END = 0.5


class Woodpecker:
    """M q'' = h(q) + W_N lamN + W_T lamT in q = (y, sleeve's tilt, bird's tilt), contacts
    g_N = g0 + W_N^T q >= 0 (the sleeve's upper and lower edges, the beak), slips W_T^T q'."""

    def __init__(self, p):
        mM, JM, mS, JS = p["mM"], p["JM"], p["mS"], p["JS"]
        r, rM, hM, lM, lG, hS, lS = (p[k] for k in ("r", "rM", "hM", "lM", "lG", "hS", "lS"))
        self.p = p
        self.M = np.array([[mM + mS, mS * lM, mS * lG],
                           [mS * lM, JM + mS * lM ** 2, mS * lM * lG],
                           [mS * lG, mS * lM * lG, JS + mS * lG ** 2]])
        self.WN = np.array([[0, hM, 0], [0, -hM, 0], [0, 0, -hS]], float).T
        self.WT = np.array([[1, rM, 0], [1, -rM, 0], [1, lM, lG - lS]], float).T
        self.g0 = np.array([rM - r, rM - r, lM + lG - lS - r])
        self.e = np.array([0.0, 0.0, p["eN"]])
        self.mu = p["mu"]

    def h(self, q):
        p = self.p
        spring = p["cp"] * (q[2] - q[1])
        return np.array([-(p["mM"] + p["mS"]) * p["g"], spring - p["mS"] * p["lM"] * p["g"],
                         -spring - p["mS"] * p["lG"] * p["g"]])

    def forces(self, q, mode):
        """The accelerations and the contact forces in a mode: per contact None (open),
        "stick", or the sliding direction +1 / -1."""
        closed = [i for i in range(3) if mode[i] is not None]
        stick = [i for i in closed if mode[i] == "stick"]
        n = 3 + len(closed) + len(stick)
        A, b = np.zeros((n, n)), np.zeros(n)
        A[:3, :3], b[:3] = self.M, self.h(q)
        for k, i in enumerate(closed):
            col = self.WN[:, i] - (0 if mode[i] == "stick" else self.mu * mode[i]) * self.WT[:, i]
            A[:3, 3 + k], A[3 + k, :3] = -col, self.WN[:, i]
        for k, i in enumerate(stick):
            A[:3, 3 + len(closed) + k] = -self.WT[:, i]
            A[3 + len(closed) + k, :3] = self.WT[:, i]
        x = np.linalg.solve(A, b)
        lamN, lamT = np.zeros(3), np.zeros(3)
        for k, i in enumerate(closed):
            lamN[i] = x[3 + k]
            if mode[i] != "stick":
                lamT[i] = -self.mu * mode[i] * x[3 + k]
        for k, i in enumerate(stick):
            lamT[i] = x[3 + len(closed) + k]
        return x[:3], lamN, lamT

    def impact(self, u, mode, hit):
        """The impulses of the contact that hits and of those closed: Newton's restitution
        on the normal rows, each friction row sticking (|LT| <= mu LN) or sliding against its
        slip after the impact; the modes enumerated, sticking first."""
        rows = sorted({hit} | {i for i in range(3) if mode[i] is not None})
        nr, Minv, mu = len(rows), np.linalg.inv(self.M), self.mu
        G = np.hstack([self.WN[:, rows], self.WT[:, rows]])
        D = G.T @ Minv @ G
        gn = self.WN.T @ u
        for bits in itertools.product(("stick", 1, -1), repeat=nr):
            A, b = np.zeros((2 * nr, 2 * nr)), np.zeros(2 * nr)
            for k, i in enumerate(rows):
                A[k] = D[k]
                b[k] = -(1 + self.e[i]) * gn[i] if i == hit or mode[i] is None else -gn[i]
                if bits[k] == "stick":
                    A[nr + k], b[nr + k] = D[nr + k], -(self.WT[:, i] @ u)
                else:
                    A[nr + k, nr + k], A[nr + k, k] = 1, mu * bits[k]
            x = np.linalg.solve(A, b)
            after = u + Minv @ G @ x
            ok = all(x[:nr] >= -1e-15)
            for k, i in enumerate(rows):
                if bits[k] == "stick":
                    ok &= abs(x[nr + k]) <= mu * x[k] * (1 + 1e-12) + 1e-18
                else:
                    ok &= bits[k] * (self.WT[:, i] @ after) >= -1e-12
            if ok:
                new = list(mode)
                for k, i in enumerate(rows):
                    new[i] = bits[k] if self.e[i] == 0 else None
                return after, new
        raise AssertionError("no admissible impulse")

    def settle(self, q, u, mode, broken=()):
        """The contact modes consistent at the acceleration level: each touching contact
        closed with lamN >= 0 or open with gN'' >= 0; closed, its friction sticking inside the
        cone, or sliding the way it slips (at zero slip, a way its slip's acceleration
        follows); there must be exactly one."""
        touching = [i for i in range(3) if mode[i] is not None]
        options = []
        for i in touching:
            slip = self.WT[:, i] @ u
            if abs(slip) > 1e-12:
                options.append((int(np.sign(slip)), None))
            else:
                options.append((1, -1, None) if i in broken else ("stick", 1, -1, None))
        found = []
        for choice in itertools.product(*options):
            m = list(mode)
            for i, c in zip(touching, choice):
                m[i] = c
            a, lamN, lamT = self.forces(q, m)
            ok = True
            for i, c in zip(touching, choice):
                if c is None:
                    ok &= self.WN[:, i] @ a >= -1e-9
                    continue
                ok &= lamN[i] >= -1e-15
                if c == "stick":
                    ok &= abs(lamT[i]) <= self.mu * lamN[i] * (1 + 1e-12)
                elif abs(self.WT[:, i] @ u) <= 1e-12:
                    ok &= c * (self.WT[:, i] @ a) >= -1e-9
            if ok:
                found.append(m)
        assert len(found) == 1, found
        return found[0]

    def run(self, t_end, wb0=-10.0):
        """The events [(t, kind, contact)] and the flight segments' dense outputs."""
        mu, WT = self.mu, self.WT
        q, u = np.zeros(3), np.array([0.0, 0.0, wb0])
        mode, t, events, pieces = [None] * 3, 0.0, [], []
        while t < t_end:
            m = tuple(mode)
            watch = []
            for i in range(3):
                if m[i] is None:
                    watch.append(("contact", i, lambda _, x, i=i: self.g0[i] + self.WN[:, i] @ x[:3]))
                    continue
                watch.append(("release", i, lambda _, x, i=i: self.forces(x[:3], m)[1][i]))
                if m[i] == "stick":
                    watch.append(("break", i, lambda _, x, i=i: mu * self.forces(x[:3], m)[1][i]
                                  - abs(self.forces(x[:3], m)[2][i])))
                else:
                    watch.append(("stop", i, lambda _, x, i=i: m[i] * (WT[:, i] @ x[3:])))
            for _, _, f in watch:
                f.terminal, f.direction = True, -1
            sol = solve_ivp(lambda _, x: np.concatenate([x[3:], self.forces(x[:3], m)[0]]),
                            (t, t_end), np.concatenate([q, u]), method="DOP853", rtol=1e-12,
                            atol=1e-15, events=[f for _, _, f in watch], dense_output=True)
            pieces.append((sol.t[0], sol.t[-1], sol.sol))
            t, q, u = sol.t[-1], sol.y[:3, -1].copy(), sol.y[3:, -1].copy()
            if sol.status != 1:
                break
            kind, i, _ = watch[next(k for k, te in enumerate(sol.t_events) if len(te))]
            events.append((t, kind, i))
            assert len(events) < 200 and (len(events) < 3 or events[-3][0] < t)
            if kind == "contact":
                u, mode = self.impact(u, mode, i)
            elif kind == "release":
                mode[i] = None
            elif kind == "break":
                mode[i] = -int(np.sign(self.forces(q, m)[2][i]))
            else:  # its slip stops: the storages take the state that stops it
                w = np.linalg.solve(self.M, WT[:, i])
                u, mode[i] = u - w * (WT[:, i] @ u) / (WT[:, i] @ w), "stick"
            mode = self.settle(q, u, mode, (i,) if kind == "break" else ())
        return events, pieces


@pytest.fixture(scope="module")
def reference():
    events, pieces = Woodpecker(DATA).run(T_END)

    def at(t):
        return next(sol(t) for t0, t1, sol in pieces if t0 <= t <= t1)
    return events, at


@pytest.fixture(scope="module")
def compiled():
    return bgc.build(Source("woodpecker.bg", MODEL), "run")


def simulate(compiled, backend, tmp_path, **options):
    program = runner.prepare(compiled, backend)
    log = tmp_path / f"{backend}-events.csv"
    settings = runner.settings_for(compiled.program.scene,
                                   [p.name for p in compiled.program.params],
                                   events=str(log), **options)
    result = runner.run(program, settings)
    assert result.status == 0, result.stderr
    rows = list(csv.reader(io.StringIO(result.csv)))
    with open(log, newline="") as f:
        logged = list(csv.reader(f))[1:]
    return result.csv, np.array([[float(v) for v in r] for r in rows[1:]]), logged


KINDS = {"contact (phi < 0)": "contact", "release (lambda would pull)": "release",
         "stops (f reverses)": "stop", "breaks away (|e| > Fs)": "break"}


def instants(logged):
    """The first contact or friction event at each instant of bgc's log, as (t, kind,
    contact): a contact that opens at once, or a friction that stops and breaks away at
    once, is one event of the reference, whose mode is settled at that instant."""
    out = []
    for t, what, change in logged:
        name, _, text = what.partition(": ")
        if text in KINDS and change == "0 -> 1" and (not out or out[-1][0] != float(t)):
            out.append((float(t), KINDS[text], int(name[1:]) - 1))
    return out


def test_the_woodpecker_against_its_event_driven_reference(compiled, reference, tmp_path):
    """Half a second, 28 events (the sleeve jamming and sliding at either edge, the beak's
    strikes): bgc has the reference's events in the same order, each within 1e-8 s, and
    its coordinates and rates within 1e-7 of each one's size over the run; at rtol 1e-8
    within 1e-5, the error falling as the tolerance tightens (measured: 7e-7 at 1e-8, 6e-9
    at 1e-10)."""
    events, at = reference
    errors = []
    for rtol in (1e-8, 1e-10):
        backend = "c" if have_cc() else "vm"
        _, y, logged = simulate(compiled, backend, tmp_path, rtol=rtol, atol=rtol * 1e-2)
        X = np.array([at(t) for t in y[:, 0]])
        errors.append(np.max(np.abs(y[:, 1:7] - X) / np.abs(X).max(axis=0)))
        if rtol == 1e-10:
            got = instants(logged)
            assert [(k, i) for _, k, i in got] == [(k, i) for _, k, i in events]
            assert max(abs(a[0] - b[0]) for a, b in zip(got, events)) < 1e-8
    assert len(events) >= 25 and {k for _, k, _ in events} == {"contact", "release", "stop",
                                                               "break"}
    assert errors[1] < 1e-7 and errors[0] < 1e-5 and errors[1] < errors[0] / 10, errors


def test_the_woodpecker_in_every_backend_is_the_same_bytes(compiled, tmp_path):
    """The first 0.12 s (a jam, its release, the beak's strike): C, Python and the
    interpreter write the same rows and the same event log."""
    backends = (["c"] if have_cc() else []) + ["python", "vm"]
    runs = [simulate(compiled, b, tmp_path, t_end=0.12) for b in backends]
    assert len({text for text, _, _ in runs}) == 1
    assert len({tuple(map(tuple, log)) for _, _, log in runs}) == 1


DEPENDENT = """model bar "a bar's centre and spin, with a point mass at its tip in derivative causality"
parameter m = 1
parameter J = 0.1
parameter m2 = 0.5
parameter l = 0.5
centre : I(m)
spin   : I(J)
tip    : I(m2)
w      : Se(-m*9.81)
v  : 1
om : 1
sum : 0
tv : 1
w -> v
v -> centre
om -> spin
v -> sum
om -> arm
arm : TF(l)
arm -> sum
sum -> tv
tv -> tip
signal y  = integral(v.f, init = 1)
signal th = integral(om.f, init = 0)
om -> lever
lever : TF(1)
lever -> floor
floor : 0 constraint unilateral(phi = th + 1)
scene run { time 0 .. 1 every 0.1; outputs y, th }
"""


def test_an_impulse_through_an_inertia_in_derivative_causality_is_refused():
    """The woodpecker written with point masses (one of them, the bird's, in derivative
    causality) ran silently wrong from its first impact: the impulse's metric was the
    states' alone.  Such an impulse is refused at the contact, naming the dependent inertia
    and what to write instead; here a bar whose tip mass follows its centre and spin."""
    from bgc.api import BgcModelError
    with pytest.raises(BgcModelError) as err:
        bgc.build(Source("bar.bg", DEPENDENT), "run")
    message = str(err.value)
    assert "bar.bg:28:1: error: 'floor': its impulse moves spin.p, whose velocities the " \
        "inertia 'tip' in derivative causality follows" in message, message
    assert "coupled field I[n](M)" in message
