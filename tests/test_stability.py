"""The stability suite (issue 9): hard cases against bounds from theory or an independent
reference, never against bgc's own output.  Long horizons (the pendulum over 1e4 s, with and
without its corrector), the corrector's own law from a start off the constraint
(--allow-inconsistent), the energy of the chaotic double pendulum, stiffness (high gains, the
Bari test set's Van der Pol, mu = 1e5 against its relaxation limit, a fixed step beyond the
stability bound), parameters from 1e-9 to 1e9 in one model, a linkage driven through its
dead centres, and every model with a parameter set to 0, +-1e308 or 1e-308.

The runs use the C program (at -O0, as conftest sets); where the point is that both backends
behave the same, the Python module runs too, in this process (its command line, main()).
The stiff circuits are in tests/test_stiff.py (closed form of the RC pair, Van der Pol at
mu = 1e5 as explicit equations against SciPy) and tests/test_benchmarks_smoke.py
(models/rc_pair.bg against its closed form); the step budget and the failure messages in
tests/test_budgets.py.  docs/stability.md has the figures (benchmarks/stability.py)."""
import contextlib
import functools
import io
import math
import os
import random
import re
from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import brentq
from scipy.special import ellipj, ellipk

import bgc
from bgc.base import cache, processes, toolchain
from bgc.api import Source, build
from bgc.codegen.emit import emit_c, emit_python
from conftest import MODELS, ROOT, run_bgc

TEST_MODELS = ROOT / "tests" / "models"
HAVE_C = toolchain.have_c_compiler()
needs_c = pytest.mark.skipif(not HAVE_C, reason="no C compiler")


# ---------------------------------------------------------------- running


@functools.lru_cache(maxsize=None)
def _program(path, scene, backend):
    """The compiled C program's path, or the Python module, of a model's scene."""
    compiled = build(path, scene)
    if backend == "c":
        (text,) = emit_c(compiled.program).values()
        return cache.compile_c(text)
    (text,) = emit_python(compiled.program).values()
    return processes.load_python_module(text)


class Run:
    """A program's run: exit status, the CSV's names and rows, stderr's lines, the stats."""

    def __init__(self, code, out, err):
        self.code, self.out = code, out
        self.err = err.strip().splitlines()
        stats = [ln for ln in self.err if ln.startswith("stats:")]
        self.stats = {k: float(v) for k, v in (w.split("=") for w in stats[0].split()[1:])} \
            if stats else {}
        messages = [ln for ln in self.err if not ln.startswith("stats:")]
        self.last = messages[-1] if messages else ""

    @functools.cached_property
    def names(self):
        return self.out.split("\n", 1)[0].split(",")[1:]

    @functools.cached_property
    def data(self):
        lines = self.out.splitlines()[1:]
        return np.loadtxt(lines, delimiter=",", ndmin=2) if lines else \
            np.zeros((0, len(self.names) + 1))

    @property
    def t(self):
        return self.data[:, 0]

    def __getitem__(self, name):
        return self.data[:, 1 + self.names.index(name)]


def run(path, scene, backend, *args) -> Run:
    """The program of (path, scene) with these command-line arguments: C as a process, Python
    through its main() in this process."""
    program = _program(path, scene, backend)
    args = [str(a) for a in args]
    if backend == "c":
        return Run(*processes.run_c(program, args, timeout=120))
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = program.main(args)
    return Run(code, out.getvalue(), err.getvalue())


def params(**values):
    return [a for name, value in values.items() for a in ("-p", f"{name}={value!r}")]


# ---------------------------------------------------------------- closed forms


def pendulum_angle(t, theta0, g=9.81, l=1.0):
    """The rigid pendulum released from rest at theta0: theta = 2 arcsin(k sn(K - w t | k^2)),
    k = sin(theta0/2), w = sqrt(g/l), K the complete elliptic integral of the first kind."""
    k = math.sin(theta0 / 2)
    sn, _, _, _ = ellipj(ellipk(k * k) - math.sqrt(g / l) * np.asarray(t), k * k)
    return 2 * np.arcsin(k * sn)


def damped(t, phi0, dphi0, alpha, beta):
    """Phi'' + 2 alpha Phi' + beta^2 Phi = 0 from Phi(0) = phi0, Phi'(0) = dphi0 (the paper's
    eq. 2): Phi = c1 e^(r1 t) + c2 e^(r2 t), r = -alpha +- sqrt(alpha^2 - beta^2), or
    (phi0 + (dphi0 + alpha phi0) t) e^(-alpha t) for the double root."""
    t = np.asarray(t, dtype=float)
    if alpha == beta:
        return (phi0 + (dphi0 + alpha * phi0) * t) * np.exp(-alpha * t)
    root = np.sqrt(complex(alpha * alpha - beta * beta))
    r1, r2 = -alpha + root, -alpha - root
    c1, c2 = (dphi0 - r2 * phi0) / (r1 - r2), (r1 * phi0 - dphi0) / (r1 - r2)
    return (c1 * np.exp(r1 * t) + c2 * np.exp(r2 * t)).real


def real_axis_bound(coefficients):
    """The largest x with |R(-s)| <= 1 on [0, x] for the polynomial R(z) = sum c_k z^k."""
    R = np.polynomial.Polynomial(coefficients)
    x = 0.0
    while abs(R(-(x + 1e-3))) <= 1.0:
        x += 1e-3
    return brentq(lambda s: abs(R(-s)) - 1.0, x, x + 1e-3)


# ---------------------------------------------------------------- 1. long horizons

PENDULUM = MODELS / "pendulum.bg"


@needs_c
def test_the_corrected_pendulum_keeps_its_rod_over_ten_thousand_seconds():
    """The `long` scene (dopri5, rtol 1e-8, atol 1e-10) run to 1e4 s, 5000 swings.  The bound:
    each accepted step leaves a local error of at most sqrt(N) (atol + rtol |y|) in each of
    the N = 4 states (the controller's acceptance test, the estimate taken as the error; |y| is
    at most max(l, m v_max), v_max = sqrt(2 g l (1 - cos theta0)) by energy).  In Phi = x^2 +
    y^2 - l^2 that is a jump of at most a = 2 (|x| + |y|) e <= 2 sqrt(2) l e, in dPhi/dt =
    2 (x px + y py)/m one of at most b = 2 sqrt(2) (l/m + v_max) e.  The corrector turns each
    jump into the impulse response of Phi'' + 2 alpha Phi' + beta^2 Phi = 0, whose integral
    over time is at most 2|a|/alpha + |b|/alpha^2 for the critical gains alpha = beta; with n
    steps a second the drift is at most n (2a/alpha + b/alpha^2) at any time."""
    r = run(PENDULUM, "long", "c", "--t-end", 1e4, "--dt", 10, "--stats")
    assert r.code == 0 and r.t[-1] == 1e4
    m, l, g, theta0, alpha = 1.0, 1.0, 9.81, 0.5, 5.0
    v_max = math.sqrt(2 * g * l * (1 - math.cos(theta0)))
    e = math.sqrt(4) * (1e-10 + 1e-8 * max(l, m * v_max))
    a, b = 2 * math.sqrt(2) * l * e, 2 * math.sqrt(2) * (l / m + v_max) * e
    n = r.stats["steps"] / 1e4
    bound = n * (2 * a / alpha + b / alpha**2)
    drift = np.abs(r["rod.residual"]).max()
    assert drift < bound, (drift, bound)
    assert bound < 1e-4  # the bound says something: 1e-4 of l^2 after 5000 swings


@needs_c
def test_without_a_corrector_the_drift_grows():
    """The same program with alpha = beta = 0: Phi'' = 0, the law of `corrector none`, so
    every local error in dPhi/dt stays and Phi drifts at least linearly in t (quadratically
    when the errors keep their sign).  Its drift at 1e4 s is at least ten times that at
    1e3 s, and far beyond the corrected run's bound (previous test)."""
    r = run(PENDULUM, "long", "c", "--t-end", 1e4, "--dt", 10, *params(alpha=0.0, beta=0.0))
    assert r.code == 0
    drift = np.abs(r["rod.residual"])
    early, late = drift[r.t <= 1e3].max(), drift.max()
    assert late > 10 * early, (early, late)
    assert late > 1e-3


# ---------------------------------------------------------------- 2. the corrector's own law

OFFSET = TEST_MODELS / "pendulum_offset.bg"
SLIP = TEST_MODELS / "knife_slip.bg"
R0, VR0 = 1.001, 0.01


@needs_c
@pytest.mark.parametrize("alpha, beta", [(2.0, 10.0), (5.0, 5.0), (10.0, 4.0)],
                         ids=["underdamped", "critical", "overdamped"])
def test_a_holonomic_drift_follows_the_pid_law(alpha, beta):
    """Started off the rod (r0 = 1.001, moving outwards at 0.01 m/s): Phi(0) = r0^2 - l^2,
    Phi'(0) = 2 r0 vr0, then eq. (2) exactly, whatever the swing.  The run (dopri5 at rtol
    1e-11) keeps its states to about 1e-10, so Phi to 1e-5 of Phi(0)."""
    r = run(OFFSET, "settle", "c", "--allow-inconsistent",
            *params(r0=R0, vr0=VR0, alpha=alpha, beta=beta))
    assert r.code == 0, r.err
    want = damped(r.t, R0**2 - 1.0, 2 * R0 * VR0, alpha, beta)
    assert abs(want[0]) > 2e-3
    err = np.abs(r["rod.residual"] - want).max()
    assert err < 1e-5 * abs(want[0]), err
    if alpha < beta:  # it rings: the closed form crosses zero, and so does the run
        assert np.sign(r["rod.residual"]).min() < 0


@needs_c
@pytest.mark.parametrize("gamma", [3.0, 10.0])
def test_a_non_holonomic_drift_follows_the_pd_law(gamma):
    """The knife edge started slipping sideways at s0: Phi(0) = s0, then eq. (3),
    Phi = s0 e^(-gamma t)."""
    s0 = 0.01
    r = run(SLIP, "settle", "c", "--allow-inconsistent", *params(s0=s0, gamma=gamma))
    assert r.code == 0, r.err
    want = s0 * np.exp(-gamma * r.t)
    assert np.abs(r["blade.residual"] - want).max() < 1e-5 * s0


def test_allow_inconsistent_is_the_same_in_both_backends():
    args = ["--t-end", 0.2, "--allow-inconsistent", *params(r0=R0, vr0=VR0)]
    results = [run(OFFSET, "settle", b, *args) for b in (["python", "c"] if HAVE_C else
                                                         ["python"])]
    for r in results:
        assert r.code == 0 and len(r.t) == 21
        assert r.out == results[0].out  # the same rows, to the bit
    # without the flag the start is refused; with --project-initial too it is a usage error
    for b in (["python", "c"] if HAVE_C else ["python"]):
        refused = run(OFFSET, "settle", b, *params(r0=R0))
        assert refused.code == 1 and refused.out == ""
        assert refused.last.startswith("error: initial conditions violate constraint 'rod' "
                                       "(position): residual = 0.0020")
        both = run(OFFSET, "settle", b, "--allow-inconsistent", "--project-initial")
        assert both.code == 2
        assert both.last == ("error: --project-initial and --allow-inconsistent exclude each "
                             "other")


def test_allow_inconsistent_in_batch_mode(tmp_path):
    """--batch (what `bgc sweep` runs): each run is refused or started as the flag says."""
    lines = tmp_path / "runs.txt"
    lines.write_text("r0=1\nr0=1.001\n", encoding="utf-8")
    for b in (["python", "c"] if HAVE_C else ["python"]):
        for flag, status in (([], "constraint"), (["--allow-inconsistent"], "ok")):
            r = run(OFFSET, "settle", b, "--batch", lines, "--t-end", 0.1, *flag)
            assert r.code == 0
            rows = r.out.splitlines()[1:]
            assert [row.split(",")[1] for row in rows] == ["ok", status], r.out


def test_allow_inconsistent_through_the_api_and_the_command_line(tmp_path):
    """A model whose own initial values violate its constraint: compiling refuses it (a located
    error) unless the flag says the start is meant."""
    text, n = re.subn(r"^parameter r0( *)= l ", r"parameter r0\1= 1.001 ",
                      OFFSET.read_text(encoding="utf-8"), flags=re.M)
    assert n == 1
    path = tmp_path / "off.bg"
    path.write_text(text, encoding="utf-8")
    refused = run_bgc("simulate", path, "-s", "settle", "--backend", "python",
                      "-o", tmp_path / "a.csv")
    assert refused.returncode == 1 and not (tmp_path / "a.csv").exists()
    assert "error: initial conditions violate constraint 'rod'" in refused.stderr
    assert "off.bg:" in refused.stderr
    t, Y, names = bgc.simulate(Source(str(path), text), "settle", backend="python", t_end=0.5,
                               allow_inconsistent=True)
    want = damped(t, R0**2 - 1.0, 0.0, 2.0, 10.0)
    assert np.abs(Y[:, names.index("rod.residual")] - want).max() < 1e-5 * want[0]
    with pytest.raises(ValueError, match="exclude each other"):
        bgc.simulate(Source(str(path), text), "settle", backend="python",
                     allow_inconsistent=True, project_initial=True)
    both = run_bgc("simulate", path, "--allow-inconsistent", "--project-initial")
    assert both.returncode == 2 and "exclude each other" in both.stderr
    # bgc sweep takes the flag too: the run that starts off the rod is a row, not a refusal
    swept = run_bgc("sweep", path, "-s", "settle", "--grid", "vr0=0,0.01", "--metric",
                    "final:rod.residual", "--t-end", "0.5", "--workers", "0", "--backend",
                    "python", "--no-timing", "--allow-inconsistent")
    assert swept.returncode == 0, swept.stderr
    rows = [line.split(",") for line in swept.stdout.splitlines()[1:]]
    assert [r[-2] for r in rows] == ["ok", "ok"]
    assert float(rows[0][2]) == pytest.approx(want[-1], rel=1e-4)


# ---------------------------------------------------------------- 3. energy

DOUBLE = MODELS / "double_pendulum.bg"


@needs_c
def test_the_chaotic_double_pendulum_keeps_its_energy():
    """Both rods started high (theta1 = 2, theta2 = 2.6 rad), dop853 at rtol = atol = 1e-12,
    100 s.  E = |p1|^2/(2 m1) + |p2|^2/(2 m2) - g (m1 y1 + m2 y2) (y down) from the CSV.  The
    constrained flow conserves E, so an error in it is not amplified by the chaos: E's drift is
    the sum over the steps of grad E . delta, each delta at most sqrt(N) (atol + rtol |y|) per
    state (N = 8), plus the work of the corrector's forces, lambda Phi', which the corrector
    keeps at the size of the residuals (1e-10 here).  That the start is chaotic: a second run
    with theta2 changed by 1e-8 ends elsewhere."""
    m1, m2, g = 1.0, 0.5, 9.81
    args = ["--t-end", 100, "--dt", 0.1, "--solver", "dop853", "--rtol", 1e-12, "--atol",
            1e-12, "--stats"]
    r = run(DOUBLE, None, "c", *args, *params(theta1=2.0, theta2=2.6))
    assert r.code == 0 and r.t[-1] == 100
    v1 = np.hypot(r["mx1.p"], r["my1.p"]) / m1
    v2 = np.hypot(r["mx2.p"], r["my2.p"]) / m2
    E = 0.5 * m1 * v1**2 + 0.5 * m2 * v2**2 - g * (m1 * r["y1"] + m2 * r["y2"])
    grad = 2 * v1.max() + 2 * v2.max() + g * (m1 + m2)  # sum of |dE/dy_i| over the states
    size = max(np.abs(r.data[:, 1:]).max(), 1.0)
    bound = r.stats["steps"] * grad * math.sqrt(8) * (1e-12 + 1e-12 * size)
    drift = np.abs(E - E[0]).max()
    assert drift < bound, (drift, bound)
    assert bound < 1e-5 * (m1 + m2) * g * (1.0 + 0.7)
    other = run(DOUBLE, None, "c", *args, *params(theta1=2.0, theta2=2.6 + 1e-8))
    apart = np.hypot(r["x2"] - other["x2"], r["y2"] - other["y2"])
    assert apart[-1] > 1e-2 and apart[10] < 1e-6, (apart[10], apart[-1])


# ---------------------------------------------------------------- 4. stiffness

STIFF = ["radau5", "rodas4", "rodas5p"]


@functools.lru_cache(maxsize=None)
def _high_gains(solver):
    return run(PENDULUM, "swing", "c", "--solver", solver, "--rtol", 1e-8, "--atol", 1e-10,
               "--t-end", 3, "--stats", *params(alpha=1e3, beta=1e3))


@needs_c
@pytest.mark.parametrize("solver", STIFF)
def test_high_corrector_gains_with_a_stiff_solver(solver):
    """alpha = beta = 1e3: the corrector's double eigenvalue -1e3 next to the swing's 3 rad/s.
    On the rod the corrector does nothing, so the motion is the rigid pendulum's: its closed
    form in Jacobi's elliptic functions, to 100 rtol."""
    r = _high_gains(solver)
    assert r.code == 0, r.err
    theta = pendulum_angle(r.t, 0.5)
    assert np.abs(r["x"] - np.sin(theta)).max() < 1e-6
    assert np.abs(r["y"] - np.cos(theta)).max() < 1e-6
    assert np.abs(r["rod.residual"]).max() < 1e-6


@needs_c
def test_high_gains_cost_an_explicit_solver_its_stability_bound():
    """dopri5's stability polynomial (1 + z + .. + z^5/120 + z^6/600) bounds h |lambda| by
    3.31 on the negative axis: over 3 s with lambda = -1e3 it needs at least about
    3 * 1e3 / 3.31 steps whatever the tolerance; radau5 (A-stable) needs fewer."""
    bound = real_axis_bound([1, 1, 1 / 2, 1 / 6, 1 / 24, 1 / 120, 1 / 600])
    assert 3.2 < bound < 3.4
    least = 3.0 * 1e3 / bound
    explicit = run(PENDULUM, "swing", "c", "--solver", "dopri5", "--rtol", 1e-8, "--atol",
                   1e-10, "--t-end", 3, "--stats", *params(alpha=1e3, beta=1e3))
    assert explicit.code == 0
    assert explicit.stats["steps"] > 0.5 * least
    assert _high_gains("radau5").stats["steps"] < 0.5 * least


VDPOL = TEST_MODELS / "vdpol_testset.bg"
# Test Set for IVP Solvers (Bari), problem VDPOL (vdpol.f, subroutine solut): y at t = 2,
# computed with RADAU at rtol = atol = 1.1e-18 in extended precision.
VDPOL_Y2 = (0.1706167732170483e1, -0.8928097010247975e0)


@needs_c
@pytest.mark.parametrize("solver", STIFF)
def test_van_der_pol_matches_the_test_set_reference(solver):
    """Van der Pol as a bond graph (a nonlinear resistor), eps = 1e-6, y(0) = (2, 0): y(2)
    against the test set's published values, to 100 times the tolerance."""
    tol = 1e-8
    r = run(VDPOL, "testset", "c", "--solver", solver, "--rtol", tol, "--atol", tol)
    assert r.code == 0, r.err
    got = (r["cap.q"][-1], r["ind.p"][-1])
    for value, ref in zip(got, VDPOL_Y2):
        assert abs(value - ref) < 100 * tol * abs(ref), (got, VDPOL_Y2)


@needs_c
def test_van_der_pol_at_mu_1e5_follows_its_relaxation_limit():
    """models/van_der_pol.bg at mu = 1e5 (eps = 1e-10): as eps -> 0 the solution creeps along
    the slow manifold y2 = y1/(1 - y1^2), t = ln(y1/2) - (y1^2 - 4)/2 from y1 = 2, jumps at
    |y1| = 1 to the other branch; the period is 3 - 2 ln 2.  At t = 2 it is on the first
    branch again, 2 - (3 - 2 ln 2) after the second jump.  The limit's error is of order
    eps^(2/3) = 2e-7 (the jumps' delay, a few times that); 1e-5 allows for it and still
    checks the timing of both jumps (|dy1/dt| is 0.9 there)."""
    r = run(MODELS / "van_der_pol.bg", "period", "c", "--solver", "radau5", "--rtol", 1e-8,
            "--atol", 1e-8, "--dt", 0.5, *params(mu=1e5))
    assert r.code == 0, r.err
    since = 2.0 - (3.0 - 2.0 * math.log(2.0))
    y1 = brentq(lambda y: math.log(y / 2) - (y * y - 4) / 2 - since, 1.01, 2.0)
    assert abs(r["cap.q"][-1] - y1) < 1e-5, (r["cap.q"][-1], y1)
    assert abs(r["ind.p"][-1] - y1 / (1 - y1 * y1)) < 1e-5


def test_a_fixed_step_beyond_the_stability_bound_is_caught(tmp_path):
    """rk4 with h = 0.01 on gains alpha = beta = 1e3: h lambda = -10, and rk4's
    R(z) = 1 + z + z^2/2 + z^3/6 + z^4/24 gives |R(-10)| = 291 > 1.  bgc warns before the
    run, which then stops at the first non-finite value, its rows kept, the same in both
    backends."""
    R = abs(np.polynomial.Polynomial([1, 1, 1 / 2, 1 / 6, 1 / 24])(-10.0))
    out = tmp_path / "rk4.csv"
    args = ["-s", "swing", "--solver", "rk4", "--dt", 0.01, "--t-end", 1, "-p", "alpha=1e3",
            "-p", "beta=1e3"]
    result = run_bgc("simulate", PENDULUM, *args, "--backend", "c" if HAVE_C else "python",
                     "-o", out)
    assert result.returncode == 1
    lines = result.stderr.strip().splitlines()
    assert lines[0].startswith("warning: rk4 with fixed step 0.01 is unstable on the corrector "
                               "of 'rod'") and f"|R(h*lambda)| = {R:.3g} > 1" in lines[0]
    assert re.fullmatch(r"error: at t = ([0-9.e+-]+): state '[^']+' is not finite", lines[-2])
    stop = float(lines[-2].split("at t = ")[1].split(":")[0])
    text = out.read_text(encoding="utf-8")
    rows = np.loadtxt(text.splitlines()[1:], delimiter=",")
    assert np.all(np.isfinite(rows)) and rows[-1, 0] < stop < 1
    last_time = text.splitlines()[-1].split(",")[0]
    assert lines[-1] == f"bgc: the run stopped; the rows up to t = {last_time} are in {out}"
    assert np.abs(rows[-1, 4]) > 1e6  # the residual blew up before anything overflowed
    program = [run(PENDULUM, "swing", b, *args[2:]) for b in
               (["python", "c"] if HAVE_C else ["python"])]
    assert all(p.code == 3 and p.last == lines[-2] and p.out == program[0].out
               for p in program)


# ---------------------------------------------------------------- 5. scales


@needs_c
def test_parameters_from_1e_minus_9_to_1e9_match_the_scaled_closed_forms():
    """tests/models/scales.bg: five subsystems with unit time constants whose states span
    eighteen orders of magnitude (atol = 1e-25 so that the smallest are held to rtol too).
    Each output against its closed form, relative to its own scale."""
    r = run(TEST_MODELS / "scales.bg", "scaled", "c")
    assert r.code == 0, r.err
    t = r.t
    small, large = 1e-9, 1e9
    tau = large * small * large / (small + large)  # R C1 C2 / (C1 + C2)
    v2 = large / (large + small) * (1 - np.exp(-t / tau))
    m1, m2, b = large, small, small
    vcm = m1 / (m1 + m2)
    u = np.exp(-t * b * (1 / m1 + 1 / m2))  # the relative speed, from 1
    want = {"rc1c.q": small * (1 - np.exp(-t)), "rc2c.q": large * (1 - np.exp(-t)),
            "k1.q": np.cos(t), "m1.p": -small * np.sin(t),
            "k2.q": np.cos(t), "m2.p": -large * np.sin(t),
            "c2.q": small * v2, "c1.q": large - small * v2,
            "heavy.p": m1 * (vcm + m2 / (m1 + m2) * u), "light.p": m2 * (vcm - m1 / (m1 + m2) * u)}
    for name, value in want.items():
        scale = np.abs(value).max()
        assert np.abs(r[name] - value).max() < 1e-8 * scale, name
    assert np.abs(r["rc1c.q"]).max() < 1e-8 and np.abs(r["rc2c.q"]).max() > 1e8


# ---------------------------------------------------------------- 6. near-singular


FOUR_BAR = MODELS / "four_bar.bg"


def test_a_parallelogram_driven_through_its_dead_centres():
    """models/four_bar.bg with c = a and d = b, a parallelogram, released with gravity
    reversed so that it falls through the positions where all four joints are on the ground
    line: there the three rows of the constraint Jacobian span only the x directions (rank 2),
    and the multipliers are not determined.  The run either goes through with the loop closed
    to its tolerance, or stops there with a message naming the constraint's multipliers and
    the time; either way the rows written are finite, and both backends agree."""
    args = ["--t-end", 5, *params(c=1.0, g=-9.81, phi0=0.3)]
    results = [run(FOUR_BAR, "swing", b, *args) for b in
               (["python", "c"] if HAVE_C else ["python"])]
    for r in results:
        assert r.code == results[0].code and r.last == results[0].last
        assert np.array_equal(r.data, results[0].data)
    r = results[0]
    assert np.all(np.isfinite(r.data)) and len(r.t) > 10
    crank_y = r["q[1]"]
    assert np.count_nonzero(np.diff(np.sign(crank_y))) >= 1  # through a dead centre
    for k in range(3):
        assert np.abs(r[f"rods.residual[{k}]"]).max() < 1e-6
    if r.code != 0:
        m = re.fullmatch(r"error: at t = ([0-9.e+-]+): algebraic block \d+ \(rods\.lambda\[0\], "
                         r"rods\.lambda\[1\], rods\.lambda\[2\]\) is singular", r.last)
        assert m and r.code == 3, r.last
        assert r.t[-1] <= float(m.group(1)) < r.t[-1] + 0.01
        assert abs(crank_y[-1]) < 0.02  # it stopped at a dead centre, not elsewhere


# ---------------------------------------------------------------- 7. extreme parameters

EXTREME = ("0", "1e308", "-1e308", "1e-308")
FULL = os.environ.get("BGC_EXTREME", "") not in ("", "0")
SAMPLE_MODELS = ("pendulum", "four_bar", "van_der_pol")  # compiled for the tests above too
SAMPLE_SIZE = 24


def _extreme_cases():
    """(model, its first scene, parameter, value): every parameter (derived ones too) of every
    model, or a seeded sample of those of SAMPLE_MODELS."""
    paths = sorted(MODELS.glob("*.bg")) if FULL else [MODELS / f"{m}.bg" for m in SAMPLE_MODELS]
    cases = []
    for path in paths:
        text = path.read_text(encoding="utf-8")
        scene = (re.findall(r"^scene\s+(\w+)", text, re.M) or [None])[0]
        cases += [(path, scene, name, v) for name in re.findall(r"^parameter\s+(\w+)", text, re.M)
                  for v in EXTREME]
    return cases if FULL else random.Random(9).sample(cases, SAMPLE_SIZE)


def _kind(message):
    """A message with its numbers left out: the stiff solvers' linear algebra (LAPACK in
    Python, bgc's LU in C) and the explicit solvers' vector sums agree to rounding, not to the
    bit, so a step budget spent after 2000 steps may end at a time that differs in its last
    digits."""
    return re.sub(r"[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?", "#", message)


@functools.lru_cache(maxsize=None)
def _settings(path, scene):
    return build(path, scene, program=False).settings


@pytest.mark.parametrize("path, scene, name, value", _extreme_cases(),
                         ids=lambda v: v.stem if isinstance(v, Path) else str(v))
def test_an_extreme_parameter_ends_the_run_with_an_answer(path, scene, name, value):
    """Every model's first scene (BGC_EXTREME=1; else a seeded sample of three models) with
    one parameter at 0, +-1e308 or 1e-308, ten output intervals, a budget of 2000 steps: the
    run ends, with success or a message naming the time and what failed (or, before the first
    row, the parameter or constraint that refused the start); no row holds a non-finite value;
    the C program and the Python module end the same way."""
    settings = _settings(path, scene)
    t_end = settings.t0 + 10 * settings.dt
    args = ["--t-end", repr(t_end), "--max-steps", "2000", "-p", f"{name}={value}"]
    results = [run(path, scene, b, *args) for b in (["python", "c"] if HAVE_C else ["python"])]
    for r in results:  # the same kind of end: the numbers may differ in the last digits
        assert (r.code, _kind(r.last), len(r.t)) == \
            (results[0].code, _kind(results[0].last), len(results[0].t)), (r.last, results[0].last)
    r = results[0]
    assert np.all(np.isfinite(r.data))
    if r.code == 0:
        assert r.t[-1] == t_end
        return
    assert r.code in (1, 3) and r.last.startswith("error: "), r.last
    at = re.match(r"error: at t = ([^:]+): ", r.last)
    if at:
        stop = float(at.group(1))
        assert len(r.t) == 0 or r.t[-1] <= stop <= t_end
    else:  # refused before the start
        assert len(r.t) == 0
        assert re.match(r"error: (parameter '[^']+' is not finite|initial conditions violate "
                        r"constraint '[^']+')", r.last), r.last
