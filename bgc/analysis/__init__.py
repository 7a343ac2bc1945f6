"""Analysis on top of the pipeline: linearize (linear, operating), steady (equilibrium), fit and
sensitivities (estimate), accuracy, stability."""
from ..symbolic import conditions  # noqa: F401 (first: SymPy's Piecewise made safe)
