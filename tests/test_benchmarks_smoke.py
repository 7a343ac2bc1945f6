"""The references of benchmarks/solvers.py and the models it runs, no timing: the RC pair's
closed form against expm and SciPy, the right sides the baselines use against the generated
modules', and models/rc_pair.bg and models/van_der_pol.bg simulated by bgc (Python backend,
rodas4) against the closed form and SciPy's Radau.  And benchmarks/scenes.py's counts."""
import importlib.util
import sys
from pathlib import Path

import numpy as np
import pytest

import bgc
from bgc.backends import load_python_module

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
