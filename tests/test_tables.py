"""Lookup tables (docs/language.md, "Tables"): read at compile time, embedded in the generated
code, the breakpoints of a table of t stepped onto as time events by every solver, the same
bytes in both backends.  References: SciPy (piece by piece between the breakpoints, and its
PchipInterpolator for cubic tables) and closed forms, computed here."""
import csv
import io
import math

import numpy as np
import pytest

import bgc
from bgc.execute import runner
from bgc.base import solvers
from bgc.api import Source

from conftest import have_cc

BACKENDS = ["c", "python"] if have_cc() else ["python"]

# a road of a few segments at non-round breakpoints, with a jump at 0.41 (two rows of one x)
ROAD = [(0.0, 0.0), (0.37, 0.02), (0.41, 0.02), (0.41, 0.05), (1.13, 0.01), (1.9, 0.0)]

QUARTER_CAR = """model quarter_car "a quarter car over a road given as a table of time"
parameter ms = 300.0 "sprung mass"
parameter mu = 40.0 "unsprung mass"
parameter ks = 20000.0
parameter cs = 1500.0
parameter kt = 200000.0 "tyre"
signal road = table("road.csv", t)
signal zs = integral(vs, init = 0)
signal zu = integral(vu, init = 0)
signal vs = integral((-ks*(zs - zu) - cs*(vs - vu))/ms, init = 0)
signal vu = integral((ks*(zs - zu) + cs*(vs - vu) - kt*(zu - road))/mu, init = 0)
scene run { time 0 .. 1.3 every 0.01; outputs zs, zu, road; solver dopri5(rtol = 1e-8, atol = 1e-10) }
"""


def write_road(directory):
    (directory / "road.csv").write_text(
        "t,z\n" + "".join(f"{x!r},{z!r}\n" for x, z in ROAD), encoding="utf-8")


_MODULES: list = []  # (compiled, its module loaded here)


def run_csv(compiled, backend, **options) -> str:
    """The run's CSV and statistics: the C program's, or the Python module's loaded in this
    process (the same text as its command line writes)."""
    if backend == "python":
        found = [m for c, m in _MODULES if c is compiled]
        if not found:
            found = [runner.prepare(compiled, "python", in_process=True).module]
            _MODULES.append((compiled, found[0]))
        module, stats, out = found[0], {}, io.StringIO()
        module._stream(module.rows(stats=stats, **options), out)
        return out.getvalue(), {k: str(v) for k, v in stats.items()}
    program = runner.prepare(compiled, backend)
    names = [p.name for p in compiled.program.params]
    settings = runner.settings_for(compiled.program.scene, names, **options)
    result = runner.run(program, settings, stats=True)
    assert result.status == 0, result.stderr
    return result.csv, result.stats


def read(text):
    rows = list(csv.reader(io.StringIO(text)))
    return rows[0], np.array([[float(v) for v in r] for r in rows[1:]])


def road_reference(t_out, ms=300.0, mu=40.0, ks=20000.0, cs=1500.0, kt=200000.0):
    """SciPy at tight tolerance, piece by piece between the road's breakpoints, the road
    linear on each piece (held after the last row)."""
    from scipy.integrate import solve_ivp

    def f(z0, slope, t0):
        def rhs(t, y):
            zs, zu, vs, vu = y
            road = z0 + slope * (t - t0)
            fs = ks * (zs - zu) + cs * (vs - vu)
            return [vs, vu, -fs / ms, (fs - kt * (zu - road)) / mu]
        return rhs
    pieces = []
    for (xa, za), (xb, zb) in zip(ROAD, ROAD[1:]):
        if xb > xa:
            pieces.append((xa, xb, za, (zb - za) / (xb - xa)))
    pieces.append((ROAD[-1][0], t_out[-1], ROAD[-1][1], 0.0))
    y, out = [0.0] * 4, np.zeros((len(t_out), 2))
    for a, b, z0, slope in pieces:
        sol = solve_ivp(f(z0, slope, a), (a, b), y, rtol=1e-12, atol=1e-14, dense_output=True,
                        method="DOP853")
        mask = (t_out >= a) & (t_out < b) if b < t_out[-1] else (t_out >= a)
        if mask.any():
            out[mask] = sol.sol(t_out[mask])[:2].T
        y = sol.y[:, -1]
    return out


# steps that do not divide the breakpoints, so that each is a step of its own; first order,
# Euler's error is 4.9e-5 at a step of 2e-6 and under 1e-6 at 3.9e-8 (3.3e7 steps, a few
# seconds in C); its bytes in Python are compared with C's over the first breakpoints below
FIXED_STEP = {"euler": 3.9e-8, "rk4": 4.7e-4}
# ros2, second order, takes 3.3e5 steps at the scene's rtol 1e-8 (28 s in Python, 0.3 s in C):
# it too runs in C alone here, its bytes compared with Python's in the test below
C_ONLY = ("euler", "ros2")


def test_a_quarter_car_on_a_road_table_with_every_solver(tmp_path):
    """Every solver steps onto the road's breakpoints (its jump and its kinks): the run matches
    SciPy integrated piece by piece to 1e-6, with the same bytes in both backends."""
    write_road(tmp_path)
    compiled = bgc.build(Source(str(tmp_path / "car.bg"), QUARTER_CAR), "run")
    ref = None
    for solver in solvers.SOLVERS:
        options = {"solver": solver}
        if solver in FIXED_STEP:
            options["step"] = FIXED_STEP[solver]
        if solver == "euler":
            options["max_steps"] = 10 ** 6  # 250 000 steps between two outputs
        texts = {}
        for backend in BACKENDS:
            if backend == "python" and solver in C_ONLY and "c" in BACKENDS:
                continue  # its bytes are compared with C's in the test below
            texts[backend], stats = run_csv(compiled, backend, **options)
            assert int(stats["events"]) == 3, (solver, stats)  # at 0.37, 0.41 and 1.13
        if len(texts) == 2:
            assert texts["c"] == texts["python"], solver
        head, y = read(next(iter(texts.values())))
        assert head == ["t", "zs", "zu", "road"]
        if ref is None:
            ref = road_reference(y[:, 0])
            after_jump = ROAD[:2] + ROAD[3:]
            road = np.interp(y[:, 0], [x for x, _ in after_jump], [z for _, z in after_jump])
        scale = np.max(np.abs(ref), axis=0)
        err = np.max(np.abs(y[:, 1:3] - ref), axis=0) / scale
        assert np.all(err <= 1e-6), (solver, err)
        after = y[:, 0] > 0.41
        assert np.allclose(y[after, 3], road[after], rtol=0, atol=1e-15), solver


@pytest.mark.skipif(len(BACKENDS) < 2, reason="needs a C compiler")
@pytest.mark.parametrize("options", [dict(solver="euler", step=3e-5),
                                     dict(solver="ros2", rtol=1e-4)], ids=C_ONLY)
def test_the_long_runs_take_the_same_steps_over_the_road_in_both_backends(tmp_path, options):
    """Euler's and ros2's long runs above are in C; over the kink at 0.37 and the jump at 0.41
    the Python module takes the same steps onto the same breakpoints and writes the same bytes
    (ros2 adaptive, at a tolerance that keeps Python's run short)."""
    write_road(tmp_path)
    compiled = bgc.build(Source(str(tmp_path / "car.bg"), QUARTER_CAR), "run")
    texts = {}
    for backend in BACKENDS:
        texts[backend], stats = run_csv(compiled, backend, t_end=0.45, **options)
        assert int(stats["events"]) == 2, stats
    head, y = read(texts["c"])
    assert np.all(np.diff(y[:, 0]) > 0) and y[-1, 0] == 0.45
    assert texts["c"] == texts["python"]


def table_model(rows, interp, extrapolate="hold", x="t"):
    text = ", ".join(f"[{a!r}, {b!r}]" for a, b in rows)
    return (f"model tab\nsignal y = table([{text}], {x}, interp = {interp}, "
            f"extrapolate = {extrapolate})\n"
            "signal dy = integral(y, init = 0)\n"
            "scene run { time -1 .. 5 every 0.125; outputs y, dy }\n")


ROWS = [(0.0, 1.0), (0.5, 2.0), (1.25, 1.5), (2.0, 4.0), (2.0, 3.0), (3.5, 3.5)]


def outputs(text, backend="python"):
    compiled = bgc.build(Source("tab.bg", text), "run")
    csv_text, _ = run_csv(compiled, backend)
    return read(csv_text)[1]


def test_step_and_linear_interpolation_and_extrapolation():
    """Known values: a step table takes its interval's left row; a linear one interpolates;
    both hold or extend their end's slope outside, and a jump takes the row after it at its x.
    The integral of the table checks that the time events split the run at every row."""
    xs = np.array([r[0] for r in ROWS])
    ys = np.array([r[1] for r in ROWS])
    for x_expr in ("t", "2*t/2"):  # a time table (events) and a static one (a law of X)
        y = outputs(table_model(ROWS, "step", x=x_expr))
        t = y[:, 0]
        want = np.where(t < 0, 1.0, ys[np.searchsorted(xs, t, side="right") - 1])
        assert np.array_equal(y[:, 1], want), x_expr
        y = outputs(table_model(ROWS, "linear", "linear", x=x_expr))
        t = y[:, 0]
        left = 1.0 + 2.0 * t  # the first interval's slope, extended
        right = 3.0 + (3.5 - 3.0) / 1.5 * (t - 2.0)  # the last interval, extended
        inside = np.interp(t, [0, 0.5, 1.25, 2.0], [1, 2, 1.5, 4.0])
        want = np.where(t < 0, left, np.where(t >= 2.0, right, inside))
        assert np.allclose(y[:, 1], want, rtol=0, atol=1e-15), x_expr
    # the time table's integral, exactly piecewise quadratic: every kink stepped onto
    y = outputs(table_model(ROWS, "linear", "hold"))
    t, integral = y[:, 0], y[:, 2]

    def exact(T):  # trapezoids are exact on each linear piece
        pieces = [(-1, 0, 1, 1), (0, 0.5, 1, 2), (0.5, 1.25, 2, 1.5), (1.25, 2, 1.5, 4),
                  (2, 3.5, 3, 3.5), (3.5, math.inf, 3.5, 3.5)]
        total = 0.0
        for a, b, fa, fb in pieces:
            if T <= a:
                break
            e = min(b, T)
            fe = fb if e == b else fa + (fb - fa) * (e - a) / (b - a)
            total += (e - a) * (fa + fe) / 2
        return total
    for T, got in zip(t[::8], integral[::8]):
        assert abs(got - exact(T)) < 1e-6, T


def test_cubic_is_scipys_monotone_hermite_interpolant():
    from scipy.interpolate import PchipInterpolator
    rows = [(0.0, 0.0), (0.3, 0.1), (1.0, 1.4), (1.7, 1.5), (2.2, 0.2), (3.1, -0.4),
            (4.0, 2.0)]
    pchip = PchipInterpolator([r[0] for r in rows], [r[1] for r in rows])
    for backend in BACKENDS:
        y = outputs(table_model(rows, "cubic", x="t"), backend)
        t = y[:, 0]
        inside = (t >= 0) & (t <= 4.0)
        assert np.allclose(y[inside, 1], pchip(t[inside]), rtol=0, atol=1e-14)
        assert np.all(y[t < 0, 1] == 0.0) and np.all(y[t > 4, 1] == 2.0)  # held
    # its slope is the Jacobian's entry of a table of a state
    text = ("model law\nsignal x = integral(-table([" +
            ", ".join(f"[{a!r}, {b!r}]" for a, b in rows) +
            "], x, interp = cubic), init = 3)\nscene run { time 0 .. 1 every 0.5 }\n")
    compiled = bgc.build(Source("law.bg", text), "run")
    module = runner.prepare(compiled, "python", in_process=True).module
    for x in (0.1, 0.65, 1.9, 2.2, 3.7):
        J = module.jacobian(0.0, [x], module._param_values({}))
        assert math.isclose(J[0][0], -pchip(x, 1), rel_tol=1e-13, abs_tol=1e-15), x


def test_extrapolate_error_stops_the_run_when_x_leaves_the_range():
    compiled = bgc.build(Source("tab.bg", table_model(ROWS, "linear", "error", x="t + 1")),
                         "run")
    for backend in BACKENDS:
        program = runner.prepare(compiled, backend)
        result = runner.run(program, runner.settings_for(compiled.program.scene, []))
        assert result.status != 0
        assert "at t = 2.500000000" in result.stderr, result.stderr  # t + 1 leaves [0, 3.5]
        assert ("'table([[0.0, 1.0], [0.5, 2.0], [1.25, 1.5], [2.0, 4.0], [2.0, 3.0], [3.5, 3.5]], "
                "t + 1, interp = linear, extrapolate = error) is read outside its rows, x from "
                "0.0 to 3.5") in result.stderr, result.stderr  # (named as written)
        assert result.csv.splitlines()[-1].startswith("2.5,")  # the rows up to it kept


def check(directory, name):
    """`bgc check NAME` in directory, in this process."""
    import os
    from click.testing import CliRunner
    from bgc.cli import main
    here = os.getcwd()
    os.chdir(directory)
    try:
        return CliRunner().invoke(main, ["check", name])
    finally:
        os.chdir(here)


@pytest.mark.parametrize("content, where, message", [
    ("t,z\n0,0\n0.5,1\n0.4,2\n", "road.csv:4:1", "x decreases here (0.4 after 0.5)"),
    ("t,z\n0,0\n0.5,inf\n", "road.csv:3:1", "'inf' is not a finite number (column 'z')"),
    ("t,z\n0,0\n0.5\n", "road.csv:3:1", "this row has 1 fields, the header 2"),
    ("t,z\n0,0\n0.5,1\n0.5,2\n0.5,3\n", "road.csv:5:1", "x = 0.5 a third time"),
])
def test_a_bad_table_file_is_an_error_at_its_row(tmp_path, content, where, message):
    (tmp_path / "road.csv").write_text(content, encoding="utf-8")
    (tmp_path / "car.bg").write_text("model car\nsignal z = integral(table(road.csv, t), "
                                     "init = 0)\n", encoding="utf-8")
    done = check(tmp_path, "car.bg")
    assert done.exit_code == 1 and "Traceback" not in done.stderr
    assert done.stderr.splitlines()[0].startswith(f"{where}: error: {message}"), done.stderr
    assert "car.bg:2:27: note: the table is read here" in done.stderr


def test_a_table_file_too_large_is_refused_before_it_is_read(tmp_path):
    from bgc.front.tables import MAX_TABLE_BYTES
    with open(tmp_path / "big.csv", "wb") as f:
        f.truncate(MAX_TABLE_BYTES + 1)  # sparse: nothing is written, nothing is read
    (tmp_path / "m.bg").write_text('model m\nsignal z = integral(table("big.csv", t), '
                                   'init = 0)\n', encoding="utf-8")
    done = check(tmp_path, "m.bg")
    assert done.exit_code == 1
    assert f"is too large ({MAX_TABLE_BYTES + 1} bytes; the limit is {MAX_TABLE_BYTES})" \
        in done.stderr


def test_a_librarys_table_file_is_read_beside_the_library(tmp_path):
    """A component of a library reads its table relative to the library's file, so that the
    library can carry its data; the model's own tables stay relative to the model."""
    (tmp_path / "parts").mkdir()
    (tmp_path / "parts" / "curves.bg").write_text(
        "library curves\ncomponent source() {\n  port p\n"
        "  s : Se(table(curve.csv, t))\n  s -> p\n}\n")
    (tmp_path / "parts" / "curve.csv").write_text("x,y\n0,2\n1,4\n")
    (tmp_path / "own.csv").write_text("x,y\n0,10\n1,30\n")
    (tmp_path / "m.bg").write_text(
        'model m\nimport "parts/curves.bg" as lib\nsrc : lib.source()\nj : 1\nr : R(2)\n'
        "src.p -> j\nj -> r\nsignal own = table(own.csv, t)\n"
        "scene run { outputs r.f, own; time 0 .. 1 every 0.5 }\n")
    t, Y, _ = bgc.simulate(str(tmp_path / "m.bg"), "run", backend="python")
    assert np.allclose(Y[:, 0], (2 + 2 * np.asarray(t)) / 2, rtol=0, atol=1e-14)
    assert np.allclose(Y[:, 1], 10 + 20 * np.asarray(t), rtol=0, atol=1e-13)
