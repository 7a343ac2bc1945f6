"""Coupled switched elements (docs/hybrid.md, section 13): a switch and its freewheeling diode
whose modes are chosen together.  The buck converter (models/buck.bg) is linear between its
events, so the reference here integrates it exactly, segment by segment, with matrix
exponentials: the PWM's edges are known, the diode's turn-off (the coil's current reaching
zero) is solved by brentq on the exact solution."""
import csv
import io
from pathlib import Path

import numpy as np
import pytest
from scipy.linalg import expm
from scipy.optimize import brentq

import bgc
from bgc.execute import runner

from conftest import have_cc

ROOT = Path(__file__).resolve().parent.parent
BACKENDS = (["c"] if have_cc() else []) + ["python", "vm"]
CCM = {}
DCM = {"L": 1e-5, "R": 20.0, "v0": 8.0}  # the coil's current reaches zero in each period


@pytest.fixture(scope="module")
def buck():
    return bgc.build(ROOT / "models" / "buck.bg", "run")


def run(compiled, backend, params, log, **options):
    program = runner.prepare(compiled, backend)
    names = [p.name for p in compiled.program.params]
    settings = runner.settings_for(compiled.program.scene, names, params=params,
                                   events=str(log), **options)
    result = runner.run(program, settings)
    assert result.status == 0, result.stderr
    rows = list(csv.reader(io.StringIO(result.csv)))
    return result.csv, np.array([[float(v) for v in r] for r in rows[1:]])


def buck_reference(t_out, V=12.0, L=1e-4, C=1e-5, R=5.0, T=1e-5, duty=0.5, v0=0.0):
    """(i_L, v_C) at t_out: z = (flux, charge, 1) moves by expm(A dt) in each mode: on (the
    node at V), freewheeling (the node at 0) and, once the current reaches zero with the
    switch open, both blocking (the current held at zero)."""
    def affine(node):  # flux' = v_node - q/C, q' = p/L - q/(R C)
        return np.array([[0, -1 / C, node], [1 / L, -1 / (R * C), 0], [0, 0, 0]])
    modes = {"on": affine(V), "free": affine(0.0),
             "dcm": np.array([[0, 0, 0], [0, -1 / (R * C), 0], [0, 0, 0]])}
    z, t, out, k = np.array([0.0, C * v0, 1.0]), 0.0, [], 0
    edges = sorted({n * T for n in range(int(t_out[-1] / T) + 2)} |
                   {(n + duty) * T for n in range(int(t_out[-1] / T) + 2)})
    pieces = []  # (t0, t1, mode, z0)
    for a, b in zip(edges, edges[1:]):
        on = (a / T) % 1 < duty - 1e-9
        if on:
            pieces.append((a, b, "on", z))
            z = expm(modes["on"] * (b - a)) @ z
            continue
        flux = lambda s: (expm(modes["free"] * (s - a)) @ z)[0]
        if z[0] > 0 and flux(b) < 0:
            tz = brentq(flux, a, b, xtol=1e-22, rtol=1e-15)
            pieces.append((a, tz, "free", z))
            z = expm(modes["free"] * (tz - a)) @ z
            z[0] = 0.0
            pieces.append((tz, b, "dcm", z))
            z = expm(modes["dcm"] * (b - tz)) @ z
        else:
            mode = "free" if z[0] > 0 else "dcm"
            pieces.append((a, b, mode, z))
            z = expm(modes[mode] * (b - a)) @ z
    for tq in t_out:
        a, b, mode, z0 = next(p for p in reversed(pieces) if p[0] <= tq)
        zq = expm(modes[mode] * (tq - a)) @ z0
        out.append((zq[0] / L, zq[1] / C))
    return np.array(out), [p for p in pieces if p[2] == "dcm" and p[0] < t_out[-1]]


@pytest.mark.parametrize("params", [CCM, DCM], ids=["continuous", "discontinuous"])
def test_the_buck_converter_against_its_exact_reference(buck, params, tmp_path):
    texts = {}
    for backend in BACKENDS:
        texts[backend], y = run(buck, backend, params, tmp_path / f"{backend}.csv",
                                rtol=1e-12, atol=1e-14)
    assert len(set(texts.values())) == 1, "the backends' CSVs differ"
    ref, dcm = buck_reference(y[:, 0], **params)
    assert bool(dcm) == (params is DCM)  # the discontinuous case does reach zero current
    scale = np.max(np.abs(ref), axis=0)
    err = np.max(np.abs(y[:, 1:] - ref) / scale)
    print(f"buck {'dcm' if params else 'ccm'}: max relative error {err:.2e}")
    assert err < 1e-8, err
    if params is DCM:
        events = list(csv.reader(open(tmp_path / "python.csv")))[1:]
        offs = [float(t) for t, what, change in events
                if what == "fw.blocking" and change == "0 -> 1"]
        for (t0, _, _, _), got in zip(dcm, offs):
            assert abs(got - t0) < 1e-12
        assert len(offs) == len(dcm)
