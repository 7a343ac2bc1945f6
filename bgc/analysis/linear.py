"""`bgc linearize`: the state-space matrices A, B, C, D of a model about an operating point,
from the derivatives the compiler derives symbolically (bgc.analysis.operating), not from finite
differences.

    dx = A dx + B du,   dy = C dx + D du      (dx = x - x*, du = u - u*, dy = y - y*)

The point is the scene's initial state, the state of the scene's run at a time T, or an
equilibrium (bgc.steady).  A constrained model is reduced to independent coordinates by
coordinate partitioning: the Jacobian G of the constraint rows (holonomic constraints at
position and velocity level, nonholonomic ones at velocity level) picks, by Gaussian
elimination with complete pivoting, as many dependent states as it has independent rows; the
other states are the independent coordinates z, and the tangent space of the constraint
manifold, G dx = 0, is dx = N z with N = [I; -G_d^-1 G_i] (rows reordered).  With R the
right inverse of G that is zero on the independent states, T = [N R] is a change of
coordinates (its inverse is [S; G], S selecting the independent states) in which

    T^-1 A T = [[S A N, S A R], [G A N, G A R]].

The reduced matrices are A_r = S A N, B_r = S B, C_r = C N, D_r = D; E = G A R is the
constraint error's own dynamics: the corrector's artificial modes (the roots of
s^2 + 2 alpha s + beta^2 for a `pid(alpha, beta)` corrector, 0 and 0 without one).  At an
equilibrium on the constraint manifold the manifold is invariant, G A N = 0, and the full
model's eigenvalues are exactly those of A_r and those of E; elsewhere `coupling` (the norm
of G A N relative to A's) says how far this is from exact.
"""
from __future__ import annotations

import io
import json
import math
import zipfile
from dataclasses import dataclass

import numpy as np

from . import operating
from .operating import AnalysisArgumentError, AnalysisError

FORMATS = ("json", "npz", "csv")
CONTROL_INSTALL = "pip install 'bgc[control]'"


@dataclass(frozen=True)
class Linearization:
    """A, B, C, D about a point; for a constrained model in independent coordinates."""

    states: tuple[str, ...]  # the coordinates of A: the independent states
    inputs: tuple[str, ...]
    outputs: tuple[str, ...]
    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    t: float  # the operating point: its time and every state's value
    point: tuple[tuple[str, float], ...]
    full_states: tuple[str, ...]  # every state of the model
    basis: np.ndarray  # N: x - x* = N z (identity without constraints)
    constraint_rows: tuple[str, ...] = ()  # the independent constraint rows, as E's
    corrector: np.ndarray = None  # E, the constraint error's dynamics (0 x 0 without)
    coupling: float = 0.0  # |G A N| / |A|: 0 where the manifold is invariant
    input_values: tuple[tuple[str, float], ...] = ()  # the inputs given data: their value
    #                                                   there, (name, value) each

    @property
    def eigenvalues(self) -> np.ndarray:
        return _sorted(np.linalg.eigvals(self.A) if self.A.size else np.zeros(0, complex))

    @property
    def corrector_eigenvalues(self) -> np.ndarray:
        E = self.corrector
        return _sorted(np.linalg.eigvals(E) if E is not None and E.size
                       else np.zeros(0, complex))

    def state_space(self):
        """A python-control StateSpace of (A, B, C, D) (ImportError without python-control)."""
        try:
            import control
        except ImportError:
            raise ImportError(f"python-control is not installed: {CONTROL_INSTALL}") from None
        return control.ss(self.A, self.B, self.C, self.D)

    def frequency_response(self, omega) -> np.ndarray:
        """H(i w) = C (i w I - A)^-1 B + D for each w, shape (outputs, inputs, len(omega));
        NaN where i w is an eigenvalue of A."""
        omega = np.atleast_1d(np.asarray(omega, dtype=float))
        n = self.A.shape[0]
        out = np.empty((len(self.outputs), len(self.inputs), len(omega)), dtype=complex)
        for k, w in enumerate(omega):
            try:
                X = np.linalg.solve(1j * w * np.eye(n) - self.A, self.B)
            except np.linalg.LinAlgError:
                out[:, :, k] = np.nan
                continue
            out[:, :, k] = self.C @ X + self.D
        return out

    def as_dict(self) -> dict:
        """The JSON document: states, inputs, outputs, A, B, C, D (row-major lists),
        eigenvalues ([re, im]), at (t and every state's value), and for constrained models
        the full states, the basis N and the corrector's eigenvalues."""
        return {
            "states": list(self.states), "inputs": list(self.inputs),
            "outputs": list(self.outputs),
            "A": _rows(self.A), "B": _rows(self.B), "C": _rows(self.C), "D": _rows(self.D),
            "eigenvalues": _pairs(self.eigenvalues),
            "at": {"t": self.t, **dict(self.point)},
            "full_states": list(self.full_states), "basis": _rows(self.basis),
            "constraint_rows": list(self.constraint_rows),
            "corrector_eigenvalues": _pairs(self.corrector_eigenvalues),
            **({"input_values": dict(self.input_values)} if self.input_values else {}),
        }


def _sorted(eig) -> np.ndarray:
    """Eigenvalues by modulus, then real part, the positive imaginary part of a pair first."""
    return np.array(sorted(eig, key=lambda z: (abs(z), z.real, -z.imag)), dtype=complex)


def _rows(M) -> list:
    return [[float(v) for v in row] for row in np.asarray(M, dtype=float)]


def _pairs(eig) -> list:
    return [[float(z.real), float(z.imag)] for z in eig]


# ---------------------------------------------------------------- the operating point


def parse_at(at) -> tuple[str, float | None]:
    """("initial", None), ("time", T) or ("steady", None) from None, "t=T", a number or
    "steady"; ValueError for anything else."""
    if at is None or at == "initial":
        return "initial", None
    if isinstance(at, (int, float)) and not isinstance(at, bool):
        value = float(at)
    elif isinstance(at, str) and at.strip() == "steady":
        return "steady", None
    elif isinstance(at, str) and at.strip().startswith("t="):
        try:
            value = float(at.strip()[2:])
        except ValueError:
            value = math.nan
    else:
        raise ValueError(f"--at expects t=TIME or steady, got {at!r}")
    if not math.isfinite(value):
        raise ValueError(f"--at t=TIME: {at!r} is not a finite time")
    return "time", value


def operating_point(ev: operating.Evaluator, at, run=None) -> tuple[float, np.ndarray]:
    """(t, x) for `at` (parse_at's forms), ev's discrete values set to a run's there.
    run(T) -> (x, the discrete variables): the scene's run to T (run_to), needed for a time
    after the start."""
    kind, T = parse_at(at)
    if kind == "steady":
        from . import equilibrium
        eq = equilibrium.solve(ev)
        return eq.t, np.array([v for _, v in eq.states])
    if kind == "time" and T < ev.t0:
        raise AnalysisArgumentError(f"--at t={T:g} is before the scene's start t0 = {ev.t0:g}")
    x0 = ev.settle(ev.t0, ev.initial(), start=True)  # the run's first row
    if kind == "initial" or T == ev.t0:
        return ev.t0, x0
    x, held = run(T)
    ev.hold(T, x, held)
    return T, x


MAX_STEPS = 10_000_000  # a run to --at t=T: its steps (an adaptive solver's budget)


def fixed_step(scene) -> float | None:
    """The step of a run of scene's settings if its steps are fixed (a fixed-step solver, or
    a scene's step), bounded by its largest step; None for an adaptive run."""
    from ..base import solvers
    if scene.step is None and solvers.get(scene.solver).adaptive:
        return None
    h = scene.step or scene.dt
    return min(h, scene.max_step) if scene.max_step else h


def run_to(ev: operating.Evaluator, params: dict, T: float, max_steps: int | None = None,
           input_data=None):
    """The state and the discrete variables at T of the scene's run (the C backend when
    there is a C compiler).  Its only output rows are t0's and T's: the rows of the scene's
    grid are not needed, and their number is no bound of the work.  The steps are: at most
    max_steps (default MAX_STEPS; 0: no bound), and a run of fixed steps whose count is
    more is refused before it starts.  input_data: {name: (t, values)}, the declared inputs'
    data the run follows."""
    from .. import api
    from ..execute import runner
    program = ev.analysed.compiled.program
    scene = program.scene
    span = T - ev.t0
    budget = MAX_STEPS if max_steps is None else int(max_steps)
    if not math.isfinite(span):
        raise AnalysisArgumentError(f"--at t={T:g}: the time from the scene's start "
                                    f"t0 = {ev.t0:g} is beyond a double")
    h = fixed_step(scene)
    options = dict(t_end=T, dt=span, max_steps=budget)
    if h is not None:
        steps = span / h
        if budget and not steps <= budget:
            raise AnalysisError(
                f"--at t={T:g}: the scene's steps are fixed (h = {h:g}): reaching t = {T:g} "
                f"takes {_steps_text(math.ceil(steps) if math.isfinite(steps) else steps)}, "
                f"more than the {budget} a run to one time may take (--max-steps raises the "
                "bound)")
        options["step"] = h
    else:
        steps, why = explicit_steps(ev, scene.solver, span)
        if budget and steps > budget:
            raise AnalysisError(
                f"--at t={T:g}: the scene's solver {scene.solver} is explicit, its steps "
                f"bounded by its stability ({why}): reaching t = {T:g} takes "
                f"{_steps_text(steps, 'at least ')}, more than the {budget} a run to one time "
                "may take (--max-steps raises the bound; a stiff solver's steps are not so "
                "bounded)")
    if input_data:
        options["input_data"] = tuple((name, t, u) for name, (t, u) in input_data.items())
    settings = runner.settings_for(scene, [p.name for p in program.params], params,
                                   **options)
    backend, _ = runner.choose_backend("c")
    prepared = runner.prepare(ev.analysed.compiled, backend, in_process=True)
    failures = (prepared.module.SimulationError, prepared.module.ConstraintError) \
        if prepared.module is not None else ()
    try:
        result = runner.run(prepared, settings)
    except failures as error:
        raise AnalysisError(f"the run to t = {T:g} failed: {error}") from None
    if result.status != 0:
        raise AnalysisError(f"the run to t = {T:g} failed: {result.message}")
    _, Y = api.arrays(result)
    where = {name: k for k, name in enumerate(program.outputs)}
    return (np.array([Y[-1, where[s]] for s in program.states]),
            [Y[-1, where[d]] for d in ev.held_names])


def _steps_text(steps: float, least: str = "") -> str:
    """A count of steps for a message: "[at least ]3.03e+09 of them", or where it is beyond
    a double's range, "more of them than a double counts"."""
    if not math.isfinite(steps):
        return "more of them than a double counts"
    return f"{least}{steps:.3g} of them"


def explicit_steps(ev: operating.Evaluator, solver: str, span: float) -> tuple[float, str]:
    """A lower bound of the steps an explicit adaptive solver takes over span, from its
    stability at the start: a step h keeps h lambda inside the method's stability region for
    every eigenvalue lambda of the Jacobian with Re lambda < 0 (past its edge the error
    estimate grows and the step is cut), so h <= reach / |lambda|; and why (the eigenvalue).
    (0, "") for an implicit solver, for auto (which switches to one), and where the
    Jacobian cannot be had."""
    from ..base import solvers
    method = solvers.get(solver)
    if method.family != "erk":
        return 0.0, ""
    try:
        J = ev.jacobian(ev.t0, ev.initial())
        eig = np.linalg.eigvals(J) if J.size and np.all(np.isfinite(J)) else []
    except (AnalysisError, np.linalg.LinAlgError):
        return 0.0, ""
    polynomial = _stability_polynomial(method.tableau)
    best, why, reaches = 0.0, "", {}
    for z in eig:
        if not z.real < 0:
            continue
        angle = round(math.atan2(abs(z.imag), z.real), 2)  # (the region is symmetric)
        if angle not in reaches:
            reaches[angle] = _reach(polynomial, angle)
        reach, size = reaches[angle], float(abs(z))  # (Python floats: inf past a double)
        if reach > 0 and span * size / reach > best:
            best = span * size / reach
            why = f"|lambda| = {size:.3g} at the start, h |lambda| <= {reach:.3g}"
    return best, why


def _stability_polynomial(tableau) -> np.ndarray:
    """The coefficients of R(z) = 1 + sum_k b^T A^(k-1) 1 z^k, lowest first."""
    s = len(tableau.b)
    A = [[float(tableau.a[i][j]) if j < len(tableau.a[i]) else 0.0 for j in range(s)]
         for i in range(s)]
    v, out = np.ones(s), [1.0]
    for _ in range(s):
        out.append(float(np.dot([float(b) for b in tableau.b], v)))
        v = np.array(A) @ v
    return np.array(out)


def _reach(polynomial, angle: float, resolution: float = 1e-2) -> float:
    """How far the stability region |R(z)| <= 1 reaches from 0 along e^(i angle): the last
    r of a scan (step `resolution`, as far as 2 s^2 for a polynomial of degree s, beyond
    which no explicit method's region reaches) before |R| exceeds 1; 0 if it does at once."""
    r = np.arange(1, int(2 * len(polynomial) ** 2 / resolution)) * resolution
    z = r * complex(math.cos(angle), math.sin(angle))
    R = np.polynomial.polynomial.polyval(z, polynomial)
    out = np.nonzero(np.abs(R) > 1 + 1e-12)[0]
    return float(r[out[0] - 1]) if len(out) and out[0] > 0 else \
        (0.0 if len(out) else float(r[-1]))


# ---------------------------------------------------------------- the reduction


def partition(G: np.ndarray, tol: float = 1e-10) -> tuple[list[int], list[int]]:
    """(independent rows, dependent columns) of G by Gaussian elimination with complete
    pivoting (ties: the first in row-major order); pivots below tol * max|G| end it."""
    M = np.array(G, dtype=float)
    rows, cols = list(range(M.shape[0])), list(range(M.shape[1]))
    scale = np.abs(M).max() if M.size else 0.0
    free_r, free_c = list(rows), list(cols)
    piv_r, piv_c = [], []
    while free_r and free_c:
        sub = np.abs(M[np.ix_(free_r, free_c)])
        i, j = np.unravel_index(np.argmax(sub), sub.shape)
        if not sub[i, j] > tol * scale:
            break
        r, c = free_r[i], free_c[j]
        for k in free_r:
            if k != r:
                M[k] -= M[k, c] / M[r, c] * M[r]
        piv_r.append(r)
        piv_c.append(c)
        free_r.remove(r)
        free_c.remove(c)
    return sorted(piv_r), sorted(piv_c)


def reduction(G: np.ndarray, n: int):
    """(independent states, N, R, the rows of G used): see the module's doc."""
    rows, dep = partition(G)
    ind = [k for k in range(n) if k not in dep]
    N = np.zeros((n, len(ind)))
    R = np.zeros((n, len(dep)))
    N[ind, range(len(ind))] = 1.0
    if dep:
        Gr = G[rows]
        Gd = Gr[:, dep]
        N[dep] = -np.linalg.solve(Gd, Gr[:, ind])
        R[dep] = np.linalg.inv(Gd)
    return ind, N, R, rows


def linearization(ev: operating.Evaluator, t: float, x, input_data=None) -> Linearization:
    """A, B, C, D of ev's model at (t, x), reduced to independent coordinates when it has
    constraints; input_data ({name: (t, values)}): the inputs given data at their values
    at t (ev's discrete values set to them)."""
    x = np.asarray(x, dtype=float)
    values = ev.set_inputs(t, input_data) if input_data else ()
    A = ev.jacobian(t, x)
    Cfull = ev.output_jacobian(t, x)
    Bfull, Dfull = ev.input_jacobians(t, x)
    k = len(ev.analysed.outputs)
    C, D = Cfull[:k], Dfull[:k]
    n = ev.n
    for what, M, rows, cols in (("A", A, ev.states, ev.states),
                                ("B", Bfull, ev.states, ev.analysed.inputs),
                                ("C", Cfull, ev.analysed.compiled.program.outputs, ev.states),
                                ("D", Dfull, ev.analysed.compiled.program.outputs,
                                 ev.analysed.inputs)):
        bad = np.argwhere(~np.isfinite(M))
        if bad.size:
            i, j = bad[0]
            raise AnalysisError(
                f"at t = {t:.17g} the linearisation is not finite: {what}[{i}, {j}] = "
                f"d({rows[i] if i < len(rows) else i})/d({cols[j] if j < len(cols) else j})"
                f" is {M[i, j]} (a law without a finite derivative there: give another "
                "point with --at)")
    point = tuple(zip(ev.states, (float(v) for v in x)))
    common = dict(inputs=ev.analysed.inputs, outputs=ev.analysed.outputs, t=float(t),
                  point=point, full_states=ev.states, input_values=values)
    if not ev.constraints:
        return Linearization(ev.states, A=A, B=Bfull, C=C, D=D, basis=np.eye(n),
                             corrector=np.zeros((0, 0)), **common)
    G, _ = ev.constraint_rows(t, x)
    if not np.all(np.isfinite(G)):
        raise AnalysisError(f"at t = {t:.17g} the constraints' Jacobian is not finite")
    ind, N, R, rows = reduction(G, n)
    Gr = G[rows]
    E = Gr @ A @ R
    norm = np.abs(A).max() or 1.0
    coupling = float(np.abs(Gr @ A @ N).max() / norm) if N.size and rows else 0.0
    names = ev.constraint_names()
    return Linearization(tuple(ev.states[i] for i in ind), A=A[ind] @ N, B=Bfull[ind],
                         C=C @ N, D=D, basis=N, constraint_rows=tuple(names[r] for r in rows),
                         corrector=E, coupling=coupling, **common)


def linearize(model, scene=None, at=None, inputs=None, outputs=None, params=None,
              effects=None, algebra="auto", max_steps=None, input_data=None) -> Linearization:
    """The linearisation of model's scene (bgc.linearize; see the module's doc): at the
    initial state (at=None), at "t=T" (or a number T) of the scene's run, or at "steady".
    inputs: names of the model's inputs (`input NAME`, at their defaults) or of parameters
    (None: the model's inputs); outputs, effects: as a scene's (default: the scene's);
    params: {name: value} overrides; algebra: as bgc.build's; max_steps: the run to T's
    (run_to); input_data: {name: (t, values)}, data of the model's inputs (as bgc.simulate's
    inputs=): the run to T follows them, and the point takes their values at its time."""
    analysed = operating.build(model, scene, outputs, effects,
                               None if inputs is None else tuple(inputs), algebra)
    ev = operating.Evaluator(analysed, params)
    data = check_input_data(analysed, input_data, at)
    t, x = operating_point(ev, at, lambda T: run_to(ev, dict(params or {}), T, max_steps,
                                                    data))
    return linearization(ev, t, x, data)


def check_input_data(analysed: operating.Analysed, input_data, at) -> dict:
    """input_data ({name: (t, values)}) checked: the model's declared inputs, a pair of
    finite numbers as many, t non-decreasing; not with at="steady" (data are a time
    source); AnalysisArgumentError for people."""
    from ..base.run_settings import input_data as checked_data
    if not input_data:
        return {}
    if at is not None and parse_at(at)[0] == "steady":
        raise AnalysisArgumentError(
            "--at steady with --input: an input's data are a time source, so the model has "
            "no equilibrium to linearise about; linearise about a point of the run with "
            "--at t=TIME")
    names = [u.name for u in analysed.compiled.program.inputs]
    for name in input_data:
        if name not in names:
            raise AnalysisArgumentError(f"unknown input {name!r} (inputs: "
                                        f"{', '.join(names) or 'none'})")
    try:
        checked = checked_data(dict(input_data))
    except (TypeError, ValueError) as error:
        raise AnalysisArgumentError(str(error)) from None
    return {name: (ts, us) for name, ts, us in checked}


# ---------------------------------------------------------------- reports and files


def modes_table(lin: Linearization) -> str:
    """The eigenvalues with their natural frequencies and damping ratios, then the
    corrector's modes apart."""
    lines = [f"linearised at t = {lin.t:.6g}: {len(lin.states)} states"
             + (f" (independent coordinates: {', '.join(lin.states)})"
                if len(lin.states) < len(lin.full_states) else "")
             + f", {_count(lin.inputs, 'input')}, {_count(lin.outputs, 'output')}"]
    if lin.input_values:
        lines.append(f"inputs from their data at t = {lin.t:.6g}: " + ", ".join(
            f"{name} = {value:.17g}" for name, value in lin.input_values))
    lines += _modes(lin.eigenvalues)
    if lin.corrector is not None and lin.corrector.size:
        lines.append(f"corrector modes (artificial, of the constraint rows "
                     f"{', '.join(lin.constraint_rows)}):")
        lines += _modes(lin.corrector_eigenvalues)
        if lin.coupling > 1e-9:
            lines.append(f"note: not at an equilibrium, the constraint manifold is not "
                         f"invariant here (coupling {lin.coupling:.3g}); the split into "
                         "independent and corrector modes is approximate")
    return "\n".join(lines) + "\n"


def _count(items, what: str) -> str:
    return f"{len(items)} {what}{'' if len(items) == 1 else 's'}"


def _modes(eig) -> list[str]:
    """One line per eigenvalue (parts below 1e-12 of its modulus shown as 0)."""
    out = [f"  {'eigenvalue':>30}  {'frequency (rad/s)':>18}  {'damping':>10}"]
    for z in eig:
        wn = abs(z)
        z = complex(*(0.0 if abs(v) <= 1e-12 * wn else v for v in (z.real, z.imag)))
        zeta = f"{-z.real / wn + 0.0:10.6g}" if wn > 0 else f"{'-':>10}"
        out.append(f"  {_complex(z):>30}  {wn:18.6g}  {zeta}")
    return out


def _complex(z: complex) -> str:
    if z.imag == 0:
        return f"{z.real:.9g}"
    return f"{z.real:.9g} {'+' if z.imag > 0 else '-'} {abs(z.imag):.9g}i"


def check_format(path: str) -> str:
    """The file format of -o from its suffix; ValueError if none of FORMATS."""
    fmt = str(path).rsplit(".", 1)[-1].lower() if "." in str(path) else ""
    if fmt not in FORMATS:
        raise ValueError(f"'{path}': the file name must end in "
                         + ", ".join("." + f for f in FORMATS))
    return fmt


def to_json(lin: Linearization) -> str:
    """as_dict as JSON, one key a line."""
    return json_lines(lin.as_dict())


def json_lines(d: dict) -> str:
    """A JSON object with one key a line, each value compact."""
    return "{\n" + ",\n".join(f" {json.dumps(k)}: {json.dumps(v)}" for k, v in d.items()) \
        + "\n}\n"


def to_csv(lin: Linearization) -> str:
    """One row per entry: matrix,row,column,value (the names of the rows and columns; the
    eigenvalues' rows numbered, their columns re and im; `at`'s column `value`)."""
    lines = ["matrix,row,column,value"]

    def add(label, M, rows, cols):
        for i, r in enumerate(rows):
            for j, c in enumerate(cols):
                lines.append(f"{label},{_field(r)},{_field(c)},{float(M[i][j]):.17g}")
    add("A", lin.A, lin.states, lin.states)
    add("B", lin.B, lin.states, lin.inputs)
    add("C", lin.C, lin.outputs, lin.states)
    add("D", lin.D, lin.outputs, lin.inputs)
    eig = lin.eigenvalues
    add("eigenvalue", [[z.real, z.imag] for z in eig], [str(k) for k in range(len(eig))],
        ["re", "im"])
    add("at", [[lin.t]] + [[v] for _, v in lin.point], ["t"] + [s for s, _ in lin.point],
        ["value"])
    return "\n".join(lines) + "\n"


def _field(name: str) -> str:
    return f'"{name}"' if "," in name or '"' in name else name


NPZ_MATRICES = ("A", "B", "C", "D", "basis")  # as_dict's keys held as the arrays themselves


def npz_arrays(lin: Linearization) -> dict:
    """Every key of as_dict as an array, in its order: the matrices as they are (their shapes
    kept when empty), eigenvalues as (n, 2) of re and im, names as strings, and `at` as
    at_t, at_states and at_values."""
    arrays = {}
    for key, value in lin.as_dict().items():
        if key == "at":
            arrays.update(at_t=np.array(lin.t),
                          at_states=np.array([s for s, _ in lin.point], dtype=str),
                          at_values=np.array([v for _, v in lin.point], dtype=float))
        elif key in NPZ_MATRICES:
            arrays[key] = np.asarray(getattr(lin, key), dtype=float)
        elif key.endswith("eigenvalues"):
            arrays[key] = np.array(value, dtype=float).reshape(-1, 2)
        else:
            arrays[key] = np.array(value, dtype=str)
    return arrays


def to_npz(lin: Linearization) -> bytes:
    """The arrays of as_dict (npz_arrays) in an .npz archive, written with fixed time stamps
    (the same linearisation gives the same bytes)."""
    arrays = npz_arrays(lin)
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as z:
        for name, value in arrays.items():
            data = io.BytesIO()
            np.lib.format.write_array(data, np.asarray(value), allow_pickle=False)
            z.writestr(zipfile.ZipInfo(name + ".npy", date_time=(1980, 1, 1, 0, 0, 0)),
                       data.getvalue(), zipfile.ZIP_DEFLATED)
    return buf.getvalue()


def render(lin: Linearization, fmt: str) -> str | bytes:
    return {"json": to_json, "csv": to_csv, "npz": to_npz}[fmt](lin)


def frequencies(lin: Linearization, points: int = 400) -> np.ndarray:
    """A logarithmic grid two decades around the moduli of the nonzero eigenvalues."""
    mods = [abs(z) for z in lin.eigenvalues if abs(z) > 1e-12] or [1.0]
    lo, hi = math.floor(math.log10(min(mods))) - 1, math.ceil(math.log10(max(mods))) + 1
    return np.logspace(lo, hi, points)


def bode(lin: Linearization, target, fmt: str = "png", units: dict | None = None) -> None:
    """The Bode plot of every input-output pair into target (a file name or a binary file);
    AnalysisArgumentError without inputs or outputs.  units: of the inputs and outputs by
    name (bgc.api.units): each pair's gain unit in its label (dB of |H| in it)."""
    from ..front.units import ratio
    units = units or {}
    if not lin.inputs or not lin.outputs:
        raise AnalysisArgumentError("a Bode plot needs an input and an output: name the input "
                                    "with --inputs (an input or a parameter)")
    from ..reports import plot
    plt = plot.pyplot()
    w = frequencies(lin)
    H = lin.frequency_response(w)
    fig, (mag, phase) = plt.subplots(2, 1, sharex=True, figsize=(7, 5.5))
    with np.errstate(divide="ignore", invalid="ignore"):
        for i, y in enumerate(lin.outputs):
            for j, u in enumerate(lin.inputs):
                h = H[i, j]
                gain = ratio(units.get(y), units.get(u))
                label = plot.shorten(f"{u} → {y}") + (f" [{gain}]" if gain else "")
                mag.semilogx(w, 20 * np.log10(np.abs(h)), label=label)
                phase.semilogx(w, np.degrees(np.unwrap(np.angle(h))), label=label)
    mag.set_ylabel("magnitude (dB of |H| in the gain's unit)")
    phase.set_ylabel("phase (deg)")
    phase.set_xlabel("frequency ω (rad/s)")
    mag.set_title(f"Bode plot, linearised at t = {lin.t:.6g}")
    for ax in (mag, phase):
        plot.style(ax)
    mag.legend(fontsize="small")
    fig.tight_layout()
    plot.save(fig, target, fmt)
