"""Diagnosis against a design: the design values as a prior, drift reported, causes sought from the design.

The three examples in ``pris_cosim/data/diagnosis_examples`` were made by an
independent nodal solver (not pris-cosim) with 0.3 % complex noise; their
truth is in ``cases.json`` (see the README there).
"""

import json
from dataclasses import replace
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import pris_cosim
from estimation.diagnosis import diagnose_frequency
from estimation.diagnosis.drift import release_gains
from estimation.diagnosis.fit import FrequencyFit
from estimation.diagnosis.prior import design_prior
from pris_cosim.frf.response import Response
from pris_cosim.measured.formats import load_measured
from pris_cosim.models.builtin import Configuration
from pris_cosim.circuits.netlist import parse_netlist, read_netlist

DATA = Path(pris_cosim.__file__).parent / "data" / "diagnosis_examples"
CASES = {c["data"].removesuffix(".csv"): c for c in json.loads((DATA / "cases.json").read_text())["cases"]}


def _diagnose(name, **kw):
    m = load_measured(str(DATA / f"{name}.csv"))
    return diagnose_frequency(m.frequency_hz, m.responses, circuit=read_netlist(str(DATA / "design_cascade5.cir")),
                              port="n1", progress=False, **kw)


def _check(d, name):
    case = CASES[name]
    assert d.causes == case["truth_causes"], (d.causes, d.candidates())
    assert sorted(x["name"] for x in d.drift) == sorted(case["truth_drift"]), d.drift
    assert all(x["ratio"] > 1.2 or x["ratio"] < 1 / 1.2 for x in d.drift)


def test_within_tolerance_gives_no_cause_and_no_drift():
    d = _diagnose("within_tolerance")
    _check(d, "within_tolerance")
    assert d.baseline.cost <= 1.25 * d.noise["cost"]
    assert d.as_json()["tolerance"] == 0.2


@pytest.mark.slow
@pytest.mark.long
def test_doubled_capacitance_is_drift_not_a_cause():
    d = _diagnose("c3_doubled")
    _check(d, "c3_doubled")
    c3 = d.drift[0]
    assert c3["design"] == pytest.approx(0.85e-9) and c3["ratio"] > 1.4


@pytest.mark.slow
@pytest.mark.long
def test_skin_effect_named_from_the_design_values(tmp_path):
    from estimation.diagnosis.report import write_report

    d = _diagnose("within_tolerance_skin")
    _check(d, "within_tolerance_skin")
    assert d.baseline_drift, "the baseline alone needs resistances far from the design"
    assert any(x["name"].upper().startswith("R") and x["ratio"] > 1.5 for x in d.baseline_drift)
    assert d.best.cost <= 1.25 * d.noise["cost"] and d.gain > 0.2
    text = write_report(d, tmp_path / "rep", source="within_tolerance_skin").read_text()
    assert "Drift from the design" in text and "skin-effect" in text


def test_prior_penalty_is_the_log_normal_in_nats():
    """Penalty of a fit against ``sum ln^2(v/d) / (2 tau^2)`` written out here, in cost units."""
    net = parse_netlist("* two sections\nR1 n1 x1 1\nL1 x1 n2 1m\nC1 n1 0 1n\nR2 n2 x2 2\nL2 x2 0 2m\nC2 n2 0 1n\n")
    f = np.logspace(3, 6, 50)
    z = np.full(f.size, 10.0 + 1j)
    cfg = [Configuration("default", "n1", (), (Response("Zin"),))]
    free = FrequencyFit(net, cfg, f, {"Zin": z})
    design = dict(zip(free.free, free.start))
    prior = design_prior(design, 0.2, noise_cost=1e-4, n_frequencies=f.size, n_responses=1, circuit=net)
    fit = FrequencyFit(net, cfg, f, {"Zin": z}, prior=prior)
    x = np.zeros(fit.nc)
    x[fit.free.index("R1")], x[fit.free.index("R2")] = math.log(1.5), math.log(0.5)
    r = fit.result(x)
    nats = (math.log(1.5) ** 2 + math.log(0.5) ** 2) / (2 * math.log(1.2) ** 2)
    assert r.penalty == pytest.approx(1e-4 / f.size * nats, rel=1e-9)
    assert r.objective == pytest.approx(r.cost + r.penalty)
    drifted = prior.drift(r.values)
    assert [d["name"] for d in drifted] == ["R2", "R1"] and drifted[1]["ratio"] == pytest.approx(1.5)
    # free values (tolerance inf): no prior at all
    assert design_prior(design, math.inf, 1e-4, f.size, 1) is None


@pytest.mark.slow
def test_cli_reads_tolerance_and_values_with_suffixes(tmp_path):
    proc = subprocess.run([sys.executable, "-m", "pris_cosim", "diagnose", "--measured",
                           str(DATA / "within_tolerance.csv"), "--netlist", str(DATA / "design_cascade5.cir"),
                           "--port", "n1", "--tolerance", "0.2", "--json"], capture_output=True, text=True,
                          timeout=300)
    assert proc.returncode == 0, proc.stderr
    out = json.loads(proc.stdout)
    assert out["cause"] == "none" and out["drift"] == [] and out["tolerance"] == 0.2
    from estimation.diagnosis.cli import _tolerance
    from pris_cosim.cli.sim import si_value as _value

    assert _value("4m") == pytest.approx(4e-3) and _value("1u") == pytest.approx(1e-6) and _value("1e-6") == 1e-6
    assert math.isinf(_tolerance("inf")) and _tolerance("20%") == pytest.approx(0.2)
    bad = subprocess.run([sys.executable, "-m", "pris_cosim", "diagnose", "--measured", "x.csv", "--tolerance", "-1"],
                         capture_output=True, text=True, timeout=60)
    assert bad.returncode == 2 and "--tolerance" in bad.stderr and "Traceback" not in bad.stderr


@pytest.mark.slow
@pytest.mark.long
def test_skin_effect_named_beside_a_doubled_capacitance():
    """An independent generator's design case: C6 at twice its design value plus a skin effect.

    Under the prior the baseline reaches the noise only by moving a dozen
    values more than two tolerances; the skin-effect fit reaches it with
    fewer such values (C6 stays off in every model: it really is), so it is
    named on the BIC margin alone, and C6 is reported as drift.
    """
    from hidden_cases import design_case

    case = design_case(("skin-effect",), 701, drift=True)
    d = diagnose_frequency(case.frequency_hz, case.measured, circuit=parse_netlist(case.baseline_netlist),
                           port=case.port, progress=False, tolerance=0.2)
    assert case.truth["drift"] == ["C6"]
    # a lamination's loss grows as (1 + j) sqrt(f) above its corner, as a skin effect's does: when the two fits
    # alone are within 2 in BIC, the other is named and the skin effect reported as not told apart from it
    tied = [c["cause"] for c in d.cause_alternatives]
    assert d.causes == ["skin-effect"] or (d.causes == ["core-loss"] and "skin-effect" in tied), d.candidates()
    assert [x["name"] for x in d.drift] == ["C6"] and 1.6 < d.drift[0]["ratio"] < 2.5


@pytest.mark.slow
@pytest.mark.long
def test_one_doubled_capacitance_located_where_the_prior_spread_it():
    """An independent generator's design case: C5 of a 6-section winding at twice its design value, nothing else.

    Under the prior the baseline spreads the change over values near the
    tolerance (Cg2 x0.72, C4 x1.27) and stops at 2.5x the noise floor. C5
    alone, scanned for the resonances it brings onto the measured ones and
    then fitted free of its prior, explains the data; it is the one
    reported, at its true ratio, and the report names it.
    """
    from hidden_cases import design_case
    from estimation.diagnosis.report import drift_lines

    case = design_case((), 701, drift=True)
    d = diagnose_frequency(case.frequency_hz, case.measured, circuit=parse_netlist(case.baseline_netlist),
                           port=case.port, progress=False, tolerance=0.2)
    assert case.truth["drift"] == ["C5"]
    assert d.causes == [], d.candidates()
    assert [x["name"] for x in d.drift] == ["C5"] and 1.8 < d.drift[0]["ratio"] < 2.2, d.drift
    assert d.baseline.objective <= 1.25 * d.noise["cost"]
    assert any("| C5 |" in line for line in drift_lines(d.as_json()))


def test_drift_on_a_value_in_parallel_names_its_partners_and_their_combination():
    """A section ending at ground: its capacitance and the node's capacitance to ground are in parallel, and the
    terminals see only their sum. Combinations by hand: capacitances add, resistances combine as conductances."""
    from estimation.diagnosis.drift import with_parallel
    from estimation.diagnosis.report import drift_lines

    circuit = parse_netlist("* end section\nR1 n1 x1 2\nL1 x1 n2 1m\nC1 n1 n2 1n\nCg1 n1 0 1n\n"
                            "R2 n2 x2 3\nL2 x2 0 2m\nC2 n2 0 0.8n\nCg2 n2 gnd 0.7n\nRp n2 0 1k\nRq 0 n2 4k\n"
                            "K1 L1 L2 0.5\n")
    design = {"c2": 0.8e-9, "cg2": 0.7e-9, "rp": 1e3, "rq": 4e3, "c1": 1e-9, "l2": 2e-3}
    values = {"C2": 0.8e-9, "Cg2": 1.9e-9, "Rp": 1e3, "Rq": 9e3, "C1": 2.2e-9, "L2": 4e-3}
    drift = [{"name": "Cg2", "design": 0.7e-9, "fitted": 1.9e-9, "ratio": 1.9 / 0.7},
             {"name": "Rq", "design": 4e3, "fitted": 9e3, "ratio": 2.25},
             {"name": "C1", "design": 1e-9, "fitted": 2.2e-9, "ratio": 2.2},
             {"name": "L2", "design": 2e-3, "fitted": 4e-3, "ratio": 2.0}]
    out = with_parallel(circuit, values, design, drift)
    cg2, rq, c1, l2 = out
    assert cg2["parallel"] == ["C2"]
    assert cg2["combined"]["design"] == pytest.approx(1.5e-9) and cg2["combined"]["fitted"] == pytest.approx(2.7e-9)
    assert cg2["combined"]["ratio"] == pytest.approx(1.8)
    assert rq["parallel"] == ["Rp"]
    assert rq["combined"]["design"] == pytest.approx(800.0)  # 1k || 4k
    assert rq["combined"]["fitted"] == pytest.approx(900.0)  # 1k || 9k
    assert "parallel" not in c1  # C1 spans n1-n2, Cg1 n1-ground: not in parallel
    assert "parallel" not in l2  # a coupled inductor is not combined
    assert drift[0].get("parallel") is None  # the input is not changed
    text = "\n".join(drift_lines({"tolerance": 0.2, "drift": out}))
    assert "Cg2 is in parallel with C2" in text and "x1.8" in text


_R, _L, _C1, _C2 = 2.0, 1.0e-3, 0.5e-9, 2.0e-9


def _two_modes(f: np.ndarray, c2: float) -> np.ndarray:
    s = 2j * np.pi * f
    return 1 / (1 / (_R + s * _L + 1 / (s * c2)) + s * _C1)


def _two_mode_fit(f, z, prior):
    net = parse_netlist(f"* two modes\nC1 p 0 {_C1}\nR1 p a {_R}\nL1 a b {_L}\nC2 b 0 {_C2}\n")
    cfg = [Configuration("default", "p", (), (Response("Zin"),))]
    return FrequencyFit(net, cfg, f, {"Zin": z}, prior=prior)


def test_the_value_off_the_design_is_the_one_whose_release_gains_most():
    """The score test of each design value's prior (:func:`.drift.release_gains`) on a two-mode network written out
    in closed form, ``Z = (R + s L + 1/(s C2)) || 1/(s C1)``, with C2 1.6 times its design value in the data: C2's
    release is ranked first, and the fall it predicts agrees with the refit's with C2's prior removed."""
    f = np.logspace(4, 6.5, 300)
    rng = np.random.default_rng(5)
    z = _two_modes(f, 1.6 * _C2) * np.exp(0.02 / np.sqrt(2) * (rng.standard_normal(f.size)
                                                                 + 1j * rng.standard_normal(f.size)))
    design = {"R1": _R, "L1": _L, "C1": _C1, "C2": _C2}
    # a prior weighted as for 70 % noise: it holds C2 back, and L1 and C1 move to make up for it
    prior = design_prior(design, 0.2, noise_cost=0.5, n_frequencies=f.size, n_responses=1)
    fit = _two_mode_fit(f, z, prior)
    held = fit.fit(max_nfev=300)
    gains = release_gains(fit, held.x)
    names = [fit.free[c] for c in fit.anchored_columns]
    assert names[int(np.argmax(gains))] == "C2", dict(zip(names, gains))
    # the fall predicted for C2 against the refit with its prior removed, from the same values
    loose = _two_mode_fit(f, z, replace(prior, design={k: v for k, v in prior.design.items() if k != "c2"}))
    refit = loose.fit(x0s=held.x[None], grid=False, keep_starts=1, max_nfev=300)
    before = float(np.sum(fit.residuals(held.x) ** 2))
    after = float(np.sum(loose.residuals(refit.x) ** 2))
    assert abs(np.max(gains) - (before - after)) <= 0.1 * (before - after), (gains, before - after)
