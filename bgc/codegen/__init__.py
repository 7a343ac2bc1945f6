"""Code generation: lower (Program), sensitivity, emit (C, Python), vm (the interpreter's program),
fmu.  Entry: lower.lower, then emit."""
from ..symbolic import conditions  # noqa: F401 (first: SymPy's Piecewise made safe)
