"""The references of benchmarks/solvers.py and the models it runs, no timing: the RC pair's
closed form against expm and SciPy, the right sides the baselines use against the generated
modules', and models/rc_pair.bg and models/van_der_pol.bg simulated by bgc (Python backend,
rodas4) against the closed form and SciPy's Radau.  And benchmarks/scenes.py's counts."""
import importlib.util
import math
import os
import shutil
import sys
from pathlib import Path

import numpy as np
import pytest

import bgc
from bgc.base.processes import load_python_module

pytest.importorskip("scipy")
ROOT = Path(__file__).resolve().parent.parent


def _benchmark(name="solvers"):
    spec = importlib.util.spec_from_file_location(f"bench_{name}",
                                                  ROOT / "benchmarks" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # for its dataclasses
    spec.loader.exec_module(module)
    return module


BENCH = _benchmark()
TIMES = np.linspace(0.0, 5.0, 101)


def _module(model, scene):
    (text,) = bgc.compile(ROOT / "models" / model, target="python", scene=scene).values()
    return load_python_module(text)


def _scaled_error(Y, ref):
    return np.max(np.abs(Y - ref), axis=0) / np.maximum(1.0, np.max(np.abs(ref), axis=0))


def test_rc_closed_form_agrees_with_expm_and_radau():
    from scipy.integrate import solve_ivp
    from scipy.linalg import expm

    exact = BENCH.rc_exact(TIMES)
    A, b = BENCH.rc_matrix()
    v_inf = np.linalg.solve(A, -b)
    by_expm = np.array([v_inf - expm(A * t) @ v_inf for t in TIMES])
    assert np.all(_scaled_error(by_expm, exact) < 1e-10)  # measured: 5e-12, expm's own error
    f, jac, y0 = BENCH.rc_system()
    sol = solve_ivp(f, (0.0, 5.0), y0, method="Radau", jac=jac, t_eval=TIMES, rtol=1e-12,
                    atol=1e-14)
    assert sol.success and np.all(_scaled_error(sol.y.T, exact) < 1e-9)
    assert exact[1, 0] > 0.999 and 0.99 < exact[-1, 1] < 0.9933  # fast, then slow


@pytest.mark.parametrize("model, scene, system", [
    ("rc_pair.bg", "step", lambda: BENCH.rc_system()),
    ("van_der_pol.bg", "period", lambda: BENCH.vdp_system(1e3))])
def test_baselines_right_sides_are_the_models(model, scene, system):
    module = _module(model, scene)
    f, jac, y0 = system()
    p = np.array(list(module.PARAMETERS.values()), dtype=float)
    for x in np.random.default_rng(3).uniform(-2.0, 2.0, (5, 2)):
        np.testing.assert_allclose(module.rhs(0.0, x, p), f(0.0, x), rtol=1e-12, atol=1e-9)
        np.testing.assert_allclose(module.jacobian(0.0, x, p), jac(0.0, x), rtol=1e-12,
                                   atol=1e-9)
    t, Y = module.simulate(t_end=0.0)
    np.testing.assert_allclose(Y[0], y0, rtol=1e-15)


def test_rc_pair_model_matches_the_closed_form():
    t, Y = _module("rc_pair.bg", "step").simulate(solver="rodas4", rtol=1e-6, atol=1e-9)
    assert len(t) == 101 and t[-1] == 5.0
    assert np.all(_scaled_error(Y, BENCH.rc_exact(t)) < 1e-5)


def test_van_der_pol_model_matches_radau():
    from scipy.integrate import solve_ivp

    t, Y = _module("van_der_pol.bg", "period").simulate(solver="rodas4", rtol=1e-7, atol=1e-10)
    f, jac, y0 = BENCH.vdp_system(1e3)
    ref = solve_ivp(f, (0.0, 2.0), y0, method="Radau", jac=jac, t_eval=t, rtol=1e-9, atol=1e-9)
    assert ref.success and ref.y[0].min() < -1.9  # through the jump
    assert np.all(_scaled_error(Y, ref.y.T) < 1e-5), _scaled_error(Y, ref.y.T)


def test_scenes_benchmark_counts_the_generated_programs():
    """benchmarks/scenes.py's static columns, no timing: its states are the generated modules'
    STATES, and swing (same effects as everything) only prunes."""
    scenes = _benchmark("scenes")
    full, everything, swing = scenes.describe_all(ROOT / "models" / "gantry_crane.bg",
                                                  ["everything", "swing"])
    for row in (everything, swing):
        assert row.states == len(_module("gantry_crane.bg", row.scene).STATES)
    assert (full.physics, everything.physics, swing.physics) == (
        "all effects", "-1 effect", "= everything")
    assert everything.effects_out == swing.effects_out == ("given_drive",)
    assert (swing.states, swing.pruned, swing.out) == (everything.states - 4, 4, 0)
    assert 0 < swing.rhs_ops < everything.rhs_ops and 0 < swing.c_bytes < everything.c_bytes
    assert full.multipliers == swing.multipliers == 1 and full.out_ops == 0


def test_before_after_lists_its_cases(capsys):
    """benchmarks/before_after.py's argument parsing and case list, nothing built or timed."""
    before_after = _benchmark("before_after")
    args = before_after.parse(["--before", "HEAD", "--quick"])
    assert (args.after, args.repeats) == ("worktree", 2)
    before_after.main(["--before", "HEAD", "--quick", "--list"])
    listed = capsys.readouterr().out.splitlines()
    assert len(listed) == 6 and listed[0].startswith("pendulum dopri5 c: model models/pendulum.bg")
    full = before_after.cases(quick=False)
    assert {c.backend for c in full} == {"c", "python"} and len(full) == 18


@pytest.mark.skipif(not (ROOT / ".git").exists(), reason="not a git checkout")
def test_before_after_removes_its_worktree_on_failure(monkeypatch):
    """The temporary worktree of --before goes even when the measurement fails."""
    before_after = _benchmark("before_after")
    seen = {}

    def fail(args, chosen, trees, work, cc):
        seen.update(trees)
        assert (trees["before"] / "bgc" / "__init__.py").is_file()
        raise RuntimeError("stop")

    monkeypatch.setattr(before_after, "run", fail)
    with pytest.raises(RuntimeError, match="stop"):
        before_after.main(["--before", "HEAD", "--quick"])
    assert seen["after"] == ROOT and not seen["before"].exists()
    assert str(seen["before"]) not in before_after.git("worktree", "list")


def test_events_closed_forms():
    """benchmarks/events.py's references: the PWM current against solve_ivp piece by piece at
    tight tolerance, the ball's parabolas meeting the floor at the impacts."""
    from scipy.integrate import solve_ivp

    events = _benchmark("events")
    t_end = 0.01
    edges = events.pwm_edges(t_end)
    assert len(edges) == 19 and edges[0] == 0.3 * 0.001 and edges[1] == 0.001
    grid = np.linspace(0.0, t_end, 41)
    ref, exact = events.pwm_exact(grid, t_end)
    y, t, ys = [0.0], 0.0, []
    for k, stop in enumerate([*edges, t_end]):
        f = events.pwm_rhs(1.0 if k == 0 else events.pwm_input(k - 1))
        sol = solve_ivp(f, (t, stop), y, method="DOP853", rtol=1e-13, atol=1e-16,
                        dense_output=True)
        inside = grid[(grid >= t) & (grid < stop)]
        ys += list(sol.sol(inside)[0]) if len(inside) else []
        t, y = stop, [sol.y[0, -1]]
    ys.append(y[0])
    np.testing.assert_allclose(np.array(ys), ref[:, 0], rtol=1e-10, atol=1e-16)
    impacts = events.ball_impacts(4.0)
    assert len(impacts) == 19 and abs(impacts[0] - math.sqrt(2 / 9.81)) < 1e-15
    around = events.ball_exact(np.concatenate([impacts - 1e-9, impacts + 1e-9]), 4.0)[0]
    assert np.all(np.abs(around[:, 0]) < 1e-8)  # x = 0 on both sides of every impact
    before, after = around[:19, 1], around[19:, 1]
    np.testing.assert_allclose(after, -0.8 * before, rtol=1e-7)


@pytest.mark.skipif(not shutil.which(os.environ.get("CC", "cc").split()[0]),
                    reason="no C compiler")
def test_events_quick_run(capsys):
    """benchmarks/events.py --quick: every method has its rows or says why not (scikit-sundae
    or SUNDIALS' C library missing), bgc's rows match the closed forms, no timing checked."""
    events = _benchmark("events")
    assert events.main(["--quick"]) == 0
    out = capsys.readouterr().out
    for problem in events.problems(quick=True):
        section = out.split(f"== {problem.key}:")[1].split("\n==")[0]
        rows = {}
        for line in section.splitlines():
            for method in problem.rtols:
                if line.startswith(method + " "):
                    rows.setdefault(method, []).append(line[len(method):].split())
        for method in problem.rtols:
            assert method in rows or f"not run: {method}: " in section, method
        for cells in rows["bgc C"]:
            t_error, error = float(cells[7]), float(cells[8])
            assert error < 1e-6 and t_error < 1e-9
            assert t_error == 0.0 or problem.key == "ball"  # time events: stepped onto
        for method, found in rows.items():
            assert all(float(c[8]) < 1e-2 for c in found), (method, found)
    assert out.count("goal: pwm at equal error") == 6


def test_fit_baseline_is_the_model():
    """benchmarks/fit.py's SciPy baseline integrates the DC motor's equations written by hand:
    they are models/dc_motor.bg's (bgc's run at the data's parameters, to 1e-8), so both
    sides of its table fit the same model."""
    fit = _benchmark("fit")
    t = np.linspace(0.0, 0.5, 51)
    by_hand = fit.motor_ivp([fit.TRUE[n] for n in fit.NAMES], t)
    _, Y, _ = bgc.simulate(ROOT / "models" / "dc_motor.bg", "run", backend="python",
                           outputs="ind.f, rotor.f", params=fit.TRUE, t_end=0.5, dt=0.01)
    assert np.max(np.abs(Y - by_hand)) < 1e-8 * max(1.0, np.max(np.abs(Y)))


def test_stiff_scale_closed_form_agrees_with_expm():
    """benchmarks/stiff_scale.py's closed form of the thermal grid (its modes, a Kronecker sum)
    against expm of the grid's equations written out here, and the families' numpy right side
    against them."""
    from scipy.linalg import expm

    grid = _benchmark("stiff_scale")
    n, N = 4, 16
    A, b = np.zeros((N, N)), np.zeros(N)
    for i in range(n):
        for j in range(n):
            k = i * n + j
            for a, c in ((i, j - 1), (i, j + 1), (i - 1, j), (i + 1, j)):
                if 0 <= a < n and 0 <= c < n:
                    A[k, a * n + c] += 1.0  # r = 1, c = 1
                    A[k, k] -= 1.0
            if j == n - 1:
                A[k, k] -= 0.5  # rb = 2
    b[0] = 1.0  # q_in
    T0 = 1.0 + np.sin(np.arange(1, N + 1))
    steady = np.linalg.solve(A, -b)
    for t in (0.0, 0.5, 50.0):
        want = steady + expm(A * t) @ (T0 - steady)
        assert np.allclose(grid.exact(n, t), want, rtol=0, atol=1e-12)
    families = sys.modules["families"]
    assert np.allclose(families.thermal_grid_rhs(n, T0), A @ T0 + b, rtol=0, atol=1e-12)


def test_hbridge_reference_is_bgcs_edges_and_the_motors_exact_solution():
    """benchmarks/hbridge.py's reference, no timing: its switching instants are those of the
    runtime's square_next, chained from t = 0, and its exact march agrees with SciPy's DOP853
    at tight tolerance, restarted at each of those instants (the current stays positive after
    the start, so the diodes in the dead time apply -V)."""
    from scipy.integrate import solve_ivp
    from helpers import pyruntime

    rt = pyruntime()
    hb = _benchmark("hbridge")
    p, t_end = hb.HBRIDGE, 2e-4
    chained = []
    for period, duty, t0 in hb.waves(p):
        t = 0.0
        while (t := rt._square_next(t, period, duty, t0)) < t_end:
            chained.append(t)
    assert sorted(chained) == [e for e, _, _ in hb.edges(p, t_end)]
    times = np.linspace(0.0, t_end, 201)
    ref, events = hb.exact(p, t_end, times)
    R, L, k, J, b, V = (p[n] for n in ("R", "L", "k", "J", "b", "V"))
    x, t, Y = np.zeros(2), 0.0, np.empty_like(ref)
    bounds = sorted(set(chained)) + [t_end]
    for n, end in enumerate(bounds):
        phase = (t * p["f"]) % 1.0  # +V for s1 and s4, -V in the dead times and for s2 and s3
        v = V if phase < p["duty"] - 1e-9 or phase > 1 - 1e-9 else -V
        sol = solve_ivp(lambda s, y: [(v - R * y[0] - k * y[1]) / L, (k * y[0] - b * y[1]) / J],
                        (t, end), x, method="DOP853", rtol=1e-13, atol=1e-15, dense_output=True)
        inside = (times >= t) & (times <= end)
        Y[inside] = sol.sol(times[inside]).T
        x, t = sol.y[:, -1], end
    assert len(events) == len(chained) and ref[1:, 0].min() > 0.0
    assert np.all(np.abs(Y - ref).max(axis=0) < 1e-10 * np.abs(ref).max(axis=0))
