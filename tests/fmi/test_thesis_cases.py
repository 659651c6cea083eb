"""Each built-in model starts from its own thesis case: the table against the design notes, and the shipped FMUs."""

from __future__ import annotations

import re
import zipfile
from pathlib import Path
from xml.etree import ElementTree

import pytest

from pris_cosim.models.builtin import get_model, model_names
from pris_cosim.fmi.thesis_cases import CASES, HV_TERMINAL, LV_TERMINAL, THREE_SECTION, TWO_SECTION, case_for

ROOT = Path(__file__).parents[2]
#: The thesis's source settings, transcribed by hand as data (not generated from the code under test).
SETTINGS_MD = ROOT / "tests" / "data" / "thesis" / "pris_settings.md"
_PREFIX = {"": 1.0, "k": 1e3, "M": 1e6, "m": 1e-3, "u": 1e-6, "n": 1e-9}


def _quantities(cell: str) -> list[tuple[float, str]]:
    """Numbers with SI prefix and unit, in order: '31.8 kOhm, 2.53 H' -> [(31800.0, 'Ohm'), (2.53, 'H')]."""
    found = re.findall(r"(\d+(?:\.\d+)?)\s*(k|M|m|u|n)?(Ohm|Hz|MS/s|V|H|F|ms)\b", cell)
    out = []
    for number, prefix, unit in found:
        value = float(number) * _PREFIX[prefix or ""]
        if unit == "MS/s":
            value, unit = float(number) * 1e6, "Hz"
        if unit == "ms":
            value, unit = float(number) * 1e-3, "s"
        out.append((value, unit))
    return out


def _table() -> dict[str, list[str]]:
    text = SETTINGS_MD.read_text()
    section = text[text.index("## PRIS source"):]
    rows = {}
    for line in section.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) == 6 and "(" in cells[0]:
            rows[cells[0]] = cells[1:]
    return rows


@pytest.mark.parametrize("row, case", [("two-section (4.1.2)", TWO_SECTION), ("three-section (4.2.2)", THREE_SECTION),
                                       ("LV terminal (5.1.2)", LV_TERMINAL), ("HV terminal (5.1.3)", HV_TERMINAL)])
def test_cases_equal_the_thesis_settings_table(row, case):
    vdc, prbs, fclk, rlc, sampling = _table()[row]
    s = case.settings
    assert case.section in row
    assert _quantities(vdc)[0] == pytest.approx((s.vdc, "V"))
    assert _quantities(fclk)[0] == pytest.approx((s.fclk, "Hz"))
    parts = _quantities(rlc)
    assert parts[:3] == [pytest.approx((s.rpris, "Ohm")), pytest.approx((s.lpris, "H")), pytest.approx((s.cpris, "F"))]
    if "snubber" in rlc:
        assert parts[3:5] == [pytest.approx((s.rsnub, "Ohm")), pytest.approx((s.csnub, "F"))]
    else:
        assert s.rsnub == 0 and s.csnub == 0
    orders = [int(x) for x in re.findall(r"\b(\d+)\b", prbs)]
    if orders:
        assert s.prbs_order == orders[0]
    elif "as LV" in prbs:
        assert s.prbs_order == LV_TERMINAL.settings.prbs_order
    rates = [v for v, u in _quantities(sampling) if u == "Hz"]
    assert case.fs == pytest.approx(rates[0])
    lengths = [v for v, u in _quantities(sampling) if u == "s"]
    period = (2**s.prbs_order - 1) / s.fclk
    assert case.duration == pytest.approx(lengths[0] if lengths else period)


def test_every_builtin_model_has_its_case():
    for name in model_names():
        model = get_model(name.replace("-N", "-4"))
        for cfg in model.configurations.values():
            case = case_for(model.name, cfg.port)
            assert case in CASES.values()
            if model.name.startswith("hv-"):
                assert case is (HV_TERMINAL if cfg.port == "b1" else LV_TERMINAL)
    assert case_for("two-section") is TWO_SECTION
    assert case_for("cascade-7-open") is THREE_SECTION


def _start_values(fmu: Path) -> tuple[dict[str, float], dict[str, float]]:
    with zipfile.ZipFile(fmu) as zf:
        root = ElementTree.fromstring(zf.read("modelDescription.xml"))
    values = {}
    for sv in root.iter("ScalarVariable"):
        typed = next(iter(sv))
        if typed.get("start") is not None:
            values[sv.get("name")] = float(typed.get("start"))
    exp = root.find("DefaultExperiment")
    return values, {k: float(v) for k, v in exp.attrib.items()}


@pytest.mark.parametrize("folder, base, case", [("two-section", "two_section", TWO_SECTION),
                                                ("three-section", "three_section", THREE_SECTION)])
def test_shipped_fmus_and_modelica_start_from_their_case(folder, base, case):
    s = case.settings
    for kind in ("pris", "source"):
        fmu = ROOT / "fmus" / folder / f"{base}_{kind}.fmu"
        values, exp = _start_values(fmu)
        for name, want in (("vdc", s.vdc), ("fclk", s.fclk), ("prbs_order", s.prbs_order), ("Rpris", s.rpris),
                           ("Lpris", s.lpris), ("Cpris", s.cpris)):
            assert values[name] == pytest.approx(want, rel=1e-15), (fmu.name, name)
        assert exp["stopTime"] == pytest.approx(case.duration)
        _assert_whole_ns_step(exp, case)
        text = fmu.with_suffix(".mo").read_text()
        assert f"vdc = {float(s.vdc)!r}" in text and f"fclk = {float(s.fclk)!r}" in text
        assert f"prbs_order = {s.prbs_order}" in text
        assert f"StopTime = {float(case.duration)!r}" in text
    _, exp = _start_values(ROOT / "fmus" / folder / f"{base}_dut.fmu")
    _assert_whole_ns_step(exp, case)


def _assert_whole_ns_step(exp: dict[str, float], case) -> None:
    """The default step: whole nanoseconds, a divisor of the PRBS bit and of the record, at most 1/fs, within 15 %."""
    step_ns = exp["stepSize"] * 1e9
    assert step_ns == pytest.approx(round(step_ns), abs=1e-6)
    bit_ns = round(1e9 / case.settings.fclk)
    assert bit_ns % round(step_ns) == 0
    assert (exp["stopTime"] * 1e9 / round(step_ns)) == pytest.approx(round(exp["stopTime"] * 1e9 / round(step_ns)))
    assert 0.85 / case.fs <= exp["stepSize"] <= 1 / case.fs
