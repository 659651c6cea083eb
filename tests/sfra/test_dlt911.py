"""DL/T 911 relative factors and verdict, repeatability, FRA instrument CSV exports, and the SFRA report.

The expected factors are computed here by the standard's formula written out
in the test (plain sums, closed forms); the real data are the IPN sweeps
(pris_cosim/data/real/ipn_winding_interturn/, two healthy references and 16 shorts).
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from estimation.diagnosis.sfra.dlt911 import band_masks, dlt911_indices, relative_factor, verdict
from estimation.diagnosis.sfra.indices import band_indices
from estimation.diagnosis.sfra.repeatability import repeatability
from estimation.diagnosis.sfra.sweep import load_sweep
from pris_cosim.datafiles import REAL
from pris_cosim.measured.formats import MeasuredDataError
from pris_cosim.measured.fra_csv import RESPONSE, read_fra_csv

ROOT = Path(__file__).resolve().parents[2]
DATA = REAL / "ipn_winding_interturn"
REFERENCE = DATA / "reference_23072517.s2p"
REPEAT = DATA / "reference_2317.s2p"
SHORTS = sorted((DATA / "bolted").glob("*.s2p")) + sorted((DATA / "resistive").glob("*.s2p"))


def _standard_r(x: list[float], y: list[float]) -> float:
    """DL/T 911's R written out with plain sums (independent of the code under test)."""
    n = len(x)
    mx, my = sum(x) / n, sum(y) / n
    dx = sum((a - mx) ** 2 for a in x) / n
    dy = sum((b - my) ** 2 for b in y) / n
    cxy = sum((a - mx) * (b - my) for a, b in zip(x, y)) / n
    lr = cxy / math.sqrt(dx * dy)
    return 10.0 if 1.0 - lr < 1e-10 else -math.log10(1.0 - lr)


# ---------------------------------------------------------------------------
# the standard's formula on small curves
# ---------------------------------------------------------------------------


def test_factor_closed_form():
    # x = 0 1 2 3, y = 0 1 3 2: Cxy = 1, Dx = Dy = 5/4, LR = 0.8, R = -lg 0.2
    assert relative_factor([0, 1, 2, 3], [0, 1, 3, 2]) == pytest.approx(-math.log10(0.2), rel=1e-12)


@pytest.mark.parametrize("x, y", [
    ([-10.0, -20.0, -35.0, -30.0, -25.0], [-11.0, -19.0, -33.0, -31.0, -24.0]),
    ([-40.0, -52.5, -61.0, -48.0, -70.0, -66.0], [-41.0, -50.0, -64.0, -47.5, -69.0, -68.0]),
    ([-60.0, -55.0, -50.0], [-50.0, -55.0, -60.0]),  # anti-correlated: LR = -1, R = -lg 2
])
def test_factor_matches_the_standard_written_out(x, y):
    assert relative_factor(x, y) == pytest.approx(_standard_r(x, y), rel=1e-12, abs=1e-12)


def test_anticorrelated_curves_give_negative_factor():
    assert relative_factor([-60.0, -55.0, -50.0], [-50.0, -55.0, -60.0]) == pytest.approx(-math.log10(2.0))


def test_identical_and_offset_curves_clamp_at_10():
    x = [-30.0, -42.0, -55.0, -48.0, -61.0]
    assert relative_factor(x, x) == 10.0
    offset = [v + 6.0 for v in x]
    assert _standard_r(x, offset) == 10.0
    assert relative_factor(x, offset) == 10.0  # centred: a constant offset is no change of shape
    # the uncentred CC of the literature does see the offset: it is a different index
    assert band_indices(np.array(x), np.array(offset))["cc"] < 1.0 - 1e-4


def test_near_clamp_is_finite_below_10():
    x = np.array([-30.0, -42.0, -55.0, -48.0, -61.0])
    y = x + np.array([0.0, 1e-3, -1e-3, 0.0, 1e-3])
    r = relative_factor(x, y)
    assert r == pytest.approx(_standard_r(list(x), list(y)), rel=1e-9)
    assert 5.0 < r < 10.0


def test_too_few_points_or_flat_curve_give_none():
    assert relative_factor([1.0, 2.0], [1.0, 2.0]) is None
    assert relative_factor([-20.0, -20.0, -20.0], [-20.0, -21.0, -22.0]) is None


# ---------------------------------------------------------------------------
# verdict table
# ---------------------------------------------------------------------------


@pytest.mark.parametrize("r, expected", [
    ((0.59, 5, 5), "severe"),
    ((-0.2, 5, 5), "severe"),
    ((0.6, 5, 5), "obvious"),
    ((0.99, 5, 5), "obvious"),
    ((5, 0.59, 5), "obvious"),
    ((1.0, 5, 5), "slight"),
    ((1.99, 5, 5), "slight"),
    ((5, 0.6, 5), "slight"),
    ((5, 0.99, 5), "slight"),
    ((2.0, 1.0, 0.6), "normal"),
    ((10, 10, 10), "normal"),
    ((2.0, 1.0, 0.59), "slight"),  # the corner the table leaves open
    ((0.3, None, None), "severe"),  # decided by LF alone
    ((0.7, None, 5), "obvious"),
])
def test_verdict_table(r, expected):
    assert verdict(*r)[0] == expected


def test_corner_is_explained():
    v, note = verdict(3.0, 2.0, 0.2)
    assert v == "slight" and "R_HF < 0.6" in note and "corner" in note


@pytest.mark.parametrize("r", [(None, 5, 5), (5, None, 5), (5, 5, None), (None, 0.3, 5)])
def test_missing_band_leaves_verdict_open(r):
    v, note = verdict(*r)
    assert v is None and "missing" in note
    if r == (None, 0.3, 5):
        assert "at least 'obvious'" in note


def test_sweep_not_reaching_a_band_has_no_factor():
    f = np.logspace(1, np.log10(5e5), 400)  # 10 Hz - 500 kHz: MF and HF not covered
    h_ref = 1.0 / (1.0 + 1j * f / 3e4)
    h_new = 1.0 / (1.0 + 1j * f / 1e4)
    masks = band_masks(f)
    assert masks["LF"] is not None and masks["MF"] is None and masks["HF"] is None
    d = dlt911_indices(f, h_ref, h_new)
    assert d["R_MF"] is None and d["R_HF"] is None and d["points"]["HF"] == 0
    x = 20 * np.log10(np.abs(h_ref[masks["LF"]]))
    y = 20 * np.log10(np.abs(h_new[masks["LF"]]))
    assert d["R_LF"] == pytest.approx(_standard_r(list(x), list(y)), rel=1e-9)
    assert d["R_LF"] >= 0.6 and d["verdict"] is None and "R_MF, R_HF missing" in d["note"]
    # a change LF alone makes severe is severe whatever the missing bands would say
    d = dlt911_indices(f, h_ref, 1.0 / h_ref)
    assert d["R_LF"] == pytest.approx(-math.log10(2.0)) and d["verdict"] == "severe"


# ---------------------------------------------------------------------------
# the response an FRA instrument records
# ---------------------------------------------------------------------------


def test_voltage_ratio_of_a_touchstone_sweep_is_s21_over_1_plus_s11(tmp_path):
    import skrf

    # series R between the ports, C from port 2 to ground; with 50 Ohm on port 2: V2/V1 = Zp / (R + Zp)
    f = np.logspace(2, 6.5, 60)
    r, c, r0 = 330.0, 4.7e-9, 50.0
    zp = 1.0 / (1.0 / r0 + 2j * np.pi * f * c)
    expected = zp / (r + zp)
    y = np.zeros((f.size, 2, 2), complex)
    y[:, 0, 0] = 1 / r
    y[:, 0, 1] = y[:, 1, 0] = -1 / r
    y[:, 1, 1] = 1 / r + 2j * np.pi * f * c
    net = skrf.Network(frequency=skrf.Frequency.from_f(f, unit="hz"), s=skrf.network.y2s(y, r0), z0=r0, name="rc")
    p = tmp_path / "rc.s2p"
    p.write_text(net.write_touchstone(return_string=True, form="db"))
    sw = load_sweep(p)
    np.testing.assert_allclose(sw.voltage_ratio, expected, rtol=1e-6)
    s = skrf.Network(str(REFERENCE)).s
    np.testing.assert_allclose(load_sweep(REFERENCE).voltage_ratio, s[:, 1, 0] / (1 + s[:, 0, 0]), rtol=1e-9)


# ---------------------------------------------------------------------------
# the real IPN sweeps
# ---------------------------------------------------------------------------


@pytest.fixture(scope="module")
def reference():
    return load_sweep(REFERENCE)


def test_ipn_second_reference_is_normal(reference):
    rep = load_sweep(REPEAT)
    d = dlt911_indices(reference.frequency_hz, reference.voltage_ratio, rep.voltage_ratio)
    assert d["verdict"] == "normal", d
    assert d["R_LF"] >= 2.0 and d["R_MF"] >= 1.0 and d["R_HF"] >= 0.6


def test_ipn_every_short_is_severe(reference):
    assert len(SHORTS) == 16
    for p in SHORTS:
        new = load_sweep(p)
        d = dlt911_indices(reference.frequency_hz, reference.voltage_ratio, new.voltage_ratio)
        assert d["verdict"] == "severe", (p.name, d)
        assert d["R_LF"] < 0.6


def test_ipn_repeatability(reference):
    rep = load_sweep(REPEAT)
    f, h0, h1 = reference.frequency_hz, reference.voltage_ratio, rep.voltage_ratio
    short = load_sweep(DATA / "resistive" / "2309.s2p").voltage_ratio
    bands = repeatability(f, h0, h1, short)
    assert all(b["judgement"] == "beyond repeatability" for b in bands.values())
    # another healthy sweep: the repeat's own dB difference, with its points in another order (same spread)
    rng = np.random.default_rng(5)
    d = 20 * np.log10(np.abs(h1 / h0))
    other = np.empty_like(h0)
    for m in band_masks(f).values():
        other[m] = h0[m] * 10 ** (rng.permutation(d[m]) / 20)
    rest = ~np.logical_or.reduce([m for m in band_masks(f).values()])
    other[rest] = h1[rest]
    bands = repeatability(f, h0, h1, other)
    assert all(b["judgement"] == "within repeatability" for b in bands.values()), bands
    for b in bands.values():
        assert b["ratio"] == pytest.approx(1.0, rel=1e-9) and b["limit"] > 1.0


# ---------------------------------------------------------------------------
# CSV exports of FRA instruments
# ---------------------------------------------------------------------------


def _layouts(f: np.ndarray, h: np.ndarray) -> dict[str, str]:
    db = 20 * np.log10(np.abs(h))
    deg = np.degrees(np.angle(h))
    rows_c = "\n".join(f"{a:.6g},{b:.6f},{c:.4f}" for a, b, c in zip(f, db, deg))
    rows_s = "\n".join(f"{a:.6g};{b:.6f};{c:.4f}".replace(".", ",") for a, b, c in zip(f, db, deg))
    rows_t = "\n".join(f"{i}\t{a / 1e3:.9g}\t{b:.6f}\t{c:.4f}" for i, (a, b, c) in enumerate(zip(f, db, deg)))
    rows_d = "\n".join(f"{a:.6g},{b:.6f},{c:.4f}," for a, b, c in zip(f[::-1], db[::-1], deg[::-1]))
    return {
        # preamble of test-object fields, then a name row and a unit row
        "unit_row": ("Test object,T1 HV winding\nConnection,H1-H2 open circuit\nDate,2025-07-23 12:13\n\n"
                     f"Frequency,Magnitude,Phase\nHz,dB,deg\n{rows_c}\n"),
        # units inside the names, semicolons, decimal commas, quoted names
        "semicolon_decimal_comma": f'"Frequency (Hz)";"Magnitude (dB)";"Phase (°)"\n{rows_s}\n',
        # an index column, tabs, kHz
        "tab_index_khz": f"No.\tFreq [kHz]\tMag [dB]\tPhase [deg]\n{rows_t}\n",
        # a sweep from high to low frequency, a trailing separator, comment lines
        "descending": f"# exported trace\nFrequency(Hz),Response(dB),Phase(deg),\n{rows_d}\n",
    }


@pytest.mark.parametrize("layout", ["unit_row", "semicolon_decimal_comma", "tab_index_khz", "descending"])
def test_fra_csv_layouts_read_as_they_are(tmp_path, reference, layout):
    f, h = reference.frequency_hz, reference.voltage_ratio
    p = tmp_path / f"{layout}.csv"
    p.write_text(_layouts(f, h)[layout], encoding="utf-8")
    d = read_fra_csv(p)
    np.testing.assert_allclose(d.frequency_hz, f, rtol=1e-5)
    got = d.responses[RESPONSE]
    np.testing.assert_allclose(20 * np.log10(np.abs(got)), 20 * np.log10(np.abs(h)), atol=1e-5)
    np.testing.assert_allclose(np.angle(got / h), 0.0, atol=1e-5)
    if layout == "unit_row":
        assert "Test object,T1 HV winding" in d.comments


@pytest.mark.parametrize("text, where", [
    ("Frequency,Magnitude,Phase\nHz,dB,deg\n10,-20,5\n20,oops,4\n30,-22,3\n", r":4: column 2 'magnitude': not a number"),
    ("f,g,h\n1,2,3\n", r"no column-name row"),
    ("Frequency,Magnitude,Phase\nHz,Ohm,deg\n10,-20,5\n20,-21,4\n", r":1: column 2: unknown magnitude unit"),
    ("Frequency,Magnitude,Phase\n10,-20,5\n30,-21,4\n20,-22,3\n", r":4: column 1 'frequency': frequency 20.0 is below"),
    ("Frequency,Magnitude,Phase\n10,-20,5\n20\n", r":3: expected at least 3 columns"),
])
def test_bad_fra_csv_is_one_line(tmp_path, text, where):
    p = tmp_path / "bad.csv"
    p.write_text(text)
    with pytest.raises(MeasuredDataError, match=where) as e:
        read_fra_csv(p)
    assert "\n" not in str(e.value) and "bad.csv" in str(e.value)


# ---------------------------------------------------------------------------
# command line: CSV exports, --repeat, --report (no model fit: seconds)
# ---------------------------------------------------------------------------


def _cli(*argv: str) -> subprocess.CompletedProcess:
    env = dict(os.environ)
    env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
    return subprocess.run([sys.executable, "-m", "pris_cosim", "diagnose", *argv], cwd=ROOT, env=env,
                          capture_output=True, text=True, timeout=300)


def test_cli_csv_exports_repeat_and_report(tmp_path, reference):
    paths = {}
    for name, src in (("ref", REFERENCE), ("new", DATA / "bolted" / "23072507.s2p"), ("rep", REPEAT)):
        sw = reference if src == REFERENCE else load_sweep(src)
        paths[name] = tmp_path / f"{name}.csv"
        paths[name].write_text(_layouts(sw.frequency_hz, sw.voltage_ratio)["unit_row"])
    rep_dir = tmp_path / "report"
    out = _cli("--reference", str(paths["ref"]), "--measured", str(paths["new"]), "--repeat", str(paths["rep"]),
               "--json", "--quiet", "--report", str(rep_dir))
    assert out.returncode == 0, out.stderr
    assert out.stderr == ""
    obj = json.loads(out.stdout)
    d = obj["standard_indices"]["dlt911"]
    assert set(d) >= {"R_LF", "R_MF", "R_HF", "verdict"} and d["verdict"] == "severe"
    # the same factors as from the Touchstone files
    ts = dlt911_indices(reference.frequency_hz, reference.voltage_ratio,
                        load_sweep(DATA / "bolted" / "23072507.s2p").voltage_ratio)
    for k in ("R_LF", "R_MF", "R_HF"):
        assert d[k] == pytest.approx(ts[k], abs=2e-3)
    assert obj["standard_indices"]["dlt911_repeat"]["verdict"] == "normal"
    assert obj["repeatability"]["bands"]["LF"]["judgement"] == "beyond repeatability"
    assert obj["cause"] is None and "CSV" in obj["model_diagnosis"]
    assert obj["indices_definitions"]["cc"]["centred"] is False
    assert "NaN" not in out.stdout and "Infinity" not in out.stdout
    assert (rep_dir / "fra.png").stat().st_size > 10_000
    text = (rep_dir / "report.md").read_text()
    assert "**Verdict: severe**" in text and "beyond repeatability" in text and "fra.png" in text


def test_cli_no_model_on_touchstone_and_text_output():
    out = _cli("--reference", str(REFERENCE), "--measured", str(REPEAT), "--no-model", "--quiet")
    assert out.returncode == 0, out.stderr
    assert out.stdout.startswith("DL/T 911: normal")


def test_cli_bad_csv_is_one_line_exit_2(tmp_path):
    p = tmp_path / "bad.csv"
    p.write_text("Frequency,Magnitude,Phase\nHz,dB,deg\n10,-20,5\n20,x,4\n")
    out = _cli("--reference", str(REFERENCE), "--measured", str(p), "--json")
    assert out.returncode == 2 and out.stdout == ""
    lines = out.stderr.strip().splitlines()
    assert len(lines) == 1 and "bad.csv:4" in lines[0] and "Traceback" not in out.stderr


# ---------------------------------------------------------------------------
# the full path with the winding model (minutes without a cached reference model)
# ---------------------------------------------------------------------------


@pytest.mark.slow
def test_cli_model_repeat_and_report(tmp_path):
    rep_dir = tmp_path / "report"
    out = _cli("--reference", str(REFERENCE), "--measured", str(DATA / "bolted" / "23072507.s2p"), "--repeat",
               str(REPEAT), "--json", "--quiet", "--report", str(rep_dir))
    assert out.returncode == 0, out.stderr
    obj = json.loads(out.stdout)
    assert obj["cause"] == "shorted-turns"
    assert obj["standard_indices"]["dlt911"]["verdict"] == "severe"
    assert 0 < obj["location_std"] < 0.5
    for name in ("report.md", "fra.png", "response.png", "winding.png"):
        assert (rep_dir / name).stat().st_size > 1000
    text = (rep_dir / "report.md").read_text()
    assert "**Verdict: severe**" in text and "one standard deviation" in text
