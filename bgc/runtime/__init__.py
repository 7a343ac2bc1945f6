"""bgc's runtimes: the model-independent code of every generated program, as plain source files
inlined verbatim by bgc.emit: C (api.h, the declarations; runtime.c, drive.c, erk.c, stiff.c,
main.c, batch.c) and Python (runtime.py, a module of its own whose head is its contract
with the model part)."""
