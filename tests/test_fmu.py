"""FMU export (`bgc compile --target fmu`): FMPy validates the pendulum's and the RLC's FMUs,
simulates them as Model Exchange (its CVODE) and as Co-Simulation (bgc's solver inside), and
the trajectories match bgc's own run of the same build; parameters set through FMPy change
the RLC as its closed-form solution says; the directional derivatives are the Jacobians
written out by hand; model text is escaped in the XML.  FMPy is an optional test dependency
(the `test` extra)."""
import ctypes
import shutil
import subprocess
import sys
import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path

import numpy as np
import pytest

import bgc
from bgc import api
from bgc.base import cache, processes, toolchain
from bgc.codegen import fmu
from bgc.codegen.emit import emit_c
from conftest import run_bgc

fmpy = pytest.importorskip("fmpy")
from fmpy.fmi2 import FMU2Model, FMU2Slave  # noqa: E402
from fmpy.validation import validate_fmu  # noqa: E402

if not toolchain.have_c_compiler():
    pytest.skip("FMU export builds its binary with a C compiler", allow_module_level=True)

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "tools"))
import fuzz_fmu  # noqa: E402
T_END = 2.0  # the runs compared: 200 output intervals of 0.01
RLC = dict(V0=1.0, resistance=0.5, inductance=1.0, capacitance=0.25, q0=0.1, i0=-0.2)
PENDULUM = dict(m=1.0, l=1.0, g=9.81, theta0=0.5, alpha=5.0, beta=5.0)  # models/pendulum.bg


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    """Each model built once: its Compiled, its FMU (the RLC's through the command line, the
    pendulum's through api.compile) and bgc's own run of the same program to T_END."""
    tmp = tmp_path_factory.mktemp("fmu")
    out = {}
    for name, scene in (("rlc", "step"), ("pendulum", "swing")):
        model = ROOT / "models" / f"{name}.bg"
        compiled = api.build(model, scene)
        path = tmp / f"{name}.fmu"
        if name == "rlc":
            done = run_bgc("compile", model, "--scene", scene, "--target", "fmu", "-o", path)
            assert done.returncode == 0, done.stderr
        else:
            ((file, data),) = api.compile(model, "fmu", scene).items()
            assert file == "pendulum.fmu"
            path.write_bytes(data)
        (text,) = emit_c(compiled.program).values()
        code, csv, err = processes.run_c(cache.compile_c(text), ["--t-end", str(T_END)])
        assert code == 0, err
        out[name] = (compiled, path, api._parse_csv(csv))
    return out


def simulate(path, kind, **options):
    if kind == "ModelExchange":
        options.setdefault("relative_tolerance", 1e-11)  # CVODE; the FMU's own is 1e-10
    return fmpy.simulate_fmu(str(path), fmi_type=kind, stop_time=T_END, output_interval=0.01,
                             **options)


def relative_difference(got, ref):
    return np.max(np.abs(got - ref)) / np.max(np.abs(ref))


@pytest.mark.parametrize("name", ["rlc", "pendulum"])
def test_fmpy_validates(built, name):
    assert validate_fmu(str(built[name][1])) == []


@pytest.mark.parametrize("kind", ["ModelExchange", "CoSimulation"])
@pytest.mark.parametrize("name", ["rlc", "pendulum"])
def test_trajectories_match_bgc(built, name, kind):
    _, path, (t, Y, names) = built[name]
    result = simulate(path, kind)
    assert np.array_equal(result["time"], t)
    for k, output in enumerate(names):
        if output == "rod.residual":  # Phi = x^2 + y^2 - l^2: zero up to the drift
            assert np.max(np.abs(result[output])) < 1e-8
        else:
            assert relative_difference(result[output], Y[:, k]) < 1e-6, output


def rlc_closed_form(t, V0, resistance, inductance, capacitance, q0, i0):
    """The series RLC's charge and current, underdamped: L q'' + R q' + q/C = V0."""
    alpha = resistance / (2 * inductance)
    wd = np.sqrt(1 / (inductance * capacitance) - alpha**2)
    a = q0 - capacitance * V0
    b = (i0 + alpha * a) / wd
    e = np.exp(-alpha * t)
    q = capacitance * V0 + e * (a * np.cos(wd * t) + b * np.sin(wd * t))
    i = e * ((b * wd - alpha * a) * np.cos(wd * t) - (a * wd + alpha * b) * np.sin(wd * t))
    return q, i


@pytest.mark.parametrize("kind", ["ModelExchange", "CoSimulation"])
def test_parameters_set_through_fmpy(built, kind):
    """A different resistance and inductance (and the initial flux linkage L i0 following
    the inductance): the closed form with those values."""
    changed = dict(RLC, resistance=1.0, inductance=0.5)
    result = simulate(built["rlc"][1], kind,
                      start_values={"resistance": 1.0, "inductance": 0.5})
    q, i = rlc_closed_form(result["time"], **changed)
    assert relative_difference(result["cap.q"], q) < 1e-6
    assert relative_difference(result["ind.p"], changed["inductance"] * i) < 1e-6
    assert relative_difference(result["cap.e"], q / changed["capacitance"]) < 1e-6
    assert relative_difference(result["res.e"], changed["resistance"] * i) < 1e-6
    assert relative_difference(q, rlc_closed_form(result["time"], **RLC)[0]) > 0.01


def test_variables_agree_with_the_model(built):
    for name, params in (("rlc", RLC), ("pendulum", PENDULUM)):
        compiled, path, (_, _, outputs) = built[name]
        md = fmpy.read_model_description(str(path))
        assert md.fmiVersion == "2.0" and md.numberOfEventIndicators == 0
        assert md.modelExchange.modelIdentifier == md.coSimulation.modelIdentifier == name
        assert md.modelExchange.providesDirectionalDerivative
        for kind in (md.modelExchange, md.coSimulation):
            assert kind.canGetAndSetFMUstate and kind.canSerializeFMUstate
        # the parameters as the model file declares them, settable before initialisation
        got = {v.name: float(v.start) for v in md.modelVariables if v.causality == "parameter"}
        assert got == params
        assert all(v.variability == "fixed" for v in md.modelVariables
                   if v.causality == "parameter")
        # the continuous states in the order of the derivatives: the model's states
        states = [d.variable.derivative.name for d in md.derivatives]
        assert states == list(compiled.program.states)
        assert [d.variable.name for d in md.derivatives] == [f"der({s})" for s in states]
        assert {v.name for v in md.modelVariables if v.causality == "output"} == set(outputs)
        assert {u.variable.name for u in md.outputs} == set(outputs)
        with zipfile.ZipFile(path) as z:
            assert sorted(z.namelist()) == sorted([
                "modelDescription.xml", f"binaries/linux64/{name}.so", f"sources/{name}.c"])
            assert md.guid in z.read(f"sources/{name}.c").decode()
    rlc = fmpy.read_model_description(str(built["rlc"][1]))
    units = {v.name: v.unit for v in rlc.modelVariables}
    assert units["V0"] == "V" and units["resistance"] == "ohm"
    # dq/dt = i = p/L depends on the flux linkage only; dp/dt = V0 - R p/L - q/C on both
    deps = {d.variable.name: sorted(v.name for v in d.dependencies) for d in rlc.derivatives}
    assert deps == {"der(ind.p)": ["cap.q", "ind.p"], "der(cap.q)": ["ind.p"]}


def test_same_xml_and_sources_every_time(built):
    compiled = built["pendulum"][0]
    first, second = fmu.fmu_texts(compiled), fmu.fmu_texts(compiled)
    assert first[1:] == second[1:]
    with zipfile.ZipFile(built["pendulum"][1]) as z:
        assert z.read("modelDescription.xml").decode() == first[1]


def instantiate(path, md, kind="ModelExchange"):
    unzip = fmpy.extract(str(path))
    ident = (md.modelExchange if kind == "ModelExchange" else md.coSimulation).modelIdentifier
    model = FMU2Model(guid=md.guid, unzipDirectory=unzip, modelIdentifier=ident,
                      instanceName="test")
    model.instantiate()
    return model, unzip


def test_directional_derivatives(built):
    """RLC, states (p, q): dp/dt = V0 - R p/L - q/C, dq/dt = p/L; outputs cap.e = q/C,
    ind.f = p/L.  Pendulum: rod.residual = x^2 + y^2 - l^2."""
    path = built["rlc"][1]
    md = fmpy.read_model_description(str(path))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    model, unzip = instantiate(path, md)
    try:
        model.setupExperiment(startTime=0.0)
        model.setReal([vr["resistance"], vr["inductance"]], [1.5, 0.5])
        model.enterInitializationMode()
        model.exitInitializationMode()
        model.enterContinuousTimeMode()
        R, L, C = 1.5, 0.5, RLC["capacitance"]
        unknowns = [vr["der(ind.p)"], vr["der(cap.q)"], vr["cap.e"], vr["ind.f"], vr["cap.q"]]
        dp = model.getDirectionalDerivative(unknowns, [vr["ind.p"]], [1.0])
        dq = model.getDirectionalDerivative(unknowns, [vr["cap.q"]], [1.0])
        assert np.allclose(dp, [-R / L, 1 / L, 0.0, 1 / L, 0.0], rtol=1e-14, atol=0)
        assert np.allclose(dq, [-1 / C, 0.0, 1 / C, 0.0, 1.0], rtol=1e-14, atol=0)
        # parameters are fixed once initialisation has ended
        with pytest.raises(Exception):
            model.setReal([vr["resistance"]], [2.0])
        model.terminate()
    finally:
        model.freeInstance()
        shutil.rmtree(unzip, ignore_errors=True)

    path = built["pendulum"][1]
    md = fmpy.read_model_description(str(path))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    model, unzip = instantiate(path, md)
    try:
        model.setupExperiment(startTime=0.0)
        model.setReal([vr["theta0"]], [0.3])
        model.enterInitializationMode()
        model.exitInitializationMode()
        x, y = model.getReal([vr["x"], vr["y"]])
        assert np.allclose([x, y], [np.sin(0.3), np.cos(0.3)], rtol=1e-15)
        grad = model.getDirectionalDerivative([vr["rod.residual"]], [vr["x"], vr["y"]],
                                              [1.0, 2.0])
        assert np.isclose(grad[0], 2 * x + 2 * 2 * y, rtol=1e-14)
        model.terminate()
    finally:
        model.freeInstance()
        shutil.rmtree(unzip, ignore_errors=True)


def test_fmu_state_rolls_back_and_serialises(built):
    """Co-Simulation of the pendulum in steps of 0.01: the state saved at t = 1 (and its bytes,
    deserialised) brings the FMU back there, and the next 100 steps repeat bit for bit; they
    follow bgc's own run.  Model Exchange: a saved state restores the time and the states.
    A state of the other FMU type, or bytes that are not a state, are refused."""
    path = built["pendulum"][1]
    _, _, (t_ref, Y_ref, names) = built["pendulum"]
    md = fmpy.read_model_description(str(path))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    unzip = fmpy.extract(str(path))
    slave = FMU2Slave(guid=md.guid, unzipDirectory=unzip,
                      modelIdentifier=md.coSimulation.modelIdentifier, instanceName="cs")
    model = None
    try:
        slave.instantiate()
        slave.setupExperiment(startTime=0.0)
        slave.enterInitializationMode()
        slave.exitInitializationMode()
        refs = [vr["x"], vr["y"]]

        def run(k0, n):
            out = []
            for k in range(k0, k0 + n):
                slave.doStep(k * 0.01, 0.01)
                out.append(slave.getReal(refs))
            return np.array(out)

        run(0, 100)
        state = slave.getFMUState()
        blob = slave.serializeFMUState(state)
        first = run(100, 100)
        slave.setFMUState(state)
        assert np.array_equal(run(100, 100), first)
        restored = slave.deserializeFMUState(blob)
        slave.setFMUState(restored)
        assert np.array_equal(run(100, 100), first)
        columns = [names.index("x"), names.index("y")]
        assert np.allclose(t_ref[101:201], np.arange(101, 201) * 0.01, atol=1e-12)
        assert relative_difference(first, Y_ref[101:201][:, columns]) < 1e-6
        # refused: bytes that are not a state, and a state of the other FMU type
        with pytest.raises(Exception):
            slave.deserializeFMUState(bytes(len(blob)))
        model, unzip_me = instantiate(path, md)
        model.setupExperiment(startTime=0.0)
        model.enterInitializationMode()
        model.exitInitializationMode()
        with pytest.raises(Exception):
            model.setFMUState(state)
        model.enterContinuousTimeMode()
        model.setTime(0.25)
        array = ctypes.c_double * 4
        model.setContinuousStates(array(0.5, -0.5, 0.25, 0.75), 4)
        saved = model.getFMUState()
        model.setTime(0.5)
        model.setContinuousStates(array(1.0, 2.0, 3.0, 4.0), 4)
        model.setFMUState(saved)
        x = array()
        model.getContinuousStates(x, 4)
        assert list(x) == [0.5, -0.5, 0.25, 0.75]
        model.freeFMUState(saved)
        slave.freeFMUState(state)
        slave.freeFMUState(restored)
    finally:
        slave.freeInstance()
        shutil.rmtree(unzip, ignore_errors=True)
        if model is not None:
            model.freeInstance()
            shutil.rmtree(unzip_me, ignore_errors=True)


NO_STATES = """model wire "a source and a resistor: no states"
parameter V = 2.0
src : Se(V)
j : 1
r : R(4.0)
src -> j
j -> r
"""


def test_only_the_fmi_functions_are_exported_and_the_sources_build(built, tmp_path):
    """The binary exports the FMI functions and nothing of bgc's; the sources compile as C99
    with every warning an error: the pendulum's, the diode's (its outputs go through a Newton
    block, and so do their derivatives) and a model without states."""
    path = built["pendulum"][1]
    with zipfile.ZipFile(path) as z:
        z.extractall(tmp_path)
    lib = ctypes.CDLL(str(tmp_path / "binaries" / "linux64" / "pendulum.so"))
    assert hasattr(lib, "fmi2DoStep") and hasattr(lib, "fmi2GetDirectionalDerivative")
    assert not hasattr(lib, "bgc_simulate") and not hasattr(lib, "bgc_rhs")
    sources = [tmp_path / "sources" / "pendulum.c"]
    for name, model in (("diode", bgc.load(ROOT / "models" / "diode.bg")),
                        ("wire", bgc.load("wire.bg", NO_STATES))):
        _, _, source = fmu.fmu_texts(api.build(model, "charge" if name == "diode" else None))
        sources.append(tmp_path / f"{name}.c")
        sources[-1].write_text(source, encoding="utf-8")
    for source in sources:
        done = subprocess.run([*toolchain.c_compiler(), "-std=c99", "-Wall", "-Wextra",
                               "-pedantic", "-Werror", "-fsyntax-only", str(source)],
                              capture_output=True, text=True)
        assert done.returncode == 0, done.stderr


def test_model_text_is_escaped(tmp_path):
    """Doc strings with XML's special characters and a control character: the XML parses and
    says what the model says."""
    text = ('model odd "a <b> & \\"c\\" ]]> %s\x01"\n'
            'parameter k = 2.0 "spring <k> [N/m]"\n'
            'parameter m = 2*k "mass & co [kg]"\n'
            'j : 1\n'
            'mass : I(m) init f = 1 "a \\"mass\\""\n'
            'spring : C(1/k)\n'
            'j -> mass\nj -> spring\n')
    compiled = api.build(bgc.load("odd.bg", text))
    _, xml, _ = fmu.fmu_texts(compiled)
    root = ET.fromstring(xml.encode("utf-8"))
    assert root.get("description") == 'a <b> & "c" ]]> %s\ufffd'
    variables = {v.get("name"): v for v in root.iter("ScalarVariable")}
    assert variables["k"].get("description") == "spring <k> [N/m]"
    assert variables["k"].find("Real").get("unit") == "N/m"
    assert variables["m"].find("Real").get("start") == "4.0"  # its default, 2 k
    assert variables["mass.p"].get("description").endswith('(a "mass")')
    (tmp_path / "modelDescription.xml").write_text(xml, encoding="utf-8")
    assert validate_fmu(str(tmp_path)) == []


UNITS = """model units "units declared with `unit`"
parameter k = 8 unit "N/m"
input push = 0 unit "N" "the force"
j : 1
mass : I(2)
spring : C(1/k)
f : MSe(push)
f -> j
j -> mass
j -> spring
signal x = integral(j.f, init = 0) unit "m"
signal energy = k*x^2/2 unit "J"
signal pair[2] = [x, 2*x] unit "m"
scene run { outputs x, energy, pair, mass.p }
"""


def test_declared_units_reach_the_variables(tmp_path):
    """`unit "..."` of a parameter, an input, a state's integral signal, a signal and a vector
    signal's parts is the unit of its variable in modelDescription.xml, each unit defined
    once; the units the laws give are there too (bgc.front.units: the force's N on the
    junction, x's m/s as its flow, so the mass's momentum is N*s and the spring's
    displacement m), their time derivatives in m/s and N, time in s."""
    (tmp_path / "units.bg").write_text(UNITS, encoding="utf-8")
    done = run_bgc("compile", "units.bg", "--scene", "run", "--target", "fmu",
                   "-o", "units.fmu", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    with zipfile.ZipFile(tmp_path / "units.fmu") as z:
        root = ET.fromstring(z.read("modelDescription.xml"))
    units = {v.get("name"): v.find("Real").get("unit") for v in root.iter("ScalarVariable")}
    assert units == {"k": "N/m", "push": "N", "x": "m", "energy": "J", "pair[0]": "m",
                     "pair[1]": "m", "mass.p": "N*s", "spring.q": "m", "der(x)": "m/s",
                     "der(mass.p)": "N", "der(spring.q)": "m/s", "time": "s"}
    assert [u.get("name") for u in root.iter("Unit")] == ["N/m", "N*s", "m", "N", "m/s", "J", "s"]
    assert validate_fmu(str(tmp_path / "units.fmu")) == []


def test_a_saved_state_holds_the_inputs(tmp_path):
    """An input set before fmi2GetFMUstate is the input's value again after fmi2SetFMUstate
    (and after its bytes are read back), in both FMU types: it was left as last set."""
    path = tmp_path / "units.fmu"
    path.write_bytes(fmu.build_fmu(api.build(bgc.load("units.bg", UNITS), "run")))
    md = fmpy.read_model_description(str(path))
    (push,) = [v.valueReference for v in md.modelVariables if v.name == "push"]
    unzip = fmpy.extract(str(path))
    for cls, ident in ((FMU2Model, md.modelExchange), (FMU2Slave, md.coSimulation)):
        instance = cls(guid=md.guid, unzipDirectory=unzip,
                       modelIdentifier=ident.modelIdentifier, instanceName="in")
        try:
            instance.instantiate()
            instance.setupExperiment(startTime=0.0)
            instance.enterInitializationMode()
            instance.exitInitializationMode()
            instance.setReal([push], [2.0])
            state = instance.getFMUState()
            blob = instance.serializeFMUState(state)
            instance.setReal([push], [5.0])
            instance.setFMUState(state)
            assert instance.getReal([push]) == [2.0]
            instance.setReal([push], [5.0])
            instance.setFMUState(instance.deserializeFMUState(blob))
            assert instance.getReal([push]) == [2.0]
        finally:
            instance.fmi2FreeInstance(instance.component)
    shutil.rmtree(unzip, ignore_errors=True)


def test_command_line_errors(tmp_path):
    done = run_bgc("compile", ROOT / "models" / "rlc.bg", "--target", "fmu")
    assert done.returncode == 2 and "-o NAME.fmu" in done.stderr
    done = run_bgc("compile", ROOT / "models" / "pendulum.bg", "--outputs", "x, m",
                   "--target", "fmu", "-o", tmp_path / "p.fmu")
    assert done.returncode == 1 and "output 'm' is a parameter" in done.stderr
    assert not (tmp_path / "p.fmu").exists() and list(tmp_path.iterdir()) == []
    with pytest.raises(ValueError, match="target"):
        api.compile(ROOT / "models" / "rlc.bg", "fmu2")


def test_an_inconsistent_start_when_asked_for(tmp_path):
    """compile --target fmu --allow-inconsistent: the FMU starts off the constraint as the
    program does with --allow-inconsistent (and follows the same trajectory)."""
    model = ROOT / "tests" / "models" / "pendulum_offset.bg"
    path = tmp_path / "offset.fmu"
    done = run_bgc("compile", model, "--target", "fmu", "--allow-inconsistent", "-o", path,
                   "--outputs", "x, y")
    assert done.returncode == 0, done.stderr
    options = dict(start_values={"r0": 1.05}, stop_time=1.0, output_interval=0.01)
    got = fmpy.simulate_fmu(str(path), fmi_type="CoSimulation", **options)
    compiled = api.build(model, allow_inconsistent=True, outputs="x, y")
    (text,) = emit_c(compiled.program).values()
    code, csv, err = processes.run_c(cache.compile_c(text), [
        "--t-end", "1", "--dt", "0.01", "-p", "r0=1.05", "--allow-inconsistent"])
    assert code == 0, err
    t, Y, names = api._parse_csv(csv)
    assert abs(Y[0, 0] ** 2 + Y[0, 1] ** 2 - 1.05 ** 2) < 1e-12  # off the rod (l = 1)
    for k, name in enumerate(names):
        assert relative_difference(got[name], Y[:, k]) < 1e-6, name


def test_output_derivatives_through_a_newton_block(tmp_path):
    """The diode's current is solved by Newton's method in the generated code; its derivative
    with respect to the capacitor's charge (through the block, by the pass that derives jvp)
    agrees with a central difference of the output itself."""
    path = tmp_path / "diode.fmu"
    path.write_bytes(fmu.build_fmu(api.build(bgc.load(ROOT / "models" / "diode.bg"), "charge")))
    md = fmpy.read_model_description(str(path))
    assert md.modelExchange.providesDirectionalDerivative
    vr = {v.name: v.valueReference for v in md.modelVariables}
    model, unzip = instantiate(path, md)
    try:
        model.setupExperiment(startTime=0.0)
        model.enterInitializationMode()
        model.exitInitializationMode()
        model.enterContinuousTimeMode()
        states = [d.variable.derivative.name for d in md.derivatives]
        x = model.getReal([vr[s] for s in states])
        k = states.index("cap.q")
        (got,) = model.getDirectionalDerivative([vr["d1.f"]], [vr["cap.q"]], [1.0])
        h = 1e-6 * max(abs(x[k]), 1e-3)
        sides = []
        for sign in (1, -1):
            moved = (ctypes.c_double * len(x))(*x)
            moved[k] += sign * h
            model.setContinuousStates(moved, len(x))
            sides.append(model.getReal([vr["d1.f"]])[0])
        assert got != 0 and np.isclose(got, (sides[0] - sides[1]) / (2 * h), rtol=1e-5)
        model.terminate()
    finally:
        model.freeInstance()
        shutil.rmtree(unzip, ignore_errors=True)


# ---------------------------------------------------------------- the life cycle

OK, ERROR = 0, 3


def _run_calls(path, tmp, calls):
    """calls [(request, status FMI 2.0 wants)] made one by one through ctypes, in a process
    of its own (tools/fuzz_fmu.py's, so that a crash fails the test, not the suite): each
    answer."""
    fmu_ = fuzz_fmu.extract(path, tmp)
    runner = fuzz_fmu.Runner(fmu_.binary, time_limit=30)
    answers = []
    try:
        for request, _ in calls:
            request = {k: fmu_.guid if v == "GUID" else v for k, v in request.items()}
            answers.append(runner.call(request))
    finally:
        runner.stop()
    return fmu_, answers


def _call(op, **args):
    return {"op": op, "slot": 0, **args}


def test_the_life_cycle_through_ctypes(built, tmp_path):
    """The RLC's binary called through ctypes as FMI 2.0's state machines say (its tables,
    sections 3.2.3 and 4.2.4): a call of a state that does not allow it, of the other FMU
    type, or through a handle that is NULL (before fmi2Instantiate) or freed is fmi2Error;
    fmi2FreeInstance twice returns (no crash); the refusals of a live instance are logged,
    those of a freed one cannot be (its logger need not exist); a refused call changes
    nothing, so the legal calls after it go on."""
    p = {v.name: v.valueReference
         for v in fmpy.read_model_description(str(built["rlc"][1])).modelVariables}
    me = [
        (_call("fmi2GetReal", vr=[0]), ERROR),  # before fmi2Instantiate: a NULL handle
        (_call("fmi2Instantiate", kind="me", guid="GUID", name="me", logging=False), OK),
        (_call("fmi2GetReal", vr=[0]), ERROR),  # instantiated: no values before initialization
        (_call("fmi2GetDerivatives", n=2), ERROR),
        (_call("fmi2DoStep", t=0.0, h=0.1), ERROR),  # Co-Simulation's
        (_call("fmi2SetupExperiment", tol=None, start=0.0), OK),
        (_call("fmi2EnterInitializationMode"), OK),
        (_call("fmi2EnterInitializationMode"), ERROR),
        (_call("fmi2GetReal", vr=[p["resistance"], p["cap.q"]]), OK),
        (_call("fmi2ExitInitializationMode"), OK),
        (_call("fmi2SetContinuousStates", n=2, values=[0.1, 0.2]), ERROR),  # event mode
        (_call("fmi2SetReal", vr=[p["resistance"]], values=[2.0]), ERROR),  # fixed by now
        (_call("fmi2NewDiscreteStates"), OK),
        (_call("fmi2EnterContinuousTimeMode"), OK),
        (_call("fmi2SetContinuousStates", n=2, values=[0.1, 0.2]), OK),
        (_call("fmi2NewDiscreteStates"), ERROR),  # continuous-time mode
        (_call("fmi2Terminate"), OK),
        (_call("fmi2SetTime", t=1.0), ERROR),
        (_call("fmi2GetReal", vr=[p["ind.p"], p["time"]]), OK),  # terminated: values
        (_call("fmi2Terminate"), ERROR),
        (_call("fmi2FreeInstance"), None),
        (_call("fmi2FreeInstance"), None),  # twice
        (_call("fmi2GetReal", vr=[0]), ERROR),
        (_call("fmi2Reset"), ERROR),
        (_call("fmi2SetupExperiment", tol=None, start=0.0), ERROR),
    ]
    cs = [
        (_call("fmi2Instantiate", kind="cs", guid="GUID", name="cs", logging=True), OK),
        (_call("fmi2ExitInitializationMode"), ERROR),
        (_call("fmi2EnterInitializationMode"), OK),
        (_call("fmi2EnterEventMode"), ERROR),  # Model Exchange's
        (_call("fmi2ExitInitializationMode"), OK),
        (_call("fmi2DoStep", t=0.0, h=0.125), OK),
        (_call("fmi2DoStep", t=0.0, h=0.125), ERROR),  # not the FMU's time
        (_call("fmi2DoStep", t=0.125, h=0.125), OK),
        (_call("fmi2GetReal", vr=[p["time"]]), OK),
        (_call("fmi2SetReal", vr=[p["time"]], values=[1.0]), ERROR),  # independent
        (_call("fmi2Terminate"), OK),
        (_call("fmi2DoStep", t=0.25, h=0.125), ERROR),  # after fmi2Terminate
        (_call("fmi2GetRealStatus", kind=2), OK),  # fmi2LastSuccessfulTime
        (_call("fmi2Reset"), OK),
        (_call("fmi2GetReal", vr=[p["time"]]), ERROR),  # instantiated again
        (_call("fmi2FreeInstance"), None),
        (_call("fmi2FreeInstance"), None),
        (_call("fmi2DoStep", t=0.0, h=0.125), ERROR),
    ]
    for kind, calls in (("me", me), ("cs", cs)):
        _, answers = _run_calls(built["rlc"][1], tmp_path / kind, calls)
        live = False  # (a handle of an instance, not yet freed)
        for (request, want), got in zip(calls, answers):
            assert got["status"] == want, (request, got)
            live = request["op"] == "fmi2Instantiate" or live \
                and request["op"] != "fmi2FreeInstance"
            if want == ERROR:  # logged (errors always are), where there is a logger
                assert got["errors"] == (1 if live else 0), (request, got)
    assert answers[8]["values"] == [0.125 + 0.125]  # time: the communication point reached


FMPY_LIFE = """
import ctypes
import sys
from fmpy import read_model_description, extract
from fmpy.fmi2 import FMU2Model, FMU2Slave
path = sys.argv[1]
md = read_model_description(path)
unzip = extract(path)
def fails(call, *args):
    try:
        call(*args)
    except Exception as e:
        return "status 3" in str(e)
    return False
model = FMU2Model(guid=md.guid, unzipDirectory=unzip,
                  modelIdentifier=md.modelExchange.modelIdentifier, instanceName="me")
model.instantiate()
assert fails(model.getReal, [0])  # before initialization
model.setupExperiment(startTime=0.0)
model.enterInitializationMode()
model.exitInitializationMode()
x = (ctypes.c_double * 2)(0.1, 0.2)
assert fails(model.setContinuousStates, x, 2)  # event mode
model.fmi2FreeInstance(model.component)
model.fmi2FreeInstance(model.component)  # twice: returns
assert fails(model.getReal, [0])  # after fmi2FreeInstance
slave = FMU2Slave(guid=md.guid, unzipDirectory=unzip,
                  modelIdentifier=md.coSimulation.modelIdentifier, instanceName="cs")
slave.instantiate()
slave.setupExperiment(startTime=0.0)
slave.enterInitializationMode()
slave.exitInitializationMode()
slave.doStep(0.0, 0.5)
slave.terminate()
assert fails(slave.doStep, 0.5, 0.5)  # after fmi2Terminate
slave.fmi2FreeInstance(slave.component)
slave.fmi2FreeInstance(slave.component)
assert fails(slave.getReal, [0])
print("done")
"""


def test_the_life_cycle_through_fmpy(built):
    """FMPy's calls of the same misuses, in a process of its own: each an error (FMPy raises
    on fmi2Error) and, on a live instance, logged; fmi2FreeInstance twice returns."""
    done = subprocess.run([sys.executable, "-c", FMPY_LIFE, str(built["rlc"][1])],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    # FMPy's logger prints what the FMU logged: each refusal of a live instance
    assert done.stdout.splitlines() == [
        "[ERROR] fmi2GetReal: not allowed in the instantiated state",
        "[ERROR] fmi2SetContinuousStates: not allowed in event mode",
        "[ERROR] fmi2DoStep: not allowed in the terminated state", "done"]


# ---------------------------------------------------------------- degenerate models

DEGENERATE = {  # every one a valid FMU: its variables at least the time
    "empty": "model empty\n",
    "no_states_no_parameters": "model src\nsrc : Se(2)\nj : 1\nr : R(4)\nsrc -> j\nj -> r\n",
    "no_states_no_outputs": NO_STATES,
    "no_parameters": "model np\nj : 1\nm : I(1) init f = 1\nk : C(1)\nj -> m\nj -> k\n",
    "only_parameters": "model p\nparameter a = 1\nparameter b = 2*a\n",
    "only_a_signal": "model s\nsignal y = sin(t)\n",
    "only_an_input": "model u\ninput u = 0\n",
    "a_constant_output": "model c\nsignal y = 3\nscene run { outputs y }\n",
}


@pytest.mark.parametrize("name", list(DEGENERATE))
def test_degenerate_models_give_valid_fmus(name, tmp_path, capsys):
    """FMPy's validator takes the description of each (the schema wants a variable in
    ModelVariables: an empty model had none), and fmpy.dump lists it; the time is FMI 2.0's
    independent variable, listed last, without a start."""
    text = DEGENERATE[name]
    compiled = api.build(bgc.load(f"{name}.bg", text), "run" if "scene" in text else None)
    _, xml, _ = fmu.fmu_texts(compiled)
    (tmp_path / "modelDescription.xml").write_text(xml, encoding="utf-8")
    assert validate_fmu(str(tmp_path)) == []
    fmpy.dump(str(tmp_path), causalities=["independent"])
    assert "time               independent" in capsys.readouterr().out
    md = fmpy.read_model_description(str(tmp_path))
    last = md.modelVariables[-1]
    assert (last.name, last.causality, last.variability, last.start) == \
        ("time", "independent", "continuous", None)
    assert [v.causality for v in md.modelVariables].count("independent") == 1


def test_an_empty_model_runs_as_an_fmu(tmp_path):
    """The empty model's FMU (the time its only variable) runs in FMPy, both types, and its
    time is the communication point reached."""
    path = tmp_path / "empty.fmu"
    path.write_bytes(fmu.build_fmu(api.build(bgc.load("empty.bg", DEGENERATE["empty"]))))
    assert validate_fmu(str(path)) == []
    for kind in ("ModelExchange", "CoSimulation"):
        result = fmpy.simulate_fmu(str(path), fmi_type=kind, stop_time=0.5,
                                   output_interval=0.125, output=["time"])
        assert list(result["time"]) == [0.0, 0.125, 0.25, 0.375, 0.5]
    md = fmpy.read_model_description(str(path))
    unzip = fmpy.extract(str(path))
    slave = FMU2Slave(guid=md.guid, unzipDirectory=unzip,
                      modelIdentifier=md.coSimulation.modelIdentifier, instanceName="cs")
    try:
        slave.instantiate()
        slave.setupExperiment(startTime=0.0)
        slave.enterInitializationMode()
        slave.exitInitializationMode()
        for k in range(3):
            slave.doStep(k * 0.1, 0.1)
        assert slave.getReal([md.modelVariables[0].valueReference]) == [0.1 + 0.1 + 0.1]
        slave.terminate()
    finally:
        slave.freeInstance()
        shutil.rmtree(unzip, ignore_errors=True)
