"""The solvers bgc's runtimes provide, described once.

Every solver name, its family, its order and its coefficients live here and nowhere else: the
scene stage checks names against SOLVERS, the command line offers them, and the emitters print
the tables below into each generated program (C: static const arrays and an enum; Python: a
tuple of dicts), where the runtimes' step functions read them.  Adding a solver of an existing
family is one entry here; a new family is an entry plus its step function in both runtimes
(bgc/runtime/).

Coefficients (bgc/base/tableaux.py, imported when first read) are the published methods' and are
written as decimal (or exact rational) strings; the derived tables (the polynomials of the dense
output) are computed from them in exact rational arithmetic and rounded once, so the generated
bytes do not depend on the platform (vern7's, fixed by its stages through the order conditions, are
given as decimals).

Families:
  erk         explicit Runge-Kutta; with error weights an embedded pair, with step-size
              control (Hairer's controller, optional Lund stabilisation) and dense output by a
              continuous extension, else a fixed-step method.
  rosenbrock  linearly implicit (Rosenbrock-Wanner) in Hairer's transformed form: each stage
              solves (I/(gamma h) - J) k_i = f(t + c_i h, y + sum a_ij k_j)
              + sum C_ij k_j / h + h d_i df/dt with the Jacobian J of the step's start.
  radau       Radau IIA (s = 3, 5 or 7 stages, order 2s - 1), Hairer's RADAU5 and RADAU design:
              simplified Newton on the transformed stage system (one real and (s - 1)/2
              complex factorisations), Jacobian and factorisation reuse, error estimate by an
              extra solve, collocation dense output.  The tableau is a tuple of stage sets,
              lowest first; with more than one the order varies (RADAU's strategy: up while the
              Newton iteration contracts fast and the step size settles, down when it
              contracts slowly or fails); a fixed step (--step) runs the first.
  auto        explicit until its stiffness test fires, then the stiff method named in `stiff`.
"""
from __future__ import annotations

from dataclasses import dataclass, field


@dataclass(frozen=True)
class Control:
    """Step-size control: h_new = h / fac, fac = clamp(err^expo / facold^beta / safe) between
    1/fac_max and 1/fac_min, expo = 1/q - expo_beta * beta, for a pair whose estimate is of
    order q - 1: Hairer's controllers of DOPRI5 (expo_beta 0.75) and DOP853 (0.2) with Lund's
    stabilisation (beta > 0; beta = 0 is the plain controller).  The stiff families use
    Gustafsson's predictive controller with these bounds."""

    safe: float
    fac_min: float
    fac_max: float
    beta: float
    q: int  # order of the error estimate + 1
    expo_beta: float = 0.75


@dataclass(frozen=True)
class Stiffness:
    """Hairer's stiffness test for an explicit pair: stages i and j are evaluated at the same
    time, h |f(Y_i) - f(Y_j)| / |Y_i - Y_j| estimates h |lambda|; above `bound` (the edge of
    the stability region) on 15 of the last accepted steps, the problem is stiff."""

    stage_i: int
    stage_j: int
    bound: float


@dataclass(frozen=True)
class Solver:
    name: str
    family: str  # fixed | erk | rosenbrock | radau | auto
    order: int
    summary: str
    tableau_name: object = None  # its tableau's name in bgc.base.tableaux (radau: a tuple of them)
    control: Control | None = None
    stiffness: Stiffness | None = None
    explicit: str | None = None  # auto: the explicit method it starts with ...
    stiff: str | None = None  # ... and the stiff one it switches to
    uses_jacobian: bool = False
    references: tuple = field(default=())
    for_fixed_steps: bool = False  # meant for --step (ros2): `bgc accuracy` sweeps its step

    @property
    def swept_by_step(self) -> bool:
        """Whether `bgc accuracy` sweeps the method's step rather than its tolerance."""
        return self.family == "fixed" or self.for_fixed_steps

    @property
    def adaptive(self) -> bool:
        return self.family != "fixed"

    @property
    def tableau(self):
        """Its coefficients (bgc.base.tableaux, imported on first use): an ERKTableau, a
        RosenbrockTableau, a tuple of RadauTableau, or None (auto)."""
        if self.tableau_name is None:
            return None
        from . import tableaux
        if isinstance(self.tableau_name, tuple):
            return tuple(getattr(tableaux, k) for k in self.tableau_name)
        return getattr(tableaux, self.tableau_name)


# ---------------------------------------------------------------- the registry

_HAIRER_I = "Hairer, Norsett & Wanner, Solving Ordinary Differential Equations I (1993)"
_HAIRER_II = "Hairer & Wanner, Solving Ordinary Differential Equations II (1996)"
_HAIRER_1999 = ("Hairer & Wanner, Stiff differential equations solved by Radau methods, "
                "Journal of Computational and Applied Mathematics 111 (1999)")
_STEINEBACH = ("Steinebach, Construction of Rosenbrock-Wanner method Rodas5P and numerical "
               "benchmarks within the Julia Differential Equations package, BIT Numerical "
               "Mathematics 63 (2023)")
_VERWER = ("Verwer, Spee, Blom & Hundsdorfer, A second-order Rosenbrock method applied to "
           "photochemical dispersion problems, SIAM Journal on Scientific Computing 20 (1999)")
_VERNER = ("Verner, Numerically optimal Runge-Kutta pairs with interpolants, Numerical "
           "Algorithms 53 (2010)")

SOLVER_LIST = (
    Solver("euler", "fixed", 1, "explicit Euler, fixed step", "_EULER"),
    Solver("rk4", "fixed", 4, "classical Runge-Kutta, fixed step", "_RK4"),
    Solver("dopri5", "erk", 5, "Dormand-Prince 5(4), adaptive, dense output of order 4",
           "_DOPRI5", Control(0.9, 0.2, 10.0, 0.04, 5), Stiffness(5, 6, 3.25),
           references=(_HAIRER_I,)),
    Solver("vern7", "erk", 7,
           "Verner 7(6), adaptive, dense output of order 7: moderate to tight tolerances",
           "_VERN7", Control(0.9, 0.333, 6.0, 0.04, 7), references=(_VERNER,)),
    Solver("dop853", "erk", 8,
           "Dormand-Prince 8(5,3), adaptive, dense output of order 7: tight tolerances",
           "_DOP853", Control(0.9, 0.333, 6.0, 0.04, 8, 0.2), references=(_HAIRER_I,)),
    Solver("ros2", "rosenbrock", 2,
           "Rosenbrock 2(1), L-stable, two stages: stiff plants at a fixed step (--step, the "
           "embedded target); the Jacobian every step", "_ROS2",
           Control(0.9, 0.2, 6.0, 0.0, 2), uses_jacobian=True, references=(_VERWER,),
           for_fixed_steps=True),
    Solver("rodas4", "rosenbrock", 4,
           "Rosenbrock 4(3), L-stable, stiff; the Jacobian every step", "_RODAS4",
           Control(0.9, 0.2, 6.0, 0.0, 4), uses_jacobian=True, references=(_HAIRER_II,)),
    Solver("radau5", "radau", 5,
           "Radau IIA of order 5, implicit, L-stable, stiff; Jacobian and factorisations "
           "reused", ("_RADAU_3",), Control(0.9, 0.2, 8.0, 0.0, 4), uses_jacobian=True,
           references=(_HAIRER_II,)),
    Solver("rodas5p", "rosenbrock", 5,
           "Rosenbrock 5(4), L-stable, stiff; the Jacobian every step", "_RODAS5P",
           Control(0.9, 0.2, 6.0, 0.0, 5), uses_jacobian=True, references=(_STEINEBACH,)),
    Solver("radau9", "radau", 9,
           "Radau IIA of order 9 (5 stages), implicit, L-stable, stiff: tight tolerances",
           ("_RADAU_5",), Control(0.9, 0.2, 8.0, 0.0, 4), uses_jacobian=True,
           references=(_HAIRER_II, _HAIRER_1999)),
    Solver("radau13", "radau", 13,
           "Radau IIA of order 13 (7 stages), implicit, L-stable, stiff: very tight tolerances",
           ("_RADAU_7",), Control(0.9, 0.2, 8.0, 0.0, 4), uses_jacobian=True,
           references=(_HAIRER_II, _HAIRER_1999)),
    Solver("radau", "radau", 13,
           "Radau IIA of variable order 5, 9, 13 (Hairer's RADAU): the order follows the "
           "Newton iteration's convergence; stiff, any tolerance",
           ("_RADAU_3", "_RADAU_5", "_RADAU_7"), Control(0.9, 0.2, 8.0, 0.0, 4),
           uses_jacobian=True, references=(_HAIRER_II, _HAIRER_1999)),
    Solver("auto", "auto", 5,
           "dopri5 until its stiffness test fires, then radau (variable order) for the rest "
           "of the run", None, explicit="dopri5", stiff="radau", uses_jacobian=True),
)

SOLVERS = {s.name: s for s in SOLVER_LIST}
NAMES = tuple(SOLVERS)
FAMILIES = ("fixed", "erk", "rosenbrock", "radau", "auto")
DEFAULT = "dopri5"


def get(name: str) -> Solver:
    return SOLVERS[name]


def index(name: str) -> int:
    """The solver's number in the generated programs (BGC_SOLVER_<NAME>)."""
    return NAMES.index(name)


def names_text(conjunction: str = "or") -> str:
    """'euler, rk4, ... or auto' for messages."""
    return ", ".join(NAMES[:-1]) + f" {conjunction} " + NAMES[-1]


def __getattr__(name: str):
    """The tableaux' types (ERKTableau, RosenbrockTableau, RadauTableau), from bgc.base.tableaux."""
    if name in ("ERKTableau", "RosenbrockTableau", "RadauTableau"):
        from . import tableaux
        return getattr(tableaux, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
