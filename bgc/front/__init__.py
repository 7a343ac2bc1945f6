"""The front end: parse (grammar/bg.lark), instantiate components, resolve names into the bond
graph, flatten multibonds, check units; tables, events, spelling.  Entry: its stages in order,
parser.parse -> instantiate.instantiate -> resolve.resolve -> flatten.flatten ->
units.check_units, the model's text to the checked Graph (bgc.api.build chains them;
instantiate.front is the first two)."""
from ..symbolic import conditions  # noqa: F401 (first: SymPy's Piecewise made safe)
