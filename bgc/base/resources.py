"""What bgc reads besides the model, and how much of a model it takes on.

grammar/ and templates/ sit inside the package once installed (bgc/grammar, bgc/templates, see
pyproject.toml), beside it in a source tree.

The limits below are checked before the work they bound, never by a timer: input beyond them is
refused with a located message (or, for symbolic work, handed to the generated code's numeric
solvers instead), so that no model can make bgc hang, exhaust memory or recurse without end.
"""
from __future__ import annotations

import gc
import threading
from contextlib import contextmanager
from math import comb
from pathlib import Path

PACKAGE_DIR = Path(__file__).resolve().parent.parent  # the package bgc

# the model text
MAX_SOURCE_BYTES = 1 << 20  # 1 MiB: larger input is refused, not read
MAX_REFERENCE_BYTES = 64 << 20  # a reference CSV (bgc accuracy --reference): 64 MiB
MAX_NESTING = 100  # levels of nested brackets / operators of different kinds
MAX_OPTION_CHARS = 1 << 16  # --outputs, --effects
MAX_LITERAL_DIGITS = 309  # an integer literal longer than this does not fit a double
MAX_DIMENSION = 10_000  # KIND[n]: the components of one multiport
MAX_SCALAR_PARTS = 50_000  # scalar elements, signals and bonds once multiports are split
MAX_MATRIX_ENTRIES = 100_000  # vector and matrix entries (and products) the expressions build
MAX_EXTREMUM_ARGUMENTS = 32  # of one min() or max(): each one's derivative names all the others
MAX_INSTANCE_DEPTH = 32  # components instantiating components, levels deep
MAX_GENERATED = 100_000  # declarations and bonds that components and `for` loops make in all
#                           (a loop charges its body once per pass before expanding it, and
#                           each statement again as it is made: about 50 000 statements)
MAX_SCENES = 100  # of one model (`bgc check` builds each)
MAX_OUTPUT_ROWS = 10 ** 9  # rows of one run's CSV (the generated programs refuse more too)

# symbolic work: one expression as SymPy walks it (a tree, shared subexpressions counted
# every time they occur; most SymPy functions recurse once per level)
MAX_EXPRESSION_NODES = 20_000
MAX_EXPRESSION_DEPTH = 200
MAX_EXPANDED_TERMS = 5_000  # the terms that expanding products and powers may produce
MAX_SYMBOLIC_EXPONENT = 64  # of x^n, n an integer: SymPy expands (re + i im)^n to decide
#                             whether a power is real, minutes for n = 1000
SYMBOLIC_MAX_BLOCK = 12  # unknowns of a block that `--algebra symbolic` solves by LU
MAX_GCD_BITS = 4096  # the integers SymPy's heuristic gcd would build to cancel a fraction
#                      (bgc.symbolic.algebra.gcd_bits): past this, the fraction is not cancelled. 
# They                      grow by a factor per variable, 2^N for a sum of N reciprocals: minutes
#                      at N = 30, where the models' own fractions need under 20 bits


# the garbage collector during a compile: what exists when it starts (the imported modules,
# SymPy's caches) is frozen out of the collector's walks, and the youngest generation is
# collected every COMPILE_GC_THRESHOLD allocations instead of 700.  The compiler makes few
# reference cycles, and walking every live expression again and again cost a fifth of a
# large model's compile (benchmarks/compile_scale.py measures it).
COMPILE_GC_THRESHOLD = 100_000
_collector = threading.local()


@contextmanager
def quiet_collector():
    """Within: the collector as a compile wants it (above); nested uses are the outer one's.
    The collector's state is restored when the outermost use ends."""
    depth = getattr(_collector, "depth", 0)
    _collector.depth = depth + 1
    if depth or threading.current_thread() is not threading.main_thread():
        try:  # (the collector is the process's: only the main thread's outermost use sets it)
            yield
        finally:
            _collector.depth = depth
        return
    threshold = gc.get_threshold()
    gc.freeze()
    gc.set_threshold(COMPILE_GC_THRESHOLD, *threshold[1:])
    try:
        yield
    finally:
        _collector.depth = depth
        gc.set_threshold(*threshold)
        gc.unfreeze()


def resource_dir(name: str) -> Path:
    """The directory `name` ("grammar" or "templates")."""
    for candidate in (PACKAGE_DIR / name, PACKAGE_DIR.parent / name):
        if candidate.is_dir():
            return candidate
    raise FileNotFoundError(f"bgc is installed without its {name}/ directory")


def read_bounded(path: str, limit: int = MAX_SOURCE_BYTES) -> bytes:
    """The bytes of a file, at most limit + 1 of them (a longer file, /dev/zero or a pipe that
    never ends is read no further); OSError as open() and read() raise it."""
    with open(path, "rb") as fh:
        return fh.read(limit + 1)


def fits(expr, nodes: int = MAX_EXPRESSION_NODES, depth: int = MAX_EXPRESSION_DEPTH) -> bool:
    """Whether expr, walked as a tree, has at most `nodes` nodes and `depth` levels.  The walk
    stops at the first node past either limit, so the answer costs at most `nodes` steps."""
    count, stack = 0, [(expr, 1)]
    while stack:
        e, level = stack.pop()
        count += 1
        if count > nodes or level > depth:
            return False
        stack.extend((a, level + 1) for a in e.args)
    return True


def expanded_terms(expr, limit: int = MAX_EXPANDED_TERMS) -> int:
    """An upper bound of the terms that sp.expand(expr) builds: sums add, products multiply,
    a sum of k terms to the integer power n gives C(n+k-1, k-1) terms, and the arguments of a
    function are expanded inside it.  Counted only to limit + 1; expr must fit (see fits)."""
    top: dict = {}  # the terms of each subexpression, once expanded
    inside = 0  # the terms built inside functions
    stack = [(expr, False)]
    while stack:
        e, ready = stack.pop()
        if e in top:
            continue
        if not e.args:
            top[e] = 1
            continue
        if not ready:
            stack.append((e, True))
            stack.extend((a, False) for a in e.args if a not in top)
            continue
        parts = [top[a] for a in e.args]
        if e.is_Add:
            n = sum(parts)
        elif e.is_Mul:
            n = 1
            for p in parts:
                n = min(n * p, limit + 1)
        elif e.is_Pow and e.exp.is_Integer:
            k, p = parts[0], min(abs(int(e.exp)), limit + 1)
            n = comb(p + k - 1, k - 1) if k <= limit else limit + 1
        else:
            n, inside = 1, min(inside + sum(parts), limit + 1)
        top[e] = min(n, limit + 1)
    return min(top[expr] + inside, limit + 1)
