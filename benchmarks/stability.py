"""The stability suite's figures (docs/stability.md): each hard case of tests/test_stability.py
run on the normal build (the C program at cc -O2 -std=c99) and measured against the same
independent references, printed as one table.

    python benchmarks/stability.py [--quick]

Columns: case, setting, figure (what the case shows, measured), bound (what theory or the
reference allows, as the test asserts it), steps (accepted steps, from --stats), cpu (the
program's own clock around its integration, ms).  --quick leaves out the sweep of every model
with each parameter at 0, +-1e308 and 1e-308 (about 800 runs of each backend, a minute or two).
Figures are measured, never asserted here; the assertions are the tests'.
"""
from __future__ import annotations

import argparse
import contextlib
import io
import math
import re
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path[:0] = [str(HERE), str(ROOT)]
import machine  # noqa: E402

from bgc.base import cache, processes, toolchain  # noqa: E402
from bgc.api import build  # noqa: E402
from bgc.codegen.emit import emit_c, emit_python  # noqa: E402

MODELS, TEST_MODELS = ROOT / "models", ROOT / "tests" / "models"
FLAGS = ("-O2", "-std=c99")
_PROGRAMS: dict = {}


def program(path, scene=None, backend="c"):
    key = (str(path), scene, backend)
    if key not in _PROGRAMS:
        compiled = build(path, scene)
        if backend == "c":
            (text,) = emit_c(compiled.program).values()
            _PROGRAMS[key] = cache.compile_c(text, flags=FLAGS)
        else:
            (text,) = emit_python(compiled.program).values()
            _PROGRAMS[key] = processes.load_python_module(text)
    return _PROGRAMS[key]


class Run:
    def __init__(self, code, out, err):
        self.code = code
        self.err = err.strip().splitlines()
        lines = out.splitlines()
        self.names = lines[0].split(",")[1:] if lines else []
        self.data = np.loadtxt(lines[1:], delimiter=",", ndmin=2) if len(lines) > 1 else \
            np.zeros((0, len(self.names) + 1))
        stats = [ln for ln in self.err if ln.startswith("stats:")]
        self.stats = {k: float(v) for k, v in (w.split("=") for w in stats[0].split()[1:])} \
            if stats else {}
        messages = [ln for ln in self.err if not ln.startswith("stats:")]
        self.last = messages[-1] if messages else ""

    @property
    def t(self):
        return self.data[:, 0]

    def __getitem__(self, name):
        return self.data[:, 1 + self.names.index(name)]


def run(path, scene, *args, backend="c"):
    args = [str(a) for a in args]
    prog = program(path, scene, backend)
    if backend == "c":
        return Run(*processes.run_c(prog, args))
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = prog.main(args)
    return Run(code, out.getvalue(), err.getvalue())


def p(**values):
    return [a for k, v in values.items() for a in ("-p", f"{k}={v!r}")]


# ------------------------------------------------------------------ references (as the tests')


def pendulum_angle(t, theta0, g=9.81, l=1.0):
    from scipy.special import ellipj, ellipk
    k = math.sin(theta0 / 2)
    sn = ellipj(ellipk(k * k) - math.sqrt(g / l) * np.asarray(t), k * k)[0]
    return 2 * np.arcsin(k * sn)


def damped(t, phi0, dphi0, alpha, beta):
    if alpha == beta:
        return (phi0 + (dphi0 + alpha * phi0) * t) * np.exp(-alpha * t)
    root = np.sqrt(complex(alpha * alpha - beta * beta))
    r1, r2 = -alpha + root, -alpha - root
    c1, c2 = (dphi0 - r2 * phi0) / (r1 - r2), (r1 * phi0 - dphi0) / (r1 - r2)
    return (c1 * np.exp(r1 * t) + c2 * np.exp(r2 * t)).real


VDPOL_Y2 = (0.1706167732170483e1, -0.8928097010247975e0)  # Bari test set, vdpol.f, solut


def relaxation_limit():
    from scipy.optimize import brentq
    since = 2.0 - (3.0 - 2.0 * math.log(2.0))
    y1 = brentq(lambda y: math.log(y / 2) - (y * y - 4) / 2 - since, 1.01, 2.0)
    return y1, y1 / (1 - y1 * y1)


# ------------------------------------------------------------------ the cases

ROWS: list[tuple] = []


def row(case, setting, figure, bound, r=None):
    steps = f"{int(r.stats['steps'])}" if r is not None and "steps" in r.stats else "-"
    cpu = f"{1e3 * r.stats['cpu']:.1f}" if r is not None and "cpu" in r.stats else "-"
    ROWS.append((case, setting, figure, bound, steps, cpu))


def long_horizons():
    pid = run(MODELS / "pendulum.bg", "long", "--t-end", 1e4, "--dt", 10, "--stats")
    drift = np.abs(pid["rod.residual"])
    m, l, g, theta0, alpha = 1.0, 1.0, 9.81, 0.5, 5.0
    v_max = math.sqrt(2 * g * l * (1 - math.cos(theta0)))
    e = 2 * (1e-10 + 1e-8 * max(l, m * v_max))
    a, b = 2 * math.sqrt(2) * l * e, 2 * math.sqrt(2) * (l / m + v_max) * e
    bound = pid.stats["steps"] / 1e4 * (2 * a / alpha + b / alpha**2)
    row("1 long horizon", "pendulum, pid(5, 5), dopri5 1e-8, 1e4 s",
        f"max |Phi| = {drift.max():.2g}", f"< {bound:.2g}", pid)
    none = run(MODELS / "pendulum.bg", "long", "--t-end", 1e4, "--dt", 10, "--stats",
               *p(alpha=0.0, beta=0.0))
    d = np.abs(none["rod.residual"])
    row("1 long horizon", "the same, no corrector (alpha = beta = 0)",
        f"max |Phi| = {d[none.t <= 1e3].max():.2g} to 1e3 s, {d.max():.2g} to 1e4 s",
        "grows (x10 or more)", none)


def corrector_law():
    for alpha, beta in ((2.0, 10.0), (5.0, 5.0), (10.0, 4.0)):
        r = run(TEST_MODELS / "pendulum_offset.bg", "settle", "--allow-inconsistent", "--stats",
                *p(r0=1.001, vr0=0.01, alpha=alpha, beta=beta))
        want = damped(r.t, 1.001**2 - 1, 2 * 1.001 * 0.01, alpha, beta)
        err = np.abs(r["rod.residual"] - want).max() / abs(want[0])
        row("2 corrector law", f"pid({alpha:g}, {beta:g}) from Phi = 2e-3, Phi' = 0.02",
            f"|Phi - closed form| = {err:.1e} Phi(0)", "< 1e-5 Phi(0)", r)
    r = run(TEST_MODELS / "knife_slip.bg", "settle", "--allow-inconsistent", "--stats",
            *p(s0=0.01, gamma=10.0))
    err = np.abs(r["blade.residual"] - 0.01 * np.exp(-10 * r.t)).max() / 0.01
    row("2 corrector law", "pd(10) from a slip of 0.01 m/s",
        f"|Phi - closed form| = {err:.1e} Phi(0)", "< 1e-5 Phi(0)", r)


def energy():
    m1, m2, g = 1.0, 0.5, 9.81
    for solver in ("dop853", "vern7", "radau5", "rodas5p"):
        r = run(MODELS / "double_pendulum.bg", None, "--t-end", 100, "--dt", 0.1, "--solver",
                solver, "--rtol", 1e-12, "--atol", 1e-12, "--stats", *p(theta1=2.0, theta2=2.6))
        if r.code:
            row("3 energy", f"double pendulum, {solver} 1e-12, 100 s", r.last, "", r)
            continue
        v1 = np.hypot(r["mx1.p"], r["my1.p"]) / m1
        v2 = np.hypot(r["mx2.p"], r["my2.p"]) / m2
        E = 0.5 * m1 * v1**2 + 0.5 * m2 * v2**2 - g * (m1 * r["y1"] + m2 * r["y2"])
        grad = 2 * v1.max() + 2 * v2.max() + g * (m1 + m2)
        size = max(np.abs(r.data[:, 1:]).max(), 1.0)
        bound = r.stats["steps"] * grad * math.sqrt(8) * (1e-12 + 1e-12 * size)
        row("3 energy", f"double pendulum (2, 2.6 rad), {solver} 1e-12, 100 s",
            f"max |E - E(0)| = {np.abs(E - E[0]).max():.1e} J (E(0) = {E[0]:.3g} J)",
            f"< {bound:.1e} J", r)


def stiffness():
    for solver in ("dopri5", "radau5", "rodas4", "rodas5p"):
        r = run(MODELS / "pendulum.bg", "swing", "--solver", solver, "--rtol", 1e-8, "--atol",
                1e-10, "--t-end", 3, "--stats", *p(alpha=1e3, beta=1e3))
        th = pendulum_angle(r.t, 0.5)
        err = max(np.abs(r["x"] - np.sin(th)).max(), np.abs(r["y"] - np.cos(th)).max())
        row("4 high gains", f"pendulum, alpha = beta = 1e3, {solver} 1e-8, 3 s",
            f"|x - elliptic closed form| = {err:.1e}",
            "< 1e-6" + ("; dopri5 >= 453 steps" if solver == "dopri5" else ""), r)
    for solver in ("radau5", "rodas4", "rodas5p"):
        for tol in (1e-6, 1e-8, 1e-10):
            r = run(TEST_MODELS / "vdpol_testset.bg", "testset", "--solver", solver, "--rtol",
                    tol, "--atol", tol, "--stats")
            err = max(abs(r["cap.q"][-1] - VDPOL_Y2[0]) / abs(VDPOL_Y2[0]),
                      abs(r["ind.p"][-1] - VDPOL_Y2[1]) / abs(VDPOL_Y2[1]))
            row("4 Van der Pol", f"Bari VDPOL (eps 1e-6), {solver} {tol:g}",
                f"rel. error of y(2) = {err:.1e}", f"< {100 * tol:g}" if tol == 1e-8 else "", r)
    y1, y2 = relaxation_limit()
    for solver in ("radau5", "rodas4", "rodas5p"):
        r = run(MODELS / "van_der_pol.bg", "period", "--solver", solver, "--rtol", 1e-8,
                "--atol", 1e-8, "--dt", 0.5, "--stats", *p(mu=1e5))
        row("4 Van der Pol", f"mu = 1e5 (eps 1e-10), {solver} 1e-8",
            f"y(2) - relaxation limit = ({r['cap.q'][-1] - y1:.1e}, {r['ind.p'][-1] - y2:.1e})",
            "< 1e-5 (limit's own error ~eps^(2/3))", r)
    r = run(MODELS / "pendulum.bg", "swing", "--solver", "rk4", "--dt", 0.01, "--t-end", 1,
            "--stats", *p(alpha=1e3, beta=1e3))
    R = abs(np.polynomial.Polynomial([1, 1, 1 / 2, 1 / 6, 1 / 24])(-10.0))
    row("4 fixed step", "rk4, h = 0.01, alpha = beta = 1e3 (h lambda = -10)",
        f"stops: {r.last[7:]}; rows to t = {r.t[-1]:g}, all finite",
        f"|R(-10)| = {R:.0f} > 1: warned", r)


def scales():
    r = run(TEST_MODELS / "scales.bg", "scaled", "--stats")
    t = r.t
    small, large = 1e-9, 1e9
    tau = large * small * large / (small + large)
    v2 = large / (large + small) * (1 - np.exp(-t / tau))
    vcm = large / (large + small)
    u = np.exp(-t * small * (1 / large + 1 / small))
    want = {"rc1c.q": small * (1 - np.exp(-t)), "rc2c.q": large * (1 - np.exp(-t)),
            "k1.q": np.cos(t), "m1.p": -small * np.sin(t), "k2.q": np.cos(t),
            "m2.p": -large * np.sin(t), "c2.q": small * v2, "c1.q": large - small * v2,
            "heavy.p": large * (vcm + small / (large + small) * u),
            "light.p": small * (vcm - large / (large + small) * u)}
    worst = max(np.abs(r[n] - v).max() / np.abs(v).max() for n, v in want.items())
    row("5 scales", "C, m from 1e-9 to 1e9, dopri5 1e-10 (atol 1e-25), 5 s",
        f"worst error / own scale = {worst:.1e}", "< 1e-8", r)


def dead_centre():
    args = ["--t-end", 5, "--stats", *p(c=1.0, g=-9.81, phi0=0.3)]
    r = run(MODELS / "four_bar.bg", "swing", *args)
    passes = np.count_nonzero(np.diff(np.sign(r["q[1]"])))
    resid = max(np.abs(r[f"rods.residual[{k}]"]).max() for k in range(3))
    stop = re.match(r"error: at t = ([^:]+): algebraic block \d+ \((\w+)", r.last)
    end = f"stops at t = {float(stop.group(1)):.4f}, {stop.group(2)}.lambda singular" if stop \
        else (r.last or f"runs to t = {r.t[-1]:g}")
    row("6 dead centre", "four-bar as a parallelogram (c = a, d = b), gravity reversed",
        f"{passes} dead centres passed, max |Phi| = {resid:.1e}; {end}",
        "stop named, rows finite", r)


def extreme():
    values = ("0", "1e308", "-1e308", "1e-308")
    counts: dict = {}
    slowest, agree, total, nonfinite = 0.0, 0, 0, 0
    for path in sorted(MODELS.glob("*.bg")):
        text = path.read_text(encoding="utf-8")
        scene = (re.findall(r"^scene\s+(\w+)", text, re.M) or [None])[0]
        settings = build(path, scene, program=False).settings
        t_end = settings.t0 + 10 * settings.dt
        program(path, scene)  # compiled before the timing
        for name in re.findall(r"^parameter\s+(\w+)", text, re.M):
            for v in values:
                args = ["--t-end", repr(t_end), "--max-steps", "2000", "-p", f"{name}={v}"]
                start = time.perf_counter()
                c = run(path, scene, *args)
                slowest = max(slowest, time.perf_counter() - start)
                py = run(path, scene, *args, backend="python")
                total += 1
                kind = "ok" if c.code == 0 else _cause(c.last)
                counts[kind] = counts.get(kind, 0) + 1
                nonfinite += int(not (np.all(np.isfinite(c.data)) and
                                      np.all(np.isfinite(py.data))))
                mask = re.compile(r"[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?")
                agree += int(c.code == py.code and mask.sub("#", c.last) == mask.sub("#", py.last)
                             and len(c.t) == len(py.t))
    summary = ", ".join(f"{k} {n}" for k, n in sorted(counts.items(), key=lambda kv: -kv[1]))
    row("7 extreme", f"{total} runs: every model, each parameter at 0, +-1e308, 1e-308",
        summary, f"non-finite rows {nonfinite}; C and Python alike in {agree}/{total}; "
        f"slowest C run {1e3 * slowest:.0f} ms")


def _cause(message):
    for key, text in (("step budget", "budget spent"), ("step too small", "step size too small"),
                      ("not finite", "not finite"), ("not finite", "non-finite"),
                      ("singular", "singular"),
                      ("Newton", "not converge"), ("constraint", "violate constraint")):
        if text in message:
            return key
    return "other: " + message


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="leave out the extreme sweep")
    args = parser.parse_args()
    cc = toolchain.c_compiler()
    print(f"cc:   {machine.cc_version(cc)}  (flags: {' '.join(FLAGS)})")
    print(f"cpu:  {machine.processor()}")
    print(f"load: {machine.load_average()}")
    for case in (long_horizons, corrector_law, energy, stiffness, scales, dead_centre):
        case()
    if not args.quick:
        extreme()
    head = ("case", "setting", "figure", "bound", "steps", "cpu [ms]")
    widths = [max(len(str(r[i])) for r in ROWS + [head]) for i in range(len(head))]
    print(" | ".join(h.ljust(w) for h, w in zip(head, widths)))
    print("-|-".join("-" * w for w in widths))
    for r in ROWS:
        print(" | ".join(str(c).ljust(w) for c, w in zip(r, widths)))


if __name__ == "__main__":
    main()
