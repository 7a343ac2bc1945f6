"""Symbolic machinery on SymPy expressions and integer structures: law inversion and tests,
canonical sums and products, forward differentiation, BLT and tearing, sparse LU plans,
orthogonal bases."""
from . import conditions  # noqa: F401 (first: SymPy's Piecewise made safe, bgc.symbolic.conditions)
