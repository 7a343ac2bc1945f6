#!/usr/bin/env python3
"""Fuzzing the FMU's life cycle: random sequences of FMI 2.0 calls, legal and not, through
ctypes on the binaries of FMUs that bgc exports, each checked against the standard's state
machine (its tables of the functions each state allows, FMI 2.0 sections 3.2.3 and 4.2.4,
written out below independently of bgc/runtime/fmi2.c).

    python tools/fuzz_fmu.py --fmu rlc.fmu --seed 1 --sequences 2000
    python tools/fuzz_fmu.py --seed 1 --models 40 --sequences 50    (models from tools/fuzz.py)

What counts as a failure:
- the process that makes the calls dies (a signal: a crash, a sanitizer's abort with
  --sanitize, which builds the binary with -fsanitize=address,undefined) or does not answer
  within --time-limit seconds;
- a call its state does not allow (or of the other FMU type, or with arguments it cannot
  take: an unknown value reference, a parameter set once initialisation has ended, an array
  of the wrong size or none, a time that is not finite, fmi2DoStep off the FMU's time) returns
  anything but fmi2Error, or returns it without an error through the logger, or changes the
  state (the next calls are judged from the state before it);
- a call through a freed handle (fmi2FreeInstance twice, any call after it) or a NULL one
  returns anything but fmi2Error (fmi2FreeInstance: returns at all);
- a legal call returns anything but fmi2OK, except those that evaluate the model, which may
  fail as the model does: fmi2Discard in Model Exchange (no change), fmi2Error from
  fmi2ExitInitializationMode, fmi2NewDiscreteStates, fmi2DoStep or a Co-Simulation's
  fmi2GetReal, after which the instance is in the error state (--strict: a model that cannot
  fail, every legal call fmi2OK).
The calls go one at a time to a process that has loaded the binary, and each answer decides
the next call; a failing sequence is written as JSON (the calls and the answers) under --out,
with the generated model beside it, and `--fmu M.fmu --replay FILE` makes its calls again
(`bgc compile model.bg --target fmu -o M.fmu` builds the FMU of a generated model).

Importable: Fmu.load(folder), fuzz(fmu, seed, sequences, ...) (tests/test_fmu_events.py runs a
short seeded one), fuzz_model(text, seed, ...) (tools/fuzz.py calls it with --fmu-every).
"""
from __future__ import annotations

import argparse
import ctypes
import json
import math
import os
import random
import select
import signal
import subprocess
import sys
import tempfile
import time
import xml.etree.ElementTree as ET
import zipfile
from dataclasses import dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
OK, WARNING, DISCARD, ERROR = 0, 1, 2, 3

# ------------------------------------------------------------ the standard's tables

INST, INIT, EVENT, CONT, STEP, TERM, ERR = ("instantiated", "initialization mode", "event mode",
                                            "continuous-time mode", "step complete",
                                            "terminated", "error")
LIVE = {INST, INIT, EVENT, CONT, STEP, TERM, ERR}
GETS = ("fmi2GetReal", "fmi2GetInteger", "fmi2GetBoolean", "fmi2GetString")
SETS_OTHER = ("fmi2SetInteger", "fmi2SetBoolean", "fmi2SetString")
STATE_FUNCTIONS = ("fmi2GetFMUstate", "fmi2SetFMUstate", "fmi2FreeFMUstate",
                   "fmi2SerializedFMUstateSize", "fmi2SerializeFMUstate",
                   "fmi2DeSerializeFMUstate")
STATUS_FUNCTIONS = ("fmi2GetStatus", "fmi2GetRealStatus", "fmi2GetIntegerStatus",
                    "fmi2GetBooleanStatus", "fmi2GetStringStatus")


def _table(common: dict, own: dict) -> dict:
    out = {fn: set(states) for fn, states in common.items()}
    out.update({fn: set(states) for fn, states in own.items()})
    return out


# FMI 2.0, 3.2.3: the functions of Model Exchange and the states they may be called in
MODEL_EXCHANGE = _table({
    "fmi2SetDebugLogging": LIVE, "fmi2SetupExperiment": {INST},
    "fmi2EnterInitializationMode": {INST}, "fmi2ExitInitializationMode": {INIT},
    "fmi2Terminate": {EVENT, CONT}, "fmi2Reset": LIVE,
    **{fn: {INIT, EVENT, CONT, TERM, ERR} for fn in GETS},
    "fmi2SetReal": {INST, INIT, EVENT, CONT},
    **{fn: {INST, INIT, EVENT} for fn in SETS_OTHER},
    **{fn: LIVE for fn in STATE_FUNCTIONS},
    "fmi2GetDirectionalDerivative": {INIT, EVENT, CONT, TERM, ERR},
}, {
    "fmi2EnterEventMode": {EVENT, CONT}, "fmi2NewDiscreteStates": {EVENT},
    "fmi2EnterContinuousTimeMode": {EVENT}, "fmi2CompletedIntegratorStep": {CONT},
    "fmi2SetTime": {EVENT, CONT}, "fmi2SetContinuousStates": {CONT},
    "fmi2GetEventIndicators": {INIT, EVENT, CONT, TERM, ERR},
    "fmi2GetContinuousStates": {INIT, EVENT, CONT, TERM, ERR},
    "fmi2GetDerivatives": {EVENT, CONT, TERM, ERR},
    "fmi2GetNominalsOfContinuousStates": {INST, EVENT, CONT, TERM, ERR},
})
# FMI 2.0, 4.2.4: Co-Simulation's (step in progress, failed, canceled: never entered here)
CO_SIMULATION = _table({
    "fmi2SetDebugLogging": LIVE, "fmi2SetupExperiment": {INST},
    "fmi2EnterInitializationMode": {INST}, "fmi2ExitInitializationMode": {INIT},
    "fmi2Terminate": {STEP}, "fmi2Reset": LIVE,
    **{fn: {INIT, STEP, TERM, ERR} for fn in GETS},
    "fmi2SetReal": {INST, INIT, STEP},
    **{fn: {INST, INIT, STEP} for fn in SETS_OTHER},
    **{fn: LIVE for fn in STATE_FUNCTIONS},
    "fmi2GetDirectionalDerivative": {INIT, STEP, TERM, ERR},
}, {
    "fmi2SetRealInputDerivatives": {INST, INIT, STEP},
    "fmi2GetRealOutputDerivatives": {STEP, TERM, ERR},
    "fmi2DoStep": {STEP}, "fmi2CancelStep": set(),  # (step in progress only)
    **{fn: {STEP, TERM} for fn in STATUS_FUNCTIONS},
})
FUNCTIONS = sorted(set(MODEL_EXCHANGE) | set(CO_SIMULATION) | {"fmi2FreeInstance"})
TABLES = {"me": MODEL_EXCHANGE, "cs": CO_SIMULATION}
# legal calls that evaluate the model: the statuses they may give besides fmi2OK (fmi2Error:
# the instance is then in the error state)
MAY_FAIL = {
    "me": {"fmi2GetReal": {DISCARD}, "fmi2GetDerivatives": {DISCARD},
           "fmi2GetEventIndicators": {DISCARD}, "fmi2CompletedIntegratorStep": {DISCARD},
           "fmi2GetDirectionalDerivative": {DISCARD}, "fmi2ExitInitializationMode": {ERROR},
           "fmi2NewDiscreteStates": {ERROR}},
    "cs": {"fmi2GetReal": {ERROR}, "fmi2ExitInitializationMode": {ERROR},
           "fmi2DoStep": {ERROR}},
}
# the calls that take a sequence further: half the legal calls are drawn among them
PROGRESS = {"fmi2EnterInitializationMode": 4, "fmi2ExitInitializationMode": 4,
            "fmi2EnterContinuousTimeMode": 3, "fmi2EnterEventMode": 3, "fmi2DoStep": 5,
            "fmi2NewDiscreteStates": 3, "fmi2SetTime": 2, "fmi2SetContinuousStates": 3,
            "fmi2CompletedIntegratorStep": 2}


# ------------------------------------------------------------ what the FMU says it is

@dataclass(frozen=True)
class Fmu:
    """An extracted FMU: its binary and what modelDescription.xml says."""

    folder: str
    binary: str
    guid: str
    kinds: tuple[str, ...]  # "me", "cs"
    variables: tuple[tuple[int, str, str], ...]  # (value reference, causality, variability)
    states: tuple[int, ...]  # the value references of the continuous states
    derivatives: tuple[int, ...]
    indicators: int
    t0: float
    span: float  # the default experiment's, stop time minus start time
    directional: bool  # Model Exchange's providesDirectionalDerivative
    starts: tuple[tuple[int, float], ...] = ()  # the parameters' and inputs' start values

    @staticmethod
    def load(folder) -> "Fmu":
        folder = Path(folder)
        root = ET.parse(folder / "modelDescription.xml").getroot()
        kinds, ident = [], None
        for tag, kind in (("ModelExchange", "me"), ("CoSimulation", "cs")):
            node = root.find(tag)
            if node is not None:
                kinds.append(kind)
                ident = node.get("modelIdentifier")
        me = root.find("ModelExchange")
        variables, starts, index = [], [], {}
        for k, v in enumerate(root.find("ModelVariables"), 1):
            vr = int(v.get("valueReference"))
            real = v.find("Real")
            variables.append((vr, v.get("causality", "local"), v.get("variability", "continuous")))
            index[k] = (vr, real)
            if real is not None and real.get("start") is not None:
                starts.append((vr, float(real.get("start"))))
        structure = root.find("ModelStructure")
        listed = structure.find("Derivatives") if structure is not None else None
        derivatives = [index[int(u.get("index"))] for u in
                       (listed.findall("Unknown") if listed is not None else [])]
        states = tuple(index[int(real.get("derivative"))][0] for _, real in derivatives)
        suffix = ".dylib" if sys.platform == "darwin" else ".so"
        binaries = sorted((folder / "binaries").glob(f"*/{ident}{suffix}"))
        ex = root.find("DefaultExperiment")
        return Fmu(str(folder), str(binaries[0]), root.get("guid"), tuple(kinds),
                   tuple(variables), states, tuple(vr for vr, _ in derivatives),
                   int(root.get("numberOfEventIndicators", "0")),
                   float(ex.get("startTime", "0")) if ex is not None else 0.0,
                   float(ex.get("stopTime", "1")) - float(ex.get("startTime", "0"))
                   if ex is not None else 1.0,
                   me is not None and me.get("providesDirectionalDerivative") == "true",
                   tuple(starts))

    def refs(self, *causalities) -> list[int]:
        return [vr for vr, c, _ in self.variables if not causalities or c in causalities]


def extract(fmu_path, folder) -> Fmu:
    with zipfile.ZipFile(fmu_path) as z:
        z.extractall(folder)
    for path in Path(folder, "binaries").rglob("*"):
        path.chmod(0o755)
    return Fmu.load(folder)


# ------------------------------------------------------------ the process making the calls

def _runner_main(binary: str):
    """Loads the binary and makes the calls it is sent, one a line (JSON), answering each
    with {"status", "errors", "messages", ...}: the status (None for a void function) and the
    errors the FMU logged meanwhile."""
    from ctypes import (CFUNCTYPE, Structure, byref, c_char, c_char_p, c_double, c_int,
                        c_size_t, c_uint, c_void_p)
    lib = ctypes.CDLL(binary)
    logged = []

    class Callbacks(Structure):
        _fields_ = [("logger", CFUNCTYPE(None, c_void_p, c_char_p, c_int, c_char_p, c_char_p)),
                    ("allocateMemory", CFUNCTYPE(c_void_p, c_size_t, c_size_t)),
                    ("freeMemory", CFUNCTYPE(None, c_void_p)),
                    ("stepFinished", c_void_p), ("componentEnvironment", c_void_p)]

    def logger(env, name, status, category, message):
        logged.append((status, (message or b"").decode("utf-8", "replace")))

    callbacks = Callbacks()
    callbacks.logger = Callbacks._fields_[0][1](logger)
    callbacks.allocateMemory = Callbacks._fields_[1][1](lambda n, s: None)
    callbacks.freeMemory = Callbacks._fields_[2][1](lambda p: None)
    try:  # FMPy's native proxy formats the message's printf arguments (ctypes cannot)
        from fmpy.logging import addLoggerProxy
        addLoggerProxy(byref(callbacks))
    except Exception:  # noqa: BLE001  (without it: the statuses only)
        pass
    fn = {name: getattr(lib, name) for name in FUNCTIONS + ["fmi2Instantiate"]}
    fn["fmi2Instantiate"].restype = c_void_p
    fn["fmi2FreeInstance"].restype = None
    handles: dict[int, int | None] = {}
    saved: dict[int, c_void_p] = {}
    blobs: dict[int, bytes] = {}

    def doubles(values, n=None):
        n = len(values) if n is None else n
        return (c_double * max(n, 1))(*values[:n])

    def refs(values):
        return (c_uint * max(len(values), 1))(*values)

    out = os.fdopen(os.dup(1), "w")
    os.dup2(os.open(os.devnull, os.O_WRONLY), 1)
    for line in sys.stdin:
        req = json.loads(line)
        op, a = req["op"], req
        c = c_void_p(handles.get(a.get("slot", -1)))
        logged.clear()
        res = {}
        if op == "forget":  # a new sequence: no handles, no states (nothing is freed)
            handles.clear()
            saved.clear()
            blobs.clear()
            status = None
        elif op == "fmi2Instantiate":
            h = fn[op](a["name"].encode() if a["name"] is not None else None,
                       {"me": 0, "cs": 1}[a["kind"]], a["guid"].encode(), None,
                       byref(callbacks), 0, 1 if a["logging"] else 0)
            handles[a["slot"]] = h
            status = OK if h else ERROR
        elif op == "fmi2FreeInstance":
            fn[op](c)
            status = None
        elif op in ("fmi2EnterInitializationMode", "fmi2ExitInitializationMode",
                    "fmi2Terminate", "fmi2Reset", "fmi2EnterEventMode",
                    "fmi2EnterContinuousTimeMode", "fmi2CancelStep"):
            status = fn[op](c)
        elif op == "fmi2SetDebugLogging":
            cats = (c_char_p * max(len(a["categories"]), 1))(*[x.encode()
                                                                for x in a["categories"]])
            status = fn[op](c, int(a["on"]), c_size_t(len(a["categories"])), cats)
        elif op == "fmi2SetupExperiment":
            status = fn[op](c, int(a["tol"] is not None), c_double(a["tol"] or 0.0),
                            c_double(a["start"]), 0, c_double(0.0))
        elif op in ("fmi2GetReal", "fmi2SetReal"):
            vr, values = a["vr"], doubles(a.get("values", [0.0] * len(a["vr"])))
            status = fn[op](c, None if a.get("null") else refs(vr), c_size_t(len(vr)),
                            None if a.get("null") else values)
            if op == "fmi2GetReal" and status in (OK, WARNING):
                res["values"] = list(values)[:len(vr)]
        elif op in GETS + SETS_OTHER + ("fmi2SetRealInputDerivatives",
                                        "fmi2GetRealOutputDerivatives"):
            n = a["n"]
            buf = (ctypes.c_int * max(n, 1))() if "Integer" in op or "Boolean" in op \
                else (c_char_p * max(n, 1))()
            if op.endswith("Derivatives"):
                status = fn[op](c, refs([0] * n), c_size_t(n), (ctypes.c_int * max(n, 1))(),
                                doubles([0.0] * n))
            else:
                status = fn[op](c, refs([0] * n), c_size_t(n), buf)
        elif op == "fmi2SetTime":
            status = fn[op](c, c_double(a["t"]))
        elif op in ("fmi2SetContinuousStates", "fmi2GetDerivatives", "fmi2GetContinuousStates",
                    "fmi2GetNominalsOfContinuousStates", "fmi2GetEventIndicators"):
            values = doubles(a.get("values", []) + [0.0] * a["n"], a["n"])
            status = fn[op](c, None if a.get("null") else values, c_size_t(a["n"]))
            if op != "fmi2SetContinuousStates" and status in (OK, WARNING):
                res["values"] = list(values)[:a["n"]]
        elif op == "fmi2NewDiscreteStates":
            info = (c_char * 64)()  # (an fmi2EventInfo: five ints and a double)
            status = fn[op](c, None if a.get("null") else info)
        elif op == "fmi2CompletedIntegratorStep":
            enter, stop = c_int(0), c_int(0)
            status = fn[op](c, 1, byref(enter), byref(stop))
        elif op == "fmi2DoStep":
            status = fn[op](c, c_double(a["t"]), c_double(a["h"]), 0)
        elif op == "fmi2GetDirectionalDerivative":
            unknown, known = a["unknown"], a["known"]
            dv = doubles([1.0] * len(known))
            result = doubles([0.0] * len(unknown))
            status = fn[op](c, refs(unknown), c_size_t(len(unknown)),
                            None if a.get("null") else refs(known), c_size_t(len(known)),
                            None if a.get("null") else dv, result)
        elif op in STATUS_FUNCTIONS:
            value = (c_char * 16)()
            status = fn[op](c, c_int(a["kind"]), value)
        elif op == "fmi2GetFMUstate":
            slot = saved.setdefault(a["state"], c_void_p(None))
            status = fn[op](c, None if a.get("null") else byref(slot))
        elif op == "fmi2SetFMUstate":
            status = fn[op](c, saved.get(a["state"], c_void_p(None)))
        elif op == "fmi2FreeFMUstate":
            slot = saved.setdefault(a["state"], c_void_p(None))
            status = fn[op](c, byref(slot))
        elif op == "fmi2SerializedFMUstateSize":
            size = c_size_t(0)
            status = fn[op](c, saved.get(a["state"], c_void_p(None)), byref(size))
            res["size"] = size.value
        elif op == "fmi2SerializeFMUstate":
            size = c_size_t(0)
            state = saved.get(a["state"], c_void_p(None))
            fn["fmi2SerializedFMUstateSize"](c, state, byref(size))
            n = max(size.value + a.get("short", 0), 0)
            buf = (c_char * max(n, 1))()
            status = fn[op](c, state, buf, c_size_t(n))
            if status == OK:
                blobs[a["blob"]] = bytes(buf)[:size.value]
        elif op == "fmi2DeSerializeFMUstate":
            data = blobs.get(a["blob"], b"")
            if a.get("spoil"):
                data = bytes(len(data))
            buf = (c_char * max(len(data), 1)).from_buffer_copy(data or b"\0")
            slot = saved.setdefault(a["state"], c_void_p(None))
            status = fn[op](c, buf, c_size_t(len(data)), byref(slot))
        else:
            raise ValueError(op)
        res.update(status=status, errors=sum(1 for s, _ in logged if s >= ERROR),
                   messages=[m for _, m in logged][-3:])
        out.write(json.dumps(res) + "\n")
        out.flush()


class Crash(Exception):
    """The calling process died or did not answer: why."""


class Runner:
    """The process that has loaded an FMU's binary (killed and started again on demand)."""

    def __init__(self, binary: str, time_limit: float = 30.0, env: dict | None = None):
        self.binary, self.time_limit, self.env = binary, time_limit, env
        self.proc = None

    def start(self):
        self.stop()
        env = dict(os.environ, **(self.env or {}))
        self.proc = subprocess.Popen([sys.executable, str(Path(__file__).resolve()), "--runner",
                                      self.binary], stdin=subprocess.PIPE,
                                     stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env,
                                     start_new_session=True)

    def stop(self):
        if self.proc is not None:
            try:
                os.killpg(self.proc.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
            self.proc.communicate()
            self.proc = None

    def call(self, req: dict) -> dict:
        if self.proc is None:
            self.start()
        try:
            self.proc.stdin.write((json.dumps(req) + "\n").encode())
            self.proc.stdin.flush()
        except BrokenPipeError:
            pass
        ready, _, _ = select.select([self.proc.stdout], [], [], self.time_limit)
        line = self.proc.stdout.readline() if ready else b""
        if not line:
            hang = not ready
            if hang:
                os.killpg(self.proc.pid, signal.SIGKILL)
            code = self.proc.wait()
            err = self.proc.stderr.read().decode("utf-8", "replace")[-3000:]
            self.proc = None
            what = "no answer" if hang else \
                f"killed by {signal.Signals(-code).name}" if code < 0 else \
                f"a sanitizer's report (exit {code})" if "Sanitizer" in err else f"exit {code}"
            raise Crash(f"{req['op']}: {what}\n{err}")
        return json.loads(line)


# ------------------------------------------------------------ sequences and their checks

@dataclass
class Instance:
    """What the harness expects of one handle: its kind, its state (None: never
    instantiated, or NULL; "freed") and its time."""

    kind: str = "me"
    state: str | None = None
    t: float = 0.0
    live: bool = False


@dataclass
class Session:
    """One sequence of calls on an FMU, drawn and checked as it goes."""

    fmu: Fmu
    runner: Runner
    rng: random.Random
    strict: bool = False
    instances: list = field(default_factory=lambda: [Instance(), Instance()])
    saved: dict = field(default_factory=dict)  # state slot -> (kind, state, t)
    blobs: dict = field(default_factory=dict)  # blob slot -> (kind, state, t)
    log: list = field(default_factory=list)
    seen: dict = field(default_factory=dict)  # ("me" or "cs", state, "legal" or "illegal")
    #                                           or ("dead", "freed" or "NULL"): calls made

    # -- drawing a call
    def draw(self) -> tuple[dict, dict]:
        """(the request, what to expect: {"legal", "next": state, "t": time}): mostly a call
        its state allows with arguments it takes, else any function with arguments valid or
        not; on a handle never instantiated (NULL) or freed, an fmi2Instantiate or any call."""
        rng = self.rng
        slot = 0 if rng.random() < 0.8 else 1
        inst = self.instances[slot]
        if not inst.live:
            if rng.random() < 0.6:
                return self._instantiate(slot)
            name = rng.choice(FUNCTIONS)
            req, _ = self._args(name, Instance(rng.choice(self.fmu.kinds), INST), True)
            return {"op": name, "slot": slot, **req}, {"legal": False}
        table = TABLES[inst.kind]
        if rng.random() < 0.75:
            names = [f for f in table if inst.state in table[f] and self._can_be_legal(f, inst)]
            forward = [f for f in names if f in PROGRESS]
            if forward and rng.random() < 0.5:
                name = rng.choices(forward, [PROGRESS[f] for f in forward])[0]
            else:
                name = rng.choice(names)
            req, valid = self._args(name, inst, True)
        else:
            name = rng.choice(FUNCTIONS)
            req, valid = self._args(name, inst, rng.random() < 0.5)
        req = {"op": name, "slot": slot, **req}
        if name == "fmi2FreeInstance":
            return req, {"legal": True, "next": "freed"}
        if valid and inst.state in table.get(name, ()) and self._can_be_legal(name, inst):
            return req, self._legal(name, inst, req)
        return req, {"legal": False}

    def _instantiate(self, slot):
        kind = self.rng.choice(self.fmu.kinds)
        good = self.rng.random() < 0.9
        req = {"op": "fmi2Instantiate", "slot": slot, "kind": kind,
               "guid": self.fmu.guid if good else "{not-this-fmu}",
               "name": "fuzz" if good or self.rng.random() < 0.5 else "",
               "logging": self.rng.random() < 0.5}
        return req, {"legal": good, "next": INST, "t": self.fmu.t0, "kind": kind}

    def _can_be_legal(self, name, inst):
        if name == "fmi2GetDirectionalDerivative":
            return inst.kind == "me" and self.fmu.directional
        return name in TABLES[inst.kind]

    def _legal(self, name, inst, req):
        """The state and time after a legal call that succeeds."""
        nxt, t = inst.state, inst.t
        if name == "fmi2SetupExperiment":
            t = req["start"]
        elif name == "fmi2EnterInitializationMode":
            nxt = INIT
        elif name == "fmi2ExitInitializationMode":
            nxt = EVENT if inst.kind == "me" else STEP
        elif name == "fmi2Terminate":
            nxt = TERM
        elif name == "fmi2Reset":
            nxt, t = INST, self.fmu.t0
        elif name == "fmi2EnterEventMode":
            nxt = EVENT
        elif name == "fmi2EnterContinuousTimeMode":
            nxt = CONT
        elif name == "fmi2SetTime":
            t = req["t"]
        elif name == "fmi2DoStep":
            t = req["t"] + req["h"]
        elif name == "fmi2SetFMUstate":
            _, nxt, t = self.saved[req["state"]]
        return {"legal": True, "next": nxt, "t": t}

    # -- the arguments of a call
    def _args(self, name, inst, valid) -> tuple[dict, bool]:
        """(arguments for name on inst, whether the call can take them): valid ones if asked
        and there are any, else ones it cannot take if there are any."""
        rng, fmu = self.rng, self.fmu
        nx, ni = len(fmu.states), fmu.indicators
        refs, params, inputs = fmu.refs(), fmu.refs("parameter"), fmu.refs("input")
        if name == "fmi2SetDebugLogging":
            cats = rng.sample(["logStatusWarning", "logStatusDiscard", "logStatusError",
                               "logAll"], rng.randint(0, 2))
            return {"on": rng.random() < 0.5, "categories": cats + ([] if valid else ["x"])}, valid
        if name == "fmi2SetupExperiment":
            if valid:
                return {"tol": rng.choice([None, 1e-6, 1e-9]), "start": rng.choice([0.0, 0.5])}, \
                    True
            return rng.choice([{"tol": None, "start": math.inf}, {"tol": -1.0, "start": 0.0}]), \
                False
        if name == "fmi2GetReal":
            if valid:
                return {"vr": rng.sample(refs, rng.randint(0, min(4, len(refs))))}, True
            return rng.choice([{"vr": [max(refs) + 1000]}, {"vr": refs[:1], "null": True}]), False
        if name == "fmi2SetReal":
            settable = inputs + (params if inst.state in (INST, INIT) else [])
            start = dict(fmu.starts)
            if valid:
                vr = rng.sample(settable, rng.randint(0, min(2, len(settable))))
                return {"vr": vr, "values": [self._value(start.get(v, 0.0), v in inputs)
                                             for v in vr]}, True
            wrong = [vr for vr, c, _ in fmu.variables if c not in ("parameter", "input")]
            choices = [{"vr": [max(refs) + 1000], "values": [1.0]},
                       {"vr": [rng.choice(wrong)], "values": [1.0]}]
            choices += [{"vr": [v], "values": [math.nan]} for v in settable[:1]]
            if inst.state not in (INST, INIT) and params:
                choices.append({"vr": [params[0]], "values": [start.get(params[0], 1.0)]})
            return rng.choice(choices), False
        if name in GETS[1:] + SETS_OTHER + ("fmi2SetRealInputDerivatives",
                                            "fmi2GetRealOutputDerivatives"):
            return {"n": 0 if valid else 1}, valid  # (the FMU has Real variables only)
        if name == "fmi2SetTime":
            if valid:
                return {"t": inst.t + rng.choice([0.0, 1e-3, 0.01, 0.1]) * fmu.span}, True
            return {"t": rng.choice([math.nan, math.inf])}, False
        if name in ("fmi2SetContinuousStates", "fmi2GetDerivatives", "fmi2GetContinuousStates",
                    "fmi2GetNominalsOfContinuousStates", "fmi2GetEventIndicators"):
            n = ni if name == "fmi2GetEventIndicators" else nx
            values = [rng.choice([0.0, 0.5, 1.0, -1.0, 20.0]) for _ in range(n)]
            if valid:
                return {"n": n, "values": values}, True
            return rng.choice([{"n": n + 1, "values": values}]
                              + ([{"n": n, "null": True}] if n > 0 else [])), False
        if name == "fmi2NewDiscreteStates":
            return ({}, True) if valid else ({"null": True}, False)
        if name == "fmi2DoStep":
            if valid:
                h = rng.choice([0.0, 1e-3, 0.01, 0.1, 0.3]) * fmu.span
                return {"t": inst.t, "h": h}, True
            return rng.choice([{"t": inst.t + 1.0, "h": 0.01}, {"t": inst.t, "h": -1.0},
                               {"t": inst.t, "h": math.nan}]), False
        if name == "fmi2GetDirectionalDerivative":
            continuous = [vr for vr, c, v in fmu.variables if c == "output" and v == "continuous"]
            unknown = list(fmu.derivatives) + continuous
            req = {"unknown": rng.sample(unknown, min(len(unknown), 2)),
                   "known": rng.sample(fmu.states, min(nx, 2))}
            if valid or not (params or req["known"]):
                return req, True
            return (dict(req, known=[params[0]]) if params else dict(req, null=True)), False
        if name in STATUS_FUNCTIONS:
            return {"kind": rng.randint(0, 3)}, True
        if name == "fmi2GetFMUstate":
            return ({"state": rng.randint(0, 2)}, True) if valid else \
                ({"state": 0, "null": True}, False)
        if name == "fmi2FreeFMUstate":
            return {"state": rng.randint(0, 2)}, True
        if name in ("fmi2SetFMUstate", "fmi2SerializedFMUstateSize", "fmi2SerializeFMUstate"):
            good = [k for k, (kind, _, _) in self.saved.items()
                    if kind == inst.kind or name != "fmi2SetFMUstate"]
            if valid and good:
                return {"state": rng.choice(good), "blob": rng.randint(0, 1)}, True
            if name == "fmi2SerializeFMUstate" and good and rng.random() < 0.5:
                return {"state": rng.choice(good), "blob": 0, "short": -1}, False
            bad = [k for k in range(3) if k not in good] + [9]  # (9: never filled)
            return {"state": rng.choice(bad), "blob": 0}, False
        if name == "fmi2DeSerializeFMUstate":
            good = [k for k, (kind, _, _) in self.blobs.items() if kind == inst.kind]
            if valid and good:
                return {"blob": rng.choice(good), "state": rng.randint(0, 2)}, True
            if self.blobs and rng.random() < 0.5:
                return {"blob": rng.choice(list(self.blobs)), "state": 0, "spoil": True}, False
            return {"blob": rng.choice([k for k in range(3) if k not in good] + [9]),
                    "state": 0}, False
        return {}, True  # (no arguments)

    def _value(self, start, is_input):
        if is_input:
            return self.rng.choice([0.0, 1.0, -2.5, start])
        return start if self.strict else self.rng.choice([start, start, 2 * start, 0.5 * start])

    # -- making it and checking the answer
    def step(self) -> str | None:
        """One call: None, or what went wrong (the Crash propagates)."""
        req, want = self.draw()
        slot = req["slot"]
        inst = self.instances[slot]
        self.log.append({"call": req})  # (before the call: a crash's call is the last)
        got = self.log[-1]["answer"] = self.runner.call(req)
        status, fn = got["status"], req["op"]
        key = (inst.kind, inst.state, "legal" if want["legal"] else "illegal") if inst.live \
            else ("dead", "freed" if inst.state == "freed" else "NULL")
        self.seen[key] = self.seen.get(key, 0) + 1
        if fn == "fmi2Instantiate":
            if want["legal"]:
                if status != OK:
                    return "fmi2Instantiate: no instance"
                self.instances[slot] = Instance(want["kind"], INST, want["t"], True)
            else:
                if status != ERROR:
                    return "fmi2Instantiate with a wrong GUID or no name: an instance"
                self.instances[slot] = Instance(want["kind"], None, 0.0, False)
            return None
        if fn == "fmi2FreeInstance":
            if inst.live:
                self.instances[slot] = Instance(inst.kind, "freed", inst.t, False)
            return None
        if not inst.live:
            if status != ERROR:
                return f"{fn} through a {'freed' if inst.state == 'freed' else 'NULL'} " \
                       f"handle: status {status}, not fmi2Error"
            return None
        if not want["legal"]:
            if status != ERROR:
                return f"{fn} in {inst.state} ({inst.kind}, {_brief(req)}): status {status}, " \
                       "not fmi2Error"
            if got["errors"] == 0:
                return f"{fn} in {inst.state} ({inst.kind}, {_brief(req)}): fmi2Error without " \
                       "an error logged"
            return None
        allowed = {OK} | (set() if self.strict else MAY_FAIL[inst.kind].get(fn, set()))
        if fn in STATUS_FUNCTIONS and not (fn, req["kind"]) in (("fmi2GetRealStatus", 2),
                                                                ("fmi2GetBooleanStatus", 3)):
            allowed = {DISCARD}  # (a status the FMU has not: documented as fmi2Discard)
        if status not in allowed:
            return f"{fn} in {inst.state} ({inst.kind}, {_brief(req)}): status {status}, " \
                   f"legal: {sorted(allowed)} ({'; '.join(got['messages'])})"
        if status == ERROR:
            inst.state = ERR
            return None
        if status == DISCARD:
            return None
        inst.state, inst.t = want["next"], want["t"]
        if fn == "fmi2GetFMUstate":
            self.saved[req["state"]] = (inst.kind, inst.state, inst.t)
        elif fn == "fmi2FreeFMUstate":
            self.saved.pop(req["state"], None)
        elif fn == "fmi2SerializeFMUstate":
            self.blobs[req["blob"]] = self.saved[req["state"]]
        elif fn == "fmi2DeSerializeFMUstate":
            self.saved[req["state"]] = self.blobs[req["blob"]]
        return None

    def finish(self) -> str | None:
        """Frees what is live (from whatever state), then once more."""
        calls = [{"op": "fmi2FreeInstance", "slot": slot} for slot in (0, 0, 1, 1)]
        for req in calls + [{"op": "fmi2GetReal", "slot": 0, "vr": self.fmu.refs()[:1]}]:
            self.log.append({"call": req})
            got = self.log[-1]["answer"] = self.runner.call(req)
        if got["status"] != ERROR:
            return f"fmi2GetReal after fmi2FreeInstance: status {got['status']}"
        return None


def _brief(req: dict) -> str:
    return ", ".join(f"{k}={v}" for k, v in req.items() if k not in ("op", "slot")) or "-"


def fuzz(fmu: Fmu, seed: int, sequences: int, length: int = 40, strict: bool = False,
         time_limit: float = 30.0, env: dict | None = None, out: Path | None = None) -> dict:
    """sequences random sequences of about `length` calls on fmu, from seed: {"calls",
    "sequences", "seen": {"KIND STATE legal|illegal" or "dead freed|NULL": calls},
    "failures": [{"failure", "sequence", "log"}]} (a failing sequence's calls and answers
    also under out, if given)."""
    runner = Runner(fmu.binary, time_limit, env)
    failures, calls, seen = [], 0, {}
    try:
        for k in range(sequences):
            rng = random.Random(f"{seed}:{k}")
            session = Session(fmu, runner, rng, strict)
            problem = None
            try:
                for _ in range(rng.randint(1, 2 * length)):
                    problem = session.step()
                    if problem:
                        break
                problem = problem or session.finish()
            except Crash as crash:
                problem = f"crash: {crash}"
            calls += len(session.log)
            for key, n in session.seen.items():
                seen[" ".join(key)] = seen.get(" ".join(key), 0) + n
            if problem:
                entry = {"failure": problem, "sequence": k, "seed": seed, "fmu": fmu.folder,
                         "log": session.log}
                failures.append(entry)
                if out is not None:
                    out.mkdir(parents=True, exist_ok=True)
                    (out / f"fmu-{seed}-{k}.json").write_text(json.dumps(entry, indent=1))
            if problem:
                runner.stop()  # (the next sequence in a fresh process)
            else:
                runner.call({"op": "forget"})
    finally:
        runner.stop()
    return {"sequences": sequences, "calls": calls, "seen": dict(sorted(seen.items())),
            "failures": failures}


def sanitizer_env() -> dict | None:
    """The environment that loads AddressSanitizer into Python (for a binary built with it),
    or None where the compiler has none."""
    try:
        lib = subprocess.run(["cc", "-print-file-name=libasan.so"], capture_output=True,
                             text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return None
    if not os.path.isabs(lib):
        return None
    return {"LD_PRELOAD": lib, "ASAN_OPTIONS": "detect_leaks=0:abort_on_error=0:exitcode=99",
            "UBSAN_OPTIONS": "halt_on_error=1:print_stacktrace=1:exitcode=98"}


def build(text: str, folder, sanitize: bool = False) -> Fmu | None:
    """The FMU of model text (its first scene), extracted into folder; None if bgc refuses
    the model or its FMU with a message (a model error, a model an FMU cannot hold).  Any
    other exception is bgc's failure, and propagates."""
    sys.path.insert(0, str(ROOT))
    from bgc import api
    from bgc.base import toolchain
    from bgc.codegen import fmu as fmu_export
    from bgc.base.diagnostics import ModelError
    try:
        compiled = api.build(api.Source("m.bg", text))
        flags = ("-O1", "-g", "-std=c99", "-fsanitize=address,undefined",
                 "-fno-sanitize-recover=all") if sanitize else None
        data = fmu_export.build_fmu(compiled, flags=flags)
    except (api.BgcModelError, ModelError, fmu_export.FmuError, toolchain.BackendError):
        return None
    Path(folder, "m.fmu").write_bytes(data)
    return extract(Path(folder, "m.fmu"), folder)


def fuzz_model(text: str, seed: int, sequences: int = 20, length: int = 30,
               time_limit: float = 30.0, out: Path | None = None) -> dict | None:
    """tools/fuzz.py's entry: the FMU of a generated model, fuzzed (fuzz's result); None if
    bgc exports none for the model."""
    with tempfile.TemporaryDirectory(prefix="bgcfuzz-fmu-") as tmp:
        fmu = build(text, tmp)
        if fmu is None:
            return None
        return fuzz(fmu, seed, sequences, length, time_limit=time_limit, out=out)


def replay(fmu_path, entry: dict, time_limit: float) -> int:
    """The calls of a failing sequence (fuzz's entry) made again, each printed with its
    answer: 1 if the process dies, else 0."""
    with tempfile.TemporaryDirectory(prefix="bgcfuzz-fmu-") as tmp:
        fmu = extract(fmu_path, tmp)
        runner = Runner(fmu.binary, time_limit)
        try:
            for item in entry["log"]:
                req = dict(item["call"], guid=fmu.guid) if item["call"]["op"] == \
                    "fmi2Instantiate" and item["call"].get("guid") != "{not-this-fmu}" \
                    else item["call"]
                got = runner.call(req)
                print(f"{_brief(req)} [{req['op']}, slot {req['slot']}] -> {got['status']} "
                      f"{'; '.join(got['messages'])}")
        except Crash as crash:
            print(f"crash: {crash}")
            return 1
        finally:
            runner.stop()
    print(f"failure as found: {entry['failure']}")
    return 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--fmu", type=Path, help="an FMU to fuzz (else: generated models)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--models", type=int, default=20, help="generated models (without --fmu)")
    ap.add_argument("--sequences", type=int, default=100, help="sequences of calls per FMU")
    ap.add_argument("--length", type=int, default=40, help="calls in a sequence, on average")
    ap.add_argument("--strict", action="store_true",
                    help="every legal call must succeed (a model that cannot fail)")
    ap.add_argument("--sanitize", action="store_true",
                    help="build with -fsanitize=address,undefined and load ASan into Python")
    ap.add_argument("--time-limit", type=float, default=30.0, help="seconds per call")
    ap.add_argument("--out", type=Path, default=Path("fuzz-fmu-out"))
    ap.add_argument("--replay", type=Path, help="the calls of a failing sequence's JSON, made "
                    "again on --fmu, each printed with its answer")
    ap.add_argument("--model", type=Path, help="one model: its FMU fuzzed, the result as JSON "
                    "on stdout's last line (tools/fuzz.py's way in)")
    ap.add_argument("--runner", help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.runner:
        _runner_main(a.runner)
        return 0
    env = sanitizer_env() if a.sanitize else None
    if a.sanitize and env is None:
        ap.error("--sanitize: the C compiler has no AddressSanitizer here")
    if a.model:
        res = fuzz_model(a.model.read_text(encoding="utf-8"), a.seed, a.sequences, a.length,
                         a.time_limit, a.out)
        print(json.dumps(res and {k: v for k, v in res.items() if k != "failures"}
                         | {"failures": [f["failure"] for f in res["failures"]]}))
        return 0
    if a.replay:
        if not a.fmu:
            ap.error("--replay needs --fmu")
        return replay(a.fmu, json.loads(a.replay.read_text(encoding="utf-8")), a.time_limit)
    a.out.mkdir(parents=True, exist_ok=True)
    start, results = time.monotonic(), []
    with tempfile.TemporaryDirectory(prefix="bgcfuzz-fmu-") as tmp:
        if a.fmu:
            fmus = [extract(a.fmu, tmp)]
            if a.sanitize:
                print("--sanitize: only with generated models (the FMU is built here)")
        else:
            sys.path.insert(0, str(ROOT / "tools"))
            import fuzz as model_fuzz
            rng, fmus, tried = random.Random(a.seed), [], 0
            while len(fmus) < a.models:
                folder = Path(tmp, f"m{tried}")
                folder.mkdir()
                tried += 1
                text = model_fuzz.generate(rng)
                built = build(text, folder, a.sanitize)
                if built is not None:
                    (a.out / f"model-{a.seed}-{len(fmus)}.bg").write_text(text, encoding="utf-8")
                    fmus.append(built)
            print(f"{len(fmus)} FMUs of {tried} generated models (models in {a.out})")
        for k, fmu in enumerate(fmus):
            res = fuzz(fmu, a.seed * 1000 + k, a.sequences, a.length, a.strict, a.time_limit,
                       env, a.out)
            results.append(res)
            print(f"FMU {k}: {res['calls']} calls, {len(res['failures'])} failing sequences",
                  flush=True)
            for f in res["failures"][:3]:
                print(f"  sequence {f['sequence']}: {f['failure']}")
    summary = {"seed": a.seed, "fmus": len(results),
               "sequences": sum(r["sequences"] for r in results),
               "calls": sum(r["calls"] for r in results),
               "failing_sequences": sum(len(r["failures"]) for r in results),
               "seconds": round(time.monotonic() - start)}
    (a.out / "summary.json").write_text(json.dumps(summary, indent=1) + "\n")
    print(json.dumps(summary, indent=1))
    return 1 if summary["failing_sequences"] else 0


if __name__ == "__main__":
    sys.exit(main())
