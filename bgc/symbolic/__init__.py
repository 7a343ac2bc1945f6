"""Symbolic machinery on SymPy expressions and integer structures: law inversion and tests,
canonical sums and products, forward differentiation, BLT and tearing, sparse LU plans,
orthogonal bases."""
