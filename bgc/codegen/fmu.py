"""FMU export: a compiled model as an FMI 2.0 FMU for Model Exchange and Co-Simulation.

The FMU (a zip archive) holds
  modelDescription.xml            the variables, the model structure, the default experiment;
  sources/<id>.c                  one C99 file: the generated program (bgc.codegen.emit.emit_c, its
                                  main left out), the FMU part below and bgc/runtime/fmi2.c;
  binaries/<platform>/<id>.so     that file built with the system C compiler (cc or $CC) as a
                                  shared library (.dylib on macOS);
where <id>, the model identifier, is the model's name as a C identifier.

The variables, their value references as bgc/runtime/fmi2.c numbers them:
  parameters   causality "parameter", variability "fixed", start = the default;
  states       "local" (or "output" when the scene outputs the state), initial "calculated":
               computed from the parameters when initialisation ends;
  derivatives  der(<state>), with the `derivative` attribute naming their state;
  outputs      the scene's other outputs, causality "output";
  discrete     the model's discrete variables (`discrete heat = 1`), "local", variability
               "discrete": set at events;
  inputs       the model's inputs (`input u = 0`), causality "input", variability
               "continuous", start = the default: set with fmi2SetReal, held until set again;
  time         the time t, causality "independent" (FMI 2.0's independent variable, which
               an FMU without it has implicitly): listed, so that every FMU has a variable
               (the schema requires one; a model of no parameters, states, outputs or inputs
               has no other) and fmi2GetReal gives the instance's time.
A model with events has an event indicator per state relation (numberOfEventIndicators) and
time events (fmi2NewDiscreteStates' nextEventTime); bgc/runtime/fmi2.c says how.
Descriptions come from the model's doc strings; a unit from the declaration's `unit "..."`
(a parameter's, a signal's, an input's), else, for a parameter, from a trailing "[unit]" in
its doc string; every text from the model is escaped.

Pure up to the build: the same model gives the same XML and sources (hence the same GUID,
derived from them) under any hash seed; the archive's entries carry fixed dates and modes.
"""
from __future__ import annotations

import hashlib
import io
import math
import re
import shutil
import struct
import sys
import tempfile
import uuid
import zipfile
from dataclasses import dataclass
from pathlib import Path

import sympy as sp

from ..base import toolchain
from .. import ir
from .emit import runtime_text, c_string_literal, emit_c, identifier
from .lower import with_tangent

GUID_PLACEHOLDER = "{00000000-0000-0000-0000-000000000000}"
SHARED_FLAGS = ("-shared", "-fPIC", "-fvisibility=hidden")
PLATFORMS = {"linux": ("linux64", ".so"), "darwin": ("darwin64", ".dylib")}
LOG_CATEGORIES = (
    ("logStatusWarning", "warnings"),
    ("logStatusDiscard", "a model evaluation that failed (an algebraic block)"),
    ("logStatusError", "errors (always reported)"),
    ("logAll", "all messages"),
)
C_KEYWORDS = frozenset(
    "auto break case char const continue default do double else enum extern float for goto "
    "if inline int long register restrict return short signed sizeof static struct switch "
    "typedef union unsigned void volatile while _Bool _Complex _Imaginary".split())
_STRUCTURED = re.compile(
    r"(der\()?(?P<id>[A-Za-z_][A-Za-z0-9_]*(?:\[[0-9]+(?:,[0-9]+)*\])?"
    r"(?:\.[A-Za-z_][A-Za-z0-9_]*(?:\[[0-9]+(?:,[0-9]+)*\])?)*)(?(1)\))\Z")
_UNIT = re.compile(r"\[([^\[\]]+)\]\s*\Z")
_NOT_XML = re.compile("[\x00-\x08\x0b\x0c\x0e-\x1f\ud800-\udfff\ufffe\uffff]")


class FmuError(ValueError):
    """A model that this FMU export cannot represent (the message says why, for people)."""


@dataclass(frozen=True)
class Variable:
    """One ScalarVariable of modelDescription.xml (all Real)."""

    name: str
    vr: int
    causality: str  # parameter | local | output | input | independent
    variability: str  # fixed | continuous | discrete
    initial: str | None  # exact | calculated (None: an input or time, which have none)
    description: str | None = None
    start: float | None = None
    unit: str | None = None
    derivative: int | None = None  # the 1-based index of the state this is the derivative of


@dataclass(frozen=True)
class Description:
    """What modelDescription.xml says, before it is printed."""

    name: str
    ident: str
    doc: str | None
    variables: tuple[Variable, ...]
    outputs: tuple[tuple[int, tuple[int, ...]], ...]  # (index, dependencies), 1-based
    derivatives: tuple[tuple[int, tuple[int, ...]], ...]
    initial_unknowns: tuple[int, ...]
    units: tuple[str, ...]
    experiment: ir.SceneSettings
    structured: bool
    indicators: int = 0  # event indicators: the state relations
    discrete: tuple[int, ...] = ()  # each discrete variable's place among the discrete values
    input_slots: tuple[int, ...] = ()  # each input's value's place among the discrete values
    #                                    (-1: the scene does not use it)


def model_identifier(name: str) -> str:
    """The model's name as a C identifier (the binary's and the source's name)."""
    ident = identifier(name)
    return ident + "_" if ident in C_KEYWORDS or ident.startswith("fmi2") else ident


def platform() -> tuple[str, str]:
    """The FMI 2.0 platform folder and the shared library's suffix of this machine, or
    BackendError on one the export does not build for."""
    for prefix, answer in PLATFORMS.items():
        if sys.platform.startswith(prefix) and struct.calcsize("P") == 8:
            return answer
    raise toolchain.BackendError(
        f"FMU export builds binaries on 64-bit Linux and macOS only, not on {sys.platform} "
        f"({8 * struct.calcsize('P')}-bit)")


# ---------------------------------------------------------------- the description


def describe(compiled) -> Description:
    """The variables and the model structure of compiled's program (a build with its
    program)."""
    program = compiled.program
    graph = compiled.graph
    events = program.events or ir.Events((), 0, (), ())
    n, m = len(program.states), len(program.params)
    state_index = {name: i for i, name in enumerate(program.states)}
    param_names = {p.name for p in program.params}
    for name in program.outputs:
        if name in param_names:
            raise FmuError(f"output '{name}' is a parameter: in an FMU a variable is either a "
                           "parameter or an output; leave it out of the outputs "
                           "(the parameter is in the FMU)")
    docs = {p.name: p.doc for p in graph.parameters}
    declared_units = _declared_units(graph)
    outputs_of_state = {state_index[o]: k for k, o in enumerate(program.outputs)
                        if o in state_index}
    variables: list[Variable] = []
    for j, (p, value) in enumerate(zip(program.params, _parameter_values(program))):
        doc = docs.get(p.name)
        unit = declared_units.get(p.name) or _unit(doc)
        variables.append(Variable(p.name, j, "parameter", "fixed", "exact", doc, value, unit))
    state_pos = {}
    for i, name in enumerate(program.states):
        state_pos[i] = len(variables) + 1
        causality = "output" if i in outputs_of_state else "local"
        variables.append(Variable(name, m + i, causality, "continuous", "calculated",
                                  _variable_doc(graph, name), unit=declared_units.get(name)))
    der_pos = {}
    for i, name in enumerate(program.states):
        der_pos[i] = len(variables) + 1
        variables.append(Variable(f"der({name})", m + n + i, "local", "continuous",
                                  "calculated", f"time derivative of {name}",
                                  unit=ratio(declared_units.get(name), "s"),
                                  derivative=state_pos[i]))
    out_pos = {}
    input_names = {u.name for u in program.inputs}
    discrete = tuple(k for k, kind in enumerate(events.kinds) if kind == "discrete")
    discrete_names = [events.names[place] for place in discrete]
    for k, name in enumerate(program.outputs):
        if name in input_names or name in discrete_names:  # (that variable, set below)
            continue
        if name in state_index:
            out_pos[k] = state_pos[state_index[name]]
            continue
        out_pos[k] = len(variables) + 1
        variables.append(Variable(name, m + 2 * n + k, "output", "continuous", "calculated",
                                  _variable_doc(graph, name), unit=declared_units.get(name)))
    for k, name in enumerate(discrete_names):  # an output too: the discrete variable's
        outputs_it = [j for j, o in enumerate(program.outputs) if o == name]
        for j in outputs_it:
            out_pos[j] = len(variables) + 1
        variables.append(Variable(name, m + 2 * n + len(program.outputs) + k,
                                  "output" if outputs_it else "local", "discrete",
                                  "calculated", "a discrete variable, set at events",
                                  unit=declared_units.get(name)))
    params = _parameter_values(program)
    input_pos, input_slots = [], []
    for j, u in enumerate(program.inputs):
        input_pos.append(len(variables) + 1)
        variables.append(Variable(u.name, m + 2 * n + len(program.outputs) + len(discrete) + j,
                                  "input", "continuous", None, u.doc,
                                  _value_of(u.default, params, f"the default of input '{u.name}'"),
                                  declared_units.get(u.name)))
        slot = [k for k, (kind, name) in enumerate(zip(events.kinds, events.names))
                if kind == "input" and name == u.name]
        input_slots.append(slot[0] if slot else -1)
    vr_time = m + 2 * n + len(program.outputs) + len(discrete) + len(program.inputs)
    variables.append(Variable("time", vr_time, "independent", "continuous", None,
                              "the time t", unit="s"))  # (`time` is a keyword: no model's name)
    names = [v.name for v in variables]
    if len(set(names)) != len(names):
        twice = sorted({x for x in names if names.count(x) > 1})
        raise FmuError(f"variable names occur twice in the FMU: {', '.join(twice)}")
    rows = [[] for _ in range(n)]
    for j, column in enumerate(program.jacobian.columns):
        for i in column:
            rows[i].append(state_pos[j])
    for i in range(n):  # (an input may reach every derivative)
        rows[i] += input_pos
    out_deps = _state_dependence(program.function("outputs"), len(program.outputs))
    outputs = {}
    for k, name in enumerate(program.outputs):
        if name in input_names:
            continue
        deps = (state_pos[state_index[name]],) if name in state_index else () \
            if name in discrete_names else \
            tuple(state_pos[j] for j in out_deps[k]) + tuple(input_pos)
        outputs.setdefault(out_pos[k], deps)
    initial = sorted(set(outputs) | set(state_pos.values()) | set(der_pos.values()))
    return Description(
        name=program.name, ident=model_identifier(program.name), doc=graph.doc,
        variables=tuple(variables),
        outputs=tuple(sorted(outputs.items())),
        derivatives=tuple((der_pos[i], tuple(sorted(rows[i]))) for i in range(n)),
        initial_unknowns=tuple(initial), units=tuple(dict.fromkeys(v.unit for v in variables
                                                                   if v.unit)),
        experiment=program.scene,
        structured=all(_STRUCTURED.match(v) for v in names),
        indicators=events.indicators, discrete=discrete, input_slots=tuple(input_slots))


def _value_of(expr, params: list, what: str) -> float:
    """An expression of the parameters at their defaults, as a number."""
    e = ir.as_expr(expr).xreplace({ir.P[k]: sp.Float(v, 30) for k, v in enumerate(params)})
    try:
        value = float(sp.N(e, 30))
    except (TypeError, ValueError):
        value = math.nan
    if not math.isfinite(value):
        raise FmuError(f"{what} is not a finite number, so it has no start value in the FMU")
    return value


def _parameter_values(program) -> list[float]:
    """The parameters' defaults as numbers, each from the ones before it."""
    values: list[float] = []
    for p in program.params:
        expr = ir.as_expr(p.default).xreplace(
            {ir.P[k]: sp.Float(v, 30) for k, v in enumerate(values)})
        try:
            value = float(sp.N(expr, 30))
        except (TypeError, ValueError):
            value = math.nan
        if not math.isfinite(value):
            raise FmuError(f"the default of parameter '{p.name}' is not a finite number, so it "
                           "has no start value in the FMU")
        values.append(value)
    return values


def _declared_units(graph) -> dict:
    """The units of the model's variables by name: declared (`unit "kg"`: of its parameters,
    its signals, each scalar part of a vector one, and its inputs) or found by the units stage
    (bgc.front.units: a bond's effort from its port's domain, a state from its law)."""
    declared = [*graph.parameters, *graph.signals, *graph.inputs]
    return {**dict(graph.units), **{d.name: d.unit for d in declared if d.unit}}


def ratio(num, den):
    """The unit of num/den (bgc.front.units.ratio)."""
    from ..front.units import ratio as quotient
    return quotient(num, den)


def _unit_element(name: str) -> str:
    """A UnitDefinitions entry: the unit and its exponents of the SI base units (FMI 2.0's
    BaseUnit, integers only: a unit with a fractional exponent, Pa^0.5, is named only)."""
    try:
        from ..base import si
        u = si.parse(name)
    except ValueError:
        return f"    <Unit{_attrs(name=name)}/>"
    if any(e.denominator != 1 for e in u.dims):
        return f"    <Unit{_attrs(name=name)}/>"
    base = {b: str(int(e)) for b, e in zip(si.BASE, u.dims) if e}
    if u.scale != 1.0:
        base["factor"] = repr(u.scale)
    return (f"    <Unit{_attrs(name=name)}><BaseUnit{_attrs(**base)}/></Unit>" if base
            else f"    <Unit{_attrs(name=name)}/>")


def _unit(doc: str | None) -> str | None:
    """The unit a doc string ends with in brackets ("source voltage [V]"), if any."""
    m = _UNIT.search(doc or "")
    unit = m.group(1).strip() if m else ""
    return unit or None


FIELDS = {"e": "effort", "f": "flow", "p": "generalized momentum",
          "q": "generalized displacement", "lambda": "constraint multiplier",
          "residual": "constraint residual", "balance": "constraint balance"}


def _variable_doc(graph, name: str) -> str | None:
    """What a variable is, with its element's doc string: "ind.p" -> "generalized momentum
    of ind (inductor: ...)", "mass.p[2]" -> "... of mass[2] (...)"; None for a signal."""
    head, dot, rest = name.rpartition(".")  # (a path: `s[1].cap.q` is variable q of s[1].cap)
    if not dot:
        return None
    m = re.fullmatch(r"(.*?)(\[[0-9]+\])?", rest)
    field, index = m.group(1), m.group(2) or ""
    element = head + index
    el = graph.by_name.get(element) or graph.by_name.get(head)
    text = f"{FIELDS.get(field, field)} of {element}"
    return f"{text} ({el.doc})" if el is not None and el.doc else text


def _state_dependence(f: ir.Function, size: int) -> list[tuple[int, ...]]:
    """The states each result of f may depend on (structurally, through its solves), sorted."""
    return [tuple(sorted(row)) for row in ir.state_dependencies(f, size)]


# ---------------------------------------------------------------- modelDescription.xml


def _text(value: str) -> str:
    """An XML attribute value: escaped, characters XML cannot hold replaced by U+FFFD."""
    value = _NOT_XML.sub("\ufffd", value)
    return (value.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;")
            .replace('"', "&quot;").replace("\t", "&#9;").replace("\n", "&#10;")
            .replace("\r", "&#13;"))


def _attrs(**attrs) -> str:
    return "".join(f' {k}="{_text(str(v))}"' for k, v in attrs.items() if v is not None)


def _number(value: float) -> str:
    return repr(float(value))


def model_description(d: Description, guid: str) -> str:
    """modelDescription.xml (FMI 2.0) for d."""
    ident = d.ident
    lines = ['<?xml version="1.0" encoding="UTF-8"?>',
             "<fmiModelDescription" + _attrs(
                 fmiVersion="2.0", modelName=d.name, guid=guid, description=d.doc,
                 generationTool="bgc",
                 variableNamingConvention="structured" if d.structured else "flat",
                 numberOfEventIndicators=d.indicators) + ">"]
    common = dict(canNotUseMemoryManagementFunctions="true", canGetAndSetFMUstate="true",
                  canSerializeFMUstate="true")
    sources = ["    <SourceFiles>", f'      <File name="{_text(ident)}.c"/>', "    </SourceFiles>"]
    lines.append("  <ModelExchange" + _attrs(
        modelIdentifier=ident, completedIntegratorStepNotNeeded=str(d.indicators == 0).lower(),
        **common,
        providesDirectionalDerivative="true") + ">")
    lines += sources + ["  </ModelExchange>"]
    lines.append("  <CoSimulation" + _attrs(
        modelIdentifier=ident, canHandleVariableCommunicationStepSize="true",
        canInterpolateInputs="false", maxOutputDerivativeOrder=0,
        canRunAsynchronuously="false", **common, providesDirectionalDerivative="false") + ">")
    lines += sources + ["  </CoSimulation>"]
    if d.units:
        lines.append("  <UnitDefinitions>")
        lines += [_unit_element(u) for u in d.units]
        lines.append("  </UnitDefinitions>")
    lines.append("  <LogCategories>")
    lines += [f"    <Category{_attrs(name=n, description=t)}/>" for n, t in LOG_CATEGORIES]
    lines.append("  </LogCategories>")
    ex = d.experiment
    lines.append("  <DefaultExperiment" + _attrs(
        startTime=_number(ex.t0), stopTime=_number(ex.t_end), tolerance=_number(ex.rtol),
        stepSize=_number(ex.dt)) + "/>")
    lines.append("  <ModelVariables>")
    for k, v in enumerate(d.variables, 1):
        lines.append(f"    <!-- {k} -->")
        lines.append("    <ScalarVariable" + _attrs(
            name=v.name, valueReference=v.vr, description=v.description,
            causality=v.causality, variability=v.variability, initial=v.initial) + ">")
        start = None if v.start is None else _number(v.start)
        lines.append(f"      <Real{_attrs(unit=v.unit, start=start, derivative=v.derivative)}/>")
        lines.append("    </ScalarVariable>")
    lines.append("  </ModelVariables>")
    lines.append("  <ModelStructure>")
    for tag, unknowns in (("Outputs", d.outputs), ("Derivatives", d.derivatives),
                          ("InitialUnknowns", [(k, None) for k in d.initial_unknowns])):
        if not unknowns:
            continue
        lines.append(f"    <{tag}>")
        for index, deps in unknowns:
            dep = None if deps is None else " ".join(map(str, deps))
            lines.append(f"      <Unknown{_attrs(index=index, dependencies=dep)}/>")
        lines.append(f"    </{tag}>")
    lines.append("  </ModelStructure>")
    lines.append("</fmiModelDescription>")
    return "\n".join(lines) + "\n"


# ---------------------------------------------------------------- the C source


def fmu_program(program) -> ir.Program:
    """The program with the model functions only an FMU needs: outputs_jvp, the outputs'
    derivative along a direction v of the states (fmi2GetDirectionalDerivative)."""
    return with_tangent(program, "outputs", "outputs_jvp")


def fmu_source(program, guid: str, project_initial: bool = False,
               allow_inconsistent: bool = False, discrete: tuple[int, ...] = (),
               input_slots: tuple[int, ...] = ()) -> str:
    """The FMU's one C file: the generated program (fmu_program's, its main left out), the
    FMU part, bgc/runtime/fmi2.c; discrete: Description.discrete."""
    (text,) = emit_c(fmu_program(program)).values()
    states = {name: i for i, name in enumerate(program.states)}
    out_state = [str(states.get(o, -1)) for o in program.outputs] or ["-1"]
    ident = model_identifier(program.name)
    head = [
        f"/* FMI 2.0 FMU {ident} (Model Exchange and Co-Simulation), generated by bgc.  Build:",
        f" *   cc -shared -fPIC -fvisibility=hidden -O2 -std=c99 {ident}.c -o {ident}.so -lm",
        " * (.dylib on macOS).  The generated program follows, its command line left out. */",
        "#define BGC_NO_MAIN 1",
        "#define BGC_FMU 1 /* the runtime's messages say what applies in an FMU */",
    ]
    part = [
        "/* ============================================================= FMU part === */",
        f"#define BGC_FMI_GUID {c_string_literal(guid)}",
        f"#define BGC_FMI_PROJECT_INITIAL {int(project_initial)}",
        f"#define BGC_FMI_ALLOW_INCONSISTENT {int(allow_inconsistent)}",
        "/* The state each output is (-1: an output of its own). */",
        "static const int bgc_fmi_output_state[BGC_DIM(BGC_NUM_OUTPUTS)] = { "
        + ", ".join(out_state) + " };",
        "/* Where each discrete variable is among the discrete values d. */",
        f"#define BGC_FMI_NUM_DISCRETE_VARS {len(discrete)}",
        "static const int bgc_fmi_discrete[BGC_DIM(BGC_FMI_NUM_DISCRETE_VARS)] = { "
        + ", ".join(map(str, discrete or (0,))) + " };",
        "/* Where each input's value is among the discrete values d (-1: not used). */",
        f"#define BGC_FMI_NUM_INPUTS {len(program.inputs)}",
        "static const int bgc_fmi_input_slot[BGC_DIM(BGC_FMI_NUM_INPUTS)] = { "
        + ", ".join(map(str, input_slots or (0,))) + " };",
    ]
    return "\n".join(head) + "\n" + text + "\n" + "\n".join(part) + "\n" + \
        runtime_text("fmi2.c")


def make_guid(*texts: str) -> str:
    """A GUID derived from the texts (name-based, SHA-1: RFC 4122 version 5)."""
    digest = hashlib.sha256("\0".join(texts).encode("utf-8")).hexdigest()
    return "{" + str(uuid.uuid5(uuid.NAMESPACE_URL, "urn:bgc:fmu:" + digest)) + "}"


def fmu_texts(compiled, project_initial: bool = False,
              allow_inconsistent: bool = False) -> tuple[Description, str, str]:
    """(description, modelDescription.xml, the C source), the GUID derived from both."""
    d = describe(compiled)
    xml = model_description(d, GUID_PLACEHOLDER)
    source = fmu_source(compiled.program, GUID_PLACEHOLDER, project_initial, allow_inconsistent,
                        d.discrete, d.input_slots)
    guid = make_guid(xml, source)
    return d, xml.replace(GUID_PLACEHOLDER, guid), source.replace(GUID_PLACEHOLDER, guid)


# ---------------------------------------------------------------- building


def build_binary(source: str, ident: str, suffix: str, cc: str | None = None,
                 flags: tuple[str, ...] | None = None) -> bytes:
    """The shared library built from source with the system C compiler ($CC or cc) and the C
    backend's flags ($BGC_CFLAGS, else -O2 -std=c99), plus SHARED_FLAGS."""
    command = toolchain.c_compiler(cc)
    if not command or shutil.which(command[0]) is None:
        raise toolchain.BackendError(
            "FMU export needs a C compiler to build the FMU's binary: install one (cc), or "
            "set CC")
    flags = toolchain.c_flags() if flags is None else tuple(flags)
    with tempfile.TemporaryDirectory(prefix="bgc-fmu-") as tmp:
        work = Path(tmp)
        (work / f"{ident}.c").write_text(source, encoding="utf-8")
        out = f"{ident}{suffix}"
        toolchain.run_compiler([*command, *flags, *SHARED_FLAGS, f"{ident}.c", "-o", out,
                                *toolchain.C_LIBS], work, cwd=work)
        return (work / out).read_bytes()


def archive(files: dict[str, bytes]) -> bytes:
    """A zip of files (path -> bytes) in the given order, with fixed dates and modes."""
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w", zipfile.ZIP_DEFLATED) as z:
        for name, data in files.items():
            info = zipfile.ZipInfo(name, date_time=(1980, 1, 1, 0, 0, 0))
            info.compress_type = zipfile.ZIP_DEFLATED
            info.create_system = 3  # Unix: the modes below apply
            info.external_attr = (0o755 if name.startswith("binaries/") else 0o644) << 16
            z.writestr(info, data)
    return buffer.getvalue()


def build_fmu(compiled, project_initial: bool = False, cc: str | None = None,
              flags: tuple[str, ...] | None = None, allow_inconsistent: bool = False) -> bytes:
    """The FMU of compiled (a build with its program) as the bytes of a zip archive; its
    initial state projected onto the constraints (project_initial), or taken as it is when
    it violates them (allow_inconsistent), else refused by fmi2ExitInitializationMode."""
    folder, suffix = platform()
    d, xml, source = fmu_texts(compiled, project_initial, allow_inconsistent)
    binary = build_binary(source, d.ident, suffix, cc, flags)
    return archive({
        "modelDescription.xml": xml.encode("utf-8"),
        f"binaries/{folder}/{d.ident}{suffix}": binary,
        f"sources/{d.ident}.c": source.encode("utf-8"),
    })


def file_name(compiled) -> str:
    return f"{model_identifier(compiled.program.name)}.fmu"
