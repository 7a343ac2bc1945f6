"""bgc's modules import each other without a cycle, and the package's API names are served
without rewriting its attributes: the graph of imports is read from the source with `ast`.

Every import of a bgc module is an edge, at the top of a module or inside a function alike: a
lazy import only moves a cycle from import time to call time, where it still ties the two
modules into one (neither can be understood, tested or changed alone).  bgc/runtime/ is not
in the graph: its files are text the emitter inlines into generated programs.
"""
from __future__ import annotations

import ast
import importlib
import types
from pathlib import Path

PACKAGE = Path(__file__).resolve().parent.parent / "bgc"


def _imported(node: ast.AST, modules: set[str]) -> set[str]:
    """The bgc modules an import statement (or the command line's _Later(".name")) names."""
    names: list[str] = []
    if isinstance(node, ast.ImportFrom):
        base = node.module or ""
        if node.level == 0:
            if base != "bgc" and not base.startswith("bgc."):
                return set()
            base = base[len("bgc"):].lstrip(".")
        elif node.level > 1:
            return set()
        names = [base.split(".")[0]] if base else [a.name for a in node.names]
    elif isinstance(node, ast.Import):
        names = [a.name.split(".")[1] for a in node.names
                 if a.name.startswith("bgc.") and a.name.count(".") >= 1]
    elif isinstance(node, ast.Call) and (getattr(node.func, "id", None) == "_Later"
                                         or getattr(node.func, "attr", None) == "import_module"):
        names = [a.value.lstrip(".") for a in node.args[:1]
                 if isinstance(a, ast.Constant) and isinstance(a.value, str)]
    return {n for n in names if n in modules}


def import_graph() -> dict[str, set[str]]:
    modules = {p.stem for p in PACKAGE.glob("*.py")}
    graph = {}
    for name in sorted(modules):
        tree = ast.parse((PACKAGE / f"{name}.py").read_text(encoding="utf-8"))
        edges = set()
        for node in ast.walk(tree):
            edges |= _imported(node, modules)
        graph[name] = edges - {name}
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan's, iterative)."""
    index, low, stack, on, out = {}, {}, [], set(), []
    for root in graph:
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on.add(root)
        while work:
            v, children = work[-1]
            w = next(children, None)
            if w is not None:
                if w not in index:
                    index[w] = low[w] = len(index)
                    stack.append(w)
                    on.add(w)
                    work.append((w, iter(sorted(graph[w]))))
                elif w in on:
                    low[v] = min(low[v], index[w])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[v])
            if low[v] == index[v]:
                component = []
                while True:
                    w = stack.pop()
                    on.discard(w)
                    component.append(w)
                    if w == v:
                        break
                if len(component) > 1:
                    out.append(sorted(component))
    return out


def test_the_cycle_finder_finds_a_cycle():
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert cycles({"a": {"b"}, "b": set()}) == []


def test_the_graph_sees_lazy_imports():
    graph = import_graph()
    assert "emit" in graph["runner"]  # inside runner.prepare
    assert "api" in graph["cli"]  # _Later(".api")
    assert "api" in graph["model"] and "model" in graph["__init__"]


def test_bgc_modules_import_each_other_without_a_cycle():
    assert cycles(import_graph()) == []


def test_only_the_command_line_imports_click():
    for path in PACKAGE.glob("*.py"):
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for node in ast.walk(tree):
            if isinstance(node, (ast.Import, ast.ImportFrom)):
                names = [a.name for a in node.names] if isinstance(node, ast.Import) \
                    else [node.module or ""]
                if any(n.split(".")[0] == "click" for n in names):
                    assert path.name == "cli.py", path


def test_the_api_names_leave_the_submodules_alone():
    """`import bgc.X` is a module, `bgc.equations` and the other API names are the API's
    functions whatever was imported before, and nothing writes them on the package."""
    import bgc
    import bgc.api
    import bgc.model
    import bgc.run
    import bgc.system
    assert isinstance(bgc.system, types.ModuleType) and isinstance(bgc.run, types.ModuleType)
    assert importlib.import_module("bgc.run") is bgc.run
    assert bgc.equations is bgc.api.equations and bgc.load is bgc.model.load
    assert bgc.simulate is bgc.api.simulate and bgc.compile is bgc.api.compile
    assert not set(bgc.__all__) & set(vars(bgc))  # served by __getattr__, never stored
