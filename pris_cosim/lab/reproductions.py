"""Reproductions of the thesis's simulated-perturbation figures, with plots and figures of merit.

- :func:`impedance_level_study`: Figs. 4.3-4.6, the source RLC scaled by
  ``alpha`` (4.15)-(4.17) in front of the two-section winding: PSDs of v_in
  and i_in with the RLC impedance, and Zin by simulated PRIS perturbation
  against the analytic Zin. A low ``alpha`` makes the current spiky and the
  estimate alias.
- :func:`two_section_responses`: Fig. 4.7, Zin, R1in and R2in by PRIS
  perturbation against the analytic responses.
- :func:`three_section_responses`: Figs. 4.11 and 4.12, the waveforms and Zin
  of the three-section winding.

Every function returns its figures of merit (median and 90th-percentile
relative error of the estimate where the coherence exceeds 0.99) and writes
PNG files when given a directory. The base RLC is 31.8 Ohm, 2.53 mH, 10 uF:
with ``alpha = 1000`` it is the thesis's final two-section source (31.8 kOhm,
2.53 H, 10 nF); the thesis prints the base inductance as 253 mH, which
cannot give that source.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from pris_cosim.circuits.arrangement import SourceSettings
from pris_cosim.frf.response import ResponseModel
from pris_cosim.plotting import pyplot
from pris_cosim.models.builtin import get_model
from pris_cosim.signals.spectral import estimate_response, welch_psd
from pris_cosim.lab.timedomain import simulate_pris

BASE_RLC = (31.8, 2.53e-3, 10e-6)  # Ohm, H, F; alpha = 1000 gives 31.8 kOhm, 2.53 H, 10 nF (thesis 4.1.2)
COHERENCE_MIN = 0.99


def _merit(est: np.ndarray, ref: np.ndarray, mask: np.ndarray) -> dict[str, float]:
    err = np.abs(est[mask] / ref[mask] - 1)
    return {"median_rel_error": float(np.median(err)) if err.size else float("nan"),
            "p90_rel_error": float(np.percentile(err, 90)) if err.size else float("nan"),
            "points": int(mask.sum())}


def _band(f: np.ndarray, coh: np.ndarray, fmin: float, fmax: float) -> np.ndarray:
    return (f >= fmin) & (f <= fmax) & (coh > COHERENCE_MIN)


def two_section_waveforms(alpha: float = 1000.0, fs: float = 300e3, prbs_order: int = 12) -> dict[str, np.ndarray]:
    """PRIS waveforms of the two-section winding (30 V, 10 kHz clock, base RLC scaled by ``alpha``, one PRBS period)."""
    r, l, c = BASE_RLC
    settings = SourceSettings(vdc=30.0, prbs_order=prbs_order, fclk=10e3, rpris=r * alpha, lpris=l * alpha, cpris=c / alpha)
    return simulate_pris(get_model("two-section").circuit, "in", settings, fs, periods=1)


def impedance_level_study(alphas: tuple[float, ...] = (1.0, 1e3, 1e6), fs: float = 300e3,
                          out_dir: str | Path | None = None) -> dict[str, Any]:
    """Figs. 4.3-4.6: effect of the RLC impedance level on the estimated Zin (two-section winding).

    Returns
    -------
    dict
        Per alpha: figures of merit of Zin from 20 Hz to f_clk/3 where the coherence exceeds 0.99.
    """
    rm = ResponseModel(get_model("two-section").circuit, "in")
    results: dict[str, Any] = {}
    plt = pyplot() if out_dir else None
    for alpha in alphas:
        w = two_section_waveforms(alpha, fs)
        resp = estimate_response(w["i_in"], w["v_in"], fs, fmin=1.0)
        f, z, coh = resp.frequency_hz, resp.values, resp.coherence
        ref = rm.evaluate(f)["Zin"]
        results[f"alpha={alpha:g}"] = _merit(z, ref, _band(f, coh, 20.0, 10e3 / 3))
        if plt is not None:
            s = 2j * np.pi * f
            r, l, c = BASE_RLC
            z_rlc = r * alpha + s * l * alpha + alpha / (s * c)
            fig, ax = plt.subplots(1, 2, figsize=(11, 4))
            fv, pv = welch_psd(w["v_in"], fs)
            fi, pi = welch_psd(w["i_in"], fs)
            ax[0].loglog(fv[1:], pv[1:], label="v_in PSD (V²/Hz)")
            ax[0].loglog(fi[1:], pi[1:], label="i_in PSD (A²/Hz)")
            ax[0].set_xlabel("frequency (Hz)")
            ax[0].legend(fontsize="small")
            ax[0].set_title(f"PSDs, alpha = {alpha:g}")
            ax[1].loglog(f, np.abs(z), label="PRIS estimate", lw=1)
            ax[1].loglog(f, np.abs(ref), "k--", label="analytic", lw=1)
            ax[1].loglog(f, np.abs(z_rlc), ":", color="gray", label="|Z_rlc|")
            ax[1].set_xlabel("frequency (Hz)")
            ax[1].set_ylabel("|Zin| (Ohm)")
            ax[1].legend(fontsize="small")
            ax[1].set_title(f"Zin, alpha = {alpha:g}")
            for a in ax:
                a.grid(True, which="both", alpha=0.3)
            fig.tight_layout()
            Path(out_dir).mkdir(parents=True, exist_ok=True)
            fig.savefig(Path(out_dir) / f"fig4_3-4_6_alpha_{alpha:g}.png", dpi=100)
            plt.close(fig)
    return results


def two_section_responses(fs: float = 300e3, out_dir: str | Path | None = None) -> dict[str, Any]:
    """Fig. 4.7: Zin, R1in, R2in of the two-section winding by PRIS perturbation (alpha = 1000) against analytic."""
    model = get_model("two-section")
    w = two_section_waveforms(1000.0, fs)
    est = {
        "Zin": estimate_response(w["i_in"], w["v_in"], fs, fmin=1.0),
        "R1in": estimate_response(w["v_in"], w["v_in"] - w["v_mid"], fs, fmin=1.0),
        "R2in": estimate_response(w["v_in"], w["v_mid"], fs, fmin=1.0),
    }
    f = est["Zin"].frequency_hz
    ref = model.response_set().evaluate(f)
    results = {n: _merit(e.values, ref[n], _band(f, e.coherence, 20.0, 10e3 / 3)) for n, e in est.items()}
    if out_dir:
        plt = pyplot()
        fig, ax = plt.subplots(2, 3, figsize=(13, 6), sharex=True)
        for j, n in enumerate(est):
            ax[0, j].loglog(f, np.abs(est[n].values), lw=1, label="PRIS")
            ax[0, j].loglog(f, np.abs(ref[n]), "k--", lw=1, label="analytic")
            ax[1, j].semilogx(f, np.degrees(np.angle(est[n].values)), lw=1)
            ax[1, j].semilogx(f, np.degrees(np.angle(ref[n])), "k--", lw=1)
            ax[0, j].set_title(n)
            ax[1, j].set_xlabel("frequency (Hz)")
            for a in ax[:, j]:
                a.grid(True, which="both", alpha=0.3)
                a.set_xlim(10, 10e3 / 2)
        ax[0, 0].legend(fontsize="small")
        ax[1, 0].set_ylabel("phase (deg)")
        fig.tight_layout()
        Path(out_dir).mkdir(parents=True, exist_ok=True)
        fig.savefig(Path(out_dir) / "fig4_7_two_section.png", dpi=100)
        plt.close(fig)
    return results


def three_section_responses(fs: float = 10e6, out_dir: str | Path | None = None) -> dict[str, Any]:
    """Figs. 4.11-4.12: three-section waveforms and Zin (100 V, PRBS12 at 100 kHz, 150 Ohm / 4 mH / 1 uF)."""
    model = get_model("three-section")
    settings = SourceSettings(vdc=100.0, prbs_order=12, fclk=100e3, rpris=150.0, lpris=4e-3, cpris=1e-6)
    w = simulate_pris(model.circuit, "n1", settings, fs, periods=1)
    resp = estimate_response(w["i_in"], w["v_in"], fs, fmin=1.0)
    f = resp.frequency_hz
    ref = ResponseModel(model.circuit, "n1").evaluate(f)["Zin"]
    results = {"Zin": _merit(resp.values, ref, _band(f, resp.coherence, 1e3, 100e3 / 3 * 10))}
    if out_dir:
        plt = pyplot()
        fig, ax = plt.subplots(1, 2, figsize=(12, 4))
        k = int(200e-6 * fs)
        ax[0].plot(w["time_s"][:k] * 1e6, w["v_in"][:k], lw=0.8, label="v_in (V)")
        ax[0].plot(w["time_s"][:k] * 1e6, w["i_in"][:k] * 100, lw=0.8, label="i_in x 100 (A)")
        ax[0].plot(w["time_s"][:k] * 1e6, w["v_bprbs"][:k], lw=0.6, alpha=0.5, label="v_bprbs (V)")
        ax[0].set_xlabel("time (us)")
        ax[0].legend(fontsize="small")
        ax[0].set_title("Fig. 4.11: waveforms")
        ax[1].loglog(f, np.abs(resp.values), lw=1, label="PRIS")
        ax[1].loglog(f, np.abs(ref), "k--", lw=1, label="analytic")
        ax[1].set_xlim(1e3, 2e6)
        ax[1].set_xlabel("frequency (Hz)")
        ax[1].set_title("Fig. 4.12: Zin")
        ax[1].legend(fontsize="small")
        for a in ax:
            a.grid(True, which="both", alpha=0.3)
        fig.tight_layout()
        Path(out_dir).mkdir(parents=True, exist_ok=True)
        fig.savefig(Path(out_dir) / "fig4_11-4_12_three_section.png", dpi=100)
        plt.close(fig)
    return results
