"""`bgc draw` (bgc/reports/draw.py): the DOT it writes, read back by a small DOT reader written here
(not draw.py's own code), checked against the causality the compiler assigned, the paper's
figure-8 structure, the scene's left-out elements, multibonds, hostile doc strings, and
determinism; SVG/PNG through Graphviz when `dot` is installed."""
from __future__ import annotations

import html
import os
import re
import shutil
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from bgc import api
from bgc.reports import draw
from bgc.reports.report import check_report
from conftest import MODELS, ROOT, run_bgc
from test_components import CIRCUIT, HYD

HAVE_DOT = shutil.which("dot") is not None
PENDULUM = str(MODELS / "pendulum.bg")


# ---------------------------------------------------------------- a small DOT reader

TOKEN = re.compile(r'''\s+|//[^\n]*|(?P<str>"(?:[^"\\]|\\.)*")|(?P<arrow>->)|(?P<punct>[{}\[\];,=])
                   |(?P<id>[A-Za-z_][A-Za-z0-9_.]*|-?[0-9.]+)|(?P<html><)''', re.X | re.S)


def tokens(text: str) -> list[tuple[str, str]]:
    """(kind, value) of every token: a quoted string decoded, an HTML string as its text."""
    out, i = [], 0
    while i < len(text):
        m = TOKEN.match(text, i)
        assert m, f"not DOT at {i}: {text[i:i + 40]!r}"
        if m["html"]:
            depth, j = 0, i
            while True:  # an HTML string: balanced < >
                depth += {"<": 1, ">": -1}.get(text[j], 0)
                j += 1
                if depth == 0:
                    break
            out.append(("html", text[i + 1:j - 1]))
            i = j
            continue
        i = m.end()
        if m["str"]:
            out.append(("str", re.sub(r"\\(.)", r"\1", m["str"][1:-1])))
        elif m["arrow"] or m["punct"] or m["id"]:
            out.append(("p" if not m["id"] else "id", m.group(0)))
    return out


def read_dot(text: str) -> dict:
    """{"nodes": {id: attrs}, "edges": [(tail, head, attrs)], "clusters": {name: [node ids]},
    "graph": attrs} of a digraph made of node, edge, attribute and subgraph statements (a
    node named alone inside a subgraph, `"a.b";`, is a member of it, declared elsewhere)."""
    toks = tokens(text)
    assert toks[0] == ("id", "digraph") and toks[2] == ("p", "{")
    out = {"nodes": {}, "edges": [], "clusters": {}, "graph": {}}
    stack, i = [], 3

    def attrs(i):
        found = {}
        assert toks[i] == ("p", "[")
        i += 1
        while toks[i] != ("p", "]"):
            key, eq, value = toks[i], toks[i + 1], toks[i + 2]
            assert eq == ("p", "=") and key[0] in ("id", "str"), toks[i:i + 3]
            found[key[1]] = value[1]
            i += 3
            if toks[i] == ("p", ","):
                i += 1
        return found, i + 1

    while True:
        kind, value = toks[i]
        if (kind, value) == ("p", "}"):
            if not stack:
                assert i == len(toks) - 1, "text after the graph"
                return out
            stack.pop()
            i += 1
        elif (kind, value) == ("id", "subgraph"):
            stack.append(toks[i + 1][1])
            out["clusters"][stack[-1]] = []
            assert toks[i + 2] == ("p", "{")
            i += 3
        elif value in ("graph", "node", "edge") and kind == "id":
            found, i = attrs(i + 1)
            if value == "graph":
                out["graph"].update(found)
            i += 1 if toks[i] == ("p", ";") else 0
        elif toks[i + 1] == ("p", "="):  # key=value; inside a subgraph
            i += 3
            i += 1 if toks[i] == ("p", ";") else 0
        elif toks[i + 1] == ("p", ";") and stack:  # a node named in a cluster: drawn there
            out["clusters"][stack[-1]].append(value)
            i += 2
        elif toks[i + 1] == ("p", "->"):
            found, j = attrs(i + 3)
            out["edges"].append((value, toks[i + 2][1], found))
            for n in (value, toks[i + 2][1]):
                if stack:
                    out["clusters"][stack[-1]].append(n)
            i = j + (1 if toks[j] == ("p", ";") else 0)
        else:
            found, j = attrs(i + 1)
            assert value not in out["nodes"], f"node {value} declared twice"
            out["nodes"][value] = found
            if stack:
                out["clusters"][stack[-1]].append(value)
            i = j + (1 if toks[j] == ("p", ";") else 0)


def text_of(label: str) -> str:
    """The text of an HTML label (tags out, entities decoded)."""
    plain = re.sub(r"<BR/>", "\n", label)
    plain = re.sub(r"<[^>]*>", "", plain)
    for a, b in (("&lt;", "<"), ("&gt;", ">"), ("&quot;", '"'), ("&#39;", "'"), ("&amp;", "&")):
        plain = plain.replace(a, b)
    return plain


def bonds_of(g: dict) -> dict:
    """{bond label: (tail, head, attrs)} of the edges drawn as bonds."""
    return {a["id"][len("bond "):]: (t, h, a) for t, h, a in g["edges"]
            if a.get("id", "").startswith("bond ")}


def stroke_end(tail: str, head: str, attrs: dict) -> str | None:
    at_head, at_tail = "tee" in attrs["arrowhead"], "tee" in attrs["arrowtail"]
    assert not (at_head and at_tail), "a bond with two strokes"
    return head if at_head else tail if at_tail else None


def causality_from_check(compiled) -> dict:
    """{bond as written: the node that sets its flow} as `bgc check` prints it
    (`bond: effort set by -> flow set by`); the stroke is at the flow setter."""
    report = check_report(compiled)
    section = report.split("causality (bond: effort set by -> flow set by):\n")[1]
    out = {}
    for line in section.splitlines():
        m = re.fullmatch(r"  (\S+?)(?: \[\d+\])?: (\S+) -> (\S+)", line)
        if not m:
            break
        out[m[1]] = m[3]
    return out


# ---------------------------------------------------------------- the pendulum


@pytest.fixture(scope="module")
def pendulum():
    compiled = api.build(PENDULUM, "swing", program=False)
    text = draw.draw_dot(compiled)
    return compiled, text, read_dot(text)


def test_strokes_are_where_the_compiler_put_them(pendulum):
    """Every bond's causal stroke sits at the end that receives its effort: the end that the
    causality stage (CausalGraph.effort_by) does not name as the effort's setter."""
    compiled, _, g = pendulum
    drawn = bonds_of(g)
    graph, effort_by = compiled.graph, compiled.causal.effort_by
    assert sorted(drawn) == sorted(b.label for b in graph.bonds)
    for b, setter in zip(graph.bonds, effort_by):
        tail, head, attrs = drawn[b.label]
        assert (tail, head) == (b.src, b.dst), "a bond points the way power flows"
        assert "lvee" in attrs["arrowhead"] and attrs["dir"] == "both"
        assert stroke_end(tail, head, attrs) == b.other(setter), b.label


def test_pendulum_strokes_as_the_paper_draws_them(pendulum):
    """Figure 8 by hand: the masses in integral causality (stroke at the I), the weight
    imposes its effort (stroke at the junction), the constraint junction imposes lambda on
    both transformers, which pass it on to the velocity junctions."""
    _, _, g = pendulum
    drawn = bonds_of(g)
    want = {"vx->mx": "mx", "vy->my": "my", "weight->vy": "vy", "vx->tx": "vx",
            "tx->rod": "tx", "vy->ty": "vy", "ty->rod": "ty"}
    assert {k: stroke_end(*v) for k, v in drawn.items()} == want
    assert want == causality_from_check(pendulum[0])


def test_pendulum_labels(pendulum):
    _, _, g = pendulum
    labels = {n: text_of(a["label"]) for n, a in g["nodes"].items()}
    assert labels["mx"] == "I : m\nmx"
    assert labels["weight"] == "Se : m*g\nweight"
    assert labels["tx"] == "MTF : 2*x\ntx"
    assert labels["vx"].split("\n")[0] == "1"
    assert labels["rod"].split("\n")[0] == "0"
    assert g["graph"]["rankdir"] == "LR"


def test_figure_8_corrector(pendulum):
    """The constraint junction's PID corrector as the paper's figure 8 draws it: the flow
    balance dPhi/dt, its derivative, 2 alpha times it and beta^2 times its integral Phi
    (initial condition -l^2) summed to zero, which gives lambda back to the junction; and the
    figure-9 annotation, -l^2 into the junction."""
    _, _, g = pendulum
    (name, members), = [(k, v) for k, v in g["clusters"].items() if "corrector" in k]
    assert "rod" not in members, "the junction stays in the bond graph, not the cluster"
    label = {n: text_of(g["nodes"][n]["label"]).split("\n")[0] for n in members
             if n in g["nodes"]}
    by_text = {v: k for k, v in label.items()}
    for block in ("dΦ/dt", "d/dt", "2·alpha", "∫", "beta²", "Σ = 0", "-l^2"):
        assert block in by_text, f"no {block} block in {sorted(label.values())}"
    edges = {(t, h) for t, h, _ in g["edges"]}
    B, D, K1, INT, K2, S = (by_text[k] for k in ("dΦ/dt", "d/dt", "2·alpha", "∫", "beta²",
                                                 "Σ = 0"))
    for a, b in [("rod", B), (B, D), (D, S), (B, K1), (K1, S), (B, INT), (INT, K2), (K2, S),
                 (by_text["-l^2"], INT), (S, "rod")]:
        assert (a, b) in edges, f"no signal {label.get(a, a)} -> {label.get(b, b)}"
    back = [a for t, h, a in g["edges"] if (t, h) == (S, "rod")][0]
    assert back["label"] == "λ"
    into_rod = [t for t, h, _ in g["edges"] if h == "rod" and t not in members]
    assert any(text_of(g["nodes"][t]["label"]) == "-l^2" for t in into_rod if t in g["nodes"])


def test_the_integrators_of_the_coordinates(pendulum):
    """x integrates vx's flow and modulates tx, its initial value an arrow into it."""
    _, _, g = pendulum
    edges = {(t, h) for t, h, _ in g["edges"]}
    assert {("vx", "x"), ("x", "tx"), ("vy", "y"), ("y", "ty")} <= edges
    assert text_of(g["nodes"]["x"]["label"]).startswith("∫")
    inits = [t for t, h, _ in g["edges"] if h == "x" and t != "vx"]
    assert [text_of(g["nodes"][t]["label"]) for t in inits] == ["l*sin(theta0)"]


def test_unstabilised_greys_the_corrector_gains():
    """Figure 7 against figure 8: without @stabilisation the corrector falls back to none,
    so its gains and integrator are drawn grey and dashed, d/dt stays."""
    g = read_dot(draw.draw_dot(api.build(PENDULUM, "unstabilised", program=False)))
    nodes = {text_of(a["label"]).split("\n")[0]: a for a in g["nodes"].values()}
    for block in ("2·alpha", "beta²", "∫"):
        assert nodes[block]["color"] == draw.GREY and "gray60" in nodes[block]["label"]
    assert nodes["d/dt"]["color"] != draw.GREY
    (name,) = [k for k in g["clusters"] if "corrector" in k]
    assert "left out" in re.search(r'label="([^"]*)"', draw.draw_dot(
        api.build(PENDULUM, "unstabilised", program=False)).split(name)[1])[1]


def test_left_out_elements_are_grey_not_omitted():
    compiled = api.build(PENDULUM, None, program=False, effects="none")
    g = read_dot(draw.draw_dot(compiled))
    assert "weight" in g["nodes"] and "weight" not in compiled.graph.by_name
    assert draw.GREY in g["nodes"]["weight"]["label"]
    assert "tagged @gravity" in g["nodes"]["weight"]["tooltip"]
    tail, head, attrs = bonds_of(g)["weight->vy"]
    assert attrs["style"] == "dashed" and attrs["color"] == draw.GREY
    assert stroke_end(tail, head, attrs) is None, "a bond left out has no causality"
    assert draw.GREY not in g["nodes"]["mx"]["label"]


# ---------------------------------------------------------------- multibonds


def test_multibonds_and_arrays():
    """twin_motors without its load (a scene leaving out a vector source): every vector bond
    a double line labelled 2 with one stroke where `bgc check` says, junction arrays marked
    [2], the load grey."""
    compiled = api.build(str(MODELS / "twin_motors.bg"), None, program=False, effects="none")
    g = read_dot(draw.draw_dot(compiled))
    drawn = bonds_of(g)
    flow_setter = causality_from_check(compiled)
    assert set(flow_setter) == set(drawn) - {"shaft->load"}
    for label, (tail, head, attrs) in drawn.items():
        assert attrs["label"] == "2" and attrs["color"].count(":") == 1, label
        if label == "shaft->load":
            assert stroke_end(tail, head, attrs) is None and attrs["style"] == "dashed"
        else:
            assert stroke_end(tail, head, attrs) == flow_setter[label], label
    assert text_of(g["nodes"]["elec"]["label"]).split("\n")[0] == "1[2]"
    assert text_of(g["nodes"]["motor"]["label"]).startswith("MGY[2] : diag(kt1, kt2)")
    assert draw.GREY in g["nodes"]["load"]["label"]


def test_vector_pendulum_matrix_transformer():
    compiled = api.build(str(MODELS / "pendulum_vector.bg"), "swing", program=False)
    g = read_dot(draw.draw_dot(compiled))
    drawn = bonds_of(g)
    assert drawn["v->rodT"][2]["label"] == "2" and "label" not in drawn["rodT->rod"][2]
    assert text_of(g["nodes"]["rodT"]["label"]).startswith("MTF[2→1] : ")
    for label, flow in causality_from_check(compiled).items():
        assert stroke_end(*drawn[label]) == flow, label


# ---------------------------------------------------------------- untrusted text


HOSTILE = 'evil " ] ; } { "a" -> "b" [label=<b>x</b>] \\N \\G \\ & &amp; \' // <!-- -->'


def test_hostile_doc_strings_stay_in_their_strings(tmp_path):
    written = '"' + HOSTILE.replace("\\", "\\\\").replace('"', '\\"') + '"'
    model = tmp_path / "evil.bg"
    model.write_text(f'model evil {written}\nsrc : Se(1) {written}\nj : 1\n'
                     f'c : C(1)\nsrc -> j\nj -> c\n', encoding="utf-8")
    compiled = api.build(str(model), None, program=False)
    doc = compiled.graph.by_name["src"].doc
    assert doc == HOSTILE and '"' in doc and "\\" in doc and "<b>" in doc
    text = draw.draw_dot(compiled)
    g = read_dot(text)
    assert sorted(g["nodes"]) == ["c", "j", "src"] and len(g["edges"]) == 2
    shown = doc.replace("\\", draw.BACKSLASH)  # Graphviz would expand \N, \G
    assert "\\" not in text.replace('\\"', "")
    assert html.unescape(g["nodes"]["src"]["tooltip"]) == shown
    assert shown in html.unescape(g["graph"]["label"])
    if HAVE_DOT:
        svg = draw.render(text, "svg").decode("utf-8")
        root = ET.fromstring(svg)  # well-formed XML: nothing broke out of a label
        titles = [el.get("{http://www.w3.org/1999/xlink}title") for el in root.iter()]
        assert shown in titles
        texts = " ".join(el.text or "" for el in root.iter("{http://www.w3.org/2000/svg}text"))
        assert shown in texts


def test_escaping_of_any_text():
    for s in ['a\nb', 'q"uote', 'back\\slash\\', '<tag>&amp;', '\x00\x07ctl', '}{][;']:
        (kind, value), = tokens(draw._quoted(s))
        assert kind == "str" and "\n" not in value and "\x00" not in value
        assert html.unescape(value) == draw._clean(s)
        assert "\\" not in draw._clean(s)
        (kind, value), = tokens("<" + draw._html(s) + ">")
        assert text_of(value) == draw._clean(s)


# ---------------------------------------------------------------- determinism


def test_same_bytes_every_run(pendulum):
    compiled, text, _ = pendulum
    assert draw.draw_dot(compiled) == text
    again = api.build(PENDULUM, "swing", program=False)
    assert draw.draw_dot(again) == text
    env = dict(os.environ, PYTHONHASHSEED="12345", PATH="/nonexistent")
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(ROOT), env.get("PYTHONPATH")]))
    done = subprocess.run([sys.executable, "-m", "bgc", "draw", PENDULUM, "--scene", "swing"],
                          capture_output=True, text=True, env=env, timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stdout == text


# ---------------------------------------------------------------- the command line


def test_cli_dot_file_and_stdout(tmp_path):
    done = run_bgc("draw", PENDULUM, "--scene", "swing", "-o", tmp_path / "p.dot")
    assert done.returncode == 0, done.stderr
    text = (tmp_path / "p.dot").read_text(encoding="utf-8")
    assert text == run_bgc("draw", PENDULUM, "--scene", "swing", "-o", "-").stdout
    assert text == run_bgc("draw", PENDULUM, "--scene", "swing").stdout
    read_dot(text)


def test_cli_unknown_extension_is_a_usage_error(tmp_path):
    done = run_bgc("draw", tmp_path / "missing.bg", "-o", tmp_path / "p.pdf")
    assert done.returncode == 2 and ".svg" in done.stderr
    assert not (tmp_path / "p.pdf").exists()


def test_cli_without_graphviz(tmp_path):
    empty = tmp_path / "bin"
    empty.mkdir()
    done = run_bgc("draw", PENDULUM, "-o", tmp_path / "p.png", env={"PATH": str(empty)})
    assert done.returncode == 1
    assert "Graphviz" in done.stderr and "FILE.dot" in done.stderr
    assert "Traceback" not in done.stderr
    assert list(tmp_path.iterdir()) == [empty], "no output file"


def test_render_without_graphviz(monkeypatch, tmp_path):
    monkeypatch.setenv("PATH", str(tmp_path))
    with pytest.raises(draw.GraphvizMissing, match="apt install graphviz"):
        draw.render("digraph { }", "svg")
    assert draw.render("digraph { }", "dot") == b"digraph { }"


@pytest.mark.skipif(not HAVE_DOT, reason="Graphviz's dot is not installed")
def test_cli_svg_and_png(tmp_path):
    done = run_bgc("draw", PENDULUM, "--scene", "swing", "-o", tmp_path / "p.svg")
    assert done.returncode == 0, done.stderr
    root = ET.parse(tmp_path / "p.svg").getroot()
    ids = {el.get("id") for el in root.iter()}
    assert {"bond vx->mx", "bond tx->rod"} <= ids
    done = run_bgc("draw", PENDULUM, "-o", tmp_path / "p.png")
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "p.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["p.png", "p.svg"]


# ---------------------------------------------------------------- instances of components

def _circuit(tmp_path):
    """test_components' circuit: instance p1 of hyd.pipe, which holds p1.o, an orifice."""
    (tmp_path / "hyd.bg").write_text(HYD)
    path = tmp_path / "circuit.bg"
    path.write_text(CIRCUIT.format(what="hyd", alias="hyd"))
    return path


def _nested(tmp_path, *args):
    done = run_bgc("draw", _circuit(tmp_path), *args)
    assert done.returncode == 0, done.stderr
    return read_dot(done.stdout)


def test_one_cluster_per_instance(tmp_path):
    g = _nested(tmp_path)
    assert g["clusters"]["cluster p1"] == ["p1.j", "p1.fluid"]
    assert g["clusters"]["cluster p1.o"] == ["p1.o.res"]
    assert {"p1.j", "p1.fluid", "p1.o.res", "pump", "tank"} <= set(g["nodes"])
    assert ("p1.j", "p1.o.res") in [(a, b) for a, b, _ in g["edges"]]


def test_depth_collapses_deeper_instances_into_boxes_with_their_ports(tmp_path):
    g = _nested(tmp_path, "--depth", "1")
    assert "cluster p1" in g["clusters"] and "cluster p1.o" not in g["clusters"]
    assert "p1.o.res" not in g["nodes"]
    assert text_of(g["nodes"]["p1.o"]["label"]) == "p1.o : orifice\nports a : hydraulic"
    assert ("p1.j", "p1.o") in [(a, b) for a, b, _ in g["edges"]]
    g = _nested(tmp_path, "--depth", "0")
    assert not g["clusters"] and set(g["nodes"]) == {"pump", "p1", "tank"}
    assert sorted((a, b) for a, b, _ in g["edges"]) == [("p1", "tank"), ("pump", "p1")]
    assert text_of(g["nodes"]["p1"]["label"]) == \
        "p1 : hyd.pipe\nports a : hydraulic, b : hydraulic"


def test_check_lists_the_instances(tmp_path):
    done = run_bgc("check", _circuit(tmp_path))
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    k = lines.index("instances (2):")
    assert lines[k + 1:k + 3] == ["  p1  hyd.pipe, ports a : hydraulic, b : hydraulic",
                                  "  p1.o  orifice, ports a : hydraulic"]
