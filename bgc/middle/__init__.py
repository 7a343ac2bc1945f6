"""The middle: scene, causality (SCAP), the equation system (system), reduce (the sorted, pruned
program), contact (switched elements' events).  Entry: reduce.reduce."""
from ..symbolic import conditions  # noqa: F401 (first: SymPy's Piecewise made safe)
