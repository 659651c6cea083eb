"""Property tests for pris_cosim.signals.perturbation (PRBS, H-bridge, PRIS, metrics, RLC design)."""

from fractions import Fraction

import numpy as np
import pytest
import sympy

from pris_cosim.signals import perturbation as sg
from pris_cosim.signals.spectral import welch_psd

SMALL_ORDERS = range(2, 17)


# ---------------------------------------------------------------- helpers


def _gf2_mulmod(a: int, b: int, mod: int, degree: int) -> int:
    """Product of GF(2) polynomials a*b modulo mod (bit i = coefficient of x**i)."""
    result = 0
    while b:
        if b & 1:
            result ^= a
        b >>= 1
        a <<= 1
        if a >> degree & 1:
            a ^= mod
    return result


def _x_power(exponent: int, mod: int, degree: int) -> int:
    result, base = 1, 0b10
    while exponent:
        if exponent & 1:
            result = _gf2_mulmod(result, base, mod, degree)
        base = _gf2_mulmod(base, base, mod, degree)
        exponent >>= 1
    return result


def _windows(bits: np.ndarray, n: int) -> np.ndarray:
    """Integer value of every cyclic n-bit window of one period."""
    ext = np.concatenate([bits, bits[: n - 1]]).astype(np.int64)
    return sum(ext[i : i + bits.size] << (n - 1 - i) for i in range(n))


def _runs(bits: np.ndarray) -> list[tuple[int, int]]:
    """(bit value, length) of the runs of one period, read cyclically from a run start."""
    start = int(np.flatnonzero(bits != np.roll(bits, 1))[0])
    rotated = np.roll(bits, -start)
    cuts = np.flatnonzero(np.diff(rotated)) + 1
    return [(int(r[0]), r.size) for r in np.split(rotated, cuts)]


# ---------------------------------------------------------------- PRBS


@pytest.mark.parametrize("order", sorted(sg.MAX_LENGTH_TAPS))
def test_tap_polynomials_are_primitive(order):
    """x has multiplicative order exactly 2**n - 1 modulo 1 + sum(x**t)."""
    mod = 1 + sum(1 << t for t in sg.MAX_LENGTH_TAPS[order])
    n_max = 2**order - 1
    assert _x_power(n_max, mod, order) == 1
    for prime in sympy.factorint(n_max):
        assert _x_power(n_max // prime, mod, order) != 1


@pytest.mark.parametrize("order", SMALL_ORDERS)
def test_period_is_maximal(order):
    n_max = 2**order - 1
    two = sg.lfsr_prbs(order, periods=2)
    assert two.dtype == np.uint8 and two.size == 2 * n_max
    np.testing.assert_array_equal(two[n_max:], two[:n_max])
    # Every nonzero register state occurs exactly once per period, so no shorter repetition.
    states = _windows(two[:n_max], order)
    assert np.unique(states).size == n_max and states.min() == 1


@pytest.mark.parametrize("order", SMALL_ORDERS)
def test_balance(order):
    assert int(sg.lfsr_prbs(order).sum()) == 2 ** (order - 1)


@pytest.mark.parametrize("order", range(3, 13))
def test_circular_autocorrelation_is_two_valued(order):
    x = 2.0 * sg.lfsr_prbs(order) - 1
    acf = np.fft.ifft(np.abs(np.fft.fft(x)) ** 2).real
    n_max = x.size
    assert acf[0] == pytest.approx(n_max)
    np.testing.assert_allclose(acf[1:], -1, atol=1e-8)


@pytest.mark.parametrize("order", [3, 7, 12, 20])
def test_pieces_with_carried_state_equal_one_shot(order):
    seed = 5
    whole = sg.lfsr_prbs(order, periods=2, seed=seed)
    cuts = np.sort(np.random.default_rng(order).integers(0, whole.size, 5))
    sizes = [1, 0, order - 1, *np.diff(cuts)]  # includes empty and shorter-than-register pieces
    gen = sg.LFSR(order, seed)
    parts = [gen.next_bits(s) for s in sizes]
    resumed = sg.LFSR(order, seed=gen.state)  # a fresh generator from the carried state
    parts.append(resumed.next_bits(whole.size - sum(sizes)))
    np.testing.assert_array_equal(np.concatenate(parts), whole)
    assert resumed.state == seed  # two whole periods bring the register back


def test_prbs4_seed_1111_is_the_x4_x3_m_sequence():
    bits = sg.lfsr_prbs(4, seed=0b1111)
    np.testing.assert_array_equal(bits, sg.lfsr_prbs(4))  # all-ones is the default
    np.testing.assert_array_equal(bits[:4], 1)  # the seed is output first
    for j in range(4, 15):  # recurrence of the taps (4, 3)
        assert bits[j] == bits[j - 4] ^ bits[j - 3]
    # Run property: 2**(n-1) = 8 runs; 4 of length 1, 2 of length 2, then one
    # run of n-1 = 3 zeros and one of n = 4 ones.
    runs = _runs(bits)
    assert sorted(length for _, length in runs) == [1, 1, 1, 1, 2, 2, 3, 4]
    assert (0, 3) in runs and (1, 4) in runs
    # Shift-and-add property: s XOR shift(s, k) is another shift of s.
    shifts = {tuple(np.roll(bits, m)) for m in range(15)}
    for k in range(1, 15):
        assert tuple(bits ^ np.roll(bits, k)) in shifts


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"order": 1}, "order"),
        ({"order": 33}, "order"),
        ({"order": 4, "periods": 0}, "periods"),
        ({"order": 4, "seed": 0}, "seed"),
        ({"order": 4, "seed": 16}, "seed"),
        ({"order": 4, "seed": [1, 0, 1]}, "seed"),
    ],
)
def test_lfsr_prbs_rejects_bad_arguments(kwargs, name):
    with pytest.raises(ValueError, match=name):
        sg.lfsr_prbs(**kwargs)


def test_bipolar_levels():
    np.testing.assert_array_equal(sg.bipolar(np.array([1, 0, 1]), 30.0), [30.0, -30.0, 30.0])
    with pytest.raises(ValueError, match="bits"):
        sg.bipolar(np.array([0, 2]), 1.0)


# ---------------------------------------------------------------- H-bridge and PRIS


@pytest.mark.parametrize(("f_clk", "fs"), [(1000.0, 7777.0), (10e3, 300e3), (3e3, 44.1e3)])
def test_hbridge_samples_per_bit_and_no_drift(f_clk, fs):
    order, periods, vdc = 5, 200, 30.0
    t, v = sg.hbridge_waveform(order, f_clk, fs, vdc, periods)
    n_bits = periods * (2**order - 1)
    ratio = Fraction(fs) / Fraction(f_clk)  # exact samples per bit
    assert t.size == v.size == int(np.ceil(n_bits * ratio))
    assert t[-1] < n_bits / f_clk <= t[-1] + 1 / fs
    idx = np.array([k * Fraction(f_clk) // Fraction(fs) for k in range(t.size)], dtype=np.int64)
    counts = np.bincount(idx)
    assert counts.size == n_bits  # the last sample still falls in the last bit
    assert set(counts) <= {int(np.floor(ratio)), int(np.ceil(ratio))}
    assert counts.mean() == pytest.approx(float(ratio), abs=1 / n_bits)
    np.testing.assert_array_equal(v, sg.bipolar(sg.lfsr_prbs(order, periods)[idx], vdc))


def _peak(tau1, tau2):
    """Closed-form maximum of exp(-t/tau1) - exp(-t/tau2): (t*, value)."""
    t_star = tau1 * tau2 * np.log(tau1 / tau2) / (tau1 - tau2)
    return t_star, np.exp(-t_star / tau1) - np.exp(-t_star / tau2)


def test_pris_impulse_peak_matches_closed_form():
    f_clk, fs, tau1, tau2, amp = 1e3, 2e6, 60e-6, 8e-6, 2.5
    t, u = sg.pris_ideal(4, f_clk, fs, tau1, tau2, amp)
    first_bit = t < 1 / f_clk  # default seed: rising edge at t = 0 (last bit 0, first bit 1)
    k = np.argmax(u[first_bit])
    t_star, peak = _peak(tau1, tau2)
    assert abs(t[k] - t_star) <= 0.5 / fs  # the sampled maximum is the sample nearest t*
    assert amp * peak * (1 - 1e-4) <= u[k] <= amp * peak
    expected = amp * (np.exp(-t / tau1) - np.exp(-t / tau2))
    np.testing.assert_allclose(u[first_bit], expected[first_bit], rtol=1e-12, atol=1e-15)
    # Derivation: the only stationary point of (2.16) is the closed-form t*.
    ts, a, b = sympy.symbols("t a b", positive=True)
    (solution,) = sympy.solve(sympy.diff(sympy.exp(-ts / a) - sympy.exp(-ts / b), ts), ts)
    assert float(solution.subs({a: tau1, b: tau2})) == pytest.approx(t_star, rel=1e-12)


def test_pris_signs_chopping_and_periodicity():
    order, f_clk, fs, tau1, tau2 = 5, 1e3, 40e3, 300e-6, 50e-6  # 40 samples per bit
    t, u = sg.pris_ideal(order, f_clk, fs, tau1, tau2, 1.0, periods=2)
    bits = sg.lfsr_prbs(order, periods=2)
    edge = bits != np.roll(bits, 1)
    per_bit = u.reshape(bits.size, 40)
    np.testing.assert_array_equal(per_bit[edge, 0], 0)  # each impulse starts from zero
    # Sign follows the transition direction and persists until the next one.
    held_sign = np.where(bits == 1, 1.0, -1.0)
    assert np.all(np.sign(per_bit[:, 1:]) == held_sign[:, None])
    # Chopped: just after a transition the previous impulse has disappeared.
    t_star, peak = _peak(tau1, tau2)
    after = per_bit[edge, 1]
    np.testing.assert_allclose(np.abs(after), np.exp(-1 / fs / tau1) - np.exp(-1 / fs / tau2))
    half = u.size // 2
    np.testing.assert_allclose(u[:half], u[half:], atol=1e-12)  # exactly periodic
    assert np.abs(u).max() <= peak


def test_pris_follows_hbridge_polarity_on_a_non_multiple_grid():
    args = (6, 1000.0, 7777.0)  # order, f_clk, fs: 7.777 samples per bit
    t_v, v = sg.hbridge_waveform(*args, 1.0, periods=3)
    t_u, u = sg.pris_ideal(*args, 4e-4, 3e-5, 1.0, periods=3)
    np.testing.assert_array_equal(t_u, t_v)
    nonzero = u != 0
    assert nonzero.mean() > 0.9
    np.testing.assert_array_equal(np.sign(u[nonzero]), np.sign(v[nonzero]))


def test_pris_rejects_equal_time_constants():
    with pytest.raises(ValueError, match="tau1 and tau2"):
        sg.pris_ideal(4, 1e3, 10e3, 1e-4, 1e-4, 1.0)


# ---------------------------------------------------------------- swept sine and metrics


@pytest.mark.parametrize(("f1", "f2"), [(20.0, 2000.0), (1500.0, 100.0)])
def test_swept_sine_instantaneous_frequency(f1, f2):
    """The phase advances by pi between zero crossings: f = 1 / (2 dt) at their midpoint."""
    T0, fs, amp = 0.5, 50e3, 2.0
    t, u = sg.swept_sine(f1, f2, T0, fs, amp)
    assert t.size == 25000 and np.abs(u).max() <= amp
    k = np.flatnonzero(np.signbit(u[:-1]) != np.signbit(u[1:]))
    crossings = t[k] + u[k] / (u[k] - u[k + 1]) / fs  # linear interpolation
    mid = 0.5 * (crossings[1:] + crossings[:-1])
    f_inst = 0.5 / np.diff(crossings)
    np.testing.assert_allclose(f_inst, f1 + (f2 - f1) * mid / T0, rtol=2e-3)
    slope, start = np.polyfit(mid, f_inst, 1)
    assert start == pytest.approx(f1, rel=1e-3)
    assert start + slope * T0 == pytest.approx(f2, rel=1e-3)


def test_crest_factor_of_sine_and_square():
    t = np.arange(4000) / 4000.0  # 1 s, 4 samples per cycle at 1 kHz hit the peaks
    assert sg.crest_factor(np.sin(2 * np.pi * 50 * t)) == pytest.approx(np.sqrt(2))
    assert sg.crest_factor(np.sign(np.sin(2 * np.pi * 50 * t + 0.1))) == pytest.approx(1.0)
    with pytest.raises(ValueError, match="u"):
        sg.crest_factor(np.zeros(4))


def test_time_factor_of_sine_on_its_bin_is_one():
    fs = 1000.0
    t = np.arange(1000) / fs
    sine = 3.0 * np.cos(2 * np.pi * 50 * t)  # the samples include the peak
    assert sg.time_factor(sine, fs, 50.0, 50.0) == pytest.approx(1.0, rel=1e-9)
    shifted = 3.0 * np.cos(2 * np.pi * 50 * t + 0.3)  # sampled peak slightly missed
    assert sg.time_factor(shifted, fs, 50.0, 50.0) == pytest.approx(1.0, abs=1e-3)


def test_time_factor_of_flat_multisine_is_half_crest_squared():
    fs = 1000.0
    t = np.arange(1000) / fs
    multisine = sum(np.cos(2 * np.pi * f * t + np.pi * f**2 / 10) for f in range(10, 20))
    expected = 0.5 * sg.crest_factor(multisine) ** 2
    assert sg.time_factor(multisine, fs, 10.0, 19.0) == pytest.approx(expected, rel=1e-9)
    with pytest.raises(ValueError, match="fmin"):
        sg.time_factor(multisine, fs, 10.2, 10.8)


# ---------------------------------------------------------------- RLC design


@pytest.mark.parametrize(
    ("R", "L", "C"), [(100.0, 1e-3, 1e-6), (1e6, 2.53, 1e-9), (5.0, 2e-6, 3e-6), (1e4, 1e-6, 1e-3)]
)
def test_rlc_round_trip(R, L, C):
    tau1, tau2 = sg.rlc_time_constants(R, L, C)
    assert tau1 > tau2 > 0
    assert tau1 + tau2 == pytest.approx(R * C) and tau1 * tau2 == pytest.approx(L * C)  # Vieta

    np.testing.assert_allclose(sg.lc_from_time_constants(tau1, tau2, R), (L, C), rtol=1e-9)


def test_rlc_from_time_constants_and_scaling():
    tau1, tau2 = 80e-6, 7e-6
    base = sg.rlc_from_time_constants(tau1, tau2)
    assert base[0] == sg.THESIS_BASE_RLC[0]
    np.testing.assert_allclose(sg.rlc_time_constants(*base), (tau1, tau2), rtol=1e-9)
    for alpha in (1e-2, 1e3, 1e6):
        scaled = sg.rlc_from_time_constants(tau1, tau2, impedance_level=alpha)
        np.testing.assert_allclose(scaled, sg.scale_rlc(*base, alpha), rtol=1e-12)
        np.testing.assert_allclose(sg.rlc_time_constants(*scaled), (tau1, tau2), rtol=1e-9)


def test_underdamped_rlc_warns_and_returns_root_magnitudes():
    R, L, C = 1.0, 1e-3, 1e-6
    with pytest.warns(sg.UnderdampedWarning, match="zeta"):
        tau1, tau2 = sg.rlc_time_constants(R, L, C)
    magnitude = np.abs(np.roots([L * C, R * C, 1.0]))
    np.testing.assert_allclose([tau1, tau2], 1 / magnitude, rtol=1e-12)
    assert tau1 == tau2 == pytest.approx(np.sqrt(L * C))


def test_thesis_rlc_sets():
    """Thesis section 4.1.2: base (31.8 Ohm, 253 mH, 10 uF), alpha = 1000 and final source.

    All are underdamped, so (2.18)-(2.19) give tau1 = tau2 = sqrt(LC).  Scaling
    leaves the time constants unchanged; the quoted final source
    (31.8 kOhm, 2.53 H, 10 nF) is the alpha = 1000 image of (31.8 Ohm, 2.53 mH,
    10 uF) and has time constants 10x shorter than the printed base.
    """
    base = sg.THESIS_BASE_RLC
    scaled = sg.scale_rlc(*base, 1000.0)
    final = (31.8e3, 2.53, 10e-9)
    np.testing.assert_allclose(scaled, (31.8e3, 253.0, 10e-9))
    np.testing.assert_allclose(sg.scale_rlc(31.8, 2.53e-3, 10e-6, 1000.0), final)
    sets = {"base": base, "base x1000": scaled, "final": final}
    taus, zetas = {}, {}
    for name, rlc in sets.items():
        with pytest.warns(sg.UnderdampedWarning):
            taus[name] = sg.rlc_time_constants(*rlc)
        zetas[name] = sg.damping_ratio(*rlc)
        tau1, tau2 = taus[name]
        print(f"{name:>10}: R={rlc[0]:.4g} Ohm L={rlc[1]:.4g} H C={rlc[2]:.4g} F "
              f"zeta={zetas[name]:.4f} tau1={tau1 * 1e6:.2f} us tau2={tau2 * 1e6:.2f} us")
    assert taus["base"] == pytest.approx(taus["base x1000"], rel=1e-12)
    assert zetas["base"] == pytest.approx(zetas["base x1000"], rel=1e-12)
    assert taus["base"][0] == pytest.approx(1.5906e-3, rel=1e-4)
    assert taus["final"][0] == pytest.approx(159.06e-6, rel=1e-4)
    assert zetas["base"] == pytest.approx(0.1, abs=1e-3)
    assert zetas["final"] == pytest.approx(1.0, abs=1e-3)


# ---------------------------------------------------------------- spectra


def test_welch_psd_of_prbs_follows_sinc_squared():
    f_clk, fs, vdc = 1e3, 16e3, 2.0
    _, v = sg.hbridge_waveform(12, f_clk, fs, vdc, periods=2)
    f, psd = welch_psd(v, fs, nperseg=1024)
    band = (f >= 2 * f[1]) & (f <= f_clk / 2)
    error_db = 10 * np.log10(psd[band] / sg.prbs_psd_theory(f[band], f_clk, vdc))
    assert np.abs(error_db).max() < 0.3  # tolerance: 0.3 dB between 2 bins and f_clk/2


def test_prbs_psd_theory_landmarks():
    f_clk = 10e3
    s0 = sg.prbs_psd_theory(0.0, f_clk, 1.0)
    assert s0 == pytest.approx(2 / f_clk)
    assert sg.prbs_psd_theory(f_clk, f_clk, 1.0) == pytest.approx(0, abs=1e-20)

    def rel_db(f):
        return 10 * np.log10(sg.prbs_psd_theory(f, f_clk, 1.0) / s0)

    assert rel_db(f_clk / 3) == pytest.approx(-1.65, abs=0.01)  # not -3 dB, as often quoted
    assert rel_db(0.443 * f_clk) == pytest.approx(-3.0, abs=0.02)


def test_plot_psd_comparison_draws_one_line_per_curve():
    from matplotlib.figure import Figure

    from pris_cosim.signals.plots import plot_psd_comparison

    fs, f_clk = 20e3, 1e3
    ax = Figure().subplots()
    _, v = sg.hbridge_waveform(6, f_clk, fs, 1.0, periods=4)
    _, u = sg.pris_ideal(6, f_clk, fs, 3e-4, 5e-5, 1.0, periods=4)
    out = plot_psd_comparison(
        {"PRBS": v, "PRIS": u}, fs, nperseg=512, ax=ax,
        overlays={"theory": lambda f: sg.prbs_psd_theory(f, f_clk, 1.0)},
    )
    assert out is ax and len(ax.get_lines()) == 3
