"""Code generation: lower (Program), sensitivity, emit (C, Python), vm (the interpreter's program),
fmu, embedded.  Entry: lower.lower (Reduced -> Program), then emit.emit_c or emit.emit_python
({filename: text}); vm.program_bytes, fmu and embedded for the other targets."""
from ..symbolic import conditions  # noqa: F401 (first: SymPy's Piecewise made safe)
