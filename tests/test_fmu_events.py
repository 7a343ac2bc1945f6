"""FMU export of models with events (docs/hybrid.md): a bouncing ball (a state event and a
reinit), a thermostat (two state relations, one strict and one not, and a discrete variable)
and a first-order lag hit by a pulse (time events).  FMPy validates the FMUs; its Model
Exchange simulation (CVODE locating the event indicators' sign changes, stepping onto
nextEventTime, FMPy's event loop) and the Co-Simulation (bgc's solver inside fmi2DoStep,
events in the middle of a communication step) match bgc's own run of the model and the
closed-form solutions, the event times included."""
import ctypes
import csv
import math
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import bgc
from bgc.base import toolchain
from bgc.codegen import fmu
from bgc.api import Source

fmpy = pytest.importorskip("fmpy")
from fmpy.fmi2 import FMU2Model, FMU2Slave  # noqa: E402
from fmpy.validation import validate_fmu  # noqa: E402

from test_docs import blocks  # noqa: E402
from test_events import BALL, COUNT, LAG, bounce_times, build, lag_reference  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tools"))
import fuzz_fmu  # noqa: E402

if not toolchain.have_c_compiler():
    pytest.skip("FMU export builds its binary with a C compiler", allow_module_level=True)

TIGHT = "; solver dopri5(rtol = 1e-10, atol = 1e-12) }"
# docs/hybrid.md's thermostat, its second relation not strict (at T = 19 it holds)
THERMOSTAT = next(b.text for b in blocks(Path(__file__).parent.parent / "docs" / "hybrid.md")
                  if b.opts.get("file") == "thermostat.bg").replace("T < 19", "T <= 19")
MODELS = {  # text, scene, output interval
    "ball": (BALL.replace(" }\n", TIGHT + "\n"), "drop", 0.01),
    "thermostat": (THERMOSTAT, "day", 0.5),
    "lag": (LAG.replace(" }\n", TIGHT + "\n"), "run", 0.1),
}


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    """Each model's FMU, and bgc's own run of it (its scene) with the event log."""
    tmp = tmp_path_factory.mktemp("fmu_events")
    out = {}
    for name, (text, scene, _) in MODELS.items():
        compiled = build(text, scene)
        path = tmp / f"{name}.fmu"
        path.write_bytes(fmu.build_fmu(compiled))
        log = tmp / f"{name}.csv"
        t, Y, names = bgc.simulate(Source(f"{name}.bg", text), scene, events=str(log))
        with open(log, newline="") as f:
            events = [(float(r[0]), r[1], r[2]) for r in list(csv.reader(f))[1:]]
        out[name] = path, (t, dict(zip(names, Y.T))), events
    return out


# ---------------------------------------------------------------- closed forms


def ball_reference(t, m=1.0, g=9.81, h0=1.0, e=0.8):
    """Height and momentum: a free fall, then parabolas from each impact (the right limits)."""
    x, p = h0 - g * t**2 / 2, -m * g * t
    for t_k, v_k in bounce_times(12):
        after = t >= t_k
        s = t - t_k
        x = np.where(after, e * v_k * s - g * s**2 / 2, x)
        p = np.where(after, m * (e * v_k - g * s), p)
    return {"x": x, "b.p": p}


def thermostat_switches(t_end, k=0.1, P=5.0, Ta=10.0):
    """(time, the temperature's approach, T there) of each switching, heating from 20."""
    t, T, heating, out = 0.0, 20.0, True, [(0.0, Ta + P / k, 20.0)]
    while True:
        target, end = (21.0, Ta + P / k) if heating else (19.0, Ta)
        t += math.log((T - end) / (target - end)) / k
        if t > t_end:
            return out
        heating = not heating
        T = target
        out.append((t, Ta + P / k if heating else Ta, T))


def thermostat_reference(t, k=0.1):
    """T on a grid from the piecewise exponentials, and the heater's mode."""
    T, heat = np.empty_like(t), np.empty_like(t)
    for t_s, end, T_s in thermostat_switches(t[-1]):
        after = t >= t_s
        T[after] = end + (T_s - end) * np.exp(-k * (t[after] - t_s))
        heat[after] = 1.0 if end > 21 else 0.0
    return {"T": T, "heat": heat}


REFERENCES = {
    "ball": ball_reference,
    "thermostat": thermostat_reference,
    "lag": lambda t: {"x": np.array([lag_reference(s, 0.5, 1.7, 0.05) for s in t])},
}


def relative_difference(got, ref):
    return np.max(np.abs(got - ref)) / np.max(np.abs(ref))


def simulate(path, kind, interval, **options):
    if kind == "ModelExchange":
        options.setdefault("relative_tolerance", 1e-12)  # CVODE's (its atol the same)
    return fmpy.simulate_fmu(str(path), fmi_type=kind, output_interval=interval, **options)


# ---------------------------------------------------------------- the tests


def test_fmpy_validates_and_the_description_has_the_events(built):
    indicators = {"ball": 1, "thermostat": 2, "lag": 0}
    for name, (path, _, _) in built.items():
        assert validate_fmu(str(path)) == [], name
        md = fmpy.read_model_description(str(path))
        assert md.numberOfEventIndicators == indicators[name]
        # a step event only where there are state relations (fmi2CompletedIntegratorStep)
        assert md.modelExchange.needsCompletedIntegratorStep == (indicators[name] > 0)
    md = fmpy.read_model_description(str(built["thermostat"][0]))
    (heat,) = [v for v in md.modelVariables if v.name == "heat"]
    assert (heat.causality, heat.variability, heat.initial) == ("local", "discrete", "calculated")


@pytest.mark.parametrize("kind", ["ModelExchange", "CoSimulation"])
@pytest.mark.parametrize("name", list(MODELS))
def test_trajectories_match_bgc_and_the_closed_forms(built, name, kind):
    """On the output grid (the events between its points): FMPy's run of the FMU against
    bgc's run of the model and against the closed form.  The thermostat's heater, a discrete
    variable, is in the FMU's variables and follows its modes (Co-Simulation: it persists
    from one fmi2DoStep to the next)."""
    path, (t, bgc_run), _ = built[name]
    interval = MODELS[name][2]
    extra = ["heat"] if name == "thermostat" else []
    grid_only = {"record_events": False} if kind == "ModelExchange" else {}
    result = simulate(path, kind, interval, output=[*bgc_run, *extra], **grid_only)
    assert np.allclose(result["time"], t, rtol=0, atol=1e-12)
    reference = REFERENCES[name](t)
    for output, values in bgc_run.items():
        assert relative_difference(result[output], values) < 1e-6, output
        assert relative_difference(result[output], reference[output]) < 1e-6, output
    if extra:
        assert np.array_equal(result["heat"], reference["heat"])
        assert 0 < reference["heat"].sum() < len(t)


def event_rows(result):
    """FMPy's rows at each event (recorded twice: its left and right limits)."""
    t = result["time"]
    k = np.flatnonzero(t[1:] == t[:-1])
    return t[k], result[k], result[k + 1]


def test_model_exchange_locates_the_events(built):
    """The impacts, the switchings and the pulse's edges where FMPy's Model Exchange run
    handled them: at the closed-form times and at bgc's own (1e-9 relative: the times CVODE
    locates at its tolerance 1e-12); the momentum reversed as the reinit says."""
    path, _, log = built["ball"]
    result = simulate(path, "ModelExchange", 0.01)
    times, left, right = event_rows(result)
    impacts = right["b.p"] > left["b.p"]
    want = bounce_times(int(impacts.sum()))
    assert len(want) == 6 == len([e for e in log if e[1] == "b.p"])
    for t, before, after, (t_ref, v_ref), logged in zip(
            times[impacts], left[impacts], right[impacts], want,
            [e for e in log if e[1] == "b.p"]):
        assert abs(t - t_ref) <= 1e-9 * t_ref and abs(t - logged[0]) <= 1e-9 * t_ref
        assert abs(before["b.p"] + v_ref) <= 1e-6 * v_ref
        assert abs(after["b.p"] - 0.8 * v_ref) <= 1e-6 * v_ref

    path, _, log = built["thermostat"]
    result = simulate(path, "ModelExchange", 0.5, output=["T", "heat"])
    times, left, right = event_rows(result)
    switched = left["heat"] != right["heat"]
    want = thermostat_switches(60.0)[1:]
    logged = [e for e in log if e[1] == "heat"]
    assert len(want) == switched.sum() == len(logged) > 5
    for t, before, (t_ref, _, T_ref), e in zip(times[switched], left[switched], want, logged):
        assert abs(t - t_ref) <= 1e-9 * t_ref and abs(t - e[0]) <= 1e-9 * t_ref
        assert abs(before["T"] - T_ref) <= 1e-9 * T_ref
        if T_ref > 20:  # T >= 21 holds from there: the heater is off after the event
            assert before["T"] >= 21.0

    path, _, log = built["lag"]
    result = simulate(path, "ModelExchange", 0.1)
    times, _, _ = event_rows(result)
    assert [e[0] for e in log if e[2] == "0 -> 1"] == [1.7, 1.7 + 0.05]
    # FMPy steps onto nextEventTime, or onto its output point when that is as close as
    # 1e-9 relative (17 * 0.1 is 1.7000000000000002)
    assert np.allclose(times, [1.7, 1.7 + 0.05], rtol=1e-15, atol=0)


def test_the_fmi_functions_of_events(built):
    """Called one by one: the start's event iteration and the initialization's event mode;
    the indicators (> 0 exactly where the relation holds: at g = 0 a strict relation's is
    slightly negative, another's slightly positive); a step event where a relation changed
    unseen; the event iteration's reinit; the time events' nextEventTime."""
    fmus = []

    def instantiate(name):
        path = built[name][0]
        md = fmpy.read_model_description(str(path))
        unzip = fmpy.extract(str(path))
        model = FMU2Model(guid=md.guid, unzipDirectory=unzip,
                          modelIdentifier=md.modelExchange.modelIdentifier, instanceName=name)
        fmus.append((model, unzip))
        model.instantiate()
        model.setupExperiment(startTime=0.0)
        model.enterInitializationMode()
        model.exitInitializationMode()
        vr = {v.name: v.valueReference for v in md.modelVariables}
        return model, vr

    def states(model, *x):
        model.setContinuousStates((ctypes.c_double * len(x))(*x), len(x))

    def indicators(model, n):
        z = (ctypes.c_double * n)()
        model.getEventIndicators(z, n)
        return list(z)

    def derivatives(model, n):
        dx = (ctypes.c_double * n)()
        model.getDerivatives(dx, n)
        return list(dx)

    try:
        ball, vr = instantiate("ball")  # states (b.p, x); the relation x < 0, g = -x
        info = ball.newDiscreteStates()
        assert info == (False, False, False, False, False, 0.0)
        ball.enterContinuousTimeMode()
        assert indicators(ball, 1) == [-1.0]
        states(ball, -1.0, 0.0)
        (z,) = indicators(ball, 1)
        assert z < 0 and z > -1e-250  # x = 0: x < 0 does not hold
        assert ball.completedIntegratorStep() == (False, False)
        states(ball, -3.0, -0.01)
        assert ball.completedIntegratorStep() == (True, False)  # crossed, not located
        ball.enterEventMode()
        assert ball.newDiscreteStates()[3]  # valuesOfContinuousStatesChanged
        assert list(ball.getReal([vr["b.p"], vr["x"]])) == [-0.8 * -3.0, -0.01]
        ball.enterContinuousTimeMode()
        assert ball.completedIntegratorStep() == (False, False)

        room, vr = instantiate("thermostat")  # T > 21, T <= 19 (not strict)
        assert room.getReal([vr["heat"]]) == [1.0]  # the start's event iteration
        room.newDiscreteStates()
        room.enterContinuousTimeMode()
        assert indicators(room, 2) == [-1.0, -1.0]
        states(room, 21.0)
        z = indicators(room, 2)
        assert -1e-250 < z[0] < 0 and z[1] == -2.0  # T = 21: T > 21 does not hold
        states(room, 21.5)
        room.enterEventMode()
        room.newDiscreteStates()
        assert room.getReal([vr["heat"]]) == [0.0]
        room.enterContinuousTimeMode()
        states(room, 19.0)
        z = indicators(room, 2)
        assert z[0] == -2.0 and 0 < z[1] < 1e-250  # T = 19: T <= 19 holds
        assert room.completedIntegratorStep() == (True, False)
        room.enterEventMode()
        assert not room.newDiscreteStates()[3]  # the heater on, the state as it was
        assert room.getReal([vr["heat"], vr["T"]]) == [1.0, 19.0]

        lag, _ = instantiate("lag")
        assert lag.newDiscreteStates()[4:] == (True, 1.7)
        lag.enterContinuousTimeMode()
        lag.setTime(1.7)
        lag.enterEventMode()
        assert lag.newDiscreteStates()[4:] == (True, 1.7 + 0.05)
        lag.enterContinuousTimeMode()
        (dx,) = derivatives(lag, 1)
        assert dx == 1.0  # x = 0 and the pulse on
    finally:
        for model, unzip in fmus:
            model.freeInstance()
            shutil.rmtree(unzip, ignore_errors=True)


def test_cosimulation_state_rolls_back_across_events(built):
    """The thermostat in Co-Simulation, steps of 0.5: the state saved at t = 5 (and its
    bytes) brings back the heater's mode too, and the next 40 steps repeat bit for bit."""
    path = built["thermostat"][0]
    md = fmpy.read_model_description(str(path))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    unzip = fmpy.extract(str(path))
    slave = FMU2Slave(guid=md.guid, unzipDirectory=unzip,
                      modelIdentifier=md.coSimulation.modelIdentifier, instanceName="cs")
    try:
        slave.instantiate()
        slave.setupExperiment(startTime=0.0)
        slave.enterInitializationMode()
        slave.exitInitializationMode()

        def run(k0, n):
            out = []
            for k in range(k0, k0 + n):
                slave.doStep(k * 0.5, 0.5)
                out.append(slave.getReal([vr["T"], vr["heat"]]))
            return np.array(out)

        run(0, 10)
        state = slave.getFMUState()
        blob = slave.serializeFMUState(state)
        first = run(10, 40)
        assert len(set(first[:, 1])) == 2  # the heater switched within these steps
        slave.setFMUState(state)
        assert np.array_equal(run(10, 40), first)
        slave.setFMUState(slave.deserializeFMUState(blob))
        assert np.array_equal(run(10, 40), first)
        t = np.arange(11, 51) * 0.5
        reference = thermostat_reference(np.concatenate([[0.0], t]))
        assert relative_difference(first[:, 0], reference["T"][1:]) < 1e-8
        assert np.array_equal(first[:, 1], reference["heat"][1:])
        slave.terminate()
    finally:
        slave.freeInstance()
        shutil.rmtree(unzip, ignore_errors=True)


def test_the_sources_build_without_warnings(tmp_path):
    """The FMU's C file of each model with events compiles as C99 with every warning an
    error."""
    for name, (text, scene, _) in MODELS.items():
        _, _, source = fmu.fmu_texts(build(text, scene))
        path = tmp_path / f"{name}.c"
        path.write_text(source, encoding="utf-8")
        done = subprocess.run([*toolchain.c_compiler(), "-std=c99", "-Wall", "-Wextra",
                               "-pedantic", "-Werror", "-fsyntax-only", str(path)],
                              capture_output=True, text=True)
        assert done.returncode == 0, done.stderr


TOGGLE = """model toggle "a discrete value that never settles once x passes 1/2"
discrete n = 0
signal x = integral(1 + n, init = 0)
when n > 0.5 { n = 0 }
when n < 0.5 and x > 0.5 { n = 1 }
scene run { time 0 .. 1 every 0.1; outputs x }
"""


def test_an_event_iteration_that_does_not_settle_fails_with_a_message(tmp_path):
    """Both FMU types stop at the event (x = 1/2) with bgc's message in the log.  Random
    sequences of FMI calls on that FMU (tools/fuzz_fmu.py) reach its error state in both
    types, where the standard's tables allow fewer calls, and find no fault."""
    path = tmp_path / "toggle.fmu"
    path.write_bytes(fmu.build_fmu(build(TOGGLE, "run")))
    for kind, fn in (("ModelExchange", "fmi2NewDiscreteStates"), ("CoSimulation", "fmi2DoStep")):
        log = []
        with pytest.raises(Exception, match=fn):
            fmpy.simulate_fmu(str(path), fmi_type=kind, logger=lambda *a: log.append(a))
        (message,) = [a[4].decode() for a in log if a[2] == 3]  # fmi2Error
        assert message.startswith(f"{fn}: at t = 0.5") and "chattering" in message, message
    result = fuzz_fmu.fuzz(fuzz_fmu.extract(path, tmp_path / "toggle"), 3, 60, length=30)
    assert result["failures"] == [], result["failures"][0]["failure"]
    for kind in ("me", "cs"):
        assert result["seen"].get(f"{kind} error legal", 0) > 0
        assert result["seen"].get(f"{kind} error illegal", 0) > 0


FRICTION = """model fr "dry friction that slides with far more force than it sticks with"
v : 1
b : I(1)
w : MSe(-9)
fr : Fr(9e15, 1)
v -> b
w -> v
v -> fr
"""


def test_chattering_stops_model_exchange_under_fmpy(tmp_path):
    """Fr(9e15, 1) sticks and breaks away ever faster (bgc simulate and the FMU's
    Co-Simulation stop it as chattering).  FMPy's Model Exchange run of its FMU (CVODE
    stopping at each event) stops at the 1000th of its integrator steps in a row each cut
    short by an event (the driver's bound, docs/cli.md --max-steps), with
    fmi2NewDiscreteStates' error naming the conditions that keep changing; it ran without
    end (FMPy's timeout would end it without an error)."""
    path = tmp_path / "fr.fmu"
    path.write_bytes(fmu.build_fmu(build(FRICTION, None)))
    log = []
    with pytest.raises(Exception, match="fmi2NewDiscreteStates failed with status 3"):
        fmpy.simulate_fmu(str(path), fmi_type="ModelExchange", stop_time=0.05, timeout=120,
                          logger=lambda *a: log.append(a))
    (message,) = [a[4].decode() for a in log if a[2] == 3]
    assert message.startswith("fmi2NewDiscreteStates: at t = "), message
    assert message.endswith(": chattering: 1000 integrator steps in a row, each cut short by an "
                            "event ('fr: stops (f reverses)', 'fr: breaks away (|e| > Fs)', "
                            "'fr.stick' and 'fr.dir' keep changing: a sliding mode or a Zeno "
                            "model?)"), message


def test_the_co_simulation_fmu_names_its_own_budget_not_a_command_line_option(tmp_path):
    """Fr(9e15, 1) in Co-Simulation: 100 000 events within the first communication step
    stop it (BGC_MAX_STEPS, the FMU's fixed budget); an FMU has no command line, so its
    message says the budget is fixed where bgc simulate's names --max-steps."""
    from conftest import run_bgc
    path = tmp_path / "fr.fmu"
    path.write_bytes(fmu.build_fmu(build(FRICTION, None)))
    log = []
    with pytest.raises(Exception, match="fmi2DoStep failed with status 3"):
        fmpy.simulate_fmu(str(path), fmi_type="CoSimulation", stop_time=0.05,
                          logger=lambda *a: log.append(a))
    (message,) = [a[4].decode() for a in log if a[2] == 3]
    assert "--max-steps" not in message, message
    assert message.endswith("keep changing: a Zeno model? The FMU's budget, 100000 events per "
                            "communication step, is fixed)"), message
    model = tmp_path / "fr.bg"
    model.write_text(FRICTION)
    r = run_bgc("simulate", model, "--t-end", "0.05", "-o", tmp_path / "fr.csv")
    assert r.returncode == 1
    assert "keep changing: a Zeno model? --max-steps raises the budget)" in r.stderr, r.stderr


_RAW = {}  # FMPy's logger proxy keeps one logger for the process: one for every Raw


def _raw_callbacks():
    """The callbacks of every Raw instance: their log lines (instance, status, message)."""
    if not _RAW:
        from fmpy.fmi2 import fmi2CallbackFunctions, fmi2CallbackLoggerTYPE
        from fmpy.logging import addLoggerProxy
        _RAW["log"] = []
        _RAW["callbacks"] = callbacks = fmi2CallbackFunctions()
        callbacks.logger = fmi2CallbackLoggerTYPE(
            lambda env, name, status, cat, msg: _RAW["log"].append(
                (name.decode(), status, msg.decode())))
        addLoggerProxy(ctypes.byref(callbacks))
    return _RAW["callbacks"]


class Raw:
    """An FMU's binary through ctypes alone (FMPy's wrappers cost more than its calls): a
    Model Exchange instance, initialised and in continuous-time mode."""

    def __init__(self, path, folder):
        self.fmu = fuzz_fmu.extract(path, folder)
        self.name = Path(folder).name
        self.lib = lib = ctypes.CDLL(self.fmu.binary)
        lib.fmi2Instantiate.restype = ctypes.c_void_p
        lib.fmi2SetTime.argtypes = [ctypes.c_void_p, ctypes.c_double]
        self.c = ctypes.c_void_p(lib.fmi2Instantiate(self.name.encode(), 0,
                                                     self.fmu.guid.encode(), None,
                                                     ctypes.byref(_raw_callbacks()), 0, 0))
        self.info = (ctypes.c_char * 64)()
        self.flag = ctypes.c_int()
        for status in (lib.fmi2EnterInitializationMode(self.c),
                       lib.fmi2ExitInitializationMode(self.c),
                       lib.fmi2NewDiscreteStates(self.c, self.info),
                       lib.fmi2EnterContinuousTimeMode(self.c)):
            assert status == 0, self.errors()

    def errors(self):
        """The errors this instance logged."""
        return [m for name, s, m in _RAW["log"] if name == self.name and s == 3]

    def step(self, t):
        """An integrator step completed at t."""
        self.lib.fmi2SetTime(self.c, t)
        return self.lib.fmi2CompletedIntegratorStep(self.c, 1, ctypes.byref(self.flag),
                                                    ctypes.byref(self.flag))

    def event(self, t, x=None):
        """An event at t (the states x there, if given): fmi2NewDiscreteStates' status."""
        self.lib.fmi2SetTime(self.c, t)
        if x is not None:
            self.lib.fmi2SetContinuousStates(self.c, (ctypes.c_double * len(x))(*x), len(x))
        self.lib.fmi2EnterEventMode(self.c)
        status = self.lib.fmi2NewDiscreteStates(self.c, self.info)
        if status == 0:
            self.lib.fmi2EnterContinuousTimeMode(self.c)
        return status

    def close(self):
        self.lib.fmi2FreeInstance(self.c)


def test_model_exchange_bounds_the_events_as_the_driver_does(built, tmp_path):
    """The driver's bounds (docs/hybrid.md), on the events a Model Exchange environment
    brings (the ball: states b.p, x; the relation x < 0): 100 events in a row at one instant
    are allowed, the 101st fails; 1000 state events in a row, each ending the first
    integrator step since the one before (every step cut short), fail, and 1500 do not when
    a step ends before each; and the events since the scene's last output time (2, of its
    grid of 0.01) are bounded by the step budget, 100 000 (docs/cli.md)."""
    path = built["ball"][0]
    same = Raw(path, tmp_path / "same")
    try:
        assert all(same.event(0.25) == 0 for _ in range(100))
        assert same.event(0.25) == 3
        (message,) = same.errors()
        assert message.startswith("fmi2NewDiscreteStates: at t = 0.25: chattering: 100 events "
                                  "in a row, each within 1e-12 relative of the one before ("), \
            message
        assert same.event(0.25) == 3 and same.step(0.3) == 3  # the error state
    finally:
        same.close()
    cut = Raw(path, tmp_path / "cut")
    free = Raw(path, tmp_path / "free")
    try:
        flips = [[1.0, -0.01 if k % 2 else 0.01] for k in range(1, 1501)]  # x < 0, or not
        for k, x in enumerate(flips[:999], 1):
            assert cut.step(k * 1e-3) == 0 and cut.event(k * 1e-3, x) == 0
        assert cut.step(1.0) == 0 and cut.event(1.0, flips[999]) == 3
        (message,) = cut.errors()
        assert message == "fmi2NewDiscreteStates: at t = 1: chattering: 1000 integrator steps " \
            "in a row, each cut short by an event ('x < 0' keeps changing: a sliding mode or " \
            "a Zeno model?)"
        for k, x in enumerate(flips, 1):
            assert free.step(k * 1e-3 - 5e-4) == 0 and free.step(k * 1e-3) == 0
            assert free.event(k * 1e-3, x) == 0
        k = 0
        while True:  # (then each 1e-8 after the one before, a step between)
            k += 1
            if free.step(2.0 + (k - 0.5) * 1e-8) != 0 or free.event(2.0 + k * 1e-8) != 0:
                break
        assert k == 100001
        (message,) = free.errors()
        assert message == f"fmi2NewDiscreteStates: at t = {2.0 + k * 1e-8:.17g}: chattering: " \
            "100000 events since the scene's output time 2 (the state keeps changing: a Zeno " \
            "model?)"  # (as the driver says it when no discrete value changes)
    finally:
        cut.close()
        free.close()


def test_the_rectifier_with_an_ideal_diode_as_an_fmu(tmp_path):
    """The half-wave rectifier (an ideal diode: its modes are discrete values, its switching
    state relations): FMPy validates its FMU, and FMPy's runs of it, Model Exchange with its
    own event handling and Co-Simulation, follow bgc's run and the piecewise reference."""
    from test_contact import RECTIFIER, rectifier_reference
    text = RECTIFIER.replace("SOLVER", "dopri5")
    compiled = build(text, "run")
    path = tmp_path / "rectifier.fmu"
    path.write_bytes(fmu.build_fmu(compiled))
    assert validate_fmu(str(path)) == []
    assert fmpy.read_model_description(str(path)).numberOfEventIndicators == 2
    t, Y, names = bgc.simulate(Source("rectifier.bg", text), "run")
    ours = Y[:, names.index("l.p")]
    for kind in ("ModelExchange", "CoSimulation"):
        extra = {"record_events": False} if kind == "ModelExchange" else {}
        result = simulate(path, kind, 0.0005, output=["l.p"], **extra)
        assert np.allclose(result["time"], t, rtol=0, atol=1e-12)
        reference = 0.05 * rectifier_reference(np.asarray(t))
        assert relative_difference(result["l.p"], ours) < 1e-6, kind
        assert relative_difference(result["l.p"], reference) < 1e-6, kind


def test_a_discrete_output_is_one_variable(tmp_path):
    """A discrete variable that is an output is one FMU variable, causality output and
    variability discrete, with no continuous dependencies; FMPy validates the FMU, and its
    Co-Simulation gives the values of tests/test_events.py's closed form."""
    path = tmp_path / "count.fmu"
    path.write_bytes(fmu.build_fmu(build(COUNT, "run")))
    assert validate_fmu(str(path)) == []
    md = fmpy.read_model_description(str(path))
    names = [v.name for v in md.modelVariables]
    for name in ("n", "m", "h.k"):
        assert names.count(name) == 1
        v = md.modelVariables[names.index(name)]
        assert (v.causality, v.variability) == ("output", "discrete")
        (out,) = [u for u in md.outputs if u.variable is v]
        assert out.dependencies == []
    cs = fmpy.simulate_fmu(str(path), fmi_type="CoSimulation", output_interval=0.25)
    rises = (math.asin(0.5) + 2 * math.pi * np.arange(3)) / 3.0
    assert list(cs["n"]) == [float(np.sum(rises <= t)) for t in cs["time"]]
    assert list(cs["m"]) == [7.0 if t >= 1 else 0.0 for t in cs["time"]]


def test_random_sequences_of_fmi_calls_follow_the_state_machine(built, tmp_path):
    """tools/fuzz_fmu.py's harness, seeded, on the thermostat's FMU (a model that cannot
    fail: every legal call must succeed, --strict): random sequences of calls through ctypes,
    legal and not (a function its state does not allow, the other type's, arguments it cannot
    take, fmi2FreeInstance twice, calls through a freed or a NULL handle), each checked
    against FMI 2.0's tables; every state of both types is reached, with legal and illegal
    calls in it."""
    F = fuzz_fmu
    result = F.fuzz(F.extract(built["thermostat"][0], tmp_path), 2028, 80, length=30,
                    strict=True)
    assert result["failures"] == [], result["failures"][0]["failure"]
    seen = result["seen"]
    for kind, states in (("me", (F.INST, F.INIT, F.EVENT, F.CONT, F.TERM)),
                         ("cs", (F.INST, F.INIT, F.STEP, F.TERM))):
        for state in states:
            for legal in ("legal", "illegal"):
                assert seen.get(f"{kind} {state} {legal}", 0) > 0, (kind, state, legal)
    assert seen["dead freed"] > 0 and seen["dead NULL"] > 0
