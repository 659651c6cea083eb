"""Evidence a user can check: residuals by band, resonance counts and positions, where the misfit sits."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from ..resonances import find_resonances

REGIONS = ("low-frequency open-circuit", "low-frequency short-circuit", "resonance damping", "high frequency", "mid band")


def band_table(f: np.ndarray, errors: Mapping[str, np.ndarray], bands_per_decade: int = 1) -> list[dict[str, float]]:
    """RMS magnitude (dB) and phase (deg) error per response and per band."""
    lo, hi = np.floor(np.log10(f[0]) * bands_per_decade), np.ceil(np.log10(f[-1]) * bands_per_decade)
    edges = 10 ** (np.arange(lo, hi + 1) / bands_per_decade)
    rows = []
    for name, e in errors.items():
        for a, b in zip(edges[:-1], edges[1:]):
            sel = (f >= a) & (f < b) if b < edges[-1] else (f >= a) & (f <= b)
            if not np.any(sel):
                continue
            rows.append({
                "response": name, "band_hz": [float(max(a, f[0])), float(min(b, f[-1]))],
                "mag_rms_db": float(20 / np.log(10) * np.sqrt(np.mean(e[sel].real ** 2))),
                "phase_rms_deg": float(np.degrees(np.sqrt(np.mean(e[sel].imag ** 2)))),
            })
    return rows


def resonance_comparison(f: np.ndarray, measured: Mapping[str, np.ndarray], model: Mapping[str, np.ndarray]) -> dict[str, dict]:
    """Parallel/series resonances found in the measured and the model responses (impedances only)."""
    out = {}
    for name in measured:
        if not name.startswith("Z"):
            continue
        m = find_resonances(f, measured[name], min_prominence_db=1.0)
        p = find_resonances(f, model[name], min_prominence_db=1.0)
        out[name] = {
            "measured_parallel_hz": [r.frequency_hz for r in m if r.kind == "parallel"],
            "model_parallel_hz": [r.frequency_hz for r in p if r.kind == "parallel"],
            "measured_series_hz": [r.frequency_hz for r in m if r.kind == "series"],
            "model_series_hz": [r.frequency_hz for r in p if r.kind == "series"],
        }
    return out


def localise(f: np.ndarray, measured: Mapping[str, np.ndarray], errors: Mapping[str, np.ndarray]) -> dict[str, object]:
    """Where the baseline misfit sits: share of squared residual per region, and the dominant region."""
    energy = dict.fromkeys(REGIONS, 0.0)
    for name, e in errors.items():
        w = np.abs(e) ** 2
        res = [r.frequency_hz for r in find_resonances(f, measured[name], min_prominence_db=1.0)]
        near = np.zeros(f.size, bool)
        for fr in res:
            near |= np.abs(np.log(f / fr)) < np.log(1.15)
        first = res[0] if res else np.sqrt(f[0] * f[-1])
        last = res[-1] if res else np.sqrt(f[0] * f[-1])
        low = (f < first / 1.15) & ~near
        high = (f > last * 1.15) & ~near
        lowname = "low-frequency short-circuit" if "sc" in name.lower() else "low-frequency open-circuit"
        energy[lowname] += float(w[low].sum())
        energy["resonance damping"] += float(w[near].sum())
        energy["high frequency"] += float(w[high].sum())
        energy["mid band"] += float(w[~(low | high | near)].sum())
    total = sum(energy.values()) or 1.0
    shares = {k: v / total for k, v in energy.items()}
    return {"region": max(shares, key=lambda k: shares[k]), "shares": shares}
