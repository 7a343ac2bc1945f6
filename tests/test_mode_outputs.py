"""A switched element's or a contact's mode as an output (`floor.active`, `d.blocking`,
`s.open`, `f.stick`, `f.dir`), which the analyses' programs also read: a ball dropped from
1 m onto a floor that holds it (restitution 0) lands at sqrt(2 h / g) and rests there."""
import math

import numpy as np

import bgc
from conftest import run_bgc

BALL = """model ball "a ball dropped onto a floor, coming to rest"
parameter m = 1.0
parameter g = 9.81
w : Se(-m*g)
b : I(m)
j : 1
signal x = integral(b.f, init = 1)
w -> j
j -> b
floor : 0 constraint unilateral(phi = x) restitution(0)
j -> floor
"""


def test_a_contact_s_mode_is_an_output_and_the_analyses_read_it(tmp_path):
    path = tmp_path / "ball.bg"
    path.write_text(BALL)
    t, Y, names = bgc.simulate(path, outputs="x, floor.active, floor.lambda", t_end=1.0,
                               dt=0.01, backend="python")
    landing = math.sqrt(2 * 1.0 / 9.81)  # the free fall's closed form
    active = Y[:, names.index("floor.active")]
    assert np.all(active[t < landing - 1e-9] == 0) and np.all(active[t > landing + 1e-9] == 1)
    resting = t > landing + 1e-9
    assert np.allclose(np.abs(Y[resting, names.index("floor.lambda")]), 9.81, rtol=1e-9)
    # the analysis program asks for the modes too: linearize and steady at rest
    r = run_bgc("linearize", str(path), "--at", "t=1")
    assert r.returncode == 0, r.stderr
    r = run_bgc("simulate", str(path), "--outputs", "floor.nope", "--t-end", "0.1")
    assert r.returncode == 2 and "(it has: e, lambda, residual, active, vmax)" in r.stderr
