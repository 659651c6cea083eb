"""Build FMI 2.0 and 3.0 FMUs (Co-Simulation and Model Exchange in one) from circuit descriptions.

An FMU is assembled from a :class:`~pris_cosim.fmi.codegen.NetworkModel`: the
generated ``model.c`` plus the C runtime go into ``sources/`` (listed in the
model description, so that any tool can rebuild the binary; the binary links
the C math library explicitly), ``modelDescription.xml`` is written here, and the
binary is compiled with fmpy's CMake project (``fmpy/c-code``, configured by
:func:`fmpy.build.create_cmake_settings`). Builds are cached by content hash
in :func:`cache_dir`: the same network with the same start values is compiled
once. A Modelica text of the network (``NAME.mo``) is written next to each FMU.
"""

from __future__ import annotations

import dataclasses
import hashlib
import os
import shutil
import subprocess
import tempfile
import uuid
import zipfile
from collections.abc import Sequence
from pathlib import Path
from xml.sax.saxutils import quoteattr

from pris_cosim import __version__
from pris_cosim.circuits.arrangement import SourceSettings
from pris_cosim.circuits.circuit import Circuit
from pris_cosim.fmi.codegen import (NetworkModel, Variable, arrangement_model, c_source_files, bridge_model,
    dut_model, generate_sources, load_model, source_model)

#: SI base-unit exponents of the units the FMUs use (kg, m, s, A).
_BASE_UNITS: dict[str, dict[str, int]] = {
    "V": {"kg": 1, "m": 2, "s": -3, "A": -1},
    "A": {"A": 1},
    "Ohm": {"kg": 1, "m": 2, "s": -3, "A": -2},
    "H": {"kg": 1, "m": 2, "s": -2, "A": -2},
    "F": {"kg": -1, "m": -2, "s": 4, "A": 2},
    "Hz": {"s": -1},
    "V/s": {"kg": 1, "m": 2, "s": -4, "A": -1},
    "A/s": {"s": -1, "A": 1},
    "1": {},
}

BUILD_DESCRIPTION = "buildDescription.xml"


class FmuBuildError(OSError):
    """CMake or the C compiler failed; the message ends with the compiler's last lines."""


def cache_dir() -> Path:
    """Directory of cached FMU builds: ``$PRIS_COSIM_FMU_CACHE`` or ``~/.cache/pris_cosim/fmus``."""
    env = os.environ.get("PRIS_COSIM_FMU_CACHE")
    return Path(env) if env else Path.home() / ".cache" / "pris_cosim" / "fmus"


# ---------------------------------------------------------------------- model description
def _fmt(x: float) -> str:
    return repr(float(x))


def _variable_xml(v: Variable, index_of: dict[tuple[str, int], int]) -> str:
    attrs = [f"name={quoteattr(v.name)}", f'valueReference="{v.vr}"']
    if v.description:
        attrs.append(f"description={quoteattr(v.description)}")
    attrs += [f'causality="{v.causality}"', f'variability="{v.variability}"']
    if v.initial is not None:
        attrs.append(f'initial="{v.initial}"')
    inner = []
    if v.unit:
        inner.append(f"unit={quoteattr(v.unit)}")
    for attr in ("min", "max", "nominal"):
        x = getattr(v, attr)
        if x is not None:
            inner.append(f'{attr}="{_fmt(x) if v.type == "Real" else int(x)}"')
    if v.start is not None:
        inner.append(f'start="{_fmt(v.start) if v.type == "Real" else int(v.start)}"')
    if v.derivative_of is not None:
        inner.append(f'derivative="{index_of[("Real", v.derivative_of)]}"')
    body = f"<{v.type}{''.join(' ' + a for a in inner)}/>"
    return f"    <ScalarVariable {' '.join(attrs)}>\n      {body}\n    </ScalarVariable>"


def _unit_xml(units: Sequence[str]) -> str:
    rows = []
    for u in units:
        exps = _BASE_UNITS.get(u)
        if exps:
            base = " ".join(f'{k}="{e}"' for k, e in exps.items())
            rows.append(f"    <Unit name={quoteattr(u)}>\n      <BaseUnit {base}/>\n    </Unit>")
        else:
            rows.append(f"    <Unit name={quoteattr(u)}/>")
    return "  <UnitDefinitions>\n" + "\n".join(rows) + "\n  </UnitDefinitions>"


def model_description(model: NetworkModel, guid: str) -> str:
    """``modelDescription.xml`` (FMI 2.0, Model Exchange and Co-Simulation).

    Parameters
    ----------
    model : NetworkModel
    guid : str

    Returns
    -------
    str
        XML text.
    """
    exposed = [v for v in model.real if v.exposed] + [v for v in model.integer if v.exposed]
    index_of = {(v.type, v.vr): i + 1 for i, v in enumerate(exposed)}
    sources = "\n".join(f'      <File name="{f}"/>' for f in c_source_files())
    ident = model.identifier
    units = sorted({v.unit for v in exposed if v.unit})
    state_index = [index_of[("Real", v.vr)] for v in model.real
                   if v.nominal is not None and v.causality == "local" and v.derivative_of is None]
    inputs = [index_of[("Real", v.vr)] for v in model.real if v.causality == "input"]

    def unknown(i: int, idx: list[int]) -> str:
        idx = sorted(set(idx))
        if not idx:
            return f'      <Unknown index="{i}" dependencies=""/>'
        kinds = " ".join(["dependent"] * len(idx))
        return f'      <Unknown index="{i}" dependencies="{" ".join(map(str, idx))}" dependenciesKind="{kinds}"/>'

    def run_time(deps: tuple[list[int], bool]) -> list[int]:
        states, feedthrough = deps
        return [state_index[k] for k in states] + (inputs if feedthrough else [])

    def params(variables: list[Variable]) -> list[int]:
        return [index_of[(v.type, v.vr)] for v in variables]

    derivs = [v for v in model.real if v.derivative_of is not None]
    outputs = [unknown(index_of[("Real", o.variable.vr)], run_time(d)) for o, d in zip(model.outputs, model.output_deps)]
    derivatives = [unknown(index_of[("Real", v.vr)], run_time(d)) for v, d in zip(derivs, model.derivative_deps)]
    # initialization: the knowns are the input, the states (initial="exact") and the parameters
    init_deps: dict[int, list[int]] = {}
    for o, d, p in zip(model.outputs, model.output_deps, model.output_param_deps):
        init_deps[index_of[("Real", o.variable.vr)]] = run_time(d) + params(p)
    for v, d, p in zip(derivs, model.derivative_deps, model.derivative_param_deps):
        init_deps[index_of[("Real", v.vr)]] = run_time(d) + params(p)
    for vr, p in model.calculated_deps.items():
        init_deps[index_of[("Real", vr)]] = params(p)
    initial = sorted(
        index_of[(v.type, v.vr)] for v in exposed
        if v.causality == "calculatedParameter" or (v.initial == "calculated" and v.causality in ("output", "local"))
    )
    experiment = ""
    if model.experiment is not None:
        stop, step = model.experiment
        experiment = f'  <DefaultExperiment startTime="0.0" stopTime="{_fmt(stop)}" stepSize="{_fmt(step)}"/>\n'
    desc = model.description or model.kind
    lines = [
        '<?xml version="1.0" encoding="UTF-8"?>',
        "<fmiModelDescription",
        '  fmiVersion="2.0"',
        f"  modelName={quoteattr(ident)}",
        f'  guid="{guid}"',
        f"  description={quoteattr(desc)}",
        f'  generationTool="pris_cosim {__version__}"',
        '  variableNamingConvention="flat"',
        '  numberOfEventIndicators="0">',
        f'  <ModelExchange modelIdentifier="{ident}" canGetAndSetFMUstate="true" '
        'canSerializeFMUstate="true" providesDirectionalDerivative="true" '
        'canNotUseMemoryManagementFunctions="false">',
        "    <SourceFiles>",
        sources,
        "    </SourceFiles>",
        "  </ModelExchange>",
        f'  <CoSimulation modelIdentifier="{ident}" canHandleVariableCommunicationStepSize="true" '
        'canInterpolateInputs="false" maxOutputDerivativeOrder="0" canRunAsynchronuously="false" '
        'canGetAndSetFMUstate="true" canSerializeFMUstate="true" providesDirectionalDerivative="true" '
        'canNotUseMemoryManagementFunctions="false">',
        "    <SourceFiles>",
        sources,
        "    </SourceFiles>",
        "  </CoSimulation>",
        _unit_xml(units),
        "  <LogCategories>",
        '    <Category name="logStatusError" description="errors, e.g. rejected parameter values"/>',
        '    <Category name="logAll" description="progress messages"/>',
        "  </LogCategories>",
        experiment.rstrip("\n"),
        "  <ModelVariables>",
        *[_variable_xml(v, index_of) for v in exposed],
        "  </ModelVariables>",
        "  <ModelStructure>",
        "    <Outputs>",
        *outputs,
        "    </Outputs>",
        *(["    <Derivatives>", *derivatives, "    </Derivatives>"] if derivatives else []),
        "    <InitialUnknowns>",
        *[unknown(i, init_deps[i]) for i in initial],
        "    </InitialUnknowns>",
        "  </ModelStructure>",
        "</fmiModelDescription>",
        "",
    ]
    return "\n".join(line for line in lines if line != "")


def _description(model: NetworkModel, guid: str, fmi_version: int) -> str:
    if fmi_version == 3:
        from pris_cosim.fmi.fmi3_xml import model_description3

        exposed = [v for v in model.real if v.exposed] + [v for v in model.integer if v.exposed]
        return model_description3(model, guid, _unit_xml(sorted({v.unit for v in exposed if v.unit})))
    return model_description(model, guid)


def render(model: NetworkModel, fmi_version: int = 2) -> dict[str, str]:
    """Every text file of the FMU (FMI 2.0 or 3.0) by archive path, with a GUID derived from the content."""
    if fmi_version not in (2, 3):
        raise ValueError(f"FMI version must be 2 or 3 (got {fmi_version!r})")
    probe = generate_sources(model, "GUID", fmi_version) | {"modelDescription.xml": _description(model, "GUID",
                                                                                                 fmi_version)}
    digest = hashlib.sha256("\0".join(f"{k}\0{v}" for k, v in sorted(probe.items())).encode()).digest()
    guid = "{" + str(uuid.UUID(bytes=digest[:16], version=4)) + "}"
    files = {f"sources/{k}": v for k, v in generate_sources(model, guid, fmi_version).items()}
    files["modelDescription.xml"] = _description(model, guid, fmi_version)
    if fmi_version == 3:
        from pris_cosim.fmi.fmi3_xml import build_description3

        files[f"sources/{BUILD_DESCRIPTION}"] = build_description3(model)
    return files


# ---------------------------------------------------------------------- compiling
def compile_binary(unzipdir: str | os.PathLike[str], build_dir: str | os.PathLike[str] | None = None) -> None:
    """Compile the sources of an extracted FMU into ``binaries/<platform>/`` with fmpy's CMake project.

    Parameters
    ----------
    unzipdir : path
        Directory holding ``modelDescription.xml`` and ``sources/``.
    build_dir : path, optional
        CMake build directory (a temporary one by default).

    Raises
    ------
    FmuBuildError
        CMake or the compiler failed (message names the FMU and shows the last output lines).
    """
    import fmpy
    from fmpy.build import create_cmake_settings

    source_dir = Path(fmpy.__file__).parent / "c-code"
    with tempfile.TemporaryDirectory(prefix="pris-fmu-build-") as tmp:
        bdir = Path(build_dir) if build_dir else Path(tmp)
        bdir.mkdir(parents=True, exist_ok=True)
        # the runtime calls sqrt, log2, fmax, ldexp: link the C math library explicitly (a loader
        # that opens the binary with RTLD_LOCAL in a process without libm needs it)
        create_cmake_settings(unzipdir, bdir, cmake_options={"CMAKE_C_STANDARD_LIBRARIES:STRING": "-lm"})
        for cmd in (["cmake", "-S", str(source_dir), "-B", str(bdir)],
                    ["cmake", "--build", str(bdir), "--target", "install", "--config", "Release"]):
            try:
                proc = subprocess.run(cmd, capture_output=True, text=True)
            except FileNotFoundError:
                raise FmuBuildError("cmake is not installed (apt-get install cmake)") from None
            if proc.returncode:
                tail = " | ".join((proc.stdout + proc.stderr).strip().splitlines()[-6:])
                raise FmuBuildError(f"building FMU in {unzipdir} failed ({' '.join(cmd[:2])}): {tail}")


def _write_zip(src: Path, target: Path) -> None:
    tmp = target.with_name(f".{target.name}.{os.getpid()}.tmp")
    with zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as zf:
        for path in sorted(p for p in src.rglob("*") if p.is_file()):
            zf.write(path, path.relative_to(src).as_posix())
    os.replace(tmp, target)


def build_fmu(model: NetworkModel, out_dir: str | os.PathLike[str], *, use_cache: bool = True,
              write_modelica: bool = True, fmi_version: int = 2) -> Path:
    """Build (or fetch from the cache) the FMU of a network model.

    Parameters
    ----------
    model : NetworkModel
        From :func:`~pris_cosim.fmi.codegen.source_model`, :func:`~pris_cosim.fmi.codegen.dut_model`
        or :func:`~pris_cosim.fmi.codegen.arrangement_model`.
    out_dir : path
        Directory for ``<identifier>.fmu`` (and ``<identifier>.mo``).
    use_cache : bool
        Reuse a cached build of identical content.
    write_modelica : bool
        Also write the Modelica text of the network.
    fmi_version : {2, 3}
        FMI 2.0 or FMI 3.0 (Co-Simulation and Model Exchange either way).

    Returns
    -------
    pathlib.Path
        The FMU file.
    """
    import fmpy

    files = render(model, fmi_version)
    key = hashlib.sha256()
    for name in sorted(files):
        key.update(name.encode() + b"\0" + files[name].encode() + b"\0")
    key.update(f"fmpy {fmpy.__version__} {fmpy.platform_tuple}".encode())
    cache = cache_dir()
    cached = cache / f"{model.identifier}-{key.hexdigest()[:20]}.fmu"
    if not (use_cache and cached.is_file()):
        cache.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryDirectory(prefix="pris-fmu-") as tmp:
            root = Path(tmp) / "fmu"
            for name, text in files.items():
                path = root / name
                path.parent.mkdir(parents=True, exist_ok=True)
                path.write_text(text)
            compile_binary(root, Path(tmp) / "build")
            _write_zip(root, cached)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    target = out / f"{model.identifier}.fmu"
    tmp_target = target.with_name(f".{target.name}.{os.getpid()}.tmp")
    shutil.copyfile(cached, tmp_target)
    os.replace(tmp_target, target)
    if write_modelica:
        from pris_cosim.fmi.modelica import write_modelica as _write_mo

        _write_mo(model, out / f"{model.identifier}.mo")
    return target


def build_pris_fmus(
    dut: Circuit,
    port: str,
    out_dir: str | os.PathLike[str],
    settings: SourceSettings | None = None,
    shorts: Sequence[str] = (),
    name: str = "dut",
    experiment: tuple[float, float] | None = None,
    dut_experiment: tuple[float, float] | None = None,
    fmi_version: int = 2,
    bridge_split: bool = False,
) -> dict[str, Path]:
    """Build the DUT FMU, and with source settings also the source and monolithic FMUs.

    Parameters
    ----------
    dut : Circuit
    port : str
        Driven DUT node.
    out_dir : path
    settings : SourceSettings, optional
        PRIS source; None builds the DUT FMU only.
    shorts : sequence of str
        DUT nodes tied to ground (test configuration).
    name : str
        Base name of the FMUs (``NAME_dut``, ``NAME_source``, ``NAME_pris``).
    experiment : tuple of float, optional
        ``(stop_time, step_size)`` in s of the source and arrangement FMUs'
        default experiment (default: one PRBS period at 100 steps per bit).
    dut_experiment : tuple of float, optional
        The DUT FMU's default experiment (default: ``experiment``, else from
        the network's fastest time constant).
    fmi_version : {2, 3}
        FMI 2.0 or FMI 3.0 FMUs.
    bridge_split : bool
        With source settings, also the H-bridge FMU (``NAME_bridge``) and
        the FMU of what it drives (``NAME_load``: series RLC and DUT).

    Returns
    -------
    dict
        ``{"dut": path[, "source": path, "arrangement": path[, "bridge": path, "load": path]]}``.

    Raises
    ------
    NonPassiveError
        The DUT's inductance matrix is not positive definite.
    """
    def timed(model: NetworkModel, exp: tuple[float, float] | None) -> NetworkModel:
        return model if exp is None else dataclasses.replace(model, experiment=(float(exp[0]), float(exp[1])))

    dut_exp = dut_experiment or experiment
    v = fmi_version
    out = {"dut": build_fmu(timed(dut_model(dut, port, shorts, name=f"{name}_dut"), dut_exp), out_dir, fmi_version=v)}
    if settings is not None:
        out["source"] = build_fmu(timed(source_model(settings, name=f"{name}_source"), experiment), out_dir,
                                  fmi_version=v)
        out["arrangement"] = build_fmu(
            timed(arrangement_model(dut, port, settings, shorts, name=f"{name}_pris"), experiment), out_dir,
            fmi_version=v)
        if bridge_split:
            out["bridge"] = build_fmu(timed(bridge_model(settings, name=f"{name}_bridge"), experiment), out_dir,
                                      fmi_version=v)
            out["load"] = build_fmu(timed(load_model(dut, port, settings, shorts, name=f"{name}_load"), experiment),
                                    out_dir, fmi_version=v)
    return out
