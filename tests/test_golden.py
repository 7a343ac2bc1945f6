"""Golden files per model and scene: the check dump, the equation dump, the C program and the
Python module.  A diff shows which stage changed; `pytest --update-golden` rewrites them."""
import hashlib
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import sympy as sp

import bgc
from bgc.base import backends
from bgc.codegen.emit import c_runtime_parts, emit_c, emit_python, python_runtime
from bgc.front.graph import TIME, var
from bgc.middle.reduce import explicit_forms
from bgc.reports.report import check_report, equations_text

ROOT = Path(__file__).resolve().parent.parent
GOLDEN = Path(__file__).parent / "golden"
MODEL_FILES = sorted((ROOT / "models").glob("*.bg"))


def _cases():
    for path in MODEL_FILES:
        graph = bgc.build(path).graph
        for scene in [None] + [s.name for s in graph.scenes]:
            yield pytest.param(path, scene, id=f"{path.stem}-{scene or 'default'}")


CASES = list(_cases())


def model_part(text: str) -> str:
    """The generated file without its model-independent parts (the solver tables and the
    runtime of bgc/runtime/, the same in every file, in the runtime goldens below): the
    goldens of the models show what depends on the model."""
    parts = dict(c_runtime_parts(), python=python_runtime())
    for name, part in parts.items():
        assert text.count(part) <= 1
        text = text.replace(part, f"[runtime: {name}]\n")
    return text


def test_runtime_golden(golden):
    """The runtimes once, as they appear in every generated program."""
    parts = c_runtime_parts()
    golden(GOLDEN / "runtime" / "runtime.c",
           "\n".join((parts["solver_enum"], parts["api"], parts["runtime"])))
    golden(GOLDEN / "runtime" / "runtime.py", python_runtime())


@pytest.mark.parametrize("path, scene", CASES)
def test_golden(path, scene, golden):
    compiled = bgc.build(path, scene)
    base = GOLDEN / path.stem / (scene or "default")
    golden(base.with_suffix(".check.txt"), check_report(compiled))
    golden(base.with_suffix(".equations.txt"), equations_text(compiled))
    (c_text,) = emit_c(compiled.program).values()
    (py_text,) = emit_python(compiled.program).values()
    assert "[runtime: runtime]" in model_part(c_text)
    assert "[runtime: python]" in model_part(py_text)
    golden(base.with_suffix(".c"), model_part(c_text))
    golden(base.with_suffix(".py"), model_part(py_text))


OPTIMISED = ("gantry_crane", "diode", "pendulum_chain", "knife_edge", "two_link_arm")


@pytest.mark.skipif(not backends.have_c_compiler(), reason="no C compiler")
@pytest.mark.parametrize("path", MODEL_FILES, ids=lambda p: p.stem)
def test_generated_c_compiles_strictly(path, tmp_path):
    """Every scene's program compiles without a warning, checked by the front end; the default
    scene of the models in OPTIMISED (one of each kind of generated code: LU blocks unrolled
    and not, Newton blocks, velocity constraints, a large model) is also built and linked at
    -O2, where some warnings need the optimiser's analysis.  (The runtime, the same bytes in
    every program, is built at -O1, -O2 and -O3 by test_emit.)"""
    graph = bgc.build(path).graph
    for k, scene in enumerate([None] + [s.name for s in graph.scenes]):
        k = k if path.stem in OPTIMISED else 1
        (text,) = emit_c(bgc.build(path, scene).program).values()
        src = tmp_path / "model.c"
        src.write_text(text)
        cc = os.environ.get("CC", "cc")
        how = ["-O2", str(src), "-o", str(tmp_path / "model"), "-lm"] if k == 0 else \
            ["-fsyntax-only", str(src)]
        proc = subprocess.run([cc, "-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic", *how],
                              capture_output=True, text=True)
        assert proc.returncode == 0, proc.stderr


def _symbolic_path(path) -> bool:
    """Models whose blocks are small and linear: their equations have an explicit form
    (the others are checked against references in test_algebra.py)."""
    return all(b.linear and len(b.unknowns) <= 2 for b in bgc.build(path).reduced.blocks)


@pytest.mark.parametrize("path", [p for p in MODEL_FILES if _symbolic_path(p)],
                         ids=lambda p: p.stem)
def test_python_rhs_matches_sympy_at_random_points(path):
    """The generated module's rhs against SymPy's own evaluation of the reduced equations
    (arbitrary precision, no code printer involved), solved symbolically."""
    compiled = bgc.build(path, None)
    (text,) = emit_python(compiled.program).values()
    module = backends.load_python_module(text)
    r = bgc.build(path, None, algebra="symbolic").reduced
    forms = explicit_forms(r, r.rates, max_ops=20000)
    rng = np.random.default_rng(1)
    params = np.array(list(module.PARAMETERS.values()), dtype=float)
    psyms = [var(p.name) for p in compiled.graph.parameters]
    for _ in range(5):
        x = rng.uniform(0.2, 1.5, len(r.states))
        t = float(rng.uniform(0, 2))
        values = {st.symbol: sp.Float(v) for st, v in zip(r.states, x)}
        values.update({s: sp.Float(v) for s, v in zip(psyms, params)})
        values[TIME] = sp.Float(t)
        for d in r.rates:  # a discrete value is 0 (a relation false) where the module starts
            for s in forms[d].free_symbols - values.keys():
                values[s] = sp.false if s.name.startswith("event#") else sp.Integer(0)
        expected = [float(forms[d].xreplace(values).evalf(30)) for d in r.rates]
        got = module.rhs(t, x, params)
        np.testing.assert_allclose(got, expected, rtol=1e-12, atol=1e-12)


HASHES = (
    "import hashlib, sys, bgc\n"
    "from pathlib import Path\n"
    "from bgc.codegen.emit import c_runtime_parts, emit_c, emit_python, python_runtime\n"
    "from bgc.reports.report import equations_text\n"
    "parts = dict(c_runtime_parts(), python=python_runtime())\n"
    "def model_part(text):  # as test_golden.model_part\n"
    "    for name, part in parts.items():\n"
    "        text = text.replace(part, f'[runtime: {name}]\\n')\n"
    "    return text\n"
    "for p in sorted(Path('models').glob('*.bg')):\n"
    "    g = bgc.build(p, program=False).graph\n"
    "    for s in [None] + [x.name for x in g.scenes][:1]:\n"
    "        c = bgc.build(p, s)\n"
    "        texts = {'c': model_part(next(iter(emit_c(c.program).values()))),\n"
    "                 'py': model_part(next(iter(emit_python(c.program).values()))),\n"
    "                 'equations.txt': equations_text(c)}\n"
    "        for suffix, text in texts.items():\n"
    "            h = hashlib.sha256(text.encode()).hexdigest()\n"
    "            print(p.stem, s or 'default', suffix, h)\n"
)


def test_generated_code_identical_under_hash_seeds():
    """Every model's code (less the runtime) and equations, made in a process with another hash
    seed, are the golden files' bytes (which test_golden finds this process makes)."""
    seed = "4242" if os.environ.get("PYTHONHASHSEED") != "4242" else "1"
    done = subprocess.run([sys.executable, "-c", HASHES], cwd=ROOT, text=True,
                          capture_output=True,
                          env=dict(os.environ, PYTHONHASHSEED=seed,
                                   PYTHONPATH=str(ROOT)))
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    assert len(lines) >= 3 * len(MODEL_FILES)
    for line in lines:
        model, scene, suffix, digest = line.split()
        golden = (GOLDEN / model / f"{scene}.{suffix}").read_text(encoding="utf-8")
        assert digest == hashlib.sha256(golden.encode()).hexdigest(), (model, scene, suffix)
