"""The program IR: the statement vocabulary and `Program` (bgc.ir.program, re-exported here),
forward differentiation of statements (tangent), one expression to one line of C or Python
(printers).  Entry: Program, the value bgc.codegen.lower hands on and every emitter reads."""
from ..symbolic import conditions  # noqa: F401 (first: SymPy's Piecewise made safe)
from .program import *  # noqa: F401,F403 (the IR's vocabulary)
