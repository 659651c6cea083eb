"""SFRA fault diagnosis on the measured inter-turn shorts (estimation.diagnosis.sfra) and Touchstone through scikit-rf."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.stats import spearmanr

from estimation.diagnosis.sfra.faults import diagnose_sweep
from estimation.diagnosis.sfra.fingerprint import load_or_fit, model_y
from estimation.diagnosis.sfra.indices import band_indices
from estimation.diagnosis.sfra.sweep import Sweep, load_sweep
from estimation.diagnosis.sfra.winding import admittance
from pris_cosim.datafiles import REAL
from pris_cosim.measured.formats import MeasuredDataError
from pris_cosim.measured.touchstone import read_touchstone, write_touchstone

ROOT = Path(__file__).resolve().parents[2]
DATA = REAL / "ipn_winding_interturn"
REFERENCE = DATA / "reference_23072517.s2p"
#: Position NN -> first shorted tap (README of the data).
TAPS = {1: 3, 3: 15, 5: 27, 7: 39, 9: 51, 11: 63, 13: 75, 15: 87}
KINDS = {"bolted": "bolted/230725{:02d}.s2p", "resistive": "resistive/23{:02d}.s2p"}


@pytest.fixture(scope="module")
def reference() -> Sweep:
    return load_sweep(REFERENCE)


@pytest.fixture(scope="module")
def fingerprint(reference):
    """Fitted once per session; the cache ($PRIS_COSIM_CACHE or ~/.cache/pris-cosim) keeps it across sessions."""
    return load_or_fit(reference, progress=False)


def _diagnose_one(args: tuple) -> dict:
    fingerprint, reference, path = args
    return diagnose_sweep(fingerprint, reference, load_sweep(path), progress=False)


def _diagnosed(reference, fingerprint, positions) -> dict:
    """The shorts at ``positions`` of both kinds diagnosed against the one fitted reference, two at a time."""
    from concurrent.futures import ProcessPoolExecutor

    keys = [(kind, nn) for kind in KINDS for nn in positions]
    jobs = [(fingerprint, reference, DATA / KINDS[kind].format(nn)) for kind, nn in keys]
    with ProcessPoolExecutor(max_workers=2) as pool:
        return dict(zip(keys, pool.map(_diagnose_one, jobs)))


@pytest.fixture(scope="module")
def diagnoses(reference, fingerprint):
    """The 16 shorts (``long`` tests: minutes)."""
    return _diagnosed(reference, fingerprint, TAPS)


#: Two positions far apart along the winding (taps 27 and 75), for the tests CI runs.
PAIR = (5, 13)


@pytest.fixture(scope="module")
def pair_diagnoses(reference, fingerprint):
    """The shorts at the two positions of ``PAIR``, both kinds."""
    return _diagnosed(reference, fingerprint, PAIR)


@pytest.mark.slow
def test_two_shorts_of_each_kind_are_named_located_apart_and_ordered(pair_diagnoses):
    """Both kinds at taps 27 and 75: shorted turns, the later tap placed at least two sections further along,
    the two kinds within two sections of each other, and the 10-Ohm short more resistive than the bolted one."""
    for kind in KINDS:
        first, second = (pair_diagnoses[kind, nn] for nn in PAIR)
        assert first.cause == second.cause == "shorted-turns", (kind, first.cause, second.cause)
        a, b = first.location(), second.location()
        assert b["fraction"] - a["fraction"] >= 2.0 / a["of_sections"], (kind, a, b)
    for nn in PAIR:
        a, b = pair_diagnoses["bolted", nn].location(), pair_diagnoses["resistive", nn].location()
        assert abs(a["fraction"] - b["fraction"]) <= 2.0 / a["of_sections"], (nn, a, b)
        rb = pair_diagnoses["bolted", nn].severity()["fault_resistance_ohm"]
        rr = pair_diagnoses["resistive", nn].severity()["fault_resistance_ohm"]
        assert rr > rb, nn


# ---------------------------------------------------------------------------
# the fingerprint and the diagnoses of the measured shorts
# ---------------------------------------------------------------------------


@pytest.mark.slow
def test_fingerprint_fits_the_reference(reference, fingerprint):
    assert 3 <= fingerprint.n_sections <= 12
    assert fingerprint.rms < 6.0  # weighted rms, 1 = noise + model floor
    z_data = -1 / reference.y[:, 1]
    z_model = -1 / model_y(fingerprint.model, reference.frequency_hz)[:, 1]
    lf = reference.frequency_hz < 1e4
    err_db = 20 * np.log10(np.abs(z_model[lf] / z_data[lf]))
    assert np.sqrt(np.mean(err_db**2)) < 1.5
    # tens of henries at low frequency (iron core)
    assert 10 < fingerprint.model.total_inductance() < 100


@pytest.mark.slow
@pytest.mark.long
@pytest.mark.parametrize("kind", list(KINDS))
def test_every_short_is_named_shorted_turns(diagnoses, kind):
    for nn in TAPS:
        d = diagnoses[kind, nn]
        assert d.cause == "shorted-turns", (kind, nn, [(c.cause, c.gain) for c in d.candidates])
        assert 0 < d.gain <= 1
        assert all(c.gain > 0 for c in d.candidates)


@pytest.mark.slow
@pytest.mark.long
@pytest.mark.parametrize("kind", list(KINDS))
def test_located_positions_follow_the_taps(diagnoses, kind):
    taps = [TAPS[nn] for nn in TAPS]
    locs = [diagnoses[kind, nn].location()["fraction"] for nn in TAPS]
    rho = spearmanr(taps, locs)[0]
    print(f"{kind}: Spearman rank correlation location vs tap = {rho:+.3f}")
    assert abs(rho) >= 0.8, (kind, locs)


@pytest.mark.slow
@pytest.mark.long
def test_locations_agree_between_kinds(diagnoses):
    """A bolted short and a 10-Ohm short at the same taps are placed within two sections of each other."""
    for nn in TAPS:
        a, b = diagnoses["bolted", nn].location(), diagnoses["resistive", nn].location()
        assert abs(a["fraction"] - b["fraction"]) <= 2.0 / a["of_sections"], (nn, a, b)


@pytest.mark.slow
@pytest.mark.long
def test_bolted_and_resistive_shorts_differ_in_resistance(diagnoses):
    for nn in TAPS:
        rb = diagnoses["bolted", nn].severity()["fault_resistance_ohm"]
        rr = diagnoses["resistive", nn].severity()["fault_resistance_ohm"]
        assert rr > rb, nn


@pytest.mark.slow
def test_reference_against_itself_with_noise_is_none(reference, fingerprint):
    rng = np.random.default_rng(11)
    s = reference.noise
    y = reference.y * np.exp(s * (rng.standard_normal(s.shape) + 1j * rng.standard_normal(s.shape)) / np.sqrt(2))
    noisy = Sweep.from_y(reference.frequency_hz, y, source="reference + noise")
    d = diagnose_sweep(fingerprint, reference, noisy, progress=False)
    assert d.cause == "none", [(c.cause, c.gain, c.dbic) for c in d.candidates]
    assert d.gain == 0.0
    assert all(c.gain >= 0 for c in d.candidates)


# ---------------------------------------------------------------------------
# command line
# ---------------------------------------------------------------------------


def _cli(*argv: str, env_cache: str | None = None) -> subprocess.CompletedProcess:
    env = dict(os.environ)
    env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
    return subprocess.run([sys.executable, "-m", "pris_cosim", "diagnose", *argv], cwd=ROOT, env=env,
                          capture_output=True, text=True, timeout=300)


@pytest.mark.slow
def test_cli_json_and_report(tmp_path, fingerprint):
    # the module fixture has filled the cache, so this run does not refit
    rep = tmp_path / "rep"
    out = _cli("--measured", str(DATA / "bolted" / "23072507.s2p"), "--reference", str(REFERENCE), "--json",
               "--report", str(rep), "--quiet")
    assert out.returncode == 0, out.stderr
    assert out.stderr == ""
    lines = out.stdout.strip().splitlines()
    assert len(lines) == 1
    obj = json.loads(lines[0])
    assert obj["cause"] == "shorted-turns"
    assert obj["model_order"] == fingerprint.n_sections
    assert 0 <= obj["location"] <= 1 and 1 <= obj["section"] <= obj["model_order"]
    assert obj["severity"]["fault_resistance_ohm"] > 0 and 0 < obj["severity"]["shorted_fraction"] <= 1
    assert set(obj["indices"]) == {"below 2 kHz", "2-20 kHz", "20 kHz-1 MHz", "above 1 MHz"}
    for band in obj["indices"].values():
        assert set(band) == {"points", "cc", "asle", "sd"}
    for c in obj["candidates"]:
        assert set(c) >= {"cause", "section", "gain", "dBIC"} and c["gain"] > 0
    assert "NaN" not in lines[0] and "Infinity" not in lines[0]
    assert obj["standard_indices"]["dlt911"]["verdict"] == "severe"
    for name in ("report.md", "fra.png", "response.png", "winding.png"):
        assert (rep / name).is_file()


def _bad_files(tmp: Path) -> dict[str, Path]:
    text = REFERENCE.read_text().splitlines()
    out = {}
    p = tmp / "truncated.s2p"
    p.write_text("\n".join(text[:300]) + "\n" + text[300][: len(text[300]) // 2] + "\n")
    out["truncated"] = p
    p = tmp / "oneport.s1p"
    p.write_text("# Hz S RI R 50\n10 0.5 0.1\n20 0.4 0.2\n30 0.3 0.3\n")
    out["one-port"] = p
    p = tmp / "nonmonotonic.s2p"
    p.write_text("\n".join(text[:10] + [text[11], text[10]] + text[12:]) + "\n")
    out["non-increasing"] = p
    p = tmp / "garbage.s2p"
    p.write_bytes(b"# Hz S dB R 50\nthis is not a sweep\n")
    out["garbage"] = p
    return out


@pytest.mark.slow
@pytest.mark.parametrize("which", ["truncated", "one-port", "non-increasing", "garbage"])
@pytest.mark.parametrize("role", ["--measured", "--reference"])
def test_bad_files_give_one_line_errors(tmp_path, which, role):
    bad = _bad_files(tmp_path)[which]
    other = "--reference" if role == "--measured" else "--measured"
    out = _cli(role, str(bad), other, str(REFERENCE), "--json")
    assert out.returncode == 2, out.stderr
    assert out.stdout == ""
    lines = out.stderr.strip().splitlines()
    assert len(lines) == 1, out.stderr
    assert bad.name in lines[0] and "Traceback" not in lines[0]


def test_bad_file_messages_name_the_line(tmp_path):
    bad = _bad_files(tmp_path)
    with pytest.raises(MeasuredDataError, match=r"truncated\.s2p:301: .*not a number|truncated\.s2p:301: .*incomplete"):
        load_sweep(bad["truncated"])
    with pytest.raises(MeasuredDataError, match=r"oneport\.s1p: a 1-port file where a 2-port file is needed"):
        load_sweep(bad["one-port"])
    with pytest.raises(MeasuredDataError, match=r"nonmonotonic\.s2p:12: column 1: .*must increase strictly"):
        load_sweep(bad["non-increasing"])


# ---------------------------------------------------------------------------
# Touchstone through scikit-rf
# ---------------------------------------------------------------------------


def _rc_two_port(f: np.ndarray, r: float = 330.0, c: float = 4.7e-9, r0: float = 50.0):
    """Series R between the ports, C from port 2 to ground: Y, Z and S (reference r0), closed form."""
    w = 2 * np.pi * f
    yc = 1j * w * c
    y = np.empty((f.size, 2, 2), complex)
    y[:, 0, 0] = 1 / r
    y[:, 0, 1] = y[:, 1, 0] = -1 / r
    y[:, 1, 1] = 1 / r + yc
    # Z = Y^-1 by hand: det = yc / r
    det = yc / r
    z = np.empty_like(y)
    z[:, 0, 0] = y[:, 1, 1] / det
    z[:, 1, 1] = y[:, 0, 0] / det
    z[:, 0, 1] = z[:, 1, 0] = (1 / r) / det
    # S = (I + r0 Y)^-1 (I - r0 Y), 2x2 inverse by hand
    a = np.eye(2)[None] + r0 * y
    b = np.eye(2)[None] - r0 * y
    da = a[:, 0, 0] * a[:, 1, 1] - a[:, 0, 1] * a[:, 1, 0]
    inv = np.empty_like(a)
    inv[:, 0, 0], inv[:, 1, 1] = a[:, 1, 1] / da, a[:, 0, 0] / da
    inv[:, 0, 1], inv[:, 1, 0] = -a[:, 0, 1] / da, -a[:, 1, 0] / da
    s = inv @ b
    return y, z, s


def _write_by_hand(path: Path, f: np.ndarray, m: np.ndarray, param: str, fmt: str, r0: float = 50.0) -> None:
    norm = {"S": 1.0, "Z": 1 / r0, "Y": r0}[param]
    rows = [f"! RC two-port written by the test\n# Hz {param} {fmt} R {r0:g}"]
    for k, fk in enumerate(f):
        cells = [repr(float(fk))]
        for i, j in ((0, 0), (1, 0), (0, 1), (1, 1)):  # v1 order 11 21 12 22
            v = m[k, i, j] * norm
            if fmt == "RI":
                a, b = v.real, v.imag
            elif fmt == "MA":
                a, b = abs(v), np.degrees(np.angle(v))
            else:
                a, b = 20 * np.log10(abs(v)), np.degrees(np.angle(v))
            cells += [repr(float(a)), repr(float(b))]
        rows.append(" ".join(cells))
    path.write_text("\n".join(rows) + "\n")


@pytest.mark.parametrize("param", ["S", "Y", "Z"])
@pytest.mark.parametrize("fmt", ["DB", "MA", "RI"])
def test_touchstone_reads_s_y_z_in_every_format(tmp_path, param, fmt):
    f = np.logspace(2, 7, 41)
    y, z, s = _rc_two_port(f)
    p = tmp_path / f"rc.{param.lower()}2p"
    _write_by_hand(p, f, {"S": s, "Y": y, "Z": z}[param], param, fmt)
    ts = read_touchstone(p)
    assert ts.parameter == param and ts.nports == 2 and ts.comments == ["RC two-port written by the test"]
    np.testing.assert_allclose(ts.frequency_hz, f, rtol=1e-15)
    np.testing.assert_allclose(ts.y(), y, rtol=1e-9, atol=1e-15)
    np.testing.assert_allclose(ts.z()[:, 0, 1], z[:, 0, 1], rtol=1e-9)
    np.testing.assert_allclose(ts.network.s, s, rtol=1e-9, atol=1e-12)  # the skrf.Network


@pytest.mark.slow
def test_fitted_model_round_trips_through_touchstone(tmp_path, reference, fingerprint):
    f = reference.frequency_hz
    y = admittance(fingerprint.model, f)
    for param, form in (("Y", "RI"), ("Z", "MA"), ("S", "DB")):
        p = tmp_path / f"model_{param}.s2p"
        values = {"Y": y, "Z": np.linalg.inv(y)}.get(param)
        if param == "S":
            import skrf

            values = skrf.network.y2s(y, np.full((f.size, 2), 50.0))
        write_touchstone(p, f, values, param, form, "Hz", 50.0, ["fitted winding"])
        back = load_sweep(p)
        np.testing.assert_allclose(back.frequency_hz, f, rtol=1e-15)
        np.testing.assert_allclose(back.y, model_y(fingerprint.model, f), rtol=1e-8)


@pytest.mark.slow
def test_cli_writes_the_fault_model(tmp_path, fingerprint):
    p = tmp_path / "fault_model.s2p"
    out = _cli("--measured", str(DATA / "resistive" / "2309.s2p"), "--reference", str(REFERENCE), "--quiet",
               "--model-out", str(p))
    assert out.returncode == 0, out.stderr
    assert out.stdout.startswith("cause: shorted-turns")
    ts = read_touchstone(p, nports=2)
    assert ts.parameter == "Y" and ts.frequency_hz.size == 1040


# ---------------------------------------------------------------------------
# indices
# ---------------------------------------------------------------------------


def test_indices_match_the_published_formulas():
    x = np.array([-10.0, -20.0, -30.0, -25.0])
    y = np.array([-11.0, -19.0, -33.0, -25.0])
    v = band_indices(x, y)
    assert v["cc"] == pytest.approx((110 + 380 + 990 + 625) / np.sqrt((100 + 400 + 900 + 625) * (121 + 361 + 1089 + 625)))
    assert v["asle"] == pytest.approx((1 + 1 + 3 + 0) / 4)
    assert v["sd"] == pytest.approx(np.sqrt((1 + 1 + 9 + 0) / 3))
    assert band_indices(x[:1], y[:1])["cc"] is None


def test_touchstone_version_2_and_more_ports(tmp_path):
    import skrf

    f = np.logspace(2, 7, 21)
    _, _, s = _rc_two_port(f)
    s3 = np.zeros((f.size, 3, 3), complex)
    s3[:, :2, :2] = s
    s3[:, 2, 2] = 1.0  # an open third port
    for p, m, kw in ((tmp_path / "rc.ts", s, {"version": "2.0"}), (tmp_path / "rc3.s3p", s3, {})):
        net = skrf.Network(frequency=skrf.Frequency.from_f(f, unit="hz"), s=m, z0=50.0, name="rc")
        p.write_text(net.write_touchstone(return_string=True, **kw))
        ts = read_touchstone(p)
        assert ts.nports == m.shape[1]
        np.testing.assert_allclose(ts.values, m, rtol=1e-12, atol=1e-15)
    with pytest.raises(MeasuredDataError, match=r"rc3\.s3p: a 3-port file where a 2-port file is needed"):
        load_sweep(tmp_path / "rc3.s3p")


#: One worker runs this module under ``pytest -n 2 --dist loadgroup``: its module fixtures are computed once.
pytestmark = pytest.mark.xdist_group("sfra")
