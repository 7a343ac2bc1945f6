"""The front end: parse (grammar/bg.lark), instantiate components, resolve names into the bond
graph, flatten multibonds, check units; tables, events, spelling.  Entry: `bgc.api.front` chains
parser.parse, instantiate, resolve.resolve, flatten."""
from ..symbolic import conditions  # noqa: F401 (first: SymPy's Piecewise made safe)
