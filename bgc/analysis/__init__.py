"""Analysis on top of the pipeline: linearize (linear, operating), steady (equilibrium),
periodic, fit and sensitivities (estimate), accuracy, stability.  Entry: one per analysis,
each the API's function of its name (linear.linearize, equilibrium.steady, periodic.periodic,
estimate.fit, estimate.sensitivities); accuracy serves `bgc accuracy`, stability the
warnings of a fixed step."""
from ..symbolic import conditions  # noqa: F401 (first: SymPy's Piecewise made safe)
