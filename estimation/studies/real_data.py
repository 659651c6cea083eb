"""Lumped-network fits of the real measured transformer data (:mod:`estimation.real_fits`).

Fits, in order:

1. the small transformer's open, short and 49.5 Ohm segments jointly by one
   two-winding circuit with constant winding resistances;
2. the same with the winding resistances given a skin-effect factor,
   realised as passive R-L ladders (the gain over 1);
3. the 03PK10 distribution-transformer admittance by a parallel-branch
   R-L-C ladder.

The answer (also ``<out>/study.json``) has one row per fitted case and
model, a text table, the short-circuit resistance comparison and
``checks`` against stated bounds.  The data directory defaults to
the real measurements shipped with the package (``pris_cosim/data/real``)
and is overridden by the environment variable ``PRIS_COSIM_REAL_DATA``.
"""

from __future__ import annotations

import os
import time
from pathlib import Path
from typing import Any

from pris_cosim.datafiles import REAL

from estimation import real_fits as rf
from estimation.studies import common

NAME = "real-data"
ENV_VAR = "PRIS_COSIM_REAL_DATA"

#: Bounds the checks hold the fits to.
BOUNDS = {
    "small_rms_db": 0.5,          # each load, constant-R model, in the fitted band
    "admittance_rms_db": 1.0,     # 03PK10, in the fitted band
    "peak_error_percent": 3.0,    # each admittance peak
    "measured_rise": 5.0,         # Re Z_short(350 kHz) / Re Z_short(10 kHz) at least
    "constant_r_rise": 2.0,       # the constant-R model's Re Z_short rise at most (its shunt core loss adds a little)
}

#: Swarm evaluations before the least squares (full run; the quick run uses none).
GLOBAL_EVALS = 1500


def data_dir() -> Path:
    """Directory of the real data: ``$PRIS_COSIM_REAL_DATA`` or the shipped ``pris_cosim/data/real``."""
    env = os.environ.get(ENV_VAR)
    return Path(env) if env else REAL


def _require_data(folder: Path) -> tuple[Path, Path]:
    small, adm = folder / rf.SMALL_FILE, folder / rf.ADMITTANCE_FILE
    missing = [p.name for p in (small, adm) if not p.is_file()]
    if missing:
        raise ValueError(f"real data not found in {folder}: missing {', '.join(missing)} "
                         f"(set {ENV_VAR} to the directory holding them)")
    return small, adm


def _rows_small(fit: rf.FitResult, model: str) -> list[dict[str, Any]]:
    return [{"case": rf.SMALL_LOADS[ld][0], "model": model, "errors_db": {"Zin": fit.extra["errors_db"][ld]},
             "phase_errors_deg": {"Zin": fit.extra["phase_errors_deg"][ld]}, "passive": fit.passive,
             "wall_s": fit.wall_s, "estimate": dict(fit.values), "band_hz": fit.extra["band_hz"], "nfev": fit.nfev}
            for ld in rf.SMALL_LOADS]


def _table(rows: list[dict[str, Any]]) -> str:
    head = f"{'case':<13}{'model':<34}{'RMS dB':>8}{'RMS deg':>9}{'passive':>9}{'time':>8}"
    lines = [head, "-" * len(head)]
    for r in rows:
        name = next(iter(r["errors_db"]))
        lines.append(f"{r['case']:<13}{r['model']:<34}{r['errors_db'][name]:8.3f}"
                     f"{r['phase_errors_deg'][name]:9.2f}{'yes' if r['passive'] else 'NO':>9}{r['wall_s']:7.1f}s")
    return "\n".join(lines)


def run(quick: bool, out: str | None, scheduler: str | None = None, workers: int | None = None, seed: int = 1,
        progress: bool = True) -> dict[str, Any]:
    """Run every real-data fit; the JSON answer of ``pris-cosim study real-data``.

    Parameters
    ----------
    quick : bool
        Least squares from the physics-based starts only (no swarm stage).
    out : str, optional
        Directory for ``study.json`` and the PNGs (None: nothing written).
    scheduler, workers
        Accepted for the common study interface; the fits run serially in
        this process (a few seconds in all).
    seed : int
        Seed of the swarm stage.
    progress : bool
        Progress lines on stderr.

    Returns
    -------
    dict
        ``study``, ``quick``, ``rows`` (``case``, ``model``, ``errors_db``,
        ``phase_errors_deg``, ``passive``, ``wall_s``, ``estimate``),
        ``table``, ``short_circuit``, ``admittance_peaks``, ``bounds``,
        ``checks``, ``plots``, ``out``, ``wall_s``.

    Raises
    ------
    ValueError
        The data directory lacks the files (one line naming it), or a file is
        malformed (:class:`pris_cosim.measured.formats.MeasuredDataError`).
    """
    t0 = time.perf_counter()
    say = common.say if progress else (lambda text: None)
    small_path, adm_path = _require_data(data_dir())
    evals = 0 if quick else GLOBAL_EVALS
    small = rf.read_small_transformer(small_path)
    say(f"{NAME}: small transformer, constant-R two-winding model, 3 loads jointly")
    fit = rf.fit_small_transformer(small, seed=seed, global_evals=evals)
    say(f"{NAME}:   {fit.wall_s:.1f} s, RMS dB " + ", ".join(f"{k} {v:.3f}" for k, v in fit.extra["errors_db"].items()))
    say(f"{NAME}: small transformer, skin-effect ladders")
    skin = rf.fit_small_transformer_skin(small, fit, max_nfev=40 if quick else 100)
    say(f"{NAME}:   {skin.wall_s:.1f} s, RMS dB " + ", ".join(f"{k} {v:.3f}" for k, v in skin.extra["errors_db"].items()))
    adm = rf.read_admittance(adm_path)
    say(f"{NAME}: 03PK10 admittance, parallel-branch ladder")
    afit = rf.fit_admittance(adm, seed=seed, global_evals=evals)
    say(f"{NAME}:   {afit.wall_s:.1f} s, RMS dB {afit.extra['errors_db']['band']:.3f} in band")
    sc = rf.short_circuit_resistance(small, fit, skin)

    rows = _rows_small(fit, "two-winding, constant R") + _rows_small(skin, "two-winding, skin-effect ladder R")
    rows.append({"case": "03PK10", "model": f"parallel R-L-C ladder, {afit.extra['branches']} branches",
                 "errors_db": {"Yin": afit.extra["errors_db"]["band"], "Yin_whole_file": afit.extra["errors_db"]["all"]},
                 "phase_errors_deg": {"Yin": afit.extra["phase_errors_deg"]["band"],
                                      "Yin_whole_file": afit.extra["phase_errors_deg"]["all"]},
                 "passive": afit.passive, "wall_s": afit.wall_s, "estimate": afit.values,
                 "band_hz": afit.extra["band_hz"], "nfev": afit.nfev})
    peaks = {k: afit.extra[k] for k in ("peaks_measured_hz", "peaks_fitted_hz", "peak_errors_percent")}
    checks = {
        "small_errors_below_bound": all(v < BOUNDS["small_rms_db"] for v in fit.extra["errors_db"].values()),
        "admittance_error_below_bound": afit.extra["errors_db"]["band"] < BOUNDS["admittance_rms_db"],
        "resonances_matched": len(peaks["peaks_measured_hz"]) == afit.extra["branches"]
        and all(abs(e) < BOUNDS["peak_error_percent"] for e in peaks["peak_errors_percent"]),
        "short_resistance_rises": sc["rise"]["measured"] > BOUNDS["measured_rise"],
        "constant_r_flat": sc["rise"]["constant_r"] < BOUNDS["constant_r_rise"],
        "skin_effect_improves_short": skin.extra["errors_db"]["short"] < fit.extra["errors_db"]["short"],
        "all_passive": all(r["passive"] for r in rows),
    }
    table = _table(rows)
    plots = rf.write_plots(out, small, fit, skin, adm, afit) if out is not None else []
    summary = {
        "study": NAME,
        "quick": quick,
        "data_dir": str(data_dir()),
        "rows": rows,
        "table": table,
        "short_circuit": {k: sc[k] for k in ("f_low_hz", "f_high_hz", "rise", "winding_r_ohm")},
        "admittance_peaks": peaks,
        "skin_effect": {"a": skin.values["a"], "b": skin.values["b"], "f0_hz": rf.SKIN_F0_HZ,
                        "formula_errors_db": skin.extra["formula_errors_db"]},
        "bounds": BOUNDS,
        "checks": checks,
        "plots": [str(p) for p in plots],
        "out": out,
        "wall_s": time.perf_counter() - t0,
    }
    common.write_summary(out, summary)
    if progress:
        say(table)
    return summary
