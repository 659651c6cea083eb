"""Which PRBS bins carry information and how uncertain they are: closed forms and an independent Monte Carlo."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from scipy import signal as sps

from pris_cosim.measured.formats import MeasuredResponses, read_response_csv, write_response_csv
from pris_cosim.measured.core import MeasuredDataError
from pris_cosim.signals.uncertainty import (clock_null_mask, h1_log_sd, local_linear, log_band_edges, pooled,
    welch_averages)


def test_null_mask_is_the_band_around_each_clock_multiple():
    fclk, width = 20e3, 0.08
    f = np.arange(1, 200_001, 5.0)
    mask = clock_null_mask(f, fclk, width)
    # closed form: the PRBS spectrum sinc^2(f / fclk) vanishes at n fclk, n >= 1; the band is |f - n fclk| < w fclk
    expected = np.zeros(f.size, bool)
    for n in range(1, 11):
        expected |= np.abs(f - n * fclk) < width * fclk
    np.testing.assert_array_equal(mask, expected)
    # every masked bin has less PRBS power than any kept bin below the tenth null's band
    power = np.sinc(f / fclk) ** 2
    assert power[mask].max() < np.sinc(1 - width) ** 2 + 1e-15
    assert not mask[f < (1 - width) * fclk].any()  # nothing below the first null's band


def test_null_mask_refuses_bad_arguments():
    with pytest.raises(ValueError, match="fclk"):
        clock_null_mask([1.0], 0.0)
    with pytest.raises(ValueError, match="width"):
        clock_null_mask([1.0], 1.0, 0.5)


def test_welch_averages_closed_form():
    assert welch_averages(1000, 500, 0.625) == 3  # step 188: segments at 0, 188, 376
    assert welch_averages(1024, 128, 0.0) == 8
    assert welch_averages(100, 200, 0.5) == 1


@pytest.mark.parametrize("nseg, snr", [(3, 0.5), (3, 10.0), (16, 1.5)])
def test_h1_log_sd_matches_the_scatter_of_independent_estimates(nseg, snr):
    """y = h x + n, independent segments (SciPy's estimators): the spread of ln H1 over trials against the
    formula with the coherence pooled over eight bins."""
    rng = np.random.default_rng(1)
    nperseg, trials = 64, 200
    logs, cohs = [], []
    for _ in range(trials):
        x = rng.standard_normal(nseg * nperseg)
        y = 2.0 * x + rng.standard_normal(x.size) / np.sqrt(snr)
        _, pxy = sps.csd(x, y, nperseg=nperseg, noverlap=0, window="boxcar")
        _, pxx = sps.welch(x, nperseg=nperseg, noverlap=0, window="boxcar")
        with np.errstate(invalid="ignore"):  # SciPy divides by the (zero) power of a detrended DC bin
            _, coh = sps.coherence(x, y, nperseg=nperseg, noverlap=0, window="boxcar")
        logs.append(np.log(pxy[5:13] / pxx[5:13]))
        cohs.append(pooled(coh[5:13]))
    logs, cohs = np.array(logs), np.array(cohs)
    predicted = np.sqrt(np.mean(h1_log_sd(cohs, nseg) ** 2))
    assert predicted == pytest.approx(np.std(logs.real), rel=0.15)
    assert predicted == pytest.approx(np.std(logs.imag), rel=0.15)
    if nseg == 3:  # the coherence of three segments is biased towards one: uncorrected, the error comes out low
        uncorrected = np.sqrt(np.mean((1 - cohs) / (2 * nseg * cohs)))
        assert uncorrected < 0.9 * np.std(logs.real)


def test_pooled_is_a_moving_mean():
    v = np.arange(10.0)
    np.testing.assert_allclose(pooled(v, 4), [1.5, 1.5, 1.5, 2.5, 3.5, 4.5, 5.5, 6.5, 7.5, 7.5])
    np.testing.assert_allclose(pooled(v, 1), v)


def test_local_linear_is_exact_on_a_straight_line_and_its_sd_is_that_of_a_mean():
    f = np.arange(1.0, 2001.0)
    h = (3 + 0.01 * f) + 1j * (1 - 0.002 * f)
    centres = np.geomspace(20, 1500, 60)
    s = np.full(f.size, 0.02)
    vals, sd, m = local_linear(f, h, s, centres, max_bins=5)
    edges = log_band_edges(centres)
    np.testing.assert_array_equal(m, [np.count_nonzero((f >= a) & (f < b)) for a, b in itertools.pairwise(edges)])
    ok = m > 0
    np.testing.assert_allclose(vals[ok], (3 + 0.01 * centres[ok]) + 1j * (1 - 0.002 * centres[ok]), rtol=1e-12)
    # five bins centred on the centre: the line's value there is their mean, sd s / sqrt(5)
    assert np.all(sd[m >= 5] <= 0.02 / np.sqrt(5) * 1.2)
    assert np.all(sd[ok] >= 0.02 / np.sqrt(5) * (1 - 1e-12))


def test_local_linear_leaves_bands_without_bins_empty():
    f = np.array([10.0, 12.0, 14.0, 16.0, 30.0, 32.0])
    h = np.ones(f.size, complex)
    vals, sd, m = local_linear(f, h, np.full(f.size, 0.1), np.array([10.0, 13.0, 20.0, 31.0]))
    assert m.tolist() == [1, 3, 0, 2]
    assert np.isnan(vals[2]) and np.isinf(sd[2])
    assert np.all(np.isfinite(sd[[0, 1, 3]]))
    # a centre beyond the bins its band holds (the edge of a left-out stretch) is not extrapolated
    vals, sd, m = local_linear(f, h, np.full(f.size, 0.1), np.array([14.0, 29.0, 60.0]))
    assert m[1] == 0 and np.isnan(vals[1])


def test_response_csv_uncertainty_columns_round_trip(tmp_path):
    f = np.array([10.0, 20.0, 40.0])
    data = MeasuredResponses(f, {"Zin": np.array([1 + 1j, 2 + 1j, 3 - 1j]), "Rab": np.array([0.5, 0.4, 0.3])},
                             uncertainty={"Zin": np.array([0.01, 0.02, 0.5])})
    p = tmp_path / "r.csv"
    write_response_csv(p, data)
    header = next(ln for ln in p.read_text().splitlines() if not ln.startswith("#"))
    assert header == "frequency_hz,Zin_mag,Zin_phase_deg,Zin_ln_sd,Rab_mag,Rab_phase_deg"
    back = read_response_csv(p)
    assert list(back.uncertainty) == ["Zin"]
    np.testing.assert_allclose(back.uncertainty["Zin"], [0.01, 0.02, 0.5], rtol=1e-15)
    # a file without the columns reads as before, with no uncertainty
    q = tmp_path / "plain.csv"
    q.write_text("frequency_hz,Zin_mag,Zin_phase_deg\n10,1,0\n20,2,0\n")
    assert read_response_csv(q).uncertainty == {}


@pytest.mark.parametrize("text, message", [
    ("frequency_hz,Zin_mag,Zin_phase_deg,Zx_ln_sd\n10,1,0,0.1\n20,1,0,0.1\n", "uncertainty column of no response"),
    ("frequency_hz,Zin_mag,Zin_phase_deg,Zin_ln_sd\n10,1,0,0.1\n20,1,0,0\n", "uncertainty must be > 0"),
])
def test_response_csv_refuses_bad_uncertainty(tmp_path, text, message):
    p = tmp_path / "bad.csv"
    p.write_text(text)
    with pytest.raises(MeasuredDataError, match=message):
        read_response_csv(p)


def test_measured_responses_refuse_an_uncertainty_of_no_response():
    with pytest.raises(ValueError, match="not a response"):
        MeasuredResponses([1.0, 2.0], {"Zin": [1, 2]}, uncertainty={"Zx": [0.1, 0.1]})
    with pytest.raises(ValueError, match="positive"):
        MeasuredResponses([1.0, 2.0], {"Zin": [1, 2]}, uncertainty={"Zin": [0.1, -1]})
