"""Code generation: lower (Program), sensitivity, emit (C, Python), vm (the interpreter's program),
fmu.  Entry: lower.lower, then emit."""
