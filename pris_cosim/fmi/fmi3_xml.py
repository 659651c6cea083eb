"""``modelDescription.xml`` and ``buildDescription.xml`` of FMI 3.0 FMUs.

The FMI 3.0 FMU holds the same network, variables, ranges, dependencies and
default experiment as the FMI 2.0 one (:func:`pris_cosim.fmi.build.model_description`).
FMI 3.0 numbers all variables in one value-reference space: Float64
variables keep their FMI 2.0 Real value reference, Int32 variables follow
the Real ones, and the independent variable ``time`` comes last (the C layer
``prc_fmi3.c`` maps them back).
"""

from __future__ import annotations

from xml.sax.saxutils import quoteattr

from pris_cosim import __version__
from pris_cosim.fmi.codegen import NetworkModel, Variable, c_source_files

#: Preprocessor symbol that compiles the FMI 2.0 layer under internal names for the FMI 3.0 layer.
FMI3_DEFINE = "PRC_FMI3"


def _fmt(x: float) -> str:
    return repr(float(x))


def value_reference(model: NetworkModel, v: Variable) -> int:
    """FMI 3.0 value reference of a variable."""
    return v.vr if v.type == "Real" else len(model.real) + v.vr


def time_reference(model: NetworkModel) -> int:
    """FMI 3.0 value reference of the independent variable ``time``."""
    return len(model.real) + len(model.integer)


def _variable_xml(model: NetworkModel, v: Variable) -> str:
    tag = "Float64" if v.type == "Real" else "Int32"
    attrs = [f"name={quoteattr(v.name)}", f'valueReference="{value_reference(model, v)}"']
    if v.description:
        attrs.append(f"description={quoteattr(v.description)}")
    attrs += [f'causality="{v.causality}"', f'variability="{v.variability}"']
    if v.initial is not None:
        attrs.append(f'initial="{v.initial}"')
    if v.unit and tag == "Float64":
        attrs.append(f"unit={quoteattr(v.unit)}")
    for attr in ("min", "max", "nominal"):
        x = getattr(v, attr)
        if x is not None:
            attrs.append(f'{attr}="{_fmt(x) if tag == "Float64" else int(x)}"')
    if v.start is not None:
        attrs.append(f'start="{_fmt(v.start) if tag == "Float64" else int(v.start)}"')
    if v.derivative_of is not None:
        attrs.append(f'derivative="{v.derivative_of}"')
    return f"    <{tag} {' '.join(attrs)}/>"


def model_description3(model: NetworkModel, guid: str, units_xml: str) -> str:
    """``modelDescription.xml`` (FMI 3.0, Model Exchange and Co-Simulation).

    Parameters
    ----------
    model : NetworkModel
    guid : str
        Instantiation token.
    units_xml : str
        The ``<UnitDefinitions>`` element (the same as in FMI 2.0).

    Returns
    -------
    str
        XML text.
    """
    exposed = [v for v in model.real if v.exposed] + [v for v in model.integer if v.exposed]
    states = [v for v in model.real if v.nominal is not None and v.causality == "local" and v.derivative_of is None]
    inputs = [v.vr for v in model.real if v.causality == "input"]

    def unknown(tag: str, vr: int, idx: list[int]) -> str:
        idx = sorted(set(idx))
        if not idx:
            return f'    <{tag} valueReference="{vr}" dependencies=""/>'
        kinds = " ".join(["dependent"] * len(idx))
        return f'    <{tag} valueReference="{vr}" dependencies="{" ".join(map(str, idx))}" dependenciesKind="{kinds}"/>'

    def run_time(deps: tuple[list[int], bool]) -> list[int]:
        return [states[k].vr for k in deps[0]] + (inputs if deps[1] else [])

    def params(variables: list[Variable]) -> list[int]:
        return [value_reference(model, v) for v in variables]

    derivs = [v for v in model.real if v.derivative_of is not None]
    init_deps: dict[int, list[int]] = {}
    for o, d, p in zip(model.outputs, model.output_deps, model.output_param_deps):
        init_deps[o.variable.vr] = run_time(d) + params(p)
    for v, d, p in zip(derivs, model.derivative_deps, model.derivative_param_deps):
        init_deps[v.vr] = run_time(d) + params(p)
    for vr, p in model.calculated_deps.items():
        init_deps[vr] = params(p)
    initial = sorted(
        value_reference(model, v) for v in exposed
        if v.causality == "calculatedParameter" or (v.initial == "calculated" and v.causality in ("output", "local"))
    )
    caps = 'canGetAndSetFMUState="true" canSerializeFMUState="true" providesDirectionalDerivatives="true"'
    ident = model.identifier
    lines = [
        '<?xml version="1.0" encoding="UTF-8"?>',
        "<fmiModelDescription",
        '  fmiVersion="3.0"',
        f"  modelName={quoteattr(ident)}",
        f'  instantiationToken="{guid}"',
        f"  description={quoteattr(model.description or model.kind)}",
        f'  generationTool="pris_cosim {__version__}"',
        '  variableNamingConvention="flat">',
        f'  <ModelExchange modelIdentifier="{ident}" {caps}/>',
        f'  <CoSimulation modelIdentifier="{ident}" canHandleVariableCommunicationStepSize="true" {caps} '
        'hasEventMode="false"/>',
        units_xml,
        "  <LogCategories>",
        '    <Category name="logStatusError" description="errors, e.g. rejected parameter values"/>',
        '    <Category name="logAll" description="progress messages"/>',
        "  </LogCategories>",
    ]
    if model.experiment is not None:
        stop, step = model.experiment
        lines.append(f'  <DefaultExperiment startTime="0.0" stopTime="{_fmt(stop)}" stepSize="{_fmt(step)}"/>')
    lines += [
        "  <ModelVariables>",
        f'    <Float64 name="time" valueReference="{time_reference(model)}" causality="independent" '
        'variability="continuous" description="simulation time, s"/>',
        *[_variable_xml(model, v) for v in exposed],
        "  </ModelVariables>",
        "  <ModelStructure>",
        *[unknown("Output", o.variable.vr, run_time(d)) for o, d in zip(model.outputs, model.output_deps)],
        *[unknown("ContinuousStateDerivative", v.vr, run_time(d)) for v, d in zip(derivs, model.derivative_deps)],
        *[unknown("InitialUnknown", vr, init_deps[vr]) for vr in initial],
        "  </ModelStructure>",
        "</fmiModelDescription>",
        "",
    ]
    return "\n".join(lines)


def build_description3(model: NetworkModel) -> str:
    """``sources/buildDescription.xml`` of the FMI 3.0 FMU (links the C math library)."""
    files = "\n".join(f'      <SourceFile name="{f}"/>' for f in c_source_files(3))
    return (
        '<?xml version="1.0" encoding="UTF-8"?>\n'
        '<fmiBuildDescription fmiVersion="3.0">\n'
        f'  <BuildConfiguration modelIdentifier="{model.identifier}">\n'
        '    <SourceFileSet language="C99">\n'
        f"{files}\n"
        f'      <PreprocessorDefinition name="{FMI3_DEFINE}" value="1" '
        'description="the FMI 2.0 layer under internal names, below the FMI 3.0 one"/>\n'
        "    </SourceFileSet>\n"
        '    <Library name="m" description="C math library"/>\n'
        "  </BuildConfiguration>\n"
        "</fmiBuildDescription>\n"
    )
