"""What bgc reads besides the model, and how much of a model it takes on.

grammar/ and templates/ sit inside the package once installed (bgc/grammar, bgc/templates, see
pyproject.toml), beside it in a source tree.

The limits below are checked before the work they bound, never by a timer: input beyond them is
refused with a located message (or, for symbolic work, handed to the generated code's numeric
solvers instead), so that no model can make bgc hang, exhaust memory or recurse without end.
"""
from __future__ import annotations

import gc
import os
import threading
from contextlib import contextmanager
from math import comb
from pathlib import Path

PACKAGE_DIR = Path(__file__).resolve().parent.parent  # the package bgc

# the model's size: refused where its compile would need more memory than bgc has (an
# estimate checked before the work, from the measured cost of large flat models and of
# components in `for` loops: benchmarks/compile_scale.py), not by a fixed count
MEMORY_BASE = 100 << 20  # the interpreter, SymPy and bgc before a model
MEMORY_PER_SOURCE_BYTE = 600  # a flat model's peak per byte of its text (440 measured)
MEMORY_PER_STATEMENT = 10_000  # per declaration or bond (about 7 KB measured)
SECONDS_PER_STATEMENT = 6e-4  # a compile's time per declaration or bond (measured, 2 cores)
SECONDS_PER_SOURCE_BYTE = 3.5e-5  # and per byte of a flat model's text
DEFAULT_MEMORY = 4 << 30  # where the memory available cannot be read
MIN_SOURCE_BYTES = 64 << 10  # max_source_bytes() is never below this, whatever the memory
MAX_REFERENCE_BYTES = 64 << 20  # a reference CSV (bgc accuracy --reference): 64 MiB
MAX_NESTING = 100  # levels of nested brackets / operators of different kinds
MAX_OPTION_CHARS = 1 << 16  # --outputs, --effects
MAX_LITERAL_DIGITS = 309  # an integer literal longer than this does not fit a double
MAX_DIMENSION = 10_000  # KIND[n]: the components of one multiport
MAX_INDEX = 10 ** 9  # an index of a name (`cell[k]`): the names a `for` loop makes are bounded by
#                      the memory estimate; this keeps one name's digits few
MAX_MATRIX_ENTRIES = 100_000  # vector and matrix entries (and products) the expressions build
MAX_EXTREMUM_ARGUMENTS = 32  # of one min() or max(): each one's derivative names all the others
MAX_INSTANCE_DEPTH = 32  # components instantiating components, levels deep
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



def set_aside() -> None:
    """Within a compile's quiet_collector (the main thread's): what is alive now is left out
    of the collector's walks until the compile ends (gc.freeze, undone there).  For a large
    value just built with the collector off, a parsed model: its objects, all young, would
    be walked by the next collection of each generation (a second or more at 10^5 lines)."""
    if getattr(_collector, "depth", 0) and threading.current_thread() is threading.main_thread():
        gc.freeze()

# memos of the symbolic work (an expression's free symbols, a name's symbol, ...): they hold what
# one compile asks again and again, as large as its model needs (a fixed size emptied when full
# made a large model's compile ask everything again: superlinear), and are emptied when a
# compile starts while no other runs (a long-lived process keeps one model's worth)
_memos: list = []
_compiling = 0
_compiling_lock = threading.Lock()


def compile_memo() -> dict:
    """A dict for memoising pure functions of expressions over one compile (compile_scope)."""
    memo: dict = {}
    _memos.append(memo)
    return memo


@contextmanager
def compile_scope():
    """Within: a compile.  The outermost one of all that run at once empties the memos first."""
    global _compiling
    with _compiling_lock:
        if _compiling == 0:
            for memo in _memos:
                memo.clear()
        _compiling += 1
    try:
        yield
    finally:
        with _compiling_lock:
            _compiling -= 1


def memory_budget() -> int:
    """The bytes a compile may use: $BGC_MEMORY if set (a number, with K, M or G), else what
    the machine has available (Linux: MemAvailable, bounded by an address-space limit), else
    DEFAULT_MEMORY."""
    given = os.environ.get("BGC_MEMORY", "").strip()
    if given:
        scale = {"K": 1 << 10, "M": 1 << 20, "G": 1 << 30}.get(given[-1:].upper(), 1)
        try:
            return max(0, int(float(given[:-1] if scale > 1 else given) * scale))
        except ValueError:
            pass
    available = None
    try:
        with open("/proc/meminfo", encoding="ascii") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    available = int(line.split()[1]) * 1024
    except (OSError, ValueError):
        pass
    try:
        import resource
        soft = resource.getrlimit(resource.RLIMIT_AS)[0]
        if soft != resource.RLIM_INFINITY and soft > 0:
            available = soft if available is None else min(available, soft)
    except (ImportError, OSError, ValueError):
        pass
    return DEFAULT_MEMORY if available is None else available


def max_source_bytes() -> int:
    """The largest model text a compile can take in the memory it has (at least
    MIN_SOURCE_BYTES)."""
    return max(MIN_SOURCE_BYTES, (memory_budget() - MEMORY_BASE) // MEMORY_PER_SOURCE_BYTE)


def max_statements() -> int:
    """The most declarations and bonds (components' and `for` loops' included, and scalar
    parts once multiports are split) a compile can take in the memory it has."""
    return max(1000, (memory_budget() - MEMORY_BASE) // MEMORY_PER_STATEMENT)


def too_large(what: str, count: int, per_source_byte: bool = False) -> str:
    """The message of a model refused for its size (count bytes of text, or declarations and
    bonds): the memory it needs, the memory there is, the time it would take."""
    per, seconds, unit = (MEMORY_PER_SOURCE_BYTE, SECONDS_PER_SOURCE_BYTE, "byte of its text") \
        if per_source_byte else (MEMORY_PER_STATEMENT, SECONDS_PER_STATEMENT,
                                 "declaration or bond")
    return (f"the model is too large: {what} need about {_size(MEMORY_BASE + count * per)} of "
            f"memory to compile (about {_size(per)} per {unit}, measured), more than the "
            f"{_size(memory_budget())} available (BGC_MEMORY sets what bgc may use); the "
            f"compile would take about {_duration(count * seconds)}")


def _size(n: float) -> str:
    for unit, k in (("GiB", 1 << 30), ("MiB", 1 << 20), ("KiB", 1 << 10)):
        if n >= k:
            return f"{n / k:.3g} {unit}"
    return f"{int(n)} bytes"


def _duration(seconds: float) -> str:
    if seconds >= 3600:
        return f"{seconds / 3600:.2g} hours"
    if seconds >= 60:
        return f"{seconds / 60:.2g} minutes"
    return f"{seconds:.2g} s"


def resource_dir(name: str) -> Path:
    """The directory `name` ("grammar" or "templates")."""
    for candidate in (PACKAGE_DIR / name, PACKAGE_DIR.parent / name):
        if candidate.is_dir():
            return candidate
    raise FileNotFoundError(f"bgc is installed without its {name}/ directory")


def read_bounded(path: str, limit: int | None = None) -> bytes:
    """The bytes of a file, at most limit + 1 of them (None: max_source_bytes(); a longer file,
    /dev/zero or a pipe that never ends is read no further); OSError as open() and read()
    raise it."""
    with open(path, "rb") as fh:
        return fh.read((max_source_bytes() if limit is None else limit) + 1)


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
