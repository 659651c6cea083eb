"""SSP 1.0 export of the PRIS arrangement: the source FMU and the DUT FMU wired together.

An ``.ssp`` file is a zip archive (SSP 1.0, *System Structure and
Parameterization*) that co-simulation tools open as one system:

``SystemStructure.ssd``
    The system: two components (``source`` and ``dut``, each an FMU under
    ``resources/``), their input and output connectors with units, the two
    connections ``source.i_in -> dut.i_in`` and ``dut.v_in -> source.v_in``,
    one parameter binding per component, and the default experiment (start,
    stop, and the communication step in the ``com.opensimulationplatform``
    annotation that libcosim reads).
``resources/<fmu>.fmu``
    The FMUs as built.
``resources/<fmu>.ssv``
    Every parameter of the FMU with its value (SSP parameter values).

The parameter values default to the FMUs' start values; ``values`` replaces
some of them, so one archive can describe another operating point of the
same FMUs.
"""

from __future__ import annotations

import os
import zipfile
from collections.abc import Mapping
from pathlib import Path
from xml.sax.saxutils import quoteattr

from fmpy.model_description import read_model_description

from pris_cosim import __version__
from pris_cosim.errors import CircuitError

SSD_NS = "http://ssp-standard.org/SSP1/SystemStructureDescription"
SSC_NS = "http://ssp-standard.org/SSP1/SystemStructureCommon"
SSV_NS = "http://ssp-standard.org/SSP1/SystemStructureParameterValues"
OSP_NS = "http://opensimulationplatform.com/SSP/OSPAnnotations"
SSD_NAME = "SystemStructure.ssd"
#: Connections of the PRIS arrangement: (start component, output) -> (end component, input).
CONNECTIONS = (("source", "i_in", "dut", "i_in"), ("dut", "v_in", "source", "v_in"))

#: SI base-unit exponents of the connector units.
_BASE_UNITS = {"V": 'kg="1" m="2" s="-3" A="-1"', "A": 'A="1"'}


def _num(x: float) -> str:
    return repr(float(x))


def _variables(fmu: Path) -> tuple[object, list]:
    md = read_model_description(str(fmu), validate=False)
    return md, list(md.modelVariables)


def parameter_set_xml(name: str, values: Mapping[str, float | int]) -> str:
    """An SSP 1.0 parameter values file (``.ssv``): ``ssv:ParameterSet`` with one ``ssv:Parameter`` per value.

    Integers (``int``) are written as ``ssv:Integer``, everything else as ``ssv:Real``.
    """
    rows = []
    for key, value in values.items():
        typed = (f'<ssv:Integer value="{int(value)}"/>' if isinstance(value, int) and not isinstance(value, bool)
                 else f'<ssv:Real value="{_num(value)}"/>')
        rows.append(f"    <ssv:Parameter name={quoteattr(key)}>\n      {typed}\n    </ssv:Parameter>")
    return (
        '<?xml version="1.0" encoding="UTF-8"?>\n'
        f'<ssv:ParameterSet xmlns:ssv="{SSV_NS}" version="1.0" name={quoteattr(name)}>\n'
        "  <ssv:Parameters>\n" + "\n".join(rows) + "\n  </ssv:Parameters>\n"
        "</ssv:ParameterSet>\n"
    )


def _parameters(variables: list, overrides: Mapping[str, float]) -> dict[str, float | int]:
    params = [v for v in variables if v.causality == "parameter"]
    known = {v.name for v in params}
    unknown = sorted(set(overrides) - known)
    if unknown:
        raise CircuitError(f"SSP export: no parameter named {unknown[0]!r} in the FMU")
    out: dict[str, float | int] = {}
    for v in params:
        value = overrides.get(v.name, v.start)
        out[v.name] = int(value) if v.type == "Integer" else float(value)
    return out


def _connectors(variables: list) -> list[str]:
    rows = []
    for v in variables:
        if v.causality not in ("input", "output"):
            continue
        unit = f" unit={quoteattr(v.unit)}" if v.unit in _BASE_UNITS else ""
        desc = f" description={quoteattr(v.description)}" if v.description else ""
        rows.append(f'          <ssd:Connector name={quoteattr(v.name)} kind="{v.causality}"{desc}>\n'
                    f"            <ssc:Real{unit}/>\n          </ssd:Connector>")
    return rows


def system_structure_xml(name: str, components: Mapping[str, tuple[str, str, list]],
                         experiment: tuple[float, float], description: str = "") -> str:
    """``SystemStructure.ssd`` text.

    Parameters
    ----------
    name : str
        System name.
    components : mapping
        Component name to ``(fmu resource path, ssv resource path, model variables)``.
    experiment : (float, float)
        ``(stop_time, step_size)`` in s.
    description : str
    """
    stop, step = experiment
    elements = []
    for comp, (fmu, ssv, variables) in components.items():
        elements += [
            f'      <ssd:Component name={quoteattr(comp)} type="application/x-fmu-sharedlibrary" '
            f'source={quoteattr(fmu)} implementation="CoSimulation">',
            "        <ssd:Connectors>",
            *_connectors(variables),
            "        </ssd:Connectors>",
            "        <ssd:ParameterBindings>",
            f'          <ssd:ParameterBinding type="application/x-ssp-parameter-set" source={quoteattr(ssv)}/>',
            "        </ssd:ParameterBindings>",
            "      </ssd:Component>",
        ]
    connections = [f'      <ssd:Connection startElement="{a}" startConnector="{x}" endElement="{b}" endConnector="{y}"/>'
                   for a, x, b, y in CONNECTIONS]
    units = [f'    <ssc:Unit name="{u}">\n      <ssc:BaseUnit {exps}/>\n    </ssc:Unit>' for u, exps in _BASE_UNITS.items()]
    lines = [
        '<?xml version="1.0" encoding="UTF-8"?>',
        f'<ssd:SystemStructureDescription xmlns:ssd="{SSD_NS}" xmlns:ssc="{SSC_NS}" xmlns:ssv="{SSV_NS}"',
        f'    xmlns:osp="{OSP_NS}" version="1.0" name={quoteattr(name)}'
        + (f" description={quoteattr(description)}" if description else "")
        + f' generationTool="pris_cosim {__version__}">',
        f"  <ssd:System name={quoteattr(name)} description=\"PRIS source FMU driving a DUT FMU\">",
        "    <ssd:Elements>",
        *elements,
        "    </ssd:Elements>",
        "    <ssd:Connections>",
        *connections,
        "    </ssd:Connections>",
        "  </ssd:System>",
        "  <ssd:Units>",
        *units,
        "  </ssd:Units>",
        f'  <ssd:DefaultExperiment startTime="0.0" stopTime="{_num(stop)}">',
        "    <ssd:Annotations>",
        '      <ssc:Annotation type="com.opensimulationplatform">',
        "        <osp:Algorithm>",
        f'          <osp:FixedStepAlgorithm baseStepSize="{_num(step)}" stepSize="{_num(step)}"/>',
        "        </osp:Algorithm>",
        "      </ssc:Annotation>",
        "    </ssd:Annotations>",
        "  </ssd:DefaultExperiment>",
        "</ssd:SystemStructureDescription>",
        "",
    ]
    return "\n".join(lines)


def write_ssp(
    source_fmu: str | os.PathLike[str],
    dut_fmu: str | os.PathLike[str],
    out: str | os.PathLike[str],
    name: str | None = None,
    experiment: tuple[float, float] | None = None,
    source_values: Mapping[str, float] | None = None,
    dut_values: Mapping[str, float] | None = None,
) -> Path:
    """Write the SSP 1.0 archive of a source FMU coupled to a DUT FMU.

    Parameters
    ----------
    source_fmu, dut_fmu : path
        FMUs from :func:`pris_cosim.fmi.build.build_pris_fmus` (inputs ``v_in`` /
        ``i_in``, outputs ``i_in`` / ``v_in``).
    out : path
        The ``.ssp`` file to write.
    name : str, optional
        System name (default: the file's stem).
    experiment : (float, float), optional
        ``(stop_time, step_size)`` in s (default: the source FMU's default
        experiment).
    source_values, dut_values : mapping, optional
        Parameter values replacing the FMUs' start values in the ``.ssv`` files.

    Returns
    -------
    pathlib.Path
        The archive.

    Raises
    ------
    CircuitError
        An FMU lacks the connector the arrangement needs, a value names no
        parameter, or no default experiment is known.
    """
    source_fmu, dut_fmu, out = Path(source_fmu), Path(dut_fmu), Path(out)
    comps = {}
    texts: dict[str, str] = {}
    md_source = None
    for comp, fmu, values in (("source", source_fmu, source_values), ("dut", dut_fmu, dut_values)):
        md, variables = _variables(fmu)
        if comp == "source":
            md_source = md
        names = {v.name: v.causality for v in variables}
        for a, x, b, y in CONNECTIONS:
            if a == comp and names.get(x) != "output":
                raise CircuitError(f"SSP export: {fmu.name} has no output {x!r} (is it the {comp} FMU?)")
            if b == comp and names.get(y) != "input":
                raise CircuitError(f"SSP export: {fmu.name} has no input {y!r} (is it the {comp} FMU?)")
        ssv = f"resources/{fmu.stem}.ssv"
        texts[ssv] = parameter_set_xml(f"{fmu.stem}_parameters", _parameters(variables, values or {}))
        comps[comp] = (f"resources/{fmu.name}", ssv, variables)
    if experiment is None:
        exp = md_source.defaultExperiment if md_source is not None else None
        if exp is None or exp.stopTime is None or exp.stepSize is None:
            raise CircuitError(f"SSP export: {source_fmu.name} has no default experiment; give one")
        experiment = (float(exp.stopTime), float(exp.stepSize))
    stop, step = (float(x) for x in experiment)
    if not (stop > 0 and 0 < step <= stop):
        raise CircuitError(f"SSP export: experiment needs 0 < step <= stop (got stop {stop!r}, step {step!r})")
    system = name or out.stem
    texts[SSD_NAME] = system_structure_xml(system, comps, (stop, step),
                                           description="PRIS arrangement: source FMU and DUT FMU")
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(f".{out.name}.{os.getpid()}.tmp")
    entries: list[tuple[str, bytes]] = [(SSD_NAME, texts.pop(SSD_NAME).encode("utf-8"))]
    entries += [(comps[comp][0], fmu.read_bytes()) for comp, fmu in (("source", source_fmu), ("dut", dut_fmu))]
    entries += [(path, text.encode("utf-8")) for path, text in sorted(texts.items())]
    with zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as zf:
        for path, data in entries:  # fixed timestamps: the same FMUs give the same archive
            info = zipfile.ZipInfo(path, date_time=(1980, 1, 1, 0, 0, 0))
            info.compress_type = zipfile.ZIP_DEFLATED
            info.external_attr = 0o644 << 16
            zf.writestr(info, data)
    os.replace(tmp, out)
    return out


def read_ssd(path: str | os.PathLike[str]) -> str:
    """The ``SystemStructure.ssd`` text of an ``.ssp`` archive, or of an ``.ssd`` file itself."""
    path = Path(path)
    if zipfile.is_zipfile(path):
        with zipfile.ZipFile(path) as zf:
            if SSD_NAME not in zf.namelist():
                raise CircuitError(f"{path.name}: no {SSD_NAME} in the archive")
            return zf.read(SSD_NAME).decode("utf-8")
    return path.read_text(encoding="utf-8")


def default_experiment(path: str | os.PathLike[str]) -> tuple[float, float]:
    """``(stop_time, step_size)`` in s of a system written by :func:`write_ssp`.

    Raises
    ------
    CircuitError
        The system has no default experiment, stop time or fixed-step annotation.
    """
    from xml.etree import ElementTree

    root = ElementTree.fromstring(read_ssd(path))
    exp = root.find(f"{{{SSD_NS}}}DefaultExperiment")
    algo = None if exp is None else exp.find(f".//{{{OSP_NS}}}FixedStepAlgorithm")
    if exp is None or exp.get("stopTime") is None or algo is None:
        raise CircuitError(f"{Path(path).name}: no default experiment with stop time and fixed step")
    return float(exp.get("stopTime")), float(algo.get("baseStepSize") or algo.get("stepSize"))
