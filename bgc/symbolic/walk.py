"""The one tree walk of the passes: an expression's value computed bottom up, each
subexpression once, with an explicit stack (a model's expressions are as deep as it is large;
Python's recursion is not).

    fold(root, memo, leaf, combine, children=args)

`leaf(e)` gives the value of a node the walk does not enter (a symbol, a number, a node a
rule replaces) or DESCEND; `combine(e, values)` the value of a node from its children's, in
the order `children(e)` lists them; `memo` holds every value computed (shared between calls,
it is a cache: the same subexpression in another root is not walked again).  bgc's walks are
this one with their own leaf and combine: substitution and xreplace (bgc.ir.program,
bgc.symbolic.canonical), free symbols (bgc.symbolic.canonical) and integral floats
(bgc.ir.program), polynomial degrees (bgc.symbolic.algebra) and forward derivatives
(bgc.symbolic.differentiate).
"""
from __future__ import annotations

DESCEND = object()  # leaf's answer for a node whose children are to be walked


def args(e):
    return e.args


def fold(root, memo: dict, leaf, combine, children=args):
    """root's value (see the module's doc); memo[root] too."""
    if root in memo:
        return memo[root]
    stack = [(root, False)]
    while stack:
        e, ready = stack.pop()
        if e in memo:
            continue
        if ready:
            memo[e] = combine(e, [memo[a] for a in children(e)])
            continue
        value = leaf(e)
        if value is not DESCEND:
            memo[e] = value
            continue
        stack.append((e, True))
        stack.extend((a, False) for a in children(e) if a not in memo)
    return memo[root]
