"""Golden files per model and scene: the check dump and the equation dump of every scene, the C
program and the Python module of each model's default scene and of the scenes in CODE_SCENES.
A diff shows which stage changed; `pytest --update-golden` rewrites them."""
import hashlib
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import sympy as sp

import bgc
from bgc.api import read_source
from bgc.base import processes, toolchain
from bgc.codegen.emit import c_runtime_parts, emit_c, emit_python, python_runtime
from bgc.front.graph import TIME, var
from bgc.front.instantiate import front
from bgc.front.resolve import resolve
from bgc.middle.reduce import explicit_forms
from bgc.reports.report import check_report, equations_text
from helpers import built

ROOT = Path(__file__).resolve().parent.parent
GOLDEN = Path(__file__).parent / "golden"
MODEL_FILES = sorted((ROOT / "models").glob("*.bg"))


# The scenes whose generated code (besides the default scenes') has golden files: each takes a
# path of the code generator that no default scene takes (a default scene outputs the states
# and keeps every constraint's corrector).  Every other scene's C and Python differ from its
# model's default scene's only in what the dumps of that scene (golden too) already show: its
# outputs, effects and settings; test_golden still compiles each one strictly.
CODE_SCENES = {
    ("pendulum", "swing"): "a multiplier and a residual as outputs",
    ("pendulum", "unstabilised"): "a holonomic constraint without a corrector",
    ("knife_edge", "unstabilised"): "a nonholonomic constraint without a corrector",
    ("diode", "charge"): "outputs computed through a Newton block",
    ("gantry_crane", "swing"): "states that no output needs are not integrated",
}


def has_code_golden(path, scene) -> bool:
    return scene is None or (path.stem, scene) in CODE_SCENES


def scene_names(path) -> list:
    """The model's scenes, from the front end alone (the test ids are made at collection)."""
    return [s.name for s in resolve(front(read_source(path))).scenes]


def _cases():
    for path in MODEL_FILES:
        for scene in [None] + scene_names(path):
            yield pytest.param(path, scene, id=f"{path.stem}-{scene or 'default'}")


CASES = list(_cases())


def test_code_scenes_exist():
    """CODE_SCENES names scenes of the models (a renamed scene would drop its golden files)."""
    cases = {(p.values[0].stem, p.values[1]) for p in CASES}
    assert set(CODE_SCENES) <= cases


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


OPTIMISED = ("gantry_crane", "diode", "pendulum_chain", "knife_edge", "two_link_arm")


@pytest.mark.parametrize("path, scene", CASES)
def test_golden(path, scene, golden, tmp_path):
    """The scene's dumps, and its code where it has golden files (CODE_SCENES); and its C
    program compiles without a warning (compile_strictly)."""
    code = has_code_golden(path, scene)
    compiled = built(path, scene)
    base = GOLDEN / path.stem / (scene or "default")
    golden(base.with_suffix(".check.txt"), check_report(compiled))
    golden(base.with_suffix(".equations.txt"), equations_text(compiled))
    (c_text,) = emit_c(compiled.program).values()
    if code:
        (py_text,) = emit_python(compiled.program).values()
        assert "[runtime: runtime]" in model_part(c_text)
        assert "[runtime: python]" in model_part(py_text)
        golden(base.with_suffix(".c"), model_part(c_text))
        golden(base.with_suffix(".py"), model_part(py_text))
    else:
        for suffix in (".c", ".py"):
            assert not base.with_suffix(suffix).exists(), \
                f"{base.with_suffix(suffix).relative_to(ROOT)} is no golden file (CODE_SCENES)"
    if toolchain.have_c_compiler():
        compile_strictly(c_text, tmp_path, link=scene is None and path.stem in OPTIMISED)


def compile_strictly(text: str, tmp_path, link: bool):
    """Every scene's program compiles without a warning, checked by the front end; the default
    scene of the models in OPTIMISED (one of each kind of generated code: LU blocks unrolled
    and not, Newton blocks, velocity constraints, a large model) is also built and linked at
    -O2, where some warnings need the optimiser's analysis.  (The runtime, the same bytes in
    every program, is built at -O1, -O2 and -O3 by test_emit.)"""
    src = tmp_path / "model.c"
    src.write_text(text)
    cc = os.environ.get("CC", "cc")
    how = ["-O2", str(src), "-o", str(tmp_path / "model"), "-lm"] if link else \
        ["-fsyntax-only", str(src)]
    proc = subprocess.run([cc, "-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic", *how],
                          capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr


def _symbolic_path(path) -> bool:
    """Models whose blocks are small and linear: their equations have an explicit form
    (the others are checked against references in test_algebra.py)."""
    return all(b.linear and len(b.unknowns) <= 2 for b in built(path).reduced.blocks)


# The models of _symbolic_path, named so that collecting the tests builds no model
# (test_symbolic_models_are_listed keeps the list true).
SYMBOLIC = ("buck", "car_axis", "car_axis_vector", "dc_motor", "double_pendulum",
            "double_pendulum_vector", "gantry_crane", "knife_edge", "ladder", "parallel_caps", "parallel_caps_dual",
            "pendulum", "pendulum_vector", "pendulum_wall", "rc_pair", "rlc", "twin_motors",
            "two_link_arm", "van_der_pol")


@pytest.mark.parametrize("path", [p for p in MODEL_FILES if p.stem not in SYMBOLIC],
                         ids=lambda p: p.stem)
def test_symbolic_models_are_listed(path):
    assert not _symbolic_path(path)


@pytest.mark.parametrize("path", [p for p in MODEL_FILES if p.stem in SYMBOLIC],
                         ids=lambda p: p.stem)
def test_python_rhs_matches_sympy_at_random_points(path):
    """The generated module's rhs against SymPy's own evaluation of the reduced equations
    (arbitrary precision, no code printer involved), solved symbolically."""
    assert _symbolic_path(path), "SYMBOLIC names it"
    compiled = built(path)
    (text,) = emit_python(compiled.program).values()
    module = processes.load_python_module(text)
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
    "import hashlib, json, sys, bgc\n"
    "from bgc.codegen.emit import c_runtime_parts, emit_c, emit_python, python_runtime\n"
    "from bgc.reports.report import equations_text\n"
    "parts = dict(c_runtime_parts(), python=python_runtime())\n"
    "def model_part(text):  # as test_golden.model_part\n"
    "    for name, part in parts.items():\n"
    "        text = text.replace(part, f'[runtime: {name}]\\n')\n"
    "    return text\n"
    "for path, scene, suffixes in json.load(sys.stdin):\n"
    "    c = bgc.build(path, scene, program='c' in suffixes)\n"
    "    texts = {'equations.txt': lambda: equations_text(c),\n"
    "             'c': lambda: model_part(next(iter(emit_c(c.program).values()))),\n"
    "             'py': lambda: model_part(next(iter(emit_python(c.program).values())))}\n"
    "    for suffix in suffixes:\n"
    "        h = hashlib.sha256(texts[suffix]().encode()).hexdigest()\n"
    "        print(path, scene or 'default', suffix, h)\n"
)


def _seed_cases() -> list:
    """What the other process makes: each model's default scene and the scenes of CODE_SCENES
    (code and equations), and each model's first other scene (equations)."""
    cases = []
    for path in MODEL_FILES:
        rel = str(path.relative_to(ROOT))
        cases.append([rel, None, ["c", "py", "equations.txt"]])
        for k, scene in enumerate(scene_names(path)):
            if (path.stem, scene) in CODE_SCENES:
                cases.append([rel, scene, ["c", "py", "equations.txt"]])
            elif k == 0:
                cases.append([rel, scene, ["equations.txt"]])
    return cases


def test_generated_code_identical_under_hash_seeds():
    """Every model's code (less the runtime) and equations, made in a process with another hash
    seed, are the golden files' bytes (which test_golden finds this process makes)."""
    seed = "4242" if os.environ.get("PYTHONHASHSEED") != "4242" else "1"
    cases = _seed_cases()
    done = subprocess.run([sys.executable, "-c", HASHES], cwd=ROOT, text=True,
                          input=json.dumps(cases), capture_output=True,
                          env=dict(os.environ, PYTHONHASHSEED=seed,
                                   PYTHONPATH=str(ROOT)))
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    assert len(lines) == sum(len(suffixes) for _, _, suffixes in cases)
    assert len(lines) >= 3 * len(MODEL_FILES)
    for line in lines:
        model, scene, suffix, digest = line.split()
        golden = (GOLDEN / Path(model).stem / f"{scene}.{suffix}").read_text(encoding="utf-8")
        assert digest == hashlib.sha256(golden.encode()).hexdigest(), (model, scene, suffix)
