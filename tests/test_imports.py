"""bgc's modules import each other without a cycle, each package imports only the packages
below it in the pipeline's order, and the package's API names are served without rewriting its
attributes: the graph of imports is read from the source with `ast`.

Every import of a bgc module is an edge, at the top of a module or inside a function alike: a
lazy import only moves a cycle from import time to call time, where it still ties the two
modules into one (neither can be understood, tested or changed alone).  bgc/runtime/ is not
in the graph: its files are text the emitter inlines into generated programs.
"""
from __future__ import annotations

import ast
import functools
import importlib
import re
import types
from pathlib import Path

PACKAGE = Path(__file__).resolve().parent.parent / "bgc"

# The packages from the bottom up (docs/architecture.md): a module may import its own package
# and those before it.  The modules at the top (api, model, cli) may import any package; api
# stands between execute and analysis, which builds on it; editor (bgc fmt, bgc lsp) reads
# the front end and the middle.
LAYERS = ("base", "symbolic", "ir", "front", "middle", "codegen", "reports", "execute", "api",
          "analysis", "editor", "model", "__init__", "cli", "__main__")


def _layer(module: str) -> str:
    """The layer of a module named below bgc ("middle.reduce" -> "middle", "api" -> "api")."""
    return module.split(".")[0]


def modules() -> dict[str, Path]:
    """Every module of bgc by its name below the package ("middle.reduce", "cli")."""
    return dict(_modules())


@functools.lru_cache(maxsize=None)
def _modules() -> dict[str, Path]:
    out = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        rel = path.relative_to(PACKAGE).with_suffix("")
        if rel.parts[0] == "runtime":
            continue
        parts = list(rel.parts)
        if parts[-1] == "__init__" and len(parts) > 1:
            parts = parts[:-1]
        out[".".join(parts)] = path
    return out


def _package_of(name: str, path: Path) -> list[str]:
    """The package a module's relative imports start from, as parts below bgc."""
    parts = name.split(".") if name != "__init__" else []
    return parts if path.name == "__init__.py" else parts[:-1]


def _imported(node: ast.AST, here: list[str], known: set[str]) -> set[str]:
    """The bgc modules an import statement (or the command line's _Later(".name")) names."""
    targets: list[list[str]] = []
    if isinstance(node, ast.ImportFrom):
        if node.level == 0:
            if node.module != "bgc" and not (node.module or "").startswith("bgc."):
                return set()
            base = (node.module or "").split(".")[1:]
        else:
            base = here[:len(here) - (node.level - 1)] if node.level > 1 else list(here)
            base = base + (node.module.split(".") if node.module else [])
        targets = [base + [a.name] for a in node.names] + [base]
    elif isinstance(node, ast.Import):
        targets = [a.name.split(".")[1:] for a in node.names if a.name.startswith("bgc.")]
    elif isinstance(node, ast.Call) and (getattr(node.func, "id", None) == "_Later"
                                         or getattr(node.func, "attr", None) == "import_module"):
        targets = [a.value.lstrip(".").split(".") for a in node.args[:1]
                   if isinstance(a, ast.Constant) and isinstance(a.value, str)]
    out = set()
    for t in targets:
        for k in range(len(t), 0, -1):  # the longest prefix that is a module
            if ".".join(t[:k]) in known:
                out.add(".".join(t[:k]))
                break
    return out


@functools.lru_cache(maxsize=None)
def _syntax(path: Path) -> ast.Module:
    """A file's syntax tree, read once for the tests of this file (which only walk it)."""
    return ast.parse(path.read_text(encoding="utf-8"))


def import_graph() -> dict[str, set[str]]:
    return {name: set(edges) for name, edges in _import_graph().items()}


@functools.lru_cache(maxsize=None)
def _import_graph() -> dict[str, set[str]]:
    found = modules()
    known = set(found)
    graph = {}
    for name, path in found.items():
        tree = _syntax(path)
        here = _package_of(name, path)
        edges = set()
        for node in ast.walk(tree):
            edges |= _imported(node, here, known)
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
    assert "codegen.emit" in graph["execute.runner"]  # inside runner.prepare
    assert "api" in graph["cli"]  # _Later(".api")
    assert "analysis.accuracy" in graph["cli"]  # _Later(".analysis.accuracy")
    assert "api" in graph["model"] and "model" in graph["__init__"]
    assert "ir" in graph["middle.reduce"]  # from .. import ir: the package


def test_every_import_of_bgc_names_a_module_or_the_api():
    """`from bgc import solvers` where solvers moved to bgc.base is an ImportError in an
    installed bgc (an editable install's finder may hide it in a development tree)."""
    import bgc
    found = modules()
    known = set(found)
    allowed = set(bgc.__all__) | {"__version__"}
    missing = []
    for name, path in found.items():
        tree = _syntax(path)
        here = _package_of(name, path)
        for node in ast.walk(tree):
            if not isinstance(node, ast.ImportFrom):
                continue
            if node.level == 0 and node.module != "bgc" \
                    and not (node.module or "").startswith("bgc."):
                continue
            base = (node.module or "").split(".")[1:] if node.level == 0 else \
                (here[:len(here) - (node.level - 1)] if node.level > 1 else list(here)) + \
                (node.module.split(".") if node.module else [])
            if base and ".".join(base) not in known and base[0] != "runtime":
                missing.append(f"{name}: {'.'.join(base)}")
            elif not base or ".".join(base) in known and found[".".join(base)].name == "__init__.py":
                package = ".".join(base)
                for a in node.names:
                    sub = f"{package}.{a.name}" if package else a.name
                    if sub not in known and a.name not in allowed and not package:
                        missing.append(f"{name}: bgc.{a.name}")
    assert missing == []


def test_bgc_modules_import_each_other_without_a_cycle():
    assert cycles(import_graph()) == []


def test_every_module_is_in_a_layer():
    assert {_layer(m) for m in modules()} <= set(LAYERS)


def test_no_package_imports_one_above_it():
    """The stages as packages in pipeline order: an import runs down, or within a package."""
    rank = {name: k for k, name in enumerate(LAYERS)}
    upward = sorted(f"{m} -> {d}" for m, deps in import_graph().items() for d in deps
                    if rank[_layer(d)] > rank[_layer(m)])
    assert upward == []


def private_crossings(apart=None) -> list[str]:
    """`from ..codegen.emit import _x` or `emit._x` in a module of another package (or of
    another module: apart(importer, target) says whether the two are apart; default: their
    packages differ)."""
    apart = apart or (lambda name, target: _layer(target) != _layer(name))
    crossing, known = [], set(modules())
    for name, path in modules().items():
        tree = _syntax(path)
        here = _package_of(name, path)
        aliases = {}  # local name -> the bgc module it is
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom):
                targets = _imported(node, here, known)
                for a in node.names:
                    hit = [t for t in targets if t.endswith("." + a.name) or t == a.name]
                    if hit:
                        aliases[a.asname or a.name] = hit[0]
                    elif a.name.startswith("_") and a.name != "__version__" and targets:
                        target = max(targets, key=len)
                        if apart(name, target):
                            crossing.append(f"{name}: {a.name} from {target}")
        for node in ast.walk(tree):
            if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) \
                    and node.value.id in aliases and node.attr.startswith("_") \
                    and not node.attr.startswith("__"):
                target = aliases[node.value.id]
                if apart(name, target):
                    crossing.append(f"{name}: {node.value.id}.{node.attr}")
    return sorted(set(crossing))


def test_no_private_name_crosses_a_package():
    """A private name is its package's own: none is imported or read from another package
    (the last five were made public: plot.shorten, toolchain.run_compiler,
    parser.lark_parser, resources.PACKAGE_DIR, tangent.Forward)."""
    assert private_crossings() == []


def test_no_private_name_crosses_a_module():
    """Nor from another module of its own package: the interpreter, the embedded target and
    the FMU use the emitter's public names alone (the last fifteen of emit made public:
    runtime_text, unit_text, model_functions, workspace, validate, reads_time, ...)."""
    assert private_crossings(lambda name, target: name != target) == []


def test_every_package_names_its_entry():
    """Each package's __init__ says what it holds and names its entry (docs/architecture.md,
    "The packages"), or says that it is a library without one; every `module.name` after
    "Entry:" is a function or class that module defines (read with `ast`: lsp needs pygls)."""
    found = modules()
    for init in sorted(PACKAGE.glob("*/__init__.py")):
        package = init.parent.name
        if package == "runtime":
            continue
        doc = ast.get_docstring(_syntax(init)) or ""
        assert "Entry:" in doc or "no one entry" in doc, package
        named = re.findall(r"\b([a-z_]+)\.([A-Za-z_]+)\b", doc.partition("Entry:")[2])
        for module, name in named:
            if f"{package}.{module}" not in found:
                continue  # (another package's, bgc.api.build)
            tree = _syntax(found[f"{package}.{module}"])
            defined = {n.name for n in tree.body
                       if isinstance(n, (ast.FunctionDef, ast.ClassDef))}
            assert name in defined, f"{package}: {module}.{name}"
        assert package != "ir" or "Program" in doc.partition("Entry:")[2]


def test_only_the_command_line_imports_click():
    for path in PACKAGE.rglob("*.py"):
        tree = _syntax(path)
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
    import bgc.base.run_settings
    import bgc.middle.system
    assert isinstance(bgc.middle.system, types.ModuleType)
    assert isinstance(bgc.base.run_settings, types.ModuleType)
    assert importlib.import_module("bgc.base.run_settings") is bgc.base.run_settings
    assert bgc.equations is bgc.api.equations and bgc.load is bgc.model.load
    assert bgc.simulate is bgc.api.simulate and bgc.compile is bgc.api.compile
    assert not set(bgc.__all__) & set(vars(bgc))  # served by __getattr__, never stored
