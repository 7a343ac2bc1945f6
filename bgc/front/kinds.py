"""Element kinds as data: ports, arguments, law, preferred causality.

A new kind needs an entry here, not a new pass.  `causality` names what the element imposes on
its bond when free to choose: "effort" (it sets the bond's effort), "flow", or None (either).
"""
from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Kind:
    name: str
    ports: int  # 1 or 2
    role: str  # source | storage | resistor | transformer | gyrator
    fixed: str | None = None  # sources: "effort" or "flow", imposed whatever else happens
    preferred: str | None = None  # storage: what it imposes in integral causality
    state: str | None = None  # storage: name of its state variable ("p" or "q")
    laws: tuple[str, ...] = ()  # law arguments accepted: `f = EXPR(p)` -> "f"
    modulated: bool = False


KINDS = {k.name: k for k in (
    Kind("Se", 1, "source", fixed="effort"),
    Kind("MSe", 1, "source", fixed="effort", modulated=True),
    Kind("Sf", 1, "source", fixed="flow"),
    Kind("MSf", 1, "source", fixed="flow", modulated=True),
    Kind("I", 1, "storage", preferred="flow", state="p", laws=("f",)),
    Kind("C", 1, "storage", preferred="effort", state="q", laws=("e",)),
    Kind("R", 1, "resistor", laws=("e", "f")),
    Kind("TF", 2, "transformer"),
    Kind("MTF", 2, "transformer", modulated=True),
    Kind("GY", 2, "gyrator"),
    Kind("MGY", 2, "gyrator", modulated=True),
)}
# Switched one-ports (docs/hybrid.md), each the number of its arguments: built by resolve as
# constraint junctions in one of their modes, not by the law of a Kind.
SWITCHED = {"D": 0, "Sw": 1, "Fr": 2}
# The time sources (bgc.front.events.SOURCES: their arguments): an expression that calls one
# varies in time, as one that reads t does.
TIME_SOURCES = ("step", "ramp", "pulse", "square", "initial")


def known_kinds() -> str:
    """Every element kind a declaration may name, for messages."""
    return ", ".join([*KINDS, *SWITCHED, "0", "1"])
