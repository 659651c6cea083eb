"""Lumped-network fits of real measured data: recovery from synthetic data, the real files' figures, bad input."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from estimation import real_fits as rf
from estimation.studies import real_data
from pris_cosim.frf.response import ResponseModel
from pris_cosim.measured.formats import MeasuredDataError, MeasuredResponses
from pris_cosim.datafiles import REAL
from pris_cosim.circuits.netlist import format_netlist, parse_netlist

SMALL = REAL / rf.SMALL_FILE
ADMITTANCE = REAL / rf.ADMITTANCE_FILE

#: A two-winding transformer of the fitted family (values chosen, not fitted).
SMALL_TRUE = {"R1": 0.5, "L1": 1e-3, "R2": 0.8, "L2": 1.2e-3, "sigma": 5e-3, "Rc": 5000.0,
              "C1": 5e-12, "C2": 8e-12, "C12": 3e-12}
#: A three-branch admittance ladder with peaks near 0.9, 1.2 and 1.8 MHz.
LADDER_TRUE = {"C0": 2e-10, "R0": 5e3, "R1": 9.0, "L1": 1.5e-5, "C1": 2e-9, "R2": 12.0, "L2": 1.7e-5,
               "C2": 1e-9, "R3": 10.0, "L3": 8e-6, "C3": 9e-10}
NOISE = 1e-3  # complex-log noise, about 0.01 dB and 0.06 deg RMS


def _noisy(h: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    return h * np.exp(NOISE * (rng.standard_normal(h.size) + 1j * rng.standard_normal(h.size)))


def _need(path: Path) -> Path:
    assert path.is_file(), f"shipped data missing: {path}"
    return path


# ---------------------------------------------------------------------- synthetic recovery
def test_small_transformer_fit_recovers_known_parameters_from_noisy_three_load_data():
    rng = np.random.default_rng(7)
    f = np.logspace(4, np.log10(2e7), 401)
    data = {ld: MeasuredResponses(f, {"Zin": _noisy(ResponseModel(rf.small_transformer_circuit(SMALL_TRUE, ld), "p")
                                                    .evaluate(f)["Zin"], rng)}, segment=ld)
            for ld in rf.SMALL_LOADS}
    start = rf.small_transformer_start(data)
    assert any(abs(start[k] / v - 1) > 0.1 for k, v in SMALL_TRUE.items())  # the fit has work to do
    fit = rf.fit_small_transformer(data)
    for name, value in SMALL_TRUE.items():
        assert fit.values[name] == pytest.approx(value, rel=0.03), name
    assert all(e < 0.02 for e in fit.extra["errors_db"].values())  # the noise level, no more
    assert fit.passive


def test_admittance_fit_recovers_a_known_ladder_and_its_peaks():
    rng = np.random.default_rng(3)
    f = np.arange(1, 401) * 25e3
    y = 1.0 / ResponseModel(rf.admittance_ladder_circuit(LADDER_TRUE), "p").evaluate(f)["Zin"]
    fit = rf.fit_admittance(MeasuredResponses(f, {"Yin": _noisy(y, rng)}))
    for name, value in LADDER_TRUE.items():
        assert fit.values[name] == pytest.approx(value, rel=0.03), name
    true_peaks = [1 / (2 * np.pi * np.sqrt(LADDER_TRUE[f"L{k}"] * LADDER_TRUE[f"C{k}"])) for k in (1, 2, 3)]
    assert fit.extra["peaks_fitted_hz"] == pytest.approx(true_peaks, rel=0.01)
    assert fit.passive


def test_skin_factor_real_part_rises_as_the_power_law():
    f = np.array([1e4, 1e6])
    fac = rf.skin_factor(f, 2.0, 0.5)
    assert fac.real == pytest.approx(1 + 2.0 * np.cos(np.pi / 4) * (f / rf.SKIN_F0_HZ) ** 0.5)
    assert np.all(fac.imag > 0)


# ---------------------------------------------------------------------- real data
@pytest.fixture(scope="module")
def small_fits():
    data = rf.read_small_transformer(_need(SMALL))
    fit = rf.fit_small_transformer(data)
    skin = rf.fit_small_transformer_skin(data, fit, max_nfev=40)
    return data, fit, skin


def test_real_small_transformer_joint_fit_is_within_stated_bounds(small_fits):
    _, fit, _ = small_fits
    assert set(fit.extra["errors_db"]) == set(rf.SMALL_LOADS)
    for ld in rf.SMALL_LOADS:
        assert fit.extra["errors_db"][ld] < 0.5, ld
        assert fit.extra["phase_errors_deg"][ld] < 3.0, ld
    assert fit.passive
    assert 0 < fit.values["sigma"] < 0.01  # tightly coupled: leakage under 1 % of L1


def test_real_short_circuit_resistance_rises_where_the_constant_r_model_stays_flat(small_fits):
    data, fit, skin = small_fits
    sc = rf.short_circuit_resistance(data, fit, skin)
    assert sc["rise"]["measured"] > 5.0  # README: roughly tenfold 10 kHz -> 350 kHz
    assert sc["rise"]["constant_r"] < 2.0
    assert sc["rise"]["skin"] > 5.0
    assert skin.extra["errors_db"]["short"] < 0.5 * fit.extra["errors_db"]["short"]
    assert skin.passive and skin.values["a"] > 0 and 0 < skin.values["b"] <= 1


def test_fitted_circuits_are_ordinary_circuits_that_round_trip_through_a_netlist(small_fits):
    _, _, skin = small_fits
    c = skin.extra["circuits"]["short"]
    back = parse_netlist(format_netlist(c))
    f = np.logspace(4, 6, 20)
    assert ResponseModel(back, "p").evaluate(f)["Zin"] == pytest.approx(ResponseModel(c, "p").evaluate(f)["Zin"], rel=1e-9)


def test_real_admittance_ladder_matches_the_three_resonances():
    data = rf.read_admittance(_need(ADMITTANCE))
    fit = rf.fit_admittance(data)
    assert fit.extra["errors_db"]["band"] < 1.0
    measured = fit.extra["peaks_measured_hz"]
    assert measured == pytest.approx([0.93e6, 1.23e6, 1.83e6], rel=0.02)  # as stated in the data README
    assert len(fit.extra["peaks_fitted_hz"]) == 3
    assert np.max(np.abs(fit.extra["peak_errors_percent"])) < 3.0
    assert fit.passive and all(v > 0 for v in fit.values.values())


# ---------------------------------------------------------------------- bad input
def test_missing_file_names_the_file_in_one_line(tmp_path):
    path = tmp_path / "nothere.csv"
    with pytest.raises(MeasuredDataError) as err:
        rf.read_small_transformer(path)
    assert "nothere.csv" in str(err.value) and "\n" not in str(err.value)
    with pytest.raises(MeasuredDataError, match="nothere.csv"):
        rf.read_admittance(path)


@pytest.mark.parametrize("text", ["hello,world\n1,2\n", "FREQUENCY [Hz],MAG [O],PHASE [deg]\n1e4,2,3\n2e4,2,3\n"])
def test_wrong_small_transformer_format_names_the_file(tmp_path, text):
    path = tmp_path / "bad.csv"
    path.write_text(text)
    with pytest.raises(MeasuredDataError) as err:
        rf.read_small_transformer(path)
    assert "bad.csv" in str(err.value) and "\n" not in str(err.value)


def test_wrong_admittance_format_names_the_file(tmp_path):
    path = tmp_path / "bad.txt"
    path.write_text("1 2 3\n4 5 6\n")
    with pytest.raises(MeasuredDataError, match="bad.txt"):
        rf.read_admittance(path)


def test_study_without_data_names_the_directory(tmp_path, monkeypatch):
    monkeypatch.setenv(real_data.ENV_VAR, str(tmp_path))
    with pytest.raises(ValueError) as err:
        real_data.run(quick=True, out=None, progress=False)
    assert str(tmp_path) in str(err.value) and "\n" not in str(err.value)


# ---------------------------------------------------------------------- the study
@pytest.mark.slow
def test_study_quick_writes_json_and_plots(tmp_path, monkeypatch):
    _need(SMALL)
    _need(ADMITTANCE)
    monkeypatch.setenv(real_data.ENV_VAR, str(REAL))
    out = tmp_path / "real"
    res = real_data.run(quick=True, out=str(out), progress=False)
    assert [r["case"] for r in res["rows"]][:3] == ["small-open", "small-short", "small-49.5"]
    assert res["rows"][-1]["case"] == "03PK10"
    for r in res["rows"]:
        assert {"case", "model", "errors_db", "phase_errors_deg", "passive", "wall_s", "estimate"} <= set(r)
    assert all(res["checks"].values()), res["checks"]
    assert res["wall_s"] < 60
    stored = json.loads((out / "study.json").read_text())
    assert stored["checks"] == res["checks"]
    for name in ("small_transformer.png", "short_circuit_resistance.png", "admittance_03PK10.png"):
        assert (out / name).stat().st_size > 10_000


@pytest.mark.slow
def test_cli_study_real_data(tmp_path, monkeypatch, capsys):
    """``pris-cosim study real-data --json``: one JSON object; a missing data directory exits 2 with one line."""
    from pris_cosim.cli.commands import main

    monkeypatch.setenv(real_data.ENV_VAR, str(tmp_path / "nowhere"))
    assert main(["study", "real-data", "--out", str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err.strip()
    assert "nowhere" in err and "\n" not in err
    _need(SMALL)
    _need(ADMITTANCE)
    monkeypatch.setenv(real_data.ENV_VAR, str(REAL))
    assert main(["study", "real-data", "--quick", "--json", "--out", str(tmp_path / "real")]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["rows"][-1]["case"] == "03PK10" and all(d["checks"].values())
