"""Families of bond-graph models that grow with one size parameter, as .bg text.

Used by benchmarks/compile_scale.py and by the tests (the 3-link chain against its
minimal-coordinate reference).  Each generator returns the model's source text; the models
are written the way a modeller writes them, one element per line.

- pendulum_chain(n): n point masses in a planar chain, absolute (Cartesian) coordinates, one
  holonomic constraint junction per rod with a Baumgarte pid corrector (the paper's pendulum,
  n times): 4n states, n multipliers coupled along the chain.
- pendulum_chain_vector(n): the same chain written with vector bonds (a junction array, a
  mass field, one n x 2n matrix transformer, a constraint array).
- mass_chain(n): n masses joined by spring-damper pairs, the first to a wall, a force on
  the last: 2n states, no algebraic loop.
- rc_ladder(n): n sections of series resistor and shunt capacitor fed by a voltage source:
  n states.
- resistor_ladder(n): n sections of series and shunt resistors, each its own parameter, then
  a capacitor: one state behind a linear algebraic loop through all 2n resistors.
- rc_ladder_components(n): the RC ladder written with a `section` component and a `for`
  loop (n instances); rc_ladder_flat_twin(n) is its flat twin, the same model written
  out by hand, for the cost of instantiating.
- thermal_grid(n): an n x n thermal RC grid of cells written with `for` loops: n^2 states,
  stiff, with a sparse Jacobian (benchmarks/stiff_scale.py); thermal_grid_rhs(n, T) its right
  side written from the formula; thermal_grid_cells(m) the same by its number of states.
- The Modelica ScalableTestSuite's families written as bond graphs with components and `for`
  loops (the form issue 41's array-preserving compilation takes; benchmarks/scalable.py):
  heat_line(n) (1-D heat conduction, n cells), thermal_grid(n) (the 2-D plate, above),
  transmission_line(n) (an RLC line of n sections), cascaded_first_order(n) (n buffered first-
  order lags) and harmonic_oscillators(n) (n independent mass-springs); each with the closed
  form or the matrix its tests compare against (*_matrices: x' = A x + b).
"""
from __future__ import annotations

import math


def pendulum_chain(n: int, theta0: float = 0.5, dtheta: float = 0.15) -> str:
    """Link k (1-based) starts at angle theta0 + (k - 1) * dtheta from the downward vertical,
    at rest; y points down, gravity along +y."""
    lines = [
        f'model chain{n} "{n}-link planar pendulum chain in absolute coordinates, '
        'Baumgarte-stabilised"',
        "parameter m = 1.0 \"mass of each point\"",
        "parameter l = 1.0 \"length of each rod\"",
        "parameter g = 9.81",
        "parameter alpha = 5.0 \"Baumgarte damping gain\"",
        "parameter beta = 5.0 \"Baumgarte stiffness gain\"",
        f"parameter theta0 = {theta0!r} \"initial angle of the first link\"",
        f"parameter dtheta = {dtheta!r} \"each further link starts this much further round\"",
        "",
    ]
    for k in range(1, n + 1):
        th = f"(theta0 + {k - 1}*dtheta)" if k > 1 else "theta0"
        xprev = f" + x{k - 1}_0" if k > 1 else ""
        yprev = f" + y{k - 1}_0" if k > 1 else ""
        lines += [
            f"parameter x{k}_0 = l*sin({th}){xprev}",
            f"parameter y{k}_0 = l*cos({th}){yprev}",
            f"vx{k} : 1",
            f"vy{k} : 1",
            f"mx{k} : I(m)",
            f"my{k} : I(m)",
            f"w{k} : Se(m*g) @gravity",
            f"rod{k} : 0 constraint holonomic(init = -l^2) corrector pid(alpha, beta) "
            "@stabilisation",
            f"signal x{k} = integral(vx{k}.f, init = x{k}_0)",
            f"signal y{k} = integral(vy{k}.f, init = y{k}_0)",
            f"vx{k} -> mx{k}",
            f"vy{k} -> my{k}",
            f"w{k} -> vy{k}",
        ]
        if k == 1:
            lines += [f"ax1 : MTF(2*x1)", f"ay1 : MTF(2*y1)"]
        else:
            lines += [
                f"ax{k} : MTF(2*(x{k} - x{k - 1}))",
                f"ay{k} : MTF(2*(y{k} - y{k - 1}))",
                f"bx{k} : MTF(-2*(x{k} - x{k - 1}))",
                f"by{k} : MTF(-2*(y{k} - y{k - 1}))",
                f"vx{k - 1} -> bx{k} -> rod{k}",
                f"vy{k - 1} -> by{k} -> rod{k}",
            ]
        lines += [f"vx{k} -> ax{k} -> rod{k}", f"vy{k} -> ay{k} -> rod{k}", ""]
    outputs = ", ".join(f"x{k}, y{k}" for k in range(1, n + 1))
    lines.append(f"scene swing {{ outputs {outputs}; time 0 .. 5 every 0.01; "
                 "solver dopri5(rtol = 1e-10, atol = 1e-12) }")
    return "\n".join(lines) + "\n"


def mass_chain(n: int) -> str:
    lines = [
        f'model masses{n} "{n} masses joined by springs and dampers, the first to a wall"',
        "parameter m = 1.0", "parameter k = 100.0", "parameter b = 0.5",
        "parameter F = 1.0 \"force on the last mass\"",
        "wall : Sf(0)",
        "push : Se(F)",
    ]
    for i in range(1, n + 1):
        left = "wall" if i == 1 else f"v{i - 1}"
        lines += [
            f"v{i} : 1", f"mass{i} : I(m)", f"v{i} -> mass{i}",
            f"n{i} : 0", f"d{i} : 1", f"spring{i} : C(1/k)", f"damper{i} : R(b)",
            f"{left} -> n{i} -> v{i}", f"n{i} -> d{i}", f"d{i} -> spring{i}",
            f"d{i} -> damper{i}",
        ]
    lines.append(f"push -> v{n}")
    return "\n".join(lines) + "\n"


def rc_ladder(n: int) -> str:
    lines = [
        f'model rc{n} "{n}-section RC ladder driven by a voltage source"',
        "parameter V0 = 1.0", "parameter R = 1.0", "parameter Cc = 0.01",
        "src : Se(V0)",
    ]
    for i in range(1, n + 1):
        left = "src" if i == 1 else f"n{i - 1}"
        lines += [f"j{i} : 1", f"r{i} : R(R)", f"n{i} : 0", f"c{i} : C(Cc)",
                  f"{left} -> j{i} -> n{i}", f"j{i} -> r{i}", f"n{i} -> c{i}"]
    return "\n".join(lines) + "\n"


def resistor_ladder(n: int) -> str:
    lines = [
        f'model rladder{n} "{n}-section resistor ladder with symbolic resistances charging '
        'a capacitor"',
        "parameter V0 = 10.0", "parameter Cc = 0.2",
    ]
    for i in range(1, n + 1):
        lines += [f"parameter Rs{i} = {1.0 + 0.1 * i!r}", f"parameter Rp{i} = {2.0 + 0.05 * i!r}"]
    lines += ["src : Se(V0)", "cap : C(Cc)"]
    for i in range(1, n + 1):
        left = "src" if i == 1 else f"n{i - 1}"
        lines += [f"s{i} : 1", f"rs{i} : R(Rs{i})", f"n{i} : 0", f"rp{i} : R(Rp{i})",
                  f"{left} -> s{i} -> n{i}", f"s{i} -> rs{i}", f"n{i} -> rp{i}"]
    lines += [f"last : 1", f"rl : R(Rs1)", f"n{n} -> last -> cap", "last -> rl"]
    return "\n".join(lines) + "\n"


def pendulum_chain_vector(n: int, theta0: float = 0.5, dtheta: float = 0.15) -> str:
    """pendulum_chain(n) in multibond form: one velocity junction array of 2n, one mass field,
    one weight vector, the n rods a constraint junction array reached through one n x 2n matrix
    transformer (the constraints' Jacobian), the coordinates one vector signal.  Same
    equations, same states in the same order."""
    def q(k, axis):  # the coordinate of point k (1-based), axis 0: x, 1: y
        return f"q[{2 * (k - 1) + axis}]"

    rows, inits = [], []
    for k in range(1, n + 1):
        row = ["0"] * (2 * n)
        for axis in (0, 1):
            d = f"{q(k, axis)} - {q(k - 1, axis)}" if k > 1 else q(k, axis)
            row[2 * (k - 1) + axis] = f"2*({d})"
            if k > 1:
                row[2 * (k - 2) + axis] = f"-2*({d})"
        rows.append("[" + ", ".join(row) + "]")
        th = f"(theta0 + {k - 1}*dtheta)" if k > 1 else "theta0"
        inits.append(f"x{k}_0")
        inits.append(f"y{k}_0")
    lines = pendulum_chain(n, theta0, dtheta).splitlines()[:9]
    lines[0] = lines[0].replace(f"model chain{n} ", f"model chain{n}v ")
    for k in range(1, n + 1):
        th = f"(theta0 + {k - 1}*dtheta)" if k > 1 else "theta0"
        lines += [f"parameter x{k}_0 = l*sin({th})" + (f" + x{k - 1}_0" if k > 1 else ""),
                  f"parameter y{k}_0 = l*cos({th})" + (f" + y{k - 1}_0" if k > 1 else "")]
    lines += [
        f"v : 1[{2 * n}]",
        f"mass : I[{2 * n}](m)",
        f"weight : Se[{2 * n}]([" + ", ".join(["0", "m*g"] * n) + "]) @gravity",
        f"J : MTF[{2 * n}->{n}]([" + ",\n    ".join(rows) + "])",
        f"rods : 0[{n}] constraint holonomic(init = -l^2) corrector pid(alpha, beta) "
        "@stabilisation",
        f"signal q[{2 * n}] = integral(v.f, init = [" + ", ".join(inits) + "])",
        "v -> mass",
        "weight -> v",
        "v -> J -> rods",
        "",
        "scene swing { outputs q; time 0 .. 5 every 0.01; "
        "solver dopri5(rtol = 1e-10, atol = 1e-12) }",
    ]
    return "\n".join(lines) + "\n"


def link_chain_field(n: int, theta0: float = 0.5, dtheta: float = 0.15) -> str:
    """An n-link pendulum chain in its link angles (each from the downward vertical), a point
    mass m at each link's end: one I field whose n x n mass matrix is full and depends on every
    angle, M_ij = m l^2 (n - max(i, j)) cos(th_i - th_j) (0-based: the masses beyond both links),
    and one closing constraint, the last mass held on the vertical line through its start,
    Phi = l sum sin(th_i) - x0, through its 1 x n Jacobian.  The constraint on a coupled field:
    bgc solves M(q) f = p and the augmented system [M G^T; G 0] in the generated code."""
    angles = [theta0 + k * dtheta for k in range(n)]
    rows = []
    for i in range(n):
        row = []
        for j in range(n):
            count = n - max(i, j)
            row.append(f"{count}*m*l^2" if i == j else
                       f"{count}*m*l^2*cos(th[{i}] - th[{j}])")
        rows.append("[" + ", ".join(row) + "]")
    forces = ", ".join(f"-{n - i}*m*g*l*sin(th[{i}])" for i in range(n))
    jac = ", ".join(f"l*cos(th[{i}])" for i in range(n))
    tip = " + ".join(f"l*sin(th[{i}])" for i in range(n))
    lines = [
        f'model link_chain{n} "{n}-link chain in its link angles: a full {n} x {n} M(q), '
        'its end held on a line"',
        "parameter m = 1.0", "parameter l = 1.0", "parameter g = 9.81",
        "parameter alpha = 10.0", "parameter beta = 10.0",
        f"parameter x0 = {sum(__import__('math').sin(a) for a in angles)!r}",
        f"w : 1[{n}]",
        f"links : I[{n}]([{', '.join(rows)}])",
        f"gravity : MSe[{n}]([{forces}])",
        f"tip : MTF[{n}->1]([[{jac}]])",
        f"wall : 0[1] constraint holonomic(phi = [{tip} - x0]) corrector pid(alpha, beta)",
        f"signal th[{n}] = integral(w.f, init = [{', '.join(repr(a) for a in angles)}])",
        "gravity -> w -> links",
        "w -> tip -> wall",
        "",
        "scene swing { outputs th; time 0 .. 5 every 0.01; "
        "solver dopri5(rtol = 1e-10, atol = 1e-12) }",
    ]
    return "\n".join(lines) + "\n"


def rc_ladder_components(n: int) -> str:
    """rc_ladder(n) written with a `section` component repeated by a `for` loop: n instances,
    each with its own parameters r and c (parameters of the model, s[i].r); the last node's
    free port is closed by a zero flow source."""
    return "\n".join([
        f'model rcc{n} "{n}-section RC ladder of components driven by a voltage source"',
        f"constant N = {n}",
        "parameter V0 = 1.0", "parameter R = 1.0", "parameter Cc = 0.01",
        "component section(r, c) {",
        "  port a; port b",
        "  j : 1; res : R(r); n : 0; cap : C(c)",
        "  a -> j -> n; j -> res; n -> cap; n -> b",
        "}",
        "src : Se(V0)",
        "for i in 1..N { s[i] : section(R, Cc) }",
        "src -> s[1].a",
        "for i in 2..N { s[i-1].b -> s[i].a }",
        "open : Sf(0)",
        "s[N].b -> open",
    ]) + "\n"


def rc_ladder_flat_twin(n: int) -> str:
    """The flat twin of rc_ladder_components(n): the model its instances flatten to, written
    out by hand (the same parameters, elements and bonds, `s3_j` for `s[3].j`)."""
    lines = [
        f'model rcf{n} "{n}-section RC ladder, the flat twin of the component ladder"',
        "parameter V0 = 1.0", "parameter R = 1.0", "parameter Cc = 0.01",
        "src : Se(V0)",
    ]
    for i in range(1, n + 1):
        s = f"s{i}_"
        left = "src" if i == 1 else f"s{i - 1}_n"
        lines += [f"parameter {s}r = R", f"parameter {s}c = Cc",
                  f"{s}j : 1", f"{s}res : R({s}r)", f"{s}n : 0", f"{s}cap : C({s}c)",
                  f"{left} -> {s}j -> {s}n", f"{s}j -> {s}res", f"{s}n -> {s}cap"]
    lines += ["open : Sf(0)", f"s{n}_n -> open"]
    return "\n".join(lines) + "\n"


def thermal_grid(n: int, t_end: float = 50.0) -> str:
    """An n x n thermal RC grid (a plate cut into cells): cell k = (i - 1) n + j (row i, column
    j, 1-based) is a 0-junction with a heat capacity C(c) (state cap[k].q, the cell's heat;
    cap[k].e its temperature), neighbours joined by a 1-junction with a thermal resistance
    R(r) (plain elements in `for` loops: a `link` component per joint would make the 50x50
    grid exceed the declarations that components and loops may generate), the cells of the
    last column lose heat to an ambient at temperature 0 through R(rb), a heater feeds q_in
    into cell 1, and the cells start at the temperatures 1 + sin(k) (every mode excited).  n^2 states; the fastest mode decays at
    about 8/(r c), the slowest at about pi^2/(4 n^2 r c): stiff for n >= 10.

    dT_k/dt = (q_in [k = 1] + sum over neighbours m of (T_m - T_k)/r - T_k/rb [j = n]) / c."""
    return "\n".join([
        f'model grid{n} "{n} x {n} thermal RC grid"',
        f"constant N = {n}",
        "parameter c = 1.0 \"heat capacity of a cell\"",
        "parameter r = 1.0 \"thermal resistance between neighbouring cells\"",
        "parameter rb = 2.0 \"thermal resistance from an edge cell to the ambient\"",
        "parameter q_in = 1.0 \"heat flow into cell 1\"",
        "for k in 1..N*N {",
        "  T[k] : 0",
        "  cap[k] : C(c) init e = 1 + sin(k)",
        "  T[k] -> cap[k]",
        "}",
        "for i in 1..N { for j in 1..N-1 {",
        "  h[(i-1)*(N-1)+j] : 1; hr[(i-1)*(N-1)+j] : R(r)",
        "  T[(i-1)*N+j] -> h[(i-1)*(N-1)+j] -> T[(i-1)*N+j+1]",
        "  h[(i-1)*(N-1)+j] -> hr[(i-1)*(N-1)+j]",
        "} }",
        "for i in 1..N-1 { for j in 1..N {",
        "  v[(i-1)*N+j] : 1; vr[(i-1)*N+j] : R(r)",
        "  T[(i-1)*N+j] -> v[(i-1)*N+j] -> T[i*N+j]",
        "  v[(i-1)*N+j] -> vr[(i-1)*N+j]",
        "} }",
        "for i in 1..N {",
        "  loss[i] : R(rb)",
        "  T[i*N] -> loss[i]",
        "}",
        "heater : Sf(q_in)",
        "heater -> T[1]",
        f"scene cool {{ outputs {', '.join(f'cap[{k}].e' for k in range(1, n * n + 1))}; "
        f"time 0 .. {t_end!r} every {t_end!r}; "
        "solver rodas5p(rtol = 1e-6, atol = 1e-9) }",
    ]) + "\n"


def thermal_grid_rhs(n: int, T, c=1.0, r=1.0, rb=2.0, q_in=1.0):
    """thermal_grid(n)'s right side in temperatures, written from the formula above (numpy,
    T of shape (n*n,) or (n*n, m)): dT/dt."""
    import numpy
    G = numpy.asarray(T, dtype=float).reshape((n, n) + numpy.shape(T)[1:])
    d = numpy.zeros_like(G)
    d[:, :-1] += (G[:, 1:] - G[:, :-1]) / r
    d[:, 1:] += (G[:, :-1] - G[:, 1:]) / r
    d[:-1, :] += (G[1:, :] - G[:-1, :]) / r
    d[1:, :] += (G[:-1, :] - G[1:, :]) / r
    d[:, -1] -= G[:, -1] / rb
    d[0, 0] += q_in
    return (d / c).reshape(numpy.shape(T))


def thermal_grid_cells(m: int) -> str:
    """thermal_grid(n) by its number of states m = n^2 (a perfect square), for the growth fits
    of benchmarks/compile_scale.py."""
    n = math.isqrt(m)
    if n * n != m:
        raise ValueError(f"thermal_grid_cells: {m} is not a square")
    return thermal_grid(n)


def heat_line(n: int, t_end: float = 1.0) -> str:
    """1-D heat conduction (ScalableTestSuite's HeatConduction, one dimension): a rod cut into n
    cells, each a `cell` component (a 0-junction with its heat capacity c, state cell[i].cap.q,
    its temperature cell[i].cap.e, and the thermal resistance r to the next cell), a heater
    feeding q_in into cell 1, the last cell losing heat to an ambient at 0 through rb.  The
    cells start at T0 sin(pi i / n) (every mode excited).  Stiff for large n: the fastest mode
    decays at about 4/(r c), the slowest at about 1/(n^2 r c)."""
    return "\n".join([
        f'model heatline "{n}-cell 1-D heat conduction"',
        f"constant N = {n}",
        'parameter c = 1.0 "heat capacity of a cell"',
        'parameter r = 1.0 "thermal resistance between neighbouring cells"',
        'parameter rb = 2.0 "thermal resistance from the last cell to the ambient"',
        'parameter q_in = 1.0 "heat flow into cell 1"',
        'parameter T0 = 1.0 "the initial temperature profile\'s amplitude"',
        "",
        'component cell(c = 1, r = 1, T0 = 0) "a cell: its capacity, and the resistance to '
        'the next" {',
        "  port a",
        "  port b",
        "  T : 0",
        "  cap : C(c) init e = T0",
        "  h : 1",
        "  res : R(r)",
        "  a -> T -> cap",
        "  T -> h -> b",
        "  h -> res",
        "}",
        "",
        "heater : Sf(q_in)",
        "ambient : Se(0)",
        "for i in 1..N - 1 {",
        "  cell[i] : cell(c, r, T0*sin(3.141592653589793*i/N))",
        "}",
        "cell[N] : cell(c, rb, 0)",
        "heater -> cell[1].a",
        "for i in 2..N {",
        "  cell[i - 1].b -> cell[i].a",
        "}",
        "cell[N].b -> ambient",
        "",
        f"scene cool {{ outputs cell[1].cap.e, cell[N].cap.e; time 0 .. {t_end!r} every "
        f"{t_end / 10!r}; solver rodas5p(rtol = 1e-8, atol = 1e-10) }}",
    ]) + "\n"


def heat_line_matrices(n: int, c=1.0, r=1.0, rb=2.0, q_in=1.0, T0=1.0):
    """heat_line(n) as T' = A T + b in the cells' temperatures, from the formula: (A, b,
    T(0))."""
    import numpy
    A = numpy.zeros((n, n))
    for i in range(n):
        out = r if i < n - 1 else rb
        A[i, i] -= 1 / out
        if i < n - 1:
            A[i, i + 1] += 1 / r
            A[i + 1, i] += 1 / r
            A[i + 1, i + 1] -= 1 / r
    b = numpy.zeros(n)
    b[0] = q_in
    x0 = numpy.array([T0 * math.sin(3.141592653589793 * (i + 1) / n) if i < n - 1 else 0.0
                      for i in range(n)])
    return A / c, b / c, x0


def transmission_line(n: int, t_end: float = 2.0) -> str:
    """ScalableTestSuite's TransmissionLine as a bond graph: a line of n sections, each a
    `section` component (a series inductance l with its resistance rs on a 1-junction, a shunt
    capacitance cc on the next 0-junction), driven by a voltage step V0 through the source's
    resistance rg, terminated by a load rl."""
    return "\n".join([
        f'model line "{n}-section RLC transmission line"',
        f"constant N = {n}",
        'parameter l = 1.0 "inductance of a section"',
        'parameter cc = 1.0 "capacitance of a section"',
        'parameter rs = 0.05 "series resistance of a section"',
        'parameter rg = 1.0 "the source\'s resistance"',
        'parameter rl = 1.0 "the load"',
        'parameter V0 = 1.0 "the step"',
        "",
        'component section(l = 1, cc = 1, rs = 0) "a section: series L and R, shunt C" {',
        "  port a",
        "  port b",
        "  s : 1",
        "  coil : I(l)",
        "  loss : R(rs)",
        "  n : 0",
        "  cap : C(cc)",
        "  a -> s -> n -> b",
        "  s -> coil",
        "  s -> loss",
        "  n -> cap",
        "}",
        "",
        "src : Se(V0)",
        "g : 1",
        "rgen : R(rg)",
        "load : R(rl)",
        "src -> g",
        "g -> rgen",
        "for i in 1..N {",
        "  sec[i] : section(l, cc, rs)",
        "}",
        "g -> sec[1].a",
        "for i in 2..N {",
        "  sec[i - 1].b -> sec[i].a",
        "}",
        "sec[N].b -> load",
        "",
        f"scene step {{ outputs sec[N].cap.e, sec[1].coil.f; time 0 .. {t_end!r} every "
        f"{t_end / 10!r}; solver dopri5(rtol = 1e-10, atol = 1e-12) }}",
    ]) + "\n"


def transmission_line_matrices(n: int, l=1.0, cc=1.0, rs=0.05, rg=1.0, rl=1.0, V0=1.0):
    """transmission_line(n) as x' = A x + b, x = (flux of coil 1, charge of cap 1, ...), from
    the circuit's equations: (A, b, x(0))."""
    import numpy
    A = numpy.zeros((2 * n, 2 * n))
    b = numpy.zeros(2 * n)
    for k in range(n):
        p, q = 2 * k, 2 * k + 1  # coil k's flux (current p/l), cap k's charge (voltage q/cc)
        # flux' = (voltage before) - rs i - (cap k's voltage)
        if k == 0:
            b[p] = V0
            A[p, p] -= rg / l
        else:
            A[p, q - 2] += 1 / cc
        A[p, p] -= rs / l
        A[p, q] -= 1 / cc
        # charge' = i_k - i_(k+1) (the load's current after the last)
        A[q, p] += 1 / l
        if k < n - 1:
            A[q, p + 2] -= 1 / l
        else:
            A[q, q] -= 1 / (rl * cc)
    return A, b, numpy.zeros(2 * n)


def cascaded_first_order(n: int, t_end: float = 2.0) -> str:
    """ScalableTestSuite's CascadedFirstOrder: n first-order lags in series, each a `lag`
    component (a capacitor cc charged through r from an effort source that copies the previous
    lag's voltage: a buffer), the first fed by a unit step; the lags' time constant is
    tau / n (r = tau / n, cc = 1), so the last one's output tends to the step delayed by tau as n
    grows.  x_n(t) = 1 - exp(-s) sum_(k < n) s^k / k!, s = n t / tau."""
    return "\n".join([
        f'model cascade "{n} cascaded first-order lags"',
        f"constant N = {n}",
        'parameter tau = 1.0 "the cascade\'s total time constant"',
        "",
        'component lag(u = 0, r = 1) "a first-order lag of its input u: cap.e\' = (u - cap.e) '
        '/ r" {',
        "  drive : Se(u)",
        "  s : 1",
        "  res : R(r)",
        "  cap : C(1)",
        "  drive -> s",
        "  s -> res",
        "  s -> cap",
        "}",
        "",
        "lag[1] : lag(1, tau/N)",
        "for i in 2..N {",
        "  lag[i] : lag(lag[i - 1].cap.e, tau/N)",
        "}",
        "",
        f"scene step {{ outputs lag[N].cap.e; time 0 .. {t_end!r} every {t_end / 10!r}; "
        "solver dopri5(rtol = 1e-10, atol = 1e-12) }",
    ]) + "\n"


def cascaded_first_order_exact(n: int, t, tau=1.0):
    """The last lag's output of cascaded_first_order(n) at times t, in closed form."""
    import numpy
    s = n * numpy.asarray(t, dtype=float) / tau
    term = numpy.ones_like(s)
    total = numpy.zeros_like(s)
    for k in range(n):
        total += term
        term = term * s / (k + 1)
    return 1 - numpy.exp(-s) * total


def harmonic_oscillators(n: int, t_end: float = 2.0) -> str:
    """ScalableTestSuite's HarmonicOscillator: n independent mass-spring oscillators, each an
    `oscillator` component (a mass m and a spring of stiffness k (1 + i / n) on a 1-junction),
    released at rest from x0 (the spring's charge): x_i(t) = x0 cos(w_i t), w_i = sqrt(k (1 +
    i / n) / m)."""
    return "\n".join([
        f'model oscillators "{n} independent harmonic oscillators"',
        f"constant N = {n}",
        'parameter m = 1.0 "each mass"',
        'parameter k = 100.0 "the first spring\'s stiffness, up to twice it for the last"',
        'parameter x0 = 0.01 "the springs\' initial stretch"',
        "",
        'component oscillator(m = 1, k = 1, x0 = 0) "a mass on a spring" {',
        "  v : 1",
        "  mass : I(m)",
        "  spring : C(1/k) init q = x0",
        "  v -> mass",
        "  v -> spring",
        "}",
        "",
        "for i in 1..N {",
        "  osc[i] : oscillator(m, k*(1 + i/N), x0)",
        "}",
        "",
        f"scene swing {{ outputs osc[1].spring.q, osc[N].spring.q; time 0 .. {t_end!r} every "
        f"{t_end / 10!r}; solver dopri5(rtol = 1e-10, atol = 1e-12) }}",
    ]) + "\n"


FAMILIES = {
    "pendulum_chain": pendulum_chain,
    "pendulum_chain_vector": pendulum_chain_vector,
    "mass_chain": mass_chain,
    "rc_ladder": rc_ladder,
    "resistor_ladder": resistor_ladder,
    "link_chain_field": link_chain_field,
    "rc_ladder_components": rc_ladder_components,
    "rc_ladder_flat_twin": rc_ladder_flat_twin,
    "thermal_grid": thermal_grid,
    "thermal_grid_cells": thermal_grid_cells,
    "heat_line": heat_line,
    "transmission_line": transmission_line,
    "cascaded_first_order": cascaded_first_order,
    "harmonic_oscillators": harmonic_oscillators,
}
