"""Symbolic machinery on SymPy expressions and integer structures: law inversion and tests
(algebra), canonical sums and products (canonical), forward differentiation (differentiate),
the one tree walk (walk), BLT and tearing (blt), sparse LU plans (sparse), orthogonal bases
(orthogonal), Piecewise conditions (conditions).  A library, not a stage: no one entry, each
module is read by name."""
from . import conditions  # noqa: F401 (first: SymPy's Piecewise made safe, bgc.symbolic.conditions)
