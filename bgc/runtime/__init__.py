"""bgc's runtimes: the model-independent code of every generated program, as plain source files
inlined verbatim by bgc.codegen.emit: C (api.h, the declarations; runtime.c, drive.c, erk.c, stiff.c,
main.c, batch.c) and Python (runtime.py, main.py, drive.py, erk.py, stiff.py, batch.py: parts
named after their C twins that bgc.codegen.emit.python_runtime joins into one module, whose
head, runtime.py's, is its contract with the model part)."""
