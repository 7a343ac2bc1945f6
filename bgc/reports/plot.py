"""Plots: `bgc simulate --plot FILE` (a run's CSV, one panel per kind of output) and the
shared look of bgc's figures (`bgc accuracy` uses it too).

matplotlib is optional (`pip install 'bgc[plot]'`) and imported only when a figure is drawn,
with the Agg backend (no display needed).

A run's outputs are grouped by unit where their units are known (a current and the voltage
of a capacitor in two panels, two currents in one, whatever bond-graph variables they are),
else by what they are: signals (the model's coordinates and other signals), momenta p,
displacements q, efforts e, flows f, multipliers λ, constraint residuals Φ, parameters; one
panel per group, in the order their first column comes in the CSV.
A legend names each column with the doc string of its element; a doc string that ends in
`[unit]` gives the unit of what the declaration names: a parameter's value, a 1-junction's
common flow (and so the flow of a one-port bonded to it), a 0-junction's common effort (and
so the effort of a one-port bonded to it); a parameter's or a signal's `unit "..."` (a
component's parameters included) gives theirs.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass, replace
from pathlib import Path

PLOT_INSTALL = "pip install 'bgc[plot]'"
FORMATS = ("png", "svg", "pdf")
MAX_POINTS = 50_000  # rows read from a CSV; a longer run is plotted every k-th row
MAX_LEGEND = 12  # columns a panel names in its legend
DPI = 110

KINDS = {  # group: (panel title, the quantity on its axis)
    "signal": ("signals", "value"),
    "p": ("momenta", "momentum p"),
    "q": ("displacements", "displacement q"),
    "e": ("efforts", "effort e"),
    "f": ("flows", "flow f"),
    "lambda": ("constraint multipliers", "multiplier λ"),
    "residual": ("constraint residuals", "residual Φ"),
    "parameter": ("parameters", "value"),
    "unit": ("in one unit", "value"),
}
_VARIABLE = re.compile(r"([A-Za-z_][A-Za-z0-9_.\[\]]*)\.([a-z]+)(?:\[([0-9]+)\])?")
_INDEXED = re.compile(r"([A-Za-z_][A-Za-z0-9_.\[\]]*)\[([0-9]+)\]")
_UNIT = re.compile(r"^(.*?)\s*\[([^\[\]]+)\]\s*$")


class PlotError(Exception):
    """The plot cannot be drawn (the message says why, for people)."""


def matplotlib_missing() -> str | None:
    """None if matplotlib can be imported, else what to say (and install)."""
    try:
        import matplotlib  # noqa: F401
    except ImportError:
        return f"matplotlib is not installed: {PLOT_INSTALL}"
    return None


def check_format(path) -> str:
    """The figure format of a file name, from its suffix; PlotError if none bgc writes."""
    fmt = Path(path).suffix.lower().lstrip(".")
    if fmt not in FORMATS:
        raise PlotError(f"'{path}': the plot's file name must end in "
                        + ", ".join("." + f for f in FORMATS))
    return fmt


def pyplot():
    """matplotlib.pyplot with the Agg backend (imported here, on first use)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def style(ax) -> None:
    """bgc's axes: a light grid."""
    ax.grid(True, which="both", alpha=0.3)


def save(fig, target, fmt: str = "png") -> None:
    """The figure to target (a file name or a binary file), closed afterwards."""
    fig.savefig(target, dpi=DPI, format=fmt)
    pyplot().close(fig)


def shorten(s: str, limit: int = 60) -> str:
    """Model text for a matplotlib label: no mathtext ($ escaped), one line, bounded."""
    s = " ".join(s.split())
    if len(s) > limit:
        s = s[:limit - 1] + "…"
    return s.replace("$", r"\$")


# ---------------------------------------------------------------- the columns


@dataclass(frozen=True)
class Column:
    name: str  # as in the CSV header
    kind: str  # a key of KINDS
    doc: str | None  # what its declaration's doc string says (its unit taken off)
    unit: str | None


def _doc_unit(doc: str | None) -> tuple[str | None, str | None]:
    if not doc:
        return None, None
    m = _UNIT.match(doc)
    if m:
        return (m.group(1) or None), m.group(2).strip()
    return doc, None


_COMMON = {"1": "f", "0": "e"}  # the variable a junction's doc string gives the unit of


def _unit_of(graph, el, var: str) -> str | None:
    """The unit of el's variable var: from el's doc if el is a junction and var its common
    variable; for a one-port on such a junction, from that junction's doc."""
    if _COMMON.get(el.kind) == var:
        return _doc_unit(el.doc)[1]
    bonds = graph.incident.get(el.name, ())
    if el.is_junction or len(bonds) != 1:
        return None
    b = graph.bonds[bonds[0]]
    other = graph.by_name.get(b.other(el.name))
    if other is not None and _COMMON.get(other.kind) == var:
        return _doc_unit(other.doc)[1]
    return None


def columns(compiled, names) -> list[Column]:
    """What each CSV column of a run of `compiled` is (see the module's doc)."""
    graph = compiled.graph
    params = {p.name: p for p in graph.parameters}
    signals = {s.name: s for s in graph.signals}
    known = dict(graph.units)  # what bgc.front.units found (declared or inferred)
    return [replace(c, unit=known.get(c.name) or c.unit)
            for c in _columns(graph, params, signals, names)]


def _columns(graph, params, signals, names) -> list[Column]:
    out = []
    for name in names:
        m = _VARIABLE.fullmatch(name)
        if m and m.group(2) in KINDS:
            base, var, index = m.groups()
            el = graph.by_name.get(base if index is None else f"{base}[{index}]") \
                or graph.by_name.get(base)
            doc = _doc_unit(el.doc)[0] if el is not None else None
            unit = _unit_of(graph, el, var) if el is not None else None
            out.append(Column(name, var, doc, unit))
            continue
        plain = _INDEXED.fullmatch(name)
        base = plain.group(1) if plain else name
        if base in params:
            doc, unit = _doc_unit(params[base].doc)
            out.append(Column(name, "parameter", doc, params[base].unit or unit))
        else:
            sig = signals.get(name) or signals.get(base)
            out.append(Column(name, "signal", None, sig.unit if sig is not None else None))
    return out


def panels(cols: list[Column]) -> list[tuple[str, list[Column]]]:
    """The columns grouped by unit where it is known (kind "unit": a current and a speed are
    both flows, not one panel; a flow and a signal in amperes are one), the others by kind;
    each group where its first column comes."""
    groups: dict[tuple, list[Column]] = {}
    for c in cols:
        groups.setdefault(("unit", c.unit) if c.unit else (c.kind, None), []).append(c)
    return [(kind, group) for (kind, _), group in groups.items()]


# ---------------------------------------------------------------- the CSV


@dataclass(frozen=True)
class Table:
    names: tuple[str, ...]  # the columns after t
    t: list
    values: list  # one list per column
    rows: int  # the rows in the file
    every: int  # every k-th row is in t and values (the last row always)


def read_csv(path, max_points: int = MAX_POINTS) -> Table:
    """A run's CSV (header t,<outputs>), at most about max_points rows of it: a longer file is
    read every k-th row, its last row always included."""
    with open(path, "rb") as f:
        header = f.readline().decode("utf-8", "replace").rstrip("\r\n").split(",")
        rows = sum(chunk.count(b"\n") for chunk in iter(lambda: f.read(1 << 20), b""))
    if not header or header[0] != "t":
        raise PlotError(f"'{path}' is not a bgc CSV (its header does not start with t)")
    with open(path, "rb") as f:
        f.readline()
        units = f.readline().startswith(b"s,")  # (the units' row of simulate --units)
    rows -= units
    every = max(1, math.ceil(rows / max_points))
    t: list = []
    values: list = [[] for _ in header[1:]]
    last = None
    with open(path, "rb") as f:
        f.readline()
        if units:
            f.readline()
        for k, line in enumerate(f):
            if not line.endswith(b"\n"):
                break  # a row cut short
            if k % every and k != rows - 1:
                continue
            cells = line.split(b",")
            if len(cells) != len(header):
                raise PlotError(f"'{path}': row {k + 2} has {len(cells)} values, the header "
                                f"{len(header)}")
            try:
                numbers = [float(c) for c in cells]
            except ValueError:
                raise PlotError(f"'{path}': row {k + 2} is not numbers") from None
            last = k
            t.append(numbers[0])
            for j, v in enumerate(numbers[1:]):
                values[j].append(v)
    return Table(tuple(header[1:]), t, values, rows if last is None else last + 1, every)


# ---------------------------------------------------------------- the figure


def describe(compiled) -> dict:
    """What a plot of a run of `compiled` needs, as plain data (kept in bgc.execute.warm's record,
    so
    that a warm run plots without the pipeline): plot_title, plot_columns (Column fields)."""
    names = compiled.program.outputs if compiled.program is not None else \
        [o.name for o in compiled.reduced.outputs]  # (the CSV's columns after t)
    return {"plot_title": tuple(title_lines(compiled)),
            "plot_columns": tuple((c.name, c.kind, c.doc, c.unit)
                                  for c in columns(compiled, names))}


def title_lines(compiled) -> list[str]:
    g, s = compiled.graph, compiled.settings
    scene = next((sc for sc in g.scenes if sc.name == s.scene), None)
    lines = [g.name + (f": {shorten(g.doc, 80)}" if g.doc else "")]
    if scene is not None:
        lines.append(f"scene {scene.name}" + (f": {shorten(scene.doc, 80)}" if scene.doc else ""))
    else:
        lines.append("default scene (every effect)")
    if s.given:
        lines[-1] += f", {' and '.join(s.given)} given ad hoc"
    return lines


def plot_run(table: Table, cols: list[Column], target, fmt: str, heading: list[str],
             stopped: bool = False) -> list[str]:
    """One panel per group of columns (panels()), sharing the time axis, to target; the
    panels' titles and axis labels ("title | label")."""
    fig, drawn = figure(table, cols, heading, stopped)
    save(fig, target, fmt)
    return drawn


def figure(table: Table, cols: list[Column], heading: list[str], stopped: bool = False):
    """plot_run's figure, and its panels' "title | label"."""
    plt = pyplot()
    if not table.t or not table.names:
        raise PlotError("the run computed no row: nothing to plot" if not table.t else
                        "the run has no outputs: nothing to plot")
    by_name = {c.name: c for c in cols}
    cols = [by_name.get(n, Column(n, "signal", None, None)) for n in table.names]
    groups = panels(cols)
    index = {n: j for j, n in enumerate(table.names)}
    drawn = []
    fig, axes = plt.subplots(len(groups), 1, sharex=True, squeeze=False,
                             figsize=(10, 1.2 + 2.4 * len(groups)))
    for ax, (kind, group) in zip(axes[:, 0], groups):
        title, quantity = KINDS[kind]
        unit = group[0].unit  # (one per panel)
        if kind == "unit":
            title = f"in {shorten(unit, 20)}"
        for c in group:
            label = shorten(c.name) + (f" ({shorten(c.doc, 40)})" if c.doc else "")
            ax.plot(table.t, table.values[index[c.name]], lw=1.2, label=label)
        names = ", ".join(c.name for c in group)
        ylabel = shorten(names) if len(names) <= 24 else quantity
        ax.set_ylabel(ylabel + (f" [{shorten(unit, 20)}]" if unit else ""))
        if len(group) == 1 and group[0].doc:
            title += f": {shorten(group[0].doc, 60)}"
        elif len(group) > MAX_LEGEND:
            title += f" ({len(group)} columns)"
        ax.set_title(title, fontsize=9, loc="right")
        drawn.append(f"{title} | {ax.get_ylabel()}")
        if 1 < len(group) <= MAX_LEGEND:
            ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0),
                      borderaxespad=0.0)
        style(ax)
    axes[-1, 0].set_xlabel("time t [s]")
    notes = []
    if stopped:
        notes.append(f"the run stopped at t = {table.t[-1]:.6g}: its rows up to there")
    if table.every > 1:
        notes.append(f"every {table.every}th of {table.rows} rows")
    fig.suptitle("\n".join(heading + ([", ".join(notes)] if notes else [])), fontsize=10)
    fig.tight_layout()
    return fig, drawn
