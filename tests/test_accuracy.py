"""`bgc accuracy` and the corrector stability check: the errors it reports against a SciPy
reference computed here, the ordering of errors under tightening tolerances, the stability
function of the explicit solvers against their closed forms, and the warnings of `simulate`.
No test asserts a time."""
import csv
import math
from pathlib import Path

import numpy as np
import pytest

from bgc import api
from bgc.base import solvers, toolchain
from bgc.analysis import stability
from conftest import run_bgc
from test_simulate import pendulum_reference

ROOT = Path(__file__).resolve().parent.parent
PENDULUM = ROOT / "models" / "pendulum.bg"
needs_cc = pytest.mark.skipif(not toolchain.have_c_compiler(), reason="no C compiler")


def bgc(*args, cwd=None):
    return run_bgc(*args, cwd=cwd)


def read_rows(path):
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


# ---------------------------------------------------------------- stability functions


def test_stability_functions_are_the_methods_polynomials():
    """Explicit Euler: 1 + z; RK4: the degree-4 Taylor polynomial of e^z; dopri5's propagating
    weights are order 5 with six stages, so its R has the Taylor terms up to z^5."""
    z = np.array([-0.3, -2.5 + 1j, 0.7j, -2.785])
    R_euler, R_rk4, R_dp = (stability.stability_function(n) for n in ("euler", "rk4", "dopri5"))
    taylor = [1.0 / math.factorial(k) for k in range(7)]
    for zz in z:
        assert abs(R_euler(zz) - (1 + zz)) < 1e-15
        assert abs(R_rk4(zz) - sum(taylor[k] * zz**k for k in range(5))) < 1e-14
        tail = R_dp(zz) - sum(taylor[k] * zz**k for k in range(6))
        assert abs(tail) < 0.01 * abs(zz) ** 6  # its z^6 coefficient is not 1/720's multiple
    assert stability.stability_function("radau5") is None


def test_real_axis_bounds():
    # 1 + z on [-2, 0]; RK4's bound is the real root of |T4(-x)| = 1, about 2.785293563405
    assert abs(stability.real_axis_bound("euler") - 2.0) < 1e-9
    x = stability.real_axis_bound("rk4")
    assert abs(1 - x + x**2 / 2 - x**3 / 6 + x**4 / 24 - 1.0) < 1e-9 and 2.78 < x < 2.79


def test_corrector_eigenvalues_are_the_drift_equations_roots():
    """pid(alpha, beta): Phi'' + 2 alpha Phi' + beta^2 Phi = 0."""
    compiled = api.build(PENDULUM, "swing", program=False)
    (modes,) = stability.corrector_modes(compiled, {"alpha": 10.0, "beta": 6.0})
    assert modes.junction == "rod" and modes.corrector == "pid"
    for lam in modes.eigenvalues:
        assert abs(lam * lam + 20.0 * lam + 36.0) < 1e-12
    (modes,) = stability.corrector_modes(compiled, {"alpha": 3.0, "beta": 5.0})
    assert all(abs(lam.real + 3.0) < 1e-12 and abs(abs(lam.imag) - 4.0) < 1e-12
               for lam in modes.eigenvalues)


@needs_cc
def test_simulate_warns_before_an_unstable_fixed_step(tmp_path):
    """RK4 at h = 0.01 with alpha = beta = 300: h lambda = -3, |R| = 1.375 > 1: a warning, and
    the run indeed blows up; alpha = beta = 250 (h lambda = -2.5, 90% of the bound): a warning
    that it is close; alpha = beta = 200 (72%): none."""
    out = tmp_path / "out.csv"
    done = bgc("simulate", PENDULUM, "-s", "swing", "--solver", "rk4", "-p", "alpha=300",
               "-p", "beta=300", "-o", out)
    assert "unstable on the corrector of 'rod'" in done.stderr
    assert "|R(h*lambda)| = 1.38" in done.stderr  # 1 - 3 + 9/2 - 27/6 + 81/24 = 1.375
    assert done.returncode == 1 and "not finite" in done.stderr
    done = bgc("simulate", PENDULUM, "-s", "swing", "--solver", "rk4", "--t-end", "1",
               "-p", "alpha=250", "-p", "beta=250", "-o", out)
    assert done.returncode == 0 and "within 20% of its stability bound" in done.stderr
    done = bgc("simulate", PENDULUM, "-s", "swing", "--solver", "rk4", "--t-end", "1",
               "-p", "alpha=200", "-p", "beta=200", "-o", out)
    assert done.returncode == 0 and "warning" not in done.stderr
    done = bgc("simulate", PENDULUM, "-s", "swing", "--solver", "dopri5", "--t-end", "0.1",
               "-p", "alpha=300", "-p", "beta=300", "-o", out)
    assert "unstable" not in done.stderr  # adaptive: the error control takes care


# ---------------------------------------------------------------- the sweep


@needs_cc
def test_accuracy_table_csv_png_and_ordering(tmp_path):
    """The default sweep on the pendulum: a row per solver and setting, errors falling as the
    tolerance tightens for every adaptive solver (down to the reference floor)."""
    done = bgc("accuracy", PENDULUM, "--repeats", "1", "-o", tmp_path / "acc")
    assert done.returncode == 0, done.stderr
    assert "reference: dop853 rtol=1e-13" in done.stdout
    rows = read_rows(tmp_path / "acc" / "accuracy.csv")
    assert {r["solver"] for r in rows} == set(solvers.NAMES)
    floor = float(done.stdout.split("references differ by ")[1].split()[0])
    assert floor < 1e-11
    for name in solvers.NAMES:
        mine = [r for r in rows if r["solver"] == name]
        assert all(r["status"] == "ok" for r in mine), mine
        errors = [float(r["error_max"]) for r in mine]
        if solvers.get(name).adaptive:
            assert [float(r["value"]) for r in mine] == sorted(
                (float(r["value"]) for r in mine), reverse=True)
        for looser, tighter in zip(errors, errors[1:]):
            assert tighter < looser or tighter < 10 * floor, (name, errors)
        assert all(int(r["steps"]) > 0 and float(r["cpu_s"]) >= 0 for r in mine)
        assert all(float(r["residual"]) < 0.05 for r in mine)  # rod.residual, added
    try:
        import matplotlib  # noqa: F401
    except ImportError:
        assert "matplotlib is not installed" in done.stderr
    else:
        png = (tmp_path / "acc" / "accuracy.png").read_bytes()
        assert png[:8] == b"\x89PNG\r\n\x1a\n"


@needs_cc
def test_errors_against_a_scipy_reference(tmp_path):
    """With --reference, a CSV from SciPy's DOP853 on eq. (12) typed by hand: the errors bgc
    reports equal the ones computed here from the same CSVs, and agree with the errors against
    bgc's own reference to within its floor."""
    t = np.round(np.arange(0, 201) * 0.01, 12)
    x, y, lam = pendulum_reference(t)
    ref = tmp_path / "ref.csv"
    with open(ref, "w") as fh:
        fh.write("t,x,y,rod.lambda,rod.residual\n")
        for row in zip(t, x, y, lam, x * x + y * y - 1.0):
            fh.write(",".join(f"{v:.17g}" for v in row) + "\n")
    common = ("-s", "swing", "--t-end", "2", "--solvers", "dopri5,rk4", "--rtols", "1e-4,1e-7",
              "--steps", "0.01", "--repeats", "1", "--no-plot")
    given = bgc("accuracy", PENDULUM, *common, "--reference", ref, "-o", tmp_path / "a")
    own = bgc("accuracy", PENDULUM, *common, "-o", tmp_path / "b")
    assert given.returncode == 0 and own.returncode == 0, given.stderr + own.stderr
    rows_given = read_rows(tmp_path / "a" / "accuracy.csv")
    rows_own = read_rows(tmp_path / "b" / "accuracy.csv")
    t_, Y, names = api.simulate(PENDULUM, "swing", t_end=2.0, solver="dopri5", rtol=1e-4,
                                atol=1e-4 * 1e-2)
    assert names == ["x", "y", "rod.lambda", "rod.residual"]
    R = np.column_stack([x, y, lam])
    mine = np.max(np.abs(Y[:, :3] - R) / np.max(np.abs(R), axis=0))
    assert float(rows_given[0]["error_max"]) == pytest.approx(mine, rel=1e-6)
    for a, b in zip(rows_given, rows_own):
        assert abs(float(a["error_max"]) - float(b["error_max"])) < 1e-11
        assert a["steps"] == b["steps"]


@needs_cc
def test_accuracy_on_a_stick_slip_model(tmp_path):
    """The references (DOP853 and Dopri5 at rtol 1e-13, atol 1e-15) of a mass that sticks to
    a belt and breaks away: they run (no false chattering at a stick), agree with each other,
    and the swept errors fall as the tolerance tightens."""
    from test_contact import STICK_SLIP
    (tmp_path / "stick.bg").write_text(STICK_SLIP.replace("SOLVER", "dopri5").replace(
        ", hmax = 0.05", ""), encoding="utf-8")
    done = bgc("accuracy", "stick.bg", "-s", "run", "--solvers", "dopri5,dop853", "--rtols",
               "1e-4,1e-7,1e-10", "--repeats", "1", "--no-plot", "-o", "acc", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert "reference: dop853 rtol=1e-13" in done.stdout
    floor = float(done.stdout.split("references differ by ")[1].split()[0])
    assert floor < 1e-10
    rows = read_rows(tmp_path / "acc" / "accuracy.csv")
    for name in ("dopri5", "dop853"):
        errors = [float(r["error_max"]) for r in rows if r["solver"] == name]
        assert all(r["status"] == "ok" for r in rows if r["solver"] == name)
        assert errors[0] > errors[1] > errors[2] or errors[2] < 10 * floor, (name, errors)


@needs_cc
def test_gain_sweep_reports_the_unstable_gain(tmp_path):
    done = bgc("accuracy", PENDULUM, "-s", "swing", "--t-end", "2", "--gains", "5,300",
               "--solvers", "rk4", "--steps", "0.01", "--repeats", "1", "--no-plot",
               "-o", tmp_path)
    assert done.returncode == 0, done.stderr
    rows = read_rows(tmp_path / "gains.csv")
    assert [float(r["gain"]) for r in rows] == [5.0, 300.0]
    # h lambda = -0.05 (double root): |1 + z + z^2/2 + z^3/6 + z^4/24|; and -3 for 300
    z = -0.05
    assert float(rows[0]["amplification"]) == pytest.approx(1 + z + z*z/2 + z**3/6 + z**4/24,
                                                            rel=1e-12)
    assert float(rows[1]["amplification"]) == pytest.approx(1.375, rel=1e-12)
    assert rows[0]["status"] == "ok" and "not finite" in rows[1]["status"]


@needs_cc
def test_accuracy_errors_are_for_people(tmp_path):
    bad = tmp_path / "bad.csv"
    bad.write_text("t,x\n0,1\n")
    done = bgc("accuracy", PENDULUM, "-s", "swing", "--solvers", "dopri5", "--rtols", "1e-3",
               "--reference", bad, "-o", tmp_path / "o")
    assert done.returncode == 1 and "no column 'y'" in done.stderr
    assert "Traceback" not in done.stderr and not (tmp_path / "o").exists()
    done = bgc("accuracy", PENDULUM, "--gains", "1,2", "-s", "unstabilised", "-o", tmp_path)
    assert done.returncode == 1 and "pid or pd corrector" in done.stderr
    done = bgc("accuracy", PENDULUM, "--solvers", "nope")
    assert done.returncode == 2 and "unknown solver 'nope'" in done.stderr
