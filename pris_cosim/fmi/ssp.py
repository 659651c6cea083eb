"""SSP 1.0 export of the PRIS arrangement as a system of two FMUs.

An ``.ssp`` file is a zip archive (SSP 1.0, *System Structure and
Parameterization*) that co-simulation tools open as one system:

``SystemStructure.ssd``
    The system: two components (each an FMU under ``resources/``), their
    input and output connectors with units, the connections, one parameter
    binding per component, the default experiment (start, stop, and the
    communication step in the ``com.opensimulationplatform`` annotation that
    libcosim reads), and in its descriptions which master step gives which
    accuracy.
``resources/<fmu>.fmu``
    The FMUs as built.
``resources/<fmu>.ssv``
    Every parameter of the FMU with its value (SSP parameter values), in one
    parameter set named :data:`PARAMETER_SET` in every file.

Two ways to cut the arrangement (:data:`SPLITS`):

``bridge`` (the default of ``build-fmu --ssp``)
    ``bridge`` (PRBS generator and H-bridge, output ``v_bprbs``) drives
    ``load`` (series RLC and winding, input ``v_bprbs``, outputs ``v_in``,
    ``i_in``). The one coupling signal is constant between PRBS clock
    instants, so a fixed-step master whose step divides the PRBS bit is
    exact.
``thesis``
    ``source`` (H-bridge and series RLC, input ``v_in``, output ``i_in``)
    and ``dut`` (the winding, input ``i_in``, output ``v_in``), the cut of
    the thesis. Each holds the other's output over a step: the coupling
    error grows with the step.

The parameter values default to the FMUs' start values; ``values`` replaces
some of them, so one archive can describe another operating point of the
same FMUs.
"""

from __future__ import annotations

import os
import zipfile
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING
from xml.sax.saxutils import quoteattr

from fmpy.model_description import read_model_description

from pris_cosim import __version__
from pris_cosim.errors import CircuitError

if TYPE_CHECKING:
    from pris_cosim.fmi.codegen import NetworkModel

SSD_NS = "http://ssp-standard.org/SSP1/SystemStructureDescription"
SSC_NS = "http://ssp-standard.org/SSP1/SystemStructureCommon"
SSV_NS = "http://ssp-standard.org/SSP1/SystemStructureParameterValues"
OSP_NS = "http://opensimulationplatform.com/SSP/OSPAnnotations"
SSD_NAME = "SystemStructure.ssd"
#: Connections of the thesis split: (start component, output) -> (end component, input).
CONNECTIONS = (("source", "i_in", "dut", "i_in"), ("dut", "v_in", "source", "v_in"))
#: Connection of the bridge split.
BRIDGE_CONNECTIONS = (("bridge", "v_bprbs", "load", "v_bprbs"),)
#: Name of the parameter set of every ``.ssv`` file (one name, so that a master applying one set by name,
#: such as ecos, applies it to every component).
PARAMETER_SET = "initialValues"


@dataclass(frozen=True)
class Split:
    """One way to cut the PRIS arrangement into two FMUs.

    Attributes
    ----------
    name : str
    components : (str, str)
        Component names of the driving and the driven FMU.
    connections : tuple of (str, str, str, str)
        ``(start component, output, end component, input)``.
    description : str
        What the system holds (the SSD's description starts with it).
    """

    name: str
    components: tuple[str, str]
    connections: tuple[tuple[str, str, str, str], ...]
    description: str


#: The two splits by name.
SPLITS: dict[str, Split] = {
    "bridge": Split("bridge", ("bridge", "load"), BRIDGE_CONNECTIONS,
                    "PRIS arrangement cut at the H-bridge voltage: the bridge FMU (PRBS generator and H-bridge) "
                    "drives the load FMU (series RLC and winding) through v_bprbs alone"),
    "thesis": Split("thesis", ("source", "dut"), CONNECTIONS,
                    "PRIS arrangement cut at the winding terminal (the thesis's cut): the source FMU (H-bridge and "
                    "series RLC) gives the terminal current i_in to the DUT FMU, which returns the terminal "
                    "voltage v_in"),
}


def fastest_period(model: NetworkModel) -> float | None:
    """Period in s of the fastest oscillatory mode of a network model at its start values (None if none oscillates).

    Parameters
    ----------
    model : NetworkModel
        Usually the monolithic arrangement (:func:`pris_cosim.fmi.codegen.arrangement_model`).
    """
    import numpy as np

    lam = np.linalg.eigvals(model.mna.state_space(model.circuit.resolve()).A[0])
    w = float(np.abs(lam.imag).max(initial=0.0))
    return 2 * np.pi / w if w > 0 else None


def step_guidance(split: str, step: float, fclk: float, fastest_period: float | None = None) -> str:
    """Which communication step a fixed-step master needs with this split, as a sentence for the archive.

    Parameters
    ----------
    split : {"bridge", "thesis"}
    step : float, s
        The default experiment's step.
    fclk : float, Hz
        PRBS clock (its bit 1/fclk is the coupling signal's hold time in the bridge split).
    fastest_period : float, s, optional
        Period of the arrangement's fastest oscillatory mode (thesis split).

    Returns
    -------
    str
    """
    bit = 1.0 / float(fclk)
    per_bit = bit / step
    divides = abs(per_bit - round(per_bit)) <= 1e-9 * per_bit
    if split == "bridge":
        where = (f"the default step {step:.6g} s divides it ({round(per_bit)} steps per bit)" if divides
                 else f"the default step {step:.6g} s does not divide it: choose one that does")
        return (f"Step guidance: the coupling signal v_bprbs is constant over each PRBS bit ({bit:.6g} s), and "
                "the bridge FMU gives the new level at a clock instant that ends a step, so a fixed-step master "
                "(Jacobi or Gauss-Seidel) is exact at any step that divides the bit; " + where + ".")
    if split == "thesis":
        fast = ""
        if fastest_period:
            fast = (f" The fastest mode of this arrangement has a period of {fastest_period:.3g} s, so a Jacobi "
                    f"master needs steps near {fastest_period / 1000:.2g} s for 1 %.")
        return ("Step guidance: fixed-step masters hold v_in and i_in over a communication step, which shifts the "
                "resonances of the coupled system; the error grows with the step. On the thesis cases a Jacobi "
                "master (libcosim, ecos, fmpy.ssp) needed a step near a thousandth of the arrangement's fastest "
                "period for 1 % RMS on v_in and i_in, and gave errors of 20 % to 290 % at the thesis sampling "
                f"interval (the default step here, {step:.6g} s)." + fast + " For accuracy at the sampling "
                "interval use the bridge split (build-fmu --ssp --split bridge) or the exact master "
                "(simulate --engine cosim).")
    raise CircuitError(f"SSP export: unknown split {split!r} (choose {', '.join(SPLITS)})")

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
                         experiment: tuple[float, float], description: str = "",
                         connections: Sequence[tuple[str, str, str, str]] = CONNECTIONS,
                         system_description: str = "PRIS source FMU driving a DUT FMU") -> str:
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
        Description of the whole file (``ssd:SystemStructureDescription``).
    connections : sequence of (str, str, str, str)
        ``(start component, output, end component, input)``.
    system_description : str
        Description of the ``ssd:System``.
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
                   for a, x, b, y in connections]
    units = [f'    <ssc:Unit name="{u}">\n      <ssc:BaseUnit {exps}/>\n    </ssc:Unit>' for u, exps in _BASE_UNITS.items()]
    lines = [
        '<?xml version="1.0" encoding="UTF-8"?>',
        f'<ssd:SystemStructureDescription xmlns:ssd="{SSD_NS}" xmlns:ssc="{SSC_NS}" xmlns:ssv="{SSV_NS}"',
        f'    xmlns:osp="{OSP_NS}" version="1.0" name={quoteattr(name)}'
        + (f" description={quoteattr(description)}" if description else "")
        + f' generationTool="pris_cosim {__version__}">',
        f"  <ssd:System name={quoteattr(name)} description={quoteattr(system_description)}>",
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


def detect_split(first_fmu: str | os.PathLike[str]) -> str:
    """The split a driving FMU belongs to: ``bridge`` (no inputs, output ``v_bprbs``), else ``thesis``."""
    _, variables = _variables(Path(first_fmu))
    causes = {v.name: v.causality for v in variables}
    return "bridge" if causes.get("v_bprbs") == "output" and "input" not in causes.values() else "thesis"


def write_ssp(
    source_fmu: str | os.PathLike[str],
    dut_fmu: str | os.PathLike[str],
    out: str | os.PathLike[str],
    name: str | None = None,
    experiment: tuple[float, float] | None = None,
    source_values: Mapping[str, float] | None = None,
    dut_values: Mapping[str, float] | None = None,
    split: str | None = None,
    guidance: str | None = None,
) -> Path:
    """Write the SSP 1.0 archive of a driving FMU coupled to a driven FMU.

    Parameters
    ----------
    source_fmu, dut_fmu : path
        The driving and the driven FMU: the H-bridge and load FMUs of the
        bridge split, or the source and DUT FMUs of the thesis split (from
        :func:`pris_cosim.fmi.build.build_pris_fmus`).
    out : path
        The ``.ssp`` file to write.
    name : str, optional
        System name (default: the file's stem).
    experiment : (float, float), optional
        ``(stop_time, step_size)`` in s (default: the driving FMU's default
        experiment).
    source_values, dut_values : mapping, optional
        Parameter values replacing the FMUs' start values in the ``.ssv`` files.
    split : {"bridge", "thesis"}, optional
        Which split the FMUs form (default: :func:`detect_split` of ``source_fmu``).
    guidance : str, optional
        Step guidance appended to the SSD's descriptions (default:
        :func:`step_guidance` without the fastest period).

    Returns
    -------
    pathlib.Path
        The archive.

    Raises
    ------
    CircuitError
        An FMU lacks the connector the split needs, a value names no
        parameter, or no default experiment is known.
    """
    source_fmu, dut_fmu, out = Path(source_fmu), Path(dut_fmu), Path(out)
    cut = SPLITS.get(split or detect_split(source_fmu))
    if cut is None:
        raise CircuitError(f"SSP export: unknown split {split!r} (choose {', '.join(SPLITS)})")
    first, second = cut.components
    comps = {}
    texts: dict[str, str] = {}
    md_source = None
    fclk = None
    for comp, fmu, values in ((first, source_fmu, source_values), (second, dut_fmu, dut_values)):
        md, variables = _variables(fmu)
        if comp == first:
            md_source = md
        names = {v.name: v.causality for v in variables}
        for a, x, b, y in cut.connections:
            if a == comp and names.get(x) != "output":
                raise CircuitError(f"SSP export: {fmu.name} has no output {x!r} (is it the {comp} FMU?)")
            if b == comp and names.get(y) != "input":
                raise CircuitError(f"SSP export: {fmu.name} has no input {y!r} (is it the {comp} FMU?)")
        ssv = f"resources/{fmu.stem}.ssv"
        params = _parameters(variables, values or {})
        fclk = params.get("fclk", fclk)
        texts[ssv] = parameter_set_xml(PARAMETER_SET, params)
        comps[comp] = (f"resources/{fmu.name}", ssv, variables)
    if experiment is None:
        exp = md_source.defaultExperiment if md_source is not None else None
        if exp is None or exp.stopTime is None or exp.stepSize is None:
            raise CircuitError(f"SSP export: {source_fmu.name} has no default experiment; give one")
        experiment = (float(exp.stopTime), float(exp.stepSize))
    stop, step = (float(x) for x in experiment)
    if not (stop > 0 and 0 < step <= stop):
        raise CircuitError(f"SSP export: experiment needs 0 < step <= stop (got stop {stop!r}, step {step!r})")
    if guidance is None and fclk:
        guidance = step_guidance(cut.name, step, float(fclk))
    system = name or out.stem
    text = cut.description + (f". {guidance}" if guidance else ".")
    texts[SSD_NAME] = system_structure_xml(system, comps, (stop, step), description=text,
                                           connections=cut.connections, system_description=text)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(f".{out.name}.{os.getpid()}.tmp")
    entries: list[tuple[str, bytes]] = [(SSD_NAME, texts.pop(SSD_NAME).encode("utf-8"))]
    entries += [(comps[comp][0], fmu.read_bytes()) for comp, fmu in ((first, source_fmu), (second, dut_fmu))]
    entries += [(path, text.encode("utf-8")) for path, text in sorted(texts.items())]
    with zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as zf:
        for path, data in entries:  # fixed timestamps: the same FMUs give the same archive
            info = zipfile.ZipInfo(path, date_time=(1980, 1, 1, 0, 0, 0))
            info.compress_type = zipfile.ZIP_DEFLATED
            info.external_attr = 0o644 << 16
            zf.writestr(info, data)
    os.replace(tmp, out)
    return out


def components(path: str | os.PathLike[str]) -> list[str]:
    """Component names of a system (``.ssp`` archive or ``.ssd`` file), in the order written."""
    from xml.etree import ElementTree

    root = ElementTree.fromstring(read_ssd(path))
    return [c.get("name") for c in root.iter(f"{{{SSD_NS}}}Component")]


def recorded_outputs(path: str | os.PathLike[str]) -> list[tuple[str, str]]:
    """``(component, variable)`` of the terminal voltage and current and the bridge voltage of a system.

    Raises
    ------
    CircuitError
        The system's components are neither those of the bridge nor of the thesis split.
    """
    comps = set(components(path))
    if comps == set(SPLITS["bridge"].components):
        return [("load", "v_in"), ("load", "i_in"), ("bridge", "v_bprbs")]
    if comps == set(SPLITS["thesis"].components):
        return [("dut", "v_in"), ("source", "i_in"), ("source", "v_bprbs")]
    raise CircuitError(f"{Path(path).name}: components {sorted(comps)} are neither "
                       + " nor ".join(f"{sorted(c.components)}" for c in SPLITS.values()))


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
