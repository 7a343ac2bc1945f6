"""Components, `constant`, `for` and `if` (docs/language.md, "Components"): each feature against
its twin written out flat by hand (the same equations, simplify(a - b) == 0, and the same
generated code but for names), a component model against SciPy, and the limits."""
import re
import time
from pathlib import Path

import numpy as np
import pytest
import sympy as sp
from click.testing import CliRunner

import bgc
from bgc.base import toolchain
from bgc.api import Source
from bgc.front.ast import ComponentDecl, PortDecl
from bgc.cli import main
from bgc.codegen.emit import c_param_fields, emit_c, emit_python
from bgc.front.graph import var
from bgc.front.parser import parse
from bgc.middle.reduce import explicit_forms
from bgc.base.resources import MAX_INSTANCE_DEPTH


ROOT = Path(__file__).resolve().parent.parent
COMPONENT_CHAIN = ROOT / "models" / "pendulum_chain.bg"
FLAT_CHAIN = ROOT / "tests" / "models" / "pendulum_chain_flat.bg"


def build(text, scene=None, consts=(), **kw):
    return bgc.build(Source("inline.bg", text, tuple(consts)), scene, **kw)


def error_of(text, consts=()):
    with pytest.raises(bgc.BgcModelError) as info:
        build(text, consts=consts)
    return str(info.value)


def rates(compiled):
    r = compiled.reduced
    forms = explicit_forms(r, r.rates)
    return [forms[d] for d in r.rates]


def _renaming(a, b):
    """Symbols of build a -> build b, by position: parameters, states, outputs."""
    ra, rb = a.reduced, b.reduced
    pa, pb = [p.name for p in a.program.params], [p.name for p in b.program.params]
    sa, sb = [s.name for s in ra.states], [s.name for s in rb.states]
    assert len(pa) == len(pb) and len(sa) == len(sb)
    return {var(x): var(y) for x, y in zip(pa + sa, pb + sb)}


def _renamed_code(text: str, a, b) -> str:
    """a's generated code with b's names: in strings, comments and parameter fields."""
    pa, pb = [p.name for p in a.program.params], [p.name for p in b.program.params]
    sa, sb = [s.name for s in a.reduced.states], [s.name for s in b.reduced.states]
    oa, ob = list(a.program.outputs), list(b.program.outputs)
    ea, eb = [e.name for e in a.graph.elements], [e.name for e in b.graph.elements]
    pairs = sorted(zip(pa + sa + oa + ea, pb + sb + ob + eb), key=lambda xy: -len(xy[0]))

    def rename(m):
        inside = m.group(0)
        for x, y in pairs:
            inside = re.sub(r"(?<![\w.\[])" + re.escape(x) + r"(?![\w\[])", y, inside)
        return inside
    text = re.sub(r'"(?:\\.|[^"\\\n])*"|/\*.*?\*/|#[^\n]*|//[^\n]*', rename, text,
                  flags=re.S)
    for x, y in zip(c_param_fields(tuple(pa)), c_param_fields(tuple(pb))):
        text = re.sub(r"\b" + x + r"\b", y, text)
    return text


def assert_twins(component_text, flat_text, scene=None):
    """The component model and its hand-flattened twin: the same rates and outputs
    (symbolically, after renaming), the same generated C and Python but for names."""
    a, b = build(component_text, scene), build(flat_text, scene)
    names = _renaming(a, b)
    for x, y in zip(rates(a), rates(b)):
        assert sp.simplify(x.xreplace(names) - y) == 0, (x, y)
    assert len(a.reduced.outputs) == len(b.reduced.outputs)
    oa = explicit_forms(a.reduced, [o.expr for o in a.reduced.outputs])
    ob = explicit_forms(b.reduced, [o.expr for o in b.reduced.outputs])
    for x, y in zip(a.reduced.outputs, b.reduced.outputs):
        assert sp.simplify(oa[x.expr].xreplace(names) - ob[y.expr]) == 0, (x, y)
    for emit in (emit_c, emit_python):
        (ca,), (cb,) = emit(a.program).values(), emit(b.program).values()
        assert _renamed_code(ca, a, b) == cb
    return a, b


# ------------------------------------------------------------------ twins
LADDER = """model ladder "three RC sections"
parameter V = 2.0
parameter r0 = 1.5
component section(r = 1.0 unit "ohm", c = 0.5 unit "F") {
  port a : electrical unit "V"
  port b : electrical
  node : 0
  link : 1
  res : R(r)
  cap : C(c)
  a -> link
  link -> res
  link -> node
  node -> cap
  node -> b
}
src : Se(V)
for i in 1..3 {
  s[i] : section(r = r0*i)
}
src -> s[1].a
for i in 2..3 { s[i-1].b -> s[i].a }
load : R(4)
s[3].b -> load
scene run { outputs s[1].cap.q, s[3].cap.e, s[2].res.f; time 0 .. 4 every 0.25 }
"""

LADDER_FLAT = """model ladder "three RC sections"
parameter V = 2.0
parameter r0 = 1.5
src : Se(V)
parameter s1_r = r0*1
parameter s1_c = 0.5
s1_node : 0
s1_link : 1
s1_res : R(s1_r)
s1_cap : C(s1_c)
s1_link -> s1_res
s1_link -> s1_node
s1_node -> s1_cap
parameter s2_r = r0*2
parameter s2_c = 0.5
s2_node : 0
s2_link : 1
s2_res : R(s2_r)
s2_cap : C(s2_c)
s2_link -> s2_res
s2_link -> s2_node
s2_node -> s2_cap
parameter s3_r = r0*3
parameter s3_c = 0.5
s3_node : 0
s3_link : 1
s3_res : R(s3_r)
s3_cap : C(s3_c)
s3_link -> s3_res
s3_link -> s3_node
s3_node -> s3_cap
src -> s1_link
s1_node -> s2_link
s2_node -> s3_link
load : R(4)
s3_node -> load
scene run { outputs s1_cap.q, s3_cap.e, s2_res.f; time 0 .. 4 every 0.25 }
"""


def test_ports_for_and_parameters_against_the_flat_twin():
    a, _ = assert_twins(LADDER, LADDER_FLAT, "run")
    assert [p.name for p in a.program.params] == ["V", "r0", "s[1].r", "s[1].c", "s[2].r",
                                                  "s[2].c", "s[3].r", "s[3].c"]
    assert list(a.program.outputs) == ["s[1].cap.q", "s[3].cap.e", "s[2].res.f"]
    units = {p.name: p.unit for p in a.graph.parameters}
    assert units["s[2].r"] == "ohm" and units["s[3].c"] == "F" and units["V"] is None
    assert [(p.name, p.domain) for p in a.graph.ports][:3] == [
        ("s[1].a", "electrical"), ("s[1].b", "electrical"), ("s[2].a", "electrical")]


def test_rc_ladder_against_scipy():
    from scipy.integrate import solve_ivp
    t, Y, names = bgc.simulate(Source("ladder.bg", LADDER), "run", backend="python",
                               rtol=1e-10, atol=1e-12)
    V, r0, c, rl = 2.0, 1.5, 0.5, 4.0
    r = [r0, 2 * r0, 3 * r0]

    def f(_, q):
        e = q / c
        i1 = (V - e[0]) / r[0]
        i2 = (e[0] - e[1]) / r[1]
        i3 = (e[1] - e[2]) / r[2]
        return [i1 - i2, i2 - i3, i3 - e[2] / rl]

    ref = solve_ivp(f, (0, 4), [0, 0, 0], t_eval=t, rtol=1e-12, atol=1e-14, method="LSODA")
    q = ref.y
    expected = np.column_stack([q[0], q[2] / c, (q[0] - q[1]) / c / r[1]])
    assert names == ["s[1].cap.q", "s[3].cap.e", "s[2].res.f"]
    np.testing.assert_allclose(Y, expected, rtol=1e-7, atol=1e-9)


PORT_LIST = """model port_list
component drive(m = 1) {
  port a : electrical "the supply's side", b[2] : translational unit "N"
  s : Se(3)
  masses : I[2](m)
  s -> a
  b -> masses
}
x : drive(m = 2)
r : R(1.5)
x.a -> r
g : Se[2]([1, 2])
g -> x.b
scene run { outputs x.masses.f, r.f; time 0 .. 1 every 0.25 }
"""


def test_a_list_of_ports_in_one_declaration():
    """`port a : D "doc", b[2] : D2 unit "U"`: two ports, each with its size, domain, unit and
    doc; the masses pushed by 1 and 2 from rest go at t/m and 2 t/m, the resistor takes
    3/1.5."""
    a = build(PORT_LIST, "run")
    assert [(p.name, p.dim, p.domain, p.unit) for p in a.graph.ports] == [
        ("x.a", 1, "electrical", None), ("x.b", 2, "translational", "N")]
    comp = next(d for d in parse(PORT_LIST).decls if isinstance(d, ComponentDecl))
    assert [d.doc for d in comp.body if isinstance(d, PortDecl)] == ["the supply's side", None]
    t, Y, names = bgc.simulate(Source("port_list.bg", PORT_LIST), "run", backend="python",
                               rtol=1e-10, atol=1e-12)
    assert names == ["x.masses.f[0]", "x.masses.f[1]", "r.f"]
    np.testing.assert_allclose(Y, np.column_stack([t / 2, t, np.full_like(t, 2.0)]),
                               rtol=0, atol=1e-12)


NESTED = """model nested
component spring(k = 1) {
  port a
  c : C(1/k)
  a -> c
}
component mount(k = 1, m = 2) {
  port a
  j : 1
  mass : I(m)
  inner : spring(k = 2*k)
  a -> j
  j -> mass
  j -> inner.a
}
f : Se(1)
left : mount(k = 3)
f -> left.a
"""

NESTED_FLAT = """model nested
f : Se(1)
parameter left_k = 3
parameter left_m = 2
left_j : 1
left_mass : I(left_m)
parameter left_inner_k = 2*left_k
left_inner_c : C(1/left_inner_k)
left_j -> left_mass
left_j -> left_inner_c
f -> left_j
"""


def test_nesting_against_the_flat_twin():
    a, _ = assert_twins(NESTED, NESTED_FLAT)
    assert [s.name for s in a.reduced.states] == ["left.mass.p", "left.inner.c.q"]


MODULATED = """model modulated
signal u = 0.5 + 0.25*sin(t)
component valve(opening = 1, r0 = 2) {
  port a
  res : R(r0/opening)
  a -> res
}
src : Se(1)
j : 0
tank : C(3)
src -> j
j -> tank
v : valve(opening = u)
j -> v.a
scene run { outputs tank.q, v.res.f; time 0 .. 1 every 0.5 }
"""

MODULATED_FLAT = """model modulated
signal u = 0.5 + 0.25*sin(t)
src : Se(1)
j : 0
tank : C(3)
signal v_opening = u
parameter v_r0 = 2
v_res : R(v_r0/v_opening)
src -> j
j -> tank
j -> v_res
scene run { outputs tank.q, v_res.f; time 0 .. 1 every 0.5 }
"""


def test_an_argument_that_reads_a_signal_modulates():
    a, _ = assert_twins(MODULATED, MODULATED_FLAT, "run")
    assert "v.opening" in [s.name for s in a.graph.signals]
    assert "v.opening" not in [p.name for p in a.program.params]


VECTOR = """model vector
component body(m = 1) {
  port v[2]
  mass : I[2](m)
  v -> mass
}
g : Se[2]([0, -9.81])
j : 1[2]
g -> j
b : body(m = 2)
j -> b.v
"""

VECTOR_FLAT = """model vector
g : Se[2]([0, -9.81])
j : 1[2]
parameter b_m = 2
b_mass : I[2](b_m)
g -> j
j -> b_mass
"""


def test_a_vector_port_against_the_flat_twin():
    a, _ = assert_twins(VECTOR, VECTOR_FLAT)
    # a multiport's parts are named alike inside an instance and at the top: b.mass.p[0]
    assert [s.name for s in a.reduced.states] == ["b.mass.p[0]", "b.mass.p[1]"]


# A vector element variable of an element inside an instance, indexed by its path wherever an
# expression names a variable: in the component (mass.p[0]), in a law, a signal, a component's
# argument, a condition and a reinit target, through `for` (link[i].mass.p[0]) and constant
# index expressions (p[N-2]); the same of a top-level multiport (m2.p[0]) and of a `for`'s
# indexed element (c[1].q).
CHAIN = """model chain
constant N = 3
component rod_and_mass(m = 1, k = 2) {
  port a[2]
  mass : I[2](m)
  spring : C[2](1/k)
  node : 1[2]
  a -> node
  node -> mass
  node -> spring
  signal ke = mass.p[0]^2/(2*m) + mass.p[1]^2/(2*m)
  when mass.p[1] > 0.5 { reinit mass.p[1] = 0 }
}
component push(v = 0) {
  port a
  s : Se(v)
  s -> a
}
g : Se[2]([1, 2])
j : 0[2]
g -> j
for i in 1..N {
  link[i] : rod_and_mass(m = i)
  j -> link[i].a
  c[i] : C(i)
  h[i] : 0
  when link[i].mass.p[0] > 0.3*i { reinit link[i].mass.p[0] = -link[i].mass.p[0] }
}
m2 : I[2](2)
j -> m2
pr : push(v = link[1].mass.p[0] + m2.p[N-2])
pr.a -> h[1]
h[1] -> c[1]
d : R(e = 3*f + link[2].mass.p[1])
src : Sf(link[N].spring.q[N-2])
src -> h[2]
h[2] -> c[2]
h[2] -> d
f3 : Sf(c[1].q)
f3 -> h[3]
h[3] -> c[3]
signal en = link[1].ke + link[2].mass.p[0]^2/4 + link[N].mass.p[N-2]^2/6
when en > 1 and m2.p[0] > 0 { reinit m2.p[1] = 0; reinit c[2].q = c[1].q }
scene s { outputs en, link[2].mass.p[1], link[N].spring.q[N-3], m2.p[0], c[3].q
          time 0 .. 1 every 0.25 }
"""

CHAIN_FLAT = """model chain
g : Se[2]([1, 2])
j : 0[2]
g -> j
parameter link1_m = 1
parameter link1_k = 2
link1_mass : I[2](link1_m)
link1_spring : C[2](1/link1_k)
link1_node : 1[2]
signal link1_ke = link1_mass.p[0]^2/(2*link1_m) + link1_mass.p[1]^2/(2*link1_m)
when link1_mass.p[1] > 0.5 { reinit link1_mass.p[1] = 0 }
j -> link1_node
link1_node -> link1_mass
link1_node -> link1_spring
c1 : C(1)
h1 : 0
when link1_mass.p[0] > 0.3*1 { reinit link1_mass.p[0] = -link1_mass.p[0] }
parameter link2_m = 2
parameter link2_k = 2
link2_mass : I[2](link2_m)
link2_spring : C[2](1/link2_k)
link2_node : 1[2]
signal link2_ke = link2_mass.p[0]^2/(2*link2_m) + link2_mass.p[1]^2/(2*link2_m)
when link2_mass.p[1] > 0.5 { reinit link2_mass.p[1] = 0 }
j -> link2_node
link2_node -> link2_mass
link2_node -> link2_spring
c2 : C(2)
h2 : 0
when link2_mass.p[0] > 0.3*2 { reinit link2_mass.p[0] = -link2_mass.p[0] }
parameter link3_m = 3
parameter link3_k = 2
link3_mass : I[2](link3_m)
link3_spring : C[2](1/link3_k)
link3_node : 1[2]
signal link3_ke = link3_mass.p[0]^2/(2*link3_m) + link3_mass.p[1]^2/(2*link3_m)
when link3_mass.p[1] > 0.5 { reinit link3_mass.p[1] = 0 }
j -> link3_node
link3_node -> link3_mass
link3_node -> link3_spring
c3 : C(3)
h3 : 0
when link3_mass.p[0] > 0.3*3 { reinit link3_mass.p[0] = -link3_mass.p[0] }
m2 : I[2](2)
j -> m2
signal pr_v = link1_mass.p[0] + m2.p[1]
pr_s : MSe(pr_v)
pr_s -> h1
h1 -> c1
d : R(e = 3*f + link2_mass.p[1])
src : Sf(link3_spring.q[1])
src -> h2
h2 -> c2
h2 -> d
f3 : Sf(c1.q)
f3 -> h3
h3 -> c3
signal en = link1_ke + link2_mass.p[0]^2/4 + link3_mass.p[1]^2/6
when en > 1 and m2.p[0] > 0 { reinit m2.p[1] = 0; reinit c2.q = c1.q }
scene s { outputs en, link2_mass.p[1], link3_spring.q[0], m2.p[0], c3.q
          time 0 .. 1 every 0.25 }
"""


def test_indexed_vector_variables_by_path_against_the_flat_twin(tmp_path):
    a, b = assert_twins(CHAIN, CHAIN_FLAT, "s")
    assert list(a.program.outputs) == ["en", "link[2].mass.p[1]", "link[3].spring.q[0]",
                                       "m2.p[0]", "c[3].q"]
    ya = bgc.simulate(Source("a.bg", CHAIN), "s", backend="vm")
    yb = bgc.simulate(Source("b.bg", CHAIN_FLAT), "s", backend="vm")
    np.testing.assert_array_equal(ya[1], yb[1])  # the same numbers, bit for bit
    path = tmp_path / "chain.bg"
    path.write_text(CHAIN)
    result = CliRunner().invoke(main, ["simulate", str(path), "-s", "s", "--backend", "vm",
                                       "--outputs", "link[N].mass.p[N-2],c[1].q"])
    assert result.exit_code == 0, result.output
    assert result.output.splitlines()[0] == "t,link[3].mass.p[1],c[1].q"


OSCILLATORS = """model oscillators
constant N = 2
component oscillator(m = 1, k = 4, a = 1) {
  port base[2]
  mass : I[2](m)
  spring : C[2](1/k) init q = [a, 2*a]
  node : 1[2]
  base -> node
  node -> mass
  node -> spring
}
ground : Se[2]([0, 0])
g : 0[2]
ground -> g
for i in 1..N {
  link[i] : oscillator(m = i, a = 0.5*i)
  g -> link[i].base
}
signal en = link[N].mass.p[1]^2/(2*N) + link[N].spring.q[1]^2*4/2
scene run { outputs link[1].mass.p[0], link[N].spring.q[N-1], en; time 0 .. 2 every 0.5 }
"""


def test_indexed_vector_variables_of_instances_against_the_closed_form():
    """Undamped oscillators m_i, k = 4 from q(0) = (a_i, 2 a_i): q = q(0) cos(w t),
    p = -m w q(0) sin(w t), w = sqrt(k / m); the energy k q(0)^2 / 2 stays."""
    t, Y, names = bgc.simulate(Source("osc.bg", OSCILLATORS), "run", backend="vm",
                               rtol=1e-11, atol=1e-13)
    assert names == ["link[1].mass.p[0]", "link[2].spring.q[1]", "en"]
    w1, w2 = 2.0, np.sqrt(2.0)
    expected = np.column_stack([-1 * w1 * 0.5 * np.sin(w1 * t), 2.0 * np.cos(w2 * t),
                                np.full_like(t, 4 * 2.0**2 / 2)])
    np.testing.assert_allclose(Y, expected, rtol=1e-8, atol=1e-9)


PENDULUM = """model pendulum
parameter g = 9.81
component bob(m = 1.0, l = 1.0, theta0 = 0.5, alpha = 5.0, beta = 5.0) {
  vx : 1
  vy : 1
  mx : I(m)
  my : I(m)
  weight : Se(m*g0) @gravity
  parameter g0 = 9.81
  tx : MTF(2*x)
  ty : MTF(2*y)
  rod : 0 constraint holonomic(init = -l^2) corrector pid(alpha, beta) @stabilisation
  signal x = integral(vx.f, init = l*sin(theta0))
  signal y = integral(vy.f, init = l*cos(theta0))
  vx -> mx
  vy -> my
  weight -> vy
  vx -> tx -> rod
  vy -> ty -> rod
}
p : bob(l = 2.0) @arm
scene swing { outputs p.x, p.y, p.rod.lambda, p.rod.residual; time 0 .. 1 every 0.1 }
scene free { effects gravity, arm; outputs p.x, p.rod.lambda; time 0 .. 1 every 0.1 }
"""

PENDULUM_FLAT = """model pendulum
parameter g = 9.81
parameter p_m = 1.0
parameter p_l = 2.0
parameter p_theta0 = 0.5
parameter p_alpha = 5.0
parameter p_beta = 5.0
p_vx : 1 @arm
p_vy : 1 @arm
p_mx : I(p_m) @arm
p_my : I(p_m) @arm
p_weight : Se(p_m*p_g0) @gravity @arm
parameter p_g0 = 9.81
p_tx : MTF(2*p_x) @arm
p_ty : MTF(2*p_y) @arm
p_rod : 0 constraint holonomic(init = -p_l^2) corrector pid(p_alpha, p_beta) @stabilisation @arm
signal p_x = integral(p_vx.f, init = p_l*sin(p_theta0))
signal p_y = integral(p_vy.f, init = p_l*cos(p_theta0))
p_vx -> p_mx
p_vy -> p_my
p_weight -> p_vy
p_vx -> p_tx -> p_rod
p_vy -> p_ty -> p_rod
scene swing { outputs p_x, p_y, p_rod.lambda, p_rod.residual; time 0 .. 1 every 0.1 }
scene free { effects gravity, arm; outputs p_x, p_rod.lambda; time 0 .. 1 every 0.1 }
"""


@pytest.mark.parametrize("scene", ["swing", "free"])
def test_constraint_junctions_effects_and_paths_in_outputs(scene):
    a, b = assert_twins(PENDULUM, PENDULUM_FLAT, scene)
    assert list(a.program.outputs) == (["p.x", "p.y", "p.rod.lambda", "p.rod.residual"]
                                       if scene == "swing" else ["p.x", "p.rod.lambda"])
    ya = bgc.simulate(Source("a.bg", PENDULUM), scene, backend="python")
    yb = bgc.simulate(Source("b.bg", PENDULUM_FLAT), scene, backend="python")
    np.testing.assert_array_equal(ya[1], yb[1])  # the same numbers, bit for bit
    assert ya[2][0] == "p.x"


GENERATED = """model generated
constant N = 4
for i in 0..N-1 {
  m[i] : I(1 + i)
  j[i] : 1
  j[i] -> m[i]
  if i > 0 {
    k[i] : C(0.5)
    c[i] : 0
    j[i-1] -> c[i]
    c[i] -> j[i]
    c[i] -> k[i]
  } else {
    f : Se(1)
    f -> j[i]
  }
}
"""

GENERATED_FLAT = """model generated
m0 : I(1 + 0)
j0 : 1
f : Se(1)
m1 : I(1 + 1)
j1 : 1
k1 : C(0.5)
c1 : 0
m2 : I(1 + 2)
j2 : 1
k2 : C(0.5)
c2 : 0
m3 : I(1 + 3)
j3 : 1
k3 : C(0.5)
c3 : 0
j0 -> m0
f -> j0
j1 -> m1
j0 -> c1
c1 -> j1
c1 -> k1
j2 -> m2
j1 -> c2
c2 -> j2
c2 -> k2
j3 -> m3
j2 -> c3
c3 -> j3
c3 -> k3
"""


def test_constants_for_and_if_against_the_flat_twin():
    a, _ = assert_twins(GENERATED, GENERATED_FLAT)
    # an indexed element's variables are named as a multiport's parts are: m.p[0]
    assert [s.name for s in a.reduced.states][:3] == ["m.p[0]", "m.p[1]", "k.q[1]"]


def test_const_on_the_command_line(tmp_path):
    path = tmp_path / "g.bg"
    path.write_text(GENERATED)
    assert len(build(GENERATED, consts=[("N", 7)]).reduced.states) == 7 + 6
    result = CliRunner().invoke(main, ["check", str(path), "--const", "N=2"])
    assert result.exit_code == 0, result.output
    assert "states (3)" in result.output
    result = CliRunner().invoke(main, ["check", str(path), "--const", "M=2"])
    assert result.exit_code == 2
    assert "the model has no constant 'M'" in result.stderr
    result = CliRunner().invoke(main, ["check", str(path), "--const", "N=x"])
    assert result.exit_code == 2 and "not a whole number" in result.stderr


TANKS = """model tanks
constant N = 4
component tank(k = 1) {
  fill : Sf(k)
  c : C(1)
  fill -> c
}
for i in 1..N { s[i] : tank(k = i) }
scene run { outputs s[N].c.q, s[N - 1].c.q, s[min(N, 2)].c.e; time 0 .. 1 every 0.25 }
scene faster { set s[N - 1].k = 10; outputs s[N - 1].c.q, s[N].c.q; time 0 .. 1 every 0.25 }
"""


@pytest.mark.parametrize("const, outputs, header, rates", [
    ([], [], ["s[4].c.q", "s[3].c.q", "s[2].c.e"], [4, 3, 2]),
    (["--const", "N=6"], [], ["s[6].c.q", "s[5].c.q", "s[2].c.e"], [6, 5, 2]),
    (["--const", "N=6"], ["--outputs", "s[N/2].c.q, s[N^2 - 35].c.f"],
     ["s[3].c.q", "s[1].c.f"], [3, None])])
def test_constants_in_the_indices_of_outputs(tmp_path, const, outputs, header, rates):
    """Outputs indexed by constants, in the scene and in --outputs, with --const: tank i
    is filled at the rate i, so its charge is i t (its flow i)."""
    (tmp_path / "tanks.bg").write_text(TANKS)
    result = CliRunner().invoke(main, ["simulate", str(tmp_path / "tanks.bg"), "--scene", "run",
                                       "--backend", "python", *const, *outputs])
    assert result.exit_code == 0, result.stderr
    lines = result.stdout.splitlines()
    assert lines[0].split(",") == ["t", *header]
    rows = np.array([[float(x) for x in line.split(",")] for line in lines[1:]])
    t = rows[:, 0]
    assert np.allclose(t, [0, 0.25, 0.5, 0.75, 1])
    expected = [r * t if r is not None else np.ones_like(t) for r in rates]
    np.testing.assert_allclose(rows[:, 1:], np.column_stack(expected), rtol=0, atol=1e-12)


@pytest.mark.parametrize("consts, charges", [((), (10, 4)), ((("N", 2),), (10, 2))])
def test_a_scene_sets_a_parameter_through_constant_indices(consts, charges):
    """`set s[N - 1].k = 10`: that tank fills at 10, the last one at N."""
    t, Y, names = bgc.simulate(Source("tanks.bg", TANKS, consts), "faster", backend="python")
    n = dict(consts).get("N", 4)
    assert names == [f"s[{n - 1}].c.q", f"s[{n}].c.q"]
    np.testing.assert_allclose(Y, np.outer(t, charges), rtol=0, atol=1e-12)


def test_paths_in_the_csv_header_and_in_overrides(tmp_path):
    path = tmp_path / "ladder.bg"
    path.write_text(LADDER)
    out = tmp_path / "out.csv"
    result = CliRunner().invoke(main, ["simulate", str(path), "--scene", "run", "-o", str(out),
                                       "-p", "s[2].r=30", "--backend", "python"])
    assert result.exit_code == 0, result.output
    header, first, second = out.read_text().splitlines()[:3]
    assert header == "t,s[1].cap.q,s[3].cap.e,s[2].res.f"
    base = bgc.simulate(Source("l.bg", LADDER), "run", backend="python")
    assert float(second.split(",")[3]) != pytest.approx(base[1][1, 2])
    result = CliRunner().invoke(main, ["simulate", str(path), "--outputs", "s[2].cap.e, s[1].r",
                                       "--backend", "python", "--t-end", "0.5"])
    assert result.exit_code == 0 and result.stdout.startswith("t,s[2].cap.e,s[1].r\n")
    result = CliRunner().invoke(main, ["equations", str(path), "--scene", "run", "--format",
                                       "latex"])
    assert result.exit_code == 0 and r"\mathrm{s[1].cap.q}" in result.output


# ------------------------------------------------------------------ size and limits
def _chain(n: int) -> str:
    return f"""model long
component section(r = 1, c = 1) {{
  port a
  port b
  node : 0
  link : 1
  res : R(r)
  cap : C(c)
  a -> link -> res
  link -> node -> cap
  node -> b
}}
constant N = {n}
src : Se(1)
for i in 1..N {{ s[i] : section() }}
src -> s[1].a
for i in 2..N {{ s[i-1].b -> s[i].a }}
end : Sf(0)
s[N].b -> end
"""


def test_a_thousand_instances_compile():
    start = time.perf_counter()
    c = build(_chain(1000), program=False)
    assert len(c.reduced.states) == 1000
    assert c.reduced.states[-1].name == "s[1000].cap.q"
    assert time.perf_counter() - start < 120  # (a safety net, not a benchmark)


def test_the_expansion_is_counted_before_it_is_made(monkeypatch):
    """instantiate's estimate (before any statement is made) counts exactly what the
    expansion then makes: loops whose bodies read their variable and loops whose bodies do
    not, `if` on the index, a loop-local constant, nested components, an imported one."""
    from bgc.front import instantiate as stage
    text = "\n".join([
        "model counted", "constant N = 7",
        "component leaf(k = 1) { port a; e : C(k); a -> e }",
        "component pair(k = 1) { port a; j : 0; a -> j; for i in 1..3 { x[i] : leaf(k = k); "
        "j -> x[i].a } }",
        "s : Sf(1)", "top : 0", "s -> top",
        "for i in 1..N { p[i] : pair(); top -> p[i].a }",
        "for i in 1..N { for j in i..N { if j > i + 1 { r[i*100+j] : R(1); top -> r[i*100+j] } "
        "} }",
        "for i in 1..2*N { constant M = i - 1; if M == 3 { extra : C(1); top -> extra } }",
    ])
    model = parse(text + "\n", "counted.bg")
    st = stage._Instantiate(model, {}, stage.search_path())
    flat = st.build()
    assert st.generated == st.estimated > 0
    assert len(flat.decls) > 7 * (1 + 3 * 3)
    monkeypatch.setenv("BGC_MEMORY", "110M")  # room for 1048 declarations and bonds
    wide = "model wide\ns : Sf(1)\ntop : 0\ns -> top\nfor i in 1..600 { c[i] : C(1); top -> c[i] }\n"
    message = error_of(wide.replace("model wide\n", "model wide\n"))
    assert ":5:1: error: the model is too large: the more than 1048 declarations and bonds " \
           "its components and 'for' loops make need about " in message, message
    assert "more than the 110 MiB available" in message


def test_a_loop_of_empty_passes_is_refused_before_it_runs(monkeypatch):
    start = time.perf_counter()
    message = error_of("model idle\ns : Sf(1)\ne : C(1)\ns -> e\n"
                       "for i in 1..1000000000 { if i < 0 { x : C(1) } }\n")
    assert "the model is too large: the more than" in message
    assert time.perf_counter() - start < 10  # (refused before a billion passes are made)


def test_nesting_depth_is_refused_before_the_work():
    parts = ["model deep", "component c0(k = 1) { port a; e : C(k); a -> e }"]
    for level in range(1, MAX_INSTANCE_DEPTH + 2):
        parts.append(f"component c{level}(k = 1) {{ port a; x : c{level - 1}(k = k); "
                     f"a -> x.a }}")
    parts += [f"top : c{MAX_INSTANCE_DEPTH + 1}()", "s : Sf(1)", "s -> top.a"]
    text = error_of("\n".join(parts))
    assert f"instances nested more than {MAX_INSTANCE_DEPTH} levels deep" in text
    assert text.count("note: in instance") == MAX_INSTANCE_DEPTH


def test_an_exponential_tree_is_refused():
    parts = ["model wide", "component c0(k = 1) { port a; e : C(k); a -> e }"]
    for level in range(1, 8):
        inner = "; ".join(f"x[{i}] : c{level - 1}(); j -> x[{i}].a" for i in range(10))
        parts.append(f"component c{level}(k = 1) {{ port a; j : 0; a -> j; {inner} }}")
    parts += ["top : c7()", "s : Sf(1)", "s -> top.a"]
    start = time.perf_counter()
    text = error_of("\n".join(parts))
    assert "the model is too large" in text and text.count("error:") == 1
    assert time.perf_counter() - start < 30


def test_errors_inside_components_name_the_chain_of_instances():
    text = error_of("""model m
component leaf(k = 1) {
  port a
  c : C(k)
  a -> c
  d : C(1)
}
component branch() {
  port a
  l[2] : leaf()
  a -> l[2].a
}
s : Sf(1)
b : branch()
s -> b.a
""")
    assert text.splitlines()[0] == "inline.bg:6:3: error: 'b.l[2].d' (C) needs exactly one " \
                                   "bond; it has 0"
    notes = [line for line in text.splitlines() if "note:" in line]
    assert notes == ["inline.bg:10:3: note: in instance b.l[2]",
                     "inline.bg:14:1: note: in instance b"]


def test_names_from_the_model_stay_out_of_the_generated_code():
    c = build(LADDER, "run")
    (code,) = emit_c(c.program).values()
    fields = re.findall(r"p->(\w+)", code)
    assert "p_s_1__r" in fields and all(re.fullmatch(r"\w+(\[\d+\])?", f) for f in fields)
    assert "s[1].r" not in re.sub(r'"(?:\\.|[^"\\\n])*"|/\*.*?\*/', "", code, flags=re.S)


# ------------------------------------------------------------------ libraries
HYD = """library hyd "hydraulic parts"
component orifice(r = 1 unit "Pa*s/m^3") "a linear restriction" {
  port a : hydraulic
  res : R(r)
  a -> res
}
component pipe(r = 1, l = 0.1) "a restriction and the fluid's inertia" {
  port a : hydraulic
  port b : hydraulic
  j : 1
  fluid : I(l)
  a -> j
  j -> fluid
  o : orifice(r = r)
  j -> o.a
  j -> b
}
"""

CIRCUIT = """model circuit
import {what}
pump : Se(1)
p1 : {alias}.pipe(r = 2)
tank : C(1)
pump -> p1.a
p1.b -> tank
"""


def _library_model(tmp_path, what, alias, lib_dir=None):
    tmp_path.mkdir(exist_ok=True)
    (lib_dir or tmp_path).mkdir(exist_ok=True)
    ((lib_dir or tmp_path) / "hyd.bg").write_text(HYD)
    model = tmp_path / "circuit.bg"
    model.write_text(CIRCUIT.format(what=what, alias=alias))
    return model


@pytest.mark.parametrize("what, alias", [("hyd", "hyd"), ("hyd as h", "h"),
                                         ('"hyd.bg" as h', "h")])
def test_imports_beside_the_model(tmp_path, what, alias):
    c = bgc.build(_library_model(tmp_path, what, alias), program=False)
    assert [s.name for s in c.reduced.states] == ["p1.fluid.p", "tank.q"]
    assert {p.name: p.unit for p in c.graph.parameters}["p1.o.r"] == "Pa*s/m^3"


def test_imports_search_bgc_path_after_the_model_directory(tmp_path, monkeypatch):
    model = _library_model(tmp_path / "m", "hyd", "hyd", lib_dir=tmp_path / "libs")
    monkeypatch.setenv("BGC_PATH", str(tmp_path / "libs"))
    assert len(bgc.build(model, program=False).reduced.states) == 2
    (tmp_path / "m" / "hyd.bg").write_text(HYD.replace("fluid : I(l)", "fluid : C(l)"))
    assert bgc.build(model, program=False).reduced.states[0].name == "p1.fluid.q"  # beside wins
    monkeypatch.delenv("BGC_PATH")
    (tmp_path / "m" / "hyd.bg").unlink()
    with pytest.raises(bgc.BgcModelError, match="cannot find the library 'hyd'"):
        bgc.build(model, program=False)


def test_an_error_inside_a_library_names_its_file_and_the_instances(tmp_path):
    model = _library_model(tmp_path, "hyd", "hyd")
    (tmp_path / "hyd.bg").write_text(HYD.replace("res : R(r)", "res : R(r*rr)"))
    with pytest.raises(bgc.BgcModelError) as info:
        bgc.build(model, program=False)
    lines = str(info.value).splitlines()
    assert lines[0] == f"{tmp_path / 'hyd.bg'}:4:13: error: unknown name 'p1.o.rr'"
    assert [ln for ln in lines if "note:" in ln] == [
        f"{tmp_path / 'hyd.bg'}:14:3: note: in instance p1.o",
        f"{model}:4:1: note: in instance p1"]


def test_a_library_holds_components_only(tmp_path):
    model = _library_model(tmp_path, "hyd", "hyd")
    (tmp_path / "hyd.bg").write_text(HYD + "x : C(1)\n")
    with pytest.raises(bgc.BgcModelError, match="a library holds only components, constants "
                                                "and imports"):
        bgc.build(model, program=False)


# ------------------------------------------------------------------ the pendulum chain
@pytest.mark.parametrize("backend", ["python"] + (["c"] if toolchain.have_c_compiler() else []))
def test_the_pendulum_chain_as_a_component_gives_the_same_csv(backend, tmp_path):
    """models/pendulum_chain.bg (a `link` component and a for loop, under half the lines)
    against its flat twin tests/models/pendulum_chain_flat.bg (written out by
    benchmarks/families.py): the same CSV, byte for byte, column names included (signals
    x1 ... y8 name the links' coordinates)."""
    text = COMPONENT_CHAIN.read_text()
    assert len(text.splitlines()) < len(FLAT_CHAIN.read_text().splitlines()) / 2
    out = {}
    for name, model in (("component", COMPONENT_CHAIN), ("flat", FLAT_CHAIN)):
        out[name] = tmp_path / f"{name}.csv"
        result = CliRunner().invoke(main, ["simulate", str(model), "--scene", "swing", "--t-end",
                                           "1", "--backend", backend, "-o", str(out[name])])
        assert result.exit_code == 0, result.output
    data = out["component"].read_bytes()
    assert data == out["flat"].read_bytes()
    assert data.startswith(b"t," + ",".join(f"{c}{k}" for k in range(1, 9)
                                            for c in "xy").encode() + b"\n")


def test_an_import_cycle_is_an_error(tmp_path):
    (tmp_path / "a.bg").write_text("library a\nimport b\n"
                                   "component x() { port p; r : R(1); p -> r }\n")
    (tmp_path / "b.bg").write_text("library b\nimport a\n")
    model = tmp_path / "m.bg"
    model.write_text("model m\nimport a\ns : Se(1)\nq : a.x()\ns -> q.p\n")
    with pytest.raises(bgc.BgcModelError, match="library a.bg imports itself"):
        bgc.build(model, program=False)
