"""The middle: scene, causality (SCAP), the equation system (system), reduce (the sorted, pruned
program), contact and groups (switched elements' events and modes).  Entry: its stages in
order, scene.apply_scene -> causality.assign_causality -> system.build_equations ->
reduce.reduce, a Graph to the Reduced program that bgc.codegen.lower reads."""
from ..symbolic import conditions  # noqa: F401 (first: SymPy's Piecewise made safe)
