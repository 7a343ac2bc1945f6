"""bgc's runtimes: the model-independent code of every generated program, as plain source files
(runtime.c with its declarations api.h, and runtime.py), inlined verbatim by bgc.emit."""
