"""Tests for pris_cosim.measured.formats: readers, writers, validation, real data."""

from __future__ import annotations

import math
import os
import pickle
from pathlib import Path

import numpy as np
import pytest

from pris_cosim.measured import formats as M
from pris_cosim.measured import (instruments as measured_instruments, response_csv as measured_response_csv,
    waveform_csv as measured_waveform_csv)
from pris_cosim.datafiles import REAL
from pris_cosim.measured.formats import (MeasuredDataError, MeasuredResponses, Waveforms, detect_format,
    list_segments, load_measured, read_e4990a, read_mag_phase_rows, read_mat, read_multisegment_csv,
    read_response_csv, read_touchstone_z, read_waveform_csv, segment_info, write_e4990a, write_mag_phase_rows,
    write_mat, write_multisegment_csv, write_response_csv, write_touchstone_z, write_waveform_csv)

DATA = Path(__file__).resolve().parents[1] / "data" / "measured"

RTOL = 1e-15


# ---------------------------------------------------------------------------
# helpers
# ---------------------------------------------------------------------------


def random_responses(names=("Zin",), n=60, seed=1, fmin=10.0, fmax=2e7, **kw) -> MeasuredResponses:
    """Seeded random complex responses on log-spaced frequencies."""
    rng = np.random.default_rng(seed)
    f = np.logspace(math.log10(fmin), math.log10(fmax), n)
    resp = {}
    for name in names:
        mag = 10.0 ** rng.uniform(-3, 4, n)
        ph = rng.uniform(-180, 180, n)
        resp[name] = mag * np.exp(1j * np.radians(ph))
    return MeasuredResponses(f, resp, **kw)


def assert_same(a: MeasuredResponses, b: MeasuredResponses, rtol: float = RTOL) -> None:
    assert a.names == b.names
    np.testing.assert_array_equal(a.frequency_hz, b.frequency_hz)
    for n in a.names:
        # complex comparison: |a - b| <= rtol * |b| element by element
        np.testing.assert_allclose(a.responses[n], b.responses[n], rtol=rtol, atol=0)


def expect_error(path: Path, line: int | None, *fragments: str, reader=load_measured, **kw) -> str:
    with pytest.raises(MeasuredDataError) as info:
        reader(path, **kw)
    msg = str(info.value)
    assert "\n" not in msg
    assert path.name in msg
    if line is not None:
        assert f"{path.name}:{line}:" in msg, msg
        assert info.value.line == line
    for frag in fragments:
        assert frag in msg, msg
    return msg


# ---------------------------------------------------------------------------
# container
# ---------------------------------------------------------------------------


def test_container_helpers():
    d = random_responses(("Zin", "V_out"), n=20, seed=3)
    assert d.names == ["Zin", "V_out"]
    assert len(d) == 20
    np.testing.assert_allclose(d.mag("Zin"), np.abs(d.responses["Zin"]))
    ph = d.phase_deg("Zin")
    assert np.all((ph > -180) & (ph <= 180))
    sub = d.select(1e3, 1e5)
    assert np.all((sub.frequency_hz >= 1e3) & (sub.frequency_hz <= 1e5))
    assert sub.names == d.names and 0 < len(sub) < len(d)
    with pytest.raises(ValueError):
        d.select(1e9, None)
    with pytest.raises(KeyError, match="available"):
        d.mag("nope")


@pytest.mark.parametrize(
    "f, z",
    [
        ([1.0, 1.0], [1, 2]),
        ([2.0, 1.0], [1, 2]),
        ([0.0, 1.0], [1, 2]),
        ([1.0, np.nan], [1, 2]),
        ([1.0, 2.0], [1, np.inf]),
        ([1.0, 2.0], [1, 2, 3]),
    ],
)
def test_container_rejects_bad_arrays(f, z):
    with pytest.raises(ValueError):
        MeasuredResponses(np.array(f), {"Zin": np.array(z, dtype=complex)})


def test_error_is_one_line_and_picklable():
    e = MeasuredDataError("dir/data.csv", "negative magnitude -3.2\nsecond", 14, 2, "Zin_mag")
    assert str(e) == "dir/data.csv:14: column 2 'Zin_mag': negative magnitude -3.2 second"
    e2 = pickle.loads(pickle.dumps(e))
    assert str(e2) == str(e) and e2.line == 14
    assert isinstance(e, ValueError)


# ---------------------------------------------------------------------------
# round trips
# ---------------------------------------------------------------------------


@pytest.mark.parametrize("form", ["magphase", "reim"])
def test_response_csv_round_trip(tmp_path, form):
    d = random_responses(("Zin", "Zlvsc", "V_n2"), comments=["made by a test", "", " indented"])
    p = tmp_path / "resp.csv"
    write_response_csv(p, d, form=form)
    back = read_response_csv(p)
    assert_same(back, d)
    assert back.comments == d.comments
    assert back.source == str(p)
    assert detect_format(p) == "response_csv"
    assert_same(load_measured(p), d)


def test_response_csv_reim_is_bit_exact(tmp_path):
    d = random_responses(("Zin",), seed=7)
    p = tmp_path / "exact.csv"
    write_response_csv(p, d, form="reim")
    back = read_response_csv(p)
    np.testing.assert_array_equal(back.responses["Zin"], d.responses["Zin"])


def test_response_csv_segments_round_trip(tmp_path):
    a = random_responses(("Zin",), seed=1, segment="open", comments=["a"])
    b = random_responses(("Zin",), seed=2, n=30, segment="49.5R", comments=["b"])
    p = tmp_path / "segs.csv"
    write_response_csv(p, [a, b])
    assert list_segments(p) == ["open", "49.5R"]
    for want in (a, b):
        back = read_response_csv(p, segment=want.segment)
        assert_same(back, want)
        assert back.segment == want.segment and back.comments == want.comments
    assert_same(read_response_csv(p, segment="49.5 ohm"), b)  # numeric match
    with pytest.raises(MeasuredDataError, match="2 segments"):
        read_response_csv(p)
    with pytest.raises(MeasuredDataError, match="no segment 'closed'"):
        read_response_csv(p, segment="closed")


def test_multisegment_round_trip(tmp_path):
    segs = [
        random_responses(seed=s, n=40 + s, segment=lab, comments=[f"load {lab}"])
        for s, lab in enumerate(["1/(j*w*.2e-12)", "5e-3", "49.5"])
    ]
    p = tmp_path / "three.csv"
    write_multisegment_csv(p, segs)
    assert list_segments(p) == [s.segment for s in segs]
    assert detect_format(p) == "multisegment_csv"
    for s in segs:
        back = read_multisegment_csv(p, s.segment)
        assert_same(back, s)
        assert back.comments == s.comments
        assert_same(load_measured(p, segment=s.segment), s)


def test_mag_phase_rows_round_trip(tmp_path):
    rng = np.random.default_rng(11)
    n = 80
    f = 25e3 * np.arange(1, n + 1)
    z = 10.0 ** rng.uniform(-4, 1, n) * np.exp(1j * rng.uniform(-np.pi, np.pi, n))
    d = MeasuredResponses(f, {"Yin": z})
    p = tmp_path / "rows.txt"
    df = write_mag_phase_rows(p, d, dc_value=0.27 - 0.01j)
    assert df == 25e3
    back = read_mag_phase_rows(p, df=df)
    assert_same(back, d)
    assert "DC row" in back.comments[-1]
    assert detect_format(p) == "mag_phase_rows"
    # without a DC row the first row is at df
    p2 = tmp_path / "rows_nodc.txt"
    p2.write_text("".join(ln + "\n" for ln in p.read_text().splitlines()[1:]))
    assert_same(read_mag_phase_rows(p2, df=df, has_dc_row=False), d)


@pytest.mark.parametrize("form", ["rx", "zphase"])
def test_e4990a_round_trip(tmp_path, form):
    d = random_responses(n=50, fmin=20, fmax=2e3, comments=["Agilent Technologies,E4990A,X", "Date: test"])
    p = tmp_path / f"e4990a_{form}.csv"
    write_e4990a(p, d, form=form)
    assert b"\r\n" in p.read_bytes()
    back = read_e4990a(p)
    assert_same(back, d)
    assert back.comments == d.comments
    assert detect_format(p) == "e4990a"


@pytest.mark.parametrize("form", ["RI", "MA"])
@pytest.mark.parametrize("ports", [1, 2])
def test_touchstone_round_trip(tmp_path, form, ports):
    names = ("Zin",) if ports == 1 else ("Z11", "Z12", "Z21", "Z22")
    d = random_responses(names, seed=5, comments=["touchstone test"])
    p = tmp_path / f"z.s{ports}p"
    write_touchstone_z(p, d, form=form, unit="Hz", r_ref=50.0)
    back = read_touchstone_z(p)
    assert_same(back, d)
    assert back.comments == ["touchstone test"]
    assert detect_format(p) == "touchstone"


def test_touchstone_db_and_units(tmp_path):
    d = random_responses(("Z11", "Z12", "Z21", "Z22"), seed=9)
    # dB storage: 20*log10|z| loses ~|dB| ulps -> a few 1e-15 relative; the
    # accuracy limit of the format, not of the reader.
    p = tmp_path / "db.s2p"
    write_touchstone_z(p, d, form="DB", r_ref=75.0)
    assert_same(read_touchstone_z(p), d, rtol=1e-13)
    # frequency unit scaling (MHz) rounds f/1e6*1e6 to within an ulp
    p2 = tmp_path / "mhz.ts"
    write_touchstone_z(p2, d, form="RI", unit="MHz")
    back = read_touchstone_z(p2)
    np.testing.assert_allclose(back.frequency_hz, d.frequency_hz, rtol=1e-15, atol=0)
    for n in d.names:
        np.testing.assert_allclose(back.responses[n], d.responses[n], rtol=RTOL, atol=0)


def test_touchstone_known_values():
    """Hand-written files check the v1 2-port order and the R normalisation."""
    d = read_touchstone_z(DATA / "z_known.s2p")
    np.testing.assert_array_equal(d.frequency_hz, [1e6, 2e6])
    np.testing.assert_allclose(d.responses["Z11"], [50, 50 + 50j])
    np.testing.assert_allclose(d.responses["Z21"], [100, 100 + 100j])  # 2nd pair
    np.testing.assert_allclose(d.responses["Z12"], [150, 150 + 150j])  # 3rd pair
    np.testing.assert_allclose(d.responses["Z22"], [200, 200 + 200j])
    s = read_touchstone_z(DATA / "s_known.s1p")
    np.testing.assert_array_equal(s.frequency_hz, [1e3, 2e3, 3e3])
    np.testing.assert_allclose(s.responses["Zin"], [50, 100, 25], rtol=1e-14)


def test_mat_round_trip(tmp_path):
    d = random_responses(("Zin", "Zhvoc", "V_n3"), seed=4, comments=["one", "", "three"], segment="short")
    p = tmp_path / "resp.mat"
    write_mat(p, d)
    back = read_mat(p)
    assert_same(back, d, rtol=0)  # binary storage: exact
    assert back.comments == d.comments
    assert back.segment == "short"
    assert detect_format(p) == "mat"
    # also without comments/segment
    d2 = random_responses(("Zin",), seed=6)
    write_mat(tmp_path / "plain.mat", d2)
    back2 = read_mat(tmp_path / "plain.mat")
    assert_same(back2, d2, rtol=0)
    assert back2.comments == [] and back2.segment is None


def test_mat_alternative_layouts(tmp_path):
    import scipy.io

    d = random_responses(("Zin", "Zout"), seed=8, n=12)
    z, y = d.responses["Zin"], d.responses["Zout"]
    p = tmp_path / "alt.mat"
    scipy.io.savemat(
        p,
        {
            "f": d.frequency_hz,
            "Zin_mag": np.abs(z), "Zin_phase_deg": np.degrees(np.angle(z)),
            "Zout_re": y.real, "Zout_im": y.imag,
            "note": "ignored text", "fs": 1.0,
        },
    )
    back = read_mat(p)
    assert sorted(back.names) == ["Zin", "Zout"]
    np.testing.assert_allclose(back.responses["Zin"], z, rtol=RTOL, atol=0)
    np.testing.assert_array_equal(back.responses["Zout"], y)
    bad = tmp_path / "bad.mat"
    scipy.io.savemat(bad, {"frequency_hz": [1.0, 3.0, 2.0], "Zin": [1, 2, 3]})
    with pytest.raises(MeasuredDataError, match=r"bad.mat: variable 'frequency_hz': element 3"):
        read_mat(bad)


def test_waveform_round_trip(tmp_path):
    rng = np.random.default_rng(2)
    n, fs = 2000, 12.5e6
    t = np.arange(n) / fs
    cols = [np.sign(rng.standard_normal(n)) * 50.0, rng.standard_normal(n), rng.standard_normal(n) * 1e-3]
    p = tmp_path / "w.csv"
    write_waveform_csv(p, t, *cols, comments=["PRIS test"])
    assert detect_format(p) == "waveform_csv"
    w = read_waveform_csv(p)
    assert isinstance(w, Waveforms) and w.v_out is None
    np.testing.assert_array_equal(w.time_s, t)
    for got, want in zip((w.v_bprbs, w.v_in, w.i_in), cols):
        np.testing.assert_array_equal(got, want)
    assert w.comments == ["PRIS test"]
    assert w.fs == pytest.approx(fs, rel=1e-12)
    # with v_out, through a Waveforms object
    w2 = Waveforms(t, *cols, v_out=cols[1] * 0.5, comments=["x"])
    write_waveform_csv(p, w2)
    back = load_measured(p)
    assert isinstance(back, Waveforms)
    np.testing.assert_array_equal(back.v_out, w2.v_out)
    assert back.names == ["time_s", "v_bprbs", "v_in", "i_in", "v_out"]


def test_waveform_fixture_and_errors():
    w = read_waveform_csv(DATA / "wave_good.csv")
    assert w.n_samples == 4 and w.fs == pytest.approx(1e6)
    np.testing.assert_array_equal(w.v_out, [1, 1.1, 1.2, 1.0])
    expect_error(DATA / "wave_nonuniform.csv", 5, "non-uniform sampling", "time_s", reader=read_waveform_csv)
    with pytest.raises(ValueError, match="non-uniform"):
        Waveforms([0, 1, 3], [0, 0, 0], [0, 0, 0], [0, 0, 0])


def test_waveform_slow_path_line_numbers(tmp_path):
    p = tmp_path / "w_bad.csv"
    p.write_text("# c\ntime_s,v_bprbs,v_in,i_in\n0,1,1,1\n1,1,x,1\n2,1,1,1\n")
    expect_error(p, 4, "column 3 'v_in'", "not a number", reader=read_waveform_csv)
    p.write_text("time_s,v_bprbs,v_in,i_in,v_out,extra\n0,1,1,1,1,1\n")
    expect_error(p, 1, "'extra'", "unknown column", reader=read_waveform_csv)


# ---------------------------------------------------------------------------
# bad files
# ---------------------------------------------------------------------------

BAD_CSV = [
    ("empty.csv", 1, "empty file"),
    ("comments_only.csv", 2, "no header"),
    ("unknown_column.csv", 2, "column 4 'Zin_foo'"),
    ("mixed_columns.csv", 1, "mixes"),
    ("unpaired_column.csv", 1, "no matching column 'Zin_phase_deg'"),
    ("missing_frequency.csv", 1, "first column must be 'frequency_hz'"),
    ("wrong_count.csv", 4, "expected 3 columns"),
    ("nonmonotonic.csv", 5, "must increase strictly"),
    ("duplicated.csv", 5, "duplicated frequency 20.0 (same as line 3)"),
    ("nan.csv", 3, "column 2 'Zin_mag': non-finite value 'nan'"),
    ("inf.csv", 3, "non-finite value 'inf'"),
    ("negative_mag.csv", 3, "column 2 'Zin_mag': negative magnitude -3.2"),
    ("non_numeric.csv", 3, "column 2 'Zin_mag': not a number: 'abc'"),
    ("zero_frequency.csv", 2, "must be > 0"),
    ("one_point.csv", 2, "too few data rows: 1"),
]


@pytest.mark.parametrize("name, line, fragment", BAD_CSV)
def test_bad_response_csv(name, line, fragment):
    path = DATA / name
    expect_error(path, line, fragment, reader=read_response_csv)
    expect_error(path, line, fragment, reader=load_measured)


@pytest.mark.parametrize(
    "name, line, fragment, reader",
    [
        ("ts_nonmonotonic.s1p", 5, "must increase strictly", read_touchstone_z),
        ("ts_negative.s1p", 3, "column 2: negative magnitude -1.0", read_touchstone_z),
        ("e4990a_negative.csv", 6, "column 2 '|Z|(Ohm)-data': negative magnitude -2.0", read_e4990a),
        ("e4990a_no_end.csv", 4, "missing END", read_e4990a),
        ("rows_bad.txt", 3, "expected 2 columns", read_mag_phase_rows),
    ],
)
def test_bad_other_formats(name, line, fragment, reader):
    expect_error(DATA / name, line, fragment, reader=reader)
    expect_error(DATA / name, line, fragment, reader=load_measured)


def test_fixture_with_segments():
    p = DATA / "good_segments.csv"
    assert list_segments(p) == ["open", "49.5R"]
    info = segment_info(p)
    assert [s.n_rows for s in info] == [3, 2] and info[0].line == 3
    d = read_response_csv(p, "OPEN")
    assert d.names == ["Zin", "V_out"] and d.segment == "open"
    np.testing.assert_allclose(d.responses["Zin"], [100j, 200j, 300 * np.exp(1j * np.radians(89.5))], atol=1e-12)
    np.testing.assert_array_equal(d.responses["V_out"], [1, 0.5 - 0.5j, 0.25 - 0.25j])
    assert d.comments == ["good file, two responses, two segments", "load open (open)"]
    r = read_response_csv(p, 1)
    assert r.segment == "49.5R" and len(r) == 2
    with pytest.raises(MeasuredDataError, match="segment 'open' given"):
        load_measured(DATA / "z_known.s2p", segment="open")


# ---------------------------------------------------------------------------
# atomic writing
# ---------------------------------------------------------------------------


def _fail_after(n: int):
    calls = {"n": 0}
    real = M._fmt

    def fmt(x):
        calls["n"] += 1
        if calls["n"] > n:
            raise RuntimeError("simulated failure while writing")
        return real(x)

    return fmt


@pytest.mark.parametrize(
    "writer",
    [
        lambda p, d: write_response_csv(p, d),
        lambda p, d: write_multisegment_csv(p, MeasuredResponses(d.frequency_hz, d.responses, segment="s")),
        lambda p, d: write_e4990a(p, d),
        lambda p, d: write_waveform_csv(p, np.arange(len(d)) * 1e-6, d.mag("Zin"), d.mag("Zin"), d.mag("Zin")),
    ],
)
def test_failed_write_leaves_original_intact(tmp_path, monkeypatch, writer):
    target = tmp_path / "target.s1p"
    original = b"original content\n"
    target.write_bytes(original)
    fmt = _fail_after(25)
    for module in (measured_response_csv, measured_instruments, measured_waveform_csv):
        monkeypatch.setattr(module, "_fmt", fmt)  # each writer module formats its own numbers
    with pytest.raises(RuntimeError, match="simulated failure"):
        writer(target, random_responses(n=40))
    assert target.read_bytes() == original
    assert sorted(os.listdir(tmp_path)) == ["target.s1p"]  # no temporary left behind


def test_failed_touchstone_write_leaves_original_intact(tmp_path, monkeypatch):
    """Touchstone text comes from scikit-rf; a failure while it is written keeps the target."""
    from pris_cosim.measured import core as C
    from pris_cosim.measured import touchstone as T

    target = tmp_path / "target.s1p"
    original = b"original content\n"
    target.write_bytes(original)

    def failing(path, write, binary=False):
        def half(fh):
            fh.write("partial")
            raise RuntimeError("simulated failure while writing")

        return real(path, half, binary)

    real = C._atomic_write
    monkeypatch.setattr(C, "_atomic_write", failing)
    with pytest.raises(RuntimeError, match="simulated failure"):
        write_touchstone_z(target, random_responses(n=40))
    assert target.read_bytes() == original
    assert sorted(os.listdir(tmp_path)) == ["target.s1p"]
    assert "Z RI R 50.0" in T.touchstone_text([1.0, 2.0], np.ones((2, 1, 1)), "Z")


def test_failed_mat_write_leaves_original_intact(tmp_path, monkeypatch):
    import scipy.io

    target = tmp_path / "target.mat"
    d = random_responses(n=10)
    write_mat(target, d)
    before = target.read_bytes()

    def broken(fh, mdict, **kw):
        fh.write(b"MATLAB 5.0 partial")
        raise OSError("disk full (simulated)")

    monkeypatch.setattr(scipy.io, "savemat", broken)
    with pytest.raises(OSError, match="simulated"):
        write_mat(target, random_responses(n=10, seed=99))
    assert target.read_bytes() == before
    assert sorted(os.listdir(tmp_path)) == ["target.mat"]


def test_write_keeps_permissions(tmp_path):
    p = tmp_path / "perm.csv"
    p.write_text("x\n")
    os.chmod(p, 0o640)
    write_response_csv(p, random_responses(n=5))
    assert (os.stat(p).st_mode & 0o777) == 0o640


# ---------------------------------------------------------------------------
# real measured files (facts from the README and the physics, not from code)
# ---------------------------------------------------------------------------


def test_real_small_transformer_segments():
    p = REAL / "small_transformer_3_loads.csv"
    labels = list_segments(p)
    assert labels == ["1/(j*w*.2e-12)", "5e-3", "49.5"]
    assert [s.aliases for s in segment_info(p)] == [("open",), ("short",), ("measured",)]
    segs = {key: read_multisegment_csv(p, key) for key in ("open", "short", "49.5R")}
    for d in segs.values():
        assert 380 <= len(d) <= 420
        assert d.names == ["Zin"]
        assert d.frequency_hz[0] == pytest.approx(1e4, rel=0.01)
        assert d.frequency_hz[-1] == pytest.approx(2e7, rel=0.01)
        ratio = np.diff(np.log(d.frequency_hz))
        assert np.ptp(ratio) < 0.01 * ratio.mean()  # log-spaced
    assert segs["49.5R"].segment == "49.5"
    zo, zs = segs["open"].mag("Zin")[0], segs["short"].mag("Zin")[0]
    assert zs < 0.05 * zo  # short-circuit |Z| small vs open at 10 kHz
    # README: short-circuit resistance rises roughly tenfold 10 kHz -> 350 kHz
    short = segs["short"]
    r10 = short.response("Zin").real[0]
    r350 = np.interp(350e3, short.frequency_hz, short.response("Zin").real)
    assert 5 < r350 / r10 < 20
    # the resistor load looks like ~49.5 Ohm somewhere in the band
    assert np.min(np.abs(segs["49.5R"].mag("Zin") - 49.5)) < 1.0


def test_real_03pk10_admittance():
    d = load_measured(REAL / "distribution_transformer_admittance_03PK10.txt")
    assert d.names == ["Yin"]
    assert len(d) == 400
    np.testing.assert_allclose(np.diff(d.frequency_hz), 25e3)
    assert d.frequency_hz[0] == 25e3 and d.frequency_hz[-1] == 10e6
    mag, ph, f = d.mag("Yin"), d.phase_deg("Yin"), d.frequency_hz
    peaks = [i for i in range(1, len(f) - 1) if mag[i] > mag[i - 1] and mag[i] >= mag[i + 1]]
    for target in (0.93e6, 1.23e6, 1.83e6):
        near = [i for i in peaks if abs(f[i] - target) <= 30e3]
        assert near, f"no |Y| maximum within 30 kHz of {target} Hz"
        i = near[0]
        # admittance maximum = impedance minimum = series resonance: the phase
        # of Y passes through 0 from capacitive (+) to inductive (-) there
        assert ph[i - 2] > 0 > ph[i + 2]
        assert abs(ph[i]) < 35
    # the largest admittance (above DC) is the 0.93 MHz series resonance
    assert abs(f[np.argmax(mag)] - 0.925e6) <= 25e3


def test_real_e4990a_rx():
    d = load_measured(REAL / "coil_E4990A_R_X.csv")
    f, z = d.frequency_hz, d.response("Zin")
    assert d.names == ["Zin"] and len(d) == 201
    assert f[0] == 20.0 and f[-1] == 1000.0
    assert z.real[0] == pytest.approx(0.0915, rel=0.01)
    assert z.real[-1] == pytest.approx(1.80, rel=0.01)
    assert np.all(np.diff(z.real[::10]) > 0)  # R rises with frequency
    L = z.imag / (2 * np.pi * f)
    # ~9.4 mH coil: 9.93 mH at 20 Hz falling to 9.43 mH at 1 kHz
    assert L[0] == pytest.approx(9.93e-3, rel=0.01)
    assert L[-1] == pytest.approx(9.43e-3, rel=0.01)
    assert np.all((L > 9.3e-3) & (L < 10.0e-3))
    assert any("E4990A" in c for c in d.comments)


def test_real_e4990a_mag_phase_consistent():
    a = load_measured(REAL / "coil_E4990A_R_X.csv")
    b = load_measured(REAL / "coil_E4990A_mag_phase.csv")
    assert len(b) == 201 and b.frequency_hz[0] == 20.0 and b.frequency_hz[-1] == 2000.0
    assert np.all((b.phase_deg("Zin") > 85) & (b.phase_deg("Zin") < 90))  # inductive
    la = a.response("Zin").imag / (2 * np.pi * a.frequency_hz)
    lb = b.response("Zin").imag / (2 * np.pi * b.frequency_hz)
    for fq in (20, 50, 100, 200, 500, 1000):
        x = np.interp(fq, a.frequency_hz, la)
        y = np.interp(fq, b.frequency_hz, lb)
        assert y == pytest.approx(x, rel=0.02), fq
    ra = np.interp(1000, a.frequency_hz, a.response("Zin").real)
    rb = np.interp(1000, b.frequency_hz, b.response("Zin").real)
    assert rb == pytest.approx(ra, rel=0.1)


def test_real_detect_formats():
    assert detect_format(REAL / "small_transformer_3_loads.csv") == "multisegment_csv"
    assert detect_format(REAL / "distribution_transformer_admittance_03PK10.txt") == "mag_phase_rows"
    assert detect_format(REAL / "coil_E4990A_R_X.csv") == "e4990a"
    assert detect_format(REAL / "coil_E4990A_mag_phase.csv") == "e4990a"
    with pytest.raises(MeasuredDataError, match="3 segments"):
        load_measured(REAL / "small_transformer_3_loads.csv")
