"""The one settings type (bgc.base.run_settings.RunSettings) and the one run function
(bgc.execute.runner): options laid over a scene's settings, a program started with only what
differs from its own, the parameters checked once, the C compiler's fallback said once, the
run policy of `bgc simulate`, a run's result."""
from __future__ import annotations

import io
from dataclasses import FrozenInstanceError
from pathlib import Path

import pytest

import bgc
from bgc.base import toolchain
from bgc.execute import runner
from bgc.base.run_settings import RunSettings, parameter_overrides

RLC = Path(__file__).parent.parent / "models" / "rlc.bg"
SCENE = RunSettings(0.0, 10.0, 0.01, "dopri5", 1e-6, 1e-9)


def test_options_are_laid_over_the_scene_and_only_changes_reach_the_program():
    s = SCENE.with_options(t_end=2.0, dt=None, solver="dopri5", params={"R": 2},
                           project_initial=False)
    assert (s.t_end, s.dt, s.solver, s.params) == (2.0, 0.01, "dopri5", (("R", 2),))
    assert s.options(SCENE) == {"t_end": 2.0, "params": {"R": 2}}
    assert s.args(SCENE) == ["--t-end", "2.0", "-p", "R=2.0"]
    assert SCENE.args(SCENE) == []  # the scene's own run: the program as compiled
    with pytest.raises(FrozenInstanceError):
        s.t_end = 3.0


def test_the_program_arguments_keep_their_order_and_flags():
    s = SCENE.with_options(rtol=1e-8, atol=1e-10, step=0.001, max_steps=7, solver="rk4",
                           allow_inconsistent=True)
    assert s.args(SCENE) == ["--solver", "rk4", "--rtol", "1e-08", "--atol", "1e-10",
                             "--step", "0.001", "--max-steps", "7", "--allow-inconsistent"]


def test_parameters_are_checked_once_with_one_message():
    assert parameter_overrides({"b": 1.0}, ["a", "b"]) == (("b", 1.0),)
    with pytest.raises(ValueError, match=r"unknown parameter 'c' \(parameters: a, b\)"):
        parameter_overrides({"c": 1.0}, ["a", "b"])
    with pytest.raises(ValueError, match="is not after the start time"):
        runner.settings_for(SCENE, ["a"], t_end=-1.0)


def test_without_a_c_compiler_the_python_backend_runs_and_says_so(monkeypatch):
    monkeypatch.setenv("CC", "no-such-compiler-bgc")
    assert runner.choose_backend("c") == ("python", runner.NO_C_COMPILER)
    assert runner.choose_backend("python") == ("python", None)


def test_the_run_policy_chooses_the_backend_and_the_interpreter_for_a_short_run(monkeypatch):
    monkeypatch.setattr(toolchain, "have_c_compiler", lambda cc=None: True)
    auto = runner.run_policy("auto")
    assert (auto.backend, auto.warning, auto.auto, auto.warm) == ("c", None, True, True)
    for backend in ("c", "vm", "python"):  # asked for: never chosen
        given = runner.run_policy(backend, warm=False)
        assert (given.backend, given.auto, given.warm) == (backend, False, False)
        assert not given.interpreted(SCENE, 1, 1)
    # SCENE: 0..10 every 0.01, 1001 rows; VM_WORK = 1e7 (rows x (operations + states))
    assert runner.VM_WORK == 10_000_000
    assert auto.interpreted(SCENE, 8_000, 990)  # 1001 x 8 990 = 9.0e6
    assert not auto.interpreted(SCENE, 10_000, 990)  # 1001 x 10 990 = 1.1e7
    shorter = runner.run_policy("auto", t_end=1.0)  # 101 rows
    assert shorter.interpreted(SCENE, 10_000, 990)
    finer = runner.run_policy("auto", dt=0.001)  # 10 001 rows
    assert not finer.interpreted(SCENE, 1_000, 10) and finer.interpreted(SCENE, 900, 10)
    monkeypatch.setattr(toolchain, "have_c_compiler", lambda cc=None: False)
    fallback = runner.run_policy("auto")  # without a C compiler: Python, nothing chosen
    assert (fallback.backend, fallback.warning, fallback.auto) == \
        ("python", runner.NO_C_COMPILER, False)
    assert not fallback.interpreted(SCENE, 1, 1)
    assert runner.run_policy("vm").backend == "python"


def test_a_run_streams_into_a_sink_or_returns_its_rows(tmp_path, monkeypatch):
    monkeypatch.setenv("BGC_CACHE_DIR", str(tmp_path))
    compiled = bgc.build(RLC, "step")
    program = runner.prepare(compiled, "python")
    settings = runner.settings_for(program.defaults, program.params, {"resistance": 1.0},
                                   t_end=0.5)
    captured = runner.run(program, settings, stats=True)
    assert captured.status == 0 and int(captured.stats["steps"]) > 0
    sink = io.StringIO()
    streamed = runner.run(program, settings, sink)
    assert streamed.status == 0 and streamed.csv is None
    assert sink.getvalue() == captured.csv
    refused = runner.run(program, SCENE.with_options(solver="rk4", dt=-1.0))
    assert refused.status == 2 and refused.message


def test_in_this_process_a_run_gives_arrays_and_raises_its_errors():
    compiled = bgc.build(RLC, "step")
    program = runner.prepare(compiled, "python", in_process=True)
    result = runner.run(program, runner.settings_for(program.defaults, program.params,
                                                     t_end=1.0))
    t, Y = bgc.api.arrays(result)
    assert t[-1] == 1.0 and Y.shape == (len(t), len(program.outputs))
    with pytest.raises(ValueError):
        runner.run(program, SCENE.with_options(dt=-1.0))


def test_a_compiled_model_runs_as_it_is_with_its_scene_settings():
    result = bgc.api.run(bgc.build(RLC, "step"), backend="python")
    t, Y = bgc.api.arrays(result)
    assert t[0] == 0.0 and t[-1] == 10.0 and result.status == 0
