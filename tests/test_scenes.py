"""Scenes: effects and outputs checked against the model (located errors with suggestions),
scenes made on the command line or through the API, pruning below the level of states (a
multiplier, one component of a vector, a block, an output's own sub-expressions), and the
reports (`bgc check --scene`, `bgc scenes`).  Values are checked against closed forms or
SciPy; models/gantry_crane.bg has its own file (test_scenes_crane.py)."""
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

import bgc
from bgc import ir
from bgc.api import Source
from bgc.base.processes import load_python_module
from bgc.cli import main
from bgc.codegen.emit import emit_python

ROOT = Path(__file__).resolve().parent.parent
PENDULUM = ROOT / "models" / "pendulum.bg"

# A pendulum (the paper's) beside an RC circuit that does not touch it.
PENDULUM_AND_RC = """model pr
parameter C1 = 0.5
parameter R1 = 2
vx : 1
vy : 1
mx : I(1)
my : I(1)
weight : Se(9.81) @gravity
tx : MTF(2*x)
ty : MTF(2*y)
rod : 0 constraint holonomic(init = -1) corrector pid(5, 5) @stabilisation
signal x = integral(vx.f, init = 0.6)
signal y = integral(vy.f, init = 0.8)
vx -> mx
vy -> my
weight -> vy
vx -> tx -> rod
vy -> ty -> rod
src : Se(1) @circuit
n : 1
r : R(R1)
c : C(C1)
src -> n
n -> r
n -> c
scene rc "the circuit alone" { outputs c.e; time 0 .. 2 every 0.5; solver rk4(step = 0.001) }
scene swing { effects gravity, stabilisation, circuit; outputs x, rod.lambda }
"""


def build(text, scene=None, **kw):
    return bgc.build(Source("inline.bg", text), scene, **kw)


def module(compiled):
    (text,) = emit_python(compiled.program).values()
    return load_python_module(text)


# ------------------------------------------------------------------ errors


def test_a_misspelt_effect_in_a_scene_is_a_located_error_with_a_suggestion():
    text = PENDULUM_AND_RC.replace("effects gravity, stabilisation, circuit",
                                   "effects gravity, stabilization, circuit")
    with pytest.raises(bgc.BgcModelError) as exc:
        build(text)  # every scene is checked, not only the one asked for
    message = str(exc.value)
    line = text.splitlines().index(next(s for s in text.splitlines() if "stabilization" in s))
    col = text.splitlines()[line].index("stabilization") + 1
    assert message.startswith(f"inline.bg:{line + 1}:{col}: error: unknown effect "
                              "'stabilization' in scene 'swing' (did you mean 'stabilisation'?)")
    assert "the model's effects: gravity, stabilisation, circuit" in message


@pytest.mark.parametrize("args, where, message", [
    (["--effects", "gravity,stablisation"], "--effects:1:9:",
     "unknown effect 'stablisation' in --effects (did you mean 'stabilisation'?)"),
    (["--outputs", "x, rod.lamda"], "--outputs:1:4:", "'rod' has no variable 'lamda' (it has: "),
    (["--outputs", "x, rood.lambda"], "--outputs:1:4:",
     "unknown element 'rood' in outputs (did you mean 'rod'?)"),
    (["--outputs", "xx"], "--outputs:1:1:", "unknown output 'xx' (did you mean 'x'?)"),
    (["--outputs", "x,,y"], "--outputs:1:3:", "syntax error: unexpected ','"),
    (["--scene", "swng"], "--scene:1:1:", "no scene named 'swng' in model 'pendulum' (did you "
                                          "mean 'swing'?)"),
])
def test_command_line_scene_errors_are_located_and_write_nothing(tmp_path, args, where, message):
    """Errors in an option's value: located in its text, and usage errors (exit 2)."""
    out = tmp_path / "out.csv"
    result = CliRunner().invoke(main, ["simulate", str(PENDULUM), "--backend", "python",
                                       "-o", str(out)] + args)
    assert result.exit_code == 2, result.output
    assert result.stderr.startswith(where)
    assert message in result.stderr
    assert "\n   1 | " in result.stderr and "^" in result.stderr  # the option's text, a caret
    assert "Traceback" not in result.stderr and not out.exists()


def test_an_output_that_reads_what_the_effects_leave_out_says_why():
    with pytest.raises(bgc.BgcModelError) as exc:
        bgc.build(ROOT / "models" / "gantry_crane.bg", "drive", outputs="ind.f, x")
    assert str(exc.value).startswith("outputs=:1:8: error: output 'x' is left out by this "
                                     "scene's effects: 'x' is left out: reads 'vx', left out")


def test_a_variable_nothing_sets_is_a_located_error_not_a_crash():
    text = ("model r\nv : 1\nw : 1\nmass : I(1) @moving\npush : Se(1) @moving\n"
            "signal x = integral(w.f, init = 0)\npush -> v -> mass\n"
            "scene s { effects none; outputs x }\n")
    with pytest.raises(bgc.BgcModelError) as exc:
        build(text, "s")
    assert str(exc.value).startswith("inline.bg:6:1: error: 'w.f' is not determined in this "
                                     "scene")


# ------------------------------------------------------------------ ad-hoc scenes


def test_an_adhoc_scene_compiles_to_the_same_bytes_as_the_scene_written_out():
    written = PENDULUM.read_text() + (
        "scene same { effects gravity; outputs x, rod.lambda; time 0 .. 10 every 0.01\n"
        "  solver dopri5(rtol = 1e-10, atol = 1e-12) }\n")
    a = bgc.compile(Source("p.bg", written), "python", scene="same")
    b = bgc.compile(PENDULUM, "python", scene="swing", outputs="x, rod.lambda",
                    effects=["gravity"])
    assert list(a.values()) == list(b.values())
    c = bgc.build(PENDULUM, "swing", outputs=["x", "rod.lambda"], effects="gravity",
                  program=False)
    assert c.settings.given == ("effects", "outputs")
    assert c.reduced.constraints[0].corrector == "none"  # stabilisation left out


def test_adhoc_scene_on_the_command_line(tmp_path):
    out = tmp_path / "out.csv"
    result = CliRunner().invoke(main, ["simulate", str(PENDULUM), "--scene", "swing",
                                       "--outputs", "y,x", "--effects", "none", "--backend",
                                       "python", "--t-end", "0.5", "-o", str(out)])
    assert result.exit_code == 0, result.stderr
    rows = out.read_text().splitlines()
    assert rows[0] == "t,y,x"
    # no gravity: the mass at rest stays where it is (theta0 = 0.5, l = 1)
    last = [float(v) for v in rows[-1].split(",")]
    assert last[0] == 0.5
    assert abs(last[1] - np.cos(0.5)) < 1e-12 and abs(last[2] - np.sin(0.5)) < 1e-12
    code = CliRunner().invoke(main, ["compile", str(PENDULUM), "--target", "python",
                                     "--outputs", "x", "--effects", "gravity"])
    assert code.exit_code == 0 and "OUTPUTS = ['x']" in code.output.replace('"', "'")


# ------------------------------------------------------------------ pruning


def test_a_multiplier_no_output_needs_is_not_computed():
    c = build(PENDULUM_AND_RC, "rc")
    m = module(c)
    assert list(m.STATES) == ["c.q"] and list(m.OUTPUTS) == ["c.e"]
    assert c.program.blocks == () and c.program.constraints == ()
    (text,) = emit_python(c.program).values()
    assert "9.81" not in text  # nothing of the pendulum
    t, Y = m.simulate()
    tau = 2 * 0.5  # R1 C1
    assert np.max(np.abs(Y[:, 0] - (1 - np.exp(-t / tau)))) < 1e-12  # rk4, h = 1e-3: h^4/tau^4
    report = bgc.check(Source("inline.bg", PENDULUM_AND_RC), "rc")
    assert "pruned, no output needs them (4): mx.p, my.p, x, y" in report
    assert "pruned, no output needs them (1): rod.lambda" in report
    assert "rod: holonomic (declared), corrector pid(5, 5); pruned" in report


def test_one_component_of_a_vector_is_all_that_is_integrated():
    from scipy.linalg import expm

    c = bgc.build(ROOT / "models" / "twin_motors.bg", "run", outputs="rotor.f[1], ind.f[1]")
    m = module(c)
    assert list(m.STATES) == ["ind.p[1]", "rotor.p[1]"]
    assert list(m.OUTPUTS) == ["rotor.f[1]", "ind.f[1]"]
    full = bgc.build(ROOT / "models" / "twin_motors.bg", "run")
    assert len(full.program.states) == 6
    assert sum(ir.count_ops(c.program, ("rhs",)).values()) * 2 == \
        sum(ir.count_ops(full.program, ("rhs",)).values())  # the two motors are alike
    # motor 2 (models/twin_motors.bg): L di/dt = V - R i - k w, J dw/dt = k i - b w - tau
    V, R, L, k, J, b, tau = 24.0, 1.0, 0.2, 0.5, 0.02, 0.05, 0.2
    A = np.array([[-R / L, -k / L], [k / J, -b / J]])
    u = np.array([V / L, -tau / J])
    x_inf = np.linalg.solve(A, -u)
    t, Y = m.simulate(t_end=1.0)
    exact = np.array([x_inf - expm(A * ti) @ x_inf for ti in t])  # from rest
    assert np.max(np.abs(Y[:, 0] - exact[:, 1])) < 1e-7 * np.max(np.abs(exact[:, 1]))
    assert np.max(np.abs(Y[:, 1] - exact[:, 0])) < 1e-7 * np.max(np.abs(exact[:, 0]))


TWO_DIODES = """model dd
parameter Is = 1e-12
parameter Vt = 0.02585
s1 : Se(5)
l1 : 1
r1 : R(100)
d1 : R(f = Is*(exp(e/Vt) - 1))
c1 : C(1e-4)
s1 -> l1
l1 -> r1
l1 -> d1
l1 -> c1
s2 : MSe(2*c1.e)
l2 : 1
r2 : R(50)
d2 : R(f = Is*(exp(e/Vt) - 1))
c2 : C(1e-4)
s2 -> l2
l2 -> r2
l2 -> d2
l2 -> c2
"""


def test_a_newton_block_the_outputs_do_not_need_is_not_solved():
    first = build(TWO_DIODES, outputs="c1.e")
    both = build(TWO_DIODES, outputs="c2.e")
    assert [b.unknowns for b in first.reduced.blocks] == [("e[l1->d1]",)]
    assert len(both.reduced.blocks) == 2  # the second circuit reads the first
    assert len(first.program.blocks) == 1 and len(both.program.blocks) == 2
    assert [s for s in first.program.function("rhs").body if isinstance(s, ir.Newton)]


def test_outputs_compute_only_their_own_sub_expressions():
    just_x = bgc.build(PENDULUM, "swing", outputs="x")
    with_lambda = bgc.build(PENDULUM, "swing", outputs="x, rod.lambda")
    assert just_x.program.function("rhs") == with_lambda.program.function("rhs")
    assert sum(ir.count_ops(just_x.program, ("outputs",)).values()) == 0
    assert sum(ir.count_ops(with_lambda.program, ("outputs",)).values()) > 10


# ------------------------------------------------------------------ reports


def test_check_reports_what_a_scene_leaves_out_and_prunes():
    c = build(PENDULUM_AND_RC, "swing", effects="gravity, circuit")
    sm = bgc.api.summary(c)
    assert sm.effects_in == ("gravity", "circuit") and sm.effects_out == ("stabilisation",)
    assert sm.states_kept == ("mx.p", "my.p", "x", "y") and sm.states_pruned == ("c.q",)
    assert [b.unknowns for b in sm.blocks_kept] == [("rod.lambda",)]
    full_rhs = sum(sm.ops["full", "rhs"].values())
    assert 0 < sum(sm.ops["scene", "rhs"].values()) < full_rhs
    text = bgc.check(Source("inline.bg", PENDULUM_AND_RC), "swing", effects="gravity, circuit")
    assert "correctors set to none with their effects: rod (@stabilisation)" in text
    assert "states: 4 of 5 integrated" in text
    result = CliRunner().invoke(main, ["check", str(PENDULUM), "--scene", "unstabilised"])
    assert result.exit_code == 0 and "effects in: gravity; left out: stabilisation" \
        in result.output


def test_emptied_junctions_and_the_signals_reading_them_go_with_the_effects():
    c = bgc.build(ROOT / "models" / "gantry_crane.bg", "drive", program=False)
    left = dict(c.settings.left_out)
    assert left["rod"] == "its bonds are all left out"
    assert left["x"] == "reads 'vx', left out"
    assert "rod" not in c.graph.by_name and "x" not in {s.name for s in c.graph.signals}


def test_scenes_command_lists_docs_effects_outputs_and_settings():
    result = CliRunner().invoke(main, ["scenes", str(ROOT / "models" / "dc_motor.bg")])
    assert result.exit_code == 0
    lines = result.output.splitlines()
    assert lines[0] == "model dc_motor: 3 scenes; effects: loading"
    i = lines.index("scene noload: start-up without the load torque")
    assert lines[i + 1:i + 5] == ["  effects: none (left out: loading)",
                                  "  outputs: ind.f, rotor.f, angle",
                                  "  time 0 .. 5 every 0.01",
                                  "  solver dopri5(rtol = 1e-10, atol = 1e-12)"]
    assert "  set V = 24" in lines
